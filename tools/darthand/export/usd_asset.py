"""One self-contained USD asset package per hand, in the common asset structure.

    <out>/                       e.g. build/usd/right/
      <name>.usda                interface layer: defaultPrim </RightHand> (</LeftHand>), a SkelRoot of kind
                                 `component` with assetInfo and darthand's conventions in customData, stage
                                 metadata (metersPerUnit = 1, upAxis = Y, time codes), the variant sets `texture`,
                                 `accessory` and `gesture`, and a payload to payload.usdc
      payload.usdc               the rig (usd_skel.py): Skeleton with oriented joints, a SkelAnimation per gesture
                                 and one of all gestures in turn, the hand Mesh (skin, UVs, normals, pose-corrective
                                 BlendShapes with weights in [0, 1], then the shape dials of shape_dials.py) and
                                 the forearm cap Mesh, bound to the skin
                                 material </RightHand/RightHandSkin>
      texture/<id>.usda, texture/<id>/*.png        one skin material per texture variant
      accessory/<id>.usdc, accessory/<id>/*.png    one accessory per accessory variant
      asset.json                 what was written: options, counts, gesture names by time code, error bounds,
                                 the built shape's betas and the shape dials' error (shape_dials)

Every asset path is relative. The package is written into a temporary folder next to <out> and renamed into place,
so an interrupted export never leaves a half-written package.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Sdf, UsdGeom, Vt

import darthand
from darthand.accessories.loader import Accessory
from darthand.errors import InputError
from darthand.export.conventions import asset_conventions
from darthand.export.correctives import Correctives, export_correctives
from darthand.export.gestures import gesture_poses
from darthand.export.options import check_export_options
from darthand.export.shape_dials import DIAL_RANGE, ShapeDials, dial_error, shape_dials
from darthand.export.texture_files import check_textures_fit
from darthand.export.usd_materials import MaterialSpec, bind_material
from darthand.export.usd_skel import ALL_GESTURES, SPARSE_TOL, RigNames, define_rig
from darthand.export.usd_variants import (add_accessory_variants, add_gesture_variants, add_texture_variants,
                                          check_variant_id, new_layer_stage, skin_material, write_accessory_variant,
                                          write_texture_variant)
from darthand.fileio import replace_folder, staging_folder, write_json
from darthand.model.hand_model import HandModel
from darthand.textures.loader import TextureSet

PLAIN_TEXTURE = "plain"  # the texture variant used when no texture catalogue is given: a constant skin colour


@dataclass(frozen=True)
class ExportOptions:
    """influences: joints per vertex, at most (None: as many as any vertex has non-zero weights, lossless);
    correctives: 'full' | 'pca:K' | 'pose-pca:K' | 'none' (correctives.export_correctives); texture_size: downsize
    every texture so its longer side is at most this many pixels (texture_files.place_texture; None: link the files
    unchanged); sparse_tol: blend-shape offsets shorter than this (metres) are left out; shape_dials: the range of
    delta beta the shape-direction blend shapes reach (shape_dials.py; 0: none)."""

    influences: int | None = None
    correctives: str = "full"
    texture_size: int | None = None
    sparse_tol: float = SPARSE_TOL
    shape_dials: float = DIAL_RANGE

    def check(self) -> None:
        check_export_options(self.influences, self.correctives, self.texture_size)


def export_usd(model: HandModel, out: str | os.PathLike, *, textures: list[TextureSet] | tuple = (),
               default_texture: str | None = None, accessories: list[Accessory] | tuple = (),
               options: ExportOptions = ExportOptions(), gestures: tuple[list[str], np.ndarray] | None = None,
               name: str | None = None) -> dict:
    """Write the asset package of `model` (wrist-enhanced, with UVs) to the folder `out`; returns asset.json's dict
    plus `write_seconds`.

    gestures: (names, poses (G, 48) axis-angle) for the animation (default: the named gestures of
    assets_src/poses). textures: the `texture` variants (default: one constant-colour variant, 'plain').
    accessories: the `accessory` variants besides 'none'.
    """
    out = Path(out)
    options.check()
    name = name or model.side
    names, poses = gesture_poses(model) if gestures is None else (list(gestures[0]), np.asarray(gestures[1]))
    if len(names) != len(poses) or len(names) == 0:
        raise InputError(f"gestures: {len(names)} names for {len(poses)} poses (need at least one)")
    _check_unique(list(names) + [ALL_GESTURES], "gesture")
    for g in names:
        check_variant_id(g, "gesture")
    rig_names = RigNames.for_side(model.side)
    root = Sdf.Path(f"/{rig_names.root}")
    check_textures_fit(model, textures)
    materials = {t.id: skin_material(t) for t in textures} or {PLAIN_TEXTURE: MaterialSpec(wrap="clamp")}
    _check_unique([t.id for t in textures], "texture")
    default_texture = default_texture or next(iter(materials))
    if default_texture not in materials:
        raise InputError(f"texture: the default {default_texture!r} is not one of the texture variants")
    _check_unique([a.id for a in accessories] + ["none"], "accessory")
    tmp = staging_folder(out)      # also removes the staging folders a killed run left beside `out`
    try:
        t0 = time.perf_counter()
        correctives = export_correctives(model, options.correctives)
        dials = shape_dials(model, options.shape_dials)
        stats = write_payload(tmp / "payload.usdc", root, model, correctives, options, names, poses, dials)
        texture_layers = {vid: write_texture_variant(tmp, vid, spec, options.texture_size)
                          for vid, spec in materials.items()}
        accessory_layers = {a.id: write_accessory_variant(tmp, a, correctives, options.influences,
                                                          options.texture_size, options.sparse_tol, rig_names.prefix)
                            for a in accessories}
        write_interface(tmp / f"{name}.usda", name, root, rig_names, names, texture_layers, accessory_layers,
                        default_texture, model)
        info = {
            "name": name,
            "side": model.side,
            "interface": f"{name}.usda",
            "payload": "payload.usdc",
            "root_prim": str(root),
            "prims": stats.prims,
            "conventions": asset_conventions(model),
            "blend_shapes": correctives.encoding.as_dict(),
            "shape_dials": {**dials.as_dict(dial_error(model, dials, poses)), "blend_shapes": dials.encoding.as_dict()},
            "model": {"source": model.meta.get("source"), "vertices": model.num_vertices,
                      "faces": model.num_faces, "tip_ids": model.tip_ids.tolist()},
            "options": {"influences": options.influences or "all", "correctives": options.correctives,
                        "texture_size": options.texture_size, "sparse_tol_m": options.sparse_tol,
                        "shape_dials": options.shape_dials},
            "rig": stats.as_dict(),
            "gestures": {"names": names, "time_codes": list(range(len(names))), "variant_set": "gesture",
                         "timeline_variant": ALL_GESTURES,
                         "poses": np.asarray(poses, dtype=np.float64).round(12).tolist()},
            "variants": {"texture": list(texture_layers), "accessory": ["none"] + list(accessory_layers),
                         "gesture": [ALL_GESTURES] + list(names)},
        }
        info["files"] = {p.relative_to(tmp).as_posix(): p.stat().st_size for p in sorted(tmp.rglob("*"))
                         if p.is_file()}
        write_json(tmp / "asset.json", info)
        replace_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    reload_open_layers(out)
    return {**info, "write_seconds": round(time.perf_counter() - t0, 3)}


def write_payload(path: Path, root: Sdf.Path, model: HandModel, correctives: Correctives, options: ExportOptions,
                  names: list[str], poses: np.ndarray, dials: ShapeDials | None = None):
    """payload.usdc: the SkelRoot `root` with the rig; the hand and the cap bound to the texture variant's material
    (composed in by the interface's `texture` variant)."""
    stage = new_layer_stage(path, root.name)
    _time_metadata(stage.GetRootLayer(), len(names))
    stats = define_rig(stage, root, model, correctives, names, poses, options.influences, options.sparse_tol, dials)
    for role in ("hand", "forearm_cap"):
        bind_material(stage.GetPrimAtPath(stats.prims[role]), Sdf.Path(stats.prims["material"]))
    stage.GetRootLayer().Save()
    return stats


def write_interface(path: Path, name: str, root: Sdf.Path, rig_names: RigNames, gesture_names: list[str],
                    texture_layers: dict[str, str], accessory_layers: dict[str, str], default_texture: str,
                    model: HandModel) -> None:
    """The interface layer: metadata, the component root prim with assetInfo and conventions, the payload, the
    variant sets."""
    layer = Sdf.Layer.CreateNew(str(path))
    layer.defaultPrim = root.name
    layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
    layer.pseudoRoot.SetInfo("upAxis", UsdGeom.Tokens.y)
    _time_metadata(layer, len(gesture_names))
    layer.customLayerData = {"darthand:gestures": Vt.StringArray(gesture_names)}
    prim = Sdf.PrimSpec(layer, root.name, Sdf.SpecifierDef, "SkelRoot")
    prim.kind = "component"
    prim.assetInfo = {"identifier": Sdf.AssetPath(f"./{path.name}"), "name": f"darthand_{name}",
                      "version": darthand.__version__}
    prim.customData = {"darthand": {"conventions": _vt_dict(asset_conventions(model))}}
    prim.payloadList.Prepend(Sdf.Payload("./payload.usdc"))
    add_texture_variants(layer, root, rig_names.material, texture_layers, default_texture)
    add_accessory_variants(layer, root, rig_names.prefix, accessory_layers, "none")
    add_gesture_variants(layer, root, rig_names, gesture_names)
    layer.Save()


def reload_open_layers(folder: Path) -> None:
    """Layers of a previous package at the same paths may still be open in this process (Sdf's layer registry
    keeps them by path while anything holds them); reload them so that later opens see the new files."""
    for path in folder.rglob("*.usd*"):
        layer = Sdf.Layer.Find(str(path))
        if layer is not None:
            layer.Reload(force=True)


def _time_metadata(layer: Sdf.Layer, count: int) -> None:
    """One time code per gesture, one gesture per second."""
    layer.startTimeCode = 0
    layer.endTimeCode = max(0, count - 1)
    layer.timeCodesPerSecond = 1
    layer.framesPerSecond = 1


def _vt_dict(d: dict) -> dict:
    """A JSON-like dict as USD dictionary metadata (lists of strings / numbers as Vt arrays)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[k] = _vt_dict(v)
        elif isinstance(v, (list, tuple)):
            out[k] = Vt.StringArray([str(x) for x in v]) if any(isinstance(x, str) for x in v) else \
                Vt.DoubleArray([float(x) for x in v])
        else:
            out[k] = v
    return out


def _check_unique(ids: list[str], what: str) -> None:
    seen = set()
    for i in ids:
        if i in seen:
            raise InputError(f"{what} id {i!r} is used twice")
        seen.add(i)
