"""Rules: graph transformations of G-maps, written in rule files (``.tmr``).

A rule file is checked when it loads: a rule the checker accepts keeps every map of its
dimension valid, and a refused file raises :class:`RuleError` with one
``FILE:LINE:COL: error[CONDITION]: message`` line per problem. Apply a rule at every match or
at given hook darts::

    >>> import topomech
    >>> g = topomech.GMap.from_mesh([[0, 0], [1, 0], [1, 1], [0, 1]], [("quad", [[0, 1, 2, 3]])])
    >>> rules = RuleSet.library(2)
    >>> rules.apply(g, "split_edge")
    {'matches': 4, 'created': 8, 'deleted': 0}
    >>> g.cell_counts()["vertices"]
    8

A rule that does not apply raises :class:`ApplyError` naming why, and the map is unchanged.
"""

from __future__ import annotations

import operator
import os
import re
import stat
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict, Union

from topomech import _core
from topomech._core import ApplyError, RuleError

if TYPE_CHECKING:
    import numpy.typing as npt

    from topomech._gmap import GMap, PathLike

__all__ = ["ApplyError", "ApplyReport", "ParamValue", "RuleError", "RuleInfo", "RuleSet"]

#: A parameter value: a number or a bool for ``f64``, ``i64`` and ``bool``; 2 or 3 numbers
#: (a list, a tuple or a numpy array) for ``vec2`` and ``vec3``; a 2-D list or array for a
#: matrix. An int is accepted where ``f64`` is declared.
ParamValue = Union[float, bool, Sequence[float], Sequence[Sequence[float]], "npt.NDArray[Any]"]


class ApplyReport(TypedDict):
    """What :meth:`RuleSet.apply` did."""

    #: Matches applied.
    matches: int
    #: Darts created.
    created: int
    #: Darts deleted.
    deleted: int


class RuleInfo(TypedDict):
    """What :meth:`RuleSet.rule_info` returns."""

    name: str
    #: The rule file it comes from.
    file: str
    #: ``(name, type)`` of each parameter, in declaration order (types as written in the
    #: language: ``f64``, ``i64``, ``bool``, ``vec2``, ``vec3``, ``mat3``, ``mat2x3``, ...).
    params: list[tuple[str, str]]
    #: The number of hook darts :meth:`RuleSet.apply` needs with ``at``.
    hooks: int
    #: Whether the rule changes the topology (else it only computes embeddings).
    changes_topology: bool


def _dimension(dimension: Any) -> int | None:
    """``dimension`` as the kernel takes it: None, 2 or 3 (a bool is refused, not read as
    0 or 1). Raises :class:`TypeError` for another type; the kernel refuses other ints."""
    if dimension is None:
        return None
    if not isinstance(dimension, bool):
        try:
            return operator.index(dimension)  # an int, numpy's included
        except TypeError:
            pass
    raise TypeError(f"dimension must be 2 or 3 (or None), got {dimension!r}")


#: A line that starts a model declaration (``model NAME(...) {`` or ``model NAME {``): how
#: ``topomech check`` tells a model file (checked with the shipped common rules) from a rule
#: file.
_MODEL_DECLARATION = re.compile(r"^[ \t]*model[ \t]+[A-Za-z_][A-Za-z0-9_]*[ \t]*[({]", re.MULTILINE)


def _add_model_hint(
    e: RuleError, loader: str, texts: Callable[[], Iterable[tuple[str, str]]]
) -> None:
    """Adds a hint as the last line of ``e``'s message when one of the files (``texts()``,
    called only then: their ``(name, text)``) declares a model and an error is an unknown
    embedding, the mark of a model file checked without the shipped prelude. ``loader`` is
    the method that refused them. ``diagnostics`` and ``warnings`` are unchanged."""
    if not e.args or not any("unknown embedding" in d for d in getattr(e, "diagnostics", [])):
        return
    files = [name for name, text in texts() if _MODEL_DECLARATION.search(text)]
    if not files:
        return
    which = (
        f"{files[0]} declares a model: load it"
        if len(files) == 1
        else f"{', '.join(files[:-1])} and {files[-1]} declare models: load them"
    )
    hint = (
        f"hint: {which} with RuleSet.from_model_sources (or topomech.Model.load), which adds "
        "the shipped prelude and common rules declaring position, rest, velocity, force, "
        f"mass, dx, ..., as `topomech check` and a simulation do; {loader} does not"
    )
    e.args = (f"{e.args[0]}\n{hint}", *e.args[1:])


def _read_texts(paths: list[str]) -> Iterable[tuple[str, str]]:
    """The ``(path, text)`` of each regular file of ``paths`` that reads as UTF-8 (as the
    kernel reads them: up to the size it has; the others are skipped, the kernel has said
    why)."""
    for p in paths:
        try:
            st = Path(p).stat()
            if not stat.S_ISREG(st.st_mode):
                continue  # a FIFO or device: never opened (it could block or never end)
            with Path(p).open("rb") as f:
                yield p, f.read(st.st_size).decode("utf-8")
        except (OSError, UnicodeDecodeError):
            continue


class RuleSet:
    """Checked rules of one dimension, from one or several rule files sharing their
    embeddings. The kernel object is :attr:`core`; this class adds typing."""

    __slots__ = ("_core",)

    def __init__(self, core: _core.RuleSet) -> None:
        if not isinstance(core, _core.RuleSet):
            raise TypeError(
                "RuleSet wraps a topomech._core.RuleSet; load one with RuleSet.load, "
                "RuleSet.from_source or RuleSet.library"
            )
        self._core = core

    # ------------------------------------------------------------------ loading

    @classmethod
    def load(cls, paths: PathLike | Sequence[PathLike], dimension: int | None = None) -> RuleSet:
        """Reads and checks one rule file or several together, for ``dimension`` (2 or 3:
        needed when every file serves both, with ``dimension 2 3`` or no dimension line; by
        default the dimension the files say). Raises :class:`FileNotFoundError` naming the
        first file that does not exist, :class:`RuleError` with every error (a file that
        exists but cannot be read included, and one that is not a regular file: a directory,
        or a device or FIFO such as ``/dev/zero``, refused before reading), ValueError for
        another dimension.

        The files are checked alone. A model file (one that declares a ``model``) uses the
        embeddings of the shipped prelude and common rules (``position``, ``rest``, ``dx``,
        ...) without declaring them: load it with :meth:`from_model_sources` (or
        :meth:`topomech.Model.load`), as ``topomech check`` and a simulation do. Refused here
        for an unknown embedding, its :class:`RuleError` message ends with a ``hint:`` line
        saying so (not one of its ``diagnostics``)."""
        if isinstance(paths, (str, os.PathLike)):
            paths = [paths]
        names = [os.fspath(p) for p in paths]
        dim = _dimension(dimension)
        try:
            core = _core.RuleSet.load(names, dim)
        except RuleError as e:
            _add_model_hint(e, "RuleSet.load", lambda: _read_texts(names))
            raise
        return cls(core)

    @classmethod
    def from_source(
        cls, text: str, name: str = "<string>", dimension: int | None = None
    ) -> RuleSet:
        """Checks the text of a rule file; ``name`` is the file name diagnostics show; for
        ``dimension`` as :meth:`load` (needed for a ``dimension 2 3`` file). The text is
        checked alone: a model file is refused as in :meth:`load` (with its ``hint:`` line);
        :meth:`from_model_sources` loads it."""
        dim = _dimension(dimension)
        try:
            core = _core.RuleSet.from_source(text, name, dim)
        except RuleError as e:
            _add_model_hint(e, "RuleSet.from_source", lambda: [(name, text)])
            raise
        return cls(core)

    @classmethod
    def from_sources(
        cls, sources: Sequence[tuple[str, str]], dimension: int | None = None
    ) -> RuleSet:
        """Checks ``(name, text)`` rule files together, for ``dimension`` (2 or 3: needed
        when every file serves both, with ``dimension 2 3`` or no dimension line; by default
        the dimension the files say). Raises :class:`RuleError` with every error at its
        ``FILE:LINE:COL``, ValueError for another dimension. The files are checked alone: model
        files are refused as in :meth:`load` (with its ``hint:`` line);
        :meth:`from_model_sources` loads them."""
        sources = list(sources)
        dim = _dimension(dimension)
        try:
            core = _core.RuleSet.from_sources(sources, dim)
        except RuleError as e:
            _add_model_hint(e, "RuleSet.from_sources", lambda: sources)
            raise
        return cls(core)

    @staticmethod
    def file_dimensions(text: str) -> list[int]:
        """The dimensions a rule file's ``dimension`` line names (``[2, 3]`` for
        ``dimension 2 3``); empty when it names none (the file serves both) or does not
        parse."""
        return [int(d) for d in _core.RuleSet.file_dimensions(text)]

    @classmethod
    def from_model_sources(
        cls, sources: Sequence[tuple[str, str]], dimension: int | None = None
    ) -> RuleSet:
        """Checks ``(name, text)`` model files together as a simulation loads them: after
        the shipped common rules of the dimension they declare (``position``, ``rest``,
        ``velocity``, ``force``, ``mass``, ``dx``, ``dv``, ``df``, the material, ...), so a
        model file declares only ``dimension`` and its own embeddings. Raises
        :class:`RuleError` with every error at its ``FILE:LINE:COL``. ``dimension`` as
        :meth:`from_sources`."""
        return cls(_core.RuleSet.from_model_sources(list(sources), dimension))

    @classmethod
    def library(cls, dimension: int) -> RuleSet:
        """The modeling rules shipped with topomech for surfaces (2) or volumes (3)."""
        dim = _dimension(dimension)
        if dim is None:
            raise TypeError("dimension must be 2 or 3, got None")
        return cls(_core.RuleSet.library(dim))

    # ------------------------------------------------------------------ queries

    @property
    def core(self) -> _core.RuleSet:
        """The kernel object."""
        return self._core

    @property
    def dimension(self) -> int:
        """The dimension of the maps the rules apply to."""
        return self._core.dimension

    @property
    def warnings(self) -> list[str]:
        """The checker's warnings, one ``FILE:LINE:COL: warning[CONDITION]: message`` each."""
        return self._core.warnings

    def rule_names(self) -> list[str]:
        """The rules' names, in file order."""
        return self._core.rule_names()

    def rule_info(self, name: str) -> RuleInfo:
        """Name, file, parameters, number of hooks of a rule, and whether it changes the
        topology. An unknown name raises :class:`ApplyError`."""
        d = self._core.rule_info(name)
        return RuleInfo(
            name=d["name"],
            file=d["file"],
            params=[(p, t) for p, t in d["params"]],
            hooks=d["hooks"],
            changes_topology=d["changes_topology"],
        )

    def models(self) -> list[dict[str, Any]]:
        """The model declarations, in file order: dicts with ``name``, ``file``, ``line``,
        ``col``, ``params`` (``(name, type, default or None)`` each), ``dimensions``,
        ``needs`` (str or None), ``forces``, ``jvp_outputs``, ``has_jvp`` and
        ``per_element``. :class:`topomech.Model` wraps one."""
        return self._core.models()

    # ------------------------------------------------------------------ application

    def apply(
        self,
        gmap: GMap | _core.GMap,
        name: str,
        at: int | Sequence[int] | None = None,
        params: Mapping[str, ParamValue] | None = None,
    ) -> ApplyReport:
        """Applies rule ``name`` to ``gmap`` in place: at every match when ``at`` is None, else
        once with its hooks at the darts ``at`` (one per hook).

        Raises :class:`ApplyError` when the rule does not apply (the message says which arc,
        orbit or dart failed; the map is unchanged), ``IndexError`` for a dart that is not in
        the map, ``TypeError`` or ``ValueError`` for a parameter value of the wrong kind or
        shape."""
        r = self._core.apply(gmap, name, at, params)
        return ApplyReport(matches=r["matches"], created=r["created"], deleted=r["deleted"])

    def count_matches(
        self,
        gmap: GMap | _core.GMap,
        name: str,
        params: Mapping[str, ParamValue] | None = None,
    ) -> int:
        """The number of matches :meth:`apply` would apply at every match."""
        return self._core.count_matches(gmap, name, params)

    def __repr__(self) -> str:
        names = ", ".join(self.rule_names())
        return f"topomech.RuleSet(dimension={self.dimension}, rules=[{names}])"
