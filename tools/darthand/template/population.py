"""The adult population the open hand's shape space is learnt from: MakeHuman parameters drawn per person.

MakeHuman's sliders are an artist's controls, not measured statistics: at their extremes they make giants and
dwarfs, its female -> male slider alone lengthens the hand by 21 % where adult men's hands are 7 % longer than
women's, and it widens men's hands no more than it lengthens them, where men's are 13 % broader. So the population
keeps MakeHuman's directions of variation and sets their amounts from hand anthropometry:

    sex                 half women, half men; MakeHuman's gender = 0.5 -+ `sex_offset`
    age                 uniform over AGE_YEARS (MakeHuman's young -> old span; below 25 its age slider blends in
                        its 10-year-old child, whose hands are a child's)
    muscle, weight,     0.5 + `spread` * N(0, 1) / 6, clipped to [0, 1]: at spread 1 the slider's ends are 3 SD
    height, proportions
    local controls      `spread` * N(0, 1) / 3, clipped to [-1, 1] (hand scale, finger length and diameter, finger
                        spacing, hand in/out, wrist circumference, forearm length, girth and shape:
                        `targets.LOCAL_CONTROLS`); the breadth controls (finger diameter and spacing) are shifted by
                        -+ `breadth_offset` for women and men
    race                MakeHuman's default mix (1/3 each), not varied

The three numbers (`Calibration`) are solved so that the population's hand length matches ANSUR II's difference
between men's and women's means and its SD within a sex, and its hand breadth the difference of means
(`shape_space.calibrate`); the breadth's SD within a sex is left as the check. (Fitting it too needs the breadth
controls at three times the general spread, which puts MakeHuman's finger-diameter target at its ends, where its
combinations fold small faces between the fingers.) Every draw comes from numpy Generators seeded from
(seed, stream), so the population is the same on every machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.template import targets

AGE_YEARS = (25.0, 65.0)
MACRO_SLIDERS = ("muscle", "weight", "height", "proportions")
MACRO_SD = 1.0 / 6.0
LOCAL_SD = 1.0 / 3.0
BREADTH_CONTROLS = ("finger_diameter", "finger_spacing")


@dataclass(frozen=True)
class Calibration:
    """The population's amounts of variation (see the module docstring); all dimensionless slider units."""

    sex_offset: float
    spread: float
    breadth_offset: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Draws:
    """The random part of a population of N people, independent of its calibration (common random numbers).

    male (N,) bool; years (N,) age in years; macro_z (N, 4) and local_z (N, L) standard normal scores of the
    MACRO_SLIDERS and of the local controls (targets.LOCAL_CONTROLS order).
    """

    male: np.ndarray
    years: np.ndarray
    macro_z: np.ndarray
    local_z: np.ndarray

    @property
    def size(self) -> int:
        return int(len(self.male))


def draw(n: int, seed=0) -> Draws:
    """The random scores of `n` people, each quantity from its own stream (*seed, k); seed an int or a list."""
    seed = list(np.atleast_1d(seed))
    streams = [np.random.default_rng(seed + [k]) for k in range(4)]
    return Draws(male=streams[0].random(n) < 0.5,
                 years=streams[1].uniform(*AGE_YEARS, n),
                 macro_z=streams[2].standard_normal((n, len(MACRO_SLIDERS))),
                 local_z=streams[3].standard_normal((n, len(targets.LOCAL_CONTROLS))))


def years_to_age(years) -> np.ndarray:
    """MakeHuman's age slider for ages in years (apps/human.py: 1 -> 0, 25 -> 0.5, 90 -> 1, linear between)."""
    y = np.asarray(years, dtype=np.float64)
    return np.where(y < 25.0, (y - 1.0) / 48.0, 0.5 + (y - 25.0) / 130.0)


def parameters(d: Draws, c: Calibration) -> tuple[dict, dict]:
    """MakeHuman macro parameters {variable: (N,)} and local controls {control: (N,)} of the population."""
    sign = np.where(d.male, 1.0, -1.0)
    macro = {"gender": 0.5 + sign * c.sex_offset, "age": years_to_age(d.years)}
    for k, name in enumerate(MACRO_SLIDERS):
        macro[name] = np.clip(0.5 + c.spread * MACRO_SD * d.macro_z[:, k], 0.0, 1.0)
    local = {}
    for k, name in enumerate(targets.LOCAL_CONTROLS):
        shift = sign * c.breadth_offset if name in BREADTH_CONTROLS else 0.0
        local[name] = np.clip(shift + c.spread * LOCAL_SD * d.local_z[:, k], -1.0, 1.0)
    return macro, local


def target_weights(d: Draws, c: Calibration, names: list[str]) -> np.ndarray:
    """(N, len(names)) weight of each MakeHuman target for every person."""
    macro, local = parameters(d, c)
    return targets.macro_weights(macro, names) + targets.local_weights(local, names)
