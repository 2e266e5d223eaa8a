"""The fixture folder of the hostile-input corpus (probe_fixtures.py), built once per test session and shared by the
xdist workers (a file lock: the first worker builds it, the others wait for it)."""

from __future__ import annotations

import fcntl
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent), str(HERE.parent / "model")]


@pytest.fixture(scope="session")
def fx(tmp_path_factory) -> Path:
    from probe_fixtures import build_fixtures

    shared = tmp_path_factory.getbasetemp().parent      # the same folder for every xdist worker of this session
    with open(shared / "hostile-fixtures.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return build_fixtures(shared / "hostile-fixtures")
