"""Shared test set-up: the tests folder is importable (tests build their own fixtures from `synthetic`), so is the
repository root (`testkit` and `benchmarks`, kept out of the wheel, whatever the working directory), under CI
the property tests draw a fixed sequence of examples so a run is repeatable (locally they keep exploring), and
`small_build` is one small real build shared by the whole session."""

import fcntl
import os
import sys
from pathlib import Path

import pytest
from hypothesis import settings

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
sys.path.insert(0, str(TESTS))
if str(REPO) not in sys.path:
    sys.path.insert(1, str(REPO))

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")


@pytest.fixture(scope="session")
def small_build(tmp_path_factory) -> Path:
    """A small real build through the CLI (tests/robustness/probe_fixtures.py: the open hand's wrist-enhanced model,
    two catalogue textures at 64 px, a fitted ring, the USD, .glb and .gltf packages, a MANO-format pickle), made once
    per session and shared by the xdist workers (a file lock: the first worker builds it, the others wait)."""
    sys.path[:0] = [str(TESTS / "robustness"), str(TESTS / "model")]
    from probe_fixtures import build_fixtures

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base    # this session's folder, not older ones
    with open(shared / "small-build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return build_fixtures(shared / "small-build")
