#!/usr/bin/env python3
"""Builds topomech's wheel for `make wheel` and its test (tests/test_wheel.py): a stripped
abi3 manylinux2014 (glibc 2.17) wheel for CPython >= 3.9, with maturin
(``--release --strip --compatibility manylinux2014 --zig``), zig from the ``ziglang``
package (installed into the venv when missing: the local glibc is usually newer than 2.17,
and linking against it would make a wheel for this glibc only).

    python scripts/wheel.py build    build into target/wheels (quiet: maturin's output goes
                                     to .venv/wheel.log, printed when the build fails)
    python scripts/wheel.py start    the same in the background, at the lowest priority
                                     (`make test` starts it first, so that the release
                                     build uses the CPU the other steps leave idle)
    python scripts/wheel.py path     wait for a build started by `start` (if one runs), then
                                     print the wheel's path when it is newer than every
                                     source; exit 3 when there is none
    python scripts/wheel.py develop  `make develop`: wait for or build the wheel, then install
                                     it into .venv as an editable install, like `maturin
                                     develop` (the wheel's extension copied into
                                     python/topomech, a .pth naming python/), so that the
                                     release build is done once for both

The build has a target folder of its own (target/wheel, or $TOPOMECH_WHEEL_TARGET_DIR:
zig's linker is part of cargo's fingerprints, so nothing could be shared with a plain
release build in target/; `make develop` therefore installs this build, see `develop`);
the wheel goes to target/wheels (or $TOPOMECH_WHEEL_DIR). Exit
status: 0 built; 1 the build failed (the log is printed); 2 it cannot be built here
(no cargo, or no zig and ziglang cannot be installed), saying why.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VENV = ROOT / ".venv"
#: Where the wheel goes, and the build's target folder (the variables move them).
WHEELS = Path(os.environ.get("TOPOMECH_WHEEL_DIR", ROOT / "target" / "wheels"))
TARGET = Path(os.environ.get("TOPOMECH_WHEEL_TARGET_DIR", ROOT / "target" / "wheel"))
LOG = VENV / "wheel.log"
PID = WHEELS / ".build-pid"
STATUS = WHEELS / ".build-status"
#: What `make test` waits for a background build at most (seconds).
WAIT = 1800

CANNOT = 2


def python() -> str:
    vpy = VENV / "bin" / "python"
    return str(vpy) if vpy.is_file() else sys.executable


def sources() -> list[Path]:
    """What the wheel is built from."""
    out = [ROOT / "Cargo.toml", ROOT / "Cargo.lock", ROOT / "pyproject.toml"]
    for p in (ROOT / "crates").rglob("*"):
        if (
            p.is_file()
            and (p.suffix == ".rs" or p.name == "Cargo.toml")
            and "target" not in p.parts
        ):
            out.append(p)
    for p in (ROOT / "python" / "topomech").rglob("*"):
        if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith("_core."):
            out.append(p)
    return [p for p in out if p.exists()]


def fresh_wheel() -> Path | None:
    """The wheel in target/wheels when it is newer than every source."""
    wheels = sorted(WHEELS.glob("topomech-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        return None
    newest = max(p.stat().st_mtime for p in sources())
    return wheels[-1] if wheels[-1].stat().st_mtime >= newest else None


def _zig_ok(py: str) -> bool:
    if shutil.which("zig"):
        return True
    r = subprocess.run([py, "-m", "ziglang", "version"], capture_output=True, check=False)
    return r.returncode == 0


def build() -> int:
    """One build at a time (a lock in the wheels' folder): a second one waits for the
    first, then finds its wheel up to date."""
    WHEELS.mkdir(parents=True, exist_ok=True)
    with (WHEELS / ".build-lock").open("w") as lock:
        try:
            import fcntl

            fcntl.flock(lock, fcntl.LOCK_EX)
        except ImportError:  # pragma: no cover - not POSIX
            pass
        return _build()


def _build() -> int:
    done = fresh_wheel()
    if done is not None:
        print(f"make: the wheel is up to date: {_describe(done)}")
        return 0
    LOG.parent.mkdir(parents=True, exist_ok=True)
    py = python()
    env = {**os.environ, "CARGO_TARGET_DIR": str(TARGET), "CARGO_PROFILE_RELEASE_DEBUG": "0"}
    env["PATH"] = f"{Path(py).parent}{os.pathsep}{env.get('PATH', '')}"
    if shutil.which("cargo", path=env["PATH"]) is None:
        print("make: the wheel cannot be built here: no cargo on PATH (Rust)", file=sys.stderr)
        return CANNOT
    print(f"make: building the wheel (release, zig; log: {LOG})", flush=True)
    with LOG.open("w", encoding="utf-8") as log:
        if not _zig_ok(py):
            r = subprocess.run(
                [py, "-m", "pip", "install", "--quiet", "ziglang>=0.13"],
                stdout=log,
                stderr=subprocess.STDOUT,
                check=False,
            )
            if r.returncode != 0 or not _zig_ok(py):
                print(
                    "make: the wheel cannot be built here: no zig, and the ziglang package "
                    f"does not install (log: {LOG})",
                    file=sys.stderr,
                )
                return CANNOT
        for old in WHEELS.glob("topomech-*.whl"):
            old.unlink()
        maturin = Path(py).parent / "maturin"
        cmd = [
            str(maturin) if maturin.is_file() else "maturin",
            "build",
            "--release",
            "--strip",
            "--compatibility",
            "manylinux2014",
            "--zig",
            "--interpreter",
            py,
            "--out",
            str(WHEELS),
        ]
        log.write(f"$ {' '.join(cmd)}\n")
        log.flush()
        started = time.time()
        t = time.perf_counter()
        r = subprocess.run(
            cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, check=False
        )
        log.write(f"(maturin took {time.perf_counter() - t:.0f} s, exit {r.returncode})\n")
    wheels = list(WHEELS.glob("topomech-*.whl"))
    if r.returncode != 0 or len(wheels) != 1:
        sys.stderr.write(LOG.read_text(encoding="utf-8", errors="replace"))
        print(f"make: building the wheel failed (log: {LOG})", file=sys.stderr)
        return 1
    # dated from the build's start: a source changed while it ran makes it out of date
    os.utime(wheels[0], (started, started))
    print(f"make: built {_describe(wheels[0])}")
    return 0


def _describe(wheel: Path) -> str:
    try:
        rel = wheel.relative_to(ROOT)
    except ValueError:
        rel = wheel
    return f"{rel} ({wheel.stat().st_size / 1e6:.1f} MB)"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie (our own child not reaped) counts as finished
    with contextlib.suppress(OSError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat.split(") ", 1)[1][:1] != "Z"
    return True


def running() -> int | None:
    """The pid of a background build still running."""
    try:
        pid = int(PID.read_text().strip())
    except (OSError, ValueError):
        return None
    return pid if _alive(pid) and not STATUS.exists() else None


def start() -> int:
    WHEELS.mkdir(parents=True, exist_ok=True)
    if running() is not None:
        return 0
    STATUS.unlink(missing_ok=True)
    child = (
        "import subprocess, sys\n"
        f"r = subprocess.run([sys.executable, {str(Path(__file__).resolve())!r}, 'build'],"
        " stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
        f"open({str(STATUS)!r}, 'w').write(str(r.returncode))\n"
    )
    p = subprocess.Popen(
        ["nice", "-n", "19", python(), "-c", child]
        if shutil.which("nice")
        else [python(), "-c", child],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    PID.write_text(str(p.pid))
    print(f"make: building the wheel in the background (log: {LOG})")
    return 0


def path() -> int:
    deadline = time.monotonic() + WAIT
    while running() is not None and time.monotonic() < deadline:
        time.sleep(2)
    pid = running()
    if pid is not None:
        with contextlib.suppress(OSError):
            os.killpg(pid, signal.SIGTERM)
        print(f"the background wheel build ran over {WAIT} s", file=sys.stderr)
        return 1
    if STATUS.exists():
        code = STATUS.read_text().strip()
        if code == str(CANNOT):
            print("the background build said the wheel cannot be built here", file=sys.stderr)
            return CANNOT
    wheel = fresh_wheel()
    if wheel is None:
        return 3
    print(wheel)
    return 0


def develop() -> int:
    """An editable install from the wheel: the wheel's files minus the package's, plus a
    ``topomech.pth`` naming ``python/``, installed by pip (entry point, metadata); the
    wheel's extension module copied into ``python/topomech``. The same as ``maturin develop``
    gives, without a second release build (zig's linker makes it a different build)."""
    code = path()
    if code == 3:
        code = build()
        if code == 0:
            code = path()
            if code == 3:
                print(
                    "the wheel just built is older than the sources (one changed during the "
                    "build): run the command again",
                    file=sys.stderr,
                )
    if code != 0:
        return code
    wheel = fresh_wheel()
    assert wheel is not None
    py = python()
    with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(wheel) as src:
        editable = Path(tmp) / wheel.name
        records = []
        with zipfile.ZipFile(editable, "w", zipfile.ZIP_DEFLATED) as dst:
            pth = f"{ROOT / 'python'}\n".encode()
            for info in src.infolist():
                name = info.filename
                if name.startswith("topomech/"):
                    if name == "topomech/_core.abi3.so":
                        so = ROOT / "python" / "topomech" / "_core.abi3.so"
                        tmp_so = so.with_suffix(".so.tmp")
                        tmp_so.write_bytes(src.read(info))
                        tmp_so.chmod(0o755)
                        tmp_so.replace(so)  # atomic: a running import keeps the old file
                    continue
                if name.endswith(".dist-info/RECORD"):
                    record = name
                    continue
                data = src.read(info)
                dst.writestr(info, data)
                records.append(_record_line(name, data))
            dst.writestr("topomech.pth", pth)
            records.append(_record_line("topomech.pth", pth))
            records.append(f"{record},,")
            dst.writestr(record, "\n".join(records) + "\n")
        r = subprocess.run(
            [
                py,
                "-m",
                "pip",
                "install",
                "--quiet",
                "--no-deps",
                "--force-reinstall",
                str(editable),
            ],
            capture_output=True,
            text=True,
            check=False,
        )
    if r.returncode != 0:
        sys.stderr.write(r.stdout + r.stderr)
        print("make: installing the editable package failed", file=sys.stderr)
        return 1
    print(f"make: installed topomech (editable) from {_describe(wheel)}")
    return 0


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def main(argv: list[str]) -> int:
    commands = {"build": build, "start": start, "path": path, "develop": develop}
    if len(argv) != 1 or argv[0] not in commands:
        print(__doc__, file=sys.stderr)
        return 64
    return commands[argv[0]]()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
