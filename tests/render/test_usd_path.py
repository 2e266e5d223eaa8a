"""The USD path: a package written by the exporter, its variants selected and posed by UsdSkel, renders the same
image, mask and keypoints as the internal path (darthand's forward pass) for the same gesture; the render checks
pass on it and catch broken UVs."""

from __future__ import annotations

import dataclasses

import jsonschema
import numpy as np
import pytest
from darthand.errors import InputError
from darthand.export.usd_asset import export_usd
from darthand.model.poses import gesture_poses
from darthand.render.api import Renderer, open_source
from darthand.render.checks import check_package, check_uv_seams
from darthand.schemas import load_schema

GESTURES = ["flat", "fist", "ok"]
SIZE = 128


@pytest.fixture(scope="module")
def package(hand, texture_files, ring, tmp_path_factory):
    out = tmp_path_factory.mktemp("usd") / "right"
    export_usd(hand, out, textures=[texture_files], accessories=[ring], gestures=gesture_poses(hand, GESTURES))
    return out


@pytest.mark.parametrize("gesture, accessory, view", [("fist", "ring_test", "dorsal"), ("ok", "none", "radial")])
def test_usd_and_internal_paths_render_the_same(package, assets, hand, gesture, accessory, view):
    usd = Renderer(open_source(package, model=hand), threads=1)
    a = usd.render(gesture, texture="skin_test", accessory=accessory, camera=view, width=SIZE, height=SIZE)
    b = Renderer(assets, threads=1).render(gesture, texture="skin_test", accessory=accessory, camera=view,
                                           width=SIZE, height=SIZE)
    # UsdSkel's skinning of float32 points agrees with the forward pass to ~1e-7 m: the same pixels are covered.
    for s, t in zip(a.subject.surfaces, b.subject.surfaces):
        assert np.abs(s.vertices - t.vertices).max() < 1e-6
    assert np.abs(a.alpha - b.alpha).mean() < 1e-3
    assert np.array_equal(a.geom, b.geom) or (a.geom != b.geom).mean() < 1e-3
    assert np.abs(a.colour - b.colour).mean() < 1e-3
    assert np.allclose(a.labels["keypoints_2d"], b.labels["keypoints_2d"], atol=1e-3)
    assert a.labels["visibility"] == b.labels["visibility"]
    assert a.labels["mano_pose"] == pytest.approx(b.labels["mano_pose"], abs=1e-9)
    assert a.labels["accessory"] == b.labels["accessory"]
    jsonschema.Draft202012Validator(load_schema("labels.schema.json")).validate(a.labels)


def test_usd_variants_and_errors(package, hand):
    src = open_source(package, model=hand)
    assert src.gestures == GESTURES
    assert "skin_test" in src.texture_ids() and src.accessory_ids() == ["none", "ring_test"]
    with pytest.raises(InputError, match="texture"):
        src.subject("fist", texture="nope")
    with pytest.raises(InputError, match="gestures"):
        src.subject("wave")
    with pytest.raises(InputError, match="time code"):
        src.subject(7)
    # The package lists the fingertip vertices itself (asset.json), so it opens without the model.
    np.testing.assert_array_equal(open_source(package).tip_ids, hand.tip_ids)


def test_checks_pass_on_a_good_package_and_catch_flipped_uvs(package, hand):
    src = open_source(package, model=hand)
    result = check_package(src, size=128, all_accessories=True)
    failed = {k: v["failures"] for k, v in result["checks"].items() if not v["ok"]}
    assert not failed, failed
    assert result["checks"]["accessories"]["checked"] == 1
    assert result["checks"]["uv_seams"]["max_error_m"] < 3 * result["checks"]["uv_seams"]["texel_m"]

    # The position texture is rasterised from the unflipped package, the lookup uses flipped UVs.
    good = check_uv_seams(Renderer(src), 96)["result"]
    assert not good["failures"]
    from darthand.render import checks as checks_module

    original = checks_module.position_texture
    try:
        checks_module.position_texture = lambda surface, res=checks_module.SEAM_RES: original(
            dataclasses.replace(surface, uvs=surface.uvs * [1, -1] + [0, 1]), res)
        bad = check_uv_seams(Renderer(src), 96)["result"]
    finally:
        checks_module.position_texture = original
    assert bad["failures"] and bad["max_error_m"] > 0.01


def test_run_checks_writes_report_and_sheets(package, hand, tmp_path):
    import json
    import shutil

    from darthand.model.npz_io import save_npz
    from darthand.render.checks import run_checks

    build = tmp_path / "build"
    shutil.copytree(package, build / "usd" / "right")
    save_npz(hand, build / "model" / "right.npz")
    report = run_checks(build, size=96)
    assert report["ok"], report
    saved = json.loads((build / "checks" / "report.json").read_text())
    assert saved["packages"]["right"]["renders"] >= 6
    for name in ("right.png", "right_accessories.png"):
        assert (build / "checks" / name).stat().st_size > 1000
