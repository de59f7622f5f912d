"""Poses in each robot brand's own convention: the numbers a robot program sends and receives.

A pose is the flange ``T_base_flange`` (4×4, mm) inside binpick; on the wire it is what the
brand's robot language writes for a position and orientation:

========  ==========================  =============================================================
brand     numbers                     rotation
========  ==========================  =============================================================
ur        x, y, z (m), rx, ry, rz     rotation vector (axis × angle, rad), as URScript's ``p[…]``
abb       x, y, z (mm), q1..q4        unit quaternion, scalar first (RAPID's ``orient``), q1 ≥ 0
kuka      X, Y, Z (mm), A, B, C       degrees, R = Rz(A)·Ry(B)·Rx(C) (KRL's E6POS / FRAME)
fanuc     X, Y, Z (mm), W, P, R       degrees, R = Rz(R)·Ry(P)·Rx(W) (a Cartesian position, XYZWPR)
yaskawa   X, Y, Z (mm), Rx, Ry, Rz    degrees, R = Rz(Rz)·Ry(Ry)·Rx(Rx) (the fixed-angle pose, INFORM)
melfa     X, Y, Z (mm), A, B, C       degrees, R = Rz(C)·Ry(B)·Rx(A) (MELFA-BASIC's POSE)
========  ==========================  =============================================================

Every Euler convention is the one decomposition of :mod:`binpick.devices.xyzabc` with its angles
renamed or reversed; decoding checks the count, finiteness and size of every number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_transform
from ..devices.xyzabc import transform_from_xyzabc, xyzabc_from_transform
from ..errors import InvalidInputError
from ..transforms import matrix_quaternion, quaternion_matrix, rotation_about, rotation_vector

__all__ = ["PoseConvention", "CONVENTIONS", "convention"]

#: Largest coordinate a pose may hold, mm (ten metres: no arm reaches further).
MAX_COORDINATE_MM = 10_000.0
#: Largest Euler angle accepted, degrees (controllers write angles within ±360°).
MAX_ANGLE_DEG = 720.0
#: How far from unit length a received quaternion may be (RAPID writes four to six decimals).
QUATERNION_NORM_TOLERANCE = 1e-3


@dataclass(frozen=True)
class PoseConvention:
    """One brand's way of writing a flange pose (see the module docstring).

    Attributes:
        brand: the name a cell file's ``[server] brand`` gives.
        fields: the names of the numbers, in order.
        mm_per_unit: the length unit of the first three numbers, in mm (1000 for metres).
        rotation: ``"rotvec"``, ``"quaternion"``, ``"abc"`` (R = Rz(3rd)·Ry(2nd)·Rx(1st)) or
            ``"cba"`` (R = Rz(1st)·Ry(2nd)·Rx(3rd)).
    """

    brand: str
    fields: tuple[str, ...]
    mm_per_unit: float
    rotation: str

    @property
    def size(self) -> int:
        """How many numbers one pose takes."""
        return len(self.fields)

    def to_robot(self, T_base_flange: Any) -> np.ndarray:
        """The numbers of the flange pose ``T_base_flange`` (4×4, mm) in this convention."""
        T = as_transform(T_base_flange, "T_base_flange")
        xyz = T[:3, 3] / self.mm_per_unit
        R = T[:3, :3]
        if self.rotation == "rotvec":
            return np.concatenate([xyz, rotation_vector(R)])
        if self.rotation == "quaternion":
            return np.concatenate([xyz, matrix_quaternion(R)])
        a, b, c = np.degrees(xyzabc_from_transform(T)[3:])
        return np.concatenate([xyz, [a, b, c] if self.rotation == "abc" else [c, b, a]])

    def from_robot(self, values: Any, name: str = "pose") -> np.ndarray:
        """The flange pose (4×4, mm) of the numbers ``values`` in this convention;
        InvalidInputError naming ``name`` and the field for a wrong count, a non-finite number, a
        coordinate beyond :data:`MAX_COORDINATE_MM`, an angle beyond :data:`MAX_ANGLE_DEG` or a
        quaternion that is not of unit length."""
        v = self._numbers(values, name)
        xyz = v[:3] * self.mm_per_unit
        if self.rotation == "rotvec":
            T = np.eye(4)
            angle = float(np.linalg.norm(v[3:]))
            if angle > 1e-12:
                T[:3, :3] = rotation_about(v[3:], angle)
        elif self.rotation == "quaternion":
            norm = float(np.linalg.norm(v[3:]))
            if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
                raise InvalidInputError(
                    f"{name}: the quaternion {self.fields[3:]} has length {norm:.6f}; send a unit quaternion"
                )
            T = np.eye(4)
            T[:3, :3] = quaternion_matrix(v[3:])
        else:
            a, b, c = np.radians(v[3:] if self.rotation == "abc" else v[3:][::-1])
            T = transform_from_xyzabc([0.0, 0.0, 0.0, a, b, c])
        T[:3, 3] = xyz
        return T

    def _numbers(self, values: Any, name: str) -> np.ndarray:
        try:
            v = np.array(values, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise InvalidInputError(f"{name}: expected {self.size} numbers ({', '.join(self.fields)})") from None
        if v.shape != (self.size,):
            raise InvalidInputError(
                f"{name}: expected {self.size} numbers ({', '.join(self.fields)}) for brand {self.brand!r}, "
                f"got {v.size}"
            )
        bad = [f for f, x in zip(self.fields, v) if not math.isfinite(x)]
        if bad:
            raise InvalidInputError(f"{name}: {bad[0]} is not a finite number; send finite values")
        far = [f for f, x in zip(self.fields[:3], v[:3]) if abs(x * self.mm_per_unit) > MAX_COORDINATE_MM]
        if far:
            raise InvalidInputError(
                f"{name}: {far[0]} lies beyond {MAX_COORDINATE_MM / self.mm_per_unit:g} "
                f"{'m' if self.mm_per_unit == 1000.0 else 'mm'}; check the unit ({self.fields[0]} is in "
                f"{'metres' if self.mm_per_unit == 1000.0 else 'millimetres'} for brand {self.brand!r})"
            )
        limit = 4 * math.pi if self.rotation == "rotvec" else 2.0 if self.rotation == "quaternion" else MAX_ANGLE_DEG
        wild = [f for f, x in zip(self.fields[3:], v[3:]) if abs(x) > limit]
        if wild:
            raise InvalidInputError(f"{name}: {wild[0]} = {v[3 + self.fields[3:].index(wild[0])]:g} is not an angle")
        return v


CONVENTIONS: dict[str, PoseConvention] = {
    c.brand: c
    for c in (
        PoseConvention("ur", ("x", "y", "z", "rx", "ry", "rz"), 1000.0, "rotvec"),
        PoseConvention("abb", ("x", "y", "z", "q1", "q2", "q3", "q4"), 1.0, "quaternion"),
        PoseConvention("kuka", ("X", "Y", "Z", "A", "B", "C"), 1.0, "cba"),
        PoseConvention("fanuc", ("X", "Y", "Z", "W", "P", "R"), 1.0, "abc"),
        PoseConvention("yaskawa", ("X", "Y", "Z", "Rx", "Ry", "Rz"), 1.0, "abc"),
        PoseConvention("melfa", ("X", "Y", "Z", "A", "B", "C"), 1.0, "abc"),
    )
}


def convention(brand: Any) -> PoseConvention:
    """The :class:`PoseConvention` of ``brand`` (case-insensitive); InvalidInputError listing the brands."""
    key = brand.strip().lower() if isinstance(brand, str) else None
    if key not in CONVENTIONS:
        known = ", ".join(CONVENTIONS)
        raise InvalidInputError(f"brand: {brand!r:.40} is not a robot brand binpick speaks; use {known}")
    return CONVENTIONS[key]
