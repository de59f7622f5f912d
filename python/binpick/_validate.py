"""The one validation vocabulary: every public function, driver and calibration checks its input
here. Arrays become contiguous float64 of the right shape with finite values, numbers land in
their range, or a specific exception names the argument and says what to do."""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

from ._paths import no_such_file
from .errors import (
    CalibrationError,
    DTypeError,
    InvalidInputError,
    InvalidTypeError,
    NonFiniteError,
    ShapeError,
    TooFewPointsError,
    UnknownUnitError,
)


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


#: Largest coordinate magnitude :func:`as_points` takes: beyond about 1e154 squared distances
#: overflow a float64, and nothing a cell measures is within orders of magnitude of 1e12 mm.
MAX_COORDINATE = 1e12


def as_points(value: Any, name: str, *, min_points: int = 1, columns: int = 3) -> np.ndarray:
    """An (N, columns) float64 C-contiguous array with finite values and at least ``min_points`` rows."""
    arr = as_float_array(value, name)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ShapeError(f"{name}: expected an (N, {columns}) array, got shape {arr.shape}")
    check_finite(arr, name)
    if arr.size and float(np.abs(arr).max()) > MAX_COORDINATE:
        raise InvalidInputError(
            f"{name}: a coordinate of {float(np.abs(arr).max()):.3g} exceeds {MAX_COORDINATE:g} (a million km in mm), "
            "where squared distances overflow; pass millimetres near the cell's origin"
        )
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


_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def check_rigid(arr: np.ndarray, name: str, error: type = InvalidInputError) -> np.ndarray:
    """Raises ``error`` unless the 4×4 ``arr`` is rigid: last row 0 0 0 1, rotation block
    orthonormal with determinant +1 (to 1e-6)."""
    # np.allclose(arr[3], [0, 0, 0, 1], atol=1e-9) written out: this check runs on every transform.
    if not (np.abs(arr[3] - _LAST_ROW) <= 1e-9 + 1e-5 * _LAST_ROW).all():
        raise error(f"{name}: the last row must be [0, 0, 0, 1], got {arr[3].tolist()}")
    rot = arr[:3, :3]
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(rot) < 0:
        raise error(
            f"{name}: the 3×3 block is not a rotation (|RᵀR − I| = {err:.2e}, det = {np.linalg.det(rot):.4f}); "
            "pass a rigid transform without scale or reflection"
        )
    return arr


def _real(value: Any, name: str, unit: str = "") -> float:
    """``value`` as a finite float: a bool, a string or any non-number is InvalidTypeError, NaN
    or infinity InvalidInputError, each naming ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidTypeError(f"{name}: must be a number{_unit(unit)}, got {type(value).__name__} {value!r:.40}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond the float range
        v = math.inf
    if not math.isfinite(v):
        raise InvalidInputError(f"{name}: must be a finite number{_unit(unit)}, got {value!r:.40}")
    return v


def positive(value: Any, name: str, unit: str = "mm") -> float:
    """A positive finite float, or InvalidInputError (InvalidTypeError for a non-number)."""
    v = _real(value, name, unit)
    if v <= 0:
        raise InvalidInputError(f"{name}: must be a positive finite number ({unit}), got {value!r}")
    return v


def non_negative(value: Any, name: str, unit: str = "") -> float:
    """A finite float ≥ 0, or InvalidInputError (InvalidTypeError for a non-number)."""
    v = _real(value, name, unit)
    if v < 0:
        raise InvalidInputError(f"{name}: must be a finite number ≥ 0, got {value!r}")
    return v


def number(value: Any, name: str, low: float = -math.inf, high: float = math.inf, unit: str = "") -> float:
    """A finite float in [low, high], or InvalidInputError (InvalidTypeError for a non-number)."""
    v = _real(value, name, unit)
    if not low <= v <= high:
        raise InvalidInputError(f"{name}: {v:g}{_unit(unit)} is outside [{low:g}, {high:g}]; pass a value inside it")
    return v


#: Largest unsigned integer the native core takes (its ``usize``/``u64``).
MAX_UNSIGNED = 2**64 - 1


def count(value: Any, name: str, minimum: int = 0, maximum: int = MAX_UNSIGNED) -> int:
    """An integer in [minimum, maximum], or InvalidInputError naming ``name``
    (InvalidTypeError for a bool, a float or any non-integer)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InvalidTypeError(f"{name}: must be an integer, got {type(value).__name__} {value!r:.40}")
    if value < minimum:
        raise InvalidInputError(f"{name}: must be at least {minimum}, got {value}")
    if value > maximum:
        raise InvalidInputError(f"{name}: must be at most {maximum}, got {value}")
    return int(value)


#: Largest ``num_threads`` accepted; a request above the machine's cores (and up to this) is
#: clamped to the cores by the binding, beyond it the request is refused as a mistake.
MAX_THREADS = 256


def thread_count(value: Any) -> int:
    """Worker threads, 0 = all cores, at most :data:`MAX_THREADS` (the binding clamps any
    request to the machine's cores)."""
    return count(value, "num_threads", 0, MAX_THREADS)


def optional_count(value: Any, name: str, minimum: int = 0, maximum: int = MAX_UNSIGNED) -> Optional[int]:
    """None, or :func:`count`."""
    return None if value is None else count(value, name, minimum, maximum)


def optional_number(value: Any, name: str, low: float = -math.inf, high: float = math.inf) -> Optional[float]:
    """None, or :func:`number`."""
    return None if value is None else number(value, name, low, high)


#: The length units binpick reads, each with its millimetres: written once, for meshes and arrays.
LENGTH_UNITS = {
    **dict.fromkeys(("mm", "millimeter", "millimetre", "millimeters", "millimetres"), 1.0),
    **dict.fromkeys(("cm", "centimeter", "centimetre", "centimeters", "centimetres"), 10.0),
    **dict.fromkeys(("m", "meter", "metre", "meters", "metres"), 1000.0),
    **dict.fromkeys(("in", "inch", "inches"), 25.4),
}


def unit_scale(unit: Any) -> float:
    """Millimetres per ``unit`` (:data:`LENGTH_UNITS`, case and surrounding spaces ignored), or
    UnknownUnitError listing the accepted units."""
    key = unit.strip().lower() if isinstance(unit, str) else None
    if key not in LENGTH_UNITS:
        raise UnknownUnitError(
            f"unit: unknown unit {unit!r:.40}; use one of {', '.join(repr(u) for u in LENGTH_UNITS)}"
        )
    return LENGTH_UNITS[key]


def native_config(cls: Any, **options: Any) -> Any:
    """A frozen config of the native core, ``cls(**options)``: the binding converts each option's
    type (a wrong one becomes InvalidInputError naming it) and leaves the core's default where an
    option is None; the core checks the values when it runs."""
    try:
        return cls(**options)
    except (TypeError, OverflowError):
        pass
    for name, value in options.items():  # name the option the binding could not convert
        try:
            cls(**{name: value})
        except (TypeError, OverflowError) as exc:
            raise InvalidInputError(
                f"{name}: cannot take {value!r} ({exc}); pass a value of the documented type"
            ) from None
    raise InvalidInputError(f"{cls.__name__}: cannot take these options: {options!r}")


def as_faces(value: Any, name: str, vertex_count: int) -> np.ndarray:
    """An (F, 3) int64 C-contiguous array of triangle vertex indices, each in [0, ``vertex_count``),
    or InvalidInputError naming ``name`` (DTypeError for non-integer indices, which would be truncated)."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise DTypeError(f"{name}: cannot be read as an integer array ({exc}); pass an (F, 3) integer array") from None
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ShapeError(f"{name}: expected an (F, 3) array of vertex indices, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise DTypeError(f"{name}: dtype {arr.dtype}; vertex indices must be integers")
    if arr.size and (arr.min() < 0 or arr.max() >= vertex_count):
        raise InvalidInputError(
            f"{name}: indices span [{arr.min()}, {arr.max()}] but there are {vertex_count} vertices; "
            f"each index must be in [0, {vertex_count})"
        )
    return np.ascontiguousarray(arr, dtype=np.int64)


def choice(value: Any, name: str, allowed: tuple[str, ...]) -> str:
    """``value`` when it is one of the strings ``allowed``, else InvalidInputError naming ``name``
    and listing them (an array or any unhashable value is refused, not compared)."""
    if not isinstance(value, str) or value not in allowed:
        raise InvalidInputError(f"{name}: {value!r:.40} is not one of {', '.join(repr(a) for a in allowed)}")
    return value


def flag(value: Any, name: str) -> bool:
    """``value`` as a bool; anything but True or False (a string, an array, a number) is
    InvalidTypeError naming ``name``, rather than taken for its truth."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidTypeError(f"{name}: must be True or False, got {type(value).__name__} {value!r:.40}")
    return bool(value)


def as_indices(value: Any, name: str) -> np.ndarray:
    """A 1-D int64 array of indices, or DTypeError (ShapeError) naming ``name``; their range is the caller's."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise DTypeError(f"{name}: cannot be read as an index array ({exc}); pass a 1-D integer array") from None
    if arr.dtype.kind not in "iu" and not (arr.size == 0 and arr.dtype.kind == "f"):
        raise DTypeError(f"{name}: dtype {arr.dtype}; indices must be integers")
    if arr.ndim != 1:
        raise ShapeError(f"{name}: expected a 1-D array of indices, got shape {arr.shape}")
    if arr.dtype == np.uint64 and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise InvalidInputError(f"{name}: index {arr.max()} is beyond any array")
    return arr.astype(np.int64)


def as_mask(value: Any, name: str, size: int) -> np.ndarray:
    """A 1-D bool array of ``size`` flags (one per point), or DTypeError (ShapeError) naming ``name``."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise DTypeError(f"{name}: cannot be read as a mask ({exc}); pass a 1-D bool array") from None
    if arr.dtype != np.bool_:
        raise DTypeError(f"{name}: dtype {arr.dtype}; a mask must be bool (one True or False per point)")
    if arr.shape != (size,):
        raise ShapeError(f"{name}: expected {size} flags, one per point, got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def instance_of(value: Any, cls: type, name: str, example: str = "") -> Any:
    """``value`` when it is a ``cls``, else InvalidTypeError naming ``name`` (and how to make one)."""
    if not isinstance(value, cls):
        hint = f" (e.g. {example})" if example else ""
        raise InvalidTypeError(f"{name}: expected a {cls.__module__}.{cls.__name__}{hint}, got {type(value).__name__}")
    return value


# --------------------------------------------------------------------------- devices


def check_number(
    value: Any, name: str, *, low: Optional[float] = None, high: Optional[float] = None, unit: str = ""
) -> float:
    """``value`` as a finite float within [low, high], or InvalidInputError naming ``name``."""
    return number(value, name, -math.inf if low is None else low, math.inf if high is None else high, unit)


def check_int(value: Any, name: str, low: int, high: int) -> int:
    """``value`` as an int within [low, high], or InvalidInputError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidInputError(f"{name}: must be an integer in [{low}, {high}], got {value!r}")
    v = int(value)
    if not low <= v <= high:
        raise InvalidInputError(f"{name}: {v} is outside [{low}, {high}]; pass an integer inside that range")
    return v


def check_transform(value: Any, name: str) -> np.ndarray:
    """A finite 4×4 float64 rigid transform, or a specific InvalidInputError saying what is wrong
    (the drivers' form of :func:`as_transform`: any unreadable value is InvalidInputError)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond the float range
        raise InvalidInputError(
            f"{name}: cannot be read as a 4×4 numeric array; pass a numpy (4, 4) float array"
        ) from None
    if arr.shape != (4, 4):
        raise ShapeError(f"{name}: expected a (4, 4) homogeneous transform, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise InvalidInputError(f"{name}: holds NaN or infinity; pass a finite transform")
    return check_rigid(arr, name)


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


# --------------------------------------------------------------------------- the measuring chain

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
            raise ShapeError(
                f"{name}: a grey image of shape {value.shape}; the laser "
                "line is found by colour, pass the BGR frame (H, W, 3)"
            )
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
    except (TypeError, ValueError, OverflowError, RecursionError):
        raise CalibrationError(
            f"{field}: expected numbers of shape {shape}, got {value!r:.80}; write them as nested lists of numbers"
        ) from None
    if arr.shape != shape:
        raise CalibrationError(f"{field}: expected shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise CalibrationError(f"{field}: holds NaN or infinity")
    return arr


def frozen_copy(arr: np.ndarray) -> np.ndarray:
    """A read-only float64 copy of ``arr`` (for the arrays of frozen dataclasses)."""
    arr = np.array(arr, dtype=np.float64, copy=True)
    arr.flags.writeable = False
    return arr


def pixel_window(value: Any, name: str, width: int, height: int, *, span: int, whole: str) -> tuple[int, int, int, int]:
    """A rectangle of an image ``width`` × ``height`` px, (u0, v0, u1, v1) half-open, as four
    ints spanning at least ``span`` pixels each way, or InvalidInputError naming ``name`` (whose
    fix says ``whole``: what None does instead)."""
    r = np.asarray(value)
    if r.shape != (4,) or r.dtype.kind not in "iu":
        raise InvalidInputError(f"{name}: expected four integers (u0, v0, u1, v1) in pixels, got {value!r:.60}")
    u0, v0, u1, v1 = (int(x) for x in r)
    if not (0 <= u0 <= u1 - span and u1 <= width and 0 <= v0 <= v1 - span and v1 <= height):
        raise InvalidInputError(
            f"{name}: ({u0}, {v0}, {u1}, {v1}) must satisfy 0 ≤ u0 < u1 ≤ {width} and 0 ≤ v0 < v1 ≤ {height} "
            f"(the image's width and height) and span at least {span} pixel{'s' if span > 1 else ''} each way; "
            f"pass None to {whole}"
        )
    return u0, v0, u1, v1


def as_box(value: Any, name: str = "bin") -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box ((xmin, ymin, zmin), (xmax, ymax, zmax)) in mm as its two corners, or
    InvalidInputError naming ``name``."""
    b = np.asarray(value, dtype=np.float64)
    if b.shape != (2, 3) or not np.isfinite(b).all():
        raise InvalidInputError(
            f"{name}: expected ((xmin, ymin, zmin), (xmax, ymax, zmax)) in mm, got {np.asarray(value).tolist()}"
        )
    if not (b[1] > b[0]).all():
        raise InvalidInputError(
            f"{name}: the max corner {b[1].tolist()} must exceed the min corner {b[0].tolist()} on every axis"
        )
    return b[0], b[1]


# --------------------------------------------------------------------------- files

#: Largest image width or height a calibration or scan file may declare, pixels.
MAX_IMAGE_SIDE = 65_536

#: Most frames (and columns) of a contact sheet.
MAX_SHEET_TILES = 1000

#: Largest image a calibration or scan file may declare, pixels (width × height): 2**28 px,
#: 768 MiB for one 8-bit BGR frame; beyond it one frame would not fit in a machine's memory.
MAX_IMAGE_PIXELS = 2**28


def image_size(width: Any, height: Any, where: str, error: type = CalibrationError) -> tuple[int, int]:
    """``(width, height)`` in pixels as read from a file, each a whole number in
    [2, :data:`MAX_IMAGE_SIDE`] and together at most :data:`MAX_IMAGE_PIXELS`, or ``error``
    naming ``where.width`` / ``where.height``."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 2 <= v <= MAX_IMAGE_SIDE:
            raise error(
                f"{where}.{name}: must be a whole number of pixels in [2, {MAX_IMAGE_SIDE}], got {v!r:.40}; "
                f"write the camera's image {name} in pixels"
            )
    w, h = int(width), int(height)
    if w * h > MAX_IMAGE_PIXELS:
        raise error(
            f"{where}: a {w}×{h} image has {w * h} pixels, more than the {MAX_IMAGE_PIXELS} binpick reads "
            f"(one BGR frame would take {3 * w * h / 2**30:.1f} GiB); write the camera's real image size"
        )
    return w, h


def as_path(value: Any, name: str = "path") -> Any:
    """``value`` (a str or os.PathLike) as a :class:`pathlib.Path`, or InvalidInputError naming
    ``name`` when it holds a NUL byte (which no file name can); a non-path is Python's TypeError."""
    from pathlib import Path

    path = Path(value)
    if "\x00" in str(path):
        raise InvalidInputError(f"{name}: {str(path)!r:.80} holds a NUL byte; no file name can")
    return path


def write_atomic(path: Any, data: bytes | str) -> None:
    """Writes ``data`` (text as UTF-8) to ``path`` through a temporary file in the same folder and
    :func:`os.replace`, so that a reader sees the old file or the new one, never a part of it."""
    import os
    from pathlib import Path

    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    os.replace(tmp, path)


def read_text_file(path: Any, what: str, error: type, *, max_bytes: int, missing: str = "") -> str:
    """The UTF-8 text of the file ``path``, or ``error`` naming the file: when it cannot be read
    (when it does not exist: :func:`binpick._paths.no_such_file`, with ``missing`` as its fix),
    when it is larger than ``max_bytes`` (a ceiling well above any real file, so a wrong or
    hostile file is not read whole), or when it is not UTF-8 (naming the first bad byte)."""
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise error(no_such_file(path, what, fix=missing)) from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
        raise error(f"{path}: cannot read the {what} ({getattr(exc, 'strerror', None) or exc})") from None
    if len(data) > max_bytes:
        raise error(
            f"{path}: the {what} is larger than {max_bytes} bytes, far beyond any real one; is it the right file?"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            f"{path}: byte {exc.start} of the {what} is not UTF-8 text ({exc.reason}); save the file as UTF-8"
        ) from None


def parse_toml(text: str, source: str, error: type) -> dict:
    """The TOML document in ``text``, or ``error`` naming ``source``: for bad syntax (with the line),
    for arrays or tables nested too deeply to parse, and for integers too long to convert."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise error(
            f"{source}: not valid TOML (arrays or tables nested too deeply); nest lists two levels at most"
        ) from None
    except ValueError as exc:  # TOMLDecodeError, and integers longer than Python converts
        raise error(f"{source}: not valid TOML ({str(exc)[:200]}); fix the line it names") from None


def edge_use_counts(faces: np.ndarray) -> np.ndarray:
    """How many faces use each undirected edge of the mesh (2 everywhere for a closed manifold)."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)[1]
