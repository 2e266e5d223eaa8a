"""Fixtures of the dataset stage's tests: a package on disk (the open hand with the wrist, two texture variants of a
generated skin, a ring), built here as worker processes open it, and one small rendered dataset shared by the
writer, report and eval tests."""

from __future__ import annotations

import json

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))
from helpers_dataset import TEXTURES, render  # noqa: E402
from render_scenes import RING_JOINT, ring_around, write_image  # noqa: E402

from darthand.model.load import load_model
from darthand.model.npz_io import save_npz
from darthand.model.wrist import add_wrist



@pytest.fixture(scope="session")
def hand():
    return add_wrist(load_model("open"))


@pytest.fixture(scope="session")
def package(hand, tmp_path_factory):
    """(model .npz, texture catalogue, accessory catalogue) on disk."""
    root = tmp_path_factory.mktemp("package")
    model = root / "model" / "right.npz"
    save_npz(hand, model)
    tex = root / "textures"
    tex.mkdir()
    y, x = np.mgrid[0:64, 0:64] / 63.0
    write_image(tex / "skin.png", np.clip(np.array([224, 172, 140]) * (0.85 + 0.15 * x[..., None]), 0, 255)
                .astype(np.uint8))
    write_image(tex / "rough.png", np.full((64, 64), 140, np.uint8))
    sha = "0" * 64
    entry = {"category": "moles", "kind": "overlay", "tone": "light", "mst": 2.0, "tone_srgb": [0.8, 0.6, 0.5],
             "offset": 0.0, "seed": 1, "resolution": 64, "sha256": sha, "fingerprint": sha, "params": {"skin": {}},
             "files": {"albedo": "skin.png", "roughness": "rough.png", "tx": None}}
    _write(tex / "catalog.json", {
        "format": "darthand-texture-catalog", "version": 1, "resolution": 64, "seed": 1, "spec_sha256": sha,
        "bake": {"key": sha, "uvs": "model", "labels": "labels.png", "coverage": "coverage.png"},
        "model": {"source": "test", "vertices": len(hand.v_template), "faces": len(hand.faces)},
        "contact_sheet": None, "entries": [dict(entry, id=t, index=i) for i, t in enumerate(TEXTURES)]})
    ring = ring_around(hand, RING_JOINT, RING_JOINT + 1)
    acc = root / "accessories"
    acc.mkdir()
    np.savez(acc / "ring_test.npz", vertices=ring.vertices, faces=ring.faces, rest_transform=ring_frame(hand))
    _write(acc / "catalog.json", {
        "format": "darthand-accessory-catalog", "format_version": 1, "seed": 1,
        "model": {"source": "test", "side": "right"},
        "accessories": [{"id": "ring_test", "type": "ring", "style": "torus", "parent_joint": ring.parent_joint,
                         "rest_transform": np.eye(4).tolist(), "fitted_size": {}, "vertices": len(ring.vertices),
                         "triangles": len(ring.faces), "max_penetration_mm": {"rest": 0.0, "poses": None},
                         "files": {"npz": "ring_test.npz", "obj": "-", "mtl": "-", "base_color": "-",
                                   "metallic_roughness": "-"},
                         "material": {**ring.material, "kind": "metal", "base_color_texture": None,
                                      "metallic_roughness_texture": None}}]})
    return str(model), str(tex), str(acc)


def ring_frame(hand) -> np.ndarray:
    """(4, 4) the test ring's local frame in the rest hand (as a catalogue's fit records it): x along its bone, at
    the bone's middle, where ring_around centres it; dataset sources wear rings along that axis."""
    J = hand.J_regressor @ hand.v_template
    a, b = J[RING_JOINT], J[RING_JOINT + 1]
    axis = (b - a) / np.linalg.norm(b - a)
    side = np.cross(axis, [0, 0, 1.0])
    side /= np.linalg.norm(side)
    frame = np.eye(4)
    frame[:3, :3] = np.stack([axis, side, np.cross(axis, side)], axis=1)
    frame[:3, 3] = (a + b) / 2
    return frame


@pytest.fixture(scope="session")
def sources(package):
    """{side: opened source} for both hands (the left one is the model mirrored)."""
    from darthand.dataset.sources import source_specs

    model, tex, acc = package
    specs = source_specs(model, ("right", "left"), textures=tex, accessories=acc)
    return {side: spec.open() for side, spec in specs.items()}, specs


@pytest.fixture(scope="session")
def planner(sources):
    from darthand.dataset.plan import Planner

    return Planner({"seed": 3, "accessory_share": 0.5}, sources[0])


@pytest.fixture(scope="session")
def small_dataset(planner, sources, tmp_path_factory):
    """A rendered dataset of 16 frames (both hands, backgrounds, random lights, the DART pose sampler)."""
    out = tmp_path_factory.mktemp("dataset")
    doc = render(planner, sources, out, 16, shard_size=8)
    return out, doc


@pytest.fixture(scope="session")
def mano_dataset(tmp_path_factory):
    """(dataset folder, MANO_RIGHT.pkl, MANO_LEFT.pkl): 12 frames of both hands rendered from the MANO-format fixture
    (tests/model/mano_fixture.py), each side's model read from its own pickle and given DART's wrist, as
    `make assets MANO=...` builds them; plain skin, no accessories."""
    from darthand.dataset.plan import Planner
    from darthand.dataset.sources import source_specs

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "model"))
    from mano_fixture import write_mano_like

    root = tmp_path_factory.mktemp("mano_dataset")
    pkls = write_mano_like(root / "mano")
    for side, pkl in zip(("right", "left"), pkls):
        save_npz(add_wrist(load_model(str(pkl))), root / "model" / f"{side}.npz")
    specs = source_specs(str(root / "model" / "right.npz"), ("right", "left"))
    opened = {side: spec.open() for side, spec in specs.items()}
    render(Planner({"seed": 5, "accessory_share": 0.0}, opened), (opened, specs), root / "dataset", 12)
    return root / "dataset", pkls[0], pkls[1]


def _write(path, doc) -> None:
    path.write_text(json.dumps(doc))


@pytest.fixture(scope="session")
def two_hand_dataset(sources, tmp_path_factory):
    """(dataset folder, two-hand frame indices): 16 frames planned with two hands on half of them (issue 29: the
    interaction sampler, the renderer's per-hand labels, (2, V, 3) meshes and instance maps), as `small_dataset`'s
    plan otherwise."""
    from darthand.dataset.plan import Planner

    out = tmp_path_factory.mktemp("two_hands") / "dataset"
    render(Planner({"seed": 3, "accessory_share": 0.5, "two_hands": 0.5}, sources[0]), sources, out, 16)
    return out, [int(p.stem) for p in sorted((out / "labels").glob("*.json")) if "hands" in json.loads(p.read_text())]
