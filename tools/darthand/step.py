"""One `make assets` step: run a command, print a progress line, record its seconds for the manifest.

    python -m darthand.step NAME -- COMMAND [ARGS...]

writes build/steps/NAME.json ({"name", "seconds", "cpu_seconds", "command", "exit_code"}) atomically and exits with
the command's code, so a failing step stops make and leaves no record that a later run would trust. cpu_seconds
(user + system of the command and its children) is the figure to compare on a machine other work shares.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

from darthand.fileio import write_json

STEPS_DIR = Path("build/steps")


def run_step(name: str, command: list[str], steps_dir: Path = STEPS_DIR) -> int:
    print(f"[{name}] ...", file=sys.stderr, flush=True)
    t0, cpu0 = time.perf_counter(), _children_cpu()
    code = subprocess.call(command)
    seconds, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    record = steps_dir / f"{name}.json"
    if code == 0:
        write_json(record, {"name": name, "seconds": round(seconds, 3), "cpu_seconds": round(cpu, 3),
                            "command": command, "exit_code": code})
        print(f"[{name}] done in {seconds:.1f} s", file=sys.stderr, flush=True)
    else:
        record.unlink(missing_ok=True)
        print(f"[{name}] failed (exit {code}) after {seconds:.1f} s", file=sys.stderr, flush=True)
    return code


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 3 or argv[1] != "--":
        print("usage: python -m darthand.step NAME -- COMMAND [ARGS...]", file=sys.stderr)
        return 2
    return run_step(argv[0], argv[2:])


if __name__ == "__main__":
    sys.exit(main())
