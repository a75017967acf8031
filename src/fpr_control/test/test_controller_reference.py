"""The controller step reproduces the recorded reference outputs (``data/controller_reference.npz``, see
``controller_reference.py``) of every mode, n = 3 and 6, to floating-point rounding.

The fixture was recorded before the hot-path optimisation (issue "Speed and determinism"); any change of the
step's results beyond rounding (a different equation, branch or saturation) fails here. Tolerance: 1e-10
absolute + 1e-10 relative on every float output (N, rad, m/s, N·m), exact on modes, flags and warnings.
"""

from __future__ import annotations

import numpy as np
import pytest
from controller_reference import CASES, FIXTURE, SIZES, case_names, record, run_case

TOLERANCE = 1e-10
NAMES = case_names()


@pytest.fixture(scope="module")
def reference():
    with np.load(FIXTURE) as data:
        return {key: data[key] for key in data.files}


@pytest.mark.parametrize("index", range(len(NAMES)), ids=NAMES)
def test_step_matches_the_reference(reference, index):
    name = NAMES[index]
    fields = record(run_case(index), SIZES[index // len(CASES)])
    warnings = reference["warnings"]
    assert list(fields.pop("warning")) == [str(warnings[code]) for code in reference[f"{name}/warning"]]
    np.testing.assert_array_equal(fields.pop("flags"), reference[f"{name}/flags"])
    for key, value in fields.items():
        np.testing.assert_allclose(value, reference[f"{name}/{key}"], rtol=TOLERANCE, atol=TOLERANCE,
                                   equal_nan=True, err_msg=f"{name}: {key}")
