"""`topomech view`: the self-contained viewer page, its server, and the page itself in headless
Chromium (Debian's, driven by Playwright): it draws, plays, and its dart view draws the map's
darts and shows alpha links disappearing after a cut.

The browser tests need the playwright package and /usr/bin/chromium (or $TOPOMECH_CHROMIUM);
`make test` installs both when it can (scripts/install_browser.sh). Without them they are
skipped, saying which is missing."""

from __future__ import annotations

import io
import json
import os
import shutil
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from topomech import cli
from topomech.recording import read_view
from topomech.run import run_scene
from topomech.viewer import Server, viewer_html, write_viewer

# A 2D sheet of 2 quads and 4 triangles (40 darts), cut in two along x = 0.5 at step 20.
SHEET = """
name = "sheet"
[mesh]
generator = "grid"
element = "mixed"
size = [1.0, 1.0]
cells = [2, 2]
[[model]]
kind = "stretch_elementary"
stiffness = 100.0
[material]
density = 1.0
[[fix]]
where = "y > 1.0 - 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 40
[output]
every = 10
[[event]]
time = 0.02
kind = "cut"
plane = { normal = [1.0, 0.0, 0.0], offset = 0.5 }
"""

# A bar of 12 tetrahedra (288 darts), cut in two by the plane x = 0.5 at the second step.
BAR = """
name = "bar"
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.3, 0.3]
cells = [2, 1, 1]
[[model]]
kind = "corotational"
young = 1e5
poisson = 0.3
[material]
density = 100.0
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 6
[output]
every = 2
[[event]]
time = 0.002
kind = "cut"
plane = { normal = [1.0, 0.0, 0.0], offset = 0.5 }
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, dict[str, Any]]]:
    root = tmp_path_factory.mktemp("viewer")
    out = {}
    for name, text in (("sheet", SHEET), ("bar", BAR)):
        scene = root / f"{name}.toml"
        scene.write_text(text)
        summary = run_scene(scene, root / name, preview=False)
        assert "error" not in summary
        out[name] = (root / name, summary)
    return out


# ---------------------------------------------------------------------------------- page


def test_page_is_self_contained(runs: dict[str, tuple[Path, dict[str, Any]]]) -> None:
    out, _ = runs["bar"]
    html = viewer_html(out)
    assert "<script src" not in html
    assert "http://" not in html
    assert "https://" not in html
    assert "__META__" not in html
    assert "__BIN__" not in html
    assert "__SCRIPT__" not in html
    assert '<canvas id="view">' in html


def test_cli_view_html_writes_the_page(
    runs: dict[str, tuple[Path, dict[str, Any]]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out, _ = runs["sheet"]
    target = tmp_path / "page.html"
    assert cli.main(["view", str(out), "--html", "--output", str(target)]) == 0
    assert f"wrote {target}" in capsys.readouterr().out
    assert target.read_text() == viewer_html(out)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: d / "missing", "no such directory"),
        (lambda d: d, "not a run directory (no view.json)"),
        (lambda d: (d / "f.txt").write_text("x") and d / "f.txt", "not a directory"),
    ],
)
def test_cli_view_refuses_what_is_not_a_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], make: Any, message: str
) -> None:
    target = make(tmp_path)
    assert cli.main(["view", str(target)]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err


def test_cli_view_refuses_broken_view_data(
    runs: dict[str, tuple[Path, dict[str, Any]]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out, _ = runs["sheet"]
    broken = tmp_path / "broken"
    shutil.copytree(out, broken)
    data = (broken / "view.bin").read_bytes()
    (broken / "view.bin").write_bytes(data[:-8])
    assert cli.main(["view", str(broken), "--html"]) == 2
    assert "truncated" in capsys.readouterr().err
    (broken / "view.json").write_text("{not json")
    assert cli.main(["view", str(broken), "--html"]) == 2
    assert "cannot read the view description" in capsys.readouterr().err
    # a run without frames has nothing to view
    noframes = tmp_path / "noframes"
    noframes.mkdir()
    (noframes / "summary.json").write_text("{}")
    assert cli.main(["view", str(noframes)]) == 2
    assert "wrote no frames" in capsys.readouterr().err


def test_server_serves_the_page_on_localhost(
    runs: dict[str, tuple[Path, dict[str, Any]]],
) -> None:
    out, _ = runs["sheet"]
    with Server(out) as server:
        assert server.url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(server.url, timeout=10) as r:
            body = r.read().decode()
    assert r.status == 200
    assert 'id="view-meta"' in body


# ---------------------------------------------------------------------------------- browser


def _chromium() -> str | None:
    path = os.environ.get("TOPOMECH_CHROMIUM", "/usr/bin/chromium")
    if Path(path).is_file():
        return path
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip(
            "browser tests skipped: the playwright package is not installed "
            "(`make browser` or scripts/install_browser.sh installs it)"
        )
    exe = _chromium()
    if exe is None:
        pytest.skip(
            "browser tests skipped: no Chromium (/usr/bin/chromium is missing and "
            "scripts/install_browser.sh could not apt-get install chromium here; "
            "or set TOPOMECH_CHROMIUM)"
        )
    with sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        except Exception as e:
            pytest.skip(f"browser tests skipped: {exe} does not start headless: {e}")
        yield b
        b.close()


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    pg = browser.new_page(viewport={"width": 900, "height": 640})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    yield pg
    pg.close()
    assert errors == []


def _state(pg: Any) -> dict[str, str]:
    s: dict[str, str] = pg.eval_on_selector("#state", "e => ({...e.dataset})")
    return s


def _scrub_to(pg: Any, k: int) -> None:
    pg.eval_on_selector(
        "#scrub", f"e => {{ e.value = '{k}'; e.dispatchEvent(new Event('input')); }}"
    )


def _canvas_pixels(pg: Any) -> np.ndarray:
    from PIL import Image

    png = pg.locator("#view").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)


def test_viewer_draws_and_plays(runs: dict[str, tuple[Path, dict[str, Any]]], page: Any) -> None:
    out, summary = runs["bar"]
    page.goto(write_viewer(out).resolve().as_uri())
    assert _state(page)["frame"] == "0"
    assert _state(page)["mode"] == "surface"
    px = _canvas_pixels(page)
    assert px.std() > 20  # colored, shaded surfaces on white
    assert (px.sum(axis=2) < 600).mean() > 0.02
    assert len(np.unique(px.reshape(-1, 3), axis=0)) > 20
    page.click("#play")
    assert _state(page)["playing"] == "true"
    page.wait_for_function("document.getElementById('state').dataset.frame !== '0'", timeout=5000)
    page.click("#play")
    assert _state(page)["playing"] == "false"
    shown = int(_state(page)["frame"])
    assert 0 < shown < summary["frames"]
    assert f"frame {shown + 1} / {summary['frames']}" in page.inner_text("#state")
    # the wireframe draws something else
    page.check("#wireframe")
    assert _state(page)["mode"] == "wireframe"
    assert np.abs(_canvas_pixels(page) - px).mean() > 1


def _count_links(out: Path, frame: int) -> list[int]:
    """Alpha-i links (pairs of darts) of a frame's map, from the recorded tables."""
    view = read_view(out)
    t = view.meta["topologies"][view.frames[frame]["topology"]]["dart_table"]
    alpha = view.array(t["alpha"])
    live = view.array(t["vertex"]) >= 0
    d = np.arange(alpha.shape[1])
    return [int(((alpha[i] > d) & live).sum()) for i in range(4)]


def test_dart_view_draws_every_dart_and_links_disappear_after_a_cut_2d(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["sheet"]
    page.goto(write_viewer(out).resolve().as_uri())
    page.check("#darts")
    s = _state(page)
    assert s["mode"] == "darts"
    # 2 quads (8 darts each) and 4 triangles (6 each): the map's 40 darts, all drawn
    assert summary["darts"] == 40
    assert s["darts"] == "40"
    links = [int(x) for x in s["links"].split(",")]
    # alpha0 and alpha1 pair every dart; alpha2 the darts on either side of inner edges
    assert links == _count_links(out, 0)
    assert links[0] == links[1] == 20
    assert links[3] == 0
    px = _canvas_pixels(page)
    assert px.std() > 5
    last = summary["frames"] - 1
    _scrub_to(page, last)
    after = [int(x) for x in _state(page)["links"].split(",")]
    cut = summary["topology_changes"]
    assert len(cut) == 1
    # each edge opened by the cut had two alpha2 links (one per side of its two darts)
    assert after[2] == links[2] - 2 * cut[0]["unsewn"]
    assert after[:2] == links[:2]
    assert _state(page)["darts"] == "40"


def test_dart_view_of_a_volume_shows_the_alpha3_links_cut(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["bar"]
    page.goto(write_viewer(out).resolve().as_uri())
    page.check("#darts")
    s = _state(page)
    assert s["darts"] == str(summary["darts"]) == "288"  # 12 tetrahedra x 24 darts
    before = [int(x) for x in s["links"].split(",")]
    # alpha3 pairs the 6 darts of each side of an inner face: 3 (4 T - boundary faces)
    view = read_view(out)
    boundary0 = len(view.faces(0))
    assert before[3] == 3 * (4 * 12 - boundary0)
    _scrub_to(page, summary["frames"] - 1)
    after = [int(x) for x in _state(page)["links"].split(",")]
    opened = sum(c["unsewn"] for c in summary["topology_changes"])
    assert opened > 0
    assert after[3] == before[3] - 6 * opened
    assert after[:3] == before[:3]
    assert after == _count_links(out, summary["frames"] - 1)


def test_dart_view_says_when_the_map_is_too_large(
    tmp_path: Path, runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, _ = runs["bar"]
    big = tmp_path / "big"
    shutil.copytree(out, big)
    meta = json.loads((big / "view.json").read_text())
    for t in meta["topologies"]:
        t["dart_table"] = None
    (big / "view.json").write_text(json.dumps(meta))
    page.goto(write_viewer(big).resolve().as_uri())
    page.check("#darts")
    assert _state(page)["darts"] == "0"
    assert "more than the" in page.inner_text("#note")
