"""The long byte-mutation fuzz of binpick's file readers (the test suite runs a few hundred cases
of each in seconds): calibration.toml, a scan folder's scan.json and a PNG frame, the cell file,
every mesh format (binary and ASCII STL and PLY, OBJ), PLY clouds, XYZ and NPY scenes, and the
PPF cache (a tenth of the cases: each prepares a model, about 50 ms). Every outcome must be a
valid load or a BinpickError, and a damaged PPF cache must be rebuilt, never loaded; prints the
counts and the time per reader. Run: python benches/file_fuzz.py [--cases 5000] [--seed 100]"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the suite's file helpers

import binpick  # noqa: E402
from _files import fuzz, mesh_and_scene_readers, ppf_cache_reader, small_calibration, small_scan  # noqa: E402
from binpick.calibration import CellCalibration  # noqa: E402
from binpick.cell import CELL_FILE_EXAMPLE, config_from_file, load_cell_file  # noqa: E402
from binpick.scan import load_scan  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=5000, help="mutations per reader (default 5000)")
    p.add_argument("--seed", type=int, default=100, help="seed of the mutations (default 100)")
    args = p.parse_args()
    root = Path(tempfile.mkdtemp(prefix="binpick_fuzz_"))
    calibration = root / "calibration.toml"
    small_calibration().save(calibration)
    scan = small_scan(root / "scan")
    frame = load_scan(scan).frames[0]
    cell = root / "cell.toml"
    cell.write_text(CELL_FILE_EXAMPLE)
    tee = binpick.parts.tee()
    binpick.parts.tee = lambda: tee  # the cell file names the built-in tee: build it once
    readers = [
        ("calibration.toml", calibration, lambda: CellCalibration.load(root / "fuzzed.toml"), root / "fuzzed.toml"),
        ("scan.json", scan / "scan.json", lambda: load_scan(scan), scan / "scan.json"),
        ("frame PNG", frame.image_path, frame.image, frame.image_path),
        (
            "cell file",
            cell,
            lambda: config_from_file(load_cell_file(root / "fuzzed_cell.toml")),
            root / "fuzzed_cell.toml",
        ),
        *[(name, path, load, path) for name, path, load in mesh_and_scene_readers(root / "meshes")],
    ]
    os.environ["BINPICK_CACHE_DIR"] = str(root / "cache")
    cache, load_cache = ppf_cache_reader(root / "cache")
    readers.append(("PPF cache", cache, load_cache, cache))
    print(f"{'reader':<28}{'cases':>7}{'valid':>8}{'Binpick':>9}{'other':>7}{'seconds':>9}")
    failed = False
    for name, original, load, target in readers:
        data = original.read_bytes()
        cases = max(1, args.cases // 10) if name == "PPF cache" else args.cases
        t = time.perf_counter()
        outcomes, other = fuzz(target, data, load, args.seed, cases=cases)
        target.write_bytes(data)
        print(
            f"{name:<28}{cases:>7}{outcomes['valid']:>8}{outcomes['BinpickError']:>9}"
            f"{outcomes['other']:>7}{time.perf_counter() - t:>9.1f}"
        )
        for case in other[:5]:
            print("   ", case)
        failed = failed or bool(other)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
