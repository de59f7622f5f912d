"""binpick serve's server on the digital twin (its own process: robot, motor and gripper on ptys,
the camera on a socket), spoken to over TCP on loopback by the client of
examples/robots/twin_program.py (written from docs/protocol.md): a scan and picks in ABB
quaternions, every waypoint inside the cell's limits, the order rules, one robot program at a
time, reconnects, timeouts, and a fuzz of 2,000+ malformed, truncated, oversized and out-of-order
messages after which the server still serves."""

from __future__ import annotations

import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from binpick.cell.cell_file import cell_from_file, config_from_file, load_cell_file, robot_from_file
from binpick.devices import safety
from binpick.server import Code, ProgramGripper, ProgramRobot, VisionServer, VisionService, convention

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "robots"))
from twin_program import VisionClient, pose_matrix, pose_numbers  # noqa: E402

from _twin import twin_process  # noqa: E402

BRAND = "abb"
N = 7  # numbers per ABB pose


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    with twin_process(tmp_path_factory.mktemp("twin"), "--count", "4") as out:
        yield out


@pytest.fixture(scope="module")
def served(twin):
    f = load_cell_file(twin / "cell.toml")
    config = config_from_file(f)
    arm = robot_from_file(f)  # the robot program's arm: at the scan pose, as a program puts it
    arm.open_session()
    arm.move_to(config.scan_poses[0])
    T_scan = arm.read_pose()
    robot = ProgramRobot(limits=None)
    cell = cell_from_file(f, robot=robot, gripper=ProgramGripper(True))
    robot.limits = cell.config.limits
    cell.motor.enable()
    service = VisionService(cell, convention(BRAND))
    server = VisionServer(service, port=0, idle_timeout_s=20.0).start()
    try:
        yield server, service, T_scan
    finally:
        server.close()
        cell.close()
        arm.close_session()
        arm.close()


def _client(server) -> VisionClient:
    return VisionClient(*server.address, BRAND, timeout_s=60.0, wait_s=5.0)


def _scan_line(T) -> str:
    return "SCAN " + ",".join(f"{x:.6f}" for x in pose_numbers(BRAND, T))


def _poses(reply) -> list:
    return [pose_matrix(BRAND, reply.numbers[5 + k * N : 5 + (k + 1) * N]) for k in range(4)]


def test_a_scan_and_the_picks_it_offers_in_abb_quaternions_stay_inside_the_limits(served):
    server, service, T_scan = served
    c = _client(server)
    try:
        assert c.call("HELLO 1").numbers == [1, 2, N]
        scan = c.call(_scan_line(T_scan))
        assert scan.code == 0 and scan.numbers[1] > 5000, scan
        limits = service.cell.config.limits
        offered = []
        for k in range(2):  # the program passes each over: another part of the same scan comes next
            pick = c.call("NEXT")
            assert pick.code == 0 and len(pick.numbers) == 5 + 4 * N, pick
            pick_id, part, confidence, decided, opening = pick.numbers[:5]
            assert pick_id == k + 1 and part == 1 and 0 <= confidence <= 1 and decided in (0, 1)
            assert 0 < opening <= service.cell.config.gripper.open_width_mm
            above, approach, grasp, lift = _poses(pick)
            for name, T in zip(("above", "approach", "grasp", "lift"), (above, approach, grasp, lift)):
                safety.check_pose(T, limits, name=name)  # raises on a pose outside the cell's limits
            _, _, plan = service.offer
            assert np.abs(grasp - plan.T_base_flange).max() < 1e-4
            assert c.call("NEXT").code == Code.OUT_OF_ORDER  # the offer awaits its RESULT
            offered.append(grasp[:3, 3])
            assert c.call(f"RESULT {pick_id:.0f} -1").numbers == [pick_id, 0, 0]
        assert np.linalg.norm(offered[0] - offered[1]) > 10.0
        status = c.call("STATUS")
        assert status.code == 0 and status.numbers[:3] == [1, service.scans, 0]
    finally:
        c.close()


def test_requests_out_of_turn_are_refused_and_change_nothing(served):
    server, service, T_scan = served
    c = _client(server)
    try:
        assert c.call("RESULT 99 1").code == Code.OUT_OF_ORDER
        assert c.call("HELLO 2").code == Code.VERSION
        far = T_scan.copy()
        far[0, 3] += 15000.0
        assert c.call(_scan_line(far)).code == Code.BAD_VALUE  # beyond any arm's reach
        outside = T_scan.copy()
        outside[2, 3] += 400.0
        refused = c.call(_scan_line(outside))
        assert refused.code == Code.UNSAFE and "workspace" in refused.text
        before = (service.scans, service.picks, service.state)
        assert c.call("SCAN 1,2,3").code == Code.FIELD_COUNT
        assert (service.scans, service.picks, service.state) == before
    finally:
        c.close()


def test_one_robot_program_at_a_time_and_it_may_reconnect(served):
    server, service, _ = served
    first = _client(server)
    try:
        assert first.call("STATUS").code == 0
        second = socket.create_connection(server.address, timeout=10)
        busy = second.makefile("rb").readline()
        assert busy.startswith(b"(21) busy") and second.recv(10) == b""
        second.close()
        assert first.call("BYE").code == 0 and first.file.readline() == b""  # closed after BYE
    finally:
        first.close()
    again = _client(server)  # a restarted program reconnects: the state is kept
    try:
        status = again.call("STATUS")
        assert status.code == 0 and status.numbers[1] == service.scans
    finally:
        again.close()


def test_a_silent_program_is_disconnected_and_a_line_without_end_is_refused(served):
    _, service, _ = served
    quick = VisionServer(service, port=0, idle_timeout_s=0.3).start()
    try:
        s = socket.create_connection(quick.address, timeout=10)
        time.sleep(0.8)
        assert s.recv(10) == b""  # closed for silence
        s.close()
        s = socket.create_connection(quick.address, timeout=10)
        s.sendall(b"HELLO " + b"1" * 700)
        reply = s.makefile("rb").readline()
        assert reply.startswith(b"(6) ") and s.recv(10) == b""
        s.close()
    finally:
        quick.close()


def _fuzz_lines(rng: np.random.Generator, T_scan: np.ndarray) -> list[bytes]:
    verbs = [b"HELLO", b"SCAN", b"NEXT", b"RESULT", b"STATUS", b"hello", b"SCAN,", b"RESULTS", b"NEX", b"P", b""]
    far = T_scan.copy()
    far[0, 3] = 2000.0  # a well-formed SCAN outside the workspace: refused before any sweep
    lines = []
    for i in range(2200):
        kind = i % 8
        if kind == 0:
            line = bytes(rng.integers(0, 256, int(rng.integers(1, 80))).astype(np.uint8))
        elif kind == 1:
            numbers = rng.choice(["1", "-1", "nan", "inf", "1e999", "x", "0x10", "--1", "1,,2", "[", "p[", ")"], 8)
            line = verbs[int(rng.integers(len(verbs)))] + b" " + " ".join(numbers[: int(rng.integers(0, 9))]).encode()
        elif kind == 2:
            line = b"RESULT %d %d" % (int(rng.integers(-3, 50)), int(rng.integers(-3, 4)))
        elif kind == 3:
            line = _scan_line(far).encode()[: int(rng.integers(1, 80))]  # truncated
        elif kind == 4:
            line = _scan_line(far).encode()
        elif kind == 5:
            line = b"NEXT"
        elif kind == 6:
            line = bytes(rng.choice(list(b"SCANEXTRSULHO0123456789.,-+e []()p\t"), int(rng.integers(1, 120))))
        else:
            line = b"STATUS" if i % 3 else b"HELLO 1"
        lines.append(line.replace(b"\n", b" ").replace(b"\r", b" "))
    return lines


def test_a_fuzz_of_malformed_and_out_of_order_messages_gets_replies_and_the_server_keeps_serving(served):
    server, service, T_scan = served
    rng = np.random.default_rng(40)
    limits = service.cell.config.limits
    scans = service.scans
    c = _client(server)
    answered = closed = 0
    try:
        for line in _fuzz_lines(rng, T_scan):
            c.sock.sendall(line + b"\n")
            if not line.strip():
                continue  # an empty line gets no reply
            r = c.read()
            answered += 1
            assert r.code in set(Code), (line, r)
            if r.code == 0 and len(r.numbers) == 5 + 4 * N:  # a real offer: inside the limits
                for T in _poses(r):
                    safety.check_pose(T, limits)
        for size in (600, 5000):  # oversized: a reply, then the connection closes
            c.sock.sendall(b"S" * size)
            assert c.read().code == Code.TOO_LONG and c.file.readline() == b""
            closed += 1
            c.close()
            c = _client(server)
        assert c.call("STATUS").code == 0
    finally:
        c.close()
    print(f"\nfuzz: {answered} replies, {closed} connections closed for a line too long, server still serving")
    assert answered + closed >= 2000
    assert service.scans == scans  # no malformed SCAN started a sweep
