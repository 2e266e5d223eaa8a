"""The path-traced tier: a frame's image from Blender's Cycles, its labels from the fast renderer.

`CyclesRenderer` wraps a render.api.Renderer: `render_scene` renders the frame with the fast path (the pose, camera,
labels, mask and truth maps are the fast renderer's, unchanged), then the same posed subject, camera, lights and
environment (render/cycles_scene.py) in Cycles, and composites Cycles' image over the frame's background (the same
pixels as the fast renderer's, the environment backdrop included). The labels record the engine and its samples.

Cycles runs in a persistent worker process under Blender's Python (render/blender/cycles_worker.py; which Python:
$DARTHAND_BLENDER_PYTHON, else <repo>/.venv-blender/bin/python), one per process that renders (`shared_worker`),
started on first use: it builds the scene once and updates it per frame. Per frame it is sent an .npz of the posed
surfaces and a JSON request (textures go as PNGs, each written once per pyramid) in a temporary folder, and answers
with a multilayer EXR: Combined (linear, premultiplied, OpenImageDenoise'd; film transparent: alpha is coverage)
and Environment (the world seen through each pixel).
"""

from __future__ import annotations

import atexit
import json
import subprocess
import tempfile
import threading
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import DarthandError, InputError
from darthand.export.blender_engine import BlenderUnavailable, blender_python
from darthand.render.api import frame_background
from darthand.render.camera import Camera
from darthand.render.engines import DEFAULT_CYCLES_SAMPLES, MAX_CYCLES_SAMPLES
from darthand.render.cycles_scene import MaterialFiles, camera_spec, frame_arrays, light_specs, world_spec
from darthand.render.image import compose
from darthand.render.lights import Lighting, load_lighting
from darthand.render.scenes import Scene
from darthand.render.subject import Subject

WORKER = Path(__file__).resolve().parent / "blender" / "cycles_worker.py"
_CHECKED: dict = {}


def check_available() -> Path:
    """The Blender Python the tier runs, after checking once that it imports bpy; InputError, one line, when it
    does not (before anything renders)."""
    try:
        python = blender_python()
    except BlenderUnavailable as e:
        raise InputError(f"--engine cycles: {e}") from None
    if python not in _CHECKED:
        try:
            proc = subprocess.run([str(python), "-c", "import bpy"], capture_output=True, text=True, timeout=300)
            _CHECKED[python] = proc.returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            _CHECKED[python] = False
    if not _CHECKED[python]:
        raise InputError(f"--engine cycles: {python} cannot import bpy (run `make blender`, or set "
                         "DARTHAND_BLENDER_PYTHON to a Python that has it)")
    return python


def check_samples(samples) -> int:
    ok = isinstance(samples, (int, np.integer)) and not isinstance(samples, bool)
    if not (ok and 1 <= samples <= MAX_CYCLES_SAMPLES):
        raise InputError(f"--cycles-samples: {samples!r} is not a whole number in 1..{MAX_CYCLES_SAMPLES}")
    return int(samples)


@dataclass
class CyclesImage:
    """A Cycles render: premult (H, W, 3) float32 linear colour premultiplied by alpha (H, W) float32 coverage;
    environment (H, W, 3) float32 linear, the world seen through each pixel (behind everything); seconds and
    cpu_seconds (all its threads) of the worker's render."""

    premult: np.ndarray
    alpha: np.ndarray
    environment: np.ndarray
    seconds: float
    cpu_seconds: float


class CyclesWorker:
    """The Cycles worker process (module docstring), started on first use; `render` one frame at a time."""

    def __init__(self, python: Path | None = None):
        self.python = python
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()
        self._folder = tempfile.TemporaryDirectory(prefix="darthand-cycles-")
        self.folder = Path(self._folder.name)
        self.materials = MaterialFiles(self.folder / "textures")
        self._frames = 0

    def _start(self) -> subprocess.Popen:
        python = self.python or check_available()
        log = open(self.folder / "blender.log", "w")
        # Its own session: Ctrl-C goes to darthand, which stops after the frame; it ends on its stdin's end.
        self._proc = subprocess.Popen([str(python), str(WORKER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=log, text=True, start_new_session=True)
        log.close()
        return self._proc

    def render(self, subject: Subject, cam: Camera, lighting: Lighting, *, samples: int = DEFAULT_CYCLES_SAMPLES,
               seed: int = 0, threads: int = 1, denoise: bool = True) -> CyclesImage:
        """One frame of the posed subject seen by `cam` under `lighting` (its ambient, lights and environment)."""
        with self._lock:
            n = self._frames = self._frames + 1
            arrays, surfaces = frame_arrays(subject, self.materials)
            npz, exr = self.folder / f"frame{n % 2}.npz", self.folder / f"frame{n % 2}.exr"
            np.savez(npz, **arrays)
            request = {"cmd": "render", "arrays": str(npz), "out": str(exr), "width": cam.width,
                       "height": cam.height, "samples": int(samples), "seed": int(seed) & 0x7FFFFFFF,
                       "threads": int(threads), "denoise": bool(denoise), "camera": camera_spec(cam),
                       "surfaces": surfaces, "lights": light_specs(lighting, cam),
                       "world": world_spec(lighting, cam)}
            answer = self._ask(request)
            premult, alpha, env = read_layers(exr, cam.height, cam.width)
            return CyclesImage(premult, alpha, env, float(answer["seconds"]), float(answer["cpu_seconds"]))

    def _ask(self, request: dict) -> dict:
        proc = self._proc if self._proc is not None and self._proc.poll() is None else self._start()
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(json.dumps(request) + "\n")
            proc.stdin.flush()
            line = proc.stdout.readline()
        except (BrokenPipeError, OSError):
            line = ""
        if not line:
            raise DarthandError(f"Cycles worker ended: {self._log_tail()}")
        answer = json.loads(line)
        if not answer.get("ok"):
            raise DarthandError(f"Cycles: {answer.get('error')}")
        return answer

    def _log_tail(self) -> str:
        try:
            lines = (self.folder / "blender.log").read_text(errors="replace").strip().splitlines()
        except OSError:
            lines = []
        return (lines[-1] if lines else "no output")[:300]

    def close(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            try:
                assert proc.stdin is not None
                proc.stdin.write(json.dumps({"cmd": "quit"}) + "\n")
                proc.stdin.close()
                proc.wait(timeout=30)
            except (OSError, subprocess.TimeoutExpired):
                proc.kill()
                proc.wait()
        self._folder.cleanup()


_SHARED: dict = {}


def shared_worker() -> CyclesWorker:
    """This process's Cycles worker (one per process that renders), closed when the process exits."""
    if "worker" not in _SHARED:
        _SHARED["worker"] = CyclesWorker()
        atexit.register(close_shared_worker)
    return _SHARED["worker"]


def close_shared_worker() -> None:
    worker = _SHARED.pop("worker", None)
    if worker is not None:
        worker.close()


def read_layers(path: Path, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(premult (H, W, 3), alpha (H, W), environment (H, W, 3)) float32 of the worker's multilayer EXR (its
    'Combined' and 'Environment' layers, top row first); premult is 0 where alpha is."""
    layers: dict = {}
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise DarthandError(f"Cycles: no image from the worker ({oiio.geterror()})")
    try:
        index = 0
        while inp.seek_subimage(index, 0):
            names = inp.spec().channelnames
            pixels = inp.read_image(index, 0, 0, len(names), oiio.FLOAT)
            for c, name in enumerate(names):
                layers[name.split(".", 1)[-1]] = np.asarray(pixels)[..., c]
            index += 1
    finally:
        inp.close()
    rgb = lambda layer: np.stack([layers[f"{layer}.{c}"] for c in "RGB"], axis=-1).astype(np.float32)
    premult, alpha, env = rgb("Combined"), layers["Combined.A"].astype(np.float32), rgb("Environment")
    if premult.shape != (height, width, 3):
        raise DarthandError(f"Cycles: image of shape {premult.shape}, expected ({height}, {width}, 3)")
    premult[alpha <= 0] = 0        # the denoiser spreads colour past the silhouette into pixels nothing covers
    return premult, alpha, env


def scene_seed(scene: Scene) -> int:
    """Cycles' sampling seed of a scene: a hash of its job form, so a frame's noise depends only on what it shows
    (a dataset frame's job depends only on (seed, index))."""
    return zlib.crc32(json.dumps(scene.to_job(), sort_keys=True, default=str).encode()) & 0x7FFFFFFF


class CyclesRenderer:
    """A Renderer (render.api) whose images come from Cycles: `render_scene` as Renderer.render_scene, with the
    fast renderer's labels, mask and maps, and Cycles' image (module docstring). samples: Cycles' samples per pixel
    (OpenImageDenoise on); worker: the Cycles process (default: this process's shared one)."""

    def __init__(self, renderer, samples: int = DEFAULT_CYCLES_SAMPLES, worker: CyclesWorker | None = None):
        self.renderer = renderer
        self.samples = check_samples(samples)
        self.worker = worker

    @property
    def source(self):
        return self.renderer.source

    def render_scene(self, scene: Scene, *, background=None, **options):
        """One frame (render.api.Frame) of a scene: labels from the fast renderer, the image from Cycles over the
        same background (`render_scene_image`)."""
        return self.render_scene_image(scene, background=background, **options)[0]

    def render_scene_image(self, scene: Scene, *, background=None, **options) -> tuple:
        """(render.api.Frame, CyclesImage) of a scene: `render_scene`'s frame and Cycles' own layers.

        Both renderers light the frame with the scene's whole lighting, its environment included (the fast one for
        the labels, mask and maps, Cycles for the image). The background is api.frame_background's, as the fast
        renderer composites it: for the environment backdrop ('environment' or {'environment': True, 'blur'}) that
        is the fast renderer's environment.background_view at the same blur under Cycles' image with its alpha, so
        both tiers show the same backdrop pixels (Cycles' film is transparent; its own view of the world is only in
        CyclesImage.environment)."""
        frame = self.renderer.render_scene(scene, background=background, **options)
        if background is None and isinstance(scene.background, str):
            background = scene.background
        lighting = load_lighting(scene.lights)
        worker = self.worker or shared_worker()
        image = worker.render(frame.subject, frame.camera, lighting, samples=self.samples, seed=scene_seed(scene),
                              threads=self.renderer.threads)
        H, W = frame.camera.height, frame.camera.width
        bg, _ = frame_background(background, lighting, frame.camera)
        frame.colour, frame.rgba = compose(np.moveaxis(image.premult, -1, 0), image.alpha, (0, 0), bg, (H, W))
        frame.timings["cycles"] = image.seconds
        frame.stats["cycles_cpu_s"] = image.cpu_seconds
        frame.labels.setdefault("render", {}).update(
            engine="cycles", cycles={"samples": self.samples, "denoiser": "OpenImageDenoise"})
        return frame, image
