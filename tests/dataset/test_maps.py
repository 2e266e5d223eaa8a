"""Per-pixel truth maps (render-dataset --maps depth,normals,parts) against independent truth: each frame's posed
mesh (meshes/<n>.npy, camera frame) traced here through every pixel centre with the frame's K by a float64
Moller-Trumbore intersection, its hits' depth, face normal and face part compared with the maps."""

from __future__ import annotations

import io
import json
import tarfile

import numpy as np
import OpenImageIO as oiio
import pytest
from helpers_dataset import SIZE, files_of, render

from darthand.cli import main
from darthand.dataset.frames import job_digest
from darthand.schemas import check_schema

MAPS = ("depth", "normals", "parts")
COUNT = 6
# The part table, written out here rather than taken from render/truth.py.
TABLE = ["background", "palm", "thumb_1", "thumb_2", "thumb_3", "index_1", "index_2", "index_3", "middle_1",
         "middle_2", "middle_3", "ring_1", "ring_2", "ring_3", "pinky_1", "pinky_2", "pinky_3", "nail", "forearm",
         "accessory", "object"]
FINGER_JOINTS = {"thumb": (13, 14, 15), "index": (1, 2, 3), "middle": (4, 5, 6), "ring": (10, 11, 12),
                 "pinky": (7, 8, 9)}


@pytest.fixture(scope="module")
def with_maps(planner, sources, tmp_path_factory):
    out = tmp_path_factory.mktemp("maps")
    doc = render(planner, sources, out, COUNT, maps=MAPS)
    return out, doc


@pytest.fixture(scope="module")
def without_maps(planner, sources, tmp_path_factory):
    out = tmp_path_factory.mktemp("no_maps")
    render(planner, sources, out, COUNT)
    return out


def read_map(path, dtype) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    assert buf.spec().format == (oiio.UINT16 if dtype == np.uint16 else oiio.UINT8), path
    return np.asarray(buf.get_pixels(oiio.UINT16 if dtype == np.uint16 else oiio.UINT8))


def trace(vertices: np.ndarray, faces: np.ndarray, K: np.ndarray, size: tuple) -> tuple:
    """(depth (H, W) camera z of the nearest hit, 0 none; face (H, W) its index, -1 none; barycentrics bu, bv
    (H, W) of its corners 1 and 2) of rays from the camera centre through every pixel centre, float64
    Moller-Trumbore over every face."""
    W, H = size
    v, u = np.mgrid[0:H, 0:W]
    pix = np.stack([u.ravel() + 0.5, v.ravel() + 0.5, np.ones(H * W)], axis=1)
    dirs = pix @ np.linalg.inv(K).T                     # camera z = 1: the ray parameter is the depth
    a, b, c = (vertices[faces[:, k]].astype(np.float64) for k in range(3))
    e1, e2 = b - a, c - a
    q = np.cross(-a, e1)                                # T x E1 with T = origin - a, the origin at 0
    t_num, depth, face = np.einsum("fc,fc->f", e2, q), np.full(H * W, np.inf), np.full(H * W, -1)
    bary = np.zeros((2, H * W))
    for s in range(0, len(dirs), 128):
        d = dirs[s:s + 128]
        p = np.cross(d[:, None, :], e2[None])           # (R, F, 3)
        det = np.einsum("rfc,fc->rf", p, e1)
        inv = 1 / np.where(np.abs(det) > 1e-18, det, np.nan)
        bu = np.einsum("fc,rfc->rf", -a, p) * inv
        bv = np.einsum("rc,fc->rf", d, q) * inv
        t = t_num[None] * inv
        t = np.where((bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 0), t, np.inf)
        best = t.argmin(axis=1)
        rows = np.arange(len(best))
        depth[s:s + 128] = t[rows, best]
        bary[:, s:s + 128] = bu[rows, best], bv[rows, best]
        face[s:s + 128] = np.where(np.isfinite(depth[s:s + 128]), best, -1)
    depth[~np.isfinite(depth)] = 0
    return depth.reshape(H, W), face.reshape(H, W), bary[0].reshape(H, W), bary[1].reshape(H, W)


def expected_parts(model) -> np.ndarray:
    """(F,) the part index of each face of the model: nails by label, DART's wrist rings forearm, else the
    finger segment of the face's dominant skinning joint (the wrist joint: palm)."""
    joints = np.argmax(model.weights[model.faces].sum(axis=1), axis=1)
    by_joint = {0: "palm", **{j: f"{finger}_{k}" for finger, js in FINGER_JOINTS.items()
                               for k, j in enumerate(js, 1)}}
    parts = np.array([TABLE.index(by_joint[j]) for j in joints])
    parts[np.asarray(model.face_labels) == 0] = TABLE.index("nail")           # FACE_LABELS[0] is 'nail'
    parts[model.meta["wrist"]["base_faces"]:] = TABLE.index("forearm")
    return parts


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) area-weighted unit vertex normals (the sum of the corners' face cross products)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], np.cross(b - a, c - a))
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-30)


def frames_of(out):
    for path in sorted((out / "labels").glob("*.json")):
        labels = json.loads(path.read_text())
        n = path.stem
        yield n, labels


def test_maps_files_labels_and_encodings(with_maps):
    out, doc = with_maps
    assert doc["maps"]["parts"]["table"] == TABLE
    assert doc["files"]["depth"] == "maps/depth/<index>.png"
    for n, labels in frames_of(out):
        check_schema(labels, "labels.schema.json", n)
        assert set(labels["maps"]) == set(MAPS)
        assert labels["maps"]["depth"]["units"] == "mm" and labels["maps"]["depth"]["dtype"] == "uint16"
        assert labels["maps"]["parts"]["table"] == TABLE
        for kind in MAPS:
            assert labels["files"][kind] == f"../maps/{kind}/{n}.png"
            assert (out / "labels" / labels["files"][kind]).is_file()
        depth = read_map(out / f"maps/depth/{n}.png", np.uint16)
        normals = read_map(out / f"maps/normals/{n}.png", np.uint8)
        parts = read_map(out / f"maps/parts/{n}.png", np.uint8)
        assert depth.shape[2] == 1 and normals.shape[2] == 3 and parts.shape[2] == 1
        hit = depth[..., 0] > 0
        mask = read_map(out / f"masks/{n}.png", np.uint8)[..., 0]
        assert hit.any() and (normals.any(axis=2) == hit).all() and ((parts[..., 0] > 0) == hit).all()
        # a pixel centre that hits is covered, but for the arm drawn past the cut (forearm, outside the mask)
        assert not (hit & (mask == 0) & (parts[..., 0] != TABLE.index("forearm"))).any()


def test_depth_normals_and_parts_against_the_traced_mesh(with_maps, sources):
    out, _ = with_maps
    opened, _ = sources
    checked = accessories = 0
    for n, labels in frames_of(out):
        model = opened[labels["side"]].pose_model()
        K = np.asarray(labels["K"])
        vertices = np.load(out / f"meshes/{n}.npy")
        z, face, bu, bv = trace(vertices, model.faces, K, labels["image_size"])
        depth = read_map(out / f"maps/depth/{n}.png", np.uint16)[..., 0] / 1000.0
        normals = read_map(out / f"maps/normals/{n}.png", np.uint8) / 255.0 * 2 - 1
        parts = read_map(out / f"maps/parts/{n}.png", np.uint8)[..., 0]
        hand = (parts > 0) & (parts < TABLE.index("forearm"))       # hits on the hand mesh (not a ring, the cap)
        # where the renderer hit the hand, the mesh traced here is hit at the same depth (0.5 mm rounding)
        both = hand & (face >= 0)
        assert both.sum() >= hand.sum() - 2                         # a grazing ray may fall either side
        assert np.abs(depth[both] - z[both]).max() < 5.1e-4
        # where the renderer saw background, the hand mesh is not there either
        assert ((depth == 0) & (face >= 0)).sum() <= 2
        # an accessory or the forearm (cap or wrist rings) is never behind the hand mesh
        other = parts >= TABLE.index("forearm")
        assert ((face[other] < 0) | (z[other] >= depth[other] - 5.1e-4)).all()
        accessories += int((parts == TABLE.index("accessory")).sum())
        # parts: the model's face labels and skinning at the faces hit
        want = expected_parts(model)[face[both]]
        assert (parts[both] == want).mean() >= 0.99
        # normals: unit, facing the camera, near the traced face's normal turned to the camera
        n_map = normals[both]
        assert np.abs(np.linalg.norm(n_map, axis=1) - 1).max() < 0.01
        n_map /= np.linalg.norm(n_map, axis=1, keepdims=True)      # angles from directions, not 8-bit lengths
        v, u = np.nonzero(both)
        rays = np.stack([u + 0.5, v + 0.5, np.ones(len(u))], 1) @ np.linalg.inv(K).T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        assert (np.einsum("nc,nc->n", n_map, -rays) > -0.01).all()
        f = model.faces[face[both]]
        g = np.cross(vertices[f[:, 1]] - vertices[f[:, 0]], vertices[f[:, 2]] - vertices[f[:, 0]])
        g /= np.linalg.norm(g, axis=1, keepdims=True)
        g *= -np.sign(np.einsum("nc,nc->n", g, rays))[:, None]
        angle = np.degrees(np.arccos(np.clip(np.einsum("nc,nc->n", g, n_map), -1, 1)))
        assert np.median(angle) < 12 and np.percentile(angle, 95) < 30 and angle.max() < 60
        # and within the 8-bit encoding's 0.4 degrees (and float32's) of the interpolated vertex normal, where it
        # needed no bending into the visible hemisphere (silhouettes)
        smooth = vertex_normals(vertices.astype(np.float64), model.faces)[f]
        w = np.stack([1 - bu[both] - bv[both], bu[both], bv[both]], 1)
        s = np.einsum("nk,nkc->nc", w, smooth)
        s /= np.linalg.norm(s, axis=1, keepdims=True)
        s *= np.sign(np.einsum("nc,nc->n", g, s))[:, None]          # to the camera's side of the face
        front = np.einsum("nc,nc->n", s, -rays) > 0.01
        angle = np.degrees(np.arccos(np.clip(np.einsum("nc,nc->n", s, n_map)[front], -1, 1)))
        assert front.mean() > 0.9 and angle.max() < 0.5, angle.max()
        checked += int(both.sum())
    assert checked > 500 and accessories > 0


def test_maps_change_nothing_else(with_maps, without_maps):
    out, _ = with_maps
    a, b = files_of(out), files_of(without_maps)
    assert not any(name.startswith("maps") for name in b)
    for name, data in b.items():
        if name.startswith(("images", "masks", "meshes")):
            assert a[name] == data, name
    la, lb = (json.loads(x[f"labels/{n}.json"]) for x in (a, b) for n in ["000000"])
    for labels in (la, lb):
        labels["render"]["dataset"].pop("job_sha256")
        labels["files"] = {k: v for k, v in labels["files"].items() if k not in MAPS}
    la.pop("maps")
    assert la == lb


def test_digest_only_with_maps():
    job = {"index": 3, "side": "right"}
    settings = {"size": 48, "samples": 4, "aa_shading": "triangle", "shading": None}
    assert job_digest(job, {**settings, "maps": ()}) == job_digest(job, settings)
    assert job_digest(job, {**settings, "maps": ("depth",)}) != job_digest(job, settings)


def test_resume_and_webdataset_members(with_maps, planner, sources):
    from darthand.dataset.webdataset import write_webdataset

    out, _ = with_maps
    (out / "maps/normals/000002.png").unlink()
    doc = render(planner, sources, out, COUNT, maps=MAPS)
    assert doc["rendered"] == 1 and (out / "maps/normals/000002.png").is_file()
    where = write_webdataset(out, out / "wds")
    names = [m for tar in sorted(where.glob("*.tar")) for m in tarfile.open(tar).getnames()]
    for kind in MAPS:
        assert sum(name.endswith(f".{kind}.png") for name in names) == COUNT
    tar = tarfile.open(sorted(where.glob("*.tar"))[0])
    member = next(m for m in tar.getnames() if m.endswith(".depth.png"))
    data = tar.extractfile(member).read()
    assert data == (out / "maps/depth" / (member.split(".")[0] + ".png")).read_bytes()
    assert io.BytesIO(data).read(8) == b"\x89PNG\r\n\x1a\n"


def test_the_command_line_option(package, tmp_path, capsys):
    model, tex, acc = package
    common = [model, "--textures", tex, "--accessories", acc, "--size", str(SIZE), "--processes", "1", "--count",
              "2"]
    assert main(["render-dataset", *common, "--maps", "parts,depth", "--out", str(tmp_path / "a")]) == 0
    assert sorted(p.name for p in (tmp_path / "a" / "maps").iterdir()) == ["depth", "parts"]
    labels = json.loads((tmp_path / "a" / "labels" / "000001.json").read_text())
    assert list(labels["maps"]) == ["depth", "parts"]
    assert main(["render-dataset", *common, "--maps", "depth,albedo", "--out", str(tmp_path / "b")]) == 2
    assert "maps: 'albedo' is not one of depth, normals, parts" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
