"""Headless previews of a run: ``preview.gif`` (and ``preview.mp4`` when imageio-ffmpeg's
encoder is installed) and ``energy.png``, from the view data a run writes (see
:mod:`topomech.recording`). Pillow draws the frames, matplotlib (Agg) the energy plot; nothing
needs a display.

The frames are shaded polygons (both sides lit; drawn far to near), colored by a field —
von Mises stress for the continuous 3D models, displacement magnitude otherwise — on one
color scale for the whole run, seen by a fixed orthographic camera whose frame holds every
position of every frame (so nothing leaves the picture), with the simulated time and a color
bar. The camera looks from the front-right and above, "above" being against gravity.
"""

from __future__ import annotations

import math
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from topomech.recording import View, read_energy, read_view

if TYPE_CHECKING:
    from PIL import Image as PILImage

__all__ = [
    "Camera",
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
        p = points[np.isfinite(points).all(axis=1)]
        if len(p) == 0:
            p = np.zeros((1, 3))
        u, v = p @ self.right, p @ self.up
        du, dv = float(u.max() - u.min()), float(v.max() - v.min())
        w, h = width * (1 - 2 * margin), height * (1 - 2 * margin)
        ext = [s for s in (w / du if du > 0 else 0.0, h / dv if dv > 0 else 0.0) if s > 0]
        self.scale = min(ext) if ext else 1.0
        self.cx = width / 2 - self.scale * (u.max() + u.min()) / 2
        self.cy = height / 2 + self.scale * (v.max() + v.min()) / 2

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
    """The fixed camera of a run: fitted to every position of every frame, leaving room for
    the color bar on the right and the title on top."""
    cam = Camera.looking(view.meta["up"], azimuth=azimuth)
    w, h = size
    pts = np.concatenate([np.asarray(view.positions(k)) for k in range(len(view.frames))])
    bar, title = 90, max(40, h // 9)
    cam.fit(pts.astype(np.float64), w - bar, h - title)
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


def render_frames(
    view: View,
    frames: list[int] | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
) -> list[PILImage.Image]:
    """Frames of the run (all by default) as RGB images, seen by its fixed camera."""
    ks = list(range(len(view.frames))) if frames is None else frames
    cam = frame_camera(view, size)
    return [render_frame(view, k, cam, size, field) for k in ks]


def save_gif(images: list[PILImage.Image], path: Path) -> None:
    """An animated, looping GIF of the images, one palette each."""
    from PIL import Image

    pal = [
        im.quantize(colors=255, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        for im in images
    ]
    pal[0].save(
        path,
        save_all=True,
        append_images=pal[1:],
        duration=_frame_ms(len(images)),
        loop=0,
        optimize=False,
    )


def write_gif(
    view: View,
    path: Path,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
    limit: int = MAX_GIF_FRAMES,
) -> int:
    """Writes an animated GIF of the run (looping); returns its number of frames."""
    images = render_frames(view, gif_frames(view, limit), size=size, field=field)
    save_gif(images, path)
    return len(images)


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


def save_mp4(images: list[PILImage.Image], path: Path, exe: str | None = None) -> bool:
    """An H.264 MP4 of the images (their size a multiple of 16) with imageio-ffmpeg's
    encoder; False when there is no encoder or it fails (nothing is left behind then)."""
    exe = exe or ffmpeg_exe()
    if exe is None or not images:
        return False
    w, h = images[0].size
    fps = max(1, round(1000 / _frame_ms(len(images))))
    for codec in (["libx264", "-pix_fmt", "yuv420p"], ["mpeg4", "-q:v", "3"]):
        cmd = [
            exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
            "-s", f"{w}x{h}", "-r", str(fps), "-i", "-", "-an", "-c:v", *codec,
            "-movflags", "+faststart", str(path),
        ]  # fmt: skip
        try:
            subprocess.run(
                cmd,
                input=b"".join(im.tobytes() for im in images),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                check=True,
                timeout=600,
            )
        except (OSError, subprocess.SubprocessError):
            path.unlink(missing_ok=True)
            continue
        if path.is_file() and path.stat().st_size > 0:
            return True
    path.unlink(missing_ok=True)
    return False


def write_mp4(
    view: View,
    path: Path,
    *,
    size: tuple[int, int] = (640, 480),
    field: str | None = None,
) -> bool:
    """Writes an MP4 of every frame (see :func:`save_mp4`)."""
    if ffmpeg_exe() is None:
        return False
    w, h = (size[0] // 16) * 16, (size[1] // 16) * 16
    return save_mp4(render_frames(view, size=(w, h), field=field), path)


def plot_energy(
    csv_path: Path,
    png_path: Path,
    *,
    title: str = "",
    events: list[dict[str, Any]] | None = None,
) -> None:
    """Plots ``energy.csv``: kinetic, gravitational (when there is gravity), elastic and
    total energy over time, topology changes marked."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    e = read_energy(csv_path)
    fig = Figure(figsize=(7.2, 4.0), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    t = e["time"]
    ax.plot(t, e["kinetic"], label="kinetic", color="#d62728")
    ax.plot(t, e["elastic"], label="elastic", color="#1f77b4")
    if np.any(e["gravitational"] != 0):
        ax.plot(t, e["gravitational"], label="gravitational", color="#2ca02c")
    ax.plot(t, e["total"], label="total", color="black", linewidth=2)
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
    ``events`` (the topology changes) title and mark the energy plot."""
    out_dir = Path(out_dir)
    written: dict[str, str | None] = {"preview": None, "video": None, "energy_plot": None}
    if (out_dir / "view.json").is_file():
        view = read_view(out_dir)
        name = name if name is not None else str(view.meta["name"])
        events = events if events is not None else list(view.meta.get("events", []))
        size = ((size[0] // 16) * 16, (size[1] // 16) * 16)  # for the video's encoder
        ks = gif_frames(view)
        images = render_frames(view, ks, size=size)
        save_gif(images, out_dir / "preview.gif")
        written["preview"] = "preview.gif"
        if video and ffmpeg_exe() is not None:
            if len(ks) != len(view.frames):
                images = render_frames(view, size=size)
            if save_mp4(images, out_dir / "preview.mp4"):
                written["video"] = "preview.mp4"
    if (out_dir / "energy.csv").is_file():
        plot_energy(out_dir / "energy.csv", out_dir / "energy.png", title=name or "", events=events)
        written["energy_plot"] = "energy.png"
    return written
