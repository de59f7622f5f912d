"""The cell's calibration: camera intrinsics, laser pose at motor angle 0, hand-eye transform,
saved to and loaded from a versioned TOML file (``calibration.toml``, version 1)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import calibration_matrix, check_rigid, frozen_copy, image_size, parse_toml, read_text_file
from ..camera import CameraIntrinsics
from ..errors import CalibrationError, FileWriteError
from ..transforms import rot_y

#: The calibration file format this code writes and reads.
FORMAT_VERSION = 1

#: Largest calibration file read, bytes (a real one is under a kilobyte).
MAX_FILE_BYTES = 1 << 20


def _rigid(value: Any, field: str) -> np.ndarray:
    return check_rigid(calibration_matrix(value, field, (4, 4)), field, CalibrationError)


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
        object.__setattr__(self, "T_camera_laser", frozen_copy(_rigid(self.T_camera_laser, "laser.T_camera_laser")))
        object.__setattr__(
            self, "T_flange_camera", frozen_copy(_rigid(self.T_flange_camera, "hand_eye.T_flange_camera"))
        )

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
        return self.T_camera_laser @ rot_y(angle)

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
    def from_toml(cls, text: str, *, source: str = "calibration") -> CellCalibration:
        """Parses TOML text; ``source`` names the file in error messages."""
        if not isinstance(text, str):
            raise CalibrationError(f"{source}: expected the file's text as a str, got {type(text).__name__}")
        doc = parse_toml(text, source, CalibrationError)
        return cls.from_dict(doc, source=source)

    @classmethod
    def from_dict(cls, doc: dict, *, source: str = "calibration") -> CellCalibration:
        """Builds a calibration from the parsed TOML document, checking every field."""
        if not isinstance(doc, dict):
            raise CalibrationError(f"{source}: expected a TOML document (a table), got {type(doc).__name__}")

        def get(table: str, key: str) -> Any:
            sect = doc.get(table)
            if not isinstance(sect, dict):
                raise CalibrationError(
                    f"{source}: the [{table}] table is missing; a version-1 file needs [camera], [laser] and [hand_eye]"
                )
            if key not in sect:
                raise CalibrationError(f"{source}: field {table}.{key} is missing")
            return sect[key]

        version = doc.get("version")
        if version is None:
            raise CalibrationError(
                f"{source}: field version is missing; a calibration file starts with 'version = {FORMAT_VERSION}'"
            )
        if type(version) is not int or version != FORMAT_VERSION:  # not bool: True == 1
            raise CalibrationError(
                f"{source}: field version is {version!r:.40}; this binpick reads version {FORMAT_VERSION} only "
                f"(write 'version = {FORMAT_VERSION}')"
            )
        axis = get("laser", "axis")
        if axis != "y":
            raise CalibrationError(
                f"{source}: field laser.axis is {axis!r:.40}; the projector turns about its own y axis, "
                'write axis = "y"'
            )
        try:
            width, height = image_size(get("camera", "width"), get("camera", "height"), "camera")
            camera = CameraIntrinsics(
                width=width,
                height=height,
                K=calibration_matrix(get("camera", "K"), "camera.K", (3, 3)),
                dist=calibration_matrix(get("camera", "dist"), "camera.dist", (5,)),
            )
            return cls(
                camera=camera,
                T_camera_laser=get("laser", "T_camera_laser"),
                T_flange_camera=get("hand_eye", "T_flange_camera"),
            )
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
    def load(cls, path: str | os.PathLike) -> CellCalibration:
        """Reads a calibration file; a missing or inconsistent field raises ``CalibrationError`` naming it."""
        path = Path(path)
        text = read_text_file(path, "calibration file", CalibrationError, max_bytes=MAX_FILE_BYTES)
        return cls.from_toml(text, source=str(path))


def _toml_row(values: np.ndarray) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _toml_matrix(m: np.ndarray) -> str:
    return "[" + ", ".join(_toml_row(r) for r in m) + "]"
