"""Headless previews of a run: ``preview.gif`` (and ``preview.mp4`` when imageio-ffmpeg's
encoder is installed) and ``energy.png``, from the view data a run writes (see
:mod:`topomech.recording`). Pillow draws the frames, matplotlib (Agg) the energy plot; nothing
needs a display.

Frames are rendered one at a time and handed to the encoders as they come (the GIF written
frame by frame with Pillow's GIF encoder, the MP4 piped to ffmpeg), and the energy plot reads
``energy.csv`` row by row into a bounded min/max envelope (:class:`EnergyEnvelope`): memory
does not grow with the number of frames or steps.

The frames are shaded polygons (both sides lit; drawn far to near), colored by a field —
von Mises stress for the continuous 3D models, displacement magnitude otherwise — on one
color scale for the whole run, seen by a fixed orthographic camera whose frame holds every
position of every frame (so nothing leaves the picture), with the simulated time and a color
bar. The camera looks from the front-right and above, "above" being against gravity.
"""

from __future__ import annotations

import csv
import math
import subprocess
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from topomech.recording import ENERGY_COLUMNS, View, read_view

if TYPE_CHECKING:
    from PIL import Image as PILImage

__all__ = [
    "ENERGY_BUCKETS",
    "Camera",
    "EnergyEnvelope",
    "GifWriter",
    "Mp4Writer",
    "colormap",
    "ffmpeg_exe",
    "plot_energy",
    "render_frame",
    "render_previews",
    "write_gif",
    "write_mp4",
]

F64 = npt.NDArray[np.float64]

#: Viridis, sampled at 9 points (the viewer uses the same table).
VIRIDIS = np.array(
    [
        [68, 1, 84],
        [71, 44, 122],
        [59, 81, 139],
        [44, 113, 142],
        [33, 144, 141],
        [39, 173, 129],
        [92, 200, 99],
        [170, 220, 50],
        [253, 231, 37],
    ],
    dtype=np.float64,
)
#: The camera's default azimuth and elevation (degrees).
AZIMUTH = 35.0
ELEVATION = 25.0
#: The longest GIF: runs with more frames are sampled evenly.
MAX_GIF_FRAMES = 300
#: The energy plot's buckets: a longer history is plotted as the min and max of each of at
#: most this many buckets of consecutive rows (at most twice as many points per curve).
ENERGY_BUCKETS = 1024


def colormap(t: F64) -> F64:
    """RGB (0-255) of values in [0, 1] (viridis; NaN as grey)."""
    t = np.asarray(t, dtype=np.float64)
    bad = ~np.isfinite(t)
    s = np.clip(np.where(bad, 0.0, t), 0.0, 1.0) * (len(VIRIDIS) - 1)
    i = np.minimum(s.astype(np.int64), len(VIRIDIS) - 2)
    f = (s - i)[..., None]
    rgb = VIRIDIS[i] * (1 - f) + VIRIDIS[i + 1] * f
    rgb[bad] = 160.0
    return np.asarray(rgb, dtype=np.float64)


@dataclass
class Camera:
    """An orthographic camera: screen axes ``right``, ``up`` and ``eye`` (towards the
    viewer), a scale (pixels per metre) and the screen point of the origin."""

    right: F64
    up: F64
    eye: F64
    scale: float = 1.0
    cx: float = 0.0
    cy: float = 0.0

    @classmethod
    def looking(cls, up: Any, azimuth: float = AZIMUTH, elevation: float = ELEVATION) -> Camera:
        """Looking from ``azimuth`` degrees right of the front and ``elevation`` above (the
        front is +z when up is along y, else -y)."""
        u = np.asarray(up, dtype=np.float64)
        u = u / np.linalg.norm(u)
        front = np.array([0.0, 0.0, 1.0]) if abs(u[1]) > 0.7 else np.array([0.0, -1.0, 0.0])
        front = front - (front @ u) * u
        front /= np.linalg.norm(front)
        side = np.cross(u, front)
        a, e = math.radians(azimuth), math.radians(elevation)
        eye = math.cos(e) * (math.cos(a) * front + math.sin(a) * side) + math.sin(e) * u
        right = np.cross(u, eye)
        right /= np.linalg.norm(right)
        upv = np.cross(eye, right)
        return cls(right, upv, eye)

    def fit(self, points: F64, width: int, height: int, margin: float = 0.06) -> None:
        """Scales and centres so that every point is inside ``width`` x ``height``."""
        self.fit_extent(self.extent(points), width, height, margin)

    def extent(self, points: F64, extent: F64 | None = None) -> F64:
        """The screen extent ``[u_min, u_max, v_min, v_max]`` (m, along :attr:`right` and
        :attr:`up`) of the finite ``points`` ``(N, 3)``, merged with ``extent`` when given
        (for points that come a frame at a time); NaNs when there is none."""
        p = points[np.isfinite(points).all(axis=1)]
        box = np.full(4, np.nan)
        if len(p):
            u, v = p @ self.right, p @ self.up
            box = np.array([u.min(), u.max(), v.min(), v.max()])
        if extent is None or np.isnan(extent[0]):
            return box
        if np.isnan(box[0]):
            return extent
        return np.array(
            [
                min(extent[0], box[0]),
                max(extent[1], box[1]),
                min(extent[2], box[2]),
                max(extent[3], box[3]),
            ]
        )

    def fit_extent(self, extent: F64, width: int, height: int, margin: float = 0.06) -> None:
        """Scales and centres so that the screen extent (see :meth:`extent`; NaNs: the
        origin) is inside ``width`` x ``height``."""
        u0, u1, v0, v1 = (0.0, 0.0, 0.0, 0.0) if np.isnan(extent[0]) else extent
        du, dv = float(u1 - u0), float(v1 - v0)
        w, h = width * (1 - 2 * margin), height * (1 - 2 * margin)
        ext = [s for s in (w / du if du > 0 else 0.0, h / dv if dv > 0 else 0.0) if s > 0]
        self.scale = min(ext) if ext else 1.0
        self.cx = width / 2 - self.scale * (u1 + u0) / 2
        self.cy = height / 2 + self.scale * (v1 + v0) / 2

    def project(self, x: F64) -> tuple[F64, F64]:
        """Screen coordinates ``(N, 2)`` (y down) and depth (larger is nearer)."""
        sx = self.cx + self.scale * (x @ self.right)
        sy = self.cy - self.scale * (x @ self.up)
        return np.stack([sx, sy], axis=1), x @ self.eye


def _font(size: int) -> Any:
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: the bitmap font
        return ImageFont.load_default()


def _field_name(view: View, field: str | None) -> str | None:
    fields = view.meta["fields"]
    name = field if field is not None else view.meta["default_field"]
    if name == "none":
        return None
    if name not in fields:
        raise ValueError(f"no field {name!r} in this run (it has {', '.join(fields)})")
    return str(name)


def _light(camera: Camera) -> F64:
    light = camera.eye + 0.5 * camera.right + 0.8 * camera.up
    return np.asarray(light / np.linalg.norm(light), dtype=np.float64)


def render_frame(
    view: View,
    k: int,
    camera: Camera,
    size: tuple[int, int],
    field: str | None = None,
    *,
    supersample: int = 2,
) -> PILImage.Image:
    """Frame ``k`` as an RGB image of ``size``; ``camera`` fitted to ``size`` minus the color
    bar (see :func:`frame_camera`)."""
    from PIL import Image, ImageDraw

    w, h = size
    ss = supersample
    img = Image.new("RGB", (w * ss, h * ss), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    x = np.asarray(view.positions(k), dtype=np.float64)
    xy, depth = camera.project(x)
    xy = xy * ss
    name = _field_name(view, field)
    if name is not None:
        meta = view.meta["fields"][name]
        span = meta["max"] - meta["min"]
        values = np.asarray(view.field(k, name), dtype=np.float64)
        t = (values - meta["min"]) / span if span > 0 else np.zeros_like(values)
    else:
        t = None
    light = _light(camera)
    faces = view.faces(k)
    # mesh lines where the faces are large enough on screen for them not to darken the picture
    first = np.array([f[:2] for f in faces if len(f) >= 2], dtype=np.int64).reshape(-1, 2)
    seg = np.linalg.norm(xy[first[:, 0]] - xy[first[:, 1]], axis=1) / ss
    outline = len(faces) <= 4000 and bool(np.nanmedian(seg) > 12) if len(seg) else False
    polys: list[tuple[float, list[tuple[float, float]], tuple[int, ...], tuple[int, ...]]] = []
    by_size: dict[int, list[int]] = {}
    for i, f in enumerate(faces):
        by_size.setdefault(len(f), []).append(i)
    for n, ids in by_size.items():
        if n < 3:
            continue
        idx = np.array([faces[i] for i in ids], dtype=np.int64)
        p = x[idx]  # (F, n, 3)
        c = p.mean(axis=1, keepdims=True)
        q = p - c
        normal = np.cross(q, np.roll(q, -1, axis=1)).sum(axis=1)
        norm = np.linalg.norm(normal, axis=1)
        ok = np.isfinite(p).all(axis=(1, 2)) & (norm > 0)
        normal = normal / np.where(norm > 0, norm, 1.0)[:, None]
        shade = 0.35 + 0.65 * np.abs(normal @ light)
        base = colormap(t[idx].mean(axis=1)) if t is not None else np.full((len(idx), 3), 190.0)
        rgb = np.clip(base * shade[:, None], 0, 255).astype(np.int64)
        edge = np.clip(rgb * 0.6, 0, 255).astype(np.int64)
        d = depth[idx].mean(axis=1)
        for j in np.flatnonzero(ok):
            pts = [(float(a), float(b)) for a, b in xy[idx[j]]]
            polys.append((float(d[j]), pts, tuple(rgb[j]), tuple(edge[j])))
    polys.sort(key=lambda p: p[0])
    for _, pts, fill, edge_rgb in polys:
        draw.polygon(pts, fill=fill, outline=edge_rgb if outline else None)
    if ss > 1:
        img = img.reduce(ss)
    _decorate(img, view, k, name)
    return img


def _decorate(img: PILImage.Image, view: View, k: int, name: str | None) -> None:
    """Title, time and color bar."""
    from PIL import ImageDraw

    draw = ImageDraw.Draw(img)
    w, h = img.size
    font = _font(max(11, h // 30))
    small = _font(max(10, h // 36))
    fr = view.frames[k]
    draw.text((10, 8), view.meta["name"], fill=(20, 20, 20), font=font)
    draw.text(
        (10, 12 + int(font.getbbox("Ag")[3])),
        f"t = {fr['time']:.4g} s   step {fr['step']}   frame {k + 1}/{len(view.frames)}",
        fill=(70, 70, 70),
        font=small,
    )
    if name is None:
        return
    meta = view.meta["fields"][name]
    bar_w, top, bottom = 14, int(h * 0.22), int(h * 0.8)
    left = w - bar_w - 66
    ramp = colormap(np.linspace(1.0, 0.0, bottom - top)).astype(np.uint8)
    for r, rgb in enumerate(ramp):
        draw.line([(left, top + r), (left + bar_w, top + r)], fill=tuple(int(c) for c in rgb))
    draw.rectangle([left, top, left + bar_w, bottom], outline=(60, 60, 60))
    unit = meta["unit"]
    draw.text((left + bar_w + 4, top - 6), f"{meta['max']:.3g}", fill=(40, 40, 40), font=small)
    draw.text((left + bar_w + 4, bottom - 8), f"{meta['min']:.3g}", fill=(40, 40, 40), font=small)
    label = f"{meta['label']} ({unit})"
    tw = draw.textlength(label, font=small)
    draw.text((w - tw - 8, top - 12 - 2 * small.size), label, fill=(40, 40, 40), font=small)


def frame_camera(view: View, size: tuple[int, int], azimuth: float = AZIMUTH) -> Camera:
    """The fixed camera of a run: fitted to every position of every frame (read one frame
    at a time), leaving room for the color bar on the right and the title on top."""
    cam = Camera.looking(view.meta["up"], azimuth=azimuth)
    w, h = size
    extent = None
    for k in range(len(view.frames)):
        extent = cam.extent(np.asarray(view.positions(k), dtype=np.float64), extent)
    bar, title = 90, max(40, h // 9)
    cam.fit_extent(extent if extent is not None else np.full(4, np.nan), w - bar, h - title)
    cam.cy += title
    return cam


def _sampled(n: int, limit: int) -> list[int]:
    if n <= limit:
        return list(range(n))
    return sorted({round(i * (n - 1) / (limit - 1)) for i in range(limit)})


def gif_frames(view: View, limit: int = MAX_GIF_FRAMES) -> list[int]:
    """The frames a GIF shows: all of them, or ``limit`` evenly sampled."""
    return _sampled(len(view.frames), limit)


def _frame_ms(n: int) -> int:
    """Per frame: about 6 s for the whole run, between 40 and 200 ms (GIF ticks are 10 ms)."""
    return int(min(200, max(40, round(6000 / max(n, 1), -1))))


def iter_frames(
    view: View,
    frames: Iterable[int] | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
) -> Iterator[PILImage.Image]:
    """Frames of the run (all by default) as RGB images, seen by its fixed camera, rendered
    one at a time as they are asked for."""
    ks = range(len(view.frames)) if frames is None else frames
    cam = frame_camera(view, size)
    for k in ks:
        yield render_frame(view, k, cam, size, field)


def render_frames(
    view: View,
    frames: list[int] | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
) -> list[PILImage.Image]:
    """Frames of the run (all by default) as RGB images, seen by its fixed camera (all in
    memory: for a few; :func:`iter_frames` renders them one at a time)."""
    return list(iter_frames(view, frames, size=size, field=field))


class GifWriter:
    """An animated, looping GIF written frame by frame: each RGB image is quantized (one
    palette of at most 255 colors per frame, no dithering) and encoded when it is appended.

    The file is what Pillow's ``save(save_all=True, loop=0, optimize=False)`` writes for the
    same quantized frames: the first frame whole with its palette as the global color table;
    each later one cropped to the box where it differs from the one before, with its own
    palette; a frame identical to the one before lengthens that one's duration. Only the
    previous frame is kept (its encoded bytes wait for the next frame, which may lengthen
    it). ``duration``: milliseconds per frame. Raises :class:`OSError` when the file cannot
    be written."""

    def __init__(self, path: Path, duration: int) -> None:
        self.path = Path(path)
        self.duration = int(duration)
        self.frames = 0
        self._fh: IO[bytes] | None = self.path.open("wb")
        self._previous: PILImage.Image | None = None
        self._written = 0
        #: The previous frame's image, offset and duration, encoded when its duration is
        #: final (when the next different frame comes, or at :meth:`close`).
        self._held: tuple[PILImage.Image, tuple[int, int], int] | None = None

    def append(self, image: PILImage.Image) -> None:
        """Quantizes and encodes one RGB frame."""
        from PIL import GifImagePlugin, Image, ImageChops

        if self._fh is None:
            raise ValueError(f"{self.path}: the GIF is closed")
        im = image.quantize(colors=255, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        assert im.palette is not None
        im.palette.palette = bytearray(im.getpalette(None) or b"")  # as Pillow's writer does
        if self._previous is None:
            header, _ = GifImagePlugin.getheader(
                im, None, {"loop": 0, "duration": self.duration, "optimize": False}
            )
            for chunk in header:
                self._fh.write(chunk)
            self._held = (im, (0, 0), self.duration)
            self._previous = im
            self.frames = 1
            return
        prev = self._previous
        a, b = prev, im
        if bytes(prev.palette.palette if prev.palette else b"") != bytes(im.palette.palette):
            a, b = prev.convert("RGBA"), im.convert("RGBA")
        bbox = ImageChops.subtract_modulo(b, a).getbbox(alpha_only=False)
        assert self._held is not None
        if not bbox:  # identical: the previous frame lasts longer
            held, offset, ms = self._held
            self._held = (held, offset, ms + self.duration)
            return
        self._flush_held()
        crop = im if bbox == (0, 0, *im.size) else im.crop(bbox)
        self._held = (crop, (bbox[0], bbox[1]), self.duration)
        self._previous = im
        self.frames += 1

    def _flush_held(self) -> None:
        from PIL import GifImagePlugin

        if self._held is None or self._fh is None:
            return
        im, offset, ms = self._held
        params: dict[str, Any] = {"duration": ms, "loop": 0, "optimize": False}
        if self._written:  # the first frame's palette is the global one
            params["include_color_table"] = True
        for chunk in GifImagePlugin.getdata(im, offset, **params):
            self._fh.write(chunk)
        self._held = None
        self._written += 1

    def close(self) -> int:
        """Writes the last frame and the trailer; returns the number of frames written."""
        if self._fh is None:
            return self.frames
        try:
            self._flush_held()
            self._fh.write(b";")
        finally:
            self._fh.close()
            self._fh = None
        return self.frames

    def abort(self) -> None:
        """Closes and removes the unfinished file."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        self.path.unlink(missing_ok=True)


def save_gif(images: Iterable[PILImage.Image], path: Path, *, count: int | None = None) -> int:
    """An animated, looping GIF of the images (an iterable: they are encoded as they come),
    one palette each; ``count`` (the number of images, for the frame duration: about 6 s in
    all) defaults to ``len(images)``. Returns the number of frames written."""
    n = count if count is not None else len(images)  # type: ignore[arg-type]
    gif = GifWriter(Path(path), _frame_ms(n))
    try:
        for im in images:
            gif.append(im)
    except BaseException:
        gif.abort()
        raise
    return gif.close()


def write_gif(
    view: View,
    path: Path,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
    limit: int = MAX_GIF_FRAMES,
) -> int:
    """Writes an animated GIF of the run (looping), frame by frame; returns its number of
    frames."""
    ks = gif_frames(view, limit)
    save_gif(iter_frames(view, ks, size=size, field=field), path, count=len(ks))
    return len(ks)


def ffmpeg_exe() -> str | None:
    """The ffmpeg of the imageio-ffmpeg package, or None when it is not installed."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    try:
        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except RuntimeError:
        return None


#: The encoders tried, in order: H.264 where ffmpeg has it, else MPEG-4 part 2.
_CODECS = (["libx264", "-pix_fmt", "yuv420p"], ["mpeg4", "-q:v", "3"])


class Mp4Writer:
    """An MP4 encoded by ffmpeg as frames are appended (raw RGB piped to its input, one
    frame at a time). :attr:`failed` once the encoder has stopped (missing codec, full
    disk); :meth:`close` says whether the file is complete, and removes it otherwise."""

    def __init__(
        self, path: Path, size: tuple[int, int], fps: int, exe: str, codec: list[str]
    ) -> None:
        self.path = Path(path)
        self.size = size
        self.failed = False
        w, h = size
        cmd = [
            exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
            "-s", f"{w}x{h}", "-r", str(fps), "-i", "-", "-an", "-c:v", *codec,
            "-movflags", "+faststart", str(self.path),
        ]  # fmt: skip
        self._proc: subprocess.Popen[bytes] | None
        try:
            self._proc = subprocess.Popen(
                cmd,
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        except OSError:
            self._proc = None
            self.failed = True

    def append(self, image: PILImage.Image) -> bool:
        """Sends one frame (of :attr:`size`) to the encoder; False once it has failed."""
        if self.failed or self._proc is None or self._proc.stdin is None:
            return False
        if image.size != self.size:
            raise ValueError(f"a frame of {image.size}, the video is {self.size}")
        try:
            self._proc.stdin.write(image.convert("RGB").tobytes())
        except (BrokenPipeError, OSError):
            self.failed = True
        return not self.failed

    def close(self, timeout: float = 600) -> bool:
        """Ends the input and waits for the encoder; True when the file is written."""
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                if proc.stdin is not None:
                    proc.stdin.close()
            except OSError:
                self.failed = True
            try:
                if proc.wait(timeout=timeout) != 0:
                    self.failed = True
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                self.failed = True
        ok = not self.failed and self.path.is_file() and self.path.stat().st_size > 0
        if not ok:
            self.failed = True
            self.path.unlink(missing_ok=True)
        return ok


def _encode_mp4(
    frames: Callable[[], Iterable[PILImage.Image]],
    path: Path,
    size: tuple[int, int],
    count: int,
    exe: str,
    codecs: Iterable[list[str]] = _CODECS,
) -> bool:
    """Tries each codec on the frames ``frames()`` yields (rendered again for each try)."""
    fps = max(1, round(1000 / _frame_ms(count)))
    for codec in codecs:
        mp4 = Mp4Writer(path, size, fps, exe, codec)
        try:
            for im in frames():
                if not mp4.append(im):
                    break
        finally:
            ok = mp4.close()
        if ok:
            return True
    path.unlink(missing_ok=True)
    return False


def save_mp4(
    images: Iterable[PILImage.Image],
    path: Path,
    exe: str | None = None,
    *,
    count: int | None = None,
) -> bool:
    """An H.264 MP4 of the images (their size a multiple of 16) with imageio-ffmpeg's
    encoder, each frame piped to it as it comes; False when there is no encoder or it fails
    (nothing is left behind then). A list of images can be encoded again with the fallback
    codec; an iterator only once. ``count`` (for the frame rate: about 6 s in all) defaults
    to ``len(images)``."""
    exe = exe or ffmpeg_exe()
    if exe is None:
        return False
    reusable = isinstance(images, (list, tuple))
    it = iter(images)
    first = next(it, None)
    if first is None:
        return False
    n = count if count is not None else len(images)  # type: ignore[arg-type]

    def frames() -> Iterable[PILImage.Image]:
        if reusable:
            return images
        return _chain_first(first, it)

    return _encode_mp4(frames, Path(path), first.size, n, exe, _CODECS if reusable else _CODECS[:1])


def _chain_first(first: PILImage.Image, rest: Iterator[PILImage.Image]) -> Iterator[PILImage.Image]:
    yield first
    yield from rest


def write_mp4(
    view: View,
    path: Path,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
) -> bool:
    """Writes an MP4 of every frame, rendered and encoded one at a time (see
    :class:`Mp4Writer`)."""
    exe = ffmpeg_exe()
    if exe is None:
        return False
    w, h = (size[0] // 16) * 16, (size[1] // 16) * 16
    n = len(view.frames)
    return _encode_mp4(
        lambda: iter_frames(view, size=(w, h), field=field), Path(path), (w, h), n, exe
    )


class EnergyEnvelope:
    """A bounded history of energies for plotting: the rows (time and one value per column)
    are kept in at most :data:`ENERGY_BUCKETS` buckets of consecutive rows, each holding the
    min and the max of every column with their times (the earliest on ties; NaNs are left
    out). Buckets start one row wide; when they are all used, neighbours are merged two by
    two (the width doubles), so that a long history keeps every spike (the extreme of its
    bucket) and at most ``2 * ENERGY_BUCKETS`` points per column, whatever its length.
    Raises :class:`ValueError` for an odd or too small ``buckets``."""

    def __init__(self, buckets: int = ENERGY_BUCKETS) -> None:
        if buckets < 2 or buckets % 2:
            raise ValueError(f"buckets must be an even number >= 2, got {buckets}")
        self.buckets = buckets
        #: Rows per bucket (a power of two).
        self.width = 1
        #: Rows added.
        self.rows = 0
        self._cols: dict[str, F64] = {}  # name -> (buckets, 4): t_min, v_min, t_max, v_max

    def add(self, time: float, values: dict[str, float]) -> None:
        """Adds one row."""
        self.add_rows(np.array([time]), {k: np.array([v]) for k, v in values.items()})

    def add_rows(self, times: F64, values: dict[str, F64]) -> None:
        """Adds rows: ``times`` ``(R,)`` and, per column, its values ``(R,)``."""
        times = np.asarray(times, dtype=np.float64)
        done = 0
        while done < len(times):
            room = self.buckets * self.width - self.rows
            if room == 0:
                self._merge()
                continue
            m = min(room, len(times) - done)
            part = slice(done, done + m)
            for name, v in values.items():
                self._add_part(name, times[part], np.asarray(v, dtype=np.float64)[part])
            self.rows += m
            done += m

    def _add_part(self, name: str, t: F64, v: F64) -> None:
        a = self._cols.get(name)
        if a is None:
            a = self._cols[name] = np.full((self.buckets, 4), np.nan)
        idx = (self.rows + np.arange(len(t))) // self.width
        starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
        gid = np.cumsum(np.r_[False, idx[1:] != idx[:-1]])
        pos = np.arange(len(t))
        far = len(t)
        with np.errstate(invalid="ignore"):
            lo = np.fmin.reduceat(v, starts)
            hi = np.fmax.reduceat(v, starts)
            i_lo = np.minimum.reduceat(np.where(v == lo[gid], pos, far), starts)
            i_hi = np.minimum.reduceat(np.where(v == hi[gid], pos, far), starts)
        new = np.full((len(starts), 4), np.nan)
        ok = i_lo < far
        new[ok, 0], new[ok, 1] = t[i_lo[ok]], lo[ok]
        ok = i_hi < far
        new[ok, 2], new[ok, 3] = t[i_hi[ok]], hi[ok]
        b = idx[starts]
        old = a[b]
        # a bucket begun by earlier rows keeps its extremes unless the new rows pass them
        take = np.isnan(old[:, 1]) | (new[:, 1] < old[:, 1])
        old[take, 0:2] = new[take, 0:2]
        take = np.isnan(old[:, 3]) | (new[:, 3] > old[:, 3])
        old[take, 2:4] = new[take, 2:4]
        a[b] = old

    def _merge(self) -> None:
        half = self.buckets // 2
        for name, a in self._cols.items():
            first, second = a[0::2], a[1::2]
            m = np.full_like(a, np.nan)
            take = np.isnan(first[:, 1]) | (second[:, 1] < first[:, 1])
            m[:half, 0:2] = np.where(take[:, None], second[:, 0:2], first[:, 0:2])
            take = np.isnan(first[:, 3]) | (second[:, 3] > first[:, 3])
            m[:half, 2:4] = np.where(take[:, None], second[:, 2:4], first[:, 2:4])
            self._cols[name] = m
        self.width *= 2

    def series(self, name: str) -> tuple[F64, F64]:
        """Times and values to plot for column ``name``: each bucket's min and max in time
        order (one point where they are the same row)."""
        a = self._cols.get(name)
        if a is None:
            return np.zeros(0), np.zeros(0)
        used = -(-self.rows // self.width)
        a = a[:used]
        a = a[~np.isnan(a[:, 1])]
        first_min = a[:, 0] <= a[:, 2]
        t1 = np.where(first_min, a[:, 0], a[:, 2])
        v1 = np.where(first_min, a[:, 1], a[:, 3])
        t2 = np.where(first_min, a[:, 2], a[:, 0])
        v2 = np.where(first_min, a[:, 3], a[:, 1])
        t = np.stack([t1, t2], axis=1).ravel()
        v = np.stack([v1, v2], axis=1).ravel()
        same = np.zeros(len(t), dtype=bool)
        same[1::2] = (t1 == t2) & (v1 == v2)
        return t[~same], v[~same]


#: Rows of energy.csv converted at a time.
_ROWS = 1024


def energy_envelope(csv_path: Path, buckets: int = ENERGY_BUCKETS) -> EnergyEnvelope:
    """``energy.csv`` read in blocks of rows into an :class:`EnergyEnvelope`; raises
    :class:`ValueError` naming the line of a row that is not numbers."""
    env = EnergyEnvelope(buckets)
    with Path(csv_path).open(encoding="utf-8", newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None or "time" not in header:
            raise ValueError(f"{csv_path}: no header with a time column")
        cols = [header.index("time")]
        names = [h for h in header if h in ENERGY_COLUMNS and h not in ("step", "time")]
        cols += [header.index(h) for h in names]
        block: list[list[float]] = []

        def flush() -> None:
            if block:
                a = np.array(block, dtype=np.float64)
                env.add_rows(a[:, 0], {h: a[:, 1 + i] for i, h in enumerate(names)})
                block.clear()

        for row in reader:
            try:
                block.append([float(row[i]) for i in cols])
            except (ValueError, IndexError):
                raise ValueError(
                    f"{csv_path}:{reader.line_num}: not a row of numbers: {row!r}"
                ) from None
            if len(block) == _ROWS:
                flush()
        flush()
    return env


def plot_energy(
    csv_path: Path,
    png_path: Path,
    *,
    title: str = "",
    events: list[dict[str, Any]] | None = None,
) -> None:
    """Plots ``energy.csv``: kinetic, gravitational (when there is gravity), elastic and
    total energy over time, topology changes marked. The file is read row by row into an
    :class:`EnergyEnvelope`: a history longer than :data:`ENERGY_BUCKETS` rows is drawn as
    each bucket's min and max, so spikes stay visible and memory stays bounded."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    env = energy_envelope(csv_path)
    fig = Figure(figsize=(7.2, 4.0), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(*env.series("kinetic"), label="kinetic", color="#d62728")
    ax.plot(*env.series("elastic"), label="elastic", color="#1f77b4")
    tg, g = env.series("gravitational")
    if np.any(g != 0):
        ax.plot(tg, g, label="gravitational", color="#2ca02c")
    ax.plot(*env.series("total"), label="total", color="black", linewidth=2)
    for i, c in enumerate(events or []):
        ax.axvline(
            c["time"],
            color="grey",
            linestyle=":",
            label=f"{c['kind']}" if i == 0 else None,
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy (J)")
    ax.set_title(f"{title}: energy" if title else "energy")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    fig.savefig(png_path)


def render_previews(
    out_dir: Path,
    *,
    video: bool = True,
    size: tuple[int, int] = (640, 480),
    name: str | None = None,
    events: list[dict[str, Any]] | None = None,
) -> dict[str, str | None]:
    """Writes ``preview.gif`` (when the run has frames), ``preview.mp4`` (when ``video`` and
    an encoder is installed) and ``energy.png`` (when it has ``energy.csv``) in a run's
    directory; returns the files written, by kind (None for those not written). ``name`` and
    ``events`` (the topology changes) title and mark the energy plot.

    The frames are rendered once each, in order, and handed to both encoders as they come
    (the GIF takes at most :data:`MAX_GIF_FRAMES` of them, evenly sampled): one frame is in
    memory at a time, whatever the run's length. Raises :class:`ViewError` for unreadable
    view data and :class:`OSError` when a file cannot be written."""
    out_dir = Path(out_dir)
    written: dict[str, str | None] = {"preview": None, "video": None, "energy_plot": None}
    if (out_dir / "view.json").is_file():
        view = read_view(out_dir)
        name = name if name is not None else str(view.meta["name"])
        events = events if events is not None else list(view.meta.get("events", []))
        size = ((size[0] // 16) * 16, (size[1] // 16) * 16)  # for the video's encoder
        n = len(view.frames)
        ks = gif_frames(view)
        in_gif = set(ks)
        exe = ffmpeg_exe() if video else None
        gif = GifWriter(out_dir / "preview.gif", _frame_ms(len(ks)))
        mp4 = (
            Mp4Writer(
                out_dir / "preview.mp4", size, max(1, round(1000 / _frame_ms(n))), exe, _CODECS[0]
            )
            if exe is not None
            else None
        )
        try:
            frames = range(n) if mp4 is not None else ks
            for k, im in zip(frames, iter_frames(view, frames, size=size)):
                if k in in_gif:
                    gif.append(im)
                if mp4 is not None:
                    mp4.append(im)
        except BaseException:
            gif.abort()
            if mp4 is not None:
                mp4.failed = True
                mp4.close()
            raise
        gif.close()
        written["preview"] = "preview.gif"
        if mp4 is not None and exe is not None:
            ok = mp4.close()
            if not ok:  # H.264 missing from this ffmpeg: the next codec, frames rendered again
                ok = _encode_mp4(
                    lambda: iter_frames(view, size=size),
                    out_dir / "preview.mp4",
                    size,
                    n,
                    exe,
                    _CODECS[1:],
                )
            if ok:
                written["video"] = "preview.mp4"
    if (out_dir / "energy.csv").is_file():
        plot_energy(out_dir / "energy.csv", out_dir / "energy.png", title=name or "", events=events)
        written["energy_plot"] = "energy.png"
    return written
