"""Recorded ROS 2 bags as scenes (:func:`binpick.read_scene` takes a bag; this leaf reads it):
``sensor_msgs/msg/PointCloud2`` messages read from rosbag2 files
(SQLite ``.db3`` or MCAP) with the pure-Python ``rosbags`` library — no ROS installation needed
(``pip install "binpick[ros]"``).

A PointCloud2 carries its points as records of ``point_step`` bytes, the ``x``, ``y`` and ``z``
fields at their offsets (FLOAT32 or FLOAT64, either byte order), ``width`` × ``height`` records
(``row_step`` bytes per row). ROS lengths are metres (REP 103): binpick converts to mm unless told
the bag's unit. Every size is checked against the message's bytes before anything is allocated;
a record with a NaN coordinate (an organized cloud's hole) is dropped and counted.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ._paths import no_such_file
from ._validate import unit_scale
from .errors import InvalidInputError, MeshFileError, MeshFileNotFoundError

__all__ = ["RosScan", "is_rosbag", "read_rosbag", "pointcloud2_points", "POINTCLOUD2"]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
#: PointField datatypes binpick reads for x, y, z.
_FLOAT_TYPES = {7: "f4", 8: "f8"}
#: Largest cloud read from one message, points.
MAX_POINTS = 50_000_000


@dataclass(frozen=True, eq=False)
class RosScan:
    """One PointCloud2 message: its points (N, 3) float64 in mm, the records dropped for a
    non-finite coordinate, its topic, its header stamp (ns) and frame."""

    points: np.ndarray
    dropped: int
    topic: str
    stamp_ns: int
    frame_id: str

    def __len__(self) -> int:
        return len(self.points)


def is_rosbag(path: Any) -> bool:
    """Whether ``path`` is a rosbag2: a folder holding ``metadata.yaml``, or an ``.mcap``/``.db3`` file."""
    p = Path(os.fspath(path))
    return (p.is_dir() and (p / "metadata.yaml").is_file()) or p.suffix.lower() in (".mcap", ".db3")


def pointcloud2_points(msg: Any, where: str = "PointCloud2") -> tuple[np.ndarray, int]:
    """The (N, 3) float64 points of a PointCloud2 message (its own unit) and how many records
    were dropped for a non-finite coordinate; MeshFileError naming ``where`` for a message whose
    fields or sizes do not add up."""
    fields = {f.name: f for f in msg.fields}
    missing = [a for a in "xyz" if a not in fields]
    if missing:
        raise MeshFileError(f"{where}: has no {', '.join(missing)} field (fields: {', '.join(fields) or 'none'})")
    width, height, step, row = int(msg.width), int(msg.height), int(msg.point_step), int(msg.row_step)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    n = width * height
    if n > MAX_POINTS:
        raise MeshFileError(f"{where}: claims {width} × {height} points, more than the {MAX_POINTS} binpick reads")
    need = (height - 1) * row + width * step if n else 0
    if step <= 0 or row < width * step or len(data) < need:
        raise MeshFileError(
            f"{where}: {width} × {height} records of {step} bytes ({row} per row) do not fit its {len(data)} bytes"
        )
    order = ">" if msg.is_bigendian else "<"
    out = np.empty((n, 3), dtype=np.float64)
    for k, axis in enumerate("xyz"):
        f = fields[axis]
        kind = _FLOAT_TYPES.get(int(f.datatype))
        if kind is None or int(f.count) < 1:
            raise MeshFileError(
                f"{where}: field {axis} has datatype {int(f.datatype)}; binpick reads FLOAT32 (7) and FLOAT64 (8)"
            )
        size = int(kind[1])
        if int(f.offset) + size > step:
            raise MeshFileError(f"{where}: field {axis} at offset {int(f.offset)} runs past the {step}-byte record")
        rows = np.lib.stride_tricks.as_strided(
            data[int(f.offset) :], shape=(height, width, size), strides=(row, step, 1), writeable=False
        )
        out[:, k] = np.ascontiguousarray(rows).view(order + kind).reshape(n)
    finite = np.isfinite(out).all(axis=1)
    return out[finite], int(n - np.count_nonzero(finite))


def read_rosbag(
    path: Any, *, topic: Optional[str] = None, unit: str = "m", max_messages: Optional[int] = None
) -> list[RosScan]:
    """The PointCloud2 messages of a rosbag2 (of ``topic``, or of the bag's only PointCloud2
    topic), in recorded order, at most ``max_messages``; points in mm (``unit`` is the bag's,
    metres as ROS has it). MeshFileNotFoundError for a missing bag, MeshFileError for a damaged
    one or one without such a topic, InvalidInputError naming the topics when ``topic`` is not one."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise InvalidInputError(
            'reading ROS 2 bags needs the rosbags library: pip install "binpick[ros]" (or pip install rosbags)'
        ) from None
    p = Path(os.fspath(path))
    if not p.exists():
        raise MeshFileNotFoundError(no_such_file(p, "ROS 2 bag"))
    scale = unit_scale(unit)
    try:
        with AnyReader([p]) as reader:
            clouds = sorted({c.topic for c in reader.connections if c.msgtype == POINTCLOUD2})
            if not clouds:
                raise MeshFileError(f"{p}: has no {POINTCLOUD2} topic")
            if topic is None and len(clouds) > 1:
                raise InvalidInputError(f"topic: {p} has the PointCloud2 topics {clouds}; name one")
            topic = clouds[0] if topic is None else topic
            if topic not in clouds:
                raise InvalidInputError(f"topic: {topic!r:.60} is not a PointCloud2 topic of {p}; use one of {clouds}")
            out: list[RosScan] = []
            connections = [c for c in reader.connections if c.topic == topic]
            for connection, _, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, connection.msgtype)
                where = f"{p} {topic} message {len(out)}"
                pts, dropped = pointcloud2_points(msg, where)
                stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
                out.append(RosScan(pts * scale, dropped, topic, stamp, str(msg.header.frame_id)))
                if max_messages is not None and len(out) >= max_messages:
                    break
    except (MeshFileError, InvalidInputError):
        raise
    except Exception as exc:  # rosbags' own errors: a damaged or unsupported bag
        raise MeshFileError(f"{p}: cannot be read as a ROS 2 bag ({type(exc).__name__}: {exc})") from None
    if not out:
        raise MeshFileError(f"{p}: the topic {topic} holds no message")
    return out
