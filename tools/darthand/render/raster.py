"""Camera visibility by rasterisation: the closest hit of each camera sample without a ray query.

Every camera ray leaves the camera centre, so which triangle it meets first is a rasterisation question: project
each posed surface's vertices into the image (surfaces in the world frame Embree sees: a rigid accessory's world
vertices), cover the samples inside each projected triangle, keep the nearest. The samples are any pixel
positions (trace.intersect_samples': the pixel centres of the traced tiles, or an edge pixel's sub-samples, each
offset of aa.sample_offsets a shifted grid); they are bucketed by the pixel they lie in (without a sort when
they come in pixel order, as both do), and a triangle visits, row by row, the buckets of the pixels its outline
spans (faces sorted by their top row, so the samples' memory is walked top to bottom).

Coverage is decided in the image plane with edge functions in float64, with the top-left rule for samples exactly
on an edge (Direct3D's: a sample on an edge shared by two triangles, or on a vertex shared by a fan, is covered by
one of them). Each edge's function is evaluated with its endpoints in one canonical order (the smaller projected
point first), so the two triangles of a shared edge compute the same number and the tie rule decides. Depth and
barycentrics are those of the ray through the sample and the triangle's plane (Moeller-Trumbore), from the same
float32 ray direction trace._directions_kernel gives Embree, in float64: the camera centre is a metre or less
from the hand and the triangles are millimetres wide, so float32 differences of camera-relative positions would
add errors of 1e-4 to the barycentrics, which float64 keeps at 1e-12; what remains against Embree is Embree's own
float32 rounding. u, v: hit = (1 - u - v) v0 + u v1 + v v2 over faces[prim] (Embree's); depth: the ray parameter
along the camera-z = 1 direction, the hit's camera z (Embree's tfar). Between surfaces the nearer hit wins; at an
exact tie, the surface rasterised first (the lower index), and within a surface the lower face.

A face reaching behind the camera (the arm going on past it) is clipped at the near limit NEAR (camera z): its
part in front, projected, is a triangle or a quad, fanned into triangles; the part within NEAR of the camera plane
(a nanometre) is left out, and a face wholly behind is skipped (no camera ray reaches it). The depth and
barycentrics stay the whole face's. Rasterising applies when every vertex of every surface is finite and the
camera is render/camera.Camera (a pinhole with an upper-triangular K: straight lines stay straight in the image);
otherwise `camera_hits` returns None and the caller asks Embree. Shadow, occlusion and indirect rays always go to
Embree.

The switch is ENABLED (on by default; off: every camera ray goes to Embree, as before the rasteriser:
benchmarks/render_raster.py compares the two).
"""

from __future__ import annotations

import numpy as np

from darthand.jit import inlined, kernel
from darthand.render.camera import Camera
from darthand.render.scene import Scene

ENABLED = True           # rasterise camera samples (trace.intersect_samples); off: Embree's (tests, benchmarks)
NEAR = 1e-9              # metres of camera z: faces are clipped there (trace.touched_tiles' limit)
TINY = 5e-324            # the smallest positive double: e > 0 is e >= TINY
HIDDEN_MARGIN = 1e-3     # share of depth below a face's nearest corner that rounding cannot reach (_hidden_depth)
TILE = 8                 # pixels: the blocks whose farthest sample decides whether a face is hidden


def camera_hits(scene: Scene, camera: Camera, uv: np.ndarray, directions: np.ndarray) -> tuple | None:
    """(geom (N,) int32 surface index or -1, prim (N,) int32 (-1 background), u, v (N,) float32 Embree's
    barycentrics (0 for background), depth (N,) float32 camera z (inf for background)) of the camera samples at
    pixel positions uv (N, 2) float64, whose ray directions (3, N) float32 (camera z = 1) are given; None when
    rasterising is off or does not apply (see the module docstring; or the scene has no surface): ask Embree."""
    if not ENABLED or type(camera) is not Camera or not scene.surfaces:
        return None
    mesh = SceneMesh.of(scene)
    P = camera.K @ np.hstack([camera.R, camera.t[:, None]])
    projected = mesh.project(P)
    if projected is None:
        return None
    xy, z = projected
    n = len(uv)
    geom, prim = np.empty(n, np.int32), np.empty(n, np.int32)
    u, v, depth = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)
    if not n:
        return geom, prim, u, v, depth
    grid = SampleGrid(uv, directions)
    origin = camera.centre.astype(np.float32).astype(np.float64)
    nearest, face = np.full(n, np.inf, np.float64), np.full(n, -1, np.int64)
    _cover_kernel(xy, z, P, NEAR, mesh.vertices, mesh.faces, grid.face_order(xy, mesh.faces), origin, grid.xy,
                  grid.directions, grid.x0, grid.y0, grid.width, grid.height, grid.start, grid.row_band, nearest, face)
    _barycentrics_kernel(mesh.vertices, mesh.faces, mesh.surface, mesh.first, origin, grid.directions, grid.order,
                         face, nearest, geom, prim, u, v, depth)
    return geom, prim, u, v, depth


class SceneMesh:
    """A scene's surfaces as one mesh in the world frame Embree sees (a rigid surface's world vertices): vertices
    (V, 3) float32, faces (F, 3) int64 into them, surface (F,) int32 each face's surface index, first (S,) int64
    the first face of each surface (a face's index in its surface is f - first[surface[f]]). The last one built is
    kept: a frame's primary samples and its edge sub-samples share it."""

    _last: tuple = ((), None)

    def __init__(self, surfaces):
        counts = [len(s.vertices) for s in surfaces]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.vertices = np.ascontiguousarray(np.concatenate([s.vertices for s in surfaces]), np.float32)
        self.faces = np.ascontiguousarray(np.concatenate([np.asarray(s.faces, np.int64) + offsets[k]
                                                          for k, s in enumerate(surfaces)]), np.int64)
        sizes = [len(s.faces) for s in surfaces]
        self.surface = np.repeat(np.arange(len(surfaces), dtype=np.int32), sizes)
        self.first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)

    @classmethod
    def of(cls, scene: Scene) -> "SceneMesh":
        """The mesh of the scene's surfaces, built again only when their vertex or face arrays changed."""
        key = tuple(a for s in scene.surfaces for a in (s.vertices, s.faces))
        last_key, mesh = cls._last
        if mesh is None or len(last_key) != len(key) or any(a is not b for a, b in zip(key, last_key)):
            mesh = cls(scene.surfaces)
            cls._last = (key, mesh)
        return mesh

    def project(self, P: np.ndarray) -> tuple | None:
        """(xy (V, 2) float64 pixel positions of the vertices under P = K [R | t] (3, 4) (NaN for a vertex at or
        behind NEAR), z (V,) float64 their camera z), or None when a vertex is not finite."""
        xy = np.empty((len(self.vertices), 2), np.float64)
        z = np.empty(len(self.vertices), np.float64)
        return (xy, z) if _project_kernel(self.vertices, P, NEAR, xy, z) else None


@kernel
def _project_kernel(vertices, P, near, xy, z):
    """xy (V, 2) the pixel positions of vertices (V, 3) float32 under P = K [R | t] (3, 4) and z (V,) their camera z
    (P's last row: K[2] = (0, 0, 1)), in float64; xy NaN where z is at or below `near`. False (the outputs partly
    written) as soon as a vertex or its projection is not finite."""
    for i in range(vertices.shape[0]):
        x, y, w = np.float64(vertices[i, 0]), np.float64(vertices[i, 1]), np.float64(vertices[i, 2])
        z[i] = P[2, 0] * x + P[2, 1] * y + P[2, 2] * w + P[2, 3]
        if not (np.isfinite(x + y + w) and np.isfinite(z[i])):
            return False
        if z[i] <= near:
            xy[i, 0], xy[i, 1] = np.nan, np.nan
            continue
        xy[i, 0] = (P[0, 0] * x + P[0, 1] * y + P[0, 2] * w + P[0, 3]) / z[i]
        xy[i, 1] = (P[1, 0] * x + P[1, 1] * y + P[1, 2] * w + P[1, 3]) / z[i]
        if not (np.isfinite(xy[i, 0]) and np.isfinite(xy[i, 1])):
            return False
    return True


class SampleGrid:
    """Samples at pixel positions uv (N, 2) grouped by the pixel they lie in (floor of each coordinate), over the
    box of pixels [x0, x0 + width) x [y0, y0 + height) that holds them, each pixel's samples side by side in
    memory, in pixel order (row-major over the box, then ascending sample index): column j is the sample order[j]
    (`order` (N,) int64; empty when that is j itself: the samples came in pixel order, as pixel centres and edge
    sub-samples do), `xy` (2, N) float64 its position as the ray saw it (rounded to float32, as
    trace._directions_kernel does) and `directions` (3, N) float32 its ray's direction (the given array itself when
    `order` is empty); the columns of pixel (r, c) of the box are start[r * width + c]:start[r * width + c + 1].
    One row a quantity: a face's test of a run of samples reads contiguous vectors. row_band (2, height): the
    least and the greatest y of each pixel row's samples (NaN for none); equal where they all share it (pixel
    centres). N >= 1."""

    def __init__(self, uv: np.ndarray, directions: np.ndarray):
        n = len(uv)
        uv = np.ascontiguousarray(uv, np.float64)
        directions = np.ascontiguousarray(directions, np.float32)
        box = np.empty(4, np.int64)
        in_order = _box_kernel(uv, box)
        self.x0, self.y0 = int(box[0]), int(box[1])
        self.width, self.height = int(box[2] - box[0] + 1), int(box[3] - box[1] + 1)
        self.start = np.empty(self.width * self.height + 1, np.int32)
        self.xy = np.empty((2, n), np.float64)
        self.row_band = np.empty((2, self.height), np.float64)
        if in_order:
            self.order, self.directions = np.empty(0, np.int64), directions
            _runs_kernel(uv, self.x0, self.y0, self.width, self.start, self.xy)
        else:
            self.order, self.directions = np.empty(n, np.int64), np.empty((3, n), np.float32)
            self.start[:] = 0
            _bucket_kernel(uv, directions, self.x0, self.y0, self.width, self.start, self.order, self.xy,
                           self.directions)
        _row_band_kernel(self.xy, self.start, self.width, self.row_band)

    def face_order(self, xy: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(F,) int64 the faces (F, 3) of vertices at pixel positions xy (V, 2) by their top pixel row in the box
        (a counting sort, stable): the faces then walk the samples' memory top to bottom, in cache."""
        order = np.empty(len(faces), np.int64)
        _face_order_kernel(xy, faces, self.y0, self.height, order)
        return order


@kernel
def _box_kernel(uv, box):
    """box (4,) int64: the smallest and largest pixel column and row (x0, y0, x1, y1) holding the float32-rounded
    positions uv (N >= 1, 2). Returns whether the samples come in pixel order (row, then column, never down)."""
    in_order, previous = True, np.int64(0)
    for i in range(uv.shape[0]):
        c = np.int64(np.floor(np.float32(uv[i, 0])))
        r = np.int64(np.floor(np.float32(uv[i, 1])))
        if i > 0 and (r < box[3] or (r == box[3] and c < previous)):
            in_order = False
        previous = c
        if i == 0 or c < box[0]:
            box[0] = c
        if i == 0 or r < box[1]:
            box[1] = r
        if i == 0 or c > box[2]:
            box[2] = c
        if i == 0 or r > box[3]:
            box[3] = r
    return in_order


@kernel
def _runs_kernel(uv, x0, y0, width, start, xy):
    """SampleGrid's start and xy of samples uv (N, 2) that come in pixel order (order: the identity)."""
    b = 0                                # the next pixel whose first column is not yet known
    for i in range(uv.shape[0]):
        x, y = np.float32(uv[i, 0]), np.float32(uv[i, 1])
        pixel = (np.int64(np.floor(y)) - y0) * width + np.int64(np.floor(x)) - x0
        while b <= pixel:
            start[b] = i
            b += 1
        xy[0, i], xy[1, i] = x, y
    for k in range(b, start.shape[0]):
        start[k] = uv.shape[0]


@kernel
def _bucket_kernel(uv, directions, x0, y0, width, start, order, xy, sorted_directions):
    """SampleGrid's start (zeros on entry), order, xy and directions by a counting sort of the samples uv (N, 2)
    by pixel (directions (3, N) theirs, in input order)."""
    n = uv.shape[0]
    pixel = np.empty(n, np.int64)
    for i in range(n):
        pixel[i] = ((np.int64(np.floor(np.float32(uv[i, 1]))) - y0) * width
                    + np.int64(np.floor(np.float32(uv[i, 0]))) - x0)
        start[pixel[i]] += 1
    for b in range(1, start.shape[0]):
        start[b] += start[b - 1]     # start[b]: the end of pixel b's samples, until the fill below moves it back
    for i in range(n - 1, -1, -1):  # backwards, so each pixel's samples stay in ascending index
        start[pixel[i]] -= 1
        j = start[pixel[i]]
        order[j] = i
        xy[0, j], xy[1, j] = np.float32(uv[i, 0]), np.float32(uv[i, 1])
        for c in range(3):
            sorted_directions[c, j] = directions[c, i]


@kernel
def _row_band_kernel(xy, start, width, row_band):
    """row_band (2, height): the least and greatest y (xy (2, N) row 1) of the samples of each pixel row of the
    box (start: its pixels' columns), NaN for a row without samples."""
    for r in range(row_band.shape[1]):
        a, b = start[r * width], start[(r + 1) * width]
        lo = hi = xy[1, a] if a < b else np.nan
        for j in range(a + 1, b):
            lo, hi = min(lo, xy[1, j]), max(hi, xy[1, j])
        row_band[0, r], row_band[1, r] = lo, hi


@kernel
def _face_order_kernel(xy, faces, y0, height, order):
    """order (F,): the faces by the box row (clipped to 0 .. height - 1) of their highest corner, stable."""
    count = np.zeros(height + 1, np.int64)
    rows = np.empty(faces.shape[0], np.int64)
    for f in range(faces.shape[0]):
        r = np.floor(min(xy[faces[f, 0], 1], xy[faces[f, 1], 1], xy[faces[f, 2], 1])) - y0
        rows[f] = np.int64(min(max(r, 0.0), height - 1.0)) if r == r else 0      # NaN: a corner behind the camera
        count[rows[f] + 1] += 1
    for r in range(1, height + 1):
        count[r] += count[r - 1]
    for f in range(faces.shape[0]):
        order[count[rows[f]]] = f
        count[rows[f]] += 1


@inlined(always=True)
def _cover_run(xy, directions, a, b, y, edges, nx, ny, nz, nd0, f, nearest, face):
    """Columns a .. b - 1 of a SampleGrid's samples (xy (2, N), directions (3, N)) against one triangle: its edges
    (3, 6) (p, the inside-signed q - p, the tie threshold), its plane (normal nx, ny, nz; nd0 the normal's dot with
    a corner from the ray origin) and index f. A covered sample whose ray meets the plane nearer than nearest[j]
    (N,), or as near and f < face[j] (N,), takes it. y: the run's shared sample y, or NaN (each sample's own)."""
    p0x, p0y, d0x, d0y, h0 = edges[0, 0], edges[0, 1], edges[0, 2], edges[0, 3], edges[0, 4]
    p1x, p1y, d1x, d1y, h1 = edges[1, 0], edges[1, 1], edges[1, 2], edges[1, 3], edges[1, 4]
    p2x, p2y, d2x, d2y, h2 = edges[2, 0], edges[2, 1], edges[2, 2], edges[2, 3], edges[2, 4]
    y0, y1, y2 = d0x * (y - p0y), d1x * (y - p1y), d2x * (y - p2y)
    xs, ys = xy[0], xy[1]
    for j in range(a, b):
        if y == y:                   # the same products as below: ys[j] is y
            e0 = y0 - d0y * (xs[j] - p0x)
            e1 = y1 - d1y * (xs[j] - p1x)
            e2 = y2 - d2y * (xs[j] - p2x)
        else:
            e0 = d0x * (ys[j] - p0y) - d0y * (xs[j] - p0x)
            e1 = d1x * (ys[j] - p1y) - d1y * (xs[j] - p1x)
            e2 = d2x * (ys[j] - p2y) - d2y * (xs[j] - p2x)
        # no branch on the (unpredictable) coverage: a sample the face does not cover, or whose ray runs in its
        # plane (nd = 0, divided by 1 instead), keeps what it had
        nd = nx * directions[0, j] + ny * directions[1, j] + nz * directions[2, j]
        t = nd0 / (nd if nd != 0.0 else 1.0)
        best, held = nearest[j], face[j]
        better = (e0 >= h0) & (e1 >= h1) & (e2 >= h2) & (nd != 0.0) & ((t < best) | ((t == best) & (f < held)))
        nearest[j] = t if better else best
        face[j] = f if better else held


@inlined(always=True)
def _front_part(f, faces, xy, z, vertices, P, near, poly, X):
    """The number of corners (0, 3 or 4) of face f's part in front of `near`, projected, written to poly (4, 2):
    its corners in front and the points where its edges cross `near` (X (3,) scratch); 0 when it is wholly behind
    (no camera ray, t > near, reaches it)."""
    ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
    if max(z[ia], z[ib], z[ic]) <= near:
        return 0
    corners = 0
    for k in range(3):
        a, b = faces[f, k], faces[f, (k + 1) % 3]
        if z[a] > near:
            poly[corners, 0], poly[corners, 1] = xy[a, 0], xy[a, 1]
            corners += 1
        if (z[a] > near) != (z[b] > near):
            # where the edge crosses `near`, from its endpoints in index order (the same point for both faces)
            ea, eb = min(a, b), max(a, b)
            w = (near - z[ea]) / (z[eb] - z[ea])
            for c in range(3):
                X[c] = np.float64(vertices[ea, c]) + w * (np.float64(vertices[eb, c]) - vertices[ea, c])
            depth = P[2, 0] * X[0] + P[2, 1] * X[1] + P[2, 2] * X[2] + P[2, 3]
            poly[corners, 0] = (P[0, 0] * X[0] + P[0, 1] * X[1] + P[0, 2] * X[2] + P[0, 3]) / depth
            poly[corners, 1] = (P[1, 0] * X[0] + P[1, 1] * X[1] + P[1, 2] * X[2] + P[1, 3]) / depth
            corners += 1
    return corners


@inlined(always=True)
def _edge_functions(cx, cy, turn, edges):
    """edges (3, 6) of the triangle (cx, cy) (3,) wound `turn` (the sign of its doubled area): per edge k (corner k
    to k + 1) p (x, y) and q - p (x, y), the endpoints in canonical order (the smaller point first: both faces of a
    shared edge compute the same function) and q - p times the inside sign (negating both factors negates the
    function exactly, so the inside is where it is positive); the tie threshold (0: the edge claims samples on it
    by the top-left rule, e >= 0; TINY: e > 0); and dx/dy (0 for a level edge), for the row spans."""
    for k in range(3):
        ax, ay, bx, by = cx[k], cy[k], cx[(k + 1) % 3], cy[(k + 1) % 3]
        first = ax < bx or (ax == bx and ay < by)
        px, py, qx, qy = (ax, ay, bx, by) if first else (bx, by, ax, ay)
        sign = turn if first else -turn
        edges[k, 0], edges[k, 1], edges[k, 2], edges[k, 3] = px, py, sign * (qx - px), sign * (qy - py)
        # top-left: the edge as the face winds it clockwise on screen (y down) goes up, or right when level
        dx, dy = turn * (bx - ax), turn * (by - ay)
        edges[k, 4] = 0.0 if dy < 0 or (dy == 0 and dx > 0) else TINY
        edges[k, 5] = (bx - ax) / (by - ay) if ay != by else 0.0


@inlined(always=True)
def _row_span(cx, cy, edges, band_lo, band_hi):
    """(left, right) pixel x of the triangle (cx, cy) (3,)'s outline between the lines y = band_lo and band_hi
    (band_lo <= band_hi): its corners in the band and its edges' crossings of the two lines (edges[:, 5] their
    dx/dy); left > right when it misses the band."""
    left, right = np.inf, -np.inf
    for k in range(3):
        ax, ay, by = cx[k], cy[k], cy[(k + 1) % 3]
        if band_lo <= ay <= band_hi:
            left, right = min(left, ax), max(right, ax)
        if ay != by:
            lo, hi = min(ay, by), max(ay, by)
            if lo <= band_lo <= hi:
                x = ax + (band_lo - ay) * edges[k, 5]
                left, right = min(left, x), max(right, x)
            if band_hi != band_lo and lo <= band_hi <= hi:
                x = ax + (band_hi - ay) * edges[k, 5]
                left, right = min(left, x), max(right, x)
    return left, right


@inlined(always=True)
def _plane(f, faces, vertices, origin):
    """(nx, ny, nz, nd0): face f's normal (e1 x e2 of its float32 world corners, in float64) and its dot with the
    first corner from the ray origin (3,): a ray o + t d meets the plane at t = nd0 / (n . d)."""
    ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
    ox, oy, oz = np.float64(vertices[ia, 0]), np.float64(vertices[ia, 1]), np.float64(vertices[ia, 2])
    e1x, e1y, e1z = vertices[ib, 0] - ox, vertices[ib, 1] - oy, vertices[ib, 2] - oz
    e2x, e2y, e2z = vertices[ic, 0] - ox, vertices[ic, 1] - oy, vertices[ic, 2] - oz
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    return nx, ny, nz, nx * (ox - origin[0]) + ny * (oy - origin[1]) + nz * (oz - origin[2])


@inlined(always=True)
def _hidden_depth(f, faces, vertices, z, origin, nx, ny, nz, nd0):
    """A camera z (metres) below the depth t any sample face f covers can compute, for a face turned away from the
    camera (nd0 > 0) that is neither seen edge-on nor near the camera; 0 for any other face (drawn at once).

    A covered sample's exact ray (from the camera centre through its position) meets the plane inside the face, at
    a camera z between the corners'; the computed t differs by the float32 rounding of the ray's direction (5e-7
    of it; the plane's distance from the origin at least 5 % of the farthest corner's: at most 1e-5 of t) and of
    the origin (6e-8 of |origin|; the corners' z and the plane's distance at least 1 cm + 1 % of |origin|: at most
    1e-5 of t), which move the hit at most 1e-4 of t off the face: HIDDEN_MARGIN is ten times all that."""
    zmin = min(z[faces[f, 0]], z[faces[f, 1]], z[faces[f, 2]])
    reach = 1e-2 * (1.0 + np.sqrt(origin[0] ** 2 + origin[1] ** 2 + origin[2] ** 2))
    if nd0 <= 0.0 or zmin < reach:
        return 0.0
    far = 0.0
    for k in range(3):
        v = faces[f, k]
        far = max(far, (vertices[v, 0] - origin[0]) ** 2 + (vertices[v, 1] - origin[1]) ** 2
                  + (vertices[v, 2] - origin[2]) ** 2)
    distance = nd0 / np.sqrt(nx * nx + ny * ny + nz * nz)
    if distance < reach or distance * distance < 0.0025 * far:
        return 0.0
    return zmin * (1.0 - HIDDEN_MARGIN)


@inlined(always=True)
def _tile_maxima(nearest, start, width, height, tiles):
    """tiles (ceil(height / TILE), ceil(width / TILE)): the largest nearest (N,) of the samples in each TILE x TILE
    block of a SampleGrid's box (start: its pixels' columns), -inf for a block without samples."""
    tiles[:] = -np.inf
    for r in range(height):
        for c in range(tiles.shape[1]):
            most = tiles[r // TILE, c]
            for j in range(start[r * width + c * TILE], start[r * width + min((c + 1) * TILE, width)]):
                most = max(most, nearest[j])
            tiles[r // TILE, c] = most


@inlined(always=True)
def _hidden(f, faces, xy, depth, tiles, x0, y0, width, height):
    """Whether every sample in the box of face f's corners (xy (V, 2) pixel positions; all in front of the camera) is
    nearer than `depth` (tiles: _tile_maxima's)."""
    ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
    r_lo = max(np.floor(min(xy[ia, 1], xy[ib, 1], xy[ic, 1])) - y0, 0.0)
    r_hi = min(np.floor(max(xy[ia, 1], xy[ib, 1], xy[ic, 1])) - y0, height - 1.0)
    c_lo = max(np.floor(min(xy[ia, 0], xy[ib, 0], xy[ic, 0])) - x0, 0.0)
    c_hi = min(np.floor(max(xy[ia, 0], xy[ib, 0], xy[ic, 0])) - x0, width - 1.0)
    for tr in range(int(r_lo) // TILE, int(r_hi) // TILE + 1):
        for tc in range(int(c_lo) // TILE, int(c_hi) // TILE + 1):
            if not tiles[tr, tc] < depth:
                return False
    return True


@inlined(always=True)
def _draw(f, corners, poly, nx, ny, nz, nd0, xy, directions, x0, y0, width, height, start, row_band, nearest, face, cx,
          cy, edges, hidden):
    """Face f's part in front (poly (4, 2), `corners` of them, fanned into triangles) over the samples: each
    triangle visits, row by row of pixels, only the columns its outline spans in that row (cx, cy (3,), edges
    (3, 6): scratch), but for a row whose samples are all nearer than `hidden` (_hidden_depth's, or 0)."""
    for fan in range(corners - 2):
        for k in range(3):
            corner = 0 if k == 0 else fan + k
            cx[k], cy[k] = poly[corner, 0], poly[corner, 1]
        area = (cx[1] - cx[0]) * (cy[2] - cy[0]) - (cy[1] - cy[0]) * (cx[2] - cx[0])
        if area == 0.0 or not np.isfinite(area):
            continue
        r_lo = max(np.floor(min(cy[0], cy[1], cy[2])) - y0, 0.0)
        r_hi = min(np.floor(max(cy[0], cy[1], cy[2])) - y0, height - 1.0)
        box_lo = max(np.floor(min(cx[0], cx[1], cx[2])) - x0, 0.0)
        box_hi = min(np.floor(max(cx[0], cx[1], cx[2])) - x0, width - 1.0)
        if r_lo > r_hi or box_lo > box_hi:
            continue
        b_lo, b_hi = int(box_lo), int(box_hi) + 1
        _edge_functions(cx, cy, 1.0 if area > 0 else -1.0, edges)
        for r in range(int(r_lo), int(r_hi) + 1):
            if start[r * width + b_lo] == start[r * width + b_hi]:
                continue                 # no sample in this row of the face's box (edge sub-samples are sparse)
            # the outline's columns between the least and the greatest y of the row's samples (one line for pixel
            # centres), widened by rounding's share so no sample on the outline is left out
            lo, hi = row_band[0, r], row_band[1, r]
            y = lo if lo == hi else np.nan
            left, right = _row_span(cx, cy, edges, lo, hi)
            if left > right:
                continue
            pad = 1e-9 * (1.0 + abs(left) + abs(right))
            c_lo = int(max(np.floor(left - pad) - x0, 0.0))
            c_hi = int(min(np.floor(right + pad) - x0, width - 1.0))
            if c_lo > c_hi:
                continue
            a, b = start[r * width + c_lo], start[r * width + c_hi + 1]
            if hidden > 0.0:
                farthest = -np.inf
                for j in range(a, b):
                    farthest = max(farthest, nearest[j])
                if farthest < hidden:
                    continue
            _cover_run(xy, directions, a, b, y, edges, nx, ny, nz, nd0, f, nearest, face)


@kernel(error_model="numpy")
def _cover_kernel(xy, z, P, near, vertices, faces, face_order, origin, sample_xy, directions, x0, y0, width, height,
                  start, row_band, nearest, face):
    """Rasterise the faces (F, 3) (vertices (V, 3) float32 world, xy (V, 2) their pixel positions and z (V,) camera
    z under P (3, 4)), in face_order, over a SampleGrid's samples (sample_xy, directions, x0, y0, width, height,
    start, row_band): where a
    face covers a sample (edge functions, top-left rule) and its plane is nearer along the sample's ray (from
    origin (3,)) than nearest[j] (float64, per grid row), or as near and a lower face, the sample takes it
    (nearest, face (N,) int64). A face with corners at or behind `near` is clipped there first (its part in front,
    a triangle or a quad, fanned into triangles); one wholly behind is skipped.

    The outcome does not depend on the order (each sample keeps the least depth, then the least face), so the
    faces turned away from the camera (_hidden_depth) are drawn last, and only where their box, then each row of
    their outline, holds a sample farther than their nearest corner: on a closed surface those turned toward it
    already hide most of them. Only for pixel centres (rows whose samples share y): edge sub-samples lie on
    outlines, where a tile rarely hides a face (it measured slower there, and so did also drawing last the faces
    turned toward the camera beyond a quarter of the depth range)."""
    edges = np.empty((3, 6))             # _edge_functions'
    cx, cy = np.empty(3), np.empty(3)
    poly = np.empty((4, 2))              # the face's part in front of `near`, projected
    X = np.empty(3)
    n = face_order.shape[0]
    later, later_depth = np.empty(n, np.int64), np.empty(n)     # the faces drawn last, their _hidden_depth
    n_later = 0
    dense = (row_band[0] == row_band[1]).any()   # pixel centres; edge sub-samples lie where tiles rarely hide a face
    tiles = np.empty(((height + TILE - 1) // TILE, (width + TILE - 1) // TILE))
    for m in range(n + n):
        if m < n:
            f = face_order[m]
        elif m - n < n_later:
            if m == n:
                _tile_maxima(nearest, start, width, height, tiles)
            f = later[m - n]
            if _hidden(f, faces, xy, later_depth[m - n], tiles, x0, y0, width, height):
                continue
        else:
            break
        corners = _front_part(f, faces, xy, z, vertices, P, near, poly, X)
        if corners == 0:
            continue
        nx, ny, nz, nd0 = _plane(f, faces, vertices, origin)
        if m < n and dense:
            depth = _hidden_depth(f, faces, vertices, z, origin, nx, ny, nz, nd0)
            if depth > 0.0:
                later[n_later], later_depth[n_later] = f, depth
                n_later += 1
                continue
        _draw(f, corners, poly, nx, ny, nz, nd0, sample_xy, directions, x0, y0, width, height, start, row_band, nearest,
              face, cx, cy, edges, later_depth[m - n] if m >= n else 0.0)


@kernel
def _barycentrics_kernel(vertices, faces, surface, first, origin, directions, order, face, nearest, geom, prim, u, v,
                         depth):
    """geom, prim, u, v, depth (N,) of the original sample i = order[j] (j itself when order is empty) of each
    SampleGrid column j: where a face covers it (face[j] >= 0, nearest[j] its depth), the ray (origin (3,) float64,
    direction directions[:, j] float32) against that face by Moeller-Trumbore in float64 (hit = (1 - u - v) v0 +
    u v1 + v v2, depth the ray parameter), rounded to float32, and a ray in the face's plane to rounding (no
    determinant) u = v = 0 and depth nearest[j]; elsewhere background (-1, -1, 0, 0, inf). What depends on the face
    alone (its corners, edges, s = origin - v0, q = s x e1 and e2 . q) is computed once per run of columns on one
    face: the same operations, once."""
    identity = order.shape[0] == 0
    held = -1                            # the face whose values below are held: runs of a row share a face
    ox = oy = oz = e1x = e1y = e1z = e2x = e2y = e2z = qx = qy = qz = sx = sy = sz = tq = 0.0
    g, p = np.int32(-1), np.int32(-1)
    for j in range(face.shape[0]):
        i = j if identity else order[j]
        f = face[j]
        if f < 0:
            geom[i], prim[i], u[i], v[i], depth[i] = -1, -1, np.float32(0.0), np.float32(0.0), np.float32(np.inf)
            continue
        if f != held:
            held = f
            g, p = surface[f], np.int32(f - first[surface[f]])
            ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
            ox, oy, oz = np.float64(vertices[ia, 0]), np.float64(vertices[ia, 1]), np.float64(vertices[ia, 2])
            e1x, e1y, e1z = vertices[ib, 0] - ox, vertices[ib, 1] - oy, vertices[ib, 2] - oz
            e2x, e2y, e2z = vertices[ic, 0] - ox, vertices[ic, 1] - oy, vertices[ic, 2] - oz
            sx, sy, sz = origin[0] - ox, origin[1] - oy, origin[2] - oz
            qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
            tq = e2x * qx + e2y * qy + e2z * qz
        geom[i], prim[i] = g, p
        dx, dy, dz = np.float64(directions[0, j]), np.float64(directions[1, j]), np.float64(directions[2, j])
        px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
        det = e1x * px + e1y * py + e1z * pz
        if det == 0.0:
            u[i], v[i], depth[i] = np.float32(0.0), np.float32(0.0), np.float32(nearest[j])
            continue
        inverse = 1.0 / det
        u[i] = np.float32((sx * px + sy * py + sz * pz) * inverse)
        v[i] = np.float32((dx * qx + dy * qy + dz * qz) * inverse)
        depth[i] = np.float32(tq * inverse)
