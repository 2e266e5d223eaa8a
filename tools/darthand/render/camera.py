"""Pinhole cameras: intrinsics K, world -> camera extrinsics, look-at, auto-framed named views, projection, rays.

Conventions (schemas/camera.schema.json, schemas/labels.schema.json):

- World frame: the model's frame (MANO canonical, metres; a left hand is the x -> -x mirror of a right one).
- Camera frame: OpenCV's, x right, y down, z forward (the viewing direction); X_cam = R X_world + t.
- Pixels: continuous image coordinates (u, v), u to the right, v down, origin at the top-left CORNER of the image;
  pixel (row r, column c) covers [c, c + 1) x [r, r + 1) and its centre is (c + 0.5, r + 0.5). A point projects to
  (u, v, 1) ~ K X_cam. (OpenCV's pixel centres are at integers: subtract 0.5 from u and v to convert.)
- Rays: the direction of pixel position (u, v) is R^T K^-1 (u, v, 1), whose camera-frame z is 1, so a ray
  parameter t is the camera depth z of the point it reaches.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.model.preview import VIEWS, camera_basis
from darthand.schemas import check_schema

DEFAULT_FOV_DEG = 30.0
DEFAULT_MARGIN = 0.08
MAX_MAGNITUDE = 1e9      # largest entry of K (pixels) and t (metres): beyond it projections stop being finite
MAX_SIDE = 1 << 20       # image side in pixels (the memory budget refuses far less)
MIN_FOCAL_PX = 1e-3      # smallest focal length in pixels: ray directions stay finite in float32


@dataclass(frozen=True, eq=False)
class Camera:
    """K (3, 3) intrinsics in pixels, R (3, 3) and t (3,) world -> camera, image size in pixels."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        for name, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            object.__setattr__(self, name, checked_field(name, getattr(self, name), shape))
        if not (np.abs(self.R @ self.R.T - np.eye(3)).max() < 1e-6 and np.linalg.det(self.R) > 0):
            raise InputError("camera: field 'R' is not a rotation matrix")
        check_intrinsics(self.K)
        if not (1 <= int(self.width) <= MAX_SIDE and 1 <= int(self.height) <= MAX_SIDE):
            raise InputError(f"camera: image size {self.width}x{self.height} is outside 1..{MAX_SIDE} pixels a side")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @property
    def centre(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return -self.R.T @ self.t

    @property
    def extrinsics(self) -> np.ndarray:
        """(4, 4) world -> camera transform [R t; 0 1]."""
        E = np.eye(4)
        E[:3, :3], E[:3, 3] = self.R, self.t
        return E

    def to_camera(self, points) -> np.ndarray:
        """(N, 3) world points -> camera coordinates (metres)."""
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.t

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> pixel positions (N, 2) (u, v) and camera depths z (N,)."""
        return project_rotated(np.asarray(points, dtype=np.float64) @ self.R.T, self.t, self.K)

    def directions(self, uv) -> np.ndarray:
        """(N, 3) float64 world ray directions through pixel positions uv (N, 2), scaled so camera z = 1."""
        uv = np.asarray(uv, dtype=np.float64)
        d = np.linalg.solve(self.K, np.stack([uv[:, 0], uv[:, 1], np.ones(len(uv))])).T
        return d @ self.R

    def direction_derivatives(self) -> tuple[np.ndarray, np.ndarray]:
        """d(direction)/du and d(direction)/dv (3,) each, world frame: constant for a pinhole camera."""
        Kinv = np.linalg.inv(self.K)
        return Kinv[:, 0] @ self.R, Kinv[:, 1] @ self.R

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "K": self.K.tolist(), "R": self.R.tolist(),
                "t": self.t.tolist()}


def checked_field(name: str, value, shape: tuple) -> np.ndarray:
    """`value` as a float64 array, or InputError unless it has `shape` and entries within +-MAX_MAGNITUDE."""
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape or not (np.abs(a) <= MAX_MAGNITUDE).all():
        raise InputError(f"camera: field '{name}' must be finite (within +-{MAX_MAGNITUDE:g}) with shape {shape}, "
                         f"got {a.shape}")
    return a


def check_intrinsics(K: np.ndarray) -> None:
    """InputError unless K (3, 3) is upper triangular with K[2,2] = 1 and focal lengths of at least MIN_FOCAL_PX
    pixels (a smaller one makes ray directions overflow float32, and zero divides by zero when framing)."""
    if (not K[0, 0] >= MIN_FOCAL_PX or not K[1, 1] >= MIN_FOCAL_PX or K[2, 2] != 1 or K[1, 0] or K[2, 0]
            or K[2, 1]):
        raise InputError(f"camera: field 'K' must be upper triangular with focal lengths of at least {MIN_FOCAL_PX:g} "
                         "pixel and K[2,2] = 1")


def point_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (D,) per-coordinate minimum and maximum of points (N, D), in their dtype. Column by column: numpy's
    min(axis=0) over a few columns takes 10-20x longer (150 us for 5,000 2-D points), and frames call this a dozen
    times."""
    pts = np.asarray(points)
    lo = np.array([pts[:, k].min() for k in range(pts.shape[1])], pts.dtype)
    hi = np.array([pts[:, k].max() for k in range(pts.shape[1])], pts.dtype)
    return lo, hi


def intrinsics(width: int, height: int, fov_deg: float | None = None, focal_px: float | None = None) -> np.ndarray:
    """(3, 3) K with square pixels, the principal point at the image centre (width/2, height/2) and the focal
    length `focal_px` or the one giving a field of view of `fov_deg` across the smaller image side."""
    if focal_px is None:
        fov = DEFAULT_FOV_DEG if fov_deg is None else float(fov_deg)
        if not 0.1 <= fov <= 170:
            raise InputError(f"camera: fov_deg {fov} is outside 0.1..170")
        focal_px = 0.5 * min(width, height) / np.tan(np.deg2rad(fov) / 2)
    if not focal_px > 0:
        raise InputError(f"camera: focal_px must be positive, got {focal_px}")
    return np.array([[focal_px, 0.0, width / 2], [0.0, focal_px, height / 2], [0.0, 0.0, 1.0]])


def look_at_rotation(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(3, 3) world -> camera rotation of a camera at `eye` looking at `target`, `up` pointing up in the image."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    forward = target - eye
    if np.linalg.norm(forward) < 1e-12:
        raise InputError("camera: look_at eye and target coincide")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        raise InputError("camera: look_at 'up' is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(forward, right), forward])   # rows x (right), y (down), z (forward)


def look_at(eye, target, up=(0.0, 1.0, 0.0), *, width: int = 512, height: int = 512, fov_deg: float | None = None,
            focal_px: float | None = None) -> Camera:
    """A camera at `eye` (world, metres) looking at `target`."""
    R = look_at_rotation(eye, target, up)
    return Camera(intrinsics(width, height, fov_deg, focal_px), R, -R @ np.asarray(eye, np.float64), width, height)


def view_direction(view) -> np.ndarray:
    """Unit direction from the hand toward the camera, in a right hand's frame, for a named view (preview.VIEWS)
    or a 3-vector (checked)."""
    if isinstance(view, str):
        if view not in VIEWS:
            raise InputError(f"camera: unknown view {view!r} (known: {', '.join(VIEWS)})")
        d = np.array(VIEWS[view], dtype=np.float64)
    else:
        d = np.asarray(view, dtype=np.float64)
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise InputError("camera: field 'view' must be a view name or a non-zero 3-vector")
    return d / np.linalg.norm(d)


def frame_points(points, view="three_quarter", *, width: int = 512, height: int = 512, fov_deg: float | None = None,
                 margin: float = DEFAULT_MARGIN, distance: float | None = None, side: str = "right",
                 roll_deg: float = 0.0, K=None, keep_in_frame: bool = False) -> Camera:
    """A camera looking at `points` (N, 3) from `view`, fingers up in the image, placed so that their projection
    fills the frame up to `margin` (fraction of the smaller side) on the tighter axis and is centred (or at
    `distance` metres from their centre; with keep_in_frame, at least as far as the fitting distance for `margin`,
    so the points stay inside the frame). The view is given for a right hand and mirrored (x -> -x) for a left one
    (preview.camera_basis), so that both hands are seen alike."""
    if distance is not None and keep_in_frame:
        options = dict(width=width, height=height, fov_deg=fov_deg, margin=margin, side=side, roll_deg=roll_deg, K=K)
        fit = frame_points(points, view, **options)
        pts = np.asarray(points, np.float64)
        fit_distance = float(fit.to_camera(0.5 * np.add(*point_bounds(pts))[None])[0, 2])
        return fit if fit_distance >= float(distance) else frame_points(points, view, distance=distance, **options)
    pts = np.asarray(points, dtype=np.float64)
    basis = camera_basis(view_direction(view), side=side)           # rows right, up, forward
    R = np.stack([basis[0], -basis[1], basis[2]])
    if roll_deg:
        c, s = np.cos(np.deg2rad(roll_deg)), np.sin(np.deg2rad(roll_deg))
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ R
    K = intrinsics(width, height, fov_deg) if K is None else np.asarray(K, dtype=np.float64)
    centre = 0.5 * np.add(*point_bounds(pts))
    radius = float(np.linalg.norm(pts - centre, axis=1).max()) or 1e-3
    half = np.arctan(0.5 * min(width / K[0, 0], height / K[1, 1]))
    d = radius / np.sin(half) if distance is None else float(distance)
    target = centre
    Camera(K, R, -R @ (target - d * R[2]), width, height)       # R and K checked once: only t changes below
    rotated = pts @ R.T
    middle = middle_rows(rotated[:, 2])
    for _ in range(1 if distance is not None else 4):
        eye = target - d * R[2]
        uv, z = project_rotated(rotated, checked_field("t", -R @ eye, (3,)), K)
        if (z <= 0).any():
            d *= 2
            continue
        lo, hi = point_bounds(uv)
        # Recentre: move the target by the pixel offset of the projection's centre, at the points' depth.
        depth = np.median(z) if middle is None else np.mean(z[middle])         # np.median's own numbers
        shift = (0.5 * (lo + hi) - K[:2, 2]) / K[[0, 1], [0, 1]] * float(depth)
        target = target + shift[0] * R[0] + shift[1] * R[1]
        if distance is None:
            fill = max((hi - lo)[0] / width, (hi - lo)[1] / height)
            d *= fill / (1 - 2 * margin)
    eye = target - d * R[2]
    return Camera(K, R, -R @ eye, width, height)


def middle_rows(values: np.ndarray) -> np.ndarray | None:
    """Indices of the middle value (odd count) or two middle values (even) of `values` (N,) in sorted order, the ones
    np.median averages; None for NaN values or none. A depth z = r + t_z of every point moved by one t_z keeps that
    order (rounding never swaps two sums), so the framing's four medians are np.mean(z[middle]) with one partition."""
    n = len(values)
    if n == 0 or np.isnan(values).any():
        return None
    kth = [n // 2] if n % 2 else [n // 2 - 1, n // 2]
    return np.argpartition(values, kth)[kth]


def project_rotated(rotated: np.ndarray, t: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera.project of points whose rotation into the camera, points @ R.T (N, 3), is given: the same pixel
    positions (N, 2) and depths (N,), bit for bit, when a camera moves along its axes and keeps R."""
    X = rotated + t
    uvw = X @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        return uvw[:, :2] / uvw[:, 2:3], X[:, 2]


# ------------------------------------------------------------------------------------------------ camera files


def load_camera(spec, points=None, *, width: int | None = None, height: int | None = None, side: str = "right",
                source: str = "camera") -> Camera:
    """A camera from a spec: a view name ('three_quarter', 'dorsal', ...), a JSON file path, or its dict
    (schemas/camera.schema.json). Views and {"view": ...} specs are framed on `points` (N, 3).

    JSON forms (width/height optional, default 512 or the given width/height):
        {"K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "R": [[...]], "t": [...]}       explicit world -> camera
        {"fov_deg": 30, "look_at": {"eye": [...], "target": [...], "up": [...]}}    or "focal_px" for the lens
        {"fov_deg": 30, "view": "dorsal" | [x, y, z], "distance": 0.5, "margin": 0.08, "roll_deg": 0}
    A view with both distance and margin is placed at the distance or farther, keeping the hand inside the margin.
    """
    if isinstance(spec, Camera):
        return spec
    if isinstance(spec, (str, Path)) and str(spec) in VIEWS:
        spec, source = {"view": str(spec)}, f"camera view {spec}"
    elif isinstance(spec, (str, Path)):
        path = Path(spec)
        spec, source = read_json(path, f"camera file, and not a view name ({', '.join(VIEWS)})"), str(path)
    _validate(spec, source)
    w = int(spec.get("width", width or 512))
    h = int(spec.get("height", height or 512))
    if "K" in spec:
        K = np.asarray(spec["K"], dtype=np.float64)
        check_intrinsics(K)                   # before framing divides by its focal lengths
    else:
        K = intrinsics(w, h, spec.get("fov_deg"), spec.get("focal_px"))
    if "R" in spec:
        return Camera(K, np.asarray(spec["R"]), np.asarray(spec["t"]), w, h)
    if "look_at" in spec:
        la = spec["look_at"]
        R = look_at_rotation(la["eye"], la["target"], la.get("up", (0.0, 1.0, 0.0)))
        return Camera(K, R, -R @ np.asarray(la["eye"], np.float64), w, h)
    if points is None:
        raise InputError(f"{source}: a 'view' camera needs the posed hand to frame")
    return frame_points(points, spec["view"], width=w, height=h, margin=float(spec.get("margin", DEFAULT_MARGIN)),
                        distance=spec.get("distance"), side=side, roll_deg=float(spec.get("roll_deg", 0.0)), K=K,
                        keep_in_frame="distance" in spec and "margin" in spec)


def _validate(spec, source: str) -> None:
    check_schema(spec, "camera.schema.json", source)
