"""Geometry helpers the tests share: meshes and clouds they make themselves, mesh-file writers,
random rigid transforms, and pose errors (the library's :func:`binpick.transforms.pose_error`)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from binpick.transforms import pose_error, rotation_about


def box_mesh(size=(20.0, 30.0, 40.0)) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box with one corner at the origin, outward-wound triangles."""
    sx, sy, sz = size
    v = np.array([[x, y, z] for z in (0, sz) for y in (0, sy) for x in (0, sx)], dtype=float)
    f = np.array(
        [
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ]
    )
    return v, f


def write_stl_binary(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    with open(path, "wb") as fh:
        fh.write(b"binpick test".ljust(80, b" "))
        fh.write(struct.pack("<I", len(f)))
        for tri in f:
            a, b, c = v[tri]
            n = np.cross(b - a, c - a)
            n = n / np.linalg.norm(n)
            fh.write(struct.pack("<12fH", *n, *a, *b, *c, 0))


def write_stl_ascii(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    lines = ["solid test"]
    for tri in f:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {p[0]:.9e} {p[1]:.9e} {p[2]:.9e}" for p in v[tri]]
        lines += ["    endloop", "  endfacet"]
    lines.append("endsolid test")
    path.write_text("\n".join(lines) + "\n")


def write_obj(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    out = [f"v {p[0]} {p[1]} {p[2]}" for p in v] + [f"f {a + 1}/1/1 {b + 1}//2 {c + 1}" for a, b, c in f]
    path.write_text("# test\n" + "\n".join(out) + "\n")


def write_ply_mesh(path: Path, v: np.ndarray, f: np.ndarray, binary: bool) -> None:
    head = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\ncomment test\n"
        f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(head.encode())
        if binary:
            for p in v:
                fh.write(struct.pack("<fffB", *p, 200))
            for tri in f:
                fh.write(struct.pack("<B3i", 3, *tri))
        else:
            for p in v:
                fh.write(f"{p[0]} {p[1]} {p[2]} 200\n".encode())
            for tri in f:
                fh.write(f"3 {tri[0]} {tri[1]} {tri[2]}\n".encode())


#: A writer of every mesh format binpick reads, by a file name of that format: ``write(path, v, f)``.
MESH_WRITERS = {
    "binary.stl": write_stl_binary,
    "ascii.stl": write_stl_ascii,
    "part.obj": write_obj,
    "binary.ply": lambda path, v, f: write_ply_mesh(path, v, f, True),
    "ascii.ply": lambda path, v, f: write_ply_mesh(path, v, f, False),
}


def random_rigid(rng: np.random.Generator, max_angle: float, max_shift: float) -> np.ndarray:
    """A random 4×4 rigid transform: rotation up to ``max_angle`` rad, shift up to ``max_shift`` mm."""
    axis = rng.normal(size=3)
    ang = rng.uniform(0, max_angle)
    shift = rng.normal(size=3)
    shift *= rng.uniform(0, max_shift) / np.linalg.norm(shift)
    t = np.eye(4)
    t[:3, :3] = rotation_about(axis, ang)
    t[:3, 3] = shift
    return t


def apply(t: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return pts @ t[:3, :3].T + t[:3, 3]


def _ear_clip(poly: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles of a simple counter-clockwise polygon (N, 2) by ear clipping."""
    idx = list(range(len(poly)))
    tris = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    while len(idx) > 3:
        for k in range(len(idx)):
            i, j, n = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = poly[i], poly[j], poly[n]
            if cross(a, b, c) <= 0:
                continue
            inside = any(
                cross(a, b, poly[m]) >= 0 and cross(b, c, poly[m]) >= 0 and cross(c, a, poly[m]) >= 0
                for m in idx
                if m not in (i, j, n)
            )
            if not inside:
                tris.append((i, j, n))
                idx.pop(k)
                break
        else:
            raise ValueError("polygon is not simple and counter-clockwise")
    tris.append(tuple(idx))
    return tris


def extruded_mesh(polygon, height: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed prism: the simple counter-clockwise ``polygon`` (N, 2) in the xy plane, extruded
    from z = 0 to ``height``, outward-wound."""
    poly = np.asarray(polygon, dtype=float)
    n = len(poly)
    v = np.vstack([np.c_[poly, np.zeros(n)], np.c_[poly, np.full(n, height)]])
    tris = _ear_clip(poly)
    faces = [(c, b, a) for a, b, c in tris] + [(a + n, b + n, c + n) for a, b, c in tris]
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, j + n), (i, j + n, i + n)]
    return v, np.array(faces, dtype=np.int64)


def revolved_mesh(profile, segments: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """A closed solid of revolution about z: ``profile`` is a list of (radius, z) from the bottom
    axis point to the top axis point (first and last radius 0), outward-wound."""
    prof = np.asarray(profile, dtype=float)
    ring = [k for k in range(len(prof)) if prof[k, 0] > 0]
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    v = [[0.0, 0.0, prof[0, 1]]]
    for k in ring:
        r, z = prof[k]
        v += [[r * np.cos(a), r * np.sin(a), z] for a in ang]
    v.append([0.0, 0.0, prof[-1, 1]])
    top = len(v) - 1
    faces = []
    s = segments
    for i in range(s):
        j = (i + 1) % s
        faces.append((0, 1 + j, 1 + i))
        for r in range(len(ring) - 1):
            a, b = 1 + r * s, 1 + (r + 1) * s
            faces += [(a + i, a + j, b + j), (a + i, b + j, b + i)]
        last = 1 + (len(ring) - 1) * s
        faces.append((last + i, last + j, top))
    return np.array(v), np.array(faces, dtype=np.int64)


def rot(axis, angle) -> np.ndarray:
    """3×3 rotation about ``axis`` by ``angle`` rad."""
    return rotation_about(axis, angle)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random 3×3 rotation."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def symmetric_pose_error(
    t_est: np.ndarray, t_true: np.ndarray, rotations, center=(0.0, 0.0, 0.0), continuous_axis=None
) -> tuple[float, float]:
    """(rotation deg, translation mm) of ``t_est`` against ``t_true`` minimised over symmetry
    rotations about ``center`` (model frame) and a continuous axis through it: the library's
    :func:`binpick.transforms.pose_error` with the group written as 4×4 maps."""
    c = np.asarray(center, float)
    maps = []
    for s in rotations:
        t = np.eye(4)
        t[:3, :3] = np.asarray(s, float)
        t[:3, 3] = c - t[:3, :3] @ c
        maps.append(t)
    return pose_error(t_est, t_true, maps, continuous_axis=continuous_axis, center=c)


def camera_cloud(view, cell, step: int, seed: int = 0, noise: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """The points a simulated camera view sees (every ``step``-th pixel with a surface), in the
    base frame with Gaussian ``noise`` (mm), and the instance id of each."""
    pts = view.points.reshape(-1, 3).astype(np.float64)
    ids = view.ids.reshape(-1)
    keep = np.isfinite(pts).all(axis=1)
    pts, ids = pts[keep][::step], ids[keep][::step]
    T = cell.T_base_camera
    return pts @ T[:3, :3].T + T[:3, 3] + np.random.default_rng(seed).normal(0, noise, pts.shape), ids


def pile_view(model, count: int, seed: int, step: int, noise_seed: int = 0):
    """``count`` copies of ``model`` dropped into the simulated cell's bin by the physics engine
    and seen by its camera from the scan pose (every ``step``-th pixel, noise drawn with
    ``noise_seed``): (cell, pile, scene points, their part ids)."""
    from binpick import sim

    cell = sim.Cell()
    pile = sim.Pile(model, count, bin=cell.bin, seed=seed)
    view = sim.World.of_pile(pile, bin=cell.bin).view(cell)
    scene, ids = camera_cloud(view, cell, step=step, seed=noise_seed)
    return cell, pile, scene, ids


def rendered_view(model, T_base_object: np.ndarray, rng: np.random.Generator, noise: float = 0.15) -> np.ndarray:
    """What the simulated cell's camera sees of the part alone at ``T_base_object`` (base frame, mm)."""
    from binpick import sim

    cell = sim.Cell()
    world = sim.World()
    world.add_parts(model, [0], T_base_object[None])
    return camera_cloud(world.view(cell), cell, step=1, seed=int(rng.integers(1 << 31)), noise=noise)[0]
