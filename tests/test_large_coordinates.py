"""Previews and the viewer at large coordinates: a mesh placed at 5e6 m.

The view data (what `topomech view` and the previews draw) holds positions in float32,
whose spacing at 5e6 is 0.5 m: absolute coordinates would wreck a 1 m mesh. They are stored
relative to a local origin (the centre of the rest bounding box, in view.json), so the same
run translated by 5e6 m must give the same float32 buffers, bounds and preview images as the
untranslated one, to float32 precision of the mesh's own size.
"""

from __future__ import annotations

import io
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import meshio
import numpy as np
import numpy.typing as npt
import pytest

from topomech import _core
from topomech.recording import View, read_view
from topomech.render import render_frames
from topomech.run import run_scene
from topomech.viewer import write_viewer

SHIFT = 5e6
#: float32 spacing near 1 m is 1.2e-7: 8 of them, plus the float64 round-off of the
#: translated run's dynamics (1e-9 m per step at 5e6 m, 20 steps): both far below 1e-6 m.
LOCAL_ATOL = 1e-6


def _run(tmp: Path, dimension: int, shift: float) -> View:
    if dimension == 3:
        pts, _, _, conn = _core.box(4, 1, 1, 1.0, 0.25, 0.25, "tetra")
        cells = [("tetra", np.asarray(conn, dtype=np.int64).reshape(-1, 4))]
        model = 'kind = "corotational"\nyoung = 1e5\npoisson = 0.3'
    else:
        pts, _, _, conn = _core.grid(4, 2, 1.0, 0.5, "triangle")
        cells = [("triangle", np.asarray(conn, dtype=np.int64).reshape(-1, 3))]
        model = 'kind = "stretch_elementary"\nstiffness = 1e4'
    points = np.asarray(pts, dtype=np.float64) + shift
    if dimension == 2:
        points[:, 2] = 0.0  # the plane stays z = 0; x and y move far away
    d = tmp / f"shift{shift:g}"
    d.mkdir()
    meshio.write(d / "m.vtu", meshio.Mesh(points, cells))
    (d / "s.toml").write_text(
        f"""
name = "far"
[mesh]
file = "m.vtu"
[[model]]
{model}
[material]
density = 100.0
[[fix]]
where = "x < {shift + 1e-6!r}"
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 20
[output]
every = 5
"""
    )
    summary = run_scene(d / "s.toml", d / "out", preview=False)
    assert "error" not in summary
    return read_view(d / "out")


def _all_positions(view: View) -> npt.NDArray[np.float32]:
    return np.concatenate([view.positions(k) for k in range(len(view.frames))])


@pytest.mark.parametrize("dimension", [2, 3])
def test_view_buffers_are_local_and_match_the_untranslated_run(
    tmp_path: Path, dimension: int
) -> None:
    """Same float32 buffers (positions, fields) and bounds; origins 5e6 apart; positions
    plus origin are the simulated ones (float64) to float32 precision of the local size."""
    near = _run(tmp_path, dimension, 0.0)
    far = _run(tmp_path, dimension, SHIFT)
    moved = np.array([SHIFT, SHIFT, SHIFT if dimension == 3 else 0.0])
    np.testing.assert_allclose(far.origin - near.origin, moved, rtol=0, atol=1e-6)
    assert len(far.frames) == len(near.frames)
    a, b = _all_positions(near), _all_positions(far)
    assert np.abs(a).max() < 1.0  # local: within the mesh's size of the origin
    np.testing.assert_allclose(b, a, rtol=0, atol=LOCAL_ATOL)
    for k in range(len(near.frames)):
        np.testing.assert_allclose(
            far.world_positions(k), near.world_positions(k) + moved, rtol=0, atol=LOCAL_ATOL
        )
        for name, meta in near.meta["fields"].items():
            # the translated run's own float64 positions are rounded to 1e-9 m: in strains
            # of 0.25 m elements 4e-9, times young = 1e5 Pa, 4e-4 Pa of stresses up to
            # about 40 Pa; 1e-4 of the field's range is 25 times less than a color step
            np.testing.assert_allclose(
                far.field(k, name), near.field(k, name), rtol=0, atol=1e-4 * meta["max"]
            )
    for side in ("min", "max"):
        np.testing.assert_allclose(
            far.meta["bounds"][side], near.meta["bounds"][side], rtol=0, atol=LOCAL_ATOL
        )
    # the run did move (gravity), so the comparison is not of the rest state only
    assert np.abs(a[-len(near.positions(0)) :] - near.positions(0)).max() > 1e-5
    # and absolute float32 positions would not do: their spacing at 5e6 m is 0.5 m
    world = far.world_positions(0)
    assert np.abs(world.astype(np.float32).astype(np.float64) - world).max() > 0.01


def test_previews_at_5e6_m_are_the_previews_at_the_origin(tmp_path: Path) -> None:
    """The headless previews of the translated run are the untranslated run's images: at
    most a few pixels differ, by little (antialiasing of edges that moved by 1e-7 m)."""
    near = _run(tmp_path, 3, 0.0)
    far = _run(tmp_path, 3, SHIFT)
    size = (320, 240)
    for im_near, im_far in zip(render_frames(near, size=size), render_frames(far, size=size)):
        x = np.asarray(im_near, dtype=np.int64)
        y = np.asarray(im_far, dtype=np.int64)
        diff = np.abs(x - y).max(axis=2)
        assert (diff > 8).mean() < 1e-3, (diff > 8).sum()
        # the picture is not blank: the mesh covers a good part of it
        assert (x.min(axis=2) < 200).mean() > 0.05


# ---------------------------------------------------------------------------------- browser


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Headless Chromium, as in test_viewer.py (skipped, saying why, without it)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("browser test skipped: the playwright package is not installed")
    exe = os.environ.get("TOPOMECH_CHROMIUM", "/usr/bin/chromium")
    if not Path(exe).is_file():
        found = shutil.which("chromium") or shutil.which("chromium-browser")
        if found is None:
            pytest.skip("browser test skipped: no Chromium (make browser installs it)")
        exe = found
    with sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        except Exception as e:
            pytest.skip(f"browser test skipped: {exe} does not start headless: {e}")
        yield b
        b.close()


def _viewer_pixels(browser: Any, out: Path, frame: int) -> npt.NDArray[np.int64]:
    from PIL import Image

    pg = browser.new_page(viewport={"width": 640, "height": 480})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    try:
        pg.goto(write_viewer(out).resolve().as_uri())
        pg.eval_on_selector(
            "#scrub", f"e => {{ e.value = '{frame}'; e.dispatchEvent(new Event('input')); }}"
        )
        png = pg.locator("#view").screenshot()
    finally:
        pg.close()
    assert errors == []
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int64)


def test_the_viewer_draws_the_run_at_5e6_m_as_the_run_at_the_origin(
    tmp_path: Path, browser: Any
) -> None:
    """The viewer page (its float32 buffers, its camera fitted to the recorded bounds) draws
    the translated run as the untranslated one: at most a few edge pixels differ."""
    near = _run(tmp_path, 3, 0.0)
    far = _run(tmp_path, 3, SHIFT)
    last = len(near.frames) - 1
    x = _viewer_pixels(browser, near.directory, last)
    y = _viewer_pixels(browser, far.directory, last)
    assert (x.min(axis=2) < 200).mean() > 0.02  # something is drawn
    diff = np.abs(x - y).max(axis=2)
    assert (diff > 8).mean() < 1e-3, (diff > 8).sum()
