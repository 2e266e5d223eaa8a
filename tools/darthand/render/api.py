"""The renderer's top level: `render(...)` one labelled image of a built package; `Renderer` for many (it keeps the
loaded package, textures and the last scene); `write_frame` writes image.png, mask.png, labels.json (+ depth.exr).

A frame: pose the subject (internal forward pass or UsdSkel), frame the camera, build (or reuse) the Embree scene,
trace one sample per pixel inside the scene's projected bounds, light the vertices those samples need with indirect
light (indirect.py), shade with shadows (skin: skin.py), supersample the edge pixels, composite over the
background, label.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.fileio import write_json
from darthand.jit import kernel
from darthand.render import aa, truth
from darthand.render.assets import HandAssets, default_catalogues
from darthand.render.bodies import body_pose, is_group, pose_group
from darthand.render.camera import Camera, load_camera
from darthand.render.environment import (ENVIRONMENT_BACKGROUND, Backdrop, backdrop_blur, backdrop_grid,
                                         frame_environment)
from darthand.render.film import Film, develop_frame
from darthand.render.dress import Dresser, geometry_options, model_coverage
from darthand.render.image import compose, compose_over_grid, encode_mask8, load_background, write_exr, write_png
from darthand.render.indirect import VertexLight
from darthand.render.labels import frame_labels, group_labels
from darthand.render.lights import Lighting, load_lighting, world_lights
from darthand.render.objects import ObjectLibrary
from darthand.render.scene import Scene as TraceScene, scene_for
from darthand.render.scenes import Scene
from darthand.render.shade import ShadingOptions
from darthand.render.subject import Subject
from darthand.render.trace import (Context, Samples, default_threads, pixel_positions, scene_bounds,
                                   single_threaded_blas, tile_pixels, touched_tiles, trace_parallel)

DEFAULT_SAMPLES = aa.DEFAULT_SAMPLES
# Peak memory per image pixel while rendering (measured about 115 bytes at 2048^2 with the hand filling the frame).
BYTES_PER_PIXEL = 200
IMAGE, MASK, LABELS, DEPTH = "image.png", "mask.png", "labels.json", "depth.exr"


@dataclass
class Frame:
    """One rendered frame.

    rgba (H, W, 4) uint8: image.png (sRGB, straight alpha; opaque over a background). colour (H, W, 3) float32
    linear, premultiplied by alpha (composited when a background was given). alpha (H, W) float32 coverage of hand
    and accessory (an arm, render/arm.py, is in rgba's alpha, not in this one: dress.model_coverage). geom (H, W)
    int8 what the pixel centre's ray hit (-1 background, else the subject's surface index: 0 hand, 1 accessory).
    depth (H, W) float32 camera z at pixel centres, 0 for background. labels: the
    labels.json document. timings: seconds per step. stats: ray counts. maps: the per-pixel truth maps asked for
    ({kind: full-frame array}, render/truth.py; empty unless asked).
    """

    rgba: np.ndarray
    colour: np.ndarray
    alpha: np.ndarray
    geom: np.ndarray
    depth: np.ndarray
    labels: dict
    subject: Subject
    camera: Camera
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    maps: dict = field(default_factory=dict)


class Renderer:
    """Renders frames of one source (assets.HandAssets or usd_source.UsdPackage), keeping what does not change.
    sources: {side: source} of the other hands a scene may hold (render_scene; `source` is its side's). objects: the
    object catalogue a scene's held objects come from (render/objects.ObjectLibrary, or a catalogue path; None:
    none)."""

    def __init__(self, source, threads: int | None = None, sources: dict | None = None, objects=None):
        self.source = source
        self.objects = objects if objects is None or isinstance(objects, ObjectLibrary) else ObjectLibrary.load(objects)
        self.sources = {**(sources or {}), source.side: source}
        self.threads = default_threads() if threads is None else max(1, int(threads))
        self._scene: TraceScene | None = None
        self._lights: tuple | None = None
        self._dresser = Dresser()

    def _lighting(self, lights) -> Lighting:
        """load_lighting, remembered for the same argument (validating a lights document costs milliseconds)."""
        import json

        key = json.dumps(lights, sort_keys=True, default=str) if not isinstance(lights, Lighting) else id(lights)
        if isinstance(lights, (str, Path)):
            key = (str(lights), Path(lights).stat().st_mtime_ns if Path(lights).is_file() else None)
        if self._lights is None or self._lights[0] != key:
            self._lights = (key, load_lighting(lights))
        return self._lights[1]

    def render(self, pose=None, *, texture: str | None = None, skin_tone_offset: float = 0.0,
               accessory: str | None = None, camera="three_quarter", lights=None, background=None,
               width: int = 512, height: int = 512, samples: int = DEFAULT_SAMPLES, aa_shading: str = "triangle",
               shading=None, labels: bool = True, keypoint_order: str = "openpose", betas=None,
               maps: tuple = (), film=None, film_seed: int = 0, subdivision: int = 0, arm: float = 0.0) -> Frame:
        """One frame. pose: None (flat), a gesture name, a pose file or (48,) MANO axis-angle (flat-hand relative).
        camera: a Camera, a view name, a camera JSON path or dict (camera.load_camera), framed on the posed hand.
        lights: a Lighting, a lights JSON path or dict, or None (lights.default_lighting). background: image path or
        (H, W, 3) linear array, 'environment' or {'environment': True, 'blur': degrees} (the lights' environment
        map seen through the camera: environment.background_view), or None (transparent). samples: sub-samples
        per edge pixel (1, 4, 8, 16);
        aa_shading: shade them once per pixel per triangle ('triangle') or each ('sample') (see aa.py). shading: a
        shade.ShadingOptions or a dict of its fields (ambient occlusion, skin model), None for the defaults. betas:
        the hand's shape (S,) for a model source (None: the model's own). maps: per-pixel truth maps to compute
        too (render/truth.KINDS: 'depth', 'normals', 'parts'), in Frame.maps. film: a camera's image (render/film.py:
        a Film or a dict of its fields; None: the renderer's own image), its sensor noise seeded by film_seed.
        subdivision: Loop levels of the skin (0, 1, 2; render/subdivision.py); arm: metres of forearm drawn past the
        cut instead of its cap (0: the cap; a model source only; render/arm.py). Neither moves the camera or the
        labels' hand (render/dress.py)."""
        with single_threaded_blas():
            prepared = self._prepare(pose, texture=texture, skin_tone_offset=skin_tone_offset, accessory=accessory,
                                     camera=camera, lights=lights, width=width, height=height,
                                     keypoint_order=keypoint_order, betas=betas, subdivision=subdivision, arm=arm)
            return self._finish(prepared, background=background, samples=samples, aa_shading=aa_shading,
                                shading=shading, labels=labels, maps=maps, film=film, film_seed=film_seed)

    def render_scene(self, scene: Scene, *, background=None, **options) -> Frame:
        """One frame of a scene (render/scenes.py): its hand posed, dressed and shaped as the scene says, seen by its
        camera under its lights. background: pixels or an image path to composite under it (None: the scene's own
        background when it is an image path, else transparent; a dataset resolves its background documents itself).
        options: `render`'s width, height, samples, aa_shading, shading, labels, keypoint_order, maps, film,
        film_seed, subdivision, arm. A scene of several hands (render/bodies.py) poses each with its side's source."""
        if is_group(scene):
            return self._render_group(scene, background, options)
        hand = scene.single_hand()
        if background is None and isinstance(scene.background, str):
            background = scene.background
        return self.render(body_pose(self.source, hand), texture=hand.texture,
                           skin_tone_offset=float(hand.skin_tone_offset), accessory=hand.accessory,
                           camera=scene.camera or "three_quarter", lights=scene.lights, background=background,
                           betas=hand.betas, **options)

    def _render_group(self, scene: Scene, background, options: dict) -> Frame:
        """render_scene of a scene of several hands (render/bodies.py), with `render`'s options."""
        geometry = geometry_options(subdivision=options.pop("subdivision", 0), arm=options.pop("arm", 0.0))
        framing = {"width": options.pop("width", 512), "height": options.pop("height", 512),
                   "keypoint_order": options.pop("keypoint_order", "openpose")}
        with single_threaded_blas():
            timings: dict = {}
            t = time.perf_counter()
            subject, cam = pose_group(scene, self.sources, self.source.side, self._dresser, geometry,
                                      camera=scene.camera or "three_quarter", objects=self.objects, **framing)
            timings["pose"] = _lap(t)
            self._scene = trace_scene = scene_for(subject, self._scene)
            prepared = (subject, trace_scene, cam, self._lighting(scene.lights), timings)
            return self._finish(prepared, background=background, **options)

    def render_many(self, poses, **options) -> Iterator[Frame]:
        """Frames of `poses` (an iterable of what `render` takes as pose), in order, with the other options of
        `render` shared by all. Frame k+1 is posed and its scene built on a helper thread while frame k is traced
        and shaded, so the work outside tracing overlaps it: the loop's throughput, not each frame's latency, is
        what improves. OpenBLAS runs single-threaded while the generator is active (trace.single_threaded_blas).
        Do not call `render` on the same Renderer while iterating: the helper thread owns its caches meanwhile."""
        from concurrent.futures import ThreadPoolExecutor

        finish = {k: options.pop(k) for k in ("background", "samples", "aa_shading", "shading", "labels", "maps",
                                              "film", "film_seed") if k in options}
        poses = iter(poses)
        # The helper is the only thread that calls _prepare (the source's caches and self._scene are not locked).
        with single_threaded_blas(), ThreadPoolExecutor(max_workers=1, thread_name_prefix="darthand-prepare") as helper:
            first = next(poses, _END)
            ahead = None if first is _END else helper.submit(self._prepare, first, **options)
            while ahead is not None:
                prepared = ahead.result()
                following = next(poses, _END)
                ahead = None if following is _END else helper.submit(self._prepare, following, **options)
                yield self._finish(prepared, **finish)

    def _prepare(self, pose, *, texture=None, skin_tone_offset=0.0, accessory=None, camera="three_quarter",
                 lights=None, width=512, height=512, keypoint_order="openpose", betas=None, subdivision=0,
                 arm=0.0) -> tuple:
        """(subject, scene, camera, lighting, timings): the frame's work before tracing."""
        check_skin_tone_offset(skin_tone_offset)
        geometry = geometry_options(subdivision=subdivision, arm=arm)
        if geometry.arm and self.source.kind != "model":
            raise InputError(f"arm: a {self.source.kind} source has no forearm rig to extend (use a model .npz)")
        timings: dict = {}
        t = time.perf_counter()
        shape = {} if betas is None else {"betas": betas}      # a USD package has no shape to change
        shape.update({"arm": geometry.arm} if geometry.arm else {})
        subject = self.source.subject(pose, texture=texture, skin_tone_offset=skin_tone_offset, accessory=accessory,
                                      keypoint_order=keypoint_order, **shape)
        timings["pose"] = _lap(t)
        t = time.perf_counter()
        points = subject.framing_points()
        cam = load_camera(camera, points, width=width, height=height, side=subject.side)
        lighting = self._lighting(lights)
        timings["setup"] = _lap(t)
        if not geometry.is_default:
            t = time.perf_counter()
            subject = self._dresser.dress(subject, cam, geometry)
            timings["dress"] = _lap(t)
        t = time.perf_counter()
        self._scene = scene = scene_for(subject, self._scene)
        timings["scene"] = _lap(t)
        return subject, scene, cam, lighting, timings

    def _finish(self, prepared: tuple, *, background=None, samples: int = DEFAULT_SAMPLES,
                aa_shading: str = "triangle", shading=None, labels: bool = True, maps: tuple = (), film=None,
                film_seed: int = 0) -> Frame:
        subject, scene, cam, lighting, timings = prepared
        return render_subject(subject, scene, cam, lighting, background=background, samples=samples,
                              aa_shading=aa_shading, shading=shading, threads=self.threads, labels=labels,
                              timings=timings, maps=maps, film=film, film_seed=film_seed)


_END = object()


def shading_options(shading) -> ShadingOptions:
    """ShadingOptions from None (the defaults), an instance, or a dict of its fields (InputError naming an unknown
    one)."""
    if shading is None:
        return ShadingOptions()
    if isinstance(shading, ShadingOptions):
        return shading
    if isinstance(shading, dict):
        known = ShadingOptions.__dataclass_fields__
        unknown = sorted(set(shading) - set(known))
        if unknown:
            raise InputError(f"shading: unknown option {unknown[0]!r} (known: {', '.join(known)})")
        return ShadingOptions(**shading)
    raise InputError(f"shading: expected ShadingOptions or a dict, got {type(shading).__name__}")


def render_subject(subject: Subject, scene: TraceScene, cam: Camera, lighting: Lighting, *, background=None,
                   samples: int = DEFAULT_SAMPLES, aa_shading: str = "triangle", shading=None, threads: int = 1,
                   labels: bool = True, timings: dict | None = None, maps: tuple = (), film=None,
                   film_seed: int = 0) -> Frame:
    """Render a posed subject whose scene is built: primary samples in the projected bounds with indirect light at
    the vertices they need (indirect.py), adaptive supersampling of edges (aa.supersample: `samples` sub-samples,
    `aa_shading` 'triangle' or 'sample'), compositing, labels. shading: see `shading_options`. maps: per-pixel
    truth maps to compute from the primary samples (truth.KINDS; none by default, at no cost). film: develop the
    composited colour as a camera would (render/film.py; Frame.colour stays the linear colour, Frame.rgba and
    labels['render']['film'] are the film's), None: the image as composited."""
    timings = {} if timings is None else timings
    aa.check_options(samples, aa_shading)
    maps = truth.check_kinds(maps)
    options = shading_options(shading)
    H, W = cam.height, cam.width
    check_memory(f"rendering a {W}x{H} image", BYTES_PER_PIXEL * W * H)
    stats: dict = {}
    t = time.perf_counter()
    lights = world_lights(lighting, cam.R, cam.t)
    environment = None if lighting.environment is None else frame_environment(lighting.environment, cam.R)
    if environment is not None:
        lights = lights + environment.lights
    indirect = None
    if options.ao_rays:
        indirect = VertexLight(scene, lights, lighting.ambient, options.ao_rays, options.interreflection, stats,
                               environment)
    timings["indirect_setup"] = _lap(t)
    ctx = Context(scene, cam, lights, lighting.ambient, threads, indirect, options.skin, environment,
                  options.skin_specular, float(options.skin_detail), options.shadows)

    t = time.perf_counter()
    r0, r1, c0, c1 = scene_bounds(cam, subject.all_vertices())
    h, w = r1 - r0, c1 - c0
    tiles = touched_tiles(cam, subject.surfaces, (r0, r1, c0, c1))
    traced = tile_pixels(tiles, h, w)
    primary = scatter(trace_parallel(ctx, pixel_positions(traced, r0, c0, w), 1.0, stats), traced, h * w)
    timings["primary"] = _lap(t)
    stats["primary_rays"] = int(len(traced))

    t = time.perf_counter()
    geom = primary.geom.reshape(h, w)
    premult = primary.radiance.reshape(3, h, w)        # zero where nothing was hit
    alpha = (geom >= 0).astype(np.float32)
    edge_count = 0
    if samples > 1 and h and w:
        edges = aa.edge_pixels(geom, primary.depth.reshape(h, w), primary.normal.reshape(3, h, w), cam.K[0, 0])
        where = np.flatnonzero(edges.reshape(-1))
        edge_count = len(where)
        if edge_count:
            colour, cover = aa.supersample(ctx, pixel_positions(where, r0, c0, w), primary.geom[where],
                                           primary.prim[where], primary.radiance[:, where], samples, aa_shading,
                                           stats)
            premult.reshape(3, -1)[:, where] = colour
            alpha.reshape(-1)[where] = cover
    timings["aa"] = _lap(t)
    stats["edge_pixels"] = int(edge_count)
    stats["aa_rays"] = int(edge_count * samples)

    t = time.perf_counter()
    # the environment backdrop's grid is blended in the compositing itself unless a film needs its pixels
    bg, bg_name = frame_background(background, lighting, cam, grid=film is None)
    if isinstance(bg, Backdrop):
        colour, rgba = compose_over_grid(premult, alpha, (r0, c0), bg.grid, bg.axes(), (H, W))
    else:
        colour, rgba = compose(premult, alpha, (r0, c0), bg, (H, W))
    region = (slice(r0, r1), slice(c0, c1))
    full_alpha = np.zeros((H, W), np.float32)
    # the image's alpha keeps an arm; outside the region nothing was hit: the model's coverage is the region's
    full_alpha[region] = model_coverage(alpha, geom, subject.surfaces)
    full_geom = np.full((H, W), -1, np.int8)
    full_geom[region] = geom
    full_depth = np.zeros((H, W), np.float32)
    full_depth[region] = np.where(geom >= 0, primary.depth.reshape(h, w), 0)
    timings["compose"] = _lap(t)
    film_record = None
    if film is not None:
        t = time.perf_counter()
        rgba, film_record = develop_frame(colour, full_alpha, full_depth, Film.from_json(film), film_seed,
                                          lighting, cam, subject.all_vertices().mean(axis=0), bg)
        timings["film"] = _lap(t)
    truth_maps = {}
    if maps:
        t = time.perf_counter()
        truth_maps = truth.truth_maps(maps, subject, cam, primary, (r0, r1, c0, c1), full_depth)
        timings["maps"] = _lap(t)

    t = time.perf_counter()
    doc = {}
    if labels:
        record = {"samples": samples, "aa_shading": aa_shading, "background": bg_name,
                  "lights": lighting.to_json(), "shading": options.to_json(),
                  **({"geometry": subject.info["geometry"]} if subject.info.get("geometry") else {})}
        if film_record is not None:
            record["film"] = film_record
        # A subdivided skin is labelled on the model's own faces (render/dress.py): the plain frame's visibility.
        label_scene = scene if subject.labelled is None else TraceScene(subject.labelled)
        files = {"image": IMAGE, "mask": MASK}
        if subject.members:
            doc = group_labels(subject, cam, label_scene, full_alpha, full_geom, files=files, extra={"render": record})
        else:
            doc = frame_labels(subject, cam, label_scene, full_alpha, files=files, extra={"render": record})
    timings["labels"] = _lap(t)
    stats["total_rays"] = (stats.get("rays", 0) + stats.get("shadow_rays", 0) + stats.get("indirect_rays", 0)
                           + (21 if labels else 0))
    return Frame(rgba, colour, full_alpha, full_geom, full_depth, doc, subject, cam, timings, stats, truth_maps)


def frame_background(background, lighting: Lighting, cam: Camera, grid: bool = False) -> tuple:
    """(pixels (H, W, 3) float32 linear or None, the name labels record or None) of `render`'s background argument:
    the environment seen through `cam` (environment.background_view) for 'environment' or {'environment': True,
    'blur': degrees}, an image path loaded to the camera's size, an array as given, None for none. grid: the
    environment as its environment.Backdrop (looked up on a grid coarser than the pixels) when that grid is
    coarser, in place of its pixels."""
    H, W = cam.height, cam.width
    blur = backdrop_blur(background)
    if blur is not None:
        if lighting.environment is None:
            raise InputError("background: 'environment' needs lights with an environment (--environment)")
        backdrop = backdrop_grid(lighting.environment, cam, blur)
        return backdrop if grid and backdrop.step > 1 else backdrop.pixels(), ENVIRONMENT_BACKGROUND
    if background is None:
        return None, None
    path = isinstance(background, (str, Path))
    bg = load_background(background, W, H) if path else np.asarray(background, np.float32)
    if bg.shape != (H, W, 3):
        raise InputError(f"background: shape {bg.shape} does not match the image ({H}, {W}, 3)")
    return bg, Path(background).name if path else "array"


def scatter(samples: Samples, index: np.ndarray, n: int) -> Samples:
    """Samples of `n` pixels of which those at `index` (ascending) were traced; the others are background."""
    if len(index) == n:
        return samples
    out = Samples(np.empty(n, np.int32), np.empty(n, np.int32), np.empty(n, np.float32),
                  np.empty((3, n), np.float32), np.empty((3, n), np.float32))
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    _scatter_kernel(np.ascontiguousarray(index, np.int64), np.ascontiguousarray(samples.geom, np.int32),
                    np.ascontiguousarray(samples.prim, np.int32), f32(samples.depth), f32(samples.normal),
                    f32(samples.radiance), out.geom, out.prim, out.depth, out.normal, out.radiance)
    return out


@kernel
def _scatter_kernel(index, geom, prim, depth, normal, radiance, out_geom, out_prim, out_depth, out_normal,
                    out_radiance):
    """`scatter` in one pass over the n outputs: traced sample k goes to pixel index[k] (ascending), every other
    pixel is background (geom, prim -1, depth inf, normal and radiance 0)."""
    k = 0
    for i in range(out_geom.shape[0]):
        if k < index.shape[0] and index[k] == i:
            out_geom[i], out_prim[i], out_depth[i] = geom[k], prim[k], depth[k]
            for c in range(3):
                out_normal[c, i] = normal[c, k]
                out_radiance[c, i] = radiance[c, k]
            k += 1
        else:
            out_geom[i], out_prim[i], out_depth[i] = -1, -1, np.float32(np.inf)
            for c in range(3):
                out_normal[c, i] = np.float32(0.0)
                out_radiance[c, i] = np.float32(0.0)


def write_frame(frame: Frame, out_dir: str | Path, *, depth: bool = False, names: dict | None = None) -> dict:
    """Write image.png (RGBA), mask.png (8-bit coverage), labels.json (and depth.exr, camera z in metres, 0 for
    background) into `out_dir`; returns {kind: path}. names: other file names for some kinds ('image', 'mask',
    'labels', 'depth'), relative paths under `out_dir` (e.g. {'image': 'images/000042.png'}); labels.json's
    'files' then gives the image, mask and depth paths relative to the labels file's folder. Adds the write time to
    frame.timings['write']."""
    t = time.perf_counter()
    out = Path(out_dir)
    names = {"image": IMAGE, "mask": MASK, "labels": LABELS, "depth": DEPTH, **(names or {})}
    paths = {kind: out / names[kind] for kind in ("image", "mask", "labels") + (("depth",) if depth else ())}
    write_png(paths["image"], frame.rgba)
    write_png(paths["mask"], encode_mask8(frame.alpha), srgb=False)
    if depth:
        write_exr(paths["depth"], frame.depth)
    labels = dict(frame.labels)
    labels["files"] = {**labels.get("files", {}), **{
        kind: os.path.relpath(path, paths["labels"].parent) for kind, path in paths.items() if kind != "labels"}}
    write_json(paths["labels"], labels)
    frame.timings["write"] = _lap(t)
    return paths


class FrameWriter:
    """Writes frames on a background thread while the next ones render (image.write_png's zlib compression releases
    the GIL). At most `pending` frames wait; `close()` (or leaving the `with` block) waits for all and re-raises the
    first error."""

    def __init__(self, pending: int = 2):
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="darthand-write")
        self._futures: deque = deque()
        self.pending = max(1, int(pending))

    def submit(self, frame: Frame, out_dir: str | Path, *, depth: bool = False):
        while len(self._futures) >= self.pending:
            self._futures.popleft().result()
        future = self._pool.submit(write_frame, frame, out_dir, depth=depth)
        self._futures.append(future)
        return future

    def close(self) -> None:
        try:
            while self._futures:
                self._futures.popleft().result()
        finally:
            self._pool.shutdown(wait=True)

    def __enter__(self) -> "FrameWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_source(package, *, textures=None, accessories=None, model=None):
    """The frame source of PACKAGE: a USD package (its folder or interface .usda/.usd) -> usd_source.UsdPackage;
    a model (.npz, .pkl, 'open', 'right'/'left' for build/model/<side>.npz) -> assets.HandAssets with the texture
    and accessory catalogues (default: the build's, next to build/model/)."""
    path = Path(str(package))
    if path.is_dir() and os.path.lexists(path / "asset.json") or path.suffix in (".usda", ".usd", ".usdc"):
        from darthand.render.usd_source import UsdPackage  # lazy: OpenUSD takes 0.6 s to import, for packages only

        return UsdPackage.open(path, model=model)
    if str(package) in ("right", "left"):
        path = Path("build") / "model" / f"{package}.npz"
        if not path.is_file():
            raise InputError(f"{path}: not built yet (run `make assets` or `darthand model build`)")
        package = path
    if Path(str(package)).suffix == ".npz" and Path(str(package)).is_file():
        tex, acc = default_catalogues(package)
        textures = tex if textures is None else textures
        accessories = acc if accessories is None else accessories
    return HandAssets.load(package, textures or None, accessories or None)


def render(package, pose=None, **options) -> Frame:
    """One frame of PACKAGE (see `open_source`); options as `Renderer.render` plus textures=, accessories=
    (catalogue paths for the internal path), model= (for a USD package without fingertip ids) and threads=."""
    source_opts = {k: options.pop(k) for k in ("textures", "accessories", "model") if k in options}
    threads = options.pop("threads", None)
    return Renderer(open_source(package, **source_opts), threads).render(pose, **options)


def check_skin_tone_offset(offset) -> None:
    """The sRGB skin-tone offset must be a number in [-1, 1] (beyond it every channel saturates)."""
    if not (isinstance(offset, (int, float, np.number)) and -1 <= offset <= 1):
        raise InputError(f"skin_tone_offset: {offset!r} is not a number in [-1, 1]")


def _lap(t0: float) -> float:
    return time.perf_counter() - t0
