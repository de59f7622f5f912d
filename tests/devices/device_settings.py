"""Driver settings the device tests share (a module of its own, not the conftest, so that its
names import without clashing with other folders' conftest modules)."""

from __future__ import annotations

from binpick.devices import MelfaConfig, SerialSettings

FAST_ROBOT = MelfaConfig(
    serial=SerialSettings(baudrate=9600, parity="E", stopbits=2, timeout_s=0.3, retries=2),
    initial_override_percent=50,
    initial_linear_speed_mm_s=200,
    poll_interval_s=0.005,
    motion_timeout_s=5.0,
)
