"""4×4 rigid-transform helpers shared by the pick loop, the simulator and the tests.

Transforms are 4×4 float arrays named ``T_to_from``; lengths in mm, angles in radians unless a
name says ``_deg``. This is a leaf module: it imports nothing from binpick but the validation
vocabulary and its errors.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Optional

import numpy as np

from ._validate import as_float_array, as_transform, as_vector, count, number
from .errors import InvalidInputError, ShapeError

__all__ = [
    "inverse",
    "translation",
    "rotation_about",
    "quaternion_matrix",
    "matrix_quaternion",
    "rotation_vector",
    "rot_y",
    "rotation_angle_deg",
    "look_down",
    "looking_at",
    "pose_error",
    "laser_sweep",
]


def inverse(T: np.ndarray) -> np.ndarray:
    """The inverse of the rigid transform ``T`` (transposed rotation, rotated-back translation)."""
    T = as_transform(T, "T")
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def translation(x: float, y: float, z: float) -> np.ndarray:
    """The pure translation by (x, y, z) mm."""
    T = np.eye(4)
    x, y, z = _xyz(x, y, z)
    T[:3, 3] = (x, y, z)
    return T


def rotation_about(axis: Any, angle: float) -> np.ndarray:
    """The 3×3 rotation by ``angle`` radians about ``axis`` (any non-zero length; Rodrigues)."""
    a = as_vector(axis, "axis", 3)
    norm = float(np.linalg.norm(a))
    if not norm > 1e-12:
        raise InvalidInputError(f"axis: {a.tolist()} has no direction; pass a non-zero axis")
    a = a / norm
    angle = number(angle, "angle", unit="rad")
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def quaternion_matrix(q: Any) -> np.ndarray:
    """The 3×3 rotation of the quaternion ``q`` = (w, x, y, z), scalar first (any non-zero length)."""
    v = as_vector(q, "q", 4)
    norm = float(np.linalg.norm(v))
    if not norm > 1e-12:
        raise InvalidInputError(f"q: {v.tolist()} is no rotation; pass a non-zero quaternion (w, x, y, z)")
    w, x, y, z = v / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quaternion(R: Any) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of the 3×3 rotation ``R``, with w ≥ 0 (the inverse of
    :func:`quaternion_matrix`). From the largest of the four diagonal combinations (Shepperd), so
    that no component is found by dividing by a small one."""
    R = _rotation(R)
    trace = float(np.trace(R))
    candidates = (trace, R[0, 0], R[1, 1], R[2, 2])
    k = int(np.argmax(candidates))
    if k == 0:
        w = math.sqrt(max(0.0, 1.0 + trace)) / 2.0
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        v = [0.0, 0.0, 0.0]
        v[i] = math.sqrt(max(0.0, 1.0 + R[i, i] - R[j, j] - R[m, m])) / 2.0
        v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
        v[m] = (R[m, i] + R[i, m]) / (4 * v[i])
        q = [(R[m, j] - R[j, m]) / (4 * v[i]), *v]
    out = np.array(q, dtype=np.float64)
    out /= np.linalg.norm(out)
    return -out if out[0] < 0 else out


def rotation_vector(R: Any) -> np.ndarray:
    """The rotation vector (axis × angle, radians, angle in [0, π]) of the 3×3 rotation ``R``; the
    inverse of :func:`rotation_about` (``rotation_about(v, |v|)``). Through the quaternion, so
    that turns near 0 and near π keep their precision."""
    w, *xyz = matrix_quaternion(R)
    v = np.array(xyz)
    s = float(np.linalg.norm(v))
    if s < 1e-15:
        return np.zeros(3)
    return v / s * (2.0 * math.atan2(s, w))


def _rotation(R: Any) -> np.ndarray:
    R = as_float_array(R, "R")
    if R.shape != (3, 3):
        raise ShapeError(f"R: expected a (3, 3) rotation, got shape {R.shape}")
    if not np.isfinite(R).all():
        raise InvalidInputError("R: holds NaN or infinity; pass a finite rotation")
    return R


def rot_y(angle: float) -> np.ndarray:
    """4×4 rotation about y by ``angle`` radians (the laser motor's axis)."""
    angle = number(angle, "angle", unit="rad")
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rotation_angle_deg(R: np.ndarray) -> Any:
    """The angle of the 3×3 rotation ``R`` (or of each of a stack (..., 3, 3)), degrees in [0, 180].

    From cos θ = (tr R − 1) / 2 and sin θ = |axial part of R|, with atan2, so that angles near
    0° and 180° keep full precision (arccos alone loses half the digits near 0°)."""
    R = as_float_array(R, "R")
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ShapeError(f"R: expected a (3, 3) rotation or a stack (..., 3, 3), got shape {R.shape}")
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    axial = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    deg = np.degrees(np.arctan2(np.linalg.norm(axial, axis=-1) / 2.0, cos))
    return float(deg) if deg.ndim == 0 else deg


def look_down(x: float, y: float, z: float) -> np.ndarray:
    """A pose at (x, y, z) whose z axis points straight down (−z of the base) and x axis along base +x."""
    T = np.eye(4)
    x, y, z = _xyz(x, y, z)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (x, y, z)
    return T


#: Steepest tilt :func:`looking_at` takes: beyond it the camera looks nearly level, where the image's
#: x axis (base +x made square to the optical axis) loses its direction.
MAX_LOOK_TILT = math.radians(85.0)


def looking_at(
    target: Any, *, distance: float, tilt: float = 0.0, azimuth: float = 0.0, roll: float = 0.0
) -> np.ndarray:
    """``T_base_camera`` of a camera ``distance`` mm from ``target`` (base frame, mm) with its
    optical axis (+z) through it, tilted ``tilt`` from looking straight down towards ``azimuth``
    (the camera stands on that side of the target: 0 = on its +x side, π/2 = on its +y side) and
    rolled ``roll`` about its optical axis (radians). Before the roll the image's x axis is base
    +x made square to the optical axis, as when looking straight down (:func:`look_down`)."""
    t = as_vector(target, "target", 3)
    distance = number(distance, "distance", 1e-6, 1e9, unit="mm")
    tilt = number(tilt, "tilt", 0.0, MAX_LOOK_TILT, unit="rad")
    azimuth, roll = number(azimuth, "azimuth", unit="rad"), number(roll, "roll", unit="rad")
    toward = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    z = -math.cos(tilt) * np.array([0.0, 0.0, 1.0]) - math.sin(tilt) * toward
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1) @ rotation_about([0.0, 0.0, 1.0], roll)
    T[:3, 3] = t - z * distance
    return T


def _xyz(x: Any, y: Any, z: Any) -> tuple[float, float, float]:
    return number(x, "x", unit="mm"), number(y, "y", unit="mm"), number(z, "z", unit="mm")


def _closest_spin(M: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The rotation R_φ about ``axis`` maximising trace(M R_φ), i.e. minimising the angle of M R_φ.

    With R_φ = a aᵀ + cos φ (I − a aᵀ) + sin φ [a]ₓ the trace is
    aᵀMa + cos φ (tr M − aᵀMa) + sin φ tr(M [a]ₓ), which peaks in closed form."""
    a = axis / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    along = float(a @ M @ a)
    return rotation_about(a, math.atan2(float(np.trace(M @ K)), float(np.trace(M)) - along))


def pose_error(
    T_est: Any,
    T_true: Any,
    symmetries: Sequence[Any] = (),
    *,
    continuous_axis: Optional[Any] = None,
    center: Any = (0.0, 0.0, 0.0),
) -> tuple[float, float]:
    """(rotation error in degrees, translation error in mm) of ``T_est`` against ``T_true``, the
    smallest over the part's symmetries.

    ``symmetries`` are 4×4 ``T_object_object`` maps of the part onto itself (the identity is always
    included). With ``continuous_axis`` (a unit axis in the model frame through ``center``) each of
    them is also turned about that axis by the angle that minimises the rotation error (exactly).
    Of the candidates, the one closest in pick-grade units (5° ~ 3 mm) is reported.
    """
    A = as_transform(T_est, "T_est")
    B = as_transform(T_true, "T_true")
    axis = None if continuous_axis is None else as_vector(continuous_axis, "continuous_axis", 3)
    c = None if axis is None else as_vector(center, "center", 3)
    errors = []
    maps = [as_transform(S, f"symmetries[{i}]") for i, S in enumerate(symmetries)]
    for S in [np.eye(4), *maps]:
        if axis is not None:
            spin = np.eye(4)
            spin[:3, :3] = _closest_spin(A[:3, :3].T @ B[:3, :3] @ S[:3, :3], axis)
            spin[:3, 3] = c - spin[:3, :3] @ c
            S = S @ spin
        Bs = B @ S
        errors.append((rotation_angle_deg(Bs[:3, :3].T @ A[:3, :3]), float(np.linalg.norm(A[:3, 3] - Bs[:3, 3]))))
    return min(errors, key=lambda e: e[0] / 5.0 + e[1] / 3.0)


#: Most frames one laser sweep takes: a scan is 30–200 frames; beyond this the frames alone
#: (at 1 MP each) would not fit in memory.
MAX_SWEEP_FRAMES = 10_000


def sheet_angles(T_base_laser: np.ndarray, points: Any) -> np.ndarray:
    """The motor angle (rad) whose laser sheet passes through each of ``points`` (N, 3, base
    frame), for the laser at motor angle 0 posed at ``T_base_laser``: at angle θ the sheet is
    x cos θ − z sin θ = 0 in the laser frame, so it meets a point at θ = atan2(x, z)."""
    local = _in_laser_frame(T_base_laser, points)
    return np.arctan2(local[:, 0], local[:, 2])


def _in_laser_frame(T_base_laser: np.ndarray, points: Any) -> np.ndarray:
    T_laser_base = inverse(T_base_laser)
    return np.asarray(points, dtype=np.float64) @ T_laser_base[:3, :3].T + T_laser_base[:3, 3]


def laser_sweep(
    T_base_laser: np.ndarray, lo: np.ndarray, hi: np.ndarray, frames: int, margin: float = 10.0
) -> np.ndarray:
    """``frames`` motor angles (rad), evenly spaced, whose laser sheets sweep the box ``lo``..``hi``
    (floor corners widened by ``margin`` mm along x, and the rim), for the laser at motor angle 0
    posed at ``T_base_laser`` (the others already checked; ``margin`` is checked here)."""
    margin = number(margin, "margin", -1e6, 1e6, unit="mm")
    T_base_laser = as_transform(T_base_laser, "T_base_laser")
    frames = count(frames, "frames", 1, MAX_SWEEP_FRAMES)
    corners = [[x, y, lo[2]] for x in (lo[0] - margin, hi[0] + margin) for y in (lo[1], hi[1])]
    corners += [[x, y, hi[2]] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]
    local = _in_laser_frame(T_base_laser, corners)
    behind = local[:, 2] <= 0
    if behind.any():
        raise InvalidInputError(
            f"margin: the box corner {np.round(corners[int(np.argmax(behind))], 1).tolist()} mm lies behind the laser "
            "(its light travels along +z_L), where no sheet reaches; use a smaller margin or a scan pose above the box"
        )
    theta = sheet_angles(T_base_laser, corners)
    return np.array([float(theta.mean())]) if frames == 1 else np.linspace(theta.min(), theta.max(), frames)
