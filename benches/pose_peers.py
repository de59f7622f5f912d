"""Pose estimation side by side (issue 7): binpick PPF against Open3D, OpenCV and ICP from the centroids.

Every method runs on the same scenes, in one process, one thread each:

- ``binpick``  — ``binpick.estimate_pose(..., method="ppf", num_threads=1)`` (piles:
  ``estimate_poses(..., max_instances=3)``), given the bin box on piles. When the installed binpick
  does not support PPF yet, its column is reported as unavailable.
- ``open3d``   — Open3D FPFH (3 mm voxels, as the data README) + RANSAC on feature matches
  (``registration_ransac_based_on_feature_matching``) + point-to-plane ICP.
- ``opencv``   — OpenCV 5 contrib ``cv2.ppf_match_3d``: ``PPF3DDetector`` trained on the mesh's
  samples with normals, ``match``, then ``ICP.registerModelToScene`` on the best hypotheses.
- ``centroid`` — the paper's baseline: ``binpick.icp`` (point-to-plane) from the centroids.

Scenes: ``views/NAME_k.npz`` (one part alone) and ``piles/NAME_k.npz`` (4–10 parts in a bin) of the
reference sample (``../shared/data/sample`` beside the repository, or ``--data DIR``), and ``--sim N``
piles of binpick's built-in tee and elbow made by binpick's own simulator: rendered laser frames
written as a scan folder, read back and reconstructed by ``binpick.vision.reconstruct``. On piles the
peers see the scene cropped to the bin's interior (points within a few mm of the floor and the walls
dropped); binpick gets the bin box itself.

Judging follows the data README: against the nearest ground-truth instance, minimised over the
part's proper symmetries, about the mesh frame's origin. Pick-grade = rotation < 5° and translation
< 3 mm; MSSD (max over mesh vertices of |T_est v − T_gt S v|) succeeds below 0.1 × the diameter.
On piles the first instance returned counts, and "top-3" asks for a pick-grade instance among the
first three (the peers' best three hypotheses where they give several, else their one).

Reports per method, part and scene kind: success rates, median and max time per scene (the model's
preparation, e.g. OpenCV's training, is done once per part before and reported as ``prepare_ms``
in the JSON) and the peers' time ratios to binpick; a markdown table on stdout, ``OUT/pose_peers.json`` and
``OUT/pose_peers.png`` (``--out``, default ``bench-out``).

Run it in a bench virtualenv of its own: OpenCV 5 contrib (for ``ppf_match_3d``) and binpick's pinned
``opencv-python-headless<5`` cannot share one environment (both provide ``cv2``)::

    python -m venv bench-venv
    bench-venv/bin/pip install --no-deps .       # binpick itself, without its cv2 < 5 pin
    bench-venv/bin/pip install numpy matplotlib pyserial open3d opencv-contrib-python-headless==5.0.0.93
    bench-venv/bin/python benches/pose_peers.py [--methods binpick,open3d,opencv,centroid]
        [--parts gear,bunny] [--limit N] [--views | --piles] [--sim 2] [--peer-threads 1|default]
        [--data DIR] [--out bench-out]

(binpick's own vision chain only uses cv2 calls that OpenCV 5 keeps, so the simulated piles work
there.) Open3D's wheel needs ``libusb-1.0`` (Debian: ``apt-get install libusb-1.0-0``). For a local
run without reinstalling binpick, a ``.pth`` file in the venv's site-packages holding the path of
``python/`` of an editable checkout (with its built ``_core`` module) does instead of ``pip install``.
Peers that are not installed are reported as unavailable; without the sample data its scenes are
skipped with a message (the simulated piles still run).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional

import numpy as np

import binpick
from binpick.transforms import inverse, rotation_about, rotation_angle_deg

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parent.parent / "shared" / "data" / "sample"

VOXEL = 3.0  # mm: FPFH voxel size, as the data README's peer results
DENSE_SPACING = 1.0  # mm: the mesh sample the peers' model clouds are made from
CROP_MARGIN = 5.0  # mm: points this close to the bin's floor or walls are dropped for the peers
PICK_ROTATION, PICK_TRANSLATION = 5.0, 3.0  # deg, mm
MSSD_FRACTION = 0.1  # of the part's diameter
TOP_K = 3
SAMPLE_CAMERA = (0.0, 0.0, 700.0)  # the sample's camera centre: 700 mm above the bin floor (README)
RANSAC_SEED = 7
SIM_PARTS = ("tee", "elbow")
SIM_PILE_SIZE = 8

# Proper symmetries about the mesh frame's origin: (axis, angles in degrees).
SYMMETRIES: dict[str, Optional[tuple[tuple[float, float, float], tuple[float, ...]]]] = {
    "IPAGearShaft": ((0.0, 0.0, 1.0), tuple(float(a) for a in range(360))),  # continuous, sampled at 1°
    "IPARingScrew": ((0.0, 0.0, 1.0), (0.0, 180.0)),
    "SileaneBunny": None,
    "tee": None,  # the boss breaks the run's symmetry
    "elbow": ((1.0, 1.0, 0.0), (0.0, 180.0)),  # swaps the two branches
}

METHOD_NAMES = ("binpick", "open3d", "opencv", "centroid")


# ---------------------------------------------------------------------------------------------
# geometry and judging


def symmetries(name: str) -> np.ndarray:
    if name not in SYMMETRIES:
        print(f"note: no symmetry known for part {name!r}; judging it as asymmetric", file=sys.stderr)
    sym = SYMMETRIES.get(name)
    if sym is None:
        return np.eye(3)[None]
    axis, angles = sym
    return np.stack([rotation_about(axis, np.radians(a)) for a in angles])


@dataclass
class Part:
    """A part as every method sees it: the binpick model, a dense surface sample, its symmetries."""

    name: str
    model: binpick.Model
    dense: binpick.Model
    symmetries: np.ndarray  # (S, 3, 3)


@dataclass
class Judgement:
    rotation: float
    translation: float
    mssd: float
    pick: bool
    mssd_ok: bool
    truth: int = 0  # index of the ground-truth instance judged against

    def as_dict(self) -> dict:
        return {
            "rot_deg": self.rotation,
            "trans_mm": self.translation,
            "mssd_mm": self.mssd,
            "pick": self.pick,
            "mssd_ok": self.mssd_ok,
            "truth": self.truth,
        }


def judge(t_est: np.ndarray, truths: np.ndarray, part: Part) -> Judgement:
    """The data README's measures against the nearest ground-truth instance."""
    nearest = int(np.argmin(np.linalg.norm(truths[:, :3, 3] - t_est[:3, 3], axis=1)))
    t_gt = truths[nearest]
    r_sym = t_gt[:3, :3] @ part.symmetries  # (S, 3, 3): R_gt·S
    rot = float(rotation_angle_deg(t_est[:3, :3].T @ r_sym).min())
    trans = float(np.linalg.norm(t_est[:3, 3] - t_gt[:3, 3]))
    v = part.model.vertices
    est = v @ t_est[:3, :3].T + t_est[:3, 3]
    # max over vertices of |T_est v − T_gt S v|, minimised over S (chunked: a continuous symmetry has 360 S)
    mssd = min(
        float(
            np.linalg.norm(est[None] - (np.einsum("sij,vj->svi", r_sym[i : i + 32], v) + t_gt[:3, 3]), axis=2)
            .max(axis=1)
            .min()
        )
        for i in range(0, len(r_sym), 32)
    )
    return Judgement(
        rot,
        trans,
        mssd,
        rot < PICK_ROTATION and trans < PICK_TRANSLATION,
        mssd < MSSD_FRACTION * part.model.diameter,
        nearest,
    )


# ---------------------------------------------------------------------------------------------
# scenes


@dataclass
class Scene:
    name: str
    kind: str  # "views", "piles" (the sample's) or "sim" (binpick's simulator)
    part: Part
    points: np.ndarray
    truths: np.ndarray  # (M, 4, 4) mesh frame -> scene
    viewpoint: np.ndarray  # the camera centre, to orient normals toward
    bin: Optional[np.ndarray] = None  # (2, 3) box; piles only
    _cropped: Optional[np.ndarray] = field(default=None, repr=False)

    @property
    def is_pile(self) -> bool:
        return self.bin is not None

    def cropped(self) -> np.ndarray:
        """The points the peers see: on piles, the bin's interior above the floor, off the walls."""
        if self.bin is None:
            return self.points
        if self._cropped is None:
            lo, hi = self.bin[0] + CROP_MARGIN, self.bin[1] - CROP_MARGIN
            p = self.points
            inside = (p[:, 0] > lo[0]) & (p[:, 0] < hi[0]) & (p[:, 1] > lo[1]) & (p[:, 1] < hi[1]) & (p[:, 2] > lo[2])
            self._cropped = np.ascontiguousarray(p[inside])
        return self._cropped


def wanted(name: str, parts: Optional[list[str]]) -> bool:
    return parts is None or any(p.lower() in name.lower() for p in parts)


def make_part(name: str, model: binpick.Model, dense: binpick.Model) -> Part:
    return Part(name=name, model=model, dense=dense, symmetries=symmetries(name))


def sample_scenes(root: Path, kinds: list[str], parts: Optional[list[str]], limit: Optional[int]) -> list[Scene]:
    """The reference sample's views/ and piles/ (one Part per part name: views/ and piles/ carry the same mesh)."""
    cache: dict[str, tuple[str, Part]] = {}
    scenes = []
    for kind in kinds:
        per_part: dict[str, int] = {}
        for f in sorted((root / kind).glob("*.npz")):
            with np.load(f) as d:
                name, mesh = str(d["part"]), f.parent / str(d["mesh"])
                if not wanted(name, parts) or (limit is not None and per_part.get(name, 0) >= limit):
                    continue
                digest = hashlib.sha1(mesh.read_bytes()).hexdigest()
                if name not in cache:
                    model = binpick.Model.from_mesh(mesh, name=name)
                    cache[name] = (
                        digest,
                        make_part(name, model, binpick.Model.from_mesh(mesh, spacing=DENSE_SPACING, name=name)),
                    )
                elif cache[name][0] != digest:
                    raise SystemExit(
                        f"{mesh}: differs from the {name} mesh read before; one mesh per part name, please"
                    )
                per_part[name] = per_part.get(name, 0) + 1
                scenes.append(
                    Scene(
                        name=f"{kind}/{f.stem}",
                        kind=kind,
                        part=cache[name][1],
                        points=np.ascontiguousarray(d["scene"], dtype=np.float64),
                        truths=np.asarray(d["T_scene_model"], dtype=np.float64),
                        viewpoint=np.array(SAMPLE_CAMERA),
                        bin=np.asarray(d["bin"], dtype=np.float64) if "bin" in d.files else None,
                    )
                )
    return scenes


def sim_scenes(count: int, parts: Optional[list[str]]) -> list[Scene]:
    """Piles from binpick's simulator, reconstructed through the real vision chain from a scan folder."""
    from binpick import sim
    from binpick.scan import load_scan
    from binpick.vision import reconstruct

    names = [n for n in SIM_PARTS if wanted(n, parts)]
    if not names or count <= 0:
        return []
    models = {n: getattr(binpick.parts, n)() for n in names}
    by_name = {n: make_part(n, m, m) for n, m in models.items()}
    scenes = []
    for k in range(count):
        name = names[k % len(names)]
        start = time.perf_counter()
        simulated = sim.simulate_scan(models[name], SIM_PILE_SIZE, seed=k)
        with tempfile.TemporaryDirectory(prefix="pose_peers_scan_") as tmp:
            scan = load_scan(sim.write_scan(simulated, tmp))
            cloud = reconstruct(scan)
        gt = scan.ground_truth
        camera = (scan.T_base_flanges[0] @ scan.calibration.T_flange_camera)[:3, 3]
        scenes.append(
            Scene(
                name=f"sim/{name}_{k:03d}",
                kind="sim",
                part=by_name[name],
                points=np.ascontiguousarray(cloud.points, dtype=np.float64),
                truths=np.asarray(gt["T_base_object"], dtype=np.float64),
                viewpoint=camera,
                bin=np.asarray(gt["bin"], dtype=np.float64),
            )
        )
        print(
            f"simulated {scenes[-1].name}: {len(gt['T_base_object'])} parts, "
            f"{len(cloud)} points, {time.perf_counter() - start:.1f} s",
            file=sys.stderr,
            flush=True,
        )
    return scenes


# ---------------------------------------------------------------------------------------------
# methods: prepare(part) once per part, untimed; estimate(scene, k) -> up to k poses, best first


class Unavailable(Exception):
    """The method cannot run here (not installed, or not supported by the installed version)."""


def model_cloud(part: Part, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """The part's dense surface sample at ``voxel`` mm, with unit outward normals."""
    pts, nrm, _ = binpick.voxel_downsample(part.dense.points, voxel, part.dense.normals)
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


class Method:
    name = ""
    label = ""

    def prepare(self, part: Part) -> None:
        pass

    def estimate(self, scene: Scene, k: int) -> list[np.ndarray]:
        raise NotImplementedError


class BinpickPPF(Method):
    name, label = "binpick", "binpick PPF"

    def prepare(self, part: Part) -> None:
        part.model.prepared()

    def estimate(self, scene: Scene, k: int) -> list[np.ndarray]:
        args = dict(bin=scene.bin, method="ppf", num_threads=1)
        try:
            if k > 1 and hasattr(binpick, "estimate_poses"):
                return [
                    r.T_scene_model
                    for r in binpick.estimate_poses(scene.points, scene.part.model, max_instances=k, **args)
                ]
            return [binpick.estimate_pose(scene.points, scene.part.model, **args).T_scene_model]
        except binpick.NoObjectFound:
            return []
        except TypeError as exc:
            raise Unavailable(f"this binpick's estimate_pose does not take these arguments ({exc})") from None
        except binpick.InvalidInputError as exc:
            if "method" in str(exc):
                raise Unavailable(f"this binpick has no method='ppf' ({exc})") from None
            raise


class Open3DFeatures(Method):
    name, label = "open3d", "Open3D FPFH + RANSAC + ICP"

    def __init__(self, one_thread: bool) -> None:
        try:
            import open3d as o3d
        except Exception as exc:  # not installed, or its shared libraries are missing
            raise Unavailable(f"cannot import open3d ({exc}); pip install open3d") from None
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        if one_thread and hasattr(o3d.utility, "set_max_threads"):
            o3d.utility.set_max_threads(1)
        self.o3d, self.reg = o3d, o3d.pipelines.registration
        self.models: dict[str, tuple] = {}

    def _cloud(self, points, normals=None):
        pc = self.o3d.geometry.PointCloud(self.o3d.utility.Vector3dVector(points))
        if normals is not None:
            pc.normals = self.o3d.utility.Vector3dVector(normals)
        return pc

    def _fpfh(self, pc):
        return self.reg.compute_fpfh_feature(
            pc, self.o3d.geometry.KDTreeSearchParamHybrid(radius=5 * VOXEL, max_nn=100)
        )

    def prepare(self, part: Part) -> None:
        pc = self._cloud(*model_cloud(part, VOXEL))
        self.models[part.name] = (pc, self._fpfh(pc))

    def estimate(self, scene: Scene, k: int) -> list[np.ndarray]:
        model, model_fpfh = self.models[scene.part.name]
        self.o3d.utility.random.seed(
            RANSAC_SEED
        )  # RANSAC draws from a global generator: the same per scene, whatever ran before
        pc = self._cloud(scene.cropped()).voxel_down_sample(VOXEL)
        pc.estimate_normals(self.o3d.geometry.KDTreeSearchParamHybrid(radius=2 * VOXEL, max_nn=30))
        pc.orient_normals_towards_camera_location(scene.viewpoint)
        reg = self.reg
        coarse = reg.registration_ransac_based_on_feature_matching(
            model,
            pc,
            model_fpfh,
            self._fpfh(pc),
            mutual_filter=True,
            max_correspondence_distance=1.5 * VOXEL,
            estimation_method=reg.TransformationEstimationPointToPoint(False),
            ransac_n=3,
            checkers=[
                reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                reg.CorrespondenceCheckerBasedOnDistance(1.5 * VOXEL),
            ],
            criteria=reg.RANSACConvergenceCriteria(100000, 0.999),
        )
        fine = reg.registration_icp(
            model,
            pc,
            VOXEL,
            coarse.transformation,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=50),
        )
        return [np.asarray(fine.transformation)]


class OpenCVPPF(Method):
    name, label = "opencv", "OpenCV ppf_match_3d PPF + ICP"
    SAMPLING = 0.04  # model sampling step and scene distance, relative to the model's bounding-box diagonal
    SCENE_STEP = 1.0 / 5.0  # fraction of the sampled scene points used as reference points
    NORMAL_NEIGHBOURS = 10
    ICP_LEVELS = 4

    def __init__(self, one_thread: bool) -> None:
        try:
            import cv2

            self.ppf = cv2.ppf_match_3d
        except (ImportError, AttributeError) as exc:
            raise Unavailable(
                f"no cv2.ppf_match_3d ({exc}); pip install "
                "opencv-contrib-python-headless==5.0.0.93 in a venv of its own"
            ) from None
        if one_thread:
            cv2.setNumThreads(1)
        self.models: dict[str, tuple] = {}

    def prepare(self, part: Part) -> None:
        # Fed at its own sampling step (relative to the bounding-box diagonal, as OpenCV measures the
        # model): trainModel's cost grows with the square of the points it is given.
        diagonal = float(np.linalg.norm(np.ptp(part.model.vertices, axis=0)))
        pts, nrm = model_cloud(part, self.SAMPLING * diagonal)
        cloud = np.ascontiguousarray(np.hstack([pts, nrm]), dtype=np.float32)
        detector = self.ppf.PPF3DDetector(self.SAMPLING, 0.05)
        detector.trainModel(cloud)
        self.models[part.name] = (detector, cloud)

    def estimate(self, scene: Scene, k: int) -> list[np.ndarray]:
        detector, model = self.models[scene.part.name]
        pts = np.ascontiguousarray(scene.cropped(), dtype=np.float32)
        _, cloud = self.ppf.computeNormalsPC3d(pts, self.NORMAL_NEIGHBOURS, True, scene.viewpoint.astype(np.float32))
        hypotheses = detector.match(cloud, self.SCENE_STEP, self.SAMPLING)[:k]
        if not hypotheses:
            return []
        # OpenCV's sample uses 8 pyramid levels; on these scenes the coarsest levels send good
        # hypotheses astray (residual 1e10, poses metres off), 4 levels refine them reliably.
        _, refined = self.ppf.ICP(100, 0.005, 2.5, self.ICP_LEVELS).registerModelToScene(model, cloud, hypotheses)
        return [np.asarray(h.pose, dtype=np.float64) for h in refined]


class CentroidIcp(Method):
    name, label = "centroid", "ICP from the centroids"

    def estimate(self, scene: Scene, k: int) -> list[np.ndarray]:
        model = scene.part.model
        pts = scene.cropped()
        init = np.eye(4)
        init[:3, 3] = model.points.mean(axis=0) - pts.mean(axis=0)
        # The scan's points onto the whole model (every scanned point has a counterpart there), then inverted.
        r = binpick.icp(
            pts,
            model.points,
            target_normals=model.normals,
            init=init,
            method="point_to_plane",
            max_correspondence_distance=0.1 * model.diameter,
            max_iterations=50,
            num_threads=1,
        )
        return [inverse(r.T_target_source)]


FACTORIES: dict[str, Callable[[bool], Method]] = {
    "binpick": lambda one: BinpickPPF(),
    "open3d": Open3DFeatures,
    "opencv": OpenCVPPF,
    "centroid": lambda one: CentroidIcp(),
}


# ---------------------------------------------------------------------------------------------
# running and reporting


@dataclass
class Runner:
    """One method's column: runs it scene by scene, or says why it cannot."""

    name: str
    label: str
    method: Optional[Method] = None
    unavailable: Optional[str] = None
    prepare_ms: dict = field(default_factory=dict)  # part name -> ms, once per part

    @classmethod
    def of(cls, name: str, one_thread: bool) -> Runner:
        try:
            method = FACTORIES[name](one_thread)
        except Unavailable as exc:
            print(f"{name}: unavailable: {exc}", file=sys.stderr)
            return cls(name, name, unavailable=str(exc))
        return cls(name, method.label, method)

    def _poses(self, scene: Scene, k: int) -> tuple[list[np.ndarray], float]:
        if scene.part.name not in self.prepare_ms:
            start = time.perf_counter()
            self.method.prepare(scene.part)
            self.prepare_ms[scene.part.name] = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        poses = self.method.estimate(scene, k)[:k]
        return poses, (time.perf_counter() - start) * 1e3

    def run(self, scene: Scene) -> dict:
        rec: dict = {"method": self.name, "scene": scene.name, "kind": scene.kind, "part": scene.part.name}
        if self.unavailable is None:
            try:
                poses, rec["time_ms"] = self._poses(scene, TOP_K if scene.is_pile else 1)
            except Unavailable as exc:
                self.unavailable = str(exc)
                print(f"{self.name}: unavailable: {exc}", file=sys.stderr, flush=True)
            except Exception as exc:  # a method's fault on one scene is a failed scene, not a crashed bench
                poses, rec["error"] = [], f"{type(exc).__name__}: {exc}"
        if self.unavailable is not None:
            return {**rec, "unavailable": True}
        judged = [judge(t, scene.truths, scene.part) for t in poses]
        rec["found"] = len(poses)
        rec["first"] = judged[0].as_dict() if judged else None
        rec["pick"] = bool(judged and judged[0].pick)
        rec["mssd_ok"] = bool(judged and judged[0].mssd_ok)
        rec["top3"] = any(j.pick for j in judged)
        # Issue 7's pile criterion: the first instance is pick-grade on one of the three highest parts.
        highest = set(np.argsort(-scene.truths[:, 2, 3])[:3].tolist())
        rec["top_part"] = bool(judged and judged[0].pick and judged[0].truth in highest)
        rec["T_scene_model"] = poses[0].tolist() if poses else None
        return rec


def progress(i: int, n: int, scene: Scene, recs: list[dict]) -> str:
    cells = []
    for r in recs:
        if r.get("unavailable"):
            cells.append(f"{r['method']} n/a")
        elif r.get("first") is None:
            cells.append(
                f"{r['method']} {r.get('time_ms') or 0:.0f} ms none"
                + (f" ({r['error'][:60]})" if r.get("error") else "")
            )
        else:
            f = r["first"]
            mark = "ok" if r["pick"] else ("top3" if r["top3"] else "--")
            cells.append(f"{r['method']} {r['time_ms']:.0f} ms {f['rot_deg']:.1f}° {f['trans_mm']:.1f} mm {mark}")
    return f"[{i}/{n}] {scene.name} ({len(scene.points)} pts): " + " | ".join(cells)


def pct(flags: list[bool]) -> float:
    return 100.0 * sum(flags) / len(flags) if flags else float("nan")


def summarise(records: list[dict], methods: list[str]) -> list[dict]:
    rows = []
    kinds = sorted({r["kind"] for r in records}, key=["views", "piles", "sim"].index)
    for kind in kinds:
        parts = sorted({r["part"] for r in records if r["kind"] == kind})
        for part in parts + ["all"]:
            group = [r for r in records if r["kind"] == kind and (part == "all" or r["part"] == part)]
            base = None
            for m in methods:
                rs = [r for r in group if r["method"] == m]
                if not rs or any(r.get("unavailable") for r in rs):
                    rows.append({"kind": kind, "part": part, "method": m, "available": False})
                    continue
                times = [r["time_ms"] for r in rs if r.get("time_ms") is not None]
                row = {
                    "kind": kind,
                    "part": part,
                    "method": m,
                    "available": True,
                    "scenes": len(rs),
                    "pick_pct": pct([r["pick"] for r in rs]),
                    "mssd_pct": pct([r["mssd_ok"] for r in rs]),
                    "top3_pct": pct([r["top3"] for r in rs]) if kind != "views" else None,
                    "top_part_pct": pct([r["top_part"] for r in rs]) if kind != "views" else None,
                    "median_ms": statistics.median(times) if times else None,
                    "max_ms": max(times) if times else None,
                    "errors": sum(1 for r in rs if r.get("error")),
                }
                if m == "binpick":
                    base = row["median_ms"]
                row["ratio_to_binpick"] = (
                    row["median_ms"] / base if base and row["median_ms"] and m != "binpick" else None
                )
                rows.append(row)
    return rows


def ms(value: Optional[float]) -> str:
    return "—" if value is None else f"{value:.0f}"


KIND_TITLES = {
    "views": "sample views (one part alone)",
    "piles": "sample piles (4–10 parts in a bin)",
    "sim": "binpick simulator piles (reconstructed scans)",
}


def markdown(rows: list[dict], labels: dict[str, str], threads: str) -> str:
    out = []
    for kind in dict.fromkeys(r["kind"] for r in rows):
        piles = kind != "views"
        n = next((r["scenes"] for r in rows if r["kind"] == kind and r["part"] == "all" and r["available"]), 0)
        out.append(f"\n### {KIND_TITLES[kind]}: {n} scene{'' if n == 1 else 's'}, {threads}\n")
        head = (
            "| part | method | scenes | pick-grade | MSSD |"
            + (" top-3 pick | first on a top-3 part |" if piles else "")
            + " median ms | max ms | time / binpick |"
        )
        out += [head, "|" + "---|" * (head.count("|") - 1)]
        for r in (r for r in rows if r["kind"] == kind):
            name = f"**{r['part']}**" if r["part"] == "all" else r["part"]
            if not r["available"]:
                out.append(
                    f"| {name} | {labels[r['method']]} | — | unavailable | |" + (" | |" if piles else "") + " | | |"
                )
                continue
            ratio = f"{r['ratio_to_binpick']:.2f}×" if r["ratio_to_binpick"] else ""
            top3 = f" {r['top3_pct']:.0f} % | {r['top_part_pct']:.0f} % |" if piles else ""
            errors = f" ({r['errors']} failed)" if r["errors"] else ""
            out.append(
                f"| {name} | {labels[r['method']]} | {r['scenes']}{errors} "
                f"| {r['pick_pct']:.0f} % | {r['mssd_pct']:.0f} % |{top3} "
                f"{ms(r['median_ms'])} | {ms(r['max_ms'])} | {ratio} |"
            )
    return "\n".join(out)


def plot(rows: list[dict], labels: dict[str, str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, NullFormatter

    kinds = list(dict.fromkeys(r["kind"] for r in rows))
    fig, axes = plt.subplots(1, len(kinds), figsize=(5.5 * len(kinds), 4.8), squeeze=False)
    colours = dict(zip(METHOD_NAMES, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    shown = set()
    for ax, kind in zip(axes[0], kinds):
        for r in rows:
            if r["kind"] != kind or r["part"] != "all" or not r["available"] or not r["median_ms"]:
                continue
            x, c = r["median_ms"] / 1e3, colours[r["method"]]
            ax.scatter([x], [r["pick_pct"]], color=c, s=70, zorder=3)
            ax.scatter([x], [r["mssd_pct"]], s=70, marker="^", facecolors="none", edgecolors=c, zorder=3)
            ax.annotate(r["method"], (x, r["pick_pct"]), textcoords="offset points", xytext=(7, 4), fontsize=8)
            shown.add(r["method"])
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.margins(x=0.25)
        ax.set_ylim(-5, 105)
        ax.set_xlabel("median time per scene (s)")
        ax.set_ylabel("success (%)")
        ax.set_title(KIND_TITLES[kind], fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    handles = [
        Line2D([], [], color=colours[m], marker="o", linestyle="", label=labels[m]) for m in METHOD_NAMES if m in shown
    ]
    handles += [
        Line2D([], [], color="grey", marker="o", linestyle="", label="pick-grade (< 5°, < 3 mm)"),
        Line2D([], [], color="grey", marker="^", markerfacecolor="none", linestyle="", label="MSSD < 0.1 × diameter"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle("Pose estimation: success vs time per scene")
    fig.tight_layout(rect=(0, 0.12, 1, 0.95))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="the sample folder (views/, piles/)")
    ap.add_argument("--methods", default=",".join(METHOD_NAMES), help=f"comma-separated, of {', '.join(METHOD_NAMES)}")
    ap.add_argument(
        "--parts", default=None, help="comma-separated part names (case-insensitive substrings), e.g. gear,tee"
    )
    ap.add_argument("--limit", type=int, default=None, help="scenes per part and kind")
    only = ap.add_mutually_exclusive_group()
    only.add_argument("--views", action="store_true", help="views only")
    only.add_argument("--piles", action="store_true", help="piles only (the sample's and the simulated)")
    ap.add_argument("--sim", type=int, default=2, help="simulated piles of binpick's tee and elbow (0: none)")
    ap.add_argument("--peer-threads", choices=("1", "default"), default="1", help="'default': the peers' own threading")
    ap.add_argument("--out", type=Path, default=Path("bench-out"))
    args = ap.parse_args(argv)

    names = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in names if m not in FACTORIES]
    if unknown:
        ap.error(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHOD_NAMES)}")
    parts = [p.strip() for p in args.parts.split(",")] if args.parts else None
    kinds = ["views"] if args.views else ["piles"] if args.piles else ["views", "piles"]

    scenes: list[Scene] = []
    if (args.data / "views").is_dir() or (args.data / "piles").is_dir():
        scenes += sample_scenes(args.data, kinds, parts, args.limit)
    else:
        print(f"no sample data at {args.data}; skipping its scenes (see ../shared/data/README.md)", file=sys.stderr)
    if not args.views:
        scenes += sim_scenes(args.sim if args.limit is None else min(args.sim, args.limit * len(SIM_PARTS)), parts)
    if not scenes:
        print("no scenes to run; nothing to do", file=sys.stderr)
        return 0

    runners = [Runner.of(m, args.peer_threads == "1") for m in names]
    labels = {r.name: r.label for r in runners}

    records = []
    for i, scene in enumerate(scenes, 1):
        recs = [r.run(scene) for r in runners]
        records += recs
        print(progress(i, len(scenes), scene, recs), file=sys.stderr, flush=True)

    rows = summarise(records, names)
    print(
        markdown(
            rows,
            labels,
            "one thread each" if args.peer_threads == "1" else "binpick one thread, peers their default threading",
        )
    )
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {
        "config": {
            "voxel_mm": VOXEL,
            "crop_margin_mm": CROP_MARGIN,
            "pick_grade": [PICK_ROTATION, PICK_TRANSLATION],
            "mssd_fraction": MSSD_FRACTION,
            "top_k": TOP_K,
            "peer_threads": args.peer_threads,
            "binpick_threads": 1,
            "binpick_version": binpick.__version__,
            "data": str(args.data),
            "sim_piles": sum(s.kind == "sim" for s in scenes),
        },
        "methods": {
            r.name: {"label": r.label, "unavailable": r.unavailable, "prepare_ms": r.prepare_ms} for r in runners
        },
        "summary": rows,
        "scenes": records,
    }
    (args.out / "pose_peers.json").write_text(json.dumps(doc, indent=1), encoding="utf-8")
    plot(rows, labels, args.out / "pose_peers.png")
    print(f"\nwrote {args.out / 'pose_peers.json'} and {args.out / 'pose_peers.png'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
