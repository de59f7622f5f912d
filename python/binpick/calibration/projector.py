"""The paper's projector calibration (Table 1, Eq. 15–19): the laser origin (p_x, 0, p_z) in
the camera frame from the board distance along the optical axis and the motor angle at which
the line passes through the principal point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_angles, as_float_array, as_transform, check_finite
from ..errors import CalibrationError, ShapeError, SingularGeometryError

__all__ = ["ProjectorCalibration", "axis_depth", "calibrate_projector"]

#: Smallest |sin θ| accepted: at θ = 0 the sheet is parallel to the optical axis and never crosses it.
_MIN_SINE = 1e-3


def axis_depth(T_camera_board: np.ndarray) -> float:
    """The distance (mm) along the camera's optical axis to the board plane (Eq. 15's use in Table 1)."""
    T = as_transform(T_camera_board, "T_camera_board")
    n, p = T[:3, 2], T[:3, 3]
    if abs(n[2]) < 1e-6:
        raise SingularGeometryError(
            "T_camera_board: the board is edge-on to the camera; the optical axis never meets it"
        )
    depth = float(n @ p / n[2])
    if depth <= 0:
        raise SingularGeometryError(
            f"T_camera_board: the board plane meets the optical axis behind the camera ({depth:.1f} mm)"
        )
    return depth


@dataclass(frozen=True)
class ProjectorCalibration:
    """The laser origin in the camera frame, ``p_x`` and ``p_z`` (mm; ``p_y`` = 0 by the paper's
    assumption), the residual of each observation (mm along the optical axis) and their RMS."""

    p_x: float
    p_z: float
    residuals: np.ndarray
    rms: float

    @property
    def T_camera_laser(self) -> np.ndarray:
        """The projector pose at motor angle 0 under the paper's assumptions (no tilt about x or z)."""
        T = np.eye(4)
        T[0, 3], T[2, 3] = self.p_x, self.p_z
        return T


def calibrate_projector(distances, angles) -> ProjectorCalibration:
    """Solves the paper's Eq. 16–19 for p_x and p_z by least squares.

    ``distances[i]`` is the board's distance along the optical axis at step i (mm; the paper's
    d_1 + d_i, see :func:`axis_depth`) and ``angles[i]`` the motor angle (radians) at which the
    laser line passes through the principal point. With the laser at (p_x, 0, p_z) and normal
    (cos θ, 0, −sin θ) (Eq. 11), the sheet meets the optical axis at ``p_z − p_x·cot θ`` — the
    paper's ``p_x tan θ = p_z + d`` with its angle measured from the other axis.
    """
    d = as_float_array(distances, "distances")
    if d.ndim != 1:
        raise ShapeError(f"distances: expected a 1-D array of distances (mm), got shape {d.shape}")
    check_finite(d, "distances")
    theta = as_angles(angles, "angles", size=len(d))
    if len(d) < 3:
        raise CalibrationError(
            f"distances: {len(d)} observations; at least 3 are needed to solve p_x, p_z and see a residual"
        )
    if (np.abs(np.sin(theta)) < _MIN_SINE).any():
        i = int(np.argmax(np.abs(np.sin(theta)) < _MIN_SINE))
        raise SingularGeometryError(
            f"angles: element {i} is {theta[i]:g} rad; at angle 0 the "
            "sheet is parallel to the optical axis and cannot cross it"
        )
    A = np.stack([-1.0 / np.tan(theta), np.ones_like(theta)], axis=1)
    if np.ptp(d) < 1e-6 or np.linalg.cond(A) > 1e8:
        raise SingularGeometryError(
            "distances: all observations at one distance do not separate "
            "p_x from p_z; move the camera along its z axis between steps"
        )
    (p_x, p_z), *_ = np.linalg.lstsq(A, d, rcond=None)
    residuals = d - A @ np.array([p_x, p_z])
    return ProjectorCalibration(
        p_x=float(p_x), p_z=float(p_z), residuals=residuals, rms=float(np.sqrt(np.mean(residuals**2)))
    )
