"""Subsurface scattering of skin, pre-integrated over the surface's curvature (after Penner, "Pre-Integrated Skin
Shading", GPU Pro 2, 2011), with the diffusion profile of Christensen and Burley ("Approximate Reflectance Profiles
for Efficient Subsurface Scattering", 2015).

Light that enters skin leaves it again a few millimetres away, red light furthest. Where the light's angle changes
within that distance -- around the terminator of a finger -- the skin's diffuse response is the irradiance blurred by
the diffusion profile R(r), not the Lambert cosine. On a sphere of radius r lit by a directional light, the blurred
response at a point whose normal makes angle theta with the light depends only on theta and r / d (d the profile's
width), so it is tabulated once:

    D(cos theta, r / d) = integral over the sphere of R(|p - q|) max(0, n_q . l) dA_q / integral of R(|p - q|) dA_q

with Burley's normalised profile R(x) = (exp(-x / d) + exp(-x / 3d)) / (8 pi d x). The integral over the azimuth about
p has a closed form, so each entry is a one-dimensional quadrature. D is energy-conserving (a normalised average of
the irradiance over the surface: lit uniformly, D is 1) and Lambert's cosine on a flat surface (r / d -> infinity).

Per shaded point: r is the radius of the sphere of the surface's mean curvature there (per vertex, from the rest
mesh: a finger of radius 8 mm gives r = 16 mm; concave or flat places are flat); d per colour channel from the
skin's mean free path l (SKIN_MFP_MM, red longest) and its tone A (the median albedo of its texture), d = l / s(A),
s(A) = 1.85 - A + 7 |A - 0.8|^3 (Christensen and Burley's fit for a searchlight on a semi-infinite medium). A darker
skin tone absorbs more of the light on its way, so its profile is narrower and its terminator sharper: the model is
parameterised by the skin tone. Nails (face label 'nail') are not skin and keep Lambert's cosine.

Not modelled: the softening of cast shadow edges (a shadow ray per point decides) and light through thin parts
(fingers lit from behind); `make bench` measures the whole against a volumetric path tracer
(benchmarks/render_reference.py).
"""

from __future__ import annotations

import functools
import weakref

import numpy as np
import scipy.sparse as sp

from darthand.model.topology import boundary_loops

SKIN_MFP_MM = (1.30, 0.95, 0.67)     # mean free path 1 / sigma_t per channel, mm (Jensen et al. 2001, skin 1)
FLAT_RADIUS = 1.0                    # m: radius standing for flat or concave (far past the table's flat end)
MIN_RADIUS = 1e-3                    # m: curvature radii below a millimetre are mesh noise, not anatomy
COS_STEPS, RATIO_STEPS = 129, 49     # table resolution over cos theta in [-1, 1] and log2(r / d) in [LOG_LO, LOG_HI]
LOG_LO, LOG_HI = -2.0, 10.0


def profile_width(albedo: np.ndarray, mfp_m) -> np.ndarray:
    """(3, M) float32 profile width d (metres) per channel at albedos (3, M), mean free paths mfp_m (3,) metres."""
    a = np.asarray(albedo, np.float32)
    s = 1.85 - a + 7 * np.abs(a - 0.8) ** 3
    return np.asarray(mfp_m, np.float32)[:, None] / s


def _azimuth_integral(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """integral over psi in [0, 2 pi) of max(0, a + b cos psi), b >= 0 (closed form)."""
    out = np.where(a >= b, 2 * np.pi * a, 0.0)
    mid = (np.abs(a) < b)
    with np.errstate(invalid="ignore", divide="ignore"):
        psi0 = np.arccos(np.clip(-a / np.where(b > 0, b, 1), -1, 1))
    return np.where(mid, 2 * (a * psi0 + b * np.sin(psi0)), out)


@functools.lru_cache(maxsize=1)
def sphere_table() -> np.ndarray:
    """(RATIO_STEPS, COS_STEPS) float32 D(cos theta, r / d) (see the module doc), rows log2(r / d) from LOG_LO to
    LOG_HI, columns cos theta from -1 to 1."""
    cos_t = np.linspace(-1, 1, COS_STEPS)
    sin_t = np.sqrt(1 - cos_t ** 2)
    rows = []
    for log_ratio in np.linspace(LOG_LO, LOG_HI, RATIO_STEPS):
        rho = 2.0 ** log_ratio                     # sphere radius in units of d
        # gamma: angle between p and q on the sphere; chord x = 2 rho sin(gamma / 2). Points dense near gamma = 0,
        # where R ~ 1 / x, on a log scale in the chord length (midpoint rule in gamma).
        edges = np.concatenate([[0.0], np.geomspace(1e-4 / rho, np.pi, 400)])
        gamma = 0.5 * (edges[1:] + edges[:-1])
        dg = np.diff(edges)
        x = 2 * rho * np.sin(gamma / 2)
        w = (np.exp(-x) + np.exp(-x / 3)) / x * np.sin(gamma) * dg       # R(x) dA up to constant factors
        a = cos_t[:, None] * np.cos(gamma)[None, :]
        b = sin_t[:, None] * np.sin(gamma)[None, :]
        rows.append((_azimuth_integral(a, b) * w).sum(1) / (2 * np.pi * w.sum()))
    return np.asarray(rows, np.float32)


@functools.lru_cache(maxsize=1)
def sphere_blend_table() -> np.ndarray:
    """(RATIO_STEPS * COS_STEPS, 2) float64: each entry of the flattened sphere_table and its float32 step to the
    next (hi - lo), as subsurface_diffuse's blend lo + fc (hi - lo) reads them (float32 difference, float64 blend)."""
    flat = sphere_table().ravel()
    step = np.zeros_like(flat)
    step[:-1] = flat[1:] - flat[:-1]
    return np.stack([flat, step], axis=1).astype(np.float64)


def subsurface_diffuse(ndl: np.ndarray, radius: np.ndarray, width: np.ndarray) -> np.ndarray:
    """(3, M) float32 diffuse response per unit irradiance (D above) at cosines ndl (M,) on spheres of radius
    `radius` (M,) metres, with profile widths `width` (3,) metres per channel: linear in cos theta, nearest row in
    log2(r / d) (rows a quarter octave apart). The definition in numpy; the renderer does the same lookup inside its
    shading kernel (shade._lights_kernel), from the same `table_rows`, and the tests hold the two equal."""
    flat_table = sphere_table().ravel()
    cu = (np.clip(ndl, -1, 1) + 1) * np.float32((COS_STEPS - 1) / 2)
    c0 = np.minimum(cu.astype(np.int32), COS_STEPS - 2)
    fc = cu - c0                      # float64 (float32 - int32): the blend below is in float64, rounded once
    row_r, shifts = table_rows(radius, width)
    out = np.empty((3, len(ndl)), np.float32)
    for c in range(3):
        row = np.clip(np.rint(row_r + shifts[c]), 0, RATIO_STEPS - 1).astype(np.int32)
        flat = row * np.int32(COS_STEPS) + c0
        lo = flat_table[flat]
        out[c] = lo + fc * (flat_table[flat + 1] - lo)
    return out


def table_rows(radius: np.ndarray, width: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The table row of each hit and channel, before rounding, as (row_r (M,), shifts (3,)) float32: row =
    clip(rint(row_r + shifts[c]), 0, RATIO_STEPS - 1), in units of the table's step: log2(r) once per hit
    (`radius` (M,) metres), each channel's log2(d) (`width` (3,) metres) as a shift of it."""
    step = (RATIO_STEPS - 1) / (LOG_HI - LOG_LO)
    row_r = np.log2(radius) * np.float32(step)
    shifts = np.array([-(np.log2(width[c]) + LOG_LO) * step for c in range(3)], np.float32)
    return row_r, shifts


_WIDTHS: dict = {}


def skin_width(material) -> np.ndarray:
    """(3,) float32 profile width d (metres) of a skin material: `profile_width` at the median albedo of its texture
    (a coarse mip level: the skin tone, moles and tattoos aside) and its mean free paths. Remembered per texture
    storage, decode table (skin-tone offset) and mean free paths. The storage is held weakly: a texture the
    pyramid cache (render/texture.py) lets go of must be freed, not kept alive here."""
    maps = material.maps
    key = (id(maps.flat), None if maps.decode is None else maps.decode.tobytes(), tuple(material.mfp_mm))
    entry = _WIDTHS.get(key)
    if entry is None or entry[0]() is not maps.flat:
        levels = maps.levels
        level = levels[max(0, len(levels) - 5)][..., :3].reshape(-1, 3)
        tone = np.median(level, axis=0)[:, None]
        if len(_WIDTHS) > 256:
            _WIDTHS.clear()
        width = profile_width(tone, np.asarray(material.mfp_mm, np.float32) * 1e-3)[:, 0]
        entry = _WIDTHS[key] = (weakref.ref(maps.flat), width)
    return entry[1]


def curvature_radius(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N,) float32 radius (metres) of the sphere of each vertex's mean curvature H (r = 1 / H), from the cotangent
    Laplacian (H n = -1/2 Laplace-Beltrami x); FLAT_RADIUS where the surface is flat or concave (H <= 0) or the
    vertex is on a boundary; between MIN_RADIUS and FLAT_RADIUS. What depends on the faces alone (the Laplacian's
    sparsity, the boundary) is worked out once per face array (mesh_structure)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    n = len(v)
    structure = mesh_structure(f, n)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    face_area = 0.5 * np.linalg.norm(fn, axis=1)
    vals = []
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        # the angle at corner i is opposite edge (j, k): cot weight on that edge
        e1, e2 = v[f[:, j]] - v[f[:, i]], v[f[:, k]] - v[f[:, i]]
        cot = np.einsum("ij,ij->i", e1, e2) / np.maximum(np.linalg.norm(np.cross(e1, e2), axis=1), 1e-30)
        vals += [0.5 * cot, 0.5 * cot]
    W = structure.laplacian_weights(np.concatenate(vals))
    # corner by corner in face order, as np.add.at would add them (bincount adds in the same order: same bits)
    area = np.bincount(structure.corners, np.tile(face_area / 3, 3), minlength=n)
    lap = (W @ v - np.asarray(W.sum(axis=1)) * v) / np.maximum(area, 1e-30)[:, None]       # Laplace-Beltrami of x
    normals: np.ndarray = np.stack([np.bincount(structure.face_vertices, np.repeat(fn[:, c], 3), minlength=n)
                                    for c in range(3)], axis=1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    H = -0.5 * np.einsum("ij,ij->i", lap, normals)
    radius = np.where(H > 0, 1 / np.maximum(H, 1e-30), FLAT_RADIUS)
    radius[structure.boundary] = FLAT_RADIUS
    return np.clip(radius, MIN_RADIUS, FLAT_RADIUS).astype(np.float32)


class MeshStructure:
    """What curvature_radius needs of a face array (F, 3) int64 over n vertices that the vertices' positions do
    not change: the boundary vertices, the corners' vertex orders for its sums, and the cotangent Laplacian's
    sparsity (CSR) with where each cotangent entry (rows then columns: (j, k) and (k, j) per corner, corners 0, 1,
    2) lands in it."""

    def __init__(self, faces: np.ndarray, n: int):
        self.n = n
        self.boundary = np.concatenate([np.zeros(0, np.int64), *boundary_loops(faces)])
        self.corners = faces.T.ravel()                  # corner 0 of every face, then corner 1, then corner 2
        self.face_vertices = faces.ravel()
        rows, cols = [], []
        for _, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            rows += [faces[:, j], faces[:, k]]
            cols += [faces[:, k], faces[:, j]]
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        keys, self.slot, counts = np.unique(rows * max(n, 1) + cols, return_inverse=True, return_counts=True)
        # An entry summed from more than two cotangents depends on the order scipy adds them in (a + b is the same
        # bits either way, a + b + c is not): such a (non-manifold) mesh takes scipy's own assembly.
        self.exact = bool((counts <= 2).all())
        self.rows, self.cols = rows, cols
        self.indices = (keys % max(n, 1)).astype(np.int32)
        self.indptr = np.searchsorted(keys // max(n, 1), np.arange(n + 1)).astype(np.int32)

    def laplacian_weights(self, vals: np.ndarray) -> sp.csr_matrix:
        """(n, n) CSR matrix of the cotangent entries `vals` (the constructor's order) with repeated entries summed:
        the matrix sp.csr_matrix((vals, (rows, cols))) builds, without its sort."""
        if not self.exact:
            return sp.csr_matrix((vals, (self.rows, self.cols)), shape=(self.n, self.n))
        data = np.bincount(self.slot, vals, minlength=len(self.indices))
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


_STRUCTURES: dict = {}


def mesh_structure(faces: np.ndarray, n: int) -> MeshStructure:
    """MeshStructure of a face array (F, 3) int64 over n vertices, remembered by the faces' contents (each frame's
    rest mesh is new, its faces are not; a face array changed in place is a new key, never a stale entry)."""
    key = (n, faces.shape, faces.tobytes())
    entry = _STRUCTURES.get(key)
    if entry is None:
        if len(_STRUCTURES) > 16:
            _STRUCTURES.clear()
        entry = _STRUCTURES[key] = MeshStructure(np.ascontiguousarray(faces, np.int64), n)
    return entry


_RADII: dict = {}


def surface_radius(surface) -> np.ndarray | None:
    """`curvature_radius` of a skin surface's rest mesh (`Surface.rest`), computed once per rest array; None for a
    surface without one."""
    if surface.rest is None:
        return None
    key = (id(surface.rest), id(surface.faces))
    entry = _RADII.get(key)
    if entry is None or entry[0] is not surface.rest or entry[1] is not surface.faces:
        if len(_RADII) > 16:
            _RADII.clear()
        entry = _RADII[key] = (surface.rest, surface.faces, curvature_radius(surface.rest, surface.faces))
    return entry[2]
