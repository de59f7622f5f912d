"""The scenes of ``benches/sensors.py`` (see its docstring): the parts, the real bunny scans with
their registration, and the simulated cells, piles and sensors that render every class."""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np

import binpick
from binpick import sim
from binpick.transforms import inverse, quaternion_matrix, rotation_about
from near_symmetric import sim_cloud
from pose_peers import DENSE_SPACING, SYMMETRIES, Part, Scene
from pose_peers import symmetries as table_symmetries

HERE = Path(__file__).resolve().parent
DEFAULT_REAL = HERE.parents[1] / "shared" / "data" / "real" / "bunny"
DEFAULT_PARTS_DIR = HERE.parents[1] / "shared" / "data" / "parts"

SETS = ("bunny", "laser", "structured", "kinect", "tof")
BUILT_IN = ("tee", "elbow", "cross")
CAD = {"IPAGearShaft": "IPAGearShaft.stl", "IPARingScrew": "IPARingScrew.stl", "SileaneBunny": "SileaneBunny.obj"}
SIGMAS = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0)
MAX_INSTANCES = 3
TILT_DEG = 30.0
#: Distance range (mm) from the bin floor's centre per depth-camera class.
DISTANCES = {"structured": (700.0, 1000.0), "kinect": (800.0, 1200.0), "tof": (800.0, 1200.0)}
CAMERAS: dict[str, Callable[[], sim.DepthCamera]] = {
    "structured": sim.DepthCamera.structured_light,
    "kinect": sim.DepthCamera.kinect,
    "tof": sim.DepthCamera.tof,
}
STRUCTURED_SIGMA = 0.3  # mm at the scene's distance, normal incidence
LASER_FRAMES = 45
PILE_SIZE = 8
UNCOVERED = 0.9  # share of an instance's own pixels that must be visible
PILE_PLACEMENTS = 50  # piles take the depth cameras' placements from this index on, views from 0
#: The pile of another part each part is asked for on (issue: "a pile of a different part").
OTHER = {
    "tee": "elbow",
    "elbow": "keyed_shaft",
    "cross": "tee",
    "IPAGearShaft": "IPARingScrew",
    "IPARingScrew": "SileaneBunny",
    "SileaneBunny": "IPARingScrew",
}
BUNNY_NEGATIVE_PARTS = ("tee", "cross")
TITLES = {
    "bunny": "real Cyberware scans of the Stanford bunny, Gaussian noise along z",
    "laser": "simulated laser-line cell scans",
    "structured": f"structured light, {TILT_DEG:.0f}° off vertical, σ {STRUCTURED_SIGMA} mm",
    "kinect": f"Kinect-like, {TILT_DEG:.0f}° off vertical, 0.8–1.2 m",
    "tof": f"time of flight, {TILT_DEG:.0f}° off vertical, 0.8–1.2 m",
}


def note(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# parts


def group_of(name: str, model: binpick.Model) -> np.ndarray:
    """(S, 3, 3) proper symmetries about the mesh origin: ``pose_peers.SYMMETRIES`` where it knows
    the part, else the model's detected group when its centre lies on every axis (a rotation
    about the centre is then one about the origin); else the identity, with a warning."""
    if name in SYMMETRIES:
        return table_symmetries(name)
    sym = model.symmetries
    c = np.asarray(sym.center, dtype=np.float64)
    rotations = [np.asarray(R) for R in sym.rotations]
    if sym.continuous_axis is not None:
        axis = np.asarray(sym.continuous_axis, dtype=np.float64)
        rotations = [R @ rotation_about(axis, np.radians(a)) for R in rotations for a in range(360)]
    if any(np.linalg.norm(R @ c - c) > 0.5 for R in rotations):
        note(f"note: {name}: symmetry centre {np.round(c, 2)} off the axes through the origin; judged as asymmetric")
        return np.eye(3)[None]
    return np.stack(rotations)


def load_parts(names: Optional[list[str]], parts_dir: Path) -> dict[str, Part]:
    out: dict[str, Part] = {}
    for name in [*BUILT_IN, *CAD]:
        if names is not None and not any(n.lower() in name.lower() for n in names):
            continue
        if name in BUILT_IN:
            model = getattr(binpick.parts, name)()
            dense = model
        else:
            path = parts_dir / CAD[name]
            if not path.is_file():
                note(f"no {path}; skipping {name} (see ../shared/data/README.md)")
                continue
            model = binpick.Model.from_mesh(path, unit="m", name=name)
            dense = binpick.Model.from_mesh(path, unit="m", spacing=DENSE_SPACING, name=name)
        out[name] = Part(name=name, model=model, dense=dense, symmetries=group_of(name, model))
    return out


def other_model(name: str, parts_dir: Path) -> tuple[str, binpick.Model]:
    """The part whose pile ``name`` is asked for on (the tee where a CAD part is absent)."""
    other = OTHER[name]
    if other in BUILT_IN:
        return other, getattr(binpick.parts, other)()
    if other in CAD:
        path = parts_dir / CAD[other]
        if path.is_file():
            return other, binpick.Model.from_mesh(path, unit="m", name=other)
        return "tee", binpick.parts.tee()
    return other, binpick.parts.NEAR_SYMMETRIC[other]()


def pile_size(model: binpick.Model, bin: sim.Bin) -> int:
    """8, or fewer where a part's footprint (its two longest sides) fills much of the bin's floor."""
    a, b = sorted(np.ptp(np.asarray(model.vertices), axis=0))[1:]
    return int(np.clip(1.5 * bin.size[0] * bin.size[1] / (a * b), 3, PILE_SIZE))


# ---------------------------------------------------------------------------------------------
# scenes


@dataclass
class Case:
    """One scene as binpick sees it, and what judging it needs beyond ``pose_peers.Scene``."""

    set: str
    kind: str  # "view", "pile" or "scan" (the bunny's)
    scene: Scene
    up: Optional[tuple] = None
    meta: dict = field(default_factory=dict)
    pixels: Optional[Callable[[], np.ndarray]] = None  # visible pixel count per truth instance
    alone: Optional[Callable[[int], int]] = None  # pixels truth instance i fills rendered alone with the bin

    def sensor(self) -> dict:
        """How binpick is told where the sensor is: ``up`` (the bunny's scans) or the viewpoint; a
        swept laser scan judged along up, as the cell asks (binpick.cell)."""
        if self.up is not None:
            return {"up": self.up}
        return {"viewpoint": self.scene.viewpoint, "along_rays": self.set != "laser"}


def bunny_scans(root: Path, limit: Optional[int]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, points mm in the scan's frame, T_scan_mesh) of each scan ``bun.conf`` registers."""
    scans = []
    for line in (root / "bun.conf").read_text().splitlines():
        f = line.split()
        if not f or f[0] != "bmesh":
            continue
        t, (x, y, z, w) = np.array(f[2:5], dtype=np.float64) * 1e3, np.array(f[5:9], dtype=np.float64)
        T_mesh_scan = np.eye(4)
        T_mesh_scan[:3, :3], T_mesh_scan[:3, 3] = quaternion_matrix((w, x, y, z)).T, t
        scans.append((Path(f[1]).stem, binpick.read_scene(root / f[1]).points * 1e3, inverse(T_mesh_scan)))
        if limit is not None and len(scans) >= limit:
            break
    return scans


def bunny_cases(part: Part, scans: list[tuple], sigmas: list[float], seeds: int) -> list[Case]:
    cases = []
    for i, (name, pts, truth) in enumerate(scans):
        for sigma in sigmas:
            for s in range(seeds):
                rng = np.random.default_rng([i, int(round(sigma * 100)), s])
                noisy = pts.copy()
                noisy[:, 2] += sigma * rng.standard_normal(len(pts))
                viewpoint = noisy.mean(axis=0) + (0.0, 0.0, 1000.0)  # for Open3D's normals only
                scene = Scene(f"bunny/{name}/s{sigma:g}/{s}", "scan", part, noisy, truth[None], viewpoint)
                cases.append(Case("bunny", "scan", scene, up=(0.0, 0.0, 1.0), meta={"sigma": sigma, "scan": name}))
    return cases


def world_of(bin: sim.Bin, model: Optional[binpick.Model], ids, poses) -> sim.World:
    world = sim.World()
    world.add_bin(bin)
    if model is not None and len(ids):
        world.add_parts(model, list(ids), np.asarray(poses))
    return world


def placement(set_name: str, k: int) -> tuple[float, float]:
    """(distance mm, azimuth deg) of the depth camera for scene ``k``: spread by golden ratios."""
    lo, hi = DISTANCES[set_name]
    return lo + (hi - lo) * ((k * 0.6180339887) % 1.0), (k * 137.508 + 20.0) % 360.0


def depth_camera(set_name: str, bin: sim.Bin, k: int) -> tuple[sim.DepthCamera, dict]:
    distance, azimuth = placement(set_name, k)
    target = (bin.center[0], bin.center[1], bin.floor_z)
    cam = CAMERAS[set_name]().looking_at(target, distance=distance, tilt_deg=TILT_DEG, azimuth_deg=azimuth)
    meta = {"distance_mm": distance, "azimuth_deg": azimuth}
    if set_name == "structured":
        n = cam.noise
        a0 = STRUCTURED_SIGMA - (float(n.axial_sigma(distance)) - n.axial_sigma_0)
        cam = dataclasses.replace(cam, noise=dataclasses.replace(n, axial_sigma_0=max(a0, 0.0)))
    meta["sigma_z_mm"] = float(cam.noise.axial_sigma(distance))
    return cam, meta


@dataclass
class Rendered:
    """A world through one sensor: the cloud binpick gets, and the pixel counts judging needs."""

    cloud: np.ndarray
    viewpoint: np.ndarray
    pixels: Callable[[], np.ndarray]  # visible pixels per instance, in pile order
    alone: Callable[[int], int]  # pixels instance i fills rendered alone with the bin
    meta: dict


class Simulator:
    """The cells, piles and renders: each part's cell (``Cell.for_part``), its views and piles
    dropped once and shared by every class, rendered through each class's sensor."""

    def __init__(self, frames: int) -> None:
        self.frames = frames
        self.cells: dict[int, sim.Cell] = {}
        self.piles: dict[tuple, sim.Pile] = {}

    def cell(self, model: binpick.Model) -> sim.Cell:
        if id(model) not in self.cells:
            self.cells[id(model)] = sim.Cell.for_part(model)
        return self.cells[id(model)]

    def pile(self, model: binpick.Model, count: int, cell: sim.Cell, seed: int) -> sim.Pile:
        key = (id(model), count, cell.bin, seed)
        if key not in self.piles:
            self.piles[key] = sim.Pile(model, count, bin=cell.bin, seed=seed)
        return self.piles[key]

    def render(self, set_name: str, cell: sim.Cell, model: Optional[binpick.Model], ids, poses, k: int, seed: int):
        """The world of ``model`` at ``poses`` (None: the empty bin) through the set's sensor,
        placed for scene ``k``, its noise seeded by ``seed``."""
        bin, ids = cell.bin, list(ids)
        world = world_of(bin, model, ids, poses)

        def counts(seen: np.ndarray) -> Callable[[], np.ndarray]:
            return lambda: np.array([int((seen == i).sum()) for i in ids])

        if set_name == "laser":

            def alone(i: int) -> int:
                w = world_of(bin, model, [ids[i]], [poses[i]])
                return int((w.view(cell, num_threads=1).ids == ids[i]).sum())

            cloud = sim_cloud(world, cell, self.frames, seed)
            seen = world.view(cell, num_threads=1).ids
            return Rendered(cloud, cell.T_base_camera[:3, 3], counts(seen), alone, {"frames": self.frames})
        cam, meta = depth_camera(set_name, bin, k)
        frame = sim.render_depth(world, cam, seed=seed, num_threads=1)

        def alone_px(i: int) -> int:
            w = world_of(bin, model, [ids[i]], [poses[i]])
            return int((w.surfaces(cam.intrinsics, cam.T_base_camera, num_threads=1).ids == ids[i]).sum())

        return Rendered(np.ascontiguousarray(frame.cloud), frame.viewpoint, counts(frame.ids), alone_px, meta)


def sim_cases(set_name: str, part: Part, views: int, piles: int, simulator: Simulator) -> list[Case]:
    model = part.model
    cell = simulator.cell(model)
    plans = [("view", k, 1, k) for k in range(views)]
    plans += [("pile", k, pile_size(model, cell.bin), 100 + k) for k in range(piles)]
    cases = []
    for kind, k, count, seed in plans:
        pile = simulator.pile(model, count, cell, seed)
        start = time.perf_counter()
        placed = k if kind == "view" else PILE_PLACEMENTS + k  # a pile's placement does not move with --views
        r = simulator.render(set_name, cell, model, pile.ids, pile.poses, placed, seed)
        r.meta.update(render_s=time.perf_counter() - start, seed=seed)
        name = f"{set_name}/{part.name}/{kind}{k}"
        scene = Scene(name, kind, part, r.cloud, np.asarray(pile.poses), np.asarray(r.viewpoint), bin=cell.bin.bounds)
        cases.append(Case(set_name, kind, scene, meta=r.meta, pixels=r.pixels, alone=r.alone))
    return cases
