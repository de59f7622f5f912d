"""Analytic test scenes for the measuring chain: planes, cylinders and checkerboards seen by
the calibrated camera, lit by the laser sheet, with ambient light and sensor noise.

This is a ground-truth generator for tests and benchmarks, not the cell simulator
(:mod:`binpick.sim`): every surface is exact, so the line centre and the 3-D points it
should give are known to numerical precision.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _core
from ..calibration import CameraIntrinsics, CellCalibration
from ..camera import camera_args


def pose(rx: float = 0.0, ry: float = 0.0, rz: float = 0.0, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A 4×4 transform ``Rz·Ry·Rx`` (angles in radians) with translation ``t`` (mm)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    T = np.eye(4)
    T[:3, :3] = (
        np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    )
    T[:3, 3] = t
    return T


@dataclass(frozen=True)
class Plane:
    """The plane through ``point`` with normal ``normal`` (base frame, mm)."""

    point: np.ndarray
    normal: np.ndarray
    albedo: float = 0.7

    def intersect(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal, float) / np.linalg.norm(self.normal)
        denom = dirs @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (np.asarray(self.point, float) - origin) @ n / denom
        return np.where((t > 0) & np.isfinite(t), t, np.inf)

    def distance(self, pts: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal, float) / np.linalg.norm(self.normal)
        return np.abs((pts - np.asarray(self.point, float)) @ n)

    def albedo_at(self, pts: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        return np.full(len(pts), self.albedo)


@dataclass(frozen=True)
class Cylinder:
    """The infinite cylinder of ``radius`` around the line through ``point`` along ``axis`` (mm)."""

    point: np.ndarray
    axis: np.ndarray
    radius: float
    albedo: float = 0.6

    def intersect(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        a = np.asarray(self.axis, float) / np.linalg.norm(self.axis)
        w = origin - np.asarray(self.point, float)
        dp = dirs - np.outer(dirs @ a, a)
        wp = w - (w @ a) * a
        qa = np.einsum("ij,ij->i", dp, dp)
        qb = 2 * dp @ wp
        qc = wp @ wp - self.radius**2
        disc = qb * qb - 4 * qa * qc
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-qb - np.sqrt(disc)) / (2 * qa)
        return np.where((disc > 0) & (t > 0), t, np.inf)

    def distance(self, pts: np.ndarray) -> np.ndarray:
        a = np.asarray(self.axis, float) / np.linalg.norm(self.axis)
        w = pts - np.asarray(self.point, float)
        radial = w - np.outer(w @ a, a)
        return np.abs(np.linalg.norm(radial, axis=1) - self.radius)

    def albedo_at(self, pts: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        return np.full(len(pts), self.albedo)


@dataclass(frozen=True)
class Checkerboard(Plane):
    """A checkerboard on the plane z = 0 of ``T_base_board`` (OpenCV's corner order): ``pattern``
    inner corners (columns, rows), squares of ``square`` mm, a white margin of one square."""

    T_base_board: np.ndarray = field(default_factory=lambda: np.eye(4))
    pattern: tuple[int, int] = (9, 6)
    square: float = 20.0

    @classmethod
    def at(cls, T_base_board: np.ndarray, pattern: tuple[int, int] = (9, 6), square: float = 20.0) -> Checkerboard:
        T = np.asarray(T_base_board, float)
        return cls(point=T[:3, 3], normal=T[:3, 2], T_base_board=T, pattern=pattern, square=square)

    def object_points(self) -> np.ndarray:
        """The inner corners in the board frame, in OpenCV's order (row by row), (N, 3)."""
        cols, rows = self.pattern
        gx, gy = np.meshgrid(np.arange(cols), np.arange(rows))
        return np.stack([gx.ravel(), gy.ravel(), np.zeros(cols * rows)], axis=1) * self.square

    def albedo_at(self, pts: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        T = self.T_base_board
        local = (pts - T[:3, 3]) @ T[:3, :3]
        s = self.square
        cols, rows = self.pattern

        # Soft edges: the share of the pixel footprint on either side of the nearest edge.
        def soft(c):
            frac = c / s - np.floor(c / s)
            edge = np.minimum(frac, 1 - frac) * s
            side = np.floor(c / s) % 2 == 0
            cover = np.clip(0.5 + edge / footprint, 0, 1)
            return np.where(side, cover, 1 - cover)

        ax, ay = soft(local[:, 0] + s), soft(local[:, 1] + s)
        dark = ax * ay + (1 - ax) * (1 - ay)
        inside = (local[:, 0] > -s) & (local[:, 0] < cols * s) & (local[:, 1] > -s) & (local[:, 1] < rows * s)
        margin = (
            (local[:, 0] > -2 * s)
            & (local[:, 0] < (cols + 1) * s)
            & (local[:, 1] > -2 * s)
            & (local[:, 1] < (rows + 1) * s)
        )
        return np.where(inside, 0.9 - 0.8 * dark, np.where(margin, 0.9, 0.3))


def camera_rays(camera: CameraIntrinsics, pixels: np.ndarray | None = None) -> np.ndarray:
    """Undistorted unit rays (camera frame) through ``pixels`` (N, 2), or through every pixel centre
    (row-major, H·W rays) when ``pixels`` is None."""
    if pixels is None:
        v, u = np.mgrid[0 : camera.height, 0 : camera.width]
        pixels = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    rays = _core.pixel_rays(camera_args(camera), np.ascontiguousarray(pixels, dtype=np.float64))
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def laser_plane_base(calibration: CellCalibration, angle: float, T_base_flange: np.ndarray) -> tuple[np.ndarray, float]:
    """The laser sheet in the base frame as (unit normal n, offset d) with n·x = d."""
    T_base_laser = np.asarray(T_base_flange) @ calibration.T_flange_camera @ calibration.T_camera_laser_at(angle)
    n = T_base_laser[:3, 0]
    return n, float(n @ T_base_laser[:3, 3])


def _hits(surfaces, origin, dirs):
    ts = np.stack([s.intersect(origin, dirs) for s in surfaces])
    which = ts.argmin(axis=0)
    return ts[which, np.arange(len(dirs))], which


def render(
    calibration: CellCalibration,
    surfaces: list,
    T_base_flange: np.ndarray,
    *,
    angle: float | None = None,
    rng: np.random.Generator | None = None,
    sheet_sigma: float = 0.6,
    laser_peak: float = 170.0,
    ambient: float = 90.0,
    ambient_tint: tuple[float, float, float] = (1.0, 1.0, 1.0),
    noise: float = 2.0,
    rays: np.ndarray | None = None,
) -> np.ndarray:
    """A BGR uint8 frame of ``surfaces`` (nearest hit wins) under ambient light, lit by the laser
    sheet at motor ``angle`` (None: laser off). ``sheet_sigma`` is the Gaussian half-thickness
    of the sheet (mm); ``noise`` the sensor noise (grey levels, 1 σ)."""
    cam = calibration.camera
    rng = rng if rng is not None else np.random.default_rng(0)
    T_base_camera = np.asarray(T_base_flange) @ calibration.T_flange_camera
    rays = camera_rays(cam) if rays is None else rays
    dirs = rays @ T_base_camera[:3, :3].T
    origin = T_base_camera[:3, 3]
    t, which = _hits(surfaces, origin, dirs)
    hit = np.isfinite(t)
    pts = origin + dirs * np.where(hit, t, 0)[:, None]
    footprint = np.maximum(np.where(hit, t, 1.0) / cam.K[0, 0], 1e-6)
    albedo = np.zeros(len(dirs))
    for i, s in enumerate(surfaces):
        sel = hit & (which == i)
        albedo[sel] = s.albedo_at(pts[sel], footprint[sel])
    base = albedo[:, None] * ambient * np.asarray(ambient_tint)[None, [2, 1, 0]]
    if angle is not None:
        n, d = laser_plane_base(calibration, angle, T_base_flange)
        s = np.where(hit, pts @ n - d, np.inf)
        sheet = laser_peak * np.exp(-0.5 * (s / sheet_sigma) ** 2) * (0.4 + 0.6 * albedo)
        base[:, 2] += sheet
        base[:, 1] += 0.15 * sheet
    img = base.reshape(cam.height, cam.width, 3) + rng.normal(0.0, noise, (cam.height, cam.width, 3))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def true_line_centres(
    calibration: CellCalibration, surfaces: list, T_base_flange: np.ndarray, angle: float, *, iterations: int = 6
) -> np.ndarray:
    """For each image row crossed by the lit line, the exact column where the laser sheet's centre
    meets the first surface hit: (M, 2) of (u, v). Rows where that crossing falls on a depth edge
    between two surfaces, or where there is none, are left out."""
    cam = calibration.camera
    T_base_camera = np.asarray(T_base_flange) @ calibration.T_flange_camera
    origin = T_base_camera[:3, 3]
    n, d = laser_plane_base(calibration, angle, T_base_flange)

    def signed(u, v):
        r = camera_rays(cam, np.stack([u, v], axis=1)) @ T_base_camera[:3, :3].T
        t, which = _hits(surfaces, origin, r)
        return np.where(np.isfinite(t), (origin + r * np.where(np.isfinite(t), t, 0)[:, None]) @ n - d, np.nan), which

    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    s, which = signed(u.ravel().astype(float), v.ravel().astype(float))
    s, which = s.reshape(cam.height, cam.width), which.reshape(cam.height, cam.width)
    cross = (
        (np.sign(s[:, :-1]) != np.sign(s[:, 1:]))
        & np.isfinite(s[:, :-1])
        & np.isfinite(s[:, 1:])
        & (which[:, :-1] == which[:, 1:])
    )
    rows, cols = np.nonzero(cross)
    lo, hi = cols.astype(float), cols + 1.0
    slo, shi = s[rows, cols], s[rows, cols + 1]
    vv = rows.astype(float)
    for _ in range(iterations):  # bisection to 1/64 px, then a secant step: s is smooth across a pixel
        mid = 0.5 * (lo + hi)
        sm, _ = signed(mid, vv)
        left = np.sign(sm) == np.sign(slo)
        lo, slo = np.where(left, mid, lo), np.where(left, sm, slo)
        hi, shi = np.where(left, hi, mid), np.where(left, shi, sm)
    u0 = lo - slo * (hi - lo) / (shi - slo)
    return np.stack([u0, vv], axis=1)
