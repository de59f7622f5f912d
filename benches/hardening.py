"""The measurement of issue 16: generated bad inputs and misuse over seven classes (arrays, integer
and float parameters, units, corrupt meshes, other files, vision inputs, hostile serial devices)
plus the robot's raw ``command``, and four over the layers above the core (benches/hardening_layers.py:
device configs and safety checks, simulator arguments, calibration, the cell), each case run in a
long-lived worker process under a 4 GiB address-space limit and a 5 s wall-clock limit. Counts per
class: ok, BinpickError subclasses, Python TypeError, InternalError, other exceptions, aborts, hangs,
and silent wrong answers where an oracle exists. Prints a table per class and the totals; writes
results.json to --out.

Run: PYTHONPATH=python python benches/hardening.py [--cases 2000 | --quick] [--seed 16]
     [--workers 1] [--classes arrays,params,...] [--out DIR]"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import select
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from hardening_cases import Cases, WrongAnswer, _bad_scalar
from hardening_layers import LAYERS

ROOT = Path(__file__).resolve().parents[1]
CLASSES = ("arrays", "params", "units", "meshes", "files", "vision", "devices", "command", *LAYERS)
CASE_LIMIT_S = 5.0
ADDRESS_LIMIT = 4 << 30
EXAMPLES = 5


def _cloud(rng: random.Random):
    """An array argument: valid clouds among wrong shapes, dtypes, NaN/inf, empty, degenerate, huge."""
    n = rng.choice([0, 1, 2, 3, 4, 10, 50, 200])
    g = np.random.default_rng(rng.randrange(2**32))
    base = g.normal(size=(n, 3)) * 20.0
    kind = rng.randrange(16)
    if kind == 0:
        return base
    if kind == 1:
        return base[:, :2]
    if kind == 2:
        return base.reshape(-1)
    if kind == 3:
        return np.zeros((n, 3, 1))
    if kind == 4:
        return base.astype(rng.choice([np.float32, np.int32, np.int8, np.uint64, np.float16, np.bool_]))
    if kind == 5:
        return base.astype(rng.choice([np.complex128, object, str]))
    if kind == 6:
        bad = base.copy()
        if n:
            bad[rng.randrange(n), rng.randrange(3)] = rng.choice([np.nan, np.inf, -np.inf])
        return bad
    if kind == 7:
        return np.zeros((n, 3))  # all equal
    if kind == 8:
        return np.outer(np.arange(n), [1.0, 2.0, 3.0])  # collinear
    if kind == 9:
        return base * rng.choice([1e16, 1e30, 1e300, 1e-300])
    if kind == 10:
        return base + rng.choice([1e16, -1e19, 1e200])
    if kind == 11:
        return np.asfortranarray(base)[::-1] if n else base
    if kind == 12:
        return base.tolist()
    if kind == 13:
        return rng.choice([None, "points", 3, [[1, 2]], [[1, 2, 3], [4, 5]], b"\x00" * 24])
    if kind == 14:
        big = np.zeros((3, 3))
        big[:, 0] = [0.0, 2e19, 4e19]
        return big
    return np.column_stack([g.uniform(0, 100, n), g.uniform(0, 100, n), np.zeros(n)])  # planar


# --------------------------------------------------------------------------- oracles


def _finite(a, shape_cols=None, name="result"):
    a = np.asarray(a)
    if a.dtype.kind != "f" or not np.all(np.isfinite(a)):
        raise WrongAnswer(f"{name}: non-finite or non-float ({a.dtype})")
    if shape_cols is not None and (a.ndim != 2 or a.shape[1] != shape_cols):
        raise WrongAnswer(f"{name}: shape {a.shape}")
    return a


def _transform(T, name="T"):
    T = _finite(T, 4, name)
    if T.shape != (4, 4) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise WrongAnswer(f"{name}: not a rigid transform")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
        raise WrongAnswer(f"{name}: rotation not orthonormal")


def _mesh_ok(vertices, faces):
    v = _finite(vertices, 3, "vertices")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu":
        raise WrongAnswer(f"faces: shape {f.shape} dtype {f.dtype}")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise WrongAnswer(f"faces: index {f.max()} out of {len(v)} vertices")


def _model_ok(m):
    _mesh_ok(m.vertices, m.faces)
    _finite(m.points, 3, "points")
    _finite(m.normals, 3, "normals")


# --------------------------------------------------------------------------- the classes


class Arrays(Cases):
    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        import binpick

        self.model = binpick.parts.elbow(count=300)
        self.target = np.random.default_rng(0).normal(size=(200, 3)) * 20.0

    def run(self, i):
        bp, rng = self.bp, self.rng(i)
        a = _cloud(rng)
        which = rng.randrange(7)
        if which == 0:
            n = bp.estimate_normals(a, k=3)
            _finite(n, 3, "normals")
            if len(n) != len(np.asarray(a)) or not np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-6):
                raise WrongAnswer("normals: count or length")
        elif which == 1:
            out = _finite(bp.voxel_downsample(a, rng.choice([0.5, 1.0, 10.0]))[0], 3)
            if len(out) > len(np.asarray(a)):
                raise WrongAnswer("voxel_downsample grew the cloud")
        elif which == 2:
            src, tgt = (a, self.target) if rng.random() < 0.5 else (self.target, a)
            r = bp.icp(
                src, tgt, max_correspondence_distance=5.0, method=rng.choice(["point_to_point", "point_to_plane"])
            )
            _transform(r.T_target_source)
        elif which == 3:
            faces = np.array([[0, 1, 2]]) if rng.random() < 0.7 else _cloud(rng)
            _model_ok(bp.Model.from_arrays(a, faces, count=50))
        elif which == 4:
            path = self.tmp / "arr.ply"
            bp.write_ply(path, a)
            _finite(bp.read_ply(path)[0], 3)
        elif which == 5:
            r = bp.estimate_pose(a, self.model)
            _transform(r.T_scene_model)
        else:
            init = a if rng.random() < 0.5 else None
            r = bp.icp(self.target, self.target, init=init, max_correspondence_distance=5.0)
            _transform(r.T_target_source)


class Params(Arrays):
    def run(self, i):
        bp, rng = self.bp, self.rng(i)
        v, w = _bad_scalar(rng), _bad_scalar(rng)
        t = self.target
        which = rng.randrange(9)
        if which == 0:
            _finite(bp.estimate_normals(t, k=v, num_threads=rng.choice([0, 1, w])), 3)
        elif which == 1:
            _finite(bp.voxel_downsample(t, v)[0], 3)
        elif which == 2:
            names = ["max_correspondence_distance", "max_iterations", "num_threads", "trim_fraction"]
            kw = {"max_correspondence_distance": 5.0, rng.choice(names): v}
            bp.icp(t, t, **kw)
        elif which == 3:
            key = rng.choice(["count", "spacing", "seed"])
            kw = {"count": 40} if key == "seed" else {}
            kw[key] = v
            _model_ok(bp.Model.from_arrays(t[:4] * 0 + np.eye(4, 3) * 10, np.array([[0, 1, 2], [1, 2, 3]]), **kw))
        elif which == 4:
            bp.PpfParams(**{rng.choice(["sampling_ratio", "angle_bins", "rotation_bins"]): v})
        elif which == 5:
            key = rng.choice(["max_instances", "num_threads", "max_hypotheses", "min_fitness"])
            for r in bp.estimate_poses(t, self.model, **{key: v}):
                _transform(r.T_scene_model)
        elif which == 6:
            from binpick.camera import CameraIntrinsics

            f = v if rng.random() < 0.5 and isinstance(v, (int, float)) and not isinstance(v, bool) else 100.0
            try:
                K = np.array([[f, 0, 1], [0, 100, 1], [0, 0, 1]], dtype=float)
            except OverflowError:  # a Python int beyond a float: not the camera's input
                K = np.array([[100.0, 0, 1], [0, 100, 1], [0, 0, 1]])
            CameraIntrinsics(width=rng.choice([v, 64]), height=rng.choice([w, 48]), K=K, dist=np.zeros(5))
        elif which == 7:
            bp.parts.elbow(count=v) if rng.random() < 0.5 else bp.parts.tee(resolution=v)
        else:
            image = np.zeros((20, 20, 3), np.uint8)
            key = rng.choice(["threshold", "window", "max_jump"])
            bp.extract_line(image, **{key: v})


class Units(Arrays):
    def run(self, i):
        bp, rng = self.bp, self.rng(i)
        from binpick._validate import LENGTH_UNITS

        u = rng.choice(list(LENGTH_UNITS))
        # fmt: off
        unit = rng.choice([
            u, u.upper(), f"  {u} ", u[:-1] or "x", u + "s", "furlong", "", "µm", "mm\x00", "M", "in.", "inches",
            "mils", "km", "foot", None, 1, 1.0, b"mm", ["mm"], True,
            "".join(chr(rng.randrange(32, 0x3000)) for _ in range(rng.randint(0, 6))),
        ])
        # fmt: on
        expected = LENGTH_UNITS.get(unit.strip().lower()) if isinstance(unit, str) else None
        which = rng.randrange(3)
        if which == 2 and unit is None:
            expected = 1.0  # read_scene: None is the file's own unit, mm when it declares none
        v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
        f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        if which == 0:
            got = bp.Model.from_arrays(v, f, unit=unit, count=30).vertices
        elif which == 1:
            path = self.tmp / "unit.stl"
            if not path.exists():
                sys.path.insert(0, str(ROOT / "tests"))
                from _geometry import write_stl_binary

                write_stl_binary(path, v, f)
            got = bp.Model.from_mesh(path, unit=unit, count=30).vertices
        else:
            path = self.tmp / "unit.xyz"
            path.write_text("\n".join(" ".join(map(str, p)) for p in v) + "\n")
            got = bp.read_scene(path, unit=unit).points
        if expected is None:
            raise WrongAnswer(f"unit {unit!r} accepted")
        if not np.allclose(np.sort(np.asarray(got).ravel()), np.sort((v * expected).ravel()), rtol=1e-5):
            raise WrongAnswer(f"unit {unit!r}: scale wrong")


class Meshes(Cases):
    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        import binpick
        from binpick import _core

        sys.path.insert(0, str(ROOT / "tests"))
        from _files import mutate
        from _geometry import box_mesh, write_stl_ascii, write_stl_binary

        self.bp, self.core, self.mutate = binpick, _core, mutate
        v, f = box_mesh((40.0, 30.0, 20.0))
        self.originals = {}
        for name, write in (("stl", write_stl_binary), ("astl", write_stl_ascii)):
            p = tmp / f"box.{name}"
            write(p, v, f)
            self.originals[name] = p.read_bytes()
        ply = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x", "property float y"]
        ply += ["property float z", f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
        ply += [" ".join(map(str, p)) for p in v] + ["3 " + " ".join(map(str, t)) for t in f]
        self.originals["ply"] = ("\n".join(ply) + "\n").encode()
        head = "\n".join(ply[:9]).replace("ascii", "binary_little_endian") + "\n"
        body = v.astype("<f4").tobytes()
        body += b"".join(bytes([3]) + t.astype("<i4").tobytes() for t in f)
        self.originals["bply"] = head.encode() + body
        obj = [f"v {x} {y} {z}" for x, y, z in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
        self.originals["obj"] = ("\n".join(obj) + "\n").encode()
        pts = self.tmp / "pts.ply"
        binpick.write_ply(pts, np.random.default_rng(1).normal(size=(30, 3)), np.tile([0.0, 0.0, 1.0], (30, 1)))
        self.originals["cloudply"] = pts.read_bytes()

    def run(self, i):
        rng = self.rng(i)
        kind = rng.choice(sorted(self.originals))
        data = self.mutate(self.originals[kind], rng)
        if rng.random() < 0.4:  # a single flipped byte keeps most files loadable, so the oracle gets used
            data = bytearray(self.originals[kind])
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
            data = bytes(data)
        ext = {"astl": "stl", "bply": "ply", "cloudply": "ply"}.get(kind, kind)
        path = self.tmp / f"mutated.{ext}"
        path.write_bytes(data)
        which = rng.randrange(3)
        if which == 0:
            v, f = self.core.read_mesh(str(path), "mm")
            _mesh_ok(v, f)
        elif which == 1:
            _model_ok(self.bp.Model.from_mesh(path, count=100))
        elif ext == "ply":
            points, normals = self.bp.read_ply(path)
            _finite(points, 3, "read_ply points")
            if normals is not None and _finite(normals, 3, "read_ply normals").shape != points.shape:
                raise WrongAnswer("read_ply: normals and points differ in count")
        else:
            _finite(self.bp.read_scene(path).points, 3, "read_scene")


class Files(Cases):
    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        import binpick

        sys.path.insert(0, str(ROOT / "tests"))
        from _files import mutate, small_calibration, small_scan
        from binpick.calibration import CellCalibration
        from binpick.cell import CELL_FILE_EXAMPLE, config_from_file, load_cell_file
        from binpick.scan import load_scan

        self.mutate = mutate
        calibration = tmp / "calibration.toml"
        small_calibration().save(calibration)
        scan = small_scan(tmp / "scan")
        frame = load_scan(scan).frames[0]
        tee = binpick.parts.tee()
        binpick.parts.tee = lambda *a, **k: tee  # the cell file names the built-in tee: build it once
        pts = np.random.default_rng(2).normal(size=(40, 3)) * 10
        scenes = {}
        for ext in ("pcd", "xyz", "npy", "ply"):
            p = binpick.write_scene(tmp / f"scene.{ext}", pts)
            scenes[ext] = (p.read_bytes(), tmp / f"fuzzed.{ext}")
        self.model = binpick.parts.elbow(count=300)
        os.environ["BINPICK_CACHE_DIR"] = str(tmp / "cache")
        self.model.prepared()
        self.cache = next((tmp / "cache").rglob("*.*"))
        cache_bytes = self.cache.read_bytes()

        def prepared_again():
            self.model._prepared = None
            native = self.model.prepared()
            if native.ppf_pairs() <= 0:
                raise WrongAnswer("PPF table empty after a corrupt cache")

        def scene_reader(path):
            return lambda: _finite(binpick.read_scene(path).points, 3, "read_scene")

        fuzzed_cal, fuzzed_cell = tmp / "fuzzed.toml", tmp / "fuzzed_cell.toml"
        self.readers = [
            ("calibration", calibration.read_bytes(), fuzzed_cal, lambda: CellCalibration.load(fuzzed_cal)),
            ("scan.json", (scan / "scan.json").read_bytes(), scan / "scan.json", lambda: load_scan(scan)),
            ("frame PNG", frame.image_path.read_bytes(), frame.image_path, frame.image),
            (
                "cell file",
                CELL_FILE_EXAMPLE.encode(),
                fuzzed_cell,
                lambda: config_from_file(load_cell_file(fuzzed_cell)),
            ),
            ("PPF cache", cache_bytes, self.cache, prepared_again),
        ]
        self.readers += [(f"scene {ext}", data, p, scene_reader(p)) for ext, (data, p) in scenes.items()]

    def run(self, i):
        rng = self.rng(i)
        name, original, path, load = self.readers[i % len(self.readers)]
        data = self.mutate(original, rng)
        if name == "PPF cache" and rng.random() < 0.5:  # lying counts: overwrite a word with a huge one
            j = rng.randrange(max(1, len(data) - 8))
            data = data[:j] + rng.choice([b"\xff" * 8, (2**62).to_bytes(8, "little"), b"\0" * 8]) + data[j + 8 :]
        path.write_bytes(data)
        try:
            load()
        finally:
            path.write_bytes(original)


class Vision(Cases):
    def run(self, i):
        rng = self.rng(i)
        g = np.random.default_rng(rng.randrange(2**32))
        h, w = rng.choice([0, 1, 2, 5, 48, 480]), rng.choice([0, 1, 3, 64, 640])
        shape = rng.choice([(h, w, 3), (h, w), (h, w, 4), (h, w, 1), (h,), (h, w, 3, 1), (3, h, w)])
        dtype = rng.choice([np.uint8] * 4 + [np.uint16, np.float32, np.float64, np.int8, np.bool_, np.int64])
        img = g.integers(0, 256, size=shape).astype(dtype) if all(shape) or 0 in shape else None
        if img is not None and img.ndim >= 2 and img.size and dtype is np.uint8 and rng.random() < 0.6:
            img[:] = 0
            img[:, img.shape[1] // 2] = 255  # a line, so the extraction finds something
        if img is not None and dtype in (np.float32, np.float64) and img.size and rng.random() < 0.5:
            img.flat[rng.randrange(img.size)] = rng.choice([np.nan, np.inf])
        if rng.random() < 0.1:
            img = rng.choice([None, "image", [[1, 2], [3, 4]], b"\x00" * 12])
        elif rng.random() < 0.1 and img is not None and img.ndim >= 2:
            img = img[::-1, ::2] if img.shape[0] else img
        kw = {}
        if rng.random() < 0.3:
            kw[rng.choice(["threshold", "window", "max_jump", "method", "direction"])] = rng.choice(
                [_bad_scalar(rng), "cog", "gaussian", "rows", "columns", "auto", "x"]
            )
        uv = self.bp.extract_line(img, **kw)
        uv = np.asarray(uv)
        if uv.size:
            _finite(uv, 2, "extract_line")
            hh, ww = np.asarray(img).shape[:2]
            if uv[:, 0].min() < -0.5 or uv[:, 0].max() > ww or uv[:, 1].min() < -0.5 or uv[:, 1].max() > hh:
                raise WrongAnswer("extract_line: a point outside the image")


class Devices(Cases):
    """Hostile peers: a chatterer answering every request with random bytes, and the emulators
    playing transport faults; each call must end in a result or a DeviceError within its bound,
    and a faulted motion is never sent twice."""

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        sys.path.insert(0, str(ROOT / "tests" / "devices"))
        from device_settings import FAST_ROBOT
        from test_devices_fuzz import Chatter

        from binpick import devices as dv
        from binpick.devices.emulators import Fault, GripperEmulator, RobotEmulator, RobotEmulatorConfig

        self.Fault = Fault
        self.chatter = Chatter().start()
        line = dict(timeout_s=0.02, retries=1)
        path = self.chatter.slave_path
        self.robot_c = dv.MelfaRobot(
            path, config=dv.MelfaConfig(serial=dv.SerialSettings(parity="E", stopbits=2, **line))
        )
        self.bus = dv.DynamixelBus(path, settings=dv.SerialSettings(baudrate=57600, **line))
        self.ai = dv.AiMotor(path, config=dv.AiMotorConfig(serial=dv.SerialSettings(baudrate=57600, **line)))
        self.grip_c = dv.ModbusGripper(path, config=dv.GripperConfig(serial=dv.SerialSettings(baudrate=115200, **line)))
        self.remu = RobotEmulator(config=RobotEmulatorConfig(speed_scale=40.0)).start()
        self.robot = dv.MelfaRobot(self.remu.slave_path, config=FAST_ROBOT)
        self.robot.open_session()
        self.gemu = GripperEmulator().start()
        self.gripper = dv.ModbusGripper(
            self.gemu.slave_path,
            config=dv.GripperConfig(
                serial=dv.SerialSettings(baudrate=115200, timeout_s=0.05), poll_interval_s=0.005, move_timeout_s=1.0
            ),
        )

    def _robot_case(self, rng):
        from binpick.transforms import look_down

        emu, robot = self.remu, self.robot
        fault = rng.choice(sorted(emu.supported_faults - {self.Fault.CLOSE_PORT}, key=lambda f: f.value))
        emu.inject(fault, times=rng.randint(1, 3), delay_s=rng.choice([0.01, 0.1, 0.4]))
        before = len(emu.requests)
        op = rng.randrange(3)
        try:
            if op == 0:
                _transform(robot.read_pose(), "read_pose")
            elif op == 1:
                robot.state()
            else:
                robot.move_to(look_down(rng.uniform(250, 350), rng.uniform(-50, 50), rng.uniform(250, 350)))
        finally:
            sent = [r.split(";", 2)[-1] for r in emu.requests[before:]]
            emu.clear_faults()
            self._recover()
        if sum(c.startswith(("EXECMOV", "EXECMVS")) for c in sent) > 1:
            raise WrongAnswer(f"a motion was sent twice under {fault.name}: {sent}")

    def _recover(self):
        from binpick.errors import DeviceError

        try:
            self.robot.wait_until_idle(2.0)
            if self.robot.alarm_active or self.robot.state().error_number:
                self.robot.reset_alarm()
        except DeviceError:
            try:
                self.robot.open_session()
            except DeviceError:
                pass

    def _gripper_case(self, rng):
        emu, g = self.gemu, self.gripper
        fault = rng.choice(sorted(emu.supported_faults - {self.Fault.CLOSE_PORT}, key=lambda f: f.value))
        emu.inject(fault, times=rng.randint(1, 3), delay_s=rng.choice([0.01, 0.1]))
        try:
            rng.choice([g.status, g.open, g.close])()
        finally:
            emu.clear_faults()

    def run(self, i):
        rng = self.rng(i)
        t = time.monotonic()
        kind = rng.randrange(4)
        if kind <= 1:
            payload = bytes(rng.randrange(256) for _ in range(rng.randint(0, 64)))
            payload = rng.choice([payload, b"QoK" + payload + b"\r", b"\xff\xff\xfd\x00" + payload, b""])
            self.chatter.payload = payload
            # fmt: off
            call = rng.choice([
                self.robot_c.read_pose, self.robot_c.state, lambda: self.bus.ping(1), lambda: self.bus.read(1, 132, 4),
                self.ai.present_angle, self.grip_c.status,
            ])
            # fmt: on
            out = call()
            if isinstance(out, float) and not math.isfinite(out):
                raise WrongAnswer("a non-finite angle")
        elif kind == 2:
            self._robot_case(rng)
        else:
            self._gripper_case(rng)
        if time.monotonic() - t > 3.0:
            raise WrongAnswer(f"a device call took {time.monotonic() - t:.1f} s")


class Command(Cases):
    """``MelfaRobot.command`` with generated strings against the R3 emulator: nothing that moves
    the arm or changes speed or override may pass; a refused command sends nothing."""

    PREFIXES = ["EXEC", "EXECSPD", "OVRD", "EXECOVRD", "EXECJOVRD", "RUN", "JOG", "MOV", "MVS", "PRG", "HND", "SRV"]
    PREFIXES += ["CNTL", "OPEN=", "STOP", "PPOSF", "JPOSF", "DSTATE", "ERRORMES", "EXECP1=", "EXECMOV P", "SLOT"]
    MOTION = ("EXEC", "OVRD", "RUN", "JOG", "MOV", "MVS", "HND", "PRG", "SLOT")

    def __init__(self, seed, tmp):
        super().__init__(seed, tmp)
        sys.path.insert(0, str(ROOT / "tests" / "devices"))
        from device_settings import FAST_ROBOT

        from binpick.devices import CellLimits, MelfaRobot
        from binpick.devices.emulators import RobotEmulator, RobotEmulatorConfig
        from binpick.devices.melfa import SAFE_COMMANDS

        self.patterns = [p for p, _ in SAFE_COMMANDS.values()]
        self.safe = [n.replace("<n>", "1").replace("<client>", "NARCUSR") for n in SAFE_COMMANDS]
        self.emu = RobotEmulator(config=RobotEmulatorConfig(speed_scale=40.0)).start()
        self.robot = MelfaRobot(self.emu.slave_path, config=FAST_ROBOT, limits=CellLimits())
        self.robot.open_session()

    def _text(self, rng):
        alphabet = "EXCSPDOVRMJGNUHTLAF0123456789 =;,.()-P\t\r\n" + "".join(map(chr, range(32, 127)))
        tail = "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 14)))
        kind = rng.randrange(6)
        if kind == 0:
            return tail
        if kind in (1, 2):
            head = rng.choice(self.PREFIXES)
            return rng.choice([head, head.lower(), " " + head, head + " "]) + tail
        if kind == 3:
            return rng.choice(self.safe) + rng.choice(["", tail, ";" + tail, " ", "\r" + tail])
        if kind == 4:
            return rng.choice(self.safe)
        return rng.choice([None, 5, b"PPOSF", ["STOP"], "", "\x00PPOSF", "PPOSF\x00", "\u00c9XECSPD 9999"])

    def run(self, i):
        from binpick.errors import DeviceError, InvalidInputError, SafetyError

        if i % 100 == 0:
            try:
                self.robot.open_session()
            except DeviceError:
                pass
        rng = self.rng(i)
        cmd = self._text(rng)
        emu = self.emu
        before, speeds, joints = len(emu.requests), emu.speeds, emu.joints()
        refused = False
        try:
            self.robot.command(cmd, retry=rng.random() < 0.2)
        except (SafetyError, InvalidInputError):
            refused = True
            raise
        finally:
            sent = [r.split(";", 2)[-1] for r in emu.requests[before:]]
            if refused and sent:
                raise WrongAnswer(f"{cmd!r} was refused but {sent} reached the controller")
            if sent and not (
                isinstance(cmd, str)
                and any(re.fullmatch(p, cmd) for p in self.patterns)
                and not cmd.startswith(self.MOTION)
                and sent[0] == cmd
                and all(re.fullmatch(r"ERRORMES\d+", c) for c in sent[1:])  # the driver asks for an error's text
            ):
                raise WrongAnswer(f"{cmd!r} passed: {sent}")
            if emu.speeds != speeds or not np.allclose(emu.joints(), joints, atol=1e-6):
                raise WrongAnswer(f"{cmd!r} changed the speed or moved the arm")


CLASS_TYPES = {**dict(zip(CLASSES, (Arrays, Params, Units, Meshes, Files, Vision, Devices, Command))), **LAYERS}


# --------------------------------------------------------------------------- the worker


def _outcome(exc: BaseException) -> str:
    from binpick import errors

    if isinstance(exc, WrongAnswer):
        return "wrong"
    if isinstance(exc, errors.InternalError):
        return "InternalError"
    if isinstance(exc, errors.BinpickError):
        return f"BinpickError:{type(exc).__name__}"
    if type(exc) is TypeError:
        return "TypeError"
    return f"other:{type(exc).__name__}"


def worker(name: str, seed: int) -> None:
    """Reads case indices on stdin, answers one JSON line per case on the original stdout (the
    library's own prints go to stderr)."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_LIMIT, ADDRESS_LIMIT))
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    tmp = Path(tempfile.mkdtemp(prefix=f"binpick_hardening_{name}_"))
    cases = CLASS_TYPES[name](seed, tmp)
    reply.write(json.dumps({"ready": True}) + "\n")
    for line in sys.stdin:
        i = int(line)
        t = time.perf_counter()
        try:
            cases.run(i)
            out, detail = "ok", ""
        except Exception as exc:  # every outcome is counted, the point of the bench
            out = _outcome(exc)
            detail = f"{type(exc).__name__}: {str(exc)[:200]}"
            if out.startswith("other") or out == "InternalError":
                detail += " | " + traceback.format_exc(limit=-2)[-400:].replace("\n", " ")
        reply.write(json.dumps({"i": i, "outcome": out, "detail": detail, "s": time.perf_counter() - t}) + "\n")


# --------------------------------------------------------------------------- the parent


class Worker:
    def __init__(self, name: str, seed: int, log):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "python"), os.environ.get("PYTHONPATH", "")]))
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--worker", name, "--seed", str(seed)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=log,
            env=env,
            text=True,
            bufsize=1,
        )
        self.buf = ""
        ready = self.read(120.0)
        if not ready or not ready.get("ready"):
            raise RuntimeError(f"the {name} worker did not start (see the log)")

    def read(self, timeout: float):
        """One JSON reply, None when the worker died, "hang" after ``timeout``."""
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while "\n" not in self.buf:
            left = deadline - time.monotonic()
            if left <= 0:
                return "hang"
            r, _, _ = select.select([fd], [], [], left)
            if r:
                chunk = os.read(fd, 65536).decode()
                if not chunk:
                    return None
                self.buf += chunk
        line, self.buf = self.buf.split("\n", 1)
        return json.loads(line)

    def kill(self):
        self.proc.kill()
        self.proc.wait()


def run_class(name: str, cases: int, seed: int, workers: int, log) -> dict:
    counts: Counter = Counter()
    examples: dict[str, list] = {}
    slowest = (0.0, None)
    pool = [Worker(name, seed, log) for _ in range(workers)]
    pending = list(range(cases))[::-1]
    busy: dict[int, tuple[int, float]] = {}
    t0 = time.monotonic()

    def record(out, i, detail):
        counts[out] += 1
        if out != "ok" and not out.startswith("BinpickError") and len(examples.setdefault(out, [])) < EXAMPLES:
            examples[out].append({"case": i, "detail": detail})

    while pending or busy:
        for k, w in enumerate(pool):
            if k not in busy and pending:
                i = pending.pop()
                w.proc.stdin.write(f"{i}\n")
                w.proc.stdin.flush()
                busy[k] = (i, time.monotonic())
        for k in list(busy):
            i, started = busy[k]
            left = CASE_LIMIT_S - (time.monotonic() - started)
            got = pool[k].read(max(0.0, left) if len(busy) == 1 else min(0.02, max(0.0, left)))
            if got == "hang" and time.monotonic() - started < CASE_LIMIT_S:
                continue
            del busy[k]
            if isinstance(got, dict):
                record(got["outcome"], i, got["detail"])
                if got["s"] > slowest[0]:
                    slowest = (got["s"], i)
                continue
            if got == "hang":
                record("hang", i, f"over {CASE_LIMIT_S} s")
            else:
                pool[k].proc.wait()
                record("abort", i, f"worker died, exit status {pool[k].proc.returncode}")
            pool[k].kill()
            pool[k] = Worker(name, seed, log)
    for w in pool:
        w.proc.stdin.close()
        w.kill()
    return {
        "cases": cases,
        "counts": dict(counts),
        "examples": examples,
        "seconds": round(time.monotonic() - t0, 1),
        "slowest_case": {"seconds": round(slowest[0], 3), "case": slowest[1]},
    }


COLUMNS = ["ok", "BinpickError", "TypeError", "InternalError", "other", "abort", "hang", "wrong"]


def print_table(results: dict) -> None:
    head = f"{'class':<9}{'cases':>7}" + "".join(f"{c:>14}" for c in COLUMNS) + f"{'s':>8}"
    print(head)
    total: Counter = Counter()
    for name, r in results.items():
        row = Counter()
        for out, n in r["counts"].items():
            row[out.split(":")[0]] += n
        total.update(row)
        total["cases"] += r["cases"]
        print(f"{name:<9}{r['cases']:>7}" + "".join(f"{row[c]:>14}" for c in COLUMNS) + f"{r['seconds']:>8.0f}")
        errs = sorted((n, out.split(":", 1)[1]) for out, n in r["counts"].items() if out.startswith("BinpickError"))
        if errs:
            print("           BinpickError: " + ", ".join(f"{cls} {n}" for n, cls in errs[::-1]))
        for out, ex in r["examples"].items():
            for e in ex[:3]:
                print(f"           {out} case {e['case']}: {e['detail'][:300]}")
    print(f"{'total':<9}{total['cases']:>7}" + "".join(f"{total[c]:>14}" for c in COLUMNS))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=2000, help="cases per class (default 2000)")
    p.add_argument("--quick", action="store_true", help="about 100 cases per class")
    p.add_argument("--seed", type=int, default=16)
    p.add_argument("--workers", type=int, default=1, help="worker processes per class (default 1)")
    p.add_argument("--classes", default=",".join(CLASSES), help="comma-separated subset of " + ",".join(CLASSES))
    p.add_argument("--out", type=Path, default=None, help="folder for results.json and the workers' log")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        worker(args.worker, args.seed)
        return 0
    cases = 100 if args.quick else args.cases
    out = args.out or Path(tempfile.mkdtemp(prefix="binpick_hardening_"))
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    with open(out / "workers.log", "w") as log:
        for name in args.classes.split(","):
            results[name] = run_class(name, cases, args.seed, max(1, args.workers), log)
            print(f"{name}: {results[name]['counts']} in {results[name]['seconds']} s", flush=True)
    print_table(results)
    summary = {"seed": args.seed, "cases_per_class": cases, "limits": {"address_bytes": ADDRESS_LIMIT}}
    summary["limits"]["case_seconds"] = CASE_LIMIT_S
    (out / "results.json").write_text(json.dumps({**summary, "classes": results}, indent=1))
    print(f"results: {out / 'results.json'}")
    bad = sum(n for r in results.values() for o, n in r["counts"].items() if o.split(":")[0] in COLUMNS[3:])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
