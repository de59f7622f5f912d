"""Byte-mutation fuzz of the calibration and scan readers, seeded and bounded to seconds: every
mutated file is either a valid load or a BinpickError, nothing else, and no case hangs."""

from __future__ import annotations

import pytest

from _files import CASES, fuzz, small_calibration, small_scan
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
