"""``[camera] source = "opencv"``: a real video file (MJPG, written with ``cv2.VideoWriter``) read
through a cell file, as ``binpick pick`` reads it, by the pick loop's own scan on emulated drivers;
a device path relative to the cell file; a missing device named in a DeviceError."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from _cell_helpers import emulated_cell_file, emulators

from binpick.cell import OpenCVCamera, cell_from_file, load_cell_file
from binpick.errors import DeviceError
from binpick.vision import extract_line

WIDTH, HEIGHT = 1032, 778  # the simulated cell's camera
FRAMES = 6  # per scan, in the cell file
FLUSH = 2  # frames OpenCVCamera drops before each grab (its default)


def line_column(i: int) -> int:
    """The column of the vertical laser line drawn in frame ``i`` of the video."""
    return 120 + 37 * i


def write_video(path, n: int) -> None:
    """``n`` frames of a black scene crossed top to bottom by a red laser line 5 px wide, at
    :func:`line_column` of the frame's number."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (WIDTH, HEIGHT))
    assert writer.isOpened(), "this OpenCV writes MJPG"
    for i in range(n):
        frame = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
        u = line_column(i)
        frame[:, u - 2 : u + 3] = (0, 0, 255)
        writer.write(frame)
    writer.release()


@pytest.fixture
def video(tmp_path):
    (tmp_path / "clips").mkdir()
    path = tmp_path / "clips" / "scan.avi"
    write_video(path, (FLUSH + 1) * FRAMES + 3)
    return path


def test_a_video_file_is_what_the_pick_loop_scans(tmp_path, video):
    with emulators() as (robot, motor, gripper):
        cfg = emulated_cell_file(
            tmp_path, robot, motor, gripper, camera=f'source = "opencv"\ndevice = "{video}"', frames=FRAMES
        )
        cell = cell_from_file(load_cell_file(cfg))
        assert isinstance(cell.camera, OpenCVCamera) and cell.camera.device == str(video)
        with cell:
            scan = cell.scan()
        assert robot.failures == motor.failures == gripper.failures == []
    assert len(scan.angles) == FRAMES and sorted(scan.frames) == list(range(FRAMES))
    for k, image in scan.frames.items():
        assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.uint8
        uv = extract_line(image)
        assert len(uv) > 0.9 * HEIGHT, "the line crosses every row"
        # Each grab drops FLUSH frames first: grab k is frame (FLUSH + 1) k + FLUSH of the video.
        assert abs(np.median(uv[:, 0]) - line_column((FLUSH + 1) * k + FLUSH)) < 1.0, k


def test_a_relative_device_path_is_read_from_the_cell_files_folder(tmp_path, video, monkeypatch):
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")  # not where the cell file is
    with emulators() as (robot, motor, gripper):
        cfg = emulated_cell_file(
            tmp_path, robot, motor, gripper, camera='source = "opencv"\ndevice = "clips/scan.avi"', frames=FRAMES
        )
        cell = cell_from_file(load_cell_file(cfg))
        try:
            assert cell.camera.device == str(video)
            first = cell.camera.grab()
        finally:
            cell.close()
    assert abs(np.median(extract_line(first)[:, 0]) - line_column(FLUSH)) < 1.0


@pytest.mark.parametrize(
    ("device", "match"),
    [
        ('"clips/missing.avi"', r"camera: '.*/clips/missing\.avi' does not exist; give a device index"),
        ("97", r"camera: cannot open 97; check the device index"),
        ('"rtsp://127.0.0.1:9/cell"', r"camera: cannot open 'rtsp://127\.0\.0\.1:9/cell'; check"),
    ],
    ids=["missing-file", "index", "url"],
)
def test_a_camera_that_cannot_be_opened_is_a_device_error_naming_it(tmp_path, device, match):
    # A device index and a URL reach OpenCV as written; only a path is resolved.
    with emulators() as (robot, motor, gripper):
        cfg = emulated_cell_file(tmp_path, robot, motor, gripper, camera=f'source = "opencv"\ndevice = {device}')
        with pytest.raises(DeviceError, match=match) as info:
            cell_from_file(load_cell_file(cfg))
    if "clips" in device:  # resolved against the cell file's folder
        assert f"'{tmp_path / 'clips' / 'missing.avi'}'" in str(info.value)
