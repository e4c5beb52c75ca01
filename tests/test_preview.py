"""What `topomech run` renders: preview.gif (and .mp4), energy.csv and energy.png, and the
quantities behind them (energies, von Mises stress)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from topomech import cli
from topomech.recording import Recorder, element_stress, read_energy, read_view
from topomech.render import ffmpeg_exe
from topomech.run import run_scene
from topomech.scene import load_scene

BEAM = """
name = "beam"
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [{cells}, 1, 1]
[[model]]
kind = "{model}"
{params}
[material]
density = 1000.0
damping = {damping}
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "{integrator}"
dt = {dt}
steps = {steps}
[output]
every = {every}
"""


def beam(tmp_path: Path, name: str = "beam.toml", **kw: object) -> Path:
    values: dict[str, object] = {
        "cells": 4,
        "model": "corotational",
        "params": "young = 1e6\npoisson = 0.3",
        "damping": 0.0,
        "integrator": "symplectic_euler",
        "dt": 1e-3,
        "steps": 12,
        "every": 3,
    }
    values.update(kw)
    p = tmp_path / name
    p.write_text(BEAM.format(**values))
    return p


def test_gif_has_a_frame_per_run_frame_and_is_not_blank(tmp_path: Path) -> None:
    out = tmp_path / "o"
    s = run_scene(beam(tmp_path), out)
    assert s["frames"] == 5  # steps 0, 3, 6, 9, 12
    assert s["outputs"]["preview"] == "preview.gif"
    with Image.open(out / "preview.gif") as gif:
        assert gif.format == "GIF"
        assert gif.n_frames == s["frames"]
        assert gif.info.get("loop") == 0
        frames = []
        for k in range(gif.n_frames):
            gif.seek(k)
            frames.append(np.asarray(gif.convert("RGB"), dtype=np.float64))
    for f in frames:
        assert f.shape == (480, 640, 3)
        assert f.std() > 20  # a shaded, colored beam on white, not an empty picture
        assert (f.sum(axis=2) < 600).mean() > 0.05  # a good part of it is not background
    # the beam sags and the time changes: consecutive frames differ
    assert all(np.abs(a - b).mean() > 0 for a, b in zip(frames, frames[1:]))


def test_fixed_camera_frames_the_whole_motion(tmp_path: Path) -> None:
    """Nothing of the object touches the picture's border in any frame, though the beam
    moves: the camera is fitted to every frame's positions."""
    out = tmp_path / "o"
    run_scene(beam(tmp_path, steps=150, every=30, dt=2e-3), out, video=False)
    with Image.open(out / "preview.gif") as gif:
        for k in range(gif.n_frames):
            gif.seek(k)
            f = np.asarray(gif.convert("RGB"), dtype=np.int64)
            border = np.concatenate([f[:, :4].reshape(-1, 3), f[-4:, :].reshape(-1, 3)])
            assert (border.sum(axis=1) > 700).all()  # white: the bottom and left edges


def test_energy_png_is_a_plot(tmp_path: Path) -> None:
    out = tmp_path / "o"
    s = run_scene(beam(tmp_path), out, video=False)
    assert s["outputs"]["energy_plot"] == "energy.png"
    with Image.open(out / "energy.png") as im:
        assert im.format == "PNG"
        assert im.size == (720, 400)
        a = np.asarray(im.convert("RGB"), dtype=np.float64)
    assert a.std() > 10


@pytest.mark.skipif(ffmpeg_exe() is None, reason="imageio-ffmpeg is not installed (no encoder)")
def test_mp4_is_written_when_an_encoder_is_installed(tmp_path: Path) -> None:
    out = tmp_path / "o"
    s = run_scene(beam(tmp_path), out)
    assert s["outputs"]["video"] == "preview.mp4"
    head = (out / "preview.mp4").read_bytes()[:12]
    assert head[4:8] == b"ftyp"  # an ISO media file


def test_no_preview_writes_only_the_view_data(tmp_path: Path) -> None:
    out = tmp_path / "o"
    s = run_scene(beam(tmp_path), out, preview=False)
    for k in ("preview", "video", "energy_plot", "energy"):
        assert s["outputs"][k] is None
        assert not (out / {"preview": "preview.gif", "video": "preview.mp4"}.get(k, "x")).exists()
    assert not (out / "energy.png").exists()
    assert s["outputs"]["view"] == "view.json"
    assert len(read_view(out).frames) == s["frames"]


def test_cli_run_reports_the_previews(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    assert cli.main(["run", str(beam(tmp_path)), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert str(out / "preview.gif") in printed
    assert f"topomech view {out}" in printed
    assert cli.main(["run", str(beam(tmp_path)), "--out", str(out), "--no-preview", "-q"]) == 0
    assert not (out / "preview.gif").exists()  # stale previews are removed


# ---------------------------------------------------------------------------------- energy


def drift(e: dict[str, np.ndarray]) -> float:
    """The largest change of the total energy, relative to the energy exchanged."""
    scale = max(e["kinetic"].max(), e["elastic"].max())
    return float(np.abs(e["total"] - e["total"][0]).max() / scale)


def test_total_energy_is_conserved_without_damping(tmp_path: Path) -> None:
    """Undamped symplectic Euler: the total (kinetic + gravitational + elastic) stays within
    0.5 % of the energy exchanged over 600 steps of a swinging beam. Symplectic Euler keeps a
    modified energy within O(dt) of the true one, so the total oscillates by an amount
    proportional to dt (about 0.1 % here): halving dt halves the drift, which shows that the
    drift is the integrator's and not an error in how the energies are summed."""
    drifts = []
    for dt, steps in ((2e-3, 300), (1e-3, 600)):
        out = tmp_path / f"dt{dt}"
        run_scene(beam(tmp_path, dt=dt, steps=steps, every=0), out, video=False)
        e = read_energy(out / "energy.csv")
        assert len(e["step"]) == steps + 1
        assert e["elastic"][0] == 0.0
        assert e["kinetic"][0] == 0.0
        assert e["kinetic"].max() > 1.0  # it moved
        np.testing.assert_allclose(e["total"], e["kinetic"] + e["gravitational"] + e["elastic"])
        drifts.append(drift(e))
    assert drifts[0] < 5e-3
    assert drifts[1] < 5e-3
    assert drifts[1] < 0.7 * drifts[0]


def test_damping_dissipates(tmp_path: Path) -> None:
    out = tmp_path / "o"
    run_scene(beam(tmp_path, damping=2.0, steps=300, every=0), out, video=False)
    e = read_energy(out / "energy.csv")
    assert e["total"][-1] < e["total"][0] - 0.05 * e["kinetic"].max()
    # viscous damping only removes energy (up to the integrator's O(dt) oscillation)
    assert np.all(np.diff(e["total"]) < 1e-3 * e["kinetic"].max())


def test_static_linear_fem_elastic_energy_is_half_the_load_work(tmp_path: Path) -> None:
    """Clapeyron: at the static equilibrium of a linear elastic body under a fixed load, the
    strain energy is half the work of the load, here -gravitational / 2. The one static step
    goes from rest to equilibrium; the trapezoid rule is exact for linear forces."""
    out = tmp_path / "o"
    run_scene(
        beam(tmp_path, model="linear_fem", integrator="static", dt=1.0, steps=1, every=1),
        out,
        video=False,
    )
    e = read_energy(out / "energy.csv")
    assert e["elastic"][-1] > 0
    assert e["elastic"][-1] == pytest.approx(-0.5 * e["gravitational"][-1], rel=1e-6)


def test_forces_read_after_the_step_equal_forces_computed(tmp_path: Path) -> None:
    """The lagged mode (forces read from the kernel after each step) gives the energies of
    computing them again at every state."""
    sc = load_scene(beam(tmp_path))
    elastic = []
    for lagged in (True, False):
        sim = sc.build()
        rec = Recorder(sim, sc)
        assert rec.lagged
        rec.lagged = lagged
        rec.start()
        for _ in range(40):
            sim.step()
            rec.after_step()
        rec.finish()
        elastic.append(np.array(rec.energy["elastic"]))
    assert len(elastic[0]) == 41
    np.testing.assert_allclose(elastic[0], elastic[1], rtol=1e-12, atol=0)


def test_prescribed_displacement_starts_with_its_elastic_energy(tmp_path: Path) -> None:
    """The cube of cube_cut starts stretched: its initial elastic energy is integrated from
    the rest positions, about (1/2) E strain^2 x volume for a 20 % stretch."""
    sc = load_scene("cube_cut")
    sim = sc.build()
    rec = Recorder(sim, sc)
    rec.start()
    e0 = rec.energy["elastic"][0]
    uniaxial = 0.5 * 1e5 * 0.2**2 * 1.0
    assert 0.5 * uniaxial < e0 < 3 * uniaxial


# ---------------------------------------------------------------------------------- stress


def test_von_mises_of_a_uniaxial_strain() -> None:
    """F = diag(1 + e, 1, 1): sigma = lambda e I + 2 mu e e1 e1, von Mises |s11 - s22| =
    2 mu e; a rotation of the stretched tetrahedron changes nothing for the co-rotated
    strain, and a lot for the linear one."""
    rest = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    e, young, nu = 0.01, np.array([1e6]), np.array([0.3])
    x = rest * np.array([1 + e, 1, 1])
    mu = 1e6 / (2 * 1.3)
    for strain in ("linear", "corotated"):
        vm = element_stress("tetra", rest, x, young, nu, strain)
        assert vm[0] == pytest.approx(2 * mu * e, rel=1e-9)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    xr = x @ rot.T
    assert element_stress("tetra", rest, xr, young, nu, "corotated")[0] == pytest.approx(
        2 * mu * e, rel=1e-9
    )
    assert element_stress("tetra", rest, xr, young, nu, "linear")[0] > 10 * 2 * mu * e


def test_fem_runs_are_colored_by_von_mises(tmp_path: Path) -> None:
    out = tmp_path / "o"
    run_scene(beam(tmp_path), out, preview=False)
    view = read_view(out)
    assert view.meta["default_field"] == "von_mises"
    top = view.meta["fields"]["von_mises"]["max"]
    assert top > 1e3
    assert float(view.field(0, "von_mises").max()) < 1e-9 * top  # at rest (round-off)
    springs = beam(tmp_path, "springs.toml", model="stretch_elementary", params="stiffness = 1e4")
    run_scene(springs, tmp_path / "s", preview=False)
    meta = json.loads((tmp_path / "s" / "view.json").read_text())
    assert meta["default_field"] == "displacement"
    assert set(meta["fields"]) == {"displacement"}


def test_an_interruption_while_a_state_is_recorded_leaves_consistent_energies(
    tmp_path: Path,
) -> None:
    """Regression: a Ctrl-C arriving in ``after_step`` between recording a state's row and
    noting it as pending (or the reverse, as the code once ordered them) made ``finish`` pop
    from an empty list and the run end in a traceback instead of exit 130. Both halves of the
    window are reproduced: a pending state without its row, and a row without its pending
    state; ``finish`` keeps every column the same length, the rows of completed states only."""
    sc = load_scene(beam(tmp_path))
    for lose in ("row", "pending"):
        sim = sc.build()
        rec = Recorder(sim, sc)
        assert rec.lagged
        rec.start()
        for _ in range(3):
            sim.step()
            rec.after_step()
        if lose == "row":
            rec._drop_partial()  # the pending state's row was never appended
        else:
            rec._pending = None  # the row was appended, the state not yet noted as pending
        rec.finish()
        lengths = {c: len(v) for c, v in rec.energy.items()}
        assert len(set(lengths.values())) == 1, (lose, lengths)
        assert lengths["elastic"] == 3, (lose, lengths)
