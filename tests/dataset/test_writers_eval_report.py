"""The FreiHAND layout against FreiHAND's own recipe (root from uv and scale, MANO posed from the 61 values), the
WebDataset shards read by the `webdataset` package, `darthand eval` on cases with known answers, the report."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from darthand.cli import main
from darthand.dataset import metrics
from darthand.dataset.evaluate import evaluate_files, write_predictions
from darthand.errors import InputError
from darthand.model.forward import forward


def test_freihand_layout_rebuilds_its_keypoints_by_freihands_recipe(small_dataset, sources, tmp_path, capsys):
    out, _ = small_dataset
    assert main(["dataset", "export", str(out), "--format", "freihand", "--out", str(tmp_path)]) == 0
    right = sources[0]["right"].model
    total = 0
    for name in ("training", "validation", "evaluation"):
        if not (tmp_path / f"{name}_xyz.json").is_file():
            continue
        K, xyz, verts, mano, frames = (json.loads((tmp_path / f"{name}_{k}.json").read_text())
                                       for k in ("K", "xyz", "verts", "mano", "frames"))
        assert len(K) == len(xyz) == len(verts) == len(mano) == len(frames)
        total += len(frames)
        for k in range(len(xyz)):
            theta = np.asarray(mano[k][0])
            assert theta.shape == (61,)
            # FreiHAND's toolbox: root = [(uv - pp), focal] / scale; MANO posed with the mean hand added
            # (flat_hand_mean false) and translated so its keypoint 9 lands on the root
            Kk = np.asarray(K[k])
            focal, pp = 0.5 * (Kk[0, 0] + Kk[1, 1]), Kk[:2, 2]
            root = np.append(theta[58:60] - pp, focal) / theta[60]
            posed = forward(right, theta[:48][None], theta[48:48 + right.num_betas][None] if right.num_betas
                            else None, flat_hand_mean=False, keypoint_order="openpose")
            kp = posed.keypoints[0] - posed.keypoints[0, 9] + root
            assert np.abs(kp - np.asarray(xyz[k])).max() < 2e-6
            assert len(verts[k]) == right.meta["wrist"]["base_vertices"]
            v = posed.vertices[0, :len(verts[k])] - posed.keypoints[0, 9] + root
            assert np.abs(v - np.asarray(verts[k])).max() < 5e-6
            # K in OpenCV's convention: the projection is darthand's keypoints_2d minus half a pixel
            labels = json.loads((out / "labels" / f"{frames[k]:06d}.json").read_text())
            uv = np.asarray(xyz[k]) @ Kk.T
            assert np.allclose(uv[:, :2] / uv[:, 2:], np.asarray(labels["keypoints_2d"]) - 0.5, atol=1e-6)
        assert len(list((tmp_path / name / "rgb").glob("*.jpg"))) == len(frames)
    right_frames = sum(1 for p in (out / "labels").iterdir() if json.loads(p.read_text())["side"] == "right")
    assert total == right_frames > 0
    assert "left-hand frames left out" in capsys.readouterr().out


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
    assert cov["reference_poses"] == 12 and cov["dataset_poses"] == 16 and 0 <= cov["median_deg"] < 90
    from darthand.dataset.report import coverage_figures

    q = Rotation.random(30, random_state=1).as_quat()[:, [3, 0, 1, 2]].reshape(2, 15, 4)
    assert coverage_figures(q, q[:1])["median_deg"] == pytest.approx(0, abs=1e-5)   # a reference pose in the set
