"""A Universal Robots arm behind :class:`~binpick.devices.robot.Robot`: state over RTDE (port
30004), power and program control over the Dashboard server (29999), motion as URScript over the
secondary interface (30002).

* :meth:`URRobot.read_pose` is the flange pose: every program the driver sends sets the TCP to
  the flange (``set_tcp(p[0,0,0,0,0,0])``), so RTDE's ``actual_TCP_pose`` is the flange's.
* :meth:`URRobot.move_to` checks the move against the cell's limits with the same rules as the
  MELFA driver (:mod:`binpick.devices.safety`; SafetyError, nothing sent), then sends a program
  of one ``movej``/``movel`` and waits until the controller has run it and the arm stands at the
  target; a program the controller stopped short (a protective stop, an unreachable target, a
  stop from the pendant) raises DeviceFault, a controller silent past the timeout DeviceTimeout.

Poses on the wire are UR's: metres and a rotation vector (:mod:`binpick.server.conventions`'s
``ur``).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from .._validate import as_transform, flag
from ..errors import DeviceError, DeviceFault, DeviceTimeout, ProtocolError
from ..transforms import pose_error
from . import rtde
from .robot import Robot
from .safety import CellLimits, check_linear_speed, check_move, check_pose

__all__ = ["URConfig", "URRobot", "STATE_VARIABLES"]

#: What the driver reads over RTDE.
STATE_VARIABLES = ("timestamp", "actual_TCP_pose", "actual_q", "robot_mode", "safety_mode", "runtime_state")
ROBOT_MODE_RUNNING, ROBOT_MODE_IDLE = 7, 5
RUNTIME_PLAYING = 2
SAFETY_NORMAL, SAFETY_REDUCED = 1, 2


#: How long (controller time, s) a program without motion may go unseen before it counts as run.
_START_GRACE_S = 2.0


@dataclass(frozen=True)
class URConfig:
    """Settings of a :class:`URRobot`.

    Attributes:
        rtde_port, dashboard_port, secondary_port: the controller's ports.
        frequency_hz: RTDE state rate (125 Hz is every controller's; e-Series reach 500).
        joint_speed_rad_s, joint_acceleration_rad_s2: of a joint move (``movej``).
        linear_speed_mm_s, linear_acceleration_mm_s2: of a straight move (``movel``); the speed
            is checked against the cell's ``max_linear_speed_mm_s``.
        timeout_s: connecting, and each answer of the controller.
        motion_timeout_s: longest move.
        arrive_mm, arrive_deg: how near the target the arm must stand after a move.
    """

    rtde_port: int = 30004
    dashboard_port: int = 29999
    secondary_port: int = 30002
    frequency_hz: float = 125.0
    joint_speed_rad_s: float = 1.0
    joint_acceleration_rad_s2: float = 1.4
    linear_speed_mm_s: float = 250.0
    linear_acceleration_mm_s2: float = 1200.0
    timeout_s: float = 5.0
    motion_timeout_s: float = 60.0
    arrive_mm: float = 0.5
    arrive_deg: float = 0.1


def _ur_pose(T: np.ndarray) -> str:
    return "p[" + ", ".join(f"{x:.7f}" for x in rtde.ur_pose(T)) + "]"


class URRobot(Robot):
    """A UR controller at ``host`` (see the module docstring); ``limits`` are checked before
    anything is sent. Connects at once (DeviceError naming the port that refused)."""

    def __init__(self, host: str, *, limits: Optional[CellLimits], config: URConfig = URConfig()) -> None:
        self.host = host
        self.limits = limits
        self.config = config
        self._state: dict[str, Any] = {}
        self._fresh = threading.Condition()
        self._closed = threading.Event()
        self._rtde = self._connect(config.rtde_port, "RTDE")
        try:
            self._types = self._start_rtde()
            self._reader = threading.Thread(target=self._read_rtde, name="ur-rtde", daemon=True)
            self._reader.start()
            self._dashboard = self._connect(config.dashboard_port, "dashboard")
            self._dashboard_lines = self._dashboard.makefile("rb")
            self._dashboard_lines.readline(4096)  # the welcome line
            self._secondary = self._connect(config.secondary_port, "secondary interface")
        except BaseException:
            self.close()
            raise
        self._wait_state(lambda s: True, "the first RTDE state package")

    # -- connections
    def _connect(self, port: int, what: str) -> socket.socket:
        try:
            s = socket.create_connection((self.host, port), timeout=self.config.timeout_s)
        except OSError as exc:
            raise DeviceError(f"cannot connect to the UR controller's {what} at {self.host}:{port} ({exc})") from None
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return s

    def _rtde_request(self, kind: str, payload: bytes = b"") -> bytes:
        self._rtde.sendall(rtde.encode(kind, payload))
        pending = b""
        while True:
            package, pending = rtde.split_package(pending)
            if package is not None:
                got, body = package
                if got == kind:
                    return body
                continue  # a text message or a data package before the answer
            try:
                chunk = self._rtde.recv(65536)
            except (socket.timeout, TimeoutError):
                raise DeviceTimeout(
                    f"the UR controller did not answer RTDE {kind!r} in {self.config.timeout_s:g} s"
                ) from None
            if not chunk:
                raise ProtocolError(f"the UR controller closed RTDE while answering {kind!r}")
            pending += chunk

    def _start_rtde(self) -> list[str]:
        if self._rtde_request("V", struct.pack(">H", rtde.PROTOCOL_VERSION))[:1] != b"\x01":
            raise ProtocolError(f"the UR controller does not speak RTDE protocol {rtde.PROTOCOL_VERSION}")
        body = self._rtde_request("O", struct.pack(">d", self.config.frequency_hz) + ",".join(STATE_VARIABLES).encode())
        types = body[1:].decode("latin-1").split(",")
        if body[:1] == b"\x00" or len(types) != len(STATE_VARIABLES) or "NOT_FOUND" in types:
            raise ProtocolError(f"the UR controller refused the RTDE recipe {STATE_VARIABLES}: {types}")
        self._recipe = body[0]
        if self._rtde_request("S")[:1] != b"\x01":
            raise ProtocolError("the UR controller refused to start RTDE")
        return types

    def _read_rtde(self) -> None:
        pending = b""
        self._rtde.settimeout(0.5)
        while not self._closed.is_set():
            try:
                chunk = self._rtde.recv(65536)
            except (socket.timeout, TimeoutError):
                continue
            except OSError:
                break
            if not chunk:
                break
            pending += chunk
            try:
                while True:
                    package, pending = rtde.split_package(pending)
                    if package is None:
                        break
                    if package[0] == "U" and package[1][:1] == bytes([self._recipe]):
                        _, values = rtde.unpack_data(package[1], self._types)
                        with self._fresh:
                            self._state = dict(zip(STATE_VARIABLES, values), received=time.monotonic())
                            self._fresh.notify_all()
            except ProtocolError:
                break
        with self._fresh:
            self._state = dict(self._state, lost=True)
            self._fresh.notify_all()

    def _wait_state(self, ready: Any, what: str, timeout_s: Optional[float] = None) -> dict[str, Any]:
        """The latest state once ``ready(state)``; DeviceTimeout naming ``what`` after ``timeout_s``."""
        limit = self.config.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + limit
        with self._fresh:
            while True:
                if self._state.get("lost"):
                    raise DeviceError("the UR controller's RTDE connection was lost")
                if self._state and ready(self._state):
                    return dict(self._state)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise DeviceTimeout(f"the UR controller: no {what} within {limit:g} s")
                self._fresh.wait(left)

    def dashboard(self, command: str) -> str:
        """Sends one Dashboard server command; returns its answer line."""
        self._dashboard.sendall(command.encode("latin-1") + b"\n")
        try:
            line = self._dashboard_lines.readline(4096)
        except (socket.timeout, TimeoutError):
            raise DeviceTimeout(f"the UR dashboard server did not answer {command!r}") from None
        if not line:
            raise DeviceError(f"the UR dashboard server closed the connection after {command!r}")
        return line.decode("latin-1").strip()

    def _send_program(self, *statements: str) -> float:
        """Sends a program; returns the RTDE timestamp before it was sent."""
        before = self._wait_state(lambda s: True, "state")["timestamp"]
        body = "".join(f"  {s}\n" for s in ("set_tcp(p[0, 0, 0, 0, 0, 0])", *statements))
        self._secondary.sendall(f"def binpick_move():\n{body}end\n".encode("latin-1"))
        return before

    # -- Robot
    def open_session(self) -> None:
        """Powers the arm on, releases its brakes and sets the TCP to the flange."""
        if self._wait_state(lambda s: True, "state")["robot_mode"] != ROBOT_MODE_RUNNING:
            self.dashboard("power on")
            self._wait_state(lambda s: s["robot_mode"] >= ROBOT_MODE_IDLE, "power on (robot mode IDLE)", 30.0)
            answer = self.dashboard("brake release")
            if not answer.startswith("Brake releasing"):
                raise DeviceFault(f"the UR controller refused 'brake release': {answer}")
            self._wait_state(
                lambda s: s["robot_mode"] == ROBOT_MODE_RUNNING, "brake release (robot mode RUNNING)", 30.0
            )
        self._run_and_wait()

    def read_pose(self) -> np.ndarray:
        return rtde.transform_from_ur_pose(self._wait_state(lambda s: True, "state")["actual_TCP_pose"])

    def move_to(self, T_base_flange: Any, *, linear: bool = False) -> None:
        """Moves the flange to ``T_base_flange`` (``movel`` when ``linear``, else ``movej``),
        checked first against the cell's limits (SafetyError, nothing sent); returns on arrival."""
        linear = flag(linear, "linear")
        target = as_transform(T_base_flange, "T_base_flange")
        if self.limits is not None:
            target = check_pose(target, self.limits)
            check_move(self.read_pose(), target, linear=linear, limits=self.limits)
            speed = check_linear_speed(self.config.linear_speed_mm_s, self.limits)
        else:
            speed = self.config.linear_speed_mm_s
        state = self._wait_state(lambda s: True, "state")
        if state["robot_mode"] != ROBOT_MODE_RUNNING or state["safety_mode"] not in (SAFETY_NORMAL, SAFETY_REDUCED):
            raise DeviceFault(
                f"the UR arm is not ready to move (robot mode {state['robot_mode']}, safety mode "
                f"{state['safety_mode']}); nothing was sent — open_session() powers it on and releases the brakes"
            )
        c = self.config
        move = (
            f"movel({_ur_pose(target)}, a={c.linear_acceleration_mm_s2 / 1000:.4f}, v={speed / 1000:.4f})"
            if linear
            else f"movej({_ur_pose(target)}, a={c.joint_acceleration_rad_s2:.4f}, v={c.joint_speed_rad_s:.4f})"
        )
        self._run_and_wait(move, target=target)
        deg, mm = pose_error(target, self.read_pose())
        if mm > c.arrive_mm or deg > c.arrive_deg:
            raise DeviceFault(
                f"the UR controller stopped the program {mm:.1f} mm and {deg:.2f}° from the target "
                "(a protective stop, an unreachable target or a stop from the pendant; see PolyScope's log)"
            )

    def _run_and_wait(self, *statements: str, target: Optional[np.ndarray] = None) -> None:
        """Sends a program and returns once it ran. It runs (PLAYING), then ends (not PLAYING).
        A program without motion may end between two packages: its end is also seen as a package
        _START_GRACE_S later with nothing playing. One that moves the arm to ``target`` has run
        when it was seen playing and then not, or when the arm stands at ``target`` with nothing
        playing (it ran between packages the controller sent late, under load); a controller slow
        to start it is waited for, not taken for one that already ran."""
        sent = self._send_program(*statements)
        c = self.config

        def ran(s: dict[str, Any]) -> bool:
            if s["runtime_state"] == RUNTIME_PLAYING:
                return True
            if target is None:
                return s["timestamp"] > sent + _START_GRACE_S
            deg, mm = pose_error(target, rtde.transform_from_ur_pose(s["actual_TCP_pose"]))
            return mm <= c.arrive_mm and deg <= c.arrive_deg

        started = self._wait_state(ran, "program start")
        if started["runtime_state"] == RUNTIME_PLAYING:
            self._wait_state(lambda s: s["runtime_state"] != RUNTIME_PLAYING, "program end", c.motion_timeout_s)

    def stop(self) -> None:
        """Stops the running program (the Dashboard's ``stop``)."""
        answer = self.dashboard("stop")
        if not answer.startswith("Stopped"):
            raise DeviceFault(f"the UR controller answered 'stop' with {answer!r}")

    def close(self) -> None:
        self._closed.set()
        for name in ("_rtde", "_dashboard", "_secondary"):
            s = getattr(self, name, None)
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
