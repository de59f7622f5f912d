"""Eye-to-hand calibration: where a fixed 3-D camera stands in the robot's base frame.

The arm carries a sphere (a matte ball on the flange, anywhere on it: its offset need not be
known) through stations in the camera's view; at each the camera takes a depth shot and the
robot reports its flange pose. The sphere's centre is fitted in each shot (:func:`fit_sphere`
on the points :func:`sphere_points` picks: the nearest surface to the camera, the ball held
above everything else). Then, for every station i,

    T_base_camera · c_cam_i = T_base_flange_i · c_flange

with two unknowns, the camera's pose and the centre's offset on the flange
(:func:`solve_eye_to_hand`): a linear solution of all twelve entries of T_base_camera and the
three of c_flange, its rotation projected onto SO(3), then alternating Kabsch and least squares
until neither moves. It needs stations whose flange orientations differ (at least two axes of
turn) and positions spread over the view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from .._validate import as_points, positive
from ..errors import CalibrationError

__all__ = ["fit_sphere", "sphere_points", "solve_eye_to_hand", "EyeToHandSolution", "sphere_mesh"]


def sphere_mesh(radius: float, subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere of ``radius`` mm about the origin: (vertices, faces), for rendering the target."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t)]
    v += [(t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = [np.array(p, dtype=float) / np.linalg.norm(p) for p in v]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2)]
    faces += [(10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5)]
    faces += [(2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        mid: dict[tuple[int, int], int] = {}
        split = []
        for a, b, c in faces:
            ab, bc, ca = (_middle(verts, mid, x, y) for x, y in ((a, b), (b, c), (c, a)))
            split += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = split
    return np.array(verts) * positive(radius, "radius"), np.array(faces, dtype=np.int64)


def _middle(verts: list, mid: dict, a: int, b: int) -> int:
    """The index of the unit vertex halfway between ``a`` and ``b`` (added once per edge)."""
    key = (min(a, b), max(a, b))
    if key not in mid:
        p = verts[a] + verts[b]
        verts.append(p / np.linalg.norm(p))
        mid[key] = len(verts) - 1
    return mid[key]


def fit_sphere(points: Any, radius: Optional[float] = None, *, iterations: int = 20) -> tuple[np.ndarray, float, float]:
    """The sphere through ``points`` (N, 3, mm): (centre, radius, rms residual). Algebraic least
    squares first, then Gauss–Newton on the distances (the radius held at ``radius`` when it is
    known); points more than 3 rms off are dropped once. CalibrationError for too few points."""
    p = as_points(points, "points", min_points=10)
    centre = _algebraic_centre(p)
    for trim in (False, True):
        for _ in range(iterations):
            d = p - centre
            dist = np.linalg.norm(d, axis=1)
            r = float(dist.mean()) if radius is None else float(radius)
            J = -d / dist[:, None]
            residual = dist - r
            if radius is None:
                J = np.hstack([J, -np.ones((len(p), 1))])
            step, *_ = np.linalg.lstsq(J, -residual, rcond=None)
            centre = centre + step[:3]
            if np.linalg.norm(step[:3]) < 1e-7:
                break
        dist = np.linalg.norm(p - centre, axis=1)
        r = float(dist.mean()) if radius is None else float(radius)
        rms = float(np.sqrt(np.mean((dist - r) ** 2)))
        if not trim:
            keep = np.abs(dist - r) <= max(3.0 * rms, 1e-9)
            if keep.sum() < 10:
                break
            p = p[keep]
    return centre, r, rms


def _algebraic_centre(p: np.ndarray) -> np.ndarray:
    A = np.hstack([2.0 * p, np.ones((len(p), 1))])
    b = np.einsum("ij,ij->i", p, p)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    return sol[:3]


def sphere_points(shot: Any, radius: float) -> np.ndarray:
    """The points of a depth shot (camera frame, mm) on the calibration sphere held nearest the
    camera: those within 1.1 radii in depth of the nearest surface, then those within 1.5 radii
    of their median (a ball seen from one side shows a cap less than a radius deep)."""
    p = as_points(shot, "shot", min_points=10)
    r = positive(radius, "radius")
    near = p[p[:, 2] < np.quantile(p[:, 2], 0.0005) + 1.1 * r]
    if len(near) < 10:
        raise CalibrationError("shot: fewer than 10 points near the camera; is the sphere in view?")
    centre = np.median(near, axis=0)
    return near[np.linalg.norm(near - centre, axis=1) < 1.5 * r]


@dataclass(frozen=True, eq=False)
class EyeToHandSolution:
    """``T_base_camera`` (4×4, mm), the sphere's centre on the flange ``c_flange`` (mm), and the
    residual of each station (mm) with their rms."""

    T_base_camera: np.ndarray
    c_flange: np.ndarray
    residuals_mm: np.ndarray
    rms_mm: float


def _kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising Σ |R p + t − q|²."""
    pm, qm = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - pm).T @ (Q - qm))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, qm - R @ pm


def solve_eye_to_hand(T_base_flanges: Any, centres_camera: Any, *, iterations: int = 200) -> EyeToHandSolution:
    """The fixed camera's pose from the sphere's centres ``centres_camera`` (N, 3, camera frame)
    seen at the flange poses ``T_base_flanges`` (N, 4, 4); see the module docstring.
    CalibrationError for fewer than 5 stations or stations that do not constrain the solution."""
    T_bf = np.asarray(T_base_flanges, dtype=np.float64)
    c = as_points(centres_camera, "centres_camera", min_points=5)
    if T_bf.shape != (len(c), 4, 4):
        raise CalibrationError(f"T_base_flanges: expected ({len(c)}, 4, 4), got {T_bf.shape}")
    R_i, t_i = T_bf[:, :3, :3], T_bf[:, :3, 3]
    n = len(c)
    # R c_i + t − R_i x = t_i, linear in the 9 entries of R, t and x.
    A = np.zeros((3 * n, 15))
    for i in range(n):
        for r in range(3):
            A[3 * i + r, 3 * r : 3 * r + 3] = c[i]
            A[3 * i + r, 9 + r] = 1.0
            A[3 * i + r, 12:15] = -R_i[i, r]
    sv = np.linalg.svd(A, compute_uv=False)
    if sv[-1] < 1e-9 * sv[0]:
        raise CalibrationError(
            "the stations do not determine the camera's pose: turn the flange about at least two axes between them"
        )
    sol, *_ = np.linalg.lstsq(A, t_i.reshape(-1), rcond=None)
    U, _, Vt = np.linalg.svd(sol[:9].reshape(3, 3))
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    x = sol[12:15]
    for _ in range(iterations):
        targets = np.einsum("nij,j->ni", R_i, x) + t_i
        R, t = _kabsch(c, targets)
        B = R_i.reshape(-1, 3)
        x_new, *_ = np.linalg.lstsq(B, (c @ R.T + t - t_i).reshape(-1), rcond=None)
        moved = float(np.linalg.norm(x_new - x))
        x = x_new
        if moved < 1e-9:
            break
    targets = np.einsum("nij,j->ni", R_i, x) + t_i
    R, t = _kabsch(c, targets)
    residuals = np.linalg.norm(c @ R.T + t - targets, axis=1)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return EyeToHandSolution(T, x, residuals, float(np.sqrt(np.mean(residuals**2))))
