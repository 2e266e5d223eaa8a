"""Interrupted runs: Ctrl-C during a real `make` build, the step runner, worker processes ending with their parent,
temporaries and staging folders of killed runs removed by the next run, and outputs damaged after a build found by
`darthand verify` and rebuilt by `make assets`.

Ctrl-C is sent as a terminal sends it: SIGINT to the whole foreground process group (here: a new session)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from probe import DARTHAND, Proc, make_tree, session_processes

from darthand.fileio import remove_stale_temporaries, temporary_prefix
from darthand.manifest import invalidate, verify_outputs, write_manifest

PYTHON = sys.executable


def dead_pid() -> int:
    """The id of a process that has exited (and been reaped)."""
    p = subprocess.Popen([PYTHON, "-c", "pass"])
    p.wait()
    return p.pid


def wait_gone(sid: int, seconds: float) -> list[int]:
    end = time.monotonic() + seconds
    while time.monotonic() < end and session_processes(sid):
        time.sleep(0.1)
    return session_processes(sid)


def test_step_runner_stops_its_command_with_one_line(tmp_path):
    child = ("import signal, sys, time; signal.signal(signal.SIGINT, lambda *a: sys.exit(130)); "
             "print('ready', flush=True); time.sleep(60)")
    proc = Proc([PYTHON, "-m", "darthand.step", "demo", "--", PYTHON, "-c", child], tmp_path, limit=False)
    assert proc.wait_for("ready", 60)
    os.killpg(proc.p.pid, signal.SIGINT)
    assert proc.wait(30) == 130
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "interrupt" in line]
    assert len(lines) == 1 and lines[0].startswith("[demo] interrupted after ")
    assert wait_gone(proc.p.pid, 5) == []


def test_step_runner_ends_a_command_that_ignores_ctrl_c(tmp_path, monkeypatch):
    import darthand.step as step

    monkeypatch.setattr(step, "GRACE", (0.5, 0.5, 0.5))
    child = ("import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
             "signal.signal(signal.SIGTERM, signal.SIG_IGN); time.sleep(60)")
    p = subprocess.Popen([PYTHON, "-c", child])
    t0 = time.monotonic()
    step.stop(p)
    assert p.returncode == -signal.SIGKILL and time.monotonic() - t0 < 10


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead = dead_pid()
    (tmp_path / "usd").mkdir()
    stale_dir = tmp_path / "usd" / f".right.tmp-{dead}.abc"
    stale_dir.mkdir()
    (stale_dir / "payload.usdc").write_bytes(b"half")
    stale_file = tmp_path / f".x.png.tmp-{dead}.q1.png"
    stale_file.write_bytes(b"half")
    ours = tmp_path / (temporary_prefix("y.png") + "q2.png")
    ours.write_bytes(b"being written")
    other = tmp_path / ".hidden-but-not-ours"
    other.write_bytes(b"keep")
    removed = remove_stale_temporaries(tmp_path)
    assert sorted(removed) == sorted([stale_dir, stale_file])
    assert ours.exists() and other.exists() and not stale_dir.exists() and not stale_file.exists()


def test_export_usd_removes_the_staging_folder_a_killed_run_left(fx, tmp_path):
    from darthand.export.usd_asset import export_usd
    from darthand.model.npz_io import load_npz

    out = tmp_path / "usd" / "right"
    out.parent.mkdir(parents=True)
    stale = out.parent / f".right.tmp-{dead_pid()}.x"
    stale.mkdir()
    (stale / "payload.usdc").write_bytes(b"half-written")
    export_usd(load_npz(fx / "model" / "right.npz"), out)
    assert sorted(p.name for p in out.parent.iterdir()) == ["right"]


def test_workers_end_when_their_parent_is_killed(fx, tmp_path):
    argv = [DARTHAND, "textures", "build", str(fx / "model" / "right.npz"), "--out", str(tmp_path / "tex"),
            "--res", "256", "--category", "tattoos", "--jobs", "2", "--no-tx", "--no-sheet"]
    proc = Proc(argv, tmp_path)
    assert proc.wait_for(r"\[textures\] \d+/", 120), proc.stderr
    workers = [p for p in session_processes(proc.p.pid) if p != proc.p.pid]
    assert workers
    os.kill(proc.p.pid, signal.SIGKILL)           # the parent only, as an out-of-memory kill would
    proc.wait(10)
    left = wait_gone(proc.p.pid, 20)
    assert left == [], f"outlived their parent: {[Path(f'/proc/{p}/cmdline').read_bytes()[:120] for p in left]}"


def test_ctrl_c_during_make_stops_the_step_and_its_workers_cleanly(tmp_path):
    """A real build: `make build/textures/catalog.json RES=64` (the model step, then the textures step with two
    worker processes), interrupted while the workers render."""
    tree = make_tree(tmp_path)
    proc = Proc(["make", "build/textures/catalog.json", "RES=64"], tree, env=dict(os.environ, MAKEFLAGS=""),
                limit=False)
    assert proc.wait_for(r"\[textures\] \.\.\.", 300), proc.stderr
    time.sleep(3.0)                  # the bake is done and the workers start, or render
    os.killpg(proc.p.pid, signal.SIGINT)
    code = proc.wait(120)
    assert code is not None and code != 0
    assert "Traceback" not in proc.stderr and "leaked" not in proc.stderr, proc.stderr
    assert "[textures] interrupted after" in proc.stderr
    assert wait_gone(proc.p.pid, 10) == []
    build = tree / "build"
    assert not [p for p in build.rglob(".*")], "temporaries left under build/"
    assert not (build / "steps" / "textures.json").exists()
    assert not (build / "textures" / "catalog.json").exists()


COMPILING = """
import numba  # imported before the signal can come: only the compile is under test
import numpy as np
from darthand.jit import kernel


@kernel
def kernel_under_test(a):
    total = 0.0
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            total += np.sqrt(abs(a[i, j])) * np.cos(a[i, j])
    return total


print("compiling", flush=True)
try:
    kernel_under_test(np.ones((3, 3)))
    print("returned", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


def test_ctrl_c_while_a_kernel_compiles_waits_for_the_compile_and_prints_no_traceback(tmp_path):
    """A kernel's first call compiles it (numba, into tmp_path/__pycache__: nothing cached yet). A Ctrl-C then must
    not land inside LLVM's callbacks, where Python prints it as an ignored exception and drops it: it is held until
    the compile is done (its cache files written) and interrupts the call as it returns."""
    script = tmp_path / "compiling.py"
    script.write_text(COMPILING)
    proc = Proc([PYTHON, str(script)], tmp_path, limit=False)
    assert proc.wait_for("compiling", 60), proc.stderr
    time.sleep(0.05)                                       # well inside the compile (0.3 s or more)
    os.killpg(proc.p.pid, signal.SIGINT)
    assert proc.wait(60) == 0, proc.stderr
    assert proc.stdout.split() == ["compiling", "interrupted"], proc.stdout + proc.stderr
    assert "Exception ignored" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    cached = sorted(p.suffix for p in (tmp_path / "__pycache__").glob("compiling.kernel_under_test-*"))
    assert cached == [".nbc", ".nbi"], cached


# ------------------------------------------------------------------------------------------------ damaged outputs


def small_build(root: Path, fx: Path) -> Path:
    """A build folder with a manifest: the fixture textures, one PNG hard-linked into two packages."""
    build = root / "build"
    shutil.copytree(fx / "tex", build / "textures")
    for side in ("right", "left"):
        folder = build / "usd" / side / "texture"
        folder.mkdir(parents=True)
        os.link(build / "textures" / "brown_moles_00.png", folder / "brown_moles_00.png")
        (build / "usd" / side / f"{side}.usda").write_text("#usda 1.0\n")
    write_manifest(build)
    return build


def test_verify_names_every_link_of_a_damaged_file_and_repair_dates_their_steps_back(fx, tmp_path):
    build = small_build(tmp_path, fx)
    assert verify_outputs(build) == []
    png = build / "textures" / "brown_moles_00.png"
    with open(png, "r+b") as f:
        f.truncate(png.stat().st_size // 2)
    damaged = verify_outputs(build)
    assert sorted(rel for rel, _ in damaged) == ["textures/brown_moles_00.png", "usd/left/texture/brown_moles_00.png",
                                                 "usd/right/texture/brown_moles_00.png"]
    assert all("bytes" in why for _, why in damaged)
    targets = invalidate(build, damaged)
    assert targets == ["textures/catalog.json", "usd/left/left.usda", "usd/right/right.usda"]
    assert not png.exists()
    assert all((build / t).stat().st_mtime_ns == 0 for t in targets)


def test_verify_finds_an_edit_that_keeps_the_size(fx, tmp_path):
    build = small_build(tmp_path, fx)
    png = build / "textures" / "light_tattoos_07.png"
    data = bytearray(png.read_bytes())
    data[100] ^= 0xFF
    png.write_bytes(bytes(data))
    assert [rel for rel, _ in verify_outputs(build)] == ["textures/light_tattoos_07.png"]
    st = png.stat()
    os.utime(png, ns=(st.st_atime_ns, next(e["mtime_ns"] for e in __import__("json").loads(
        (build / "manifest.json").read_text())["outputs"] if e["path"] == "textures/light_tattoos_07.png")))
    assert verify_outputs(build) == []                         # same size and time: only --full hashes it
    assert [rel for rel, _ in verify_outputs(build, full=True)] == ["textures/light_tattoos_07.png"]


def test_verify_command_exit_codes(fx, tmp_path):
    from darthand.cli import main

    build = small_build(tmp_path, fx)
    assert main(["verify", "--build", str(build)]) == 0
    (build / "usd" / "right" / "right.usda").unlink()
    assert main(["verify", "--build", str(build)]) == 1
    assert main(["verify", "--build", str(build), "--repair"]) == 0
    assert main(["verify", "--build", str(tmp_path / "none"), "--repair"]) == 0      # no manifest yet: nothing to do
    assert main(["verify", "--build", str(tmp_path / "none")]) == 2


@pytest.mark.slow
def test_make_assets_rebuilds_a_damaged_texture(tmp_path):
    """A real `make assets RES=64 SIDE=right`; a texture PNG (hard-linked into the packages) truncated; the next
    `make assets` finds it, rebuilds it and the manifest matches every output again."""
    tree = make_tree(tmp_path)
    env = dict(os.environ, MAKEFLAGS="")
    run = subprocess.run(["make", "assets", "RES=64", "SIDE=right"], cwd=tree, env=env, capture_output=True,
                         text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-2000:]
    build = tree / "build"
    png = build / "textures" / "brown_moles_00.png"
    good = png.read_bytes()
    assert png.stat().st_nlink > 1                                  # linked into the packages
    with open(png, "r+b") as f:
        f.truncate(len(good) // 3)
    assert subprocess.run([DARTHAND, "verify", "--build", str(build)], capture_output=True).returncode == 1
    run = subprocess.run(["make", "assets", "RES=64", "SIDE=right"], cwd=tree, env=env, capture_output=True,
                         text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "damaged" in run.stdout and "[textures] done" in run.stderr
    assert png.read_bytes() == good
    assert subprocess.run([DARTHAND, "verify", "--build", str(build), "--full"], capture_output=True).returncode == 0
