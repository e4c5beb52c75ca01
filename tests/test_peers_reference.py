"""The peer benchmark's static reference (bench/peers/common.py: linear FEM assembled and
solved with numpy alone) agrees with topomech's own static `linear_fem` solve on the shipped
cantilever's mesh. Needs numpy and topomech only, never a peer."""

import importlib.util
import sys
from pathlib import Path

import numpy as np

import topomech

COMMON = Path(__file__).resolve().parent.parent / "bench" / "peers" / "common.py"


def _common():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("peers_common", COMMON)
    assert spec is not None
    assert spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def test_numpy_reference_matches_topomech_static_solve() -> None:
    c = _common()
    mesh = c.tet_mesh((10, 2, 2))
    ref = c.static_reference(mesh)
    sim = topomech.Simulation(
        c.topomech_tet_map((10, 2, 2)),
        models=[{"kind": "linear_fem"}],
        density=c.DENSITY,
        young=c.YOUNG,
        poisson=c.POISSON,
        gravity=list(c.GRAVITY),
        fixed=[c.BEAM_FIXED],
        integrator="static",
        dt=1.0,
    )
    assert np.array_equal(sim.rest_positions(), mesh.points)
    np.testing.assert_allclose(sim.masses(), mesh.masses, rtol=1e-12)
    sim.step(1)
    tip = c.tip_deflection(mesh, sim.positions())
    assert tip < 0.0
    assert abs(tip - ref["tip_deflection"]) <= 1e-8 * abs(ref["tip_deflection"])
    # the explicit time step of the benchmark's cantilever run is stable
    assert ref["dt_stable"] > c.case_by_name("cantilever_240").dt
