"""The runners' interface (dataset/runner.Runner): every runner in the table implements what run.py uses, with the
Protocol's signatures, without a cluster being started (importing the Ray runner does not import Ray)."""

from __future__ import annotations

import importlib
import inspect

import pytest

from darthand.dataset.runner import RUNNERS, Runner, make_runner
from darthand.errors import InputError

METHODS = [name for name, value in vars(Runner).items() if callable(value) and not name.startswith("_")]


def _runner_class(kind: str):
    module, _, name = RUNNERS[kind].partition(":")
    return getattr(importlib.import_module(module), name)


def _parameters(function) -> list[str]:
    return list(inspect.signature(function).parameters)


@pytest.mark.parametrize("kind", sorted(RUNNERS))
def test_every_runner_implements_the_runner_protocol(kind):
    cls = _runner_class(kind)
    assert Runner in cls.__mro__
    assert sorted(METHODS) == ["close", "describe", "stop", "submit"]
    for name in METHODS:
        assert getattr(cls, name) is not getattr(Runner, name), f"{cls.__name__}.{name} is the Protocol's stub"
        assert _parameters(getattr(cls, name)) == _parameters(getattr(Runner, name)), name
    assert _parameters(cls.__init__)[:6] == ["self", "specs", "settings", "sources", "processes", "threads"]


def test_a_local_runner_in_this_process_is_a_runner(tmp_path):
    runner = make_runner(None, {}, {"out_dir": str(tmp_path)}, None, processes=4, threads=None, frames=1)
    try:
        assert isinstance(runner, Runner)
        assert runner.processes == 1 and runner.describe() == {"kind": "local"}
    finally:
        runner.close()


def test_an_unknown_cluster_engine_is_a_one_line_error(tmp_path):
    with pytest.raises(InputError, match="'slurm' is not one of ray"):
        make_runner({"engine": "slurm"}, {}, {"out_dir": str(tmp_path)}, None, None, None, 1)
