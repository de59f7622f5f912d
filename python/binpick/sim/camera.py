"""Virtual cameras for the pick loop (:class:`binpick.cell.FrameSource` s): the simulated cell's
camera (:class:`SimCamera`, rendering the pile from where the emulated robot and laser motor
really are) and :class:`RenderedCamera` (a pile of a part rendered from the poses the drivers
report, to try a cell configuration without a camera). Both see the layout's calibration board
(:class:`binpick.sim.CalibrationBoard`) where it lies: per pixel the nearer of the board and the
ray-cast scene, the laser line drawn on the board as on the scene (the board's laser light is
not shadowed by objects between projector and board: keep the board clear of the bin's shadow)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Optional

import numpy as np

from .._validate import as_transform
from ..camera import CameraIntrinsics
from ..cell.frames import FrameSource
from ..errors import InvalidInputError
from ..models import Model
from ..transforms import inverse
from .cell import Cell as Layout
from .pile import Pile
from .render import View, World, render_checkerboard

if TYPE_CHECKING:  # annotations only: twin builds a SimCamera
    from .twin import SimulatedCell

__all__ = ["SimCamera", "RenderedCamera"]


_RAYS: dict[tuple, np.ndarray] = {}
#: Samples per pixel side of the board's image: the pixel integrates the light over its area;
#: 4 × 4 keeps the aliasing of the squares' edges below the corner detector's noise.
_SUPERSAMPLE = 4


def _pixel_rays(camera: CameraIntrinsics) -> np.ndarray:
    """The undistorted ray (x, y, 1) of every pixel centre, (H·W, 3), cached per camera."""
    from ..vision._triangulate import pixel_rays

    key = (camera.width, camera.height, camera.K.tobytes(), camera.dist.tobytes())
    if key not in _RAYS:
        v, u = np.mgrid[0 : camera.height, 0 : camera.width]
        _RAYS.clear()  # one camera per process in practice; do not grow without bound
        _RAYS[key] = pixel_rays(np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64), camera)
    return _RAYS[key]


class _BoardLayer:
    """The layout's calibration board seen from one robot pose: where it is nearer than the
    ray-cast scene (``mask``), and its image with the laser at an angle composed over a frame."""

    def __init__(
        self, layout: Layout, view: View, T_base_flange: np.ndarray, window: Optional[tuple[slice, slice]] = None
    ) -> None:
        board = layout.board
        self.layout = layout
        self.T_camera_board = inverse(T_base_flange @ layout.T_flange_camera) @ board.T_base_board
        cam = layout.camera
        # Only the pixels that may see the board are tested (rows, columns; all by default).
        rows, cols = window or (slice(0, cam.height), slice(0, cam.width))
        rays = _pixel_rays(cam).reshape(cam.height, cam.width, 3)[rows, cols].reshape(-1, 3)
        n, p0 = self.T_camera_board[:3, 2], self.T_camera_board[:3, 3]
        denom = rays @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = np.where(np.abs(denom) > 1e-12, (n @ p0) / denom, -1.0)
        local = (rays * depth[:, None] - p0) @ self.T_camera_board[:3, :3]
        (xmin, ymin), (xmax, ymax) = board.extent
        on = (depth > 0) & (local[:, 0] >= xmin) & (local[:, 0] <= xmax) & (local[:, 1] >= ymin)
        on &= local[:, 1] <= ymax
        scene = view.depth[rows, cols].ravel().astype(np.float64)
        nearer = np.isnan(scene) | (depth < scene)
        self.mask = np.zeros((cam.height, cam.width), dtype=bool)
        self.mask[rows, cols] = (on & nearer).reshape(self.mask[rows, cols].shape)
        # The board is drawn only over the mask's box: the rest of its image is not used.
        v, u = np.flatnonzero(self.mask.any(axis=1)), np.flatnonzero(self.mask.any(axis=0))
        self.window = (int(u[0]), int(v[0]), int(u[-1]) + 1, int(v[-1]) + 1) if len(u) else None

    @classmethod
    def of(cls, layout: Layout, view: View, T_base_flange: np.ndarray) -> Optional[_BoardLayer]:
        """The layer, or None when the layout has no board or the camera does not see it."""
        if layout.board is None:
            return None
        window = _window(layout, T_base_flange)
        if window is None:  # the board far from the picture: no pixel to test
            return None
        layer = cls(layout, view, T_base_flange, window)
        return layer if layer.mask.any() else None

    def over(self, rgb: np.ndarray, angle: float, seed: int) -> np.ndarray:
        """``rgb`` (the scene's frame) with the board drawn where it is nearer, the laser at ``angle``."""
        lay, board = self.layout, self.layout.board
        img = render_checkerboard(
            lay.camera,
            self.T_camera_board,
            pattern=board.pattern,
            square=board.square,
            margin=board.margin,
            lighting=lay.lighting,
            laser=lay.laser,
            angle=angle,
            noise=lay.noise,
            supersample=_SUPERSAMPLE,
            seed=seed,
            window=self.window,
        )
        return np.where(self.mask[:, :, None], img, rgb)


def _window(layout: Layout, T_base_flange: np.ndarray) -> Optional[tuple[slice, slice]]:
    """The rows and columns of the picture that may see the board: the box of its corners'
    pinhole projections grown by a tenth of the image's size each way (more than any lens
    distortion moves them), clipped to the image; None when that box misses the image (the board
    clearly out of the picture), the whole image when a corner is not in front of the camera."""
    board, cam = layout.board, layout.camera
    (xmin, ymin), (xmax, ymax) = board.extent
    corners = np.array([[x, y, 0.0, 1.0] for x in (xmin, xmax) for y in (ymin, ymax)])
    local = (inverse(T_base_flange @ layout.T_flange_camera) @ board.T_base_board @ corners.T).T[:, :3]
    if (local[:, 2] <= 1e-6).any():
        return slice(0, cam.height), slice(0, cam.width)
    K = cam.K
    u = K[0, 0] * local[:, 0] / local[:, 2] + K[0, 2]
    v = K[1, 1] * local[:, 1] / local[:, 2] + K[1, 2]
    du, dv = 0.1 * cam.width, 0.1 * cam.height
    u0, u1 = max(0, math.floor(u.min() - du)), min(cam.width, math.ceil(u.max() + du) + 1)
    v0, v1 = max(0, math.floor(v.min() - dv)), min(cam.height, math.ceil(v.max() + dv) + 1)
    if u0 >= u1 or v0 >= v1:
        return None
    return slice(v0, v1), slice(u0, u1)


def _frame(view: View, board: Optional[_BoardLayer], angle: float, seed: int, num_threads: int = 0) -> np.ndarray:
    """The BGR frame of ``view`` (and the board, if seen) with the laser at ``angle``, rendered on
    ``num_threads`` threads (0: all cores)."""
    import cv2

    rgb = view.frames([angle], seed=seed, num_threads=num_threads)[0]
    if board is not None:
        rgb = board.over(rgb, angle, seed)
    # OpenCV swaps the channels in a fifth of the time numpy's strided copy takes (a full frame per grab).
    return cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR)


class SimCamera(FrameSource):
    """The simulated camera: renders the pile of a :class:`SimulatedCell` from the flange pose the
    robot emulator reports, with the laser at the angle the motor emulator reports."""

    def __init__(self, sim: SimulatedCell, *, seed: int = 0) -> None:
        self.sim = sim
        self.seed = int(seed)
        self._view: Optional[View] = None
        self._world: Optional[World] = None
        self._world_key: Optional[tuple[bytes, bytes]] = None
        self._board: Optional[_BoardLayer] = None
        self._frame = 0
        self._stream: Optional[list[float]] = None  # streaming: [start time, frames since]

    def streaming(self, on: bool) -> None:
        """Free-running from now (``on``): frames follow each other at the frame rate, whatever
        the host does between grabs; else each grab triggers a frame."""
        self._stream = [self.sim.clock.now(), 0.0] if on else None

    def begin(self, T_base_flange: np.ndarray) -> None:
        self.sim.settle_pending()
        pile = self.sim.pile
        ids, poses = pile.ids, pile.poses
        key = (np.asarray(ids).tobytes(), np.asarray(poses, dtype=np.float64).tobytes())
        if self._world is None:
            self._world = World.of_pile(pile)
        elif key != self._world_key:  # the parts placed again only when one has moved or left
            self._world.place_parts(pile.model, ids, poses)
        self._world_key = key
        actual = self.sim.robot_emulator.pose()
        self._view = self._world.view(self.sim.layout, actual, num_threads=self.sim.num_threads)
        self._board = _BoardLayer.of(self.sim.layout, self._view, actual)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError(
                "camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose"
            )
        # A triggered frame takes 1 / fps of the cell's time from the grab; a streaming one is the
        # next whose middle is yet to come. The laser is drawn where the motor stands at the
        # middle of the frame (where it turns during the frame: a continuous sweep).
        clock, period = self.sim.clock, 1.0 / self.sim.layout.camera_fps
        if self._stream is None:
            mid = clock.now() + period / 2
        else:
            start, k = self._stream
            k = max(k, float(math.ceil((clock.now() - start) / period - 0.5 - 1e-9)))
            mid, self._stream[1] = start + (k + 0.5) * period, k + 1
        clock.advance_to(mid, "camera")
        self.frame_time_s = mid
        img = _frame(self._view, self._board, self.sim.laser_angle(), self.seed + self._frame, self.sim.num_threads)
        clock.advance_to(mid + period / 2, "camera")
        self._frame += 1
        return img

    @property
    def fps(self) -> float:  # type: ignore[override]
        """The simulated camera's frame rate (``layout.camera_fps``)."""
        return float(self.sim.layout.camera_fps)


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
        self._view: Optional[View] = None
        self._board: Optional[_BoardLayer] = None
        self._angle = 0.0
        self._frame = 0

    def begin(self, T_base_flange: np.ndarray) -> None:
        T = as_transform(T_base_flange, "T_base_flange")
        self._view = self.world.view(self.layout, T, num_threads=self.num_threads)
        self._board = _BoardLayer.of(self.layout, self._view, T)

    def laser_at(self, angle: float) -> None:
        self._angle = float(angle)

    def grab(self) -> np.ndarray:
        if self._view is None:
            raise InvalidInputError(
                "camera: call begin(T_base_flange) before grab(); the cell does this at each scan pose"
            )
        img = _frame(self._view, self._board, self._angle, self.seed + self._frame, self.num_threads)
        self._frame += 1
        return img
