"""Byte-mutation fuzz of the file readers, seeded and bounded to seconds: calibration.toml,
scan.json and PNG frames, every mesh format (binary and ASCII STL and PLY, OBJ), PLY clouds, XYZ
and NPY scenes, and the PPF cache. Every mutated file is either a valid load or a BinpickError,
nothing else, no case hangs, and a damaged PPF cache is rebuilt, never loaded. (PCD files are
fuzzed in test_clouds.py, the cell file in cell/test_cell_file.py.)"""

from __future__ import annotations

import pytest

from _files import CASES, fuzz, mesh_and_scene_readers, ppf_cache_reader, small_calibration, small_scan
from binpick.calibration import CellCalibration
from binpick.scan import load_scan


@pytest.mark.parametrize("seed", [1, 2])
def test_mutated_calibration_files_load_or_raise_binpick_errors(tmp_path, seed):
    path = tmp_path / "calibration.toml"
    outcomes, other = fuzz(path, small_calibration().to_toml().encode(), lambda: CellCalibration.load(path), seed)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes  # both sides are exercised


@pytest.mark.parametrize("seed", [1, 2])
def test_mutated_scan_json_loads_or_raises_binpick_errors(tmp_path, seed):
    root = small_scan(tmp_path / "scan")
    path = root / "scan.json"
    outcomes, other = fuzz(path, path.read_bytes(), lambda: load_scan(root), seed)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes


def test_mutated_frame_images_read_or_raise_binpick_errors(tmp_path):
    root = small_scan(tmp_path / "scan")
    frame = load_scan(root).frames[0]
    outcomes, other = fuzz(frame.image_path, frame.image_path.read_bytes(), frame.image, 3)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["BinpickError"] > 0, outcomes


@pytest.fixture(scope="module")
def readers(tmp_path_factory):
    return {name: (path, load) for name, path, load in mesh_and_scene_readers(tmp_path_factory.mktemp("readers"))}


@pytest.mark.parametrize(
    "name",
    [
        "mesh binary.stl",
        "mesh ascii.stl",
        "mesh part.obj",
        "mesh binary.ply",
        "mesh ascii.ply",
        "read_ply cloud_ascii.ply",
        "read_ply cloud_binary.ply",
        "read_scene .xyz",
        "read_scene .npy",
    ],
)
def test_mutated_mesh_and_scene_files_read_or_raise_binpick_errors(readers, name):
    path, load = readers[name]
    original = path.read_bytes()
    try:
        outcomes, other = fuzz(path, original, load, 4)
    finally:
        path.write_bytes(original)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes


def test_a_mutated_ppf_cache_is_rebuilt_never_loaded(tmp_path, monkeypatch):
    """The cache file closes with the SHA-256 of its table: a flipped byte in a point, which the
    core's structural checks cannot see, used to load a wrong table (15 of 300 mutations)."""
    monkeypatch.setenv("BINPICK_CACHE_DIR", str(tmp_path))
    path, load = ppf_cache_reader(tmp_path)
    outcomes, other = fuzz(path, path.read_bytes(), load, 5, cases=40)
    assert other == [] and outcomes["valid"] == 40, (outcomes, other[:3])
