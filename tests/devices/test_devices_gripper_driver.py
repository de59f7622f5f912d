"""The real Modbus RTU gripper driver over a pty against the gripper emulator."""

import time

import pytest

from binpick.devices.emulators import Fault
from binpick.devices.gripper import FC_WRITE_MULTIPLE
from binpick.errors import (
    ChecksumError,
    DeviceFault,
    DeviceTimeout,
    PortClosedError,
    ProtocolError,
    SafetyError,
    TruncatedReplyError,
    UnknownReplyError,
)

writes = lambda frame: frame[1] == FC_WRITE_MULTIPLE  # noqa: E731
reads = lambda frame: frame[1] == 0x04  # noqa: E731


def test_activate_open_close_on_air(gripper, gripper_emulator):
    st = gripper.activate()
    assert st.activated
    gripper.open()
    assert gripper.status().position == 0
    assert gripper.close() is False  # nothing between the fingers
    assert gripper.status().position == 255 and gripper.status().object_state == 3


def test_close_on_an_object_reports_holding(gripper, gripper_emulator):
    gripper.activate()
    gripper.open()
    gripper_emulator.object_at = 140
    assert gripper.close() is True
    st = gripper.status()
    assert st.holding and st.object_state == 2 and st.position == 140


def test_width_maps_to_position(gripper, gripper_emulator):
    gripper.activate()
    st = gripper.move_to_width(42.5)
    assert st.position_request == 128 and st.position == 128


def test_command_before_activation_is_a_fault(gripper):
    with pytest.raises(DeviceFault, match="activation must complete"):
        gripper.close()


def test_limits_send_nothing(gripper, gripper_emulator):
    before = len(gripper_emulator.requests)
    with pytest.raises(SafetyError):
        gripper.move_to_width(10, force=255)
    assert len(gripper_emulator.requests) == before


@pytest.mark.parametrize(
    "fault,error",
    [
        (Fault.NO_REPLY, DeviceTimeout),
        (Fault.GARBLED, ProtocolError),
        (Fault.PARTIAL, TruncatedReplyError),
        (Fault.BAD_CRC, ChecksumError),
        (Fault.UNKNOWN_REPLY, UnknownReplyError),
    ],
)
def test_status_faults_after_bounded_retries(gripper, gripper_emulator, fault, error):
    gripper_emulator.inject(fault, times=10, when=reads)
    t = time.monotonic()
    with pytest.raises(error, match="3 attempts"):
        gripper.status()
    assert time.monotonic() - t < 2.0  # 3 attempts × 0.1 s, never more


def test_device_exception_is_a_fault(gripper, gripper_emulator):
    gripper_emulator.inject(Fault.DEVICE_ERROR, when=reads)
    with pytest.raises(DeviceFault, match="slave device failure"):
        gripper.status()


def test_lost_command_reply_is_checked_not_resent(gripper, gripper_emulator):
    gripper.activate()
    gripper_emulator.inject(Fault.NO_REPLY, when=writes)
    assert gripper.close() is False
    assert sum(map(writes, gripper_emulator.requests)) == 3  # reset, activate, close: each once


def test_command_that_never_arrived_is_reported(gripper, gripper_emulator):
    gripper.activate()
    gripper_emulator.inject(Fault.IGNORED, when=writes)
    with pytest.raises(DeviceTimeout, match="not taken"):
        gripper.close()
    assert sum(map(writes, gripper_emulator.requests)) == 3


def test_port_disappearing(gripper, gripper_emulator):
    gripper_emulator.inject(Fault.CLOSE_PORT)
    with pytest.raises(PortClosedError):
        gripper.status()
