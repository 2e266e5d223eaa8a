"""Run corpus cases (hostile_corpus.py) in this process through `darthand.cli.main`: far cheaper than the probe's
subprocesses (no interpreter start per case), for the test suite. Judged like the probe, minus what needs a process
of its own (signals, orphans): a hang is an alarm after the timeout, an escaping exception is a traceback."""

from __future__ import annotations

import contextlib
import io
import signal
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent), str(HERE.parent / "model")]

from hostile_corpus import Case  # noqa: E402
from probe import Watch, fill, judge_output  # noqa: E402


class _Timeout(BaseException):
    """Raised by the alarm in the middle of a hanging case."""


def run_in_process(c: Case, t: Path, fx: Path) -> tuple[str, str]:
    """(verdict, detail) of one argv case, run by darthand.cli.main in this process (main thread only)."""
    from darthand.cli import main

    t.mkdir(parents=True, exist_ok=True)
    if c.setup:
        c.setup(t, fx)
    argv = [fill(a, t, fx) for a in c.argv]
    watch = Watch([fill(w, t, fx) for w in c.watch])
    err = io.StringIO()

    def alarm(signum, frame):
        raise _Timeout

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(int(c.timeout))
    code: int | None
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as e:          # argparse
                code = int(e.code or 0)
    except _Timeout:
        code = None
    except Exception as e:                   # what the CLI would print as a traceback
        import traceback
        err.write("Traceback (most recent call last):\n" + "".join(traceback.format_exception_only(e)))
        code = 1
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    opened = watch.opened()
    verdict, detail = judge_output(code, err.getvalue(), c.expect)
    if verdict == "handled" and opened:
        verdict, detail = "read outside", f"opened {', '.join(opened)}"
    elif verdict == "handled" and c.canary and Path(fill(c.canary, t, fx)).exists():
        verdict, detail = "payload ran", c.canary
    elif verdict == "handled" and c.check:
        problem = c.check(t, fx)
        if problem:
            verdict, detail = "check", problem
    return verdict, detail
