"""High-level control laws of the FPR: impedance (3.25)-(3.31) / (4.33)-(4.34), PID motion law (4.27)-(4.29),
PD and PD+C (Table 3.4), and the model terms they need (:class:`fpr_model.dynamics.ModelTerms`). The thrust
distribution ``f = [Jᵀ]† τ`` (3.32) / (4.33) is :meth:`fpr_model.kinematics.JacobianAt.thrusts`
(:func:`fpr_model.dynamics.thrusts_from_wrench`).

All vectors follow fpr_model: ``q = [p_p (3), q_p (4, [w,x,y,z]), θ (n)]``, ``ν = [v_p (controller world frame,
m/s), ω_p (Fp, rad/s), θ̇ (rad/s)]``, wrenches ``[f_p (world, N), m_p (Fp, N·m), m_l (N·m)]``. The controller
"world" frame is F0 for the centralized variants and the flat platform frame F_Fp for the decentralized ones
(thesis §4.3.1). Gains are diagonals given as vectors of length 6 + n. No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from fpr_model.dynamics import ModelTerms, model_terms
from fpr_model.kinematics import jacobian_at
from fpr_model.parameters import FprParameters
from fpr_model.rotations import attitude_error_vector

from fpr_control.observers import expand_gains


def compute_model_terms(params: FprParameters, q: np.ndarray, nu: np.ndarray) -> ModelTerms:
    """M(q), C(q, ν), g(q) (2.25) and J(q) (2.20) from fpr_model, in the frame of q and ν (one parse of q:
    :func:`fpr_model.dynamics.model_terms`; J^† is computed, with its singularity test, on first use)."""
    return model_terms(params, jacobian_at(params, q, check_leg_range=False), nu)


def observer_inputs(terms: ModelTerms, nu: np.ndarray, thrusts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Momentum ``P = M ν`` and the known momentum rate ``β = Cᵀ ν − g + Jᵀ f`` (3.6), (2.28), for the
    observers; ``thrusts`` f (3n,) are the thrust vectors applied during the last period [N]."""
    return terms.mass @ nu, terms.coriolis.T @ nu - terms.gravity + terms.jacobian.matrix.T @ thrusts


@dataclass(frozen=True)
class ImpedanceGains:
    """Desired impedance M^d, B^d, K^d of (3.25) as diagonals (length 6 + n)."""

    inertia: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray

    @staticmethod
    def from_groups(inertia, damping, stiffness, n: int) -> ImpedanceGains:
        """From (position, orientation, legs) triples, e.g. Table 3.1: (5, 8, 5), (10, 25, 20), (25, 25, 15)."""
        return ImpedanceGains(expand_gains(inertia, n), expand_gains(damping, n), expand_gains(stiffness, n))


@dataclass(frozen=True)
class PidGains:
    """K_p, K_d, K_i of (4.28) as diagonals (length 6 + n) and the anti-windup: the bound on |K_i ∫ε| (same
    units as u: m/s², rad/s²) and the integration zone (ε_j is integrated only while |ε_j| ≤ zone_j; m, rad)."""

    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray
    integral_limit: np.ndarray
    integral_zone: np.ndarray


def pid_gains_from_groups(groups: dict, n: int) -> PidGains:
    """Table 4.1 layout: ``groups[name] = (kp, kd, ki)`` for names position_xy, position_z, orientation_xy,
    orientation_z, legs, plus ``integral_limit`` and ``integral_zone`` = (position, orientation, legs)."""
    def vector(column: int) -> np.ndarray:
        pxy, pz = groups["position_xy"][column], groups["position_z"][column]
        oxy, oz = groups["orientation_xy"][column], groups["orientation_z"][column]
        return np.concatenate([[pxy, pxy, pz, oxy, oxy, oz], np.full(n, groups["legs"][column])]).astype(float)

    limit = expand_gains(groups.get("integral_limit", (2.0, 2.0, 2.0)), n)
    zone = expand_gains(groups.get("integral_zone", (math.inf, math.inf, math.inf)), n)
    return PidGains(vector(0), vector(1), vector(2), limit, zone)


def configuration_error(q: np.ndarray, q_d: np.ndarray, use_position: bool = True) -> np.ndarray:
    """ε_q(q^d, q) of (3.27): ``[p^d − p; ε_o(q^d_p, q_p); θ^d − θ]`` with ε_o of (3.28)-(3.29) (Fp, about
    δφ/2 for small errors, spec §0.3). ``use_position=False`` gives (4.29): the position rows are 0."""
    error = np.empty(q.size - 1)
    error[:3] = (q_d[:3] - q[:3]) if use_position else 0.0
    error[3:6] = attitude_error_vector(q[3:7], q_d[3:7])
    error[6:] = q_d[7:] - q[7:]
    return error


def wrench_tracking_error(tau_hat: np.ndarray, tau_desired: np.ndarray,
                          force_selection: np.ndarray | None = None) -> np.ndarray:
    """ε_τ = −τ̂_e − τ^d_e (3.26): estimated wrench exerted on the environment minus the desired one
    (layout of τ̂_e: platform force [N] in the controller frame, moments [N·m]).

    ``force_selection`` S (3×3, controller frame), when given, replaces the platform-force rows by
    ``−S f̂_p,e − f^d_p,e``: only the selected part of the estimated force is an input of the impedance (4.34); the
    rest is left to the compensation −τ̂_e of (4.33) (see :func:`interaction_force_selection`). None: (3.26)."""
    error = -np.asarray(tau_hat, dtype=float) - np.asarray(tau_desired, dtype=float)
    if force_selection is not None:
        error[:3] = -np.asarray(force_selection, dtype=float) @ np.asarray(tau_hat[:3], dtype=float) \
            - np.asarray(tau_desired[:3], dtype=float)
    return error


def interaction_force_selection(desired_force: np.ndarray) -> np.ndarray:
    """S = d dᵀ with d = f^d_p,e / ‖f^d_p,e‖ the direction of the desired interaction force (3.43)-(3.44)
    (controller frame); 0 (3×3) when no interaction force is desired. [OURS, decentralized controller.]

    Why: without a position measurement the position rows of (4.34) have no stiffness (Table 4.5 "*", (4.29)
    ε_q,p = 0), so (4.33)-(4.34) with ε_τ of (3.26) close the loop ``M^d (ν̇ − ν̇^d) + B^d (ν − ν^d) = τ̂_e + τ^d_e``
    on those rows: a persistent force f_e (a load) is not a compliance offset f_e/K^d as in Ch. 3 but a steady
    velocity error f_e/B^d (−0.29 m/s for 300 g with B^d = 10, −0.39 m/s for the 400 g of §4.4.2, more than the
    operator's stick), i.e. the robot descends onto its quadrotors. With S the estimate enters the translational
    impedance only along the force the operator asks the robot to exert (Scenario II: the normal contact force
    still tracks f^d_c, since along d the law is (4.34) unchanged); across d, and everywhere when f^d = 0
    (Scenario I, free flight with a load), the −τ̂_e of (4.33) compensates it and the operator's velocity
    command is tracked. The orientation and leg rows (with stiffness) keep (3.26)."""
    f = np.asarray(desired_force, dtype=float)
    norm = float(np.linalg.norm(f))
    if not norm > 0.0:
        return np.zeros((3, 3))
    d = f / norm
    return np.outer(d, d)


def impedance_acceleration(gains: ImpedanceGains, config_error: np.ndarray, nu: np.ndarray, nu_d: np.ndarray,
                           nu_dot_d: np.ndarray, wrench_error: np.ndarray) -> np.ndarray:
    """Auxiliary input u of (3.30) / (4.34): ``ν̇^d + (M^d)^{-1} (B^d (ν^d − ν) + K^d ε_q − ε_τ)``."""
    return nu_dot_d + (gains.damping * (nu_d - nu) + gains.stiffness * config_error - wrench_error) / gains.inertia


def control_wrench(terms: ModelTerms, u: np.ndarray, nu: np.ndarray,
                     tau_hat: np.ndarray | None = None) -> np.ndarray:
    """Feedback linearisation ``τ = M u + C ν + g (− τ̂_e)`` of (3.31) / (4.27) / (4.33) [N, N·m]."""
    tau = terms.mass @ u + terms.coriolis @ nu + terms.gravity
    if tau_hat is not None:
        tau = tau - tau_hat
    return tau


@dataclass
class PidMotionLaw:
    """PID auxiliary input (4.28) with integral anti-windup (thesis §4.4.1, [Azar 2015]): the integral state is
    clamped so that ``|K_i ∫ε| ≤ integral_limit`` element-wise, and an element is integrated only while its
    error is inside ``integral_zone`` (conditional integration: no wind-up during large steps)."""

    gains: PidGains
    integral: np.ndarray = field(init=False)
    _bound: tuple = field(init=False, repr=False, compare=False, default=(None, None))  # (gains, |∫ε| bound)

    def __post_init__(self) -> None:
        self.integral = np.zeros(len(self.gains.kp))

    def _integral_bound(self) -> np.ndarray:
        """|∫ε| ≤ integral_limit / K_i element-wise (0 where K_i = 0: nothing to integrate), per gains object."""
        gains, bound = self._bound
        if gains is not self.gains:
            g = self.gains
            bound = np.where(g.ki > 0.0, g.integral_limit / np.where(g.ki > 0.0, g.ki, 1.0), 0.0)
            self._bound = (g, bound)
        return bound

    def reset(self) -> None:
        self.integral[:] = 0.0

    def acceleration(self, config_error: np.ndarray, nu: np.ndarray, nu_d: np.ndarray, nu_dot_d: np.ndarray,
                     dt: float, integrate: bool = True) -> np.ndarray:
        """``u = ν̇^d + K_d (ν^d − ν) + K_p ε + K_i ∫ε dt`` (4.28)."""
        g = self.gains
        if integrate and dt > 0.0:
            inside = np.abs(config_error) <= g.integral_zone
            self.integral += np.where(inside, config_error, 0.0) * dt
            bound = self._integral_bound()
            np.clip(self.integral, -bound, bound, out=self.integral)
        return nu_dot_d + g.kd * (nu_d - nu) + g.kp * config_error + g.ki * self.integral


def pd_acceleration(gains: PidGains, config_error: np.ndarray, nu: np.ndarray, nu_d: np.ndarray,
                    nu_dot_d: np.ndarray) -> np.ndarray:
    """PD law of Table 3.4 ([Six 2018]): ``u = ν̇^d + K_d (ν^d − ν) + K_p ε``; used with
    :func:`control_wrench` without (PD) or with (PD+C, feed-forward −τ̂_e) the wrench estimate."""
    return nu_dot_d + gains.kd * (nu_d - nu) + gains.kp * config_error
