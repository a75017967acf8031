"""Quadrotor thrust regulation against the battery voltage: thesis Appendix C, (C.1)-(C.2), Table C.1.

PX4 takes only a normalized collective thrust ``u_f`` in [0, 1]. The companion computer divides the desired
thrust magnitude by the maximum thrust the vehicle can produce at the present battery voltage:

- (C.1) ``u_f = f_t^d / f_max``                      (``f_t^d`` [N] along body +z, ``u_f`` dimensionless)
- (C.2) ``f_max = a_f · V + b_f``                     (``V`` [V], ``a_f`` [N/V], ``b_f`` [N])

Table C.1 gives ``(a_f, b_f)`` for the three prototype quadrotors; e.g. quadrotor 1 at 12.0 V gives
``f_max = 34.58 N`` (spec test X7). ``u_f`` is clamped to ``[thrust_min, 1]`` (spec §3.3: u_f in [0, 1];
``thrust_min`` > 0 keeps the motors spinning in flight).

ROS-free; used by ``fpr_px4_bridge`` (newtons -> normalized) and the simulator's PX4 emulator (the inverse
:func:`thrust_from_normalized`, with the plant's own true coefficients).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "TABLE_C1",
    "ThrustCoefficients",
    "max_thrust",
    "normalized_thrust",
    "thrust_coefficients",
    "thrust_from_normalized",
]


def _finite(name: str, value: float) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected a real number ({error})") from None
    if not math.isfinite(number):
        raise ValueError(f"{name}: must be finite, got {number}")
    return number


@dataclass(frozen=True)
class ThrustCoefficients:
    """Coefficients of the linear maximum-thrust model (C.2) of one quadrotor: ``f_max = a_f·V + b_f``."""

    a_f: float  #: slope [N/V]
    b_f: float  #: offset [N]

    def max_thrust(self, voltage: float) -> float:
        """``f_max`` [N] at battery voltage ``voltage`` [V], (C.2)."""
        return max_thrust(voltage, self.a_f, self.b_f)

    def normalized_thrust(self, thrust_newton: float, voltage: float, thrust_min: float = 0.0) -> float:
        """Normalized thrust ``u_f`` in ``[thrust_min, 1]``, (C.1)-(C.2)."""
        return normalized_thrust(thrust_newton, voltage, self.a_f, self.b_f, thrust_min)

    def thrust_from_normalized(self, normalized: float, voltage: float) -> float:
        """Thrust [N] produced by the normalized command ``normalized`` at ``voltage`` [V], (C.1) inverted."""
        return thrust_from_normalized(normalized, voltage, self.a_f, self.b_f)


#: Table C.1 (thesis Appendix C): linear fit of the maximum thrust vs battery voltage, per quadrotor id 1..3.
TABLE_C1: dict[int, ThrustCoefficients] = {
    1: ThrustCoefficients(a_f=8.02, b_f=-61.66),
    2: ThrustCoefficients(a_f=8.22, b_f=-64.01),
    3: ThrustCoefficients(a_f=8.15, b_f=-62.28),
}


def thrust_coefficients(uav_id: int) -> ThrustCoefficients:
    """Default coefficients for UAV ``uav_id`` (1-based): Table C.1 for 1..3, the row mean for other ids.

    The thesis identified only three quadrotors; vehicles 4.. of an n > 3 robot get the mean of the three
    rows until they are identified (configure ``a_f``/``b_f`` per vehicle when they are).
    """
    if uav_id in TABLE_C1:
        return TABLE_C1[uav_id]
    if uav_id < 1:
        raise ValueError(f"uav_id must be >= 1 (1-based), got {uav_id}")
    rows = list(TABLE_C1.values())
    return ThrustCoefficients(a_f=sum(r.a_f for r in rows) / len(rows), b_f=sum(r.b_f for r in rows) / len(rows))


def max_thrust(voltage: float, a_f: float, b_f: float) -> float:
    """Maximum thrust ``f_max = a_f·V + b_f`` [N] (C.2); ``voltage`` [V], ``a_f`` [N/V], ``b_f`` [N].

    Raises ValueError on non-finite inputs. The result may be <= 0 for a voltage below the fit's range;
    :func:`normalized_thrust` refuses that case.
    """
    return _finite("a_f", a_f) * _finite("voltage", voltage) + _finite("b_f", b_f)


def normalized_thrust(thrust_newton: float, voltage: float, a_f: float, b_f: float, thrust_min: float = 0.0) -> float:
    """PX4 normalized collective thrust ``u_f = f_t^d / f_max`` (C.1), ``f_max`` from (C.2), clamped.

    ``thrust_newton`` [N] (desired magnitude along body +z), ``voltage`` [V], ``a_f`` [N/V], ``b_f`` [N],
    ``thrust_min`` in [0, 1]. Returns ``u_f`` in ``[thrust_min, 1]``. Raises ValueError on non-finite inputs,
    ``thrust_min`` outside [0, 1], or ``f_max <= 0`` (voltage outside the model's range): never returns NaN.
    """
    thrust = _finite("thrust_newton", thrust_newton)
    low = _finite("thrust_min", thrust_min)
    if not 0.0 <= low <= 1.0:
        raise ValueError(f"thrust_min must be in [0, 1], got {low}")
    f_max = max_thrust(voltage, a_f, b_f)
    if f_max <= 0.0:
        raise ValueError(f"f_max = a_f*V + b_f = {f_max:.3f} N <= 0 at V = {voltage} V: voltage outside the model")
    return min(1.0, max(low, thrust / f_max))


def thrust_from_normalized(normalized: float, voltage: float, a_f: float, b_f: float) -> float:
    """Thrust [N] for a normalized command: ``f = clip(u_f, 0, 1) · max(f_max, 0)`` ((C.1) inverted, (C.2)).

    This is what the vehicle produces (the simulator's view): a depleted battery (``f_max <= 0``) gives 0 N.
    """
    u = min(1.0, max(0.0, _finite("normalized", normalized)))
    return u * max(0.0, max_thrust(voltage, a_f, b_f))
