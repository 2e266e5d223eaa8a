"""One `make assets` step: run a command, print a progress line, record its seconds for the manifest.

    python -m darthand.step NAME -- COMMAND [ARGS...]

writes build/steps/NAME.json ({"name", "started", "seconds", "cpu_seconds", "command", "exit_code"}; started: Unix
time, so the steps of one build can be laid out on a time line to see how they overlap) atomically and exits with
the command's code, so a failing step stops make and leaves no record that a later run would trust. cpu_seconds
(user + system of the command and its children) is the figure to compare on a machine other work shares.

Interruption: before the command starts, the temporaries and staging folders that interrupted or killed runs left
under build/ are removed (fileio.remove_stale_temporaries). Ctrl-C reaches the whole process group, the command
included; the step waits for the command to stop (then asks it again, then ends it), prints one line and exits 130
without a traceback. The command is told (DARTHAND_STEP) that the step reports the interruption, so it stays quiet.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

from darthand.fileio import remove_stale_temporaries, write_json

STEPS_DIR = Path("build/steps")
INTERRUPTED = 130
STEP_ENV = "DARTHAND_STEP"
# After Ctrl-C: seconds to let the command stop by itself, then after a second SIGINT, then after SIGTERM.
GRACE = (5.0, 10.0, 5.0)


def run_step(name: str, command: list[str], steps_dir: Path = STEPS_DIR) -> int:
    print(f"[{name}] ...", file=sys.stderr, flush=True)
    if steps_dir.parent.is_dir():
        remove_stale_temporaries(steps_dir.parent)
    started, t0, cpu0 = time.time(), time.perf_counter(), _children_cpu()
    record = steps_dir / f"{name}.json"
    try:
        proc = subprocess.Popen(command, env=dict(os.environ, **{STEP_ENV: name}))
    except OSError as e:
        print(f"[{name}] failed: cannot run {command[0]} ({e.strerror})", file=sys.stderr, flush=True)
        return 127
    try:
        code = proc.wait()
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)        # a second Ctrl-C must not cut the clean-up short
        stop(proc)
        record.unlink(missing_ok=True)
        print(f"[{name}] interrupted after {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        return INTERRUPTED
    seconds, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if code == 0:
        write_json(record, {"name": name, "started": round(started, 3), "seconds": round(seconds, 3),
                            "cpu_seconds": round(cpu, 3),
                            "command": command, "exit_code": code})
        print(f"[{name}] done in {seconds:.1f} s", file=sys.stderr, flush=True)
    else:
        record.unlink(missing_ok=True)
        print(f"[{name}] failed (exit {code}) after {seconds:.1f} s", file=sys.stderr, flush=True)
    return code


def stop(proc: subprocess.Popen) -> None:
    """End an interrupted command: it got the Ctrl-C too, so wait for it; then SIGINT again (when only this
    process was signalled), SIGTERM, SIGKILL."""
    for sig, grace in zip((None, signal.SIGINT, signal.SIGTERM), GRACE):
        if sig is not None and proc.poll() is None:
            proc.send_signal(sig)
        try:
            proc.wait(grace)
            return
        except subprocess.TimeoutExpired:
            continue
    proc.kill()
    proc.wait()


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 3 or argv[1] != "--":
        print("usage: python -m darthand.step NAME -- COMMAND [ARGS...]", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, _as_interrupt)      # make ends its children with SIGTERM: stop the command too
    return run_step(argv[0], argv[2:])


def _as_interrupt(signum, frame):
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(main())
