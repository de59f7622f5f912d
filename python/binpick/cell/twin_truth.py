"""The digital twin's ground truth for a pick run against it (``binpick pick`` on the cell file
``binpick emulate cell`` writes): the twin answers WORLD on its camera socket
(:mod:`binpick.cell.camera_socket`) with the parts in the bin and their true poses, those that
left it and every contact of the gripper its physics saw. A rehearsal's report then names the
part each pick removed, each located pose's error and each collision, as the simulated cell's
does. A real cell has none of this: its camera source is not the twin."""

from __future__ import annotations

import threading
from typing import Any, Optional

import numpy as np

from ..errors import InvalidInputError, NoObjectFound
from . import camera_socket as wire
from .records import PoseTruth

__all__ = ["TwinTruth"]

_HINT = "start the twin first: binpick emulate cell --out DIR"


class TwinTruth:
    """The ground truth of the twin serving the camera socket ``path``, for the part ``model``;
    the pick loop's ``truth`` (:class:`binpick.cell.Cell`): :meth:`judge`, :meth:`take_picked`,
    :meth:`take_collisions`, :meth:`parts_left`; and its ``clock`` (:meth:`clock`). Connects on first use."""

    def __init__(self, path: str, model: Any, *, timeout_s: float = 60.0) -> None:
        self.path, self.model, self.timeout_s = str(path), model, float(timeout_s)
        self._sock = None
        self._lock = threading.Lock()
        self._removed_seen: Optional[int] = None
        self._collisions_seen: Optional[int] = None

    def close(self) -> None:
        """Closes the connection (reopened on the next question)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _document(self, op: int) -> dict:
        with self._lock:
            if self._sock is None:
                self._sock = wire.connect(self.path, self.timeout_s, _HINT)
            return wire.request_document(self._sock, op, self.path)

    def clock(self) -> float:
        """The twin's hardware time, s: what its emulated arm, laser motor, gripper and camera
        have taken (the pick loop's ``clock``, for the physical cycle time)."""
        t = self._document(wire.OP_CLOCK).get("clock_s")
        if not isinstance(t, (int, float)) or not t >= 0:
            raise InvalidInputError(f"the twin's clock: expected seconds ≥ 0, got {t!r:.40}")
        return float(t)

    def world(self) -> dict:
        """The twin's world now (world.json's document, the world settled first)."""
        doc = self._document(wire.OP_WORLD)
        if self._removed_seen is None:  # what happened before this run is not this run's
            self._removed_seen = len(doc.get("removed", []))
            self._collisions_seen = len(doc.get("collisions", []))
        return doc

    def judge(self, T_base_object: np.ndarray, *, turn_about: Any = None) -> PoseTruth:
        """The located pose against the nearest part in the twin's bin, its errors modulo the
        part's symmetries (:meth:`binpick.Model.pose_error`)."""
        best = None
        for part in self.world().get("in_bin", []):
            T_bo = np.asarray(part["T_base_object"], dtype=np.float64)
            deg, mm = self.model.pose_error(T_base_object, T_bo, turn_about=turn_about)
            if best is None or mm < best.translation_error_mm:
                best = PoseTruth(
                    instance=int(part["id"]), rotation_error_deg=deg, translation_error_mm=mm, T_base_truth=T_bo
                )
        if best is None:
            raise NoObjectFound("the twin's bin is empty")
        return best

    def take_picked(self) -> Optional[int]:
        """The part that left the twin's bin since the last call (the last, if several), or None."""
        removed = self.world().get("removed", [])
        new, self._removed_seen = removed[self._removed_seen :], len(removed)
        return int(new[-1]) if new else None

    def take_collisions(self) -> list[dict]:
        """The gripper's contacts the twin saw since the last call."""
        seen = self.world().get("collisions", [])
        new, self._collisions_seen = seen[self._collisions_seen :], len(seen)
        if not all(isinstance(c, dict) and "with" in c and "points" in c for c in new):
            raise InvalidInputError("the twin's collisions: each must name what it touched ('with') and 'points'")
        return list(new)

    def parts_left(self) -> int:
        """How many parts are in the twin's bin."""
        return len(self.world().get("in_bin", []))
