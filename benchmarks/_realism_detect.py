"""Run MediaPipe Hands over a folder of frames and write what it finds as JSON: the realism benchmark's detector.

Runs in the detector's own environment (`make detector`: .venv-detector/bin/python), never in the project's: it
imports neither darthand nor anything of the benchmarks package, only MediaPipe, OpenCV and numpy 1.x.

    .venv-detector/bin/python benchmarks/_realism_detect.py IMAGES_DIR OUT.json [MIN_DETECTION_CONFIDENCE]

The detector: MediaPipe's legacy `solutions.hands` (the 0.10.14 wheel carries its palm detector and hand landmark
models; it has no Tasks .task bundle), static_image_mode=True (every image detected afresh, no tracking between
frames), model_complexity=1 (the full landmark model), max_num_hands=1 (a frame shows one hand: the most confident
detection is the one kept), min_detection_confidence 0.5 (MediaPipe's default; the third argument changes it).

OUT.json: {"detector": {settings, version}, "images": {file name: {"found": bool, "landmarks": 21 [x, y] in
pixels (x right, y down, pixel centres at +0.5) or [], "handedness": MediaPipe's label ('Left'/'Right') or None,
"score": its score or None}}}. MediaPipe's handedness assumes a mirrored (selfie) image: its 'Left' is a right hand
in an unmirrored frame; the label is written as MediaPipe gives it and benchmarks/realism.py turns it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("GLOG_minloglevel", "2")          # MediaPipe's C++ start-up lines
os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")

import cv2  # noqa: E402  (after the logging environment above)
import mediapipe as mp  # noqa: E402
import numpy as np  # noqa: E402

SETTINGS = {"static_image_mode": True, "model_complexity": 1, "max_num_hands": 1, "min_detection_confidence": 0.5}


def srgb_over_black(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an 8-bit PNG read by OpenCV (BGR or BGRA, straight alpha): an RGBA frame is composited
    over black in linear light, as the project's layouts composite frames without a background."""
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    c = image[..., :3].astype(np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4) * (image[..., 3:] / 255.0)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return cv2.cvtColor(np.round(srgb * 255).astype(np.uint8), cv2.COLOR_BGR2RGB)


def detect(hands, path: Path) -> dict:
    """One image's detection (see the module docstring for the fields)."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        return {"found": False, "landmarks": [], "handedness": None, "score": None, "error": "does not decode"}
    rgb = srgb_over_black(image)
    h, w = rgb.shape[:2]
    result = hands.process(rgb)
    if not result.multi_hand_landmarks:
        return {"found": False, "landmarks": [], "handedness": None, "score": None}
    points = [[lm.x * w, lm.y * h] for lm in result.multi_hand_landmarks[0].landmark]
    label = result.multi_handedness[0].classification[0]
    return {"found": True, "landmarks": points, "handedness": label.label, "score": float(label.score)}


def main(argv: list[str]) -> int:
    if len(argv) not in (2, 3):
        print("usage: _realism_detect.py IMAGES_DIR OUT.json [MIN_DETECTION_CONFIDENCE]", file=sys.stderr)
        return 2
    images, out = Path(argv[0]), Path(argv[1])
    settings = {**SETTINGS, **({"min_detection_confidence": float(argv[2])} if len(argv) == 3 else {})}
    files = sorted(p for p in images.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    with mp.solutions.hands.Hands(**settings) as hands:
        found = {p.name: detect(hands, p) for p in files}
    doc = {"detector": {"name": "mediapipe.solutions.hands", "version": mp.__version__, **settings},
           "images": found}
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(doc))
    tmp.replace(out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
