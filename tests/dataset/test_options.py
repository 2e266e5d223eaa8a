"""One way in: the options object's defaults are the command's, and the command and the documented Python call
render the same dataset."""

from __future__ import annotations

import dataclasses
import json

from helpers_dataset import SIZE, files_of

from darthand.cli import build_parser, main
from darthand.dataset.api import render_dataset, write_plan
from darthand.dataset.commands import dataset_options
from darthand.dataset.options import DatasetOptions
from darthand.dataset.plan import DEFAULTS, PlanOptions, PoseOptions
from darthand.render.api import shading_options


def test_the_commands_defaults_are_the_options_defaults():
    args = build_parser("render-dataset").parse_args(["render-dataset", "PKG", "--out", "OUT"])
    got, expected = dataset_options(args), DatasetOptions("PKG", "OUT")
    assert got.plan.spec() == expected.plan.spec() == DEFAULTS
    assert shading_options(got.shading).to_json() == shading_options(expected.shading).to_json()
    assert got.formats == expected.formats and got.cluster is None
    skip = {"plan", "shading", "formats"}
    for field in dataclasses.fields(DatasetOptions):
        if field.name not in skip:
            assert getattr(got, field.name) == getattr(expected, field.name), field.name


def test_the_command_and_the_python_call_render_the_same_dataset(package, tmp_path, capsys):
    model, tex, acc = package
    assert main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--samples",
                 "4", "--processes", "1", "--count", "4", "--seed", "21", "--pose-mode", "jitter",
                 "--accessory-share", "0.5", "--out", str(tmp_path / "cli")]) == 0
    options = DatasetOptions(model, str(tmp_path / "py"), count=4, textures=tex, accessories=acc, size=SIZE,
                             samples=4, processes=1, progress=False,
                             plan=PlanOptions(seed=21, poses=PoseOptions(mode="jitter"), accessory_share=0.5))
    doc = render_dataset(options)
    assert doc["rendered"] == 4 and files_of(tmp_path / "cli") == files_of(tmp_path / "py")
    cli_doc = json.loads((tmp_path / "cli" / "dataset.json").read_text())
    assert cli_doc["jobs"] == doc["jobs"] and cli_doc["plan"] == doc["plan"]
    assert write_plan(dataclasses.replace(options, count=2), tmp_path / "jobs.json") == 2
    frames = json.loads((tmp_path / "jobs.json").read_text())["frames"]
    assert [f["index"] for f in frames] == [0, 1]
