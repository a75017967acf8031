"""Realism effects of the plant (issue 11, "physics"): model mismatch, actuation, aerodynamics.

Each effect is a section of the scenario (:class:`~fpr_sim.scenario.ModelMismatchConfig`,
:class:`~fpr_sim.scenario.ActuationConfig`, :class:`~fpr_sim.scenario.AerodynamicsConfig`), off in the ideal
profile. What this module gives the plant:

- :func:`draw_model_mismatch`: the plant's TRUE FprParameters overrides (fpr_model names), drawn once per run;
- :func:`draw_actuation`: the true (C.2) coefficients per UAV and the per-rotor thrust gains, drawn once per run;
- :class:`ThrustNoise`: the multiplicative per-rotor thrust noise, one sample per physics step;
- :func:`ground_effect_gain` and :func:`rotor_drag_force`: the aerodynamic laws;
- :class:`PlantRealism`: all of it for one plant; :meth:`PlantRealism.step_inputs` gives, at the start of each
  physics step, the per-rotor thrust factors (gain × noise × ground effect, held over the step) and the rotor
  drag on each quadrotor (world, held over the step). Both plant kernels (Python reference and C) take these as
  inputs, so they see the same numbers; with every effect off nothing is computed and the plant runs exactly as
  before.

Random streams: ``SeedSequence([scenario.seed, stream])`` with the streams below, distinct from the sensors'
(``SeedSequence(seed).spawn(n)``), the cameras' (7), the fan's (11) and the target's (12). Each draw function
always draws the same number of values in the same order, whatever half-widths are zero, so one knob's change
never reshuffles the others' draws.

Units SI; world frame ENU; quadrotor body frames FLU.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from fpr_model.parameters import default_parameters

from fpr_sim.scenario import BatteryConfig, QuadrotorConfig, Scenario, per_uav

__all__ = ["ACTUATION_SEED_STREAM", "MISMATCH_SEED_STREAM", "THRUST_NOISE_SEED_STREAM", "ActuationDraws",
           "PlantRealism", "ThrustNoise", "draw_actuation", "draw_model_mismatch", "ground_effect_gain",
           "quadrotor_inertia_factors", "rotor_drag_force"]

MISMATCH_SEED_STREAM = 21  #: model-mismatch draws
ACTUATION_SEED_STREAM = 22  #: thrust-curve and per-rotor gain draws
THRUST_NOISE_SEED_STREAM = 23  #: the thrust noise sequence
THRUST_NOISE_COMMON_SEED_STREAM = 24  #: its part common to a UAV's rotors (drawn only when the share is > 0)


def _generator(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), stream]))


def draw_model_mismatch(scenario: Scenario) -> dict[str, Any]:
    """The TRUE parameters' overrides (fpr_model.parameters field names) drawn for ``scenario``: Table B.1
    (:func:`fpr_model.parameters.default_parameters`) plus a uniform draw in ``±`` each half-width of
    ``scenario.mismatch`` (relative for the inertias); {} when the mismatch is disabled. The quadrotor inertia
    is not an FprParameters field: see :func:`quadrotor_inertia_factors`."""
    return _mismatch_draws(scenario)[0]


def _mismatch_draws(scenario: Scenario) -> tuple[dict[str, Any], list[float]]:
    """(FprParameters overrides, quadrotor inertia factors) of the mismatch, drawn in a fixed order."""
    config = scenario.mismatch
    if not config.enabled:
        return {}, [1.0, 1.0, 1.0]
    base = default_parameters(scenario.n)
    rng = _generator(scenario.seed, MISMATCH_SEED_STREAM)
    n = scenario.n

    def unit(size: int | None = None):
        return rng.uniform(-1.0, 1.0, size)

    draws: dict[str, Any] = {}
    draws["platform_mass"] = base.platform_mass + config.platform_mass * unit()
    draws["uav_masses"] = (base.uav_masses + config.uav_mass * unit(n)).tolist()
    draws["leg_mass"] = base.leg_mass + config.leg_mass * unit()
    com = unit(3)
    draws["platform_com"] = (base.platform_com + np.array([config.platform_com_xy * com[0],
                                                          config.platform_com_xy * com[1],
                                                          config.platform_com_z * com[2]])).tolist()
    draws["leg_com"] = (base.leg_com + np.array([config.leg_com * unit(), 0.0, 0.0])).tolist()
    draws["platform_inertia"] = (np.diag(base.platform_inertia) * (1.0 + config.platform_inertia * unit(3))).tolist()
    draws["leg_inertia"] = (np.diag(base.leg_inertia) * (1.0 + config.leg_inertia * unit(3))).tolist()
    draws["leg_length"] = base.leg_length + config.leg_length * unit()
    draws["platform_radius"] = base.platform_radius + config.platform_radius * unit()
    draws["joint_offset"] = base.joint_offset + config.joint_offset * unit()
    draws["joint_offset_angle"] = base.joint_offset_angle + config.joint_offset_angle * unit()
    inertia_factors = (1.0 + config.quadrotor_inertia * unit(3)).tolist()
    overrides = {name: (float(value) if isinstance(value, (float, np.floating)) else value)
                 for name, value in draws.items()}
    return overrides, inertia_factors


def quadrotor_inertia_factors(scenario: Scenario) -> list[float]:
    """Relative factors (3,) on ``quadrotor.inertia`` (all UAVs alike): ``1 + mismatch.quadrotor_inertia·u``, u
    uniform in [−1, 1], drawn after the FprParameters draws of :func:`draw_model_mismatch` (same stream);
    [1, 1, 1] when the mismatch is disabled."""
    return _mismatch_draws(scenario)[1]


@dataclass(frozen=True)
class ActuationDraws:
    """The per-run actuation draws: the plant's true (C.2) coefficients per UAV ``[a_f, b_f]`` (n, 2) and the
    per-rotor thrust gains (n, 4) (rotor order of (3.41): 1 front, 2 left, 3 back, 4 right)."""

    thrust_coefficients: list[list[float]]
    rotor_gains: list[list[float]]


def draw_actuation(scenario: Scenario) -> ActuationDraws | None:
    """The actuation draws of ``scenario`` (None when ``actuation`` is disabled): per UAV i, ``a_f,i (1 + ε_a)``
    and ``b_f,i + δ_b`` from ``quadrotor.thrust_coefficients`` (Table C.1 by default), then per rotor
    ``k_ij = 1 + ε_ij``; every ε, δ uniform within its ``±`` half-width."""
    config = scenario.actuation
    if not config.enabled:
        return None
    rng = _generator(scenario.seed, ACTUATION_SEED_STREAM)
    n = scenario.n
    slope = rng.uniform(-1.0, 1.0, n)
    offset = rng.uniform(-1.0, 1.0, n)
    spread = rng.uniform(-1.0, 1.0, (n, 4))
    coefficients = []
    for i in range(n):
        a_f, b_f = map(float, per_uav(scenario.quadrotor.thrust_coefficients, i))
        coefficients.append([a_f * (1.0 + config.thrust_slope_error * slope[i]),
                             b_f + config.thrust_offset_error * offset[i]])
    gains = (1.0 + config.rotor_thrust_spread * spread).tolist()
    return ActuationDraws(coefficients, gains)


class ThrustNoise:
    """Multiplicative per-rotor thrust noise ``1 + σ ξ_ij``: ξ a unit-variance first-order Gauss-Markov process
    per rotor, ``ξ_{k+1} = a ξ_k + √(1 − a²) w_k``, ``a = exp(−dt/τ)``, w standard normal, started from its
    stationary distribution (ξ_0 ~ N(0, 1)); one sample per physics step ``dt`` [s]. With ``common`` ρ > 0,
    ``ξ_ij = √ρ c_i + √(1 − ρ) e_ij``: c_i one process per UAV (its own random stream), e_ij the per-rotor ones
    (the same draws as with ρ = 0). Samples are generated in blocks of ``block`` steps (vectorized),
    deterministic with the seed."""

    def __init__(self, sigma: float, time_constant: float, dt: float, n: int, seed: int, block: int = 512,
                 common: float = 0.0, gains: list[list[float]] | None = None) -> None:
        self.sigma = float(sigma)
        self.n = n
        #: (4n,) constant per-rotor factors the samples are multiplied by (the thrust-gain spread), or None
        self._gains = None if gains is None else np.asarray(gains, dtype=float).reshape(4 * n)
        self._a = math.exp(-float(dt) / float(time_constant))
        self._b = math.sqrt(1.0 - self._a * self._a)
        self._rng = _generator(seed, THRUST_NOISE_SEED_STREAM)
        self._xi = self._rng.standard_normal(4 * n)
        self.common = float(common)
        self._common_rng = _generator(seed, THRUST_NOISE_COMMON_SEED_STREAM) if self.common > 0.0 else None
        self._xc = self._common_rng.standard_normal(n) if self._common_rng is not None else None
        self._block = block
        self._rows: list[list[float]] = []

    def _gauss_markov(self, start: np.ndarray, draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rows = np.empty_like(draws)
        xi = start
        for k in range(len(draws)):
            xi = self._a * xi + self._b * draws[k]
            rows[k] = xi
        return rows, xi

    def _refill(self) -> None:
        rows, self._xi = self._gauss_markov(self._xi, self._rng.standard_normal((self._block, 4 * self.n)))
        if self._common_rng is not None:
            common, self._xc = self._gauss_markov(self._xc, self._common_rng.standard_normal((self._block, self.n)))
            rows = math.sqrt(1.0 - self.common) * rows + math.sqrt(self.common) * np.repeat(common, 4, axis=1)
        factors = 1.0 + self.sigma * rows
        if self._gains is not None:
            factors = self._gains * factors  # the products g_ij (1 + σ ξ_ij) as the plant formed them one by one
        self._rows = factors.tolist()[::-1]

    def next(self) -> list[float]:
        """The factors ``1 + σ ξ`` (4n, UAV-major) of the next physics step, times ``gains`` if given."""
        if not self._rows:
            self._refill()
        return self._rows.pop()


def ground_effect_gain(height: float, rotor_radius: float, min_ratio: float = 0.5) -> float:
    """Thrust ratio in/out of ground effect at constant power, Cheeseman & Bennett (1955), ARC R&M 3021:
    ``T_IGE / T_OGE = 1 / (1 − (R / 4z)²)``; ``height`` z [m] of the rotor plane above the ground, ``rotor_radius``
    R [m] (≤ 0: no effect, 1), z clamped to ``z ≥ min_ratio·R`` (the law diverges at z = R/4; min_ratio 0.5 caps
    the gain at 4/3)."""
    if rotor_radius <= 0.0:
        return 1.0
    ratio = rotor_radius / (4.0 * max(height, min_ratio * rotor_radius))
    return 1.0 / (1.0 - ratio * ratio)


def rotor_drag_force(coefficient: float, thrust: float, axis: tuple, velocity: tuple,
                     air: tuple) -> tuple[float, float, float]:
    """Rotor drag [N] (world) on one quadrotor: ``f = −c · f_t · (I − z zᵀ)(v − w)``, linear in the airspeed in
    the rotor plane and proportional to the thrust (blade flapping + induced drag, Mahony, Kumar & Corke, IEEE
    RAM 19(3) 2012, §"rotor drag"; the linear drag model of Faessler, Franchi & Scaramuzza, IEEE RA-L 3(2)
    2018). ``coefficient`` c [s/m], ``thrust`` f_t [N] (≥ 0 used), ``axis`` z_b (world unit rotor axis),
    ``velocity`` v and ``air`` w [m/s] (world)."""
    r0, r1, r2 = velocity[0] - air[0], velocity[1] - air[1], velocity[2] - air[2]
    z0, z1, z2 = axis
    along = r0 * z0 + r1 * z1 + r2 * z2
    scale = -coefficient * max(thrust, 0.0)
    return scale * (r0 - along * z0), scale * (r1 - along * z1), scale * (r2 - along * z2)


class PlantRealism:
    """The realism effects of one plant (see the module doc). ``quadrotor`` and ``battery`` are the configs the
    plant's fleet is built with (the scenario's, with the actuation's motor lag / internal resistance and the
    mismatch's quadrotor inertia applied); ``rotor_gains`` (n, 4) or None."""

    def __init__(self, scenario: Scenario, dt: float) -> None:
        self.scenario = scenario
        self.n = n = scenario.n
        self.mismatch, self.inertia_factors = _mismatch_draws(scenario)
        self.actuation = draw_actuation(scenario)
        self.quadrotor, self.battery = _effective_configs(scenario, self.actuation, self.inertia_factors)
        actuation = scenario.actuation
        aero = scenario.aerodynamics
        self.rotor_gains = self.actuation.rotor_gains if self.actuation is not None else None
        if self.rotor_gains is not None and all(g == 1.0 for row in self.rotor_gains for g in row):
            self.rotor_gains = None
        self.noise = (ThrustNoise(actuation.thrust_noise, actuation.thrust_noise_time_constant, dt, n, scenario.seed,
                                  common=actuation.thrust_noise_common, gains=self.rotor_gains)
                      if actuation.enabled and actuation.thrust_noise > 0.0 else None)
        self.rotor_radius = float(aero.rotor_radius) if aero.enabled and scenario.ground.enabled else 0.0
        self.rotor_height = float(aero.rotor_height)
        self.min_ratio = float(aero.ground_effect_min_ratio)
        self.ground_height = float(scenario.ground.height)
        self.rotor_drag = float(aero.rotor_drag) if aero.enabled else 0.0
        #: per-rotor thrust factors vary (gains, noise or ground effect): the plant passes them every step
        self.has_factors = self.rotor_gains is not None or self.noise is not None or self.rotor_radius > 0.0
        self.active = self.has_factors or self.rotor_drag > 0.0

    def thrust_factors(self, tip_positions: list[tuple]) -> list[list[float]]:
        """Per-rotor factors (n, 4) of the produced thrust for the step: gain × (1 + σξ) × ground-effect gain of the
        UAV's rotor height (``tip_positions`` [m] world, the quadrotors' CoMs at the step's start). Plain floats,
        1 kHz: the gains are folded into the noise samples when both are on (the same products)."""
        n = self.n
        if self.noise is not None:
            flat = self.noise.next()
        elif self.rotor_gains is not None:
            flat = [g for row in self.rotor_gains for g in row]
        else:
            flat = [1.0] * (4 * n)
        if self.rotor_radius <= 0.0:
            return [flat[4 * i:4 * i + 4] for i in range(n)]
        out = []
        for i in range(n):
            gain = ground_effect_gain(tip_positions[i][2] - self.ground_height + self.rotor_height,
                                      self.rotor_radius, self.min_ratio)
            out.append([flat[4 * i] * gain, flat[4 * i + 1] * gain, flat[4 * i + 2] * gain, flat[4 * i + 3] * gain])
        return out

    def drag_forces(self, quats: list[list[float]], rotors: list[list[float]], factors: list[list[float]] | None,
                    tip_velocities: list[tuple], air: list[float] | None) -> list[tuple[float, float, float]]:
        """Rotor drag (n, 3) [N] world on each quadrotor (:func:`rotor_drag_force`) with the produced thrust of
        the step (``rotors`` × ``factors``), rotor axes of ``quats`` [w,x,y,z] (FLU → ENU), CoM velocities and the
        air velocities of Plant._air_velocities (None: still air)."""
        out = []
        for i in range(self.n):
            w, x, y, z = quats[i]
            axis = (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), w * w - x * x - y * y + z * z)
            r = rotors[i]
            k = factors[i] if factors is not None else (1.0, 1.0, 1.0, 1.0)
            thrust = k[0] * r[0] + k[1] * r[1] + k[2] * r[2] + k[3] * r[3]
            wind = (0.0, 0.0, 0.0) if air is None else (air[3 + 3 * i], air[4 + 3 * i], air[5 + 3 * i])
            out.append(rotor_drag_force(self.rotor_drag, thrust, axis, tip_velocities[i], wind))
        return out

    def report(self) -> dict[str, Any]:
        """What was drawn for this run (for experiment reports): the true parameter overrides, the quadrotor
        inertia, the true (C.2) coefficients, rotor gains, the motor time constant, the internal resistance and
        the aerodynamic constants in use (plain lists and floats)."""
        return {
            "mismatch": dict(self.mismatch),
            "quadrotor_inertia": list(self.quadrotor.inertia),
            "thrust_coefficients": [list(map(float, per_uav(self.quadrotor.thrust_coefficients, i)))
                                    for i in range(self.n)],
            "rotor_gains": self.rotor_gains,
            "thrust_noise": self.noise.sigma if self.noise is not None else 0.0,
            "motor_time_constant": float(self.quadrotor.motor_time_constant),
            "battery_internal_resistance": float(self.battery.internal_resistance),
            "ground_effect_rotor_radius": self.rotor_radius,
            "rotor_drag": self.rotor_drag,
        }


def _effective_configs(scenario: Scenario, actuation: ActuationDraws | None,
                       inertia_factors: list[float]) -> tuple[QuadrotorConfig, BatteryConfig]:
    """The scenario's quadrotor and battery configs with the realism effects applied (copies)."""
    quad = scenario.quadrotor
    battery = scenario.battery
    changes: dict[str, Any] = {}
    if inertia_factors != [1.0, 1.0, 1.0]:
        changes["inertia"] = [float(v) * f for v, f in zip(quad.inertia, inertia_factors, strict=True)]
    if actuation is not None:
        changes["thrust_coefficients"] = actuation.thrust_coefficients
        if scenario.actuation.motor_time_constant > 0.0:
            changes["motor_time_constant"] = float(scenario.actuation.motor_time_constant)
        if scenario.actuation.battery_internal_resistance > 0.0:
            battery = dataclasses.replace(battery,
                                          internal_resistance=float(scenario.actuation.battery_internal_resistance))
    return (dataclasses.replace(quad, **changes) if changes else quad), battery
