"""``topomech view OUT_DIR``: a self-contained web page that plays a run's frames in 3D.

:func:`write_viewer` writes ``viewer.html`` into a run's directory: one file with its scripts
and the run's view data (``view.json``, and ``view.bin`` in base64) inlined, so that it opens
from disk or from any server, without network access. :func:`serve` serves the directory on
127.0.0.1 (a free port unless one is given) in a background thread.

The page (``web/viewer.html`` and ``web/viewer.js`` in this package) draws with WebGL through
three.js, vendored in ``web/three/`` (``three.min.js``: the classes the viewer uses and
OrbitControls, bundled by ``scripts/vendor_three.sh``; its version and MIT licence beside it):
orbit, pan and zoom; a click picks a vertex (its row, its input ``point_id``, its fields);
play/pause, previous/next, a scrub bar; the field that colors the surface (with a legend); a
wireframe toggle; and the dart view, instanced line segments over the translucent surface
(see :mod:`topomech.recording` for what is recorded). ``window.topomechViewer`` in the page
tells scripts and tests what is drawn: ``frame``, ``mode``, ``darts`` and ``links`` (the
darts and alpha links drawn), ``mapDarts``, ``picked``, ``camera``, the renderer's ``info``
of the last render, and ``pick(x, y)``, ``project(vertex)``, ``setFrame(k)``, ``render()``.
A browser that gives the page no WebGL gets the 2D viewer the 3D one replaced (Canvas 2D, no
picking), with a line saying so.
"""

from __future__ import annotations

import base64
import contextlib
import http.server
import json
import os
import stat
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from importlib import resources
from pathlib import Path

from topomech.recording import ViewError, read_view

__all__ = ["Server", "ViewError", "port_number", "serve", "viewer_html", "write_viewer"]

VIEWER_FILE = "viewer.html"


def _asset(name: str) -> str:
    return (resources.files("topomech") / "web" / name).read_text(encoding="utf-8")


#: three.js, bundled (``scripts/vendor_three.sh``), under ``web/``.
THREE_JS = "three/three.min.js"


def _script_safe(text: str) -> str:
    """Text that cannot end the ``<script>`` element it is inlined in."""
    return text.replace("</", "<\\/")


#: Bytes of view.bin encoded at a time (a multiple of 3: the base64 of the blocks, one after
#: the other, is that of the whole file).
_B64_BLOCK = 3 << 14


def _page_parts(out_dir: Path) -> Iterator[str]:
    """The viewer page of a run directory, piece by piece: the template with its markers
    (``__TITLE__``, ``__META__``, ``__BIN__``, ``__LIB__`` (three.js), ``__SCRIPT__``, each
    replaced once, in this order) filled in, view.bin base64-encoded a block at a time.
    Raises :class:`ViewError` when the directory has no readable view data."""
    view = read_view(Path(out_dir))
    page = _asset("viewer.html")
    title = str(view.meta.get("name", "run"))

    def data() -> Iterator[str]:
        try:
            with view.bin_path.open("rb") as fh:
                while block := fh.read(_B64_BLOCK):
                    yield base64.b64encode(block).decode("ascii")
        except OSError as e:
            msg = f"{view.bin_path}: cannot read the view data: {e.strerror or e}"
            raise ViewError(msg) from None

    values: list[tuple[str, Callable[[], Iterator[str]]]] = [
        ("__TITLE__", lambda: iter([title.replace("&", "&amp;").replace("<", "&lt;")])),
        ("__META__", lambda: iter([_script_safe(json.dumps(view.meta))])),
        ("__BIN__", data),
        ("__LIB__", lambda: iter([_asset(THREE_JS)])),
        ("__SCRIPT__", lambda: iter([_asset("viewer.js")])),
    ]
    rest = page
    for key, value in values:
        head, found, rest = rest.partition(key)
        yield head
        if found:
            yield from value()
    yield rest


def viewer_html(out_dir: Path) -> str:
    """The viewer page of a run directory, data inlined; raises :class:`ViewError` when the
    directory has no readable view data."""
    return "".join(_page_parts(out_dir))


def write_viewer(out_dir: Path, path: Path | None = None) -> Path:
    """Writes the viewer page (default ``OUT_DIR/viewer.html``); returns its path. The page
    is written piece by piece (view.bin encoded a block at a time), so writing it takes
    memory for view.json, not for the whole of view.bin.

    The page is written to a new file then renamed over the target, so a symlink at the
    target is replaced, never followed. Raises :class:`ViewError` when the directory has no
    readable view data and :class:`OSError` when the page cannot be written."""
    out_dir = Path(out_dir)
    parts = _page_parts(out_dir)
    first = next(parts)  # reads view.json: a directory without view data fails here
    target = Path(path) if path is not None else out_dir / VIEWER_FILE
    if path is None:
        from topomech._manifest import register

        register(out_dir, VIEWER_FILE)  # a rerun of the run may then replace it
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(first)
            for part in parts:
                f.write(part)
        tmp.chmod(0o644)
        tmp.replace(target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return target


#: The ``Host`` names the server answers to; any other is refused (DNS rebinding).
LOCAL_HOSTS = frozenset({"localhost", "127.0.0.1", "[::1]"})

#: Seconds a connection may stay silent before the server drops it.
REQUEST_TIMEOUT = 10.0


def _host_name(header: str) -> str:
    """The host of a ``Host`` header, without its port, lowercased (``[::1]`` keeps its
    brackets)."""
    host = header.strip().lower()
    if host.startswith("["):
        end = host.find("]")
        return host[: end + 1] if end >= 0 else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def port_number(value: object) -> int:
    """``value`` as a TCP port to serve on: an int from 0 (a free port) to 65535; raises
    :class:`ValueError` naming the value otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise ValueError(f"port must be an integer from 0 to 65535, got {value!r}")
    try:
        port = int(value)
    except ValueError:
        raise ValueError(f"port must be an integer from 0 to 65535, got {value!r}") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"port must be an integer from 0 to 65535 (0: a free one), got {port}")
    return port


class _ViewerHandler(http.server.BaseHTTPRequestHandler):
    """Answers GET and HEAD for the files the viewer wrote, and nothing else: no directory
    listing, no other file of the folder, no path that leaves it, no symlink; a request whose
    ``Host`` is not this machine is refused with 403."""

    server: _ViewerHTTPServer
    timeout = REQUEST_TIMEOUT
    server_version = "topomech-viewer"
    sys_version = ""

    def log_message(self, format: str, *args: object) -> None:
        pass

    def do_GET(self) -> None:
        self._answer(body=True)

    def do_HEAD(self) -> None:
        self._answer(body=False)

    def _answer(self, body: bool) -> None:
        host = self.headers.get("Host")
        if host is None:
            self.send_error(400, "missing Host header")
            return
        if _host_name(host) not in LOCAL_HOSTS:
            self.send_error(403, "this server answers only to localhost")
            return
        path = self.path.split("?", 1)[0].split("#", 1)[0]
        if path == "/":
            self.send_response(302)
            self.send_header("Location", f"/{VIEWER_FILE}")
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        name = path[1:] if path.startswith("/") else None
        target = self.server.files.get(name) if name is not None else None
        data = _read_own_file(target) if target is not None else None
        if data is None:
            self.send_error(404)
            return
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if body:
            self.wfile.write(data)


def _read_own_file(path: Path) -> bytes | None:
    """The bytes of ``path`` when it is still a regular file and not a symlink (opened without
    following one), else None."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
    try:
        if path.is_symlink():
            return None
        fd = os.open(path, flags)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            return None
        return f.read()


class _ViewerHTTPServer(http.server.ThreadingHTTPServer):
    """The HTTP server of :class:`Server`: ``files`` maps the URL names it serves to the files
    the viewer wrote; a client that hangs up or times out is dropped without a traceback."""

    daemon_threads = True

    def __init__(self, address: tuple[str, int], files: dict[str, Path]) -> None:
        self.files = files
        super().__init__(address, _ViewerHandler)

    def handle_error(self, request: object, client_address: object) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, (ConnectionError, TimeoutError)):
            return  # the client hung up or went silent: nothing to report
        print(f"topomech view: error answering {client_address}: {exc!r}", file=sys.stderr)


class Server:
    """A run directory's viewer page served over HTTP on 127.0.0.1 from a background thread.

    Only the page the viewer wrote (``OUT_DIR/viewer.html``) is served; ``/`` redirects to it,
    every other path is 404, and a ``Host`` other than localhost, 127.0.0.1 or [::1] gets 403.
    Raises :class:`ViewError` when the directory has no readable view data, :class:`ValueError`
    for a port outside 0..65535 and :class:`OSError` when the port cannot be bound."""

    def __init__(self, out_dir: Path, port: int = 0, host: str = "127.0.0.1") -> None:
        port = port_number(port)
        self.page = write_viewer(Path(out_dir))
        self.httpd = _ViewerHTTPServer((host, port), {VIEWER_FILE: self.page.resolve()})
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
