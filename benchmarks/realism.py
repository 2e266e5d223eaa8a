"""Realism: how often a hand landmarker trained on real photographs finds darthand's hands, per render setting
(issue 28, "How it is measured").

The detector: MediaPipe Hands 0.10.14 (`make detector`: its own venv, .venv-detector; benchmarks/_realism_detect.py
says how it is run: static images, the full landmark model, one hand). Without it this benchmark reports itself
skipped, with the reason.

The frames: one fixed plan, `darthand render-dataset build/model/right.npz --seed 11 --count N` (N =
DARTHAND_REALISM_FRAMES, default 500; both hands, as a new user's run), rendered once per SETTING below with that
setting's options added. Figures per setting, over the frames whose labels have at least MIN_VISIBLE of their 21
keypoints visible, for the frames without an accessory ('bare', the headline), with one ('accessory') and both:

- detection_rate: share of frames where MediaPipe finds a hand (with its 95 % Wilson interval);
- pck_0.1, pck_0.2: over the frames where it finds one, the share of its 21 landmarks within 0.1 / 0.2 of the hand's
  size of the labels' keypoint of the same name (all 21; pck_visible_*: the labels' visible keypoints only). The
  hand's size: the diagonal of the bounding box of the labels' 21 2D keypoints, in pixels. MediaPipe's landmark
  order (wrist; thumb CMC, MCP, IP, tip; index MCP, PIP, DIP, tip; middle; ring; pinky) is the labels' 'openpose'
  order (wrist, then each finger root to tip, thumb to pinky); `order_check` verifies it on the run's detections;
- handedness: share of those frames whose MediaPipe handedness, turned (it assumes a mirrored selfie image: its
  'Left' is a right hand), is the frame's side;
- washed_out: whether skin washes out (issue 28: "the tone a frame's labels record is the tone its image shows"):
  of the bare counted frames, how many have over 5 % and over 20 % of their hand's inner pixels (the mask's full
  pixels eroded by one: an edge pixel mixes in the backdrop) at 255 in some channel, and the mean share;
- tone_agreement: the rank correlation (Spearman) across the bare counted frames between the skin tone a frame's
  labels record (texture.tone_srgb's luminance) and its image's (the inner hand pixels' median luminance);
- cpu_s_per_frame: CPU seconds of the whole render-dataset command (its workers included, start-up too) per frame
  rendered; cpu_ms_per_image: the run's own steady-state figure (dataset.json timings).

A contact sheet (realism_sheet.png in the output folder): the same 16 frames under each setting, rows = settings,
each frame composited over black, bordered green where MediaPipe finds the hand (its landmarks drawn) and red where
it does not.

Environment: DARTHAND_REALISM_FRAMES (frame count), DARTHAND_REALISM_SETTINGS (comma-separated setting names,
default all), DARTHAND_REALISM_CONFIDENCE (MediaPipe's min_detection_confidence, default 0.5, its own; 0.3 finds
4 more of the issue's 79 frames, its 73 %), DARTHAND_REALISM_WORK (a folder to keep the rendered frames and
detections in: a second run resumes there; default a temporary folder). Or: `python -m benchmarks.realism --frames
40 --settings default --out DIR`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage, stats

from darthand.dataset.frames import frame_names
from darthand.fileio import write_json
from darthand.model.layout import KEYPOINT_ORDERS
from darthand.render.image import over_black, read_straight_png
from darthand.textures.color import luminance, srgb_to_linear

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "build" / "model" / "right.npz"
DETECTOR_PYTHON = ROOT / ".venv-detector" / "bin" / "python"
DETECT_SCRIPT = Path(__file__).resolve().with_name("_realism_detect.py")
SEED = 11
DEFAULT_FRAMES = 500
MIN_VISIBLE = 15
SHEET_FRAMES = 16
SHEET_TILE = 128
THRESHOLDS = (0.1, 0.2)
DEFAULT_CONFIDENCE = 0.5          # MediaPipe's min_detection_confidence (its own default)

# The render settings compared: name -> the render-dataset options added to the plan's (any option of the command,
# so any DatasetOptions field). A new setting is one line, e.g. "environments": ["--environments", "builtin"] or
# "cycles": ["--engine", "cycles"] (the CPU figures count the command's child processes, Blender's too). The headline
# is 'default''s (else the first row run).
BEFORE = ["--lights", "random", "--backgrounds", "builtin", "--film", "none", "--skin-specular", "single",
          "--skin-detail", "0", "--arm", "off"]          # the defaults before issue 28
SETTINGS: dict[str, list[str]] = {
    "default": [],
    "before": BEFORE,
    "gesture-poses": ["--poses", "gestures"],
    "lights-random": ["--lights", "random", "--backgrounds", "builtin"],
    "no-backdrop": ["--backgrounds", "builtin"],
    "random-film": ["--film", "random"],
    "no-arm": ["--arm", "off"],
    "dual-skin": ["--skin-specular", "dual", "--skin-detail", "1"],
    "skin-relief": ["--skin-detail", "1"],
    "subdivision": ["--subdivision", "1"],
    "no-background": ["--backgrounds", "none"],
    "cycles": ["--engine", "cycles", "--film", "none"],
}
# Rows too slow for the whole plan render the first SUBSET_FRAMES qualifying frames of the first row's plan (the
# contact sheet's 16 first), through a jobs file of those frames; their figures are compared with the first row's
# on the same frames. DARTHAND_REALISM_SUBSET changes the count.
SUBSET_ROWS = ("cycles",)
SUBSET_FRAMES = 64


# ------------------------------------------------------------------ the maths (tests/benchmarks/)

def side_of(mediapipe_label: str | None) -> str | None:
    """'right' or 'left' of MediaPipe's handedness label in an unmirrored frame: MediaPipe assumes a mirrored (selfie)
    image, so its 'Left' is a right hand."""
    return {"Left": "right", "Right": "left"}.get(str(mediapipe_label))


def hand_size(keypoints: np.ndarray) -> float:
    """The hand's size in pixels: the diagonal of the bounding box of its (21, 2) 2D keypoints."""
    span = keypoints.max(axis=0) - keypoints.min(axis=0)
    return float(np.hypot(span[0], span[1]))


def relative_errors(detected: np.ndarray, keypoints: np.ndarray) -> np.ndarray:
    """(21,) distance of each detected landmark (21, 2) from the labels' keypoint (21, 2) of the same name (both in
    the 'openpose' order, pixels), over the hand's size."""
    return np.linalg.norm(detected - keypoints, axis=1) / max(hand_size(keypoints), 1e-9)


def pck(errors: np.ndarray, threshold: float) -> float | None:
    """Share of keypoints whose relative error is within `threshold` (of the hand's size); None without any."""
    return float(np.mean(np.asarray(errors) <= threshold)) if len(errors) else None


def labels_openpose(labels: dict) -> tuple[np.ndarray, np.ndarray]:
    """((21, 2) pixels, (21,) bool visibility) of a frame's labels, in the 'openpose' order whatever order they were
    written in (render --keypoint-order mano writes MANO's)."""
    kp, vis = np.asarray(labels["keypoints_2d"], np.float64), np.asarray(labels["visibility"], bool)
    if labels.get("keypoint_order", "openpose") == "mano":
        kp, vis = kp[KEYPOINT_ORDERS["openpose"]], vis[KEYPOINT_ORDERS["openpose"]]
    return kp, vis


def frame_record(labels: dict, detection: dict) -> dict:
    """One frame's figures: its subset fields (visible count, accessory) and, where MediaPipe found a hand, its
    landmarks' relative errors and whether its handedness is the frame's side."""
    kp, vis = labels_openpose(labels)
    record = {"side": labels["side"], "visible": int(vis.sum()),
              "accessory": (labels.get("accessory") or {}).get("id", "none") not in (None, "none"),
              "found": bool(detection.get("found"))}
    if record["found"]:
        errors = relative_errors(np.asarray(detection["landmarks"], np.float64), kp)
        record.update(errors=errors, visible_errors=errors[vis], handedness_right=side_of(detection["handedness"])
                      == labels["side"])
    return record


def wilson(successes: int, n: int, z: float = 1.96) -> list:
    """95 % Wilson score interval [lo, hi] of a rate successes / n ([None, None] for n = 0)."""
    if n == 0:
        return [None, None]
    p = successes / n
    centre, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return [(centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)]


def figures(records: list[dict]) -> dict:
    """Detection rate (and interval), PCK at THRESHOLDS (all 21 and the visible keypoints, pooled over the keypoints
    of the frames where a hand was found), mean relative error, each keypoint's median relative error (the
    'openpose' order) and handedness accuracy of some frames' records;
    None where there is nothing to count (JSON has no NaN)."""
    found = [r for r in records if r["found"]]
    out = {"frames": len(records), "found": len(found),
           "detection_rate": len(found) / len(records) if records else None,
           "detection_rate_95": wilson(len(found), len(records))}
    errors = np.concatenate([r["errors"] for r in found]) if found else np.zeros(0)
    visible = np.concatenate([r["visible_errors"] for r in found]) if found else np.zeros(0)
    for t in THRESHOLDS:
        out[f"pck_{t}"] = pck(errors, t)
        out[f"pck_visible_{t}"] = pck(visible, t)
    out["mean_error"] = float(errors.mean()) if len(errors) else None
    out["median_error_per_keypoint"] = np.median([r["errors"] for r in found], axis=0).round(4).tolist() \
        if found else None
    out["handedness"] = float(np.mean([r["handedness_right"] for r in found])) if found else None
    return out


def subsets(records: list[dict]) -> dict:
    """figures() of the frames with at least MIN_VISIBLE visible keypoints: without an accessory ('bare'), with one
    ('accessory'), both ('any')."""
    seen = [r for r in records if r["visible"] >= MIN_VISIBLE]
    return {"bare": figures([r for r in seen if not r["accessory"]]),
            "accessory": figures([r for r in seen if r["accessory"]]), "any": figures(seen)}


def order_check(records: list[dict], labels_by_index: dict, detections_by_index: dict) -> dict:
    """For each of MediaPipe's 21 landmarks, the labels' keypoint nearest to it over the frames where a hand was
    found (the median relative distance: a frame whose detection is off does not decide): the identity when the two
    orders agree. {'frames', 'agrees': landmarks whose nearest keypoint is their own, 'nearest': the 21 nearest
    keypoints' indices}."""
    distances = []
    for r in records:
        if r["found"]:
            kp, _ = labels_openpose(labels_by_index[r["index"]])
            det = np.asarray(detections_by_index[r["index"]]["landmarks"], np.float64)
            distances.append(np.linalg.norm(det[:, None] - kp[None], axis=2) / max(hand_size(kp), 1e-9))
    if not distances:
        return {"frames": 0, "agrees": None, "nearest": None}
    nearest = np.median(distances, axis=0).argmin(axis=1)
    return {"frames": len(distances), "agrees": int((nearest == np.arange(21)).sum()), "nearest": nearest.tolist()}


# ------------------------------------------------------------------ rendering and detecting

def detector_problem() -> str | None:
    """Why the detector cannot run (None when it can)."""
    if not DETECTOR_PYTHON.is_file():
        return f"no hand detector environment ({DETECTOR_PYTHON}): run `make detector`"
    probe = subprocess.run([str(DETECTOR_PYTHON), "-c", "import mediapipe.python.solutions.hands"],
                           capture_output=True, text=True)
    if probe.returncode:
        return "mediapipe does not import in .venv-detector: " + (probe.stderr.strip().splitlines() or ["?"])[-1]
    return None


def render_setting(folder: Path, frames: int, options: list[str], subset: list[int] | None = None) -> dict:
    """Render the plan's frames (or only the frames `subset`, through a jobs file) with a setting's options into
    `folder` (resuming frames already there) through the CLI; {'rendered', 'cpu_s_per_frame', 'cpu_ms_per_image',
    'command'}, or {'error': the command's last line}. The CPU figures of the run that last rendered frames there
    are kept in folder/realism_render.json."""
    plan = ["--count", str(frames), "--seed", str(SEED)]
    if subset is not None:
        folder.mkdir(parents=True, exist_ok=True)
        plan = ["--jobs", str(subset_jobs(folder, frames, subset))]
    command = ["render-dataset", str(MODEL), "--out", str(folder), *plan, *options]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, "-m", "darthand.cli", *command], capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        return {"error": (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1],
                "command": " ".join(command)}
    doc = json.loads((folder / "dataset.json").read_text())
    record = folder / "realism_render.json"
    if doc["rendered"]:
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        record.write_text(json.dumps({"rendered": doc["rendered"], "cpu_s_per_frame": cpu / doc["rendered"],
                                      "cpu_ms_per_image": doc["timings"].get("cpu_ms_per_image")}))
    measured = json.loads(record.read_text()) if record.is_file() else \
        {"rendered": 0, "cpu_s_per_frame": None, "cpu_ms_per_image": None}       # frames another run left there
    return {**measured, "command": "darthand " + " ".join(command)}


def subset_jobs(folder: Path, frames: int, subset: list[int]) -> Path:
    """folder/subset_jobs.json: the planned jobs (render-dataset --plan, the plan's defaults) of the frames
    `subset`."""
    planned = folder / "planned_jobs.json"
    if not planned.is_file():
        subprocess.run([sys.executable, "-m", "darthand.cli", "render-dataset", str(MODEL), "--out", str(folder),
                        "--count", str(frames), "--seed", str(SEED), "--plan", str(planned)], check=True,
                       capture_output=True)
    from darthand.dataset.jobs import load_jobs

    wanted = set(subset)
    path = folder / "subset_jobs.json"
    path.write_text(json.dumps({"frames": [job for job in load_jobs(planned) if job.get("index") in wanted]}))
    return path


def detect(images: Path, out: Path, confidence: float) -> dict:
    """MediaPipe's document over a folder of frames (benchmarks/_realism_detect.py; confidence: its
    min_detection_confidence), run again only when a frame is newer than the last result or that was another
    confidence's. RuntimeError with the detector's last line when it fails."""
    newest = max((p.stat().st_mtime for p in images.iterdir()), default=0.0)
    if out.is_file() and out.stat().st_mtime >= newest:
        doc = json.loads(out.read_text())
        if doc["detector"]["min_detection_confidence"] == confidence:
            return doc
    done = subprocess.run([str(DETECTOR_PYTHON), str(DETECT_SCRIPT), str(images), str(out), repr(confidence)],
                          capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError("the detector failed: " + (done.stderr.strip().splitlines() or ["?"])[-1])
    return json.loads(out.read_text())


def read_labels(folder: Path, frames: int, subset: list[int] | None = None) -> dict:
    """{frame index: labels} of the frames rendered in a dataset folder (all `frames`, or the frames `subset`)."""
    return {i: json.loads((folder / frame_names(i)["labels"]).read_text())
            for i in (range(frames) if subset is None else subset)}


def measure_setting(folder: Path, frames: int, options: list[str], confidence: float,
                    subset: list[int] | None = None) -> tuple[dict, dict]:
    """(figures of one setting, {frame index: detection}): render, detect, compare (only the frames `subset`, when
    given)."""
    render = render_setting(folder, frames, options, subset)
    if "error" in render:
        return render, {}
    t0 = time.process_time()
    labels = read_labels(folder, frames, subset)
    try:
        found = detect(folder / "images", folder / "detections.json", confidence)["images"]
    except RuntimeError as e:
        return {**render, "error": str(e)}, {}
    by_index = {i: found[Path(frame_names(i)["image"]).name] for i in labels}
    records = [{"index": i, **frame_record(labels[i], by_index[i])} for i in sorted(labels)]
    counted = [r["index"] for r in records if r["visible"] >= MIN_VISIBLE and not r["accessory"]]
    hands = {i: inner_hand(folder, i) for i in counted}
    result = {**render, **subsets(records), "order_check": order_check(records, labels, by_index),
              "washed_out": washed_out([clipped_share(hand) for hand in hands.values()]),
              "tone_agreement": tone_agreement(hands, labels),
              "harness_cpu_s": round(time.process_time() - t0, 2)}
    return result, by_index


def inner_hand(folder: Path, index: int) -> np.ndarray:
    """(K, 3) uint8 frame `index`'s inner hand pixels: its mask's full pixels eroded by one (an edge pixel mixes in
    the backdrop)."""
    names = frame_names(index)
    image = read_straight_png(folder / names["image"])[..., :3]
    return image[ndimage.binary_erosion(read_straight_png(folder / names["mask"])[..., 0] == 255)]


def clipped_share(hand: np.ndarray) -> float:
    """The share of a frame's inner hand pixels (K, 3) uint8 (inner_hand) that are 255 in some channel (0 without
    any)."""
    return float((hand.max(axis=1) == 255).mean()) if len(hand) else 0.0


def tone_agreement(hands: dict, labels: dict) -> dict:
    """{'frames', 'spearman'}: over the frames of `hands` ({frame index: its inner hand pixels}) with pixels and
    whose labels record a tone (texture.tone_srgb), the rank correlation between that tone's luminance and the
    median luminance of the frame's inner hand pixels. The issue's "the tone a frame's labels record is the tone its
    image shows", measured across frames (light and exposure vary per frame, so 1 is not the aim; higher is
    closer)."""
    pairs = [(float(luminance(srgb_to_linear(labels[i]["texture"]["tone_srgb"]))),
              float(np.median(luminance(srgb_to_linear(hand / 255.0))))) for i, hand in hands.items()
             if labels[i].get("texture", {}).get("tone_srgb") is not None and len(hand)]
    if len(pairs) < 3:
        return {"frames": len(pairs), "spearman": None}
    return {"frames": len(pairs), "spearman": round(float(stats.spearmanr(*zip(*pairs)).statistic), 3)}


def washed_out(shares: list[float]) -> dict:
    """{'frames', 'over_5', 'over_20': frames with over 5 % / 20 % of their hand clipped, 'mean': the mean share}
    of per-frame clipped shares (clipped_share)."""
    shares_array = np.asarray(shares, np.float64)
    return {"frames": len(shares), "over_5": int((shares_array > 0.05).sum()),
            "over_20": int((shares_array > 0.2).sum()),
            "mean": round(float(shares_array.mean()), 5) if len(shares) else None}


# ------------------------------------------------------------------ the contact sheet

def sheet_frames(labels: dict, count: int = SHEET_FRAMES) -> list[int]:
    """`count` frame indices spread evenly over the plan's bare frames with at least MIN_VISIBLE visible keypoints."""
    bare = [i for i in sorted(labels) if (labels[i].get("accessory") or {}).get("id", "none") in (None, "none")
            and labels_openpose(labels[i])[1].sum() >= MIN_VISIBLE]
    if not bare:
        return []
    return [bare[k] for k in sorted(set(np.linspace(0, len(bare) - 1, min(count, len(bare))).round().astype(int)))]


def subset_frames(labels: dict, sheet: list[int], count: int) -> list[int]:
    """The frames a subset row renders: the sheet's, then the plan's other bare frames with at least MIN_VISIBLE
    visible keypoints in order, `count` in all (sorted)."""
    bare = [i for i in sorted(labels) if (labels[i].get("accessory") or {}).get("id", "none") in (None, "none")
            and labels_openpose(labels[i])[1].sum() >= MIN_VISIBLE]
    chosen = list(dict.fromkeys([*sheet, *bare]))[:max(count, len(sheet))]
    return sorted(chosen)


def same_frames(folder: Path, subset: list[int]) -> dict:
    """subsets() of a full row's frames `subset` only (its labels and detections in `folder`)."""
    labels = read_labels(folder, 0, subset)
    found = json.loads((folder / "detections.json").read_text())["images"]
    return subsets([{"index": i, **frame_record(labels[i], found[Path(frame_names(i)["image"]).name])}
                    for i in subset])


def shrink(image: np.ndarray, size: int) -> np.ndarray:
    """(size, size, 3) uint8 of a square (N, N, 3) uint8 image: the mean of each k x k block where N = k size (sRGB
    codes averaged: a thumbnail), else the nearest pixel."""
    n = image.shape[0]
    if n % size == 0:
        k = n // size
        return image.reshape(size, k, size, k, 3).mean(axis=(1, 3)).round().astype(np.uint8)
    pick = (np.arange(size) * n / size).astype(int)
    return image[pick][:, pick].copy()


def sheet_row(folder: Path, indices: list[int], detections: dict) -> tuple[np.ndarray, list]:
    """((T, T * len(indices), 3) uint8 tiles of the frames over black, each bordered green where a hand was found and
    red where not; [(x, y) landmark arrays in the row's pixels]) at SHEET_TILE pixels a tile."""
    tiles, marks = [], []
    for k, i in enumerate(indices):
        rgb = over_black(read_straight_png(folder / frame_names(i)["image"]))
        step = rgb.shape[0] / SHEET_TILE
        tile = shrink(rgb, SHEET_TILE)
        found = detections.get(i, {}).get("found", False)
        tile[:3], tile[-3:], tile[:, :3], tile[:, -3:] = [(40, 200, 60) if found else (220, 40, 40)] * 4
        tiles.append(tile)
        if found:
            marks.append(np.asarray(detections[i]["landmarks"]) / step - 0.5 + [k * SHEET_TILE, 0])   # centres: +0.5
    return np.concatenate(tiles, axis=1), marks


def contact_sheet(path: Path, rows: list[tuple[str, Path, dict]], indices: list[int]) -> None:
    """Write the sheet (rows: (label, dataset folder, {index: detection})) as a PNG, a frame's tile SHEET_TILE pixels
    of the image to the tile (axes placed in pixels: nothing resampled)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt       # imported here: only the sheet needs matplotlib

    left, top, row_h, dpi = 150, 30, SHEET_TILE + 22, 100
    width, height = SHEET_TILE * len(indices), top + row_h * len(rows)
    fig = plt.figure(figsize=((left + width + 10) / dpi, height / dpi), dpi=dpi)
    for r, (label, folder, detections) in enumerate(rows):
        bottom = height - top - r * row_h - SHEET_TILE
        ax = fig.add_axes((left / fig.bbox.width, bottom / height, width / fig.bbox.width, SHEET_TILE / height))
        image, marks = sheet_row(folder, indices, detections)
        ax.imshow(image, interpolation="nearest")
        for m in marks:
            ax.plot(m[:, 0], m[:, 1], ".", color="yellow", markersize=2.5)
        ax.set_xticks([SHEET_TILE * (k + 0.5) for k in range(len(indices))], [str(i) for i in indices], fontsize=6)
        ax.tick_params(length=0, pad=2)
        ax.set_yticks([])
        ax.set_ylabel(label, rotation=0, ha="right", va="center", fontsize=9)
        ax.set_xlim(0, width)
        ax.set_ylim(SHEET_TILE, 0)
    fig.text(0.5, 1 - 10 / height, f"seed {SEED}: the same frames per setting (green: MediaPipe finds the hand, its "
             "landmarks in yellow; red: not found)", ha="center", va="top", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


# ------------------------------------------------------------------ the benchmark

def chosen_settings(names: str | None) -> dict:
    """The SETTINGS rows named (comma-separated; None or '' for all), in the table's order."""
    if not names:
        return dict(SETTINGS)
    wanted = [n.strip() for n in names.split(",") if n.strip()]
    unknown = [n for n in wanted if n not in SETTINGS]
    if unknown:
        raise SystemExit(f"realism: unknown settings {', '.join(unknown)} (known: {', '.join(SETTINGS)})")
    return {n: SETTINGS[n] for n in SETTINGS if n in wanted}


def run(out: Path | None = None, frames: int | None = None, settings: str | None = None) -> dict:
    """Render and detect every chosen setting's frames (see the module docstring); the contact sheet goes to
    out/realism_sheet.png (out: the benchmarks' output folder; None: build/bench)."""
    frames = int(frames or os.environ.get("DARTHAND_REALISM_FRAMES") or DEFAULT_FRAMES)
    table = chosen_settings(settings or os.environ.get("DARTHAND_REALISM_SETTINGS"))
    confidence = float(os.environ.get("DARTHAND_REALISM_CONFIDENCE") or DEFAULT_CONFIDENCE)
    problem = detector_problem() or (None if MODEL.is_file() else "no build/model/right.npz: run `make assets`")
    if problem:
        return {"skipped": problem}
    work = os.environ.get("DARTHAND_REALISM_WORK")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(work or tmp)
        results, rows, indices, subset, first = {}, [], [], None, None
        for name, options in table.items():
            partial = name in SUBSET_ROWS and first is not None
            if partial and subset is None:
                subset = subset_frames(read_labels(root / first, frames), indices, int(
                    os.environ.get("DARTHAND_REALISM_SUBSET") or SUBSET_FRAMES))
            print(f"[bench] realism: {name} ({len(subset) if partial else frames} frames)", file=sys.stderr,
                  flush=True)
            results[name], detections = measure_setting(root / name, frames, options, confidence,
                                                        subset if partial else None)
            if "error" in results[name]:
                continue
            if partial:
                results[name]["compared_with"] = {"setting": first, **same_frames(root / first, subset)}
            first = first or name
            indices = indices or sheet_frames(read_labels(root / name, frames))
            rows.append((f"{name}\n{_pct(results[name]['bare']['detection_rate'])} found", root / name, detections))
        sheet = Path(out or ROOT / "build" / "bench") / "realism_sheet.png"
        if rows and indices:
            contact_sheet(sheet, rows, indices)
    head = "default" if "default" in results else next(iter(table))      # the headline's setting
    return {"detection_rate_default": results.get("default", {}).get("bare", {}).get("detection_rate"),
            "headline": {"setting": head, "detection_rate": results[head].get("bare", {}).get("detection_rate")},
            "frames": frames, "seed": SEED, "min_visible": MIN_VISIBLE, "min_detection_confidence": confidence,
            "settings": results,
            "sheet": sheet.name if rows and indices else None, "sheet_frames": indices,
            "options": {name: table[name] for name in table}, "order": list(table),
            "what": f"MediaPipe Hands 0.10.14 on `render-dataset --seed {SEED} --count {frames}` per setting; frames "
                    f"with >= {MIN_VISIBLE} of 21 keypoints visible; PCK relative to the 2D keypoints' bounding-box "
                    "diagonal"}


def summary(res: dict) -> str:
    """The markdown section: the headline, then a line per setting."""
    if "skipped" in res:
        return f"Skipped: {res['skipped']}"
    head = res.get("headline", {"setting": "default", "detection_rate": res["detection_rate_default"]})
    lines = [f"Headline: MediaPipe finds the hand in {_pct(head['detection_rate'])} of the {head['setting']} frames "
             f"(no accessory, >= {res['min_visible']} of 21 keypoints visible; seed {res['seed']}, {res['frames']} "
             "frames planned).", "",
             "| setting | frames | detection (95 %) | PCK 0.1 | PCK 0.2 | handedness | with accessory: detection | "
             "skin clipped: frames over 5 % | tone: labels vs image (Spearman) | CPU ms/frame: steady, whole command |",
             "|---" * 10 + "|"]
    for name in res.get("order", res["settings"]):       # the table's order (JSON files sort their keys)
        r = res["settings"][name]
        if "error" in r:
            lines.append(f"| {name} | failed: {r['error']} (`{r['command']}`) | | | | | | | | |")
            continue
        b = r["bare"]
        lo, hi = b["detection_rate_95"]
        lines.append(f"| {name} | {b['frames']} | {_pct(b['detection_rate'])} ({_pct(lo)}-{_pct(hi)}) | "
                     f"{_num(b['pck_0.1'])} | {_num(b['pck_0.2'])} | {_pct(b['handedness'])} | "
                     f"{_pct(r['accessory']['detection_rate'])} of {r['accessory']['frames']} | "
                     f"{_clipped(r.get('washed_out'))} | {_num((r.get('tone_agreement') or {}).get('spearman'))} | "
                     f"{_ms(r['cpu_ms_per_image'])}, "
                     f"{_ms(r['cpu_s_per_frame'] and 1000 * r['cpu_s_per_frame'])} |")
        if r.get("compared_with"):
            c = r["compared_with"]
            lines.append(f"| ({c['setting']} on {name}'s frames) | {c['bare']['frames']} | "
                         f"{_pct(c['bare']['detection_rate'])} | {_num(c['bare']['pck_0.1'])} | "
                         f"{_num(c['bare']['pck_0.2'])} | {_pct(c['bare']['handedness'])} | | | | |")
    if res.get("sheet"):
        lines += ["", f"Contact sheet: `{res['sheet']}` (frames {', '.join(map(str, res['sheet_frames']))})."]
    return "\n".join(lines)


def _clipped(w: dict | None) -> str:
    return "n/a" if not w else f"{w['over_5']} of {w['frames']}"


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.0f} %"


def _ms(x) -> str:
    return "n/a" if x is None else f"{x:.0f}"


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.realism", description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=None, help=f"frames planned (default {DEFAULT_FRAMES})")
    p.add_argument("--settings", default=None, help=f"comma-separated settings (default all: {', '.join(SETTINGS)})")
    p.add_argument("--out", default="build/bench", help="folder of realism.json and the contact sheet")
    args = p.parse_args(argv)
    res = run(Path(args.out), args.frames, args.settings)
    write_json(Path(args.out) / "realism.json", res)
    print(summary(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
