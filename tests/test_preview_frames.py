"""The preview renderer (topomech.render): frames drawn straight into palette images (no
quantizing), the GIF made of exactly those frames, frames that follow the mesh, the energy
plot drawn with Pillow (matplotlib is not imported). How long previews take against the
stepping is measured by ``make bench`` (bench/previews.py), not here."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from topomech import render
from topomech.recording import read_view
from topomech.run import run_scene
from topomech.scene import shipped_scenes


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Short runs of three shipped scenes: a volume (von Mises), a cut (a topology change
    between frames) and a surface (displacement)."""
    tmp = tmp_path_factory.mktemp("previews")
    out = {}
    for name, steps in (("corotational", 60), ("cube_cut", 8), ("cloth", 150)):
        d = tmp / name
        s = run_scene(shipped_scenes()[name], d, steps=steps, video=False)
        assert "error" not in s, s
        out[name] = d
    return out


def _rgb(im: Image.Image) -> np.ndarray:
    return np.asarray(im.convert("RGB"), dtype=np.int64)


@pytest.mark.parametrize("name", ["corotational", "cube_cut", "cloth"])
def test_frames_are_pictures_of_the_mesh(runs: dict[str, Path], name: str) -> None:
    view = read_view(runs[name])
    size = (640, 480)
    r = render.FrameRenderer(view, render.frame_camera(view, size), size)
    frames = [r.indexed(k) for k in range(len(view.frames))]
    for im in frames:
        assert im.mode == "P"
        assert im.size == size
        a = _rgb(im)
        assert a.std() > 20  # shaded colored faces on white
        covered = (np.abs(a - 255).sum(axis=2) > 30).mean()
        assert 0.03 < covered < 0.9, covered
        # the indexed and the RGB frame are the same picture
    np.testing.assert_array_equal(_rgb(frames[-1]), np.asarray(r.rgb(len(frames) - 1)))
    # the mesh moves (or is cut): frames differ from the first one
    assert np.abs(_rgb(frames[-1]) - _rgb(frames[0])).mean() > 0.5


def test_gif_frames_are_the_rendered_frames_exactly(runs: dict[str, Path]) -> None:
    """The GIF holds the palette frames as drawn (no quantizing: the same pixels)."""
    out = runs["corotational"]
    view = read_view(out)
    r = render.FrameRenderer(view, render.frame_camera(view, (640, 480)), (640, 480))
    with Image.open(out / "preview.gif") as gif:
        assert gif.n_frames == len(view.frames)
        for k in (0, len(view.frames) // 2, len(view.frames) - 1):
            gif.seek(k)
            np.testing.assert_array_equal(_rgb(gif), _rgb(r.indexed(k)))


def test_a_cut_opens_in_the_frames(runs: dict[str, Path]) -> None:
    """cube_cut: the frames after the cut are drawn on the new topology (more faces), and
    the picture changes where the halves part."""
    view = read_view(runs["cube_cut"])
    tops = [f["topology"] for f in view.frames]
    assert tops[0] != tops[-1]
    assert len(view.faces(len(tops) - 1)) > len(view.faces(0))
    r = render.FrameRenderer(view, render.frame_camera(view, (320, 240)), (320, 240))
    before, after = _rgb(r.indexed(0)), _rgb(r.indexed(len(tops) - 1))
    assert np.abs(before - after).max(axis=2).astype(bool).mean() > 0.01


def test_supersampled_frames_are_smoother_and_alike(runs: dict[str, Path]) -> None:
    view = read_view(runs["corotational"])
    cam = render.frame_camera(view, (320, 240))
    plain = np.asarray(render.render_frame(view, 2, cam, (320, 240)), dtype=np.int64)
    smooth = np.asarray(render.render_frame(view, 2, cam, (320, 240), supersample=2))
    assert smooth.shape == plain.shape == (240, 320, 3)
    # the same picture but for the faces' edges
    assert (np.abs(plain - smooth).max(axis=2) > 60).mean() < 0.05
    # more colors: the edges blend
    n = len(np.unique(smooth.reshape(-1, 3), axis=0))
    assert n > len(np.unique(plain.reshape(-1, 3), axis=0))
    with pytest.raises(ValueError, match="supersampling"):
        render.FrameRenderer(view, cam, (320, 240), supersample=2).indexed(0)


def test_no_field_and_nan_values_draw_grey(runs: dict[str, Path]) -> None:
    view = read_view(runs["cloth"])
    cam = render.frame_camera(view, (320, 240))
    a = np.asarray(render.render_frame(view, 1, cam, (320, 240), field="none"), dtype=np.int64)
    face = a[np.abs(a - 255).sum(axis=2) > 30]
    grey = np.abs(face - face.mean(axis=1, keepdims=True)).max(axis=1) <= 2
    assert grey.mean() > 0.95  # the faces (and the ink) are grey
    with pytest.raises(ValueError, match="no field 'nope'"):
        render.render_frame(view, 1, cam, (320, 240), field="nope")


def test_palette_is_a_gif_palette() -> None:
    assert len(render.PALETTE) <= 256
    assert tuple(render.PALETTE[0]) == (255, 255, 255)
    assert render.PALETTE.dtype == np.uint8


# ---------------------------------------------------------------------------------- energy


def test_energy_plot_is_drawn_without_matplotlib(runs: dict[str, Path], tmp_path: Path) -> None:
    """energy.png in a fresh interpreter: the plot is 720 x 400, has the curves' colors,
    and matplotlib is never imported (importing it alone took half a second)."""
    png = tmp_path / "e.png"
    probe = textwrap.dedent(
        f"""
        import json, sys
        from topomech.render import plot_energy
        plot_energy({str(runs["cloth"] / "energy.csv")!r}, {str(png)!r}, title="t",
                    events=[{{"time": 0.5, "kind": "cut"}}])
        print(json.dumps(sorted(m for m in sys.modules if m.startswith("matplotlib"))))
        """
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    r = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True
    )
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []
    with Image.open(png) as im:
        assert im.size == (720, 400)
        a = np.asarray(im.convert("RGB"), dtype=np.int64)
    colors = {(214, 39, 40): "kinetic", (0, 0, 0): "total", (44, 160, 44): "gravitational"}
    for rgb, what in colors.items():
        near = (np.abs(a - np.array(rgb)).sum(axis=2) < 40).sum()
        assert near > 50, what


def test_energy_plot_of_odd_histories(tmp_path: Path) -> None:
    """A constant history, a single row and NaNs still give a plot (no division by zero)."""
    header = "step,time,kinetic,gravitational,elastic,total\n"
    cases = {
        "constant": header + "".join(f"{i},{i * 0.1},1,0,1,2\n" for i in range(5)),
        "one": header + "0,0,0,0,0,0\n",
        "nan": header + "0,0,nan,0,1,nan\n1,0.1,2,0,1,3\n",
        "big": header + "".join(f"{i},{i * 1e-6},{i * 1e7},0,0,{i * 1e7}\n" for i in range(5)),
    }
    for name, text in cases.items():
        csv = tmp_path / f"{name}.csv"
        csv.write_text(text)
        png = tmp_path / f"{name}.png"
        render.plot_energy(csv, png, title=name)
        with Image.open(png) as im:
            assert im.size == (720, 400)
            assert np.asarray(im.convert("L")).std() > 5


@pytest.mark.parametrize(
    ("lo", "hi"), [(0.0, 1.0), (-0.6, 0.5), (0.0, 2.1e-5), (1e6, 5e7), (-3.0, -2.99)]
)
def test_ticks_are_round_and_inside(lo: float, hi: float) -> None:
    ticks, step = render._nice_ticks(lo, hi)
    assert 3 <= len(ticks) <= 11
    assert all(lo - 1e-9 * abs(step) <= t <= hi + 1e-9 * abs(step) for t in ticks)
    mantissa = step / 10 ** np.floor(np.log10(step))
    assert any(abs(mantissa - m) < 1e-9 for m in (1, 2, 2.5, 5))
    scale = render._axis_scale(ticks)
    labels = [render._tick_label(t, step, scale) for t in ticks]
    assert len(set(labels)) == len(labels)  # distinct: enough decimals


# ---------------------------------------------------------------------------------- video

FAKE_FFMPEG = """#!/bin/sh
# a stand-in ffmpeg: no H.264 ({fail_all}: no codec at all); else reads the frames and
# writes their byte count into the output file (the last argument)
for a in "$@"; do out="$a"; done
case " $* " in *" libx264 "*) exit 1;; esac
[ "{fail_all}" = yes ] && exit 1
wc -c > "$out"
"""


@pytest.mark.parametrize("fail_all", [False, True])
def test_video_falls_back_to_the_next_codec_or_to_none(
    runs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fail_all: bool
) -> None:
    """The frames go to the encoder through a thread: an encoder without H.264 gets them
    again for MPEG-4 (every frame's bytes arrive); one that fails on every codec leaves no
    file, and the GIF is written all the same."""
    exe = tmp_path / "ffmpeg"
    exe.write_text(FAKE_FFMPEG.format(fail_all="yes" if fail_all else "no"))
    exe.chmod(0o755)
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(exe))
    out = tmp_path / "run"
    s = run_scene(shipped_scenes()["cube_cut"], out, steps=4)
    assert s["outputs"]["preview"] == "preview.gif"
    n = s["frames"]
    if fail_all:
        assert s["outputs"]["video"] is None
        assert not (out / "preview.mp4").exists()
    else:
        assert s["outputs"]["video"] == "preview.mp4"
        assert int((out / "preview.mp4").read_text()) == n * 640 * 480 * 3


def test_mp4_writer_stops_when_the_encoder_dies(tmp_path: Path) -> None:
    exe = tmp_path / "ffmpeg"
    exe.write_text("#!/bin/sh\nexit 3\n")
    exe.chmod(0o755)
    w = render.Mp4Writer(tmp_path / "x.mp4", (320, 240), 10, str(exe), ["libx264"])
    frame = Image.new("RGB", (320, 240), (10, 20, 30))
    for _ in range(40):  # more than the pipe holds: the writes fail once ffmpeg has exited
        w.append(frame)
    assert w.failed
    assert w.append(frame) is False
    assert w.close() is False
    assert not (tmp_path / "x.mp4").exists()


def test_an_error_encoding_the_gif_reaches_the_caller(
    runs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The GIF is encoded in a thread: a full disk there is raised by render_previews, and
    the unfinished file is removed."""
    out = tmp_path / "run"
    shutil.copytree(runs["corotational"], out)
    (out / "preview.gif").unlink()
    calls = []
    append = render.GifWriter.append

    def failing(self: render.GifWriter, image: Image.Image) -> None:
        calls.append(1)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        append(self, image)

    monkeypatch.setattr(render.GifWriter, "append", failing)
    with pytest.raises(OSError, match="No space left"):
        render.render_previews(out, video=False)
    assert not (out / "preview.gif").exists()


@pytest.mark.skipif(render.ffmpeg_exe() is None, reason="imageio-ffmpeg is not installed")
def test_mp4_shows_the_frames(runs: dict[str, Path], tmp_path: Path) -> None:
    """The palette frames go to ffmpeg as they are (pal8): the video's frames are the
    pictures, but for H.264's loss."""
    import imageio_ffmpeg

    out = tmp_path / "run"
    shutil.copytree(runs["corotational"], out)
    written = render.render_previews(out)
    assert written["video"] == "preview.mp4"
    view = read_view(out)
    r = render.FrameRenderer(view, render.frame_camera(view, (640, 480)), (640, 480))
    gen = imageio_ffmpeg.read_frames(str(out / "preview.mp4"))
    meta = next(gen)
    assert tuple(meta["size"]) == (640, 480)
    decoded = [np.frombuffer(f, dtype=np.uint8).reshape(480, 640, 3) for f in gen]
    assert len(decoded) == len(view.frames)
    for k in (0, len(decoded) - 1):
        diff = np.abs(decoded[k].astype(np.int64) - _rgb(r.indexed(k)))
        assert diff.mean() < 4, (k, diff.mean())
