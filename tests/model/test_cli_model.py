"""`darthand model ...` end to end: outputs, exit codes, one-line errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from darthand.cli import main
from darthand.model.forward import forward
from darthand.model.npz_io import load_npz, save_npz
from darthand.model.wrist import add_wrist
from synthetic import tube_hand


@pytest.fixture()
def model_file(tmp_path):
    path = tmp_path / "tube.npz"
    save_npz(tube_hand(seed=5), path)
    return path


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_info_json(capsys, model_file):
    code, out, _ = run(capsys, "model", "info", model_file, "--json")
    assert code == 0
    d = json.loads(out)
    m = tube_hand(seed=5)
    assert (d["vertices"], d["faces"], d["joints"], d["correctives"], d["shape_dims"]) == (
        m.num_vertices, m.num_faces, 16, 135, 4)
    assert d["boundary_loops"] == [16] and d["side"] == "right" and d["has_uvs"] is True


def test_wrist_then_info(capsys, model_file, tmp_path):
    out_file = tmp_path / "w.npz"
    code, out, _ = run(capsys, "model", "wrist", model_file, "--out", out_file, "--rings", "3")
    assert code == 0 and "3 rings of 16" in out
    w = load_npz(out_file)
    expected = add_wrist(tube_hand(seed=5), rings=3)
    np.testing.assert_array_equal(w.v_template, expected.v_template)
    code, out, _ = run(capsys, "model", "info", out_file)
    assert code == 0 and "3 rings of 16" in out


def test_build_writes_both_sides(capsys, model_file, tmp_path):
    code, _, _ = run(capsys, "model", "build", model_file, "--out-dir", tmp_path / "out")
    assert code == 0
    right, left = load_npz(tmp_path / "out/right.npz"), load_npz(tmp_path / "out/left.npz")
    assert (right.side, left.side) == ("right", "left")
    np.testing.assert_allclose(left.v_template, right.v_template * [-1, 1, 1])


def test_build_of_a_shape(capsys, model_file, tmp_path):
    """`--betas` bakes the shape: each side's rest surface is the wrist-enhanced source posed at rest with those
    betas (its mirror for the left), joints regressed from it, the betas recorded."""
    code, out, _ = run(capsys, "model", "build", model_file, "--out-dir", tmp_path / "out", "--betas", "1.5, -2 0.5")
    assert code == 0 and "shape betas 1.5 -2 0.5" in out
    right, left = load_npz(tmp_path / "out/right.npz"), load_npz(tmp_path / "out/left.npz")
    source = add_wrist(tube_hand(seed=5))
    truth = forward(source, np.zeros(48), [1.5, -2.0, 0.5])
    np.testing.assert_allclose(forward(right, np.zeros(48)).vertices, truth.vertices, atol=1e-12)
    np.testing.assert_allclose(forward(right, np.zeros(48)).joints, truth.joints, atol=1e-12)
    np.testing.assert_allclose(left.v_template, truth.vertices[0] * [-1, 1, 1], atol=1e-12)
    assert right.meta["betas"] == pytest.approx([1.5, -2.0, 0.5, 0.0]) == left.meta["betas"]
    code, _, err = run(capsys, "model", "build", model_file, "--out-dir", tmp_path / "bad", "--betas", "1 x")
    assert code == 2 and "--betas: 'x' is not a number" in err and not (tmp_path / "bad").exists()
    code, _, err = run(capsys, "model", "build", model_file, "--out-dir", tmp_path / "bad", "--betas", "1 2 3 4 5")
    assert code == 2 and "betas: 5 given but the model has 4" in err


def test_pose(capsys, model_file, tmp_path):
    poses = np.random.default_rng(0).normal(size=(3, 48))
    (tmp_path / "p.json").write_text(json.dumps({"pose": poses.tolist(), "flat_hand_mean": True}))
    code, _, err = run(capsys, "model", "pose", model_file, "--pose", tmp_path / "p.json", "--out",
                       tmp_path / "o.npz", "--dtype", "float32")
    assert code == 0, err
    with np.load(tmp_path / "o.npz") as z:
        assert z["vertices"].shape == (3, tube_hand().num_vertices, 3) and z["vertices"].dtype == np.float32
        assert z["joints"].shape == (3, 16, 3) and z["keypoints"].shape == (3, 21, 3)
        ref = forward(tube_hand(seed=5), poses, keypoint_order="openpose")
        np.testing.assert_allclose(z["keypoints"], ref.keypoints, atol=1e-6)


@pytest.mark.parametrize("argv, needle", [
    (["model", "info", "/nonexistent/m.npz"], "/nonexistent/m.npz"),
    (["model", "info", "nothing-here"], "nothing-here"),
    (["model", "wrist", "/nonexistent/m.pkl", "--out", "x.npz"], "/nonexistent/m.pkl"),
])
def test_bad_input_is_one_line_exit_2(capsys, argv, needle):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert err.count("\n") == 1 and needle in err and "Traceback" not in err


def test_nan_pose_file_is_one_line_exit_2(capsys, model_file, tmp_path):
    (tmp_path / "p.json").write_text('{"pose": [' + ", ".join(["0"] * 20 + ["NaN"] + ["0"] * 27) + "]}")
    code, _, err = run(capsys, "model", "pose", model_file, "--pose", tmp_path / "p.json", "--out",
                       tmp_path / "o.npz")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o.npz").exists()


def test_console_script_help_on_every_subcommand():
    exe = Path(sys.executable).with_name("darthand")
    for argv in (["--help"], ["model", "--help"], ["model", "info", "--help"], ["model", "pose", "--help"],
                 ["model", "wrist", "--help"], ["model", "build", "--help"]):
        r = subprocess.run([str(exe), *argv], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0 and "usage:" in r.stdout, (argv, r.stderr)


def test_mano_pickle_left_build_reports_the_fix(capsys, tmp_path):
    from model.mano_fixture import write_mano_pkl

    pkl = tmp_path / "MANO_LEFT.pkl"
    write_mano_pkl(pkl, side="left", left_bug=True)
    code, out, err = run(capsys, "model", "build", pkl, "--out-dir", tmp_path / "out")
    assert code == 0, err
    assert "left shapedirs x sign flipped" in out
    right, left = load_npz(tmp_path / "out/right.npz"), load_npz(tmp_path / "out/left.npz")
    assert (right.side, left.side) == ("right", "left")
    # The build keeps the source's own side as given and mirrors the other from it.
    np.testing.assert_allclose(right.v_template, left.v_template * [-1, 1, 1])


def test_malicious_pickle_via_cli_executes_nothing(capsys, tmp_path):
    from model.mano_fixture import malicious_pickle

    marker = tmp_path / "pwned"
    (tmp_path / "evil.pkl").write_bytes(malicious_pickle("os.system", marker))
    code, _, err = run(capsys, "model", "info", tmp_path / "evil.pkl")
    assert code == 2 and "evil.pkl" in err and err.count("\n") == 1
    assert not marker.exists()


def test_build_gives_a_model_without_uvs_an_atlas(capsys, tmp_path):
    from model.mano_fixture import write_mano_pkl

    pkl = tmp_path / "MANO_RIGHT.pkl"
    write_mano_pkl(pkl, side="right")
    code, out, err = run(capsys, "model", "build", pkl, "--out-dir", tmp_path / "out", "--atlas-res", "256")
    assert code == 0, err
    right, left = load_npz(tmp_path / "out/right.npz"), load_npz(tmp_path / "out/left.npz")
    assert right.has_uvs and left.has_uvs and "xatlas" in out
    assert right.uvs.min() >= 0 and right.uvs.max() <= 1
    # The left hand carries the right's atlas (mirroring keeps UVs), so one texture serves both sides.
    np.testing.assert_array_equal(left.uvs, right.uvs)
    assert right.meta["uv_atlas"]["resolution"] == 256
