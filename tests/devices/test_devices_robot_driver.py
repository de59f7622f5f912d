"""The real MELFA driver over a pty against the R3 controller emulator, with every fault injected."""

import math
import time
from dataclasses import replace

import numpy as np
import pytest
from device_settings import FAST_ROBOT

from binpick.devices import MelfaConfig, MelfaHandGripper, MelfaRobot, SerialSettings
from binpick.devices.emulators import Fault, RobotEmulator, RobotEmulatorConfig
from binpick.devices.emulators.robot import ArmModel
from binpick.devices.xyzabc import transform_from_xyzabc
from binpick.errors import (
    DeviceFault,
    DeviceTimeout,
    InvalidInputError,
    PortClosedError,
    ProtocolError,
    SafetyError,
    TruncatedReplyError,
    UnknownReplyError,
)


def down(x, y, z):
    return transform_from_xyzabc([x, y, z, math.pi, 0, math.pi])


def commands(emulator):
    return [r.split(";", 2)[2] for r in emulator.requests]


def is_cmd(prefix):
    return lambda request: request.split(";", 2)[-1].startswith(prefix)


def test_session_opens_and_closes_in_order(robot_emulator):
    with MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT):
        pass
    sent = commands(robot_emulator)
    assert sent[:3] == ["OPEN=NARCUSR", "CNTLON", "SRVON"]
    assert "OVRD=50" in sent and "EXECSPD 200.00" in sent
    assert sent[-3:] == ["SRVOFF", "CNTLOFF", "CLOSE"]


def test_reads_home_pose_and_joints(robot):
    T = robot.read_pose()
    np.testing.assert_allclose(T[:3, 3], [160, 0, 478], atol=0.01)
    np.testing.assert_allclose(T[:3, :3], np.diag([-1.0, 1.0, -1.0]), atol=1e-6)
    np.testing.assert_allclose(np.degrees(robot.read_joints()), [0, 0, 90, 0, 90, 0], atol=0.01)
    st = robot.state()
    assert st.control_on and st.servo_on and not st.moving and st.error_number == 0


def test_joint_then_linear_moves_arrive(robot, robot_emulator):
    robot.move_to(down(300, 50, 300))
    np.testing.assert_allclose(robot.read_pose()[:3, 3], [300, 50, 300], atol=0.02)
    robot.move_to(down(300, 50, 120), linear=True)
    np.testing.assert_allclose(robot_emulator.pose()[:3, 3], [300, 50, 120], atol=0.02)
    sent = commands(robot_emulator)
    assert "EXECP1=(300.00,50.00,300.00,180.00,0.00,180.00)(7,0)" in sent
    assert sent.count("EXECMOV P1") == 1 and sent.count("EXECMVS P1") == 1


def test_moving_takes_time_and_wait_false_returns_at_once(robot, robot_emulator):
    robot.set_override(5)
    robot.move_to(down(300, 0, 300), wait=False)
    assert robot.state().moving and robot_emulator.is_moving()
    robot.wait_until_idle()
    assert not robot_emulator.is_moving()


def test_unsafe_motion_sends_nothing(robot, robot_emulator):
    before = len(robot_emulator.requests)
    with pytest.raises(SafetyError):
        robot.move_to(down(600, 0, 300))  # outside the box
    with pytest.raises(SafetyError):
        robot.set_override(90)
    with pytest.raises(SafetyError):
        robot.set_linear_speed(1000)
    with pytest.raises(SafetyError):
        robot.move_sequence([down(300, 0, 300), down(300, 0, 100), down(200, 0, 100)], linear=True)
    with pytest.raises(SafetyError):
        robot.command("EXECMOV P1")
    with pytest.raises(SafetyError):
        robot.command("OVRD=100")
    sent = commands(robot_emulator)[before:]
    assert not any(c.startswith(("EXECM", "OVRD", "EXECP", "EXECSPD")) for c in sent)


def test_joint_move_into_the_bin_sends_no_motion(robot, robot_emulator):
    with pytest.raises(SafetyError, match="joint move"):
        robot.move_to(down(300, 0, 150))
    assert not any(c.startswith("EXECM") for c in commands(robot_emulator))


def test_controller_refusal_carries_error_text(robot):
    # inside the cell's box, but beyond the arm's reach: the controller refuses
    with pytest.raises(DeviceFault, match="out of the arm's reach") as info:
        robot.move_to(down(420, 0, 320))
    assert info.value.error_number == 3002


def test_joint_limits_enforced_by_the_controller():
    arm = ArmModel(joint_min_deg=(-10, -60, -30, -160, -120, -360), joint_max_deg=(10, 120, 160, 160, 120, 360))
    with RobotEmulator(config=RobotEmulatorConfig(arm=arm, speed_scale=40)) as emu:
        with MelfaRobot(emu.slave_path, config=FAST_ROBOT) as r:
            with pytest.raises(DeviceFault, match="Joint limit"):
                r.move_to(down(300, 150, 300))
            assert "STOP" in commands(emu)


def test_j6_stays_continuous_through_half_a_turn():
    # J6 turns ±360°: a pose just past J6 = 180° is reached by turning on to 181°, not by
    # unwinding a whole turn to -179° (as the controller keeps it through a straight move).
    arm = ArmModel()
    q = np.radians([10.0, 20.0, 100.0, 5.0, 60.0, 179.0])
    on = q.copy()
    on[5] = math.radians(181.0)
    np.testing.assert_allclose(np.degrees(arm.inverse(arm.forward(on), 7, q)), np.degrees(on), atol=1e-6)
    back = q.copy()
    back[5] = math.radians(-179.0)
    np.testing.assert_allclose(np.degrees(arm.inverse(arm.forward(back), 7, back)), np.degrees(back), atol=1e-6)
    at_limit = q.copy()
    at_limit[5] = math.radians(359.0)  # 361° is past the +360° limit: the nearest turn within it
    got = arm.inverse(arm.forward(np.radians([10.0, 20.0, 100.0, 5.0, 60.0, 1.0])), 7, at_limit)
    assert math.degrees(got[5]) == pytest.approx(1.0, abs=1e-6)


def test_operation_range_enforced_by_the_controller():
    arm = ArmModel(workspace_min_mm=(-450, -450, 180), workspace_max_mm=(450, 450, 750))
    with RobotEmulator(config=RobotEmulatorConfig(arm=arm, speed_scale=40)) as emu:
        with MelfaRobot(emu.slave_path, config=FAST_ROBOT) as r:
            r.move_to(down(300, 0, 250))
            with pytest.raises(DeviceFault, match="operation range") as info:
                r.move_to(down(300, 0, 150), linear=True)
            assert info.value.error_number == 3005
            np.testing.assert_allclose(r.read_pose()[:3, 3], [300, 0, 250], atol=0.02)


def test_config_is_validated():
    with pytest.raises(InvalidInputError, match="client_name"):
        MelfaConfig(client_name="A;B")
    with pytest.raises(InvalidInputError, match="parity"):
        SerialSettings(parity="X")
    with pytest.raises(InvalidInputError, match="stopbits"):
        SerialSettings(stopbits=3)


def test_commands_need_operation_rights(robot_emulator):
    r = MelfaRobot(robot_emulator.slave_path, config=FAST_ROBOT)
    try:
        with pytest.raises(DeviceFault, match="not opened"):
            r.command("SRVON")
        r.command("OPEN=NARCUSR")
        with pytest.raises(DeviceFault, match="Operation rights"):
            r.command("SRVON")
    finally:
        r.close()


def test_hand_open_close(robot, robot_emulator):
    robot.open_hand(1)
    assert robot_emulator.hands[1] is True
    robot.close_hand(1)
    assert robot_emulator.hands[1] is False
    g = MelfaHandGripper(robot, hand=2, settle_s=0.0)
    g.open()
    assert robot_emulator.hands[2] is True
    assert g.close() is None and robot_emulator.hands[2] is False


# ----------------------------------------------------------------------------- faults


def test_lost_reply_to_a_query_is_retried(robot, robot_emulator):
    robot_emulator.inject(Fault.NO_REPLY, when=is_cmd("PPOSF"))
    np.testing.assert_allclose(robot.read_pose()[:3, 3], [160, 0, 478], atol=0.01)
    assert commands(robot_emulator).count("PPOSF") == 2


def test_query_gives_up_after_bounded_retries(robot, robot_emulator):
    robot_emulator.inject(Fault.NO_REPLY, times=10, when=is_cmd("JPOSF"))
    t = time.monotonic()
    with pytest.raises(DeviceTimeout, match="3 attempts"):
        robot.read_joints()
    assert time.monotonic() - t < 3.0  # 3 attempts × 0.3 s, never more
    assert commands(robot_emulator).count("JPOSF") == 3


@pytest.mark.parametrize(
    "fault,error",
    [(Fault.GARBLED, ProtocolError), (Fault.PARTIAL, TruncatedReplyError), (Fault.UNKNOWN_REPLY, UnknownReplyError)],
)
def test_bad_replies_raise_their_class(robot, robot_emulator, fault, error):
    robot_emulator.inject(fault, times=3, when=is_cmd("DSTATE"))
    with pytest.raises(error):
        robot.state()
    robot_emulator.clear_faults()
    assert not robot.state().moving  # the link recovers


def test_late_reply_times_out_then_recovers(robot_emulator):
    config = replace(FAST_ROBOT, serial=replace(FAST_ROBOT.serial, retries=0, timeout_s=0.15))
    with MelfaRobot(robot_emulator.slave_path, config=config) as r:
        robot_emulator.inject(Fault.DELAY, when=is_cmd("PPOSF"), delay_s=0.5)
        t = time.monotonic()
        with pytest.raises(DeviceTimeout):
            r.read_pose()
        assert time.monotonic() - t < 0.45
        time.sleep(0.5)  # the late reply arrives and is dropped before the next request
        np.testing.assert_allclose(np.degrees(r.read_joints()), [0, 0, 90, 0, 90, 0], atol=0.01)


def test_late_reply_to_a_retried_query_keeps_the_link_in_step(robot, robot_emulator):
    robot_emulator.inject(Fault.DELAY, when=is_cmd("JPOSF"), delay_s=0.4)
    np.testing.assert_allclose(np.degrees(robot.read_joints()), [0, 0, 90, 0, 90, 0], atol=0.01)
    np.testing.assert_allclose(robot.read_pose()[:3, 3], [160, 0, 478], atol=0.01)
    assert not robot.state().moving


def test_device_error_is_a_fault_with_its_text(robot, robot_emulator):
    robot_emulator.inject(Fault.DEVICE_ERROR, when=is_cmd("HNDON"))
    with pytest.raises(DeviceFault, match="4002: Controller internal error"):
        robot.open_hand()


def test_port_disappearing(robot, robot_emulator):
    robot_emulator.inject(Fault.CLOSE_PORT, when=is_cmd("PPOSF"))
    with pytest.raises(PortClosedError):
        robot.read_pose()
    with pytest.raises(PortClosedError):
        robot.state()


def test_lost_motion_reply_is_not_resent_and_the_arm_is_stopped(robot, robot_emulator):
    robot.set_override(5)
    robot_emulator.inject(Fault.NO_REPLY, when=is_cmd("EXECMOV"))
    with pytest.raises(DeviceTimeout, match="STOP sent"):
        robot.move_to(down(300, 0, 300))
    sent = commands(robot_emulator)
    assert sent.count("EXECMOV P1") == 1
    assert sent[-1] == "STOP"
    assert not robot_emulator.is_moving()


def test_fault_mid_sequence_stops_and_skips_the_rest(robot, robot_emulator):
    targets = [down(300, 0, 300), down(300, 0, 150), down(300, 0, 300), down(250, 100, 300)]
    robot_emulator.inject(Fault.NO_REPLY, when=is_cmd("EXECMVS"))
    with pytest.raises(DeviceTimeout, match="step 2 of 4.*STOP sent"):
        robot.move_sequence(targets, linear=[False, True, True, False])
    sent = commands(robot_emulator)
    assert sent.count("EXECMOV P1") == 1 and sent.count("EXECMVS P1") == 1
    assert "STOP" in sent
    assert not robot_emulator.is_moving()


def test_alarm_during_motion_is_reported_and_stopped(robot, robot_emulator):
    robot_emulator.inject_motion_alarm(at_fraction=0.4)
    with pytest.raises(DeviceFault, match="4001: Collision detected.*STOP sent"):
        robot.move_to(down(300, 0, 300))
    assert robot_emulator.alarm == 4001
    assert not np.allclose(robot_emulator.pose()[:3, 3], [300, 0, 300], atol=1.0)
    with pytest.raises(DeviceFault, match="Alarm active"):
        robot.move_to(down(300, 0, 300))
    robot.reset_alarm()
    robot.move_to(down(300, 0, 300))
    np.testing.assert_allclose(robot.read_pose()[:3, 3], [300, 0, 300], atol=0.02)


def test_bad_port_path_is_a_clear_error():
    with pytest.raises(PortClosedError, match="cannot open serial port"):
        MelfaRobot("/dev/does-not-exist-binpick", config=FAST_ROBOT)


def test_limits_and_config_types_are_checked(robot_emulator):
    with pytest.raises(Exception, match="CellLimits"):
        MelfaRobot(robot_emulator.slave_path, limits={"x": 1})
