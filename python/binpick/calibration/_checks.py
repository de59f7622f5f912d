"""Input checks specific to the measuring chain: images, angles, intrinsics."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validate import as_float_array, check_finite
from ..errors import CalibrationError, DTypeError, InvalidInputError, ShapeError

#: Largest motor angle accepted, in radians; anything beyond is taken for degrees passed by mistake.
MAX_ANGLE = math.pi


def as_angles(value: Any, name: str, *, size: int | None = None) -> np.ndarray:
    """A 1-D finite float64 array of angles in radians, each within ±π.

    Values beyond π are almost always degrees passed where radians are expected, so the error
    says so instead of silently producing a wrong laser plane.
    """
    arr = as_float_array(value, name)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise ShapeError(f"{name}: expected a 1-D array of angles, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ShapeError(f"{name}: expected {size} angles (one per frame), got {arr.shape[0]}")
    check_finite(arr, name)
    big = np.abs(arr) > MAX_ANGLE
    if big.any():
        i = int(np.argmax(big))
        raise InvalidInputError(
            f"{name}: element {i} is {arr[i]:g}, beyond ±π; angles are radians — "
            f"if these are degrees, pass np.radians({name})"
        )
    return arr


def as_image(value: Any, name: str, *, shape: tuple[int, int] | None = None, color: bool | None = None) -> np.ndarray:
    """A uint8 image, (H, W) or (H, W, 3), optionally of a given (height, width).

    ``color=True`` requires three channels (BGR), ``False`` one, ``None`` either.
    """
    if not isinstance(value, np.ndarray):
        raise DTypeError(f"{name}: expected a numpy image array (as cv2.imread returns), got {type(value).__name__}")
    if value.dtype != np.uint8:
        raise DTypeError(
            f"{name}: dtype {value.dtype}; pass an 8-bit image (uint8), e.g. cv2.imread(path) or "
            f"(img / img.max() * 255).astype(np.uint8)"
        )
    if value.ndim == 3 and value.shape[2] == 1:
        value = value[:, :, 0]
    if value.ndim == 2:
        if color:
            raise ShapeError(f"{name}: a grey image of shape {value.shape}; the laser line is found by colour, pass the BGR frame (H, W, 3)")
    elif value.ndim == 3 and value.shape[2] == 3:
        if color is False:
            raise ShapeError(f"{name}: expected a single-channel image, got shape {value.shape}")
    else:
        raise ShapeError(f"{name}: expected an image of shape (H, W) or (H, W, 3), got {value.shape}")
    if value.shape[0] < 2 or value.shape[1] < 2:
        raise ShapeError(f"{name}: image of shape {value.shape} is too small")
    if shape is not None and value.shape[:2] != tuple(shape):
        raise ShapeError(
            f"{name}: image is {value.shape[1]}×{value.shape[0]} (width×height) but the camera "
            f"calibration says {shape[1]}×{shape[0]}; use frames from the calibrated camera"
        )
    return value


def calibration_matrix(value: Any, field: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite float64 array of ``shape`` read from a calibration source, or CalibrationError naming ``field``."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{field}: expected numbers of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise CalibrationError(f"{field}: expected shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise CalibrationError(f"{field}: holds NaN or infinity")
    return arr
