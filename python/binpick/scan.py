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

from ._validate import MAX_IMAGE_PIXELS, as_angles, as_image, as_path, as_transform, image_size, read_text_file
from .calibration import CellCalibration
from .errors import FileWriteError, InvalidInputError, InvalidTypeError, MeshFileNotFoundError, ScanFormatError

__all__ = ["SCAN_VERSION", "Scan", "ScanFrame", "load_scan", "save_scan"]

#: The scan format this code writes and reads.
SCAN_VERSION = 1

#: Largest scan.json or ground_truth.json read, bytes (a 1,000-frame scan.json is about 400 kB).
MAX_JSON_BYTES = 64 << 20

#: Most frames a scan.json may list.
MAX_FRAMES = 100_000

#: Largest frame image file read, bytes (an uncompressed BGR frame of the largest image allowed).
MAX_FRAME_BYTES = 3 * MAX_IMAGE_PIXELS + (1 << 20)

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a readable file's name; False for names the OS refuses (too long, …)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


@dataclass(frozen=True, eq=False)
class ScanFrame:
    """One frame of a scan: where its image is, the motor angle (rad) and ``T_base_flange`` at
    capture, and the (height, width) its image must have (None: any)."""

    image_path: Path
    angle: float
    T_base_flange: np.ndarray
    shape: tuple[int, int] | None = None

    def image(self) -> np.ndarray:
        """The frame as cv2.imread returns it: uint8 BGR (H, W, 3).

        A PNG's chunks are checked against the bytes present and its header against ``shape``
        and the pixel ceilings before the image is decoded, so a file that declares a huge image
        or a huge chunk is refused without allocating for it. Other formats are left to OpenCV's
        own checks; every decoded image is checked against ``shape``.
        """
        import cv2

        try:
            with open(self.image_path, "rb") as f:
                data = f.read(MAX_FRAME_BYTES + 1)
        except (OSError, ValueError):
            raise MeshFileNotFoundError(
                f"{self.image_path}: cannot read the frame image; is the scan folder complete?"
            ) from None
        if len(data) > MAX_FRAME_BYTES:
            raise ScanFormatError(f"{self.image_path}: the frame file is larger than {MAX_FRAME_BYTES} bytes")
        if data.startswith(_PNG_SIGNATURE):
            self._check_png(data)
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR) if data else None
        if img is None:
            raise ScanFormatError(f"{self.image_path}: the frame image is corrupt or not an image; grab it again")
        if self.shape is not None and img.shape[:2] != tuple(self.shape):
            raise ScanFormatError(
                f"{self.image_path}: the frame is {img.shape[1]}×{img.shape[0]} but the scan's calibration says "
                f"{self.shape[1]}×{self.shape[0]} (camera.width × camera.height); use the calibration of the "
                "camera that grabbed it"
            )
        return img

    def _check_png(self, data: bytes) -> None:
        """Walks the PNG's chunks: each declared length must fit in the bytes that follow, the
        first chunk is IHDR, and its width × height passes :func:`image_size` and ``shape``."""
        where = f"{self.image_path}: PNG"
        pos, size = len(_PNG_SIGNATURE), None
        while pos < len(data):
            if pos + 12 > len(data):
                raise ScanFormatError(f"{where} stops inside a chunk at byte {pos}; the file is truncated")
            length, kind = int.from_bytes(data[pos : pos + 4], "big"), data[pos + 4 : pos + 8]
            if length > len(data) - pos - 12:
                raise ScanFormatError(
                    f"{where} chunk {kind!r} at byte {pos} declares {length} bytes but {len(data) - pos - 12} "
                    "follow; the file is truncated or damaged, grab the frame again"
                )
            if size is None:
                if kind != b"IHDR" or length != 13:
                    raise ScanFormatError(f"{where} does not start with its IHDR header chunk; the file is damaged")
                size = int.from_bytes(data[pos + 8 : pos + 12], "big"), int.from_bytes(data[pos + 12 : pos + 16], "big")
            if kind == b"IEND":
                break
            pos += 12 + length
        if size is None:
            raise ScanFormatError(f"{where} holds no IHDR header chunk; the file is truncated")
        width, height = image_size(size[0], size[1], f"{where} header", ScanFormatError)
        if self.shape is not None and (height, width) != tuple(self.shape):
            raise ScanFormatError(
                f"{where} header declares {width}×{height} pixels but the scan's calibration says "
                f"{self.shape[1]}×{self.shape[0]}; the frame belongs to another camera or is damaged"
            )


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
    truth = None if ground_truth is None else _truth_json(ground_truth)

    root = as_path(directory, "directory")
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
        if truth is not None:
            (root / "ground_truth.json").write_text(truth, encoding="utf-8")
    except OSError as exc:
        raise FileWriteError(f"{root}: cannot write the scan ({exc})") from None
    return root


def _truth_json(ground_truth: Any) -> str:
    """``ground_truth`` as JSON text, checked before anything of the scan is written: a dict of
    JSON values (InvalidInputError naming ``ground_truth`` otherwise)."""
    if not isinstance(ground_truth, dict):
        raise InvalidTypeError(f"ground_truth: expected a dict, got {type(ground_truth).__name__}")
    try:
        return json.dumps(ground_truth)
    except (TypeError, ValueError, RecursionError) as exc:  # a value JSON has no form for, a cycle
        raise InvalidInputError(f"ground_truth: cannot be written as JSON ({str(exc)[:120]})") from None


def _read_json(path: Path, what: str, missing: str = "") -> Any:
    """The parsed JSON document of ``path``, or ScanFormatError naming the file and the problem."""
    text = read_text_file(path, what, ScanFormatError, max_bytes=MAX_JSON_BYTES, missing=missing)
    try:
        return json.loads(text)
    except RecursionError:
        raise ScanFormatError(f"{path}: arrays or objects nested too deeply to be a {what}") from None
    except ValueError as exc:  # JSONDecodeError, and integers longer than Python converts
        raise ScanFormatError(f"{path}: cannot be read as JSON ({str(exc)[:200]}); fix or rewrite the {what}") from None


def _frame_entry(entry: Any, root: Path, where: str) -> tuple[Path, float, np.ndarray]:
    """One checked entry of scan.json's ``frames``: the image's path, the angle and the pose."""
    if not isinstance(entry, dict):
        raise ScanFormatError(f"{where} must be an object with image, angle and T_base_flange")
    for key in ("image", "angle", "T_base_flange"):
        if key not in entry:
            raise ScanFormatError(f"{where}.{key} is missing")
    rel = entry["image"]
    if not isinstance(rel, str) or not rel or "\x00" in rel or len(rel) > 4096:
        raise ScanFormatError(f"{where}.image must be a path such as 'frames/000.png', got {rel!r:.60}")
    if Path(rel).is_absolute() or ".." in Path(rel).parts:
        raise ScanFormatError(f"{where}.image is {rel!r:.60}; it must be a path inside the scan folder")
    try:
        angle = float(as_angles([entry["angle"]], f"{where}.angle")[0])
        pose = as_transform(entry["T_base_flange"], f"{where}.T_base_flange")
    except (TypeError, ValueError, RecursionError) as exc:
        raise ScanFormatError(f"{str(exc)[:300]}; fix the frame's entry or save the scan again") from None
    pose.flags.writeable = False
    return root / rel, angle, pose


def load_scan(directory: str | os.PathLike) -> Scan:
    """Reads a scan folder written by :func:`save_scan` or by the real cell.

    Every frame's entry and the calibration are checked on load, and each listed image must be
    present; the images themselves are read lazily (``ScanFrame.image()``, which checks their
    size against the calibration). A wrong file raises ScanFormatError (CalibrationError for
    calibration.toml) naming the file and the field.
    """
    root = Path(directory)
    meta_path = root / "scan.json"
    doc = _read_json(meta_path, "scan.json", missing=f"{root} is not a scan folder")
    if not isinstance(doc, dict) or type(doc.get("version")) is not int or doc.get("version") != SCAN_VERSION:
        got = doc.get("version") if isinstance(doc, dict) else None
        raise ScanFormatError(
            f"{meta_path}: version is {got!r:.40}; this binpick reads scan version {SCAN_VERSION} "
            f'(an object starting {{"version": {SCAN_VERSION}, ...}})'
        )
    raw = doc.get("frames")
    if not isinstance(raw, list) or not raw:
        raise ScanFormatError(f"{meta_path}: 'frames' must be a non-empty list of frame entries")
    if len(raw) > MAX_FRAMES:
        raise ScanFormatError(f"{meta_path}: 'frames' lists {len(raw)} frames, more than the {MAX_FRAMES} read")
    entries = [_frame_entry(entry, root, f"{meta_path}: frames[{i}]") for i, entry in enumerate(raw)]
    absent = [i for i, (path, _, _) in enumerate(entries) if not _is_file(path)]
    if absent:
        raise ScanFormatError(
            f"{meta_path}: lists {len(entries)} frames but the image of {len(absent)} of them is not in the folder "
            f"(frames[{absent[0]}].image = {str(entries[absent[0]][0].relative_to(root))!r:.60}); copy the whole "
            "scan folder"
        )
    calibration = CellCalibration.load(root / "calibration.toml")
    shape = calibration.camera.shape
    frames = tuple(ScanFrame(image_path=p, angle=a, T_base_flange=T, shape=shape) for p, a, T in entries)
    gt_path = root / "ground_truth.json"
    ground_truth = None
    if gt_path.exists():
        ground_truth = _read_json(gt_path, "ground_truth.json")
        if not isinstance(ground_truth, dict):
            raise ScanFormatError(f"{gt_path}: must hold a JSON object, got {type(ground_truth).__name__}")
    return Scan(directory=root, frames=frames, calibration=calibration, ground_truth=ground_truth)
