"""The studio page in a real browser: headless Chromium (Debian's `chromium`) driven by npm's puppeteer-core
through testkit/driver/drive.mjs, and a `darthand studio` server in a child process. The tests and `make bench` use
both; neither is installed by `pip install darthand`.

Nothing here downloads a browser: `chromium()` finds the system one (or $DARTHAND_CHROMIUM) and says why not.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from darthand.errors import InputError

DRIVER = Path(__file__).resolve().parent / "driver" / "drive.mjs"
REPO_ROOT = Path(__file__).resolve().parents[1]


class BrowserUnavailable(InputError):
    """Chromium, node or puppeteer-core is missing; the message says which and how to install it."""


def chromium() -> str:
    """The path of the system Chromium ($DARTHAND_CHROMIUM, else `chromium` on PATH); BrowserUnavailable if none,
    or if node / puppeteer-core (npm) are missing."""
    path = os.environ.get("DARTHAND_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        raise BrowserUnavailable("chromium is not installed (Debian: `apt-get install chromium`; `make test` does it "
                                 "as root)")
    if shutil.which("node") is None:
        raise BrowserUnavailable("node is not installed: the page is driven by puppeteer-core (Node.js)")
    if not (REPO_ROOT / "node_modules" / "puppeteer-core" / "package.json").is_file():
        raise BrowserUnavailable(f"puppeteer-core is not installed; run `npm ci` in {REPO_ROOT}")
    return path


def drive(url: str, steps: list[dict], timeout: float = 300.0) -> dict:
    """Run driver steps (see driver/drive.mjs) on the page at `url`; the driver's JSON report. An error inside the
    page or the driver is in report['error'] (the steps after it did not run)."""
    browser = chromium()
    with tempfile.TemporaryDirectory() as tmp:
        steps_file = Path(tmp) / "steps.json"
        steps_file.write_text(json.dumps(steps))
        proc = subprocess.run(["node", str(DRIVER), browser, url, str(steps_file)], capture_output=True, text=True,
                              timeout=timeout, cwd=REPO_ROOT)
    if proc.returncode != 0 or not proc.stdout.strip():
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"the browser driver failed (exit {proc.returncode}): {tail}")
    return json.loads(proc.stdout)


class StudioProcess:
    """`darthand studio BUILD --port 0` in a child process (a context manager): `url` once it listens; stopped with
    SIGINT (Ctrl-C) on exit, `returncode` and `stderr` kept."""

    def __init__(self, build: Path, *extra: str):
        self.args = [sys.executable, "-m", "darthand.cli", "studio", str(build), "--port", "0", *extra]
        self.url = None
        self.returncode = None
        self.stderr = ""

    def __enter__(self) -> "StudioProcess":
        self.proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     preexec_fn=_ctrl_c_as_in_a_terminal)
        line = self.proc.stdout.readline()
        match = re.search(r"open (http://\S+/)", line)
        if not match:
            self.__exit__(None, None, None)
            raise RuntimeError(f"darthand studio did not start: {line.strip() or self.stderr.strip()}")
        self.url = match.group(1)
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            _, self.stderr = self.proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, self.stderr = self.proc.communicate()
        self.returncode = self.proc.returncode


def _ctrl_c_as_in_a_terminal() -> None:
    """In the child, before it runs the studio: SIGINT at its default, as a terminal's foreground job has it. When
    the tests themselves run in the background (`make test &`, nohup), SIGINT comes ignored, Python keeps it ignored
    in the children, and the Ctrl-C this class sends would never reach the server."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
