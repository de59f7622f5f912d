"""The vision server's protocol, version 1: pure encoding and decoding, no sockets (the spec is
``docs/protocol.md``; this module is its one implementation on binpick's side).

One line of ASCII per message. A request ends with LF, CR or CR LF (robot languages differ) and
is at most :data:`MAX_LINE_BYTES` bytes with its end; an empty line is ignored. A reply ends with
CR LF. A request is a verb and its numbers, separated
by spaces or commas; brackets and URScript's ``p[`` are ignored, so that what a robot language
prints for a pose can be sent as it is. A reply is ``(`` numbers ``)``, then, for an error,
a space and a text without parentheses; the first number is the reply code (:class:`Code`), and
every reply to a verb has the same count of numbers (an error's are zeros after the code), so
that a robot program reads each reply with one fixed-size read.
"""

from __future__ import annotations

import enum
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import ProtocolError

__all__ = [
    "PROTOCOL_VERSION",
    "MAX_LINE_BYTES",
    "Code",
    "Verb",
    "Request",
    "RequestError",
    "parse_request",
    "encode_reply",
    "reply_size",
]

#: The protocol version this binpick speaks (HELLO negotiates it).
PROTOCOL_VERSION = 1
#: Longest message, bytes with the terminator; a longer one closes the connection.
MAX_LINE_BYTES = 512
#: Longest error text in a reply, characters (a reply stays within :data:`MAX_LINE_BYTES`).
MAX_TEXT = 200


class Code(enum.IntEnum):
    """Reply codes: 0 is success; 1–9 the request; 10–19 the bin; 20–29 the cell; 30 binpick."""

    OK = 0
    MALFORMED = 1
    UNKNOWN_VERB = 2
    FIELD_COUNT = 3
    BAD_VALUE = 4
    OUT_OF_ORDER = 5
    TOO_LONG = 6
    VERSION = 7
    NOTHING_FOUND = 10
    NO_PICKABLE_PART = 11
    UNSAFE = 12
    DEVICE_FAULT = 20
    BUSY = 21
    INTERNAL = 30


class Verb(str, enum.Enum):
    """The requests a robot program sends."""

    HELLO = "HELLO"
    SCAN = "SCAN"
    NEXT = "NEXT"
    RESULT = "RESULT"
    STATUS = "STATUS"
    BYE = "BYE"


#: How many numbers each verb's reply holds besides the grip poses (NEXT adds four poses).
_REPLY_NUMBERS = {
    Verb.HELLO: 4,  # code, version, brand id, numbers per pose
    Verb.SCAN: 4,  # code, scan id, points, scan time (ms)
    Verb.NEXT: 6,  # code, pick id, part id, confidence, decided, opening (mm); then above, approach, grasp, lift
    Verb.RESULT: 4,  # code, pick id, picks reported, parts held
    Verb.STATUS: 6,  # code, state, scans, picks reported, parts held, last error code
    Verb.BYE: 1,  # code
}
#: Poses in a NEXT reply: above the approach, the approach, the grasp, the lift.
NEXT_POSES = ("above", "approach", "grasp", "lift")


def reply_size(verb: Verb | None, pose_size: int) -> int:
    """How many numbers a reply to ``verb`` holds (1 for a request whose verb is unknown)."""
    if verb is None:
        return 1
    return _REPLY_NUMBERS[verb] + (len(NEXT_POSES) * pose_size if verb is Verb.NEXT else 0)


class RequestError(ProtocolError):
    """A robot program's request cannot be answered as asked; ``code`` is the reply code."""

    def __init__(self, code: Code, message: str, verb: Verb | None = None) -> None:
        super().__init__(message)
        self.code = Code(code)
        self.verb = verb


@dataclass(frozen=True)
class Request:
    """A parsed request: its verb and its numbers."""

    verb: Verb
    numbers: tuple[float, ...]


#: What may appear between a request's numbers: separators and the wrappers robot languages print.
_NOISE = re.compile(r"p\[|[\[\]()]")
_SPLIT = re.compile(r"[\s,]+")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_ARGUMENTS = {
    Verb.HELLO: 1,
    Verb.NEXT: 0,
    Verb.RESULT: 2,
    Verb.STATUS: 0,
    Verb.BYE: 0,
}


def parse_request(line: bytes, pose_size: int) -> Request:
    """The request in ``line`` (without its line end); RequestError with the code to reply for a line
    that is not printable ASCII, an unknown verb, a wrong count of numbers or a number that is
    not one. SCAN takes ``pose_size`` numbers (the flange pose in the brand's convention)."""
    if len(line) >= MAX_LINE_BYTES:
        raise RequestError(Code.TOO_LONG, f"a message is at most {MAX_LINE_BYTES - 1} bytes before its LF")
    if any(b < 0x20 or b > 0x7E for b in line if b != 0x09):
        raise RequestError(Code.MALFORMED, "a message is one line of printable ASCII")
    text = line.decode("ascii").strip()
    head, _, rest = text.partition(" ")
    head, comma, tail = head.partition(",")
    rest = tail + " " + rest if comma else rest
    try:
        verb = Verb(head.upper())
    except ValueError:
        shown = head[:20].replace("(", "[").replace(")", "]")
        raise RequestError(
            Code.UNKNOWN_VERB, f"unknown request {shown!r}; send one of {', '.join(v.value for v in Verb)}"
        ) from None
    tokens = [t for t in _SPLIT.split(_NOISE.sub(" ", rest)) if t]
    wanted = pose_size if verb is Verb.SCAN else _ARGUMENTS[verb]
    if len(tokens) != wanted:
        raise RequestError(Code.FIELD_COUNT, f"{verb.value} takes {wanted} numbers, got {len(tokens)}", verb)
    numbers = []
    for i, t in enumerate(tokens):
        if _NUMBER.fullmatch(t) is None:
            raise RequestError(Code.MALFORMED, f"{verb.value}: field {i + 1} is not a number", verb)
        x = float(t)
        if not math.isfinite(x):
            raise RequestError(Code.BAD_VALUE, f"{verb.value}: field {i + 1} is not finite", verb)
        numbers.append(x)
    return Request(verb, tuple(numbers))


def encode_reply(code: Code, numbers: Sequence[float] = (), *, size: int, text: str = "") -> bytes:
    """The reply line: ``(code,numbers…)`` padded with zeros to ``size`` numbers, then, when
    ``text`` is given, a space and the text (printable ASCII, parentheses made brackets, at most
    :data:`MAX_TEXT` characters), then CR LF."""
    values = [int(code), *numbers]
    if len(values) > size:
        raise ValueError(f"a reply of {size} numbers cannot hold {len(values)}")
    values += [0] * (size - len(values))
    body = ",".join(_number(v) for v in values)
    line = f"({body})"
    if text:
        spelled = "".join(_ASCII.get(c, c) for c in text)
        clean = "".join(c if " " <= c <= "~" else "?" for c in spelled).replace("(", "[").replace(")", "]")
        line += " " + (clean if len(clean) <= MAX_TEXT else clean[: MAX_TEXT - 3] + "...")
    return line.encode("ascii") + b"\r\n"


#: binpick's messages' few non-ASCII characters, spelled in ASCII.
_ASCII = {
    "\u2014": "-",
    "\u2013": "-",
    "\u00b0": " deg",
    "\u00d7": "x",
    "\u2026": "...",
    "\u03c3": "sigma",
    "\u2264": "<=",
    "\u2265": ">=",
}


def _number(v: float) -> str:
    if isinstance(v, (int, bool)) or float(v).is_integer() and abs(v) < 1e15:
        return str(int(v))
    text = f"{float(v):.6f}".rstrip("0")
    return text + "0" if text.endswith(".") else text
