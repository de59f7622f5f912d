"""The cell's calibration: camera intrinsics, laser pose at motor angle 0, hand-eye transform,
saved to and loaded from a versioned TOML file (``calibration.toml``, version 1)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]

from .._validate import check_rigid
from ..errors import CalibrationError, FileWriteError
from ._checks import calibration_matrix

#: The calibration file format this code writes and reads.
FORMAT_VERSION = 1


def _rigid(value: Any, field: str) -> np.ndarray:
    return check_rigid(calibration_matrix(value, field, (4, 4)), field, CalibrationError)


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=np.float64, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class CameraIntrinsics:
    """An OpenCV pinhole camera: image size in pixels, ``K`` (3×3) and ``dist = [k1, k2, p1, p2, k3]``.

    Checked on construction: positive focal lengths, principal point inside the image,
    ``K[2] == [0, 0, 1]``; a wrong value raises ``CalibrationError`` naming the field.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray

    def __post_init__(self) -> None:
        for field in ("width", "height"):
            v = getattr(self, field)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 2:
                raise CalibrationError(f"camera.{field}: must be an integer number of pixels ≥ 2, got {v!r}")
            object.__setattr__(self, field, int(v))
        K = calibration_matrix(self.K, "camera.K", (3, 3))
        dist = np.asarray(self.dist, dtype=np.float64).ravel() if not isinstance(self.dist, str) else self.dist
        dist = calibration_matrix(dist, "camera.dist", (5,))
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(f"camera.K: focal lengths fx={K[0, 0]:g}, fy={K[1, 1]:g} must be positive (pixels)")
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
            raise CalibrationError(f"camera.K: must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        if not (0 <= K[0, 2] <= self.width and 0 <= K[1, 2] <= self.height):
            raise CalibrationError(
                f"camera.K: principal point ({K[0, 2]:g}, {K[1, 2]:g}) lies outside the "
                f"{self.width}×{self.height} image; K and the image size do not belong together"
            )
        object.__setattr__(self, "K", _frozen(K))
        object.__setattr__(self, "dist", _frozen(dist))

    @property
    def shape(self) -> tuple[int, int]:
        """The image shape as numpy writes it: ``(height, width)``."""
        return (self.height, self.width)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraIntrinsics):
            return NotImplemented
        return (self.width, self.height) == (other.width, other.height) and np.array_equal(self.K, other.K) and np.array_equal(self.dist, other.dist)

    def __repr__(self) -> str:
        K = self.K
        return (
            f"CameraIntrinsics({self.width}×{self.height}, fx={K[0, 0]:.2f}, fy={K[1, 1]:.2f}, "
            f"cx={K[0, 2]:.2f}, cy={K[1, 2]:.2f}, dist={np.round(self.dist, 5).tolist()})"
        )


@dataclass(frozen=True, eq=False)
class CellCalibration:
    """Everything the cell needs to turn laser-line pixels into points in the robot's base frame.

    ``T_camera_laser`` is the projector pose at motor angle 0 (the motor turns the laser frame
    about its own y axis: ``T_camera_laser(θ) = T_camera_laser @ Rot_y(θ)``);
    ``T_flange_camera`` is the hand-eye transform. Lengths in mm.
    """

    camera: CameraIntrinsics
    T_camera_laser: np.ndarray
    T_flange_camera: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.camera, CameraIntrinsics):
            raise CalibrationError(f"camera: expected a CameraIntrinsics, got {type(self.camera).__name__}")
        object.__setattr__(self, "T_camera_laser", _frozen(_rigid(self.T_camera_laser, "laser.T_camera_laser")))
        object.__setattr__(self, "T_flange_camera", _frozen(_rigid(self.T_flange_camera, "hand_eye.T_flange_camera")))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CellCalibration):
            return NotImplemented
        return (
            self.camera == other.camera
            and np.array_equal(self.T_camera_laser, other.T_camera_laser)
            and np.array_equal(self.T_flange_camera, other.T_flange_camera)
        )

    def T_camera_laser_at(self, angle: float) -> np.ndarray:
        """The projector pose at motor angle ``angle`` (radians)."""
        c, s = np.cos(angle), np.sin(angle)
        rot_y = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])
        return self.T_camera_laser @ rot_y

    def to_toml(self) -> str:
        """The calibration as TOML text (format version 1)."""
        cam = self.camera
        return "\n".join(
            [
                "# binpick cell calibration: lengths in mm, angles in radians",
                f"version = {FORMAT_VERSION}",
                "",
                "[camera]",
                f"width = {cam.width}",
                f"height = {cam.height}",
                f"K = {_toml_matrix(cam.K)}",
                f"dist = {_toml_row(cam.dist)}",
                "",
                "[laser]",
                "# projector pose at motor angle 0; the motor turns it about its own y axis",
                f"T_camera_laser = {_toml_matrix(self.T_camera_laser)}",
                'axis = "y"',
                "",
                "[hand_eye]",
                f"T_flange_camera = {_toml_matrix(self.T_flange_camera)}",
                "",
            ]
        )

    @classmethod
    def from_toml(cls, text: str, *, source: str = "calibration") -> "CellCalibration":
        """Parses TOML text; ``source`` names the file in error messages."""
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CalibrationError(f"{source}: not valid TOML ({exc})") from None
        return cls.from_dict(doc, source=source)

    @classmethod
    def from_dict(cls, doc: dict, *, source: str = "calibration") -> "CellCalibration":
        """Builds a calibration from the parsed TOML document, checking every field."""

        def get(table: str, key: str) -> Any:
            sect = doc.get(table)
            if not isinstance(sect, dict):
                raise CalibrationError(f"{source}: the [{table}] table is missing; a version-1 file needs [camera], [laser] and [hand_eye]")
            if key not in sect:
                raise CalibrationError(f"{source}: field {table}.{key} is missing")
            return sect[key]

        version = doc.get("version")
        if version is None:
            raise CalibrationError(f"{source}: field version is missing; a calibration file starts with 'version = {FORMAT_VERSION}'")
        if version != FORMAT_VERSION:
            raise CalibrationError(f"{source}: field version is {version!r}; this binpick reads version {FORMAT_VERSION} only")
        axis = get("laser", "axis")
        if axis != "y":
            raise CalibrationError(f'{source}: field laser.axis is {axis!r}; the projector turns about its own y axis, write axis = "y"')
        try:
            camera = CameraIntrinsics(
                width=get("camera", "width"), height=get("camera", "height"), K=get("camera", "K"), dist=get("camera", "dist")
            )
            return cls(camera=camera, T_camera_laser=get("laser", "T_camera_laser"), T_flange_camera=get("hand_eye", "T_flange_camera"))
        except CalibrationError as exc:
            if str(exc).startswith(source):
                raise
            raise CalibrationError(f"{source}: {exc}") from None

    def save(self, path: str | os.PathLike) -> Path:
        """Writes ``path`` (TOML, version 1) and returns it."""
        path = Path(path)
        try:
            path.write_text(self.to_toml(), encoding="utf-8")
        except OSError as exc:
            raise FileWriteError(f"{path}: cannot write the calibration ({exc})") from None
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "CellCalibration":
        """Reads a calibration file; a missing or inconsistent field raises ``CalibrationError`` naming it."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise CalibrationError(f"{path}: cannot read the calibration file ({exc.strerror or exc})") from None
        return cls.from_toml(text, source=str(path))


def _toml_row(values: np.ndarray) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _toml_matrix(m: np.ndarray) -> str:
    return "[" + ", ".join(_toml_row(r) for r in m) + "]"
