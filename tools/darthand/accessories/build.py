"""The accessories stage: fit, generate, verify across poses and write the catalogue.

Per accessory `build/accessories/<id>.*`:
  <id>.npz    geometry container (format "darthand-accessory", version 1), float64/int64, no pickles:
              vertices (N, 3)   rest-pose positions in the model's frame, metres
              local_vertices (N, 3) the same in the accessory's local frame (rigid items; = vertices for gloves)
              faces (F, 3)      outward, counter-clockwise
              normals (N, 3)    area-weighted vertex normals (model frame)
              uvs (T, 2), faces_uv (F, 3)  per-corner texture coordinates (OpenGL convention, v up)
              parent_joint ()   MANO joint index, -1 for gloves
              rest_transform (4, 4)  local frame -> model rest frame (identity for gloves); posed = G_j @ rest
              weights (N, 16), posedirs (N, 3, 135), shapedirs (N, 3, S), source_vertex (N,), layer (N,)  gloves only
              id, type, material_json
  <id>.obj + <id>.mtl   rest-pose mesh with UVs and normals, material referencing the textures
  <id>_basecolor.png    sRGB albedo;  <id>_metallic_roughness.png  raw, glTF layout (G roughness, B metallic)
and catalog.json (schemas/accessory_catalog.schema.json) and contact_sheet.png.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.accessories import catalog as cat
from darthand.accessories.attach import apply, axis_distance, pose_skinned, to_local
from darthand.accessories.collide import (ClosedHand, Solid, glove_penetration, inward_vertices, neighbourhood,
                                          rigid_penetration)
from darthand.accessories.fit import WRIST_JOINT, Fit, fit_ring, fit_wrist, wrist_axis
from darthand.accessories.generators import rigid_generator
from darthand.accessories.generators.glove import glove
from darthand.accessories.mesh import AccessoryMesh
from darthand.accessories.preview import render_view
from darthand.accessories.textures import linear_to_srgb
from darthand.errors import InputError
from darthand.fileio import atomic_path, write_bytes, write_json
from darthand.model.anatomy import bone_ends, rest_joints, sample_poses
from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, MANO_PARENTS
from darthand.model.topology import vertex_normals

FORMAT, FORMAT_VERSION = "darthand-accessory", 1


@dataclass
class Built:
    """One generated accessory: its expanded entry, local-frame mesh, fit (None for gloves) and clearance."""

    entry: dict
    mesh: AccessoryMesh
    fit: Fit | None
    clearance: float
    figures: dict = field(default_factory=dict)

    @property
    def id(self) -> str:
        return self.entry["id"]

    @property
    def rest(self) -> np.ndarray:
        return np.eye(4) if self.fit is None else self.fit.rest

    @property
    def world_vertices(self) -> np.ndarray:
        return apply(self.rest, self.mesh.vertices)


# ---------------------------------------------------------------- fitting and generating
def axial_width(entry: dict) -> float:
    """How much of the bone (m) a rigid accessory's bore spans, for the section slab."""
    if entry["type"] == "ring":
        return float(entry["width"])
    if entry["type"] == "watch":
        return float(entry["strap_width"])
    style = entry["style"]
    if style in ("bangle", "cuff"):
        return float(entry["width"])
    if style in ("chain", "charm"):
        return 2 * 4.3 * float(entry["wire"])
    if style == "beads":
        return float(entry["bead_diameter"])
    return 2.0 * float(entry["thickness"])


def generate(model: HandModel, entry: dict, seed: int, clearance: float | None = None) -> Built:
    """Fit (rigid items) and generate one catalogue entry (metres) on `model`."""
    rng = cat.item_rng(seed, entry["id"])
    what = f"accessory {entry['id']}"
    if entry["type"] == "glove":
        return Built(entry, glove(model, entry, rng), None, float(entry["clearance"]))
    clearance = float(entry["clearance"]) if clearance is None else clearance
    width = axial_width(entry)
    for _ in range(2):
        if entry["type"] == "ring":
            fit = fit_ring(model, entry["finger"], width, clearance, float(entry.get("t", 0.5)), what)
        else:
            fit = fit_wrist(model, _wrist_offset(model, entry, width), width, clearance, what)
        mesh = rigid_generator(entry["type"])({**entry, **fit.bore}, cat.item_rng(seed, entry["id"]))
        # Parts may reach past the nominal width (a rope's strands, a signet's shoulders): fit again over them.
        extent = 2 * float(np.abs(mesh.vertices[:, 0]).max())
        if entry["type"] == "watch" or extent <= width + 1e-4:      # a watch's case stands clear of the wrist
            break
        width = extent
    return Built(entry, mesh, fit, clearance)


def _wrist_offset(model: HandModel, entry: dict, width: float) -> float:
    """The entry's offset along the forearm, pulled back if the item would hang off the forearm's end."""
    j0, axis = wrist_axis(model)
    end = float(((model.v_template - j0) @ axis).max())
    return min(float(entry.get("offset", 0.03)), end - width / 2 - 0.002)


# ---------------------------------------------------------------- verification across poses
def sweep_poses(model: HandModel, seed: int, n_sampled: int, gestures: list[str] | None = None):
    """(names, (P, 48) poses): the rest pose, the named gestures, then `n_sampled` anatomical samples."""
    from darthand.model.gestures import model_gestures

    g = model_gestures(model, gestures)
    g_names, g_poses = g.names, g.poses
    sampled = sample_poses(model, n_sampled, cat.item_rng(seed, "pose-sweep")) if n_sampled else np.zeros((0, 48))
    names = ["rest"] + list(g_names) + [f"sample_{i:03d}" for i in range(n_sampled)]
    return names, np.concatenate([np.zeros((1, 48)), g_poses, sampled])


def measure(model: HandModel, built: list[Built], poses: np.ndarray, chunk: int = 16) -> dict:
    """Per accessory id: penetration depth per pose (m) and, for rigid items, the drift of the distance from
    the accessory's centre to its bone axis; gloves also get the depth through their outer surface."""
    closed = ClosedHand(model.faces, model.num_vertices)
    joints = rest_joints(model)
    ends = bone_ends(model, joints)
    j0, fore = wrist_axis(model)
    probes = {}
    for b in built:
        if b.fit is None:
            sk = b.mesh.skin
            rim = sk["layer"][b.mesh.faces].min(1) != sk["layer"][b.mesh.faces].max(1)
            on_rim = np.unique(b.mesh.faces[rim])
            interior = np.setdiff1d(np.where(sk["layer"] == 0)[0], on_rim)
            near = neighbourhood(model.faces, model.num_vertices, rings=3)
            hand_ids = sk["source_vertex"][interior]
            face_src = sk["source_vertex"][b.mesh.faces[:, 0]]
            probes[b.id] = ("glove", hand_ids,
                            lambda r, t, near=near, h=hand_ids, f=face_src: np.asarray(near[h[r], f[t]]).ravel() > 0)
        else:
            normals = b.mesh.normals
            inner = inward_vertices(b.mesh.vertices, normals)
            probes[b.id] = ("rigid", Solid(b.mesh.vertices, b.mesh.faces), b.mesh.vertices[inner],
                            own_vertices(model, b.fit.joint))
    out = {b.id: {"depth": np.zeros(len(poses)), "through": np.zeros(len(poses)), "fit": np.zeros(len(poses)),
                  "drift": 0.0} for b in built}
    for s in range(0, len(poses), chunk):
        posed = forward(model, poses[s:s + chunk])
        gloves = {b.id: pose_skinned(b.mesh.vertices, b.mesh.skin["weights"], b.mesh.skin["posedirs"],
                                     posed.rotations, posed.transforms) for b in built if b.fit is None}
        for p in range(len(posed.vertices)):
            hv = posed.vertices[p]
            hand = closed.solid(hv)
            normals = None
            for b in built:
                probe, fig = probes[b.id], out[b.id]
                if probe[0] == "rigid":
                    M = posed.transforms[p, b.fit.joint] @ b.fit.rest
                    own_d, other_d = rigid_penetration(probe[1], to_local(M, hv), hand, apply(M, probe[2]),
                                                       probe[3], hv)
                    fig["fit"][s + p], fig["depth"][s + p] = own_d, max(own_d, other_d)
                    fig["drift"] = max(fig["drift"], abs(_axis_distance(b, M, posed, p, joints, ends, j0, fore)
                                                         - _axis_distance(b, b.fit.rest, None, p, joints, ends, j0,
                                                                          fore)))
                else:
                    normals = vertex_normals(hv, model.faces) if normals is None else normals
                    idx = probe[1]
                    into, through = glove_penetration(gloves[b.id][p], b.mesh.faces, b.mesh.skin["inner_faces"],
                                                      hv[idx], normals[idx], local=probe[2])
                    fig["depth"][s + p], fig["through"][s + p] = into, through
    return out


def own_vertices(model: HandModel, joint: int) -> np.ndarray:
    """(V,) bool: the hand part a rigid accessory on `joint` is fitted to -- for a finger joint, the vertices
    skinned mostly to it or the joints after it; for the wrist, the whole hand."""
    if joint == WRIST_JOINT:
        return np.ones(model.num_vertices, bool)
    chain = [joint]
    for k in range(joint + 1, len(model.parents)):
        if model.parents[k] in chain:
            chain.append(k)
    return np.isin(np.argmax(model.weights, axis=1), chain)


def _axis_distance(b: Built, M: np.ndarray, posed, p: int, joints, ends, j0, fore) -> float:
    """Distance from the placed accessory's centre to its bone axis: for rings the line through the joint and its
    child as the forward pass reports them (posed) or the rest joints (posed None); for wrist items the forearm
    axis through the wrist joint, turned by the root's rotation."""
    j = b.fit.joint
    if j == WRIST_JOINT:
        if posed is None:
            a, e = j0, j0 + fore
        else:
            a = posed.joints[p, WRIST_JOINT]
            e = a + posed.transforms[p, WRIST_JOINT, :3, :3] @ fore
    elif posed is None:
        a, e = joints[j], ends[j]
    else:
        a, e = posed.joints[p, j], posed.joints[p, int(np.where(MANO_PARENTS == j)[0][0])]
    return float(axis_distance(M[:3, 3], a, e))


# ---------------------------------------------------------------- the stage
def build_accessories(model: HandModel, spec: dict, out_dir: str | Path, ids=None, types=None, *,
                      n_sampled: int = 300, gestures: list[str] | None = None, tolerance_mm: float = 1.0,
                      refit: bool = True, sheet: bool = True, tile: int = 192) -> dict:
    """Build the catalogue's accessories (or the `ids` / `types` subset) on `model` into `out_dir`; return and
    write catalog.json. Rigid items whose penetration across poses exceeds `tolerance_mm` are refitted once with
    their clearance grown by the excess (both figures are reported)."""
    if model.side != "right":
        raise InputError(f"{model.meta.get('source', 'model')}: accessories are fitted on a right hand "
                         f"(got side {model.side!r}); mirror the built accessories for the left")
    out_dir = Path(out_dir)
    seed = int(spec["seed"])
    items = cat.entries(spec, ids, types)
    built = [generate(model, e, seed) for e in items]
    names, poses = sweep_poses(model, seed, n_sampled, gestures)
    figures = measure(model, built, poses)
    tol = tolerance_mm / 1000.0
    n_named = len(names) - n_sampled                       # rest and gestures
    for i, b in enumerate(built):
        f = figures[b.id]
        # Refit on what resizing can fix: the part it sits on, in the named (realistic) poses; sampled poses at
        # the joint limits crush the skin itself and are reported, not chased. Growth is capped at 2 mm.
        worst = float(f["fit"][1:n_named].max(initial=0.0))
        b.figures = {"before_refit": None}
        if refit and b.fit is not None and worst > tol:
            grown = generate(model, b.entry, seed, clearance=b.clearance + min(worst - tol / 2, 0.002))
            grown.figures = {"before_refit": float(f["fit"][1:].max()) * 1000.0}
            built[i] = grown
            figures[b.id] = measure(model, [grown], poses)[b.id]
    out_dir.mkdir(parents=True, exist_ok=True)
    entries_out = [write_accessory(out_dir, b, figures[b.id], names, n_named) for b in built]
    sheet_name = None
    if sheet and built:
        sheet_name = "contact_sheet.png"
        write_contact_sheet(model, built, out_dir / sheet_name, tile)
    catalog = {"format": "darthand-accessory-catalog", "format_version": 1, "seed": seed,
               "model": {"source": str(model.meta.get("source", "model")), "side": model.side},
               "pose_sweep": {"gestures": names[1:len(names) - n_sampled], "sampled": int(n_sampled),
                              "tolerance_mm": tolerance_mm},
               "contact_sheet": sheet_name, "accessories": entries_out}
    cat.check_catalog(catalog, str(out_dir / "catalog.json"))
    write_json(out_dir / "catalog.json", catalog)
    return catalog


def write_accessory(out_dir: Path, b: Built, fig: dict, pose_names: list[str], n_named: int) -> dict:
    """Write one accessory's files; return its catalogue entry. Penetrations (mm): `rest`; `gestures` (the named
    gestures); `poses` (gestures and sampled poses) with the worst pose's name; for rigid items `fit_*` counts
    only the hand part the item is fitted to (neighbouring fingers excluded); for gloves `through_*` is the depth
    beyond the outer surface (the plain figures: beyond the inner surface)."""
    m = b.mesh
    files = {"npz": f"{b.id}.npz", "obj": f"{b.id}.obj", "mtl": f"{b.id}.mtl",
             "base_color": f"{b.id}_basecolor.png", "metallic_roughness": f"{b.id}_metallic_roughness.png"}
    material = {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in m.material.items()}
    material.update(base_color_texture=files["base_color"], metallic_roughness_texture=files["metallic_roughness"])
    world = b.world_vertices
    normals = vertex_normals(world, m.faces)
    _write_npz(out_dir / files["npz"], b, world, normals, material)
    write_bytes(out_dir / files["obj"], _obj_text(b.id, world, normals, m.uvs, m.faces, m.faces_uv).encode())
    write_bytes(out_dir / files["mtl"], _mtl_text(b.id, material, files).encode())
    write_image(out_dir / files["base_color"], m.textures["base_color"], srgb=True)
    write_image(out_dir / files["metallic_roughness"], m.textures["metallic_roughness"], srgb=False)
    depth_mm = fig["depth"] * 1000.0
    sweep = depth_mm[1:]
    pen = {"rest": float(depth_mm[0]), "poses": float(sweep.max()) if len(sweep) else None,
           "gestures": float(depth_mm[1:n_named].max()) if n_named > 1 else None,
           "worst_pose": pose_names[1 + int(np.argmax(sweep))] if len(sweep) and sweep.max() > 0 else None,
           "before_refit": b.figures.get("before_refit")}
    if b.fit is not None:
        fit_mm = fig["fit"] * 1000.0
        pen.update(fit_rest=float(fit_mm[0]), fit_poses=float(fit_mm[1:].max()) if len(sweep) else None,
                   fit_gestures=float(fit_mm[1:n_named].max()) if n_named > 1 else None)
    else:
        through = fig["through"] * 1000.0
        pen.update(through_rest=float(through[0]), through_poses=float(through[1:].max()) if len(sweep) else None,
                   through_gestures=float(through[1:n_named].max()) if n_named > 1 else None)
    joint = None if b.fit is None else int(b.fit.joint)
    entry = {"id": b.id, "type": b.entry["type"], "style": _style(b.entry), "parent_joint": joint,
             "parent_joint_name": None if joint is None else JOINT_NAMES[joint],
             "fitted_size": {k + "_mm": round(float(v) * 1000.0, 4) for k, v in m.dims.items()
                             if not k.startswith("ring_size") and k != "covered_faces"},
             "clearance_mm": round(b.clearance * 1000.0, 4),
             "max_penetration_mm": pen, "material": material, "files": files,
             "vertices": int(len(m.vertices)), "triangles": int(len(m.faces)), "parts": int(m.part_count)}
    for k in ("ring_size_eu", "ring_size_us"):
        if k in m.dims:
            entry["fitted_size"][k] = round(float(m.dims[k]), 3)
    if b.fit is not None:
        entry["rest_transform"] = b.fit.rest.tolist()
        entry["axis_distance_mm"] = round(b.fit.axis_distance * 1000.0, 4)
        entry["max_axis_drift_mm"] = float(fig["drift"] * 1000.0) if len(sweep) else None
        if b.entry["type"] == "ring":
            entry["finger"] = b.entry["finger"]
    return entry


def _style(entry: dict) -> str:
    if entry["type"] == "watch":
        return f"{entry['case']}_{entry['strap']}"
    return str(entry["style"])


def _write_npz(path: Path, b: Built, world: np.ndarray, normals: np.ndarray, material: dict) -> None:
    m = b.mesh
    arrays = dict(format=np.array(FORMAT), format_version=np.array(FORMAT_VERSION), id=np.array(b.id),
                  type=np.array(b.entry["type"]), vertices=world, local_vertices=m.vertices,
                  faces=m.faces.astype(np.int64), normals=normals, uvs=m.uvs, faces_uv=m.faces_uv.astype(np.int64),
                  parent_joint=np.array(-1 if b.fit is None else b.fit.joint, np.int64), rest_transform=b.rest,
                  material_json=np.array(json.dumps(material, sort_keys=True)))
    if m.skin is not None:
        arrays.update({k: m.skin[k] for k in ("weights", "posedirs", "shapedirs", "source_vertex", "layer")})
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    write_bytes(path, buf.getvalue())


def _obj_text(name: str, v, n, uv, f, fuv) -> str:
    lines = [f"# darthand accessory {name} (metres, rest pose, model frame)", f"mtllib {name}.mtl", f"o {name}"]
    lines += [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in v]
    lines += [f"vt {a:.6f} {c:.6f}" for a, c in uv]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in n]
    lines.append(f"usemtl {name}")
    lines += [f"f {a + 1}/{ta + 1}/{a + 1} {b + 1}/{tb + 1}/{b + 1} {c + 1}/{tc + 1}/{c + 1}"
              for (a, b, c), (ta, tb, tc) in zip(f.tolist(), fuv.tolist())]
    return "\n".join(lines) + "\n"


def _mtl_text(name: str, material: dict, files: dict) -> str:
    return (f"newmtl {name}\nKd 1 1 1\nKs 0 0 0\nNs 10\nmap_Kd {files['base_color']}\n"
            f"Pm {material['metallic']:.3f}\nPr {material['roughness']:.3f}\n"
            f"# metallic-roughness texture (glTF layout): {files['metallic_roughness']}\n")


def write_image(path: str | Path, image: np.ndarray, srgb: bool) -> None:
    """Write a float image (H, W, 3) in [0, 1] as an 8-bit PNG, sRGB-encoded if `srgb` (albedo) else raw (data)."""
    data = linear_to_srgb(image) if srgb else np.clip(image, 0, 1)
    px = (np.asarray(data) * 255.0 + 0.5).astype(np.uint8)
    spec = oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], oiio.UINT8)
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec) or not out.write_image(px) or not out.close():
            raise InputError(f"{path}: could not write PNG ({oiio.geterror()})")


# ---------------------------------------------------------------- contact sheet
def write_contact_sheet(model: HandModel, built: list[Built], path: Path, tile: int = 192) -> None:
    """All accessories on the rest hand, one tile each (rings close up from the back of the hand, wrist items
    three-quarter, gloves the whole hand), labelled with their ids."""
    from darthand.model.preview import contact_sheet, write_png

    hand = {"vertices": model.v_template, "faces": model.faces}
    images, labels = [], []
    for b in built:
        m = b.mesh
        acc = {"vertices": b.world_vertices, "faces": m.faces, "uvs": m.uvs, "faces_uv": m.faces_uv,
               "texture": m.textures["base_color"], "metallic": float(m.material.get("metallic", 0.0))}
        if b.entry["type"] == "ring":
            centre, view, extent = b.rest[:3, 3], (-0.3, -1.0, -0.5), 0.06
        elif b.entry["type"] == "glove":
            centre, view, extent = model.v_template.mean(0), (0.0, -1.0, -0.15), 0.24
        else:
            centre, view, extent = b.rest[:3, 3], (-0.4, -0.8, -0.6), 0.13
        images.append(render_view([hand, acc], centre, view, (-1.0, 0.0, 0.0), extent, tile))
        labels.append(b.id[:26])
    write_png(path, contact_sheet(images, labels, cols=10))
