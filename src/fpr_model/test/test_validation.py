"""The input checks of fpr_model._validation: every non-finite value is refused whatever the array's size (the
small arrays take a Python path, the large ones numpy's)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fpr_model._validation import _SMALL, as_angles, as_array, as_trailing, as_vector


@pytest.mark.parametrize("size", [1, 4, _SMALL, _SMALL + 1, 200])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_every_helper_refuses_a_non_finite_value_at_any_position(size, bad):
    for position in {0, size // 2, size - 1}:
        values = np.linspace(-1e300, 1e300, size)  # finite, huge: a sum would overflow, the check must not
        assert as_vector("v", values).shape == (size,)
        values[position] = bad
        for helper, args in ((as_vector, ()), (as_angles, ()), (as_array, ((size,),))):
            with pytest.raises(ValueError, match="v: contains NaN or inf"):
                helper("v", values, *args)
        with pytest.raises(ValueError, match="v: contains NaN or inf"):
            as_trailing("v", values.reshape(1, size), (size,))


def test_shapes_and_scalars():
    assert as_trailing("q", np.zeros((5, 4)), (4,)).shape == (5, 4)
    assert as_angles("a", 0.5).shape == ()
    with pytest.raises(ValueError, match="contains NaN"):
        as_angles("a", math.nan)
    with pytest.raises(ValueError, match="expected shape"):
        as_array("x", [1.0, 2.0], (3,))
