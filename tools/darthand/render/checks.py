"""The render checks of `make assets`: render every USD package of a build (a few gestures, views, textures, every
accessory, a UV checker), check what was built, write contact sheets and build/checks/report.json.

Checks per package (each {"ok", figures..., "failures": [...]} in the report):
    finite          no NaN or infinity in any render (colour, coverage, depth)
    coverage        every gesture render covers a plausible share of the frame (COVERAGE_RANGE)
    keypoints       every keypoint inside the image lies on the mask or within KEYPOINT_SLACK_PX of it
    accessories     every accessory variant is seen (at least MIN_ACCESSORY_PIXELS in the dorsal or palmar view, at
                    the tile size or else twice it)
                    and lies next to its bone: a rigid one's centroid within NEXT_TO_BONE_M of its parent joint's
                    bone, a glove over most of the hand (GLOVE_COVER of the hand's silhouette)
    uv_seams        a UV-checker render, and the same view looked up in a texture that stores each texel's rest-pose
                    position (rasterised from the package's own UVs, with a dilated gutter): at every hand pixel the
                    position read through the UVs must match the position the ray hit within SEAM_TEXELS texels
                    (measured at mip level 0, so it tests the UV mapping, not the filter); a torn, flipped or
                    misassigned UV island reads positions centimetres away
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from darthand.errors import InputError
from darthand.fileio import write_json
from darthand.model.layout import MANO_PARENTS
from darthand.model.preview import contact_sheet, write_png
from darthand.render.api import Frame, Renderer, render_subject
from darthand.render.camera import load_camera
from darthand.render.lights import default_lighting
from darthand.render.scene import Scene
from darthand.render.subject import Subject, checker_material
from darthand.render.texture import MipTexture, mip_levels
from darthand.textures.raster import rasterize

COVERAGE_RANGE = (0.02, 0.75)
KEYPOINT_SLACK_PX = 3.0
MIN_ACCESSORY_PIXELS = 12
NEXT_TO_BONE_M = 0.025
GLOVE_COVER = 0.3
SEAM_TEXELS = 3.0
ACCESSORY_SIZE = 128                    # pixels, at least, of the accessory renders
SEAM_RES = 512
REPORT_FORMAT = "darthand-render-checks"
GESTURE_VIEWS = [("flat", "dorsal"), ("flat", "palmar"), ("fist", "three_quarter"), ("ok", "radial"),
                 ("point", "three_quarter"), ("spread", "palmar"), ("grasp", "ulnar"), ("thumbs_up", "radial")]
SHEET_BACKGROUND = (0.18, 0.18, 0.19)


def run_checks(build: str | Path = "build", out: str | Path | None = None, *, sides=None, size: int = 256,
               all_accessories: bool = True) -> dict:
    """Check every package build/usd/<side> (or `sides`); write OUT/<side>.png, OUT/<side>_accessories.png and
    OUT/report.json (OUT = build/checks); return the report."""
    from darthand.render.usd_source import UsdPackage  # lazy: OpenUSD takes 0.6 s to import

    build = Path(build)
    out = Path(out) if out is not None else build / "checks"
    usd = build / "usd"
    found = sorted(d.name for d in usd.iterdir() if (d / "asset.json").is_file()) if usd.is_dir() else []
    sides = list(sides) if sides else found
    if not sides:
        raise InputError(f"{usd}: no USD packages to check (run the export step first)")
    report: dict = {"format": REPORT_FORMAT, "version": 1, "build": str(build), "size": size, "packages": {},
              "thresholds": {"coverage": list(COVERAGE_RANGE), "keypoint_slack_px": KEYPOINT_SLACK_PX,
                             "min_accessory_pixels": MIN_ACCESSORY_PIXELS, "next_to_bone_m": NEXT_TO_BONE_M,
                             "glove_cover": GLOVE_COVER, "seam_texels": SEAM_TEXELS}}
    for side in sides:
        if side not in found:
            raise InputError(f"{usd / side}: no USD package (asset.json) there")
        t0 = time.perf_counter()
        package = UsdPackage.open(usd / side, model=build / "model" / f"{side}.npz")
        result = check_package(package, size=size, all_accessories=all_accessories)
        sheets = {"renders": out / f"{side}.png", "accessories": out / f"{side}_accessories.png"}
        write_sheet(sheets["renders"], result.pop("tiles"), cols=4)
        write_sheet(sheets["accessories"], result.pop("accessory_tiles"), cols=7)
        result["sheets"] = {k: v.relative_to(out).as_posix() for k, v in sheets.items()}
        result["seconds"] = round(time.perf_counter() - t0, 2)
        result["ok"] = all(c["ok"] for c in result["checks"].values())
        report["packages"][side] = result
    report["ok"] = all(p["ok"] for p in report["packages"].values())
    report["report"] = str(out / "report.json")
    write_json(out / "report.json", report)
    return report


# ------------------------------------------------------------------------------------------------ one package


def check_package(package, *, size: int = 256, all_accessories: bool = True) -> dict:
    """Render and check one package (a usd_source.UsdPackage or assets.HandAssets); returns {"checks", "renders",
    "tiles", "accessory_tiles"}."""
    renderer = Renderer(package)
    gestures = set(getattr(package, "gestures", None) or [])
    textures = [t for t in package.texture_ids() if t not in ("plain", "checker")] or package.texture_ids()
    accessories = [a for a in package.accessory_ids() if a != "none"]
    checks: dict[str, dict] = {name: {"ok": True, "failures": []} for name in
              ("finite", "coverage", "keypoints", "accessories", "uv_seams")}
    tiles, renders = [], 0
    pairs = [(g, v) for g, v in GESTURE_VIEWS if not gestures or g in gestures]
    for i, (gesture, view) in enumerate(pairs):
        texture = textures[i % len(textures)]
        offset = (0.0, -0.08, 0.06)[i % 3]
        frame = renderer.render(gesture, texture=texture, skin_tone_offset=offset, accessory="none", camera=view,
                                width=size, height=size)
        renders += 1
        name = f"{gesture} {view}"
        _check_frame(frame, name, checks)
        tiles.append((frame, f"{gesture}/{view} {texture[:18]}"))
    uv = check_uv_seams(renderer, size)
    checks["uv_seams"].update(uv.pop("result"))
    tiles.append((uv.pop("frame"), "uv checker"))
    renders += 1
    chosen = accessories if all_accessories else _one_of_each_kind(accessories)
    acc_size = max(ACCESSORY_SIZE, size // 2)
    accessory_tiles = []
    acc = checks["accessories"]
    acc.update(checked=len(chosen), rigid_max_distance_m=0.0, glove_min_cover=None)
    pose = "flat" if not gestures or "flat" in gestures else None
    for acc_id in chosen:
        best, seen = None, 0
        # A thin band on a large hand may cover fewer pixels than the threshold at the tile size: such an item is
        # looked at again at twice the size before it counts as unseen (hidden inside the hand, or missing).
        for res in (acc_size, 2 * acc_size):
            for view in ("dorsal", "palmar"):
                frame = renderer.render(pose, texture=textures[0], accessory=acc_id, camera=view, width=res,
                                        height=res)
                renders += 1
                _check_frame(frame, f"{acc_id} {view}", checks, coverage=False)
                pixels = int((frame.geom == 1).sum())
                if pixels >= seen:
                    best, seen = frame, pixels
            if seen >= MIN_ACCESSORY_PIXELS:
                break
        assert best is not None                     # at least one view was rendered
        accessory_tiles.append((best, acc_id[:20]))
        _check_accessory(best, acc_id, seen, acc)
    for c in checks.values():
        c["ok"] = not c["failures"]
        c["failures"] = c["failures"][:20]
    return {"checks": checks, "renders": renders, "gestures": [p[0] for p in pairs], "textures": textures,
            "accessories": chosen, "tiles": tiles, "accessory_tiles": accessory_tiles}


def _check_frame(frame: Frame, name: str, checks: dict, coverage: bool = True) -> None:
    if not (np.isfinite(frame.colour).all() and np.isfinite(frame.alpha).all() and np.isfinite(frame.depth).all()):
        checks["finite"]["failures"].append(name)
    cov = float(frame.alpha.mean())
    if coverage and not COVERAGE_RANGE[0] <= cov <= COVERAGE_RANGE[1]:
        checks["coverage"]["failures"].append(f"{name}: coverage {cov:.3f}")
    kp = np.array(frame.labels["keypoints_2d"])
    inside = np.array(frame.labels["in_image"])
    near = ndimage.distance_transform_edt(frame.alpha <= 0)          # pixels to the nearest covered pixel
    r = np.clip(kp[:, 1].astype(int), 0, frame.camera.height - 1)
    c = np.clip(kp[:, 0].astype(int), 0, frame.camera.width - 1)
    far = inside & (near[r, c] > KEYPOINT_SLACK_PX)
    if far.any():
        names = [frame.labels["keypoint_names"][k] for k in np.flatnonzero(far)]
        checks["keypoints"]["failures"].append(f"{name}: {', '.join(names)} off the mask")


def _check_accessory(frame: Frame, acc_id: str, pixels: int, result: dict) -> None:
    subject = frame.subject
    surface = subject.accessory
    if surface is None:
        result["failures"].append(f"{acc_id}: no accessory mesh in the package variant")
        return
    if pixels < MIN_ACCESSORY_PIXELS:
        result["failures"].append(f"{acc_id}: only {pixels} pixels seen from the back or the palm")
    parent = subject.info.get("accessory_parent_joint")
    if parent is None:                                                  # a glove: it must cover the hand
        hand_or_glove = frame.geom >= 0
        cover = float((frame.geom == 1).sum() / max(1, hand_or_glove.sum()))
        result["glove_min_cover"] = cover if result["glove_min_cover"] is None else min(result["glove_min_cover"],
                                                                                        cover)
        if cover < GLOVE_COVER:
            result["failures"].append(f"{acc_id}: covers {cover:.0%} of the hand")
        return
    d = bone_distance(surface.vertices.mean(0), subject.joints, parent)
    result["rigid_max_distance_m"] = max(result["rigid_max_distance_m"], round(float(d), 5))
    if d > NEXT_TO_BONE_M:
        result["failures"].append(f"{acc_id}: {1000 * d:.0f} mm from the bone of joint {parent}")


def bone_distance(point: np.ndarray, joints: np.ndarray, joint: int) -> float:
    """Distance (m) from a point to joint `joint`'s bone: the segment to its child joint, or for the wrist (root)
    the segment from it away from the middle finger's base, 8 cm along the forearm."""
    children = np.flatnonzero(MANO_PARENTS == joint)
    a = joints[joint]
    if joint == 0:
        back = a - joints[4]
        b = a + 0.08 * back / np.linalg.norm(back)
    else:
        b = joints[children[0]] if len(children) else a
    ab = b - a
    t = np.clip(np.dot(point - a, ab) / max(np.dot(ab, ab), 1e-12), 0, 1)
    return float(np.linalg.norm(point - (a + t * ab)))


def _one_of_each_kind(ids: list[str]) -> list[str]:
    seen, out = set(), []
    for i in ids:
        kind = i.split("_")[0]
        if kind not in seen:
            seen.add(kind)
            out.append(i)
    return out


# ------------------------------------------------------------------------------------------------ UV seams


def position_texture(surface, res: int = SEAM_RES) -> tuple[MipTexture, float]:
    """A (res, res) texture storing, at every texel, the rest-pose position of the surface point the package's UVs
    map there (rasterised with textures.raster, a 2-texel margin, then every other texel filled from its nearest
    covered texel); and the median texel size in metres on the surface."""
    uv = surface.uvs[surface.faces_uv].astype(np.float64)               # (F, 3, 2)
    tri = np.stack([uv[..., 0] * res, (1 - uv[..., 1]) * res], -1)      # pixel units, v up (bake.py's convention)
    frags = rasterize(tri, res, res, margin=2.0)
    corners = surface.rest[surface.faces][frags.face]                   # (N, 3, 3)
    values = np.einsum("nk,nkc->nc", frags.bary, corners)
    img = np.zeros((res * res, 3))
    covered = np.zeros(res * res, bool)
    img[frags.pixel], covered[frags.pixel] = values, True
    _, (rows, cols) = ndimage.distance_transform_edt(~covered.reshape(res, res), return_indices=True)
    img = img.reshape(res, res, 3)[rows, cols]
    area3 = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    e1, e2 = tri[frags.face, 1] - tri[frags.face, 0], tri[frags.face, 2] - tri[frags.face, 0]
    area_px = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    texel = float(np.median(np.sqrt(area3 / np.maximum(area_px, 1e-12))))
    return MipTexture(mip_levels(img.astype(np.float32))), texel


def check_uv_seams(renderer: Renderer, size: int) -> dict:
    """The UV-checker render of the flat hand (three-quarter view) and the position-texture test of its UVs."""
    subject = renderer.source.subject(None, accessory="none")
    hand = subject.hand
    checker = dataclasses.replace(hand, material=checker_material())
    subj = Subject((checker,), subject.joints, subject.keypoints, subject.side, subject.pose, subject.keypoint_order,
                   {**subject.info, "texture": "checker"})
    scene = Scene(subj)
    cam = load_camera("three_quarter", subj.all_vertices(), width=size, height=size, side=subj.side)
    frame = render_subject(subj, scene, cam, default_lighting(), samples=8)
    if hand.uvs is None:
        return {"frame": frame, "result": {"failures": ["the hand mesh has no UVs"]}}
    tex, texel = position_texture(hand)
    rows, cols = np.nonzero(frame.geom == 0)
    uv_px = np.stack([cols + 0.5, rows + 0.5], 1)
    d = cam.directions(uv_px).astype(np.float32)
    hit = scene.intersect(np.ascontiguousarray(np.broadcast_to(cam.centre.astype(np.float32), d.shape)), d)
    ok = hit["primID"] >= 0
    prim, bu, bv = hit["primID"][ok], hit["u"][ok], hit["v"][ok]
    w = np.stack([1 - bu - bv, bu, bv], 1).astype(np.float64)
    true = np.einsum("nk,nkc->nc", w, hand.rest[hand.faces[prim]])
    uv = np.einsum("nk,nkc->nc", w, hand.uvs[hand.faces_uv[prim]].astype(np.float64))
    looked_up = tex.bilinear(uv.T.astype(np.float32), 0).T
    err = np.linalg.norm(looked_up - true, axis=1)
    bad = err > SEAM_TEXELS * texel
    result = {"pixels": int(len(err)), "texel_m": round(texel, 7), "max_error_m": round(float(err.max()), 6),
              "p99_error_m": round(float(np.percentile(err, 99)), 7), "pixels_over": int(bad.sum()),
              "failures": [] if bad.mean() <= 1e-3 else
              [f"{bad.sum()} of {len(err)} hand pixels read positions more than {SEAM_TEXELS:g} texels away "
               f"(max {1000 * err.max():.1f} mm)"]}
    return {"frame": frame, "result": result}


# ------------------------------------------------------------------------------------------------ sheets


def annotated(frame: Frame) -> np.ndarray:
    """(H, W, 3) linear RGB of a frame over mid-grey, with its keypoints (green visible, red occluded) and its
    bounding box (yellow)."""
    a = frame.alpha[..., None]
    img = frame.colour + (1 - a) * np.asarray(SHEET_BACKGROUND, np.float32)
    if frame.labels.get("bbox"):
        x0, y0, x1, y1 = (int(round(v)) for v in frame.labels["bbox"])
        x1, y1 = min(x1, img.shape[1]) - 1, min(y1, img.shape[0]) - 1
        for r in (y0, y1):
            img[r, x0:x1 + 1] = (0.9, 0.8, 0.1)
        for c in (x0, x1):
            img[y0:y1 + 1, c] = (0.9, 0.8, 0.1)
    for (u, v), vis in zip(frame.labels.get("keypoints_2d", []), frame.labels.get("visibility", [])):
        r, c = int(v), int(u)
        img[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] = (0.05, 0.9, 0.1) if vis else (0.95, 0.05, 0.05)
    return img.astype(np.float32)


def write_sheet(path: Path, tiles: list, cols: int) -> None:
    """A contact sheet of (frame, label) tiles, all resized to the first tile's size."""
    if not tiles:
        return
    h, w = tiles[0][0].camera.height, tiles[0][0].camera.width
    images = []
    for frame, _ in tiles:
        img = annotated(frame)
        if img.shape[0] > h:                    # a tile looked at again at a multiple of the size
            img = img[::-(-img.shape[0] // h), ::-(-img.shape[1] // w)]
        if img.shape[:2] != (h, w):
            img = np.repeat(np.repeat(img, -(-h // img.shape[0]), axis=0), -(-w // img.shape[1]), axis=1)[:h, :w]
        images.append(img)
    write_png(path, contact_sheet(images, [label for _, label in tiles], cols))
