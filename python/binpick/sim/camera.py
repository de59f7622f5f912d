"""Virtual cameras for the pick loop (:class:`binpick.cell.FrameSource` s): the simulated cell's
camera (:class:`SimCamera`, rendering the pile from where the emulated robot and laser motor
really are) and :class:`RenderedCamera` (a pile of a part rendered from the poses the drivers
report, to try a cell configuration without a camera)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import as_transform
from ..cell.frames import FrameSource
from ..errors import InvalidInputError
from ..models import Model
from .cell import Cell as Layout
from .pile import Pile
from .render import World

if TYPE_CHECKING:  # annotations only: twin builds a SimCamera
    from .twin import SimulatedCell

__all__ = ["SimCamera", "RenderedCamera"]


class SimCamera(FrameSource):
    """The simulated camera: renders the pile of a :class:`SimulatedCell` from the flange pose the
    robot emulator reports, with the laser at the angle the motor emulator reports."""

    def __init__(self, sim: SimulatedCell, *, seed: int = 0) -> None:
        self.sim = sim
        self.seed = int(seed)
        self._view = None
        self._frame = 0

    def begin(self, T_base_flange: np.ndarray) -> None:
        self.sim.settle_pending()
        world = World.of_pile(self.sim.pile)
        actual = self.sim.robot_emulator.pose()
        self._view = world.view(self.sim.layout, actual, num_threads=self.sim.num_threads)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError(
                "camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose"
            )
        angle = self.sim.laser_angle()
        rgb = self._view.frame(angle, seed=self.seed + self._frame)
        self._frame += 1
        return np.ascontiguousarray(rgb[:, :, ::-1])


class RenderedCamera(FrameSource):
    """A simulated camera for trying a cell configuration without one: a pile of ``model``
    rendered from the flange pose and laser angle the drivers report (``begin``/``laser_at``)."""

    def __init__(
        self, model: Model, *, count: int = 8, seed: int = 0, layout: Any = None, num_threads: int = 0
    ) -> None:
        self.layout = layout if layout is not None else Layout()
        self.pile = Pile(model, count, bin=self.layout.bin, seed=seed)
        self.world = World.of_pile(self.pile)
        self.seed = int(seed)
        self.num_threads = int(num_threads)
        self._view = None
        self._angle = 0.0
        self._frame = 0

    def begin(self, T_base_flange: np.ndarray) -> None:
        self._view = self.world.view(
            self.layout, as_transform(T_base_flange, "T_base_flange"), num_threads=self.num_threads
        )

    def laser_at(self, angle: float) -> None:
        self._angle = float(angle)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError(
                "camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose"
            )
        rgb = self._view.frame(self._angle, seed=self.seed + self._frame)
        self._frame += 1
        return np.ascontiguousarray(rgb[:, :, ::-1])
