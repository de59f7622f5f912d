"""Frame sources: the camera as the pick loop sees it (:class:`FrameSource`) and a real camera
opened with OpenCV (:class:`OpenCVCamera`). The simulated cameras are in :mod:`binpick.sim`."""

from __future__ import annotations

import abc
from typing import Any, Optional

import numpy as np

from .._validate import count
from ..errors import DeviceError

__all__ = ["FrameSource", "OpenCVCamera"]


class FrameSource(abc.ABC):
    """The camera as the pick loop sees it: told where the robot is before a sweep, then asked
    for one frame per laser angle (after the motor has stopped; the frame is tagged with the
    angle read at rest)."""

    def begin(self, T_base_flange: np.ndarray) -> None:
        """Called before a sweep with the flange pose read back from the robot."""

    def laser_at(self, angle: float) -> None:
        """Called before each grab with the laser angle the motor reported at rest (rad)."""

    @abc.abstractmethod
    def grab(self) -> np.ndarray:
        """One frame, uint8 BGR (H, W, 3), as the camera sees the cell now."""

    def close(self) -> None:
        """Releases the camera."""


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
