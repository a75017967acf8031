"""Node parameters that mean what they say (issue 14): one declaration helper for every fpr node.

Every parameter is declared with a description, a **range** (numbers: rclpy's ``FloatingPointRange`` /
``IntegerRange``, so ``ros2 param describe`` shows it and rclpy refuses a value outside it, NaN and ±inf included;
number arrays: the same range element-wise and a fixed length, checked here since rclpy checks scalars only) or a set
of **choices** (strings), and is either

* **read-only** (the default): read once at start-up, so a ``ros2 param set`` is refused with rclpy's reason
  ("Trying to set a read-only parameter") instead of reporting a success that changes nothing; set it with
  ``--ros-args -p name:=value`` or a params file, where the same range and choices are enforced at declaration;
* or **dynamic**: an ``apply`` function takes the new value into the node's running state (the next control period
  uses it); a ``check`` function may refuse it first with a reason (e.g. a limit below its lower partner).

This module imports no rclpy: it needs only the node's ``declare_parameter`` / ``add_on_set_parameters_callback`` /
``add_post_set_parameters_callback`` methods and the rcl_interfaces messages, so it is the one implementation the
nodes of every fpr package share (fpr_model is their common dependency).
"""

from __future__ import annotations

import gc
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult

#: the largest finite bound: a range "unbounded above" still refuses +inf (and NaN, as every range does)
FLOAT_MAX = sys.float_info.max
INT_MAX = 2**63 - 1


@dataclass(frozen=True)
class Param:
    """One parameter: default, description and what values it takes.

    ``low``/``high``: the closed range of a number (or of every element of a number array). When both are None a
    number is taken to be non-negative when its default is (every element of it), else signed; the upper end is then
    the largest finite value, so only NaN/inf (and negatives) are refused. ``choices``: the allowed strings.
    ``dynamic``: settable at run time (the node applies it, see :class:`NodeParameters`)."""

    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    dynamic: bool = False
    #: NaN is a valid value (a "use the default" sentinel): the range is then checked here only, not by rclpy
    allow_nan: bool = False

    def bounds(self) -> tuple[float, float] | None:
        """The (low, high) range of a number or number array, None for strings and booleans."""
        values = self.default if isinstance(self.default, (list, tuple)) else [self.default]
        if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            return None
        low = self.low
        if low is None:
            low = 0.0 if all(v >= 0 or math.isnan(v) for v in values) else -FLOAT_MAX
        high = FLOAT_MAX if self.high is None else self.high
        return float(low), float(high)

    def is_integer(self) -> bool:
        values = self.default if isinstance(self.default, (list, tuple)) else [self.default]
        return bool(values) and all(isinstance(v, int) and not isinstance(v, bool) for v in values)

    def descriptor(self) -> ParameterDescriptor:
        """The ParameterDescriptor: description, read-only unless dynamic, range, the choices as constraints."""
        text = self.description + ("" if self.dynamic else " (read-only: set at start-up)")
        constraints = []
        descriptor = ParameterDescriptor(description=text, read_only=not self.dynamic)
        bounds = self.bounds()
        if bounds is not None:
            low, high = bounds
            if self.allow_nan:
                pass
            elif self.is_integer():
                descriptor.integer_range = [IntegerRange(
                    from_value=int(max(low, -INT_MAX)), to_value=int(min(high, INT_MAX)), step=1)]
            else:
                descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high, step=0.0)]
            constraints.append(f"in [{_show(low)}, {_show(high)}]"
                               + (" element-wise, fixed length" if isinstance(self.default, (list, tuple)) else ""))
        if self.choices:
            constraints.append("one of: " + " | ".join(self.choices))
        descriptor.additional_constraints = "; ".join(constraints)
        return descriptor


def _show(value: float) -> str:
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if value >= FLOAT_MAX:
        return "max"
    if value <= -FLOAT_MAX:
        return "-max"
    return f"{value:g}"


def value_problem(name: str, spec: Param, value: Any) -> str | None:
    """Why ``value`` is not a valid value of ``spec`` (None: it is). rclpy already checks the type and a scalar's
    range; this adds the choices, array lengths and array element ranges (and repeats the scalar range so that the
    check holds for callers other than rclpy)."""
    if spec.choices and value not in spec.choices:
        return f"{name} = {value!r} is not one of {' | '.join(spec.choices)}"
    bounds = spec.bounds()
    if bounds is None:
        return None
    low, high = bounds
    if isinstance(spec.default, (list, tuple)):
        values = list(value)
        if len(values) != len(spec.default):
            return f"{name} must keep its length {len(spec.default)}, got {len(values)} values"
    else:
        values = [value]
    for v in values:
        if spec.allow_nan and isinstance(v, float) and math.isnan(v):
            continue
        if not (isinstance(v, (int, float)) and not math.isnan(v) and low <= v <= high):
            return f"{name} = {value!r} out of range [{_show(low)}, {_show(high)}]"
    return None


@dataclass
class NodeParameters:
    """Declares a node's parameters from :class:`Param` specs and applies the dynamic ones when they are set.

    ``node``: an rclpy Node. :meth:`declare` returns the value (start-up overrides included, checked against the
    spec; an invalid override raises rclpy's InvalidParameterValueException with the reason). On a set at run time:
    rclpy refuses read-only parameters, wrong types and out-of-range scalars; this class refuses invalid choices,
    arrays and whatever a ``check`` function refuses (with its reason), and calls ``apply(value)`` for each dynamic
    parameter once the whole set is accepted (atomically: nothing is applied when one value is refused)."""

    node: Any
    specs: dict[str, Param] = field(default_factory=dict)
    _checks: dict[str, Callable[[Any], str | None]] = field(default_factory=dict)
    _apply: dict[str, Callable[[Any], None]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.node.add_on_set_parameters_callback(self._validate)
        self.node.add_post_set_parameters_callback(self._applied)

    def declare(self, name: str, spec: Param, apply: Callable[[Any], None] | None = None,
                check: Callable[[Any], str | None] | None = None) -> Any:
        if (apply is not None or check is not None) and not spec.dynamic:
            raise ValueError(f"{name}: apply/check given for a read-only parameter")
        self.specs[name] = spec
        if check is not None:
            self._checks[name] = check
        value = self.node.declare_parameter(name, spec.default, spec.descriptor()).value
        if spec.dynamic:
            self._apply[name] = apply if apply is not None else (lambda _value: None)
        return list(value) if isinstance(value, (list, tuple)) or type(value).__name__ == "array" else value

    def __call__(self, name: str, default: Any, description: str, **kwargs) -> Any:
        """``declare(name, Param(default, description, **kwargs))``: the short form the nodes use."""
        return self.declare(name, Param(default, description, **kwargs))

    def declare_all(self, specs: Mapping[str, Param | tuple]) -> dict[str, Any]:
        """Declare every spec of a table (a :class:`Param` or a ``(default, description)`` pair, read-only);
        returns name -> value."""
        return {name: self.declare(name, spec if isinstance(spec, Param) else Param(*spec))
                for name, spec in specs.items()}

    def dynamic_names(self) -> list[str]:
        return [name for name, spec in self.specs.items() if spec.dynamic]

    def _validate(self, parameters: Sequence[Any]) -> SetParametersResult:
        for parameter in parameters:
            spec = self.specs.get(parameter.name)
            if spec is None:
                continue
            problem = value_problem(parameter.name, spec, parameter.value)
            check = self._checks.get(parameter.name)
            if problem is None and check is not None and parameter.name in self._apply:
                problem = check(parameter.value)
            if problem is not None:
                self.node.get_logger().warning(f"parameter refused: {problem}")
                return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    def _applied(self, parameters: Sequence[Any]) -> None:
        for parameter in parameters:
            apply = self._apply.get(parameter.name)
            if apply is not None:
                value = parameter.value
                apply(list(value) if not isinstance(value, (str, bool, int, float)) else value)
                self.node.get_logger().info(f"parameter {parameter.name} = {value!r} applied")


def throttle(node, seconds: float) -> dict[str, Any]:
    """Keyword arguments of a throttled log call (``node.get_logger().warning(text, **throttle(node, 5.0))``) that
    rate-limits on the node's own clock — simulated time under ``use_sim_time`` — instead of rclpy's default, the
    system clock: a simulated flight then logs the same lines whatever the machine's load (a slow run is longer in
    wall time and would print more of them)."""
    return {"throttle_duration_sec": float(seconds), "throttle_time_source_type": node.get_clock()}


def node_seconds(node) -> float:
    """The node's clock now [s] (simulated time under ``use_sim_time``): the same number as
    ``node.get_clock().now().nanoseconds * 1e-9``, in about a third of its time. rclpy's ``Clock.now()`` reads the
    rcl time under the clock's handle guard and wraps it in a ``Time`` (argument checks, ~2 µs); this reads it the
    same way without the wrapper, through ``Clock.handle`` (which rclpy calls internal: a clock without it falls
    back to ``now()``). The nodes read their clock ~9,000 times per simulated second in the n = 6 graph (issue 15:
    ×1.02 on its real-time factor, docs/benchmarks.md)."""
    clock = node.get_clock()
    handle = getattr(clock, "handle", None)
    if handle is None:
        return clock.now().nanoseconds * 1e-9
    with handle:
        return handle.get_now().nanoseconds * 1e-9


def settle_heap() -> None:
    """Call once a process's nodes are built, before they spin: collect the start-up's garbage once, then move every
    object alive (the imports, the nodes: ~100,000-370,000 objects) out of the cyclic garbage collector's sight
    (``gc.freeze``). Its full collections then walk only what the process made since, instead of pausing a callback
    for 0.03-0.35 s (measured in the simulated graph, docs/benchmarks.md): on the robot such a pause is one or more
    lost 50 Hz control periods. Frozen objects are still freed by their reference counts as usual; only reference
    cycles made before the call are never collected (there were none to find in the measured runs)."""
    gc.collect()
    gc.freeze()
