"""Mesh building for the near-symmetric parts of :mod:`binpick.parts`, and a plain ray-cast.

Every solid here has the topology of a sphere: a stack of closed rings of vertices (same count
per ring) between two pole vertices, stitched into quads and closed by fans at the poles. A part
is described by where its rings lie, e.g. an axial solid by a radius ``r(s, φ)`` at station ``s``
along its axis and angle ``φ`` about it, so a keyway, a notch or a cut corner is a change of that
function, and the part without its feature (its *base shape*) is the same grid with the change
left out. A step in the function (a keyway wall) is written as two samples ``eps`` apart.

:func:`raycast_down` renders a mesh as a z-buffer seen by an orthographic camera looking down −z.
numpy only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ._validate import edge_use_counts
from .errors import InvalidInputError

__all__ = [
    "ring_solid",
    "angle_samples",
    "stations",
    "check_grid",
    "MAX_GRID_VERTICES",
    "axial_solid",
    "polygon_radius",
    "signed_volume",
    "edge_use_counts",
    "raycast_down",
    "posed",
    "scan_down",
    "surface_distance",
    "feature_in_view",
]

#: Half-width (rad or mm) of the pair of samples that writes a step of a radius function.
STEP = 1e-3

#: Most vertices a part's mesh grid may have (rings × vertices per ring): the default parts have
#: under 50 000; four million (about 300 MB of vertices and faces) is checked before the grid is
#: built, so that sizes far beyond a real part cannot take the machine's memory.
MAX_GRID_VERTICES = 4_000_000


def check_grid(rings: int, per_ring: int, what: str) -> None:
    """InvalidInputError naming ``what`` (the part and its size arguments) when a grid of
    ``rings`` × ``per_ring`` vertices is over :data:`MAX_GRID_VERTICES`."""
    if rings * per_ring > MAX_GRID_VERTICES:
        raise InvalidInputError(
            f"{what}: these sizes need a mesh grid of {rings} × {per_ring} = {rings * per_ring} vertices, over the "
            f"ceiling of {MAX_GRID_VERTICES}; pass the part's real sizes in mm"
        )


def ring_solid(rings: np.ndarray, first_pole: Sequence[float], last_pole: Sequence[float]) -> tuple:
    """A closed triangle mesh (vertices (V, 3), faces (F, 3) int64) through ``rings`` (U, N, 3),
    U closed rings of N vertices each in order from ``first_pole`` to ``last_pole``; faces are
    wound so that the signed volume is positive (outward normals)."""
    rings = np.asarray(rings, dtype=np.float64)
    u, n = rings.shape[:2]
    v = np.vstack([np.asarray(first_pole, dtype=np.float64)[None], rings.reshape(-1, 3), np.asarray(last_pole)[None]])
    last = len(v) - 1
    j = np.arange(n)
    k = (j + 1) % n
    faces = [np.c_[np.zeros(n, dtype=np.int64), 1 + k, 1 + j]]
    for r in range(u - 1):
        a, b = 1 + r * n, 1 + (r + 1) * n
        faces += [np.c_[a + j, a + k, b + k], np.c_[a + j, b + k, b + j]]
    base = 1 + (u - 1) * n
    faces.append(np.c_[base + j, base + k, np.full(n, last)])
    f = np.vstack(faces).astype(np.int64)
    if signed_volume(v, f) < 0:
        f = f[:, ::-1].copy()
    return v, f


def angle_samples(step: float, radius: float, breaks: Sequence[float] = (), steps: Sequence[float] = ()) -> np.ndarray:
    """Angles in [0, 2π) at most ``step`` mm of arc apart at ``radius``, plus every angle of
    ``breaks`` (corners) and a pair ±:data:`STEP` around every angle of ``steps`` (walls)."""
    n = max(96, int(np.ceil(2 * np.pi * radius / step)))
    extra = [np.asarray(breaks, dtype=np.float64)]
    extra += [np.asarray(steps, dtype=np.float64) + d for d in (-STEP, STEP)]
    a = np.mod(np.concatenate([np.linspace(0, 2 * np.pi, n, endpoint=False), *extra]), 2 * np.pi)
    a = np.unique(a)
    return a[np.diff(np.r_[a, a[0] + 2 * np.pi]) > STEP / 4]


def stations(length: float, step: float, steps: Sequence[float] = ()) -> np.ndarray:
    """Stations from 0 to ``length`` at most ``step`` mm apart, with a pair ±:data:`STEP` around each of ``steps``."""
    s = np.linspace(0.0, length, max(2, int(np.ceil(length / step)) + 1))
    s = np.unique(np.concatenate([s, *[np.asarray(steps, dtype=np.float64) + d for d in (-STEP, STEP)]]))
    return s[(s >= 0) & (s <= length)]


def axial_solid(
    radius: Callable[[np.ndarray, np.ndarray], np.ndarray],
    s: np.ndarray,
    phi: np.ndarray,
    cap_rings: int = 6,
    what: str = "sizes",
) -> tuple:
    """The solid about the z axis from z = s[0] to s[-1] whose surface at height s and angle φ
    lies at ``radius(s, φ)`` (broadcasting arrays) from the axis, closed by flat end caps (each
    star-shaped from the axis: ``cap_rings`` scaled copies of its rim). The grid's size is
    checked first (:func:`check_grid`, naming ``what``)."""
    check_grid(len(s) + 2 * (cap_rings - 1), len(phi), what)
    S, P = np.meshgrid(s, phi, indexing="ij")
    r = radius(S, P)
    side = np.stack([r * np.cos(P), r * np.sin(P), S], axis=-1)
    t = np.linspace(0, 1, cap_rings + 1)[1:-1]
    bottom = [np.c_[side[0, :, :2] * f, side[0, :, 2]] for f in t]
    top = [np.c_[side[-1, :, :2] * f, side[-1, :, 2]] for f in t[::-1]]
    rings = np.concatenate([np.array(bottom).reshape(-1, len(phi), 3), side, np.array(top).reshape(-1, len(phi), 3)])
    return ring_solid(rings, (0.0, 0.0, s[0]), (0.0, 0.0, s[-1]))


def polygon_radius(polygon: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Distance from the origin along angle ``phi`` to the boundary of the convex ``polygon``
    (K, 2), counter-clockwise, containing the origin."""
    p = np.asarray(polygon, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    normal = np.c_[q[:, 1] - p[:, 1], p[:, 0] - q[:, 0]]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    dist = np.einsum("ij,ij->i", normal, p)
    u = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    along = u @ normal.T
    with np.errstate(divide="ignore"):
        hit = np.where(along > 1e-12, dist / np.where(along > 1e-12, along, 1.0), np.inf)
    return hit.min(axis=-1)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The signed volume of a closed mesh (positive when its faces are wound outward), mm³."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def raycast_down(
    vertices: np.ndarray,
    faces: np.ndarray,
    lo: Sequence[float],
    hi: Sequence[float],
    pixel: float,
    budget: int = 2_000_000,
) -> tuple[np.ndarray, np.ndarray]:
    """A z-buffer of the mesh seen from above by an orthographic camera looking down −z: one ray
    per pixel centre of the grid ``lo``..``hi`` (x, y) at ``pixel`` mm. Returns the highest z hit
    per pixel (H, W), NaN where the ray misses, and the pixel centres' x (W,) and y (H,).

    Each triangle is tested against the pixel centres inside its bounding box (barycentric
    coordinates, ties on shared edges go to both sides, so no ray slips between two faces),
    ``budget`` pixel tests at a time."""
    xs = np.arange(lo[0] + pixel / 2, hi[0], pixel)
    ys = np.arange(lo[1] + pixel / 2, hi[1], pixel)
    depth = np.full(len(ys) * len(xs), -np.inf)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    keep = np.abs(det) > 1e-12
    face_of = np.flatnonzero(keep)
    a, b, c, det = a[keep], b[keep], c[keep], det[keep]
    hits = []
    x0 = np.clip(np.ceil((np.minimum(np.minimum(a[:, 0], b[:, 0]), c[:, 0]) - xs[0]) / pixel), 0, len(xs))
    x1 = np.clip(np.floor((np.maximum(np.maximum(a[:, 0], b[:, 0]), c[:, 0]) - xs[0]) / pixel) + 1, 0, len(xs))
    y0 = np.clip(np.ceil((np.minimum(np.minimum(a[:, 1], b[:, 1]), c[:, 1]) - ys[0]) / pixel), 0, len(ys))
    y1 = np.clip(np.floor((np.maximum(np.maximum(a[:, 1], b[:, 1]), c[:, 1]) - ys[0]) / pixel) + 1, 0, len(ys))
    w = np.maximum(x1 - x0, 0).astype(np.int64)
    h = np.maximum(y1 - y0, 0).astype(np.int64)
    area = w * h
    cum = np.cumsum(area)
    cuts = np.searchsorted(cum, np.arange(budget, cum[-1] if len(cum) else 0, budget)) if len(cum) else []
    edges = np.unique(np.r_[0, cuts, len(area)]).astype(np.int64)
    for start, end in zip(edges[:-1], edges[1:]):
        sel = np.arange(start, end)
        if area[sel].sum() == 0:
            continue
        t = np.repeat(sel, area[sel])
        offset = np.arange(len(t)) - np.repeat(np.cumsum(area[sel]) - area[sel], area[sel])
        ix = (x0[t] + offset % w[t]).astype(np.int64)
        iy = (y0[t] + offset // w[t]).astype(np.int64)
        px, py = xs[ix], ys[iy]
        l1 = ((px - a[t, 0]) * (c[t, 1] - a[t, 1]) - (c[t, 0] - a[t, 0]) * (py - a[t, 1])) / det[t]
        l2 = ((b[t, 0] - a[t, 0]) * (py - a[t, 1]) - (px - a[t, 0]) * (b[t, 1] - a[t, 1])) / det[t]
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
        z = a[t, 2] + l1 * (b[t, 2] - a[t, 2]) + l2 * (c[t, 2] - a[t, 2])
        pix = (iy * len(xs) + ix)[inside]
        np.maximum.at(depth, pix, z[inside])
        hits.append(np.c_[pix, t[inside]][z[inside] >= depth[pix]])
    face = np.full(len(depth), -1, dtype=np.int64)
    if hits:
        h = np.vstack(hits)
        top = h[_last_per_pixel(h)]
        face[top[:, 0]] = face_of[top[:, 1]]
    depth = depth.reshape(len(ys), len(xs))
    depth[~np.isfinite(depth)] = np.nan
    return depth, face.reshape(depth.shape), xs, ys


def _last_per_pixel(hits: np.ndarray) -> np.ndarray:
    """Rows of ``hits`` (pixel, triangle) that come last for their pixel: a row is only added
    when it is at least as high as every earlier one, so the last is the surface seen."""
    order = np.argsort(hits[:, 0], kind="stable")
    last = np.r_[hits[order[1:], 0] != hits[order[:-1], 0], True]
    return order[last]


def posed(vertices: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Vertices (V, 3) moved by the rigid transform ``T`` (4, 4)."""
    return np.asarray(vertices) @ T[:3, :3].T + T[:3, 3]


def scan_down(
    vertices: np.ndarray,
    faces: np.ndarray,
    lo: Sequence[float],
    hi: Sequence[float],
    pixel: float,
    noise: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """The points (N, 3) an orthographic camera looking down −z sees of the mesh over the grid
    ``lo``..``hi`` at ``pixel`` mm, each moved along its ray (z) by Gaussian ``noise`` (σ, mm),
    and the face hit by each."""
    depth, face, xs, ys = raycast_down(vertices, faces, lo, hi, pixel)
    iy, ix = np.nonzero(np.isfinite(depth))
    z = depth[iy, ix] + rng.normal(0.0, noise, len(iy))
    return np.c_[xs[ix], ys[iy], z], face[iy, ix]


def surface_distance(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Exact distance (mm) from each point (N, 3) to the mesh surface (the simulator's query)."""
    from .sim.render import World

    world = World()
    world.add_instance(world.add_mesh(vertices, faces), np.eye(4), 0)
    return world.nearest_surface(points)[0]


def feature_in_view(
    part: tuple,
    base: tuple,
    T: np.ndarray,
    part_points: np.ndarray,
    base_points: np.ndarray,
    sigma: float = 0.15,
    min_points: int = 15,
) -> bool:
    """Whether a scan shows what tells ``part`` (vertices, faces) from its symmetric ``base``
    shape, both posed at ``T``: at least ``min_points`` of the part's scan points lie more than
    4 ``sigma`` from the base shape, or at least ``min_points`` points of a scan of the base shape
    (same pose, same camera) lie more than 4 ``sigma`` from the part, where it has no surface."""
    limit = 4.0 * sigma
    if len(part_points) and (surface_distance(posed(base[0], T), base[1], part_points) > limit).sum() >= min_points:
        return True
    return bool(
        len(base_points) and (surface_distance(posed(part[0], T), part[1], base_points) > limit).sum() >= min_points
    )
