"""The error of a file that does not exist, one way across the Python API; the reading of a
text file (a rule or scene file) that refuses what is not a regular file.

A missing file raises :class:`FileNotFoundError` (``errno`` ``ENOENT``, ``filename`` the
path), as :func:`open` does, whichever reader was asked for it: :meth:`GMap.load
<topomech.GMap.load>`, :meth:`RuleSet.load <topomech.RuleSet.load>` (both in the kernel's
bindings), :func:`topomech.io.read_mesh`, :func:`topomech.io.import_mesh`,
:func:`topomech.load_scene` and :meth:`Model.load <topomech.Model.load>`. topomech's own
classes (:class:`MeshReadError`, :class:`FileFormatError`, :class:`RuleError`,
:class:`SceneError`) are for files that exist and are refused.

A path that is not a regular file (``/dev/zero``, a FIFO: an endless or blocking stream; a
directory) is refused by :func:`read_text_file` before anything is read from it, as the mesh
and map readers refuse it.
"""

from __future__ import annotations

import errno
import io
import os
import stat

__all__ = ["missing_file", "read_text_file"]


def missing_file(path: str | os.PathLike[str], why: str | None = None) -> FileNotFoundError:
    """The :class:`FileNotFoundError` of ``path``: ``[Errno 2] WHY: 'PATH'``, where ``why``
    defaults to the system's ``No such file or directory``."""
    return FileNotFoundError(errno.ENOENT, why or os.strerror(errno.ENOENT), os.fspath(path))


def read_text_file(path: str | os.PathLike[str], what: str) -> str:
    """The UTF-8 text of the regular file ``path`` (newlines translated, as
    :meth:`pathlib.Path.read_text` reads it); ``what`` names the kind of file in refusals
    ("rule file", "scene file").

    Raises :class:`FileNotFoundError` when it does not exist, :class:`IsADirectoryError` for a
    directory and :class:`OSError` (``EINVAL``) for a device, FIFO or socket (``/dev/zero``,
    a named pipe: an endless or blocking stream), both before reading anything and with a
    ``strerror`` that says so; :class:`OSError` when it cannot be read and
    :class:`UnicodeDecodeError` when it is not UTF-8."""
    p = os.fspath(path)
    # O_NONBLOCK: opening a FIFO without a writer returns at once (it is refused below)
    # instead of waiting for one; on a regular file it changes nothing
    fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, f"is a directory, not a {what}", p)
        if not stat.S_ISREG(mode):
            raise OSError(
                errno.EINVAL,
                f"not a regular file (a device, FIFO or socket); a {what} is read only from "
                "a regular file",
                p,
            )
        raw = io.FileIO(fd, "r", closefd=False)
        with io.TextIOWrapper(io.BufferedReader(raw), encoding="utf-8") as f:
            text = f.read()
    finally:
        os.close(fd)
    return text
