"""Hand shapes of a dataset: the betas each frame renders, drawn from a distribution over the model's shape space.

DART renders one hand shape (DARTset's betas are all zero). The open hand's shape space is built so that
beta ~ N(0, I) covers the adult range of hand length and breadth (template/shape_space.py, checked against ANSUR II),
so the default here is that distribution, truncated at |beta_i| <= 3 (the extreme shapes `make shapes` checks
through every gesture), each frame its own hand:

    normal    beta_i ~ N(0, sigma^2) truncated to [-limit, limit] (default sigma 1, limit 3)
    uniform   beta_i ~ U(-limit, limit)
    none      the model's own shape (betas 0: DART's behaviour; the only mode for a USD package, whose shape is
              baked)

`dims` restricts the draw to the first n directions (the rest 0). Frame i's betas come from numpy's Generator
seeded with [seed, SHAPE_STREAM, i] (n uniforms through the inverse CDF, so the truncation costs no rejection and
never shifts other draws).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from darthand.errors import InputError

SHAPE_STREAM = 5
MODES = ("normal", "uniform", "none")


@dataclass
class ShapeOptions:
    """Betas per frame: mode 'normal' (N(0, sigma^2) truncated at +-limit), 'uniform' in +-limit or 'none' (the
    model's own shape); dims: only the first N directions drawn (None: all)."""

    mode: str = "normal"
    sigma: float = 1.0
    limit: float = 3.0
    dims: int | None = None


DEFAULTS = asdict(ShapeOptions())


class ShapeSampler:
    """Betas per frame for a model with `num_betas` shape directions (0: always none)."""

    def __init__(self, opts: dict | None, num_betas: int):
        opts = {**DEFAULTS, **{k: v for k, v in (opts or {}).items() if v is not None}}
        unknown = set(opts) - set(DEFAULTS)
        if unknown:
            raise InputError(f"shapes: unknown option {sorted(unknown)[0]!r} (known: {', '.join(DEFAULTS)})")
        self.mode = opts["mode"]
        if self.mode not in MODES:
            raise InputError(f"shape distribution: {self.mode!r} is not {', '.join(MODES)}")
        self.sigma, self.limit = _positive(opts["sigma"], "shape sigma"), _positive(opts["limit"], "shape limit")
        dims = num_betas if opts["dims"] is None else opts["dims"]
        if isinstance(dims, bool) or not isinstance(dims, int) or not 0 <= dims <= num_betas:
            raise InputError(f"shape dims: {opts['dims']!r} must be an integer within 0..{num_betas} (the model's "
                             "shape directions)")
        self.dims = 0 if self.mode == "none" else dims
        self.num_betas = num_betas

    @property
    def active(self) -> bool:
        return self.dims > 0

    def spec(self) -> dict:
        return {"mode": self.mode, "sigma": self.sigma, "limit": self.limit, "dims": self.dims}

    def sample(self, seed: int, index: int) -> list[float] | None:
        """Frame `index`'s betas (num_betas,), rounded to 1e-4, or None when shapes are not sampled."""
        if not self.active:
            return None
        u = np.random.default_rng([seed, SHAPE_STREAM, int(index)]).random(self.dims)
        if self.mode == "uniform":
            b = self.limit * (2 * u - 1)
        else:
            edge = ndtr(-self.limit / self.sigma)
            b = self.sigma * ndtri(edge + u * (1 - 2 * edge))
        out = np.zeros(self.num_betas)
        out[:self.dims] = np.clip(b, -self.limit, self.limit)
        return np.round(out, 4).tolist()


def _positive(value, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: {value!r} is not a number") from None
    if not (math.isfinite(x) and x > 0):
        raise InputError(f"{what}: {value!r} must be a positive number")
    return x
