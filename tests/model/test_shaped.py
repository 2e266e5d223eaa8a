"""HandModel.shaped checks only the new template of a checked model: the same model as the full check's path
(`replace`, every field checked), and a model that never passed check_model still gets the full check."""

import dataclasses

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.shape import shaped_vertices
from synthetic import tube_hand


def fields(model: HandModel) -> dict:
    return {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}


def test_shaped_equals_the_fully_checked_copy():
    model = tube_hand(0)
    rng = np.random.default_rng(11)
    for _ in range(5):
        betas = rng.normal(0, 1.5, rng.integers(1, model.num_betas + 1))
        fast = model.shaped(betas)
        full = model.replace(v_template=shaped_vertices(model, betas), meta=fast.meta)
        for name, value in fields(full).items():
            mine = getattr(fast, name)
            if hasattr(value, "toarray"):
                value, mine = value.toarray(), mine.toarray()
            assert np.array_equal(np.asarray(mine), np.asarray(value)), name
        assert fast.meta["betas"][:len(betas)] == pytest.approx(betas)
        twice = fast.shaped(betas)                         # a shaped model is a checked one too
        assert np.allclose(twice.v_template, shaped_vertices(fast, betas))


def test_a_model_never_checked_gets_the_full_check():
    model = tube_hand(0)
    posedirs = model.posedirs.copy()
    posedirs[3, 1, 7] = np.nan
    unchecked = HandModel(**{**fields(model), "posedirs": posedirs})
    with pytest.raises(InputError, match="field 'posedirs' has a non-finite value"):
        unchecked.shaped(np.ones(model.num_betas))
