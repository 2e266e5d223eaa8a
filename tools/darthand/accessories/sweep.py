"""Verifying fitted accessories across poses: the pose sweep and the penetration figures of every pose.

Figures per accessory and pose (metres):
  fit     rigid items: the overlap of the accessory and the part of the hand it is fitted to -- for a ring its
          digit, for a wrist item the whole hand -- both ways: vertices of that part inside the accessory, and the
          accessory's inward-facing vertices inside the part's closed surface (a digit's skin capped where it meets
          the palm). A neighbouring finger or the palm pressed against a ring is contact, not fit: it counts in
          `depth` only.
  depth   the overlap with the whole hand, so contact with any part of it counts (the larger of the two): hand
          vertices inside the accessory, and every accessory vertex inside the hand (a band's outside pressed into
          a neighbouring finger as well as its bore); for gloves, how far the hand reaches beyond the glove's inner
          surface;
  through gloves: how far the hand reaches beyond the glove's outer surface;
  drift   rigid items: the largest change of the distance from the accessory's centre to its bone axis;
  slide, turned  rings worn per pose (`worn`, accessories/wear): how far the ring slid along its bone (m) and the
          largest change of a joint angle made to give it room (degrees; wear never takes a turn that makes two
          digits pass through each other, by model/self_crossing's test).

With `worn` (the default), a ring is measured as a dataset frame shows it: in the pose accessories/wear gives
(digits turned aside where the ring needs room) and slid along its bone; without, rigid on its bone at its fitted
place, as a package (USD, glTF) poses it.

The sweep is split over poses: each worker process measures every accessory on its share of the poses (whole
batches of `CHUNK` poses), and a pose's figures depend only on its batch, so the result is the same, bit for bit,
for any number of workers.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from darthand.accessories import catalog as cat
from darthand.accessories.attach import apply, axis_distance, pose_skinned, to_local
from darthand.accessories.collide import ClosedHand, Solid, glove_penetration, inward_vertices, neighbourhood
from darthand.accessories.fit import WRIST_JOINT, wrist_axis
from darthand.accessories.wear import RingWear, slide_matrix
from darthand.model.anatomy import bone_ends, rest_joints, sample_poses
from darthand.model.forward import forward
from darthand.model.gestures import model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.intersections import joint_parts
from darthand.model.layout import MANO_PARENTS
from darthand.model.topology import face_joints, vertex_normals
from darthand.processes import deaf_to_ctrl_c, init_worker

CHUNK = 16               # poses posed at once
MIN_POSES_PER_WORKER = 24


def sweep_poses(model: HandModel, seed: int, n_sampled: int, gestures: list[str] | None = None,
                stream: str = "pose-sweep", skip_crossing: bool = True):
    """(names, (P, 48) poses): the rest pose, the named gestures, then those of `n_sampled` anatomical samples drawn
    from the generator of (seed, `stream`) in which the hand does not pass through itself (two digits inside each
    other: model/self_crossing), unless `skip_crossing` is False. A sample keeps the name of its draw (`sample_017`),
    so the names say which were left out."""
    g = model_gestures(model, gestures)
    sampled = sample_poses(model, n_sampled, cat.item_rng(seed, stream)) if n_sampled else np.zeros((0, 48))
    kept = np.arange(n_sampled)
    if skip_crossing and n_sampled:
        from darthand.model.self_crossing import SelfCrossing  # lazy: kept off `darthand --help`'s path

        kept = np.flatnonzero([c is None for c in SelfCrossing(model).crossing_poses(sampled)])
    names = ["rest"] + list(g.names) + [f"sample_{i:03d}" for i in kept]
    return names, np.concatenate([np.zeros((1, 48)), g.poses, sampled[kept]])


@dataclass(frozen=True)
class RigidProbe:
    """What the sweep needs of a rigid accessory: its joint and rest placement, its local-frame mesh, the
    inward-facing vertices (a mask over vertices) and the hand part it is fitted to (a digit index, or -1 for the
    whole hand)."""

    id: str
    joint: int
    rest: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    inward: np.ndarray
    part: int

    @property
    def inner(self) -> np.ndarray:
        """(K, 3) the inward-facing vertices (local)."""
        return self.vertices[self.inward]


@dataclass(frozen=True)
class GloveProbe:
    """A glove's skinned mesh and the covered hand vertices whose normals are cast through it."""

    id: str
    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    posedirs: np.ndarray
    inner_faces: np.ndarray
    hand_ids: np.ndarray
    face_source: np.ndarray


def probes(built) -> list:
    """Light, picklable probes of built accessories (`build.Built`: entry, mesh, fit)."""
    out: list = []
    for b in built:
        m = b.mesh
        if b.fit is None:
            sk = m.skin
            rim = sk["layer"][m.faces].min(1) != sk["layer"][m.faces].max(1)
            interior = np.setdiff1d(np.where(sk["layer"] == 0)[0], np.unique(m.faces[rim]))
            out.append(GloveProbe(b.id, m.vertices, m.faces, sk["weights"], sk["posedirs"], sk["inner_faces"],
                                  sk["source_vertex"][interior], sk["source_vertex"][m.faces[:, 0]]))
        else:
            out.append(RigidProbe(b.id, int(b.fit.joint), b.fit.rest, m.vertices, m.faces,
                                  inward_vertices(m.vertices, m.normals), digit_of(b.fit.joint)))
    return out


def digit_of(joint: int) -> int:
    """Index into FINGERS of the digit a joint belongs to; -1 for the wrist (the whole hand)."""
    return int(joint_parts()[joint]) - 1


def measure(model: HandModel, built, poses: np.ndarray, workers: int = 1, worn: bool = True) -> dict:
    """Per accessory id: {"fit", "depth", "through", "slide", "turned"} (P,) arrays (m; turned in degrees) and
    "drift" (m) over `poses` (P, 48); rings `worn` per pose (see the module docstring)."""
    items = probes(built)
    workers = max(1, min(int(workers), len(poses) // MIN_POSES_PER_WORKER))
    if workers == 1:
        return measure_probes(model, items, poses, worn)
    # Shares in whole chunks: each pose is posed in the same batch as in one process, so figures agree to the bit.
    chunks = -(-len(poses) // CHUNK)
    bounds = np.minimum(np.linspace(0, chunks, workers + 1).astype(int) * CHUNK, len(poses))
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                initargs=(os.getpid(),)) as pool:
        with deaf_to_ctrl_c():                  # map starts the workers; Ctrl-C is ours, even while they import
            shares = pool.map(measure_probes, [model] * workers, [items] * workers,
                              [poses[a:b] for a, b in zip(bounds[:-1], bounds[1:])], [worn] * workers)
        parts = list(shares)
    return {i.id: {**{key: np.concatenate([p[i.id][key] for p in parts]) for key in PER_POSE},
                   "drift": max(p[i.id]["drift"] for p in parts)} for i in items}


def _init_worker(parent: int) -> None:
    """A sweep worker: single-threaded BLAS, Ctrl-C left to the parent, ends when the parent dies."""
    init_worker(parent)
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


PER_POSE = ("fit", "depth", "through", "slide", "turned")


def measure_probes(model: HandModel, items: list, poses: np.ndarray, worn: bool = True) -> dict:
    """`measure` in this process, on probes, with single-threaded BLAS (its products are small, a pose at a time
    for worn rings, and threads only wait on each other, more so beside another worker)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _measure_probes(model, items, poses, worn)


def _measure_probes(model: HandModel, items: list, poses: np.ndarray, worn: bool) -> dict:
    out: dict[str, dict] = {i.id: {**{key: np.zeros(len(poses)) for key in PER_POSE}, "drift": 0.0} for i in items}
    rigid = [i for i in items if isinstance(i, RigidProbe)]
    gloves = [i for i in items if isinstance(i, GloveProbe)]
    rings = [i for i in rigid if worn and i.part >= 0]
    fixed = [i for i in rigid if not (worn and i.part >= 0)]
    hand = HandParts(model)
    axes = _BoneAxes(model)
    solids = {i.id: Solid(i.vertices, i.faces) for i in rigid}
    hands: dict = {}                                   # the rings' posed hand, shared pose by pose
    wear = {i.id: RingWear(model, i.joint, i.rest, i.vertices, hands=hands) for i in rings}
    near = neighbourhood(model.faces, model.num_vertices, rings=3) if gloves else None
    for s in range(0, len(poses), CHUNK):
        posed = forward(model, poses[s:s + CHUNK])
        B = len(posed.vertices)
        views = {i.id: posed for i in fixed}            # the posed batch each item is measured on
        placed = {i.id: posed.transforms[:, i.joint] @ i.rest for i in fixed}
        turned = {}
        worn_by: dict[str, list] = {i.id: [] for i in rings}
        for p in poses[s:s + CHUNK]:                   # pose by pose: every ring wears the same posed hand
            for i in rings:
                worn_by[i.id].append(wear[i.id].worn(p))
        for i in rings:
            w = worn_by[i.id]
            turned[i.id] = np.array([bool(x.changed) for x in w])
            views[i.id] = _with_turned(model, posed, w, turned[i.id])
            placed[i.id] = views[i.id].transforms[:, i.joint] @ i.rest @ np.stack([slide_matrix(x.slide) for x in w])
            fig = out[i.id]
            fig["slide"][s:s + B] = [x.slide for x in w]
            fig["turned"][s:s + B] = [max((np.abs(a).max() for a in x.changed.values()), default=0.0) for x in w]
        _rigid_at(hand, axes, solids, rigid, views, placed, turned, out, s)
        if gloves:
            worn_gloves = {g.id: pose_skinned(g.vertices, g.weights, g.posedirs, posed.rotations, posed.transforms)
                           for g in gloves}
            for p in range(B):
                _gloves_at(model, gloves, worn_gloves, posed.vertices[p], p, near, out, s + p)
    return out


def _with_turned(model: HandModel, posed, worn: list, turned: np.ndarray):
    """The posed batch with the poses where a ring turned digits (`turned` (B,) bool) posed as worn."""
    if not turned.any():
        return posed
    again = forward(model, np.stack([w.pose for w, t in zip(worn, turned) if t]))
    arrays = {}
    for name in ("vertices", "joints", "keypoints", "rotations", "transforms"):
        a = getattr(posed, name).copy()
        a[turned] = getattr(again, name)
        arrays[name] = a
    return replace(posed, **arrays)


def _rigid_at(hand: "HandParts", axes: "_BoneAxes", solids: dict, rigid: list, views: dict, placed: dict,
              turned: dict, out: dict, s: int) -> None:
    """Figures of rigid probes placed (`placed`: id -> (B, 4, 4)) on their posed batches (`views`: id -> Posed),
    written at poses s.. of `out`. Per pose, the items on the shared hand are measured against one closed surface;
    a ring whose wear turned the hand (`turned`: id -> (B,) bool) against its own."""
    if not rigid:
        return
    B = len(placed[rigid[0].id])
    for i in rigid:
        fig, view = out[i.id], views[i.id]
        fit, depth = hand_inside_rigid(solids[i.id], to_local(placed[i.id], view.vertices), hand.own_vertices(i.part))
        fig["fit"][s:s + B], fig["depth"][s:s + B] = fit, depth
        fig["drift"] = max(fig["drift"], axes.drift(i, placed[i.id], view))
    for p in range(B):
        alone = [i for i in rigid if i.id in turned and turned[i.id][p]]
        shared = [i for i in rigid if not (i.id in turned and turned[i.id][p])]
        groups = ([(shared, views[shared[0].id].vertices[p])] if shared else []) + \
            [([i], views[i.id].vertices[p]) for i in alone]
        for items, vertices in groups:
            for item_id, (fit, depth) in rigid_inside_hand(hand, items, placed, vertices, p).items():
                fig = out[item_id]
                fig["fit"][s + p] = max(fig["fit"][s + p], fit)
                fig["depth"][s + p] = max(fig["depth"][s + p], depth, fit)


class HandParts:
    """The hand's closed surface and, per digit, the digit's skin capped where it meets the palm; both re-posed per
    pose. A face belongs to the digit of the joint with the largest summed corner weight (the wrist and palm joint
    0 belong to no digit)."""

    def __init__(self, model: HandModel):
        self.model = model
        self.whole = ClosedHand(model.faces)
        joint_digit = np.array([digit_of(j) for j in range(len(model.parents))])
        self.face_digit = joint_digit[face_joints(model.faces, model.weights)]
        self._digits: dict[int, ClosedHand | None] = {}
        self._own: dict[int, np.ndarray] = {}

    def digit(self, k: int) -> ClosedHand | None:
        """The capped surface of digit k (None when its faces do not bound a simple tube)."""
        if k not in self._digits:
            try:
                self._digits[k] = ClosedHand(self.model.faces[self.face_digit == k])
            except ValueError:      # a pinched boundary: measure against the whole hand instead
                self._digits[k] = None
        return self._digits[k]

    def own_vertices(self, k: int) -> np.ndarray:
        """(V,) bool: the vertices of digit k's faces (every vertex for k = -1, the whole hand)."""
        if k not in self._own:
            own = np.zeros(self.model.num_vertices, bool)
            if k < 0 or self.digit(k) is None:
                own[:] = True
            else:
                own[self.model.faces[self.face_digit == k].ravel()] = True
            self._own[k] = own
        return self._own[k]


def hand_inside_rigid(solid: Solid, local: np.ndarray, own: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(fit, depth) (B,): the deepest hand vertex inside a rigid accessory per pose, among the vertices of the part
    it is fitted to (`own` (V,) bool) and among all. local (B, V, 3): the posed hand in the accessory's frame."""
    B, V = local.shape[:2]
    local = local.reshape(-1, 3)
    fit, depth = np.zeros(B), np.zeros(B)
    inside = solid.inside(local)
    pose, vid = np.divmod(inside, V)
    for p in np.unique(pose):
        here = pose == p
        depth[p] = solid.deepest(local[inside[here]])
        mine = here & own[vid]
        fit[p] = depth[p] if mine.sum() == here.sum() else solid.deepest(local[inside[mine]])
    return fit, depth


def rigid_inside_hand(hand: HandParts, rigid: list, placed: dict, vertices: np.ndarray, p: int) -> dict:
    """{id: (fit, depth)} of the rigid accessories with vertices inside the posed hand (vertices (V, 3)): depth is
    the deepest of all their vertices below the whole hand's surface, fit that of their inward-facing vertices
    inside the part they are fitted to, measured to that part's surface."""
    pts = np.concatenate([apply(placed[i.id][p], i.vertices) for i in rigid])
    owner = np.repeat(np.arange(len(rigid)), [len(i.vertices) for i in rigid])
    inward = np.concatenate([i.inward for i in rigid])
    whole = hand.whole.solid(vertices)
    inside = whole.inside(pts)
    out, digits = {}, {}
    for k in np.unique(owner[inside]):
        item = rigid[k]
        ids = inside[owner[inside] == k]
        depth = whole.deepest(pts[ids])
        mine = pts[ids[inward[ids]]]
        part = hand.digit(item.part) if item.part >= 0 else None
        if part is None:
            fit = whole.deepest(mine)
        else:
            if item.part not in digits:
                digits[item.part] = part.solid(vertices)
            own = digits[item.part]
            fit = own.deepest(mine[own.inside(mine)])
        out[item.id] = (float(fit), float(depth))
    return out


class _BoneAxes:
    """The bone axes rigid accessories are measured against: a finger joint and its child (rings), the forearm
    axis through the wrist joint (wrist items)."""

    def __init__(self, model: HandModel):
        self.joints = rest_joints(model)
        self.ends = bone_ends(model, self.joints)
        self.j0, self.fore = wrist_axis(model)

    def distance(self, joint: int, centre: np.ndarray, posed=None, p: int = 0) -> float:
        if joint == WRIST_JOINT:
            a = self.j0 if posed is None else posed.joints[p, WRIST_JOINT]
            d = self.fore if posed is None else posed.transforms[p, WRIST_JOINT, :3, :3] @ self.fore
            return float(axis_distance(centre, a, a + d))
        if posed is None:
            return float(axis_distance(centre, self.joints[joint], self.ends[joint]))
        child = int(np.where(MANO_PARENTS == joint)[0][0])
        return float(axis_distance(centre, posed.joints[p, joint], posed.joints[p, child]))

    def drift(self, item: RigidProbe, placed: np.ndarray, posed) -> float:
        """Largest change over the posed batch of the accessory centre's distance to its bone axis."""
        rest = self.distance(item.joint, item.rest[:3, 3])
        return max(abs(self.distance(item.joint, placed[p, :3, 3], posed, p) - rest) for p in range(len(placed)))


def _gloves_at(model: HandModel, gloves: list, worn: dict, hand: np.ndarray, p: int, near, out: dict,
               index: int) -> None:
    """Glove figures at pose p of the batch (worn: each glove's posed vertices (B, G, 3), hand: the posed hand
    (V, 3)): the covered hand vertices cast along their posed normals."""
    normals = vertex_normals(hand, model.faces)
    for g in gloves:
        def local(r, t, g=g):
            if len(r) == 0:
                return np.zeros(0, bool)
            return np.asarray(near[g.hand_ids[r], g.face_source[t]]).ravel() > 0

        into, through = glove_penetration(worn[g.id][p], g.faces, g.inner_faces, hand[g.hand_ids],
                                          normals[g.hand_ids], local=local)
        out[g.id]["depth"][index], out[g.id]["through"][index] = into, through
