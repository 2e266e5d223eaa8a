"""model/preshape_crossing.py: the compiled self-crossing test gives model/self_crossing.py's verdict and its
digit-pair distances, on poses drawn uniformly within the joint limits (many of them self-crossing)."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.model.anatomy import angles_to_axis_angle, joint_frames, limits_radians
from darthand.model.forward import forward
from darthand.model.load import load_model
from darthand.model.preshape_crossing import PreshapeCrossing
from darthand.model.self_crossing import DIGIT_PAIRS, SelfCrossing
from darthand.model.topology import vertex_normals


@pytest.fixture(scope="module")
def model():
    return load_model("open")


def test_same_verdicts_and_distances_as_the_reference(model):
    reference, compiled = SelfCrossing(model), PreshapeCrossing(model)
    limits, frames = limits_radians(), joint_frames(model)
    rng = np.random.default_rng(0)
    verdicts = []
    for _ in range(12):
        angles = rng.uniform(limits[..., 0], limits[..., 1])
        angles[0] = 0.0
        pose = angles_to_axis_angle(model, angles, frames).reshape(1, -1)
        v = np.asarray(forward(model, pose).vertices[0], np.float64)
        verdicts.append(reference.crossing(v))
        assert compiled.crossing(v) == verdicts[-1]
        n = vertex_normals(v, model.faces)
        for p, q in DIGIT_PAIRS:
            expected = reference.surfaces.distance(v, n, p, q)
            assert compiled.surfaces.distance(v, n, p, q) == pytest.approx(expected, abs=1e-12)
    assert any(verdicts) and not all(verdicts)     # both outcomes met
