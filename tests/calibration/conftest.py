"""Session fixtures of the calibration tests: the rig (see calibration_rig) and its board views."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_rig import Rig


@pytest.fixture(scope="session")
def rig() -> Rig:
    return Rig()


@pytest.fixture(scope="session")
def board_views(rig):
    """Ten stations around the board (flange poses) and their rendered frames."""
    rng = np.random.default_rng(5)
    stations = [
        rig.looking_at_board(*rng.uniform(-0.35, 0.35, 2), rng.uniform(-0.6, 0.6), rng.uniform(420, 560))
        for _ in range(10)
    ]
    return stations, [rig.image(T, seed=i) for i, T in enumerate(stations)]
