"""Values kept per model object (model/per_model.py) equal the same values worked out afresh, follow a new model, and
cannot be changed by a caller; the ring's sample cells (wear.first_in_cells) equal numpy's row-wise unique."""

import gc

import numpy as np
import pytest

from darthand.accessories.wear import first_in_cells
from darthand.model import anatomy
from darthand.model.mirror import mirror_model
from darthand.model.per_model import _VALUES, per_model
from synthetic import tube_hand


def test_joint_frames_kept_equal_a_fresh_computation_per_model():
    right, left = tube_hand(0), mirror_model(tube_hand(0))
    fresh_r, fresh_l = anatomy._joint_frames.__wrapped__(right), anatomy._joint_frames.__wrapped__(left)
    for _ in range(2):                               # the first call works it out, the second finds it
        assert np.array_equal(anatomy.joint_frames(right), fresh_r)
        assert np.array_equal(anatomy.joint_frames(left), fresh_l)
    assert not np.array_equal(fresh_r, fresh_l)     # two models, two entries


def test_joint_frames_hands_out_a_copy_the_caller_may_change():
    model = tube_hand(0)
    frames = anatomy.joint_frames(model)
    frames[:] = 0
    assert np.array_equal(anatomy.joint_frames(model), anatomy._joint_frames.__wrapped__(model))


def test_a_model_with_other_arrays_gets_its_own_values():
    model = tube_hand(0)
    moved = model.replace(v_template=model.v_template * 1.1)
    assert np.allclose(anatomy.joint_frames(moved), anatomy.joint_frames(model))      # frames are scale-free
    assert anatomy._joint_frames(moved) is not anatomy._joint_frames(model)


def test_kept_values_are_read_only_and_dropped_with_their_model():
    calls = []

    @per_model
    def vertex_sum(model):
        calls.append(1)
        return model.v_template.sum(0), len(model.faces)

    model = tube_hand(0)
    first = vertex_sum(model)
    assert vertex_sum(model) is first and len(calls) == 1
    with pytest.raises(ValueError):
        first[0][0] = 1.0
    gc.collect()                                     # models of earlier tests gone first: only this one dies below
    n = len(_VALUES)
    del model, first
    gc.collect()
    assert len(_VALUES) == n - 1


def test_first_in_cells_matches_numpy_unique_over_rows():
    rng = np.random.default_rng(7)
    for _ in range(200):
        n, d = int(rng.integers(0, 2000)), int(rng.integers(1, 4))
        half = int(rng.integers(1, 60))
        cells = rng.integers(-half, half, (n, d)).astype(np.int64)
        want = np.sort(np.unique(cells, axis=0, return_index=True)[1]) if n else np.zeros(0, np.int64)
        assert np.array_equal(first_in_cells(cells), want)
    huge = rng.integers(-2 ** 40, 2 ** 40, (300, 3))           # keys would overflow: the row-wise path
    huge = huge[rng.integers(0, 150, 300)]                     # rows repeated
    firsts = sorted(int(np.flatnonzero((huge == row).all(1))[0]) for row in np.unique(huge, axis=0))
    assert np.array_equal(first_in_cells(huge), firsts)
