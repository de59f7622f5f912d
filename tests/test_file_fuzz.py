"""Byte-mutation fuzz of the calibration and scan readers, seeded and bounded to seconds: every
mutated file is either a valid load or a BinpickError, nothing else, and no case hangs."""

from __future__ import annotations

import random
import time
from collections import Counter

import pytest

from _files import mutate, small_calibration, small_scan
from binpick.calibration import CellCalibration
from binpick.errors import BinpickError
from binpick.scan import load_scan

CASES = 300
SLOWEST_CASE_S = 2.0


def _fuzz(path, original: bytes, load, seed: int) -> tuple[Counter, list]:
    """Writes ``CASES`` mutations of ``original`` to ``path`` and loads each; the outcome counts
    and the cases that ended in anything but a load or a BinpickError."""
    rng = random.Random(seed)
    outcomes: Counter = Counter()
    other = []
    for case in range(CASES):
        data = mutate(original, rng)
        path.write_bytes(data)
        t = time.monotonic()
        try:
            load()
            outcomes["valid"] += 1
        except BinpickError:
            outcomes["BinpickError"] += 1
        except Exception as exc:  # the outcome the test exists to catch
            outcomes["other"] += 1
            other.append((case, type(exc).__name__, str(exc)[:120], data[:200]))
        took = time.monotonic() - t
        assert took < SLOWEST_CASE_S, f"case {case} took {took:.1f} s: {data[:200]!r}"
    return outcomes, other


@pytest.mark.parametrize("seed", [1, 2])
def test_mutated_calibration_files_load_or_raise_binpick_errors(tmp_path, seed):
    path = tmp_path / "calibration.toml"
    outcomes, other = _fuzz(path, small_calibration().to_toml().encode(), lambda: CellCalibration.load(path), seed)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes  # both sides are exercised


@pytest.mark.parametrize("seed", [1, 2])
def test_mutated_scan_json_loads_or_raises_binpick_errors(tmp_path, seed):
    root = small_scan(tmp_path / "scan")
    path = root / "scan.json"
    outcomes, other = _fuzz(path, path.read_bytes(), lambda: load_scan(root), seed)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes


def test_mutated_frame_images_read_or_raise_binpick_errors(tmp_path):
    root = small_scan(tmp_path / "scan")
    frame = load_scan(root).frames[0]
    outcomes, other = _fuzz(frame.image_path, frame.image_path.read_bytes(), frame.image, 3)
    assert other == [], f"{len(other)} of {CASES} mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["BinpickError"] > 0, outcomes
