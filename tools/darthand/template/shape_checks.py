"""Checks and figures of a model's shape space (the open hand's, or a MANO file's own ten betas).

    extreme shapes      every shape direction at -+ `magnitude` (3 SD) alone: the rest surface must not fold (no
                        face turned more than 90 degrees from the template's), every regressed joint must stay
                        inside the shaped surface and at least MIN_DEPTH_RATIO as deep under the skin as on the
                        template (the skeleton follows the surface), and every named gesture must pass the gesture
                        checks (`gesture_checks`: finite, no inverted faces, no digits through each other)
    hand sizes          hand length and breadth (`anthropometry`) of shapes drawn beta ~ N(0, I), against ANSUR II
    figures             shapes.png (contact sheet of the extremes, one scale for all), hand_sizes.png (the size
                        distributions over the survey's), shape_variance.png (explained variance, when the model
                        records it)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.fileio import write_json
from darthand.model.hand_model import HandModel
from darthand.model.preview import BACKGROUND, contact_sheet, render_mesh, write_png
from darthand.model.topology import boundary_loops
from darthand.template import anthropometry, charts
from darthand.template.decimate import closest_surface_points
from darthand.template.gesture_checks import face_normals, gesture_problems, gesture_report

MIN_DEPTH_RATIO = 0.5
GESTURE_FIGURES = ("finite", "inverted_faces", "degenerate_faces", "between_fingers_faces", "finger_palm_faces")
SHEET_VIEWS = ("dorsal", "radial")


def extreme_shapes(model: HandModel, magnitude: float = 3.0) -> list[tuple[str, np.ndarray]]:
    """[(label, betas (S,))]: the template, then each direction at -magnitude and +magnitude."""
    S = model.num_betas
    shapes = [("mean", np.zeros(S))]
    for i in range(S):
        for sign in (-1.0, 1.0):
            betas = np.zeros(S)
            betas[i] = sign * magnitude
            shapes.append((f"beta{i + 1}={sign * magnitude:+g}", betas))
    return shapes


def folded_faces(model: HandModel, vertices: np.ndarray) -> np.ndarray:
    """(F,) bool faces of rest vertices (V, 3) whose normal turned more than 90 degrees from the template's."""
    return np.einsum("fc,fc->f", face_normals(vertices, model.faces), face_normals(model.v_template, model.faces)) < 0


def joint_depths(model: HandModel, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Regressed joints of rest vertices (V, 3): their distance to the surface (16,) m and whether each lies inside
    it (16,) bool (winding number of the surface closed by a fan over each boundary loop)."""
    joints = model.J_regressor @ vertices
    _, _, depth = closest_surface_points(vertices, model.faces, joints)
    closed_v, closed_f = _closed(vertices, model.faces)
    return depth, winding_numbers(closed_v, closed_f, joints) > 0.5


def winding_numbers(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) generalised winding numbers of points (P, 3) for a closed triangle mesh (Van Oosterom-Strackee solid
    angles): 1 inside, 0 outside."""
    a, b, c = (vertices[faces[:, k]][None] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    num = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la
           + np.einsum("pfi,pfi->pf", c, a) * lb)
    return 2 * np.arctan2(num, den).sum(1) / (4 * np.pi)


def _closed(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with each boundary loop closed by a fan around its centroid (the loop's edges reversed)."""
    vs, fs = [vertices], [faces]
    for loop in boundary_loops(faces):
        centre = len(vertices) + len(vs) - 1
        vs.append(vertices[loop].mean(0, keepdims=True))
        fs.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), centre)], axis=1))
    return np.concatenate(vs), np.concatenate(fs)


def check_shape(model: HandModel, template_depth: np.ndarray, betas: np.ndarray,
                max_between_fingers: int = 10) -> dict:
    """Rest-surface, joint and gesture checks of one shape; `template_depth` (16,) the template's joint depths."""
    shaped = model.shaped(betas)
    v = shaped.v_template
    depth, inside = joint_depths(model, v)
    gestures = gesture_report(shaped)
    summary = {name: {k: g.get(k) for k in GESTURE_FIGURES} for name, g in gestures.items()}
    sizes = anthropometry.hand_sizes(model, v[None])
    return {
        "betas": [float(b) for b in betas],
        "hand_length_mm": round(float(sizes["hand_length_mm"][0]), 2),
        "hand_breadth_mm": round(float(sizes["hand_breadth_mm"][0]), 2),
        "folded_faces": int(folded_faces(model, v).sum()),
        "joints_outside": [int(j) for j in np.flatnonzero(~inside)],
        "min_joint_depth_ratio": round(float((depth / template_depth).min()), 4),
        "gestures": summary,
        "gesture_problems": gesture_problems(gestures, max_between_fingers),
    }


def shape_problems(report: dict) -> list[str]:
    """One line per failed check of a `shape_checks` report."""
    problems = []
    for label, r in report["shapes"].items():
        if r["folded_faces"]:
            problems.append(f"shape {label}: {r['folded_faces']} faces folded over at rest")
        if r["joints_outside"]:
            problems.append(f"shape {label}: joints {r['joints_outside']} lie outside the surface")
        if r["min_joint_depth_ratio"] < MIN_DEPTH_RATIO:
            problems.append(f"shape {label}: a joint lies only {r['min_joint_depth_ratio']:.2f} times as deep under "
                            f"the skin as on the template (at least {MIN_DEPTH_RATIO} expected)")
        problems += [f"shape {label}: {p}" for p in r["gesture_problems"]]
    return problems


def hand_size_sample(model: HandModel, n: int = 2000, seed: int = 0) -> dict:
    """Hand length and breadth (mm, (n,) each) of n shapes drawn beta ~ N(0, I) (Generator `seed`)."""
    betas = np.random.default_rng(seed).standard_normal((n, model.num_betas))
    vertices = model.v_template + np.einsum("vcs,ns->nvc", model.shapedirs, betas)
    return anthropometry.hand_sizes(model, vertices)


def size_summary(sizes: dict, survey: dict = anthropometry.ANSUR_II) -> dict:
    """Mean, SD and 1st/50th/99th percentiles of each measure, beside the survey's 50/50 mixture of the sexes."""
    out = {}
    for measure, values in sizes.items():
        mean, sd = anthropometry.survey_mixture(measure, survey=survey)
        p1, p50, p99 = np.percentile(values, [1, 50, 99])
        out[measure] = {"shapes": {"mean": round(float(values.mean()), 2), "sd": round(float(values.std()), 2),
                                   "p1": round(float(p1), 2), "p50": round(float(p50), 2),
                                   "p99": round(float(p99), 2)},
                        "survey_mixture": {"mean": round(mean, 2), "sd": round(sd, 2)},
                        "survey": {k: list(v) for k, v in survey[measure].items()}}
    return out


def shape_checks(model: HandModel, magnitude: float = 3.0, max_between_fingers: int = 10, samples: int = 2000,
                 seed: int = 0) -> dict:
    """The report written to shapes.json: per extreme shape its checks, the sampled hand sizes' summary, and the
    shape space's own figures when the model records them (the open hand's `meta['shape_space']`)."""
    template_depth, _ = joint_depths(model, model.v_template)
    shapes = {label: check_shape(model, template_depth, betas, max_between_fingers)
              for label, betas in extreme_shapes(model, magnitude)}
    return {"model": model.meta.get("source"), "shape_dims": model.num_betas, "magnitude": magnitude,
            "shapes": shapes, "hand_sizes": size_summary(hand_size_sample(model, samples, seed)),
            "template_joint_depth_mm": [round(1000 * float(d), 3) for d in template_depth],
            "shape_space": model.meta.get("shape_space")}


def write_shape_checks(model: HandModel, out_dir: str | Path, magnitude: float = 3.0,
                       max_between_fingers: int = 10) -> dict:
    """shapes.json, shapes.png, hand_sizes.png (and shape_variance.png) into `out_dir`; return the report."""
    out_dir = Path(out_dir)
    report = shape_checks(model, magnitude, max_between_fingers)
    report["problems"] = shape_problems(report)
    write_json(out_dir / "shapes.json", report)
    write_shape_sheet(model, extreme_shapes(model, magnitude), out_dir / "shapes.png")
    write_size_chart(hand_size_sample(model), out_dir / "hand_sizes.png")
    explained = (report["shape_space"] or {}).get("explained_variance")
    if explained:
        write_variance_chart(explained, model.num_betas, out_dir / "shape_variance.png")
    return report


def write_shape_sheet(model: HandModel, shapes: list[tuple[str, np.ndarray]], out_png: str | Path,
                      size: int = 220) -> None:
    """Contact sheet of `extreme_shapes` at rest, every tile at the same scale (so sizes compare): the mean shape
    first, then one row per direction, -magnitude and +magnitude from each of SHEET_VIEWS."""
    surfaces = {label: model.shaped(b).v_template for label, b in shapes}
    everything = np.concatenate(list(surfaces.values()))            # one framing for all tiles
    blank = np.tile(np.asarray(BACKGROUND, np.float32), (size, size, 1))
    images, labels = [], []
    rows = [[shapes[0][0]]] + [[shapes[k][0], shapes[k + 1][0]] for k in range(1, len(shapes), 2)]
    for row in rows:
        for view in SHEET_VIEWS:
            for label in row:
                images.append(render_mesh(surfaces[label], model.faces, view=view, size=size, side=model.side,
                                          frame=everything))
                labels.append(f"{label} {view}")
        while len(images) % (2 * len(SHEET_VIEWS)):
            images.append(blank)
            labels.append("")
    write_png(out_png, contact_sheet(images, labels, cols=2 * len(SHEET_VIEWS)))


def write_size_chart(sizes: dict, out_png: str | Path, survey: dict = anthropometry.ANSUR_II) -> None:
    """Histograms of sampled hand length and breadth (density) with the survey's normal curves for women, men and
    their 50/50 mixture."""
    buf = charts.canvas(1200, 480)
    panels = (("hand_length_mm", "hand length (mm)", (140.0, 235.0), 10.0),
              ("hand_breadth_mm", "hand breadth (mm)", (60.0, 110.0), 5.0))
    for k, (measure, label, (lo, hi), step) in enumerate(panels):
        values = sizes[measure]
        edges = np.linspace(lo, hi, 39)
        density, _ = np.histogram(values, bins=edges, density=True)
        x = np.linspace(lo, hi, 300)
        curves = {sex: charts.normal_pdf(x, *survey[measure][sex]) for sex in ("female", "male")}
        pooled = 0.5 * (curves["female"] + curves["male"])
        top = 1.15 * max(density.max(), max(c.max() for c in curves.values()))
        left = 80 + k * 600
        panel = charts.Panel(buf, (left, 60, left + 480, 400), (lo, hi), (0.0, top))
        panel.frame(f"{label}: {len(values)} shapes, beta ~ N(0, I) (probability density)", label, "",
                    charts.ticks(lo, hi, step), charts.ticks(0, top, _nice(top / 4)), fmt="{:g}")
        panel.bars(edges, density, charts.COLORS["samples"])
        for sex, color in (("female", "female"), ("male", "male")):
            panel.curve(x, 0.5 * curves[sex], charts.COLORS[color])
        panel.curve(x, pooled, charts.COLORS["pooled"])
        panel.legend([("shape space", charts.COLORS["samples"]), ("ANSUR II women (x 1/2)", charts.COLORS["female"]),
                      ("ANSUR II men (x 1/2)", charts.COLORS["male"]), ("ANSUR II 50/50 mix", charts.COLORS["pooled"])])
    write_png(out_png, charts.pixels(buf))


def write_variance_chart(explained: list[float], components: int, out_png: str | Path) -> None:
    """Cumulative explained variance of the first shape directions (bars), those kept marked."""
    n = len(explained)
    buf = charts.canvas(900, 420)
    lo = float(np.floor(100 * explained[0] / 5) * 5)
    panel = charts.Panel(buf, (80, 60, 860, 360), (0.5, n + 0.5), (lo, 100.0))
    panel.frame(f"cumulative explained variance (%) of the population's hand shapes ({components} kept)",
                "shape directions", "", np.arange(1, n + 1), charts.ticks(lo, 100, 2.5), fmt="{:g}")
    for i, value in enumerate(explained):
        color = charts.COLORS["bar"] if i < components else charts.GRID
        panel.bars(np.array([i + 0.6, i + 1.4]), np.array([100 * value]), color)
    write_png(out_png, charts.pixels(buf))


def _nice(step: float) -> float:
    """A round tick step near `step`."""
    exponent = 10.0 ** np.floor(np.log10(step))
    return float(min((1, 2, 5, 10), key=lambda m: abs(m * exponent - step)) * exponent)
