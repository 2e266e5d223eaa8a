"""HaMeR's layout read as HaMeR reads it: the tars through the `webdataset` package (decode('rgb8'), data.pyd
unpickled), the keys and shapes its ImageDataset takes, keypoints against the labels' K, the box, MANO posed from the
written parameters (HaMeR's joint order and fingertip vertices), left hands through HaMeR's flip, the evaluation
.npz."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from darthand.cli import main
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.model.load import load_model

# What HaMeR's ImageDataset.process_webdataset_tar_item reads from each hand's dict, with the shapes it assumes.
SHAPES = {"keypoints_2d": (21, 3), "keypoints_3d": (21, 4), "center": (2,), "scale": (2,), "hand_pose": (48,),
          "betas": (10,), "right": (), "has_hand_pose": (), "has_betas": ()}
# hamer/models/mano_wrapper.py: smplx MANO joints (16) + tip vertices (thumb, index, middle, ring, pinky) -> OpenPose.
MANO_TO_OPENPOSE = [0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20]
SMPLX_TIPS = [744, 320, 443, 554, 671]


def export(dataset, out, *extra) -> Path:
    assert main(["dataset", "export", str(dataset), "--format", "hamer", "--out", str(out), *extra]) == 0
    return Path(out)


def samples(out: Path) -> list[dict]:
    """Every sample of every split's shards as HaMeR's loader decodes them, with its split."""
    import webdataset as wds

    items = []
    for split in ("train", "val", "test"):
        urls = sorted(str(p) for p in (out / split).glob("*.tar"))
        if urls:
            ds = wds.WebDataset(urls, shardshuffle=False).decode("rgb8").rename(jpg="jpg;jpeg;png")
            items += [dict(item, split=split) for item in ds]
    return items


def labels_of(dataset: Path, key: str) -> dict:
    return json.loads((dataset / "labels" / f"{key}.json").read_text())


def mano_keypoints(model, hand_pose, betas) -> np.ndarray:
    """(21, 3) HaMeR's MANO keypoints (OpenPose order, smplx's tips) of a model posed flat-hand-relative."""
    posed = forward(model, np.asarray(hand_pose, float)[None], np.asarray(betas, float)[None], flat_hand_mean=True)
    points = np.concatenate([posed.joints[0], posed.vertices[0, SMPLX_TIPS]])
    return points[MANO_TO_OPENPOSE]


def hamer_flip(hand: dict, width: int) -> dict:
    """HaMeR's flip of a left hand (hamer/datasets/utils.py: fliplr_keypoints, keypoint_3d_processing,
    fliplr_params), written from its description: u -> W - 1 - u, x -> -x, axis-angle (x, y, z) -> (x, -y, -z)."""
    kp2, kp3 = hand["keypoints_2d"].copy(), hand["keypoints_3d"].copy()
    kp2[:, 0] = width - kp2[:, 0] - 1
    kp3[:, 0] = -kp3[:, 0]
    pose = hand["hand_pose"].reshape(16, 3) * [1, -1, -1]
    return {"keypoints_2d": kp2, "keypoints_3d": kp3, "hand_pose": pose.ravel()}


@pytest.fixture(scope="module")
def open_export(small_dataset, tmp_path_factory):
    dataset, _ = small_dataset
    return dataset, export(dataset, tmp_path_factory.mktemp("hamer_open"))


@pytest.fixture(scope="module")
def mano_export(mano_dataset, tmp_path_factory):
    dataset, right_pkl, left_pkl = mano_dataset
    return dataset, export(dataset, tmp_path_factory.mktemp("hamer_mano")), right_pkl, left_pkl


def test_samples_hold_what_hamers_loader_reads(open_export):
    """Each frame is one sample of its split: an RGB image and data.pyd, a list of one dict with HaMeR's keys and
    shapes; keypoints_2d is keypoints_3d projected through the frame's K (OpenCV's integer pixel centres); the box
    is the keypoints' box enlarged twice; a hand that is not MANO's carries no MANO parameters."""
    dataset, out = open_export
    items = samples(out)
    frames = sorted(p.stem for p in (dataset / "labels").glob("*.json"))
    assert sorted(item["__key__"] for item in items) == frames
    for item in items:
        labels = labels_of(dataset, item["__key__"])
        W, H = labels["image_size"]
        assert item["jpg"].shape == (H, W, 3) and item["jpg"].dtype == np.uint8
        assert isinstance(item["data.pyd"], list) and len(item["data.pyd"]) == 1
        hand = item["data.pyd"][0]
        for key, shape in SHAPES.items():
            assert np.asarray(hand[key]).shape == shape and np.asarray(hand[key]).dtype == np.float32, key
        assert item["split"] == labels["split"] and hand["right"] == (labels["side"] == "right")
        K = np.asarray(labels["K"])
        xyz = hand["keypoints_3d"][:, :3].astype(float)
        assert np.abs(xyz - labels["keypoints_3d"]).max() < 1e-6           # the open hand: the labels' own points
        uvw = xyz @ K.T
        assert np.abs(hand["keypoints_2d"][:, :2] - (uvw[:, :2] / uvw[:, 2:] - 0.5)).max() < 1e-3
        assert np.abs(hand["keypoints_2d"][:, :2] - (np.asarray(labels["keypoints_2d"]) - 0.5)).max() < 1e-3
        assert (hand["keypoints_2d"][:, 2] == 1).all() and (hand["keypoints_3d"][:, 3] == 1).all()
        uv = hand["keypoints_2d"][:, :2]
        lo, hi = hand["center"] - hand["scale"] * 100, hand["center"] + hand["scale"] * 100
        mid, half = (uv.min(0) + uv.max(0)) / 2, (uv.max(0) - uv.min(0)) / 2
        assert np.allclose(lo, mid - 2 * half, atol=1e-2) and np.allclose(hi, mid + 2 * half, atol=1e-2)
        assert hand["has_hand_pose"] == 0 and hand["has_betas"] == 0
        assert not hand["hand_pose"].any() and not hand["betas"].any()
        assert hand["extra_info"]["frame"] == int(item["__key__"])


def test_images_are_the_frames_over_black(open_export):
    """The JPEG is the frame's image (composited over black in linear light where it is transparent): its luma
    within 2 codes on average (JPEG halves the chroma), its mean colour within 0.5."""
    dataset, out = open_export
    assert_images_over_black(dataset, out, samples(out)[:4])


def assert_images_over_black(dataset, out, items, colour: bool = True) -> int:
    """The JPEGs of `items` against their frames over black (straight colour, decoded here): luma within 2 codes on
    average, mean colour within 2 (`colour`: a small hand over black, or a detailed environment backdrop, moves a
    channel's mean by JPEG's halved chroma at its edges: up to 1.2 codes on 48^2 photo-like frames), and luma within 8
    codes on average over the partly covered edge pixels alone (where alpha applied twice is 15 or more codes off);
    returns how many edge pixels there were."""
    luma = np.array([0.299, 0.587, 0.114])
    edges = 0
    for item in items:
        rgba = straight_pixels(dataset / "images" / f"{item['__key__']}.png")
        want = over_black(rgba)
        got = item["jpg"].astype(float)
        assert np.abs(got @ luma - want @ luma).mean() < 2
        assert not colour or np.abs(got.mean((0, 1)) - want.mean((0, 1))).max() < 2.0
        edge = (rgba[..., 3] > 0) & (rgba[..., 3] < 255) if rgba.shape[2] == 4 else np.zeros(rgba.shape[:2], bool)
        if edge.any():
            assert np.abs(got[edge] @ luma - want[edge] @ luma).mean() < 8
        edges += int(edge.sum())
    return edges


def straight_pixels(path) -> np.ndarray:
    """(H, W, C) uint8 of a PNG as stored, decoded by zlib here (no alpha association by a library)."""
    import struct
    import zlib

    data = Path(path).read_bytes()
    pos, chunks, idat = 8, {}, b""
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        chunks[kind] = body
        idat += body if kind == b"IDAT" else b""
        pos += 12 + length
    width, height, depth, colour = struct.unpack(">IIBB", chunks[b"IHDR"][:10])
    assert depth == 8
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[colour]
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, 1 + width * channels)
    rows = np.zeros((height, width * channels), np.int64)
    for y in range(height):                               # PNG's five row filters
        f, line = raw[y, 0], raw[y, 1:].astype(np.int64)
        prev = rows[y - 1] if y else np.zeros_like(line)
        out = np.zeros_like(line)
        for x in range(len(line)):
            a = out[x - channels] if x >= channels else 0
            c = prev[x - channels] if x >= channels else 0
            b = prev[x]
            p = a + b - c
            pred = (0, a, b, (a + b) // 2,
                    a if abs(p - a) <= abs(p - b) and abs(p - a) <= abs(p - c) else b if abs(p - b) <= abs(p - c)
                    else c)[f]
            out[x] = (line[x] + pred) & 255
        rows[y] = out
    return rows.astype(np.uint8).reshape(height, width, channels)


def over_black(rgba) -> np.ndarray:
    """(H, W, 3) float sRGB codes of an 8-bit RGBA image over black, composited in linear light."""
    from darthand.textures.color import linear_to_srgb, srgb_to_linear

    rgba = np.asarray(rgba, np.float32) / 255
    alpha = rgba[..., 3:4] if rgba.shape[2] == 4 else 1.0
    return linear_to_srgb(srgb_to_linear(rgba[..., :3]) * alpha).astype(float) * 255


def test_transparent_pixels_composite_over_black():
    """A transparent frame's pixels: alpha 0 black, alpha 255 unchanged, half coverage half the light."""
    from darthand.render.image import over_black as image_over_black

    rgba = np.array([[[200, 100, 50, 0], [200, 100, 50, 255], [255, 255, 255, 128]]], np.uint8)
    got = image_over_black(rgba)
    assert got.dtype == np.uint8 and got.shape == (1, 3, 3)
    assert (got[0, 0] == 0).all() and (got[0, 1] == [200, 100, 50]).all()
    assert np.abs(got.astype(float) - over_black(rgba)).max() <= 0.5
    assert 186 <= got[0, 2, 0] <= 188                       # linear 0.5 -> sRGB 188 (not 128: not sRGB maths)


def test_mano_parameters_pose_mano_onto_the_keypoints(mano_export):
    """For a MANO model: MANO (each side's own pickle) posed from hand_pose and betas, flat-hand-relative as HaMeR's
    MANOLayer poses, with HaMeR's joint order and tips, is keypoints_3d up to a translation."""
    dataset, out, right_pkl, left_pkl = mano_export
    models = {1.0: load_model(str(right_pkl)), 0.0: load_model(str(left_pkl))}
    items = samples(out)
    assert len(items) == 12 and {float(i["data.pyd"][0]["right"]) for i in items} == {0.0, 1.0}
    for item in items:
        hand = item["data.pyd"][0]
        labels = labels_of(dataset, item["__key__"])
        assert hand["has_hand_pose"] == 1 and hand["has_betas"] == 1
        assert np.allclose(hand["betas"], np.asarray(labels["mano"]["betas"])[:10], atol=1e-6)
        kp = mano_keypoints(models[float(hand["right"])], hand["hand_pose"], hand["betas"])
        xyz = hand["keypoints_3d"][:, :3]
        assert np.abs((kp - kp[0]) - (xyz - xyz[0])).max() < 2e-5
        assert np.abs(kp + labels["mano"]["trans"] - xyz).max() < 2e-5


def test_left_hands_flip_as_hamer_flips_them(mano_export):
    """A left hand through HaMeR's flip is a right hand: MANO_RIGHT posed from the flipped parameters is the flipped
    keypoints_3d, which project (through K mirrored: cx -> W - 1 - cx) onto the flipped keypoints_2d."""
    dataset, out, right_pkl, _ = mano_export
    right = load_model(str(right_pkl))
    lefts = [i for i in samples(out) if i["data.pyd"][0]["right"] == 0]
    assert lefts
    for item in lefts:
        labels = labels_of(dataset, item["__key__"])
        W = labels["image_size"][0]
        flipped = hamer_flip(item["data.pyd"][0], W)
        kp = mano_keypoints(right, flipped["hand_pose"], item["data.pyd"][0]["betas"])
        xyz = flipped["keypoints_3d"][:, :3]
        assert np.abs((kp - kp[0]) - (xyz - xyz[0])).max() < 2e-5
        K = np.asarray(labels["K"], float)
        K[:2, 2] -= 0.5                                   # OpenCV's pixel centres
        K[0, 2] = W - 1 - K[0, 2]
        uvw = xyz.astype(float) @ K.T
        assert np.abs(flipped["keypoints_2d"][:, :2] - uvw[:, :2] / uvw[:, 2:]).max() < 1e-3


def test_evaluation_npz_as_hamers_image_dataset_reads_it(mano_export):
    """val/test .npz: HaMeR's keys and shapes; scale in pixels (ImageDataset divides it by 200); imgname names the
    split's images under images/; rows are the split's tar samples."""
    _, out, _, _ = mano_export
    items = samples(out)
    found = 0
    for split in ("val", "test"):
        path = out / f"{split}.npz"
        rows = [i for i in items if i["split"] == split]
        if not rows:
            assert not path.exists()
            continue
        data = np.load(path)                          # no pickle: HaMeR's allow_pickle=True is not needed
        n = len(data["imgname"])
        assert n == len(rows)
        shapes = {"center": (n, 2), "scale": (n, 2), "right": (n,), "hand_pose": (n, 48), "has_hand_pose": (n,),
                  "betas": (n, 10), "has_betas": (n,), "hand_keypoints_2d": (n, 21, 3),
                  "hand_keypoints_3d": (n, 21, 4)}
        for key, shape in shapes.items():
            assert data[key].shape == shape, key
        for k, item in enumerate(rows):
            hand = item["data.pyd"][0]
            assert data["imgname"][k] == f"{split}/{item['__key__']}.jpg"
            assert (out / "images" / data["imgname"][k]).read_bytes()[:2] == b"\xff\xd8"
            assert np.allclose(data["scale"][k] / 200, hand["scale"]) and np.allclose(data["center"][k], hand["center"])
            assert np.allclose(data["hand_keypoints_3d"][k], hand["keypoints_3d"])
            assert np.allclose(data["hand_pose"][k], hand["hand_pose"]) and data["right"][k] == hand["right"]
            found += 1
    assert found or not any(i["split"] != "train" for i in items)


def test_export_is_deterministic_leaves_no_temporaries_and_says_what_it_holds(mano_dataset, mano_export, tmp_path):
    """A second export writes the same bytes; nothing temporary is left; README.md names the fields and configs."""
    dataset, first, _, _ = mano_export
    second = export(dataset, tmp_path / "again")
    files = sorted(p.relative_to(first) for p in first.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(second) for p in second.rglob("*") if p.is_file())
    assert not [f for f in files if f.name.startswith(".")]
    for f in files:
        if f.name != "README.md":                         # README.md names its folder
            assert (first / f).read_bytes() == (second / f).read_bytes(), f
    readme = (first / "README.md").read_text()
    for word in ("keypoints_2d", "hand_pose", "flat hand", "datasets_tar.yaml", "URLS", "744, 320, 443, 554, 671"):
        assert word in readme


def test_left_skip_and_allow_non_mano(small_dataset, tmp_path):
    """--left skip leaves left hands out; --allow-non-mano writes the open hand's pose (flag 1), never its betas."""
    dataset, _ = small_dataset
    out = export(dataset, tmp_path / "skip", "--left", "skip", "--allow-non-mano")
    items = samples(out)
    assert items and all(i["data.pyd"][0]["right"] == 1 for i in items)
    for item in items:
        hand, labels = item["data.pyd"][0], labels_of(dataset, item["__key__"])
        mano = labels["mano"]
        assert hand["has_hand_pose"] == 1 and hand["has_betas"] == 0 and not hand["betas"].any()
        assert np.allclose(hand["hand_pose"], np.concatenate([mano["global_orient"], mano["hand_pose"]]), atol=1e-6)


def test_bad_input_is_one_line(tmp_path):
    from darthand.dataset.hamer import write_hamer

    with pytest.raises(InputError, match="--left"):
        write_hamer(tmp_path, tmp_path / "out", left="flip")
    with pytest.raises(InputError, match="dataset.json"):
        write_hamer(tmp_path, tmp_path / "out")


def test_render_dataset_writes_the_layout_after_rendering(package, tmp_path):
    """`render-dataset --formats hamer`: the layout is written into OUT/hamer, a hand not of MANO accepted (its MANO
    flags 0), as `dataset export` writes it; frames without a background are over black, edges included."""
    model, tex, acc = package
    out = tmp_path / "out"
    assert main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--size", "48", "--samples", "4",
                 "--processes", "1", "--count", "2", "--seed", "2", "--out", str(out), "--formats", "hamer",
                 "--backgrounds", "none"]) == 0
    items = samples(out / "hamer")
    assert len(items) == 2 and all(i["data.pyd"][0]["has_hand_pose"] == 0 for i in items)
    assert assert_images_over_black(out, out / "hamer", items, colour=False) > 0      # transparent: edges too
    again = export(out, tmp_path / "again")
    for tar in (out / "hamer").rglob("*.tar"):
        assert tar.read_bytes() == (again / tar.relative_to(out / "hamer")).read_bytes()


def test_a_folder_with_more_shards_is_refused_before_writing(open_export, tmp_path):
    """Exporting over an earlier, larger export refuses in one line and writes nothing; over the same one it writes
    the same files in place."""
    from darthand.dataset import hamer

    dataset, first = open_export
    out = tmp_path / "out"
    export(dataset, out)
    (out / "train" / "000007.tar").write_bytes(b"earlier")
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    with pytest.raises(InputError, match=r"train: holds 1 shards \(000007.tar ..\)"):
        hamer.write_hamer(dataset, out)
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before
    (out / "train" / "000007.tar").unlink()
    export(dataset, out)
    assert (out / "train" / "000000.tar").read_bytes() == (first / "train" / "000000.tar").read_bytes()
