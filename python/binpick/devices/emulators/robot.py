"""A MELFA controller with a six-axis arm, speaking R3 on a pty (see :mod:`binpick.devices.melfa`).

The arm is a 6R arm with a spherical wrist: a vertical base axis J1 at height ``base_height_mm``,
an upper arm (J2, 0 = vertical) and a forearm (J3 relative to the upper arm, 90° = forearm
horizontal when J2 = 0), then the wrist J4 (about the forearm), J5 (bend) and J6 (flange):

    R_base_flange = Rz(J1)·Ry(J2+J3)·Rz(J4)·Ry(J5)·Rz(J6)

At J = (0, 0, 90, 0, 90, 0)° the flange points straight down at X = forearm, Z = base height +
upper arm − flange length. Posture flag FL1: bit 2 right (wrist in front of J1), bit 1 above
(J3 ≥ 0), bit 0 non-flip (J5 ≥ 0).

The emulator keeps the arm's joints, refuses what a controller refuses (no session, no operation
rights, servo off, alarm, busy, unreachable target, joint or operation-range limits, bad syntax)
with QeR/Qer and an error number whose text ERRORMES returns, and takes time to move: joint
moves at each joint's top speed × override, straight moves at the commanded speed × override,
ramping up and down over ``ramp_s`` (:meth:`RobotEmulatorConfig.move_time_s`, the time spent on
the cell's :class:`~binpick.devices.emulators.clock.PhysicalClock`), played ``speed_scale`` times
faster. The error numbers are the emulator's own, not the controller's table.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from ..._validate import check_number
from ...errors import InvalidInputError
from ...transforms import quaternion_matrix
from ..xyzabc import rotation_from_abc, xyzabc_from_transform
from ._pty import Fault, PtyEmulator, monotonic
from .clock import trapezoid_s

__all__ = ["ArmModel", "RobotEmulatorConfig", "RobotEmulator", "ERROR_TEXTS"]

ERR_SYNTAX, ERR_UNKNOWN, ERR_NOT_OPEN, ERR_VALUE = 1001, 1002, 1003, 1004
ERR_NO_CONTROL, ERR_SERVO_OFF, ERR_BUSY, ERR_ALARM = 2001, 2002, 2003, 2004
ERR_NO_POSITION, ERR_REACH, ERR_JOINT, ERR_PATH, ERR_RANGE = 3001, 3002, 3003, 3004, 3005
ERR_COLLISION, ERR_INTERNAL = 4001, 4002

ERROR_TEXTS: dict[int, str] = {
    ERR_SYNTAX: "Command syntax error",
    ERR_UNKNOWN: "Unknown command",
    ERR_NOT_OPEN: "Communication not opened (send OPEN=)",
    ERR_VALUE: "Value out of range",
    ERR_NO_CONTROL: "Operation rights not held (send CNTLON)",
    ERR_SERVO_OFF: "Servo is off (send SRVON)",
    ERR_BUSY: "Robot is moving",
    ERR_ALARM: "Alarm active (send RSTALRM)",
    ERR_NO_POSITION: "Position variable not defined",
    ERR_REACH: "Target position is out of the arm's reach",
    ERR_JOINT: "Joint limit over",
    ERR_PATH: "Straight-line path leaves the reachable space",
    ERR_RANGE: "Target outside the operation range",
    ERR_COLLISION: "Collision detected; the arm stopped",
    ERR_INTERNAL: "Controller internal error",
}


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _wrap(t: float) -> float:
    return (t + math.pi) % (2 * math.pi) - math.pi


class _Refused(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass(frozen=True)
class ArmModel:
    """Geometry and joint limits of the emulated arm (mm, degrees).

    Attributes:
        base_height_mm: height of the J2 axis above the base frame, mm.
        upper_arm_mm: J2 to J3 distance, mm.
        forearm_mm: J3 to wrist centre distance, mm.
        flange_mm: wrist centre to flange distance, mm.
        joint_min_deg: lower limits of J1..J6, degrees.
        joint_max_deg: upper limits of J1..J6, degrees.
        workspace_min_mm: lower corner of the controller's own operation range (flange), mm.
        workspace_max_mm: upper corner of that range, mm.
    """

    base_height_mm: float = 300.0
    upper_arm_mm: float = 250.0
    forearm_mm: float = 160.0
    flange_mm: float = 72.0
    joint_min_deg: tuple[float, ...] = (-150.0, -60.0, -30.0, -160.0, -120.0, -360.0)
    joint_max_deg: tuple[float, ...] = (150.0, 120.0, 160.0, 160.0, 120.0, 360.0)
    workspace_min_mm: tuple[float, float, float] = (-450.0, -450.0, -100.0)
    workspace_max_mm: tuple[float, float, float] = (450.0, 450.0, 750.0)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """T_base_flange of joint angles ``q`` (radians)."""
        j1, j2, j3, j4, j5, j6 = q
        r = self.upper_arm_mm * math.sin(j2) + self.forearm_mm * math.sin(j2 + j3)
        z = self.base_height_mm + self.upper_arm_mm * math.cos(j2) + self.forearm_mm * math.cos(j2 + j3)
        R = _rz(j1) @ _ry(j2 + j3) @ _rz(j4) @ _ry(j5) @ _rz(j6)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = np.array([r * math.cos(j1), r * math.sin(j1), z]) + self.flange_mm * R[:, 2]
        return T

    def flags(self, q: np.ndarray) -> int:
        """FL1 of joint angles ``q``."""
        r = self.upper_arm_mm * math.sin(q[1]) + self.forearm_mm * math.sin(q[1] + q[2])
        return 4 * (r >= 0) + 2 * (q[2] >= 0) + 1 * (q[4] >= 0)

    def inverse(self, T: np.ndarray, fl1: int, q_ref: np.ndarray) -> np.ndarray:
        """Joint angles (radians) reaching ``T`` in posture ``fl1``; raises _Refused if impossible."""
        R, p = T[:3, :3], T[:3, 3]
        w = p - self.flange_mm * R[:, 2]
        j1, r = math.atan2(w[1], w[0]), math.hypot(w[0], w[1])
        if not fl1 & 4:
            j1, r = _wrap(j1 + math.pi), -r
        h = w[2] - self.base_height_mm
        a, d = self.upper_arm_mm, self.forearm_mm
        cos3 = (r * r + h * h - a * a - d * d) / (2 * a * d)
        if abs(cos3) > 1.0:
            raise _Refused(ERR_REACH)
        j3 = math.acos(cos3) * (1 if fl1 & 2 else -1)
        j2 = math.atan2(r, h) - math.atan2(d * math.sin(j3), a + d * math.cos(j3))
        M = (_rz(j1) @ _ry(j2 + j3)).T @ R
        s5 = math.hypot(M[0, 2], M[1, 2])
        j5 = math.atan2(s5, M[2, 2])
        if s5 < 1e-9:  # wrist singular: keep J4, put the rest in J6
            j4 = float(q_ref[3])
            j6 = _wrap(math.atan2(M[1, 0], M[0, 0]) - j4)
        else:
            j4, j6 = math.atan2(M[1, 2], M[0, 2]), math.atan2(M[2, 1], -M[2, 0])
            if not fl1 & 1:
                j4, j5, j6 = _wrap(j4 + math.pi), -j5, _wrap(j6 + math.pi)
        q = np.array([j1, _wrap(j2), j3, j4, j5, j6])
        # A joint that turns more than once (J6: ±360°) takes the turn nearest q_ref that its
        # limits allow, as the controller keeps it continuous through a straight move.
        lo, hi = np.radians(self.joint_min_deg), np.radians(self.joint_max_deg)
        for i in np.flatnonzero(hi - lo > 2 * math.pi):
            turns = q[i] + 2 * math.pi * np.arange(-2, 3)
            turns = turns[(turns >= lo[i] - 1e-9) & (turns <= hi[i] + 1e-9)]
            if len(turns):
                q[i] = turns[np.argmin(np.abs(turns - float(q_ref[i])))]
        self.check(q, T)
        return q

    def check(self, q: np.ndarray, T: np.ndarray) -> None:
        """Raises _Refused when ``q`` passes a joint limit or ``T`` leaves the operation range."""
        deg = np.degrees(q)
        if (deg < np.asarray(self.joint_min_deg) - 1e-6).any() or (deg > np.asarray(self.joint_max_deg) + 1e-6).any():
            raise _Refused(ERR_JOINT)
        p = T[:3, 3]
        if (p < np.asarray(self.workspace_min_mm)).any() or (p > np.asarray(self.workspace_max_mm)).any():
            raise _Refused(ERR_RANGE)


@dataclass(frozen=True)
class RobotEmulatorConfig:
    """Settings of a :class:`RobotEmulator`.

    Attributes:
        arm: geometry and limits of the arm.
        robot_number: the robot number the controller answers to.
        model_name: text returned by OPEN.
        home_deg: joint angles at start-up, degrees.
        joint_speed_deg_s: joint speed of MOV at 100 % override, degrees per second.
        joint_speeds_deg_s: each joint's own top speed (six values, deg/s), where they differ
            (an arm's datasheet lists them); empty: ``joint_speed_deg_s`` for every joint.
        ramp_s: the time a joint or the straight-line speed takes to reach full speed from rest
            (and to stop): a constant acceleration of speed / ``ramp_s``; 0: at once.
        speed_scale: multiplies every speed (use > 1 to make tests quick).
        servo_on_delay_s: time servo power takes to come on after SRVON, seconds.
    """

    arm: ArmModel = ArmModel()
    robot_number: int = 1
    model_name: str = "RV-1A"
    home_deg: tuple[float, ...] = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
    joint_speed_deg_s: float = 180.0
    joint_speeds_deg_s: tuple[float, ...] = ()
    ramp_s: float = 0.0
    speed_scale: float = 1.0
    servo_on_delay_s: float = 0.0

    def __post_init__(self) -> None:
        check_number(self.joint_speed_deg_s, "RobotEmulatorConfig.joint_speed_deg_s", low=1e-3, unit="deg/s")
        check_number(self.speed_scale, "RobotEmulatorConfig.speed_scale", low=1e-3, high=1e6)
        check_number(self.ramp_s, "RobotEmulatorConfig.ramp_s", low=0.0, high=10.0, unit="s")
        if len(self.joint_speeds_deg_s) not in (0, 6):
            raise InvalidInputError("RobotEmulatorConfig.joint_speeds_deg_s: expected six speeds in deg/s, or none")
        for v in self.joint_speeds_deg_s:
            check_number(v, "RobotEmulatorConfig.joint_speeds_deg_s", low=1e-3, unit="deg/s")

    @property
    def joint_speeds_rad_s(self) -> np.ndarray:
        """Each joint's top speed at 100 % override, rad/s."""
        speeds = self.joint_speeds_deg_s or (self.joint_speed_deg_s,) * 6
        return np.radians(np.asarray(speeds, dtype=np.float64))

    def move_time_s(
        self, joints: np.ndarray, override: float = 1.0, linear_mm: float = 0.0, speed_mm_s: float = 0.0
    ) -> float:
        """The physical time of a motion through the joint samples ``joints`` (K, 6) rad at
        ``override`` (0–1): each joint over its travel at its top speed × override, ramping in
        and out over ``ramp_s`` (:func:`~binpick.devices.emulators.clock.trapezoid_s`), the
        joints finishing together (the slowest decides); for a straight move also its length
        ``linear_mm`` at ``speed_mm_s`` × override."""
        travel = np.abs(np.diff(np.asarray(joints, dtype=np.float64), axis=0)).sum(axis=0)
        speeds = self.joint_speeds_rad_s * override
        t = max((trapezoid_s(d, v, self.ramp_s) for d, v in zip(travel, speeds)), default=0.0)
        if linear_mm > 0.0:
            t = max(t, trapezoid_s(linear_mm, speed_mm_s * override, self.ramp_s))
        return t
        check_number(self.servo_on_delay_s, "RobotEmulatorConfig.servo_on_delay_s", low=0.0, unit="s")
        if len(self.home_deg) != 6:
            raise InvalidInputError("RobotEmulatorConfig.home_deg: expected six joint angles in degrees")


@dataclass
class _Motion:
    path: np.ndarray  # (K, 6) joint samples, radians
    t0: float
    duration: float
    alarm_at: Optional[float] = None  # fraction of the path where an injected alarm stops the arm
    alarm_code: int = ERR_COLLISION

    def fraction(self, now: float) -> float:
        return 1.0 if self.duration <= 0 else min(1.0, (now - self.t0) / self.duration)

    def joints(self, s: float) -> np.ndarray:
        x = s * (len(self.path) - 1)
        i = min(int(x), len(self.path) - 2)
        return self.path[i] + (x - i) * (self.path[i + 1] - self.path[i])


def _quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method, stable at 180°)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2 * math.sqrt(tr + 1.0)
        q = (s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s)
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = ((R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s)
    elif R[1, 1] > R[2, 2]:
        s = 2 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = ((R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s)
    else:
        s = 2 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = ((R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4)
    return np.array(q)


def _straight_path(T0: np.ndarray, T1: np.ndarray, steps: int) -> list[np.ndarray]:
    q0, q1 = _quat(T0[:3, :3]), _quat(T1[:3, :3])
    if q0 @ q1 < 0:
        q1 = -q1
    angle = math.acos(min(1.0, float(q0 @ q1)))
    poses = []
    for s in np.linspace(0.0, 1.0, steps):
        if angle < 1e-9:
            q = q0
        else:
            q = (math.sin((1 - s) * angle) * q0 + math.sin(s * angle) * q1) / math.sin(angle)
        T = np.eye(4)
        T[:3, :3] = quaternion_matrix(q)
        T[:3, 3] = (1 - s) * T0[:3, 3] + s * T1[:3, 3]
        poses.append(T)
    return poses


class RobotEmulator(PtyEmulator):
    """An R3 controller and its arm on a pty.

    Args:
        config: arm model, speeds and start-up pose.

    Test hooks besides :meth:`inject`: :meth:`inject_motion_alarm` stops the next motion part-way
    with an alarm, and :meth:`joints`, :meth:`pose`, :meth:`is_moving`, :attr:`speeds`, :attr:`hands` show
    the arm's state.
    """

    supported_faults = frozenset(Fault) - {Fault.BAD_CRC}
    device = "robot"

    def __init__(self, *, config: RobotEmulatorConfig = RobotEmulatorConfig()) -> None:
        super().__init__()
        self.config = config
        self._q = np.radians(np.asarray(config.home_deg, dtype=float))
        self._motion: Optional[_Motion] = None
        self._opened = False
        self._control = False
        self._servo_at: Optional[float] = None
        self._override = 100
        self._speed_mm_s = 100.0
        self._alarm = 0
        self._positions: dict[int, tuple[np.ndarray, int, int]] = {}
        self._pending_alarm: Optional[tuple[float, int]] = None
        self.hands: dict[int, bool] = {}
        #: Called as ``on_motion(T_base_flange path (K, 4, 4), speed mm/s)`` when a motion starts
        #: (the flange poses it passes through, ending where an injected alarm stops it; the speed
        #: at 100 % speed scale, its top speed along the path); a simulated world uses it to sweep
        #: the tool through its parts.
        #: It runs on the serving thread under the emulator's lock: it must not call back into
        #: the emulator. Its exceptions are recorded in :attr:`failures`.
        self.on_motion: Optional[Callable[[np.ndarray, float], None]] = None

    # -- state for tests
    def joints(self) -> np.ndarray:
        """Current joint angles, radians."""
        with self._lock:
            self._settle()
            return self._q.copy()

    def pose(self) -> np.ndarray:
        """Current T_base_flange."""
        return self.config.arm.forward(self.joints())

    def is_moving(self) -> bool:
        """Whether a motion is under way."""
        with self._lock:
            self._settle()
            return self._motion is not None

    @property
    def speeds(self) -> tuple[int, float]:
        """The override (percent) and the straight-line speed (mm/s) the controller holds now."""
        with self._lock:
            return self._override, self._speed_mm_s

    @property
    def alarm(self) -> int:
        """Number of the active alarm, 0 when none."""
        with self._lock:
            self._settle()
            return self._alarm

    def inject_motion_alarm(self, *, at_fraction: float = 0.5, code: int = ERR_COLLISION) -> None:
        """The next motion stops at ``at_fraction`` of its path with alarm ``code``."""
        with self._lock:
            self._pending_alarm = (check_number(at_fraction, "at_fraction", low=0.0, high=1.0), int(code))

    # -- motion model
    def _settle(self) -> None:
        m = self._motion
        if m is None:
            return
        s = m.fraction(monotonic())
        if m.alarm_at is not None and s >= m.alarm_at:
            self._q, self._motion, self._alarm = m.joints(m.alarm_at), None, m.alarm_code
        elif s >= 1.0:
            self._q, self._motion = m.path[-1].copy(), None
        else:
            self._q = m.joints(s)

    def _plan(self, target: np.ndarray, fl1: int, linear: bool) -> _Motion:
        arm = self.config.arm
        if linear:
            T0 = arm.forward(self._q)
            dist = float(np.linalg.norm(target[:3, 3] - T0[:3, 3]))
            steps = int(min(200, max(10, dist / 5.0)))
            path, q = [], self._q
            for T in _straight_path(T0, target, steps):
                try:
                    q = arm.inverse(T, fl1, q)
                except _Refused as exc:
                    raise _Refused(ERR_PATH if exc.code == ERR_REACH else exc.code) from None
                path.append(q)
            path[0] = self._q
            joints = np.array(path)
        else:
            q1 = arm.inverse(target, fl1, self._q)
            joints = np.array([self._q, q1])
            dist = 0.0
        physical = self.config.move_time_s(joints, self._override / 100.0, dist, self._speed_mm_s)
        motion = _Motion(joints, monotonic(), physical / self.config.speed_scale)
        if self._pending_alarm is not None:
            motion.alarm_at, motion.alarm_code = self._pending_alarm
            self._pending_alarm = None
        self._spend(physical * (1.0 if motion.alarm_at is None else motion.alarm_at))
        return motion

    def _report_motion(self, m: _Motion) -> None:
        if self.on_motion is None:
            return
        end = 1.0 if m.alarm_at is None else m.alarm_at
        samples = max(2 * len(m.path), 30)
        poses = np.array([self.config.arm.forward(m.joints(s)) for s in np.linspace(0.0, end, samples)])
        length = float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())
        # The flange's top speed along the path: the length over the time at speed, ramps aside
        # (a trapezoid's d / (T − ramp); a move too short to reach it peaks at 2d / T).
        T, r = end * m.duration * self.config.speed_scale, self.config.ramp_s
        at_speed = T - r if T >= 2 * r else T / 2
        speed = length / at_speed if at_speed > 0 else 0.0
        try:
            self.on_motion(poses, speed)
        except Exception as exc:  # keep serving; the failure shows in failures
            self.failures.append(f"on_motion: {type(exc).__name__}: {exc}")

    # -- protocol
    def _take_requests(self, buf: bytearray) -> list[str]:
        out = []
        while b"\r" in buf:
            line, _, rest = bytes(buf).partition(b"\r")
            buf[:] = rest
            out.append(line.decode("latin-1"))
        return out

    def _reply(self, ok: bool, data: str = "") -> bytes:
        status = ("Qok" if self._alarm else "QoK") if ok else ("Qer" if self._alarm else "QeR")
        return f"{status}{data}\r".encode("ascii")

    def _handle(self, request: str) -> Optional[bytes]:
        with self._lock:
            self._settle()
            m = re.fullmatch(r"(\d+);(\d+);(.*)", request)
            try:
                if not m:
                    raise _Refused(ERR_SYNTAX)
                if int(m.group(1)) != self.config.robot_number:
                    return None  # addressed to another robot
                return self._reply(True, self._execute(m.group(3)))
            except _Refused as exc:
                return self._reply(False, f"{exc.code:04d}")

    def _require_motion_ready(self) -> None:
        if not self._control:
            raise _Refused(ERR_NO_CONTROL)
        if self._servo_at is None or monotonic() < self._servo_at:
            raise _Refused(ERR_SERVO_OFF)
        if self._alarm:
            raise _Refused(ERR_ALARM)
        if self._motion is not None:
            raise _Refused(ERR_BUSY)

    def _execute(self, cmd: str) -> str:
        if cmd.startswith("OPEN="):
            self._opened = True
            return self.config.model_name
        if not self._opened and not cmd.startswith("ERRORMES"):
            raise _Refused(ERR_NOT_OPEN)
        simple = {
            "CLOSE": self._close_session,
            "CNTLON": lambda: setattr(self, "_control", True),
            "CNTLOFF": lambda: setattr(self, "_control", False),
            "SRVON": self._servo_on,
            "SRVOFF": self._servo_off,
            "RSTALRM": lambda: setattr(self, "_alarm", 0),
            "STOP": self._halt,
        }
        if cmd in simple:
            simple[cmd]()
            return ""
        if cmd == "PPOSF":
            T = self.config.arm.forward(self._q)
            v = xyzabc_from_transform(T)
            v[3:] = np.degrees(v[3:])
            body = ";".join(f"{n};{x:.2f}" for n, x in zip("XYZABC", v))
            return f"{body};;{self.config.arm.flags(self._q)},0;{self._override};0.00;00000000"
        if cmd == "JPOSF":
            body = ";".join(f"J{i + 1};{x:.2f}" for i, x in enumerate(np.degrees(self._q)))
            return f"{body};;****,****;{self._override};0.00;00000000"
        if cmd == "DSTATE":
            servo = self._servo_at is not None and monotonic() >= self._servo_at
            bits = 0x80 * self._control + 0x40 * (self._motion is not None) + 0x20 * servo
            return f"{bits:02X}{self._alarm:04d}"
        return self._execute_with_argument(cmd)

    def _execute_with_argument(self, cmd: str) -> str:
        m = re.fullmatch(r"OVRD=(\d+)", cmd)
        if m:
            if not 1 <= int(m.group(1)) <= 100:
                raise _Refused(ERR_VALUE)
            self._override = int(m.group(1))
            return ""
        m = re.fullmatch(r"EXECSPD ?([0-9.]+)", cmd)
        if m:
            self._speed_mm_s = self._positive(m.group(1))
            return ""
        m = re.fullmatch(r"HND(ON|OFF)([1-8])", cmd)
        if m:
            self.hands[int(m.group(2))] = m.group(1) == "ON"
            return ""
        m = re.fullmatch(r"ERRORMES(\d+)", cmd)
        if m:
            return ERROR_TEXTS.get(int(m.group(1)), "Undefined error")
        m = re.fullmatch(r"EXECP(\d+)=\(([^()]*)\)(?:\((\d+),(-?\d+)\))?", cmd)
        if m:
            values = [self._number(x) for x in m.group(2).split(",")]
            if len(values) != 6:
                raise _Refused(ERR_SYNTAX)
            self._positions[int(m.group(1))] = (np.array(values), int(m.group(3) or 7), int(m.group(4) or 0))
            return ""
        m = re.fullmatch(r"EXEC(MOV|MVS) ?P(\d+)", cmd)
        if m:
            self._require_motion_ready()
            if int(m.group(2)) not in self._positions:
                raise _Refused(ERR_NO_POSITION)
            xyzabc, fl1, _ = self._positions[int(m.group(2))]
            T = np.eye(4)
            T[:3, :3] = rotation_from_abc(*np.radians(xyzabc[3:]))
            T[:3, 3] = xyzabc[:3]
            self._motion = self._plan(T, fl1, linear=m.group(1) == "MVS")
            self._report_motion(self._motion)
            return ""
        raise _Refused(ERR_SYNTAX if cmd.startswith("EXEC") else ERR_UNKNOWN)

    @staticmethod
    def _number(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise _Refused(ERR_SYNTAX) from None
        if not math.isfinite(v):
            raise _Refused(ERR_VALUE)
        return v

    def _positive(self, text: str) -> float:
        v = self._number(text)
        if v <= 0:
            raise _Refused(ERR_VALUE)
        return v

    def _servo_on(self) -> None:
        if not self._control:
            raise _Refused(ERR_NO_CONTROL)
        if self._servo_at is None:
            self._servo_at = monotonic() + self.config.servo_on_delay_s

    def _servo_off(self) -> None:
        self._halt()
        self._servo_at = None

    def _halt(self) -> None:
        self._motion = None  # _settle already froze the joints where they are

    def _close_session(self) -> None:
        self._halt()
        self._opened = self._control = False
        self._servo_at = None

    # -- fault hooks
    def _garble(self, reply: bytes) -> bytes:
        body = bytearray(reply[:-1])
        for i in range(1, len(body), 3):
            body[i] ^= 0xA5
        return bytes(body) + b"\r"

    def _unknown_reply(self, request: Any) -> bytes:
        return b"RDY?\r"

    def _error_reply(self, request: Any) -> Optional[bytes]:
        with self._lock:
            return self._reply(False, f"{ERR_INTERNAL:04d}")
