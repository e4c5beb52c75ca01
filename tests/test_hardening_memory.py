"""Bounded memory on long runs (issue 13): the frames a run records, the energies it tracks and
the previews it renders are streamed to disk, so that the peak memory of a run does not grow
with its number of frames or steps.

Each test measures the peak memory of the same work for ``n`` and ``10 n`` frames (or steps)
and asserts that the larger run's peak exceeds the smaller one's by a small fraction of what
holding the extra frames (steps) in memory would take: a store that keeps every frame grows by
at least the frames' bytes, which the tests compute and print. Python allocations are measured
with :mod:`tracemalloc`; Pillow's images live outside Python's allocator, so the previews are
measured by the peak resident size (``ru_maxrss``) of a fresh interpreter.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import textwrap
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from topomech import render
from topomech.recording import Recorder, read_energy, read_view
from topomech.run import run_scene
from topomech.scene import load_scene

SCENE = """
name = "bar"
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [{nx}, {ny}, {ny}]
[[model]]
kind = "{model}"
{params}
[material]
density = 1000.0
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "symplectic_euler"
dt = 1e-4
steps = 10
[output]
every = 1
"""


def _scene(tmp: Path, nx: int, ny: int, model: str = "linear_fem") -> Path:
    """A bar of ``(nx + 1) * (ny + 1)^2`` vertices, fixed at one end, under gravity."""
    params = "young = 1e6\npoisson = 0.3" if model == "linear_fem" else "stiffness = 1e4"
    p = tmp / f"bar_{nx}_{ny}_{model}.toml"
    p.write_text(SCENE.format(nx=nx, ny=ny, model=model, params=params))
    return p


def _peak(work: Callable[[], Any]) -> int:
    """The peak of Python's traced allocations (bytes) while ``work`` runs."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        work()
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


@pytest.fixture
def no_previews(monkeypatch: pytest.MonkeyPatch) -> None:
    """A run with ``preview`` tracks its energies; its previews are measured on their own."""
    monkeypatch.setattr(
        render,
        "render_previews",
        lambda *a, **k: {"preview": None, "video": None, "energy_plot": None},
    )


# ------------------------------------------------------------------------------ frames


def _record(sc: Any, sim: Any, n: int, out: Path) -> None:
    """A frame, then ``n`` steps with a frame after each, written to ``out``."""
    out.mkdir()
    rec = Recorder(sim, sc, energy=False)
    rec.frame()
    for _ in range(n):
        sim.step()
        rec.frame()
    assert rec.write_view(out)


def test_recorded_frames_are_not_held_in_memory(tmp_path: Path) -> None:
    """Recording 10 and 100 frames of a 775-vertex bar (a frame: positions and
    displacement, 16 B a vertex, 12.4 kB), then writing view.json and view.bin: keeping the
    frames (as before) takes 90 * 12.4 kB = 1.1 MB more for the longer run, and building
    view.bin in memory as much again (2.4 MB measured). What may grow is a few numbers per
    frame (time, step, topology, offset: 40 B), so the bound is 0.3 MB. A first recording
    warms the caches."""
    sc = load_scene(_scene(tmp_path, 30, 4, model="stretch_elementary"))
    sim = sc.build()
    peaks = {}
    for n in (2, 10, 100):
        out = tmp_path / f"run{n}"
        peaks[n] = _peak(functools.partial(_record, sc, sim, n, out))
        view = read_view(out)
        assert len(view.frames) == n + 1
        assert view.positions(n).shape == (775, 3)
        np.testing.assert_allclose(view.world_positions(n), sim.positions(), atol=1e-6)
    growth = peaks[100] - peaks[10]
    print(f"peaks {peaks}, growth {growth} B, frames' bytes {90 * 775 * 16} B")
    assert growth < 300_000, peaks


def test_frames_read_back_one_at_a_time(tmp_path: Path) -> None:
    """Reading a view and fitting the previews' camera to all of its frames (what rendering
    does first) holds one frame at a time: the peak for 100 frames of the 775-vertex bar is
    within 0.4 MB of that for 10 (view.json's index of the frames, about 1 kB a frame, is
    read whole), while view.bin grows by 1.1 MB, which reading it whole takes, and gathering
    every frame's positions as float32 and float64 (as before) 2.5 MB more."""
    sc = load_scene(_scene(tmp_path, 30, 4, model="stretch_elementary"))
    sim = sc.build()
    peaks, sizes = {}, {}
    for n in (10, 10, 100):  # the first one warms the caches
        out = tmp_path / f"run{n}"
        if not out.exists():
            _record(sc, sim, n, out)
        sizes[n] = (out / "view.bin").stat().st_size

        def work(out: Path = out) -> None:
            view = read_view(out)
            render.frame_camera(view, (320, 240))
            assert float(np.abs(view.positions(len(view.frames) - 1)).max()) > 0.0

        peaks[n] = _peak(work)
    growth = peaks[100] - peaks[10]
    print(f"peaks {peaks}, view.bin {sizes}")
    assert sizes[100] - sizes[10] > 1_000_000
    assert growth < 400_000, (peaks, sizes)


# ------------------------------------------------------------------------------ energy


def test_energy_history_is_bounded_and_streamed(tmp_path: Path, no_previews: None) -> None:
    """1,000 and 10,000 steps of a small bar, without frames: energy.csv has a row per state
    (all written), and the peak memory of the longer run is within 0.3 MB of the shorter
    one's (five floats a step kept in lists, as before, are 9,000 * 5 * 32 B = 1.4 MB more;
    1.7 MB measured). A first run warms the caches."""
    scene = _scene(tmp_path, 4, 1)
    run_scene(scene, out=tmp_path / "warm", steps=2, every=0, preview=True)
    peaks = {}
    for n in (1000, 10000):
        out = tmp_path / f"run{n}"
        peaks[n] = _peak(
            functools.partial(run_scene, scene, out=out, steps=n, every=0, preview=True)
        )
        e = read_energy(out / "energy.csv")
        assert len(e["step"]) == n + 1
        np.testing.assert_array_equal(e["step"], np.arange(n + 1))
        np.testing.assert_allclose(
            e["total"], e["kinetic"] + e["gravitational"] + e["elastic"], rtol=0, atol=1e-15
        )
    growth = peaks[10000] - peaks[1000]
    print(f"peaks {peaks}, growth {growth} B")
    assert growth < 300_000, peaks


def test_energy_rows_are_on_disk_while_the_run_goes(tmp_path: Path, no_previews: None) -> None:
    """energy.csv is written (and flushed) as the steps go: read from the progress callback
    at step 300, it already has the rows of the states before."""
    scene = _scene(tmp_path, 4, 1)
    out = tmp_path / "run"
    seen: list[int] = []

    def progress(k: int, total: int) -> None:
        if k == 300:
            path = out / "energy.csv"
            seen.append(len(path.read_text().splitlines()) - 1 if path.is_file() else 0)

    run_scene(scene, out=out, steps=400, every=0, preview=True, progress=progress)
    # rows of the states 0..299 are complete (the elastic energy of a state is known once
    # the next step has computed its forces)
    assert len(seen) == 1
    assert seen[0] >= 299, seen
    assert len(read_energy(out / "energy.csv")["step"]) == 401


def _csv(path: Path, t: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    body = np.column_stack([np.arange(len(t)), t, *columns.values()])
    header = "step,time," + ",".join(columns)
    np.savetxt(path, body, delimiter=",", header=header, comments="", fmt="%.17g")


def _feed(env: render.EnergyEnvelope, t: np.ndarray, x: np.ndarray, seed: int) -> None:
    """Rows in blocks of random sizes (1 to 5,000), as energy.csv is read."""
    rng = np.random.default_rng(seed)
    i = 0
    while i < len(t):
        m = int(rng.integers(1, 5000))
        env.add_rows(t[i : i + m], {"x": x[i : i + m]})
        i += m


def test_energy_envelope_keeps_every_bucket_extreme() -> None:
    """The decimated history of the energy plot, against numpy: for 200,000 rows of noise
    with one spike up and one down, it has at most 2 * ENERGY_BUCKETS points, the spikes
    exactly, in time order; on a series of ENERGY_BUCKETS * 64 rows (buckets 64 rows wide,
    aligned at row 0) each bucket's min and max are numpy's reduceat over the same rows; a
    series shorter than ENERGY_BUCKETS is kept whole. Rows come in blocks of random sizes
    (the buckets merge in the middle of blocks) and one by one: the same result."""
    rng = np.random.default_rng(7)
    n = 200_000
    t = np.arange(n) * 1e-3
    k = rng.normal(size=n)
    k[123_457] = 50.0
    k[7] = -60.0
    env = render.EnergyEnvelope()
    _feed(env, t, k, 1)
    tk, vk = env.series("x")
    assert len(tk) <= 2 * render.ENERGY_BUCKETS
    assert vk.max() == 50.0
    assert tk[np.argmax(vk)] == t[123_457]
    assert vk.min() == -60.0
    assert tk[np.argmin(vk)] == t[7]
    assert np.all(np.diff(tk) >= 0)
    m = render.ENERGY_BUCKETS * 64
    x = rng.normal(size=m)
    tx = np.arange(m, dtype=np.float64)
    env = render.EnergyEnvelope()
    _feed(env, tx, x, 2)
    assert env.width == 64
    got_t, got_v = env.series("x")
    starts = np.arange(0, m, 64)
    lo, hi = np.minimum.reduceat(x, starts), np.maximum.reduceat(x, starts)
    bucket = (got_t // 64).astype(np.int64)
    for b in range(len(starts)):
        got = got_v[bucket == b]
        assert got.min() == lo[b]
        assert got.max() == hi[b]
    one = render.EnergyEnvelope()
    for i in range(3000):
        one.add(float(tx[i]), {"x": float(x[i])})
    blocks = render.EnergyEnvelope()
    _feed(blocks, tx[:3000], x[:3000], 3)
    for a, b in zip(one.series("x"), blocks.series("x")):
        np.testing.assert_array_equal(a, b)
    env = render.EnergyEnvelope()
    _feed(env, tx[:100], x[:100], 4)
    np.testing.assert_array_equal(env.series("x")[1], x[:100])


def test_energy_plot_memory_is_bounded(tmp_path: Path) -> None:
    """Plotting energy.csv of 2,000 and of 20,000 rows: the peak memory is within 1 MB
    (reading the rows whole, as before, takes about 450 B a row: 8 MB more), and the plot
    shows the one step where the kinetic energy spikes (red pixels over most of the plot's
    height, where the rest of the curve is a flat line). A first plot warms the caches."""
    peaks = {}
    for n in (500, 2000, 20_000):
        t = np.arange(n) * 1e-4
        kinetic = 1.0 + 0.1 * np.sin(t)
        kinetic[n // 2 + 3] = 30.0
        zero = np.zeros(n)
        total = np.full(n, 3.0)  # conserved: the elastic energy spikes down
        cols = {"kinetic": kinetic, "gravitational": zero, "elastic": total - kinetic}
        cols["total"] = total
        _csv(tmp_path / f"e{n}.csv", t, cols)
        png = tmp_path / f"e{n}.png"
        peaks[n] = _peak(functools.partial(render.plot_energy, tmp_path / f"e{n}.csv", png))
        with Image.open(png) as im:
            a = np.asarray(im.convert("RGB"), dtype=np.int64)
        red = (a[..., 0] > 180) & (a[..., 1] < 90) & (a[..., 2] < 90)
        rows = np.flatnonzero(red.any(axis=1))
        # the spike reaches the top of the axes: red pixels over most of the plot's height
        assert rows.max() - rows.min() > 0.3 * a.shape[0], (rows.min(), rows.max())
    growth = peaks[20_000] - peaks[2000]
    print(f"peaks {peaks}")
    assert growth < 1_000_000, peaks


# ------------------------------------------------------------------------------ previews

PROBE = textwrap.dedent(
    """
    import json, resource, sys
    from pathlib import Path
    import numpy as np
    import PIL.Image, matplotlib
    from topomech.recording import read_view
    from topomech.render import render_previews
    out = Path(sys.argv[1])
    read_view(out)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    written = render_previews(out, size=(320, 240))
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"growth_kb": after - before, "written": written}))
    """
)


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in kB is Linux's")
def test_previews_are_encoded_frame_by_frame(tmp_path: Path) -> None:
    """Rendering the previews (GIF and MP4, 320 x 240) of 20 and of 200 frames, each in a
    fresh interpreter: the peak resident size while rendering grows by less than 12 MB from
    the short run to the long one. Holding the long run's frames takes 180 * 320 * 240 * 3 B
    = 41 MB more for the RGB images alone (plus their GIF palettes and the video's input); a
    streaming encoder holds one frame at a time (a few MB for the supersampled canvas),
    whatever the count."""
    scene = _scene(tmp_path, 4, 1)
    growth = {}
    for n in (20, 200):
        out = tmp_path / f"run{n}"
        run_scene(scene, out=out, steps=n, every=1, preview=False)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
        r = subprocess.run(
            [sys.executable, "-c", PROBE, str(out)],
            capture_output=True,
            text=True,
            env=env,
            check=True,
            timeout=300,
        )
        got = json.loads(r.stdout.strip().splitlines()[-1])
        growth[n] = got["growth_kb"] * 1024
        assert got["written"]["preview"] == "preview.gif"
        with Image.open(out / "preview.gif") as gif:
            assert gif.n_frames == n + 1
        if render.ffmpeg_exe() is not None:
            assert got["written"]["video"] == "preview.mp4"
            import imageio_ffmpeg

            frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out / "preview.mp4"))
            assert frames == n + 1
    print(f"ru_maxrss growth while rendering: {growth}")
    assert growth[200] - growth[20] < 12 * 2**20, growth


def _images(n: int) -> list[Image.Image]:
    """Frames with changes in part of the picture (a moving square), two identical in a row."""
    rng = np.random.default_rng(3)
    base = rng.integers(0, 255, size=(60, 80, 3), dtype=np.uint8)
    out = []
    for k in range(n):
        a = base.copy()
        j = min(k, n - 2)  # the last two frames are identical
        a[10 + j : 20 + j, 5 + 2 * j : 25 + 2 * j] = (250, 20, 20)
        out.append(Image.fromarray(a))
    return out


def test_streamed_gif_decodes_as_pillows(tmp_path: Path) -> None:
    """The streamed GIF decodes to the same frames, durations and loop as Pillow's
    ``save(save_all=True)`` of the same quantized images (what render.py used before)."""
    images = _images(9)
    ref = tmp_path / "ref.gif"
    pal = [
        im.quantize(colors=255, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        for im in images
    ]
    ms = render._frame_ms(len(images))
    pal[0].save(ref, save_all=True, append_images=pal[1:], duration=ms, loop=0, optimize=False)
    got = tmp_path / "got.gif"
    render.save_gif(iter(images), got, count=len(images))

    def decode(p: Path) -> tuple[list[np.ndarray], list[int], Any]:
        frames, durations = [], []
        with Image.open(p) as g:
            loop = g.info.get("loop")
            for i in range(g.n_frames):
                g.seek(i)
                frames.append(np.asarray(g.convert("RGB")))
                durations.append(g.info["duration"])
        return frames, durations, loop

    f_ref, d_ref, l_ref = decode(ref)
    f_got, d_got, l_got = decode(got)
    assert len(f_got) == len(f_ref) == 8  # the identical last frame merged into the one before
    assert d_got == d_ref
    assert l_got == l_ref == 0
    for a, b in zip(f_ref, f_got):
        np.testing.assert_array_equal(a, b)


def test_streamed_and_spooled_recordings_are_the_same(tmp_path: Path) -> None:
    """A recorder writing into its run directory and one spooling to temporary files (then
    copied), following two identical simulations for 1,100 steps, write the same view.json,
    view.bin and energy.csv, byte for byte; the energies kept in memory are the last
    ENERGY_MEMORY rows of energy.csv, and every frame read back is the simulation's
    positions at that step (float32 relative to the origin: 1e-6 m on a 1 m bar)."""
    from topomech.recording import ENERGY_MEMORY

    sc = load_scene(_scene(tmp_path, 4, 1))
    a_dir, b_dir = tmp_path / "a", tmp_path / "b"
    a_dir.mkdir()
    b_dir.mkdir()
    sims = [sc.build(), sc.build()]
    recs = [Recorder(sims[0], sc, out_dir=a_dir), Recorder(sims[1], sc)]
    kept: list[np.ndarray] = []
    for sim, rec in zip(sims, recs):
        rec.start()
        rec.frame()
        for k in range(1, 1101):
            sim.step()
            rec.after_step()
            if k % 100 == 0:
                rec.frame()
                if rec is recs[0]:
                    kept.append(sim.positions())
        rec.finish()
    for rec, d in zip(recs, (a_dir, b_dir)):
        assert rec.write_view(d)
        assert rec.write_energy(d / "energy.csv")
    for name in ("view.json", "view.bin", "energy.csv"):
        assert (a_dir / name).read_bytes() == (b_dir / name).read_bytes(), name
    e = read_energy(a_dir / "energy.csv")
    assert len(e["step"]) == 1101
    for c in ("kinetic", "elastic", "total"):
        np.testing.assert_array_equal(np.array(recs[0].energy[c]), e[c][-ENERGY_MEMORY:])
    view = read_view(a_dir)
    assert len(view.frames) == 12
    for k, x in enumerate(kept, start=1):
        np.testing.assert_allclose(view.world_positions(k), x, rtol=0, atol=1e-6)
    for rec in recs:
        rec.close()


def _page_as_before(out: Path) -> str:
    """The viewer page as it was built before streaming: the template's markers replaced
    one after the other, view.bin base64-encoded whole."""
    import base64
    from importlib import resources

    web = resources.files("topomech") / "web"
    view = read_view(out)
    page = (web / "viewer.html").read_text(encoding="utf-8")
    title = str(view.meta.get("name", "run"))
    for key, value in (
        ("__TITLE__", title.replace("&", "&amp;").replace("<", "&lt;")),
        ("__META__", json.dumps(view.meta).replace("</", "<\\/")),
        ("__BIN__", base64.b64encode((out / "view.bin").read_bytes()).decode("ascii")),
        ("__LIB__", (web / "three" / "three.min.js").read_text(encoding="utf-8")),
        ("__SCRIPT__", (web / "viewer.js").read_text(encoding="utf-8")),
    ):
        page = page.replace(key, value, 1)
    return page


def test_viewer_page_is_written_piece_by_piece(tmp_path: Path) -> None:
    """write_viewer encodes view.bin a block at a time: the page is the one built whole (as
    before), and writing it for 100 frames of the 775-vertex bar takes within 0.5 MB of the
    peak for 10 frames, where building it whole held view.bin, its base64 and copies of the
    page (about 6 times view.bin's 1.1 MB more: 7.6 MB measured before)."""
    from topomech.viewer import write_viewer

    sc = load_scene(_scene(tmp_path, 30, 4, model="stretch_elementary"))
    sim = sc.build()
    peaks = {}
    for n in (2, 10, 100):  # the first one warms the caches
        out = tmp_path / f"run{n}"
        _record(sc, sim, n, out)
        peaks[n] = _peak(functools.partial(write_viewer, out))
        page = (out / "viewer.html").read_text(encoding="utf-8")
        assert page == _page_as_before(out)
    growth = peaks[100] - peaks[10]
    print(f"peaks {peaks}, growth {growth} B")
    assert growth < 500_000, peaks
