"""Universal Robots' Real-Time Data Exchange (RTDE, TCP port 30004), protocol version 2: the
package codec shared by the driver (:mod:`binpick.devices.ur`) and the emulator
(:mod:`binpick.devices.emulators.ur`).

A package is ``size`` (uint16, big-endian, the whole package with this header), ``type``
(uint8, an ASCII letter), then the payload:

==========  ====  =========================================================================
package     type  payload (client → controller; controller → client)
==========  ====  =========================================================================
protocol    V     uint16 version; uint8 accepted
version     v     (none); uint32 major, minor, bugfix, build
text        M     uint8 length, message, uint8 length, source, uint8 warning level
outputs     O     float64 frequency, names comma-separated; uint8 recipe id, types comma-separated
inputs      I     names comma-separated; uint8 recipe id, types comma-separated
start       S     (none); uint8 accepted
pause       P     (none); uint8 accepted
data        U     uint8 recipe id, then each variable of the recipe, big-endian
==========  ====  =========================================================================

A variable the controller does not have is typed ``NOT_FOUND`` in the reply; an input another
client already writes is ``IN_USE``.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import ProtocolError, TruncatedReplyError
from ..transforms import rotation_about, rotation_vector

__all__ = [
    "PROTOCOL_VERSION",
    "TYPES",
    "variable_type",
    "encode",
    "split_package",
    "pack_data",
    "unpack_data",
    "MAX_PACKAGE",
    "ur_pose",
    "transform_from_ur_pose",
]

PROTOCOL_VERSION = 2
#: Largest package either side sends, bytes (the size field is 16 bits).
MAX_PACKAGE = 0xFFFF

#: The struct format of each RTDE type (big-endian, without the byte order mark).
TYPES = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}

#: The controller's outputs (version 5.x), by name → type.
_OUTPUTS = {
    "timestamp": "DOUBLE",
    **{
        n: "VECTOR6D"
        for n in (
            "target_q",
            "target_qd",
            "target_qdd",
            "target_current",
            "target_moment",
            "actual_q",
            "actual_qd",
            "actual_current",
            "actual_current_window",
            "joint_control_output",
            "actual_TCP_pose",
            "actual_TCP_speed",
            "actual_TCP_force",
            "target_TCP_pose",
            "target_TCP_speed",
            "joint_temperatures",
            "actual_joint_voltage",
            "payload_inertia",
            "ft_raw_wrench",
            "actual_current_as_torque",
            "joint_position_deviation_ratio",
        )
    },
    **{
        n: "DOUBLE"
        for n in (
            "actual_execution_time",
            "speed_scaling",
            "target_speed_fraction",
            "actual_momentum",
            "actual_main_voltage",
            "actual_robot_voltage",
            "actual_robot_current",
            "standard_analog_input0",
            "standard_analog_input1",
            "standard_analog_output0",
            "standard_analog_output1",
            "io_current",
            "euromap67_24V_voltage",
            "euromap67_24V_current",
            "tool_analog_input0",
            "tool_analog_input1",
            "tool_output_current",
            "tool_temperature",
            "tcp_force_scalar",
            "payload",
            "collision_detection_ratio",
            "target_speed_fraction_limit",
        )
    },
    **{
        n: "UINT32"
        for n in (
            "runtime_state",
            "robot_status_bits",
            "safety_status_bits",
            "analog_io_types",
            "euromap67_input_bits",
            "euromap67_output_bits",
            "tool_mode",
            "tool_analog_input_types",
            "output_bit_registers0_to_31",
            "output_bit_registers32_to_63",
            "script_control_line",
            "time_scale_source",
            "input_bit_registers0_to_31",
            "input_bit_registers32_to_63",
        )
    },
    "actual_digital_input_bits": "UINT64",
    "actual_digital_output_bits": "UINT64",
    "robot_mode": "INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "tool_output_voltage": "INT32",
    "joint_mode": "VECTOR6INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "payload_cog": "VECTOR3D",
    "tool_output_mode": "UINT8",
    "tool_digital_output0_mode": "UINT8",
    "tool_digital_output1_mode": "UINT8",
}
#: The general-purpose registers: output_/input_ + bit (64–127), int (0–47) or double (0–47).
_REGISTER = re.compile(r"(output|input)_(bit|int|double)_register_(\d+)")
#: The inputs a client may write besides the registers.
_INPUTS = {
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
}


def variable_type(name: str, *, output: bool = True) -> str:
    """The RTDE type of a controller output (``output``) or input, or ``NOT_FOUND``."""
    m = _REGISTER.fullmatch(name)
    if m is not None:
        index, kind = int(m.group(3)), m.group(2)
        ok = 64 <= index <= 127 if kind == "bit" else 0 <= index <= 47
        return {"bit": "BOOL", "int": "INT32", "double": "DOUBLE"}[kind] if ok else "NOT_FOUND"
    table = _OUTPUTS if output else _INPUTS
    return table.get(name, "NOT_FOUND")


def encode(kind: str, payload: bytes = b"") -> bytes:
    """One package of type ``kind`` (a letter) around ``payload``."""
    size = 3 + len(payload)
    if size > MAX_PACKAGE:
        raise ProtocolError(f"an RTDE package holds at most {MAX_PACKAGE} bytes, not {size}")
    return struct.pack(">HB", size, ord(kind)) + payload


def split_package(buffer: bytes) -> tuple[Any, bytes]:
    """``((kind, payload), rest)`` for the first whole package in ``buffer``, or ``(None,
    buffer)`` while it is incomplete; ProtocolError for a size below the header's."""
    if len(buffer) < 3:
        return None, buffer
    size, kind = struct.unpack_from(">HB", buffer)
    if size < 3:
        raise ProtocolError(f"an RTDE package of {size} bytes is shorter than its header")
    if len(buffer) < size:
        return None, buffer
    return (chr(kind), bytes(buffer[3:size])), bytes(buffer[size:])


def _format(types: Sequence[str]) -> str:
    try:
        return ">" + "".join(TYPES[t] for t in types)
    except KeyError as exc:
        raise ProtocolError(f"RTDE type {exc.args[0]!r} is not one binpick reads") from None


def pack_data(recipe_id: int, types: Sequence[str], values: Sequence[Any]) -> bytes:
    """A data package (U) of ``values`` in the order and ``types`` of a recipe."""
    flat: list[Any] = []
    for t, v in zip(types, values):
        flat.extend(v if t.startswith("VECTOR") else [v])
    return encode("U", struct.pack(">B", recipe_id) + struct.pack(_format(types), *flat))


def unpack_data(payload: bytes, types: Sequence[str]) -> tuple[int, list[Any]]:
    """``(recipe id, values)`` of a data package's payload; TruncatedReplyError when it is short."""
    fmt = _format(types)
    if len(payload) != 1 + struct.calcsize(fmt):
        raise TruncatedReplyError(
            f"an RTDE data package of {len(payload)} bytes does not hold its recipe's {1 + struct.calcsize(fmt)}"
        )
    flat = list(struct.unpack_from(fmt, payload, 1))
    out: list[Any] = []
    for t in types:
        n = int(TYPES[t][0]) if TYPES[t][0].isdigit() else 1
        out.append(tuple(flat[:n]) if t.startswith("VECTOR") else flat[0])
        del flat[:n]
    return payload[0], out


def ur_pose(T: Any) -> tuple[float, ...]:
    """A pose (4×4, mm) as UR's controller carries it in RTDE and URScript: x, y, z in metres and
    the rotation vector in radians."""
    T = np.asarray(T, dtype=np.float64)
    return (*(T[:3, 3] / 1000.0), *rotation_vector(T[:3, :3]))


def transform_from_ur_pose(v: Any) -> np.ndarray:
    """The 4×4 pose (mm) of UR's six numbers (:func:`ur_pose`'s inverse)."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(v[:3], dtype=np.float64) * 1000.0
    angle = float(np.linalg.norm(v[3:6]))
    if angle > 1e-12:
        T[:3, :3] = rotation_about(v[3:6], angle)
    return T
