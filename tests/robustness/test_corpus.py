"""The hostile-input corpus as regression tests: every input class of issue 18 through the real CLI.

The default run takes a few cases of every class (in this process through `darthand.cli.main`, or in a subprocess
of its own for those that crashed or hung the process before: segmentation faults, FIFOs); the slow run takes every
case of the corpus in this process. `tests/robustness/probe.py` runs the whole corpus in subprocesses and prints the
table of the closing note.
"""

from __future__ import annotations

import pytest
from hostile_corpus import CASES
from inprocess import run_in_process
from probe import Result, run_case

BY_ID = {c.id: c for c in CASES if c.argv is not None}

# A few of each class: those that crashed, hung, read outside or printed a traceback before, and plain ones.
DEFAULT = [
    "pickle: code-running payloads / os.system",
    "pickle: code-running payloads / INST opcode",
    "pickle: code-running payloads / reduce inside ndarray state",
    "pickle: malformed, deep, huge / int with 5000 digits as a shape",
    "pickle: malformed, deep, huge / regressor indices out of range",
    "npz model: indices, shapes, values / regressor indptr decreasing",
    "npz model: indices, shapes, values / regressor shape 10^12 columns",
    "npz model: indices, shapes, values / declared shape 10^6 x 10^6",
    "npz model: indices, shapes, values / declared shape with 10^30",
    "npz model: indices, shapes, values / face_labels past the label list",
    "npz model: indices, shapes, values / weights as strings",
    "npz model: indices, shapes, values / v_template 1e300",
    "npz model: metadata fields / format_version NaN",
    "npz model: metadata fields / side an array",
    "npz model: metadata fields / meta_json a list",
    "npz model: metadata fields / meta_json 100000 deep",
    "npz model: metadata fields / meta_json wrist a list",
    "npz model: metadata fields / a .npy, not an .npz",
    "model files: FIFO, directory, device / pkl is a directory",
    "pose files / model pose: 1,000 nested brackets",
    "pose files / model pose: values 1e300",
    "pose files / model pose: int of 5000 digits",
    "pose files / model pose: betas NaN",
    "pose files / render --pose 48 x 1e300",
    "lights files / intensity NaN",
    "lights files / intensity 1e39 (float32 overflow)",
    "lights files / 100,000 nested objects",
    "camera files / t 1e300",
    "camera files / width 100000 x 100000",
    "jobs files (JSON only) / 1,000 nested brackets",
    "catalogues (texture, accessory) / texture: albedo file outside (../)",
    "catalogues (texture, accessory) / accessory: mesh file outside (absolute)",
    "asset.json / render: 1,000 nested brackets",
    "asset.json / validate: options a list",
    "asset.json / export usdz: interface outside",
    "USD packages: outside files, non-regular files / validate: sublayer outside (../)",
    "USD packages: outside files, non-regular files / render: payload a link to outside",
    "USD packages: outside files, non-regular files / export usdz: texture file outside (absolute)",
    "USD packages: outside files, non-regular files / validate: usdz referencing outside",
    "glTF packages: outside files, non-regular files / validate: buffer URI absolute",
    "glTF packages: outside files, non-regular files / validate: image URI a link to outside",
    "numeric options / render --skin-tone-offset nan",
    "numeric options / render --size 100000",
    "numeric options / model wrist --rings 1000000",
    "numeric options / textures build --res 3",
    "numeric options / accessories build --poses 1000000000",
    "file-system errors / render --out under a file",
    "file-system errors / model wrist --out in /proc",
    "file-system errors / export gltf --out a folder",
    "file-system errors / render --background a truncated PNG",
]
# Cases that crashed or hung the whole process before the fix: each in a subprocess of its own, with a timeout.
SUBPROCESS = [
    "pickle: malformed, deep, huge / deep tuple as a dict key",
    "npz model: indices, shapes, values / regressor index 10^9 (pose)",
    "npz model: indices, shapes, values / regressor index past the vertices (wrist)",
    "model files: FIFO, directory, device / npz is a FIFO",
    "USD packages: outside files, non-regular files / validate: sublayer a FIFO",
    "USD packages: outside files, non-regular files / render: texture file a FIFO",
    "glTF packages: outside files, non-regular files / validate: buffer URI a FIFO",
    "file-system errors / render --background a FIFO",
]


def test_the_selection_names_real_cases():
    assert not [name for name in DEFAULT + SUBPROCESS if name not in BY_ID]
    assert {BY_ID[name].klass for name in DEFAULT + SUBPROCESS} == {c.klass for c in BY_ID.values()}


@pytest.mark.parametrize("name", DEFAULT)
def test_case_is_handled(name, fx, tmp_path):
    verdict, detail = run_in_process(BY_ID[name], tmp_path / "case", fx)
    assert verdict == "handled", detail


@pytest.mark.parametrize("name", SUBPROCESS)
def test_case_is_handled_in_its_own_process(name, fx, tmp_path):
    result: Result = run_case(BY_ID[name], tmp_path / "case", fx)
    assert result.verdict == "handled", (result.detail, result.exit)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n, c in BY_ID.items() if "FIFO" not in n])
def test_every_case_is_handled(name, fx, tmp_path):
    verdict, detail = run_in_process(BY_ID[name], tmp_path / "case", fx)
    assert verdict == "handled", detail
