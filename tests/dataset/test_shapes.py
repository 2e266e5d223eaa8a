"""Hand shapes in datasets: the beta distribution of a plan, betas in the jobs and labels, the rendered hand of that
shape.

Truth: scipy.stats' truncated normal and uniform distributions (moments and a Kolmogorov-Smirnov test on the drawn
betas), and the forward pass of the labels' MANO parameters (betas included) against the mesh the frame wrote.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from darthand.dataset import plan
from helpers_dataset import BakedPackage
from darthand.dataset.shapes import ShapeSampler
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.schemas import check_schema
from darthand.template.anthropometry import hand_sizes


def draws(sampler, n=1500, seed=2):
    return np.array([sampler.sample(seed, i) for i in range(n)])


def test_default_betas_are_a_truncated_standard_normal():
    b = draws(ShapeSampler(None, 10))
    assert b.shape == (1500, 10) and np.abs(b).max() <= 3.0
    truth = stats.truncnorm(-3, 3)
    for i in range(10):
        assert stats.kstest(b[:, i], truth.cdf).pvalue > 1e-3
    assert abs(b.std() - truth.std()) < 0.03 and abs(b.mean()) < 0.03
    assert abs(np.corrcoef(b.T)[np.triu_indices(10, 1)]).max() < 0.1        # independent directions


def test_other_distributions_and_dims():
    u = draws(ShapeSampler({"mode": "uniform", "limit": 2.0}, 10))
    assert stats.kstest(u[:, 3], stats.uniform(-2, 4).cdf).pvalue > 1e-3
    narrow = draws(ShapeSampler({"sigma": 0.5, "limit": 1.0, "dims": 3}, 10))
    assert np.all(narrow[:, 3:] == 0) and np.abs(narrow).max() <= 1.0
    assert stats.kstest(narrow[:, 0], stats.truncnorm(-2, 2, scale=0.5).cdf).pvalue > 1e-3
    assert ShapeSampler({"mode": "none"}, 10).sample(0, 5) is None
    assert ShapeSampler(None, 0).sample(0, 5) is None                      # a model without shape directions


@pytest.mark.parametrize("opts, message", [
    ({"mode": "wide"}, "normal, uniform, none"), ({"sigma": 0}, "positive"), ({"limit": float("nan")}, "positive"),
    ({"dims": 11}, "0..10"), ({"spread": 1}, "unknown option"),
])
def test_bad_shape_options_are_one_line_errors(opts, message):
    with pytest.raises(InputError, match=message):
        ShapeSampler(opts, 10)


def test_jobs_carry_betas_deterministically_and_per_frame(sources):
    a = plan.Planner({"seed": 7}, sources[0])
    jobs = list(a.jobs(0, 30))
    check_schema({"frames": jobs}, "dataset_jobs.schema.json", "plan")
    assert jobs == list(plan.Planner({"seed": 7}, sources[0]).jobs(0, 30))
    betas = np.array([j["betas"] for j in jobs])
    assert betas.shape == (30, a.model.num_betas) and len({tuple(b) for b in betas}) == 30
    # the shape stream is its own: another shape distribution leaves every other choice as it was
    none = list(plan.Planner({"seed": 7, "shapes": "none"}, sources[0]).jobs(0, 30))
    assert all("betas" not in j for j in none)
    assert [{k: v for k, v in j.items() if k not in ("betas", "sample")} for j in jobs] == \
        [{k: v for k, v in j.items() if k not in ("betas", "sample")} for j in none]
    assert a.spec["shapes"] == {"mode": "normal", "sigma": 1.0, "limit": 3.0, "dims": a.model.num_betas}


def test_rendered_frames_have_the_shape_of_their_labels(small_dataset, sources):
    """The shared small dataset samples shapes by default: each frame's mesh is forward(model, labels' MANO
    parameters with their betas), and its recorded hand length and breadth are the shaped hand's."""
    out, _ = small_dataset
    opened, _ = sources
    lengths = []
    for path in sorted((out / "labels").iterdir()):
        labels = json.loads(path.read_text())
        model = opened[labels["side"]].model
        mano, shape = labels["mano"], labels["sample"]["shape"]
        assert np.abs(mano["betas"]).max() > 0.05 and mano["betas"] == shape["betas"] == shape["absolute_betas"]
        posed = forward(model, np.concatenate([mano["global_orient"], mano["hand_pose"]])[None], mano["betas"],
                        trans=np.asarray(mano["trans"])[None])
        vertices = np.load(path.parent / labels["files"]["vertices"])
        assert np.abs(posed.vertices[0] - vertices).max() < 5e-6
        mean_shape = forward(model, np.concatenate([mano["global_orient"], mano["hand_pose"]])[None],
                             trans=np.asarray(mano["trans"])[None])
        assert np.abs(mean_shape.vertices[0] - vertices).max() > 5e-4       # the shape did change the hand
        rest = forward(model, np.zeros(48), mano["betas"]).vertices
        assert shape["hand_length_mm"] == pytest.approx(hand_sizes(model, rest)["hand_length_mm"][0], abs=0.01)
        lengths.append(shape["hand_length_mm"])
    assert np.ptp(lengths) > 5                                                # hands of different sizes


def test_a_usd_package_cannot_sample_shapes(tmp_path):
    def Package():
        return BakedPackage(("fist",), ("plain",), ("none",))

    planner = plan.Planner({"seed": 0}, {"right": Package()})                  # default: its baked shape
    assert "betas" not in planner.job(0) and planner.spec["shapes"]["mode"] == "none"
    with pytest.raises(InputError, match="baked shape"):
        plan.Planner({"seed": 0, "shapes": "uniform"}, {"right": Package()})
