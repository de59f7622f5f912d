"""What the vision server does for each request, without sockets: :class:`VisionService`.

The robot program is the master. It moves the arm to its scan pose and sends SCAN with the
flange pose; binpick sweeps its laser and grabs the frames there (the camera rides on the arm)
and keeps the cloud. NEXT locates the parts in that cloud and plans the pick of the most
pickable one exactly as :class:`~binpick.cell.Cell` does for its own arm — the same grasp
choice, the same trust rules, and the whole motion checked by the same safety layer from the
flange pose the program reported — and replies with the waypoints in the brand's convention.
RESULT says what the gripper found; a pick's gripper closing on nothing is remembered, as the
cell remembers it, and every pick is written to ``picks.jsonl`` when the server has a folder.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from ..cell.grasp import NoGraspError
from ..cell.loop import Cell, quiet
from ..cell.records import Located, PickPlan, ScanResult, pose_trust
from ..devices import safety
from ..devices.gripper import Gripper
from ..devices.robot import Robot
from ..errors import BinpickError, DeviceError, InvalidInputError, NoObjectFound, SafetyError
from ..transforms import pose_error
from .conventions import CONVENTIONS, PoseConvention
from .protocol import (
    NEXT_POSES,
    PROTOCOL_VERSION,
    Code,
    Request,
    RequestError,
    Verb,
    encode_reply,
    parse_request,
    reply_size,
)

__all__ = ["VisionService", "ProgramRobot", "ProgramGripper", "BRAND_IDS"]

#: The brand's number in HELLO's reply: its place in :data:`binpick.server.conventions.CONVENTIONS`, from 1.
BRAND_IDS = {brand: i + 1 for i, brand in enumerate(CONVENTIONS)}
#: How far the arm may be from where the robot program said it is for binpick to sweep the laser
#: from there (mm, degrees): the scan's own pose is the only one binpick is ever asked to be at.
AT_POSE_MM, AT_POSE_DEG = 0.01, 0.001


class ProgramRobot(Robot):
    """The arm as the robot program drives it: its pose is the one the program last reported,
    and binpick never moves it (a move anywhere else raises SafetyError; nothing is sent)."""

    def __init__(self, limits: Optional[safety.CellLimits]) -> None:
        self.limits = limits
        self.T_base_flange: Optional[np.ndarray] = None

    def read_pose(self) -> np.ndarray:
        if self.T_base_flange is None:
            raise RequestError(Code.OUT_OF_ORDER, "the robot program has not reported the arm's pose; send SCAN")
        return self.T_base_flange.copy()

    def move_to(self, T_base_flange: Any, *, linear: bool = False) -> None:
        deg, mm = pose_error(self.read_pose(), T_base_flange)
        if mm > AT_POSE_MM or deg > AT_POSE_DEG:
            raise SafetyError("the robot program moves the arm, binpick does not; nothing was sent")

    def stop(self) -> None:
        """Nothing to stop: binpick sends the arm nothing."""


class ProgramGripper(Gripper):
    """The gripper as the robot program drives it (binpick only plans its opening)."""

    def __init__(self, sets_width: bool) -> None:
        self.sets_width = bool(sets_width)

    def open(self, *, wait: bool = True) -> None:
        raise DeviceError("the robot program drives the gripper; binpick sends it nothing")

    def close(self, *, wait: bool = True) -> Optional[bool]:
        raise DeviceError("the robot program drives the gripper; binpick sends it nothing")


class VisionService:
    """Answers requests (:meth:`handle`) for one cell: ``cell`` is a :class:`Cell` on a
    :class:`ProgramRobot` and a :class:`ProgramGripper` with the cell's laser motor and camera.

    Args:
        cell: the cell (its motor enabled by the caller).
        convention: the brand's pose convention.
        out: a folder for ``picks.jsonl`` (one line per RESULT), or None.
        progress: called with (stage, message).
    """

    def __init__(
        self,
        cell: Cell,
        convention: PoseConvention,
        *,
        out: Any = None,
        progress: Optional[Callable[[str, str], None]] = None,
    ) -> None:
        if not isinstance(cell.robot, ProgramRobot):
            raise InvalidInputError("cell: the vision server's cell drives a ProgramRobot (the robot program moves)")
        self.cell = cell
        self.convention = convention
        self.progress = progress or quiet
        self.out = None if out is None else Path(out)
        if self.out is not None:
            self.out.mkdir(parents=True, exist_ok=True)
        self.scan: Optional[ScanResult] = None
        self.offer: Optional[tuple[int, Located, PickPlan]] = None
        self.scans = self.picks = self.held = 0
        self.pick_id = 0
        self.last_error = Code.OK
        self.compute_ms = 0.0  # the last request's scan, location and planning, for the latency bench

    @property
    def state(self) -> int:
        """0: ready (no scan to plan from); 1: scanned; 2: a pick offered, its RESULT awaited."""
        return 2 if self.offer is not None else 1 if self.scan is not None else 0

    # -- one request
    def handle_line(self, line: bytes) -> bytes:
        """The reply to one request line (without its line end); never raises for anything the
        line holds. An empty line gets no reply (b""): a stray line end is not a request."""
        if not line.strip():
            return b""
        verb = None
        t0 = time.perf_counter()
        self.compute_ms = 0.0
        try:
            request = parse_request(line, self.convention.size)
            verb = request.verb
            return self._answer(request)
        except RequestError as exc:
            return self._error(exc.code, str(exc), exc.verb or verb)
        except NoObjectFound as exc:
            return self._error(Code.NOTHING_FOUND, f"nothing found: {exc}", verb)
        except SafetyError as exc:
            return self._error(Code.UNSAFE, f"refused by the cell's safety rules: {exc}", verb)
        except InvalidInputError as exc:
            return self._error(Code.BAD_VALUE, str(exc), verb)
        except DeviceError as exc:
            return self._error(Code.DEVICE_FAULT, f"{type(exc).__name__}: {exc}", verb)
        except BinpickError as exc:
            return self._error(Code.INTERNAL, f"{type(exc).__name__}: {exc}", verb)
        finally:
            self.progress("serve", f"{line[:40]!r} answered in {(time.perf_counter() - t0) * 1e3:.1f} ms")

    def _error(self, code: Code, text: str, verb: Optional[Verb]) -> bytes:
        self.last_error = code
        self.progress("serve", f"error {int(code)} ({code.name.lower()}): {text}")
        return encode_reply(code, size=reply_size(verb, self.convention.size), text=text)

    def _reply(self, verb: Verb, numbers: list) -> bytes:
        return encode_reply(Code.OK, numbers, size=reply_size(verb, self.convention.size))

    def _answer(self, request: Request) -> bytes:
        verb, n = request.verb, request.numbers
        if verb is Verb.HELLO:
            if n[0] != PROTOCOL_VERSION:
                raise RequestError(Code.VERSION, f"this binpick speaks protocol {PROTOCOL_VERSION}", verb)
            brand = self.convention.brand
            return self._reply(verb, [PROTOCOL_VERSION, BRAND_IDS[brand], self.convention.size])
        if verb is Verb.SCAN:
            return self._scan(n)
        if verb is Verb.NEXT:
            return self._next()
        if verb is Verb.RESULT:
            return self._result(n)
        if verb is Verb.STATUS:
            return self._reply(verb, [self.state, self.scans, self.picks, self.held, int(self.last_error)])
        return self._reply(verb, [])  # BYE: the server closes the connection after it

    def _scan(self, numbers: tuple[float, ...]) -> bytes:
        T = self.convention.from_robot(numbers, "SCAN pose")
        safety.check_pose(T, self.cell.config.limits, name="the reported scan pose")
        if self.offer is not None:  # a program restarted mid-pick scans again: the offer lapses unreported
            self.progress("serve", f"pick {self.offer[0]} lapsed without a RESULT (a new SCAN came first)")
            self.offer = None
        self.cell.robot.T_base_flange = T
        self.scan = None
        self.cell.decline(None)  # a new look: the parts declined before may be pickable now
        t0 = time.perf_counter()
        scan = self.cell.scan([T])
        ms = (time.perf_counter() - t0) * 1e3
        self.compute_ms = ms
        self.scan, self.scans = scan, self.scans + 1
        return self._reply(Verb.SCAN, [self.scans, len(scan.points), round(ms)])

    def _next(self) -> bytes:
        if self.offer is not None:
            raise RequestError(Code.OUT_OF_ORDER, f"pick {self.offer[0]} awaits its RESULT first", Verb.NEXT)
        if self.scan is None:
            raise RequestError(Code.OUT_OF_ORDER, "no scan to pick from: send SCAN first", Verb.NEXT)
        t0 = time.perf_counter()
        try:
            located, plan = self.cell.locate_and_plan(self.scan)
            moves = self.cell.check_plan(plan)
        except NoGraspError as exc:
            raise RequestError(Code.NO_PICKABLE_PART, f"no part can be picked: {exc}", Verb.NEXT) from None
        finally:
            self.compute_ms = (time.perf_counter() - t0) * 1e3
        self.pick_id += 1
        self.offer = (self.pick_id, located, plan)
        trust = pose_trust(located.result, plan.T_base_gripper)
        decided = trust["orientation_decided"]
        confidence = trust["confidence"] if decided else trust["confidence_any"]
        numbers = [self.pick_id, 1, round(confidence, 4), int(decided), round(self.cell.finger_opening(plan), 3)]
        for name in NEXT_POSES:
            numbers += [round(float(x), 6) for x in self.convention.to_robot(moves[name][0])]
        t = located.T_base_object[:3, 3]
        self.progress(
            "serve",
            f"pick {self.pick_id}: {self.cell.config.model.name} at ({t[0]:.1f}, {t[1]:.1f}, {t[2]:.1f}) mm, "
            f"grasp {plan.grasp}, confidence {confidence:.2f}{'' if decided else ' (orientation open)'}",
        )
        return self._reply(Verb.NEXT, numbers)

    def _result(self, numbers: tuple[float, ...]) -> bytes:
        pick_id, outcome = numbers
        if self.offer is None or pick_id != self.offer[0]:
            expected = "no pick is awaiting a result" if self.offer is None else f"pick {self.offer[0]} is"
            raise RequestError(Code.OUT_OF_ORDER, f"RESULT for pick {pick_id:g}: {expected}", Verb.RESULT)
        if outcome not in (-1, 0, 1):
            raise RequestError(Code.BAD_VALUE, "RESULT's outcome is 1 (held), 0 (empty) or -1 (not tried)", Verb.RESULT)
        _, located, plan = self.offer
        self.offer = None
        if outcome == -1:  # the program passed it over: offer another part of the same scan
            self.cell.decline(located)
        else:
            self.cell.judge_pick(located, bool(outcome), None)  # remembers an empty grip, as the cell does
            self.picks += 1
            self.held += int(outcome == 1)
            self.scan = None  # the bin changed: scan again
        self._record(int(pick_id), int(outcome), located, plan)
        return self._reply(Verb.RESULT, [int(pick_id), self.picks, self.held])

    def _record(self, pick_id: int, outcome: int, located: Located, plan: PickPlan) -> None:
        if self.out is None:
            return
        trust = pose_trust(located.result)
        line = {
            "pick": pick_id,
            "outcome": {1: "held", 0: "empty grip", -1: "not tried"}[outcome],
            "T_base_object": np.round(located.T_base_object, 6).tolist(),
            "grasp": plan.grasp,
            **trust,
            "score": float(located.result.score),
        }
        with open(self.out / "picks.jsonl", "a", encoding="utf-8") as f:
            f.write(json.dumps(line) + "\n")
