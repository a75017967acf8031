"""Bumpless rejoin (ROS-free): the law's reference after the UAV's setpoints were not flown for a while.

While a UAV's own PX4 does not fly its controller's setpoints (the swarm's emergency Hold, a restarted bridge in
its warm-up: fpr_px4_bridge's UavStatus says so), PX4's position controller levels the UAVs and the structure's
weight folds the legs: in a 2 s bridge restart they fold from 45° to 12° and the platform tilts 18°. When the
setpoints are flown again, a law that resumes at once tracks the operator's command from that configuration: a
step of 33° on every leg and 18° of attitude. The PID answered it with the legs at 50°/s and an overshoot to 72°,
faster than the onboard pose estimators can follow (their innovation gate refused every detection, the estimate
went stale and the swarm landed; fault matrix, bridge restarted, seed 0).

:class:`RejoinRamp` makes the transfer bumpless, as an operator would fly it: while the setpoints are not flown
after having been flown, the reference follows the measured configuration (leg angles, platform roll and pitch),
so nothing winds up; once they are flown again it moves from there to the operator's command at bounded rates
(``leg_rate``, ``attitude_rate``) and then hands over. The first take-off is not affected (nothing was flown
before it). Frames and units: the decentralized reference's F_Fp roll and pitch [rad], leg angles θ_i [rad]
(thesis (4.25)-(4.26)); rates in rad/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fpr_control.reference import TeleopReference

__all__ = ["RejoinConfig", "RejoinRamp"]


@dataclass(frozen=True)
class RejoinConfig:
    leg_rate: float = math.radians(8.0)        #: [rad/s] leg-angle reference rate while rejoining
    attitude_rate: float = math.radians(5.0)   #: [rad/s] roll / pitch reference rate while rejoining

    def __post_init__(self) -> None:
        for name in ("leg_rate", "attitude_rate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"rejoin {name} must be finite and > 0 rad/s, got {value}")


def _toward(value: float, target: float, step: float) -> float:
    return target if abs(target - value) <= step else value + math.copysign(step, target - value)


class RejoinRamp:
    """See the module doc. Call :meth:`apply` every control period."""

    def __init__(self, config: RejoinConfig | None = None) -> None:
        self.config = config or RejoinConfig()
        self.was_flown = False  #: the setpoints have been flown at least once (a take-off happened)
        self.suspended = False  #: not flown now, after having been flown
        self.ramping = False    #: flown again, the reference still on its way to the command
        self._roll = 0.0
        self._pitch = 0.0
        self._legs: np.ndarray | None = None

    @property
    def active(self) -> bool:
        """The reference is not the operator's command (suspended or ramping)."""
        return self.suspended or self.ramping

    def needs_measurement(self, flown: bool) -> bool:
        """:meth:`apply` needs the measured leg angles this period (suspended: the reference follows them)."""
        return self.was_flown and not flown

    def apply(self, flown: bool, dt: float, command: TeleopReference, roll: float, pitch: float,
              leg_angles: np.ndarray | None) -> TeleopReference:
        """The reference for this period: ``command`` (the operator's), or the bumpless one; ``roll``, ``pitch``,
        ``leg_angles``: the measured configuration [rad] (``leg_angles`` may be None unless
        :meth:`needs_measurement`); ``flown``: PX4 flies this controller's setpoints."""
        if flown:
            if self.suspended:
                self.suspended, self.ramping = False, True
            self.was_flown = True
        elif self.was_flown:
            self.suspended, self.ramping = True, False
        if self.suspended:
            if leg_angles is None:
                raise ValueError("RejoinRamp.apply: the measured leg angles are needed while suspended")
            self._roll, self._pitch = float(roll), float(pitch)
            self._legs = np.array(leg_angles, dtype=float)
            return replace(command.stopped(), roll=self._roll, pitch=self._pitch, leg_angles=self._legs.copy())
        if not self.ramping or self._legs is None:
            return command
        cfg = self.config
        legs_before, roll_before, pitch_before = self._legs.copy(), self._roll, self._pitch
        self._roll = _toward(self._roll, command.roll, cfg.attitude_rate * dt)
        self._pitch = _toward(self._pitch, command.pitch, cfg.attitude_rate * dt)
        self._legs = np.array([_toward(value, target, cfg.leg_rate * dt)
                               for value, target in zip(self._legs, command.leg_angles, strict=True)])
        if self._roll == command.roll and self._pitch == command.pitch and \
                np.array_equal(self._legs, np.asarray(command.leg_angles, dtype=float)):
            self.ramping = False
            return command
        rate = 1.0 / dt if dt > 0.0 else 0.0
        return replace(command, roll=self._roll, roll_rate=(self._roll - roll_before) * rate,
                       pitch=self._pitch, pitch_rate=(self._pitch - pitch_before) * rate,
                       leg_angles=self._legs.copy(), leg_rates=(self._legs - legs_before) * rate)
