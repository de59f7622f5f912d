"""Cell files that lie: a wrong value ends in InvalidInputError naming the file, the table and the
key (never ValueError, TypeError or AttributeError from deep inside), and a byte-mutation fuzz of
the reader gives only valid configurations or BinpickErrors."""

from __future__ import annotations

import re

import pytest

import binpick
from _files import fuzz, small_calibration
from binpick.cell import CELL_FILE_EXAMPLE, cell_from_file, config_from_file, load_cell_file
from binpick.errors import CalibrationError, InvalidInputError, MeshFileNotFoundError


@pytest.fixture(scope="module")
def tee():
    return binpick.parts.tee()


@pytest.fixture
def cell_dir(tmp_path, tee, monkeypatch):
    monkeypatch.setattr(binpick.parts, "tee", lambda: tee)  # built once: the fuzz reads hundreds of files
    small_calibration().save(tmp_path / "calibration.toml")
    (tmp_path / "cell.toml").write_text(CELL_FILE_EXAMPLE)
    return tmp_path


def _config(cell_dir, text=None, raw=None):
    path = cell_dir / "cell.toml"
    if raw is not None:
        path.write_bytes(raw)
    elif text is not None:
        path.write_text(text)
    return config_from_file(load_cell_file(path))


def test_the_example_reads(cell_dir):
    config = _config(cell_dir)
    assert config.frames == 90 and config.calibration == small_calibration()


@pytest.mark.parametrize(
    "old,new,match",
    [
        ("frames = 90", 'frames = "90"', r"\[cell\] frames must be a whole number"),
        ("frames = 90", "frames = true", r"\[cell\] frames must be a whole number"),
        ("frames = 90", "frames = 90.5", r"\[cell\] frames must be a whole number"),
        ('model = "tee"', "model = 3", r"\[part\] model must be a string"),
        ('calibration = "calibration.toml"', "calibration = [1]", r"\[cell\] calibration must be a string"),
        ("bin_min_mm = [250.0, -100.0, 0.0]", 'bin_min_mm = ["a", 1, 2]', r"\[cell\] bin_min_mm must be a list of 3"),
        ("bin_min_mm = [250.0, -100.0, 0.0]", "bin_min_mm = 250.0", r"\[cell\] bin_min_mm must be a list of 3"),
        ("scan_pose = [400.0, 0.0, 620.0, 180.0, 0.0, 0.0]", "scan_pose = [400.0, 0.0]", r"\[cell\] scan_pose"),
        ("tool = [0.0, 0.0, 195.0, 0.0, 0.0, 0.0]", "tool = [0, 0, nan, 0, 0, 0]", r"\[cell\] tool"),
        ("finger_length_mm = 90.0", 'finger_length_mm = "long"', r"\[gripper\] finger_length_mm must be a finite"),
        ("finger_length_mm = 90.0", "finger_length_mm = -5.0", r"\[gripper\] finger_length_mm.*positive"),
        ("preshape_clearance_mm = 5.0", "preshape_clearance_mm = true", r"\[gripper\] preshape_clearance_mm must"),
        ("approach_height_mm = 315.0", 'approach_height_mm = "high"', r"\[limits\] approach_height_mm must be a"),
        ("max_tool_tilt_deg = 45.0", "max_tool_tilt_deg = inf", r"\[limits\] max_tool_tilt_deg"),
        ("orientation_needed = false", 'orientation_needed = "yes"', r"\[cell\] orientation_needed must be true or"),
        ("# min_confidence = 0.3", "min_confidence = []", r"\[cell\] min_confidence must be a finite number"),
        ("# d_star = 12.0", "dstar = 12.0", r"\[estimate\] 'dstar' is not an option of binpick.estimate_pose"),
        ("baudrate = 9600", 'baudrate = "fast"', r"\[robot\] baudrate must be a whole number"),
        ("override_percent = 10", "override_percent = {}", r"\[robot\] override_percent must be a finite number"),
        ('port = "/dev/ttyUSB0"', "port = 0", r"\[robot\] port must be a string"),
        ("id = 1", "id = 1.5", r"\[motor\] id must be a whole number"),
        ('kind = "modbus"', "kind = false", r"\[gripper\] kind must be a string"),
        ("override_percent = 10", "override_percent = 200", r"cell.toml: MelfaConfig.initial_override_percent"),
    ],
)
def test_a_wrong_value_names_the_file_table_and_key_before_any_port_is_opened(cell_dir, old, new, match):
    assert old in CELL_FILE_EXAMPLE
    (cell_dir / "cell.toml").write_text(CELL_FILE_EXAMPLE.replace(old, new, 1))
    with pytest.raises(InvalidInputError, match=match) as info:
        cell_from_file(load_cell_file(cell_dir / "cell.toml"))  # the ports in the example do not exist
    assert str(info.value).startswith(str(cell_dir / "cell.toml"))


def test_how_sure_a_pose_must_be_is_read_from_the_cell_table(cell_dir):
    assert not _config(cell_dir).orientation_needed  # the example leaves undecided poses to shared grasps
    text = CELL_FILE_EXAMPLE.replace("orientation_needed = false", "orientation_needed = true")
    config = _config(cell_dir, text.replace("# min_confidence = 0.3", "min_confidence = 0.6"))
    assert config.orientation_needed and config.min_confidence == 0.6
    with pytest.raises(InvalidInputError, match="min_confidence"):
        _config(cell_dir, CELL_FILE_EXAMPLE.replace("# min_confidence = 0.3", "min_confidence = 1.5"))


def test_the_gripper_shape_is_read_from_the_gripper_table(cell_dir):
    g = _config(cell_dir).gripper
    assert g.finger_length_mm == 90.0 and g.T_flange_gripper[2, 3] == 195.0 and g.preshape_clearance_mm == 5.0
    text = CELL_FILE_EXAMPLE.replace("finger_length_mm = 90.0", "finger_length_mm = 120.0").replace(
        "preshape_clearance_mm = 5.0", "preshape_clearance_mm = false"
    )
    g = _config(cell_dir, text).gripper
    assert g.finger_length_mm == 120.0 and g.preshape_clearance_mm is None
    g = _config(cell_dir, re.sub(r"finger_length_mm = 90.0.*\n", "", CELL_FILE_EXAMPLE)).gripper
    assert g.finger_length_mm == binpick.cell.GripperGeometry().finger_length_mm  # absent: the default


@pytest.mark.parametrize("table", ["limits", "estimate"])
def test_a_table_that_is_not_a_table_is_named(cell_dir, table):
    text = f"{table} = [1, 2]\n" + CELL_FILE_EXAMPLE.replace(f"[{table}]", f"[{table}_]")
    with pytest.raises(InvalidInputError, match=rf"\[{table}\] table is missing"):
        _config(cell_dir, text)


def test_unreadable_cell_files_are_clear(cell_dir):
    with pytest.raises(MeshFileNotFoundError, match="no such file, the cell file does not exist; write one after"):
        load_cell_file(cell_dir / "nowhere.toml")
    with pytest.raises(InvalidInputError, match=r"byte \d+ of the cell file is not UTF-8"):
        _config(cell_dir, raw=CELL_FILE_EXAMPLE.encode() + b"\n# \xff\n")
    with pytest.raises(InvalidInputError, match="nested too deeply"):
        _config(cell_dir, raw=b"x = " + b"[" * 50000 + b"]" * 50000)
    with pytest.raises(InvalidInputError, match="not valid TOML"):
        _config(cell_dir, raw=b"[robot\n")
    with pytest.raises(CalibrationError, match="cell.toml: field version is missing"):
        _config(cell_dir, CELL_FILE_EXAMPLE.replace('"calibration.toml"', '"cell.toml"'))


def test_mutated_cell_files_give_a_configuration_or_a_binpick_error(cell_dir):
    path = cell_dir / "cell.toml"
    outcomes, other = fuzz(path, path.read_bytes(), lambda: config_from_file(load_cell_file(path)), 7, cases=200)
    assert other == [], f"{len(other)} of 200 mutations raised outside BinpickError: {other[:3]}"
    assert outcomes["valid"] > 0 and outcomes["BinpickError"] > 0, outcomes
