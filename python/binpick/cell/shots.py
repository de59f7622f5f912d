"""A fixed 3-D camera above the bin (eye-to-hand): one depth shot per scan instead of a laser
sweep, the cloud in the camera's own frame, put into the robot's base frame with the camera's
calibrated pose ``T_base_camera`` (:class:`EyeToHand`, solved by
:func:`binpick.calibration.eye_to_hand.solve_eye_to_hand`).

* :class:`DepthSource` — what the pick loop needs of such a camera (:meth:`~DepthSource.shot`);
* :class:`TwinDepthCamera` — the digital twin's (``binpick emulate cell --camera fixed``), over
  its camera socket (:data:`binpick.cell.camera_socket.OP_DEPTH`);
* :class:`ShotReplay` — recorded shots (PLY, PCD, NPY files, in name order), replayed;
* :class:`BagShots` — a recorded ROS 2 bag's PointCloud2 messages, replayed;
* :func:`depth_scan` — a scan with such a camera: the arm to its park pose (out of the camera's
  view), one shot, the cloud in the base frame with the camera's position as its viewpoint.
"""

from __future__ import annotations

import abc
import os
import time
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Optional

import numpy as np

from .._validate import as_transform, parse_toml, positive, read_text_file, write_atomic
from ..errors import CalibrationError, DeviceError
from . import camera_socket as wire

__all__ = ["EyeToHand", "DepthSource", "TwinDepthCamera", "ShotReplay", "BagShots", "DepthCloud", "depth_scan"]


@dataclass(frozen=True, eq=False)
class EyeToHand:
    """A fixed camera's calibrated pose in the robot's base frame (mm), and how well it was solved."""

    T_base_camera: np.ndarray
    rms_mm: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_base_camera", as_transform(self.T_base_camera, "T_base_camera"))

    def to_toml(self) -> str:
        rows = ",\n  ".join("[" + ", ".join(f"{v:.9f}" for v in row) + "]" for row in self.T_base_camera)
        return (
            "# binpick eye-to-hand calibration: the fixed camera's pose in the robot's base frame, mm\n"
            f"[eye_to_hand]\nrms_mm = {self.rms_mm:.6f}\nT_base_camera = [\n  {rows},\n]\n"
        )

    def save(self, path: Any) -> None:
        write_atomic(path, self.to_toml())

    @classmethod
    def load_if_there(cls, path: Any) -> Optional[EyeToHand]:
        """:meth:`load`, or None when the file does not exist yet (a camera being calibrated)."""
        return cls.load(path) if os.path.exists(os.fspath(path)) else None

    @classmethod
    def load(cls, path: Any) -> EyeToHand:
        """Reads a file :meth:`save` wrote; CalibrationError naming the file for a missing, damaged or
        non-rigid one."""
        p = os.fspath(path)
        if not os.path.exists(p):
            raise CalibrationError(f"{p}: the eye-to-hand calibration does not exist; solve it (binpick calibrate)")
        doc = parse_toml(
            read_text_file(p, "eye-to-hand calibration", CalibrationError, max_bytes=1 << 16), p, CalibrationError
        )
        table = doc.get("eye_to_hand")
        if not isinstance(table, dict) or "T_base_camera" not in table:
            raise CalibrationError(f"{p}: has no [eye_to_hand] T_base_camera")
        try:
            T = np.array(table["T_base_camera"], dtype=np.float64)
            return cls(T, float(table.get("rms_mm", 0.0)))
        except (ValueError, TypeError) as exc:
            raise CalibrationError(f"{p}: [eye_to_hand] T_base_camera is not a rigid 4×4 transform ({exc})") from None


class DepthSource(abc.ABC):
    """A fixed 3-D camera: one shot at a time, an (N, 3) cloud in the camera's frame, mm, finite;
    ``eye_to_hand`` its pose in the base frame (None before it is calibrated: shots are taken, no
    scan is made)."""

    eye_to_hand: Optional[EyeToHand]

    @abc.abstractmethod
    def shot(self) -> np.ndarray:
        """One depth shot's points, camera frame, mm (holes left out)."""

    def close(self) -> None:
        """Releases the camera."""


class TwinDepthCamera(DepthSource):
    """The twin's fixed depth camera over its socket (``binpick emulate cell --camera fixed``)."""

    def __init__(self, path: Any, eye_to_hand: Optional[EyeToHand], *, timeout_s: float = 60.0) -> None:
        self.path = os.fspath(path)
        self.eye_to_hand = eye_to_hand
        self._sock = wire.connect(
            self.path,
            positive(timeout_s, "timeout_s", "s"),
            "start `binpick emulate cell --camera fixed --out DIR` first",
        )

    def shot(self) -> np.ndarray:
        reply = wire.request(self._sock, wire.OP_DEPTH, self.path)
        if reply.image.dtype.kind != "f":
            raise DeviceError(f"camera {self.path}: sent an image, not a depth shot; is the twin's camera fixed?")
        pts = reply.image.reshape(-1, 3).astype(np.float64)
        return pts[np.isfinite(pts).all(axis=1)]

    def close(self) -> None:
        self._sock.close()


class ShotReplay(DepthSource):
    """Recorded depth shots (PLY, PCD, NPY files of a folder, in name order, camera frame, mm
    unless a file says its unit) replayed one per scan."""

    def __init__(self, folder: Any, eye_to_hand: Optional[EyeToHand]) -> None:
        from ..clouds import SCENE_FORMATS

        self.folder = Path(os.fspath(folder))
        if not self.folder.is_dir():
            raise DeviceError(f"camera: {self.folder} is not a folder of recorded shots")
        self.files = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in SCENE_FORMATS)
        if not self.files:
            raise DeviceError(f"camera: {self.folder} holds no PLY, PCD, NPY or XYZ shot")
        self.eye_to_hand = eye_to_hand
        self._next = 0

    def shot(self) -> np.ndarray:
        from ..clouds import read_scene

        if self._next >= len(self.files):
            raise DeviceError(f"camera: all {len(self.files)} recorded shots of {self.folder} were replayed")
        path = self.files[self._next]
        self._next += 1
        return read_scene(path).points


class BagShots(DepthSource):
    """A recorded ROS 2 bag's PointCloud2 messages (:func:`binpick.ros.read_rosbag`, camera frame,
    metres unless ``unit`` says otherwise) replayed one per scan."""

    def __init__(
        self, bag: Any, eye_to_hand: Optional[EyeToHand], *, topic: Optional[str] = None, unit: str = "m"
    ) -> None:
        from ..ros import read_rosbag

        self.bag = os.fspath(bag)
        self.scans = read_rosbag(self.bag, topic=topic, unit=unit)
        self.eye_to_hand = eye_to_hand
        self._next = 0

    def shot(self) -> np.ndarray:
        if self._next >= len(self.scans):
            raise DeviceError(f"camera: all {len(self.scans)} messages of {self.bag} were replayed")
        self._next += 1
        return self.scans[self._next - 1].points


@dataclass(frozen=True, eq=False)
class DepthCloud:
    """A depth shot in the base frame: ``points`` (N, 3) mm and the camera's ``viewpoint``."""

    points: np.ndarray
    viewpoint: np.ndarray


def depth_scan(cell: Any, poses: Optional[Any] = None) -> Any:
    """A scan of ``cell`` with its fixed camera: the arm to its park pose (the first of ``poses``,
    else the cell's scan pose: one out of the camera's view), one shot, the cloud in the base
    frame. A ScanResult without laser angles; its cloud's ``viewpoint`` is the camera's centre."""
    from .records import ScanResult

    cfg, camera = cell.config, cell.camera
    if camera.eye_to_hand is None:
        raise CalibrationError(
            "camera: the fixed camera's pose in the base frame is not known; solve its eye-to-hand calibration "
            "(binpick calibrate capture / solve) and name the file in the cell file's [camera] eye_to_hand"
        )
    T_park = cfg.scan_poses[0] if poses is None or not len(poses) else as_transform(poses[0], "poses[0]")
    t0 = time.perf_counter()
    cell._go_above_approach()
    cell._move(T_park, linear=False)
    T_bf = cell.robot.read_pose()
    t1 = time.perf_counter()
    pts = camera.shot()
    T = camera.eye_to_hand.T_base_camera
    cloud = DepthCloud(points=pts @ T[:3, :3].T + T[:3, 3], viewpoint=T[:3, 3].copy())
    t2 = time.perf_counter()
    timings = {"move": (t1 - t0) * 1e3, "shot": (t2 - t1) * 1e3}
    cell.progress("scan", f"one depth shot of {len(pts)} points from the fixed camera ({timings['shot']:.0f} ms)")
    return ScanResult(
        cloud=cloud,
        angles=np.zeros(0),
        T_base_flanges=T_bf[None],
        frames=MappingProxyType({}),
        timings=MappingProxyType(timings),
    )
