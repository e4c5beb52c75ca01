"""`topomech view`: the self-contained viewer page, its server, and the page itself in headless
Chromium (Debian's, driven by Playwright, WebGL by SwiftShader): it draws a non-blank 3D
picture, plays, orbits, pans and zooms, picks vertices (their row, input point_id and fields,
checked against the recording), follows frames, and its dart view draws the map's darts
(instanced, up to a 511,104-dart map) and shows alpha links disappearing after a cut.

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
from topomech.viewer import THREE_JS, Server, viewer_html, write_viewer

WEB = Path(__file__).resolve().parents[1] / "python" / "topomech" / "web"

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
    assert "<link" not in html
    assert "import(" not in html
    # the only address in the page is the XHTML namespace three.js creates elements in
    # (createElementNS), which is never fetched
    rest = html.replace("http://www.w3.org/1999/xhtml", "")
    assert "http://" not in rest
    assert "https://" not in rest
    for marker in ("__TITLE__", "__META__", "__BIN__", "__LIB__", "__SCRIPT__"):
        assert marker not in html
    assert '<canvas id="view">' in html
    # three.js inlined, with its licence header; the page stays reasonable
    assert "var THREE=" in html
    assert "SPDX-License-Identifier: MIT" in html
    assert len(html) < 1_000_000


def test_vendored_three_js_is_recorded_and_inlinable() -> None:
    """three.js is vendored with its version and MIT licence; nothing in it can end the
    <script> element it is inlined in or open an HTML comment there."""
    three = WEB / THREE_JS
    text = three.read_text(encoding="utf-8")
    assert "</script" not in text.lower()
    assert "<!--" not in text
    version = (three.parent / "VERSION").read_text()
    m = __import__("re").match(r"three\.js (\d+)\.(\d+)\.(\d+) ", version)
    assert m, version
    # three.js's REVISION constant is the minor version
    assert f'"{m.group(2)}"' in text
    licence = (three.parent / "LICENSE").read_text()
    assert "The MIT License" in licence
    assert "three.js authors" in licence
    # the package ships them (read through importlib.resources, as the viewer does)
    from importlib import resources

    assert (resources.files("topomech") / "web" / THREE_JS).is_file()
    assert (resources.files("topomech") / "web" / "three" / "LICENSE").is_file()


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


#: Headless Chromium draws WebGL with SwiftShader (its CPU renderer), allowed explicitly.
CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


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
            b = p.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        except Exception as e:
            pytest.skip(f"browser tests skipped: {exe} does not start headless: {e}")
        yield b
        b.close()


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    pg = browser.new_page(viewport={"width": 900, "height": 640})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    # three.js reports shader and WebGL problems on the console
    pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    yield pg
    pg.close()
    assert errors == []


def _open(pg: Any, out: Path) -> None:
    pg.goto(write_viewer(out).resolve().as_uri())
    assert pg.evaluate("() => window.topomechViewer.webgl"), "no WebGL in headless Chromium"


def _viewer(pg: Any, expr: str = "") -> Any:
    """window.topomechViewer (or an expression on it, `v`), as JSON."""
    return pg.evaluate(
        f"() => {{ const v = window.topomechViewer; return JSON.parse(JSON.stringify({expr or 'v'})); }}"
    )


def _frames_drawn(pg: Any) -> None:
    """Waits for two animation frames (a render the controls asked for is done)."""
    pg.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


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


def _drawn_fraction(px: np.ndarray) -> float:
    """The fraction of the picture that is not the white background."""
    return float((np.abs(px - 255.0).sum(axis=2) > 30).mean())


def test_viewer_draws_and_plays(runs: dict[str, tuple[Path, dict[str, Any]]], page: Any) -> None:
    out, summary = runs["bar"]
    _open(page, out)
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
    _open(page, out)
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
    _open(page, out)
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
    _open(page, big)
    page.check("#darts")
    assert _state(page)["darts"] == "0"
    assert "more than the" in page.inner_text("#note")


# ---------------------------------------------------------------------------------- 3D


def test_page_makes_no_network_request(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, _ = runs["bar"]
    asked: list[str] = []
    page.on("request", lambda r: asked.append(r.url))
    _open(page, out)
    page.check("#darts")
    assert [u for u in asked if not u.startswith("file://")] == []
    assert len([u for u in asked if u.startswith("file://")]) == 1  # the page itself


def test_orbit_pan_and_zoom_move_the_camera_and_change_the_picture(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, _ = runs["bar"]
    _open(page, out)
    start = _viewer(page, "v.camera")
    px0 = _canvas_pixels(page)
    assert _drawn_fraction(px0) > 0.05
    box = page.locator("#view").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    # orbit: a left drag turns the camera about the target, at the same distance
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx + 120, cy + 40, steps=6)
    page.mouse.up()
    _frames_drawn(page)
    orbited = _viewer(page, "v.camera")
    pos0, pos1 = np.array(start["position"]), np.array(orbited["position"])
    target = np.array(start["target"])
    assert np.linalg.norm(pos1 - pos0) > 1e-3 * np.linalg.norm(pos0 - target)
    assert orbited["target"] == pytest.approx(start["target"])
    assert np.linalg.norm(pos1 - target) == pytest.approx(np.linalg.norm(pos0 - target), rel=1e-6)
    px1 = _canvas_pixels(page)
    assert _drawn_fraction(px1) > 0.05
    assert np.abs(px1 - px0).mean() > 1  # another picture
    assert _viewer(page, "v.picked") is None  # a drag does not pick
    # zoom: the wheel brings the camera nearer the target
    page.mouse.move(cx, cy)
    page.mouse.wheel(0, -400)
    _frames_drawn(page)
    zoomed = _viewer(page, "v.camera")
    assert np.linalg.norm(np.array(zoomed["position"]) - target) < 0.9 * np.linalg.norm(
        pos1 - target
    )
    # pan: a right drag moves the target too
    page.mouse.move(cx, cy)
    page.mouse.down(button="right")
    page.mouse.move(cx - 80, cy + 30, steps=4)
    page.mouse.up(button="right")
    _frames_drawn(page)
    panned = _viewer(page, "v.camera")
    assert np.linalg.norm(np.array(panned["target"]) - target) > 1e-3
    # reset view: the first camera again
    page.click("#reset")
    back = _viewer(page, "v.camera")
    assert back["position"] == pytest.approx(start["position"], abs=1e-6)
    assert back["target"] == pytest.approx(start["target"], abs=1e-6)


def _pick_visible(page: Any, candidates: Any) -> tuple[int, dict[str, float]]:
    """The first candidate vertex that a click at its place on the screen (nudged towards the
    picture's centre) picks, and that place."""
    box = page.locator("#view").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    for v in candidates:
        p = page.evaluate(f"() => window.topomechViewer.project({int(v)})")
        d = np.hypot(cx - p["x"], cy - p["y"]) or 1.0
        x, y = p["x"] + 2 * (cx - p["x"]) / d, p["y"] + 2 * (cy - p["y"]) / d
        got = page.evaluate(f"() => window.topomechViewer.pick({x}, {y})")
        if got is not None and got["vertex"] == int(v):
            return int(v), {"x": x, "y": y}
    raise AssertionError("no candidate vertex could be picked")


def test_picking_a_vertex_shows_its_row_point_id_and_fields(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["bar"]
    view = read_view(out)
    last = summary["frames"] - 1
    _open(page, out)
    page.evaluate(f"() => window.topomechViewer.setFrame({last})")
    ids = view.array(view.topology(last)["point_id"])
    n0 = view.topology(0)["vertices"]
    assert len(ids) == view.topology(last)["vertices"] > n0  # the cut added rows
    # a row the cut added: its input point is the one it was split from, not its row
    added = [v for v in range(n0, len(ids)) if ids[v] != v]
    assert added
    vertex, at = _pick_visible(page, added)
    # a real click there picks it
    page.evaluate("() => window.topomechViewer.pick(-1e6, -1e6)")  # nothing under: cleared
    assert _viewer(page, "v.picked") is None
    assert not page.is_visible("#pick")
    page.mouse.click(at["x"], at["y"])
    picked = _viewer(page, "v.picked")
    assert picked["vertex"] == vertex
    assert picked["pointId"] == int(ids[vertex])
    # the nearest vertex of the triangle hit, by the recorded positions
    x = view.positions(last).astype(np.float64)
    tri = picked["triangle"]
    assert vertex in tri
    hit = np.array(picked["point"])
    assert vertex == tri[int(np.argmin([np.linalg.norm(x[t] - hit) for t in tri]))]
    assert picked["position"] == pytest.approx(x[vertex].tolist(), abs=1e-6)
    for name in view.meta["fields"]:
        assert picked["values"][name] == pytest.approx(
            float(view.field(last, name)[vertex]), rel=1e-6, abs=1e-12
        )
    # the panel says it
    assert page.is_visible("#pick")
    panel = page.inner_text("#pick")
    assert f"vertex\t{vertex}" in panel
    assert f"point_id\t{int(ids[vertex])}" in panel
    assert "von Mises stress" in panel
    assert page.get_attribute("#pick", "data-point-id") == str(int(ids[vertex]))
    # a frame change keeps the vertex and shows that frame's values
    page.evaluate("() => window.topomechViewer.setFrame(0)")
    assert _viewer(page, "v.picked") is None or _viewer(page, "v.picked")["vertex"] < n0
    page.keyboard.press("Escape")
    assert _viewer(page, "v.picked") is None


def test_picking_in_the_first_frame_matches_the_recorded_point_ids(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, _ = runs["sheet"]
    view = read_view(out)
    ids = view.array(view.topology(0)["point_id"])
    _open(page, out)
    x = view.positions(0)
    # the corners of the sheet are on the surface, seen from the camera
    corners = [int(np.argmin(x[:, 0] + x[:, 1])), int(np.argmax(x[:, 0] + x[:, 1]))]
    vertex, at = _pick_visible(page, corners)
    page.mouse.click(at["x"], at["y"])
    picked = _viewer(page, "v.picked")
    assert picked["vertex"] == vertex
    assert picked["pointId"] == int(ids[vertex])
    assert picked["values"]["displacement"] == pytest.approx(
        float(view.field(0, "displacement")[vertex]), abs=1e-9
    )


def test_frame_changes_update_positions(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["sheet"]
    view = read_view(out)
    _open(page, out)
    last = summary["frames"] - 1
    moved = int(
        np.argmax(
            np.linalg.norm(
                view.positions(last)[: len(view.positions(0))] - view.positions(0), axis=1
            )
        )
    )
    shot0 = _canvas_pixels(page)
    before = page.evaluate(f"() => window.topomechViewer.position({moved})")
    assert before == pytest.approx(view.positions(0)[moved].tolist(), abs=1e-7)
    _scrub_to(page, last)
    assert _state(page)["frame"] == str(last)
    after = page.evaluate(f"() => window.topomechViewer.position({moved})")
    assert after == pytest.approx(view.positions(last)[moved].tolist(), abs=1e-7)
    assert np.linalg.norm(np.array(after) - np.array(before)) > 1e-3
    assert _viewer(page, "v.vertices") == view.topology(last)["vertices"]
    assert np.abs(_canvas_pixels(page) - shot0).mean() > 0.5


def test_dart_view_is_instanced_and_keeps_the_surface(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["bar"]
    _open(page, out)
    surface = _canvas_pixels(page)
    page.check("#darts")
    v = _viewer(page)
    assert v["surfaceVisible"]
    assert v["info"]["triangles"] > 0  # the surface is still drawn
    items = {o["kind"]: o for o in v["items"]}
    assert items["darts"]["items"] == items["dots"]["items"] == v["darts"] == summary["darts"]
    assert [items[f"alpha{i}"]["items"] for i in range(4)] == v["links"] == _count_links(out, 0)
    # one instance draws a chunk of darts: one draw call per kind
    chunk = v["chunk"]
    assert items["darts"]["instances"] == -(-summary["darts"] // chunk)
    assert v["info"]["points"] == items["dots"]["instances"] * chunk  # one dot a dart, padded
    px = _canvas_pixels(page)
    assert _drawn_fraction(px) > 0.05
    assert np.abs(px - surface).mean() > 1  # the darts show over the surface
    dark = (px.sum(axis=2) < 150).mean()
    assert dark > 0.002  # the black darts
    page.uncheck("#darts")
    assert _viewer(page, "v.items") == []


def test_without_webgl_the_page_draws_in_2d(
    runs: dict[str, tuple[Path, dict[str, Any]]], browser: Any
) -> None:
    """A browser that gives the page no WebGL gets the 2D viewer (Canvas 2D, as before the
    3D one), saying so: it draws, plays and has its dart view."""
    out, summary = runs["bar"]
    pg = browser.new_page(viewport={"width": 900, "height": 640})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.add_init_script(
        "HTMLCanvasElement.prototype.getContext = (function (get) { return function (kind, ...a) {"
        " return String(kind).startsWith('webgl') ? null : get.call(this, kind, ...a); }; })"
        "(HTMLCanvasElement.prototype.getContext);"
    )
    pg.goto(write_viewer(out).resolve().as_uri())
    assert _state(pg)["webgl"] == "false"
    assert pg.evaluate("() => window.topomechViewer.webgl") is False
    assert "no WebGL" in pg.inner_text("#hint")
    assert _state(pg)["mode"] == "surface"
    px = _canvas_pixels(pg)
    assert _drawn_fraction(px) > 0.05
    assert px.std() > 20
    # the fields once each, and "none" (the 3D viewer set nothing up before it gave way)
    assert len(pg.query_selector_all("#field option")) == len(read_view(out).meta["fields"]) + 1
    pg.check("#darts")
    assert _state(pg)["darts"] == str(summary["darts"])
    _scrub_to(pg, summary["frames"] - 1)
    assert _state(pg)["frame"] == str(summary["frames"] - 1)
    pg.close()
    assert errors == []


# A cube of 22 x 22 x 22 hexahedra: 10,648 cells, 48 darts each, 511,104 darts.
BIG = """
name = "big"
[mesh]
generator = "box"
element = "hex"
size = [2.2, 2.2, 2.2]
cells = [22, 22, 22]
[[model]]
kind = "stretch_elementary"
stiffness = 100.0
[material]
density = 100.0
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "symplectic_euler"
dt = 1e-4
steps = 1
[output]
every = 1
"""


def test_dart_view_draws_half_a_million_darts(tmp_path: Path, page: Any) -> None:
    scene = tmp_path / "big.toml"
    scene.write_text(BIG)
    summary = run_scene(scene, tmp_path / "big", preview=False)
    assert "error" not in summary
    assert summary["darts"] == 511_104
    view = read_view(tmp_path / "big")
    assert view.topology(0)["dart_table"] is not None  # recorded: under the dart limit
    _open(page, tmp_path / "big")
    page.check("#darts")
    v = _viewer(page)
    assert v["darts"] == v["mapDarts"] == 511_104
    items = {o["kind"]: o for o in v["items"]}
    assert items["darts"]["items"] == 511_104
    assert (
        [items[f"alpha{i}"]["items"] for i in range(4)]
        == v["links"]
        == _count_links(tmp_path / "big", 0)
    )
    assert v["info"]["lines"] >= 511_104 + sum(v["links"])
    assert v["surfaceVisible"]
    px = _canvas_pixels(page)
    assert _drawn_fraction(px) > 0.1
    assert px.std() > 20


def _triangles(view: Any, k: int) -> int:
    return sum(len(f) - 2 for f in view.faces(k) if len(f) >= 3)


def test_the_surface_of_each_frame_shows_the_cut(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    """The surface drawn is the frame's recorded boundary faces: after the cut, the faces it
    opened are drawn on both of its sides."""
    out, summary = runs["bar"]
    view = read_view(out)
    last = summary["frames"] - 1
    opened = sum(c["unsewn"] for c in summary["topology_changes"])
    assert len(view.faces(last)) == len(view.faces(0)) + 2 * opened
    _open(page, out)
    assert _viewer(page, "v.info.triangles") == _triangles(view, 0)
    _scrub_to(page, last)
    assert _viewer(page, "v.topology") == view.frames[last]["topology"] > 0
    assert _viewer(page, "v.info.triangles") == _triangles(view, last)


def test_field_selector_colors_the_surface_and_the_legend(
    runs: dict[str, tuple[Path, dict[str, Any]]], page: Any
) -> None:
    out, summary = runs["bar"]
    _open(page, out)
    _scrub_to(page, summary["frames"] - 1)
    assert "von Mises stress" in page.inner_text("#field-label")
    stress = _canvas_pixels(page)
    page.select_option("#field", "displacement")
    assert "displacement magnitude (m)" in page.inner_text("#field-label")
    shown = _canvas_pixels(page)
    assert np.abs(shown - stress).mean() > 0.5
    page.select_option("#field", "none")
    assert not page.is_visible("#field-legend")
    gray = _canvas_pixels(page)
    drawn = np.abs(gray - 255.0).sum(axis=2) > 30
    # no field: the surface is gray (its channels equal, up to the antialiased edges)
    spread = gray.max(axis=2) - gray.min(axis=2)
    assert (spread[drawn] < 12).mean() > 0.9
