"""The error of a file that does not exist, one way across the Python API.

A missing file raises :class:`FileNotFoundError` (``errno`` ``ENOENT``, ``filename`` the
path), as :func:`open` does, whichever reader was asked for it: :meth:`GMap.load
<topomech.GMap.load>`, :meth:`RuleSet.load <topomech.RuleSet.load>` (both in the kernel's
bindings), :func:`topomech.io.read_mesh`, :func:`topomech.io.import_mesh`,
:func:`topomech.load_scene` and :meth:`Model.load <topomech.Model.load>`. topomech's own
classes (:class:`MeshReadError`, :class:`FileFormatError`, :class:`RuleError`,
:class:`SceneError`) are for files that exist and are refused.
"""

from __future__ import annotations

import errno
import os

__all__ = ["missing_file"]


def missing_file(path: str | os.PathLike[str], why: str | None = None) -> FileNotFoundError:
    """The :class:`FileNotFoundError` of ``path``: ``[Errno 2] WHY: 'PATH'``, where ``why``
    defaults to the system's ``No such file or directory``."""
    return FileNotFoundError(errno.ENOENT, why or os.strerror(errno.ENOENT), os.fspath(path))
