"""The ``[[model]]`` tables of a scene: a shipped model by ``kind`` with its parameters, or a
model of the user's rule file (``file = "..."``, ``name = "..."`` when it declares several),
and the check of the models against the mesh's dimension once it is known (the Rust side:
``crates/physics/src/model.rs``).
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from topomech import _core
from topomech._core import RuleError, SceneError
from topomech.models import Model, shipped_models
from topomech.models import model_files_of as _model_files_pairs
from topomech.scene._table import _ArgFail, _Fail, _or, _required_str, _show, _Table
from topomech.simulation import ModelInfo, available_models

#: Models of the paper that scenes may name but this build does not ship yet.
PLANNED_MODELS = (
    "shear_isotropic",
    "shear_anisotropic",
    "shear_volumic",
    "bending_linear",
    "bending_angular",
)


#: Keys of a model table that set the material rather than the model.
MATERIAL_KEYS_IN_MODEL = ("young", "poisson")


def _model_entries(kind: str, dim: int | None) -> list[ModelInfo]:
    """The catalogue's entries for ``kind`` (one per set of dimensions), those of dimension
    ``dim`` only when it is known."""
    return [
        m for m in available_models() if m["kind"] == kind and (dim is None or dim in m["dims"])
    ]


def _takes(kind: str, dim: int | None) -> list[str]:
    """The keys a ``[[model]]`` table of ``kind`` may have beside ``kind``: its parameters,
    and the material's ``young`` and ``poisson`` for a continuous model (declared
    ``per_element``; springs and bending ignore the material, so these are refused there)."""
    params: list[str] = []
    continuous = False
    for m in _model_entries(kind, dim):
        params += [p for p in m["params"] if p not in params]
        continuous = continuous or m["per_element"]
    return [*params, *(MATERIAL_KEYS_IN_MODEL if continuous else ())]


def _param_types(kind: str, dim: int | None) -> dict[str, str]:
    """The type (``f64`` or ``vec3``) of each parameter of the shipped model ``kind`` (of
    dimension ``dim`` when it is known)."""
    types: dict[str, str] = {}
    for m in shipped_models():
        if m.name == kind and (dim is None or dim in m.dimensions):
            for p, ty in m.param_types.items():
                types.setdefault(p, ty)
    return types


def _param(
    t: _Table, p: str, ty: str, model: str, fail: _Fail, *, nonneg: bool = False
) -> float | list[float] | None:
    """The value the model table ``t`` gives the parameter ``p`` of type ``ty`` (None when
    it gives none): a number for an ``f64`` parameter (``nonneg``: >= 0), an array of 3
    numbers for a ``vec3`` one."""
    v = t.data.get(p)
    if ty == "vec3":
        if v is not None and (not isinstance(v, list) or len(v) != 3):
            raise fail(
                t.key(p),
                f"parameter '{p}' of model '{model}' is vec3: expected an array of 3 numbers, "
                f"got {_show(v)}",
            )
        vec = t.vector(p, 3)
        return None if vec is None else list(vec)
    if isinstance(v, list):
        raise fail(
            t.key(p),
            f"parameter '{p}' of model '{model}' is {ty}: expected a number, got {_show(v)}",
        )
    return t.number(p, nonneg=nonneg)


def _shipped_param(
    t: _Table, p: str, ty: str, model: str, fail: _Fail
) -> float | list[float] | None:
    """The value the model table ``t`` gives the parameter ``p`` of type ``ty`` of the
    shipped model ``model`` (see :func:`_param`): an ``f64`` one (a stiffness, a damping, a
    thickness) is >= 0. A scene's ``[[model]]`` tables and :class:`topomech.Simulation`'s
    ``models`` (:func:`check_model_args`) are checked with it."""
    return _param(t, p, ty, model, fail, nonneg=True)


def _as_read(v: Any, ty: str) -> float | list[float] | None:
    """A Python API value as a scene's table holds it (a float, or a list of 3 floats for a
    ``vec3``) when the kernel reads it as a number there (numpy's numbers, a tuple or an
    array of 3 included); None for any other value, which the kernel refuses with its own
    message."""

    def real(x: Any) -> float | None:
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
            return None
        try:
            f = float(x)
        except (OverflowError, TypeError, ValueError):
            return None
        return f if math.isfinite(f) else None

    if ty != "vec3":
        return real(v)
    if not isinstance(v, (list, tuple, np.ndarray)) or np.ndim(v) != 1 or len(v) != 3:
        return None
    items = [real(x) for x in v]
    return None if any(x is None for x in items) else [x for x in items if x is not None]


def user_model_names(models: Sequence[Any], model_files: Any) -> set[str] | None:
    """The names of the models the user's rule files declare: those of ``model_files``
    (``(file, text)`` pairs given to :class:`topomech.Simulation`) and of the
    :class:`topomech.Model` objects loaded from a file among ``models``. None when a file of
    ``model_files`` cannot be read as rule files (the kernel refuses it with its own
    message; which names it declares is then unknown)."""
    names = {m.name for m in models if isinstance(m, Model) and m.file is not None}
    if model_files is None:
        return names
    if not isinstance(model_files, (list, tuple)):
        return None
    for pair in model_files:
        if (
            not isinstance(pair, (list, tuple))
            or len(pair) != 2
            or not all(isinstance(x, str) for x in pair)
        ):
            return None
        file, text = pair
        try:
            # as Model.load_all reads a file: one without a dimension line serves both
            dimension = None if _core.RuleSet.file_dimensions(text) else 3
            rules = _core.RuleSet.from_model_sources([(file, text)], dimension)
            names |= {str(m["name"]) for m in rules.models() if m["file"] == file}
        except (RuleError, ValueError, TypeError):  # the kernel refuses it with its own message
            return None
    return names


def check_model_args(
    models: Sequence[Any], dim: int | None, user_names: Collection[str] | None = ()
) -> None:
    """Refuses, with ``ValueError("models[i].param: problem")``, a parameter value given to
    :class:`topomech.Simulation` for a shipped model (a dict ``{"kind": ..., param:
    value}``, or a :class:`topomech.Model` from :meth:`~topomech.Model.shipped`) that a
    scene's ``[[model]]`` table refuses (:func:`_shipped_param`: a negative stiffness or
    damping, ...) and the kernel does not. Only the values the kernel reads as numbers of
    the parameter's type are checked; the others (a wrong type, a number that is not finite;
    an unknown kind or key, a material key: then the whole model) are left to the kernel,
    which refuses them with its own message. ``dim``: the map's dimension (None: any). The
    user's models (:class:`topomech.Model` loaded from a file, a kind declared in
    ``model_files``: ``user_names``, see :func:`user_model_names`; None when unknown, then
    nothing is checked) are checked as a scene checks them, by the kernel, also when one has
    the name of a shipped model (it replaces that model)."""
    if user_names is None:
        return
    fail = _ArgFail()
    for i, spec in enumerate(models):
        if isinstance(spec, Model):
            if spec.file is not None:
                continue
            spec = spec.config_entry()
        if not isinstance(spec, Mapping):
            continue
        kind = spec.get("kind")
        if not isinstance(kind, str) or kind in user_names or not _model_entries(kind, dim):
            continue
        params = [p for p in _takes(kind, dim) if p not in MATERIAL_KEYS_IN_MODEL]
        if any(k != "kind" and k not in params for k in spec):
            continue  # the kernel names the key it does not know first, as a scene does
        types = _param_types(kind, dim)
        values: dict[str, Any] = {}
        for p in params:
            if p in spec:
                v = _as_read(spec[p], types.get(p, "f64"))
                if v is not None:
                    values[p] = v
        t = _Table(values, f"models[{i}]", fail)
        for p in values:
            _shipped_param(t, p, types.get(p, "f64"), kind, fail)


def _check_models(
    models: list[dict[str, Any]],
    dim: int,
    fail: _Fail,
    user_models: Mapping[int, Model] | None = None,
) -> None:
    """Refuses a model that does not exist in dimension ``dim``, or a parameter it does not
    take there, naming the key (``model[i].file`` for a user's model, by index in
    ``user_models``)."""
    for i, spec in enumerate(models):
        user = (user_models or {}).get(i)
        if user is not None:
            if dim not in user.dimensions:
                raise fail(f"model[{i}].file", _wrong_dimension(user, dim))
            continue
        kind = spec["kind"]
        if not _model_entries(kind, dim):
            entries = _model_entries(kind, None)
            dims = sorted({d for m in entries for d in m["dims"]})
            needs = " or ".join(m["needs"] for m in entries)
            want = " or ".join(f"{d}D" for d in dims)
            raise fail(
                f"model[{i}].kind",
                f"model '{kind}' needs a {want} mesh ({needs}), the mesh is {dim}D",
            )
        takes = _takes(kind, dim)
        for p in spec:
            if p != "kind" and p not in takes:
                raise fail(
                    f"model[{i}].{p}",
                    f"model '{kind}' takes no parameter '{p}' on a {dim}D mesh "
                    f"(it takes {', '.join(takes)})",
                )


def _models(
    tables: list[_Table], dim: int | None, base: Path | None, fail: _Fail
) -> tuple[list[dict[str, Any]], dict[str, tuple[str, float]], dict[int, Model]]:
    """The models for :class:`Simulation`, the material values they set (young, poisson),
    each with the key that set it first, and the user's models (``[[model]] file = ...``)
    by table index. ``dim`` is the mesh's dimension when the scene says it (a generator),
    else None: the models are checked again once it is known. Model files are relative to
    ``base`` (the scene's folder)."""
    if not tables:
        raise fail("model", "no model: add a [[model]] table with a kind or a file")
    kinds = list(dict.fromkeys(m["kind"] for m in available_models()))
    models: list[dict[str, Any]] = []
    set_by: dict[str, tuple[str, float]] = {}
    user_models: dict[int, Model] = {}
    for i, t in enumerate(tables):
        if t.has("file"):
            if t.has("kind"):
                raise fail(
                    t.key("kind"),
                    "give either kind (a shipped model) or file (a rule file), not both",
                )
            user = _user_model(t, i, dim, base, fail)
            models.append(user.config_entry())
            user_models[i] = user
            continue
        kind = t.string("kind")
        if kind is None:
            raise fail(
                t.key("kind"),
                f"missing: the model's kind ({_or(kinds)}), or file (a rule file declaring it)",
            )
        if kind not in kinds:
            if kind in PLANNED_MODELS:
                raise fail(
                    t.key("kind"),
                    f"model '{kind}' is not available yet (available: {', '.join(kinds)})",
                )
            close = difflib.get_close_matches(kind, kinds, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise fail(t.key("kind"), f"unknown model '{kind}' ({hint}known: {', '.join(kinds)})")
        if dim is not None:
            _check_models([{"kind": kind}], dim, _Renumber(fail, i))
        takes = _takes(kind, dim)
        for k in t.data:
            if k not in ("kind", *takes):
                close = difflib.get_close_matches(k, takes, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise fail(
                    t.key(k),
                    f"unknown key{hint} (model '{kind}' takes {', '.join(takes)})",
                )
        spec: dict[str, Any] = {"kind": kind}
        types = _param_types(kind, dim)
        for p in takes:
            if p in MATERIAL_KEYS_IN_MODEL:
                continue
            v = _shipped_param(t, p, types.get(p, "f64"), kind, fail)
            if v is not None:
                spec[p] = v
        for p in MATERIAL_KEYS_IN_MODEL:
            v = t.number(p)
            if v is None:
                continue
            if p in set_by and set_by[p][1] != v:
                other, was = set_by[p]
                raise fail(
                    t.key(p),
                    f"{v:g} differs from {other} = {was:g} (the material has one {p})",
                )
            set_by.setdefault(p, (t.key(p), v))
        models.append(spec)
    return models, set_by, user_models


def _user_model(t: _Table, i: int, dim: int | None, base: Path | None, fail: _Fail) -> Model:
    """The model of a ``[[model]] file = "..."`` table: the file (relative to ``base``) read
    and checked with the shipped common rules, the model picked by ``name`` (needed when the
    file declares several), its parameters from the table's other keys. Refusals name
    ``model[i].file`` (an unreadable or refused file: the checker's ``FILE:LINE:COL`` lines
    follow), ``model[i].name`` or ``model[i].<param>``."""
    file = _required_str(t, "file", fail)
    path = Path(file).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    key = t.key("file")
    try:
        declared = Model.load_all(path)
    except UnicodeDecodeError as e:
        raise fail(
            key, f"cannot read the rule file {path}: not UTF-8 text (byte {e.start})"
        ) from None
    except OSError as e:
        raise fail(key, f"cannot read the rule file {path}: {e.strerror or e}") from None
    except RuleError as e:
        raise fail(key, f"the rule file is refused:\n{e}") from None
    if not declared:
        raise fail(key, f"{path} declares no model")
    names = ", ".join(m.name for m in declared)
    name = t.string("name")
    if name is None:
        if len(declared) > 1:
            raise fail(
                t.key("name"),
                f"missing: {path} declares several models ({names}); say which with name",
            )
        model = declared[0]
    else:
        found = [m for m in declared if m.name == name]
        if not found:
            raise fail(t.key("name"), f"{path} declares no model '{name}' (it declares: {names})")
        model = found[0]
    if dim is not None and dim not in model.dimensions:
        raise fail(key, _wrong_dimension(model, dim))
    params = list(model.params)
    takes = ", ".join(params) if params else "no parameter"
    for k in t.data:
        if k in ("file", "name"):
            continue
        if k not in params:
            close = difflib.get_close_matches(k, params, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise fail(t.key(k), f"unknown key{hint} (model '{model.name}' takes {takes})")
        if model.param_types.get(k) not in ("f64", "vec3"):
            raise fail(
                t.key(k),
                f"model '{model.name}': '{k}' has type {model.param_types.get(k)}; only f64 "
                "and vec3 parameters can be set from a scene",
            )
    values: dict[str, float | list[float]] = {}
    for p in params:
        v = _param(t, p, model.param_types.get(p, "f64"), model.name, fail)
        if v is not None:
            values[p] = v
    for p, default in model.params.items():
        if default is None and p not in values:
            raise fail(
                t.key(p), f"missing: model '{model.name}' has no default for parameter '{p}'"
            )
    return model.with_params(**values)


def _model_origins(
    models: list[dict[str, Any]], user_models: Mapping[int, Model], tables: list[_Table]
) -> list[tuple[str, str, str]]:
    """``("model", kind, key)`` for each model (see :attr:`Scene.origins`): the key a kernel
    refusal of it is named by, ``model[i].kind``, or for a user's model ``model[i].name``
    (when the table gives one) or ``model[i].file``."""
    origins: list[tuple[str, str, str]] = []
    for i, m in enumerate(models):
        if i not in user_models:
            key = f"model[{i}].kind"
        elif tables[i].has("name"):
            key = f"model[{i}].name"
        else:
            key = f"model[{i}].file"
        origins.append(("model", m["kind"], key))
    return origins


def _model_files_of(models: list[Model]) -> list[tuple[str, str]]:
    """The ``(file, text)`` pairs of the user's models' rule files, each once."""
    return _model_files_pairs(list(models))[1]


def _wrong_dimension(model: Model, dim: int) -> str:
    dims = " or ".join(f"{d}D" for d in model.dimensions)
    return f"model '{model.name}' runs on {dims} meshes, the mesh is {dim}D"


class _Renumber(_Fail):
    """A :class:`_Fail` that reads ``model[0]`` as ``model[i]`` (checking one model alone)."""

    def __init__(self, fail: _Fail, i: int) -> None:
        super().__init__(fail.source)
        self.i = i

    def __call__(self, key: str | None, problem: str) -> SceneError:
        if key is not None and key.startswith("model[0]"):
            key = f"model[{self.i}]" + key[len("model[0]") :]
        return super().__call__(key, problem)
