"""The wheel installs anywhere: `make wheel` (scripts/wheel.py) builds a stripped abi3
manylinux2014 wheel; installed into a fresh virtual environment, with no Rust on PATH and
away from this checkout, it runs the demo scene.

The wheel is the one `make wheel` (or `make test`, which builds it in the background while
the other steps run) left in target/wheels when it is newer than every source; else this
test builds it (a release build: minutes). ``TOPOMECH_WHEEL=path.whl`` tests that wheel;
``TOPOMECH_SKIP_WHEEL=1`` skips the test (for a quick pytest run without a fresh wheel).
Skipped, saying why, only where the wheel cannot be built (no cargo; no zig and the ziglang
package does not install) or its dependencies cannot be downloaded."""

from __future__ import annotations

import json
import os
import re
import shutil
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "wheel.py"
#: The oldest glibc a manylinux2014 wheel may need.
GLIBC_MAX = (2, 17)


def _wheel() -> Path:
    if os.environ.get("TOPOMECH_SKIP_WHEEL"):
        pytest.skip("TOPOMECH_SKIP_WHEEL is set: the wheel is neither built nor tested")
    given = os.environ.get("TOPOMECH_WHEEL")
    if given:
        return Path(given)
    r = subprocess.run([sys.executable, str(SCRIPT), "path"], capture_output=True, text=True)
    if r.returncode == 3:  # none fresh: build it
        r = subprocess.run(
            [sys.executable, str(SCRIPT), "build"], capture_output=True, text=True, timeout=3600
        )
        if r.returncode == 0:
            r = subprocess.run(
                [sys.executable, str(SCRIPT), "path"], capture_output=True, text=True
            )
    if r.returncode == 2:
        pytest.skip(f"the wheel cannot be built here: {r.stderr.strip()}")
    assert r.returncode == 0, f"building the wheel failed:\n{r.stderr[-4000:]}"
    return Path(r.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def wheel() -> Path:
    w = _wheel()
    assert w.is_file(), w
    return w


def _elf_sections(data: bytes) -> list[str]:
    """The section names of a 64-bit little-endian ELF file."""
    assert data[:4] == b"\x7fELF"
    assert data[4] == 2  # 64-bit
    assert data[5] == 1  # little-endian
    shoff = struct.unpack_from("<Q", data, 0x28)[0]
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    headers = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
    strtab = headers[shstrndx]
    names = data[strtab[4] : strtab[4] + strtab[5]]
    return [names[h[0] : names.index(b"\0", h[0])].decode() for h in headers]


def test_the_wheel_is_abi3_manylinux2014_and_stripped(wheel: Path) -> None:
    name = wheel.name
    assert re.match(r"topomech-[^-]+-cp39-abi3-.*manylinux_2_17_x86_64", name), name
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        libs = [n for n in names if n.endswith(".so") or ".so." in n]
        assert libs == ["topomech/_core.abi3.so"], libs  # no develop build copied in
        so = z.read(libs[0])
        for must in ("topomech/scenes/corotational.toml", "topomech/web/viewer.html"):
            assert must in names, must
    sections = _elf_sections(so)
    assert not [s for s in sections if s.startswith(".debug")], sections
    assert ".symtab" not in sections  # stripped
    glibc = {tuple(int(x) for x in v.split(b".")) for v in re.findall(rb"GLIBC_(\d+\.\d+)", so)}
    assert glibc, "no versioned glibc symbols found"
    assert max(glibc) <= GLIBC_MAX, sorted(glibc)
    print(f"{name}: {wheel.stat().st_size / 1e6:.1f} MB, _core.abi3.so {len(so) / 1e6:.1f} MB")
    assert len(so) < 15e6  # 18 MB with debug information before


def _no_rust_path() -> str:
    """PATH without the folders that have cargo or rustc."""
    keep = []
    for d in os.environ.get("PATH", "").split(os.pathsep):
        if d and not any((Path(d) / t).exists() for t in ("cargo", "rustc", "rustup")):
            keep.append(d)
    return os.pathsep.join(keep)


def test_the_wheel_installs_in_a_fresh_venv_and_runs_the_demo(wheel: Path, tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("CARGO", "RUSTUP", "PYTHON", "VIRTUAL_ENV", "TOPOMECH"))
    }
    env.update(PATH=_no_rust_path(), PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INPUT="1")
    assert shutil.which("cargo", path=env["PATH"]) is None
    assert shutil.which("rustc", path=env["PATH"]) is None
    r = subprocess.run(
        [str(py), "-m", "pip", "install", "--quiet", str(wheel)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=900,
    )
    if r.returncode != 0 and re.search(
        r"(?i)connection|network|temporary failure in name resolution|no matching distribution",
        r.stderr,
    ):
        pytest.skip(f"the wheel's dependencies cannot be downloaded here: {r.stderr[-500:]}")
    assert r.returncode == 0, r.stderr[-4000:]
    where = subprocess.run(
        [
            str(py),
            "-c",
            "import topomech, sys; print(topomech.__file__); print(topomech.__version__)",
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        check=True,
    ).stdout.split()
    assert Path(where[0]).is_relative_to(venv), where  # the installed copy, not the checkout
    out = tmp_path / "demo"
    r = subprocess.run(
        [str(venv / "bin" / "topomech"), "demo", "--steps", "3", "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 3
    assert "error" not in summary
    assert (out / "preview.gif").is_file()
    assert (out / "energy.png").is_file()
