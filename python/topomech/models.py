"""Models as rule files: a model a user writes (``Model.load``) or one topomech ships
(``Model.shipped``), for :class:`topomech.Simulation` and scenes.

A model is a ``model`` declaration in a rule file (``.tmr``)::

    model anchor(k: f64 = 10.0) {
      init   anchor_init(k)                 # rules applied once, everywhere, in order
      step   anchor_force                   # rules applied every step, everywhere, in order
      forces f_anchor                       # force embeddings summed into each vertex's force
      jvp    anchor_jvp -> df_anchor        # optional: exact Jacobian-vector product rules
      needs  "vertices"                     # optional: said when the model matches nothing
    }

A user's file is loaded after the shipped common rules of its dimension (the embeddings every
simulation has: ``position``, ``rest``, ``velocity``, ``force``, ``mass``, ``dx``, ``dv``,
``df``, the material, ...), so it declares only ``dimension`` and its own embeddings. A model
without ``jvp`` runs with the explicit integrators only (``explicit_euler``,
``symplectic_euler``); ``implicit_euler`` and ``static`` need its Jacobian rules.

    >>> m = Model.shipped("stretch_elementary")
    >>> m.params, m.has_jvp
    ({'stiffness': 1000.0, 'damping': 0.0}, True)
    >>> m.with_params(stiffness=50.0).values
    {'stiffness': 50.0}

A ``vec3`` parameter takes 3 real numbers (a list, a tuple or a numpy array of shape
``(3,)``), kept as a tuple of floats and passed to the simulation as a list.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Union

import numpy as np

from topomech import _core
from topomech._paths import read_text_file

__all__ = ["EXPLICIT_INTEGRATORS", "INTEGRATORS", "Model", "ParamDefault", "ParamValue"]

#: A parameter's default: a number (``f64``), 3 numbers (``vec3``), or None (required).
ParamDefault = Union[float, list[float], None]
#: A parameter's value as :meth:`Model.with_params` keeps it: a float (``f64``) or a tuple
#: of 3 floats (``vec3``).
ParamValue = Union[float, tuple[float, float, float]]

#: The integrators every model runs with.
EXPLICIT_INTEGRATORS = ("explicit_euler", "symplectic_euler")
#: Every integrator, in the order the CLI lists them; the last two need Jacobian rules.
INTEGRATORS = (*EXPLICIT_INTEGRATORS, "implicit_euler", "static")


@dataclass(frozen=True)
class Model:
    """A model declaration and the parameter values a simulation will run it with.

    Build one with :meth:`load` (a user's rule file) or :meth:`shipped`; give it to
    ``Simulation(models=[...])`` beside the ``"kind"`` and ``{"kind": ..., param: value}``
    forms; set parameters with :meth:`with_params`."""

    #: The declared name.
    name: str
    #: Each parameter's default, in declaration order (None: required, no default).
    params: dict[str, ParamDefault]
    #: Each parameter's type in the rule language (``f64`` or ``vec3``).
    param_types: dict[str, str]
    #: The dimensions of the maps it runs on (2: surfaces, 3: volumes).
    dimensions: tuple[int, ...]
    #: What it needs of the mesh, as declared (None when the declaration says nothing).
    needs: str | None
    #: Whether it has Jacobian rules (``jvp``): then ``implicit_euler`` and ``static`` runs too.
    has_jvp: bool
    #: The rule file that declares it, as given to :meth:`load`; None for a shipped model.
    file: str | None = None
    #: The parameter values set (:meth:`with_params`): a float for an ``f64`` parameter, a
    #: tuple of 3 floats for a ``vec3`` one; the others keep their defaults.
    values: dict[str, ParamValue] = field(default_factory=dict)
    #: The rule file's text (read once by :meth:`load`); None for a shipped model.
    source: str | None = field(default=None, repr=False, compare=False)
    #: The force embeddings it sums into each vertex's ``force`` (empty for a shipped model).
    forces: tuple[str, ...] = ()

    @property
    def integrators(self) -> tuple[str, ...]:
        """The integrators it runs with: all four with Jacobian rules, else the explicit
        ones."""
        return INTEGRATORS if self.has_jvp else EXPLICIT_INTEGRATORS

    @property
    def param_values(self) -> dict[str, ParamValue | None]:
        """Each parameter's value a simulation runs the model with, in declaration order:
        the one set by :meth:`with_params`, else the default (:attr:`params`); None for a
        required parameter not set yet (see :attr:`missing`). A ``vec3`` value is a tuple of
        3 floats, its default's too."""
        out: dict[str, ParamValue | None] = {}
        for p, d in self.params.items():
            if p in self.values:
                out[p] = self.values[p]
            elif isinstance(d, list):
                out[p] = (float(d[0]), float(d[1]), float(d[2]))
            else:
                out[p] = d
        return out

    @property
    def missing(self) -> list[str]:
        """The parameters without a default that :attr:`values` does not set."""
        return [p for p, d in self.params.items() if d is None and p not in self.values]

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        name: str | None = None,
        params: Mapping[str, Any] | None = None,
    ) -> Model:
        """The model ``name`` declared in the rule file ``path`` (the file's only model when
        ``name`` is None), with the parameter values ``params``.

        Raises :class:`FileNotFoundError` naming the file when it does not exist,
        :class:`OSError` when it cannot be read or is not a regular file (a directory, or a
        device or FIFO such as ``/dev/zero``: refused before reading), :class:`UnicodeDecodeError`
        when it is not UTF-8, :class:`topomech.RuleError` when the checker refuses it (one
        ``FILE:LINE:COL: error[CONDITION]: message`` line per problem), :class:`ValueError`
        when it declares no model, when ``name`` is None and it declares several, or when it
        declares no model ``name`` (each naming the file's models), and as
        :meth:`with_params` for ``params``."""
        models = cls.load_all(path)
        file = str(path)
        names = ", ".join(m.name for m in models)
        if not models:
            raise ValueError(f"{file}: declares no model")
        if name is None:
            if len(models) > 1:
                raise ValueError(f"{file}: declares several models ({names}): give a name")
            model = models[0]
        else:
            found = [m for m in models if m.name == name]
            if not found:
                raise ValueError(f"{file}: declares no model '{name}' (it declares: {names})")
            model = found[0]
        return model.with_params(**dict(params or {}))

    @classmethod
    def load_all(cls, path: str | os.PathLike[str]) -> list[Model]:
        """Every model the rule file ``path`` declares, in file order (errors as
        :meth:`load`; an empty list for a file without models)."""
        file = str(path)
        try:
            text = read_text_file(path, "rule file")
        except UnicodeDecodeError as e:
            # the same exception, naming the file (the codec's message does not)
            raise UnicodeDecodeError(
                e.encoding, e.object, e.start, e.end, f"{file}: not UTF-8 text ({e.reason})"
            ) from None
        # a file without a dimension line serves both dimensions, like `dimension 2 3`: its
        # declarations are read for 3-maps (they are the same for 2-maps; a rule that cannot
        # hold on a 2-map is refused when the model runs on one, as `topomech check` says)
        dimension = None if _core.RuleSet.file_dimensions(text) else 3
        rules = _core.RuleSet.from_model_sources([(file, text)], dimension)
        return [cls._from_declaration(m, text) for m in rules.models() if m["file"] == file]

    @classmethod
    def _from_declaration(cls, m: dict[str, Any], text: str | None) -> Model:
        return cls(
            name=str(m["name"]),
            params={str(p): d for p, _, d in m["params"]},
            param_types={str(p): str(t) for p, t, _ in m["params"]},
            dimensions=tuple(int(d) for d in m["dimensions"]),
            needs=m["needs"],
            has_jvp=bool(m["has_jvp"]),
            file=str(m["file"]),
            source=text,
            forces=tuple(m["forces"]),
        )

    @classmethod
    def shipped(cls, name: str, dimension: int | None = None) -> Model:
        """The shipped model ``name`` (of ``dimension`` 2 or 3 when its declarations differ
        between dimensions: the 2D co-rotational triangle has a ``thickness``, the 3D
        elements have none; without ``dimension`` the first listed). Raises
        :class:`ValueError` naming the shipped models when there is none."""
        from topomech.rules import _dimension

        dimension = _dimension(dimension)
        found = [
            m
            for m in shipped_models()
            if m.name == name and (dimension is None or dimension in m.dimensions)
        ]
        if not found:
            known = ", ".join(dict.fromkeys(m.name for m in shipped_models()))
            where = f" of dimension {dimension}" if dimension is not None else ""
            raise ValueError(f"no shipped model '{name}'{where} (shipped: {known})")
        return found[0]

    def with_params(self, **values: Any) -> Model:
        """A copy with these parameter values set (over those set before): a real number for
        an ``f64`` parameter, 3 real numbers (a list, a tuple or a numpy array of shape
        ``(3,)``, kept as a tuple of floats) for a ``vec3`` one. Raises :class:`ValueError`
        for a parameter the model does not have (naming its parameters), a non-finite value
        or a ``vec3`` value of another length than 3; :class:`TypeError` for a sequence given
        to an ``f64`` parameter, a single number given to a ``vec3`` one (each saying which
        type the parameter expects), or a value that is not a real number. Each message
        names the model and the parameter."""
        out = dict(self.values)
        for k, v in values.items():
            if k not in self.params:
                has = ", ".join(self.params) or "none"
                raise ValueError(f"model '{self.name}' has no parameter '{k}' (it has: {has})")
            ty = self.param_types.get(k, "f64")
            if ty == "vec3":
                out[k] = self._vec3(k, v)
            elif ty == "f64":
                out[k] = self._f64(k, v)
            else:
                raise ValueError(
                    f"model '{self.name}': parameter '{k}' has type {ty}; only f64 and vec3 "
                    "parameters can be set"
                )
        return replace(self, values=out)

    def _f64(self, k: str, v: Any) -> float:
        """The value of the ``f64`` parameter ``k``: a finite real number."""
        what = f"model '{self.name}': parameter '{k}'"
        if _is_sequence(v):
            raise TypeError(
                f"{what} is an f64: expected one real number, got a {type(v).__name__} "
                "(sequences of 3 numbers are for vec3 parameters)"
            )
        if isinstance(v, np.ndarray) and v.ndim == 0:
            v = v[()]  # a 0-d array: its one number (refused below unless real)
        if not _is_real(v):
            raise TypeError(f"{what} must be a real number, got {type(v).__name__}")
        try:
            x = float(v)
        except OverflowError:
            raise ValueError(f"{what} must be finite, got an integer too large for f64") from None
        if not math.isfinite(x):
            raise ValueError(f"{what} must be finite, got {v}")
        return x

    def _vec3(self, k: str, v: Any) -> tuple[float, float, float]:
        """The value of the ``vec3`` parameter ``k``: 3 finite real numbers."""
        what = f"model '{self.name}': parameter '{k}'"
        if not _is_sequence(v):
            got = "a real number" if _is_real(v) else f"a {type(v).__name__}"
            raise TypeError(
                f"{what} is a vec3: expected 3 real numbers (a list, a tuple or an array of "
                f"shape (3,)), got {got}"
            )
        if isinstance(v, np.ndarray) and v.shape != (3,):
            raise ValueError(
                f"{what} is a vec3: expected 3 real numbers, got an array of shape {v.shape}"
            )
        items = list(v)
        if len(items) != 3:
            raise ValueError(f"{what} is a vec3: expected 3 real numbers, got {len(items)}")
        for i, x in enumerate(items):
            if not _is_real(x):
                raise TypeError(
                    f"{what} is a vec3: item {i} must be a real number, got {type(x).__name__}"
                )
        try:
            xs = [float(x) for x in items]
        except OverflowError:
            raise ValueError(f"{what} is a vec3: an item is an integer too large for f64") from None
        for i, x in enumerate(xs):
            if not math.isfinite(x):
                raise ValueError(f"{what} is a vec3: item {i} must be finite, got {x}")
        return (xs[0], xs[1], xs[2])

    def config_entry(self) -> dict[str, Any]:
        """The ``models`` entry :class:`topomech.Simulation` takes: ``{"kind": name, param:
        value, ...}`` (the values set; a ``vec3`` value as a list of 3 floats)."""
        return {
            "kind": self.name,
            **{k: list(v) if isinstance(v, tuple) else v for k, v in self.values.items()},
        }

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description (``topomech models --json``): name, file, params
        (``{name: {"type", "default"}}``, a ``vec3`` default as ``[x, y, z]``, a required
        parameter's as None), dimensions, needs, has_jvp, integrators."""
        return {
            "name": self.name,
            "file": self.file,
            "params": {
                p: {"type": self.param_types.get(p, "f64"), "default": _default(d)}
                for p, d in self.params.items()
            },
            "dimensions": list(self.dimensions),
            "needs": self.needs,
            "has_jvp": self.has_jvp,
            "integrators": list(self.integrators),
        }


def _is_real(x: Any) -> bool:
    """Whether ``x`` is a real number (Python's or numpy's; not a bool)."""
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _is_sequence(x: Any) -> bool:
    """Whether ``x`` is a sequence of values (a list, a tuple, a numpy array...; not a
    string)."""
    if isinstance(x, np.ndarray):
        return x.ndim > 0
    return isinstance(x, Sequence) and not isinstance(x, (str, bytes, bytearray))


def _default(d: Any) -> ParamDefault:
    """A default as :class:`Model` keeps it: a float, a list of 3 floats (``vec3``) or
    None (required)."""
    if d is None:
        return None
    if _is_sequence(d):
        return [float(x) for x in d]
    return float(d)


def shipped_models() -> list[Model]:
    """The models topomech ships, as :class:`Model` objects (one per declaration: a name
    whose declarations differ between dimensions appears once per dimension set)."""
    return [
        Model(
            name=str(m["kind"]),
            params={str(k): _default(v) for k, v in m["params"].items()},
            # older builds of the kernel give no types: every shipped parameter was an f64
            param_types={str(k): str(m.get("param_types", {}).get(k, "f64")) for k in m["params"]},
            dimensions=tuple(int(d) for d in m["dims"]),
            needs=str(m["needs"]) or None,
            has_jvp=bool(m["has_jvp"]),
        )
        for m in _core.models()
    ]


def model_files_of(models: list[Any]) -> tuple[list[Any], list[tuple[str, str]]]:
    """``models`` with each :class:`Model` replaced by its ``{"kind", params}`` entry, and the
    ``(file, text)`` of the rule files the user's models come from (each once)."""
    entries: list[Any] = []
    files: list[tuple[str, str]] = []
    for m in models:
        if isinstance(m, Model):
            entries.append(m.config_entry())
            new = all(f != m.file for f, _ in files)
            if m.file is not None and m.source is not None and new:
                files.append((m.file, m.source))
        else:
            entries.append(m)
    return entries, files
