"""Labels of a rendered frame (schemas/labels.schema.json): camera, 3D and 2D keypoints, visibility, bounding box,
pose and the ids of what was rendered.

Keypoints are projected exactly: keypoints_2d = the pixel position (u, v) of K (R X + t) / z in float64, with the
image's convention (pixel centres at integer + 0.5; camera.py).

Visibility: a ray from the camera centre toward the keypoint; the keypoint is visible when nothing is hit before it,
or the first hit lies within VISIBILITY_SLACK_M of it, or the first hit is on the keypoint's own part of the hand
(a face skinned mostly to the bones meeting at the joint; for a fingertip, its distal phalanx) within
OWN_PART_FACTOR x the hand's thickness there + VISIBILITY_SLACK_M. The thickness is the keypoint's distance to the
nearest hand vertex (a joint lies that deep inside its finger); a fingertip takes that of its distal joint. So a
joint seen through its own finger is visible, one behind another finger, the palm or an object is not. In a frame of
several hands (`group_labels`), a hand's own part is among its own surfaces only: the other hand always occludes.

A frame of several hands (render/bodies.py) has the scene's fields at the top level and each hand's in `hands` (in
the scene's bodies order), with `hand_type` 'interacting' for two hands, per-hand instance ids (INSTANCE_HAND +
2 b for hand b's skin, INSTANCE_ACCESSORY + 2 b for its accessory: `instance_map`) and contacts (render/contacts.py).
A frame with held objects (render/objects.py) adds `objects`: each object's id, category, instance id (INSTANCE_HAND
+ 2 B + k for object k of a frame of B hands: 3 beside one hand), pose (object frame -> camera), its bounding box's
corners (camera frame and pixels), its bbox and visible fraction from the instance map (pixels where it is seen over
pixels where it is drawn alone), its contacts with the first hand (render/object_contacts.py) and, in a frame of
two hands, each hand's (`hand_contacts`; penetration_max_mm the deepest over the hands). An object occludes
keypoints as another hand does.
"""

from __future__ import annotations

import numpy as np

from darthand.jit import kernel
from darthand.model.layout import FINGER_JOINTS, FINGERS, JOINT_NAMES, KEYPOINT_ORDERS, MANO_PARENTS
from darthand.model.per_model import per_model
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from darthand.render.arm import ARM, ARM_END
from darthand.render.camera import Camera
from darthand.render.contacts import contact_vertices
from darthand.render.object_contacts import object_contacts
from darthand.render.scene import Scene
from darthand.render.subject import Subject
from darthand.render.trace import pixel_centres

OWN_PART_FACTOR = 2.0
VISIBILITY_SLACK_M = 0.003
LABELS_FORMAT = "darthand-render-labels"
LABELS_VERSION = 1
INSTANCE_HAND, INSTANCE_ACCESSORY = 1, 2       # hand b's instance ids: these + 2 b (0: background)
_MANO_KEYPOINT_NAMES = JOINT_NAMES + ("thumb4", "index4", "middle4", "ring4", "pinky4")


def keypoint_names(order: str) -> list[str]:
    """Names of the 21 keypoints in a named order (layout.KEYPOINT_ORDERS): MANO's joint names, tips '<finger>4'."""
    return [_MANO_KEYPOINT_NAMES[i] for i in KEYPOINT_ORDERS[order]]


def own_parts(order: str) -> list[frozenset]:
    """Per keypoint of `order`, the joints whose faces are its own part: a joint j's bone and its parent's bone
    (the wrist: the palm), a fingertip's distal phalanx."""
    parts = []
    for i in KEYPOINT_ORDERS[order]:
        if i < len(JOINT_NAMES):
            parts.append(frozenset({int(i), int(MANO_PARENTS[i])} - {-1}))
        else:
            parts.append(frozenset({FINGER_JOINTS[FINGERS[i - len(JOINT_NAMES)]][2]}))
    return parts


def keypoint_thickness(keypoints: np.ndarray, hand_vertices: np.ndarray, order: str) -> np.ndarray:
    """(21,) metres: each keypoint's distance to the nearest hand vertex; a fingertip takes its distal joint's."""
    vertices = np.asarray(hand_vertices)
    if vertices.dtype not in (np.float32, np.float64):
        vertices = vertices.astype(np.float64)
    nearest = np.empty(len(keypoints))
    _nearest_squared_kernel(np.ascontiguousarray(keypoints, np.float64), np.ascontiguousarray(vertices), nearest)
    depth = np.sqrt(nearest)
    mano = KEYPOINT_ORDERS[order]
    where = {int(m): k for k, m in enumerate(mano)}
    for k, m in enumerate(mano):
        if m >= len(JOINT_NAMES):
            depth[k] = depth[where[FINGER_JOINTS[FINGERS[m - len(JOINT_NAMES)]][2]]]
    return depth


@kernel
def _nearest_squared_kernel(points, vertices, out):
    """out[k] = the least squared distance (float64) from points[k] (K, 3) float64 to vertices (N, 3), as numpy's
    ((points[:, None] - vertices[None]) ** 2).sum(-1).min(1) has it: x, y and z added in that order, NaN if any
    distance is NaN. One pass, without the (K, N, 3) temporaries."""
    for k in range(points.shape[0]):
        best = np.inf
        for i in range(vertices.shape[0]):
            dx = points[k, 0] - np.float64(vertices[i, 0])
            dy = points[k, 1] - np.float64(vertices[i, 1])
            dz = points[k, 2] - np.float64(vertices[i, 2])
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < best or d2 != d2:
                best = d2
                if d2 != d2:
                    break
        out[k] = best


def visibility(scene: Scene, camera: Camera, keypoints: np.ndarray, thickness: np.ndarray,
               parts: list[frozenset], own: frozenset | None = None) -> np.ndarray:
    """(K,) bool visibility of keypoints (K, 3) (see the module docstring); keypoints behind the camera are not
    visible. own: the scene's surface indices of the keypoints' hand (None: all surfaces are its own)."""
    C = camera.centre
    d = np.asarray(keypoints, np.float64) - C
    length = np.linalg.norm(d, axis=1)
    hit = scene.intersect(np.ascontiguousarray(np.broadcast_to(C, d.shape), np.float32),
                          np.ascontiguousarray(d, np.float32), tfar=np.ones(len(d), np.float32))
    _, z = camera.project(keypoints)
    out = np.zeros(len(d), bool)
    for k in range(len(d)):
        prim, geom = int(hit["primID"][k]), int(hit["geomID"][k])
        gap = (1.0 - float(hit["tfar"][k])) * length[k]
        if prim < 0 or gap <= VISIBILITY_SLACK_M:
            out[k] = True
            continue
        joints = scene.surfaces[geom].face_joints
        own_part = joints is not None and (own is None or geom in own) and int(joints[prim]) in parts[k]
        out[k] = own_part and gap <= OWN_PART_FACTOR * thickness[k] + VISIBILITY_SLACK_M
    return out & (z > 0)


def mask_bbox(alpha: np.ndarray) -> list[float] | None:
    """[x_min, y_min, x_max, y_max] in pixels (corners of the covered pixels) of alpha > 0; None if empty."""
    rows = np.flatnonzero(alpha.max(axis=1) > 0)
    cols = np.flatnonzero(alpha.max(axis=0) > 0)
    if not len(rows):
        return None
    return [float(cols[0]), float(rows[0]), float(cols[-1] + 1), float(rows[-1] + 1)]


def frame_labels(subject: Subject, camera: Camera, scene: Scene, alpha: np.ndarray, *, files: dict,
                 extra: dict | None = None) -> dict:
    """The labels.json document of a frame of one hand (schemas/labels.schema.json)."""
    labels = {**scene_fields(subject, camera, alpha, files), **hand_fields(subject, camera, scene, alpha)}
    if extra:
        labels.update(extra)
    return labels


def scene_fields(subject: Subject, camera: Camera, alpha: np.ndarray, files: dict) -> dict:
    """The labels' fields of the frame as a whole: image size, camera, keypoint order, coverage and bbox of `alpha`
    (H, W) (all hands and accessories), source, files."""
    return {
        "format": LABELS_FORMAT,
        "version": LABELS_VERSION,
        "image_size": [camera.width, camera.height],
        "K": camera.K.tolist(),
        "camera": {"R": camera.R.tolist(), "t": camera.t.tolist(), "extrinsics": camera.extrinsics.tolist(),
                   "centre": camera.centre.tolist(), "convention": "opencv"},
        "keypoint_order": subject.keypoint_order,
        "keypoint_names": keypoint_names(subject.keypoint_order),
        "flat_hand_mean": True,
        "bbox": mask_bbox(alpha),
        "coverage": float(alpha.sum() / alpha.size),
        "source": subject.info.get("source"),
        "files": files,
    }


def hand_fields(subject: Subject, camera: Camera, scene: Scene, alpha: np.ndarray,
                own: frozenset | None = None) -> dict:
    """One hand's labels: side, keypoints (camera frame, world, 2D; visibility, in_image), joints, world pose, ids,
    and bbox and coverage of `alpha` (H, W), its own coverage. own: as `visibility`'s."""
    kp_world = np.asarray(subject.keypoints, np.float64)
    kp_2d, _ = camera.project(kp_world)
    thick = keypoint_thickness(kp_world, subject.hand_vertices, subject.keypoint_order)
    visible = visibility(scene, camera, kp_world, thick, own_parts(subject.keypoint_order), own)
    inside = (kp_2d[:, 0] >= 0) & (kp_2d[:, 0] < camera.width) & (kp_2d[:, 1] >= 0) & (kp_2d[:, 1] < camera.height)
    acc = subject.accessory
    info = subject.info
    return {
        "side": subject.side,
        "keypoints_3d": camera.to_camera(kp_world).tolist(),
        "keypoints_3d_world": kp_world.tolist(),
        "keypoints_2d": kp_2d.tolist(),
        "visibility": visible.tolist(),
        "in_image": inside.tolist(),
        "joints_3d": camera.to_camera(subject.joints).tolist(),
        "joints_3d_world": np.asarray(subject.joints, np.float64).tolist(),
        "mano_pose": np.asarray(subject.pose, np.float64).tolist(),
        "gesture": info.get("gesture"),
        "texture": {"id": info.get("texture"), "skin_tone_offset": info.get("skin_tone_offset", 0.0),
                    "tone_srgb": info.get("tone_srgb")},
        "accessory": {"id": info.get("accessory", "none"),
                      "parent_joint": info.get("accessory_parent_joint"),
                      "kind": "none" if acc is None else ("rigid" if info.get("accessory_parent_joint") is not None
                                                          else "skinned")},
        "bbox": mask_bbox(alpha),
        "bbox_keypoints": [float(kp_2d[:, 0].min()), float(kp_2d[:, 1].min()), float(kp_2d[:, 0].max()),
                           float(kp_2d[:, 1].max())],
        "coverage": float(alpha.sum() / alpha.size),
    }


def group_labels(subject: Subject, camera: Camera, scene: Scene, alpha: np.ndarray, geom: np.ndarray, *,
                 files: dict, extra: dict | None = None) -> dict:
    """The labels.json document of a frame of several hands (subject.members; see the module docstring). alpha
    (H, W) coverage of all hands and accessories; geom (H, W) the surface index each pixel centre's ray hit."""
    members = subject.members
    instances = instance_map(geom, subject)
    hands = []
    for b, member in enumerate(members):
        mine = np.isin(instances, (INSTANCE_HAND + 2 * b, INSTANCE_ACCESSORY + 2 * b))
        entry = hand_fields(member, camera, scene, np.where(mine, alpha, 0), frozenset(surface_range(subject, b)))
        others = [m for m in members if m is not member]
        entry["instance"] = {"hand": INSTANCE_HAND + 2 * b, "accessory": INSTANCE_ACCESSORY + 2 * b}
        entry["contacts"] = (contacts_with(member, others[0]) if len(others) == 1 else [])
        hands.append(entry)
    labels = {**scene_fields(subject, camera, alpha, files),
              "hand_type": "interacting" if len(members) > 1 else members[0].side, "hands": hands}
    if subject.objects:
        labels["objects"] = [object_fields(subject, k, camera, instances) for k in range(len(subject.objects))]
    if extra:
        labels.update(extra)
    return labels


def surface_range(subject: Subject, b: int) -> range:
    """The indices in subject.surfaces of member b's surfaces (members' surfaces are concatenated in order)."""
    start = sum(len(m.surfaces) for m in subject.members[:b])
    return range(start, start + len(subject.members[b].surfaces))


def instance_map(geom: np.ndarray, subject: Subject) -> np.ndarray:
    """(H, W) uint8 instance ids of a frame of several hands from `geom` (H, W), the surface index each pixel
    centre's ray hit (-1: background): 0 background and drawn arms (they are not in the mask), INSTANCE_HAND + 2 b
    hand b's skin (and its cut's cap), INSTANCE_ACCESSORY + 2 b its accessory."""
    lookup = np.zeros(len(subject.surfaces) + 1, np.uint8)           # the last entry: background (-1)
    for b in range(len(subject.members)):
        for i in surface_range(subject, b):
            surface = subject.surfaces[i]
            kind = INSTANCE_ACCESSORY if surface.role == "accessory" else INSTANCE_HAND
            lookup[i] = 0 if surface.name in (ARM, ARM_END) else kind + 2 * b
    for k in range(len(subject.objects)):
        lookup[object_range(subject, k)] = object_instance(subject, k)
    return lookup[np.asarray(geom, np.int64)]


def object_instance(subject: Subject, k: int) -> int:
    """The instance id of held object k: INSTANCE_HAND + 2 B + k for a frame of B hands (3 beside one hand)."""
    return INSTANCE_HAND + 2 * len(subject.members) + k


def object_range(subject: Subject, k: int) -> range:
    """The indices in subject.surfaces of held object k's surfaces (after all members' surfaces)."""
    start = sum(len(m.surfaces) for m in subject.members) + sum(len(o.surfaces) for o in subject.objects[:k])
    return range(start, start + len(subject.objects[k].surfaces))


def object_fields(subject: Subject, k: int, camera: Camera, instances: np.ndarray) -> dict:
    """The labels of held object k (see the module docstring); instances (H, W) the frame's instance map."""
    held = subject.objects[k]
    P = held.placement
    R, t = camera.R @ P[:3, :3], camera.R @ P[:3, 3] + camera.t
    corners = held.corners()
    corners_2d, _ = camera.project(corners)
    instance = object_instance(subject, k)
    seen = instances == instance
    drawn = object_pixels_alone(subject, k, camera, corners_2d, seen)
    found = [object_contacts((m.labelled or m).hand_vertices, held.item, P) for m in subject.members]
    out = {"id": held.item.id, "category": held.item.category, "instance": instance,
           "pose": {"R": R.tolist(), "t": t.tolist()},
           "corners_3d": camera.to_camera(corners).tolist(), "corners_2d": corners_2d.tolist(),
           "bbox": mask_bbox(seen.astype(np.float32)),
           "visible_fraction": float(seen.sum() / drawn) if drawn else 0.0,
           "contacts": contacts_record(0, found[0]),
           "penetration_max_mm": round(1000 * max(f.penetration_max_m for f in found), 4)}
    if len(found) > 1:
        out["hand_contacts"] = [{**contacts_record(b, f), "penetration_max_mm": round(1000 * f.penetration_max_m, 4)}
                                for b, f in enumerate(found)]
    return out


def contacts_record(hand: int, found) -> dict:
    """The labels' record of hand `hand`'s contacts with an object (render/object_contacts.ObjectContacts)."""
    return {"hand": hand, "hand_vertices": found.hand_vertices.tolist(), "object_points": found.object_points.tolist()}


def object_pixels_alone(subject: Subject, k: int, camera: Camera, corners_2d: np.ndarray, seen: np.ndarray) -> int:
    """How many pixel centres' rays hit held object k with nothing else in the scene (those inside its corners'
    projected box, clipped to the image; an object reaching behind the camera counts its pixels in the image).
    seen (H, W): the pixels where it is seen (their rays hit it: only the others are traced)."""
    held = subject.objects[k]
    if (camera.to_camera(held.corners())[:, 2] <= 0).any():
        c0, r0, c1, r1 = 0, 0, camera.width, camera.height
    else:
        c0, r0 = np.clip(np.floor(corners_2d.min(axis=0)).astype(int), 0, [camera.width, camera.height])
        c1, r1 = np.clip(np.ceil(corners_2d.max(axis=0)).astype(int), 0, [camera.width, camera.height])
    if c1 <= c0 or r1 <= r0:
        return 0
    hidden = ~seen[r0:r1, c0:c1].reshape(-1)
    uv = pixel_centres(r0, r1, c0, c1)[hidden]
    directions = np.ascontiguousarray(camera.directions(uv), np.float32)
    origins = np.ascontiguousarray(np.broadcast_to(camera.centre, directions.shape), np.float32)
    alone = Scene(Subject(held.surfaces, subject.joints, subject.keypoints, subject.side, subject.pose))
    return int(seen.sum()) + int(alone.occluded(origins, directions, np.inf).sum())


def contacts_with(hand: Subject, other: Subject) -> list[int]:
    """Sorted ids of `hand`'s model vertices within contacts.CONTACT_M of `other`'s model hand surface or inside
    it (both the unsubdivided, labelled surfaces)."""
    own, theirs = hand.labelled or hand, other.labelled or other
    return contact_vertices(own.hand_vertices, theirs.hand.vertices, theirs.hand.faces).tolist()


@per_model
def root_regressor(model):
    """(1, V) sparse: the root joint's row of the model's joint regressor (kept per model: slicing a sparse row takes
    a third of a millisecond, and every dataset frame's labels ask for it)."""
    return model.J_regressor[0]


def mano_camera_parameters(model, pose, R, t, betas=None) -> dict:
    """MANO parameters of a posed hand in the camera frame: {'global_orient' (3,), 'hand_pose' (45,), 'betas' (S,),
    'trans' (3,)}, axis-angle relative to the flat hand (flat_hand_mean true), metres, such that
    forward(model, concat(global_orient, hand_pose), betas, trans=trans) gives the camera-frame joints, vertices and
    keypoints of the world-frame pose `pose` (48,) seen by a camera X_cam = R X + t.

    MANO rotates about the shaped rest root joint J0 (the forward pass puts a point x of the root's part at
    R0 (x - J0) + J0 + trans), so the camera's rotation composes with the global rotation, R0' = R R0, and the
    translation absorbs the rest: trans' = R J0 + t - J0 (for the world pose's trans of zero)."""
    pose = np.asarray(pose, np.float64).reshape(-1)
    R, t = np.asarray(R, np.float64), np.asarray(t, np.float64)
    n_betas = model.num_betas
    b = np.zeros(n_betas) if betas is None else np.asarray(betas, np.float64).reshape(-1)
    shaped = np.asarray(model.v_template) + (np.asarray(model.shapedirs)[..., :len(b)] @ b if len(b) else 0)
    j0 = np.asarray(root_regressor(model) @ shaped).reshape(3)
    root = matrix_to_axis_angle(R @ axis_angle_to_matrix(pose[:3]))
    return {"global_orient": root.tolist(), "hand_pose": pose[3:].tolist(), "betas": b.tolist(),
            "trans": (R @ j0 + t - j0).tolist(), "frame": "camera", "flat_hand_mean": True}
