"""The one place where 4×4 transforms meet MELFA's (X, Y, Z, A, B, C).

Convention (the MELFA controller's): A, B and C are roll, pitch and yaw about the *fixed* base
axes X, Y and Z, applied in that order, so

    R = Rz(C) · Ry(B) · Rx(A)

with X, Y, Z the translation in millimetres. In code the angles are radians; the R3 protocol
writes them in degrees (:func:`xyzabc_to_wire` and :func:`xyzabc_from_wire` convert).

Decomposition returns B in [-π/2, π/2] and A, C in (-π, π]. At B = ±90° (gimbal lock) only
C − A (B = +90°) or C + A (B = −90°) is defined; A is then reported as 0.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validate import check_number, check_transform
from ..errors import InvalidInputError, ShapeError

__all__ = [
    "transform_from_xyzabc",
    "xyzabc_from_transform",
    "xyzabc_to_wire",
    "xyzabc_from_wire",
    "rotation_from_abc",
]

_GIMBAL_EPS = 1e-9


def rotation_from_abc(a: float, b: float, c: float) -> np.ndarray:
    """The 3×3 rotation Rz(c)·Ry(b)·Rx(a) for angles in radians."""
    a, b, c = (check_number(v, name, unit="rad") for v, name in ((a, "a"), (b, "b"), (c, "c")))
    ca, sa = math.cos(a), math.sin(a)
    cb, sb = math.cos(b), math.sin(b)
    cc, sc = math.cos(c), math.sin(c)
    return np.array(
        [
            [cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
            [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
            [-sb, cb * sa, cb * ca],
        ]
    )


def _as_xyzabc(value: Any, name: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond the float range
        raise InvalidInputError(f"{name}: cannot be read as six numbers (X, Y, Z, A, B, C)") from None
    if arr.shape != (6,):
        raise ShapeError(f"{name}: expected six numbers (X, Y, Z, A, B, C), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"{name}: holds NaN or infinity: {arr.tolist()}; pass finite values")
    return arr


def transform_from_xyzabc(xyzabc: Any) -> np.ndarray:
    """4×4 transform from (X, Y, Z) in mm and (A, B, C) in radians, R = Rz(C)·Ry(B)·Rx(A)."""
    x, y, z, a, b, c = _as_xyzabc(xyzabc, "xyzabc")
    T = np.eye(4)
    T[:3, :3] = rotation_from_abc(a, b, c)
    T[:3, 3] = (x, y, z)
    return T


def xyzabc_from_transform(T: Any) -> np.ndarray:
    """(X, Y, Z, A, B, C), mm and radians, of a rigid 4×4 transform (see the module's convention)."""
    T = check_transform(T, "T")
    R = T[:3, :3]
    cb = math.hypot(R[0, 0], R[1, 0])
    b = math.atan2(-R[2, 0], cb)
    if cb > _GIMBAL_EPS:
        a = math.atan2(R[2, 1], R[2, 2])
        c = math.atan2(R[1, 0], R[0, 0])
    else:  # B = ±90°: put the whole rotation about Z into C
        a = 0.0
        c = math.atan2(-R[0, 1], R[1, 1])
    return np.array([T[0, 3], T[1, 3], T[2, 3], a, b, c])


def xyzabc_to_wire(xyzabc: Any) -> np.ndarray:
    """mm + radians → mm + degrees, as the controller reads and writes them."""
    v = _as_xyzabc(xyzabc, "xyzabc").copy()
    v[3:] = np.degrees(v[3:])
    return v


def xyzabc_from_wire(xyzabc_deg: Any) -> np.ndarray:
    """mm + degrees from the controller → mm + radians."""
    v = _as_xyzabc(xyzabc_deg, "xyzabc_deg").copy()
    v[3:] = np.radians(v[3:])
    return v
