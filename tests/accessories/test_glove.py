"""Gloves: a closed shell at the requested offsets from the hand, carrying the hand's skinning, posing with it."""

import numpy as np
import pytest
import trimesh

from darthand.accessories.attach import pose_skinned
from darthand.accessories.generators.glove import STYLES, glove
from darthand.model.forward import forward
from darthand.model.wrist import add_wrist
from synthetic import tube_hand


@pytest.fixture(scope="module")
def hand():
    return add_wrist(tube_hand(0), rings=4, length=0.05)


@pytest.mark.parametrize("style", STYLES)
def test_glove_is_a_closed_shell_at_its_offsets(hand, style):
    c, t = 0.0003, 0.001
    g = glove(hand, dict(style=style, thickness=t, clearance=c, cuff=0.03, cut=0.5), np.random.default_rng(0))
    tm = trimesh.Trimesh(g.vertices, g.faces, process=False)
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    sk = g.skin
    src = hand.v_template[sk["source_vertex"]]
    d = np.linalg.norm(g.vertices - src, axis=1)
    assert np.allclose(d[sk["layer"] == 0], c + t) and np.allclose(d[sk["layer"] == 1], c)
    assert np.array_equal(sk["weights"], hand.weights[sk["source_vertex"]])
    assert np.array_equal(sk["posedirs"], hand.posedirs[sk["source_vertex"]])
    assert g.uvs.min() >= 0 and g.uvs.max() <= 1
    # Nothing past the cuff (30 mm beyond the wrist joint along the forearm, +X here).
    j0 = (hand.J_regressor @ hand.v_template)[0]
    assert (src[:, 0] - j0[0]).max() <= 0.03 + 1e-9


def test_fingerless_glove_covers_less(hand):
    full = glove(hand, dict(style="wool", thickness=0.001, clearance=0.0003, cuff=0.03), np.random.default_rng(0))
    cut = glove(hand, dict(style="fingerless", thickness=0.001, clearance=0.0003, cuff=0.03, cut=0.5),
                np.random.default_rng(0))
    assert len(cut.faces) < len(full.faces)


def test_zero_offset_glove_poses_exactly_like_the_hand(hand):
    """With no offset the outer layer is the hand itself, so its skinning must reproduce the forward pass."""
    g = glove(hand, dict(style="latex", thickness=0.0, clearance=0.0, cuff=0.03), np.random.default_rng(0))
    rng = np.random.default_rng(5)
    pose = 0.4 * rng.standard_normal((3, 48))
    posed = forward(hand, pose)
    mine = pose_skinned(g.vertices, g.skin["weights"], g.skin["posedirs"], posed.rotations, posed.transforms)
    assert np.allclose(mine, posed.vertices[:, g.skin["source_vertex"]], atol=1e-12)
