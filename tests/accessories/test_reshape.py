"""Accessories refitted to hand shapes (accessories/reshape.py).

Truth: the stage's own fit cut afresh on the shaped hand (fit_ring / fit_wrist: trimesh plane sections, not the
tracked points), a glove generated on the shaped hand, and for clearance an independent inside test and distance
(trimesh's ray parity, a brute-force point-to-triangle distance over every triangle).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from darthand.accessories import catalog as cat
from darthand.accessories.fit import finger_frame, fit_ring, fit_wrist, wrist_axis
from darthand.accessories.generators.glove import glove
from darthand.accessories.item import generate
from darthand.accessories.loader import Accessory
from darthand.accessories.reshape import ShapeRefitter
from darthand.model.npz_io import load_npz
from darthand.model.wrist import add_wrist

TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"
pytestmark = pytest.mark.skipif(not TEMPLATE.is_file(), reason="open template not imported yet")


@pytest.fixture(scope="module")
def hand():
    return add_wrist(load_npz(TEMPLATE))


@pytest.fixture(scope="module")
def items(hand):
    """A ring, a watch, a bracelet and a glove of the catalogue, generated on the open hand, as the loader gives
    them (rest-frame vertices, rest transform, a glove's shape directions)."""
    spec = cat.load_spec()
    seed = int(spec["seed"])
    out = {}
    for e in cat.entries(spec, ["ring_02_flat_silver", "watch_03_round_metal", "bracelet_13_cuff_silver",
                                "glove_01_latex"]):
        b = generate(hand, e, seed)
        skin = b.mesh.skin or {}
        out[e["type"]] = Accessory(
            id=b.id, vertices=b.world_vertices, faces=b.mesh.faces, parent_joint=None if b.fit is None else b.fit.joint,
            weights=skin.get("weights"), posedirs=skin.get("posedirs"), shapedirs=skin.get("shapedirs"),
            rest_transform=None if b.fit is None else b.rest, kind=e["type"]), b
    return out


def test_the_built_shape_changes_nothing(hand, items):
    refitter = ShapeRefitter(hand, [a for a, _ in items.values()])
    for acc, refit in zip([a for a, _ in items.values()], refitter.refit(np.zeros(hand.num_betas))):
        assert np.abs(refit.vertices - acc.vertices).max() < 1e-9, acc.id


SHAPES = [np.eye(10)[0] * 3, -np.eye(10)[0] * 3, np.eye(10)[1] * 3, -np.eye(10)[1] * 3,
          *np.clip(np.random.default_rng(3).standard_normal((3, 10)), -3, 3)]


@pytest.mark.parametrize("k", range(len(SHAPES)))
def test_tracked_bores_match_a_fresh_cut_of_the_shaped_hand(hand, items, k):
    """The bore from the tracked section points against fit.py cutting the shaped mesh again (same place, same
    width): within 0.6 mm over extreme and sampled shapes, while the shapes change the bores by millimetres."""
    refitter = ShapeRefitter(hand, [a for a, _ in items.values()])
    b = SHAPES[k]
    shaped = hand.shaped(b)
    for kind in ("ring", "watch", "bracelet"):
        acc, built = items[kind]
        sec = refitter.section(acc.id)
        key = refitter.keys[acc.id]
        frame, bore = refitter.fit_of(acc.id, b)
        if kind == "ring":                    # the place it sits: its fraction along the shaped phalanx
            start, end = finger_frame(shaped, sec.finger, 0.0)[:3, 3], finger_frame(shaped, sec.finger, 1.0)[:3, 3]
            t = float((frame[:3, 3] - start) @ (end - start) / np.sum((end - start) ** 2))
            fresh = fit_ring(shaped, sec.finger, key[4], 0.0, t).bore["inner_radius"]
            assert abs(bore[0] - fresh) < 6e-4, (kind, bore, fresh)
        else:                                 # its distance from the shaped wrist joint along the forearm
            j0, axis = wrist_axis(shaped)
            f = fit_wrist(shaped, float((frame[:3, 3] - j0) @ axis), key[4], 0.0).bore
            assert abs(bore[0] - f["inner_a"]) < 6e-4 and abs(bore[1] - f["inner_b"]) < 6e-4, (kind, bore, f)


def brute_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Exact distance from points (K, 3) to a surface: the nearest of every triangle (trimesh's point-triangle
    routine over all K x F pairs; no spatial index, unlike the code under test). MeshLab's per-vertex distance
    filter was tried first and reported 0.023 mm where every triangle is at least 0.129 mm away."""
    tris = vertices[faces]
    out = np.empty(len(points))
    for k, p in enumerate(points):
        out[k] = np.linalg.norm(trimesh.triangles.closest_point(tris, np.repeat(p[None], len(tris), 0)) - p,
                                axis=1).min()
    return out


def deepest_inside(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> float:
    """Deepest of the points inside the closed surface (trimesh's ray parity; exact brute-force depth), 0 if none
    is (m)."""
    inside = trimesh.Trimesh(vertices, faces, process=False).ray.contains_points(points)
    return float(brute_distance(points[inside], vertices, faces).max()) if inside.any() else 0.0


def test_a_refitted_ring_clears_the_larger_hand_and_the_unrefitted_one_does_not(hand, items):
    """On the largest hand of the first direction (+3: about 2.5 standard deviations of hand length above the mean
    hand), no vertex of the shaped rest finger is inside the refitted ring, while the ring fitted to the mean hand
    cuts into it."""
    acc, _ = items["ring"]
    big = np.eye(10)[0] * 3
    if forward_length(hand, big) < forward_length(hand, -big):
        big = -big
    shaped = hand.shaped(big)
    refit = ShapeRefitter(hand, [acc]).refit(big)[0]
    finger = shaped.v_template
    assert deepest_inside(finger, refit.vertices, refit.faces) < 1e-5
    # the unrefitted ring, carried by the shaped hand's own finger frame (rest transforms move with the joints)
    assert deepest_inside(finger, acc.vertices, acc.faces) > 2e-4


def forward_length(hand, betas) -> float:
    v = hand.shaped(betas).v_template
    return float(np.ptp(v[:, 0]))


def test_a_refitted_glove_is_the_glove_of_the_shaped_hand(hand, items):
    """Glove vertices carry the hand's shape directions: the refit equals a glove generated on the shaped hand
    but for the turn of the vertex normals it is offset along (under 0.15 mm at |beta| = 3)."""
    acc, built = items["glove"]
    b = np.eye(10)[0] * 3
    refit = ShapeRefitter(hand, [acc]).refit(b)[0]
    fresh = glove(hand.shaped(b), built.entry, cat.item_rng(int(cat.load_spec()["seed"]), acc.id))
    # the glove of the shaped hand may end at another forearm ring (its cuff is a distance from the wrist): compare
    # the vertices both have, by (hand vertex, layer)
    mine = {(int(v), int(k)): i for i, (v, k) in enumerate(zip(built.mesh.skin["source_vertex"],
                                                                built.mesh.skin["layer"]))}
    theirs = zip(fresh.skin["source_vertex"], fresh.skin["layer"])
    pairs = [(mine[(int(v), int(k))], j) for j, (v, k) in enumerate(theirs) if (int(v), int(k)) in mine]
    assert len(pairs) > 0.95 * len(fresh.vertices)
    a, b = np.array(pairs).T
    assert np.abs(fresh.vertices[b] - refit.vertices[a]).max() < 1.5e-4


def test_the_renderer_wears_the_accessory_refitted_to_the_frames_shape(hand, items):
    """render.assets.HandAssets with betas: the hand of that shape and the ring refitted to it, carried by the
    shaped hand's joint; without betas the catalogue's own ring."""
    from darthand.model.forward import forward
    from darthand.render.assets import HandAssets

    acc, _ = items["ring"]
    assets = HandAssets(hand, accessories={acc.id: acc})
    pose = np.random.default_rng(2).normal(0, 0.3, 48)
    b = np.eye(10)[0] * 2.0
    subject = assets.subject(pose, accessory=acc.id, betas=b)
    ring = next(s for s in subject.surfaces if s.role == "accessory")
    G = forward(hand, pose[None], b[None]).transforms[0, acc.parent_joint]
    expected = ShapeRefitter(hand, [acc]).refit(b)[0].vertices @ G[:3, :3].T + G[:3, 3]
    assert np.abs(ring.vertices - expected).max() < 1e-5                   # float32 posing
    plain = next(s for s in assets.subject(pose, accessory=acc.id).surfaces if s.role == "accessory")
    G0 = forward(hand, pose[None]).transforms[0, acc.parent_joint]
    assert np.abs(plain.vertices - (acc.vertices @ G0[:3, :3].T + G0[:3, 3])).max() < 1e-5


def test_penetration_over_shapes_matches_an_independent_measure(hand, items):
    """shape_sweep's `fit` figure (Embree inside test, KD-tree distances) against trimesh's ray parity and MeshLab's
    distance for the ring, on a tight variant (no clearance: the skin reaches the bore), two shapes, two gestures;
    and the refit keeps the ring off its finger where the unrefitted one cuts in."""
    from darthand.accessories.shape_sweep import own_vertices, penetration_over_shapes
    from darthand.model.forward import forward
    from darthand.model.poses import gesture_poses

    entry = cat.entries(cat.load_spec(), ["ring_02_flat_silver"])[0]
    tight = generate(hand, {**entry, "t": 0.5}, int(cat.load_spec()["seed"]), clearance=0.0)
    acc = Accessory(id="tight", vertices=tight.world_vertices, faces=tight.mesh.faces, parent_joint=tight.fit.joint,
                    rest_transform=tight.rest, kind="ring")
    names, poses = gesture_poses(hand, ["fist", "spread"])
    betas = np.stack([np.zeros(10), np.eye(10)[0] * 3])
    res = penetration_over_shapes(hand, [acc], betas, poses)
    refit = ShapeRefitter(hand, [acc]).refit(betas[1])[0]
    posed = forward(hand, poses, np.tile(betas[1], (2, 1)))
    own = own_vertices(hand, acc)
    for g in range(2):
        G = posed.transforms[g, acc.parent_joint]
        inv = np.linalg.inv(G)
        in_frame = posed.vertices[g][own] @ inv[:3, :3].T + inv[:3, 3]
        truth = deepest_inside(in_frame, refit.vertices, refit.faces)
        assert res["fit"][0, 1, g] == pytest.approx(truth, abs=2e-5)
    assert res["fit"][0, 1].max() > 5e-5                       # the comparison above compared real depths
    unrefit = penetration_over_shapes(hand, [acc], betas, poses, refit=False)
    assert unrefit["fit"][0, 1].max() > res["fit"][0, 1].max() + 1e-4


def test_the_left_hand_refit_is_the_mirror_image_of_the_right(hand, items):
    """Accessories mirrored by the loader (rest frames included) refit on the mirrored hand to the mirror image of
    the right hand's refit."""
    from darthand.accessories.loader import mirror_accessory
    from darthand.model.mirror import mirror_model

    right = [a for a, _ in items.values()]
    b = np.random.default_rng(5).standard_normal(10)
    expected = ShapeRefitter(hand, right).refit(b)
    got = ShapeRefitter(mirror_model(hand), [mirror_accessory(a) for a in right]).refit(b)
    for e, g in zip(expected, got):
        assert np.abs(g.vertices - e.vertices * [-1, 1, 1]).max() < 1e-6, e.id
