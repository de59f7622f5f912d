"""Analytic scenes with known geometry for the measuring-chain tests: a camera 500 mm above a
tilted floor and a lying cylinder, a laser 150 mm to the camera's side."""

from __future__ import annotations

import numpy as np
import pytest

from binpick.calibration import CameraIntrinsics, CellCalibration
from binpick.vision import _synthetic as syn
from binpick.vision._synthetic import pose


class Cell:
    def __init__(self) -> None:
        cam = CameraIntrinsics(
            1032, 778, [[1200.0, 0, 520.3], [0, 1195.0, 385.7], [0, 0, 1]], [-0.09, 0.06, 0.0006, -0.0004, -0.01]
        )
        self.calibration = CellCalibration(
            cam, pose(0.01, -0.02, 0.015, (-150.0, 2.0, 5.0)), pose(0.02, -0.01, 0.3, (30.0, -10.0, 90.0))
        )
        # Flange above the floor so that the camera looks straight down from about 500 mm.
        T_base_camera = pose(np.pi, 0.0, 0.1, (10.0, -20.0, 500.0))
        self.T_base_flange = T_base_camera @ np.linalg.inv(self.calibration.T_flange_camera)
        self.floor = syn.Plane(np.zeros(3), np.array([0.05, 0.1, 1.0]))
        self.cylinder = syn.Cylinder(np.array([0.0, 0.0, 45.0]), np.array([0.3, 1.0, 0.0]), 45.0)
        self.rays = syn.camera_rays(cam)

    def angle_for_column(self, u: float) -> float:
        """The motor angle whose sheet meets the floor about column ``u`` (for sweeping scans)."""
        # The laser sits 150 mm to the side: tan θ ≈ (x_target + 150) / depth.
        K = self.calibration.camera.K
        x = (u - K[0, 2]) / K[0, 0] * 480.0
        return float(np.arctan2(x + 150.0, 480.0))


@pytest.fixture(scope="session")
def cell() -> Cell:
    return Cell()
