"""A robot program for the digital twin, in Python: it plays the part of the program a UR, ABB,
KUKA, FANUC or MELFA controller runs against `binpick serve`, and moves the twin's arm and
gripper through their serial ports as that controller would.

The protocol side (:class:`VisionClient`, :func:`pose_matrix`, :func:`pose_numbers`) is written
from docs/protocol.md alone: plain sockets and numpy, no binpick. The motion side uses binpick's
MELFA and gripper drivers, because the twin's arm speaks R3.

    python examples/robots/twin_program.py twin/cell.toml --port 50100 --brand ur --picks 5
"""

from __future__ import annotations

import argparse
import math
import re
import socket
import sys
import time
from dataclasses import dataclass

import numpy as np

#: Numbers per pose and the reply sizes of docs/protocol.md.
POSE_SIZE = {"ur": 6, "abb": 7, "kuka": 6, "fanuc": 6, "yaskawa": 6, "melfa": 6}
REPLY_SIZE = {"HELLO": 4, "SCAN": 4, "RESULT": 4, "STATUS": 6, "BYE": 1}


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def pose_matrix(brand: str, v: list) -> np.ndarray:
    """The flange pose (4×4, mm) of a brand's numbers, from the doc's table."""
    T = np.eye(4)
    if brand == "ur":
        T[:3, 3] = np.array(v[:3]) * 1000.0
        w = np.array(v[3:6], dtype=float)
        angle = float(np.linalg.norm(w))
        if angle > 0:
            k = w / angle
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            T[:3, :3] = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)
        return T
    T[:3, 3] = v[:3]
    if brand == "abb":
        w, x, y, z = np.array(v[3:7]) / np.linalg.norm(v[3:7])
        T[:3, :3] = [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
        return T
    a, b, c = (math.radians(x) for x in v[3:6])
    T[:3, :3] = _rz(a) @ _ry(b) @ _rx(c) if brand == "kuka" else _rz(c) @ _ry(b) @ _rx(a)
    return T


def pose_numbers(brand: str, T: np.ndarray) -> list:
    """A brand's numbers for a flange pose (4×4, mm): the inverse of :func:`pose_matrix`."""
    R = T[:3, :3]
    if brand == "ur":
        angle = math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2)))
        if angle < 1e-9:
            w = np.zeros(3)
        elif angle > math.pi - 1e-6:  # half-turn: the axis from R + I
            k = np.sqrt(np.maximum(np.diag(R) + 1, 0) / 2)
            i = int(np.argmax(k))
            k = (R[:, i] + np.eye(3)[:, i]) / (2 * k[i])
            w = k / np.linalg.norm(k) * angle
        else:
            w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) * angle / (2 * math.sin(angle))
        return [*(T[:3, 3] / 1000.0), *w]
    if brand == "abb":
        w = math.sqrt(max(0.0, 1 + np.trace(R))) / 2
        if w > 1e-3:
            q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
        else:  # near a half-turn: from the rotation's axis
            ur = pose_numbers("ur", T)[3:]
            angle = float(np.linalg.norm(ur))
            q = [math.cos(angle / 2), *(np.array(ur) / angle * math.sin(angle / 2))]
        return [*T[:3, 3], *q]
    # Rz(first)·Ry(second)·Rx(third) for kuka, Rz(third)·Ry(second)·Rx(first) for the others
    yaw, pitch, roll = math.atan2(R[1, 0], R[0, 0]), math.asin(-R[2, 0]), math.atan2(R[2, 1], R[2, 2])
    angles = [yaw, pitch, roll] if brand == "kuka" else [roll, pitch, yaw]
    return [*T[:3, 3], *(math.degrees(a) for a in angles)]


@dataclass
class Reply:
    code: int
    numbers: list
    text: str


class VisionClient:
    """The client side of docs/protocol.md: one request line out, one reply line in."""

    def __init__(self, host: str, port: int, brand: str, timeout_s: float = 120.0, wait_s: float = 60.0) -> None:
        self.brand = brand
        deadline = time.monotonic() + wait_s
        while True:  # as a controller does: retry until the server is up
            try:
                self.sock = socket.create_connection((host, port), timeout=timeout_s)
                break
            except ConnectionRefusedError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        self.file = self.sock.makefile("rb")

    def call(self, line: str) -> Reply:
        self.sock.sendall(line.encode("ascii") + b"\n")
        return self.read()

    def read(self) -> Reply:
        raw = self.file.readline(4096).decode("ascii")
        m = re.fullmatch(r"\(([^()]*)\)(?: (.*))?\r\n", raw)
        if m is None:
            raise RuntimeError(f"not a reply line: {raw!r}")
        numbers = [float(x) for x in m.group(1).split(",")]
        return Reply(int(numbers[0]), numbers[1:], m.group(2) or "")

    def close(self) -> None:
        self.file.close()
        self.sock.close()


def run(cell_toml: str, host: str, port: int, brand: str, picks: int, out=print) -> dict:
    """Picks until the bin is empty (or ``picks`` picks): scan at the cell file's scan pose, NEXT,
    the four waypoints, the gripper, the cell file's drop pose, RESULT. Returns the counts."""
    from binpick.cell import load_cell_file  # the motion side: the twin's arm speaks R3
    from binpick.cell.cell_file import config_from_file, gripper_from_file, robot_from_file

    f = load_cell_file(cell_toml)
    config = config_from_file(f)
    arm = robot_from_file(f)
    hand = gripper_from_file(f, arm)
    vision = VisionClient(host, port, brand)
    n = POSE_SIZE[brand]
    counts = {"held": 0, "empty": 0, "refused": 0}
    try:
        arm.open_session()
        hand.activate()
        hand.open()
        hello = vision.call("HELLO 1")
        assert hello.code == 0 and hello.numbers[2] == n, hello
        for _ in range(picks):
            arm.move_to(config.scan_poses[0])
            here = pose_numbers(brand, arm.read_pose())
            scan = vision.call("SCAN " + ",".join(f"{x:.6f}" for x in here))
            if scan.code != 0:
                out(f"SCAN: code {scan.code} {scan.text}")
                break
            pick = vision.call("NEXT")
            if pick.code != 0:
                out(f"NEXT: code {pick.code} {pick.text}")
                counts["refused"] += pick.code == 11
                break
            pick_id, _, confidence, decided, opening = pick.numbers[:5]
            poses = [pick.numbers[5 + k * n : 5 + (k + 1) * n] for k in range(4)]
            above, approach, grasp, lift = (pose_matrix(brand, v) for v in poses)
            out(f"pick {pick_id:.0f}: confidence {confidence:.2f}, decided {decided:.0f}, opening {opening:.1f} mm")
            hand.open_for_grasp(opening)
            arm.move_to(above)
            arm.move_to(approach, linear=True)
            arm.move_to(grasp, linear=True)
            held = hand.close()
            arm.move_to(lift, linear=True)
            if held:
                arm.move_to(config.drop_pose)
            hand.open()
            result = vision.call(f"RESULT {pick_id:.0f} {1 if held else 0}")
            assert result.code == 0, result
            counts["held" if held else "empty"] += 1
        vision.call("BYE")
    finally:
        vision.close()
        arm.close_session()
        arm.close()
        hand.close_port()
    return counts


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("cell", help="the twin's cell file (its robot and gripper ports, scan and drop poses)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=50100)
    p.add_argument("--brand", default="ur", choices=sorted(POSE_SIZE))
    p.add_argument("--picks", type=int, default=5)
    a = p.parse_args()
    counts = run(a.cell, a.host, a.port, a.brand, a.picks)
    print(f"held {counts['held']}, empty grips {counts['empty']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
