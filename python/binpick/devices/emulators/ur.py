"""A Universal Robots controller with a UR5e-class arm, on TCP at 127.0.0.1: ``binpick emulate ur``.

It speaks the three interfaces binpick's UR driver uses, as the controller does:

* **RTDE** (port 30004, :mod:`binpick.devices.rtde`): protocol version 2, the controller version
  (5.11), output recipes of the controller's variables at up to 500 Hz (a package every 2 ms
  control cycle; ``timestamp`` is the controller's clock, one cycle = 2 ms, and a sender that
  falls behind sends every cycle it missed), input recipes, start and pause, text messages.
* **Dashboard server** (port 29999): one line per command, one line per answer, as PolyScope 5
  answers them (``power on``, ``brake release``, ``play``, ``stop``, ``pause``, ``robotmode``,
  ``safetymode``, ``safetystatus``, ``programState``, ``PolyscopeVersion``, ``get robot model``,
  ``get serial number``, ``is in remote control``, ``running``, ``load``, ``unlock protective
  stop``, ``close popup``, ``close safety popup``, ``quit``, …).
* **Secondary client interface** (port 30002): URScript received as text — a ``def … end``
  program or single statements — compiled against the subset the driver sends (``set_tcp``,
  ``movej``, ``movel`` with ``p[…]`` poses or joint lists, ``stopj``, ``stopl``, ``sleep``,
  ``set_standard_digital_out``, ``textmsg``); a program with anything else does not start (a
  compile error, as on the controller). A new program replaces the running one. The robot state
  the real controller streams on this port is not emulated (the driver reads RTDE).

The arm moves only when powered on with its brakes released; it takes time to move (joint moves
at ``v`` rad/s, straight moves at ``v`` m/s, reaching them at the acceleration ``a``, played
``speed_scale`` times faster; the time spent on its ``clock`` when one is set); a target its inverse
kinematics cannot reach stops the program with the arm where it was.
"""

from __future__ import annotations

import math
import re
import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from ...transforms import rotation_about, rotation_vector
from .. import rtde
from .clock import PhysicalClock, trapezoid_s

__all__ = ["URArm", "UREmulator", "CONTROLLER_VERSION", "ROBOT_MODES"]

#: The controller version reported over RTDE (major, minor, bugfix, build): e-Series, PolyScope 5.
CONTROLLER_VERSION = (5, 11, 1, 108318)
#: robot_mode values (RTDE and the dashboard's names).
ROBOT_MODES = {3: "POWER_OFF", 4: "POWER_ON", 5: "IDLE", 7: "RUNNING"}
RUNTIME_STOPPED, RUNTIME_PLAYING = 1, 2
#: The shortest a program plays, s: four 2 ms controller cycles.
_MIN_PROGRAM_S = 0.008
SAFETY_NORMAL = 1
#: The control cycle, s (500 Hz).
CYCLE_S = 0.002


@dataclass(frozen=True)
class URArm:
    """A UR arm's kinematics: the standard DH parameters (mm, rad) of the UR5e, its reach and
    joint limits (±360° each). ``forward`` gives the flange pose; ``inverse`` solves from a seed."""

    a_mm: tuple[float, ...] = (0.0, -425.0, -392.2, 0.0, 0.0, 0.0)
    d_mm: tuple[float, ...] = (162.5, 0.0, 0.0, 133.3, 99.7, 99.6)
    alpha: tuple[float, ...] = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
    #: Joint angles of the home: the arm reaching along base +x, elbow up, tool pointing down.
    home: tuple[float, ...] = (math.pi, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)

    def frames(self, q: np.ndarray) -> list[np.ndarray]:
        """The base frame and each joint's frame after it (7 transforms, mm)."""
        out = [np.eye(4)]
        for th, a, d, al in zip(q, self.a_mm, self.d_mm, self.alpha):
            ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
            out.append(
                out[-1]
                @ np.array(
                    [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1.0]]
                )
            )
        return out

    def forward(self, q: Any) -> np.ndarray:
        """T_base_flange of joint angles ``q`` (rad)."""
        return self.frames(np.asarray(q, dtype=np.float64))[-1]

    def inverse(self, T: np.ndarray, seed: Any = None, *, iterations: int = 60) -> np.ndarray:
        """Joint angles that put the flange at ``T`` (mm), found from ``seed`` by damped least
        squares (without a seed: from the home turned toward the target, elbow up); ValueError
        when none is found (out of reach)."""
        if seed is None:
            seed = np.array(self.home)
            seed[0] = math.atan2(T[1, 3], T[0, 3]) + math.pi
        q = np.array(seed, dtype=np.float64)
        for _ in range(iterations):
            frames = self.frames(q)
            F = frames[-1]
            dp = T[:3, 3] - F[:3, 3]
            dr = rotation_vector(T[:3, :3] @ F[:3, :3].T)
            if np.linalg.norm(dp) < 1e-6 and np.linalg.norm(dr) < 1e-9:
                return q
            J = np.zeros((6, 6))
            for i in range(6):
                z, p = frames[i][:3, 2], frames[i][:3, 3]
                J[:3, i] = np.cross(z, F[:3, 3] - p)
                J[3:, i] = z * 1000.0  # radians weighed as metres of the error's millimetres
            err = np.concatenate([dp, dr * 1000.0])
            step = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(6), err)
            q = q + np.clip(step, -0.5, 0.5)
        raise ValueError("the pose is out of the arm's reach")

    def reaches(self, T: np.ndarray) -> bool:
        """Whether ``inverse`` finds the pose from the home."""
        try:
            self.inverse(T)
        except ValueError:
            return False
        return True


class _Compile(Exception):
    """A URScript statement outside the emulated subset, or malformed."""


_NUMBERS = r"\[\s*([^\[\]]*)\]"
_STATEMENTS = (
    ("set_tcp", re.compile(r"set_tcp\(\s*p" + _NUMBERS + r"\s*\)")),
    ("move", re.compile(r"(movej|movel)\(\s*(p?)" + _NUMBERS + r"\s*((?:,\s*[avtr]\s*=\s*[-+0-9.eE]+\s*)*)\)")),
    ("stop", re.compile(r"(stopj|stopl)\(\s*([-+0-9.eE]+)\s*\)")),
    ("sleep", re.compile(r"sleep\(\s*([-+0-9.eE]+)\s*\)")),
    ("digital_out", re.compile(r"set_standard_digital_out\(\s*(\d+)\s*,\s*(True|False)\s*\)")),
    ("textmsg", re.compile(r'textmsg\(\s*"([^"]*)"\s*\)')),
)


def compile_script(text: str) -> list[list[tuple]]:
    """The programs in ``text``: each ``def … end`` block, or each line outside one, as a list
    of statements ``(kind, args…)``; _Compile for anything outside the subset."""
    programs: list[list[tuple]] = []
    body: Optional[list[tuple]] = None
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if re.fullmatch(r"(def|sec)\s+\w+\(\s*\)\s*:", line):
            if body is not None:
                raise _Compile("a def inside a def")
            body = []
            continue
        if line == "end":
            if body is None:
                raise _Compile("end without def")
            programs.append(body)
            body = None
            continue
        statement = _statement(line)
        if body is None:
            programs.append([statement])
        else:
            body.append(statement)
    if body is not None:
        raise _Compile("a def without its end")
    return programs


def _floats(text: str, n: int) -> list[float]:
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise _Compile(f"not numbers: {text[:40]}") from None
    if len(values) != n or not all(math.isfinite(x) for x in values):
        raise _Compile(f"expected {n} finite numbers")
    return values


def _statement(line: str) -> tuple:
    for kind, pattern in _STATEMENTS:
        m = pattern.fullmatch(line)
        if m is None:
            continue
        if kind == "set_tcp":
            return ("set_tcp", _floats(m.group(1), 6))
        if kind == "move":
            options = dict(re.findall(r"([avtr])\s*=\s*([-+0-9.eE]+)", m.group(4)))
            a, v = float(options.get("a", 1.2 if m.group(1) == "movel" else 1.4)), float(options.get("v", 0.25))
            if not (a > 0 and v > 0 and math.isfinite(a) and math.isfinite(v)):
                raise _Compile("a and v must be positive")
            return (m.group(1), bool(m.group(2)), _floats(m.group(3), 6), a, v)
        if kind == "stop":
            return ("stop",)
        if kind == "sleep":
            return ("sleep", max(0.0, float(m.group(1))))
        if kind == "digital_out":
            return ("digital_out", int(m.group(1)), m.group(2) == "True")
        return ("textmsg", m.group(1))
    raise _Compile(f"{line[:60]!r} is not in the emulated URScript subset")


class UREmulator:
    """The emulated controller (see the module docstring).

    Args:
        host: the address its three servers listen on.
        rtde_port, dashboard_port, secondary_port: their ports (0: any free one).
        arm: the arm's kinematics.
        start_pose: the flange's pose at start (default: the arm's home).
        speed_scale: multiplies every speed.
    """

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        rtde_port: int = 30004,
        dashboard_port: int = 29999,
        secondary_port: int = 30002,
        arm: URArm = URArm(),
        start_pose: Optional[np.ndarray] = None,
        speed_scale: float = 1.0,
    ) -> None:
        self.arm = arm
        self.speed_scale = float(speed_scale)
        self.lock = threading.RLock()
        self.q = np.array(arm.home if start_pose is None else arm.inverse(np.asarray(start_pose, dtype=float)))
        self.T_flange_tcp = np.eye(4)
        self.robot_mode = 3  # POWER_OFF
        self.digital_out = 0
        self.loaded = "<unnamed>"
        self.log: list[str] = []
        self.failures: list[str] = []
        self.on_motion: Optional[Callable[[np.ndarray, float], None]] = None
        #: the cell's hardware time (:class:`~binpick.devices.emulators.clock.PhysicalClock`), or None
        self.clock: Optional[PhysicalClock] = None
        self._motion: Optional[tuple[float, float, np.ndarray, np.ndarray]] = None  # t0, duration, times, qs
        self._program: Optional[threading.Thread] = None
        self._abort = threading.Event()
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        self._servers = {
            name: socket.create_server((host, port))
            for name, port in (("rtde", rtde_port), ("dashboard", dashboard_port), ("secondary", secondary_port))
        }
        self._threads: list[threading.Thread] = []

    # -- life cycle
    @property
    def addresses(self) -> dict[str, tuple[str, int]]:
        """name → (host, port) of the three servers."""
        return {name: s.getsockname()[:2] for name, s in self._servers.items()}

    def start(self) -> UREmulator:
        for name, server in self._servers.items():
            server.settimeout(0.2)
            handler = {"rtde": self._rtde, "dashboard": self._dashboard, "secondary": self._secondary}[name]
            t = threading.Thread(target=self._accept, args=(server, handler), name=f"ur-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def close(self) -> None:
        self._stop.set()
        self._abort.set()
        for t in self._threads:
            t.join(timeout=2.0)
        for s in self._servers.values():
            s.close()

    def __enter__(self) -> UREmulator:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _accept(self, server: socket.socket, handler: Callable[[socket.socket], None]) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = server.accept()
            except (socket.timeout, TimeoutError):
                continue
            except OSError:
                return
            t = threading.Thread(target=self._guarded, args=(handler, conn), daemon=True)
            t.start()

    def _guarded(self, handler: Callable[[socket.socket], None], conn: socket.socket) -> None:
        try:
            handler(conn)
        except OSError:
            pass
        except Exception as exc:  # keep serving; the failure is reported
            self.failures.append(f"{handler.__name__}: {type(exc).__name__}: {exc}")
        finally:
            conn.close()

    # -- the arm's state
    def clock(self) -> float:
        """The controller's clock, s, in whole control cycles."""
        return math.floor((time.monotonic() - self._t0) / CYCLE_S) * CYCLE_S

    def joints(self) -> np.ndarray:
        """Joint angles now (rad)."""
        with self.lock:
            if self._motion is None:
                return self.q.copy()
            t0, duration, times, qs = self._motion
            s = min(1.0, (time.monotonic() - t0) / duration) if duration > 0 else 1.0
            k = min(int(np.searchsorted(times, s)), len(times) - 1)
            if k == 0:
                return qs[0].copy()
            f = (s - times[k - 1]) / max(times[k] - times[k - 1], 1e-12)
            return qs[k - 1] + f * (qs[k] - qs[k - 1])

    def pose(self) -> np.ndarray:
        """T_base_flange now."""
        return self.arm.forward(self.joints())

    @property
    def alarm(self) -> int:
        """The active alarm's number: the emulated controller raises none (a stopped program is not one)."""
        return 0

    @property
    def runtime_state(self) -> int:
        running = self._program is not None and self._program.is_alive()
        return RUNTIME_PLAYING if running else RUNTIME_STOPPED

    # -- URScript
    def _secondary(self, conn: socket.socket) -> None:
        conn.settimeout(0.5)
        pending = b""
        while not self._stop.is_set():
            try:
                chunk = conn.recv(65536)
            except (socket.timeout, TimeoutError):
                chunk = None
            if chunk == b"":
                return
            if chunk:
                pending += chunk
            text, complete = self._complete_script(pending)
            if complete:
                pending = b""
                self._run_script(text)
            elif len(pending) > 1 << 20:
                self.log.append("secondary: script over 1 MB dropped")
                pending = b""

    @staticmethod
    def _complete_script(pending: bytes) -> tuple[str, bool]:
        """Whether ``pending`` holds whole programs: every line ended, every def closed."""
        if not pending.endswith(b"\n"):
            return "", False
        text = pending.decode("latin-1")
        opened = len(re.findall(r"^(def|sec)\s", text, re.M))
        closed = len(re.findall(r"^end\s*$", text, re.M))
        return text, opened == closed

    def _run_script(self, text: str) -> None:
        try:
            programs = compile_script(text)
        except _Compile as exc:
            self.log.append(f"compile error: {exc}")
            return
        for program in programs:
            self._abort.set()
            if self._program is not None:
                self._program.join(timeout=5.0)
            self._abort = threading.Event()
            self._program = threading.Thread(target=self._execute, args=(program, self._abort), daemon=True)
            self._program.start()

    def _execute(self, program: list[tuple], abort: threading.Event) -> None:
        # A controller's program lives a few of its cycles at least (a real one takes tens of
        # milliseconds to start one): a client sees it PLAYING before it ends, even when its
        # first move is refused at once.
        abort.wait(_MIN_PROGRAM_S)
        for statement in program:
            if abort.is_set():
                break
            kind = statement[0]
            if kind == "set_tcp":
                with self.lock:
                    self.T_flange_tcp = rtde.transform_from_ur_pose(statement[1])
            elif kind == "digital_out":
                bit = 1 << statement[1]
                with self.lock:
                    self.digital_out = (self.digital_out | bit) if statement[2] else (self.digital_out & ~bit)
            elif kind == "textmsg":
                self.log.append(statement[1])
            elif kind == "sleep":
                if self.clock is not None:
                    self.clock.spend(statement[1], "robot")
                abort.wait(statement[1] / self.speed_scale)
            elif kind == "stop":
                self._halt()
            elif not self._move(statement, abort):
                break
        self._halt()

    def _halt(self) -> None:
        with self.lock:
            self.q = self.joints()
            self._motion = None

    def _move(self, statement: tuple, abort: threading.Event) -> bool:
        """Runs one movej/movel; False when it cannot (power, brakes, reach), the program then stops."""
        kind, is_pose, values, a, v = statement
        if self.robot_mode != 7:
            self.log.append(f"{kind}: the robot is not running (robot mode {ROBOT_MODES.get(self.robot_mode)})")
            return False
        q0 = self.joints()
        try:
            if kind == "movej":
                q1 = (
                    self.arm.inverse(rtde.transform_from_ur_pose(values) @ np.linalg.inv(self.T_flange_tcp), q0)
                    if is_pose
                    else np.array(values)
                )
                qs = np.linspace(q0, q1, 20)
                duration = trapezoid_s(float(np.abs(q1 - q0).max()), v, v / a)
            else:
                T0, T1 = self.arm.forward(q0), rtde.transform_from_ur_pose(values) @ np.linalg.inv(self.T_flange_tcp)
                steps = 20
                qs = [q0]
                for s in np.linspace(0.0, 1.0, steps)[1:]:
                    T = T0.copy()
                    T[:3, 3] = T0[:3, 3] + s * (T1[:3, 3] - T0[:3, 3])
                    turn = rotation_vector(T1[:3, :3] @ T0[:3, :3].T)
                    angle = float(np.linalg.norm(turn))
                    T[:3, :3] = (rotation_about(turn, s * angle) if angle > 1e-12 else np.eye(3)) @ T0[:3, :3]
                    qs.append(self.arm.inverse(T, qs[-1]))
                qs = np.array(qs)
                distance = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3])) / 1000.0
                duration = max(trapezoid_s(distance, v, v / a), float(np.abs(qs[-1] - q0).max()) / 3.0)
        except ValueError as exc:
            self.log.append(f"{kind}: {exc}")
            return False
        if self.clock is not None:  # the arm's time, from the program's speed and acceleration
            self.clock.spend(duration, "robot")
        duration /= self.speed_scale
        with self.lock:
            self._motion = (time.monotonic(), duration, np.linspace(0.0, 1.0, len(qs)), qs)
        self._report_motion(qs, duration)
        if abort.wait(duration):
            return False
        with self.lock:
            self.q = qs[-1].copy()
            self._motion = None
        return True

    def _report_motion(self, qs: np.ndarray, duration: float) -> None:
        if self.on_motion is None:
            return
        poses = np.array([self.arm.forward(q) for q in qs])
        length = float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())
        real = duration * self.speed_scale
        try:
            self.on_motion(poses, length / real if real > 0 else 0.0)
        except Exception as exc:  # keep serving; the failure shows in failures
            self.failures.append(f"on_motion: {type(exc).__name__}: {exc}")

    # -- the dashboard server
    def _dashboard(self, conn: socket.socket) -> None:
        conn.sendall(b"Connected: Universal Robots Dashboard Server\n")
        reader = conn.makefile("rb")
        while not self._stop.is_set():
            line = reader.readline(4096)
            if not line:
                return
            command = line.decode("latin-1").strip()
            answer = self._dashboard_answer(command)
            conn.sendall(answer.encode("latin-1") + b"\n")
            if command == "quit":
                return

    def _dashboard_answer(self, command: str) -> str:
        c = command.strip()
        low = c.lower()
        program_running = self.runtime_state == RUNTIME_PLAYING
        fixed = {
            "robotmode": f"Robotmode: {ROBOT_MODES.get(self.robot_mode, 'POWER_OFF')}",
            "safetymode": "Safetymode: NORMAL",
            "safetystatus": "Safetystatus: NORMAL",
            "programstate": f"{'PLAYING' if program_running else 'STOPPED'} {self.loaded}",
            "polyscopeversion": "URSoftware 5.11.1.108318 (Nov 22 2021)",
            "version": "5.11.1.108318",
            "get serial number": "20235500001",
            "get robot model": "UR5",
            "is in remote control": "true",
            "running": f"Program running: {'true' if program_running else 'false'}",
            "get loaded program": f"Loaded program: {self.loaded}",
            "isprogramsaved": f"true {self.loaded}",
            "close popup": "closing popup",
            "close safety popup": "closing safety popup",
            "unlock protective stop": "Protective stop releasing",
            "restart safety": "Restarting safety",
            "quit": "Disconnected",
            "shutdown": "Shutting down",
            "clear operational mode": "operational mode can no longer be controlled from Dashboard Server",
            "get operational mode": "NONE",
        }
        if low in fixed:
            return fixed[low]
        if low == "power on":
            self.robot_mode = max(self.robot_mode, 5)
            return "Powering on"
        if low == "power off":
            self._abort.set()
            self._halt()
            self.robot_mode = 3
            return "Powering off"
        if low == "brake release":
            if self.robot_mode < 5:
                return "Brake release failed: robot is powered off"
            self.robot_mode = 7
            return "Brake releasing"
        if low == "stop":
            self._abort.set()
            self._halt()
            return "Stopped"
        if low == "pause":
            return "Pausing program" if program_running else "Failed to execute: pause"
        if low == "play":
            return "Starting program"
        if low.startswith("load "):
            self.loaded = c[5:].strip()
            return f"Loading program: {self.loaded}"
        if low.startswith(("addtolog ", "popup ", "setuserrole ")):
            return {"addtolog": "Added log message", "popup": "showing popup", "setuserrole": "Setting user role"}[
                low.split()[0]
            ]
        return f"could not understand: '{c}'"

    # -- RTDE
    def _rtde(self, conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.settimeout(0.05)
        recipes: dict[int, tuple[list[str], list[str], float]] = {}
        sending: Optional[threading.Event] = None
        pending = b""
        version = 1
        while not self._stop.is_set():
            try:
                chunk = conn.recv(65536)
            except (socket.timeout, TimeoutError):
                continue
            if not chunk:
                break
            pending += chunk
            while True:
                package, pending = rtde.split_package(pending)
                if package is None:
                    break
                kind, payload = package
                reply = self._rtde_reply(kind, payload, recipes, version)
                if kind == "V" and reply is not None and reply[-1] == 1:
                    version = struct.unpack(">H", payload)[0]
                if kind == "S" and recipes and sending is None:
                    sending = threading.Event()
                    threading.Thread(target=self._stream, args=(conn, recipes, sending), daemon=True).start()
                if kind == "P" and sending is not None:
                    sending.set()
                    sending = None
                if reply is not None:
                    conn.sendall(reply)
        if sending is not None:
            sending.set()

    def _rtde_reply(self, kind: str, payload: bytes, recipes: dict, version: int) -> Optional[bytes]:
        if kind == "V":
            accepted = len(payload) == 2 and struct.unpack(">H", payload)[0] in (1, 2)
            return rtde.encode("V", struct.pack(">B", int(accepted)))
        if kind == "v":
            return rtde.encode("v", struct.pack(">IIII", *CONTROLLER_VERSION))
        if kind == "O":
            frequency = struct.unpack(">d", payload[:8])[0] if version >= 2 else 125.0
            # A trailing comma (ur_rtde sends one) names nothing: the controller ignores it.
            names = [n for n in payload[8 if version >= 2 else 0 :].decode("latin-1").split(",") if n]
            types = [rtde.variable_type(n) for n in names]
            if "NOT_FOUND" in types or not 0 < frequency <= 500:
                return rtde.encode("O", struct.pack(">B", 0) + ",".join(types).encode())
            recipe = len(recipes) + 1
            recipes[recipe] = (names, types, frequency)
            return rtde.encode("O", struct.pack(">B", recipe) + ",".join(types).encode())
        if kind == "I":
            names = [n for n in payload.decode("latin-1").split(",") if n]
            types = [rtde.variable_type(n, output=False) for n in names]
            return rtde.encode(
                "I", struct.pack(">B", 0 if "NOT_FOUND" in types else 100 + len(recipes)) + ",".join(types).encode()
            )
        if kind in ("S", "P"):
            return rtde.encode(kind, struct.pack(">B", 1))
        if kind == "M":
            return None
        if kind == "U":
            return None  # input data: the emulator keeps no inputs
        return rtde.encode("M", b"\x17unknown package type " + kind.encode("latin-1")[:1] + b"\x04rtde\x01")

    def _stream(self, conn: socket.socket, recipes: dict, stop: threading.Event) -> None:
        """Sends each recipe's data at its frequency, one package per due control cycle."""
        cycle = int((time.monotonic() - self._t0) / CYCLE_S) + 1
        every = {rid: max(1, round(500.0 / f)) for rid, (_, _, f) in recipes.items()}
        while not stop.is_set() and not self._stop.is_set():
            due = self._t0 + cycle * CYCLE_S
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            state = self._state(cycle * CYCLE_S)
            out = b""
            for rid, (names, types, _) in recipes.items():
                if cycle % every[rid] == 0:
                    out += rtde.pack_data(rid, types, [state.get(n, _zero(t)) for n, t in zip(names, types)])
            if out:
                try:
                    conn.sendall(out)
                except OSError:
                    return
            cycle += 1

    def _state(self, clock: float) -> dict[str, Any]:
        # The program's state first, then the arm's: a program that ends between the two reads
        # shows as still playing with the arm where it ended, never as ended with the arm short.
        runtime = self.runtime_state
        q = self.joints()
        T = self.arm.forward(q) @ self.T_flange_tcp
        pose = rtde.ur_pose(T)
        powered = self.robot_mode >= 5
        running = runtime == RUNTIME_PLAYING
        return {
            "timestamp": clock,
            "actual_q": tuple(q),
            "target_q": tuple(q),
            "actual_TCP_pose": pose,
            "target_TCP_pose": pose,
            "robot_mode": self.robot_mode,
            "safety_mode": SAFETY_NORMAL,
            "safety_status": SAFETY_NORMAL,
            "runtime_state": runtime,
            "joint_mode": (253,) * 6 if self.robot_mode == 7 else (236,) * 6,
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "actual_digital_output_bits": self.digital_out,
            "robot_status_bits": int(powered) | (int(running) << 1),
            "safety_status_bits": 1,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0 if powered else 0.0,
            "joint_temperatures": (30.0,) * 6,
        }


def _zero(t: str) -> Any:
    if t.startswith("VECTOR"):
        return (0,) * int(rtde.TYPES[t][0])
    return 0.0 if t == "DOUBLE" else False if t == "BOOL" else 0
