"""Restructuring the code changes nothing a user sees: the outputs of a fixed set of commands (golden_outputs.py:
packages, datasets of a model and of a USD package, their FreiHAND and WebDataset layouts, renders, a jobs file)
hash as they did at the reference commit (golden_outputs.json, written by that commit's code), both made with the
same CPU features whatever the machine (golden_outputs.REFERENCE_CPU)."""

import json
from pathlib import Path

from golden_outputs import reference_run

GOLDEN = Path(__file__).with_name("golden_outputs.json")


def test_every_output_is_byte_identical_to_the_reference(tmp_path):
    expected = json.loads(GOLDEN.read_text())
    got = reference_run(tmp_path)
    assert sorted(got) == sorted(expected), "files added or missing"
    changed = [name for name in expected if got[name] != expected[name]]
    assert not changed, f"{len(changed)} outputs changed: {changed[:10]}"
