"""Passive structure of the plant: platform + n legs with the quadrotors as point masses at the leg tips.

The equations are fpr_model's (thesis (2.86)-(2.88): ``M(q) ν̇ + C(q, ν) ν + g(q) = τ``), evaluated fast for
the 1 kHz plant. Two facts make that cheap:

1. In platform-body coordinates ``ξ = [u, ω, θ̇]`` with ``u = R_pᵀ v_p`` the mass matrix depends on the leg
   angles only, ``M̃(θ) = T M(q) Tᵀ`` with ``T = blkdiag(R_pᵀ, 1, 1)``, and it is a sum of one constant matrix and
   one term per leg that is linear in ``[cos θ_i, sin θ_i, cos 2θ_i, sin 2θ_i]`` (a leg inertia rotated about
   its fixed joint axis). The coefficient matrices are FITTED, once per parameter set, from
   ``fpr_model.dynamics.mass_matrix`` (no inertia algebra is repeated here); the fit residual is checked.
2. The Coriolis/centrifugal terms then follow from M̃ alone (Euler-Poincaré / Boltzmann-Hamel equations on
   SE(3) × Rⁿ, with the Kirchhoff momentum equations for the base):

   - ``d/dt p = p × ω + F``, ``d/dt π = π × ω + p × u + M`` for the base momenta ``[p; π] = (M̃ ξ)_{0:6}``,
   - ``d/dt (M̃ ξ)_{6+i} = ½ ξᵀ ∂M̃/∂θ_i ξ + Q_i`` for the legs,

   and gravity is the uniform field ``g̃ = −M̃[:, 0:3] R_pᵀ g_vec`` (a free-falling rigid mechanism accelerates
   at g). Together: ``M̃ ξ̇ = b(ξ) + M̃[:, :3] g_b + Q̃ − Σ_i θ̇_i ∂M̃/∂θ_i ξ``.

The result is checked against ``fpr_model.dynamics`` (mass matrix, Coriolis, gravity, forward dynamics) in
``test/test_structure.py``. Units SI; world frame ENU; ``v_p`` world, ``ω`` in Fp (platform body).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model._math import cross
from fpr_model.geometry import model_constants
from fpr_model.parameters import FprParameters
from fpr_model.rotations import quat_to_rotmat
from scipy.linalg.lapack import dposv as _cholesky_solve

from fpr_sim._kernels import StructureKernel, resolve_kernel

__all__ = ["PointForces", "StructureDynamics", "StructureState"]

#: Leg angle at which the other legs sit while one leg's mass-matrix dependence is fitted [rad].
_FIT_REFERENCE_ANGLE = 0.7
#: Sample leg angles of the fit [rad] (9 samples for 5 unknowns per entry: the residual checks the model).
_FIT_SAMPLES = np.linspace(0.15, 1.5, 9)


@dataclass
class StructureState:
    """State of the passive structure: q = [p_p, q_p, θ] (thesis (2.1)) and ν = [v_p, ω_p, θ̇] (2.2).

    ``position`` P in F0 [m]; ``quat`` platform [w,x,y,z] Fp -> F0; ``leg_angles`` θ [rad];
    ``velocity`` v_p in F0 [m/s]; ``rate`` ω_p in Fp [rad/s]; ``leg_rates`` θ̇ [rad/s].
    """

    position: np.ndarray
    quat: np.ndarray
    leg_angles: np.ndarray
    velocity: np.ndarray
    rate: np.ndarray
    leg_rates: np.ndarray

    def configuration(self) -> np.ndarray:
        """q ∈ R^{7+n} (2.1)."""
        return np.concatenate([self.position, self.quat, self.leg_angles])

    def generalized_velocity(self) -> np.ndarray:
        """ν ∈ R^{6+n} (2.2)."""
        return np.concatenate([self.velocity, self.rate, self.leg_rates])

    def copy(self) -> StructureState:
        return StructureState(*(np.array(getattr(self, name), dtype=float) for name in
                                ("position", "quat", "leg_angles", "velocity", "rate", "leg_rates")))


@dataclass
class PointForces:
    """Forces applied at points of the structure during one evaluation, all in the platform frame Fp.

    ``platform_points`` (k, 3) [m] from P, ``platform_forces`` (k, 3) [N];
    ``tip_forces`` (n, 3) [N] at the leg tips B_i (thrusts, ground, wind on the quadrotors);
    ``leg_mid_forces`` (n, 3) [N] at the middle of each leg; ``platform_moment`` (3,) [N m];
    ``joint_moments`` (n,) [N m] about the revolute joint axes.
    """

    platform_points: np.ndarray
    platform_forces: np.ndarray
    tip_forces: np.ndarray
    leg_mid_forces: np.ndarray
    platform_moment: np.ndarray
    joint_moments: np.ndarray


class StructureDynamics:
    """Fast forward dynamics of the passive structure for one (true) parameter set. See the module doc."""

    def __init__(self, params: FprParameters, payload_mass: float = 0.0, kernel: str | None = None) -> None:
        self.params = params
        self.n = params.n
        #: 'compiled' (accelerate runs in fpr_sim._kernels' C kernel) or 'python' (the reference below);
        #: ``kernel`` = 'auto' | 'compiled' | 'python' (None: $FPR_SIM_KERNEL, default 'auto')
        self.kernel = resolve_kernel(kernel, params.n)
        constants = model_constants(params)
        self.anchors = np.array(constants.anchors)  # a_i in Fp (n, 3)
        self.joint_axes = np.array(constants.joint_axes)  # k_i in Fp (n, 3)
        self.cos_alpha = np.array(constants.cos_alpha)
        self.sin_alpha = np.array(constants.sin_alpha)
        self.leg_length = params.leg_length
        self.gravity_vector = params.gravity_vector
        self._base_basis, self._leg_basis, self.fit_residual = _fit_mass_matrix_basis(params)
        self.payload_mass = 0.0
        self.set_payload_mass(payload_mass)
        self._compiled = StructureKernel(self) if self.kernel == "compiled" else None

    # ----------------------------------------------------------------------------------------------
    def set_payload_mass(self, mass: float) -> None:
        """Attach a point mass [kg] at P (0 detaches): changes the translational block of M̃ (and gravity)."""
        if not np.isfinite(mass) or mass < 0.0:
            raise ValueError(f"payload mass must be finite and >= 0, got {mass}")
        self.payload_mass = float(mass)
        base = self._base_basis.copy()
        base[:3, :3] += self.payload_mass * np.eye(3)
        n9 = 6 + self.n
        self._basis = np.concatenate([base.reshape(1, n9 * n9), self._leg_basis.reshape(4 * self.n, n9 * n9)])
        self._leg_basis_stack = self._leg_basis.reshape(4 * self.n * n9, n9)

    # ----------------------------------------------------------------------------------------------
    def leg_trig(self, leg_angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(cos θ, sin θ, cos 2θ, sin 2θ), each (n,)."""
        c = np.cos(leg_angles)
        s = np.sin(leg_angles)
        return c, s, c * c - s * s, 2.0 * s * c

    def body_mass_matrix(self, leg_angles: np.ndarray) -> np.ndarray:
        """M̃(θ) = T M(q) Tᵀ in platform-body coordinates ξ = [R_pᵀ v_p, ω_p, θ̇] [SI]."""
        c, s, c2, s2 = self.leg_trig(np.asarray(leg_angles, dtype=float))
        return self._mass(c, s, c2, s2)

    def _mass(self, c, s, c2, s2) -> np.ndarray:
        coef = np.empty(1 + 4 * self.n)
        coef[0] = 1.0
        coef[1::4], coef[2::4], coef[3::4], coef[4::4] = c, s, c2, s2
        n9 = 6 + self.n
        return (coef @ self._basis).reshape(n9, n9)

    def mass_matrix(self, state: StructureState) -> np.ndarray:
        """M(q) (thesis (2.86)) in the fpr_model coordinates ν = [v_p (F0), ω_p (Fp), θ̇]."""
        T = np.eye(6 + self.n)
        T[:3, :3] = quat_to_rotmat(state.quat).T
        return T.T @ self.body_mass_matrix(state.leg_angles) @ T

    def tip_positions_body(self, c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Leg tip positions ρ_i = a_i + l·e_i (Fp, from P) and leg directions e_i = pR_li e_x, each (n, 3)."""
        e = np.empty((self.n, 3))
        e[:, 0] = self.cos_alpha * c
        e[:, 1] = self.sin_alpha * c
        e[:, 2] = -s
        return self.anchors + self.leg_length * e, e

    def leg_normals_body(self, c: np.ndarray, s: np.ndarray) -> np.ndarray:
        """de_i/dθ_i = pR_li e_y (Fp), (n, 3)."""
        out = np.empty((self.n, 3))
        out[:, 0] = -self.cos_alpha * s
        out[:, 1] = -self.sin_alpha * s
        out[:, 2] = -c
        return out

    # ----------------------------------------------------------------------------------------------
    def generalized_forces(self, c, s, forces: PointForces) -> np.ndarray:
        """Q̃ = Σ (virtual power of each point force) in ξ coordinates (Fp), thesis (2.28) generalised."""
        n = self.n
        tips, e = self.tip_positions_body(c, s)
        q = np.zeros(6 + n)
        has_mid = forces.leg_mid_forces.any()
        leg_forces = forces.tip_forces + forces.leg_mid_forces if has_mid else forces.tip_forces
        q[:3] = leg_forces.sum(axis=0)
        moments = cross(tips, forces.tip_forces)
        if has_mid:
            moments += cross(self.anchors + 0.5 * self.leg_length * e, forces.leg_mid_forces)
        q[3:6] = moments.sum(axis=0) + forces.platform_moment
        if len(forces.platform_points):
            q[:3] += forces.platform_forces.sum(axis=0)
            q[3:6] += cross(forces.platform_points, forces.platform_forces).sum(axis=0)
        # about the joint axis k_i at A_i: k_i · ((ρ − a_i) × f) = k_i · (l e_i × f_tip + l/2 e_i × f_mid)
        lever_forces = forces.tip_forces + 0.5 * forces.leg_mid_forces if has_mid else forces.tip_forces
        joint = cross(e, self.leg_length * lever_forces)
        q[6:] = np.einsum("ij,ij->i", joint, self.joint_axes) + forces.joint_moments
        return q

    def body_acceleration(self, leg_angles, body_velocity, body_gravity, generalized_force) -> np.ndarray:
        """ξ̇ from M̃ ξ̇ = b(ξ) + M̃[:, :3] g_b + Q̃ − Σ θ̇_i ∂_iM̃ ξ (module doc); body_gravity = R_pᵀ g_vec."""
        c = [math.cos(a) for a in np.asarray(leg_angles, dtype=float).tolist()]
        s = [math.sin(a) for a in np.asarray(leg_angles, dtype=float).tolist()]
        g = np.asarray(body_gravity, dtype=float).tolist()
        return np.array(self.accelerate(c, s, np.asarray(body_velocity, dtype=float).tolist(), g,
                                        np.asarray(generalized_force, dtype=float).tolist()))

    def accelerate(self, c: list[float], s: list[float], xi: list[float], g_body: list[float],
                   q_force: list[float]) -> list[float]:
        """The 1 kHz kernel of :meth:`body_acceleration` on plain floats (lists): the compiled kernel (same
        equations, fpr_sim._kernels) when selected, else :meth:`accelerate_python`. Arguments: see there."""
        if self._compiled is not None:
            result = self._compiled.accelerate(self, c, s, xi, g_body, q_force)
            if result is not None:  # None: singular M̃, the reference raises as it always did
                return result
        return self.accelerate_python(c, s, xi, g_body, q_force)

    def accelerate_python(self, c: list[float], s: list[float], xi: list[float], g_body: list[float],
                          q_force: list[float]) -> list[float]:
        """The 1 kHz kernel of :meth:`body_acceleration` on plain floats (lists), few numpy calls (reference).

        ``c``, ``s``: cos θ_i, sin θ_i; ``xi`` = [u, ω, θ̇] (6+n); ``g_body`` = R_pᵀ g_vec (3); ``q_force`` Q̃ (6+n).
        Returns ξ̇ (6+n). Same equations as the module doc: M̃ from the fitted basis (one matmul), the rows
        ``B_ik ξ`` of every leg basis matrix (one matmul) give both ``Σ θ̇_i ∂_iM̃ ξ`` and ``½ ξᵀ ∂_iM̃ ξ``, the
        Kirchhoff terms b(ξ) in floats, and a Cholesky solve (M̃ is symmetric positive definite).
        """
        n = self.n
        coef = [1.0]
        rate_weights = []  # θ̇_i · d/dθ_i [c, s, c2, s2] = θ̇_i [-s, c, -2 s2, 2 c2]
        slopes = []  # d/dθ_i [c, s, c2, s2]
        for i in range(n):
            ci = c[i]
            si = s[i]
            c2 = ci * ci - si * si
            s2 = 2.0 * si * ci
            coef += (ci, si, c2, s2)
            rate = xi[6 + i]
            slopes += (-si, ci, -2.0 * s2, 2.0 * c2)
            rate_weights += (-si * rate, ci * rate, -2.0 * s2 * rate, 2.0 * c2 * rate)
        n9 = 6 + n
        M = (np.array(coef) @ self._basis).reshape(n9, n9)
        pair = np.array([xi, g_body + [0.0] * (3 + n)])  # rows ξ and [g_b, 0]
        xi_arr = pair[0]
        mu, gravity_rhs = (pair @ M).tolist()  # M̃ symmetric: ξᵀ M̃ = (M̃ ξ)ᵀ; gravity: M̃[:, :3] g_b
        rows = (self._leg_basis_stack @ xi_arr).reshape(4 * n, n9)  # B_ik ξ
        m_dot_xi = (np.array(rate_weights) @ rows).tolist()  # Σ_i θ̇_i ∂_iM̃ ξ  (= dM̃/dt ξ)
        quadratic = (rows @ xi_arr).tolist()  # ξᵀ B_ik ξ
        u0, u1, u2, w0, w1, w2 = xi[:6]
        p0, p1, p2, r0, r1, r2 = mu[:6]
        rhs = [gravity_rhs[k] + q_force[k] - m_dot_xi[k] for k in range(n9)]
        rhs[0] += p1 * w2 - p2 * w1
        rhs[1] += p2 * w0 - p0 * w2
        rhs[2] += p0 * w1 - p1 * w0
        rhs[3] += r1 * w2 - r2 * w1 + p1 * u2 - p2 * u1
        rhs[4] += r2 * w0 - r0 * w2 + p2 * u0 - p0 * u2
        rhs[5] += r0 * w1 - r1 * w0 + p0 * u1 - p1 * u0
        for i in range(n):
            k = 4 * i
            rhs[6 + i] += 0.5 * (slopes[k] * quadratic[k] + slopes[k + 1] * quadratic[k + 1]
                                 + slopes[k + 2] * quadratic[k + 2] + slopes[k + 3] * quadratic[k + 3])
        _, solution, info = _cholesky_solve(M, rhs)
        if info != 0:  # not positive definite (never for a physical parameter set): general solver
            return np.linalg.solve(M, np.array(rhs)).tolist()
        return solution.tolist()

    def forward_dynamics(self, state: StructureState, tau: np.ndarray) -> np.ndarray:
        """ν̇ for the generalized force τ = [f_p (F0), m_p (Fp), m_l] (thesis (2.86) solved), fpr_model layout."""
        R = quat_to_rotmat(state.quat)
        xi = np.concatenate([R.T @ state.velocity, state.rate, state.leg_rates])
        q_force = np.array(tau, dtype=float)
        q_force[:3] = R.T @ q_force[:3]
        xi_dot = self.body_acceleration(state.leg_angles, xi, R.T @ self.gravity_vector, q_force)
        nu_dot = xi_dot.copy()
        nu_dot[:3] = R @ (xi_dot[:3] + np.cross(xi[3:6], xi[:3]))
        return nu_dot

    def first_moment_body(self, leg_angles: np.ndarray) -> np.ndarray:
        """Total first moment h = Σ m_k ρ_k about P in Fp [kg m], read from M̃ (its u-ω block is −[h]×)."""
        M = self.body_mass_matrix(leg_angles)
        return np.array([M[1, 5], M[2, 3], M[0, 4]])

    def energy(self, state: StructureState) -> float:
        """Kinetic + gravitational potential energy [J] (potential zero at z = 0)."""
        R = quat_to_rotmat(state.quat)
        xi = np.concatenate([R.T @ state.velocity, state.rate, state.leg_rates])
        M = self.body_mass_matrix(state.leg_angles)
        mass = M[0, 0]
        h = np.array([M[1, 5], M[2, 3], M[0, 4]])
        potential = -self.gravity_vector @ (mass * state.position + R @ h)
        return 0.5 * xi @ M @ xi + float(potential)


def _fit_mass_matrix_basis(params: FprParameters) -> tuple[np.ndarray, np.ndarray, float]:
    """Fit M̃(θ) = K0 + Σ_i (c_i B_i1 + s_i B_i2 + c2_i B_i3 + s2_i B_i4) from fpr_model's mass matrix.

    At R_p = 1 (identity platform attitude) M̃ = M. Returns K0 (9, 9), the leg basis (n, 4, 9, 9) and the
    largest fit residual relative to max|M| (raises if the structure assumption does not hold).
    """
    from fpr_model.dynamics import mass_matrix

    n = params.n
    n9 = 6 + n

    def sample(angles: np.ndarray) -> np.ndarray:
        q = np.concatenate([np.zeros(3), [1.0, 0.0, 0.0, 0.0], angles])
        return np.asarray(mass_matrix(params, q), dtype=float)

    reference = np.full(n, _FIT_REFERENCE_ANGLE)
    design = np.stack([np.ones_like(_FIT_SAMPLES), np.cos(_FIT_SAMPLES), np.sin(_FIT_SAMPLES),
                       np.cos(2 * _FIT_SAMPLES), np.sin(2 * _FIT_SAMPLES)], axis=1)
    leg_basis = np.zeros((n, 4, n9, n9))
    worst = 0.0
    scale = 0.0
    for i in range(n):
        samples = []
        for angle in _FIT_SAMPLES:
            angles = reference.copy()
            angles[i] = angle
            samples.append(sample(angles).reshape(-1))
        data = np.array(samples)
        coefficients, *_ = np.linalg.lstsq(design, data, rcond=None)
        worst = max(worst, float(np.abs(design @ coefficients - data).max()))
        scale = max(scale, float(np.abs(data).max()))
        leg_basis[i] = coefficients[1:].reshape(4, n9, n9)
    c, s = np.cos(_FIT_REFERENCE_ANGLE), np.sin(_FIT_REFERENCE_ANGLE)
    ref_terms = np.array([c, s, c * c - s * s, 2 * s * c])
    base = sample(reference) - np.einsum("k,ikab->ab", ref_terms, leg_basis)
    residual = worst / max(scale, 1e-300)
    if residual > 1e-9:
        raise ValueError(f"mass-matrix basis fit residual {residual:.2e}: M(θ) is not of the assumed form")
    return base, leg_basis, residual
