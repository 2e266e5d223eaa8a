"""Shared test set-up: the tests folder is importable (tests build their own fixtures from `synthetic`), and under
CI the property tests draw a fixed sequence of examples so a run is repeatable (locally they keep exploring)."""

import os
import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
