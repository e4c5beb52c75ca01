"""Headless previews of a run: ``preview.gif`` (and ``preview.mp4`` when imageio-ffmpeg's
encoder is installed) and ``energy.png``, from the view data a run writes (see
:mod:`topomech.recording`), after the steps. Pillow draws the frames and the energy plot;
nothing needs a display.

Frames are rendered one at a time and handed to the encoders as they come (the GIF written
frame by frame with Pillow's GIF encoder, the MP4 piped to ffmpeg, which encodes it in a
process of its own while the next frames are drawn), and the energy plot reads
``energy.csv`` row by row into a bounded min/max envelope (:class:`EnergyEnvelope`): memory
does not grow with the number of frames or steps.

The frames are shaded polygons (both sides lit; drawn far to near), colored by a field —
von Mises stress for the continuous 3D models, displacement magnitude otherwise — on one
color scale for the whole run, seen by a fixed orthographic camera whose frame holds every
position of every frame (so nothing leaves the picture), with the simulated time and a color
bar. The camera looks from the front-right and above, "above" being against gravity.

Previews cost less than the steps of most runs (``make bench-previews`` measures it for the
shipped scenes): a :class:`FrameRenderer` prepares once what the frames share (each
topology's polygons, the color bar, the title) and draws each frame straight into a palette
image (:data:`PALETTE`: :data:`FIELD_LEVELS` colors of the field times
:data:`SHADE_LEVELS` shades), which is a GIF frame as it is (no quantizing, no
supersampling); the energy plot is drawn with Pillow too (:func:`line_plot`: importing
matplotlib alone took longer than most shipped scenes' steps).
"""

from __future__ import annotations

import csv
import functools
import math
import os
import queue
import subprocess
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
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
    "FIELD_LEVELS",
    "PALETTE",
    "SHADE_LEVELS",
    "Camera",
    "Curve",
    "EnergyEnvelope",
    "FrameRenderer",
    "GifWriter",
    "Mp4Writer",
    "colormap",
    "ffmpeg_exe",
    "line_plot",
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
#: Frames waiting for the MP4 encoder at most (each ``width * height * 3`` bytes once sent).
MP4_QUEUE = 3
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


@functools.cache
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


# ------------------------------------------------------------------------------ frames
#
# Frames are drawn straight into a palette ("P") image: a face's color is one of FIELD_LEVELS
# field colors times one of SHADE_LEVELS shades, so that no frame needs quantizing for the GIF
# (what took most of the time, with supersampling, before). Text is anti-aliased on a ramp of
# ink levels blended with the white background.

#: The field's color levels of the frames' palette (viridis, sampled evenly).
FIELD_LEVELS = 24
#: The shade levels (from 0.35, the darkest side, to 1, lit face on).
SHADE_LEVELS = 9
_SHADES = 0.35 + 0.65 * np.arange(SHADE_LEVELS) / (SHADE_LEVELS - 1)
_INK_RGB = np.array([30.0, 30.0, 30.0])
#: Palette indices: the background, the ink ramp (4 levels, the last one full), the color
#: bar's frame, the plain (no field) and NaN greys times the shades, the field colors times
#: the shades.
_WHITE, _INK, _BAR_EDGE = 0, 1, 5
_GREY = 6
_NAN = _GREY + SHADE_LEVELS
_FIELD = _NAN + SHADE_LEVELS


def _palette() -> npt.NDArray[np.uint8]:
    white = np.array([255.0, 255.0, 255.0])
    rows = [white]
    rows += [white + (_INK_RGB - white) * (i / 4) for i in (1, 2, 3, 4)]
    rows.append(np.array([60.0, 60.0, 60.0]))
    rows += [np.full(3, 190.0) * s for s in _SHADES]
    rows += [np.full(3, 160.0) * s for s in _SHADES]
    for rgb in colormap(np.linspace(0.0, 1.0, FIELD_LEVELS)):
        rows += [rgb * s for s in _SHADES]
    pal: npt.NDArray[np.uint8] = np.clip(np.rint(np.array(rows)), 0, 255).astype(np.uint8)
    assert len(pal) <= 256
    return pal


#: The frames' palette ``(C, 3)``, C <= 256.
PALETTE = _palette()
_PALETTE_BYTES = PALETTE.tobytes()


def _shade_level(shade: F64) -> npt.NDArray[np.int64]:
    j = np.rint((shade - _SHADES[0]) / (1.0 - _SHADES[0]) * (SHADE_LEVELS - 1))
    out: npt.NDArray[np.int64] = np.clip(np.nan_to_num(j), 0, SHADE_LEVELS - 1).astype(np.int64)
    return out


def _indexed(a: npt.NDArray[np.uint8]) -> PILImage.Image:
    """A palette image of the indices ``a`` ``(H, W)``, with :data:`PALETTE`."""
    from PIL import Image

    im = Image.fromarray(a, "P")
    im.putpalette(_PALETTE_BYTES)
    return im


@dataclass
class _Patch:
    """Anti-aliased ink (or solid palette colors) at a place: ``levels`` ``(h, w)`` are
    palette indices, 0 where the picture shows through."""

    x: int
    y: int
    levels: npt.NDArray[np.uint8]

    def apply(self, a: npt.NDArray[np.uint8]) -> None:
        h, w = a.shape[:2]
        x0, y0 = max(self.x, 0), max(self.y, 0)
        x1 = min(self.x + self.levels.shape[1], w)
        y1 = min(self.y + self.levels.shape[0], h)
        if x1 <= x0 or y1 <= y0:
            return
        p = self.levels[y0 - self.y : y1 - self.y, x0 - self.x : x1 - self.x]
        region = a[y0:y1, x0:x1]
        np.copyto(region, p, where=p > 0)


def _text_patch(x: int, y: int, text: str, font: Any) -> _Patch:
    """``text`` drawn at ``(x, y)`` (its top left, as ``ImageDraw.text`` places it) in ink."""
    from PIL import Image, ImageDraw

    box = font.getbbox(text)
    w, h = max(int(box[2]), 1), max(int(box[3]), 1)
    mask = Image.new("L", (w, h), 0)
    ImageDraw.Draw(mask).text((0, 0), text, fill=255, font=font)
    m = np.asarray(mask, dtype=np.int64)
    level = (m * 4 + 127) // 255  # 0 (nothing) .. 4 (full ink)
    idx = np.where(level > 0, _INK + level - 1, 0).astype(np.uint8)
    return _Patch(x, y, idx)


@functools.cache
def _glyph(font: Any, ch: str) -> tuple[float, npt.NDArray[np.uint8]]:
    """The advance and coverage mask ``(h, w)`` of one character (for text that changes
    from frame to frame: drawn once per character, not once per frame)."""
    from PIL import Image, ImageDraw

    ascent, descent = font.getmetrics()
    advance = float(font.getlength(ch))
    box = font.getbbox(ch)
    mask = Image.new("L", (max(math.ceil(max(advance, box[2])) + 1, 1), ascent + descent), 0)
    ImageDraw.Draw(mask).text((0, 0), ch, fill=255, font=font)
    return advance, np.asarray(mask, dtype=np.uint8)


def _line_patch(x: int, y: int, text: str, font: Any) -> _Patch:
    """Like :func:`_text_patch`, set from cached glyphs (without kerning)."""
    glyphs = [_glyph(font, ch) for ch in text]
    width = math.ceil(sum(a for a, _ in glyphs)) + 4
    height = max((m.shape[0] for _, m in glyphs), default=1)
    cover = np.zeros((height, width), dtype=np.uint8)
    pos = 0.0
    for advance, m in glyphs:
        x0 = round(pos)
        w = min(m.shape[1], width - x0)
        np.maximum(cover[: m.shape[0], x0 : x0 + w], m[:, :w], out=cover[: m.shape[0], x0 : x0 + w])
        pos += advance
    level = (cover.astype(np.int64) * 4 + 127) // 255
    return _Patch(x, y, np.where(level > 0, _INK + level - 1, 0).astype(np.uint8))


class FrameRenderer:
    """Renders a run's frames, seen by one camera, in a palette image each
    (:meth:`indexed`, :data:`PALETTE`) or RGB (:meth:`rgb`): what stays the same from frame
    to frame (the faces of each topology, the color bar, the title) is prepared once.

    ``supersample`` > 1 draws the faces that many times larger and averages them down in
    RGB (smoother edges; :meth:`indexed` then needs ``supersample`` 1)."""

    def __init__(
        self,
        view: View,
        camera: Camera,
        size: tuple[int, int],
        field: str | None = None,
        *,
        supersample: int = 1,
    ) -> None:
        self.view = view
        self.camera = camera
        self.size = (int(size[0]), int(size[1]))
        self.supersample = max(1, int(supersample))
        self.name = _field_name(view, field)
        self.light = _light(camera)
        self._groups: dict[int, list[npt.NDArray[np.int64]]] = {}
        h = self.size[1]
        self._font = _font(max(11, h // 30))
        self._small = _font(max(10, h // 36))
        self._static = [_text_patch(10, 8, str(view.meta["name"]), self._font)]
        self._time_y = 12 + int(self._font.getbbox("Ag")[3])
        if self.name is not None:
            self._static += self._color_bar()

    def _color_bar(self) -> list[_Patch]:
        assert self.name is not None
        meta = self.view.meta["fields"][self.name]
        w, h = self.size
        small = self._small
        bar_w, top, bottom = 14, int(h * 0.22), int(h * 0.8)
        left = w - bar_w - 66
        rows = bottom - top + 1
        t = np.linspace(1.0, 0.0, rows)
        level = np.rint(t * (FIELD_LEVELS - 1)).astype(np.int64)
        bar = np.empty((rows, bar_w + 1), dtype=np.uint8)
        bar[:] = (_FIELD + level * SHADE_LEVELS + SHADE_LEVELS - 1).astype(np.uint8)[:, None]
        bar[0, :] = bar[-1, :] = bar[:, 0] = bar[:, -1] = _BAR_EDGE
        patches = [_Patch(left, top, bar)]
        patches.append(_text_patch(left + bar_w + 4, top - 6, f"{meta['max']:.3g}", small))
        patches.append(_text_patch(left + bar_w + 4, bottom - 8, f"{meta['min']:.3g}", small))
        label = f"{meta['label']} ({meta['unit']})"
        tw = math.ceil(small.getlength(label))
        patches.append(_text_patch(w - tw - 8, top - 12 - 2 * int(small.size), label, small))
        return patches

    def _faces(self, k: int) -> list[npt.NDArray[np.int64]]:
        """Frame ``k``'s polygons as one ``(F, n)`` array of vertex rows per size ``n``."""
        topo = int(self.view.frames[k]["topology"])
        groups = self._groups.get(topo)
        if groups is None:
            t = self.view.topology(k)
            off = np.asarray(self.view.array(t["face_offsets"]), dtype=np.int64)
            idx = np.asarray(self.view.array(t["face_indices"]), dtype=np.int64)
            sizes = np.diff(off)
            groups = []
            for n in np.unique(sizes):
                if n < 3:
                    continue
                rows = off[:-1][sizes == n]
                groups.append(idx[rows[:, None] + np.arange(n)])
            self._groups = {topo: groups}  # topologies come in order: keep the current one
        return groups

    def _draw_faces(self, k: int, ss: int) -> PILImage.Image:
        from PIL import Image, ImageDraw

        w, h = self.size
        img = Image.new("P", (w * ss, h * ss), _WHITE)
        draw = ImageDraw.Draw(img)
        x = np.asarray(self.view.positions(k), dtype=np.float64)
        xy, depth = self.camera.project(x)
        if ss > 1:
            xy = xy * ss
        t: F64 | None = None
        if self.name is not None:
            meta = self.view.meta["fields"][self.name]
            span = meta["max"] - meta["min"]
            values = np.asarray(self.view.field(k, self.name), dtype=np.float64)
            t = (values - meta["min"]) / span if span > 0 else np.zeros_like(values)
        groups = self._faces(k)
        # mesh lines where the faces are large enough on screen not to darken the picture
        n_faces = sum(len(g) for g in groups)
        outline = False
        if groups and n_faces <= 4000:
            # (non-finite positions, recorded for values beyond float32, give NaN lengths)
            with np.errstate(over="ignore", invalid="ignore"):
                seg = np.concatenate(
                    [np.linalg.norm(xy[g[:, 0]] - xy[g[:, 1]], axis=1) for g in groups]
                )
                outline = bool(np.nanmedian(seg) / ss > 12) if np.isfinite(seg).any() else False
        coords: list[list[float]] = []
        fills: list[int] = []
        edges: list[int] = []
        depths: list[F64] = []
        for idx in groups:
            p = x[idx]  # (F, n, 3)
            # faces with a non-finite vertex get NaN normals here, and are left out by ok
            with np.errstate(over="ignore", invalid="ignore"):
                q = p - p.mean(axis=1, keepdims=True)
                normal = np.cross(q, np.roll(q, -1, axis=1)).sum(axis=1)
                norm = np.linalg.norm(normal, axis=1)
            ok = np.isfinite(p).all(axis=(1, 2)) & (norm > 0)
            if not ok.any():
                continue
            idx, normal, norm = idx[ok], normal[ok], norm[ok]
            shade = 0.35 + 0.65 * np.abs((normal / norm[:, None]) @ self.light)
            j = _shade_level(shade)
            jo = _shade_level(0.6 * shade)
            if t is None:
                fill, edge = _GREY + j, _GREY + jo
            else:
                with np.errstate(invalid="ignore"):
                    tm = t[idx].mean(axis=1)
                bad = ~np.isfinite(tm)
                level = np.clip(np.rint(np.where(bad, 0.0, tm) * (FIELD_LEVELS - 1)), 0, None)
                level = np.minimum(level, FIELD_LEVELS - 1).astype(np.int64)
                base = _FIELD + level * SHADE_LEVELS
                fill = np.where(bad, _NAN + j, base + j)
                edge = np.where(bad, _NAN + jo, base + jo)
            coords += xy[idx].reshape(len(idx), -1).tolist()
            fills += fill.tolist()
            edges += edge.tolist()
            depths.append(depth[idx].mean(axis=1))
        if coords:
            order = np.argsort(np.concatenate(depths), kind="stable").tolist()  # far to near
            # ImageDraw.polygon's own drawing call (in a palette image, a color is its index),
            # without the argument checks that cost more than the drawing of a small polygon
            core = getattr(draw, "draw", None)
            polygon = getattr(core, "draw_polygon", None)
            if polygon is None:  # pragma: no cover - another Pillow
                for i in order:
                    draw.polygon(coords[i], fill=fills[i], outline=edges[i] if outline else None)
            elif outline:
                for i in order:
                    polygon(coords[i], fills[i], 1)
                    polygon(coords[i], edges[i], 0, 1)
            else:
                for i in order:
                    polygon(coords[i], fills[i], 1)
        return img

    def _decorate(self, a: npt.NDArray[np.uint8], k: int) -> None:
        fr = self.view.frames[k]
        line = f"t = {fr['time']:.4g} s   step {fr['step']}   frame {k + 1}/{len(self.view.frames)}"
        for p in (*self._static, _line_patch(10, self._time_y, line, self._small)):
            p.apply(a)

    def indexed(self, k: int) -> PILImage.Image:
        """Frame ``k`` as a palette image (:data:`PALETTE`), without supersampling."""
        if self.supersample != 1:
            raise ValueError("palette frames are drawn without supersampling")
        a = np.array(self._draw_faces(k, 1), dtype=np.uint8)
        self._decorate(a, k)
        return _indexed(a)

    def rgb(self, k: int) -> PILImage.Image:
        """Frame ``k`` as an RGB image."""
        from PIL import Image

        ss = self.supersample
        a = np.array(self._draw_faces(k, ss), dtype=np.uint8)
        if ss == 1:
            self._decorate(a, k)
            return Image.fromarray(PALETTE[a], "RGB")
        img = Image.fromarray(PALETTE[a], "RGB").reduce(ss)
        rgb = np.array(img, dtype=np.uint8)
        ink = np.zeros(rgb.shape[:2], dtype=np.uint8)
        self._decorate(ink, k)
        on = ink > 0
        rgb[on] = PALETTE[ink[on]]
        return Image.fromarray(rgb, "RGB")


def render_frame(
    view: View,
    k: int,
    camera: Camera,
    size: tuple[int, int],
    field: str | None = None,
    *,
    supersample: int = 1,
) -> PILImage.Image:
    """Frame ``k`` as an RGB image of ``size``; ``camera`` fitted to ``size`` minus the color
    bar (see :func:`frame_camera`). For many frames, a :class:`FrameRenderer` prepares what
    they share once."""
    return FrameRenderer(view, camera, size, field, supersample=supersample).rgb(k)


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
    supersample: int = 1,
) -> Iterator[PILImage.Image]:
    """Frames of the run (all by default) as RGB images, seen by its fixed camera, rendered
    one at a time as they are asked for."""
    ks = range(len(view.frames)) if frames is None else frames
    r = FrameRenderer(view, frame_camera(view, size), size, field, supersample=supersample)
    for k in ks:
        yield r.rgb(k)


def render_frames(
    view: View,
    frames: list[int] | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
    supersample: int = 1,
) -> list[PILImage.Image]:
    """Frames of the run (all by default) as RGB images, seen by its fixed camera (all in
    memory: for a few; :func:`iter_frames` renders them one at a time)."""
    return list(iter_frames(view, frames, size=size, field=field, supersample=supersample))


class GifWriter:
    """An animated, looping GIF written frame by frame: each RGB image is quantized (one
    palette of at most 255 colors per frame, no dithering; a palette image, such as
    :meth:`FrameRenderer.indexed` draws, is taken as it is) and encoded when it is appended.

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
        im = (
            image  # a palette image (a :class:`FrameRenderer` frame) is a GIF frame as it is
            if image.mode == "P"
            else image.quantize(
                colors=255, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
            )
        )
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
    """The ffmpeg of the imageio-ffmpeg package, or None when it is not installed. Its
    bundled binary is taken as it is (imageio-ffmpeg would run it once to check it, which
    costs as much as encoding a short preview: an encoder that does not run makes no video,
    see :class:`Mp4Writer`)."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    exe = os.environ.get("IMAGEIO_FFMPEG_EXE")
    if exe:
        return exe
    try:
        from imageio_ffmpeg import _definitions, _utils

        bundled = Path(_utils._get_bin_dir()) / _definitions.FNAME_PER_PLATFORM.get(
            _definitions.get_platform(), ""
        )
        if bundled.is_file() and os.access(bundled, os.X_OK):
            return str(bundled)
    except (ImportError, AttributeError, TypeError, OSError):  # another imageio-ffmpeg
        pass
    try:
        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except RuntimeError:
        return None


#: The encoders tried, in order: H.264 where ffmpeg has it (its fastest preset: a preview's
#: video is encoded in a few milliseconds a frame, about 2.5 times faster than the default
#: preset, for files about 2.5 times larger), else MPEG-4 part 2.
_CODECS = (
    ["libx264", "-preset", "ultrafast", "-pix_fmt", "yuv420p"],
    ["mpeg4", "-q:v", "3"],
)


def _pal8(image: PILImage.Image) -> bytes:
    """A palette image's palette as ffmpeg's ``pal8`` takes it after the indices: 256
    entries of 4 bytes, B, G, R and A (a native-endian ARGB word, little-endian)."""
    rgb = np.zeros((256, 3), dtype=np.uint8)
    pal = np.frombuffer(bytes(image.getpalette("RGB") or []), dtype=np.uint8)[: 256 * 3]
    rgb[: len(pal) // 3] = pal[: len(pal) // 3 * 3].reshape(-1, 3)
    out = np.full((256, 4), 255, dtype=np.uint8)
    out[:, 0], out[:, 1], out[:, 2] = rgb[:, 2], rgb[:, 1], rgb[:, 0]
    if sys.byteorder == "big":
        out = out[:, ::-1]
    return out.tobytes()


class Mp4Writer:
    """An MP4 encoded by ffmpeg as frames are appended (raw RGB piped to its input by a
    thread of its own, so that the next frames are drawn while ffmpeg reads; at most
    :data:`MP4_QUEUE` frames wait). With ``indexed``, the frames are palette images, sent
    as they are (ffmpeg's ``pal8``: the indices, then the palette; a third of the bytes of
    RGB, and no conversion here). :attr:`failed` once the encoder has stopped (missing
    codec, full disk); :meth:`close` says whether the file is complete, and removes it
    otherwise."""

    def __init__(
        self,
        path: Path,
        size: tuple[int, int],
        fps: int,
        exe: str,
        codec: list[str],
        *,
        indexed: bool = False,
    ) -> None:
        self.path = Path(path)
        self.size = size
        self.indexed = indexed
        self.failed = False
        w, h = size
        pix_fmt = "pal8" if indexed else "rgb24"
        cmd = [
            exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", pix_fmt,
            "-s", f"{w}x{h}", "-r", str(fps), "-i", "-", "-an", "-c:v", *codec,
            "-movflags", "+faststart", str(self.path),
        ]  # fmt: skip
        self._proc: subprocess.Popen[bytes] | None
        self._queue: queue.Queue[PILImage.Image | None] = queue.Queue(maxsize=MP4_QUEUE)
        self._thread: threading.Thread | None = None
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
            return
        self._thread = threading.Thread(target=self._feed, name="topomech-mp4", daemon=True)
        self._thread.start()

    def _feed(self) -> None:
        """The thread: frames from the queue to ffmpeg's input until None, then closes it."""
        proc = self._proc
        stdin = proc.stdin if proc is not None else None
        while True:
            image = self._queue.get()
            if image is None:
                break
            if self.failed or stdin is None:
                continue  # drained: the encoder has stopped
            try:
                if self.indexed:
                    stdin.write(image.tobytes())
                    stdin.write(_pal8(image))
                else:
                    stdin.write(image.convert("RGB").tobytes())
            except (BrokenPipeError, OSError, ValueError):
                self.failed = True
        if stdin is not None:
            try:
                stdin.close()
            except OSError:
                self.failed = True

    def append(self, image: PILImage.Image) -> bool:
        """Sends one frame (of :attr:`size`) to the encoder; False once it has failed."""
        if self.failed or self._thread is None:
            return False
        if image.size != self.size:
            raise ValueError(f"a frame of {image.size}, the video is {self.size}")
        if self.indexed and image.mode != "P":
            raise ValueError(f"a frame of mode {image.mode}, the video takes palette images")
        self._queue.put(image)
        return not self.failed

    def close(self, timeout: float = 600) -> bool:
        """Ends the input and waits for the encoder; True when the file is written."""
        proc, self._proc = self._proc, None
        thread, self._thread = self._thread, None
        if thread is not None:
            self._queue.put(None)
            thread.join()
        if proc is not None:
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


def _nice_ticks(lo: float, hi: float, target: int = 6) -> tuple[list[float], float]:
    """Ticks at multiples of 1, 2 or 5 times a power of ten inside ``[lo, hi]``, and their
    step."""
    span = hi - lo
    if not (span > 0 and math.isfinite(span)):
        return [lo], 1.0
    raw = span / max(target - 1, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next((m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw), 10 * mag)
    first = math.ceil(lo / step - 1e-9)
    ticks = []
    i = first
    while i * step <= hi + 1e-9 * step:
        ticks.append(i * step)
        i += 1
    return ticks, step


def _tick_label(v: float, step: float, scale: float) -> str:
    """``v`` as an axis shows it: divided by ``scale`` (a power of ten shown once at the top
    of the axis), with as many decimals as ``step`` needs."""
    v, step = v / scale, step / scale
    if abs(v) < step * 1e-6:
        v = 0.0
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
    if step * 10**decimals % 1 > 1e-6 and decimals < 6:  # 2.5: one more
        decimals += 1
    return f"{v:.{decimals}f}"


def _axis_scale(ticks: list[float]) -> float:
    """A power of ten to divide the tick labels by when they are very large or small."""
    top = max((abs(t) for t in ticks), default=0.0)
    if top == 0 or 1e-3 <= top < 1e5:
        return 1.0
    return float(10.0 ** math.floor(math.log10(top)))


def _limits(values: list[F64], margin: float = 0.05) -> tuple[float, float]:
    """The data range with ``margin`` of it added on each side (one unit when it is empty or
    a single value)."""
    finite = [v[np.isfinite(v)] for v in values]
    finite = [v for v in finite if len(v)]
    if not finite:
        return 0.0, 1.0
    lo = float(min(v.min() for v in finite))
    hi = float(max(v.max() for v in finite))
    if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1e-300):
        d = abs(lo) * 0.05 if lo != 0 else 1.0
        return lo - d, hi + d
    d = (hi - lo) * margin
    return lo - d, hi + d


@dataclass
class Curve:
    """One curve of :func:`line_plot`: its legend label (None: not in the legend), color,
    line width (points) and points."""

    label: str | None
    color: tuple[int, int, int]
    width: float
    t: F64
    v: F64


def _hex(color: str) -> tuple[int, int, int]:
    c = color.lstrip("#")
    return int(c[0:2], 16), int(c[2:4], 16), int(c[4:6], 16)


def line_plot(
    curves: list[Curve],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    vlines: Sequence[tuple[float, str | None]] = (),
    size: tuple[int, int] = (720, 400),
    supersample: int = 2,
) -> PILImage.Image:
    """A line plot drawn with Pillow (axes, ticks, grid, legend, dotted vertical lines at
    ``vlines``: ``(x, label)``): what matplotlib drew before, at a small part of its cost
    (importing it alone took half a second)."""
    from PIL import Image, ImageDraw

    s = max(1, int(supersample))
    w, h = size[0] * s, size[1] * s
    img = Image.new("RGB", (w, h), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    font = _font(11 * s)
    big = _font(13 * s)
    ink = (30, 30, 30)
    x0, x1 = _limits([c.t for c in curves] + [np.array([x for x, _ in vlines], dtype=float)])
    y0, y1 = _limits([c.v for c in curves])
    xt, xstep = _nice_ticks(x0, x1)
    yt, ystep = _nice_ticks(y0, y1)
    xscale, yscale = _axis_scale(xt), _axis_scale(yt)
    ylabels = [_tick_label(v, ystep, yscale) for v in yt]
    lab_w = max((font.getlength(t) for t in ylabels), default=0.0)
    line_h = font.getbbox("Ag")[3]
    left = int(12 * s + line_h + 8 * s + lab_w)
    right, top, bottom = (
        w - 14 * s,
        int(16 * s + big.getbbox("Ag")[3]),
        h - int(2 * line_h + 18 * s),
    )

    def px(x: Any) -> Any:  # data to pixels, for numbers and arrays
        return left + (np.asarray(x, dtype=np.float64) - x0) / (x1 - x0) * (right - left)

    def py(y: Any) -> Any:
        return bottom - (np.asarray(y, dtype=np.float64) - y0) / (y1 - y0) * (bottom - top)

    grid = (232, 232, 232)
    for v, text in zip(yt, ylabels):
        y = float(py(v))
        draw.line([(left, y), (right, y)], fill=grid, width=s)
        draw.line([(left - 4 * s, y), (left, y)], fill=ink, width=s)
        tw = font.getlength(text)
        draw.text((left - 6 * s - tw, y - line_h / 2), text, fill=ink, font=font)
    for v in xt:
        x = float(px(v))
        draw.line([(x, top), (x, bottom)], fill=grid, width=s)
        draw.line([(x, bottom), (x, bottom + 4 * s)], fill=ink, width=s)
        text = _tick_label(v, xstep, xscale)
        tw = font.getlength(text)
        draw.text((x - tw / 2, bottom + 6 * s), text, fill=ink, font=font)
    if yscale != 1.0:
        draw.text(
            (left, top - line_h - 2 * s), f"1e{round(math.log10(yscale))}", fill=ink, font=font
        )
    if xscale != 1.0:
        text = f"1e{round(math.log10(xscale))}"
        draw.text(
            (right - font.getlength(text), bottom + 6 * s + line_h), text, fill=ink, font=font
        )
    legend: list[tuple[str, tuple[int, int, int], float, bool]] = []
    for x, label in vlines:
        xx = float(px(x))
        dash = 3 * s
        for y in range(top, bottom, 2 * dash):
            draw.line([(xx, y), (xx, min(y + dash, bottom))], fill=(128, 128, 128), width=s)
        if label is not None:
            legend.append((label, (128, 128, 128), 1.0, True))
    for c in curves:
        ok = np.isfinite(c.t) & np.isfinite(c.v)
        if ok.sum() >= 1:
            pts = np.stack([px(c.t[ok]), py(c.v[ok])], axis=1)
            width = max(1, round(c.width * 1.4 * s))
            if len(pts) == 1:
                r = width
                x, y = pts[0]
                draw.ellipse([x - r, y - r, x + r, y + r], fill=c.color)
            else:
                # round joints only where a wide line would show notches at its corners
                joint = "curve" if width > 3 else None
                draw.line(pts.ravel().tolist(), fill=c.color, width=width, joint=joint)
        if c.label is not None:
            legend.insert(
                len(legend) - sum(1 for e in legend if e[3]), (c.label, c.color, c.width, False)
            )
    draw.rectangle([left, top, right, bottom], outline=ink, width=s)
    # the legend in the corner that hides the fewest points
    if legend:
        pad, sample = 6 * s, 22 * s
        lw = int(max(font.getlength(e[0]) for e in legend) + sample + 3 * pad)
        lh = int(len(legend) * (line_h + 4 * s) + 2 * pad)
        corners = [
            (right - lw - pad, top + pad),
            (left + pad, top + pad),
            (left + pad, bottom - lh - pad),
            (right - lw - pad, bottom - lh - pad),
        ]
        xs = np.concatenate([px(c.t) for c in curves]) if curves else np.zeros(0)
        ys = np.concatenate([py(c.v) for c in curves]) if curves else np.zeros(0)

        def hidden(corner: tuple[int, int]) -> int:
            cx, cy = corner
            inside = (xs >= cx) & (xs <= cx + lw) & (ys >= cy) & (ys <= cy + lh)
            return int(inside.sum())

        lx, ly = min(corners, key=hidden)
        lx, ly = int(lx), int(ly)
        draw.rectangle(
            [lx, ly, lx + lw, ly + lh], fill=(255, 255, 255), outline=(200, 200, 200), width=s
        )
        for i, (label, color, weight, dotted) in enumerate(legend):
            y = ly + pad + i * (line_h + 4 * s) + line_h / 2
            if dotted:
                for x in range(lx + pad, lx + pad + sample, 6 * s):
                    draw.line([(x, y), (x + 3 * s, y)], fill=color, width=s)
            else:
                draw.line(
                    [(lx + pad, y), (lx + pad + sample, y)],
                    fill=color,
                    width=max(1, round(weight * 1.4 * s)),
                )
            draw.text((lx + 2 * pad + sample, y - line_h / 2), label, fill=ink, font=font)
    tw = big.getlength(title)
    draw.text(((left + right) / 2 - tw / 2, 8 * s), title, fill=ink, font=big)
    tw = font.getlength(xlabel)
    draw.text(((left + right) / 2 - tw / 2, h - line_h - 8 * s), xlabel, fill=ink, font=font)
    lab = Image.new("RGB", (int(font.getlength(ylabel)) + 2, int(line_h) + 2 * s), (255, 255, 255))
    ImageDraw.Draw(lab).text((1, 0), ylabel, fill=ink, font=font)
    lab = lab.transpose(Image.Transpose.ROTATE_90)
    img.paste(lab, (8 * s, int((top + bottom) / 2 - lab.size[1] / 2)))
    return img.reduce(s) if s > 1 else img


def plot_energy(
    csv_path: Path,
    png_path: Path,
    *,
    title: str = "",
    events: list[dict[str, Any]] | None = None,
) -> None:
    """Plots ``energy.csv``: kinetic, gravitational (when there is gravity), elastic and
    total energy over time, topology changes marked (720 x 400 pixels, drawn by
    :func:`line_plot`). The file is read row by row into an :class:`EnergyEnvelope`: a
    history longer than :data:`ENERGY_BUCKETS` rows is drawn as each bucket's min and max,
    so spikes stay visible and memory stays bounded."""
    env = energy_envelope(csv_path)
    curves = [
        Curve("kinetic", _hex("#d62728"), 1.0, *env.series("kinetic")),
        Curve("elastic", _hex("#1f77b4"), 1.0, *env.series("elastic")),
    ]
    tg, g = env.series("gravitational")
    if np.any(g != 0):
        curves.append(Curve("gravitational", _hex("#2ca02c"), 1.0, tg, g))
    curves.append(Curve("total", (0, 0, 0), 2.0, *env.series("total")))
    vlines = [
        (float(c["time"]), str(c["kind"]) if i == 0 else None) for i, c in enumerate(events or [])
    ]
    img = line_plot(
        curves,
        title=f"{title}: energy" if title else "energy",
        xlabel="time (s)",
        ylabel="energy (J)",
        vlines=vlines,
    )
    img.save(png_path, compress_level=1)  # 4 times faster than the default level


_STOP = object()


class _InThread:
    """Calls ``work(item)`` for each item :meth:`put`, in order, in a thread of its own (at
    most ``depth`` items waiting); :meth:`close` waits for the last one and raises what
    ``work`` raised (after which the items put are dropped)."""

    def __init__(self, work: Callable[[Any], object], depth: int = 3) -> None:
        self._work = work
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="topomech-gif", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            if self._error is None:
                try:
                    self._work(item)
                except BaseException as e:  # raised in the caller's thread by close()
                    self._error = e

    def put(self, item: object) -> None:
        if self._error is not None:
            self.close()
        self._queue.put(item)

    def stop(self) -> None:
        """Waits for the thread to end (what it raised is dropped)."""
        if self._thread.is_alive():
            self._queue.put(_STOP)
            self._thread.join()

    def close(self) -> None:
        self.stop()
        if self._error is not None:
            raise self._error


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
                out_dir / "preview.mp4",
                size,
                max(1, round(1000 / _frame_ms(n))),
                exe,
                _CODECS[0],
                indexed=True,
            )
            if exe is not None
            else None
        )
        # the GIF is encoded in a thread of its own (Pillow's encoder lets go of the GIL),
        # the MP4 by ffmpeg: both while the next frames are drawn
        gif_thread = _InThread(gif.append)
        try:
            frames = range(n) if mp4 is not None else ks
            renderer = FrameRenderer(view, frame_camera(view, size), size)
            for k in frames:
                im = renderer.indexed(k)
                if k in in_gif:
                    gif_thread.put(im)
                if mp4 is not None:
                    mp4.append(im)
            gif_thread.close()
        except BaseException:
            gif_thread.stop()
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
