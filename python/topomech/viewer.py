"""``topomech view OUT_DIR``: a self-contained web page that plays a run's frames.

:func:`write_viewer` writes ``viewer.html`` into a run's directory: one file with its script
and the run's view data (``view.json``, and ``view.bin`` in base64) inlined, so that it opens
from disk or from any server, without network access. :func:`serve` serves the directory on
127.0.0.1 (a free port unless one is given) in a background thread.

The page (``web/viewer.html`` and ``web/viewer.js`` in this package) draws on a Canvas 2D:
play/pause, previous/next, a scrub bar, the field that colors the surfaces, a wireframe
toggle and the dart view (see :mod:`topomech.recording` for what is recorded).
"""

from __future__ import annotations

import base64
import functools
import http.server
import json
import threading
from importlib import resources
from pathlib import Path

from topomech.recording import ViewError, read_view

__all__ = ["Server", "ViewError", "serve", "viewer_html", "write_viewer"]

VIEWER_FILE = "viewer.html"


def _asset(name: str) -> str:
    return (resources.files("topomech") / "web" / name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """Text that cannot end the ``<script>`` element it is inlined in."""
    return text.replace("</", "<\\/")


def viewer_html(out_dir: Path) -> str:
    """The viewer page of a run directory, data inlined; raises :class:`ViewError` when the
    directory has no readable view data."""
    view = read_view(Path(out_dir))
    page = _asset("viewer.html")
    title = str(view.meta.get("name", "run"))
    for key, value in (
        ("__TITLE__", title.replace("&", "&amp;").replace("<", "&lt;")),
        ("__META__", _script_safe(json.dumps(view.meta))),
        ("__BIN__", base64.b64encode(view.data).decode("ascii")),
        ("__SCRIPT__", _asset("viewer.js")),
    ):
        page = page.replace(key, value, 1)
    return page


def write_viewer(out_dir: Path, path: Path | None = None) -> Path:
    """Writes the viewer page (default ``OUT_DIR/viewer.html``); returns its path."""
    out_dir = Path(out_dir)
    html = viewer_html(out_dir)
    target = Path(path) if path is not None else out_dir / VIEWER_FILE
    target.write_text(html, encoding="utf-8")
    return target


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


class Server:
    """A run directory served over HTTP on 127.0.0.1 from a background thread."""

    def __init__(self, out_dir: Path, port: int = 0, host: str = "127.0.0.1") -> None:
        self.page = write_viewer(Path(out_dir))
        handler = functools.partial(_Quiet, directory=str(Path(out_dir).resolve()))
        self.httpd = http.server.ThreadingHTTPServer((host, port), handler)
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    @property
    def url(self) -> str:
        """The viewer page's address."""
        host, port = self.httpd.server_address[:2]
        return f"http://{host!s}:{port}/{VIEWER_FILE}"

    def start(self) -> Server:
        self.thread.start()
        return self

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=5)

    def __enter__(self) -> Server:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def serve(out_dir: Path, port: int = 0, host: str = "127.0.0.1") -> Server:
    """Writes the viewer page and serves the directory (started; call ``stop()``, or use it
    as a context manager)."""
    return Server(out_dir, port, host).start()
