"""Calibration files and scan folders that lie: each ends in the reader's own BinpickError subclass
naming the file, the field and the fix — never UnicodeDecodeError, RecursionError, JSONDecodeError,
KeyError or TypeError, and never a huge allocation from a header."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from _files import HEIGHT, WIDTH, small_calibration, small_scan
from binpick.calibration import CellCalibration
from binpick.errors import CalibrationError, ScanFormatError
from binpick.scan import load_scan


@pytest.fixture
def calibration_text() -> str:
    return small_calibration().to_toml()


def _load_calibration(tmp_path, data: bytes) -> CellCalibration:
    path = tmp_path / "calibration.toml"
    path.write_bytes(data)
    return CellCalibration.load(path)


@pytest.mark.parametrize(
    "edit,match",
    [
        (
            lambda t: t.encode() + b"\n# caf\xe9\n",
            r"byte \d+ of the calibration file is not UTF-8.*save the file as UTF-8",
        ),
        (lambda t: (t + "x = " + "[" * 20000 + "]" * 20000).encode(), "nested too deeply"),
        (lambda t: t.replace("width = 64", "width = " + "9" * 5000).encode(), "not valid TOML"),
        (lambda t: t.replace("width = 64", "width = 1000000").encode(), r"camera.width.*\[2, 65536\]"),
        (
            lambda t: t.replace("width = 64", "width = 60000").replace("height = 48", "height = 60000").encode(),
            "pixels",
        ),
        (lambda t: t.replace("height = 48", "height = 48.0").encode(), "camera.height.*whole number"),
        (lambda t: t.replace("height = 48", "height = true").encode(), "camera.height"),
        (lambda t: t.replace("dist = [", 'dist = ["a", ').encode(), "camera.dist.*nested lists of numbers"),
        (lambda t: t.replace("dist = [-0.04, 0.01, 0.0, 0.0, 0.0]", "dist = {k1 = 1}").encode(), "camera.dist"),
        (lambda t: t.replace("dist = [-0.04", "dist = [1979-05-27").encode(), "camera.dist"),
        (lambda t: t.replace("K = [[80.0", "K = [[1" + "0" * 400).encode(), "camera.K"),
        (lambda t: t.replace("K = [[80.0", "K = [[{a = 1}").encode(), "camera.K"),
        (lambda t: t.replace("version = 1", "version = true").encode(), "version is True.*version = 1"),
        (lambda t: t.replace("version = 1", 'version = "1"').encode(), "version"),
        (lambda t: t.replace("[camera]", "camera = 3\n[camera_]").encode(), r"\[camera\] table is missing"),
        (lambda t: t.replace('axis = "y"', "axis = [[[1]]]").encode(), "laser.axis"),
        (lambda t: t.replace("T_camera_laser = [[", "T_camera_laser = [[1e400, ").encode(), "T_camera_laser"),
        (lambda t: t.encode() * 2000, "larger than"),
    ],
)
def test_a_lying_calibration_file_names_the_file_the_field_and_the_fix(tmp_path, calibration_text, edit, match):
    with pytest.raises(CalibrationError, match=match) as info:
        _load_calibration(tmp_path, edit(calibration_text))
    assert str(info.value).startswith(str(tmp_path / "calibration.toml"))


def test_the_valid_calibration_file_still_loads(tmp_path, calibration_text):
    assert _load_calibration(tmp_path, calibration_text.encode()) == small_calibration()


def test_from_toml_refuses_what_is_not_text():
    with pytest.raises(CalibrationError, match="str"):
        CellCalibration.from_toml(b"version = 1")  # type: ignore[arg-type]
    with pytest.raises(CalibrationError, match="TOML document"):
        CellCalibration.from_dict([1, 2])  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- scan folders


@pytest.fixture
def scan_root(tmp_path):
    return small_scan(tmp_path / "scan")


def _edit_json(root, change):
    path = root / "scan.json"
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize(
    "raw,match",
    [
        (b'{"version": 1, "frames": [\xff]}', r"byte \d+ of the scan.json is not UTF-8"),
        (b'{"version": 1, "frames": ' + b"[" * 100000 + b"]" * 100000 + b"}", "nested too deeply"),
        (b'{"version": 1, "frames": [}', "cannot be read as JSON"),
        (b'{"version": 1, "frames": [' + b"9" * 5000 + b"]}", "cannot be read as JSON"),
        (b'{"version": true, "frames": []}', "version is True"),
        (b'{"version": 1.0, "frames": []}', "version"),
        (b"[1, 2]", "version"),
        (b'{"version": 1, "frames": {"image": "x"}}', "'frames' must be a non-empty list"),
        (b'{"version": 1, "frames": [3]}', r"frames\[0\] must be an object"),
    ],
)
def test_a_lying_scan_json_is_a_scan_format_error(scan_root, raw, match):
    (scan_root / "scan.json").write_bytes(raw)
    with pytest.raises(ScanFormatError, match=match) as info:
        load_scan(scan_root)
    assert str(scan_root / "scan.json") in str(info.value)


@pytest.mark.parametrize(
    "field,value,match",
    [
        ("angle", "0.1", r"frames\[1\].angle"),
        ("angle", {"deg": 5}, r"frames\[1\].angle"),
        ("angle", [[[[0.1]]]], r"frames\[1\].angle"),
        ("angle", 10**400, r"frames\[1\].angle"),
        ("angle", True, r"frames\[1\].angle"),
        ("T_base_flange", "eye", r"frames\[1\].T_base_flange"),
        ("T_base_flange", [[1, 2], [3]], r"frames\[1\].T_base_flange"),
        ("T_base_flange", {"a": 1}, r"frames\[1\].T_base_flange"),
        ("image", 5, r"frames\[1\].image must be a path"),
        ("image", ["frames/001.png"], r"frames\[1\].image must be a path"),
        ("image", "../../etc/passwd", "inside the scan folder"),
        ("image", "/etc/passwd", "inside the scan folder"),
        ("image", "frames/\x00.png", r"frames\[1\].image must be a path"),
        ("image", "frames/999.png", r"lists 2 frames but the image of 1 of them is not in the folder"),
        ("image", "a" * 300 + ".png", "not in the folder"),  # a name the OS refuses as too long
        ("image", "frames/\ud800.png", "not in the folder"),  # not encodable as a file name
    ],
)
def test_a_lying_frame_entry_names_the_frame_and_the_field(scan_root, field, value, match):
    _edit_json(scan_root, lambda doc: doc["frames"][1].__setitem__(field, value))
    with pytest.raises(ScanFormatError, match=match):
        load_scan(scan_root)


def test_a_missing_field_is_named(scan_root):
    _edit_json(scan_root, lambda doc: doc["frames"][0].pop("angle"))
    with pytest.raises(ScanFormatError, match=r"frames\[0\].angle is missing"):
        load_scan(scan_root)


def test_a_lying_ground_truth_is_a_scan_format_error(scan_root):
    (scan_root / "ground_truth.json").write_bytes(b"\x80{")
    with pytest.raises(ScanFormatError, match="ground_truth.json.*UTF-8"):
        load_scan(scan_root)
    (scan_root / "ground_truth.json").write_text("[1, 2]")
    with pytest.raises(ScanFormatError, match="ground_truth.json: must hold a JSON object"):
        load_scan(scan_root)
    (scan_root / "ground_truth.json").write_text('{"parts": [1, 2]}')
    assert load_scan(scan_root).ground_truth == {"parts": [1, 2]}


def test_an_absurd_camera_in_a_scan_is_refused(scan_root):
    path = scan_root / "calibration.toml"
    path.write_text(path.read_text().replace("width = 64", "width = 200000"))
    with pytest.raises(CalibrationError, match=r"calibration.toml: camera.width.*65536"):
        load_scan(scan_root)


def _patch_png_size(path, width, height):
    data = bytearray(path.read_bytes())
    data[16:20] = width.to_bytes(4, "big")
    data[20:24] = height.to_bytes(4, "big")
    path.write_bytes(bytes(data))


def test_a_png_header_declaring_a_huge_image_is_refused_before_decoding(scan_root):
    scan = load_scan(scan_root)
    _patch_png_size(scan.frames[0].image_path, 30000, 30000)  # cv2 would allocate 2.7 GB for it
    with pytest.raises(ScanFormatError, match="PNG header.*pixels"):
        scan.frames[0].image()
    _patch_png_size(scan.frames[1].image_path, WIDTH + 1, HEIGHT)
    with pytest.raises(ScanFormatError, match=f"PNG header declares {WIDTH + 1}×{HEIGHT}.*{WIDTH}×{HEIGHT}"):
        scan.frames[1].image()


def test_frames_of_another_camera_or_garbage_are_refused(scan_root):
    scan = load_scan(scan_root)
    cv2.imwrite(str(scan.frames[0].image_path.with_suffix(".jpg")), np.zeros((HEIGHT, WIDTH * 2, 3), np.uint8))
    _edit_json(scan_root, lambda doc: doc["frames"][0].__setitem__("image", "frames/000.jpg"))
    with pytest.raises(ScanFormatError, match=f"the frame is {WIDTH * 2}×{HEIGHT}"):
        load_scan(scan_root).frames[0].image()
    scan.frames[1].image_path.write_bytes(b"not an image at all")
    with pytest.raises(ScanFormatError, match="corrupt or not an image"):
        scan.frames[1].image()


def test_the_valid_scan_folder_still_loads(scan_root):
    scan = load_scan(scan_root)
    assert len(scan) == 2 and scan.calibration == small_calibration()
    assert [img.shape for img in scan.images()] == [(HEIGHT, WIDTH, 3)] * 2


def test_a_png_chunk_declaring_more_bytes_than_the_file_holds_is_refused_before_decoding(scan_root):
    frame = load_scan(scan_root).frames[0]
    data = bytearray(frame.image_path.read_bytes())
    idat = data.index(b"IDAT") - 4
    data[idat : idat + 4] = (0x52000000).to_bytes(4, "big")  # 1.3 GB of image data, of which a few bytes exist
    frame.image_path.write_bytes(bytes(data))
    with pytest.raises(ScanFormatError, match=r"chunk b'IDAT' at byte \d+ declares 1375731712 bytes but \d+ follow"):
        frame.image()
    frame.image_path.write_bytes(bytes(data[: idat - 10]))  # cut inside IHDR's CRC
    with pytest.raises(ScanFormatError, match="truncated"):
        frame.image()
