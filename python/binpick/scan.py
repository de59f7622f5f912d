"""A laser scan on disk: the frames the camera grabbed, the motor angle and robot pose of each,
and the cell's calibration. The simulator writes scans with :func:`save_scan`; the cell and
:mod:`binpick.vision` read real and simulated scans alike with :func:`load_scan`.

Layout of a scan folder (format version 1)::

    scan.json          {"version": 1, "units": "mm, rad",
                        "frames": [{"image": "frames/000.png", "angle": θ, "T_base_flange": [[4×4]]}, ...]}
    calibration.toml   see binpick.calibration.CellCalibration
    frames/000.png ... the frames as grabbed (BGR)
    ground_truth.json  simulated scans only; its content belongs to the simulator
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._validate import as_angles, as_image, as_transform
from .calibration import CellCalibration
from .errors import FileWriteError, InvalidInputError, MeshFileNotFoundError, ScanFormatError

__all__ = ["SCAN_VERSION", "Scan", "ScanFrame", "load_scan", "save_scan"]

#: The scan format this code writes and reads.
SCAN_VERSION = 1


@dataclass(frozen=True, eq=False)
class ScanFrame:
    """One frame of a scan: where its image is, the motor angle (rad) and ``T_base_flange`` at capture."""

    image_path: Path
    angle: float
    T_base_flange: np.ndarray

    def image(self) -> np.ndarray:
        """The frame as cv2.imread returns it: uint8 BGR (H, W, 3)."""
        import cv2

        img = cv2.imread(str(self.image_path), cv2.IMREAD_COLOR)
        if img is None:
            raise MeshFileNotFoundError(f"{self.image_path}: cannot read the frame image; is the scan folder complete?")
        return img


@dataclass(frozen=True, eq=False)
class Scan:
    """A scan read from disk. ``ground_truth`` is the parsed ground_truth.json of a simulated scan, else None."""

    directory: Path
    frames: tuple[ScanFrame, ...]
    calibration: CellCalibration
    ground_truth: dict | None = None

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def angles(self) -> np.ndarray:
        """The motor angle of each frame, radians, shape (F,)."""
        return np.array([f.angle for f in self.frames], dtype=np.float64)

    @property
    def T_base_flanges(self) -> np.ndarray:
        """The robot pose of each frame, shape (F, 4, 4)."""
        return np.stack([f.T_base_flange for f in self.frames]) if self.frames else np.zeros((0, 4, 4))

    def images(self) -> Iterator[np.ndarray]:
        """The frames' images in order, read one at a time."""
        for f in self.frames:
            yield f.image()


def save_scan(
    directory: str | os.PathLike,
    frames_images: Sequence[np.ndarray],
    angles: Sequence[float] | np.ndarray,
    T_base_flanges: Sequence[np.ndarray] | np.ndarray,
    calibration: CellCalibration,
    *,
    ground_truth: dict | None = None,
) -> Path:
    """Writes a scan folder: ``frames/NNN.png``, ``scan.json``, ``calibration.toml`` (and
    ``ground_truth.json`` when given, any JSON-serialisable dict). Returns the folder.

    ``frames_images`` are uint8 BGR (H, W, 3) images of the calibrated camera's size; ``angles``
    are motor angles in radians, one per frame; ``T_base_flanges`` the robot poses (4×4, mm).
    """
    import cv2

    if not isinstance(calibration, CellCalibration):
        raise InvalidInputError(f"calibration: expected a CellCalibration, got {type(calibration).__name__}")
    images = list(frames_images)
    n = len(images)
    if n == 0:
        raise InvalidInputError("frames_images: a scan needs at least one frame")
    angles_arr = as_angles(angles, "angles", size=n)
    poses = list(T_base_flanges)
    if len(poses) != n:
        raise InvalidInputError(f"T_base_flanges: expected {n} poses (one per frame), got {len(poses)}")
    poses = [as_transform(p, f"T_base_flanges[{i}]") for i, p in enumerate(poses)]
    images = [as_image(img, f"frames_images[{i}]", shape=calibration.camera.shape) for i, img in enumerate(images)]

    root = Path(directory)
    digits = max(3, len(str(n - 1)))
    try:
        (root / "frames").mkdir(parents=True, exist_ok=True)
        entries = []
        for i, (img, angle, pose) in enumerate(zip(images, angles_arr, poses)):
            rel = f"frames/{i:0{digits}d}.png"
            if not cv2.imwrite(str(root / rel), img):
                raise OSError(f"cv2.imwrite failed for {rel}")
            entries.append({"image": rel, "angle": float(angle), "T_base_flange": pose.tolist()})
        doc = {"version": SCAN_VERSION, "units": "mm, rad", "frames": entries}
        (root / "scan.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
        calibration.save(root / "calibration.toml")
        if ground_truth is not None:
            (root / "ground_truth.json").write_text(json.dumps(ground_truth), encoding="utf-8")
    except OSError as exc:
        raise FileWriteError(f"{root}: cannot write the scan ({exc})") from None
    return root


def load_scan(directory: str | os.PathLike) -> Scan:
    """Reads a scan folder written by :func:`save_scan` or by the real cell.

    Images are read lazily (``ScanFrame.image()``); the calibration is checked on load.
    """
    root = Path(directory)
    meta_path = root / "scan.json"
    try:
        doc: Any = json.loads(meta_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ScanFormatError(f"{meta_path}: not found; {root} is not a scan folder") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ScanFormatError(f"{meta_path}: cannot be read as JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("version") != SCAN_VERSION:
        got = doc.get("version") if isinstance(doc, dict) else None
        raise ScanFormatError(f"{meta_path}: version is {got!r}; this binpick reads scan version {SCAN_VERSION}")
    raw = doc.get("frames")
    if not isinstance(raw, list) or not raw:
        raise ScanFormatError(f"{meta_path}: 'frames' must be a non-empty list")
    frames = []
    for i, entry in enumerate(raw):
        where = f"{meta_path}: frames[{i}]"
        if not isinstance(entry, dict):
            raise ScanFormatError(f"{where} must be an object")
        for key in ("image", "angle", "T_base_flange"):
            if key not in entry:
                raise ScanFormatError(f"{where}.{key} is missing")
        try:
            angle = float(as_angles([entry["angle"]], f"{where}.angle")[0])
            pose = as_transform(entry["T_base_flange"], f"{where}.T_base_flange")
        except (TypeError, ValueError) as exc:
            raise ScanFormatError(str(exc)) from None
        pose.flags.writeable = False
        frames.append(ScanFrame(image_path=root / str(entry["image"]), angle=angle, T_base_flange=pose))
    calibration = CellCalibration.load(root / "calibration.toml")
    gt_path = root / "ground_truth.json"
    ground_truth = json.loads(gt_path.read_text(encoding="utf-8")) if gt_path.exists() else None
    return Scan(directory=root, frames=tuple(frames), calibration=calibration, ground_truth=ground_truth)
