"""Eye-in-hand calibration: ``T_flange_camera`` from robot poses and board poses, by every
method of ``cv2.calibrateHandEye`` (Tsai, Park, Horaud, Andreff, Daniilidis), each judged by how
still the board stays in the base frame; the stillest wins."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from .._validate import as_transform
from ..errors import CalibrationError, InvalidInputError

__all__ = ["HAND_EYE_METHODS", "HandEyeCalibration", "calibrate_hand_eye"]

#: The methods of cv2.calibrateHandEye, by name (OpenCV 4.x; the 5.0 wheels lack the function,
#: which is why the project pins opencv-python-headless below 5).
HAND_EYE_METHODS = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park": cv2.CALIB_HAND_EYE_PARK,
    "horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}
#: Lever arm (mm) that turns a rotation residual into a length when methods are ranked.
_LEVER_ARM = 500.0


@dataclass(frozen=True, eq=False)
class HandEyeCalibration:
    """The chosen ``T_flange_camera`` and ``method``, and for every method that found a solution
    its transform and its residuals: ``residuals[m] = (translation RMS mm, rotation RMS deg)`` of
    the board's pose in the base frame across the views (zero for perfect data).
    :meth:`residual_table` prints them side by side."""

    T_flange_camera: np.ndarray
    method: str
    residuals: dict[str, tuple[float, float]]
    transforms: dict[str, np.ndarray]

    def __repr__(self) -> str:
        t, r = self.residuals[self.method]
        return f"HandEyeCalibration(method={self.method!r}, residual {t:.3f} mm, {r:.4f}°)"

    def residual_table(self) -> str:
        """The residuals of every method, one line each, the chosen one marked with ``*``."""
        lines = [f"{'method':<12}{'mm':>9}{'deg':>9}"]
        for name, (t, r) in self.residuals.items():
            lines.append(f"{name:<12}{t:>9.3f}{r:>9.4f}{'  *' if name == self.method else ''}")
        return "\n".join(lines)


def _residuals(
    X: np.ndarray, T_base_flanges: list[np.ndarray], T_camera_boards: list[np.ndarray]
) -> tuple[float, float]:
    boards = np.array([Tb @ X @ Tc for Tb, Tc in zip(T_base_flanges, T_camera_boards)])
    t = boards[:, :3, 3]
    t_rms = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))
    u, _, vt = np.linalg.svd(boards[:, :3, :3].sum(axis=0))
    mean_r = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    cosines = (np.einsum("kij,ij->k", boards[:, :3, :3], mean_r) - 1) / 2
    r_rms = float(np.degrees(np.sqrt(np.mean(np.arccos(np.clip(cosines, -1, 1)) ** 2))))
    return t_rms, r_rms


def calibrate_hand_eye(
    T_base_flanges: Sequence[np.ndarray], T_camera_boards: Sequence[np.ndarray], *, method: str = "best"
) -> HandEyeCalibration:
    """``T_flange_camera`` from the robot pose ``T_base_flanges[i]`` and the board pose seen by the
    camera ``T_camera_boards[i]`` (e.g. :func:`board_pose`) at each of at least 3 stations with
    rotations about non-parallel axes. ``method``: one of HAND_EYE_METHODS, or ``"best"`` to run
    them all and keep the one whose board stays stillest in the base frame (rotation residuals
    counted at a 500 mm lever arm)."""
    if method != "best" and method not in HAND_EYE_METHODS:
        raise InvalidInputError(f"method: {method!r} is not 'best' or one of {', '.join(HAND_EYE_METHODS)}")
    flanges = [as_transform(T, f"T_base_flanges[{i}]") for i, T in enumerate(T_base_flanges)]
    boards = [as_transform(T, f"T_camera_boards[{i}]") for i, T in enumerate(T_camera_boards)]
    if len(flanges) != len(boards):
        raise CalibrationError(
            f"T_camera_boards: {len(boards)} board poses for {len(flanges)} robot poses; give one per station"
        )
    if len(flanges) < 3:
        raise CalibrationError(
            f"T_base_flanges: {len(flanges)} stations; hand-eye calibration needs at least 3 (10 or more recommended)"
        )
    rel = [np.linalg.inv(flanges[0]) @ f for f in flanges[1:]]
    axes = [cv2.Rodrigues(r[:3, :3])[0].ravel() for r in rel]
    big = [a / np.linalg.norm(a) for a in axes if np.linalg.norm(a) > np.radians(2)]
    if len(big) < 2 or np.linalg.svd(np.array(big))[1][1] < 0.1:
        raise CalibrationError(
            "T_base_flanges: the flange rotations between stations share one "
            "axis (or are tiny); tilt the hand about at least two different axes"
        )
    names = list(HAND_EYE_METHODS) if method == "best" else [method]
    transforms, residuals = {}, {}
    for name in names:
        try:
            R, t = cv2.calibrateHandEye(
                [f[:3, :3] for f in flanges],
                [f[:3, 3] for f in flanges],
                [b[:3, :3] for b in boards],
                [b[:3, 3] for b in boards],
                method=HAND_EYE_METHODS[name],
            )
        except cv2.error:
            continue
        X = np.eye(4)
        X[:3, :3], X[:3, 3] = R, np.ravel(t)
        if not np.isfinite(X).all():
            continue
        transforms[name] = X
        residuals[name] = _residuals(X, flanges, boards)
    if not transforms:
        raise CalibrationError(
            "T_base_flanges: no hand-eye method found a solution; check that robot and board poses belong together"
        )
    best = min(residuals, key=lambda m: residuals[m][0] + np.radians(residuals[m][1]) * _LEVER_ARM)
    return HandEyeCalibration(T_flange_camera=transforms[best], method=best, residuals=residuals, transforms=transforms)
