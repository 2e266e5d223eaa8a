"""`darthand dataset report DIR`: one page (report.png) a person can judge a dataset from, and its figures
(report.json):

- a contact sheet of frames spread over the dataset, with their 2D keypoints and skeleton drawn (hollow markers:
  keypoints not visible);
- counts per texture category, texture tone, accessory type, side and split; the skin-tone offsets;
- with two-hand frames: counts per interaction type and hand type, and a sheet of them per type
  (dataset/report_hands.py, two_hands.png); with object frames: counts per object category and grasp type
  (dataset/report_objects.py);
- the visibility rate of each keypoint and the share of keypoints inside the image;
- pose coverage: the dataset's finger poses and the plan's reference set in one 2-D t-SNE embedding, as DART's
  figure (dataset/embedding.py; the distance between two poses is the mean rotation angle over the 15 finger joints,
  both sets embedded together, up to EMBED_DATASET + EMBED_REFERENCE poses evenly spread), and how far each
  reference pose is from its nearest dataset pose (the same distance). When the reference set is not the pose
  library (model/pose_library: the gestures, a pose file, FreiHAND's poses), the library is drawn and measured
  beside it (`library_coverage` in report.json), so the figure always shows the dataset against the library.

Poses are read from up to MAX_POSES frames' labels (evenly spread), so a report of a large dataset stays quick.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.dataset.embedding import PERPLEXITY, tsne
from darthand.dataset.frames import frame_names
from darthand.dataset.hands import hand_type, hands_of
from darthand.dataset.poses import LIBRARY, load_reference
from darthand.dataset.report_hands import two_hand_frames, write_two_hand_sheet
from darthand.dataset.report_objects import object_counts
from darthand.dataset.run import rendered_dataset
from darthand.dataset.sources import SourceSpec
from darthand.errors import InputError
from darthand.fileio import read_json, write_json
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.rotations import axis_angle_to_quaternion
from darthand.render.image import read_png
from darthand.render.labels import keypoint_names

MAX_POSES = 3000
MAX_REFERENCE = 3000
EMBED_DATASET = 800      # poses of each set in the t-SNE picture: exact t-SNE is O(N^2), ~2-5 s for 1200 points
EMBED_REFERENCE = 400
BONES = [(0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (0, 9), (9, 10), (10, 11), (11, 12),
         (0, 13), (13, 14), (14, 15), (15, 16), (0, 17), (17, 18), (18, 19), (19, 20)]      # openpose order
FINGER_COLOURS = ["#e6194b", "#f58231", "#3cb44b", "#4363d8", "#911eb4"]                  # thumb .. pinky


def write_report(dataset, out=None, sheet: int = 24) -> Path:
    """Write report.png and report.json for a rendered dataset folder into `out` (default DATASET/report)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    root = Path(dataset)
    doc, frames = rendered_dataset(root)
    out = Path(out) if out is not None else root / "report"
    out.mkdir(parents=True, exist_ok=True)
    figures = dataset_figures(frames)
    poses, reference, ref_name = pose_sets(root, doc, frames)
    library, lib_name = library_set(doc, ref_name)
    embedding = pose_embedding(poses, reference, library)
    figures["pose_coverage"] = coverage_figures(poses, reference)
    (n, _), (m, _) = embedding["poses"][:2]
    figures["pose_coverage"]["embedding"] = {"method": "t-SNE", "perplexity": PERPLEXITY, "distance":
                                             "mean finger-joint angle", "dataset_poses": n, "reference_poses": m}
    figures["reference"] = ref_name
    figures["library_coverage"] = coverage_figures(poses, library) if len(library) else \
        {"same_as": "pose_coverage" if lib_name == ref_name else None, "library": lib_name}

    shown = min(sheet, len(frames))
    sheet_height = 5.6 * -(-shown // min(8, shown)) / min(8, shown)     # in units of the rows below: the full width
    fig = plt.figure(figsize=(20, 4 * (sheet_height + 4.9)), dpi=90)
    grid = fig.add_gridspec(5, 4, height_ratios=[sheet_height, 1, 1, 1, 1.9], hspace=0.45, wspace=0.3, top=0.96,
                            bottom=0.03)
    fig.suptitle(f"{root.name}: {len(frames)} frames, {doc.get('size')} px, package {doc.get('package')}",
                 fontsize=18, y=0.995)
    _contact_sheet(fig.add_subplot(grid[0, :]), root, frames, sheet)
    for k, key in enumerate(("category", "accessory_type", "tone", "split")):
        _bars(fig.add_subplot(grid[1, k]), figures["counts"][key], key)
    _bars(fig.add_subplot(grid[2, 0]), figures["counts"]["side"], "side")
    ax = fig.add_subplot(grid[2, 1])
    ax.hist([f["skin_tone_offset"] for f in frames], bins=20, color="#a0522d")
    ax.set_title("skin-tone offset (sRGB)")
    ax = fig.add_subplot(grid[2, 2:])
    _visibility(ax, figures)
    ax = fig.add_subplot(grid[3, :2])
    ax.hist([f["coverage"] for f in frames], bins=30, color="#708090")
    ax.set_title(f"hand coverage of the image (mean {figures['mean_coverage']:.3f})")
    ax = fig.add_subplot(grid[3, 2:])
    ax.axis("off")
    ax.text(0, 1, _summary_text(doc, figures), va="top", family="monospace", fontsize=11)
    _embedding(fig.add_subplot(grid[4, :2]), embedding, ref_name, lib_name)
    _nearest(fig.add_subplot(grid[4, 2:]), figures["pose_coverage"], figures["library_coverage"])
    page = out / "report.png"
    fig.savefig(page, bbox_inches="tight")
    plt.close(fig)
    counts, by_type = two_hand_frames(root, frames)
    if by_type:                             # only a dataset with two-hand frames: one-hand reports stay as they were
        figures["two_hands"] = counts
        write_two_hand_sheet(root, by_type, out / "two_hands.png", BONES)
    objects = object_counts(frames)
    if objects:                             # only a dataset with object frames
        figures["objects"] = objects
    write_json(out / "report.json", figures)
    return page


def dataset_figures(frames: list[dict]) -> dict:
    """Counts, visibility and coverage figures of a dataset's frame summaries."""
    counts: dict = {}
    for key in ("category", "tone", "accessory_type", "side", "split"):
        table: dict = {}
        for f in frames:
            table[str(f.get(key))] = table.get(str(f.get(key)), 0) + 1
        counts[key] = dict(sorted(table.items()))
    visible = np.array([f["visible"] for f in frames], float)
    return {"frames": len(frames), "counts": counts, "visibility_rate": visible.mean(0).round(4).tolist(),
            "visible_keypoints_mean": round(float(visible.sum(1).mean()), 3),
            "in_image_rate": round(float(np.mean([f["in_image"] for f in frames]) / 21), 4),
            "mean_coverage": round(float(np.mean([f["coverage"] for f in frames])), 5),
            "skipped_backgrounds": sorted({n for f in frames for n in f.get("skipped_backgrounds") or ()})[:100]}


def pose_sets(root: Path, doc: dict, frames: list[dict]) -> tuple[np.ndarray, np.ndarray, str]:
    """((n, 15, 4) finger-joint quaternions of up to MAX_POSES frames, right-hand convention; the plan's reference
    set's (m, 15, 4), up to MAX_REFERENCE; its name)."""
    pick = spread_index(len(frames), MAX_POSES)
    poses = []
    for k in pick:
        labels = read_json(root / frame_names(frames[k]["index"])["labels"], "labels")
        for hand in hands_of(labels):
            pose = np.asarray(hand["mano_pose"], np.float64)
            poses.append(mirror_pose(pose) if hand["side"] == "left" else pose)
    quats = axis_angle_to_quaternion(np.asarray(poses).reshape(-1, 16, 3)[:, 1:])
    reference, name = _reference(doc)
    return quats, reference, name


def library_set(doc: dict, ref_name: str) -> tuple[np.ndarray, str]:
    """The pose library's (m, 15, 4) finger quaternions on the dataset's model, up to MAX_REFERENCE, and its name;
    (0, 15, 4) when the plan's reference set is the library already (or a tagged part of it: the figure then
    shows that part) or the library cannot be posed."""
    if ref_name.startswith(LIBRARY):
        return np.zeros((0, 15, 4)), ref_name
    return _reference(doc, LIBRARY)


def _reference(doc: dict, spec: str | None = None) -> tuple[np.ndarray, str]:
    plan = (doc.get("jobs") or {}).get("plan") or {}
    spec = spec or (plan.get("poses") or {}).get("reference", "gestures")
    try:
        source = SourceSpec(doc["package"]).open()
        model = source.pose_model()
        if model is None:
            raise InputError("a USD package has no model to pose the reference set with")
        if model.side != "right":
            model = mirror_model(model)
        ref = load_reference(spec, model, float((plan.get("poses") or {}).get("max_reference_mb", 256)),
                             model_path=source.describe().get("source"))
    except (InputError, AttributeError, KeyError) as e:
        return np.zeros((0, 15, 4)), f"none ({e})"
    quats = ref.quats.astype(np.float64)
    return quats[spread_index(len(quats), MAX_REFERENCE)], ref.source


def _features(quats: np.ndarray) -> np.ndarray:
    q = np.where(quats[..., :1] < 0, -quats, quats)
    return q.reshape(len(q), -1)


def pose_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m) distances in degrees between finger poses a (n, 15, 4) and b (m, 15, 4) (unit quaternions): the mean
    over the 15 joints of the angle of the rotation taking one to the other."""
    out = np.empty((len(a), len(b)))
    for k in range(0, len(a), 256):
        dots = np.abs(np.einsum("ajc,bjc->abj", a[k:k + 256], b))
        out[k:k + 256] = np.degrees(2 * np.arccos(np.minimum(dots, 1))).mean(-1)
    return out


def pose_embedding(poses: np.ndarray, reference: np.ndarray, library: np.ndarray | None = None) -> dict:
    """2-D t-SNE coordinates of (an evenly spread subsample of) the sets, embedded together: {"dataset" (n, 2),
    "reference" (m, 2), "library" (l, 2), "poses": [n of len(poses), m of len(reference), l of len(library)]}.
    library: the pose library when it is not the reference set (default none). Starts from the sets' first two
    principal components of the sign-fixed quaternions (deterministic)."""
    library = np.zeros((0, 15, 4)) if library is None else library
    data, ref = poses[spread_index(len(poses), EMBED_DATASET)], reference[spread_index(len(reference), EMBED_REFERENCE)]
    lib = library[spread_index(len(library), EMBED_REFERENCE)]
    both = np.concatenate([data, ref, lib])
    features = _features(both)
    features = features - features.mean(0)
    axes = np.linalg.svd(features, full_matrices=False)[2][:2] if len(both) > 1 else np.eye(2, features.shape[1])
    y = tsne(pose_distances(both, both), features @ axes.T)
    n, m = len(data), len(data) + len(ref)
    return {"dataset": y[:n], "reference": y[n:m], "library": y[m:],
            "poses": [[len(data), len(poses)], [len(ref), len(reference)], [len(lib), len(library)]]}


def spread_index(n: int, most: int) -> np.ndarray:
    """Indices of up to `most` of n items, evenly spread over them (all n when n <= most)."""
    return np.unique(np.linspace(0, n - 1, min(most, n)).round().astype(int))


def coverage_figures(poses: np.ndarray, reference: np.ndarray) -> dict:
    """How well the dataset's poses cover the reference set: per reference pose, the mean rotation angle (degrees)
    over the 15 finger joints to its nearest dataset pose; and the dataset's own spread (the same to the nearest
    other dataset pose)."""
    result: dict = {"dataset_poses": int(len(poses)), "reference_poses": int(len(reference))}
    if len(reference):
        d = pose_distances(reference, poses).min(1)
        result.update({"reference_to_dataset_deg": d.round(3).tolist(),
                       "median_deg": round(float(np.median(d)), 3), "within_10deg": round(float((d <= 10).mean()), 4),
                       "within_20deg": round(float((d <= 20).mean()), 4)})
    if len(poses) > 1:
        d = pose_distances(poses, poses)
        np.fill_diagonal(d, np.inf)
        result["dataset_nearest_median_deg"] = round(float(np.median(d.min(1))), 3)
    return result


# ------------------------------------------------------------------------------------------------ panels


def _contact_sheet(ax, root: Path, frames: list[dict], count: int) -> None:
    pick = spread_index(len(frames), count)
    cols = min(8, len(pick))
    rows = -(-len(pick) // cols)
    tiles = []
    for k in pick:
        names = frame_names(frames[k]["index"])
        image = read_png(root / names["image"]).astype(np.float32) / 255
        rgb = image[..., :3] * image[..., 3:4] + 0.5 * (1 - image[..., 3:4]) if image.shape[2] == 4 else image
        labels = read_json(root / names["labels"], "labels")
        tiles.append((rgb, labels))
    size = tiles[0][0].shape[0]
    ax.imshow(np.ones((rows * size, cols * size, 3)) * 0.95, extent=(0, cols * size, rows * size, 0))
    for n, (rgb, labels) in enumerate(tiles):
        r, c = divmod(n, cols)
        ax.imshow(rgb, extent=(c * size, (c + 1) * size, (r + 1) * size, r * size))
        for hand in hands_of(labels):
            uv = np.asarray(hand["keypoints_2d"]) * (size / labels["image_size"][0]) + [c * size, r * size]
            vis = hand["visibility"]
            for b, (i, j) in enumerate(BONES):
                ax.plot(uv[[i, j], 0], uv[[i, j], 1], color=FINGER_COLOURS[b // 4], lw=1.2, alpha=0.9)
            for k, (x, y) in enumerate(uv):
                colour = "white" if k == 0 else FINGER_COLOURS[(k - 1) // 4]
                ax.plot(x, y, "o", ms=3.5, mfc=colour if vis[k] else "none", mec=colour, mew=1)
        tag = f"#{labels['render']['dataset']['frame']} {hand_type(labels)[0]} {labels['split']}"
        ax.text(c * size + 3, r * size + 12, tag, color="white", fontsize=8,
                bbox={"facecolor": "black", "alpha": 0.5, "pad": 1, "lw": 0})
    ax.set_xlim(0, cols * size)
    ax.set_ylim(rows * size, 0)
    ax.axis("off")
    ax.set_title("frames with their 2D keypoints (hollow: not visible)")


def _bars(ax, table: dict, title: str) -> None:
    names, values = list(table), list(table.values())
    ax.barh(range(len(names)), values, color="#4682b4")
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_title(f"{title} ({len(names)})")


def _visibility(ax, figures: dict) -> None:
    rates = figures["visibility_rate"]
    ax.bar(range(21), rates, color=["#808080"] + [c for c in FINGER_COLOURS for _ in range(4)])
    ax.set_xticks(range(21), keypoint_names("openpose"), rotation=90, fontsize=8)
    ax.set_ylim(0, 1)
    ax.set_title(f"keypoint visibility rate (mean {figures['visible_keypoints_mean']:.1f}/21 visible, "
                 f"{figures['in_image_rate']:.1%} inside the image)")


def _embedding(ax, embedding: dict, ref_name: str, lib_name: str) -> None:
    ref, data, lib = embedding["reference"], embedding["dataset"], embedding["library"]
    ax.scatter(data[:, 0], data[:, 1], s=5, c="#d62728", alpha=0.6, label="dataset")
    if len(lib):                                         # the library, when the reference set is something else
        ax.scatter(lib[:, 0], lib[:, 1], s=22, marker="+", c="#1f77b4", linewidths=0.9,
                   label=f"pose library ({len(lib)} poses)")
    if len(ref):                                         # on top: a few reference poses among many dataset ones
        ax.scatter(ref[:, 0], ref[:, 1], s=28, marker="D", c="#1f1f1f", edgecolors="white", linewidths=0.6,
                   label=f"reference set ({ref_name})")
    (n, total), (m, ref_total) = embedding["poses"][:2]
    ax.set_xticks([])
    ax.set_yticks([])
    ax.legend(loc="best", fontsize=9)
    ax.set_title(f"pose coverage: t-SNE of finger poses ({n} of {total} dataset"
                 + (f", {m} of {ref_total} reference)" if ref_total else ")"))


def _nearest(ax, cov: dict, library: dict) -> None:
    """Histograms of each reference pose's (and each library pose's, when the library is not the reference set)
    distance to its nearest dataset pose."""
    d, lib = cov.get("reference_to_dataset_deg"), library.get("reference_to_dataset_deg")
    if not d and not lib:
        ax.axis("off")
        return
    title = []
    if d:
        ax.hist(d, bins=30, color="#2ca02c", alpha=0.8 if lib else 1.0, label="reference set")
        title.append(f"reference pose to nearest dataset pose: median {cov['median_deg']:.1f} deg, "
                     f"{cov['within_10deg']:.0%} within 10 deg")
    if lib:
        ax.hist(lib, bins=30, color="#1f77b4", alpha=0.6, label="pose library")
        ax.legend(loc="best", fontsize=9)
        title.append(f"library pose to nearest dataset pose: median {library['median_deg']:.1f} deg, "
                     f"{library['within_10deg']:.0%} within 10 deg")
    ax.set_title("\n".join(title))
    ax.set_xlabel("mean rotation angle over the 15 finger joints (degrees)")


def _summary_text(doc: dict, figures: dict) -> str:
    t = doc.get("timings", {})
    lines = [f"frames            {figures['frames']}",
             f"rendered/skipped  {doc.get('rendered')} / {doc.get('skipped')} (last run)",
             f"image size        {doc.get('size')} px, {doc.get('samples')} AA samples",
             f"mean coverage     {figures['mean_coverage']:.3f}",
             f"visible keypoints {figures['visible_keypoints_mean']:.1f} / 21",
             f"in image          {figures['in_image_rate']:.1%}",
             f"bad backgrounds   {len(figures['skipped_backgrounds'])}"]
    if t.get("images_per_second"):
        lines.append(f"speed (last run)  {t['images_per_second']:.1f} images/s, {t.get('processes')} processes")
    plan = (doc.get("plan") or {})
    if plan.get("reference"):
        lines.append(f"reference set     {plan['reference']['source']} ({plan['reference']['poses']} poses)")
    return "\n".join(lines)

