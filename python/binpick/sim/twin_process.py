"""The digital twin as its own process: ``binpick emulate cell --out DIR``.

It runs a :class:`~binpick.sim.twin.TwinWorld` (the settled pile with physics, the robot, laser
motor and gripper emulators on ptys) and serves its camera — :class:`~binpick.sim.SimCamera`
rendering from the emulated arm's actual pose with the laser at the motor emulator's actual
angle — on the Unix-domain socket ``DIR/camera.sock`` (protocol:
:mod:`binpick.cell.camera_socket`). It writes into ``DIR``:

* ``cell.toml`` — the cell file for ``binpick pick``: the ptys, ``[camera] source = "twin"``,
  the bin, scan and drop poses, the tool, the limits, the twin's checkerboard
  (``[calibration_board]``, for ``binpick calibrate capture``) and
  ``calibration = "calibration.toml"``: the calibration the integrator solves (``binpick pick``
  needs that file);
* ``true_calibration.toml`` — the twin's exact calibration, for checking a solved one only;
* ``world.json`` — kept current (:data:`WORLD_VERSION`): the parts in the bin with their poses,
  ``removed`` (parts taken out), ``held`` (the part in the gripper), ``collisions`` (the robot's
  alarms and every contact of the gripper with the bin or a part that the twin saw), the arm's
  pose and the laser angle.

Every file is written atomically (a temporary file, then :func:`os.replace`). The twin runs
until SIGINT or SIGTERM and then exits 0, leaving the files (the socket is removed).
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from .._validate import write_atomic
from ..calibration.eye_to_hand import BALL_RADIUS_MM, T_FLANGE_BALL, sphere_mesh
from ..cell import camera_socket as wire
from ..cell.cell_file import GRIPPER_SHAPE_KEYS
from ..cell.shots import EyeToHand
from ..devices.xyzabc import xyzabc_from_transform
from ..errors import BinpickError
from ..models import Model
from .camera import SimCamera
from .render import World
from .sensors import DepthCamera, render_depth
from .twin import TwinWorld

__all__ = ["CellTwin", "WORLD_VERSION", "fixed_camera"]

#: The renderer's id of the calibration ball (a part id no pile uses).
BALL_ID = 9999

#: The version of world.json's layout.
WORLD_VERSION = 1


def _toml_list(values: Any) -> str:
    return "[" + ", ".join(f"{float(v) + 0.0:.6f}" for v in values) + "]"


def _pose_deg(T: np.ndarray) -> list[float]:
    """[X, Y, Z, A, B, C] with A, B, C in degrees, as the cell file writes poses."""
    v = xyzabc_from_transform(T)
    return [*v[:3], *np.degrees(v[3:])]


def fixed_camera(bin_bounds: Any) -> DepthCamera:
    """The twin's fixed 3-D camera: an industrial structured-light camera on a stand beyond the
    bin (``bin_bounds``: its (min, max) corners, mm), 900 mm from the floor's centre, looking down
    at it 25° from vertical."""
    lo, hi = np.asarray(bin_bounds, dtype=np.float64)
    centre = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]
    return DepthCamera.structured_light().looking_at(centre, distance=900.0, tilt_deg=25.0, azimuth_deg=0.0)


class _CameraServer:
    """Serves the twin's camera on a Unix-domain socket, one thread per connection; each frame
    is rendered under the world's lock from where the arm and the laser really are."""

    def __init__(
        self,
        world: TwinWorld,
        path: Path,
        progress: Callable[[str, str], None],
        depth: Optional[DepthCamera] = None,
        *,
        ball: bool = False,
        state: Optional[Callable[[], dict]] = None,
    ) -> None:
        self.world = world
        self.state = state
        self.depth = depth
        self.ball = sphere_mesh(BALL_RADIUS_MM, 4) if ball else None
        self.path = path
        self.progress = progress
        self.camera = SimCamera(world, seed=world.seed)
        self.frames = 0
        self._key: Optional[tuple[bytes, bytes]] = None
        self._view_pose = np.eye(4)
        self._stop = threading.Event()
        self._conns: list[socket.socket] = []
        if path.exists() or path.is_symlink():
            path.unlink()
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.bind(str(path))
        self._sock.listen(8)
        self._sock.settimeout(0.2)
        self._thread = threading.Thread(target=self._accept, name="twin-camera", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            self._conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), name="twin-camera-client", daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(None)
        self.progress("camera", "a client connected")
        try:
            while not self._stop.is_set():
                try:
                    request = wire.recv_exact(conn, wire.REQUEST_SIZE, "camera request")
                except BinpickError:
                    return  # the client hung up (or sent a part of a request and hung up)
                try:
                    op = wire.decode_request(bytes(request))
                except BinpickError as exc:
                    conn.sendall(wire.encode_error(str(exc)))
                    return  # the stream cannot be trusted past a bad request
                if op == wire.OP_WORLD:
                    conn.sendall(self._world_reply())
                elif op == wire.OP_CLOCK:  # the hardware time alone: nothing settles
                    conn.sendall(wire.encode_document({"clock_s": self.world.clock.now()}))
                else:
                    conn.sendall(self._depth_reply() if op == wire.OP_DEPTH else self._frame_reply())
        except OSError:
            pass
        finally:
            conn.close()
            self.progress("camera", "a client disconnected")

    def _world_reply(self) -> bytes:
        """The twin's ground truth now (world.json's document), the world settled first."""
        if self.state is None:
            return wire.encode_error("this twin serves no ground truth")
        try:
            with self.world.lock:
                self.world.settle_pending()
                doc = self.state()
            return wire.encode_document(doc)
        except BinpickError as exc:
            return wire.encode_error(f"{type(exc).__name__}: {exc}")

    def _frame_reply(self) -> bytes:
        try:
            with self.world.lock:
                self.world.settle_pending()
                pose = self.world.robot_emulator.pose()
                key = (np.round(pose, 6).tobytes(), self.world.pile.poses.tobytes())
                if key != self._key:
                    t0 = time.perf_counter()
                    self.camera.begin(pose)
                    self._key, self._view_pose = key, pose
                    self.progress(
                        "camera",
                        f"view from flange ({pose[0, 3]:.1f}, {pose[1, 3]:.1f}, {pose[2, 3]:.1f}) mm cast in "
                        f"{(time.perf_counter() - t0) * 1e3:.0f} ms; {self.frames} frames served so far",
                    )
                angle = self.world.laser_angle()
                image = self.camera.grab()
                counter, self.frames = self.frames, self.frames + 1
            return wire.encode_frame(image, counter, angle, self._view_pose)
        except BinpickError as exc:
            return wire.encode_error(f"{type(exc).__name__}: {exc}")

    def _depth_reply(self) -> bytes:
        """One shot of the fixed depth camera: the pile as it lies now, its noise seeded by the shot's number."""
        if self.depth is None:
            return wire.encode_error(
                "this twin's camera rides on the arm; start it with --camera fixed for depth shots"
            )
        try:
            with self.world.lock:
                self.world.settle_pending()
                world = World.of_pile(self.world.pile)
                pose = self.world.robot_emulator.pose()
                if self.ball is not None:  # the calibration ball the arm carries instead of its gripper
                    world.add_instance(world.add_mesh(*self.ball), pose @ T_FLANGE_BALL, BALL_ID)
                counter, self.frames = self.frames, self.frames + 1
            t0 = time.perf_counter()
            shot = render_depth(world, self.depth, seed=self.world.seed + counter, num_threads=self.world.num_threads)
            self.progress(
                "camera",
                f"depth shot {counter}: {int(shot.valid.sum())} points in {(time.perf_counter() - t0) * 1e3:.0f} ms",
            )
            return wire.encode_frame(shot.points.astype(np.float32), counter, 0.0, pose)
        except BinpickError as exc:
            return wire.encode_error(f"{type(exc).__name__}: {exc}")

    def close(self) -> None:
        self._stop.set()
        self._sock.close()
        for conn in self._conns:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self._thread.join(timeout=2.0)
        if self.path.exists():
            self.path.unlink()


class CellTwin:
    """The twin process's content: the :class:`TwinWorld`, its camera server and its files.

    Args:
        out: the folder for cell.toml, true_calibration.toml, world.json and camera.sock.
        model: the part.
        part_ref: how cell.toml names the part (a built-in name, or the mesh file's absolute path).
        unit: the mesh file's unit, for cell.toml.
        progress: stage printer.
        world_options: :class:`TwinWorld` arguments (count, seed, frames, speed_scale, …).
    """

    def __init__(
        self,
        out: Any,
        model: Model,
        *,
        part_ref: str,
        unit: str = "mm",
        progress: Callable[[str, str], None],
        camera: str = "arm",
        tool: str = "gripper",
        **world_options: Any,
    ) -> None:
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.part_ref, self.unit, self.progress = part_ref, unit, progress
        for stale in (self.socket_path, self.cell_file):  # a previous twin's, until this one is up
            if stale.exists() or stale.is_symlink():
                stale.unlink()
        self.world = TwinWorld(model, progress=progress, **world_options)
        self.fixed = fixed_camera(self.world.layout.bin.bounds) if camera == "fixed" else None
        self.tool = tool
        self.camera: Optional[_CameraServer] = None
        self.alarms: list[dict] = []
        self._alarm: Optional[str] = None
        self._last_world = ""
        self._t0 = time.time()

    @property
    def cell_file(self) -> Path:
        return self.out / "cell.toml"

    @property
    def world_file(self) -> Path:
        return self.out / "world.json"

    @property
    def socket_path(self) -> Path:
        return self.out / "camera.sock"

    def start(self) -> CellTwin:
        """Starts the emulators, writes the files, and opens the camera socket last: once
        ``camera.sock`` exists, cell.toml names this twin's ports (a script waits for it with
        ``until [ -S DIR/camera.sock ]``)."""
        self.world.start()
        write_atomic(self.out / "true_calibration.toml", self.world.config.calibration.to_toml())
        if self.fixed is not None:
            EyeToHand(self.fixed.T_base_camera).save(self.out / "true_eye_to_hand.toml")
        write_atomic(self.cell_file, self.cell_toml())
        self.tick()
        self.camera = _CameraServer(
            self.world, self.socket_path, self.progress, self.fixed, ball=self.tool == "ball", state=self.world_state
        )
        return self

    def close(self) -> None:
        """Stops the camera and the emulators; world.json keeps the last state."""
        if self.camera is not None:
            self.camera.close()
        try:
            self.tick()
        finally:
            self.world.close()

    def cell_toml(self) -> str:
        """The cell file of the twin (see the module docstring)."""
        w = self.world
        lo, hi = w.layout.bin.bounds
        lim = w.limits
        part = json.dumps(self.part_ref)
        return f"""\
# binpick cell file written by `binpick emulate cell`: the digital twin's ports, camera and poses.
# Lengths in mm; poses as [X, Y, Z, A, B, C] with A, B, C in degrees (MELFA: R = Rz(C)·Ry(B)·Rx(A)).

{self._robot_table()}

[motor]
port = "{w.motor_emulator.slave_path}"   # laser motor emulator
protocol = "dynamixel"
id = 1
baudrate = 57600

[gripper]
kind = "modbus"
port = "{w.gripper_emulator.slave_path}"   # Modbus RTU gripper emulator
slave = 9
baudrate = 115200
{self._gripper_shape()}

{self._camera_table()}

[part]
model = {part}
unit = "{self.unit}"

[cell]
calibration = "calibration.toml"   # the one you solve (binpick calibrate); the twin's own is true_calibration.toml
bin_min_mm = {_toml_list(lo)}
bin_max_mm = {_toml_list(hi)}
scan_pose = {_toml_list(_pose_deg(w.layout.T_base_flange if self.fixed is None else w.drop_pose))}
drop_pose = {_toml_list(_pose_deg(w.drop_pose))}
frames = {int(w.frames)}
tool = {_toml_list(_pose_deg(w.gripper_geometry.T_flange_gripper))}

{self._board_table()}[limits]
workspace_min_mm = {_toml_list(lim.workspace_min_mm)}
workspace_max_mm = {_toml_list(lim.workspace_max_mm)}
approach_height_mm = {lim.approach_height_mm:.6f}
max_tool_tilt_deg = {math.degrees(lim.max_tool_tilt_rad):.6f}
max_lateral_below_mm = {lim.max_lateral_below_mm:.6f}
max_override_percent = {lim.max_override_percent:g}
max_linear_speed_mm_s = {lim.max_linear_speed_mm_s:g}
max_push_mm = {lim.max_push_mm:g}   # sideways travel of a nudge below the approach height
"""

    def _camera_table(self) -> str:
        """cell.toml's [camera]: the camera on the arm, or the fixed depth camera and its eye-to-hand file."""
        if self.fixed is None:
            return """[camera]
source = "twin"
socket = "camera.sock"        # relative to this file"""
        return """[camera]
source = "twin_depth"         # the fixed 3-D camera above the bin (eye-to-hand); scan_pose parks the arm
socket = "camera.sock"        # relative to this file
eye_to_hand = "eye_to_hand.toml"   # the one you solve; the twin's own is true_eye_to_hand.toml"""

    def _robot_table(self) -> str:
        """cell.toml's [robot]: the MELFA emulator's pty, or the UR controller's address and ports."""
        w, lim = self.world, self.world.limits
        speed = f"linear_speed_mm_s = {min(250.0, lim.max_linear_speed_mm_s):g}"
        if w.robot == "ur":
            a = w.robot_emulator.addresses
            return f"""[robot]
driver = "ur"                 # Universal Robots controller emulator: RTDE, dashboard, URScript
host = "{a["rtde"][0]}"
rtde_port = {a["rtde"][1]}
dashboard_port = {a["dashboard"][1]}
secondary_port = {a["secondary"][1]}
{speed}"""
        return f"""[robot]
port = "{w.robot_emulator.slave_path}"   # MELFA controller emulator, R3 protocol
baudrate = 9600
override_percent = {min(50.0, lim.max_override_percent):g}
{speed}"""

    def _gripper_shape(self) -> str:
        """cell.toml's [gripper] shape keys: the twin's gripper (see :func:`binpick.sim.sim_gripper`)."""
        g = self.world.gripper_geometry
        values = {k: getattr(g, k) for k in GRIPPER_SHAPE_KEYS}
        return "\n".join(f"{k} = {'false' if v is None else f'{float(v):.6f}'}" for k, v in values.items())

    def _board_table(self) -> str:
        """cell.toml's [calibration_board]: the twin's checkerboard, for `binpick calibrate capture`
        (nothing when the layout has no board)."""
        board = self.world.layout.board
        if board is None:
            return ""
        return f"""\
[calibration_board]   # the checkerboard lying face up in the twin, for `binpick calibrate capture`
pattern = [{board.pattern[0]}, {board.pattern[1]}]   # inner corners: columns, rows
square_mm = {float(board.square):.6f}
center_mm = {_toml_list(board.center)}   # the centre of the corner grid, base frame

"""

    # -- the world's state
    def tick(self) -> None:
        """Settles a released part, looks for contacts, and rewrites world.json when it changed."""
        with self.world.lock:
            self.world.settle_pending()
            self._check_contacts()
            doc = self.world_state()
        text = json.dumps(doc, indent=1)
        key = json.dumps({k: v for k, v in doc.items() if k != "time_s"})
        if key != self._last_world:
            self._last_world = key
            write_atomic(self.world_file, text)

    def world_state(self) -> dict:
        """world.json's content (see the module docstring); call under the world's lock."""
        w = self.world
        return {
            "version": WORLD_VERSION,
            "units": "mm, rad",
            "part": w.model.name,
            "time_s": round(time.time() - self._t0, 3),
            "in_bin": [
                {"id": int(i), "T_base_object": T.tolist()} for i, T in zip(w.pile.ids, np.asarray(w.pile.poses))
            ],
            "removed": [int(i) for i in w.removed],
            "held": w.held,
            "collisions": list(w.collisions) + list(self.alarms),
            "T_base_flange": w.robot_emulator.pose().tolist(),
            "laser_angle": w.laser_angle(),
            "frames_served": 0 if self.camera is None else self.camera.frames,
            "clock_s": round(w.clock.now(), 4),
        }

    def _check_contacts(self) -> None:
        """Records each new robot alarm (the world records the gripper's contacts along every
        motion itself: :attr:`TwinWorld.collisions`)."""
        alarm = self.world.robot_emulator.alarm
        what = f"robot alarm {alarm}" if alarm else None
        if what is not None and what != self._alarm:
            event = {"time_s": round(time.time() - self._t0, 3), "with": what, "points": 0}
            event["T_base_flange"] = self.world.robot_emulator.pose().tolist()
            self.alarms.append(event)
            self.progress("ALARM", f"the robot reports {what}")
        self._alarm = what

    def run(self, stop: threading.Event, *, tick_s: float = 0.1) -> None:
        """Ticks the world until ``stop`` is set."""
        while not stop.wait(tick_s):
            self.tick()
