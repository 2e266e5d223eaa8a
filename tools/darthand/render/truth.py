"""Per-pixel truth maps of a frame, computed only when asked (`KINDS`): what the pixel centre's primary ray hit.

    depth    (H, W) float32 camera z of the hit, metres, 0 for background (the frame's `depth`)
    normals  (H, W, 3) float32 unit surface normal in the camera frame (OpenCV: x right, y down, z forward): the
             hit's interpolated vertex normal that shading uses, turned to the camera's side of the face (a
             back-facing one is flipped) and bent into the visible hemisphere at silhouettes; 0 for background
    parts    (H, W) uint8 part label (`PARTS`, 0 background), from the hit face

They come from the primary samples the frame traces anyway (trace.Samples: surface, face, shading normal, depth):
no ray is added, and a frame without maps does none of this work.

Files (`write_truth_maps`, `ENCODINGS`): PNGs, read by every image library without OpenEXR.

    depth    16-bit grey, millimetres (value / 1000 = metres), 0 background; 1 mm steps (+-0.5 mm of rounding, a
             hand is 15-30 mm thick) up to 65.535 m (a hit further away is stored as 65535); a hit nearer than
             0.5 mm is stored as 1, never as background
    normals  8-bit RGB, n * 0.5 + 0.5 scaled to 0..255 (n = value / 255 * 2 - 1), (0, 0, 0) background (no unit
             vector encodes to it); 2/255 steps per component: at most 0.4 degrees off, below the difference
             between interpolated vertex normals and the mesh's face normals
    parts    8-bit grey, the `PARTS` index

Parts of the hand come from its faces: a face's dominant skinning joint (Surface.face_joints) names its segment
(the wrist joint: palm; a finger's k-th joint, MANO's order: that finger's segment k, proximal to distal: for the
index to pinky fingers the proximal, middle and distal phalanx, for the thumb MANO's three thumb joints'
segments), its model label (Surface.face_labels, model/layout.FACE_LABELS) marks the nails, and the faces after
the model's `base_faces` (DART's wrist rings, model/wrist.py) and the forearm cap surface are the forearm. A source
without face labels (a USD package) has no nails; without the wrist's record its rings count as palm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS
from darthand.render.camera import Camera
from darthand.render.image import write_png
from darthand.render.subject import Subject, Surface

KINDS = ("depth", "normals", "parts")
PARTS = ("background", "palm", *(f"{finger}_{k}" for finger in FINGERS for k in (1, 2, 3)), "nail", "forearm",
         "accessory", "object")
PART_IDS = {name: i for i, name in enumerate(PARTS)}
ROLE_PARTS = {"cap": PART_IDS["forearm"], "arm": PART_IDS["forearm"], "accessory": PART_IDS["accessory"],
              "object": PART_IDS["object"]}
DEPTH_SCALE = 1000.0            # PNG units per metre
ENCODINGS = {
    "depth": {"format": "png", "dtype": "uint16", "channels": 1, "units": "mm", "scale": DEPTH_SCALE,
              "background": 0, "max_m": 65.535,
              "decode": "z_m = value / 1000 (0: background; 65535: 65.535 m or further)"},
    "normals": {"format": "png", "dtype": "uint8", "channels": 3, "frame": "camera (opencv: x right, y down, z "
                "forward)", "background": [0, 0, 0], "decode": "n = value / 255 * 2 - 1 (all 0: background)"},
    "parts": {"format": "png", "dtype": "uint8", "channels": 1, "background": 0, "table": list(PARTS)},
}


def check_kinds(kinds) -> tuple:
    """The map kinds asked for, in KINDS order without repeats: a tuple of KINDS' names (InputError naming an
    unknown one)."""
    asked = [str(k) for k in (kinds or ())]
    unknown = [k for k in asked if k not in KINDS]
    if unknown:
        raise InputError(f"maps: {unknown[0]!r} is not one of {', '.join(KINDS)}")
    return tuple(k for k in KINDS if k in asked)


def joint_parts() -> np.ndarray:
    """(16,) uint8 the part of the faces each MANO joint moves most: the wrist joint the palm, a finger's k-th joint
    that finger's segment k."""
    table = np.full(16, PART_IDS["palm"], np.uint8)
    for finger in FINGERS:
        for k, joint in enumerate(FINGER_JOINTS[finger], 1):
            table[joint] = PART_IDS[f"{finger}_{k}"]
    return table


def face_parts(surface: Surface, base_faces: int | None = None) -> np.ndarray:
    """(F,) uint8 the part of each face of a surface (module docstring). base_faces: the hand's faces before DART's
    wrist rings (None: no rings known)."""
    n = len(surface.faces)
    if surface.role != "hand":
        return np.full(n, ROLE_PARTS.get(surface.role, PART_IDS["object"]), np.uint8)
    if surface.face_joints is None:
        parts = np.full(n, PART_IDS["palm"], np.uint8)
    else:
        parts = joint_parts()[np.asarray(surface.face_joints, np.int64)]
    if surface.face_labels is not None:
        parts[np.asarray(surface.face_labels) == FACE_LABEL_IDS["nail"]] = PART_IDS["nail"]
    if base_faces is not None:
        parts[int(base_faces):] = PART_IDS["forearm"]
    return parts


def pixel_parts(subject: Subject, geom: np.ndarray, prim: np.ndarray) -> np.ndarray:
    """(...) uint8 parts of samples that hit surface `geom` (..., -1 background) on face `prim` (...)."""
    tables = [face_parts(s, subject.info.get("base_faces")) for s in subject.surfaces]
    offsets = np.cumsum([0] + [len(t) for t in tables])
    lookup = np.concatenate([np.zeros(1, np.uint8), *tables])      # 0: background
    hit = geom >= 0
    index = np.where(hit, offsets[np.where(hit, geom, 0)] + prim + 1, 0)
    return lookup[index]


def truth_maps(kinds: tuple, subject: Subject, cam: Camera, primary, region: tuple, depth: np.ndarray) -> dict:
    """{kind: full-frame map} of `kinds` from the primary samples (trace.Samples) of the pixels in `region` (r0, r1,
    c0, c1), row-major; depth: the frame's (H, W) float32 camera z (0 background)."""
    r0, r1, c0, c1 = region
    h, w = r1 - r0, c1 - c0
    geom = primary.geom.reshape(h, w)
    out: dict = {}
    if "depth" in kinds:
        out["depth"] = depth
    if "normals" in kinds:                 # trace.Samples' normals are 0 where nothing was hit, and stay 0
        normals = np.zeros(depth.shape + (3,), np.float32)
        normals[r0:r1, c0:c1] = (cam.R.astype(np.float32) @ primary.normal.reshape(3, h * w)).T.reshape(h, w, 3)
        out["normals"] = normals
    if "parts" in kinds:
        parts = np.zeros(depth.shape, np.uint8)
        parts[r0:r1, c0:c1] = pixel_parts(subject, geom, primary.prim.reshape(h, w))
        out["parts"] = parts
    return out


def encode(kind: str, values: np.ndarray) -> np.ndarray:
    """The PNG pixels of a map (ENCODINGS): depth (H, W) uint16 mm, normals (H, W, 3) uint8, parts (H, W) uint8."""
    if kind == "depth":
        mm = np.clip(np.rint(values.astype(np.float64) * DEPTH_SCALE), 1, 65535)
        return np.where(values > 0, mm, 0).astype(np.uint16)
    if kind == "normals":
        out = np.zeros(values.shape, np.uint8)
        _normals8_kernel(np.ascontiguousarray(values, np.float32), out)
        return out
    if kind == "parts":
        return np.asarray(values, np.uint8)
    raise InputError(f"maps: {kind!r} is not one of {', '.join(KINDS)}")


@kernel
def _normals8_kernel(values, out):
    """out (H, W, 3) uint8 = n * 127.5 + 127.5 rounded (halves up) and clipped to 0..255 for each pixel of values
    (H, W, 3) float32 that is not all 0 (background, left 0): one pass, 11 ms less than numpy's masked version at
    512^2."""
    half, scale, top = np.float32(128.0), np.float32(127.5), np.float32(255.0)
    for r in range(values.shape[0]):
        for c in range(values.shape[1]):
            if values[r, c, 0] != 0 or values[r, c, 1] != 0 or values[r, c, 2] != 0:
                for k in range(3):
                    q = np.floor(values[r, c, k] * scale + half)
                    out[r, c, k] = np.uint8(min(max(q, np.float32(0.0)), top))


def write_truth_maps(maps: dict, paths: dict) -> None:
    """Write each map of `maps` ({kind: values}) as its PNG (ENCODINGS) to paths[kind], atomically."""
    for kind, values in maps.items():
        Path(paths[kind]).parent.mkdir(parents=True, exist_ok=True)
        write_png(paths[kind], encode(kind, values), srgb=False)


def describe(kinds: tuple, files: dict) -> dict:
    """What the labels say of the maps written: {kind: {'file': path, **ENCODINGS[kind]}}."""
    return {kind: {"file": files[kind], **ENCODINGS[kind]} for kind in kinds}
