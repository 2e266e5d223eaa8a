"""The FreiHAND layout against FreiHAND's own recipe (root from uv and scale, MANO posed from the 61 values), the
WebDataset shards read by the `webdataset` package, `darthand eval` on cases with known answers, the report."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from scipy.ndimage import binary_dilation
from scipy.spatial.transform import Rotation

from darthand.cli import main
from darthand.dataset import metrics
from darthand.dataset.evaluate import evaluate_files, write_predictions
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.model.pose_library import library_poses


def freihand_sets(folder):
    """{set name: {kind: list}} of a FreiHAND export (K, xyz, verts, mano, frames)."""
    return {name: {k: json.loads((folder / f"{name}_{k}.json").read_text())
                   for k in ("K", "xyz", "verts", "mano", "frames")}
            for name in ("training", "validation", "evaluation") if (folder / f"{name}_xyz.json").is_file()}


def freihand_pose(model, theta, K, betas=None):
    """FreiHAND's toolbox recipe: (keypoints (21, 3) openpose order, vertices) of `model` posed from a 61-value row:
    the root = [(uv - pp), focal] / scale, MANO posed with its mean hand added (flat_hand_mean false) and moved so
    that its keypoint 9 lands on the root. betas: instead of the row's shape slots."""
    theta, K = np.asarray(theta, float), np.asarray(K, float)
    focal, pp = 0.5 * (K[0, 0] + K[1, 1]), K[:2, 2]
    root = np.append(theta[58:60] - pp, focal) / theta[60]
    b = theta[48:58] if betas is None else np.asarray(betas, float)
    posed = forward(model, theta[:48][None], b[None], flat_hand_mean=False, keypoint_order="openpose")
    shift = root - posed.keypoints[0, 9]
    return posed.keypoints[0] + shift, posed.vertices[0] + shift


def test_freihand_of_a_mano_model_is_manos_convention(mano_dataset, tmp_path, capsys):
    """Every row, of a right frame or a mirrored left one, posed through MANO_RIGHT (read from the pickle: 778
    vertices, no wrist) the way FreiHAND's toolbox does gives the written keypoints and vertices."""
    from darthand.model.load import load_model

    out, right_pkl, _ = mano_dataset
    assert main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path)]) == 0
    assert "left-hand frames mirrored" in capsys.readouterr().out
    mano = load_model(str(right_pkl))
    rows, mirrored = 0, 0
    for s in freihand_sets(tmp_path).values():
        for k, frame in enumerate(s["frames"]):
            labels = json.loads((out / "labels" / f"{frame:06d}.json").read_text())
            theta = np.asarray(s["mano"][k][0])
            assert theta.shape == (61,) and np.allclose(theta[48:58], labels["mano"]["betas"])   # MANO's betas
            kp, verts = freihand_pose(mano, theta, s["K"][k])
            assert len(s["verts"][k]) == mano.num_vertices == 778
            assert np.abs(kp - s["xyz"][k]).max() < 1e-6 and np.abs(verts - s["verts"][k]).max() < 1e-6
            rows += 1
            mirrored += labels["side"] == "left"
    assert rows == 12 and 0 < mirrored < 12
    assert "values 48-57: MANO's betas" in (tmp_path / "README.md").read_text()


def test_freihand_mirrors_left_frames_onto_the_flipped_image(mano_dataset, tmp_path):
    """A left frame's row: its keypoints are the left hand's mirrored (x -> -x), project through the written K onto
    darthand's 2-D keypoints flipped left-right (u -> W - u) and onto the flipped mask; the image is flipped."""
    from darthand.render.image import read_png

    out, _, _ = mano_dataset
    main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path)])
    checked, least = 0, 1.0
    for name, s in freihand_sets(tmp_path).items():
        for k, frame in enumerate(s["frames"]):
            labels = json.loads((out / "labels" / f"{frame:06d}.json").read_text())
            if labels["side"] != "left":
                continue
            W = labels["image_size"][0]
            assert np.allclose(s["xyz"][k], np.asarray(labels["keypoints_3d"]) * [-1, 1, 1], atol=1e-12)
            uv = np.asarray(s["xyz"][k]) @ np.asarray(s["K"][k]).T
            flipped = np.asarray(labels["keypoints_2d"]) * [-1, 1] + [W, 0]         # pixel-corner origin
            assert np.allclose(uv[:, :2] / uv[:, 2:] + 0.5, flipped, atol=1e-6)
            # every vertex projects into the flipped mask (grown by a pixel: 48-pixel frames, rounding at the edge)
            png = read_png(out / "masks" / f"{frame:06d}.png")[..., 0]
            grown = binary_dilation(png > 0)
            p = np.asarray(s["verts"][k]) @ np.asarray(s["K"][k]).T
            px = np.rint(p[:, :2] / p[:, 2:]).astype(int)                            # OpenCV: centres at integers
            inside = (px >= 0).all(1) & (px[:, 0] < W) & (px[:, 1] < len(png))
            assert inside.mean() > 0.9 and grown[:, ::-1][px[inside, 1], px[inside, 0]].all()
            hits_unflipped = grown[px[inside, 1], px[inside, 0]].mean()
            jpeg = read_jpeg(tmp_path / name / "mask" / f"{k:08d}.jpg")[..., 0].astype(int)
            assert np.abs(jpeg - png[:, ::-1]).mean() < 3                          # the mask and image flipped too
            rgba = read_png(out / "images" / f"{frame:06d}.png").astype(float)
            rgb = read_jpeg(tmp_path / name / "rgb" / f"{k:08d}.jpg").astype(float)
            over_black = rgba[..., :3] * rgba[..., 3:] / 255                    # JPEG of a busy 48-pixel frame
            assert np.abs(rgb - over_black[:, ::-1]).mean() < 0.5 * np.abs(rgb - over_black).mean()
            least = min(least, hits_unflipped)
            checked += 1
    assert checked > 0 and least < 0.8          # the unflipped mask would not do: the check can fail


def test_mirrored_labels_project_onto_the_flipped_image_off_centre():
    """A principal point off the image centre (a crop): the mirrored points through the mirrored K land on the
    flipped pixel columns u -> W - u; the MANO rotations are conjugated by diag(-1, 1, 1)."""
    from darthand.dataset.freihand import mirror_labels

    rng = np.random.default_rng(2)
    points = rng.normal(size=(21, 3)) * 0.03 + [0.01, -0.02, 0.5]
    K = np.array([[300.0, 0.0, 70.0], [0.0, 310.0, 40.0], [0, 0, 1]])
    rot = Rotation.from_rotvec(rng.normal(size=(16, 3)))
    labels = {"K": K.tolist(), "image_size": [128, 96], "keypoints_3d": points.tolist(),
              "mano": {"global_orient": rot[0].as_rotvec().tolist(), "hand_pose": rot[1:].as_rotvec().ravel().tolist(),
                       "betas": [0.5] * 10, "trans": [0.1, 0.2, 0.3]}}
    m = mirror_labels(labels)
    uv, uv_m = points @ K.T, np.asarray(m["keypoints_3d"]) @ np.asarray(m["K"]).T
    assert np.allclose(uv_m[:, :2] / uv_m[:, 2:], np.c_[128 - uv[:, 0] / uv[:, 2], uv[:, 1] / uv[:, 2]])
    M = np.diag([-1.0, 1, 1])
    got = Rotation.from_rotvec(np.r_[[m["mano"]["global_orient"]], np.reshape(m["mano"]["hand_pose"], (15, 3))])
    assert np.allclose(got.as_matrix(), M @ rot.as_matrix() @ M) and m["mano"]["betas"] == [0.5] * 10


def read_jpeg(path):
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    return buf.get_pixels(oiio.UINT8)


def test_freihand_of_a_dataset_without_the_model_format_names_the_missing_record(small_dataset, tmp_path, capsys):
    """A dataset.json written before the model's format was recorded: the export cannot tell whether the hand is
    MANO and says which record is missing (exit 2, nothing written)."""
    out, _ = small_dataset
    old = tmp_path / "old"
    shutil.copytree(out, old)
    doc = json.loads((old / "dataset.json").read_text())
    for info in doc["models"].values():
        info.pop("format", None)
    (old / "dataset.json").write_text(json.dumps(doc))
    assert main(["dataset", "export", str(old), "--format", "freihand", "--out", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err
    assert "models.right does not record the model's format" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "no").exists()


def test_freihand_of_the_open_hand_is_refused_unless_asked(small_dataset, sources, tmp_path, capsys):
    """The open hand is not MANO: the export says so (exit 2, nothing written); with --allow-non-mano the shape
    slots are 0, README.md says why, and the rest of each row is exact for this hand (its own betas from the labels,
    FreiHAND's recipe)."""
    out, _ = small_dataset
    assert main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path / "no")]) == 2
    assert "is not a MANO model" in capsys.readouterr().err and not (tmp_path / "no").exists()
    assert main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path),
                 "--allow-non-mano"]) == 0
    assert "values 48-57: ZERO" in (tmp_path / "README.md").read_text()
    right = sources[0]["right"].model
    total = 0
    for name, s in freihand_sets(tmp_path).items():
        for k, frame in enumerate(s["frames"]):
            labels = json.loads((out / "labels" / f"{frame:06d}.json").read_text())
            theta = np.asarray(s["mano"][k][0])
            assert not theta[48:58].any()
            kp, verts = freihand_pose(right, theta, s["K"][k], labels["mano"]["betas"])
            assert len(s["verts"][k]) == right.meta["wrist"]["base_vertices"]
            assert np.abs(kp - s["xyz"][k]).max() < 1e-5
            assert np.abs(verts[:len(s["verts"][k])] - s["verts"][k]).max() < 1e-5
            if labels["side"] == "right":     # K in OpenCV's convention: darthand's keypoints_2d minus half a pixel
                uv = np.asarray(s["xyz"][k]) @ np.asarray(s["K"][k]).T
                assert np.allclose(uv[:, :2] / uv[:, 2:], np.asarray(labels["keypoints_2d"]) - 0.5, atol=1e-6)
        assert len(list((tmp_path / name / "rgb").glob("*.jpg"))) == len(s["frames"])
        total += len(s["frames"])
    assert total == 16
    assert main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path / "r"),
                 "--allow-non-mano", "--left", "skip"]) == 0
    rights = sum(1 for p in (out / "labels").iterdir() if json.loads(p.read_text())["side"] == "right")
    assert sum(len(s["frames"]) for s in freihand_sets(tmp_path / "r").values()) == rights < 16


def test_webdataset_shards_read_back_with_the_webdataset_package(small_dataset, tmp_path):
    import webdataset as wds

    out, _ = small_dataset
    main(["dataset", "export", str(out), "--format", "webdataset", "--out", str(tmp_path / "a")])
    main(["dataset", "export", str(out), "--format", "webdataset", "--out", str(tmp_path / "b")])
    shards = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert shards and all(n.split("-")[0] in ("train", "val", "test") and n.endswith("-000000.tar") for n in shards)
    assert all((tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes() for n in shards)
    seen = 0
    for name in shards:
        for sample in wds.WebDataset(str(tmp_path / "a" / name), shardshuffle=False):
            assert set(sample) >= {"__key__", "png", "mask.png", "json", "verts.npy"}
            labels = json.loads(sample["json"])
            assert sample["__key__"] == f"{labels['render']['dataset']['frame']:06d}"
            assert name.startswith(labels["split"])
            assert sample["png"] == (out / "images" / f"{sample['__key__']}.png").read_bytes()
            seen += 1
    assert seen == 16


def test_alignment_and_metrics_on_known_answers():
    rng = np.random.default_rng(0)
    gt = rng.normal(size=(4, 21, 3)) * 0.05
    verts = rng.normal(size=(4, 300, 3)) * 0.05
    R = Rotation.random(random_state=3).as_matrix()
    similar = 1.7 * gt @ R.T + [0.3, -0.2, 1.0]                  # a similarity transform of the ground truth
    out = metrics.evaluate(similar, gt, 1.7 * verts @ R.T + 0.5, verts)
    assert out["keypoints"]["pa_mpjpe_mm"] < 1e-9 and out["vertices"]["pa_mpvpe_mm"] < 1e-9
    assert out["vertices"]["pa_f@5mm"] == out["vertices"]["pa_f@15mm"] == 1.0
    shifted = metrics.evaluate(gt + [0.01, 0, 0], gt)["keypoints"]      # every keypoint 10 mm off, no alignment
    assert shifted["mpjpe_mm"] == pytest.approx(10.0) and shifted["pa_mpjpe_mm"] < 1e-9
    steps = np.linspace(0, 50, 100)                                       # PCK is 1 from the first step >= 10 mm
    first = int(np.argmax(steps >= 10))
    assert shifted["auc"] == pytest.approx((50 - steps[first] + (steps[first] - steps[first - 1]) / 2) / 50)
    mirrored = gt * [-1, 1, 1]                                            # a reflection is not a rotation
    assert metrics.evaluate(mirrored, gt)["keypoints"]["pa_mpjpe_mm"] > 1
    # F-score: points 10 cm apart, the prediction 8 mm off each: within 15 mm, not within 5 mm
    grid = np.stack(np.meshgrid(*[np.arange(3) * 0.1] * 3), -1).reshape(-1, 3)
    assert metrics.f_score(grid + [0.008, 0, 0], grid, 0.005) == 0.0
    assert metrics.f_score(grid + [0.008, 0, 0], grid, 0.015) == 1.0
    half = grid.copy()
    half[:13] += 0.05                                                     # 13 of 27 points far from everything
    assert metrics.f_score(half, grid, 0.015) == pytest.approx(14 / 27)


def test_eval_command_on_a_dataset(small_dataset, tmp_path, capsys):
    out, _ = small_dataset
    labels = [json.loads(p.read_text()) for p in sorted((out / "labels").iterdir())]
    kp = np.array([lab["keypoints_3d"] for lab in labels])
    verts = np.array([np.load(out / "meshes" / f"{lab['render']['dataset']['frame']:06d}.npy") for lab in labels])
    write_predictions(tmp_path / "pred.json", 2 * kp + 0.1, 2 * verts + 0.1)     # darthand's full meshes
    assert main(["eval", str(tmp_path / "pred.json"), str(out), "--out", str(tmp_path / "eval")]) == 0
    table = capsys.readouterr().out
    result = json.loads((tmp_path / "eval" / "eval.json").read_text())
    assert "| keypoints pa_mpjpe_mm |" in table and result["samples"] == 16
    assert result["keypoints"]["pa_mpjpe_mm"] < 1e-6 and result["vertices"]["pa_mpvpe_mm"] < 1e-6
    write_predictions(tmp_path / "short.json", kp[:3])
    with pytest.raises(InputError, match="3 samples, the ground truth"):
        evaluate_files(tmp_path / "short.json", out)
    assert main(["eval", str(tmp_path / "missing.json"), str(out)]) == 2


def test_report_page_and_figures(small_dataset, tmp_path):
    out, doc = small_dataset
    assert main(["dataset", "report", str(out), "--out", str(tmp_path), "--sheet", "8"]) == 0
    assert (tmp_path / "report.png").stat().st_size > 50_000
    figures = json.loads((tmp_path / "report.json").read_text())
    assert figures["frames"] == 16 and figures["counts"]["side"] == doc["summary"]["counts"]["side"]
    assert figures["visibility_rate"] == pytest.approx(doc["summary"]["visibility_rate"], abs=1e-4)
    cov = figures["pose_coverage"]
    library = len(library_poses())                   # the default reference set: the whole pose library
    assert cov["reference_poses"] == library and cov["dataset_poses"] == 16 and 0 <= cov["median_deg"] < 90
    assert cov["embedding"] == {"method": "t-SNE", "perplexity": 30.0, "distance": "mean finger-joint angle",
                                "dataset_poses": 16, "reference_poses": library}
    from darthand.dataset.report import coverage_figures

    q = Rotation.random(30, random_state=1).as_quat()[:, [3, 0, 1, 2]].reshape(2, 15, 4)
    assert coverage_figures(q, q[:1])["median_deg"] == pytest.approx(0, abs=1e-5)   # a reference pose in the set
