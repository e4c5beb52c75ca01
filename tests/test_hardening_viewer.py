"""Hardening of `topomech view` (issue 13): the server answers only for the page the viewer
wrote, only to a local `Host`, and without a traceback on odd paths or clients that hang up;
a bad `--port` is a usage error.

The server runs as `python -m topomech view DIR` in a subprocess (its stderr is read back to
check that no traceback was printed), on a free port it prints; requests are raw HTTP on
127.0.0.1 only."""

from __future__ import annotations

import http.client
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from topomech import cli
from topomech.run import run_scene
from topomech.viewer import VIEWER_FILE, Server, write_viewer

SHEET = """
name = "sheet"
[mesh]
generator = "grid"
element = "quad"
size = [1.0, 1.0]
cells = [2, 2]
[[model]]
kind = "stretch_elementary"
stiffness = 100.0
[material]
density = 1.0
[[fix]]
where = "y > 1.0 - 1e-9"
[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 4
[output]
every = 2
"""

SECRET = "top secret, not for the viewer"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("hardening_viewer")
    scene = root / "sheet.toml"
    scene.write_text(SHEET)
    out = root / "out"
    summary = run_scene(scene, out, preview=False)
    assert "error" not in summary
    (root / "secret.txt").write_text(SECRET)  # next to the run folder, outside it
    (out / "sub").mkdir()
    (out / "sub" / "inner.txt").write_text(SECRET)
    return out


class Served:
    """A `topomech view` subprocess and its port."""

    def __init__(self, out: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "topomech", "view", str(out)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
        assert m, f"no address in {line!r}"
        self.port = int(m.group(1))
        self.lines: list[str] = []
        self.reader = threading.Thread(target=self._read_stderr, daemon=True)
        self.reader.start()

    def _read_stderr(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line)

    def stderr(self) -> str:
        """What the server wrote on stderr so far (after a moment for it to arrive)."""
        time.sleep(0.3)
        return "".join(self.lines)

    def request(
        self, path: str, host: str | None = "localhost", method: str = "GET"
    ) -> tuple[int, dict[str, str], bytes]:
        """Sends a raw request (the path as given, not quoted); the status, headers, body."""
        lines = [f"{method} {path} HTTP/1.1"]
        if host is not None:
            lines.append(f"Host: {host}")
        lines += ["Connection: close", "", ""]
        with socket.create_connection(("127.0.0.1", self.port), timeout=10) as s:
            s.sendall("\r\n".join(lines).encode("latin-1"))
            resp = http.client.HTTPResponse(s)
            resp.begin()
            body = resp.read()
            return resp.status, {k.lower(): v for k, v in resp.getheaders()}, body

    def stop(self) -> str:
        """Stops the server with Ctrl-C; returns its stderr."""
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.reader.join(timeout=10)
        return "".join(self.lines)


@pytest.fixture(scope="module")
def served(run_dir: Path) -> Iterator[Served]:
    """One server for the module; every test that checks stderr sees all it printed."""
    s = Served(run_dir)
    try:
        yield s
    finally:
        if s.proc.poll() is None:
            s.stop()


def test_server_lists_no_directory(served: Served) -> None:
    status, headers, body = served.request(f"/{VIEWER_FILE}?t=1", host=f"127.0.0.1:{served.port}")
    assert status == 200
    assert headers["content-type"].startswith("text/html")
    assert b'id="view-meta"' in body
    # the root redirects to the page; no folder is ever listed
    status, headers, body = served.request("/")
    assert status == 302
    assert headers["location"] == f"/{VIEWER_FILE}"
    assert b"view.json" not in body
    for path in ("/sub/", "/sub", "/./", "/sub/."):
        status, _, body = served.request(path)
        assert status == 404, path
        assert b"inner.txt" not in body
        assert b"view.json" not in body


def test_server_refuses_files_it_did_not_write(served: Served) -> None:
    for path in ("/view.json", "/view.bin", "/summary.json", "/sub/inner.txt"):
        status, _, body = served.request(path)
        assert status == 404, path
        assert SECRET.encode() not in body


def test_server_refuses_paths_leaving_the_folder(served: Served) -> None:
    for path in (
        "/../secret.txt",
        "/%2e%2e/secret.txt",
        "/..%2fsecret.txt",
        "/sub/../../secret.txt",
        "/%2E%2E%2Fsecret.txt",
        "//etc/passwd",
        "/sub/../sub/inner.txt",  # inside the folder, but not written by the viewer
    ):
        status, _, body = served.request(path)
        assert status in (400, 404), path
        assert SECRET.encode() not in body
        assert b"root:" not in body
    assert "Traceback" not in served.stderr()


def test_server_refuses_a_symlink_leading_outside(run_dir: Path, tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    with Server(run_dir) as server:
        page = run_dir / VIEWER_FILE
        page.unlink()
        page.symlink_to(secret)
        try:
            host, port = server.httpd.server_address[:2]
            conn = http.client.HTTPConnection(str(host), port, timeout=10)
            conn.request("GET", f"/{VIEWER_FILE}")
            resp = conn.getresponse()
            body = resp.read()
            conn.close()
            assert resp.status == 404
            assert SECRET.encode() not in body
        finally:
            page.unlink()
            write_viewer(run_dir)


def test_writing_the_page_replaces_a_symlink_without_following_it(
    run_dir: Path, tmp_path: Path
) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text(SECRET)
    page = run_dir / VIEWER_FILE
    page.unlink()
    page.symlink_to(victim)
    write_viewer(run_dir)
    assert victim.read_text() == SECRET
    assert not page.is_symlink()
    assert 'id="view-meta"' in page.read_text()


def test_server_refuses_a_foreign_host_header(served: Served) -> None:
    for host in ("evil.example", "evil.example:80", "127.0.0.1.evil.example", "localhost.evil"):
        status, _, body = served.request(f"/{VIEWER_FILE}", host=host)
        assert status in (403, 421), host
        assert b"view-meta" not in body
    for host in ("localhost", "LOCALHOST:1", "127.0.0.1", "[::1]", "[::1]:8000"):
        status, _, _ = served.request(f"/{VIEWER_FILE}", host=host)
        assert status == 200, host


def test_server_refuses_a_request_without_host(served: Served) -> None:
    status, _, body = served.request(f"/{VIEWER_FILE}", host=None)
    assert status == 400
    assert b"view-meta" not in body


@pytest.mark.parametrize("path", ["/%00", "/viewer.html%00", "/%00/../secret.txt", "/a%00b"])
def test_server_nul_path_gives_no_traceback(served: Served, path: str) -> None:
    status, _, _ = served.request(path)
    assert status in (400, 404)
    # the server still answers
    status, _, _ = served.request(f"/{VIEWER_FILE}")
    assert status == 200
    err = served.stderr()
    assert "Traceback" not in err, err
    assert "ValueError" not in err, err
    assert served.proc.poll() is None


def test_server_client_hanging_up_gives_no_traceback(served: Served) -> None:
    linger_rst = struct.pack("ii", 1, 0)  # close with a reset, at once
    for partial in (
        b"GET /viewer.html HTTP/1.1\r\nHost: localhost\r\n\r\n",
        b"GET /viewer.html HTTP/1.1\r\nHo",
        b"",
    ):
        for _ in range(5):
            s = socket.create_connection(("127.0.0.1", served.port), timeout=10)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, linger_rst)
            if partial:
                s.sendall(partial)
            s.close()
    time.sleep(0.5)
    status, _, _ = served.request(f"/{VIEWER_FILE}")
    assert status == 200
    err = served.stderr()
    assert "Traceback" not in err, err
    assert "ConnectionResetError" not in err, err
    assert "BrokenPipeError" not in err, err


@pytest.mark.parametrize("port", ["70000", "65536", "-1", "http", "8.5"])
def test_view_bad_port_is_a_usage_error(
    run_dir: Path, port: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        cli.main(["view", str(run_dir), "--port", port])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--port" in err
    assert "0 to 65535" in err
    assert "Traceback" not in err


def test_view_bad_port_exits_2_from_the_command_line(run_dir: Path) -> None:
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "view", str(run_dir), "--port", "99999"],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "0 to 65535" in r.stderr


def test_server_refuses_a_port_out_of_range(run_dir: Path) -> None:
    with pytest.raises(ValueError, match="port must be an integer from 0 to 65535"):
        Server(run_dir, 70000)


def test_the_up_direction_survives_a_huge_gravity() -> None:
    """The viewer's up vector is the unit vector opposite to gravity, computed without
    overflow for a gravity past 1.3e154 (where the plain norm's squares overflow; it was
    written as (-0, -0, -0) with a numpy RuntimeWarning), and +y for zero gravity."""
    import warnings

    import numpy as np

    from topomech.recording import _up_of

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(_up_of([0.0, 1e308, 0.0]), [-0.0, -1.0, -0.0])
        np.testing.assert_allclose(_up_of([3e300, 0.0, -4e300]), [-0.6, 0.0, 0.8], rtol=1e-15)
        np.testing.assert_allclose(_up_of([0.0, -9.81, 0.0]), [0.0, 1.0, 0.0], rtol=1e-15)
        np.testing.assert_array_equal(_up_of([0.0, 0.0, 0.0]), [0.0, 1.0, 0.0])
