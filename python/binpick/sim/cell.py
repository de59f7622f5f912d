"""The simulated cell's hardware: camera, laser projector, lighting, sensor noise, bin, and the
default layout of the paper's cell.

Default layout (robot base frame, +z up, mm): the bin's inner floor at z = 0, centred at
(400, 0), 300 × 200 mm inside and 80 mm deep, on a table; the flange 620 mm above the floor
looking straight down, the camera 40 mm below it (hand-eye ``T_flange_camera``), so the camera
is about 500 mm above a pile; the laser projector 130 mm to the camera's +x on the flange, its
sheet at motor angle 0 crossing the optical axis 520 mm out; the sweep covers the bin.
A calibration checkerboard (:class:`CalibrationBoard`: 9 × 6 inner corners, 20 mm squares, 15 mm
white border, on a 3 mm plate) lies face up on the table beside the bin, its centre at
(400, −250, −5): out of the scan pose's view, where the arm can look at it from many angles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Optional

import numpy as np

from .. import _core, _validate
from .._validate import as_transform, as_vector, count, instance_of, non_negative, number, positive
from ..camera import CameraIntrinsics
from ..errors import InvalidInputError
from ..transforms import laser_sweep, look_down, rot_y

__all__ = ["CalibrationBoard", "Camera", "Laser", "Lighting", "SensorNoise", "Bin", "Cell", "rot_y", "look_down"]


def Camera(  # named like a class: it builds the simulated camera, as binpick.sim.Camera(...) always has
    width: int = 1032,
    height: int = 778,
    fx: float = 1600.0,
    fy: float = 1600.0,
    cx: float = 515.5,
    cy: float = 388.5,
    dist: Sequence[float] = (-0.04, 0.01, 0.0, 0.0, 0.0),
) -> CameraIntrinsics:
    """The simulated cell's camera, as the one camera model (:class:`binpick.camera.CameraIntrinsics`):
    size (px), focal lengths and principal point (px), ``dist = [k1, k2, p1, p2, k3]``. The default
    is the paper's 1032 × 778 camera with an 8 mm-class lens and mild barrel distortion."""
    return CameraIntrinsics.pinhole(width, height, fx, fy, cx, cy, dist)


# The default projector is defined once, in the Rust core (``Laser::default``); its pose and
# parameters are read from there so the two layers cannot drift apart.
_DEFAULT_LASER = _core.sim_default_laser()


def _default_laser_pose() -> np.ndarray:
    return np.array(_DEFAULT_LASER[0], dtype=np.float64)


@dataclass(frozen=True)
class Laser:
    """The red line projector. ``T_camera_laser0`` is its pose in the camera frame at motor angle 0
    (sheet = plane x_L = 0, light along +z_L; the motor turns it about y_L); ``sheet_sigma`` the
    Gaussian σ of the sheet's thickness (mm); ``power`` the peak DN on white at
    ``reference_distance`` (mm); ``fan_angle`` the fan's full opening (rad); ``color`` the R, G, B
    response to its light. The defaults are the core's ``Laser::default()`` (the one definition):
    130 mm to the camera's +x, the sheet at angle 0 crossing the optical axis 520 mm out."""

    T_camera_laser0: np.ndarray = field(default_factory=_default_laser_pose)
    sheet_sigma: float = float(_DEFAULT_LASER[1])
    power: float = float(_DEFAULT_LASER[2])
    fan_angle: float = float(_DEFAULT_LASER[3])
    color: tuple[float, float, float] = tuple(float(c) for c in _DEFAULT_LASER[4])  # type: ignore[assignment]
    reference_distance: float = float(_DEFAULT_LASER[5])

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_camera_laser0", as_transform(self.T_camera_laser0, "T_camera_laser0"))
        positive(self.sheet_sigma, "sheet_sigma")
        non_negative(self.power, "power", "DN")
        if positive(self.fan_angle, "fan_angle", "rad") >= np.pi:
            raise InvalidInputError(f"fan_angle: must be in (0, π) radians, got {self.fan_angle!r}")
        object.__setattr__(self, "color", tuple(float(c) for c in as_vector(self.color, "color", 3)))
        positive(self.reference_distance, "reference_distance")

    def T_camera_laser(self, angle: float) -> np.ndarray:
        """The projector pose at motor angle ``angle`` (rad): ``T_camera_laser0 @ Rot_y(angle)``."""
        return self.T_camera_laser0 @ rot_y(angle)

    def _args(self) -> tuple:
        return (
            self.T_camera_laser0,
            float(self.sheet_sigma),
            float(self.power),
            float(self.fan_angle),
            list(self.color),
            float(self.reference_distance),
        )


@dataclass(frozen=True)
class Lighting:
    """Ambient light: ``ambient`` and ``lamp`` DN on white, the lamp's direction in the base frame,
    ``background`` DN."""

    ambient: float = 55.0
    lamp: float = 45.0
    lamp_direction: tuple[float, float, float] = (0.3, -0.2, 1.0)
    background: float = 6.0

    def __post_init__(self) -> None:
        non_negative(self.ambient, "ambient", "DN")
        non_negative(self.lamp, "lamp", "DN")
        non_negative(self.background, "background", "DN")
        object.__setattr__(
            self, "lamp_direction", tuple(float(v) for v in as_vector(self.lamp_direction, "lamp_direction", 3))
        )

    def _args(self) -> tuple:
        return (float(self.ambient), float(self.lamp), list(self.lamp_direction), float(self.background))


@dataclass(frozen=True)
class SensorNoise:
    """What the sensor and optics add: read noise σ (DN), shot noise (DN² per DN), laser speckle
    contrast, one-bounce laser reflections off glossy parts (strength), optical blur σ (px)."""

    read_noise: float = 1.5
    shot_noise: float = 0.08
    speckle: float = 0.0
    reflections: float = 0.0
    blur: float = 0.6

    def __post_init__(self) -> None:
        for name in ("read_noise", "shot_noise", "speckle", "reflections", "blur"):
            non_negative(getattr(self, name), name)

    @classmethod
    def none(cls, blur: float = 0.6) -> SensorNoise:
        """An ideal sensor: no noise, speckle or reflections (the optics blur stays)."""
        return cls(read_noise=0.0, shot_noise=0.0, speckle=0.0, reflections=0.0, blur=blur)

    def _args(self) -> tuple:
        return (
            float(self.read_noise),
            float(self.shot_noise),
            float(self.speckle),
            float(self.reflections),
            float(self.blur),
        )


#: A part fits the default cell when its longest side is at most this share of the bin's inner
#: length (the paper's tee, elbow and cross, and parts up to 200 mm); larger parts get a larger cell.
PART_TO_BIN = 2.0 / 3.0


@dataclass(frozen=True)
class Bin:
    """An open box on the floor: inner ``size`` (x, y, height) mm, inner floor centre ``center``
    (x, y), floor height ``floor_z``."""

    size: tuple[float, float, float] = (300.0, 200.0, 80.0)
    center: tuple[float, float] = (400.0, 0.0)
    floor_z: float = 0.0
    wall_thickness: float = 8.0

    def __post_init__(self) -> None:
        # The clouds' coordinate ceiling: beyond it floor_z + height rounds to floor_z.
        top = _validate.MAX_COORDINATE
        s = as_vector(self.size, "size", 3)
        if (s <= 0).any() or (s > top).any():
            raise InvalidInputError(
                f"size: the bin's inner length, width and height must be positive mm up to {top:g}, got {s.tolist()}"
            )
        object.__setattr__(self, "size", tuple(float(v) for v in s))
        c = as_vector(self.center, "center", 2)
        if (np.abs(c) > top).any():
            raise InvalidInputError(
                f"center: {c.tolist()} mm lies beyond ±{top:g} mm, where the bin's walls would "
                "round into each other; place the bin near the robot base"
            )
        object.__setattr__(self, "center", tuple(float(v) for v in c))
        object.__setattr__(self, "floor_z", number(self.floor_z, "floor_z", -top, top, "mm"))
        positive(self.wall_thickness, "wall_thickness")
        _validate.as_box(self.bounds, "size")  # a size too small to tell from the position's rounding leaves no inside

    @property
    def bounds(self) -> np.ndarray:
        """The inner volume as [[xmin, ymin, zmin], [xmax, ymax, zmax]] in the base frame."""
        (sx, sy, sz), (cx, cy) = self.size, self.center
        return np.array([[cx - sx / 2, cy - sy / 2, self.floor_z], [cx + sx / 2, cy + sy / 2, self.floor_z + sz]])


@dataclass(frozen=True)
class CalibrationBoard:
    """A printed checkerboard lying in the cell: ``pattern`` = (columns, rows) of inner corners,
    ``square`` and white ``margin`` (mm), placed at ``T_base_board`` (OpenCV board frame: origin
    at the first inner corner, x along the columns, y along the rows, z into the board)."""

    pattern: tuple[int, int] = (9, 6)
    square: float = 20.0
    margin: float = 15.0
    T_base_board: np.ndarray = field(default_factory=lambda: _board_on_table())

    def __post_init__(self) -> None:
        cols, rows = (count(p, "pattern", 2) for p in self.pattern)
        object.__setattr__(self, "pattern", (cols, rows))
        positive(self.square, "square")
        non_negative(self.margin, "margin", "mm")
        object.__setattr__(self, "T_base_board", as_transform(self.T_base_board, "T_base_board"))

    @property
    def extent(self) -> np.ndarray:
        """The printed area in the board frame, [[xmin, ymin], [xmax, ymax]] mm (squares and border)."""
        s, m = float(self.square), float(self.margin)
        return np.array([[-s - m, -s - m], [self.pattern[0] * s + m, self.pattern[1] * s + m]])

    @property
    def center(self) -> np.ndarray:
        """The centre of the inner-corner grid in the base frame, mm."""
        local = np.array([(self.pattern[0] - 1) * self.square / 2, (self.pattern[1] - 1) * self.square / 2, 0, 1])
        return (self.T_base_board @ local)[:3]


@dataclass(frozen=True)
class Cell:
    """The whole simulated cell: camera, laser, hand-eye ``T_flange_camera``, bin, lighting and noise,
    the robot pose ``T_base_flange`` it scans from, the calibration ``board`` lying in it (None: no
    board), and the camera's frame rate ``camera_fps`` (a triggered frame, exposed and read out,
    takes 1 / ``camera_fps`` of the cell's time: the paper's 15 fps camera)."""

    camera: CameraIntrinsics = field(default_factory=Camera)
    laser: Laser = field(default_factory=Laser)
    T_flange_camera: np.ndarray = field(default_factory=lambda: _flange_camera())
    bin: Bin = field(default_factory=Bin)
    lighting: Lighting = field(default_factory=Lighting)
    noise: SensorNoise = field(default_factory=SensorNoise)
    T_base_flange: np.ndarray = field(default_factory=lambda: _scan_flange())
    board: Optional[CalibrationBoard] = field(default_factory=CalibrationBoard)
    camera_fps: float = 15.0

    def __post_init__(self) -> None:
        positive(self.camera_fps, "camera_fps", "frames/s")
        instance_of(self.camera, CameraIntrinsics, "camera", "binpick.sim.Camera()")
        for name, kind in (("laser", Laser), ("bin", Bin), ("lighting", Lighting), ("noise", SensorNoise)):
            instance_of(getattr(self, name), kind, name, f"binpick.sim.{kind.__name__}()")
        if self.board is not None:
            instance_of(self.board, CalibrationBoard, "board", "binpick.sim.CalibrationBoard() or None")
        object.__setattr__(self, "T_flange_camera", as_transform(self.T_flange_camera, "T_flange_camera"))
        object.__setattr__(self, "T_base_flange", as_transform(self.T_base_flange, "T_base_flange"))

    @property
    def T_base_camera(self) -> np.ndarray:
        """The camera pose at the scan pose: ``T_base_flange @ T_flange_camera``."""
        return self.T_base_flange @ self.T_flange_camera

    def calibration(self):
        """The cell's exact calibration as a ``binpick.calibration.CellCalibration``."""
        from ..calibration import CellCalibration

        return CellCalibration(
            camera=self.camera,
            T_camera_laser=self.laser.T_camera_laser0,
            T_flange_camera=self.T_flange_camera,
        )

    @classmethod
    def for_part(cls, model: Any) -> Cell:
        """The simulated cell for piles of ``model``: the paper's cell (the defaults) when the
        part's longest side is at most :data:`PART_TO_BIN` of the default bin's inner length;
        otherwise the same cell grown to the part, as an integrator would build it for large parts:

        - the bin's inner size scaled by s = longest side / (PART_TO_BIN × 300 mm), its near wall
          (toward the robot) where the default's is, centred on y = 0;
        - the scan pose over the bin's centre, raised by the extra depth, so the camera stays as
          far above the rim as in the default cell;
        - a shorter lens (focal lengths scaled down, the same sensor) whose view holds the whole
          bin at its rim, with 5 % to spare.

        The laser, lighting, noise and hand-eye stay the default's; the calibration board moves
        aside with the view, out of it as in the default cell.
        The arm that reaches such a bin is :func:`binpick.sim.sim_arm`."""
        from ..models import Model

        instance_of(model, Model, "model", "binpick.parts.tee()")
        default = cls()
        extent = np.ptp(np.asarray(model.vertices, dtype=np.float64), axis=0)
        size = np.array(default.bin.size)
        scale = float(extent.max()) / (PART_TO_BIN * size[0])
        if scale <= 1.0:
            return default
        size = size * scale
        near = default.bin.bounds[0][0]
        b = Bin(size=tuple(size), center=(float(near + size[0] / 2), 0.0), floor_z=default.bin.floor_z)
        lift = float(size[2] - default.bin.size[2])
        T_flange = default.T_base_flange.copy()
        T_flange[:2, 3] = b.center
        T_flange[2, 3] += lift
        # The camera's height above the rim, and the focal length at which the rim's half-extent
        # fills 95 % of the sensor's half-width (x) and half-height (y).
        cam = default.camera
        above_rim = float((T_flange @ default.T_flange_camera)[2, 3] - b.bounds[1][2])
        f = min(
            0.95 * cam.cx * above_rim / (size[0] / 2),
            0.95 * cam.cy * above_rim / (size[1] / 2),
            cam.fx,
        )
        camera = Camera(cam.width, cam.height, f, f * cam.fy / cam.fx, cam.cx, cam.cy, tuple(cam.dist))
        # The board moves out along −y by as much as the view grew at the table, so that it stays
        # out of the scan pose's view (as in the default cell), where rendering it would only cost.
        board = default.board
        table = float(board.T_base_board[2, 3])
        half_view = [
            c.cy / c.fy * float((T @ default.T_flange_camera)[2, 3] - table)
            for c, T in ((cam, default.T_base_flange), (camera, T_flange))
        ]
        T_board = board.T_base_board.copy()
        T_board[1, 3] -= half_view[1] - half_view[0]
        return cls(camera=camera, bin=b, T_base_flange=T_flange, board=replace(board, T_base_board=T_board))

    def sweep(self, frames: int = 90, margin: float = 10.0) -> np.ndarray:
        """``frames`` motor angles (rad), evenly spaced, whose laser sheets cover the bin's inner
        floor from wall to wall (plus ``margin`` mm) at the scan pose."""
        n = count(frames, "frames", 1)
        lo, hi = self.bin.bounds
        return laser_sweep(self.T_base_camera @ self.laser.T_camera_laser0, lo, hi, n, margin)


def _flange_camera() -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = 40.0
    return T


def _board_on_table() -> np.ndarray:
    # Face up on the table top (z = −8) on a 3 mm plate, centred at (400, −250): board x along
    # base x, board y along base −y, board z (into the board) straight down.
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = (400.0 - 80.0, -250.0 + 50.0, -5.0)
    return T


def _scan_flange() -> np.ndarray:
    return look_down(400.0, 0.0, 620.0)
