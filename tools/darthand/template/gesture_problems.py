"""What a gesture report (template/gesture_checks) says is wrong, one line per failed check, each naming what to
change. Plain dicts in, strings out, and no imports of the model's numerics: `darthand manifest --check` reads the
gesture report recorded in the manifest on every `make assets`, where importing the checks themselves (MeshLab,
SciPy) would cost most of a no-op rebuild."""

from __future__ import annotations

MIRROR_FIELDS = ("finite", "inverted_faces", "between_fingers_faces", "finger_palm_faces", "between")


def gesture_problems(report: dict, max_between_fingers: int = 0) -> list[str]:
    """One line per failed check in a `gesture_report` (and its left mirror), each naming what to change:
    non-finite vertices, inverted triangles, more than `max_between_fingers` faces where two digits intersect."""
    problems = []
    for name, r in report.items():
        for side, checks in (("", r), (" (mirror)", r.get("mirror"))):
            if checks is None or (side and checks == {k: r.get(k) for k in MIRROR_FIELDS}):
                continue  # the mirror fails exactly where the model does: say it once
            at = f"gesture '{name}'{side}"
            if not checks["finite"]:
                problems.append(f"{at}: non-finite vertices")
                continue
            if checks["inverted_faces"]:
                problems.append(f"{at}: {checks['inverted_faces']} inverted triangles; {what_to_change(name, r)}")
            if checks["between_fingers_faces"] > max_between_fingers:
                pairs = ", ".join(f"{k} {n}" for k, n in checks["between"].items() if "palm" not in k)
                problems.append(f"{at}: {checks['between_fingers_faces']} faces where digits intersect ({pairs}), "
                                f"more than {max_between_fingers}; {what_to_change(name, r)}")
    return problems


def what_to_change(name: str, r: dict) -> str:
    """The remedy a failed gesture's message names: fit the gestures to the model, or change what stopped the
    fit (the angles it left at a bound, the digits that still cross) in the gesture's file."""
    fit = r.get("fit")
    if fit is None:
        return ("the gestures are not fitted to this model: build it with `darthand model build` (make assets) "
                "or change " + f"assets_src/poses/{name}.json")
    digits = sorted({p for k in r.get("between", {}) for p in k.split("-") if p != "palm"})
    bound = f", stopped at the bound of {', '.join(fit['at_bound'])}" if fit.get("at_bound") else ""
    return (f"after fitting to this model ({fit['status']}{bound}): change the {' and '.join(digits) or 'digit'} "
            f"angles or the contacts in assets_src/poses/{name}.json")
