"""Issue 13, files out: a run writes only inside its output folder, deletes only what a run
wrote there (its manifest), never through a symbolic link, and a Ctrl-C or a full disk at any
moment leaves a summary.json saying what happened, the message naming a folder that exists or
the file that could not be written. Each test was run against the code before this change
and failed there (see the report of part 13a)."""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import meshio
import pytest

import topomech.run as run_mod
from topomech import cli
from topomech._core import SceneError
from topomech._manifest import MANIFEST, OutputError, read_manifest
from topomech.run import run_scene
from topomech.scene import load_scene, parse_scene, shipped_scenes

SPRINGS = """
{name}
[mesh]
generator = "grid"
element = "tri"
size = [1.0, 1.0]
cells = [{cells}, {cells}]

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
steps = {steps}

[output]
every = {every}
"""


def springs(d: Path, *, name: str = "", steps: int = 6, every: int = 2, cells: int = 2) -> Path:
    """A small 2D spring scene (a few ms a step) written to ``d/springs.toml``."""
    p = d / "springs.toml"
    p.write_text(SPRINGS.format(name=name, steps=steps, every=every, cells=cells))
    return p


def files_under(d: Path) -> set[str]:
    """Every file and link under ``d`` (relative, ``/`` separators), links not followed."""
    found = set()
    for root, dirs, names in os.walk(d):
        for n in names + [x for x in dirs if (Path(root) / x).is_symlink()]:
            found.add((Path(root) / n).relative_to(d).as_posix())
    return found


# ---------------------------------------------------------------------- 1. scene name


BAD_NAMES = {
    "parent": "../../x",
    "absolute": "/tmp/topomech-escape",
    "separator": "a/b",
    "backslash": "a\\\\b",
    "nul": "a\\u0000b",
    "dot": ".",
    "dotdot": "..",
    "empty": "",
    "drive": "C:x",
    "control": "a\\nb",
    "blank": " ",
    "trailing-blank": "x ",
    "leading-dash": "-rf",
}


@pytest.mark.parametrize("kind", sorted(BAD_NAMES))
def test_scene_name_that_would_leave_the_output_folder_is_refused(
    kind: str, tmp_path: Path
) -> None:
    """A `name` used as `out/<name>` that is not one plain folder name is a SceneError naming
    the file and the key `name`, at load (before: accepted, and `out/../../x` written)."""
    scene = springs(tmp_path, name=f'name = "{BAD_NAMES[kind]}"')
    with pytest.raises(SceneError) as e:
        load_scene(scene)
    assert str(e.value).startswith(f"{scene}: name: ")
    assert e.value.key == "name"  # type: ignore[attr-defined]


def test_cli_run_with_an_escaping_name_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`topomech run` without --out on `name = "../escaped"`: exit 2, nothing created next
    to the working directory (before: exit 0 and `./escaped/` written outside `out/`)."""
    work = tmp_path / "work"
    work.mkdir()
    scene = springs(tmp_path, name='name = "../escaped"')
    monkeypatch.chdir(work)
    assert cli.main(["run", str(scene), "-q", "--no-preview"]) == 2
    err = capsys.readouterr().err
    assert "name:" in err
    assert "path separator" in err
    assert not (work / "escaped").exists()
    assert not (tmp_path / "escaped").exists()
    assert not (work / "out").exists()


def test_a_file_name_that_is_no_folder_name_is_refused(tmp_path: Path) -> None:
    """Without `name` the name is the file's stem: `..toml` gives `.` (before: accepted,
    and the run wrote straight into `out/`)."""
    p = tmp_path / "..toml"
    p.write_text(springs(tmp_path).read_text())
    with pytest.raises(SceneError, match=r"name: .*comes from the file name"):
        load_scene(p)


def test_run_scene_refuses_a_bad_name_set_in_python(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Scene whose name was changed in Python (not read from a file) is checked too when
    it makes the default folder (before: `out/../x` was written)."""
    monkeypatch.chdir(tmp_path)
    sc = dataclasses.replace(load_scene(springs(tmp_path)), name="../x")
    with pytest.raises(SceneError, match="name:"):
        run_scene(sc, preview=False)
    assert not (tmp_path / "x").exists()
    assert not (tmp_path / "out").exists()


def test_shipped_scene_names_are_accepted() -> None:
    """The check refuses nothing that ships (every shipped scene loads)."""
    for name, path in shipped_scenes().items():
        assert load_scene(path).name == name
    assert (
        parse_scene(
            'name = "beam v2 (ü)"\n' + SPRINGS.format(name="", steps=1, every=1, cells=1)
        ).name
        == "beam v2 (ü)"
    )


# ---------------------------------------------------------------------- 2. the manifest


def test_manifest_lists_every_file_before_it_is_created(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each VTU the run writes is in the manifest when its writer starts (so a crash leaves
    a manifest that is true), and at the end the manifest lists exactly the files there
    (before: no manifest)."""
    out = tmp_path / "o"
    seen: list[str] = []
    real = meshio.write

    def spy(path: Any, *a: Any, **kw: Any) -> None:
        rel = Path(path).relative_to(out).as_posix()
        assert rel in (read_manifest(out) or []), f"{rel} written before it was listed"
        # (a VTU is written through `<name>.part`, listed too, then renamed)
        seen.append(rel.removesuffix(".part"))
        real(path, *a, **kw)

    monkeypatch.setattr(meshio, "write", spy)
    run_scene(springs(tmp_path), out)
    assert "final.vtu" in seen
    assert "frames/frame_00003.vtu" in seen
    listed = set(read_manifest(out) or [])
    on_disk = files_under(out) - {MANIFEST}
    assert on_disk <= listed, on_disk - listed
    assert {"summary.json", "final.vtu", "view.json", "view.bin", "frames"} <= listed


def test_a_folder_with_files_no_run_wrote_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder holding the user's files (one named like an output included) is refused
    with the files and the option named, nothing touched; exit 2 from the CLI (before: the
    run overwrote final.vtu and exit 0)."""
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "final.vtu").write_text("my own final.vtu")
    scene = springs(tmp_path)
    with pytest.raises(OutputError) as e:
        run_scene(scene, out)
    assert "final.vtu" in str(e.value)
    assert "notes.txt" in str(e.value)
    assert "--overwrite" in str(e.value)
    assert cli.main(["run", str(scene), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "notes.txt" in err
    assert "--overwrite" in err
    assert files_under(out) == {"notes.txt", "final.vtu"}
    assert (out / "final.vtu").read_text() == "my own final.vtu"


def test_a_damaged_manifest_is_named_as_such(tmp_path: Path) -> None:
    """A manifest that cannot be read (here, garbage bytes) makes the folder refused (its
    files cannot be told apart), and the message says the manifest is the problem, not that
    topomech's own outputs were written by someone else."""
    out = tmp_path / "o"
    scene = springs(tmp_path)
    run_scene(scene, out, preview=False)
    (out / MANIFEST).write_bytes(b"garbage\xff")
    with pytest.raises(OutputError) as e:
        run_scene(scene, out, preview=False)
    assert f"its manifest ({MANIFEST}) cannot be read" in str(e.value)
    assert "did not write" not in str(e.value)
    assert "--overwrite" in str(e.value)


def test_a_refusal_names_a_few_files_and_counts_the_rest(tmp_path: Path) -> None:
    out = tmp_path / "o"
    out.mkdir()
    for i in range(12):
        (out / f"data{i:02d}.csv").write_text("x")
    with pytest.raises(OutputError, match=r"data04\.csv and 7 more"):
        run_scene(springs(tmp_path), out)


def test_overwrite_replaces_outputs_and_keeps_the_other_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--overwrite: files named like outputs are replaced, the others kept, and a rerun
    then works without it (the manifest now lists the outputs; the user's file stays
    foreign, so a plain rerun is still refused)."""
    out = tmp_path / "o"
    (out / "frames").mkdir(parents=True)
    (out / "notes.txt").write_text("mine")
    (out / "final.vtu").write_text("stale")
    (out / "frames" / "frame_00099.vtu").write_text("stale frame")
    scene = springs(tmp_path)
    assert cli.main(["run", str(scene), "--out", str(out), "-q", "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "mine"
    assert len(meshio.read(out / "final.vtu").points) == 9
    assert not (out / "frames" / "frame_00099.vtu").exists()
    assert cli.main(["run", str(scene), "--out", str(out), "-q"]) == 2  # notes.txt
    (out / "notes.txt").unlink()
    capsys.readouterr()
    assert cli.main(["run", str(scene), "--out", str(out), "-q", "--steps", "2"]) == 0
    assert sorted(p.name for p in (out / "frames").iterdir()) == [
        "frame_00000.vtu",
        "frame_00001.vtu",
    ]


def test_a_rerun_removes_only_listed_files(tmp_path: Path) -> None:
    """A file the user adds to a run's folder after the run is not deleted by a rerun: the
    rerun is refused (before: the rerun went ahead; a file in frames/ named like a frame
    was deleted)."""
    out = tmp_path / "o"
    scene = springs(tmp_path)
    run_scene(scene, out, preview=False)
    (out / "frames" / "frame_00042.vtu").write_text("the user's")
    with pytest.raises(OutputError, match="frame_00042"):
        run_scene(scene, out, preview=False)
    assert (out / "frames" / "frame_00042.vtu").read_text() == "the user's"


def test_manifest_entries_outside_the_folder_are_never_deleted(tmp_path: Path) -> None:
    """A manifest edited to list `../victim`, an absolute path or `frames/../../victim2` is
    harmless: those are ignored, never deleted, and the rewritten manifest drops them
    (before: no manifest was read or written)."""
    out = tmp_path / "o"
    out.mkdir()
    victims = [tmp_path / "victim", tmp_path / "victim2", tmp_path / "victim3"]
    for v in victims:
        v.write_text("keep")
    lines = [
        {"topomech_manifest": 1},
        "../victim",
        str(victims[2]),
        "frames/../../victim2",
        "",
        ".",
    ]
    (out / MANIFEST).write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    run_scene(springs(tmp_path), out, preview=False)
    assert all(v.read_text() == "keep" for v in victims)
    listed = read_manifest(out) or []
    assert not any(".." in x or x.startswith("/") for x in listed)
    assert "final.vtu" in listed


def test_frames_link_to_elsewhere_is_never_emptied(tmp_path: Path) -> None:
    """A run's `frames` folder replaced by a link to another folder, and `final.vtu` by a
    link to another file: the rerun removes the links, never what they point to, and writes
    real files (before: the frame_*.vtu files in the link's target were deleted)."""
    out = tmp_path / "o"
    scene = springs(tmp_path)
    run_scene(scene, out, preview=False)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    for name in ("frame_00000.vtu", "frame_00001.vtu", "keep.txt"):
        (elsewhere / name).write_text("precious")
    target = tmp_path / "target.vtu"
    target.write_text("precious")
    for p in (out / "frames").iterdir():
        p.unlink()
    (out / "frames").rmdir()
    (out / "frames").symlink_to(elsewhere, target_is_directory=True)
    (out / "final.vtu").unlink()
    (out / "final.vtu").symlink_to(target)
    s = run_scene(scene, out, preview=False)
    assert sorted(p.name for p in elsewhere.iterdir()) == [
        "frame_00000.vtu",
        "frame_00001.vtu",
        "keep.txt",
    ]
    assert all(p.read_text() == "precious" for p in elsewhere.iterdir())
    assert target.read_text() == "precious"
    assert not (out / "frames").is_symlink()
    assert not (out / "final.vtu").is_symlink()
    assert len(list((out / "frames").iterdir())) == s["frames"]


def test_a_link_no_manifest_lists_is_refused_then_removed_as_a_link(tmp_path: Path) -> None:
    """A link named like an output in a folder without a manifest is foreign: refused; with
    overwrite it is removed as a link, its target untouched."""
    out = tmp_path / "o"
    out.mkdir()
    target = tmp_path / "target.json"
    target.write_text("precious")
    (out / "summary.json").symlink_to(target)
    with pytest.raises(OutputError, match=r"summary\.json"):
        run_scene(springs(tmp_path), out, preview=False)
    run_scene(springs(tmp_path), out, preview=False, overwrite=True)
    assert target.read_text() == "precious"
    assert not (out / "summary.json").is_symlink()
    assert json.loads((out / "summary.json").read_text())["steps"] == 6


def test_viewer_page_of_a_run_does_not_block_a_rerun(tmp_path: Path) -> None:
    """`topomech view --no-serve` writes viewer.html into the run's folder and lists it in
    the manifest, so a rerun replaces it instead of refusing the folder."""
    out = tmp_path / "o"
    scene = springs(tmp_path)
    run_scene(scene, out, preview=False)
    assert cli.main(["view", str(out), "--no-serve"]) == 0
    assert "viewer.html" in (read_manifest(out) or [])
    run_scene(scene, out, preview=False)
    assert not (out / "viewer.html").exists()


def test_a_file_in_place_of_the_folder_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "o"
    out.write_text("a file")
    with pytest.raises(OutputError, match="not a folder"):
        run_scene(springs(tmp_path), out, preview=False)
    assert out.read_text() == "a file"


# ---------------------------------------------------------------------- 3. Ctrl-C


def interrupt_at(monkeypatch: pytest.MonkeyPatch, phase: str) -> None:
    """A KeyboardInterrupt raised when the run enters ``phase`` (the first time)."""
    real = run_mod._enter
    fired = []

    def hook(name: str) -> None:
        real(name)
        if name == phase and not fired:
            fired.append(name)
            raise KeyboardInterrupt

    monkeypatch.setattr(run_mod, "_enter", hook)


PHASES = ["setup", "frames", "steps", "final", "view", "previews", "summary"]


@pytest.mark.parametrize("phase", PHASES)
def test_ctrl_c_in_any_phase_leaves_a_summary(
    phase: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A Ctrl-C as the run enters each phase: exit 130, a summary.json with error type
    `interrupted`, the phase and the steps done, the message naming the folder, which exists
    (before: no phase in the summary; during set-up, preview rendering or the summary
    itself, no summary at all)."""
    out = tmp_path / "new" / "o"
    interrupt_at(monkeypatch, phase)
    code = cli.main(["run", str(springs(tmp_path)), "--out", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 130, err
    assert f"interrupted; what was written is in {out} (see summary.json)" in err
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["type"] == "interrupted"
    assert s["error"]["phase"] == phase
    assert s["error"]["steps_done"] == s["steps"]
    done = {"setup": 0, "frames": 0, "steps": 0}.get(phase, 6)
    assert s["steps"] == done
    assert files_under(out) - {MANIFEST} <= set(read_manifest(out) or [])
    if phase in ("steps", "frames", "view"):
        # final.vtu is still written after a Ctrl-C during the steps
        assert len(meshio.read(out / "final.vtu").points) == s["vertices"] == 9


def test_ctrl_c_during_setup_from_the_build(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Ctrl-C inside the simulation's build (the longest part of set-up) is reported as
    the set-up phase, with the values not known yet null."""
    from topomech.scene import Scene

    def slow_build(self: Scene) -> Any:
        raise KeyboardInterrupt

    monkeypatch.setattr(Scene, "build", slow_build)
    out = tmp_path / "o"
    with pytest.raises(KeyboardInterrupt):
        run_scene(springs(tmp_path), out)
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["phase"] == "setup"
    assert s["steps"] == 0
    assert s["vertices"] is None
    assert s["outputs"]["final"] is None


def test_ctrl_c_before_any_output_names_no_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A Ctrl-C while the scene file is read: exit 130 and no folder named, since none was
    made (before: `what was written is in DIR` with DIR missing)."""
    import topomech.scene

    def load(spec: Any) -> Any:
        raise KeyboardInterrupt

    monkeypatch.setattr(topomech.scene, "load_scene", load)
    out = tmp_path / "missing"
    assert cli.main(["run", str(springs(tmp_path)), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err
    assert str(out) not in err
    assert not out.exists()


WRAPPER = """
import os, signal, sys
import topomech.run as run_mod
from topomech import cli

phase = sys.argv[1]
real = run_mod._enter

def hook(name):
    real(name)
    if name == phase:
        os.kill(os.getpid(), signal.SIGINT)  # a real signal, handled as Ctrl-C is

run_mod._enter = hook
sys.exit(cli.main(sys.argv[2:]))
"""


@pytest.mark.parametrize("phase", ["setup", "previews"])
def test_real_sigint_at_a_phase(phase: str, tmp_path: Path) -> None:
    """A real SIGINT sent to a `topomech run` process as it enters set-up or the previews:
    exit 130, the summary says interrupted in that phase, and the message names the folder
    (before: no summary after a Ctrl-C in set-up; the previews' phase was not reported)."""
    out = tmp_path / "o"
    wrapper = tmp_path / "wrapper.py"
    wrapper.write_text(WRAPPER)
    r = subprocess.run(
        [sys.executable, str(wrapper), phase, "run", str(springs(tmp_path)), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 130, r.stderr
    assert f"what was written is in {out}" in r.stderr
    assert "Traceback" not in r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["type"] == "interrupted"
    assert s["error"]["phase"] == phase


def run_until_second_frame(tmp_path: Path) -> tuple[subprocess.Popen[str], Path]:
    """A long spring run in a subprocess (its output in ``tmp_path/o``), returned once its
    second frame is written (or it ended, or a minute passed)."""
    out = tmp_path / "o"
    scene = springs(tmp_path, steps=200000, every=1000)
    p = subprocess.Popen(
        [sys.executable, "-m", "topomech", "run", str(scene), "--out", str(out), "--no-preview"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    second = out / "frames" / "frame_00001.vtu"
    deadline = time.monotonic() + 60
    while not second.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    return p, out


def test_real_sigint_while_stepping(tmp_path: Path) -> None:
    """SIGINT sent from outside once frames appear: exit 130, interrupted in the steps or a
    frame, steps done counted."""
    p, out = run_until_second_frame(tmp_path)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["phase"] in ("steps", "frames")
    assert 0 < s["error"]["steps_done"] == s["steps"] < 200000


# ---------------------------------------------------------------------- 3b. SIGTERM

posix_only = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


@posix_only
def test_sigterm_while_stepping_leaves_a_summary(tmp_path: Path) -> None:
    """SIGTERM (`kill`, a batch scheduler or a container stopping the job) sent once frames
    appear is handled as Ctrl-C is: exit 143 (128 + SIGTERM), a summary.json saying
    interrupted in the steps or a frame with the steps done, final.vtu written, one line on
    stderr naming the folder (before: the process died at once, exit -15, no summary and no
    final.vtu)."""
    p, out = run_until_second_frame(tmp_path)
    assert p.poll() is None, "the run ended before the signal"
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGTERM, err
    assert f"topomech: error: terminated (SIGTERM); what was written is in {out}" in err
    assert "Traceback" not in err
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["type"] == "interrupted"
    assert s["error"]["phase"] in ("steps", "frames")
    assert 0 < s["error"]["steps_done"] == s["steps"] < 200000
    assert len(meshio.read(out / "final.vtu").points) == s["vertices"]


SIGNAL_WRAPPER = """
import os, signal, sys
import topomech.run as run_mod
from topomech import cli

signum = getattr(signal, sys.argv[1])
phase = sys.argv[2]
if sys.argv[3] == "ignored":
    signal.signal(signum, signal.SIG_IGN)  # as a parent that ignores it leaves it
real = run_mod._enter

def hook(name):
    real(name)
    if name == phase:
        os.kill(os.getpid(), signum)

run_mod._enter = hook
code = cli.main(sys.argv[4:])
print("handler after:", signal.getsignal(signum) in (signal.SIG_DFL, signal.SIG_IGN))
sys.exit(code)
"""


def run_signalled(
    tmp_path: Path, signame: str, phase: str, how: str = "default"
) -> tuple[subprocess.CompletedProcess[str], Path]:
    """`topomech run` of a small scene in a fresh interpreter that sends itself ``signame``
    as the run enters ``phase``."""
    out = tmp_path / "o"
    wrapper = tmp_path / "wrapper.py"
    wrapper.write_text(SIGNAL_WRAPPER)
    run_args = ["run", str(springs(tmp_path)), "--out", str(out), "-q"]
    r = subprocess.run(
        [sys.executable, str(wrapper), signame, phase, how, *run_args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    return r, out


@posix_only
@pytest.mark.parametrize("phase", ["setup", "steps", "final", "previews"])
def test_real_sigterm_at_a_phase(phase: str, tmp_path: Path) -> None:
    """SIGTERM as the run enters each phase: exit 143, the summary says interrupted in that
    phase, stderr names the folder, and the handler in place before the run is back after it
    (before: killed at once, nothing but what was written so far)."""
    r, out = run_signalled(tmp_path, "SIGTERM", phase)
    assert r.returncode == 128 + signal.SIGTERM, r.stderr
    assert f"terminated (SIGTERM); what was written is in {out}" in r.stderr
    assert "Traceback" not in r.stderr
    assert "handler after: True" in r.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["type"] == "interrupted"
    assert s["error"]["phase"] == phase


@posix_only
def test_sigint_still_exits_130_with_sigterm_handled(tmp_path: Path) -> None:
    """Ctrl-C is told apart from SIGTERM: exit 130 and `interrupted`."""
    r, out = run_signalled(tmp_path, "SIGINT", "steps")
    assert r.returncode == 130, r.stderr
    assert f"topomech: error: interrupted; what was written is in {out}" in r.stderr
    assert "SIGTERM" not in r.stderr


@posix_only
def test_an_ignored_sigterm_stays_ignored(tmp_path: Path) -> None:
    """A SIGTERM the parent ignores (SIG_IGN, inherited) is not turned into an
    interruption: the run completes, and SIGTERM is still ignored after it."""
    r, out = run_signalled(tmp_path, "SIGTERM", "steps", "ignored")
    assert r.returncode == 0, r.stderr
    assert "handler after: True" in r.stdout
    assert "error" not in json.loads((out / "summary.json").read_text())


@posix_only
def test_the_sigterm_handler_is_restored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """In-process: during the run SIGTERM has topomech's handler; after a run that ends, is
    refused or is interrupted, the caller's handler is back."""

    def callers(signum: int, frame: Any) -> None:  # pragma: no cover - never called
        pass

    seen: list[Any] = []
    real = run_mod._enter

    def hook(name: str) -> None:
        real(name)
        seen.append(signal.getsignal(signal.SIGTERM))

    monkeypatch.setattr(run_mod, "_enter", hook)
    old = signal.signal(signal.SIGTERM, callers)
    try:
        assert cli.main(["run", str(springs(tmp_path)), "--out", str(tmp_path / "a"), "-q"]) == 0
        assert seen
        assert all(h is not callers and callable(h) for h in seen)
        assert signal.getsignal(signal.SIGTERM) is callers
        bad = tmp_path / "bad.toml"
        bad.write_text("[mesh]\n")
        assert cli.main(["run", str(bad), "--out", str(tmp_path / "b")]) == 2
        assert signal.getsignal(signal.SIGTERM) is callers
        interrupt_at(monkeypatch, "steps")
        assert cli.main(["run", str(springs(tmp_path)), "--out", str(tmp_path / "c"), "-q"]) == 130
        assert signal.getsignal(signal.SIGTERM) is callers
    finally:
        signal.signal(signal.SIGTERM, old)
    capsys.readouterr()


# ---------------------------------------------------------------------- 4. disk full


def enospc_on(monkeypatch: pytest.MonkeyPatch, suffix: str) -> None:
    """meshio.write raising ENOSPC (no file name, as a failing write does) for a path
    ending with ``suffix`` (or the ``.part`` file a run writes it through), after creating
    the file half-written."""
    real = meshio.write

    def write(path: Any, *a: Any, **kw: Any) -> None:
        if str(path).endswith((suffix, suffix + ".part")):
            Path(path).write_bytes(b"<?xml")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(path, *a, **kw)

    monkeypatch.setattr(meshio, "write", write)


@pytest.mark.parametrize("suffix", ["frame_00002.vtu", "final.vtu"])
def test_disk_full_names_the_file(
    suffix: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """ENOSPC writing a frame or final.vtu: the run stops, summary.json has an `io` error
    with the file's path, the CLI names it and exits 1 (before: an OSError traceback without
    the file and no summary)."""
    enospc_on(monkeypatch, suffix)
    out = tmp_path / "o"
    assert cli.main(["run", str(springs(tmp_path)), "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    e = s["error"]
    assert e["type"] == "io"
    assert e["errno"] == "ENOSPC"
    assert e["path"].endswith(suffix)
    assert e["path"] in err
    assert "No space left on device" in err
    assert "Traceback" not in err
    assert s["outputs"]["final"] is None
    # nothing half-written is left: neither the file nor the one it was written through
    assert not list(out.rglob(suffix))
    assert not list(out.rglob("*.part"))


def test_ctrl_c_while_a_frame_is_written_leaves_no_truncated_frame(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C (or SIGTERM, which raises the same) in the middle of writing a frame: the
    frame is not left half-written (QA: a truncated frame_00012.vtu stayed beside the
    complete ones, and meshio could not read it); every frame file left reads, and
    animation.pvd lists exactly them."""
    real = meshio.write

    def write(path: Any, *a: Any, **kw: Any) -> None:
        if "frame_00002.vtu" in str(path):
            Path(path).write_bytes(b"<?xml")
            raise KeyboardInterrupt
        real(path, *a, **kw)

    monkeypatch.setattr(meshio, "write", write)
    out = tmp_path / "o"
    assert cli.main(["run", str(springs(tmp_path)), "--out", str(out), "-q"]) == 130
    frames = sorted(p.name for p in (out / "frames").iterdir())
    assert frames == ["frame_00000.vtu", "frame_00001.vtu"]
    for f in frames:
        real_read = meshio.read(out / "frames" / f)
        assert len(real_read.points) > 0
    pvd = (out / "animation.pvd").read_text()
    assert "frame_00001.vtu" in pvd
    assert "frame_00002.vtu" not in pvd
    assert json.loads((out / "summary.json").read_text())["error"]["type"] == "interrupted"


def test_disk_full_on_the_view_data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """ENOSPC appending a frame to view.bin (a write to an open file, which names no file):
    the error names view.bin, not the frame file written just before it."""
    import topomech.recording as recording

    real = recording.Recorder._bin_file

    class Full:
        def __init__(self, f: Any) -> None:
            self.f = f

        def write(self, data: bytes) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name: str) -> Any:
            return getattr(self.f, name)

    def bin_file(self: Any) -> Any:
        return Full(real(self))

    monkeypatch.setattr(recording.Recorder, "_bin_file", bin_file)
    s = run_scene(springs(tmp_path), tmp_path / "o")
    assert s["error"]["type"] == "io"
    assert s["error"]["path"] == str(tmp_path / "o" / "view.bin")
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["error"] == s["error"]


def test_disk_full_on_the_energy_rows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """ENOSPC appending a row to energy.csv as the run goes: the error names energy.csv."""
    import topomech.recording as recording

    real = recording.Recorder._energy_file

    class Full:
        def __init__(self, f: Any) -> None:
            self.f = f

        def write(self, data: str) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name: str) -> Any:
            return getattr(self.f, name)

    def energy_file(self: Any) -> Any:
        fh = real(self)
        self._csv_writer = csv.writer(Full(fh))
        return fh

    monkeypatch.setattr(recording.Recorder, "_energy_file", energy_file)
    s = run_scene(springs(tmp_path), tmp_path / "o")
    assert s["error"]["type"] == "io"
    assert s["error"]["path"] == str(tmp_path / "o" / "energy.csv")


def test_disk_full_on_the_summary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """ENOSPC writing summary.json: no half-written summary is left, the CLI names
    summary.json and exits 1 (before: a traceback)."""
    real = Path.write_text

    def write_text(self: Path, data: str, *a: Any, **kw: Any) -> int:
        if self.name == "summary.json":
            real(self, data[:10], *a, **kw)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, data, *a, **kw)

    monkeypatch.setattr(Path, "write_text", write_text)
    out = tmp_path / "o"
    assert cli.main(["run", str(springs(tmp_path)), "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert f"{out / 'summary.json'}: could not be written" in err
    assert "summary.json could not be written" in err
    assert not (out / "summary.json").exists()


FSIZE = """
import resource, signal, sys
from topomech import cli
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead
limit = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
sys.exit(cli.main(sys.argv[2:]))
"""


@pytest.mark.parametrize(
    ("limit", "failing"), [(3000, "frames/frame_00000.vtu"), (20000, "view.bin")]
)
def test_real_file_size_limit(limit: int, failing: str, tmp_path: Path) -> None:
    """A real failing write: RLIMIT_FSIZE in a subprocess (SIGXFSZ ignored, so the write
    fails with EFBIG) on a 12x12 grid whose frames are about 5-8 kB, view.bin about 67 kB
    and the summary about 1.5 kB: 3000 bytes stops frame 0, 20000 bytes stops view.bin (a
    bytes write whose error carries no file name). Exit 1, the message and the summary name
    that file (before: a traceback naming no file, no summary)."""
    out = tmp_path / "o"
    script = tmp_path / "fsize.py"
    script.write_text(FSIZE)
    scene = springs(tmp_path, cells=12)
    r = subprocess.run(
        [sys.executable, str(script), str(limit), "run", str(scene), "--out", str(out), "-q"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert r.returncode == 1, r.stderr
    path = out / failing
    assert f"{path}: could not be written: File too large" in r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["error"]["type"] == "io"
    assert s["error"]["errno"] == "EFBIG"
    assert s["error"]["path"] == str(path)
    assert "Traceback" not in r.stderr


def test_overwrite_never_adopts_a_users_file_in_frames(tmp_path: Path) -> None:
    """With --overwrite into a folder whose `frames/` holds a user's file, the run does not
    list that file as its own: the next runs keep refusing the folder, and never delete it."""
    out = tmp_path / "o"
    (out / "frames").mkdir(parents=True)
    (out / "frames" / "notes.txt").write_text("mine")
    scene = springs(tmp_path)
    run_scene(scene, out, preview=False, overwrite=True)
    assert "frames/notes.txt" not in (read_manifest(out) or [])
    with pytest.raises(OutputError, match=r"frames/notes\.txt"):
        run_scene(scene, out, preview=False)
    run_scene(scene, out, preview=False, overwrite=True)
    assert (out / "frames" / "notes.txt").read_text() == "mine"
