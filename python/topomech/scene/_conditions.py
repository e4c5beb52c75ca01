"""The boundary and initial conditions of a scene: the ``[[fix]]`` tables (held and
prescribed vertices), the ``[[load]]`` tables (dead loads), the ``[initial]`` table(s), the
ground plane ``world.ground``, and the selection they share (``where``, ``points`` or
``group``). :func:`topomech.loads.apply_conditions` applies what the kernel does not take
in its configuration.
"""

from __future__ import annotations

from typing import Any

from topomech.loads import LOAD_KINDS, LoadError, compile_expression, compile_predicate
from topomech.scene._table import (
    _INT_MAX,
    _check_predicate,
    _Fail,
    _number,
    _or,
    _required_str,
    _show,
    _Table,
    _too_large,
)


def _fixes(
    tables: list[_Table], fail: _Fail
) -> tuple[
    list[str],
    list[tuple[str, tuple[float, ...]]],
    list[tuple[str, dict[str, Any], list[float] | None]],
    list[tuple[str, str, str]],
    list[tuple[str, dict[str, Any], list[float] | None]],
]:
    """The ``[[fix]]`` tables: the predicates of the vertices held in place and of those held
    at a displacement (``(predicate, displacement)``), which the kernel takes; the fixes by
    ``points`` or ``group`` (``(key, selection, displacement or None)``), which
    :func:`topomech.loads.apply_conditions` applies; ``("fix" or "prescribed", predicate,
    key)`` for each predicate (see :attr:`Scene.origins`); and every table as ``(key,
    selection, displacement or None)``, in order, with which
    :func:`topomech.loads.apply_conditions` refuses two tables holding one vertex at two
    positions when one of them selects by ``points`` or ``group`` (the kernel refuses it
    between predicates)."""
    fixed: list[str] = []
    prescribed: list[tuple[str, tuple[float, ...]]] = []
    held: list[tuple[str, dict[str, Any], list[float] | None]] = []
    origins: list[tuple[str, str, str]] = []
    supports: list[tuple[str, dict[str, Any], list[float] | None]] = []
    for f in tables:
        sel = _selection(f, fail, required=True, in_python=False)
        disp = f.vector("displacement", 3)
        f.done()
        supports.append((f.path, sel, None if disp is None else list(disp)))
        if "where" not in sel:
            held.append((f.path, sel, None if disp is None else list(disp)))
            continue
        pred = sel["where"]
        if disp is None:
            fixed.append(pred)
            origins.append(("fix", pred, f.key("where")))
        else:
            prescribed.append((pred, disp))
            origins.append(("prescribed", pred, f.key("where")))
    return fixed, prescribed, held, origins, supports


def _selection(t: _Table, fail: _Fail, *, required: bool, in_python: bool = True) -> dict[str, Any]:
    """The selection of a ``[[fix]]``, ``[[load]]`` or ``[initial]`` table: exactly one of
    ``where`` (a predicate on x, y, z), ``points`` (input point indices) or ``group`` (a
    group name of the mesh file); ``{}`` when none is given and none is ``required``.
    ``in_python``: the predicate is evaluated by :mod:`topomech.loads` (on face centroids,
    or vertices of an initial field), which reads the scalar part of the rule language
    only; a fix's predicate is compiled by the kernel."""
    given = [k for k in ("where", "points", "group") if t.has(k)]
    t.known += [k for k in ("where", "points", "group") if k not in t.known]
    if len(given) > 1:
        raise fail(
            t.key(given[1]),
            f"give one selection: {t.key(given[0])} or {t.key(given[1])}, not both",
        )
    if not given:
        if required:
            raise fail(
                t.path,
                'missing the selection: where = "predicate on x, y, z", points = [input '
                'point indices] or group = "a group of the mesh file"',
            )
        return {}
    k = given[0]
    if k == "where":
        pred = _check_predicate(_required_str(t, "where", fail), t.key("where"), fail)
        if in_python:
            try:
                compile_predicate(pred)
            except LoadError as e:
                raise fail(t.key("where"), str(e)) from None
        return {"where": pred}
    if k == "group":
        name = _required_str(t, "group", fail)
        if not name:
            raise fail(t.key("group"), "the group name is empty")
        return {"group": name}
    v = t._get("points")
    if not isinstance(v, list) or not v:
        raise fail(t.key("points"), f"expected a non-empty array of point indices, got {_show(v)}")
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, int):
            raise fail(f"{t.key('points')}[{i}]", f"expected an integer, got {_show(x)}")
        if x < 0:
            raise fail(f"{t.key('points')}[{i}]", f"point indices are >= 0, got {x}")
        if x > _INT_MAX:
            raise fail(f"{t.key('points')}[{i}]", _too_large(x))
    return {"points": list(v)}


#: The key holding each load kind's value.
_LOAD_VALUE = {"point": "force", "traction": "traction", "pressure": "pressure"}


def _loads(tables: list[_Table], fail: _Fail) -> list[tuple[str, dict[str, Any]]]:
    """The ``[[load]]`` tables: ``(key, {"kind", value, "select"})``."""
    loads: list[tuple[str, dict[str, Any]]] = []
    for t in tables:
        kind = t.string("kind")
        if kind is None:
            raise fail(t.key("kind"), f"missing: the load's kind ({_or(LOAD_KINDS)})")
        if kind not in LOAD_KINDS:
            raise fail(
                t.key("kind"), f"unknown load kind {_show(kind)} (expected {_or(LOAD_KINDS)})"
            )
        want = _LOAD_VALUE[kind]
        for other in _LOAD_VALUE.values():
            if other != want and t.has(other):
                raise fail(
                    t.key(other),
                    f"a {kind} load takes {want}, not {other}",
                )
        value: Any
        raw = t.data.get(want)
        if kind == "pressure" and isinstance(raw, str):
            value = _expression(t, want, raw, t.key(want), fail)
        elif kind == "traction" and isinstance(raw, list) and any(isinstance(v, str) for v in raw):
            if len(raw) != 3:
                raise fail(t.key(want), f"expected an array of 3 numbers, got {_show(raw)}")
            value = [
                _expression(t, want, v, f"{t.key(want)}[{i}]", fail)
                if isinstance(v, str)
                else _number(v, f"{t.key(want)}[{i}]", fail)
                for i, v in enumerate(raw)
            ]
        elif kind == "pressure":
            value = t.number("pressure")
        else:
            vec = t.vector(want, 3)
            value = None if vec is None else list(vec)
        if value is None:
            unit = {
                "force": "[fx, fy, fz] in N on each selected vertex",
                "traction": "[tx, ty, tz] in Pa (3D faces) or N/m (2D edges)",
                "pressure": "a number in Pa (3D faces) or N/m (2D edges), along the inward normal",
            }[want]
            raise fail(t.key(want), f"missing: {unit}")
        sel = _selection(t, fail, required=True)
        t.done()
        loads.append((t.path, {"kind": kind, want: value, "select": sel}))
    return loads


def _expression(t: _Table, k: str, text: str, key: str, fail: _Fail) -> str:
    """A load's value given as an expression of x, y, z (checked now, evaluated on the rest
    faces when the scene is built)."""
    t.known.append(k)
    try:
        compile_expression(text)
    except LoadError as e:
        raise fail(key, str(e)) from None
    return text


def _initial(top: _Table, fail: _Fail) -> list[tuple[str, dict[str, Any]]]:
    """The ``[initial]`` table (or ``[[initial]]`` tables): ``(key, {"velocity",
    "displacement", "select"})``."""
    if not top.has("initial"):
        return []
    tables = (
        [top.table("initial")] if isinstance(top.data["initial"], dict) else top.tables("initial")
    )
    out: list[tuple[str, dict[str, Any]]] = []
    for t in tables:
        velocity = t.vector("velocity", 3)
        displacement = t.vector("displacement", 3)
        sel = _selection(t, fail, required=False)
        t.done()
        if velocity is None and displacement is None:
            raise fail(t.path, "give velocity = [vx, vy, vz] or displacement = [dx, dy, dz]")
        out.append(
            (
                t.path,
                {
                    "velocity": None if velocity is None else list(velocity),
                    "displacement": None if displacement is None else list(displacement),
                    "select": sel,
                },
            )
        )
    return out


def _ground(world: _Table, fail: _Fail) -> float | dict[str, list[float]] | None:
    """``world.ground``: a number (a height along the opposite of gravity), or a table
    ``{ point = [..], normal = [..] }`` (normal optional: the opposite of gravity)."""
    if isinstance(world.data.get("ground"), dict):
        g = world.table("ground")
        point = g.vector("point", 3)
        normal = g.vector("normal", 3)
        g.done()
        if point is None:
            raise fail(g.key("point"), "missing: a point [x, y, z] of the ground plane")
        out: dict[str, list[float]] = {"point": list(point)}
        if normal is not None:
            if all(x == 0.0 for x in normal):
                raise fail(g.key("normal"), "must not be zero")
            out["normal"] = list(normal)
        return out
    return world.number("ground")
