"""Measuring-chain throughput on one core: laser-line extraction (frames/s at 1032×778) and
triangulation (points/s, end to end from Python), on rendered frames of the test scene.
Triangulation is fed laser-line pixels as extract_line gives them (one per image row, frame
after frame, the line sweeping the image) and, as a worst case for memory access and for the
dropping of singular points, uniformly random pixels. Run: python benches/vision_bench.py"""

from __future__ import annotations

import time

import cv2
import numpy as np

from binpick.calibration import CameraIntrinsics, CellCalibration
from binpick.vision import _synthetic as syn
from binpick.vision import extract_line, triangulate


def best_of(f, repeat: int = 5, number: int = 20) -> float:
    """Seconds per call, best of ``repeat`` runs of ``number`` calls."""
    f()
    return min(_timed(f, number) for _ in range(repeat)) / number


def _timed(f, number: int) -> float:
    t0 = time.perf_counter()
    for _ in range(number):
        f()
    return time.perf_counter() - t0


def main() -> None:
    cv2.setNumThreads(1)
    cam = CameraIntrinsics(
        1032, 778, [[1200.0, 0, 520.3], [0, 1195.0, 385.7], [0, 0, 1]], [-0.09, 0.06, 0.0006, -0.0004, -0.01]
    )
    cal = CellCalibration(
        cam, syn.pose(0.01, -0.02, 0.015, (-150.0, 2.0, 5.0)), syn.pose(0.02, -0.01, 0.3, (30.0, -10.0, 90.0))
    )
    T_base_flange = syn.pose(np.pi, 0.0, 0.1, (10.0, -20.0, 500.0)) @ np.linalg.inv(cal.T_flange_camera)
    surfaces = [
        syn.Plane(np.zeros(3), np.array([0.05, 0.1, 1.0])),
        syn.Cylinder(np.array([0.0, 0.0, 45.0]), np.array([0.3, 1.0, 0.0]), 45.0),
    ]
    img = syn.render(cal, surfaces, T_base_flange, angle=0.3, noise=3.0)
    for method in ("cog", "gaussian"):
        s = best_of(lambda method=method: extract_line(img, method=method))
        print(f"extract_line[{method}] 1032x778: {1 / s:8.0f} frames/s ({s * 1e3:.2f} ms/frame)")

    rng = np.random.default_rng(0)
    for n in (10_000, 1_000_000):
        # Laser lines: frame f lights a wavy line whose mean column sweeps the image.
        rows = cam.height
        f = np.arange(n) // rows
        v = (np.arange(n) % rows).astype(np.float64)
        px = np.column_stack([60.0 + (f % 400) * 2.2 + 25.0 * np.sin(v / 60.0) + 0.37, v])
        angles = 0.1 + 0.4 * (np.arange(f[-1] + 1) % 400) / 400
        poses = np.repeat(T_base_flange[None], len(angles), axis=0)
        s = best_of(
            lambda px=px, f=f, angles=angles, poses=poses: triangulate(px, f, angles, poses, cal, num_threads=1),
            repeat=5,
            number=3,
        )
        print(f"triangulate {n:>9} laser-line pixels, 1 thread: {n / s / 1e6:6.1f} M points/s (incl. Python checks)")
    frames = 400
    angles = rng.uniform(0.1, 0.5, frames)
    poses = np.repeat(T_base_flange[None], frames, axis=0)
    n = 1_000_000
    px = np.column_stack([rng.uniform(0, 1031, n), rng.uniform(0, 777, n)])
    idx = rng.integers(0, frames, n)
    kept = len(triangulate(px, idx, angles, poses, cal, num_threads=1))
    s = best_of(lambda: triangulate(px, idx, angles, poses, cal, num_threads=1), repeat=5, number=3)
    print(
        f"triangulate {n:>9} random pixels, 1 thread:     {n / s / 1e6:6.1f} "
        f"M points/s ({100 * (1 - kept / n):.0f}% dropped as singular)"
    )


if __name__ == "__main__":
    main()
