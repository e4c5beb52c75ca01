"""Regenerates docs/scenes/NAME.gif (or .png), the README's picture of each shipped scene:
runs every scene in full (`make docs-pictures`), then renders a small animated GIF of its
frames with the preview renderer (at most 24 frames, 360x270), or a still of its last frame
when the animation would exceed 300 KB.

Usage: python scripts/make_docs_pictures.py [NAME ...]   (default: every shipped scene)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from topomech.recording import read_view
from topomech.render import gif_frames, render_frames, save_gif
from topomech.run import run_scene
from topomech.scene import shipped_scenes

DOCS = Path(__file__).resolve().parent.parent / "docs" / "scenes"
SIZE = (360, 270)
MAX_FRAMES = 24
MAX_BYTES = 300_000


def picture(name: str, path: Path, work: Path) -> Path:
    out = work / name
    t = time.perf_counter()
    summary = run_scene(path, out, preview=False)
    if "error" in summary:
        raise SystemExit(f"{name}: {summary['error']['message']}")
    view = read_view(out)
    images = render_frames(view, gif_frames(view, MAX_FRAMES), size=SIZE)
    for old in DOCS.glob(f"{name}.*"):
        old.unlink()
    target = DOCS / f"{name}.gif"
    save_gif(images, target)
    if target.stat().st_size > MAX_BYTES:
        target.unlink()
        target = DOCS / f"{name}.png"
        images[-1].save(target, optimize=True)
    size = target.stat().st_size / 1000
    print(
        f"{name:<16} {summary['steps']} steps in {time.perf_counter() - t:.1f} s -> "
        f"{target.relative_to(DOCS.parent.parent)} ({size:.0f} KB)"
    )
    return target


def main(names: list[str]) -> int:
    scenes = shipped_scenes()
    unknown = [n for n in names if n not in scenes]
    if unknown:
        print(
            f"unknown scenes: {', '.join(unknown)}; shipped: {', '.join(scenes)}", file=sys.stderr
        )
        return 2
    DOCS.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names or list(scenes):
            picture(name, scenes[name], Path(tmp))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
