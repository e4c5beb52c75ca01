"""The ``[material]`` table of a scene: density, damping, Young's modulus and Poisson's ratio,
the ``[[material.region]]`` tables (elements whose rest centroid satisfies a predicate, with
their own values), and the one ``young`` and ``poisson`` the material has when ``[[model]]``
tables set them too (the Rust side: ``crates/physics/src/config.rs``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from topomech.scene._table import _ArgFail, _check_predicate, _Fail, _required_str, _Table

#: The material values a region may set (``density`` and ``young`` positive, ``poisson``
#: in (-1, 0.5)); it sets at least one.
REGION_VALUES = ("density", "young", "poisson")


@dataclass(frozen=True)
class _Material:
    """The ``[material]`` table as read: ``young`` and ``poisson`` None when it does not give
    them (a model table may, else they default)."""

    density: float
    damping: float
    young: float | None
    poisson: float | None
    #: The ``[[material.region]]`` tables, as :class:`topomech.Simulation` takes them.
    regions: list[dict[str, Any]]
    #: ``("region", where, key)`` for each region (see :attr:`Scene.origins`).
    origins: list[tuple[str, str, str]]


def _material(mat: _Table, fail: _Fail) -> _Material:
    """The ``[material]`` table ``mat`` and its regions."""
    density = mat.number("density", 1000.0, positive=True)
    damping = mat.number("damping", 0.0, nonneg=True)
    young = mat.number("young", positive=True)
    poisson = mat.number("poisson")
    regions = []
    origins: list[tuple[str, str, str]] = []
    for r in mat.tables("region"):
        region: dict[str, Any] = {
            "where": _check_predicate(_required_str(r, "where", fail), r.key("where"), fail)
        }
        for k, pos in zip(REGION_VALUES, (True, True, False)):
            v = r.number(k, positive=pos)
            if v is not None:
                if k == "poisson":
                    _check_poisson(v, r.key(k), fail)
                region[k] = v
        r.done()
        _check_region_values(region, r.path, fail)
        regions.append(region)
        origins.append(("region", region["where"], r.key("where")))
    mat.done()

    if poisson is not None:
        _check_poisson(poisson, "material.poisson", fail)
    return _Material(density, damping, young, poisson, regions, origins)


def _check_region_values(region: Mapping[str, Any], key: str, fail: _Fail) -> None:
    """Refuses a region (its ``where`` and values, a dict) that sets none of
    :data:`REGION_VALUES`: it would change nothing. A scene's ``[[material.region]]`` tables
    and :class:`topomech.Simulation`'s ``regions`` are checked with it."""
    if not any(k in region for k in REGION_VALUES):
        raise fail(key, "a region needs density, young or poisson")


def check_region_args(regions: Sequence[Any]) -> None:
    """Refuses, with ``ValueError("regions[i]: problem")``, a region given to
    :class:`topomech.Simulation` that a scene's ``[[material.region]]`` table refuses and
    the kernel does not: one that sets no material value (:func:`_check_region_values`).
    A region that is not a mapping, lacks ``where`` or has an unknown key is left to the
    kernel, which refuses it with its own message (as it refuses a bad value)."""
    fail = _ArgFail()
    for i, region in enumerate(regions):
        if (
            isinstance(region, Mapping)
            and "where" in region
            and all(k in ("where", *REGION_VALUES) for k in region)
        ):
            _check_region_values(region, f"regions[{i}]", fail)


def _young_poisson(
    material: _Material, set_by: dict[str, tuple[str, float]], fail: _Fail
) -> tuple[float, float]:
    """The material's ``young`` and ``poisson``: those the model tables set (``set_by``: each
    with the key that set it first), which must agree with ``[material]``'s, else
    ``[material]``'s, else 1e6 and 0.3."""
    young, poisson = material.young, material.poisson
    for what, v in (("young", young), ("poisson", poisson)):
        if what in set_by and v is not None and set_by[what][1] != v:
            key, from_model = set_by[what]
            raise fail(
                key,
                f"{from_model:g} differs from material.{what} = {v:g} "
                f"(the material has one {what})",
            )
    if "young" in set_by:
        key, young = set_by["young"]
        if young <= 0:
            raise fail(key, f"must be positive, got {young:g}")
    if "poisson" in set_by:
        key, poisson = set_by["poisson"]
        _check_poisson(poisson, key, fail)
    young = 1e6 if young is None else young
    poisson = 0.3 if poisson is None else poisson
    return young, poisson


def _check_poisson(v: float, key: str, fail: _Fail) -> None:
    if not -1.0 < v < 0.5:
        raise fail(key, f"must be in (-1, 0.5), got {v:g}")
