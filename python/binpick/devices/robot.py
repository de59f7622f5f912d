"""What the pick loop needs of a robot arm: :class:`Robot`, the interface every arm driver
implements (:class:`~binpick.devices.melfa.MelfaRobot` is the one shipped)."""

from __future__ import annotations

import abc
from typing import Any, Optional

import numpy as np

from .safety import CellLimits

__all__ = ["Robot"]


class Robot(abc.ABC):
    """An arm the pick loop drives; poses are flange poses ``T_base_flange`` (4×4, mm).

    ``limits`` are the cell's motion rules; the driver checks every motion against them before
    anything is sent (:class:`~binpick.errors.SafetyError`).
    """

    limits: Optional[CellLimits] = None
    """The rules the driver enforces; None for a driver that checks nothing itself."""

    def open_session(self) -> None:
        """Prepares the arm for motion (a controller session, servo power); none by default."""

    def close_session(self) -> None:
        """Ends what :meth:`open_session` began; nothing by default."""

    @abc.abstractmethod
    def read_pose(self) -> np.ndarray:
        """The flange pose now, ``T_base_flange``."""

    @abc.abstractmethod
    def move_to(self, T_base_flange: Any, *, linear: bool = False) -> None:
        """Moves the flange to ``T_base_flange`` (straight when ``linear``), returning on arrival."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stops the arm now."""

    def close(self) -> None:
        """Releases the connection; nothing by default."""
