"""fpr_model.node_parameters: the ranges, choices and array checks every fpr node's parameters get (issue 14)."""

from __future__ import annotations

import math

import pytest
from fpr_model.node_parameters import FLOAT_MAX, Param, value_problem


def test_default_bounds_follow_the_default_sign_and_refuse_nan_and_inf():
    assert Param(0.5, "x").bounds() == (0.0, FLOAT_MAX)
    assert Param([1.0, -2.0], "x").bounds() == (-FLOAT_MAX, FLOAT_MAX)
    assert Param(3, "x", low=1, high=64).bounds() == (1.0, 64.0)
    assert Param("a", "x").bounds() is None and Param(True, "x").bounds() is None
    for bad in (math.nan, math.inf, -1.0):
        assert value_problem("x", Param(0.5, "x"), bad) is not None
    assert value_problem("x", Param(0.5, "x"), 1e300) is None
    assert value_problem("x", Param(math.inf, "x", high=math.inf), math.inf) is None  # "never" sentinel


def test_choices_arrays_and_nan_sentinel():
    spec = Param("ekf", "filter", choices=("ekf", "mekf"))
    assert value_problem("filter", spec, "mekf") is None
    assert "one of ekf | mekf" in value_problem("filter", spec, "ukf")
    gains = Param([9.0, 6.0, 0.5], "legs")
    assert "keep its length 3" in value_problem("legs", gains, [1.0, 2.0])
    assert "out of range" in value_problem("legs", gains, [1.0, math.nan, 0.0])
    assert value_problem("legs", gains, [1.0, 2.0, 0.0]) is None
    sentinel = Param(math.nan, "a_f", low=0.0, high=100.0, allow_nan=True)
    assert value_problem("a_f", sentinel, math.nan) is None and value_problem("a_f", sentinel, 200.0) is not None
    assert not sentinel.descriptor().floating_point_range  # rclpy would refuse the NaN default


def test_descriptor_carries_range_read_only_and_constraints():
    descriptor = Param(50.0, "[Hz] rate", low=1.0, high=1000.0).descriptor()
    assert descriptor.read_only and "read-only" in descriptor.description
    (r,) = descriptor.floating_point_range
    assert (r.from_value, r.to_value, r.step) == (1.0, 1000.0, 0.0)
    assert "in [1, 1000]" in descriptor.additional_constraints
    integer = Param(3, "n", low=3, high=64, dynamic=True).descriptor()
    assert not integer.read_only and integer.integer_range[0].to_value == 64
    assert "one of: a | b" in Param("a", "c", choices=("a", "b")).descriptor().additional_constraints


def test_apply_only_for_dynamic_parameters():
    from fpr_model.node_parameters import NodeParameters

    class FakeNode:
        def add_on_set_parameters_callback(self, callback):
            self.validate = callback

        def add_post_set_parameters_callback(self, callback):
            self.applied = callback

        def declare_parameter(self, name, default, descriptor):
            return type("P", (), {"value": default})()

    table = NodeParameters(FakeNode())
    with pytest.raises(ValueError, match="read-only"):
        table.declare("rate", Param(50.0, "rate"), apply=print)
    assert table.declare("gain", Param([1.0, 2.0], "gain", dynamic=True), apply=lambda v: None) == [1.0, 2.0]
    assert table.dynamic_names() == ["gain"]


def test_settle_heap_freezes_what_is_alive_and_frees_nothing_it_should_not():
    import gc
    import weakref

    from fpr_model.node_parameters import settle_heap

    class Holder:
        pass

    kept, dropped = Holder(), Holder()
    dropped.self_reference = dropped  # a reference cycle made before the call: garbage, collected by it
    dropped_ref = weakref.ref(dropped)
    del dropped
    try:
        settle_heap()
        assert dropped_ref() is None
        assert gc.get_freeze_count() > 1000  # the imports, the test session: out of the collector's sight
        made_after = Holder()
        made_after.self_reference = made_after
        after_ref = weakref.ref(made_after)
        del made_after
        gc.collect()
        assert after_ref() is None  # what is made afterwards is collected as usual
        assert isinstance(kept, Holder)
    finally:
        gc.unfreeze()
