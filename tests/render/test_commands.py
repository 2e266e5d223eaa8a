"""The `darthand render` and `darthand render-checks` commands: argument wiring, help for every option, outputs,
one-line errors."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from darthand.cli import build_parser
from darthand.errors import InputError
from darthand.model.npz_io import save_npz
from darthand.render import commands


def parser(name: str) -> argparse.ArgumentParser:
    """The real `darthand render` / `darthand render-checks` parser from cli.py."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


@pytest.mark.parametrize("name", ["render", "render-checks", "render-dataset"])
def test_every_option_has_help(name):
    p = parser(name)
    for action in p._actions:
        if action.dest != "help":
            assert action.help and len(action.help) > 10, action.dest
    text = p.format_help()
    assert all(opt in text for a in p._actions for opt in a.option_strings)


def test_render_command_writes_image_mask_labels(hand, tmp_path, capsys):
    model = tmp_path / "model" / "right.npz"
    save_npz(hand, model)
    pose = ",".join(["0"] * 3 + ["0.3"] * 45)
    args = parser("render").parse_args(
        [str(model), "--out", str(tmp_path / "out"), "--pose", pose, "--size", "64", "--camera", "palmar",
         "--samples", "4", "--depth", "--skin-tone-offset", "0.05", "--ao-rays", "8", "--skin", "wrap"])
    assert commands.render(args) == 0
    assert "64x64" in capsys.readouterr().out
    for name in ("image.png", "mask.png", "labels.json", "depth.exr"):
        assert (tmp_path / "out" / name).is_file()
    labels = json.loads((tmp_path / "out" / "labels.json").read_text())
    assert np.allclose(labels["mano_pose"][3:], 0.3) and labels["texture"]["id"] == "plain"
    assert labels["render"]["samples"] == 4
    assert labels["render"]["shading"] == {"ao_rays": 8, "interreflection": True, "skin": "wrap"}


def test_pose_argument_forms():
    assert commands.parse_pose(None) is None
    assert commands.parse_pose("fist") == "fist"
    assert commands.parse_pose("3") == 3
    assert commands.parse_pose("0,1,2").tolist() == [0, 1, 2]
    with pytest.raises(InputError, match="--pose"):
        commands.parse_pose("0,x,2")


def test_bad_package_is_an_input_error(tmp_path):
    args = parser("render").parse_args([str(tmp_path / "nothing.npz"), "--out", str(tmp_path)])
    with pytest.raises(InputError):
        commands.render(args)


def test_checks_command_needs_packages(tmp_path):
    args = parser("render-checks").parse_args(["--build", str(tmp_path)])
    with pytest.raises(InputError, match="no USD packages"):
        commands.checks(args)
