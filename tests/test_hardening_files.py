"""Hardening of files in (issue 13): `.tmg` reading is no allocation bomb, a mesh, map, rule,
model or scene path that is an endless stream (`/dev/zero`, a FIFO) is a clean error, `topomech run` refuses a saved
map that is not a valid G-map with its violations, and fuzzing `.tmg` bytes and mesh files
under a memory limit gives only typed errors or valid maps."""

from __future__ import annotations

import json
import os
import random
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import topomech
from topomech import cli
from topomech.scene import load_scene

MAGIC = b"TOPOMECH-GMAP\n"
#: The memory a child may use beyond what it holds after its imports.
HEADROOM = 1 << 30

_LIMITED = """
import resource

def limit_memory(headroom):
    with open("/proc/self/statm") as f:
        size = int(f.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (size + headroom, size + headroom))
"""

pytestmark = pytest.mark.skipif(
    sys.platform != "linux", reason="memory limits and /proc are Linux's"
)


def run_limited(body: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """Runs ``body`` in a fresh interpreter whose address space is capped at what it holds
    after importing topomech plus :data:`HEADROOM`."""
    script = (
        "import topomech, topomech.io, meshio, numpy\n"
        + _LIMITED
        + f"limit_memory({HEADROOM})\n"
        + textwrap.dedent(body)
    )
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return subprocess.run(
        [sys.executable, "-c", script, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        env=env,
    )


def tmg_66_bytes() -> bytes:
    """The issue's file: one dart, one vertex embedding claiming 2^32 - 1 slots."""
    b = MAGIC + struct.pack("<III", 1, 2, 1) + b"\x01" + struct.pack("<4I", 0, 0, 0, 0)
    b += struct.pack("<I", 1) + struct.pack("<I", 1) + b"x"
    b += bytes([0b110, 0, 1, 1, 0, 0]) + struct.pack("<I", 2**32 - 1) + struct.pack("<I", 0)
    assert len(b) == 66
    return b


# ------------------------------------------------------------------ allocation bombs


def test_tmg_claiming_4_billion_slots_is_refused_under_a_memory_limit() -> None:
    r = run_limited(
        """
        import sys
        try:
            topomech.GMap.from_bytes(bytes.fromhex(sys.argv[1]))
        except topomech.FileFormatError as e:
            print("refused:", e)
        """,
        tmg_66_bytes().hex(),
    )
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-2000:]}"
    assert "refused: corrupt file at byte 62: embedding 'x': 4294967295 slots" in r.stdout
    assert "only 4 are left" in r.stdout


# ------------------------------------------------------------------ endless streams


def _stream_paths(tmp_path: Path) -> list[Path]:
    """Mesh and map paths that are endless streams or never end: symlinks to /dev/zero under
    mesh extensions, and FIFOs nobody writes to."""
    paths = []
    for name in ("zero.vtk", "zero.msh", "zero.obj", "zero.tmg", "zero"):
        p = tmp_path / name
        p.symlink_to("/dev/zero")
        paths.append(p)
    for name in ("pipe.vtu", "pipe.tmg"):
        p = tmp_path / name
        os.mkfifo(p)
        paths.append(p)
    return paths


def test_mesh_path_that_is_an_endless_stream_is_a_clean_error(tmp_path: Path) -> None:
    paths = _stream_paths(tmp_path)
    r = run_limited(
        """
        import json, sys
        out = []
        for p in sys.argv[1:]:
            try:
                topomech.read_gmap(p)
                out.append([p, "read", ""])
            except topomech.TopomechError as e:
                out.append([p, type(e).__name__, str(e)])
        print(json.dumps(out))
        """,
        *map(str, paths),
        timeout=30,
    )
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-2000:]}"
    results = json.loads(r.stdout)
    assert [p for p, _, _ in results] == [str(p) for p in paths]
    for p, kind, msg in results:
        assert kind in ("MeshReadError", "FileFormatError"), (p, kind, msg)
        assert msg.startswith(p), (p, msg)
        assert "not a regular file" in msg, (p, msg)


def test_info_on_dev_zero_exits_with_a_message_not_a_traceback(tmp_path: Path) -> None:
    zero = tmp_path / "zero.vtk"
    zero.symlink_to("/dev/zero")
    r = subprocess.run(
        [sys.executable, "-m", "topomech", "info", str(zero)],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr, r.stderr[-2000:]
    assert "MemoryError" not in r.stderr, r.stderr[-2000:]
    assert f"{zero}: not a regular file" in r.stderr


def test_scene_mesh_file_on_a_fifo_names_mesh_file(tmp_path: Path) -> None:
    pipe = tmp_path / "pipe.msh"
    os.mkfifo(pipe)
    scene = tmp_path / "s.toml"
    scene.write_text(f'[mesh]\nfile = "{pipe.name}"\n[[model]]\nkind = "linear_fem"\n')
    with pytest.raises(topomech.SceneError, match=r"mesh\.file: .*pipe\.msh: not a regular file"):
        load_scene(scene).load_mesh()


# ------------------------------------------------------------------ rule, model and scene files


def _rule_stream_paths(tmp_path: Path) -> list[Path]:
    """Rule file paths that are endless streams or never end: a symlink to /dev/zero and a
    FIFO nobody writes to."""
    zero = tmp_path / "zero.tmr"
    zero.symlink_to("/dev/zero")
    pipe = tmp_path / "ff.tmr"
    os.mkfifo(pipe)
    return [Path("/dev/zero"), zero, pipe]


def test_rule_and_model_files_that_are_streams_are_refused_before_reading(
    tmp_path: Path,
) -> None:
    """RuleSet.load read /dev/zero until memory ran out and Model.load exhausted memory on it
    (a FIFO blocked both): now each is refused by name before anything is read, within a
    memory limit and a timeout, as mesh and map paths are."""
    paths = _rule_stream_paths(tmp_path)
    r = run_limited(
        """
        import json, sys
        out = []
        for p in sys.argv[1:]:
            try:
                topomech.RuleSet.load([p], 2)
                out.append([p, "RuleSet.load", "read", ""])
            except topomech.RuleError as e:
                out.append([p, "RuleSet.load", type(e).__name__, str(e)])
            try:
                topomech.Model.load(p)
                out.append([p, "Model.load", "read", ""])
            except OSError as e:
                out.append([p, "Model.load", type(e).__name__, str(e)])
        print(json.dumps(out))
        """,
        *map(str, paths),
        timeout=30,
    )
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-2000:]}"
    results = json.loads(r.stdout)
    assert [p for p, _, _, _ in results] == [str(p) for p in paths for _ in range(2)]
    for p, loader, kind, msg in results:
        assert kind == ("RuleError" if loader == "RuleSet.load" else "OSError"), (p, kind, msg)
        assert p in msg, (p, loader, msg)
        assert "not a regular file" in msg, (p, loader, msg)


def test_model_load_of_a_directory_names_it(tmp_path: Path) -> None:
    with pytest.raises(IsADirectoryError, match="is a directory, not a rule file") as e:
        topomech.Model.load(tmp_path)
    assert e.value.filename == str(tmp_path)


@pytest.mark.parametrize("command", ["check", "models", "apply"])
def test_cli_on_a_rule_file_that_is_a_stream_exits_2_at_once(tmp_path: Path, command: str) -> None:
    """`topomech check /dev/zero` grew memory forever and `check ff.tmr` (a FIFO) blocked:
    both are refused by name with exit 2, as any unreadable rule file is."""
    sheet = tmp_path / "sheet.obj"
    sheet.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    for p in _rule_stream_paths(tmp_path):
        args = {
            "check": ["check", str(p)],
            "models": ["models", str(p)],
            "apply": ["apply", str(sheet), str(p), "r", "--everywhere", "--out", "x.tmg"],
        }[command]
        r = subprocess.run(
            [sys.executable, "-m", "topomech", *args],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
            cwd=tmp_path,
        )
        assert r.returncode == 2, (p, r.returncode, r.stdout, r.stderr[-2000:])
        assert "Traceback" not in r.stderr, r.stderr[-2000:]
        assert f"{p}: cannot read the rule file: not a regular file" in r.stderr, r.stderr


def test_scene_model_file_and_scene_file_that_are_streams_are_refused(tmp_path: Path) -> None:
    """A scene `[[model]] file = "/dev/zero"` hung `topomech run`: now the scene's key names
    it; a scene file that is a FIFO is refused by name too."""
    for p in _rule_stream_paths(tmp_path):
        scene = tmp_path / "s.toml"
        scene.write_text(f'[mesh]\ngenerator = "grid"\n[[model]]\nfile = "{p}"\n')
        with pytest.raises(
            topomech.SceneError,
            match=r"model\[0\]\.file: cannot read the rule file .*: not a regular file",
        ):
            load_scene(scene)
    pipe = tmp_path / "scene.toml"
    os.mkfifo(pipe)
    with pytest.raises(topomech.SceneError, match=r"scene\.toml: .*not a regular file"):
        load_scene(pipe)


# ------------------------------------------------------------------ invalid saved maps

SCENE = """
[mesh]
file = "{file}"

[[model]]
kind = "stretch_elementary"
stiffness = 100.0

[material]
density = 1.0

[[fix]]
where = "x < 1e-9"

[integrator]
kind = "symplectic_euler"
dt = 1e-3
steps = 3
"""


def corrupted_maps(n: int, seed: int = 13) -> list[bytes]:
    """``n`` saved maps that load but are not valid G-maps: links of a 2x2 triangle grid
    pointed at other darts (fixed seed)."""
    g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    base = g.to_bytes()
    cap = struct.unpack_from("<I", base, 22)[0]
    links = 26 + cap
    rng = random.Random(seed)
    out: list[bytes] = []
    while len(out) < n:
        b = bytearray(base)
        for _ in range(rng.randint(1, 3)):
            k = links + 4 * rng.randrange(4 * cap)
            b[k : k + 4] = struct.pack("<I", rng.randrange(cap))
        try:
            h = topomech.GMap.from_bytes(bytes(b))
        except topomech.FileFormatError:
            continue
        if not h.is_valid():
            out.append(bytes(b))
    return out


def test_run_refuses_a_saved_map_that_is_not_a_valid_gmap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    maps = corrupted_maps(12)
    for i, b in enumerate(maps):
        tmg = tmp_path / f"bad{i}.tmg"
        tmg.write_bytes(b)
        scene = tmp_path / f"bad{i}.toml"
        scene.write_text(SCENE.format(file=tmg.name))
        out = tmp_path / f"o{i}"
        code = cli.main(["run", str(scene), "--out", str(out), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2, f"map {i} was run (exit {code}): {err}"
        assert f"{scene}: mesh.file: {tmg} is not a valid G-map" in err, err
        # the violations are listed, as `topomech info` lists them
        first = topomech.GMap.from_bytes(b).violations()[0]
        assert first in err, err
        assert not out.exists()


def test_scene_on_a_valid_saved_map_still_runs(tmp_path: Path) -> None:
    g = topomech.GMap.from_flat(*topomech._core.grid(2, 2, 1.0, 1.0, "triangle"))
    g.save(tmp_path / "ok.tmg")
    scene = tmp_path / "ok.toml"
    scene.write_text(SCENE.format(file="ok.tmg"))
    sim = load_scene(scene).build()
    assert sim is not None


def test_scene_on_an_unreadable_saved_map_names_mesh_file(tmp_path: Path) -> None:
    (tmp_path / "junk.tmg").write_bytes(b"TOPOMECH-GMAP\n\x01\x00")
    scene = tmp_path / "junk.toml"
    scene.write_text(SCENE.format(file="junk.tmg"))
    with pytest.raises(topomech.SceneError, match=r"mesh\.file: .*junk\.tmg: file truncated"):
        load_scene(scene).build()


# ------------------------------------------------------------------ fuzzing under a limit

_FUZZ = """
import json, random, sys, time
import numpy as np
from pathlib import Path

work = Path(sys.argv[1])
rng = random.Random(20261129)

def outcome(what, f):
    try:
        r = f()
    except topomech.TopomechError:
        return None
    except BaseException as e:  # anything else, MemoryError included, is a finding
        return f"{what}: {type(e).__name__}: {e}"[:300]
    return r(what) if callable(r) else None

def mutate(b):
    b = bytearray(b)
    kind = rng.randrange(4)
    if kind == 0:
        for _ in range(rng.randint(1, 6)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif kind == 1:
        del b[rng.randrange(len(b)):]
    elif kind == 2:
        k = rng.randrange(len(b))
        del b[k:k + rng.randint(1, 32)]
    else:
        # a count made huge: a run of digits, or 4 bytes of a binary count
        digits = [i for i in range(len(b)) if 48 <= b[i] <= 57]
        if digits and rng.random() < 0.7:
            k = rng.choice(digits)
            b[k:k + 1] = str(rng.choice([10**9, 2**31, 10**12, 2**63])).encode()
        else:
            k = rng.randrange(max(1, len(b) - 4))
            b[k:k + 4] = rng.choice([2**32 - 1, 2**31, 2**24]).to_bytes(4, "little")
    return bytes(b)

findings = []

# .tmg bytes: a map with every kind of embedding
g = topomech.GMap.from_flat(*topomech._core.grid(3, 2, 1.0, 1.0, "quad"))
base = g.to_bytes()

def check_map(h):
    def judge(what):
        v = h.violations()
        h.cell_counts()
        assert isinstance(v, list)
        return None
    return judge

for i in range(1500):
    b = mutate(base)
    f = outcome(f"tmg #{i}", lambda: check_map(topomech.GMap.from_bytes(b)))
    if f:
        findings.append(f)
# every 4-byte window past the header set to a huge count: each count field is hit
for k in range(14, len(base) - 3):
    b = base[:k] + (2**32 - 1).to_bytes(4, "little") + base[k + 4:]
    f = outcome(f"tmg window {k}", lambda: check_map(topomech.GMap.from_bytes(b)))
    if f:
        findings.append(f)

# mesh files written by meshio, mutated, read through read_gmap
import meshio
pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
cells = [("triangle", np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]))]
mesh = meshio.Mesh(pts, cells)
sources = {}
for name, kw in [
    ("m.vtu", {}),
    ("m.msh", {"file_format": "gmsh22", "binary": False}),
    ("m.vtk", {"binary": False}),
    ("m.obj", {}),
]:
    meshio.write(work / name, mesh, **kw)
    sources[name] = (work / name).read_bytes()

def valid_map(res):
    def judge(what):
        gm, _ = res
        if not gm.is_valid():
            return f"{what}: an invalid map: {gm.violations()[:3]}"
        return None
    return judge

for i in range(60):
    for name, data in sources.items():
        p = work / f"f{i}-{name}"
        p.write_bytes(mutate(data))
        f = outcome(f"{name} #{i}", lambda: valid_map(topomech.read_gmap(p)))
        if f:
            findings.append(f)
        p.unlink()

print(json.dumps(findings))
"""


def test_fuzz_tmg_bytes_and_mesh_files_under_a_memory_limit(tmp_path: Path) -> None:
    """Mutated `.tmg` bytes (GMap.from_bytes) and mutated VTU, Gmsh 2.2, VTK and OBJ files
    (read_gmap), fixed seed, in a child capped at 1 GiB over its imports: each gives a
    topomech error or a valid map, nothing else (no crash, no MemoryError, no other
    exception)."""
    r = run_limited(_FUZZ, str(tmp_path), timeout=120)
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-3000:]}"
    findings = json.loads(r.stdout.strip().splitlines()[-1])
    assert findings == [], "\n".join(findings[:20])
