"""The twin camera's wire protocol: frames over a Unix-domain socket (version 1).

The digital twin (``binpick emulate cell``) serves its camera on ``DIR/camera.sock``; the pick
process reads it with :class:`binpick.cell.TwinCamera`. One connection carries any number of
request/reply exchanges, one at a time. All integers little-endian.

Request, 8 bytes::

    magic   4s  b"BPCQ"
    version u8  1
    op      u8  1 = FRAME: grab one frame as the camera sees the cell now;
                2 = DEPTH: one shot of the fixed 3-D camera (``emulate cell --camera fixed``);
                3 = WORLD: the twin's ground truth now (world.json's document, after the world
                settled: the parts in the bin, those removed, the gripper's collisions), for a
                rehearsal's report;
                4 = CLOCK: the twin's hardware time (a document ``{"clock_s": …}``, the seconds
                its emulated arm, laser motor, gripper and camera have taken), for a
                rehearsal's physical cycle time
    zero    u16 0

Reply header, :data:`HEADER_SIZE` (= 168) bytes, then ``length`` payload bytes::

    magic    4s   b"BPCR"
    version  u8   1
    status   u8   0 = a frame follows, 1 = an error: the payload is its UTF-8 message, 2 = a
                  document (WORLD): the payload is UTF-8 JSON, at most MAX_DOCUMENT_BYTES
    dtype    u8   1 = uint8 (a FRAME's BGR pixels), 2 = float32 (a DEPTH shot's organised X, Y, Z
                  in the camera's frame, mm, NaN at holes)
    channels u8   3
    height   u32  rows, px
    width    u32  columns, px
    frame    u64  the frame counter (the sensor noise of frame k is seeded with seed + k)
    angle    f64  the laser motor's actual angle when the frame was exposed, rad
    pose     16 f64  the flange's actual pose T_base_flange (row-major 4×4, mm)
    length   u64  payload bytes: height·width·channels·(1 or 4) for a frame or a shot, the message's for an error

Both sides check everything: the server answers a request it cannot read with an error reply
and closes; the client refuses a header whose magic, version, status, type, shape or length is
not what the protocol allows, or a payload that stops short (:class:`~binpick.errors.DeviceError`
subclasses naming what was wrong).
"""

from __future__ import annotations

import json
import socket
import struct
from dataclasses import dataclass

import numpy as np

from .._validate import MAX_IMAGE_PIXELS
from ..errors import DeviceTimeout, PortClosedError, ProtocolError, TruncatedReplyError

__all__ = [
    "PROTOCOL_VERSION",
    "OP_FRAME",
    "OP_DEPTH",
    "OP_WORLD",
    "OP_CLOCK",
    "HEADER_SIZE",
    "REQUEST_SIZE",
    "MAX_ERROR_BYTES",
    "Frame",
    "encode_request",
    "decode_request",
    "encode_frame",
    "encode_error",
    "encode_document",
    "request_document",
    "read_reply",
    "recv_exact",
    "connect",
    "request",
]

PROTOCOL_VERSION = 1
OP_FRAME = 1
OP_DEPTH = 2
OP_WORLD = 3
OP_CLOCK = 4
STATUS_FRAME = 0
STATUS_ERROR = 1
STATUS_DOCUMENT = 2
DTYPE_UINT8 = 1
DTYPE_FLOAT32 = 2
_ITEM_BYTES = {DTYPE_UINT8: 1, DTYPE_FLOAT32: 4}

_REQUEST = struct.Struct("<4sBBH")
_HEADER = struct.Struct("<4sBBBBIIQd16dQ")
REQUEST_SIZE = _REQUEST.size
HEADER_SIZE = _HEADER.size
REQUEST_MAGIC = b"BPCQ"
REPLY_MAGIC = b"BPCR"

#: Longest error message read, bytes.
MAX_ERROR_BYTES = 1 << 16
#: Longest document (WORLD) read, bytes: a bin of thousands of parts with their poses.
MAX_DOCUMENT_BYTES = 16 << 20


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame as the twin sent it: the image (uint8 BGR (H, W, 3); a depth shot's float32
    X, Y, Z (H, W, 3), mm, camera frame), its counter, and the laser angle (rad) and flange pose
    ``T_base_flange`` (mm) at exposure."""

    image: np.ndarray
    counter: int
    angle: float
    T_base_flange: np.ndarray


def encode_request(op: int = OP_FRAME) -> bytes:
    """A request of operation ``op``."""
    return _REQUEST.pack(REQUEST_MAGIC, PROTOCOL_VERSION, int(op), 0)


def decode_request(data: bytes) -> int:
    """The operation of a request; ProtocolError naming what is wrong with one this server cannot serve."""
    if len(data) != REQUEST_SIZE:
        raise ProtocolError(f"camera request: expected {REQUEST_SIZE} bytes, got {len(data)}")
    magic, version, op, zero = _REQUEST.unpack(data)
    if magic != REQUEST_MAGIC:
        raise ProtocolError(f"camera request: magic is {magic!r}, not {REQUEST_MAGIC!r}; not a binpick camera client")
    if version != PROTOCOL_VERSION:
        raise ProtocolError(f"camera request: protocol version {version}; this twin speaks version {PROTOCOL_VERSION}")
    if op not in (OP_FRAME, OP_DEPTH, OP_WORLD, OP_CLOCK) or zero != 0:
        raise ProtocolError(
            f"camera request: unknown operation {op} ({OP_FRAME} = FRAME, {OP_DEPTH} = DEPTH, {OP_WORLD} = WORLD, "
            f"{OP_CLOCK} = CLOCK)"
        )
    return op


def encode_frame(image: np.ndarray, counter: int, angle: float, T_base_flange: np.ndarray) -> bytes:
    """The reply carrying ``image`` (uint8 (H, W, 3), or a depth shot's float32 (H, W, 3)), header then data."""
    depth = np.asarray(image).dtype.kind == "f"
    img = np.ascontiguousarray(image, dtype="<f4" if depth else np.uint8)
    h, w, c = img.shape
    pose = np.asarray(T_base_flange, dtype=np.float64).reshape(16)
    dtype = DTYPE_FLOAT32 if depth else DTYPE_UINT8
    head = _HEADER.pack(
        REPLY_MAGIC, PROTOCOL_VERSION, STATUS_FRAME, dtype, c, h, w, int(counter), float(angle), *pose, img.nbytes
    )
    return head + img.tobytes()


def encode_error(message: str) -> bytes:
    """The reply carrying an error message (cut to :data:`MAX_ERROR_BYTES`)."""
    text = message.encode("utf-8", "replace")[:MAX_ERROR_BYTES]
    return (
        _HEADER.pack(REPLY_MAGIC, PROTOCOL_VERSION, STATUS_ERROR, 0, 0, 0, 0, 0, 0.0, *([0.0] * 16), len(text)) + text
    )


def encode_document(doc: dict) -> bytes:
    """The reply carrying a JSON document (WORLD)."""
    text = json.dumps(doc).encode("utf-8")
    if len(text) > MAX_DOCUMENT_BYTES:
        return encode_error(f"the document is {len(text)} bytes, more than the protocol's {MAX_DOCUMENT_BYTES}")
    return (
        _HEADER.pack(REPLY_MAGIC, PROTOCOL_VERSION, STATUS_DOCUMENT, 0, 0, 0, 0, 0, 0.0, *([0.0] * 16), len(text))
        + text
    )


def request_document(sock: socket.socket, op: int, path: str) -> dict:
    """Sends one request of operation ``op`` (WORLD) and reads its document reply; ProtocolError
    for anything else (the twin's error message, a frame, a document that is not a JSON object)."""
    where = f"camera {path}"
    try:
        sock.sendall(encode_request(op))
    except OSError as exc:
        raise PortClosedError(f"camera: cannot send to {path} ({exc}); is the twin still running?") from None
    head = recv_exact(sock, HEADER_SIZE, f"{where} reply header")
    magic, version, status, *_, length = _HEADER.unpack(head)
    if magic != REPLY_MAGIC or version != PROTOCOL_VERSION:
        raise ProtocolError(f"{where}: the reply is not a twin camera's (magic {magic!r}, version {version})")
    if status == STATUS_ERROR and length <= MAX_ERROR_BYTES:
        text = recv_exact(sock, length, f"{where} error message").decode("utf-8", "replace")
        raise ProtocolError(f"{where}: the twin refused: {text}")
    if status != STATUS_DOCUMENT or length > MAX_DOCUMENT_BYTES:
        raise ProtocolError(f"{where}: expected a document of at most {MAX_DOCUMENT_BYTES} bytes, got status {status}")
    try:
        doc = json.loads(bytes(recv_exact(sock, length, f"{where} document")).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProtocolError(f"{where}: the document is not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ProtocolError(f"{where}: the document is a {type(doc).__name__}, not a JSON object")
    return doc


def recv_exact(sock: socket.socket, n: int, what: str) -> bytearray:
    """Exactly ``n`` bytes from ``sock``: DeviceTimeout when none come within the socket's timeout,
    TruncatedReplyError when the peer stops part-way, PortClosedError when it hung up before any."""
    buf = bytearray()
    while len(buf) < n:
        try:
            chunk = sock.recv(min(n - len(buf), 1 << 20))
        except socket.timeout:
            if buf:
                raise TruncatedReplyError(
                    f"{what}: {len(buf)} of {n} bytes arrived, then nothing within {sock.gettimeout()} s"
                ) from None
            raise DeviceTimeout(f"{what}: no answer within {sock.gettimeout()} s; is the twin still running?") from None
        except OSError as exc:
            raise PortClosedError(f"{what}: the connection failed ({exc}); is the twin still running?") from None
        if not chunk:
            if buf:
                raise TruncatedReplyError(f"{what}: the twin hung up after {len(buf)} of {n} bytes")
            raise PortClosedError(f"{what}: the twin closed the connection; is it still running?")
        buf += chunk
    return buf


def read_reply(sock: socket.socket, *, where: str = "camera") -> Frame:
    """Reads one reply: the frame, or the twin's error message raised as ProtocolError. Every
    header field is checked before the payload is read, and the payload's length against the shape."""
    head = recv_exact(sock, HEADER_SIZE, f"{where} reply header")
    magic, version, status, dtype, channels, height, width, counter, angle, *rest = _HEADER.unpack(head)
    pose, length = rest[:16], rest[16]
    if magic != REPLY_MAGIC:
        raise ProtocolError(
            f"{where}: the reply starts {magic!r}, not {REPLY_MAGIC!r}; the socket is not a twin camera"
        )
    if version != PROTOCOL_VERSION:
        raise ProtocolError(f"{where}: the twin speaks protocol version {version}, this client {PROTOCOL_VERSION}")
    if status == STATUS_ERROR:
        if length > MAX_ERROR_BYTES:
            raise ProtocolError(f"{where}: an error reply declares {length} bytes, more than {MAX_ERROR_BYTES}")
        text = recv_exact(sock, length, f"{where} error message").decode("utf-8", "replace")
        raise ProtocolError(f"{where}: the twin refused: {text}")
    if status != STATUS_FRAME:
        raise ProtocolError(f"{where}: unknown reply status {status}")
    if dtype not in _ITEM_BYTES or channels != 3:
        raise ProtocolError(
            f"{where}: pixel type {dtype} with {channels} channels; expected uint8 BGR or float32 XYZ (1 or 2, 3)"
        )
    if not (2 <= width and 2 <= height and width * height <= MAX_IMAGE_PIXELS):
        raise ProtocolError(f"{where}: the header declares a {width}×{height} frame, outside what binpick reads")
    expected = width * height * channels * _ITEM_BYTES[dtype]
    if length != expected:
        raise ProtocolError(
            f"{where}: the header declares {length} payload bytes for a {width}×{height}×{channels} frame "
            f"({expected} expected)"
        )
    T = np.array(pose, dtype=np.float64).reshape(4, 4)
    if not (np.isfinite(T).all() and np.isfinite(angle)):
        raise ProtocolError(f"{where}: the header's pose or laser angle is not finite")
    data = recv_exact(sock, length, f"{where} frame {counter}")
    image = np.frombuffer(data, dtype=np.uint8 if dtype == DTYPE_UINT8 else "<f4").reshape(height, width, channels)
    return Frame(image=image, counter=int(counter), angle=float(angle), T_base_flange=T)


def connect(path: str, timeout_s: float, start_hint: str) -> socket.socket:
    """A connection to the twin's camera socket ``path``; PortClosedError saying how to start
    the twin (``start_hint``) when nothing listens there."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout_s)
    try:
        sock.connect(path)
    except OSError as exc:
        sock.close()
        raise PortClosedError(
            f"camera: cannot connect to the twin's camera socket {path} ({exc}); {start_hint}"
        ) from None
    return sock


def request(sock: socket.socket, op: int, path: str) -> Frame:
    """Sends one request of operation ``op`` and reads its reply (:func:`read_reply`)."""
    try:
        sock.sendall(encode_request(op))
    except OSError as exc:
        raise PortClosedError(f"camera: cannot send to {path} ({exc}); is the twin still running?") from None
    return read_reply(sock, where=f"camera {path}")
