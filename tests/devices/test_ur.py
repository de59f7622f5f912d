"""The Universal Robots pair: the controller emulator (`binpick emulate ur`, its own process on a
loopback address of its own) checked with the independent ur-rtde client library — its RTDE
receive interface at 500 Hz and its Dashboard client — and binpick's URRobot driven against it."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import struct
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
    # A controller runs its RTDE server at a real-time priority; the emulator gets one where it can
    # (root and chrt), so that the tests running beside it on two cores do not starve its 2 ms cycle.
    realtime = ["chrt", "-f", "50"] if os.geteuid() == 0 and shutil.which("chrt") else []
    proc = subprocess.Popen(
        [*realtime, sys.executable, "-m", "binpick", "emulate", "ur", "--host", HOST, "--speed-scale", "10"],
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


def test_ur_rtde_reads_the_state_at_500_hz_for_10_s(controller):
    rtde_receive = pytest.importorskip("rtde_receive")
    # frequency -1: 500 Hz for an e-Series controller; the default recipe, every variable ur-rtde reads
    r = rtde_receive.RTDEReceiveInterface(HOST, rt_priority=80)
    try:
        polled = []
        t0 = time.monotonic()
        while time.monotonic() - t0 < 10.0:  # the state read as a 500 Hz control loop reads it
            start = r.initPeriod()
            polled.append(r.getTimestamp())
            r.waitPeriod(start)
        assert r.isConnected() and r.getRobotMode() in (3, 5, 7) and r.getSafetyMode() == 1
        assert len(r.getActualTCPPose()) == 6 and len(r.getActualQ()) == 6
    finally:
        r.disconnect()
    seen = np.unique(polled)
    gaps = np.diff(seen)
    # How many distinct states a 500 Hz loop sees depends on the machine's load (the emulator and
    # the client share two cores with the other tests); the emulator's own clock is checked below.
    print(
        f"\nur-rtde: {len(polled)} reads at 500 Hz, {len(seen)} distinct states, largest gap {gaps.max() * 1e3:.1f} ms"
    )
    assert seen[-1] - seen[0] > 9.9 and len(polled) > 4000 and len(seen) > 2500
    assert np.all(np.diff(polled) >= 0) and np.allclose(np.round(seen / 0.002) * 0.002, seen)


def _rtde_package(sock: socket.socket, buffer: bytearray) -> tuple[str, bytes]:
    """One RTDE package read off ``sock`` (size u16, type u8, payload), from the RTDE guide."""
    while len(buffer) < 3 or len(buffer) < struct.unpack_from(">H", buffer)[0]:
        chunk = sock.recv(65536)
        assert chunk, "the emulator closed RTDE"
        buffer += chunk
    size, kind = struct.unpack_from(">HB", buffer)
    payload = bytes(buffer[3:size])
    del buffer[:size]
    return chr(kind), payload


def test_the_emulators_clock_has_no_gap_in_every_package_of_10_s_at_500_hz(controller):
    """Every data package of a 500 Hz recipe, read by a client written here from the RTDE guide:
    consecutive timestamps exactly one 2 ms control cycle apart (a controller never skips one)."""
    sock = socket.create_connection((HOST, controller["rtde"]), timeout=5)
    buffer = bytearray()

    def ask(kind: str, payload: bytes = b"") -> bytes:
        sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)
        while True:
            got, body = _rtde_package(sock, buffer)
            if got == kind:
                return body

    try:
        assert ask("V", struct.pack(">H", 2)) == b"\x01"
        body = ask("O", struct.pack(">d", 500.0) + b"timestamp")
        assert body[1:] == b"DOUBLE"
        assert ask("S") == b"\x01"
        stamps = []
        while not stamps or stamps[-1] - stamps[0] < 10.0:
            kind, payload = _rtde_package(sock, buffer)
            if kind == "U":
                stamps.append(struct.unpack(">d", payload[1:9])[0])
    finally:
        sock.close()
    steps = np.round(np.diff(stamps) / 0.002).astype(int)
    print(
        f"\nemulator: {len(stamps)} packages over {stamps[-1] - stamps[0]:.3f} s, steps of {set(steps.tolist())} cycles"
    )
    assert np.all(steps == 1)


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


def test_a_controller_slow_to_start_a_program_is_waited_for(monkeypatch):
    """A controller under load may take longer than a package or two to start a program: a move
    is not taken for one that already ended (it was, under CI load: 'stopped the program 291 mm
    from the target' on a move that then ran), but waited for until it plays and ends."""
    from binpick.devices.emulators.ur import UREmulator

    start = UREmulator._run_script

    def slow(self, text):
        time.sleep(0.4)  # 200 packages at 500 Hz before the program plays
        start(self, text)

    monkeypatch.setattr(UREmulator, "_run_script", slow)
    emulator = UREmulator(host="127.0.0.42", rtde_port=0, dashboard_port=0, secondary_port=0, speed_scale=10.0).start()
    ports = {name: port for name, (_, port) in emulator.addresses.items()}
    config = URConfig(rtde_port=ports["rtde"], dashboard_port=ports["dashboard"], secondary_port=ports["secondary"])
    robot = URRobot("127.0.0.42", limits=LIMITS, config=config)
    try:
        robot.open_session()
        target = look_down(400.0, 100.0, 600.0)
        robot.move_to(target)
        deg, mm = pose_error(target, robot.read_pose())
        assert mm < 0.1 and deg < 0.01
    finally:
        robot.close()
        emulator.close()
