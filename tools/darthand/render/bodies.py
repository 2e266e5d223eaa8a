"""A frame of several hands: each body of a scene posed by its side's source, moved by its placement into the
scene's world, dressed, and joined into one Subject (its `members`) that the renderer draws as it draws one hand.
An object body (a held object) is drawn by render/objects.py at its placement (the Subject's `objects`, their
surfaces after the hands').

A body's placement P (4, 4 rigid) maps its model frame to the world: posed vertices, normals, joints and keypoints
are moved by it, a rigid accessory's transform G becomes P G (its local mesh, and so its ray-tracing structure,
stay the same) and the pose's root rotation R0 becomes R_P R0 (the pose the labels call the world pose). The camera
is framed on all bodies' framing points and reads its views as for the first body's side.

Units: metres; all placements map into the same world frame (the planner puts the right hand at the identity, so
the views keep their meaning).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from darthand.errors import InputError
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from darthand.render.camera import Camera, load_camera
from darthand.render.dress import Dresser, GeometryOptions
from darthand.render.poses import resolve_pose
from darthand.render.objects import ObjectLibrary
from darthand.render.scenes import HandBody, Scene
from darthand.render.subject import Subject, Surface


def is_group(scene: Scene) -> bool:
    """Whether a scene is drawn as a group of bodies: several bodies, or one given a placement."""
    return len(scene.bodies) > 1 or any(b.placement is not None for b in scene.bodies)


def posed_hand(source, body: HandBody, *, keypoint_order: str, arm: float) -> Subject:
    """The hand of `body` posed by its side's `source` (a render/source.FrameSource), in the source's own frame."""
    if arm and source.kind != "model":
        raise InputError(f"arm: a {source.kind} source has no forearm rig to extend (use a model .npz)")
    shape: dict = {} if body.betas is None else {"betas": body.betas}
    shape.update({"arm": arm} if arm else {})
    return source.subject(body_pose(source, body), texture=body.texture, skin_tone_offset=float(body.skin_tone_offset),
                          accessory=body.accessory, keypoint_order=keypoint_order, **shape)


def body_pose(source, body: HandBody):
    """The pose `source` takes for `body`: a pose file's pose number pose_index resolved to its (48,) numbers (a
    model source), else the body's pose as given."""
    pose = body.pose_value()
    model = source.pose_model()
    if isinstance(pose, str) and body.pose_index is not None and model is not None:
        pose = resolve_pose(model, pose, int(body.pose_index))[0]
    return pose


def placed(subject: Subject, placement: np.ndarray) -> Subject:
    """The subject moved by the rigid `placement` (4, 4) (see the module docstring); info['placement'] records it."""
    P = np.asarray(placement, np.float64)
    R, t = P[:3, :3], P[:3, 3]
    move = lambda x: np.asarray(x, np.float64) @ R.T + t
    pose = np.array(subject.pose, np.float64)
    pose[:3] = matrix_to_axis_angle(R @ axis_angle_to_matrix(pose[:3]))
    return dataclasses.replace(
        subject, surfaces=tuple(placed_surface(s, P) for s in subject.surfaces), joints=move(subject.joints),
        keypoints=move(subject.keypoints), pose=pose, info={**subject.info, "placement": P.tolist()},
        mesh=None if subject.mesh is None else move(subject.mesh).astype(np.float32),
        framing=None if subject.framing is None else move(subject.framing).astype(np.float32),
        labelled=None if subject.labelled is None else placed(subject.labelled, P))


def placed_surface(surface: Surface, P: np.ndarray) -> Surface:
    """A posed surface moved by the rigid transform P (4, 4): vertices, normals and a rigid surface's transform."""
    R, t = P[:3, :3], P[:3, 3]
    vertices = (surface.vertices.astype(np.float64) @ R.T + t).astype(np.float32)
    normals = (surface.normals.astype(np.float64) @ R.T).astype(np.float32)
    transform = None if surface.transform is None else P @ np.asarray(surface.transform, np.float64)
    return dataclasses.replace(surface, vertices=vertices, normals=normals, transform=transform)


def model_pose(subject: Subject) -> np.ndarray:
    """(48,) a placed member's pose in its own model frame (its world pose's root rotation without the placement)."""
    P = np.asarray(subject.info.get("placement", np.eye(4)), np.float64)
    pose = np.array(subject.pose, np.float64)
    pose[:3] = matrix_to_axis_angle(P[:3, :3].T @ axis_angle_to_matrix(pose[:3]))
    return pose


def group_subject(members: tuple, objects: tuple = ()) -> Subject:
    """One Subject drawing all `members` (placed subjects) and `objects` (render/objects.HeldObject): their surfaces
    in order, framed on all of them, labelled on their labelled surfaces when any is subdivided, with the first
    member's one-hand fields."""
    first = members[0]
    labelled = None
    if any(m.labelled is not None for m in members):
        labelled = group_subject(tuple(m.labelled or m for m in members), objects)
    info = {"source": first.info.get("source"),
            **({"geometry": first.info["geometry"]} if first.info.get("geometry") else {})}
    framing = [m.framing_points() for m in members] + [s.vertices for o in objects for s in o.surfaces]
    return Subject(tuple(s for m in members for s in m.surfaces) + tuple(s for o in objects for s in o.surfaces),
                   first.joints, first.keypoints, first.side, first.pose, first.keypoint_order, info,
                   first.hand_vertices, np.concatenate(framing), labelled, tuple(members), tuple(objects))


def pose_group(scene: Scene, sources: dict, default_side: str, dresser: Dresser, geometry: GeometryOptions, *,
               camera, width: int, height: int, keypoint_order: str,
               objects: ObjectLibrary | None = None) -> tuple[Subject, Camera]:
    """(the group's Subject, its camera) of a scene of hands and objects: each hand posed by sources[side]
    (default_side for a body without one), placed, each object drawn from `objects` at its placement, the camera
    framed on all of them, then each hand dressed as `geometry` says."""
    held = placed_objects(scene, objects)
    members = []
    for body in scene.hands:
        side = body.side or default_side
        if side not in sources:
            raise InputError(f"scene: no source for the {side} hand (sides: {', '.join(sources)})")
        members.append(placed(posed_hand(sources[side], body, keypoint_order=keypoint_order, arm=geometry.arm),
                              body.placement_matrix()))
    if not members:
        raise InputError("scene: an object needs a hand to hold it (a scene's bodies hold at least one hand)")
    points = np.concatenate([m.framing_points() for m in members] + [s.vertices for o in held for s in o.surfaces])
    cam = load_camera(camera, points, width=width, height=height, side=members[0].side)
    if not geometry.is_default:
        members = [dresser.dress(m, cam, geometry) for m in members]
    return group_subject(tuple(members), held), cam


def placed_objects(scene: Scene, objects: ObjectLibrary | None) -> tuple:
    """The scene's object bodies drawn from the library `objects` at their placements (InputError when the scene
    holds an object and the renderer was given no object catalogue)."""
    if not scene.objects:
        return ()
    if objects is None:
        raise InputError(f"scene: object {scene.objects[0].object!r} needs an object catalogue (--objects-catalog)")
    return tuple(objects.placed(body.object, body.placement_matrix()) for body in scene.objects)
