"""The Universal Robots pair: the controller emulator (`binpick emulate ur`, its own process on a
loopback address of its own) checked with the independent ur-rtde client library — its RTDE
receive interface at 500 Hz and its Dashboard client — and binpick's URRobot driven against it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from binpick.devices.safety import CellLimits
from binpick.devices.ur import URConfig, URRobot
from binpick.errors import DeviceFault, SafetyError
from binpick.transforms import look_down, pose_error

#: A loopback address of this file's own: ur-rtde's RTDE interface always dials port 30004.
HOST = "127.0.0.41"
LIMITS = CellLimits(
    workspace_min_mm=(100.0, -350.0, 60.0), workspace_max_mm=(1200.0, 350.0, 700.0), approach_height_mm=315.0
)


@pytest.fixture(scope="module")
def controller():
    proc = subprocess.Popen(
        [sys.executable, "-m", "binpick", "emulate", "ur", "--host", HOST, "--speed-scale", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    try:
        first = proc.stdout.readline().split()
        assert first[:2] == [HOST, "rtde"], first
        yield dict(zip(first[1::2], map(int, first[2::2])))
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(timeout=10) == 0


def test_ur_rtde_reads_the_state_at_500_hz_for_10_s_without_a_gap_over_10_ms(controller, tmp_path):
    rtde_receive = pytest.importorskip("rtde_receive")
    r = rtde_receive.RTDEReceiveInterface(HOST)  # frequency -1: 500 Hz for an e-Series controller
    try:
        assert r.isConnected()
        # ur-rtde's recorder writes the state as its receive thread takes it in: the emulator's clock as received.
        r.startFileRecording(str(tmp_path / "rtde.csv"), ["timestamp", "actual_q"])
        polled = []
        t0 = time.monotonic()
        while time.monotonic() - t0 < 10.0:  # and the state read as a 500 Hz control loop reads it
            start = r.initPeriod()
            polled.append(r.getTimestamp())
            r.waitPeriod(start)
        r.stopFileRecording()
        pose = r.getActualTCPPose()
        assert len(pose) == 6 and len(r.getActualQ()) == 6
    finally:
        r.disconnect()
    rows = np.loadtxt(tmp_path / "rtde.csv", delimiter=",", skiprows=1, ndmin=2)
    stamps = rows[:, 0]
    gaps = np.diff(stamps)
    print(
        f"\n{len(stamps)} states recorded over {stamps[-1] - stamps[0]:.2f} s, "
        f"largest gap {gaps.max() * 1e3:.1f} ms; {len(polled)} reads by the 500 Hz loop"
    )
    assert stamps[-1] - stamps[0] > 9.9 and len(np.unique(stamps)) >= 0.95 * (stamps[-1] - stamps[0]) / 0.002
    assert gaps.max() <= 0.010 + 1e-9 and gaps.min() >= 0  # the recorder may write a state twice
    assert np.allclose(np.round(stamps / 0.002) * 0.002, stamps)  # whole 2 ms control cycles
    assert len(polled) > 4000


def test_ur_rtde_dashboard_client_gets_the_answers_of_a_real_controller(controller):
    dashboard_client = pytest.importorskip("dashboard_client")
    d = dashboard_client.DashboardClient(HOST, controller["dashboard"])
    d.connect()
    try:
        assert d.isConnected()
        d.powerOff()
        assert d.robotmode() == "Robotmode: POWER_OFF"
        d.powerOn()
        d.brakeRelease()
        assert d.robotmode() == "Robotmode: RUNNING"
        assert d.safetystatus() == "Safetystatus: NORMAL"
        d.play()
        d.stop()
        assert d.programState().startswith("STOPPED")
        assert d.getRobotModel() == "UR5" and d.isInRemoteControl() and not d.running()
        assert d.polyscopeVersion().startswith("5.11")
        with pytest.raises(RuntimeError):
            d.pause()  # no program runs: the controller refuses, and ur-rtde raises
    finally:
        d.disconnect()


@pytest.fixture()
def arm(controller):
    robot = URRobot(HOST, limits=LIMITS, config=URConfig(rtde_port=controller["rtde"]))
    robot.open_session()
    yield robot
    robot.close()


def test_the_driver_moves_jointly_and_straight_and_arrives(arm):
    for T, linear in (
        (look_down(400.0, 0.0, 620.0), False),
        (look_down(420.0, 60.0, 560.0), False),
        (look_down(420.0, 60.0, 250.0), True),
        (look_down(420.0, 60.0, 560.0), True),
    ):
        arm.move_to(T, linear=linear)
        deg, mm = pose_error(T, arm.read_pose())
        assert mm < 0.5 and deg < 0.1


def test_an_unsafe_move_is_refused_before_anything_is_sent(arm):
    arm.move_to(look_down(400.0, 0.0, 620.0))
    before = arm.read_pose()
    with pytest.raises(SafetyError, match="joint move"):
        arm.move_to(look_down(400.0, 0.0, 200.0))  # a joint move down into the bin
    with pytest.raises(SafetyError, match="workspace"):
        arm.move_to(look_down(400.0, 500.0, 620.0))
    time.sleep(0.1)
    assert pose_error(before, arm.read_pose())[1] < 1e-6


def test_a_program_the_controller_stops_short_is_a_fault(arm):
    arm.move_to(look_down(400.0, 0.0, 620.0))
    with pytest.raises(DeviceFault, match="stopped the program"):
        arm.move_to(look_down(1150.0, 0.0, 620.0))  # inside the cell's limits, beyond the arm's reach
    slow = URRobot(HOST, limits=LIMITS, config=URConfig(joint_speed_rad_s=0.1))  # about 0.8 s for this move
    try:
        stopper = threading.Timer(0.2, slow.stop)
        stopper.start()
        with pytest.raises(DeviceFault, match="stopped the program"):
            slow.move_to(look_down(400.0, -300.0, 620.0))  # stopped from the dashboard on the way
        stopper.join()
    finally:
        slow.close()
