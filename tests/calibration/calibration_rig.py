"""A simulated cell for calibration: a 9×6 checkerboard (25 mm squares) on the table, the
camera on the flange at robot stations about 500 mm above it (a module of its own, not the
conftest, so that its names import without clashing with other folders' conftest modules)."""

from __future__ import annotations

import numpy as np

from binpick import transforms
from binpick.calibration import CameraIntrinsics, CellCalibration
from binpick.vision import _synthetic as syn
from binpick.vision._synthetic import pose

PATTERN = (9, 6)
SQUARE = 25.0


def rotation_angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle (degrees) of the rotation between the rotation parts of ``A`` and ``B``."""
    return transforms.rotation_angle_deg(A[:3, :3].T @ B[:3, :3])


class Rig:
    def __init__(self, width: int = 1032, height: int = 778) -> None:
        s = width / 1032
        cam = CameraIntrinsics(
            width,
            height,
            [[1210.0 * s, 0, 521.0 * s], [0, 1205.0 * s, 384.0 * s], [0, 0, 1]],
            [-0.1, 0.08, 0.0005, -0.0003, 0.0],
        )
        self.calibration = CellCalibration(
            cam, pose(0.01, -0.02, 0.015, (-150.0, 2.0, 5.0)), pose(0.02, -0.01, 0.3, (30.0, -10.0, 90.0))
        )
        self.board = syn.Checkerboard.at(pose(0, 0, 0.05, (-100.0, -70.0, 0.0)), PATTERN, SQUARE)
        self.table = syn.Plane(np.array([0, 0, -0.5]), np.array([0, 0, 1.0]), albedo=0.3)
        self.rays = syn.camera_rays(cam)
        self.centre = (
            self.board.T_base_board[:3, :3] @ np.array([4 * SQUARE, 2.5 * SQUARE, 0]) + self.board.T_base_board[:3, 3]
        )

    def flange_for_camera(self, T_base_camera: np.ndarray) -> np.ndarray:
        return T_base_camera @ np.linalg.inv(self.calibration.T_flange_camera)

    def looking_at_board(self, rx: float, ry: float, rz: float, distance: float) -> np.ndarray:
        """The flange pose that puts the camera ``distance`` mm from the board centre, tilted."""
        R = pose(np.pi + rx, ry, rz)[:3, :3]
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = self.centre - R[:, 2] * distance
        return self.flange_for_camera(T)

    def image(
        self, T_base_flange: np.ndarray, *, angle: float | None = None, seed: int = 0, noise: float = 2.0
    ) -> np.ndarray:
        return syn.render(
            self.calibration,
            [self.board, self.table],
            T_base_flange,
            angle=angle,
            rng=np.random.default_rng(seed),
            noise=noise,
            ambient=200.0,
            rays=self.rays,
        )
