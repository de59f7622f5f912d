"""The GigE Vision frame source (binpick.cell.gige) end to end against Debian's fake GigE Vision
camera (arv-fake-gv-camera-0.8, aravis-tools) on 127.0.0.1: opened by its id, exposure and the
software trigger set, a sweep's 90 frames grabbed through the FrameSource calls the pick loop
makes, each with its camera timestamp and a consecutive frame id; a camera losing packets with
resends off is noticed frame by frame; and the cell file's [camera] source = "gige"."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest

from binpick.errors import DeviceError

FAKE = shutil.which("arv-fake-gv-camera-0.8")
pytestmark = pytest.mark.skipif(FAKE is None, reason="Debian's aravis-tools (arv-fake-gv-camera-0.8) is not installed")


def _fake_camera(*extra: str):
    proc = subprocess.Popen(
        [FAKE, "-i", "127.0.0.1", *extra],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    time.sleep(0.5)
    return proc


def _stop(proc) -> None:
    os.killpg(proc.pid, signal.SIGTERM)
    proc.wait(timeout=10)


@pytest.fixture()
def camera_id():
    """A fake camera on 127.0.0.1 for one test (one at a time: each binds GVCP's port 3956 there)."""
    pytest.importorskip("gi")
    proc = _fake_camera()
    try:
        yield "127.0.0.1"  # opened by its address
    finally:
        _stop(proc)


def test_a_sweep_of_frames_with_timestamps_and_no_frame_lost(camera_id):
    from binpick.cell.gige import GigEVisionCamera

    cam = GigEVisionCamera(camera_id, exposure_us=2000.0)
    try:
        assert cam.exposure_us == pytest.approx(2000.0) and cam.pixel_format == "Mono8"
        cam.begin(np.eye(4))
        frames = []
        for angle in np.linspace(-0.3, 0.3, 90):  # as the cell's sweep calls it
            cam.laser_at(float(angle))
            frames.append(cam.grab())
        assert len(frames) == 90 and all(f.shape == (512, 512, 3) and f.dtype == np.uint8 for f in frames)
        assert all(np.ptp(f) > 0 for f in frames)  # the fake camera's pattern, not a blank buffer
        ids = np.array(cam.frame_ids)
        assert len(ids) == 90 and np.all((np.diff(ids) - 1) % 0xFFFF == 0)  # consecutive, past the wrap to 1
        assert cam.dropped_before_grab == 0
        stamps = np.array(cam.timestamps_ns)
        assert np.all(np.diff(stamps) > 0)
        print(
            f"\n90 frames, ids {ids[0]}..{ids[-1]}, {np.diff(stamps).mean() / 1e6:.1f} ms apart on the camera's clock"
        )
    finally:
        cam.close()


def test_lost_packets_not_resent_are_noticed_frame_by_frame():
    pytest.importorskip("gi")
    from binpick.cell.gige import GigEVisionCamera

    proc = _fake_camera("-r", "2")  # 0.2 % of the stream's packets lost: about one frame in three
    cam = None
    try:
        with pytest.raises(DeviceError, match="arrived incomplete|no whole frame|were lost"):
            cam = GigEVisionCamera("127.0.0.1", packet_resend=False, timeout_s=2.0)
            for _ in range(60):
                cam.grab()
    finally:
        if cam is not None:
            cam.close()
        _stop(proc)


def test_no_such_camera_and_no_aravis_say_what_to_do(camera_id, monkeypatch):
    from binpick.cell import gige

    with pytest.raises(DeviceError, match="cannot open the GigE Vision camera"):
        gige.GigEVisionCamera("127.0.0.9", timeout_s=1.0)  # nothing there
    monkeypatch.setitem(__import__("sys").modules, "gi", None)
    with pytest.raises(DeviceError, match="gir1.2-aravis-0.8"):
        gige.load_aravis()


def test_a_cell_file_opens_the_gige_camera(camera_id, tmp_path):
    from binpick.cell.cell_file import CELL_FILE_EXAMPLE, _camera, load_cell_file
    from binpick.parts import tee

    head, rest = CELL_FILE_EXAMPLE.split("\n[camera]", 1)
    table = f'\n[camera]\nsource = "gige"\ndevice = "{camera_id}"\nexposure_us = 1500.0\n\n'
    text = head + table + "[part]" + rest.split("\n[part]", 1)[1]
    (tmp_path / "cell.toml").write_text(text)
    cam = _camera(load_cell_file(tmp_path / "cell.toml"), tee(), 1)()
    try:
        assert cam.exposure_us == pytest.approx(1500.0) and cam.grab().shape == (512, 512, 3)
    finally:
        cam.close()
