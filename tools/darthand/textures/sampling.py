"""Drawing catalogue parameters from the ranges written in the catalogue spec.

A range is written as `[lo, hi]` (uniform), a list of names (uniform choice), `{name: weight}` (weighted
choice) or a plain value (fixed). Floats are rounded to 5 decimals so that the parameters recorded in
catalog.json are exactly the ones rendered.
"""

from __future__ import annotations

import numpy as np


def draw(rng: np.random.Generator, spec, integer: bool = False):
    """One value from a spec range (see the module docstring)."""
    if isinstance(spec, dict):
        names = sorted(spec)
        w = np.array([float(spec[n]) for n in names])
        return names[int(rng.choice(len(names), p=w / w.sum()))]
    if isinstance(spec, list) and len(spec) == 2 and all(isinstance(v, (int, float)) for v in spec):
        lo, hi = spec
        if integer:
            return int(rng.integers(int(lo), int(hi) + 1))
        return round(float(rng.uniform(lo, hi)), 5)
    if isinstance(spec, list):
        return spec[int(rng.integers(len(spec)))]
    return spec
