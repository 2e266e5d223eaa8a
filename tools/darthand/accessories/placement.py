"""Where on its finger a ring sits, and how much room its bore leaves, so that it stays clear of the skin in every
pose of the joint limits.

A rigid ring follows its bone exactly, but the skin under it does not: linear blend skinning moves skin near a joint
with a blend of the joints around it (the palm's at the finger's base, the middle phalanx's near the PIP joint,
sometimes a neighbouring finger's), so flexing a joint to its limit pushes skin through a ring fitted to the rest
pose. How far depends on where the ring sits: near the knuckle the palm's share moves it, near the PIP joint its
crease does. The hand rig stays as its source made it (a MANO file's weights are MANO's); the ring adapts:

1. candidate positions along the proximal phalanx (`POSITIONS`, fractions from the joint to the next, the usual
   place first; an item that names `t` in the catalogue keeps it) are each fitted at rest as before (smallest
   circle around the section, plus the catalogue clearance);
2. each candidate is measured against its digit over training poses -- the rest pose, the named gestures and
   `TRAINING_POSES` anatomical samples (self-crossing ones included), drawn from their own random stream, so the
   verification sweep afterwards sees poses the placement never saw. The usual place is tried first; the other
   positions only for the rings it does not suit (the sweeps are what costs);
3. per ring, the candidate needing the least extra room wins: its clearance grows by how far its worst training
   pose exceeds `TARGET` (for skin pressing on the bore, penetration falls one for one with its radius), at most
   `MAX_GROWTH`; what growth cannot fix -- the next phalanx folding onto a ring near the PIP joint, the palm onto
   one near the knuckle -- counts four times over; ties go to the position listed first.

Everything is a function of the measured hand and the catalogue seed, so fitting another hand (another shape)
places its rings for that hand.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from darthand.accessories.item import generate
from darthand.accessories.sweep import measure, sweep_poses
from darthand.model.hand_model import HandModel

POSITIONS = (0.5, 0.45, 0.575, 0.4, 0.65)   # in order of preference
TRAINING_POSES = 48
TARGET = 0.0004          # m: the fit penetration the placement aims for over its training poses
MAX_GROWTH = 0.0015      # m: the most a bore grows beyond the catalogue's clearance
TIE = 0.00005            # m: costs closer than this are equal (the position listed first wins)


@dataclass(frozen=True)
class Placement:
    """The chosen position `t` along the proximal phalanx, the clearance (m) the bore is fitted with, and the
    training figures behind the choice: per candidate position, the worst fit penetration (m) at the catalogue's
    clearance."""

    t: float
    clearance: float
    worst_by_position: dict


def positions(entry: dict) -> tuple[float, ...]:
    """The candidate positions of a ring entry: its own `t` when the catalogue names one, else `POSITIONS`."""
    return (float(entry["t"]),) if "t" in entry else POSITIONS


def place_rings(model: HandModel, entries: list[dict], seed: int, workers: int = 1,
                n_poses: int = TRAINING_POSES, gestures: list[str] | None = None) -> dict[str, Placement]:
    """Placement of every ring entry (expanded catalogue entries, metres) on `model`, trained on the rest pose,
    the named `gestures` (default all) and `n_poses` sampled poses; {} when there are none."""
    rings = [e for e in entries if e["type"] == "ring"]
    if not rings:
        return {}
    # Training keeps the samples where the hand crosses itself (the verification sweep leaves them out): a digit's
    # own skin folds the same there, and the extra extremes make a safer bore.
    _, poses = sweep_poses(model, seed, n_poses, gestures, stream="ring-placement", skip_crossing=False)
    worst = _worst_fit(model, [(e, positions(e)[0]) for e in rings], seed, poses, workers)
    unsuited = [e for e in rings if worst[e["id"]][positions(e)[0]] > TARGET]
    more = _worst_fit(model, [(e, t) for e in unsuited for t in positions(e)[1:]], seed, poses, workers)
    for ring_id, by_t in more.items():
        worst[ring_id].update(by_t)
    return {e["id"]: choose(worst[e["id"]], float(e["clearance"]), positions(e)) for e in rings}


def _worst_fit(model: HandModel, candidates: list[tuple[dict, float]], seed: int, poses: np.ndarray,
               workers: int) -> dict[str, dict[float, float]]:
    """{ring id: {position: worst fit penetration (m) over `poses`}} of (entry, position) candidates."""
    built = []
    for e, t in candidates:
        b = generate(model, {**e, "t": t}, seed)
        built.append(replace(b, entry={**b.entry, "id": f"{e['id']}@{t}"}))     # ids unique per candidate
    fit = measure(model, built, poses, workers, worn=False) if built else {}
    out: dict[str, dict[float, float]] = {}
    for (e, t), b in zip(candidates, built):
        out.setdefault(e["id"], {})[t] = float(fit[b.id]["fit"].max())
    return out


def choose(worst: dict[float, float], clearance: float, order=POSITIONS) -> Placement:
    """The placement for one ring from its candidates' worst training penetration (m) by position."""
    growth = {t: min(max(w - TARGET, 0.0), MAX_GROWTH) for t, w in worst.items()}
    # Beyond the growth cap a candidate keeps some penetration: rank it by what is left over as well.
    cost = {t: growth[t] + 4.0 * max(worst[t] - TARGET - growth[t], 0.0) for t in worst}
    best = min(cost.values())
    t = next(t for t in order if t in cost and cost[t] <= best + TIE)
    return Placement(t, clearance + growth[t], dict(sorted(worst.items())))
