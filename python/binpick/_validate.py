"""Input checks shared by every public function: arrays become contiguous float64 of the
right shape with finite values, or a specific exception says what was wrong and what to do."""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import DTypeError, InvalidInputError, NonFiniteError, ShapeError, TooFewPointsError


def as_float_array(value: Any, name: str) -> np.ndarray:
    """``value`` as a float64 ndarray, or DTypeError naming ``name``."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise DTypeError(f"{name}: cannot be read as a numeric array ({exc}); pass a numpy array of numbers") from None
    if arr.dtype.kind not in "iuf":
        raise DTypeError(
            f"{name}: dtype {arr.dtype} cannot be converted to float coordinates; pass a numeric (float or int) array"
        )
    return np.ascontiguousarray(arr, dtype=np.float64)


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raises NonFiniteError naming the first row that holds NaN or inf."""
    bad = ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise NonFiniteError(
            f"{name}: element {where} is {arr[where]}; remove NaN/inf rows first, "
            f"e.g. {name}[np.isfinite({name}).all(axis=1)]"
        )


def as_points(value: Any, name: str, *, min_points: int = 1, columns: int = 3) -> np.ndarray:
    """An (N, columns) float64 C-contiguous array with finite values and at least ``min_points`` rows."""
    arr = as_float_array(value, name)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ShapeError(f"{name}: expected an (N, {columns}) array, got shape {arr.shape}")
    check_finite(arr, name)
    if arr.shape[0] < min_points:
        raise TooFewPointsError(f"{name}: has {arr.shape[0]} points but at least {min_points} are needed")
    return arr


def as_vector(value: Any, name: str, size: int = 3) -> np.ndarray:
    """A finite float64 vector of ``size`` elements."""
    arr = as_float_array(value, name)
    if arr.shape != (size,):
        raise ShapeError(f"{name}: expected {size} numbers, got shape {arr.shape}")
    check_finite(arr, name)
    return arr


def as_transform(value: Any, name: str) -> np.ndarray:
    """A finite 4×4 float64 rigid transform (checked: rotation block orthonormal, det +1, last row 0 0 0 1)."""
    arr = as_float_array(value, name)
    if arr.shape != (4, 4):
        raise ShapeError(f"{name}: expected a (4, 4) homogeneous transform, got shape {arr.shape}")
    check_finite(arr, name)
    return check_rigid(arr, name)


def check_rigid(arr: np.ndarray, name: str, error: type = InvalidInputError) -> np.ndarray:
    """Raises ``error`` unless the 4×4 ``arr`` is rigid: last row 0 0 0 1, rotation block
    orthonormal with determinant +1 (to 1e-6)."""
    if not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise error(f"{name}: the last row must be [0, 0, 0, 1], got {arr[3].tolist()}")
    rot = arr[:3, :3]
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(rot) < 0:
        raise error(
            f"{name}: the 3×3 block is not a rotation (|RᵀR − I| = {err:.2e}, det = {np.linalg.det(rot):.4f}); "
            "pass a rigid transform without scale or reflection"
        )
    return arr


def positive(value: Any, name: str, unit: str = "mm") -> float:
    """A positive finite float, or InvalidInputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: must be a number ({unit}), got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise InvalidInputError(f"{name}: must be a positive finite number ({unit}), got {value!r}")
    return v


def non_negative(value: Any, name: str, unit: str = "") -> float:
    """A finite float ≥ 0, or InvalidInputError."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: must be a number{(' (' + unit + ')') if unit else ''}, got {value!r}") from None
    if not np.isfinite(v) or v < 0:
        raise InvalidInputError(f"{name}: must be a finite number ≥ 0, got {value!r}")
    return v


def count(value: Any, name: str, minimum: int = 0) -> int:
    """An integer ≥ ``minimum``, or InvalidInputError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidInputError(f"{name}: must be an integer, got {value!r}")
    if value < minimum:
        raise InvalidInputError(f"{name}: must be at least {minimum}, got {value}")
    return int(value)
