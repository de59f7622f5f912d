"""A solved calibration against a known one (a digital twin's ``true_calibration.toml``):
the hand-eye position and rotation errors, the focal lengths' relative errors and the laser
sheet's tilt at every motor angle, each against the commissioning targets
(:data:`TARGETS`, issue 15: hand-eye within 0.5 mm and 0.1°, fx and fy within 0.1 %, the laser
plane within 0.1° at every motor angle).

Lengths mm, angles radians in code; :meth:`CalibrationComparison.table` prints degrees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_angles, instance_of, parse_toml, read_text_file
from ..errors import CalibrationError, InvalidInputError
from ..transforms import rotation_angle_deg
from ._file import MAX_FILE_BYTES, CellCalibration

__all__ = ["TARGETS", "CalibrationComparison", "compare_calibrations", "captured_angles"]

#: The commissioning targets: hand-eye position (mm) and rotation (degrees), focal lengths
#: (relative), laser sheet tilt (degrees) at every motor angle.
TARGETS = {"hand_eye_mm": 0.5, "hand_eye_deg": 0.1, "focal_rel": 1e-3, "laser_deg": 0.1}

#: Motor angles compared by default: every degree across ±30°, wider than a scan's sweep.
DEFAULT_ANGLES = tuple(np.radians(np.arange(-30.0, 30.5, 1.0)))


@dataclass(frozen=True)
class CalibrationComparison:
    """The errors of a solved calibration against the truth (see the module docstring).

    ``laser_deg[i]`` is the angle between the two laser sheets at motor angle ``angles[i]`` (rad);
    ``captured_deg[i]`` the same at ``captured[i]``, the motor angles the calibration was
    captured at (see :func:`captured_angles`; empty when they are not known)."""

    hand_eye_mm: float
    hand_eye_deg: float
    fx_rel: float
    fy_rel: float
    angles: tuple[float, ...]
    laser_deg: tuple[float, ...]
    captured: tuple[float, ...] = ()
    captured_deg: tuple[float, ...] = ()

    def _worst_laser(self) -> tuple[float, float]:
        """(motor angle rad, sheet error deg) of the worst angle, compared or captured."""
        angles, errors = self.angles + self.captured, self.laser_deg + self.captured_deg
        worst = int(np.argmax(errors))
        return angles[worst], errors[worst]

    @property
    def failures(self) -> list[str]:
        """The targets missed, each as a sentence; empty when every target is met."""
        t, out = TARGETS, []
        if self.hand_eye_mm > t["hand_eye_mm"]:
            out.append(f"hand-eye position is {self.hand_eye_mm:.3f} mm off (target {t['hand_eye_mm']} mm)")
        if self.hand_eye_deg > t["hand_eye_deg"]:
            out.append(f"hand-eye rotation is {self.hand_eye_deg:.4f}° off (target {t['hand_eye_deg']}°)")
        for name, rel in (("fx", self.fx_rel), ("fy", self.fy_rel)):
            if abs(rel) > t["focal_rel"]:
                out.append(f"{name} is {rel * 100:+.4f} % off (target {t['focal_rel'] * 100:g} %)")
        angle, error = self._worst_laser()
        if error > t["laser_deg"]:
            out.append(
                f"the laser sheet is {error:.4f}° off at motor angle {math.degrees(angle):.1f}° "
                f"(target {t['laser_deg']}°)"
            )
        return out

    def table(self) -> str:
        """The errors and targets as printed lines: one per target, the laser sheet's at the
        worst motor angle, then one per captured motor angle (or a line saying none is known)."""
        t = TARGETS
        angle, error = self._worst_laser()
        laser = f"{t['laser_deg']}°"
        rows = [
            ("hand-eye position", f"{self.hand_eye_mm:.3f} mm", f"{t['hand_eye_mm']} mm", self.hand_eye_mm),
            ("hand-eye rotation", f"{self.hand_eye_deg:.4f}°", f"{t['hand_eye_deg']}°", self.hand_eye_deg),
            ("fx", f"{self.fx_rel * 100:+.4f} %", f"{t['focal_rel'] * 100:g} %", abs(self.fx_rel)),
            ("fy", f"{self.fy_rel * 100:+.4f} %", f"{t['focal_rel'] * 100:g} %", abs(self.fy_rel)),
            (
                f"laser sheet (worst of {len(self.angles) + len(self.captured)} angles, at {math.degrees(angle):.0f}°)",
                f"{error:.4f}°",
                laser,
                error,
            ),
            *(
                (f"laser sheet at captured motor angle {math.degrees(a):+.1f}°", f"{e:.4f}°", laser, e)
                for a, e in zip(self.captured, self.captured_deg)
            ),
        ]
        limits = (t["hand_eye_mm"], t["hand_eye_deg"], t["focal_rel"], t["focal_rel"])
        limits += (t["laser_deg"],) * (len(rows) - len(limits))
        width = max(len(r[0]) for r in rows)
        lines = [f"{'':{width}}  {'error':>11}  {'target':>7}"]
        for (name, err, target, value), limit in zip(rows, limits):
            lines.append(f"{name:{width}}  {err:>11}  {target:>7}  {'ok' if value <= limit else 'MISSED'}")
        if not self.captured:
            lines.append(
                "(no captured motor angles: `binpick calibrate compare` reads them from the solved file's "
                "[residuals.laser] table, which `binpick calibrate solve` writes)"
            )
        return "\n".join(lines)


def _sheet_tilt_deg(solved: CellCalibration, truth: CellCalibration, angles: np.ndarray) -> tuple[float, ...]:
    """The angle (deg) between the two calibrations' laser sheets at each motor angle (rad)."""
    # The sheet is the laser frame's y-z plane (the motor turns it about its own y axis), so its
    # normal is the frame's x axis; the sign of a normal is no error. atan2 of the cross and dot
    # products keeps small angles exact (arccos of the dot product loses half the digits).
    n = np.array([solved.T_camera_laser_at(x)[:3, 0] for x in angles]).reshape(-1, 3)
    n0 = np.array([truth.T_camera_laser_at(x)[:3, 0] for x in angles]).reshape(-1, 3)
    tilt = np.degrees(np.arctan2(np.linalg.norm(np.cross(n, n0), axis=1), np.abs((n * n0).sum(axis=1))))
    return tuple(float(t) for t in tilt)


def compare_calibrations(
    solved: CellCalibration,
    truth: CellCalibration,
    angles: Sequence[float] = DEFAULT_ANGLES,
    *,
    captured: Sequence[float] = (),
) -> CalibrationComparison:
    """The errors of ``solved`` against ``truth`` at the motor ``angles`` (rad) and at the motor
    angles the calibration was ``captured`` at (rad, see :func:`captured_angles`)."""
    for name, cal in (("solved", solved), ("truth", truth)):
        instance_of(cal, CellCalibration, name, "CellCalibration.load(path)")
    a = as_angles(angles, "angles")
    if len(a) == 0:
        raise InvalidInputError("angles: give at least one motor angle (rad)")
    c = as_angles(list(captured), "captured")
    X, X0 = solved.T_flange_camera, truth.T_flange_camera
    K, K0 = solved.camera.K, truth.camera.K
    return CalibrationComparison(
        hand_eye_mm=float(np.linalg.norm(X[:3, 3] - X0[:3, 3])),
        hand_eye_deg=float(rotation_angle_deg(X0[:3, :3].T @ X[:3, :3])),
        fx_rel=float(K[0, 0] / K0[0, 0] - 1.0),
        fy_rel=float(K[1, 1] / K0[1, 1] - 1.0),
        angles=tuple(float(x) for x in a),
        laser_deg=_sheet_tilt_deg(solved, truth, a),
        captured=tuple(float(x) for x in c),
        captured_deg=_sheet_tilt_deg(solved, truth, c),
    )


def captured_angles(path: Any) -> tuple[float, ...]:
    """The motor angles (rad) a solved calibration file says its laser sheet was captured at (the
    ``angles_rad`` of its ``[residuals.laser]`` table, written by ``binpick calibrate solve``);
    empty when the file has no such table. CalibrationError naming the file for a malformed one."""
    source = str(path)
    doc = parse_toml(
        read_text_file(path, "calibration file", CalibrationError, max_bytes=MAX_FILE_BYTES), source, CalibrationError
    )
    residuals = doc.get("residuals", {})
    laser = residuals.get("laser", {}) if isinstance(residuals, dict) else None
    if not isinstance(laser, dict):
        raise CalibrationError(f"{source}: [residuals.laser] must be a table; solve the calibration again")
    if "angles_rad" not in laser:
        return ()
    try:
        return tuple(float(x) for x in as_angles(laser["angles_rad"], "residuals.laser.angles_rad"))
    except InvalidInputError as exc:
        raise CalibrationError(f"{source}: {exc}") from None
