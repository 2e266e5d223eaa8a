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

from darthand.fileio import atomic_path, write_json
from darthand.model.gesture_fit import with_fitted_gestures
from darthand.model.hand_model import HandModel
from darthand.model.preview import BACKGROUND, HIGHLIGHT, SKIN, contact_sheet, render_mesh, write_png
from darthand.model.topology import boundary_loops
from darthand.template import anthropometry
from darthand.template.decimate import closest_surface_points
from darthand.template.gesture_checks import checked_gestures, face_normals
from darthand.template.gesture_problems import gesture_problems

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
                max_between_fingers: int = 10, posed: dict | None = None) -> dict:
    """Rest-surface, joint and gesture checks of one shape; `template_depth` (16,) the template's joint depths.

    The gestures are fitted to the shaped hand first (model/gesture_fit, as `model build` fits them to the hand it
    builds), so the checks see the gestures that hand's package would carry. posed: if given, gets the shape's
    (gesture names, posed vertices (G, V, 3), crossing faces (G, F)) for the gesture sheet."""
    shaped = with_fitted_gestures(model.shaped(betas))
    v = shaped.v_template
    depth, inside = joint_depths(model, v)
    names, vertices, crossing, gestures = checked_gestures(shaped)
    if posed is not None:
        posed.update(names=names, vertices=vertices, crossing=crossing)
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
                 seed: int = 0, posed: dict | None = None) -> dict:
    """The report written to shapes.json: per extreme shape its checks, the sampled hand sizes' summary, and the
    shape space's own figures when the model records them (the open hand's `meta['shape_space']`). posed: if
    given, gets {shape label: its posed gestures} (`check_shape`)."""
    template_depth, _ = joint_depths(model, model.v_template)
    shapes = {label: check_shape(model, template_depth, betas, max_between_fingers, posed.setdefault(label, {})
                                 if posed is not None else None)
              for label, betas in extreme_shapes(model, magnitude)}
    return {"model": model.meta.get("source"), "shape_dims": model.num_betas, "magnitude": magnitude,
            "shapes": shapes, "hand_sizes": size_summary(hand_size_sample(model, samples, seed)),
            "template_joint_depth_mm": [round(1000 * float(d), 3) for d in template_depth],
            "shape_space": model.meta.get("shape_space")}


def write_shape_checks(model: HandModel, out_dir: str | Path, magnitude: float = 3.0,
                       max_between_fingers: int = 10) -> dict:
    """shapes.json, shapes.png, hand_sizes.png (and shape_variance.png) into `out_dir`; return the report."""
    out_dir = Path(out_dir)
    posed: dict = {}
    report = shape_checks(model, magnitude, max_between_fingers, posed=posed)
    report["problems"] = shape_problems(report)
    write_json(out_dir / "shapes.json", report)
    write_shape_sheet(model, extreme_shapes(model, magnitude), out_dir / "shapes.png")
    write_gesture_sheet(model, posed, out_dir / "shape_gestures.png")
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


SHEET_GESTURES = ("fist", "grasp", "ok", "pinch")   # the gestures whose digits meet (where shape shows first)


def write_gesture_sheet(model: HandModel, posed: dict, out_png: str | Path, gestures=SHEET_GESTURES,
                        size: int = 180) -> None:
    """Contact sheet: one row per extreme shape, its fitted `gestures` (three-quarter view), faces that pass
    through another part of the hand in red."""
    images, labels = [], []
    for label, p in posed.items():
        for name in gestures:
            if name not in p["names"]:
                continue
            g = p["names"].index(name)
            colours = np.tile(np.asarray(SKIN, np.float32), (len(model.faces), 1))
            colours[p["crossing"][g]] = HIGHLIGHT
            images.append(render_mesh(p["vertices"][g], model.faces, view="three_quarter", size=size,
                                      face_colors=colours, side=model.side))
            labels.append(f"{label} {name} ({int(p['crossing'][g].sum())})")
    if images:
        write_png(out_png, contact_sheet(images, labels, cols=len(gestures)))


SAMPLES_COLOUR = "#8c9ec0"
SEX_COLOURS = {"female": "#cc1a1a", "male": "#0d40bf"}


def write_size_chart(sizes: dict, out_png: str | Path, survey: dict = anthropometry.ANSUR_II) -> None:
    """Histograms of sampled hand length and breadth (density) with the survey's normal curves for women and men
    (each weighted 1/2) and their 50/50 mixture."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), dpi=100)
    panels = (("hand_length_mm", "hand length (mm)", (140.0, 235.0)),
              ("hand_breadth_mm", "hand breadth (mm)", (60.0, 110.0)))
    for ax, (measure, label, (lo, hi)) in zip(axes, panels):
        values = sizes[measure]
        ax.hist(values, bins=np.linspace(lo, hi, 39), density=True, color=SAMPLES_COLOUR,
                label=f"shape space, {len(values)} shapes, beta ~ N(0, I)")
        x = np.linspace(lo, hi, 400)
        curves = {sex: _normal_pdf(x, *survey[measure][sex]) for sex in ("female", "male")}
        for sex, colour in SEX_COLOURS.items():
            who = "women" if sex == "female" else "men"
            ax.plot(x, 0.5 * curves[sex], color=colour, lw=1.8, label=f"ANSUR II {who} (x 1/2)")
        ax.plot(x, 0.5 * (curves["female"] + curves["male"]), color="black", lw=1.8, label="ANSUR II, 50/50 mix")
        ax.set_xlabel(label)
        ax.set_ylabel("probability density")
        ax.set_xlim(lo, hi)
        ax.set_ylim(0, 1.4 * ax.get_ylim()[1])          # room for the legend above the histogram
        ax.legend(fontsize=8, loc="upper left")
        ax.grid(alpha=0.3)
    fig.suptitle(f"hand sizes of the shape space against {survey['source']}", fontsize=10)
    _save(fig, out_png)


def write_variance_chart(explained: list[float], components: int, out_png: str | Path) -> None:
    """Cumulative explained variance of the first shape directions (bars), those kept in colour."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 4.2), dpi=100)
    k = np.arange(1, len(explained) + 1)
    values = 100 * np.asarray(explained)
    ax.bar(k, values, color=[SAMPLES_COLOUR if i <= components else "#dddddd" for i in k])
    for i, v in zip(k[:components], values[:components]):
        ax.annotate(f"{v:.2f}", (i, v), ha="center", va="bottom", fontsize=7)
    ax.set_ylim(np.floor(values[0] / 5) * 5, 100.5)
    ax.set_xticks(k)
    ax.set_xlabel("shape directions")
    ax.set_ylabel("cumulative explained variance (%)")
    ax.set_title(f"the population's hand shapes ({components} directions kept)")
    ax.grid(axis="y", alpha=0.3)
    _save(fig, out_png)


def _normal_pdf(x: np.ndarray, mean: float, sd: float) -> np.ndarray:
    return np.exp(-0.5 * ((x - mean) / sd) ** 2) / (sd * np.sqrt(2 * np.pi))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, out_png: str | Path) -> None:
    """Save a matplotlib figure as PNG atomically, and close it."""
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    _pyplot().close(fig)
