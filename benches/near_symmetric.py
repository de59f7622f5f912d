"""Poses you can trust (issue 13): near-symmetric parts, scenes without the part, calibrated confidence.

Parts: the five near-symmetric parts of ``binpick.parts.NEAR_SYMMETRIC`` (keyed shaft, cut plate,
flange, notched hex, bossed rod), each symmetric but for one feature 1.5–3 mm deep, and their
symmetric base shapes (``binpick.parts.base_shape``).

Scenes, every one seeded and with the ground truth ``T_scene_model`` of each instance:

- ``sim``: the project's simulator — the part at a random orientation resting on the floor of the
  cell's bin (single views), or a physics pile of 8–14 of them (``binpick.sim.Pile``), rendered
  as laser frames swept over the bin and measured by the real chain (``extract_line`` on every
  frame, ``triangulate`` with the cell's calibration); the pose is asked with the bin box.
- ``ray``: a plain ray-cast (``binpick._shapes.raycast_down``, an orthographic z-buffer looking
  down −z, 0.5 mm pixels for views and 0.6 mm for piles) with 0.15 mm Gaussian noise along the
  ray: the part alone at a random orientation, or the simulator's pile poses in the bin.

The feature is *in view* (issue 13) when at least 15 scan points of the instance lie more than
4σ (σ = 0.15 mm) from its base shape at the same pose, or at least 15 points of a scan of the base
shape (same pose, same camera: the scene re-rendered with the instance replaced) lie more than 4σ
from the part. On piles the instance judged is the ground truth nearest the first pose returned
(the highest instance when none is returned).

Per part and scene kind: pick-grade (rotation < 5°, translation < 3 mm, ``Model.pose_error``)
where the feature is in view; where it is not, the share flagged ``ambiguous``; confident-wrong
(not pick-grade, not flagged, and no ``alternatives`` pick-grade to the truth); no pose; median
and max time per ``estimate_pose`` call (one thread). Then the reliability table of
``confidence`` over all poses, and scenes without the part (uniform noise, the empty bin with and
without ``bin=``, a pile of another part, and the elbow — a tee without half its run — on the pile
of tees) for every method, each of which must raise
``NoObjectFound``. ``confidence``, ``ambiguous`` and ``alternatives`` are read with ``getattr``
and reported as n/a where the installed binpick has no such field.

    PYTHONPATH=python python benches/near_symmetric.py [--quick] [--views N] [--piles N]
        [--seeds 0,1] [--part NAME] [--renderers sim,ray] [--sizes default,a,b] [--out DIR]

``--sizes`` picks the sets of sizes the parts are made at (:data:`SIZE_SETS`; ``default,a,b`` for
all three), each other than the default labelled ``name[set]``.

Writes ``OUT/near_symmetric.json`` (every scene) and ``OUT/near_symmetric.png`` (reliability
diagram and per-part bars).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import binpick  # noqa: E402
from binpick import _core, _shapes, parts, sim  # noqa: E402
from binpick.cell.symmetry import continuous_near_axis  # noqa: E402
from binpick.transforms import pose_error, rotation_about  # noqa: E402
from binpick.vision import extract_line, triangulate  # noqa: E402

SIGMA = 0.15  # mm, the ray-cast's noise and the in-view test's σ
VIEW_PIXEL = 0.5
PILE_PIXEL = 0.6
CONFIDENCE_BINS = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95)
TARGETS = {"pick_grade_in_view": 0.98, "confident_wrong": 0.01, "confident_wrong_pile_first": 0.02}

#: The parts at other sizes (``--sizes``): figures at one size per part say little of the next
#: part. ``a`` and ``b`` change each part's proportions and its feature's share of the surface
#: (a 100 mm plate whose cut corner is 0.3 % of it, a 40 mm flange with four holes, a 50 mm hex
#: 20 mm long, a thick short shaft, a thin long rod).
SIZE_SETS: dict[str, dict[str, dict[str, float]]] = {
    "default": {},
    "a": {
        "keyed_shaft": dict(diameter=16.0, length=80.0, keyway_width=4.0, keyway_depth=1.5, keyway_length=25.0),
        "cut_plate": dict(side=100.0, thickness=6.0, cut=3.5),
        "flange": dict(
            diameter=90.0,
            thickness=12.0,
            bolt_holes=8,
            bolt_hole_diameter=9.0,
            bolt_circle_diameter=66.0,
            notch_width=12.0,
            notch_depth=3.0,
        ),
        "notched_hex": dict(across_flats=20.0, length=50.0, notch_width=4.0, notch_depth=1.2),
        "bossed_rod": dict(diameter=30.0, length=140.0, boss_diameter=14.0, boss_height=2.5),
    },
    "b": {
        "keyed_shaft": dict(diameter=40.0, length=60.0, keyway_width=8.0, keyway_depth=3.0, keyway_length=30.0),
        "cut_plate": dict(side=60.0, thickness=3.0, cut=4.0),
        "flange": dict(
            diameter=40.0,
            thickness=6.0,
            bolt_holes=4,
            bolt_hole_diameter=5.0,
            bolt_circle_diameter=28.0,
            hole_depth=2.0,
            notch_width=6.0,
            notch_depth=2.0,
        ),
        "notched_hex": dict(across_flats=50.0, length=20.0, notch_width=8.0, notch_depth=2.0),
        "bossed_rod": dict(diameter=12.0, length=120.0, boss_diameter=8.0, boss_height=1.5),
    },
}


def sized(name: str, size_set: str) -> tuple[Any, Any, str]:
    """The part ``name`` at the sizes of ``size_set``, its base shape, and its label in the tables."""
    sizes = SIZE_SETS[size_set].get(name, {})
    label = name if size_set == "default" else f"{name}[{size_set}]"
    return parts.NEAR_SYMMETRIC[name](**sizes), parts.base_shape(name, **sizes), label


@dataclass
class Scene:
    """One scene: its points, the truth of each instance, and how to re-render it for the in-view test."""

    name: str
    part: str
    renderer: str
    kind: str
    points: np.ndarray
    truths: np.ndarray
    bin: Optional[np.ndarray]
    viewpoint: Optional[np.ndarray]
    render: Any = None  # render(index, mesh) -> points of the scene with instance `index` drawn as `mesh`
    extra: dict = field(default_factory=dict)
    light: Optional[np.ndarray] = None  # where the laser that lit a swept scan came from


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    axis = q[1:] if np.linalg.norm(q[1:]) > 1e-9 else np.array([0.0, 0.0, 1.0])
    return rotation_about(axis, 2 * np.arctan2(np.linalg.norm(q[1:]), q[0]))


def resting_pose(model: binpick.Model, R: np.ndarray, x: float, y: float, floor: float) -> np.ndarray:
    """The pose turning ``model`` by ``R`` with its lowest vertex just above ``floor`` at (x, y)."""
    T = np.eye(4)
    T[:3, :3] = R
    v = model.vertices @ R.T
    T[:3, 3] = (x - v[:, 0].mean(), y - v[:, 1].mean(), floor + 0.05 - v[:, 2].min())
    return T


# ------------------------------------------------------------------------------ the simulator


def sim_cloud(world: sim.World, cell: sim.Cell, frames: int, seed: int) -> np.ndarray:
    """The cloud the real chain measures from the laser frames of ``world``."""
    view = world.view(cell, num_threads=1)
    angles = cell.sweep(frames)
    images = view.frames(angles, seed=seed, num_threads=1)
    pixels, index = [], []
    for k, rgb in enumerate(images):
        uv = extract_line(np.ascontiguousarray(rgb[:, :, ::-1]))  # the chain reads BGR, as from a PNG
        pixels.append(uv)
        index.append(np.full(len(uv), k, dtype=np.int64))
    cloud = triangulate(
        np.concatenate(pixels),
        np.concatenate(index),
        angles,
        [cell.T_base_flange] * len(angles),
        cell.calibration(),
        num_threads=1,
    )
    return np.ascontiguousarray(cloud.points, dtype=np.float64)


def sim_world(cell: sim.Cell, meshes: list[tuple], poses: np.ndarray) -> sim.World:
    world = sim.World()
    world.add_bin(cell.bin)
    for i, ((v, f), T) in enumerate(zip(meshes, poses)):
        world.add_instance(world.add_mesh(v, f), T, i)
    return world


def sim_scene(name: str, kind: str, model, poses: np.ndarray, cell: sim.Cell, frames: int, seed: int, tag: str):
    mesh = (model.vertices, model.faces)

    def render(index: int, other: tuple) -> np.ndarray:
        meshes = [other if i == index else mesh for i in range(len(poses))]
        world = sim_world(cell, meshes, poses)
        pts = sim_cloud(world, cell, frames, seed)
        dist, ids = world.nearest_surface(pts)
        return pts[(ids == index) & (dist < 1.0)]

    world = sim_world(cell, [mesh] * len(poses), poses)
    pts = sim_cloud(world, cell, frames, seed)
    dist, ids = world.nearest_surface(pts)
    scene = Scene(
        f"sim/{kind}/{name}_{tag}", name, "sim", kind, pts, poses, cell.bin.bounds, cell.T_base_camera[:3, 3], render
    )
    scene.light = (cell.T_base_camera @ cell.calibration().T_camera_laser)[:3, 3]
    scene.extra["instance_points"] = lambda i: pts[(ids == i) & (dist < 1.0)]
    return scene


# ------------------------------------------------------------------------------ the plain ray-cast


def ray_points(meshes: list[tuple], poses: np.ndarray, lo, hi, pixel: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """Scan of the posed meshes (instance id per point, −2 for the bin) from above."""
    verts, faces, owner = [], [], []
    offset = 0
    for i, ((v, f), T) in enumerate(zip(meshes, poses)):
        verts.append(v if T is None else _shapes.posed(v, T))
        faces.append(f + offset)
        owner.append(np.full(len(f), i if T is not None else -2))
        offset += len(v)
    pts, face = _shapes.scan_down(np.vstack(verts), np.vstack(faces), lo, hi, pixel, SIGMA, rng)
    return pts, np.concatenate(owner)[face]


def ray_scene(name: str, kind: str, model, poses: np.ndarray, cell: Optional[sim.Cell], seed: int, tag: str):
    """The ray-cast scene: the posed instances alone, or in ``cell``'s bin (asked with its box)."""
    mesh = (model.vertices, model.faces)
    pixel = VIEW_PIXEL if kind == "view" else PILE_PIXEL
    bin_mesh = None if cell is None else bin_mesh_of(cell)
    if bin_mesh is None:
        v = np.vstack([_shapes.posed(model.vertices, T) for T in poses])
        lo, hi = v.min(axis=0)[:2] - 5, v.max(axis=0)[:2] + 5
    else:
        lo, hi = bin_mesh[0].min(axis=0)[:2], bin_mesh[0].max(axis=0)[:2]
    extra_mesh = [bin_mesh] if bin_mesh is not None else []
    extra_pose = [None] if bin_mesh is not None else []

    def scan(meshes):
        return ray_points(meshes + extra_mesh, list(poses) + extra_pose, lo, hi, pixel, np.random.default_rng(seed))

    pts, ids = scan([mesh] * len(poses))

    def render(index: int, other: tuple) -> np.ndarray:
        p, i = scan([other if k == index else mesh for k in range(len(poses))])
        return p[i == index]

    bounds = None if cell is None else cell.bin.bounds
    scene = Scene(f"ray/{kind}/{name}_{tag}", name, "ray", kind, pts, poses, bounds, None, render)
    scene.extra["instance_points"] = lambda i: pts[ids == i]
    return scene


def bin_mesh_of(cell: sim.Cell) -> tuple:
    b = cell.bin
    return _core.sim_bin_mesh(tuple(b.center), tuple(b.size), float(b.floor_z), float(b.wall_thickness))


# ------------------------------------------------------------------------------ judging


def feature_in_view(scene: Scene, index: int, part, base) -> bool:
    T = scene.truths[index]
    pm, bm = (part.vertices, part.faces), (base.vertices, base.faces)
    seen = scene.extra["instance_points"](index)
    if _shapes.feature_in_view(pm, bm, T, seen, np.zeros((0, 3)), SIGMA):
        return True
    return _shapes.feature_in_view(pm, bm, T, np.zeros((0, 3)), scene.render(index, bm), SIGMA)


#: The one proper symmetry besides the identity that each part's geometry has (binpick.parts),
#: a half turn about this axis through the origin; used when the detected group fails the check.
HALF_TURN_AXIS = {
    "keyed_shaft": (1.0, 0.0, 0.0),
    "cut_plate": (1.0, 1.0, 0.0),
    "flange": (1.0, 0.0, 0.0),
    "notched_hex": (0.0, 1.0, 0.0),
    "bossed_rod": (0.0, 0.0, 1.0),
}


def symmetry_check(name: str, model) -> Optional[list[np.ndarray]]:
    """None when every rotation of ``model.symmetries`` maps the surface onto itself (then
    ``Model.pose_error`` judges), else the geometry's group as 4×4 maps (and a warning)."""
    sym = model.symmetries
    bad = []
    for R in sym.rotations[1:]:
        moved = (model.points - sym.center) @ R.T + sym.center
        if _shapes.surface_distance(model.vertices, model.faces, moved).max() > 0.2:
            bad.append(R)
    if not bad and sym.continuous_axis is None:
        return None
    a = np.asarray(HALF_TURN_AXIS[name]) / np.linalg.norm(HALF_TURN_AXIS[name])
    S = np.eye(4)
    S[:3, :3] = 2 * np.outer(a, a) - np.eye(3)
    print(
        f"warning: {name}: {sym} is not the part's group; judging with the half turn about {a.round(3)}",
        file=sys.stderr,
    )
    return [S]


def pick_grade(model, T_est: np.ndarray, T_true: np.ndarray, group=None) -> tuple[bool, float, float]:
    if group is None:
        rot, trans = model.pose_error(T_est, T_true)
    else:
        rot, trans = pose_error(T_est, T_true, group)
    return bool(rot < 5.0 and trans < 3.0), float(rot), float(trans)


def judge(scene: Scene, model, base, group=None) -> dict:
    """Runs ``estimate_pose`` on the scene and judges the first pose."""
    start = time.perf_counter()
    try:
        # As the cell asks for a swept laser scan: normals toward the camera, judged along up, lit
        # from the laser's origin.
        res = binpick.estimate_pose(
            scene.points,
            model,
            bin=scene.bin,
            viewpoint=scene.viewpoint,
            along_rays=False,
            light=scene.light,
            num_threads=1,
        )
    except binpick.NoObjectFound:
        res = None
    ms = 1000 * (time.perf_counter() - start)
    row: dict[str, Any] = {"scene": scene.name, "part": scene.part, "renderer": scene.renderer, "kind": scene.kind}
    row.update(points=len(scene.points), instances=len(scene.truths), ms=ms)
    if res is None:
        index = int(np.argmax(scene.truths[:, 2, 3]))
        row.update(pose=False, in_view=feature_in_view(scene, index, model, base))
        return row
    centre = res.T_scene_model[:3, :3] @ model.points.mean(axis=0) + res.T_scene_model[:3, 3]
    truth_centres = scene.truths[:, :3, :3] @ model.points.mean(axis=0) + scene.truths[:, :3, 3]
    index = int(np.argmin(np.linalg.norm(truth_centres - centre, axis=1)))
    ok, rot, trans = pick_grade(model, res.T_scene_model, scene.truths[index], group)
    alternatives = getattr(res, "alternatives", None)
    alt_ok = any(pick_grade(model, a.T_scene_model, scene.truths[index], group)[0] for a in alternatives or [])
    if getattr(res, "free_axis", None) is not None and not alt_ok:
        # The turn about a free axis is open: any turn of the pose about it is one of its alternatives.
        deg, mm = model.pose_error(res.T_scene_model, scene.truths[index], turn_about=continuous_near_axis(model))
        alt_ok = bool(deg < 5.0 and mm < 3.0)
    ambiguous = getattr(res, "ambiguous", None)
    confidence = getattr(res, "confidence", None)
    confidence_any = getattr(res, "confidence_any", None)
    row.update(
        pose=True,
        instance=index,
        in_view=feature_in_view(scene, index, model, base),
        pick_grade=ok,
        rotation_deg=rot,
        translation_mm=trans,
        score=float(res.score),
        method=res.method,
        ambiguous=None if ambiguous is None else bool(ambiguous),
        confidence=None if confidence is None else float(confidence),
        confidence_any=None if confidence_any is None else float(confidence_any),
        any_pick_grade=ok or alt_ok,
        alternatives=None if alternatives is None else len(alternatives),
        truth_among_alternatives=alt_ok,
        free_axis=None if getattr(res, "free_axis", None) is None else np.asarray(res.free_axis).tolist(),
        confident_wrong=(not ok) and not ambiguous and not alt_ok,
    )
    return row


# ------------------------------------------------------------------------------ scenes


def make_scenes(
    name: str, renderers: list[str], views: int, piles: int, seeds: list[int], frames: int, size_set: str = "default"
):
    model, _, label = sized(name, size_set)
    cell = sim.Cell()
    cx, cy = cell.bin.center
    for seed in seeds:
        rng = np.random.default_rng([seed, sorted(parts.NEAR_SYMMETRIC).index(name)])
        for k in range(views):
            R = random_rotation(rng)
            for renderer in renderers:
                tag = f"s{seed}v{k}"
                if renderer == "sim":
                    T = resting_pose(model, R, cx + rng.uniform(-40, 40), cy + rng.uniform(-30, 30), cell.bin.floor_z)
                    yield sim_scene(label, "view", model, T[None], cell, frames, seed * 1000 + k, tag)
                else:
                    yield ray_scene(
                        label, "view", model, resting_pose(model, R, 0, 0, 0)[None], None, seed * 1000 + k, tag
                    )
        for k in range(piles):
            count = int(rng.integers(8, 15))
            poses = sim.Pile(model, count, bin=cell.bin, seed=seed * 1000 + k).poses
            for renderer in renderers:
                tag = f"s{seed}p{k}"
                if renderer == "sim":
                    yield sim_scene(label, "pile", model, poses, cell, frames, seed * 1000 + k, tag)
                else:
                    yield ray_scene(label, "pile", model, poses, cell, seed * 1000 + k, tag)


def negative_scenes(frames: int) -> list[tuple[str, np.ndarray, Optional[np.ndarray], str]]:
    """(name, points, bin, the part whose pile it is or "") of scenes without the part asked for."""
    cell = sim.Cell()
    rng = np.random.default_rng(7)
    lo, hi = cell.bin.bounds
    noise = rng.uniform(lo, [hi[0], hi[1], lo[2] + 60.0], size=(20000, 3))
    world = sim.World()
    world.add_bin(cell.bin)
    empty = sim_cloud(world, cell, frames, 0)
    scenes = [
        ("noise", noise, None, ""),
        ("empty bin, bin=", empty, cell.bin.bounds, ""),
        ("empty bin", empty, None, ""),
    ]
    for other in ("tee", "keyed_shaft"):
        model = binpick.parts.tee() if other == "tee" else parts.keyed_shaft()
        pile = sim.Pile(model, 8, bin=cell.bin, seed=11)
        cloud = sim_cloud(sim.World.of_pile(pile, bin=cell.bin), cell, frames, 11)
        scenes.append((f"pile of {other}", cloud, cell.bin.bounds, other))
    return scenes


def run_negatives(names: list[str], frames: int) -> list[dict]:
    rows = []
    models = {n: parts.NEAR_SYMMETRIC[n]() for n in names}
    models["tee"] = binpick.parts.tee()
    # An elbow is a tee without half its run: asked on the pile of tees it is the hardest case.
    models["elbow"] = binpick.parts.elbow()
    for scene, pts, box, pile_of in negative_scenes(frames):
        for name, model in models.items():
            if pile_of and (pile_of == "tee") == (name == "tee"):
                continue  # the tee is asked for on a pile of shafts, the other parts on a pile of tees
            if name == "elbow" and pile_of != "tee":
                continue  # the elbow only where it is a piece of another part
            methods = ["auto", "ppf"] + (["ccp", "centroid"] if model.branches else [])
            for method in methods:
                start = time.perf_counter()
                try:
                    res = binpick.estimate_pose(pts, model, bin=box, method=method, num_threads=1)
                    found = f"pose (score {res.score:.2f}, {res.method})"
                except binpick.NoObjectFound:
                    found = ""
                rows.append(
                    {
                        "scene": scene,
                        "part": name,
                        "method": method,
                        "ghost": found,
                        "ms": 1000 * (time.perf_counter() - start),
                    }
                )
    return rows


# ------------------------------------------------------------------------------ report


def share(n: int, d: int) -> str:
    return "—" if d == 0 else f"{100 * n / d:.0f}% ({n}/{d})"


def summarise(rows: list[dict]) -> dict:
    seen = [r for r in rows if r["in_view"]]
    hidden = [r for r in rows if not r["in_view"]]
    posed = [r for r in rows if r["pose"]]
    flags = [r for r in hidden if r["pose"] and r.get("ambiguous") is not None]
    first = [r for r in rows if r["kind"] == "pile"]
    times = [r["ms"] for r in rows]
    return {
        "scenes": len(rows),
        "in_view": len(seen),
        "pick_grade_in_view": sum(bool(r.get("pick_grade")) for r in seen),
        # Issue 39: a right pose where the feature is in view comes back decided (confidence ≥ 0.8).
        "decided_in_view": sum(bool(r.get("pick_grade")) and (r.get("confidence") or 0.0) >= 0.8 for r in seen),
        "hidden": len(hidden),
        "hidden_posed": sum(r["pose"] for r in hidden),
        "hidden_flagged": None if not flags and hidden else sum(bool(r.get("ambiguous")) for r in flags),
        "hidden_pick_grade": sum(bool(r.get("pick_grade")) for r in hidden),
        "confident_wrong": sum(bool(r.get("confident_wrong")) for r in rows),
        "pile_first": len(first),
        "pile_first_confident_wrong": sum(bool(r.get("confident_wrong")) for r in first),
        "no_pose": len(rows) - len(posed),
        "median_ms": statistics.median(times) if times else float("nan"),
        "max_ms": max(times) if times else float("nan"),
    }


def table(rows: list[dict], names: list[str]) -> list[str]:
    head = (
        "| part | renderer/kind | scenes | pick-grade, feature in view | ambiguous, feature hidden | "
        "pick-grade, hidden | confident-wrong | no pose | median ms | max ms |"
    )
    out = [head, "|" + "---|" * 10]
    groups = [(n, rk) for n in names for rk in ("sim/view", "ray/view", "sim/pile", "ray/pile")]
    for name, rk in groups + [("all", "all")]:
        sel = [
            r
            for r in rows
            if (name == "all" or r["part"] == name) and (rk == "all" or f"{r['renderer']}/{r['kind']}" == rk)
        ]
        if not sel:
            continue
        s = summarise(sel)
        flagged = "n/a" if s["hidden_flagged"] is None else share(s["hidden_flagged"], s["hidden_posed"])
        out.append(
            f"| {name} | {rk} | {s['scenes']} | {share(s['pick_grade_in_view'], s['in_view'])} | {flagged} | "
            f"{share(s['hidden_pick_grade'], s['hidden'])} | {share(s['confident_wrong'], s['scenes'])} | "
            f"{share(s['no_pose'], s['scenes'])} | {s['median_ms']:.1f} | {s['max_ms']:.1f} |"
        )
    return out


def reliability(rows: list[dict], key: str = "confidence", right: str = "pick_grade") -> list[dict]:
    """Of the poses whose ``key`` is at least c, the share whose ``right`` holds, for every c:
    ``confidence`` against the pose being pick-grade, ``confidence_any`` against the pose or
    one of its alternatives being so (what a cell picking with a grasp they share stakes)."""
    posed = [r for r in rows if r["pose"] and r.get(key) is not None]
    out = []
    for c in CONFIDENCE_BINS:
        sel = [r for r in posed if r[key] >= c]
        out.append({"c": c, "count": len(sel), "pick_grade": sum(r[right] for r in sel) / len(sel) if sel else None})
    return out


def plot(rows: list[dict], names: list[str], rel: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    pts = [(r["c"], r["pick_grade"]) for r in rel if r["pick_grade"] is not None]
    a.plot([0.5, 1], [0.5, 1], "k--", lw=1, label="target: fraction = c")
    if pts:
        a.plot(*zip(*pts), "o-", label="pick-grade among confidence ≥ c")
    else:
        a.text(0.52, 0.9, "confidence: n/a in this binpick", fontsize=10)
    a.set(xlabel="confidence c", ylabel="pick-grade fraction", title="reliability", xlim=(0.45, 1.0), ylim=(0, 1.02))
    a.legend(loc="lower right")
    x = np.arange(len(names))
    bars = {"pick-grade, in view": [], "confident-wrong": [], "no pose": []}
    for n in names:
        s = summarise([r for r in rows if r["part"] == n])
        bars["pick-grade, in view"].append(s["pick_grade_in_view"] / s["in_view"] if s["in_view"] else 0)
        bars["confident-wrong"].append(s["confident_wrong"] / max(1, s["scenes"]))
        bars["no pose"].append(s["no_pose"] / max(1, s["scenes"]))
    for k, (label, values) in enumerate(bars.items()):
        b.bar(x + (k - 1) * 0.27, values, 0.27, label=label)
    b.axhline(TARGETS["pick_grade_in_view"], color="g", ls=":", lw=1)
    b.set_xticks(x, names, rotation=15)
    b.set(ylim=(0, 1.05), title="per part (all scenes)")
    b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 views and 1 pile per part and renderer, 45 frames")
    ap.add_argument("--views", type=int, default=None, help="single views per part, seed and renderer (default 20)")
    ap.add_argument("--piles", type=int, default=None, help="piles per part, seed and renderer (default 3)")
    ap.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    ap.add_argument("--part", default=None, help=f"one of {', '.join(sorted(parts.NEAR_SYMMETRIC))}")
    ap.add_argument("--renderers", default="sim,ray")
    ap.add_argument(
        "--sizes", default="default", help=f"comma-separated size sets of the parts: {', '.join(SIZE_SETS)}"
    )
    ap.add_argument("--frames", type=int, default=None, help="laser frames per simulated scan (default 90)")
    ap.add_argument("--out", default="bench-out")
    args = ap.parse_args(argv)
    views = args.views if args.views is not None else (2 if args.quick else 20)
    piles = args.piles if args.piles is not None else (1 if args.quick else 3)
    frames = args.frames if args.frames is not None else 90
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    names = sorted(parts.NEAR_SYMMETRIC) if args.part is None else [args.part]
    if any(n not in parts.NEAR_SYMMETRIC for n in names):
        ap.error(f"--part: one of {', '.join(sorted(parts.NEAR_SYMMETRIC))}")
    renderers = [r for r in args.renderers.split(",") if r]
    size_sets = [z for z in args.sizes.split(",") if z]
    if any(z not in SIZE_SETS for z in size_sets):
        ap.error(f"--sizes: of {', '.join(SIZE_SETS)}")
    rows = []
    labels = []
    for size_set, name in [(z, n) for z in size_sets for n in names]:
        model, base, label = sized(name, size_set)
        labels.append(label)
        group = symmetry_check(name, model)
        for scene in make_scenes(name, renderers, views, piles, seeds, frames, size_set):
            row = judge(scene, model, base, group)
            rows.append(row)
            verdict = "no pose" if not row["pose"] else ("pick-grade" if row["pick_grade"] else "WRONG")
            print(
                f"{scene.name}: {row['points']} pts, feature {'in view' if row['in_view'] else 'hidden'}, "
                f"{verdict} {row.get('rotation_deg', np.nan):.1f}° {row.get('translation_mm', np.nan):.1f} mm, "
                f"{row['ms']:.0f} ms",
                file=sys.stderr,
                flush=True,
            )
    negatives = run_negatives(names, frames)
    rel = reliability(rows)
    lines = ["## Near-symmetric parts (first pose per scene)", "", *table(rows, labels), ""]
    lines += [
        "## Reliability of confidence (all poses)",
        "",
        "| c | poses ≥ c | pick-grade among them | target |",
        "|---|---|---|---|",
    ]
    has_confidence = any(x.get("confidence") is not None for x in rows)
    for r in rel:
        frac = "n/a" if r["pick_grade"] is None else f"{100 * r['pick_grade']:.0f}%"
        count = r["count"] if has_confidence else "n/a"
        lines.append(f"| {r['c']:.2f} | {count} | {frac} | ≥ {100 * r['c']:.0f}% |")
    rel_any = reliability(rows, "confidence_any", "any_pick_grade")
    lines += [
        "",
        "## Reliability of confidence_any (the pose or one of its alternatives pick-grade)",
        "",
        "| c | poses ≥ c | pose or an alternative pick-grade | target |",
        "|---|---|---|---|",
    ]
    for r in rel_any:
        frac = "n/a" if r["pick_grade"] is None else f"{100 * r['pick_grade']:.0f}%"
        lines.append(f"| {r['c']:.2f} | {r['count']} | {frac} | ≥ {100 * r['c']:.0f}% |")
    ghosts = [r for r in negatives if r["ghost"]]
    lines += ["", "## Scenes without the part (must be NoObjectFound for every method)", ""]
    lines += ["| scene | part | methods | poses returned |", "|---|---|---|---|"]
    for key in dict.fromkeys((r["scene"], r["part"]) for r in negatives):
        sel = [r for r in negatives if (r["scene"], r["part"]) == key]
        bad = ", ".join(f"{r['method']}: {r['ghost']}" for r in sel if r["ghost"]) or "none"
        lines.append(f"| {key[0]} | {key[1]} | {', '.join(r['method'] for r in sel)} | {bad} |")
    s = summarise(rows)
    lines += ["", "## Totals against issue 13's targets", ""]
    lines.append(
        f"- pick-grade where the feature is in view: {share(s['pick_grade_in_view'], s['in_view'])} (target ≥ 98%)"
    )
    right_in_view = sum(bool(r.get("pick_grade")) for r in rows if r["in_view"])
    lines.append(
        "- right poses decided (confidence ≥ 0.8) where the feature is in view: "
        f"{share(s['decided_in_view'], right_in_view)} (issue 39: ≥ 90%)"
    )
    lines.append(f"- confident-wrong over all scenes: {share(s['confident_wrong'], s['scenes'])} (target ≤ 1%)")
    lines.append(
        "- confident-wrong, first instance of piles: "
        f"{share(s['pile_first_confident_wrong'], s['pile_first'])} (target ≤ 2%)"
    )
    lines.append(f"- poses on scenes without the part: {len(ghosts)} of {len(negatives)} calls (target 0)")
    views_ms = [r["ms"] for r in rows if r["kind"] == "view"]
    piles_ms = [r["ms"] for r in rows if r["kind"] == "pile"]
    if views_ms:
        lines.append(f"- median time per view: {statistics.median(views_ms):.1f} ms (target ≤ 30 ms)")
    if piles_ms:
        lines.append(f"- median time per pile: {statistics.median(piles_ms):.1f} ms (target ≤ 300 ms per 180k points)")
    print("\n".join(lines))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "scenes": rows,
        "negatives": negatives,
        "reliability": rel,
        "reliability_any": rel_any,
        "totals": s,
        "targets": TARGETS,
    }
    (out / "near_symmetric.json").write_text(json.dumps(doc, indent=1))
    plot(rows, labels, rel, out / "near_symmetric.png")
    print(f"\nwrote {out / 'near_symmetric.json'} and {out / 'near_symmetric.png'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
