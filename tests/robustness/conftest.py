"""The fixture folder of the hostile-input corpus: the session's small real build (tests/conftest.py,
probe_fixtures.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent), str(HERE.parent / "model")]


@pytest.fixture(scope="session")
def fx(small_build) -> Path:
    return small_build
