"""Thrust regulation (C.1)-(C.2) and Table C.1: spec test X7."""

import math

import pytest
from fpr_model.battery import (
    TABLE_C1,
    ThrustCoefficients,
    max_thrust,
    normalized_thrust,
    thrust_coefficients,
    thrust_from_normalized,
)


def test_table_c1_values_and_x7_example():
    # Thesis Table C.1 and the derived example of spec §3.3 / X7 at 12.0 V.
    assert TABLE_C1[1] == ThrustCoefficients(a_f=8.02, b_f=-61.66)
    expected = {1: 34.58, 2: 34.63, 3: 35.52}
    for uav_id, f_max in expected.items():
        c = thrust_coefficients(uav_id)
        assert max_thrust(12.0, c.a_f, c.b_f) == pytest.approx(f_max, abs=1e-9)
        assert c.max_thrust(12.0) == pytest.approx(f_max, abs=1e-9)
    assert max_thrust(11.1, 8.02, -61.66) == pytest.approx(27.362, abs=1e-9)


def test_unknown_ids_get_row_mean_and_invalid_ids_raise():
    c = thrust_coefficients(4)
    assert c.a_f == pytest.approx((8.02 + 8.22 + 8.15) / 3)
    assert c.b_f == pytest.approx((-61.66 - 64.01 - 62.28) / 3)
    with pytest.raises(ValueError):
        thrust_coefficients(0)


def test_normalized_thrust_is_c1_and_clamped():
    f_max = max_thrust(12.0, 8.02, -61.66)
    assert normalized_thrust(10.0, 12.0, 8.02, -61.66) == pytest.approx(10.0 / f_max)
    # Lower voltage -> smaller f_max -> larger command for the same newtons (the point of (C.2)).
    assert normalized_thrust(10.0, 11.1, 8.02, -61.66) > normalized_thrust(10.0, 12.6, 8.02, -61.66)
    assert normalized_thrust(100.0, 12.0, 8.02, -61.66, 0.05) == 1.0
    assert normalized_thrust(0.0, 12.0, 8.02, -61.66, 0.05) == 0.05
    assert normalized_thrust(-3.0, 12.0, 8.02, -61.66, 0.1) == 0.1
    c = TABLE_C1[2]
    assert c.normalized_thrust(12.0, 12.0) == pytest.approx(12.0 / 34.63)


@pytest.mark.parametrize(
    "args",
    [
        (math.nan, 12.0, 8.02, -61.66, 0.0),
        (1.0, math.inf, 8.02, -61.66, 0.0),
        (1.0, 12.0, math.nan, -61.66, 0.0),
        (1.0, 12.0, 8.02, -61.66, 1.5),
        (1.0, 12.0, 8.02, -61.66, -0.1),
        (1.0, 7.0, 8.02, -61.66, 0.0),  # f_max < 0: voltage outside the model
        ("x", 12.0, 8.02, -61.66, 0.0),
    ],
)
def test_normalized_thrust_refuses_bad_input(args):
    with pytest.raises(ValueError):
        normalized_thrust(*args)


def test_thrust_from_normalized_inverts_c1():
    for u in (0.0, 0.25, 0.6, 1.0):
        f = thrust_from_normalized(u, 11.8, 8.15, -62.28)
        assert f == pytest.approx(u * (8.15 * 11.8 - 62.28))
        if 0.0 < u < 1.0:
            assert normalized_thrust(f, 11.8, 8.15, -62.28) == pytest.approx(u)
    assert thrust_from_normalized(1.5, 12.0, 8.02, -61.66) == pytest.approx(34.58)
    assert thrust_from_normalized(0.5, 5.0, 8.02, -61.66) == 0.0  # depleted battery produces nothing
