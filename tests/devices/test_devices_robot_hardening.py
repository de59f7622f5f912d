"""The MELFA driver's raw ``command`` is an allowlist, and the session survives one lost reply:
checked over a pty against the R3 controller emulator."""

import re
import time

import numpy as np
import pytest
from device_settings import FAST_ROBOT
from hypothesis import given, settings
from hypothesis import strategies as st
from test_devices_robot_driver import commands, down, is_cmd

from binpick.devices import CellLimits, MelfaRobot
from binpick.devices.emulators import Fault, RobotEmulator, RobotEmulatorConfig
from binpick.devices.melfa import SAFE_COMMANDS, encode_command
from binpick.errors import DeviceFault, DeviceTimeout, InvalidInputError, SafetyError

# What moves the arm, starts or selects a program, jogs, changes speed or override, or works the
# hand — in the spellings a careless or hostile caller would try.
REFUSED = [
    "EXECSPD 9999",
    "EXECSPD9999",
    "execspd 9999",
    " EXECSPD 9999",
    "OVRD=100",
    "OVRD 100",
    "EXECOVRD 100",
    "EXECJOVRD 100",
    "EXECSPD 200.00",  # even a speed within the limits: set_linear_speed is the way
    "RUN1",
    "RUN 1",
    "PRGLOAD=1",
    "SLOTINIT",
    "JOG1",
    "JOG 1;1;1",
    "MOV P1",
    "MVS P1",
    "EXECMOV P1",
    "EXECMVS P1",
    "EXECMOV P1 ",
    "EXECP1=(300.00,0.00,100.00,180.00,0.00,180.00)(7,0)",
    "EXECHOPEN 1",
    "HNDON1",
    "HNDOFF1",
    "PPOSF;EXECMOV P1",
    "PPOSF ",
    "pposf",
    "OPEN=NARCUSR;RUN1",
    "STOP\tRUN1",
    "SRVONX",
]


def test_only_allowlisted_commands_pass_and_nothing_else_reaches_the_controller(robot, robot_emulator):
    before = list(robot_emulator.requests)
    for cmd in REFUSED:
        with pytest.raises(SafetyError, match="nothing was sent"):
            robot.command(cmd)
    assert robot_emulator.requests == before, "a refused command reached the controller"
    assert robot_emulator.speeds == (50, 200.0)
    # the allowed queries do reach it
    assert robot.command("PPOSF").data.startswith("X;160.00")
    assert robot.command("DSTATE", retry=True).ok
    assert robot.command("ERRORMES1001").data == "Command syntax error"
    assert commands(robot_emulator)[len(before) :] == ["PPOSF", "DSTATE", "ERRORMES1001"]


def test_every_allowlist_entry_is_a_harmless_command(robot):
    assert set(SAFE_COMMANDS) == {
        "PPOSF",
        "JPOSF",
        "DSTATE",
        "ERRORMES<n>",
        "OPEN=<client>",
        "CLOSE",
        "CNTLON",
        "CNTLOFF",
        "SRVON",
        "SRVOFF",
        "RSTALRM",
        "STOP",
    }
    robot.command("STOP")
    robot.command("RSTALRM")
    with pytest.raises(SafetyError):
        robot.command("ERRORMES123456")  # longer than any error number
    with pytest.raises(SafetyError):
        robot.command("OPEN=" + "A" * 33)


def test_a_refused_speed_change_leaves_the_next_checked_move_at_the_limited_speed():
    # Real speeds (speed_scale 1): a 78 mm straight move at 200 mm/s × 50 % takes 0.78 s; at
    # 9999 mm/s it would be over in a quarter of a second (joint speed bounds it then).
    with RobotEmulator(config=RobotEmulatorConfig(speed_scale=1.0)) as emu:
        with MelfaRobot(emu.slave_path, config=FAST_ROBOT, limits=CellLimits()) as r:
            for cmd in ("EXECSPD 9999", "OVRD=100", "EXECOVRD 100"):
                with pytest.raises(SafetyError):
                    r.command(cmd)
            t = time.monotonic()
            r.move_to(down(160, 0, 400), linear=True)
            elapsed = time.monotonic() - t
            np.testing.assert_allclose(emu.pose()[:3, 3], [160, 0, 400], atol=0.02)
            assert emu.speeds == (50, 200.0)
            assert elapsed > 0.6, f"the move took {elapsed:.2f} s: faster than the limited speed allows"
        sent = commands(emu)
        assert not any(c.startswith(("EXECSPD 9999", "OVRD=100", "EXECOVRD")) for c in sent)
        assert [c for c in sent if c.startswith(("EXECSPD", "OVRD"))] == ["OVRD=50", "EXECSPD 200.00"]


def test_open_session_retries_open_after_a_lost_reply(robot_emulator):
    robot_emulator.inject(Fault.NO_REPLY, when=is_cmd("OPEN="))
    with MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT) as r:
        assert r.state().servo_on
    sent = commands(robot_emulator)
    assert sent[:4] == ["OPEN=NARCUSR", "OPEN=NARCUSR", "CNTLON", "SRVON"]


def test_open_session_retries_cntlon_after_a_lost_reply(robot_emulator):
    robot_emulator.inject(Fault.NO_REPLY, when=is_cmd("CNTLON"))
    with MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT) as r:
        assert r.state().control_on
    assert commands(robot_emulator).count("CNTLON") == 2


def test_open_session_gives_up_after_bounded_retries(robot_emulator):
    robot_emulator.inject(Fault.NO_REPLY, times=10, when=is_cmd("OPEN="))
    t = time.monotonic()
    with pytest.raises(DeviceTimeout, match="3 attempts"):
        with MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT):
            pass
    assert time.monotonic() - t < 3.0  # 3 attempts × 0.3 s
    assert commands(robot_emulator) == ["OPEN=NARCUSR"] * 3


def test_a_refused_open_is_not_retried(robot_emulator):
    robot_emulator.inject(Fault.DEVICE_ERROR, when=is_cmd("OPEN="))
    with pytest.raises(DeviceFault, match="4002"):
        with MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT):
            pass
    assert commands(robot_emulator).count("OPEN=NARCUSR") == 1


class _RecordingLink:
    """Stands in for the serial link: records what is written, answers every request QoK."""

    def __init__(self):
        self.written = []

    def discard_input(self):
        pass

    def write(self, frame):
        self.written.append(frame)

    def deadline(self):
        return 0.0

    def read_until(self, terminator, deadline, *, what):
        return b"QoK\r"


def _recording_robot():
    r = MelfaRobot.__new__(MelfaRobot)  # no port: the link is the recorder
    r.config, r.limits, r.alarm_active, r._link = FAST_ROBOT, CellLimits(), False, _RecordingLink()
    return r


_PREFIXES = [
    "EXEC",
    "EXECSPD",
    "OVRD",
    "RUN",
    "JOG",
    "MOV",
    "MVS",
    "PRG",
    "HND",
    "SRV",
    "CNTL",
    "OPEN=",
    "STOP",
    "PPOSF",
]


@settings(max_examples=400, deadline=None)
@given(
    st.one_of(
        st.text(max_size=40),
        st.tuples(st.sampled_from(_PREFIXES), st.text(max_size=12)).map("".join),
        st.sampled_from(list(SAFE_COMMANDS)).map(lambda name: name.replace("<n>", "1").replace("<client>", "X")),
    )
)
def test_command_sends_exactly_the_allowlisted_commands_and_nothing_else(cmd):
    r = _recording_robot()
    try:
        r.command(cmd)
    except (SafetyError, InvalidInputError):
        assert r._link.written == [], f"{cmd!r} was refused but something was sent"
        return
    assert any(re.fullmatch(pattern, cmd) for pattern, _ in SAFE_COMMANDS.values()), f"{cmd!r} passed"
    assert not cmd.startswith(("EXEC", "OVRD", "RUN", "JOG", "MOV", "MVS", "HND", "PRG"))
    assert r._link.written == [encode_command(cmd)]
