"""The impedance law (3.30)-(3.32) with Table 3.1 gains and each observer, under a step of external moment: the
transient the observer's convergence leaves (evidence for the Table 3.3 row of fpr_sim's README, issue 11).

With u = ν̇^d + M_d^{-1}[B^d(ν^d − ν) + K^d ε_q + τ̂_e] and f = J^{-T}[M u + C ν + g − τ̂_e], the platform obeys
ν̇ = M_d^{-1}(−B^d ν − K^d ε + τ̂_e) + M^{-1}(τ_e − τ̂_e): until τ̂_e has converged, the unestimated part of a step
acts through the true, coupled inertia M (roll 3.3 kg m², legs 1.1 kg m², position-orientation coupling) while
the law's restoring terms act through the diagonal M_d (8 kg m², 5 kg m²). The slower the observer, the larger
the excursion before the compliance settles at its static value: SOWO (ζ = 1, ω_n = 1 rad/s on the moments)
more than FOWO (K_O = 1), SMWO least. Harness: fpr_control's closed loop (exact state, each UAV tracks its
attitude setpoint instantly), so none of this comes from actuation, sensing or latency; the last test adds a command
delay and an actuation lag to show how much of both the law tolerates.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import pytest
from closed_loop import HARNESS_PLAUSIBILITY, Sim, _jacobian, command, hover_state
from fpr_control.controller import Controller, ControllerConfig, gains_from_dict
from fpr_model.dynamics import rk4_step
from fpr_model.parameters import default_parameters
from fpr_model.rotations import quat_from_rotvec, quat_multiply, quat_to_euler_zyx

PARAMS = default_parameters(3)
LEG = math.radians(62.3)  # Table 3.3's hover configuration
STEP = 1.0  # [N m] external moment about the platform's x axis (Fp), applied at the platform


class _DelayedActuation(Sim):
    """The thrust vectors applied ``delay_ms`` later and through a first-order lag ``lag_ms`` (command uplink,
    attitude loop and rotors lumped); the controllers still believe their commands applied (observer input).
    With an ``rng``: the hardware profile's noise (fpr_sim config/realism/hardware): the motion capture's on the
    state the controllers read (0.5 mm, 0.2°, 0.01 m/s, 0.02 rad/s, legs 0.2° and 0.02 rad/s, 1σ) and a
    Gauss-Markov fluctuation of each UAV's thrust of ``thrust_sigma`` (τ 0.3 s, the calibrated values)."""

    delay_ms: int = 0
    lag_ms: float = 0.0
    rng: np.random.Generator | None = None
    thrust_sigma: float = 0.0

    def ground_truth(self):
        truth = super().ground_truth()
        if self.rng is None:
            return truth
        normal = self.rng.normal
        truth.platform_position = truth.platform_position + normal(0.0, 0.0005, 3)
        truth.platform_quat = quat_multiply(truth.platform_quat, quat_from_rotvec(normal(0.0, 0.0035, 3)))
        truth.platform_velocity = truth.platform_velocity + normal(0.0, 0.01, 3)
        truth.platform_rate = truth.platform_rate + normal(0.0, 0.02, 3)
        truth.leg_angles = truth.leg_angles + normal(0.0, 0.0035, len(truth.leg_angles))
        truth.leg_rates = truth.leg_rates + normal(0.0, 0.02, len(truth.leg_rates))
        return truth

    def run(self, duration, cmd, control_period=0.02, physics_dt=0.001, **kwargs):
        if not hasattr(self, "_queue"):
            self._queue = deque([self.thrusts.copy()] * (self.delay_ms + 1))
            self._applied = self.thrusts.copy()
            self._fluctuation = np.zeros(len(self.thrusts))
        decay = math.exp(-physics_dt / 0.3)
        for _ in range(int(round(duration / control_period))):
            self.control(cmd)
            for _ in range(int(round(control_period / physics_dt))):
                self._queue.append(self.thrusts.copy())
                target = self._queue.popleft()
                gain = physics_dt / (1e-3 * self.lag_ms) if self.lag_ms > 0.0 else 1.0
                self._applied = self._applied + gain * (target - self._applied)
                applied = self._applied
                if self.rng is not None and self.thrust_sigma > 0.0:
                    self._fluctuation = decay * self._fluctuation + math.sqrt(1.0 - decay * decay) * \
                        self.thrust_sigma * self.rng.standard_normal(len(self._fluctuation))
                    applied = applied * (1.0 + self._fluctuation)[:, None]
                external = self.external(self.q, self.nu) if self.external is not None else None
                tau = applied.reshape(-1) @ _jacobian(self.params, self.q)
                self.q, self.nu = rk4_step(self.params, self.q, self.nu, tau, physics_dt, external)
                self.t += physics_dt
            if not np.all(np.isfinite(self.q)):
                return


def _roll_after_step(observer: str, delay_ms: int = 0, lag_ms: float = 0.0) -> tuple[float, float]:
    """|roll| peak and final [deg] over 10 s after the step (hover converged for 3 s before it); 90 once lost."""
    controllers = [Controller(PARAMS, ControllerConfig(
        uav_id=i + 1, info_plausibility=HARNESS_PLAUSIBILITY, mode="impedance", gains=gains_from_dict({}, 3),
        observer=observer, state_source="ground_truth")) for i in range(3)]
    q, nu = hover_state(PARAMS, leg_angle=LEG, yaw=0.0)
    sim = _DelayedActuation(PARAMS, controllers, q, nu, np.zeros(3))
    sim.delay_ms, sim.lag_ms = delay_ms, lag_ms
    cmd = command(3, leg=LEG)
    sim.run(3.0, cmd)
    wrench = np.zeros(9)
    wrench[3] = STEP
    sim.external = lambda q, nu: wrench
    rolls = []
    for _ in range(500):
        sim.run(0.02, cmd)
        if not np.all(np.isfinite(sim.q)):
            return 90.0, 90.0
        rolls.append(abs(math.degrees(quat_to_euler_zyx(sim.q[3:7])[0])))
        if rolls[-1] >= 90.0:
            return 90.0, 90.0
    return max(rolls), rolls[-1]


@pytest.fixture(scope="module")
def responses() -> dict[str, tuple[float, float]]:
    return {observer: _roll_after_step(observer) for observer in ("fowo", "sowo", "smwo")}


def test_the_unestimated_part_of_a_step_makes_an_excursion_several_times_the_compliance(responses):
    for observer, (peak, final) in responses.items():
        assert 3.5 < final < 6.5, (observer, final)  # the compliance's static roll (coupled; K^d = 25 N m/rad)
        assert peak > 2.5 * final, (observer, peak, final)


def test_the_slower_the_observer_the_larger_the_excursion(responses):
    # measured 2026-12-07: SMWO 14.4°, FOWO 20.8°, SOWO 34.7° (final 4.6-5.4°)
    assert responses["smwo"][0] < responses["fowo"][0] < responses["sowo"][0]
    assert responses["sowo"][0] > 1.4 * responses["fowo"][0]


def test_the_law_and_its_observer_keep_their_step_response_with_a_slow_actuation(responses):
    """The law's own delay margin is large: 60 ms of command delay and a 100 ms lag (far more than PX4's attitude
    loop, the rotors and a Wi-Fi uplink together) change FOWO's excursion by ~10 % (measured 2026-12-07: 23.0°
    against 20.8°); a 200 ms lag with the same delay loses it (the harness can tell). So the 10-20 ms latency
    margin of some simulated Ch. 3 flights (fpr_sim README, issue 11) is not the law's."""
    exact = responses["fowo"][0]
    delayed, _ = _roll_after_step("fowo", delay_ms=60, lag_ms=100.0)
    assert delayed < 1.2 * exact, (delayed, exact)
    lost, _ = _roll_after_step("fowo", delay_ms=60, lag_ms=200.0)
    assert lost > 60.0, lost


def _noisy_hover_roll(observer: str, delay_ms: int, seconds: float = 20.0) -> float:
    """RMS platform roll [deg] of a hover (after 5 s) with the hardware profile's noise (:class:`_DelayedActuation`
    with an rng: motion-capture noise, 5 % thrust fluctuation), a 50 ms actuation lag and ``delay_ms``; 90 once
    lost."""
    controllers = [Controller(PARAMS, ControllerConfig(
        uav_id=i + 1, info_plausibility=HARNESS_PLAUSIBILITY, mode="impedance", gains=gains_from_dict({}, 3),
        observer=observer, state_source="ground_truth")) for i in range(3)]
    q, nu = hover_state(PARAMS, leg_angle=LEG, yaw=0.0)
    sim = _DelayedActuation(PARAMS, controllers, q, nu, np.zeros(3))
    sim.delay_ms, sim.lag_ms, sim.rng, sim.thrust_sigma = delay_ms, 50.0, np.random.default_rng(1), 0.05
    cmd = command(3, leg=LEG)
    rolls = []
    for _ in range(int(round(seconds / 0.02))):
        sim.run(0.02, cmd)
        roll = math.degrees(quat_to_euler_zyx(sim.q[3:7])[0]) if np.all(np.isfinite(sim.q)) else 90.0
        if abs(roll) >= 90.0:
            return 90.0
        rolls.append(roll)
    return float(np.sqrt(np.mean(np.square(rolls[250:]))))


def test_smwo_under_the_profile_s_noise_has_a_delay_margin_of_tens_of_ms():
    """SMWO's loop delay margin with noise (issue 11, docs/latency_margin.md: SMWO is the simulated Ch. 3 observer
    that loses control with 10-20 ms of command uplink). Without noise its step response hardly moves with 20 ms of
    delay (above); with the profile's noise its hover holds 20 ms but degrades with more (measured 2026-12-07, RMS
    roll: 4.3° at 0 ms, 4.4° at 20, 5.3° at 40, 6.6° at 60, 12.4° at 80 ms), where FOWO's barely moves (3.8° →
    4.7° at 80 ms). So SMWO's margin is a total loop delay of ~60-80 ms, of which the simulated robot's own loop
    (motion-capture latency, 50 Hz sampling, PX4's attitude loop, the rotors) already spends much."""
    undelayed = _noisy_hover_roll("smwo", 0)
    assert _noisy_hover_roll("smwo", 20) < 1.2 * undelayed
    assert _noisy_hover_roll("smwo", 80) > 2.0 * undelayed
    assert _noisy_hover_roll("fowo", 80) < 1.5 * _noisy_hover_roll("fowo", 0)
