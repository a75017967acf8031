"""Oracle test of the optimized plant: it must reproduce the frozen trajectories of the reference implementation.

data/plant_oracle.npz was recorded with the numpy-vectorized plant of commit 99797a6 (see plant_oracle_cases.py);
the optimized scalar plant runs the same cases and must agree to ~1e-9 (rounding differences only, amplified by
the closed loops over 1.5-2 s; the specific forces are a finite difference over dt, hence the looser bound).
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location("plant_oracle_cases", Path(__file__).with_name("plant_oracle_cases.py"))
cases = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault("plant_oracle_cases", cases)  # dataclasses need the module registered
_SPEC.loader.exec_module(cases)

#: absolute tolerance per recorded quantity, in units of max(1, max |reference|) of that quantity
TOLERANCE = {"specific_forces": 1e-9}
DEFAULT_TOLERANCE = 1e-10


@pytest.fixture(scope="module")
def reference():
    return np.load(cases.DATA)


@pytest.mark.parametrize("case", cases.CASES, ids=lambda c: c.name)
def test_plant_matches_frozen_reference(case, reference):
    result = cases.run_case(case)
    assert len(result["time"]) == len(reference[f"{case.name}/time"])
    for key, value in result.items():
        expected = reference[f"{case.name}/{key}"]
        assert value.shape == expected.shape, key
        assert np.array_equal(np.isnan(value), np.isnan(expected)), f"{case.name}/{key}: contact pattern differs"
        scale = max(1.0, float(np.nanmax(np.abs(expected))) if np.isfinite(expected).any() else 1.0)
        error = float(np.nanmax(np.abs(value - expected))) if np.isfinite(expected).any() else 0.0
        assert error <= TOLERANCE.get(key, DEFAULT_TOLERANCE) * scale, f"{case.name}/{key}: error {error:.2e}"


def test_reference_is_not_trivial(reference):
    """The cases exercise what they claim: contact with the ground and the board, flight, payload, wind."""
    assert reference["board_push/contact_force"].max() > 1.0
    takeoff = reference["ground_takeoff/anchors"]
    assert np.isfinite(takeoff[1, :3]).all() and np.isnan(takeoff[-1]).all()  # on the ground, then airborne
    assert np.abs(reference["wind_wrench/external_wrench"]).max() > 0.1
    x = reference["payload_drop/x"]
    assert np.ptp(x[:, 2]) > 0.05
