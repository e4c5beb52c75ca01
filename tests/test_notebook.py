"""Jupyter display: ``topomech.show(out_dir)`` and ``Simulation._repr_html_`` embed the
viewer page in a sandboxed ``<iframe srcdoc=...>`` (well-formed, the page exactly, escaped);
in headless Chromium the embedded viewer starts; with nbclient and ipykernel installed, a
real notebook displays them."""

from __future__ import annotations

import html.parser
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import topomech
from topomech import notebook
from topomech.recording import ViewError, read_view
from topomech.run import run_scene
from topomech.scene import shipped_scenes
from topomech.viewer import viewer_html

SCENE = """
name = {name}
[mesh]
generator = "box"
element = "tet"
size = [1.0, 0.2, 0.2]
cells = [3, 1, 1]
[[model]]
kind = "corotational"
young = 1e6
poisson = 0.3
[material]
density = 1000.0
[[fix]]
where = "x < 1e-9"
[world]
gravity = [0.0, -9.81, 0.0]
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 6
[output]
every = 3
"""

#: A name with every character HTML escapes.
NASTY = "a \"quoted\" <b>&amp; name<b> 'x' <script>"


class _Tags(html.parser.HTMLParser):
    """Every start tag with its attributes (unescaped by the parser), the text, and whether
    every element that was opened was closed."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.open: list[str] = []
        self.text: list[str] = []
        self.bad: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        self.open.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if not self.open or self.open[-1] != tag:
            self.bad.append(tag)
        else:
            self.open.pop()

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def parse(text: str) -> _Tags:
    p = _Tags()
    p.feed(text)
    p.close()
    assert p.bad == [], p.bad
    assert p.open == [], p.open
    return p


def iframes(p: _Tags) -> list[dict[str, str | None]]:
    return [a for t, a in p.tags if t == "iframe"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("nb")
    scene = tmp / "nasty.toml"
    scene.write_text(SCENE.format(name=_toml_string(NASTY)))
    out = tmp / "out"
    s = run_scene(scene, out, preview=False)
    assert "error" not in s, s
    return out


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def test_show_embeds_the_viewer_page_in_a_sandboxed_iframe(run_dir: Path) -> None:
    view = topomech.show(run_dir)
    out = view._repr_html_()
    p = parse(out)
    assert [t for t, _ in p.tags] == ["iframe"]  # one element: everything else is escaped
    (frame,) = iframes(p)
    assert frame["srcdoc"] == viewer_html(run_dir)  # the page itself, whole
    assert frame["sandbox"] == "allow-scripts"  # its scripts run apart from the notebook
    assert frame["title"] == f"topomech viewer: {NASTY}"
    assert frame["height"] == str(notebook.HEIGHT)
    # the attribute holds no raw markup: the page's quotes and brackets are escaped
    body = out[out.index('srcdoc="') + len('srcdoc="') : out.index('" title=')]
    for ch in '"<>':
        assert ch not in body
    assert "&lt;script" in body
    assert NASTY not in out  # the name only escaped
    assert repr(view).startswith(f"topomech.show({str(run_dir)!r}): the viewer of run ")
    assert "(3 frames)" in repr(view)


def test_show_height_and_errors(run_dir: Path, tmp_path: Path) -> None:
    (frame,) = iframes(parse(topomech.show(run_dir, height=300)._repr_html_()))
    assert frame["height"] == "300"
    with pytest.raises(ViewError, match="no such directory"):
        topomech.show(tmp_path / "missing")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ViewError):
        topomech.show(empty)


def _cells(p: _Tags) -> dict[str, str]:
    """The table's rows: header text -> cell text."""
    text = [t for t in p.text if t.strip()]
    i = text.index("topomech.Simulation")
    pairs = text[i + 1 :]
    keys = ["dimension", "vertices", "elements", "darts", "integrator", "time"]
    got = {}
    for k in keys:
        j = pairs.index(k)
        got[k] = pairs[j + 1]
    return got


def test_simulation_repr_html_is_a_table_and_the_mesh() -> None:
    sim = topomech.load_scene(shipped_scenes()["corotational"]).build()
    sim.step(5)
    out = sim._repr_html_()
    p = parse(out)
    rows = _cells(p)
    assert rows["dimension"] == "3D"
    assert rows["vertices"] == f"{sim.n_vertices:,}"
    assert rows["elements"] == f"{len(sim.elements()[0]):,}"
    assert rows["darts"] == f"{sim.gmap().core.n_darts:,}"
    assert rows["integrator"] == f"{sim.integrator} (dt = {sim.dt:g} s)"
    assert rows["time"] == f"{sim.time:g} s after 5 steps"
    (frame,) = iframes(p)
    page = frame["srcdoc"]
    assert page is not None
    assert page.lstrip().lower().startswith("<!doctype html>")
    assert "topomech viewer" in (frame["title"] or "")


def test_simulation_html_without_the_mesh(monkeypatch: pytest.MonkeyPatch) -> None:
    sim = topomech.load_scene(shipped_scenes()["cloth"]).build()
    p = parse(notebook.simulation_html(sim, mesh=False))
    assert iframes(p) == []
    assert _cells(p)["dimension"] == "2D"
    monkeypatch.setattr(notebook, "MAX_VIEW_VERTICES", 10)
    p = parse(sim._repr_html_())
    assert iframes(p) == []
    assert "too many to embed" in "".join(p.text)


def test_simulation_mesh_page_holds_the_current_positions(tmp_path: Path) -> None:
    """The embedded page's data are one frame of the simulation as it is now."""
    sim = topomech.load_scene(shipped_scenes()["corotational"]).build()
    sim.step(20)
    page = notebook._mesh_page(sim)
    assert "topomech" in page
    # the same recording, kept: one frame at the current positions
    from topomech.recording import Recorder

    rec = Recorder(sim, energy=False)
    rec.frame()
    assert rec.write_view(tmp_path)
    rec.close()
    view = read_view(tmp_path)
    assert len(view.frames) == 1
    np.testing.assert_allclose(view.world_positions(0), sim.positions(), atol=1e-6)
    assert page == viewer_html(tmp_path)


# ---------------------------------------------------------------------------------- browser

#: As tests/test_viewer.py launches it: WebGL drawn by SwiftShader (its CPU renderer).
CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def _chromium() -> str | None:
    path = os.environ.get("TOPOMECH_CHROMIUM", "/usr/bin/chromium")
    if Path(path).is_file():
        return path
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_embedded_viewer_starts_in_chromium(run_dir: Path) -> None:
    """The notebook's HTML in a page of its own: the iframe's viewer runs (its
    ``window.topomechViewer`` appears) without a script error."""
    pw = pytest.importorskip(
        "playwright.sync_api", reason="the playwright package is not installed (make browser)"
    )
    exe = _chromium()
    if exe is None:
        pytest.skip("no Chromium (/usr/bin/chromium; make browser installs it)")
    doc = f"<!DOCTYPE html><html><body><h1>notebook</h1>{topomech.show(run_dir)._repr_html_()}</body></html>"
    errors: list[str] = []
    with pw.sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        try:
            pg = b.new_page(viewport={"width": 900, "height": 700})
            pg.on("pageerror", lambda e: errors.append(str(e)))
            pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            pg.set_content(doc)
            pg.wait_for_function("document.querySelectorAll('iframe').length === 1")
            frame = None
            for _ in range(100):
                frame = next((f for f in pg.frames if f != pg.main_frame), None)
                if frame is not None:
                    break
                pg.wait_for_timeout(100)
            assert frame is not None
            frame.wait_for_function("() => window.topomechViewer !== undefined", timeout=30_000)
            assert frame.evaluate("() => typeof window.topomechViewer") == "object"
            assert frame.evaluate("() => document.querySelectorAll('canvas').length") >= 1
        finally:
            b.close()
    assert errors == []


# ---------------------------------------------------------------------------------- jupyter


NOTEBOOK_CELLS = [
    "import topomech",
    "view = topomech.show({out!r})\nview",
    "sim = topomech.load_scene(topomech.shipped_scenes()['corotational']).build()\nsim",
]


def test_a_real_notebook_displays_the_viewer(run_dir: Path, tmp_path: Path) -> None:
    """Executed by nbclient in an ipykernel: the outputs of the two display cells are HTML
    (an iframe with the viewer) beside their text repr."""
    nbformat = pytest.importorskip("nbformat", reason="nbformat is not installed")
    nbclient = pytest.importorskip("nbclient", reason="nbclient is not installed")
    pytest.importorskip("ipykernel", reason="ipykernel is not installed")
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(c.format(out=str(run_dir))) for c in NOTEBOOK_CELLS]
    client = nbclient.NotebookClient(nb, timeout=120, kernel_name="python3")
    try:
        client.execute(cwd=str(tmp_path))
    except Exception as e:  # no kernel spec: not a failure of topomech
        if "No such kernel" in str(e) or "NoSuchKernel" in type(e).__name__:
            pytest.skip(f"no python3 Jupyter kernel here: {e}")
        raise
    outs: list[Any] = [c.outputs for c in nb.cells]
    for cell in (1, 2):
        (out,) = outs[cell]
        assert out["output_type"] == "execute_result"
        data = out["data"]
        assert "<iframe srcdoc=" in data["text/html"]
        assert data["text/plain"]
    assert "the viewer of run" in outs[1][0]["data"]["text/plain"]
    assert "<table>" in outs[2][0]["data"]["text/html"]
