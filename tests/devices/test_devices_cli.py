"""``emulate_main``: one emulator alone, its pty path on the first line, served until Ctrl-C."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import binpick
from binpick.devices import DynamixelConfig, DynamixelMotor, MelfaConfig, MelfaRobot, SerialSettings
from binpick.devices.cli import emulate_main

PYTHON_ROOT = str(Path(binpick.__file__).resolve().parent.parent)


def _start(*args):
    env = dict(os.environ, PYTHONPATH=PYTHON_ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    code = f"import sys; from binpick.devices.cli import emulate_main; sys.exit(emulate_main({list(args)!r}))"
    return subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True
    )


def _stop(proc):
    proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()


def test_emulate_motor_serves_a_driver_until_ctrl_c():
    proc = _start("motor")
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/")
        motor = DynamixelMotor(path, config=DynamixelConfig(serial=SerialSettings(baudrate=57600, timeout_s=0.5)))
        try:
            assert motor.ping() == 1020
        finally:
            motor.close()
    finally:
        assert _stop(proc) == 0


def test_emulate_robot_serves_a_driver_until_ctrl_c():
    proc = _start("robot", "--speed-scale", "50")
    try:
        path = proc.stdout.readline().strip()
        with MelfaRobot(path, config=MelfaConfig(serial=SerialSettings(parity="E", stopbits=2, timeout_s=0.5))) as r:
            assert r.state().servo_on
    finally:
        assert _stop(proc) == 0


def test_bad_arguments_exit_2(capsys):
    assert emulate_main(["toaster"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert emulate_main(["robot", "--speed-scale", "-1"]) == 2
    assert "speed_scale" in capsys.readouterr().err


def test_help_exits_0(capsys):
    assert emulate_main(["--help"]) == 0
    assert "pty" in capsys.readouterr().out
