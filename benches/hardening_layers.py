"""The classes of benches/hardening.py over the layers above the core (issue 16 item 6): device
configs and safety checks, the simulator's arguments, calibration and the cell. Each case takes
one public constructor or function with valid arguments, replaces one or two of them by a bad
scalar (or a wrong object), and calls it; a result must keep the promise the oracle checks."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from hardening_cases import Cases, WrongAnswer, _bad_scalar


def _mutate(rng, valid: dict, names=None) -> dict:
    """``valid`` with one or two of ``names`` (default: all) set to a bad scalar."""
    keys = sorted(names or valid)
    out = dict(valid)
    for k in rng.sample(keys, min(len(keys), rng.choice([1, 1, 2]))):
        out[k] = _bad_scalar(rng)
    return out


def _finite(*values) -> None:
    for v in values:
        if not np.isfinite(np.asarray(v, dtype=np.float64)).all():
            raise WrongAnswer(f"accepted, but holds a non-finite value: {v!r:.80}")


class Configs(Cases):
    """Driver configs, serial settings, the motor range, the cell's limits and each safety check."""

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        from binpick import devices
        from binpick.transforms import look_down

        self.dv, self.look_down = devices, look_down
        self.kinds = [
            devices.SerialSettings,
            devices.MotorRange,
            devices.DynamixelConfig,
            devices.AiMotorConfig,
            devices.GripperConfig,
            devices.MelfaConfig,
            devices.CellLimits,
        ]

    def run(self, i):
        rng, dv = self.rng(i), self.dv
        if i % 3:
            cls = rng.choice(self.kinds)
            c = cls(**_mutate(rng, dict(cls().__dict__)))
            _finite(*(v for v in c.__dict__.values() if isinstance(v, (int, float)) and not isinstance(v, bool)))
            return
        limits = dv.CellLimits()
        T = self.look_down(rng.uniform(0, 500), rng.uniform(-400, 400), rng.uniform(-50, 600))
        args = _mutate(rng, dict(T=T, limits=limits, v=rng.uniform(0, 300)))
        which = rng.choice(["pose", "override", "speed", "xyzabc"])
        if which == "pose":
            out = dv.safety.check_pose(args["T"], args["limits"])
            lo, hi = np.asarray(limits.workspace_min_mm), np.asarray(limits.workspace_max_mm)
            if not ((lo <= out[:3, 3]) & (out[:3, 3] <= hi)).all():
                raise WrongAnswer(f"check_pose passed a pose outside the workspace: {out[:3, 3]}")
        elif which == "override":
            if dv.safety.check_override(args["v"], args["limits"]) > limits.max_override_percent:
                raise WrongAnswer(f"check_override passed {args['v']!r}")
        elif which == "speed":
            if dv.safety.check_linear_speed(args["v"], args["limits"]) > limits.max_linear_speed_mm_s:
                raise WrongAnswer(f"check_linear_speed passed {args['v']!r}")
        else:
            v = [args["v"], 0.0, 300.0, rng.uniform(-3, 3), _bad_scalar(rng), 0.5]
            _finite(dv.transform_from_xyzabc(v))


class SimArgs(Cases):
    """The simulated cell's layout, piles (one part, short settling), views, the checkerboard
    renderer and contact sheets."""

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        import binpick
        from binpick import sim

        v = np.array([[x, y, z] for x in (0.0, 20.0) for y in (0.0, 20.0) for z in (0.0, 20.0)])
        f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4]])
        f = np.vstack([f, [[2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]])
        self.sim = sim
        self.cube = binpick.Model.from_arrays(v, f, count=200)
        self.camera = sim.Camera(64, 48, 80.0, 80.0, 31.5, 23.5)
        self.cell = sim.Cell(camera=self.camera)
        self.view = sim.World.of_pile(sim.Pile(self.cube, 1, max_settle_time=0.3)).view(self.cell, num_threads=1)
        self.T_board = np.eye(4)
        self.T_board[:3, 3] = (-20.0, -10.0, 200.0)

    def run(self, i):
        rng, sim = self.rng(i), self.sim
        which = rng.choice(["layout", "pile", "frames", "checkerboard", "sheet"])
        if which == "layout":
            cls, valid = rng.choice(
                [
                    (sim.Lighting, dict(ambient=55.0, lamp=45.0, background=6.0)),
                    (sim.SensorNoise, dict(read_noise=1.5, shot_noise=0.08, speckle=0.0, blur=0.6)),
                    (sim.Laser, dict(sheet_sigma=0.6, power=120.0, fan_angle=1.0, reference_distance=500.0)),
                    (sim.Bin, dict(floor_z=0.0, wall_thickness=8.0)),
                ]
            )
            c = cls(**_mutate(rng, valid))
            _finite(*(getattr(c, k) for k in valid))
        elif which == "pile":
            # The part count and the decomposition resolution stay valid: a large valid pile is
            # legitimately slow, which is not what this class measures.
            valid = dict(seed=0, friction=0.5, restitution=0.05, time_step=1 / 120, max_settle_time=0.3, skin=0.3)
            pile = sim.Pile(self.cube, 1, **_mutate(rng, valid, [*valid, "max_convex_hulls"]))
            _finite(pile.poses)
        elif which == "frames":
            kw = _mutate(rng, dict(seed=0, num_threads=1, angle=0.1))
            frames = self.view.frames([kw.pop("angle")], **kw)
            if frames.shape != (1, 48, 64, 3):
                raise WrongAnswer(f"frames of shape {frames.shape}")
        elif which == "checkerboard":
            kw = _mutate(rng, dict(square=10.0, margin=5.0, angle=0.0, supersample=1, seed=0))
            kw["pattern"] = rng.choice([(4, 3), (4, 3), (_bad_scalar(rng), 3)])
            img = sim.render_checkerboard(self.camera, self.T_board, **kw)
            if img.shape != (48, 64, 3):
                raise WrongAnswer(f"a checkerboard of shape {img.shape}")
        else:
            kw = _mutate(rng, dict(picks=3, columns=2, width=200))
            sheet = sim.contact_sheet(np.zeros((3, 8, 8, 3), np.uint8), **kw)
            if sheet.shape[1] > kw["width"]:
                raise WrongAnswer(f"a sheet {sheet.shape[1]} px wide for width={kw['width']}")


class Calibration(Cases):
    """Board points and poses, the laser-plane fit, the projector and hand-eye solutions."""

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        from binpick import calibration
        from binpick.camera import CameraIntrinsics

        self.cal = calibration
        self.camera = CameraIntrinsics.pinhole(160, 120, 200.0, 200.0, 79.5, 59.5)
        self.plane = np.random.default_rng(2).uniform(-50, 50, size=(60, 3)) * (1, 1, 0) + (0, 0, 100)

    def run(self, i):
        rng, cal = self.rng(i), self.cal
        which = rng.choice(["points", "pose", "plane", "projector"])
        if which == "points":
            kw = _mutate(rng, dict(cols=4, rows=3, square=10.0))
            pts = cal.board_object_points((kw["cols"], kw["rows"]), kw["square"])
            _finite(pts)
        elif which == "pose":
            corners = cal.board_object_points((4, 3), 10.0)[:, :2] + (60.0, 40.0)
            kw = _mutate(rng, dict(corners=corners, camera=self.camera, square=10.0))
            _finite(cal.board_pose(kw["corners"], kw["camera"], (4, 3), kw["square"]))
        elif which == "plane":
            kw = _mutate(rng, dict(inlier_distance=0.5, iterations=50, seed=0))
            normal, offset, _ = cal.fit_plane(self.plane, **kw)
            if abs(abs(offset) - 100.0) > 1e-6:
                raise WrongAnswer(f"fit_plane: offset {offset} for the plane z = 100")
        else:
            d = [400.0, 450.0, 500.0, 550.0]
            a = [0.30, 0.27, 0.245, 0.225]
            (d if rng.random() < 0.5 else a)[rng.randrange(4)] = _bad_scalar(rng)
            p = cal.calibrate_projector(d, a)
            _finite(p.p_x, p.p_z)


class CellArgs(Cases):
    """The gripper geometry, the cell configuration and the laser sweep it plans."""

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        import binpick
        from binpick import cell
        from binpick.transforms import look_down

        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from _files import small_calibration

        self.cellmod, self.look_down = cell, look_down
        self.model = binpick.parts.tee(resolution=2.0, spacing=2.0)
        self.calibration = small_calibration()

    def run(self, i):
        rng, cell = self.rng(i), self.cellmod
        if i % 2:
            names = ("open_width_mm", "finger_length_mm", "tip_depth_mm", "body_radius_mm")
            g = cell.GripperGeometry(**_mutate(rng, {n: getattr(cell.GripperGeometry(), n) for n in names}))
            _finite(*(float(getattr(g, n)) for n in names))
            return
        valid = dict(frames=4, approach_distance_mm=40.0, max_collision_points=15, min_confidence=0.3)
        valid.update(max_candidates=5, keep_frames=6, num_threads=0, floor_clearance_mm=0.0)
        config = cell.CellConfig(
            calibration=self.calibration,
            model=self.model,
            bin_bounds=((250.0, -100.0, 0.0), (550.0, 100.0, 80.0)),
            scan_poses=(self.look_down(400.0, 0.0, 450.0),),
            drop_pose=self.look_down(400.0, -250.0, 350.0),
            **_mutate(rng, valid),
        )
        angles = cell.sweep_angles(config.calibration, config.scan_poses[0], config.bin_bounds, config.frames)
        if len(angles) != config.frames or not np.isfinite(angles).all() or (np.abs(angles) > math.pi).any():
            raise WrongAnswer(f"sweep_angles gave {angles!r:.80} for frames={config.frames}")


#: Name → class, as benches/hardening.py lists its classes.
LAYERS = {"configs": Configs, "simargs": SimArgs, "calibration": Calibration, "cell": CellArgs}
