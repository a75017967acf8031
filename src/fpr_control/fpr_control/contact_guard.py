"""Contact guard: a contact-force demand that finds no contact is faded out instead of flying the robot away.

The impedance laws track a desired interaction force f^d_c along the platform normal, τ^d_e = [R_p (0, 0, f^d_c);
0; 0] (3.43)-(3.44). In contact the board returns it; without contact nothing does, and the law turns it into motion
along the normal: with the decentralized impedance (no position, Table 4.5) a steady velocity f^d_c / B^d_p (1 m/s
for 10 N), with the Ch. 3 impedance an offset f^d_c / K^d_p (0.4 m for 10 N, Table 3.1). A platform that slides
off the edge of the board, or an operator who presses the force trigger in free air, would fly the robot until a
person reacts. The thesis has no such guard (its operator released the trigger); this module is the project's.

Rule, per control step, while the law tracks the force (mode ``impedance``) and the robot flies:

- the demand is *engaged* above ``engage_force``; below it the guard passes it through and re-arms;
- the contact is *met* while the estimated contact force −(R_pᵀ f̂_p,e)_z (3.45) is at least ``min_fraction`` of
  the demand; while it is not, the guard integrates the platform's travel along its normal (positive part of
  v_P · z_p, [m]) and the time;
- more than ``max_free_travel`` metres of travel or ``max_unmet_time`` seconds without contact: contact *lost*.
  The applied demand then ramps to 0 at ``fade_rate`` [N/s] and stays 0 until the operator releases the trigger
  (demand below ``engage_force``): a new push needs a new press.

Being met resets both integrals, so a push that briefly slips keeps going. The guard only ever lowers the demand
(0 ≤ applied ≤ demanded). Approach the board with the velocity sticks, then push: an approach by the force demand
alone is stopped after ``max_free_travel``. Units: N, m, s. No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Guard states (= fpr_msgs/ControllerStatus CONTACT_GUARD_*)
IDLE, PUSHING, LOST = 0, 1, 2
STATE_NAMES = {IDLE: "idle", PUSHING: "pushing", LOST: "lost"}


@dataclass(frozen=True)
class ContactGuardConfig:
    enabled: bool = True
    engage_force: float = 0.5  #: [N] demands above are guarded; at or below, the guard re-arms
    min_fraction: float = 0.3  #: contact met while the estimated force >= this x the demand
    max_free_travel: float = 0.3  #: [m] travel along the platform normal without contact -> lost
    max_unmet_time: float = 3.0  #: [s] time without contact -> lost
    fade_rate: float = 20.0  #: [N/s] ramp of the applied demand to 0 once lost

    def __post_init__(self) -> None:
        values = (self.engage_force, self.min_fraction, self.max_free_travel, self.max_unmet_time, self.fade_rate)
        if not all(math.isfinite(v) for v in values):
            raise ValueError("contact guard: every value must be finite")
        if not (self.engage_force >= 0.0 and 0.0 < self.min_fraction <= 1.0 and self.max_free_travel > 0.0
                and self.max_unmet_time > 0.0 and self.fade_rate > 0.0):
            raise ValueError("contact guard: engage_force >= 0, min_fraction in (0, 1], max_free_travel, "
                             "max_unmet_time and fade_rate > 0")


@dataclass(frozen=True)
class GuardStep:
    applied_force: float  #: [N] f^d_c the law tracks in this step (0 <= applied <= demanded)
    state: int  #: IDLE, PUSHING or LOST
    event: str | None = None  #: one line when the state changes to LOST or back to IDLE from LOST


class ContactGuard:
    """The rule of the module doc; call :meth:`step` once per control period."""

    def __init__(self, config: ContactGuardConfig | None = None) -> None:
        self.config = config or ContactGuardConfig()
        self.state = IDLE
        self.applied = 0.0
        self.unmet_time = 0.0
        self.travel = 0.0

    def reset(self) -> None:
        self.state, self.applied, self.unmet_time, self.travel = IDLE, 0.0, 0.0, 0.0

    def step(self, demanded: float, estimated: float, normal_speed: float, dt: float,
             tracking: bool = True) -> GuardStep:
        """``demanded`` f^d_c [N] from the operator, ``estimated`` −(R_pᵀ f̂_p,e)_z [N] (3.45), ``normal_speed``
        v_P · z_p [m/s] (the platform's velocity along its own normal), ``dt`` [s]; ``tracking``: the active law
        tracks the force and the robot flies (else the guard passes the demand through and re-arms)."""
        cfg = self.config
        demanded = float(demanded) if math.isfinite(demanded) else 0.0
        if not cfg.enabled or not tracking:
            was_lost = self.state == LOST
            self.reset()
            self.applied = demanded
            return GuardStep(demanded, IDLE, "contact guard re-armed (not pushing)" if was_lost else None)
        if demanded <= cfg.engage_force:
            was_lost = self.state == LOST
            self.reset()
            self.applied = max(demanded, 0.0)
            event = "force trigger released: contact guard re-armed" if was_lost else None
            return GuardStep(self.applied, IDLE, event)
        if self.state == LOST:
            self.applied = max(0.0, min(self.applied - cfg.fade_rate * dt, demanded))
            return GuardStep(self.applied, LOST)
        met = math.isfinite(estimated) and estimated >= cfg.min_fraction * demanded
        if met:
            self.unmet_time, self.travel = 0.0, 0.0
        else:
            self.unmet_time += dt
            if math.isfinite(normal_speed):
                self.travel += max(normal_speed, 0.0) * dt
        self.state = PUSHING
        if self.travel > cfg.max_free_travel or self.unmet_time > cfg.max_unmet_time:
            self.state = LOST
            why = (f"{self.travel:.2f} m along the platform normal (max_free_travel {cfg.max_free_travel:g} m)"
                   if self.travel > cfg.max_free_travel else
                   f"{self.unmet_time:.1f} s (max_unmet_time {cfg.max_unmet_time:g} s)")
            event = (f"contact lost: estimated contact force {estimated:.1f} N against the demanded {demanded:.1f} N "
                     f"for {why}: the force demand fades to 0 at {cfg.fade_rate:g} N/s; release the force trigger "
                     "to push again")
            self.applied = max(0.0, demanded - cfg.fade_rate * dt)
            return GuardStep(self.applied, LOST, event)
        self.applied = demanded
        return GuardStep(demanded, PUSHING)
