"""Topology changes of a scene: the ``[[event]]`` tables (timed cuts and moving blades) and
the ``[fracture]`` table, as :class:`topomech.Simulation` takes them, and the check of the
fracture criterion against the mesh once it is known (the Rust side:
``crates/physics/src/events.rs``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from topomech import _core
from topomech.scene._table import (
    _check_predicate,
    _Fail,
    _number,
    _or,
    _required_str,
    _show,
    _Table,
)

if TYPE_CHECKING:
    from topomech._gmap import GMap


#: The kinds of ``[[event]]`` tables.
EVENT_KINDS = ("cut", "blade")

#: The fracture criteria.
FRACTURE_CRITERIA = ("stress", "strain")


def _check_fracture(fracture: Mapping[str, Any] | None, g: GMap, fail: _Fail) -> None:
    """Refuses the stress criterion on a mesh it cannot measure: it needs tetrahedra."""
    if fracture is None or fracture["criterion"] != "stress":
        return
    if g.dimension != 3:
        raise fail(
            "fracture.criterion",
            "the stress criterion needs a volume mesh of tetrahedra, the mesh is 2D "
            "(a surface tears by 'strain')",
        )
    others = sorted(set(g.to_flat().kinds) - {"tetra"})
    if others:
        raise fail(
            "fracture.criterion",
            f"the stress criterion measures tetrahedra only, the mesh has {', '.join(others)} "
            "cells (use 'strain')",
        )


def _events(tables: list[_Table], fail: _Fail) -> list[dict[str, Any]]:
    """The ``[[event]]`` tables as :class:`Simulation` takes them."""
    events: list[dict[str, Any]] = []
    for t in tables:
        kind = t.string("kind")
        if kind is None:
            raise fail(t.key("kind"), f"missing: the event's kind ({_or(EVENT_KINDS)})")
        if kind not in EVENT_KINDS:
            raise fail(
                t.key("kind"), f"unknown event kind {_show(kind)} (expected {_or(EVENT_KINDS)})"
            )
        if kind == "blade":
            events.append(_blade(t, fail))
            continue
        time = t.number("time", nonneg=True)
        t.done(extra=("plane", "where"))
        if time is None:
            raise fail(t.key("time"), "missing: when the event happens (s, >= 0)")
        event: dict[str, Any] = {"time": time, "kind": kind}
        if t.has("plane") and t.has("where"):
            raise fail(
                t.key("where"),
                f"give either {t.key('plane')} or {t.key('where')}, not both",
            )
        if t.has("plane"):
            p = t.table("plane")
            normal = p.vector("normal", 3)
            offset = p.number("offset")
            p.done()
            if normal is None:
                raise fail(p.key("normal"), "missing: the plane's normal [nx, ny, nz]")
            if all(x == 0.0 for x in normal):
                raise fail(p.key("normal"), "must not be zero")
            if offset is None:
                raise fail(p.key("offset"), "missing: the plane is normal . x = offset")
            event["plane"] = {"normal": list(normal), "offset": offset}
        elif t.has("where"):
            where = _required_str(t, "where", fail)
            event["where"] = _check_predicate(where, t.key("where"), fail)
        else:
            raise fail(
                t.path,
                "missing the cut's geometry: give plane = { normal = [nx, ny, nz], "
                'offset = d } or where = "predicate on x, y, z"',
            )
        events.append(event)
    return events


def _segment(t: _Table, k: str, fail: _Fail) -> list[list[float]]:
    """A blade's segment: 2 points ``[[x, y, z], [x, y, z]]``."""
    v = t.data.get(k)
    t.known.append(k)
    if v is None:
        raise fail(t.key(k), "missing: the blade's two end points [[x, y, z], [x, y, z]]")
    if not isinstance(v, list) or len(v) != 2:
        raise fail(t.key(k), f"expected 2 points [[x, y, z], [x, y, z]], got {_show(v)}")
    points = []
    for i, p in enumerate(v):
        at = f"{t.key(k)}[{i}]"
        if not isinstance(p, list) or len(p) != 3:
            raise fail(at, f"expected an array of 3 numbers, got {_show(p)}")
        point: list[float] = []
        for j, v in enumerate(p):
            x = _number(v, f"{at}[{j}]", fail)
            # the crossing test takes products of three coordinate differences: past this
            # they overflow (Simulation refuses them too; named here, where they are written)
            if abs(x) > 1e100:
                raise fail(
                    f"{at}[{j}]",
                    f"must be at most 1e100 in magnitude (the blade's crossing test would "
                    f"overflow), got {_show(x)}",
                )
            point.append(x)
        points.append(point)
    if points[0] == points[1]:
        raise fail(t.key(k), "the blade's two end points must differ")
    return points


def _blade(t: _Table, fail: _Fail) -> dict[str, Any]:
    """A ``[[event]]`` of kind ``blade``: the segment ``from`` at time ``start`` moving
    linearly to the segment ``to`` at time ``end``, cutting what it crosses each step."""
    t.string("kind")
    start = t.number("start", nonneg=True)
    end = t.number("end", nonneg=True)
    if start is None:
        raise fail(t.key("start"), "missing: when the blade starts moving (s, >= 0)")
    if end is None:
        raise fail(t.key("end"), "missing: when the blade stops (s, after start)")
    if end <= start:
        raise fail(t.key("end"), f"must be after start ({start:g}), got {end:g}")
    if t.has("time"):
        raise fail(t.key("time"), "a blade moves from start to end: give start and end")
    src, dst = _segment(t, "from", fail), _segment(t, "to", fail)
    blade = {"kind": "blade", "start": start, "end": end, "from": src, "to": dst}
    if src == dst:
        raise fail(
            t.key("to"),
            f"the same segment as {t.key('from')}: the blade would not move, so it would "
            "sweep nothing",
        )
    # the kernel's own test (blade events and Simulation.cut_swept refuse the same): the
    # segments differ, so what it finds is a slide along the segment's own line
    if _core.blade_sweep_problem(src, dst) is not None:
        raise fail(
            t.key("to"),
            f"on the line of {t.key('from')}: the blade would slide along its own line, so "
            "it would sweep nothing",
        )
    t.done()
    return blade


def _fracture(top: _Table, fail: _Fail) -> dict[str, Any] | None:
    """The ``[fracture]`` table as :class:`Simulation` takes it (None without one)."""
    if not top.has("fracture"):
        return None
    t = top.table("fracture")
    t.done(extra=("criterion", "threshold"))
    if not t.has("criterion"):
        raise fail(t.key("criterion"), f"missing: {_or(FRACTURE_CRITERIA)}")
    criterion = t.choice("criterion", FRACTURE_CRITERIA, "strain")
    threshold = t.number("threshold", positive=True)
    if threshold is None:
        unit = "a stress in Pa" if criterion == "stress" else "a strain, l / l0 - 1"
        raise fail(t.key("threshold"), f"missing: {unit} above which a face or edge opens")
    return {"criterion": criterion, "threshold": threshold}
