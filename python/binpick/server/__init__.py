"""The vision server a robot program calls: ``binpick serve CELL.toml``.

* :mod:`~binpick.server.protocol` — the protocol (version 1, one ASCII line per message; the
  spec is ``docs/protocol.md``), pure encoding and decoding;
* :mod:`~binpick.server.conventions` — poses in each brand's convention (UR, ABB, KUKA, FANUC,
  Yaskawa, MELFA);
* :mod:`~binpick.server.service` — what each request does (scan at the pose the program reports,
  locate and plan as the cell does, every motion checked by the same safety layer);
* :mod:`~binpick.server.server` — the TCP server (one robot program at a time, timeouts,
  bounded messages).
"""

from __future__ import annotations

from .conventions import CONVENTIONS, PoseConvention, convention
from .protocol import MAX_LINE_BYTES, PROTOCOL_VERSION, Code, RequestError, Verb, encode_reply, parse_request
from .server import DEFAULT_PORT, VisionServer
from .service import ProgramGripper, ProgramRobot, VisionService

__all__ = [
    "CONVENTIONS",
    "PoseConvention",
    "convention",
    "MAX_LINE_BYTES",
    "PROTOCOL_VERSION",
    "Code",
    "RequestError",
    "Verb",
    "encode_reply",
    "parse_request",
    "DEFAULT_PORT",
    "VisionServer",
    "ProgramGripper",
    "ProgramRobot",
    "VisionService",
]
