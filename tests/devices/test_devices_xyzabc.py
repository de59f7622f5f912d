"""The (X, Y, Z, A, B, C) convention: R = Rz(C)·Ry(B)·Rx(A), fixed axes, checked against hand-worked matrices."""

import math

import numpy as np
import pytest

from binpick.devices.xyzabc import (
    transform_from_xyzabc,
    xyzabc_from_transform,
    xyzabc_from_wire,
    xyzabc_to_wire,
)
from binpick.errors import InvalidInputError, ShapeError

D = math.radians


def test_tool_pointing_down_is_a180_b0_c180():
    # MELFA's usual "flange down" pose: Rz(180)·Rx(180) = diag(-1, 1, -1)
    T = transform_from_xyzabc([300, 10, 200, D(180), 0, D(180)])
    np.testing.assert_allclose(T[:3, :3], np.diag([-1.0, 1.0, -1.0]), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [300, 10, 200])


def test_single_axis_rotations_match_hand_worked_matrices():
    np.testing.assert_allclose(
        transform_from_xyzabc([0, 0, 0, D(90), 0, 0])[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12
    )
    np.testing.assert_allclose(
        transform_from_xyzabc([0, 0, 0, 0, D(90), 0])[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12
    )
    np.testing.assert_allclose(
        transform_from_xyzabc([0, 0, 0, 0, 0, D(90)])[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12
    )


def test_order_is_x_first_then_y_then_z_about_fixed_axes():
    # A = 90° then C = 90°: Rz(90)·Rx(90) maps x→y, y→z, z→x (worked by hand)
    R = transform_from_xyzabc([0, 0, 0, D(90), 0, D(90)])[:3, :3]
    np.testing.assert_allclose(R, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-12)
    # the other order, Rx(90)·Rz(90), would be [[0,-1,0],[0,0,-1],[1,0,0]]
    assert not np.allclose(R, [[0, -1, 0], [0, 0, -1], [1, 0, 0]])


def test_decomposition_of_known_matrix():
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    T[:3, 3] = [1, 2, 3]
    np.testing.assert_allclose(xyzabc_from_transform(T), [1, 2, 3, D(90), 0, D(90)], atol=1e-12)


def test_round_trip_random_angles():
    rng = np.random.default_rng(7)
    for _ in range(200):
        v = np.concatenate(
            [
                rng.uniform(-500, 500, 3),
                rng.uniform(-math.pi, math.pi, 1),
                rng.uniform(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3, 1),
                rng.uniform(-math.pi, math.pi, 1),
            ]
        )
        back = xyzabc_from_transform(transform_from_xyzabc(v))
        np.testing.assert_allclose(back, v, atol=1e-9)


@pytest.mark.parametrize("b", [D(90), D(-90)])
def test_gimbal_lock_reports_a_zero_and_keeps_the_rotation(b):
    T = transform_from_xyzabc([0, 0, 0, D(30), b, D(50)])
    v = xyzabc_from_transform(T)
    assert v[3] == 0.0
    assert v[4] == pytest.approx(b)
    np.testing.assert_allclose(transform_from_xyzabc(v), T, atol=1e-9)


def test_wire_units_are_degrees():
    np.testing.assert_allclose(xyzabc_to_wire([1, 2, 3, math.pi, 0, -math.pi / 2]), [1, 2, 3, 180, 0, -90])
    np.testing.assert_allclose(xyzabc_from_wire([1, 2, 3, 180, 0, -90]), [1, 2, 3, math.pi, 0, -math.pi / 2])


def test_bad_inputs_are_named():
    with pytest.raises(ShapeError, match="six numbers"):
        transform_from_xyzabc([1, 2, 3])
    with pytest.raises(InvalidInputError, match="NaN"):
        transform_from_xyzabc([1, 2, 3, float("nan"), 0, 0])
    with pytest.raises(InvalidInputError, match="not a rotation"):
        xyzabc_from_transform(np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ShapeError):
        xyzabc_from_transform(np.eye(3))
