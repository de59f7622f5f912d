"""General laser calibration: the lit line on checkerboard planes at several board poses and
motor angles gives points of each sheet; a robust plane per angle; the projector's rotation
axis and its pose at angle 0 fitted across angles."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .._validate import as_angles, as_points, as_transform, count, positive
from ..camera import CameraIntrinsics
from ..errors import CalibrationError, SingularGeometryError

__all__ = ["LaserCalibration", "fit_plane", "laser_points_on_board"]


def laser_points_on_board(pixels: np.ndarray, camera: CameraIntrinsics, T_camera_board: np.ndarray) -> np.ndarray:
    """The 3-D points (camera frame, mm) where the rays through ``pixels`` meet the board plane."""
    from ..vision._triangulate import pixel_rays  # vision depends on calibration's file types, not the reverse

    T = as_transform(T_camera_board, "T_camera_board")
    rays = pixel_rays(pixels, camera)
    n = T[:3, 2]
    denom = rays @ n
    if (np.abs(denom) < 1e-9 * np.linalg.norm(rays, axis=1)).any():
        raise SingularGeometryError("pixels: a ray is parallel to the board; tilt the board towards the camera")
    s = (n @ T[:3, 3]) / denom
    if (s <= 0).any():
        raise SingularGeometryError("T_camera_board: the board plane lies behind the camera for some pixels")
    return rays * s[:, None]


#: Most RANSAC iterations :func:`fit_plane` runs: each costs a pass over every point, and a few
#: hundred find a plane holding half the points with near certainty; far more is a mistake
#: that would run for hours.
MAX_RANSAC_ITERATIONS = 100_000


def fit_plane(
    points: np.ndarray, *, inlier_distance: float = 0.5, iterations: int = 200, seed: int = 0
) -> tuple[np.ndarray, float, np.ndarray]:
    """A robust plane through ``points`` (N, 3): RANSAC on triples, then a least-squares refit on
    the inliers (within ``inlier_distance`` mm). Returns (unit normal, offset, inlier mask),
    the plane being ``normal · x = offset``. ``iterations``: RANSAC triples drawn, 1 to
    :data:`MAX_RANSAC_ITERATIONS`; ``seed``: a non-negative integer fixing the draw."""
    pts = as_points(points, "points", min_points=3)
    tol = positive(inlier_distance, "inlier_distance")
    iterations = count(iterations, "iterations", 1, MAX_RANSAC_ITERATIONS)
    rng = np.random.default_rng(count(seed, "seed"))
    best = None
    for _ in range(iterations):
        a, b, c = pts[rng.choice(len(pts), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n /= norm
        inl = np.abs((pts - a) @ n) < tol
        if best is None or inl.sum() > best.sum():
            best = inl
    if best is None or best.sum() < 3:
        raise SingularGeometryError(
            "points: collinear or too few to define a plane; observe the line on the board at more than one pose"
        )
    for _ in range(3):
        centre = pts[best].mean(axis=0)
        _, sv, vt = np.linalg.svd(pts[best] - centre, full_matrices=False)
        if sv[1] < 1e-6 * max(sv[0], 1e-12):
            raise SingularGeometryError("points: all on one line; the sheet needs the line on at least two board poses")
        n = vt[2]
        best = np.abs((pts - centre) @ n) < tol
    return n, float(n @ centre), best


@dataclass(frozen=True, eq=False)
class LaserCalibration:
    """The outcome of :meth:`LaserCalibration.fit`.

    ``T_camera_laser``: the projector pose at motor angle 0 (its y axis is the rotation axis,
    its origin the axis point nearest the camera centre); ``planes``: the plane fitted at each
    angle, (K, 4) rows ``(nx, ny, nz, offset)``; ``rms``: RMS distance (mm) of all inlier points
    to the model's sheet at their angle; ``per_angle_rms``: the same per angle.
    """

    T_camera_laser: np.ndarray
    angles: np.ndarray
    planes: np.ndarray
    rms: float
    per_angle_rms: np.ndarray

    def __repr__(self) -> str:
        return f"LaserCalibration({len(self.angles)} angles, rms={self.rms:.4f} mm)"

    @classmethod
    def fit(
        cls,
        angles: Sequence[float],
        points: Sequence[np.ndarray],
        *,
        inlier_distance: float = 0.5,
        point_angles: Optional[Sequence[np.ndarray]] = None,
    ) -> LaserCalibration:
        """Fits the projector from the sheet's points at each motor angle.

        ``points[k]`` (N_k, 3) are lit points in the camera frame (from :func:`laser_points_on_board`
        on two or more board poses) seen at motor angle ``angles[k]`` (radians); at least three
        distinct angles are needed. ``point_angles[k]`` (N_k,), if given, is the angle each point
        was really seen at (a motor stops within a tick of its goal, so the stations of one set
        differ slightly): the per-angle planes use ``angles[k]``, the final joint fit each point's own.
        """
        theta = as_angles(angles, "angles")
        pts = [as_points(p, f"points[{k}]", min_points=3) for k, p in enumerate(points)]
        if len(pts) != len(theta):
            raise CalibrationError(f"points: {len(pts)} point sets for {len(theta)} angles; give one set per angle")
        if len(np.unique(np.round(theta, 9))) < 3:
            raise CalibrationError("angles: at least three distinct motor angles are needed to find the rotation axis")
        fits = [fit_plane(p, inlier_distance=inlier_distance) for p in pts]
        normals = np.array([f[0] for f in fits])
        offsets = np.array([f[1] for f in fits])
        # Orient every normal like the one at the middle angle: the sweep spans less than π.
        ref = normals[np.argsort(theta)[len(theta) // 2]]
        flip = np.where(normals @ ref < 0, -1.0, 1.0)
        normals, offsets = normals * flip[:, None], offsets * flip
        # n(θ) = cos θ · x0 − sin θ · z0 for the laser axes x0, z0 at angle 0.
        A = np.stack([np.cos(theta), -np.sin(theta)], axis=1)
        (x0, z0), *_ = np.linalg.lstsq(A, normals, rcond=None)
        axis = np.linalg.svd(normals)[2][2]
        if np.cross(x0, axis) @ z0 < 0:
            axis = -axis
        x0 = x0 - (x0 @ axis) * axis
        x0 /= np.linalg.norm(x0)
        z0 = np.cross(x0, axis)
        if z0[2] < 0:  # the light travels away from the camera (+z_L into the scene): turn the frame by π about y
            x0, z0 = -x0, -z0
        # Every sheet contains the axis: n_k · o = d_k; the row `axis · o = 0` picks the point nearest the camera.
        origin, *_ = np.linalg.lstsq(np.vstack([normals, axis]), np.append(offsets, 0.0), rcond=None)
        T = np.eye(4)
        T[:3, :3] = np.stack([x0, axis, z0], axis=1)
        T[:3, 3] = origin
        if point_angles is None:
            own = [np.full(len(p), th) for p, th in zip(pts, theta)]
        else:
            if len(point_angles) != len(pts):
                raise CalibrationError(
                    f"point_angles: {len(point_angles)} arrays for {len(pts)} point sets; give one per set"
                )
            own = [as_angles(a, f"point_angles[{k}]", size=len(p)) for k, (a, p) in enumerate(zip(point_angles, pts))]
        T = _refine(T, [p[inl] for p, (_, _, inl) in zip(pts, fits)], [a[inl] for a, (_, _, inl) in zip(own, fits)])
        per_angle, all_res = [], []
        for p, a, (_, _, inl) in zip(pts, own, fits):
            res = _sheet_residuals(T, p[inl], a[inl])
            per_angle.append(float(np.sqrt(np.mean(res**2))))
            all_res.append(res)
        res = np.concatenate(all_res)
        return cls(
            T_camera_laser=T,
            angles=theta,
            planes=np.column_stack([normals, offsets]),
            rms=float(np.sqrt(np.mean(res**2))),
            per_angle_rms=np.array(per_angle),
        )


def _sheet_residuals(T: np.ndarray, points: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Signed distance of each point to the sheet of ``T_camera_laser = T`` at its angle."""
    normals = np.cos(theta)[:, None] * T[:3, 0] - np.sin(theta)[:, None] * T[:3, 2]
    return np.einsum("ij,ij->i", points - T[:3, 3], normals)


def _refine(
    T: np.ndarray, points: Sequence[np.ndarray], angles: Sequence[np.ndarray], iterations: int = 20
) -> np.ndarray:
    """Gauss–Newton on the projector pose: every inlier point's distance to the sheet at its own
    angle, over the pose's rotation and origin at once (the per-angle planes above are fitted one
    by one, so their errors pass into the axis unweighted). The origin is then moved along the
    axis to the point nearest the camera centre (the model cannot see where on the axis it is)."""
    from ..transforms import rotation_about

    pts = np.concatenate(points)
    theta = np.concatenate(angles)
    eps = 1e-6

    def moved(T: np.ndarray, step: np.ndarray) -> np.ndarray:
        out = T.copy()
        angle = float(np.linalg.norm(step[:3]))
        if angle > 0:
            out[:3, :3] = rotation_about(step[:3] / angle, angle) @ T[:3, :3]
        out[:3, 3] = T[:3, 3] + step[3:]
        return out

    for _ in range(iterations):
        r = _sheet_residuals(T, pts, theta)
        J = np.empty((len(r), 6))
        for k in range(6):
            d = np.zeros(6)
            d[k] = eps
            J[:, k] = (_sheet_residuals(moved(T, d), pts, theta) - r) / eps
        step, *_ = np.linalg.lstsq(J, -r, rcond=None)  # min-norm: the slide along the axis stays put
        T = moved(T, step)
        if np.linalg.norm(step[:3]) < 1e-10 and np.linalg.norm(step[3:]) < 1e-7:
            break
    axis = T[:3, 1]
    T[:3, 3] -= (T[:3, 3] @ axis) * axis
    return T
