"""Frame sources: the camera as the pick loop sees it (:class:`FrameSource`), a real camera
opened with OpenCV (:class:`OpenCVCamera`), the digital twin's camera over its socket
(:class:`TwinCamera`), a recorded scan replayed (:class:`FolderReplay`), and a recorder that
saves every sweep of another source as a scan folder (:class:`ScanRecorder`). The simulated
in-process cameras are in :mod:`binpick.sim`."""

from __future__ import annotations

import abc
import math
import os
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .._validate import as_transform, count, instance_of, positive
from ..errors import DeviceError, InvalidInputError
from . import camera_socket as wire

__all__ = ["FrameSource", "OpenCVCamera", "TwinCamera", "FolderReplay", "ReplayMismatchError", "ScanRecorder", "Sweep"]


class FrameSource(abc.ABC):
    """The camera as the pick loop sees it: told where the robot is before a sweep, then asked
    for one frame per laser angle (after the motor has stopped; the frame is tagged with the
    angle read at rest).

    A source that streams at a known rate while the laser turns (a continuous sweep,
    ``CellConfig.sweep = "continuous"``) says so: :attr:`fps`, its frame rate, and after each
    grab :attr:`frame_time_s`, the middle of that frame's exposure on the cell's clock
    (:attr:`binpick.cell.Cell.clock`); None where it cannot tell."""

    fps: Optional[float] = None
    frame_time_s: Optional[float] = None

    def begin(self, T_base_flange: np.ndarray) -> None:
        """Called before a sweep with the flange pose read back from the robot."""

    def streaming(self, on: bool) -> None:
        """Called with True when a continuous sweep starts (frames at the camera's own rate,
        whatever the host does between grabs) and False when it ends."""

    def laser_at(self, angle: float) -> None:
        """Called before each grab with the laser angle the motor reported at rest (rad)."""

    @abc.abstractmethod
    def grab(self) -> np.ndarray:
        """One frame, uint8 BGR (H, W, 3), as the camera sees the cell now."""

    def close(self) -> None:
        """Releases the camera."""


def is_device_path(device: Any) -> bool:
    """Whether ``cv2.VideoCapture`` takes ``device`` as a filesystem path (a video device, a
    video file, an image sequence): a string that is neither a URL (``scheme://…``) nor a
    GStreamer pipeline (``… ! …``). A device index is not a path."""
    return isinstance(device, str) and "://" not in device and "!" not in device


class OpenCVCamera(FrameSource):
    """A camera opened with ``cv2.VideoCapture`` (a device index, a device path or a stream URL).

    Args:
        device: what ``cv2.VideoCapture`` opens.
        width: requested frame width, px (None = the camera's default).
        height: requested frame height, px.
        flush: frames read and dropped before each grab, so that the frame kept was exposed
            after the motor arrived (drivers keep a small buffer).
    """

    def __init__(
        self, device: Any = 0, *, width: Optional[int] = None, height: Optional[int] = None, flush: int = 2
    ) -> None:
        import cv2

        self.device = device
        self.flush = count(flush, "flush")
        if is_device_path(device) and not os.path.exists(device):
            raise DeviceError(
                f"camera: {device!r} does not exist; give a device index (0), the path of a video device or "
                "file, or a stream URL (rtsp://…)"
            )
        self._cap = cv2.VideoCapture(device)
        if not self._cap.isOpened():
            raise DeviceError(
                f"camera: cannot open {device!r}; check the device index or path and that no other program holds it"
            )
        if width is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(width))
        if height is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(height))

    def grab(self) -> np.ndarray:
        for _ in range(self.flush):
            self._cap.grab()
        ok, frame = self._cap.read()
        if not ok or frame is None:
            raise DeviceError(f"camera: {self.device!r} returned no frame; check the cable and the trigger settings")
        return frame

    def close(self) -> None:
        self._cap.release()


class TwinCamera(FrameSource):
    """The digital twin's camera (``binpick emulate cell``), read over its Unix-domain socket with
    the protocol of :mod:`binpick.cell.camera_socket`. The twin renders what its camera sees
    from the emulated arm's actual pose and the motor emulator's actual angle; the pose and angle
    of the last frame are kept (:attr:`last`).

    Args:
        path: the socket, ``DIR/camera.sock``.
        timeout_s: longest wait for one reply, seconds (a frame after a pick may wait for the
            twin's physics to settle the pile).
    """

    def __init__(self, path: Any, *, timeout_s: float = 60.0) -> None:
        self.path = os.fspath(path)
        self.timeout_s = positive(timeout_s, "timeout_s", "s")
        self.last: Optional[wire.Frame] = None
        self._sock = wire.connect(
            self.path, self.timeout_s, "start `binpick emulate cell --out DIR` first and give DIR/camera.sock"
        )

    def grab(self) -> np.ndarray:
        self.last = wire.request(self._sock, wire.OP_FRAME, self.path)
        return self.last.image

    def close(self) -> None:
        self._sock.close()


class ReplayMismatchError(DeviceError):
    """A replayed scan was asked for a frame from another robot pose or laser angle than it recorded."""


class FolderReplay(FrameSource):
    """A recorded scan folder (:mod:`binpick.scan` format) replayed frame by frame, in order.

    Each :meth:`begin` is checked against the flange pose recorded for the next frame, each
    :meth:`laser_at` against its laser angle; a request the recording does not hold raises
    :class:`ReplayMismatchError` naming the frame, the recorded and the requested values. So a
    pick loop run on a replay sees exactly the frames of the run that recorded them, or stops.

    Args:
        folder: the scan folder.
        angle_tolerance_deg: largest difference between a requested and a recorded angle.
        position_tolerance_mm: largest distance between a requested and a recorded flange position …
        rotation_tolerance_deg: … and angle between their orientations.
    """

    def __init__(
        self,
        folder: Any,
        *,
        angle_tolerance_deg: float = 0.2,
        position_tolerance_mm: float = 1.0,
        rotation_tolerance_deg: float = 0.1,
    ) -> None:
        from ..scan import load_scan

        self.scan = load_scan(folder)
        self.angle_tolerance = math.radians(positive(angle_tolerance_deg, "angle_tolerance_deg", "deg"))
        self.position_tolerance_mm = positive(position_tolerance_mm, "position_tolerance_mm")
        self.rotation_tolerance = math.radians(positive(rotation_tolerance_deg, "rotation_tolerance_deg", "deg"))
        self._next = 0

    @property
    def remaining(self) -> int:
        """Frames not yet replayed."""
        return len(self.scan) - self._next

    def _frame(self, what: str) -> Any:
        if self._next >= len(self.scan):
            raise ReplayMismatchError(
                f"camera: the replayed scan {self.scan.directory} holds {len(self.scan)} frames and all were "
                f"replayed; {what} asks for one more — record a scan with as many frames as the cell sweeps"
            )
        return self.scan.frames[self._next]

    def begin(self, T_base_flange: np.ndarray) -> None:
        T = as_transform(T_base_flange, "T_base_flange")
        rec = self._frame("begin()")
        moved = float(np.linalg.norm(T[:3, 3] - rec.T_base_flange[:3, 3]))
        cos = (np.trace(rec.T_base_flange[:3, :3].T @ T[:3, :3]) - 1.0) / 2.0
        turned = math.acos(max(-1.0, min(1.0, float(cos))))
        if moved > self.position_tolerance_mm or turned > self.rotation_tolerance:
            raise ReplayMismatchError(
                f"camera: frame {self._next} of the replayed scan {self.scan.directory} was recorded with the "
                f"flange at {np.round(rec.T_base_flange[:3, 3], 2).tolist()} mm, but the robot is at "
                f"{np.round(T[:3, 3], 2).tolist()} mm ({moved:.2f} mm, {math.degrees(turned):.3f}° apart); "
                "replay the scan with the scan pose it was recorded from"
            )

    def laser_at(self, angle: float) -> None:
        rec = self._frame("laser_at()")
        if not abs(float(angle) - rec.angle) <= self.angle_tolerance:
            raise ReplayMismatchError(
                f"camera: frame {self._next} of the replayed scan {self.scan.directory} was recorded with the "
                f"laser at {math.degrees(rec.angle):.3f}°, but the motor reports {math.degrees(float(angle)):.3f}°; "
                "replay the scan with the sweep (frames, calibration, scan pose) it was recorded with"
            )

    def grab(self) -> np.ndarray:
        rec = self._frame("grab()")
        self._next += 1
        return rec.image()


class ScanRecorder(FrameSource):
    """Passes another source's frames through and saves each sweep (from one :meth:`begin` to
    the next, or to :meth:`close`) as a scan folder ``folder/sweep_NNN`` (:func:`binpick.scan.save_scan`),
    with the angles the motor reported and the pose the robot reported: a recording that
    :class:`FolderReplay` replays and :func:`binpick.vision.reconstruct` reconstructs.

    Args:
        source: the camera to record.
        calibration: the cell's calibration (saved with each sweep).
        folder: where the sweeps go.
    """

    def __init__(self, source: FrameSource, calibration: Any, folder: Any) -> None:
        from ..calibration import CellCalibration

        self.source = instance_of(source, FrameSource, "source", "OpenCVCamera(0)")
        self.calibration = instance_of(calibration, CellCalibration, "calibration", "CellCalibration.load(path)")
        self.folder = Path(folder)
        self.saved: list[Path] = []
        self._pose: Optional[np.ndarray] = None
        self._angle: Optional[float] = None
        self._images: list[np.ndarray] = []
        self._angles: list[float] = []

    def begin(self, T_base_flange: np.ndarray) -> None:
        self.flush()
        self._pose = as_transform(T_base_flange, "T_base_flange")
        self.source.begin(T_base_flange)

    def laser_at(self, angle: float) -> None:
        self._angle = float(angle)
        self.source.laser_at(angle)

    def grab(self) -> np.ndarray:
        if self._pose is None or self._angle is None:
            raise InvalidInputError("camera: call begin(T_base_flange) and laser_at(angle) before grab() to record")
        img = self.source.grab()
        self._images.append(img)
        self._angles.append(self._angle)
        return img

    def flush(self) -> Optional[Path]:
        """Saves the sweep recorded so far, if any; returns its folder."""
        if not self._images:
            return None
        from ..scan import save_scan

        out = save_scan(
            self.folder / f"sweep_{len(self.saved):03d}",
            self._images,
            self._angles,
            [self._pose] * len(self._images),
            self.calibration,
        )
        self.saved.append(out)
        self._images, self._angles = [], []
        return out

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self.source.close()


class Sweep:
    """The frames of one scan as they come in: line pixels, frame index, motor angle, flange pose."""

    def __init__(self) -> None:
        self.pixels: list[np.ndarray] = []
        self.frame_of: list[np.ndarray] = []
        self.angles: list[float] = []
        self.poses: list[np.ndarray] = []
        self.kept: dict[int, np.ndarray] = {}

    def add(self, uv: np.ndarray, angle: float, T_base_flange: np.ndarray, image: Optional[np.ndarray]) -> None:
        index = len(self.angles)
        self.pixels.append(uv)
        self.frame_of.append(np.full(len(uv), index, dtype=np.int64))
        self.angles.append(angle)
        self.poses.append(T_base_flange)
        if image is not None:
            self.kept[index] = image
