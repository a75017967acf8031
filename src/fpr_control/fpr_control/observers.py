"""Momentum-based external wrench observers (thesis §3.2, (3.6)-(3.24); (4.35) for the decentralized use).

Generalised momentum ``P = M(q) ν`` obeys ``Ṗ = β + τ_e`` with the known part
``β = C(q, ν)ᵀ ν − g(q) + τ`` (3.6), ``τ = J(q)ᵀ f`` the actuation wrench (2.28). Every observer here is fed,
once per control tick of period dt [s], with P_k and β_k (β_k computed with the thrusts applied during the
tick that just ended) and returns τ̂_e,k ∈ R^{6+n} in the wrench layout
``[f_p (controller world frame, N), p m_p (Fp, N·m), m_l (N·m)]``.

Discretisations (spec §1.4 "discrete algorithm"):

- FOWO (3.8): ``τ̂_k = τ̂_{k−1} + K_O [(P_k − P_{k−1}) − (β_k + τ̂_{k−1}) dt]``; error pole ``1 − K_O dt``.
- SOWO (3.13): ``I_k = I_{k−1} + (β_k + τ̂_{k−1}) dt``, ``r_k = P_k − P_0 − I_k`` (≈ ∫ τ̃),
  ``τ̂_k = τ̂_{k−1} + K_O1 (K_O2 r_k − τ̂_{k−1}) dt``; error dynamics (3.14)-(3.17):
  ``D_O = K_O1 = 2ζω_n``, ``K_O = K_O1 K_O2 = ω_n²``.
- SMWO (3.20)-(3.24), super-twisting: ``P̂_k = P̂_{k−1} + (β_k − K_OT |P̃_{k−1}|^½ sgn*(P̃_{k−1}) + τ̂_{k−1}) dt``,
  ``P̃_k = P̂_k − P_k``, ``τ̂_k = τ̂_{k−1} − K_OS sgn*(P̃_k) dt`` with sgn* of (3.21).

No rclpy here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

OBSERVER_KINDS = ("fowo", "sowo", "smwo")


@dataclass(frozen=True)
class ObserverGains:
    """Per-group observer gains of thesis Table 3.1, each a (position, orientation, legs) triple.

    fowo: K_O [1/s]; sowo: K_O1 [1/s], K_O2 [1/s]; smwo: K_OS, K_OT and the sgn* linear zone ε
    (momentum units, kg·m/s or kg·m²/s)."""

    fowo: tuple[float, float, float] = (2.0, 1.0, 1.0)
    sowo_k1: tuple[float, float, float] = (4.0, 2.0, 2.0)
    sowo_k2: tuple[float, float, float] = (1.0, 0.5, 0.5)
    smwo_ks: tuple[float, float, float] = (4.0, 1.0, 1.0)
    smwo_kt: tuple[float, float, float] = (3.2, 1.6, 1.6)
    smwo_epsilon: float = 0.02


def expand_gains(triple, n: int) -> np.ndarray:
    """(position, orientation, legs) -> diagonal vector of length 6 + n."""
    position, orientation, legs = (float(v) for v in triple)
    return np.concatenate([np.full(3, position), np.full(3, orientation), np.full(n, legs)])


def sgn_star(s: np.ndarray, epsilon: float) -> np.ndarray:
    """Adapted sign function (3.21), element-wise: s/ε inside |s| ≤ ε, sign(s) outside."""
    return np.clip(np.asarray(s, dtype=float) / epsilon, -1.0, 1.0)


class WrenchObserver:
    """Common interface: :meth:`update` (P_k, β_k, dt) -> τ̂_e,k; :meth:`reset`; :attr:`estimate`."""

    kind = ""

    def __init__(self, size: int) -> None:
        self.size = size
        self.estimate = np.zeros(size)
        self.initialized = False

    def reset(self, estimate: np.ndarray | None = None) -> None:
        """Forget the momentum history (next update re-initialises P_0); keep or set the estimate."""
        self.initialized = False
        if estimate is not None:
            self.estimate = np.array(estimate, dtype=float)

    def update(self, momentum: np.ndarray, beta: np.ndarray, dt: float) -> np.ndarray:
        raise NotImplementedError


class FirstOrderWrenchObserver(WrenchObserver):
    """FOWO (3.8)-(3.11): first-order error dynamics ``τ̂̇ + K_O τ̃ = 0`` per element."""

    kind = "fowo"

    def __init__(self, gain: np.ndarray) -> None:
        super().__init__(len(gain))
        self.gain = np.asarray(gain, dtype=float)
        self._previous_momentum = np.zeros(self.size)

    def update(self, momentum, beta, dt):
        momentum = np.asarray(momentum, dtype=float)
        if not self.initialized:
            self._previous_momentum = momentum.copy()
            self.initialized = True
            return self.estimate.copy()
        self.estimate = self.estimate + self.gain * (
            (momentum - self._previous_momentum) - (np.asarray(beta, dtype=float) + self.estimate) * dt
        )
        self._previous_momentum = momentum.copy()
        return self.estimate.copy()


class SecondOrderWrenchObserver(WrenchObserver):
    """SOWO (3.13)-(3.17): ``τ̂̈ + K_O1 τ̂̇ + K_O1 K_O2 τ̃ = 0`` per element."""

    kind = "sowo"

    def __init__(self, gain1: np.ndarray, gain2: np.ndarray) -> None:
        super().__init__(len(gain1))
        self.gain1 = np.asarray(gain1, dtype=float)
        self.gain2 = np.asarray(gain2, dtype=float)
        self._initial_momentum = np.zeros(self.size)
        self._integral = np.zeros(self.size)

    def update(self, momentum, beta, dt):
        momentum = np.asarray(momentum, dtype=float)
        if not self.initialized:
            # the kept estimate is this observer's rest state only with the residual that holds it, τ̂ = K_O2 r
            # (3.13): start r there (P_0 = P − τ̂ / K_O2, I = 0); r = 0 would pull τ̂ to zero at the rate K_O1 and
            # let it converge back, a transient the law feels as a step of its disturbance compensation
            self._initial_momentum = momentum - np.divide(self.estimate, self.gain2, out=np.zeros(self.size),
                                                          where=self.gain2 != 0.0)
            self._integral = np.zeros(self.size)
            self.initialized = True
            return self.estimate.copy()
        self._integral += (np.asarray(beta, dtype=float) + self.estimate) * dt
        residual = momentum - self._initial_momentum - self._integral
        self.estimate = self.estimate + self.gain1 * (self.gain2 * residual - self.estimate) * dt
        return self.estimate.copy()


class SlidingModeWrenchObserver(WrenchObserver):
    """SMWO (3.20)-(3.24): super-twisting momentum observer, σ = τ̂_e."""

    kind = "smwo"

    def __init__(self, gain_s: np.ndarray, gain_t: np.ndarray, epsilon: float) -> None:
        super().__init__(len(gain_s))
        if epsilon <= 0.0:
            raise ValueError("smwo epsilon must be > 0")
        self.gain_s = np.asarray(gain_s, dtype=float)
        self.gain_t = np.asarray(gain_t, dtype=float)
        self.epsilon = float(epsilon)
        self._momentum_estimate = np.zeros(self.size)
        self._momentum_error = np.zeros(self.size)

    def update(self, momentum, beta, dt):
        momentum = np.asarray(momentum, dtype=float)
        if not self.initialized:
            self._momentum_estimate = momentum.copy()
            self._momentum_error = np.zeros(self.size)
            self.initialized = True
            return self.estimate.copy()
        previous_error = self._momentum_error
        correction = self.gain_t * np.sqrt(np.abs(previous_error)) * sgn_star(previous_error, self.epsilon)
        self._momentum_estimate += (np.asarray(beta, dtype=float) - correction + self.estimate) * dt
        self._momentum_error = self._momentum_estimate - momentum
        self.estimate = self.estimate - self.gain_s * sgn_star(self._momentum_error, self.epsilon) * dt
        return self.estimate.copy()


def make_observer(kind: str, gains: ObserverGains, n: int) -> WrenchObserver:
    """Observer ``kind`` ∈ {"fowo", "sowo", "smwo"} for an n-leg FPR with Table 3.1-style gains."""
    if kind == "fowo":
        return FirstOrderWrenchObserver(expand_gains(gains.fowo, n))
    if kind == "sowo":
        return SecondOrderWrenchObserver(expand_gains(gains.sowo_k1, n), expand_gains(gains.sowo_k2, n))
    if kind == "smwo":
        return SlidingModeWrenchObserver(
            expand_gains(gains.smwo_ks, n), expand_gains(gains.smwo_kt, n), gains.smwo_epsilon
        )
    raise ValueError(f"observer must be one of {OBSERVER_KINDS}, got {kind!r}")
