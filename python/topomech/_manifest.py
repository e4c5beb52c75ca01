"""The manifest of a run's output folder: what topomech wrote there, so that a rerun removes
only that.

``.topomech-manifest.jsonl`` in the output folder is a header line
``{"topomech_manifest": 1}`` followed by one JSON string a line: the path, relative to the
folder and with ``/`` separators, of each file or folder a run created there. An entry is
appended (and flushed) BEFORE its file is created, so a run that crashes or is killed still
leaves a manifest that lists everything it wrote (and possibly one file it had not created
yet). A truncated last line, a line that is not a JSON string, an absolute path or one with
``..``, ``.`` or an empty component is ignored: such an entry is never deleted.

:class:`OutputFolder` uses it: :meth:`~OutputFolder.check` refuses a folder holding files no
manifest lists (:class:`OutputError`, unless ``overwrite``), :meth:`~OutputFolder.prepare`
removes what the manifest lists and :meth:`~OutputFolder.add` records each new file. Nothing
is ever deleted through a symbolic link: a link named like an output is removed as a link
(its target untouched), and nothing is deleted inside a listed folder that has become a link.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
from collections.abc import Iterable
from pathlib import Path

from topomech._core import TopomechError

__all__ = ["MANIFEST", "OUTPUT_NAMES", "OutputError", "OutputFolder", "read_manifest"]

#: The manifest's file name, in the output folder.
MANIFEST = ".topomech-manifest.jsonl"
#: The manifest being rewritten (renamed over :data:`MANIFEST` once complete).
MANIFEST_TMP = MANIFEST + ".tmp"
#: The header line of a manifest.
HEADER = {"topomech_manifest": 1}

#: The files a run writes at the top of its folder (``frames/frame_NNNNN.vtu`` besides);
#: ``--overwrite`` lets a run replace files with these names that no manifest lists.
OUTPUT_NAMES = (
    "summary.json",
    "final.vtu",
    "animation.pvd",
    "view.json",
    "view.bin",
    "viewer.html",
    "energy.csv",
    "energy.png",
    "preview.gif",
    "preview.mp4",
)
#: The frames' folder and the names of the frames in it.
FRAMES = "frames"
FRAME_NAME = re.compile(r"frame_\d{5,}\.vtu")

#: Foreign files named in a refusal before "and N more".
MAX_SHOWN = 5


class OutputError(TopomechError):
    """An output folder a run refuses to write into: it holds files that no manifest lists
    (give ``overwrite``), it is not a folder, or it cannot be created."""


def entry_ok(rel: object) -> bool:
    """Whether ``rel`` may be a manifest entry: a relative ``/``-separated path inside the
    folder (no absolute path, no drive, no ``..``, ``.`` or empty component, no NUL or
    backslash)."""
    if not isinstance(rel, str) or not rel or "\0" in rel or "\\" in rel or ":" in rel:
        return False
    if rel.startswith("/"):
        return False
    parts = rel.split("/")
    return all(p not in ("", ".", "..") for p in parts)


def read_manifest(out_dir: Path) -> list[str] | None:
    """The entries of ``out_dir``'s manifest (valid ones only, each once, in order), or None
    when there is no manifest. A manifest that cannot be read lists nothing."""
    path = out_dir / MANIFEST
    if not path.is_file() or path.is_symlink():
        return None
    try:
        lines = path.read_bytes().split(b"\n")
    except OSError:
        return []
    entries: list[str] = []
    seen: set[str] = set()
    for i, raw in enumerate(lines):
        try:
            value = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            continue  # a truncated last line, or garbage: listed nothing
        if i == 0:
            if value != HEADER:
                return []  # not a manifest this version wrote: it lists nothing
            continue
        if entry_ok(value) and value not in seen:
            seen.add(value)
            entries.append(value)
    return entries


def manifest_damaged(out_dir: Path) -> bool:
    """Whether ``out_dir`` has a manifest that cannot be read: not this version's header
    (another program's file, or damaged), undecodable, or unreadable."""
    path = out_dir / MANIFEST
    if not os.path.lexists(path):
        return False
    if path.is_symlink() or not path.is_file():
        return True
    try:
        first = path.read_bytes().split(b"\n", 1)[0]
        return bool(json.loads(first.decode("utf-8")) != HEADER)
    except (OSError, UnicodeDecodeError, ValueError):
        return True


def _under_link(out_dir: Path, rel: str) -> bool:
    """Whether a folder on the way from ``out_dir`` to ``rel`` is a symbolic link (or not a
    folder): deleting there would act outside the output folder."""
    parts = rel.split("/")[:-1]
    d = out_dir
    for p in parts:
        d = d / p
        if d.is_symlink() or not d.is_dir():
            return True
    return False


def _remove(out_dir: Path, rel: str) -> bool:
    """Removes ``out_dir/rel`` without following links: a file or a link is unlinked, a
    folder removed when empty. True when nothing is left there."""
    if _under_link(out_dir, rel):
        return False
    p = out_dir / rel
    try:
        if p.is_symlink() or not p.is_dir():
            p.unlink(missing_ok=True)
        else:
            p.rmdir()
    except OSError:
        return not os.path.lexists(p)
    return True


def _like_output(rel: str) -> bool:
    """Whether ``rel`` is named like a file a run writes (``--overwrite`` replaces those)."""
    if rel in OUTPUT_NAMES or rel == FRAMES:
        return True
    head, _, tail = rel.partition("/")
    return head == FRAMES and FRAME_NAME.fullmatch(tail) is not None


class OutputFolder:
    """A run's output folder and its manifest (see the module's documentation).

    ``overwrite``: run even when the folder holds files that no manifest lists; files named
    like the run's outputs (:data:`OUTPUT_NAMES`, ``frames/frame_NNNNN.vtu``) are then
    replaced, every other file is left as it is."""

    def __init__(self, path: Path, *, overwrite: bool = False) -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        self.listed: list[str] = []
        self._listed: set[str] = set()
        self._previous: list[str] = []
        self._foreign: list[str] = []
        self.prepared = False

    # -------------------------------------------------------------- before anything

    def foreign(self) -> list[str]:
        """The files and folders under the folder that no manifest lists (relative paths,
        folders with a trailing ``/``; nothing is looked at inside a foreign folder or a
        link)."""
        listed = set(read_manifest(self.path) or [])
        found: list[str] = []

        def walk(d: Path, prefix: str) -> None:
            try:
                with os.scandir(d) as it:
                    items = sorted(it, key=lambda e: e.name)
            except OSError:
                return
            for e in items:
                rel = prefix + e.name
                if not prefix and e.name in (MANIFEST, MANIFEST_TMP):
                    continue
                is_dir = e.is_dir(follow_symlinks=False)
                if rel in listed:
                    if is_dir:
                        walk(Path(e.path), rel + "/")
                    continue
                found.append(rel + "/" if is_dir else rel)

        if self.path.is_dir():
            walk(self.path, "")
        return found

    def check(self) -> None:
        """Raises :class:`OutputError` when the folder cannot be used: it exists and is not a
        folder, or it holds files that no manifest lists and ``overwrite`` is not given (the
        message names up to :data:`MAX_SHOWN` of them and the option). Writes nothing; a
        missing folder or an empty one is fine."""
        p = self.path
        if os.path.lexists(p) and not p.is_dir():
            raise OutputError(f"{p}: the output folder is not a folder")
        self._foreign = self.foreign()
        if self._foreign and not self.overwrite:
            shown = ", ".join(self._foreign[:MAX_SHOWN])
            more = len(self._foreign) - MAX_SHOWN
            if more > 0:
                shown += f" and {more} more"
            why = (
                f"its manifest ({MANIFEST}) cannot be read (damaged, or not written by this "
                f"version of topomech), so topomech cannot tell its own files from others "
                f"({shown})"
                if manifest_damaged(p)
                else f"the output folder holds files topomech did not write ({shown})"
            )
            raise OutputError(
                f"{p}: {why}; "
                "give --overwrite (overwrite=True) to write there anyway (files named like "
                "the outputs are then replaced, the others kept), or choose another folder "
                "with --out"
            )

    # -------------------------------------------------------------- the run starts

    def prepare(self) -> None:
        """Creates the folder, removes what its manifest lists (and, with ``overwrite``,
        the files named like outputs) and starts a new manifest listing what is left of
        the listed entries. Raises :class:`OutputError` when the folder cannot be created
        or its manifest written."""
        p = self.path
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OutputError(f"{p}: cannot create the output folder: {e.strerror or e}") from None
        previous = read_manifest(p) or []
        doomed = list(previous)
        if self.overwrite:
            doomed += [r.rstrip("/") for r in self._foreign if _like_output(r.rstrip("/"))]
            frames = p / FRAMES
            if frames.is_dir() and not frames.is_symlink():
                with contextlib.suppress(OSError):
                    doomed += [
                        f"{FRAMES}/{e.name}"
                        for e in os.scandir(frames)
                        if FRAME_NAME.fullmatch(e.name)
                    ]
        # deepest first, so that a folder is empty when its turn comes
        left = [r for r in sorted(set(doomed), key=lambda r: -r.count("/")) if not _remove(p, r)]
        self._previous = [r for r in previous if r in left]
        self.listed = []
        self._listed = set()
        self._rewrite(self._previous)
        self.prepared = True

    def _rewrite(self, entries: Iterable[str]) -> None:
        """Writes a whole new manifest (a temporary file renamed over it)."""
        text = "\n".join(json.dumps(x) for x in [HEADER, *entries]) + "\n"
        tmp = self.path / MANIFEST_TMP
        target = self.path / MANIFEST
        try:
            if tmp.is_symlink():
                tmp.unlink()
            tmp.write_text(text, encoding="utf-8")
            tmp.replace(target)
        except OSError as e:
            raise OutputError(f"{target}: cannot write the manifest: {e.strerror or e}") from None
        for x in entries:
            self._listed.add(x)

    def add(self, rel: str) -> Path:
        """Records ``rel`` (a relative ``/`` path) in the manifest, then returns its path,
        a link already there removed (so that writing never follows it). Call it BEFORE
        creating the file. Raises :class:`OSError` (with the manifest's name) when the
        manifest cannot be written."""
        if not entry_ok(rel):
            raise ValueError(f"not a path inside the output folder: {rel!r}")
        if rel not in self._listed:
            line = (json.dumps(rel) + "\n").encode("utf-8")
            target = self.path / MANIFEST
            if not os.path.lexists(target):  # a preparation cut short: start one
                try:
                    self._rewrite(list(self._listed))
                except OutputError as e:
                    raise OSError(errno.EIO, str(e), str(target)) from None
            flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
            try:
                fd = os.open(target, flags, 0o644)
            except OSError as e:
                raise OSError(e.errno, e.strerror, str(target)) from None
            try:
                if os.write(fd, line) != len(line):
                    raise OSError(errno.ENOSPC, "short write", str(target))
            except OSError as e:
                raise OSError(e.errno, e.strerror, str(target)) from None
            finally:
                os.close(fd)
            self._listed.add(rel)
            self.listed.append(rel)
        path = self.path / rel
        if path.is_symlink():
            path.unlink()
        return path

    def adopt(self) -> list[str]:
        """Records the files that appeared in the folder since :meth:`prepare` and are not
        listed yet (a writer that made a file not declared with :meth:`add`): they were
        written by this run, since everything there before was listed or foreign. Returns
        them."""
        known = {r.rstrip("/") for r in self._foreign}
        new = [
            r
            for r in self.foreign_to(self._listed)
            if r not in known and r.split("/")[0] not in known  # nor inside a foreign folder
        ]
        for r in new:
            with contextlib.suppress(OSError, ValueError):
                self.add(r)
        return new

    def foreign_to(self, listed: set[str]) -> list[str]:
        """The top-level entries and those of listed folders that ``listed`` lacks."""
        found: list[str] = []
        for prefix, d in (("", self.path), (f"{FRAMES}/", self.path / FRAMES)):
            if prefix and (FRAMES not in listed or d.is_symlink() or not d.is_dir()):
                continue
            try:
                names = sorted(x.name for x in d.iterdir())
            except OSError:
                continue
            for name in names:
                rel = prefix + name
                if not prefix and name in (MANIFEST, MANIFEST_TMP):
                    continue
                if rel not in listed:
                    found.append(rel)
        return found


def register(out_dir: Path, rel: str) -> None:
    """Lists ``rel`` in ``out_dir``'s manifest when there is one (a file topomech writes in
    a run's folder after the run, as ``topomech view`` writes ``viewer.html``), so that a
    rerun may replace it. Call it before creating the file; OSError when the manifest
    cannot be written."""
    out_dir = Path(out_dir)
    entries = read_manifest(out_dir)
    if entries is None or rel in entries or not entry_ok(rel):
        return
    folder = OutputFolder(out_dir)
    folder._listed = set(entries)
    folder.add(rel)
