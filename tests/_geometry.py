"""Geometry helpers the tests share: meshes and clouds they make themselves, mesh-file writers,
random rigid transforms and pose errors."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def box_mesh(size=(20.0, 30.0, 40.0)) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box with one corner at the origin, outward-wound triangles."""
    sx, sy, sz = size
    v = np.array([[x, y, z] for z in (0, sz) for y in (0, sy) for x in (0, sx)], dtype=float)
    f = np.array(
        [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
         [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
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


def random_rigid(rng: np.random.Generator, max_angle: float, max_shift: float) -> np.ndarray:
    """A random 4×4 rigid transform: rotation up to ``max_angle`` rad, shift up to ``max_shift`` mm."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = rng.uniform(0, max_angle)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + np.sin(ang) * k + (1 - np.cos(ang)) * k @ k
    shift = rng.normal(size=3)
    shift *= rng.uniform(0, max_shift) / np.linalg.norm(shift)
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = shift
    return t


def apply(t: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return pts @ t[:3, :3].T + t[:3, 3]


def pose_error(t_est: np.ndarray, t_true: np.ndarray) -> tuple[float, float]:
    """(rotation error in degrees, translation error in mm)."""
    d = t_true[:3, :3].T @ t_est[:3, :3]
    ang = np.degrees(np.arccos(np.clip((np.trace(d) - 1) / 2, -1, 1)))
    return float(ang), float(np.linalg.norm(t_est[:3, 3] - t_true[:3, 3]))
