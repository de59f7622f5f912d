"""The real laser-motor drivers over ptys: Dynamixel Protocol 2.0 (default) and the AI motor."""

import errno
import math
import struct
import termios
import time

import pytest

from binpick.devices import DynamixelConfig, DynamixelMotor, MotorRange, SerialSettings
from binpick.devices.dynamixel import ADDR_GOAL_POSITION, INST_READ, INST_WRITE, decode_status, encode_ping
from binpick.devices.emulators import DynamixelEmulator, DynamixelEmulatorConfig, Fault
from binpick.errors import (
    ChecksumError,
    DeviceFault,
    DeviceTimeout,
    InvalidInputError,
    PortClosedError,
    ProtocolError,
    SafetyError,
    TruncatedReplyError,
    UnknownReplyError,
)

reads = lambda p: getattr(p, "instruction", None) == INST_READ  # noqa: E731
writes = lambda p: getattr(p, "instruction", None) == INST_WRITE  # noqa: E731


def test_ping_enable_move(dxl_motor, dxl_emulator):
    assert dxl_motor.ping() == 1020
    dxl_motor.enable()
    assert dxl_emulator.torque_enabled
    reached = dxl_motor.move_to(0.8)
    assert reached == pytest.approx(0.8, abs=math.radians(0.5))
    assert dxl_emulator.present_position() == pytest.approx(2048 + 0.8 / (2 * math.pi) * 4096, abs=1)
    assert dxl_motor.read_goal_angle() == pytest.approx(0.8, abs=2e-3)
    assert not dxl_motor.is_moving()


def test_motion_takes_time(dxl_motor, dxl_emulator):
    dxl_motor.enable()
    t = time.monotonic()
    dxl_motor.move_to(-1.5, wait=False)
    assert dxl_motor.is_moving()
    dxl_motor.wait_until_reached()
    assert time.monotonic() - t > 1.5 / 30.0 * 0.8  # speed limit 30 rad/s sent as profile velocity


def test_torque_off_holds_still(dxl_motor, dxl_emulator):
    dxl_motor.disable()
    dxl_motor.move_to(0.5, wait=False)
    with pytest.raises(DeviceTimeout, match="still at"):
        dxl_motor.wait_until_reached(timeout_s=0.1)
    assert dxl_emulator.present_position() == 2048


def test_goal_outside_range_sends_nothing(dxl_motor, dxl_emulator):
    before = len(dxl_emulator.requests)
    with pytest.raises(SafetyError, match="outside the allowed range"):
        dxl_motor.move_to(2.0)
    with pytest.raises(InvalidInputError):
        dxl_motor.move_to(float("nan"))
    assert len(dxl_emulator.requests) == before


def test_motor_refuses_goal_beyond_its_own_limit():
    with DynamixelEmulator(config=DynamixelEmulatorConfig(min_position=1500, max_position=2600)) as emu:
        m = DynamixelMotor(
            emu.slave_path, config=DynamixelConfig(serial=SerialSettings(baudrate=57600, timeout_s=0.05))
        )
        try:
            m.enable()
            with pytest.raises(DeviceFault, match="data limit error"):
                m.move_to(-1.4)
        finally:
            m.close()
        assert emu.failures == []


def test_eeprom_write_with_torque_on_is_an_access_error(dxl_motor):
    dxl_motor.enable()
    with pytest.raises(DeviceFault, match="access error"):
        dxl_motor.bus.write(1, 8, b"\x03")  # baud rate lives in EEPROM


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
def test_read_faults_after_bounded_retries(dxl_motor, dxl_emulator, fault, error):
    dxl_emulator.inject(fault, times=10, when=reads)
    t = time.monotonic()
    with pytest.raises(error, match="3 attempts"):
        dxl_motor.present_angle()
    assert time.monotonic() - t < 2.0  # 3 attempts × 0.1 s, never more
    assert sum(map(reads, dxl_emulator.requests)) == 3


@pytest.mark.parametrize("fault", [Fault.NO_REPLY, Fault.GARBLED, Fault.PARTIAL, Fault.BAD_CRC, Fault.UNKNOWN_REPLY])
def test_one_bad_read_is_retried(dxl_motor, dxl_emulator, fault):
    dxl_emulator.inject(fault, when=reads)
    assert dxl_motor.present_angle() == pytest.approx(0.0)


def test_device_error_is_a_fault_not_retried(dxl_motor, dxl_emulator):
    dxl_emulator.inject(Fault.DEVICE_ERROR, when=reads)
    with pytest.raises(DeviceFault, match="result fail"):
        dxl_motor.present_angle()
    assert sum(map(reads, dxl_emulator.requests)) == 1


def test_lost_write_status_is_checked_by_reading_back_not_by_resending(dxl_motor, dxl_emulator):
    dxl_motor.enable()
    dxl_emulator.inject(Fault.NO_REPLY, when=writes)
    dxl_motor.move_to(0.3)
    goal_writes = [
        p for p in dxl_emulator.requests if writes(p) and struct.unpack_from("<H", p.params)[0] == ADDR_GOAL_POSITION
    ]
    assert len(goal_writes) == 1


def test_write_that_was_not_taken_is_reported_not_resent(dxl_motor, dxl_emulator):
    dxl_motor.enable()
    dxl_emulator.inject(Fault.IGNORED, when=writes)  # the goal write never arrives
    with pytest.raises(DeviceTimeout, match="not the written"):
        dxl_motor.move_to(0.2)
    goal_writes = [
        p for p in dxl_emulator.requests if writes(p) and struct.unpack_from("<H", p.params)[0] == ADDR_GOAL_POSITION
    ]
    assert len(goal_writes) == 1
    assert dxl_emulator.present_position() == 2048


def test_garbled_write_status_is_accepted_after_read_back(dxl_motor, dxl_emulator):
    dxl_motor.enable()
    dxl_emulator.inject(Fault.GARBLED, when=writes)
    dxl_motor.move_to(0.2)
    assert dxl_motor.read_goal_angle() == pytest.approx(0.2, abs=2e-3)


def test_request_with_bad_crc_gets_crc_error_status(dxl_motor):
    packet = encode_ping(1)
    dxl_motor.bus.link.write(packet[:-1] + bytes([packet[-1] ^ 1]))
    raw = dxl_motor.bus._read_raw(dxl_motor.bus.link.deadline())
    assert decode_status(raw).error_code == 3


def test_port_disappearing(dxl_motor, dxl_emulator):
    dxl_emulator.inject(Fault.CLOSE_PORT)
    with pytest.raises(PortClosedError):
        dxl_motor.ping()


def test_a_signal_interrupting_the_wait_for_a_write_to_drain_loses_nothing(dxl_motor, dxl_emulator):
    # A signal to the process (a child exiting, a profiler attaching: seen under py-spy) makes
    # tcdrain fail with EINTR after the bytes were written; the driver waits again.
    ser, real = dxl_motor.bus.link._ser, dxl_motor.bus.link._ser.flush
    interrupted = []

    def flush() -> None:
        if len(interrupted) < 3:
            interrupted.append(1)
            raise termios.error(errno.EINTR, "Interrupted system call")
        real()

    ser.flush = flush
    dxl_motor.enable()
    dxl_motor.move_to(math.radians(30.0))
    assert len(interrupted) == 3
    assert math.degrees(dxl_motor.present_angle()) == pytest.approx(30.0, abs=1.0)
    assert dxl_emulator.failures == []


def test_unknown_id_times_out(dxl_emulator):
    m = DynamixelMotor(
        dxl_emulator.slave_path,
        config=DynamixelConfig(motor_id=7, serial=SerialSettings(baudrate=57600, timeout_s=0.03, retries=1)),
    )
    try:
        with pytest.raises(DeviceTimeout, match="2 attempts"):
            m.ping()
    finally:
        m.close()


# ----------------------------------------------------------------------------- AI motor


def test_ai_motor_moves_and_reads(ai_motor, ai_emulator):
    assert ai_motor.ping() == 0
    assert ai_motor.present_angle() == pytest.approx(0.0)
    reached = ai_motor.move_to(math.radians(40))
    assert reached == pytest.approx(math.radians(40), abs=math.radians(1.5))
    assert not ai_emulator.passive
    ai_motor.disable()
    assert ai_emulator.passive


def test_ai_motor_requests_are_the_documented_frames(ai_motor, ai_emulator):
    ai_motor.move_to(0.0)
    assert ai_emulator.requests[0] == (0x40, 127)  # torque level 2, ID 0, centre position


@pytest.mark.parametrize(
    "fault,error",
    [(Fault.NO_REPLY, DeviceTimeout), (Fault.GARBLED, ProtocolError), (Fault.PARTIAL, TruncatedReplyError)],
)
def test_ai_motor_faults(ai_motor, ai_emulator, fault, error):
    ai_emulator.inject(fault, times=10)
    with pytest.raises(error):
        ai_motor.present_angle()


def test_ai_motor_position_command_is_not_resent(ai_motor, ai_emulator):
    ai_emulator.inject(Fault.NO_REPLY)
    with pytest.raises(DeviceTimeout):
        ai_motor.move_to(0.3)
    assert sum(1 for d1, _ in ai_emulator.requests if d1 >> 5 <= 4) == 1


def test_ai_motor_port_disappearing(ai_motor, ai_emulator):
    ai_emulator.inject(Fault.CLOSE_PORT)
    with pytest.raises(PortClosedError):
        ai_motor.present_angle()


def test_ai_motor_emulator_cannot_fake_a_crc(ai_emulator):
    with pytest.raises(InvalidInputError, match="cannot play BAD_CRC"):
        ai_emulator.inject(Fault.BAD_CRC)


def test_motor_range_validates():
    with pytest.raises(InvalidInputError, match="must exceed"):
        MotorRange(min_angle_rad=0.5, max_angle_rad=0.1)


def test_a_late_status_of_an_earlier_read_is_dropped_and_the_read_sent_again():
    # A loaded machine: the status of an earlier read (2 bytes, the Moving flags) arrives after the
    # driver gave up on it, just when the next read (4 bytes) waits. A status carries no
    # instruction: its length is what tells it apart. The driver drops it and sends the read again.
    # The device is played here, byte for byte, on a real pty.
    import os
    import select
    import threading
    import tty

    from binpick.devices.dynamixel import INST_STATUS, DynamixelBus, encode_packet

    master, slave = os.openpty()
    tty.setraw(slave)
    bus = DynamixelBus(os.ttyname(slave), settings=SerialSettings(baudrate=57600, timeout_s=0.5))
    got: list = []

    def read() -> None:
        try:
            got.append(bus.read(1, 132, 4))
        except ProtocolError as exc:
            got.append(exc)

    reader = threading.Thread(target=read)
    reader.start()
    late = encode_packet(1, INST_STATUS, b"\x00\x01\x00")
    answer = encode_packet(1, INST_STATUS, b"\x00\x10\x08\x00\x00")
    try:
        requests = []
        for reply in (late, answer):  # first the late 2-byte status, then, to the read sent again, its answer
            ready, _, _ = select.select([master], [], [], 2.0)
            assert ready, f"the driver sent no request {len(requests) + 1} (it gave up: {got})"
            requests.append(os.read(master, 64))
            os.write(master, reply)
        reader.join(timeout=5)
        assert got == [b"\x10\x08\x00\x00"]
        assert len(requests) == 2 and requests[0] == requests[1]  # the same read, sent twice
    finally:
        reader.join(timeout=5)
        bus.close()
        os.close(master)
        os.close(slave)
