"""Issue 38's measurement: reading PCL's own binary_compressed PCD files, binpick against Open3D.

For every binary_compressed cloud with x, y, z in ../shared/data/real/pcd (files PCL wrote), in
the same process and on one thread each: the median time of ``binpick.clouds.read_scene`` and of
``open3d.io.read_point_cloud`` over repeated reads, their ratio (target ≤ 1.0), and a check that
the values are the same (binpick keeps the finite points, in the file's order; Open3D keeps every
point, NaN included). Skips cleanly when the data or Open3D is absent.

    PYTHONPATH=python python benches/pcd_read.py [--repeats 15] [--out benches/results/pcd_read.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

from binpick.clouds import read_scene

PCD_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "pcd"


def _header(path: Path) -> dict:
    """The header's keys (FIELDS, WIDTH, HEIGHT, DATA, …) and their words, up to the DATA line."""
    fields: dict = {}
    for line in path.read_bytes()[:4096].decode("ascii", "replace").splitlines():
        words = line.split()
        if words and not words[0].startswith("#"):
            fields[words[0]] = words[1:]
            if words[0] == "DATA":
                break
    return fields


def _median_ms(read, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        read()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if not PCD_DIR.is_dir():
        print(f"skipped: {PCD_DIR} is absent")
        return
    try:
        import open3d as o3d
    except ImportError:
        print("skipped: open3d is not installed (pip install open3d)")
        return
    rows = []
    for path in sorted(PCD_DIR.glob("*.pcd")):
        h = _header(path)
        if h.get("DATA") != ["binary_compressed"] or not {"x", "y", "z"} <= set(h.get("FIELDS", [])):
            continue
        ours = read_scene(path).points
        theirs = np.asarray(o3d.io.read_point_cloud(str(path)).points)
        finite = theirs[np.isfinite(theirs).all(axis=1)]
        # read_scene returns mm; PCL's files are in metres unless the file says otherwise.
        size = float(np.median(np.linalg.norm(finite, axis=1))) if len(finite) else 0.0
        scale = float(np.median(np.linalg.norm(ours, axis=1))) / size if size > 0 else 1.0
        same = len(ours) == len(finite) and np.allclose(ours, finite * scale, rtol=1e-6, atol=1e-9)
        b = _median_ms(lambda p=path: read_scene(p), args.repeats)
        o = _median_ms(lambda p=str(path): o3d.io.read_point_cloud(p), args.repeats)
        rows.append(
            {
                "file": path.name,
                "width": int(h["WIDTH"][0]),
                "height": int(h["HEIGHT"][0]),
                "points_finite": len(ours),
                "binpick_ms": round(b, 2),
                "open3d_ms": round(o, 2),
                "ratio": round(b / o, 3),
                "values_same": bool(same),
            }
        )
        r = rows[-1]
        print(
            f"{r['file']:<40} {r['width']:>6}×{r['height']:<4} binpick {b:7.2f} ms  open3d {o:7.2f} ms  "
            f"ratio {r['ratio']:.2f}  values {'same' if same else 'DIFFER'}"
        )
    worst = max((r["ratio"] for r in rows), default=float("nan"))
    print(f"worst ratio {worst:.2f} (target ≤ 1.0) over {len(rows)} files")
    if args.out:
        Path(args.out).write_text(json.dumps({"files": rows, "worst_ratio": worst}, indent=1))


if __name__ == "__main__":
    main()
