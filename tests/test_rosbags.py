"""ROS 2 bags as scenes (binpick.ros): PointCloud2 messages written into real rosbag2 files by the
rosbags library's own writer, read back by binpick — the points in mm, organized clouds' holes
dropped, either byte order and float width, the topic chosen, and damaged messages refused by
name; then a pose estimated from a bag of a simulated pile."""

from __future__ import annotations

import numpy as np
import pytest

import binpick
from binpick.errors import InvalidInputError, MeshFileError
from binpick.ros import POINTCLOUD2, read_rosbag

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag2 import Writer  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

STORE = get_typestore(Stores.ROS2_HUMBLE)


def _cloud_msg(points_m: np.ndarray, *, width=None, dtype="<f4", extra_bytes=4, frame="camera_optical", t=0):
    """A PointCloud2 of ``points_m`` (x, y, z and ``extra_bytes`` of padding per record)."""
    T = STORE.types
    n = len(points_m)
    width = n if width is None else width
    height = n // width
    size = np.dtype(dtype).itemsize
    step = 3 * size + extra_bytes
    rec = np.zeros((n, step), dtype=np.uint8)
    rec[:, : 3 * size] = np.ascontiguousarray(points_m.astype(dtype)).view(np.uint8).reshape(n, 3 * size)
    fields = [
        T["sensor_msgs/msg/PointField"](name=a, offset=i * size, datatype=7 if size == 4 else 8, count=1)
        for i, a in enumerate("xyz")
    ]
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t, nanosec=5), frame_id=frame)
    return T[POINTCLOUD2](
        header=header,
        height=height,
        width=width,
        fields=fields,
        is_bigendian=dtype.startswith(">"),
        point_step=step,
        row_step=width * step,
        data=rec.reshape(-1),
        is_dense=False,
    )


def _bag(path, messages: dict) -> None:
    with Writer(path, version=8) as writer:
        for topic, msgs in messages.items():
            conn = writer.add_connection(topic, POINTCLOUD2, typestore=STORE)
            for i, msg in enumerate(msgs):
                writer.write(conn, 1_000 + i, STORE.serialize_cdr(msg, POINTCLOUD2))


def test_a_bag_of_pointclouds_reads_back_in_millimetres(tmp_path):
    rng = np.random.default_rng(3)
    a, b = rng.uniform(-1, 1, (120, 3)), rng.uniform(-1, 1, (60, 3))
    a[7] = np.nan  # a hole of an organized cloud
    _bag(tmp_path / "bag", {"/cam/points": [_cloud_msg(a, width=12, t=1), _cloud_msg(b, dtype=">f8", t=2)]})
    scans = read_rosbag(tmp_path / "bag")
    assert [s.topic for s in scans] == ["/cam/points"] * 2 and [s.stamp_ns for s in scans] == [1e9 + 5, 2e9 + 5]
    assert scans[0].dropped == 1 and len(scans[0]) == 119 and scans[0].frame_id == "camera_optical"
    assert np.allclose(scans[0].points, np.delete(a, 7, axis=0).astype("f4") * 1000.0)
    assert np.allclose(scans[1].points, b * 1000.0, atol=1e-9)  # big-endian float64
    first = binpick.read_scene(tmp_path / "bag")  # a scene: the first message
    assert first.format == "rosbag2" and np.allclose(first.points, scans[0].points)
    assert np.allclose(read_rosbag(tmp_path / "bag", unit="mm")[1].points, b, atol=1e-12)


def test_the_topic_is_chosen_and_a_wrong_one_is_named(tmp_path):
    pts = np.ones((5, 3))
    _bag(tmp_path / "bag", {"/left": [_cloud_msg(pts)], "/right": [_cloud_msg(2 * pts)]})
    with pytest.raises(InvalidInputError, match="/left"):
        read_rosbag(tmp_path / "bag")
    assert np.allclose(read_rosbag(tmp_path / "bag", topic="/right")[0].points, 2000.0)
    with pytest.raises(InvalidInputError, match="not a PointCloud2 topic"):
        read_rosbag(tmp_path / "bag", topic="/middle")


@pytest.mark.parametrize(
    "damage, says",
    [
        (lambda m: setattr(m, "width", m.width * 4), "do not fit"),
        (lambda m: setattr(m, "point_step", 2), "runs past|do not fit"),
        (lambda m: m.fields.pop(), "has no z field"),
        (lambda m: setattr(m.fields[0], "datatype", 2), "datatype 2"),
    ],
)
def test_a_message_whose_sizes_or_fields_lie_is_refused_by_name(tmp_path, damage, says):
    msg = _cloud_msg(np.ones((10, 3)))
    damage(msg)
    _bag(tmp_path / "bag", {"/points": [msg]})
    with pytest.raises(MeshFileError, match=says):
        read_rosbag(tmp_path / "bag")


def test_a_missing_or_foreign_bag_says_so(tmp_path):
    with pytest.raises(binpick.errors.MeshFileNotFoundError):
        read_rosbag(tmp_path / "nothing.mcap")
    (tmp_path / "junk.db3").write_bytes(b"not sqlite at all")
    with pytest.raises(MeshFileError, match="cannot be read as a ROS 2 bag"):
        read_rosbag(tmp_path / "junk.db3")


def test_a_pose_from_a_bag_of_a_simulated_pile(tmp_path):
    from binpick import sim
    from binpick.scan import load_scan
    from binpick.vision import reconstruct

    scan = sim.simulate_scan(binpick.parts.tee(), 3, seed=1, frames=45)
    cloud = reconstruct(load_scan(sim.write_scan(scan, tmp_path / "scan"))).points
    _bag(tmp_path / "bag", {"/laser/points": [_cloud_msg(np.asarray(cloud) / 1000.0)]})
    scene = binpick.read_scene(tmp_path / "bag")
    assert len(scene) == len(cloud)
    lo, hi = scan.cell.bin.bounds
    res = binpick.estimate_pose(scene.points, binpick.parts.tee(), bin=(lo, hi))
    errors = [binpick.parts.tee().pose_error(res.T_scene_model, T) for T in scan.pile.poses]
    assert any(deg < 5.0 and mm < 3.0 for deg, mm in errors)  # pick-grade against an instance


def test_a_bag_replays_as_a_fixed_cameras_shots(tmp_path):
    from binpick.cell.shots import BagShots, EyeToHand
    from binpick.errors import DeviceError

    a, b = np.ones((20, 3)), 2 * np.ones((30, 3))
    _bag(tmp_path / "bag", {"/camera/depth/points": [_cloud_msg(a), _cloud_msg(b)]})
    shots = BagShots(tmp_path / "bag", EyeToHand(np.eye(4)))
    assert np.allclose(shots.shot(), 1000.0) and len(shots.shot()) == 30
    with pytest.raises(DeviceError, match="all 2 messages"):
        shots.shot()
