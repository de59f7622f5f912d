"""The protocol's codec (binpick.server.protocol) and the brands' pose conventions
(binpick.server.conventions) against the formulas of docs/protocol.md, as the robot program of
examples/robots/twin_program.py writes them independently (elementary rotations, Rodrigues)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from binpick.errors import InvalidInputError
from binpick.server import CONVENTIONS, Code, RequestError, Verb, convention, encode_reply, parse_request
from binpick.server.protocol import MAX_LINE_BYTES, reply_size
from binpick.transforms import quaternion_matrix, rotation_angle_deg

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples" / "robots"))
from twin_program import pose_matrix, pose_numbers  # noqa: E402  (the doc's formulas, written apart)


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = quaternion_matrix(rng.normal(size=4))
    T[:3, 3] = rng.uniform(-800, 800, 3)
    return T


def _turned(axis: str, deg: float) -> np.ndarray:
    T = np.eye(4)
    i = "xyz".index(axis)
    v = np.zeros(3)
    v[i] = 1.0
    from binpick.transforms import rotation_about

    T[:3, :3] = rotation_about(v, math.radians(deg))
    return T


@pytest.mark.parametrize("brand", sorted(CONVENTIONS))
def test_every_brand_writes_what_the_doc_formula_reads_and_reads_what_it_writes(brand):
    rng = np.random.default_rng(7)
    c = convention(brand)
    poses = [_random_pose(rng) for _ in range(300)]
    poses += [_turned("x", 180.0), _turned("y", 180.0), _turned("z", 180.0), _turned("y", 90.0), np.eye(4)]
    for T in poses:
        numbers = c.to_robot(T)
        assert len(numbers) == c.size
        back = pose_matrix(brand, list(numbers))
        assert np.abs(back[:3, 3] - T[:3, 3]).max() < 1e-9
        assert rotation_angle_deg(back[:3, :3].T @ T[:3, :3]) < 1e-6
        read = c.from_robot(pose_numbers(brand, T))
        assert np.abs(read[:3, 3] - T[:3, 3]).max() < 1e-9
        assert rotation_angle_deg(read[:3, :3].T @ T[:3, :3]) < 1e-5


def test_known_values_of_each_convention():
    down = _turned("x", 180.0)  # a tool pointing straight down
    down[:3, 3] = (400.0, -20.0, 620.0)
    ur = convention("ur").to_robot(down)
    assert ur[:3] == pytest.approx([0.4, -0.02, 0.62]) and ur[3:] == pytest.approx([math.pi, 0, 0])
    abb = convention("abb").to_robot(down)
    assert abb == pytest.approx([400.0, -20.0, 620.0, 0.0, 1.0, 0.0, 0.0])
    yaw = _turned("z", 90.0)
    assert convention("kuka").to_robot(yaw)[3:] == pytest.approx([90.0, 0.0, 0.0])  # A about z
    assert convention("fanuc").to_robot(yaw)[3:] == pytest.approx([0.0, 0.0, 90.0])  # R about z
    assert convention("melfa").to_robot(yaw)[3:] == pytest.approx([0.0, 0.0, 90.0])  # C about z
    roll = _turned("x", 30.0)
    assert convention("kuka").to_robot(roll)[3:] == pytest.approx([0.0, 0.0, 30.0])  # C about x
    assert convention("yaskawa").to_robot(roll)[3:] == pytest.approx([30.0, 0.0, 0.0])  # Rx
    assert convention("abb").to_robot(_turned("z", 90.0))[3:] == pytest.approx([math.sqrt(0.5), 0, 0, math.sqrt(0.5)])


@pytest.mark.parametrize(
    "brand, values, says",
    [
        ("ur", [0.4, 0, 0.6, 0, 0], "expected 6 numbers"),
        ("ur", [400, 0, 600, 0, 0, 0], "check the unit"),  # millimetres sent as metres
        ("abb", [400, 0, 600, 1, 1, 0, 0], "unit quaternion"),
        ("kuka", [400, 0, 600, float("nan"), 0, 0], "A is not a finite number"),
        ("fanuc", [400, 0, 600, 0, 1e4, 0], "is not an angle"),
    ],
)
def test_a_pose_no_robot_could_mean_is_refused_naming_the_field(brand, values, says):
    with pytest.raises(InvalidInputError, match=says):
        convention(brand).from_robot(values)


def test_an_unknown_brand_lists_the_known_ones():
    with pytest.raises(InvalidInputError, match="ur, abb, kuka, fanuc, yaskawa, melfa"):
        convention("staubli")


@pytest.mark.parametrize(
    "line, verb, numbers",
    [
        (b"HELLO 1", Verb.HELLO, (1.0,)),
        (b"hello,1", Verb.HELLO, (1.0,)),
        (b"SCAN p[0.4, 0.0, 0.62, 3.1416, 0, 0]", Verb.SCAN, (0.4, 0.0, 0.62, 3.1416, 0.0, 0.0)),
        (b"SCAN [400,0,620],[0,1,0]", Verb.SCAN, (400.0, 0.0, 620.0, 0.0, 1.0, 0.0)),
        (b"SCAN,1e2,-2,.5,+3,4.,5E-1", Verb.SCAN, (100.0, -2.0, 0.5, 3.0, 4.0, 0.5)),
        (b"  NEXT  ", Verb.NEXT, ()),
        (b"RESULT 3 -1", Verb.RESULT, (3.0, -1.0)),
    ],
)
def test_requests_as_robot_languages_print_them(line, verb, numbers):
    r = parse_request(line, 6)
    assert r.verb is verb and r.numbers == pytest.approx(numbers)


@pytest.mark.parametrize(
    "line, code",
    [
        (b"PICK", Code.UNKNOWN_VERB),
        (b"HELLO", Code.FIELD_COUNT),
        (b"SCAN 1 2 3", Code.FIELD_COUNT),
        (b"NEXT 1", Code.FIELD_COUNT),
        (b"RESULT 1 x", Code.MALFORMED),
        (b"RESULT 1 nan", Code.MALFORMED),
        (b"RESULT 1 1e999", Code.BAD_VALUE),
        (b"HELLO 1\x00", Code.MALFORMED),
        ("HELLO \u00e9".encode(), Code.MALFORMED),
        (b"HELLO 1" + b" " * MAX_LINE_BYTES, Code.TOO_LONG),
    ],
)
def test_a_malformed_request_gets_the_code_that_says_why(line, code):
    with pytest.raises(RequestError) as info:
        parse_request(line, 6)
    assert info.value.code is code


def test_replies_have_a_fixed_count_per_verb_and_a_text_without_parentheses():
    assert encode_reply(Code.OK, [1, 2, 6], size=4) == b"(0,1,2,6)\r\n"
    assert encode_reply(Code.OK, [0.5, -0.0000001, 12.25], size=4) == b"(0,0.5,-0.0,12.25)\r\n"
    line = encode_reply(Code.OUT_OF_ORDER, size=reply_size(Verb.NEXT, 6), text="no scan (send SCAN)\n\x01")
    head, text = line.decode().rstrip("\r\n").split(" ", 1)
    assert head == "(" + ",".join(["5"] + ["0"] * 29) + ")"
    assert "(" not in text and ")" not in text and "\n" not in text and text.startswith("no scan [send SCAN]")
    assert reply_size(Verb.NEXT, 7) == 34 and reply_size(None, 6) == 1
    with pytest.raises(ValueError):
        encode_reply(Code.OK, [1, 2, 3, 4], size=4)
