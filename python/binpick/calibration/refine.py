"""Eye-in-hand bundle adjustment: the camera intrinsics, the hand-eye transform and the board's
pose in the base frame refined together by the corners' reprojection error, every view's camera
pose being the chain ``T_base_flange @ T_flange_camera`` (the robot poses read back are taken as
known). A free board pose per view, as intrinsics calibration alone uses, lets focal length and
distance trade against each other; the chain ties all views to the robot's measured motion."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import CalibrationError
from ..transforms import inverse, rotation_about

__all__ = ["EyeInHandRefinement", "refine_eye_in_hand"]

# Finite-difference steps: px for fx, fy, cx, cy; unitless for k1, k2, p1, p2, k3; rad; mm.
_STEPS = np.array([1e-3] * 4 + [1e-6] * 5 + [1e-7] * 3 + [1e-4] * 3 + [1e-7] * 3 + [1e-4] * 3)


@dataclass(frozen=True, eq=False)
class EyeInHandRefinement:
    """The refined ``camera``, ``T_flange_camera`` and ``T_base_board``, the reprojection RMS (px)
    overall and per view, and the Levenberg–Marquardt iterations run."""

    camera: CameraIntrinsics
    T_flange_camera: np.ndarray
    T_base_board: np.ndarray
    rms: float
    per_view_rms: np.ndarray
    iterations: int


def _moved(T: np.ndarray, rot: np.ndarray, shift: np.ndarray) -> np.ndarray:
    out = T.copy()
    angle = float(np.linalg.norm(rot))
    if angle > 0:
        out[:3, :3] = rotation_about(rot / angle, angle) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + shift
    return out


def _mean_pose(poses: Sequence[np.ndarray]) -> np.ndarray:
    u, _, vt = np.linalg.svd(sum(T[:3, :3] for T in poses))
    T = np.eye(4)
    T[:3, :3] = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    T[:3, 3] = np.mean([P[:3, 3] for P in poses], axis=0)
    return T


def refine_eye_in_hand(
    object_points: np.ndarray,
    corners: Sequence[np.ndarray],
    T_base_flanges: Sequence[np.ndarray],
    camera: CameraIntrinsics,
    T_flange_camera: np.ndarray,
    T_camera_boards: Sequence[np.ndarray],
    *,
    iterations: int = 30,
) -> EyeInHandRefinement:
    """Refines ``camera`` (fx, fy, cx, cy and the five distortion terms) and ``T_flange_camera``
    from their first estimates (e.g. :func:`calibrate_camera` and :func:`calibrate_hand_eye`), and
    the board in the base frame (started from the mean of ``T_base_flange @ X @ T_camera_board``),
    by Levenberg–Marquardt on the corners' reprojection error (px) over every view."""
    obj = np.asarray(object_points, dtype=np.float64).reshape(-1, 3)
    uv = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in corners]
    flanges = [np.asarray(F, dtype=np.float64) for F in T_base_flanges]
    if not (len(uv) == len(flanges) == len(T_camera_boards)) or len(uv) < 3:
        raise CalibrationError("corners: one set of corners, one flange pose and one board pose per view, 3 or more")
    K0, d0 = camera.K, camera.dist
    intr = np.array([K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], *d0])
    X = np.asarray(T_flange_camera, dtype=np.float64)
    B = _mean_pose([F @ X @ np.asarray(T, dtype=np.float64) for F, T in zip(flanges, T_camera_boards)])

    def residuals(intr: np.ndarray, X: np.ndarray, B: np.ndarray) -> np.ndarray:
        K = np.array([[intr[0], camera.K[0, 1], intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
        out = []
        for F, c in zip(flanges, uv):
            T = inverse(F @ X) @ B
            proj, _ = cv2.projectPoints(obj, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, intr[4:])
            out.append((proj.reshape(-1, 2) - c).ravel())
        return np.concatenate(out)

    def apply(step: np.ndarray, intr: np.ndarray, X: np.ndarray, B: np.ndarray) -> tuple:
        return intr + step[:9], _moved(X, step[9:12], step[12:15]), _moved(B, step[15:18], step[18:21])

    r = residuals(intr, X, B)
    cost, lam, done = float(r @ r), 1e-3, 0
    while done < iterations:
        done += 1
        J = np.empty((len(r), 21))
        for k in range(21):
            d = np.zeros(21)
            d[k] = _STEPS[k]
            J[:, k] = (residuals(*apply(d, intr, X, B)) - r) / _STEPS[k]
        JtJ, Jtr = J.T @ J, J.T @ r
        improved = False
        for _ in range(10):
            step = np.linalg.solve(JtJ + lam * np.diag(np.diag(JtJ)), -Jtr)
            trial = apply(step, intr, X, B)
            r_trial = residuals(*trial)
            c_trial = float(r_trial @ r_trial)
            if c_trial < cost:
                intr, X, B = trial
                r, improved = r_trial, cost - c_trial > 1e-12 * cost
                cost, lam = c_trial, max(lam / 10, 1e-9)
                break
            lam *= 10
        if not improved:
            break
    K = np.array([[intr[0], camera.K[0, 1], intr[2]], [0.0, intr[1], intr[3]], [0.0, 0.0, 1.0]])
    per_view = np.sqrt(np.mean(r.reshape(len(uv), -1, 2) ** 2 * 2, axis=(1, 2)))
    return EyeInHandRefinement(
        camera=CameraIntrinsics(width=camera.width, height=camera.height, K=K, dist=intr[4:]),
        T_flange_camera=X,
        T_base_board=B,
        rms=float(np.sqrt(np.mean(np.sum(r.reshape(-1, 2) ** 2, axis=1)))),
        per_view_rms=per_view,
        iterations=done,
    )
