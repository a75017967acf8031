"""Tests of fpr_model.dynamics: Table 2.1, Ṁ = C + Cᵀ, gravity (E2), actuation, equilibrium, energy."""

import dataclasses

import numpy as np
import pytest
from fpr_model.dynamics import (
    actuation_wrench,
    bias_forces,
    coriolis_matrix,
    forward_dynamics,
    gravity,
    integrate_configuration,
    inverse_dynamics,
    kinetic_energy,
    mass_matrix,
    mass_matrix_rnea,
    potential_energy,
    rk4_step,
    thrusts_from_wrench,
)
from fpr_model.geometry import make_configuration
from fpr_model.kinematics import SingularConfigurationError, jacobian
from fpr_model.parameters import default_parameters
from fpr_model.selfcheck import reference_state

TABLE_TOLERANCE = 1e-12


LOW, HIGH = np.radians(10), np.radians(80)


def _random_state(n, rng, low=LOW, high=HIGH):
    q = make_configuration(rng.normal(size=3), rng.normal(size=4), rng.uniform(low, high, n))
    return q, rng.normal(size=6 + n)


def _table_2_1(p, q, nu):
    zero = np.zeros(6 + p.n)
    dm = np.abs(mass_matrix_rnea(p, q) - mass_matrix(p, q)).max()
    dc = np.abs(inverse_dynamics(p, q, nu, zero, gravity=False) - coriolis_matrix(p, q, nu) @ nu).max()
    dg = np.abs(inverse_dynamics(p, q, zero, zero) - gravity(p, q)).max()
    return dm, dc, dg


@pytest.mark.parametrize("n", [3, 4, 6])
def test_table_2_1_at_thesis_state(n):
    p = default_parameters(n)
    q, nu = reference_state(n)
    assert max(_table_2_1(p, q, nu)) <= TABLE_TOLERANCE


def test_table_2_1_random_states():
    rng = np.random.default_rng(0)
    for k in range(100):
        n = (3, 4, 6)[k % 3]
        p = default_parameters(n)
        q, nu = _random_state(n, rng)
        assert max(_table_2_1(p, q, nu)) <= TABLE_TOLERANCE


def test_batched_rnea_equals_thesis_listing():
    """inverse_dynamics (bodies batched in Fp) vs the thesis's RNEA listing (legs in their own frames)."""
    from fpr_model.dynamics import _rnea_reference
    from fpr_model.geometry import _parse_configuration

    rng = np.random.default_rng(3)
    for k in range(30):
        n = (3, 4, 6)[k % 3]
        p = default_parameters(n)
        q, nu = _random_state(n, rng)
        nu_dot = rng.normal(size=6 + n)
        for with_gravity in (True, False):
            expected = _rnea_reference(p, _parse_configuration(p, q), nu, nu_dot, with_gravity)
            assert np.abs(inverse_dynamics(p, q, nu, nu_dot, gravity=with_gravity) - expected).max() <= 1e-12


def test_mass_matrix_symmetric_positive_definite_and_energy():
    p = default_parameters()
    rng = np.random.default_rng(1)
    for _ in range(20):
        q, nu = _random_state(3, rng)
        M = mass_matrix(p, q)
        assert np.abs(M - M.T).max() <= 1e-15
        assert np.linalg.eigvalsh(M).min() > 0
        assert kinetic_energy(p, q, nu) == pytest.approx(0.5 * nu @ M @ nu, rel=1e-14)
    # Free-floating rigid body limit: the platform block holds the total mass.
    assert np.allclose(M[:3, :3], p.total_mass * np.eye(3))


def test_mass_matrix_independent_of_position_and_yaw_for_leg_block():
    p = default_parameters()
    q, _ = reference_state()
    q2 = q.copy()
    q2[:3] += [5.0, -3.0, 2.0]
    assert np.allclose(mass_matrix(p, q), mass_matrix(p, q2), atol=1e-15)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_mdot_equals_c_plus_ct(n):
    p = default_parameters(n)
    rng = np.random.default_rng(30 + n)
    states = [reference_state(n)] + [_random_state(n, rng) for _ in range(10)]
    h = 1e-6
    for q, nu in states:
        M_dot = (mass_matrix(p, integrate_configuration(q, nu, h))
                 - mass_matrix(p, integrate_configuration(q, nu, -h))) / (2 * h)
        C = coriolis_matrix(p, q, nu)
        assert np.abs(M_dot - C - C.T).max() <= 1e-6 * np.abs(M_dot).max()
        # Skew-symmetry of Ṁ − 2C (2.64).
        S = M_dot - 2 * C
        assert np.abs(S + S.T).max() <= 1e-6 * np.abs(M_dot).max()


def test_coriolis_linear_in_velocity_and_bias_forces():
    p = default_parameters()
    q, nu = reference_state()
    C = coriolis_matrix(p, q, nu)
    assert np.allclose(coriolis_matrix(p, q, 2 * nu), 2 * C, atol=1e-13)
    assert np.allclose(bias_forces(p, q, nu), C @ nu + gravity(p, q), atol=1e-13)


def test_gravity_is_potential_energy_gradient():
    rng = np.random.default_rng(2)
    for n in (3, 4, 6):
        p = default_parameters(n)
        for _ in range(5):
            q, _ = _random_state(n, rng, 0.0, np.pi)
            h = 1e-6
            grad = np.array([(potential_energy(p, integrate_configuration(q, e, h))
                              - potential_energy(p, integrate_configuration(q, e, -h))) / (2 * h)
                             for e in np.eye(6 + n)])
            assert np.abs(grad - gravity(p, q)).max() <= 1e-6


def test_gravity_spec_values_e2():
    p = default_parameters()
    flat45 = make_configuration([0, 0, 0], [1, 0, 0, 0], np.full(3, np.pi / 4))
    w_g = gravity(p, flat45)
    assert w_g[2] == pytest.approx(34.345, abs=1e-3)
    expected = [0, 0, 34.3448, 0.0734, 0.1357, 0, -7.5599, -7.7118, -7.6395]
    assert np.abs(w_g - expected).max() <= 1e-3
    f_g = thrusts_from_wrench(p, flat45, w_g)
    expected_f = [[-1.0931, 0, 11.3436], [0.5466, -0.9467, 11.5496], [0.5466, 0.9467, 11.4515]]
    assert np.abs(f_g - expected_f).max() <= 1e-3
    # Vertical force is the total weight in every configuration.
    q, _ = reference_state()
    assert gravity(p, q)[:3] == pytest.approx([0, 0, p.total_mass * p.gravity])


@pytest.mark.parametrize("n", [3, 6])
def test_actuation_wrench_and_thrusts(n):
    p = default_parameters(n)
    rng = np.random.default_rng(40 + n)
    q, _ = _random_state(n, rng)
    f = rng.normal(size=(n, 3))
    tau = actuation_wrench(p, q, f)
    assert np.allclose(tau, jacobian(p, q).T @ f.reshape(-1), atol=1e-14)
    f_back = thrusts_from_wrench(p, q, tau)
    assert np.allclose(actuation_wrench(p, q, f_back), tau, atol=1e-10)
    if n == 3:
        assert np.allclose(f_back, f, atol=1e-10)
    else:  # minimum-norm solution
        assert np.linalg.norm(f_back) <= np.linalg.norm(f) + 1e-12
    # Virtual power (2.29): νᵀτ = vᵀf.
    nu = rng.normal(size=6 + n)
    assert nu @ tau == pytest.approx((jacobian(p, q) @ nu) @ f.reshape(-1), rel=1e-12)


def test_equilibrium_flat_platform_legs_60():
    p = default_parameters()
    q = make_configuration([0, 0, 1], [1, 0, 0, 0], np.full(3, np.radians(60)))
    f = thrusts_from_wrench(p, q, gravity(p, q))
    nu_dot = forward_dynamics(p, q, np.zeros(9), actuation_wrench(p, q, f))
    assert np.abs(nu_dot).max() <= 1e-9
    assert f[:, 2].sum() == pytest.approx(34.34, abs=0.01)
    assert f[:, 2].sum() == pytest.approx(p.total_mass * p.gravity, abs=1e-9)


def test_thrusts_from_wrench_singular():
    p = default_parameters()
    with pytest.raises(SingularConfigurationError):
        thrusts_from_wrench(p, make_configuration([0, 0, 0], [1, 0, 0, 0], np.zeros(3)), np.zeros(9))


@pytest.mark.parametrize("n", [3, 6])
def test_forward_and_inverse_dynamics_agree(n):
    p = default_parameters(n)
    rng = np.random.default_rng(50 + n)
    for _ in range(10):
        q, nu = _random_state(n, rng)
        tau, tau_e = rng.normal(size=(2, 6 + n))
        nu_dot = forward_dynamics(p, q, nu, tau, external_wrench=tau_e)
        assert np.allclose(inverse_dynamics(p, q, nu, nu_dot), tau + tau_e, atol=1e-10)
        M, C, g = mass_matrix(p, q), coriolis_matrix(p, q, nu), gravity(p, q)
        assert np.allclose(M @ nu_dot + C @ nu + g, tau + tau_e, atol=1e-10)
        assert np.allclose(forward_dynamics(p, q, nu, tau, gravity=False),
                           np.linalg.solve(M, tau - C @ nu), atol=1e-10)


def _energy_drift(p, q, nu, dt, duration, with_gravity):
    def energy(qs, vs):
        return kinetic_energy(p, qs, vs) + (potential_energy(p, qs) if with_gravity else 0.0)

    tau = np.zeros(6 + p.n)
    e0, drift, kinetic_max = energy(q, nu), 0.0, kinetic_energy(p, q, nu)
    for _ in range(int(round(duration / dt))):
        q, nu = rk4_step(p, q, nu, tau, dt)
        drift = max(drift, abs(energy(q, nu) - e0))
        kinetic_max = max(kinetic_max, kinetic_energy(p, q, nu))
    assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-14
    return drift / kinetic_max


def test_energy_conservation_rk4():
    """Unactuated structure, RK4 at 1 kHz for 5 s: energy kept to 1e-6 relative (to the largest kinetic
    energy of the run); halving the step cuts the drift ~16× (DESIGN.md §7).

    The free legs swing far over 5 s whatever the start; with larger velocities they can fold into the
    platform plane, where M is ill-conditioned, the structure spins up and the h⁴ drift grows (e.g. 3e-4
    with ν ~ 0.5·N(0, 1) from this start): hence the moderate ν ~ 0.2·N(0, 1).
    """
    rng = np.random.default_rng(7)
    angles = rng.uniform(np.radians(35), np.radians(55), 3)
    q = make_configuration(rng.normal(size=3), rng.normal(size=4), angles)
    nu = 0.2 * rng.normal(size=9)
    p = default_parameters()
    no_gravity = dataclasses.replace(p, gravity=0.0)
    assert _energy_drift(no_gravity, q, nu, 1e-3, 5.0, False) <= 1e-6
    assert _energy_drift(p, q, nu, 1e-3, 5.0, True) <= 1e-6
    rng = np.random.default_rng(0)
    angles = rng.uniform(np.radians(30), np.radians(70), 3)
    q = make_configuration(rng.normal(size=3), rng.normal(size=4), angles)
    nu = 0.5 * rng.normal(size=9)
    coarse = _energy_drift(no_gravity, q, nu, 4e-3, 1.0, False)
    fine = _energy_drift(no_gravity, q, nu, 2e-3, 1.0, False)
    assert 10.0 < coarse / fine < 24.0


def test_rk4_free_fall_and_hover():
    p = default_parameters()
    q = make_configuration([0, 0, 0], [1, 0, 0, 0], np.full(3, np.radians(60)))
    zero = np.zeros(9)
    q1, nu1 = rk4_step(p, q, zero, zero, 0.1)
    assert np.allclose(nu1, [0, 0, -0.981, 0, 0, 0, 0, 0, 0], atol=1e-12)
    assert q1[2] == pytest.approx(-0.5 * 9.81 * 0.01, abs=1e-12)
    hover = actuation_wrench(p, q, thrusts_from_wrench(p, q, gravity(p, q)))
    q2, nu2 = rk4_step(p, q, zero, hover, 0.1)
    assert np.allclose(q2, q, atol=1e-12) and np.abs(nu2).max() <= 1e-12


def test_bad_input_names_argument():
    p = default_parameters()
    q, nu = reference_state()
    bad = np.r_[nu[:-1], np.nan]
    with pytest.raises(ValueError, match="nu_dot"):
        inverse_dynamics(p, q, nu, bad)
    with pytest.raises(ValueError, match="nu"):
        coriolis_matrix(p, q, bad)
    with pytest.raises(ValueError, match="tau"):
        forward_dynamics(p, q, nu, bad)
    with pytest.raises(ValueError, match="external_wrench"):
        forward_dynamics(p, q, nu, nu, external_wrench=np.zeros(8))
    with pytest.raises(ValueError, match="thrusts"):
        actuation_wrench(p, q, np.full((3, 3), np.inf))
    with pytest.raises(ValueError, match="thrusts"):
        actuation_wrench(p, q, np.zeros(8))
    with pytest.raises(ValueError, match="dt"):
        rk4_step(p, q, nu, nu, float("nan"))
    with pytest.raises(ValueError, match="q"):
        mass_matrix(p, np.r_[q[:-1], np.inf])
    with pytest.raises(ValueError, match="q"):
        gravity(p, q[:-1])
    with pytest.raises(ValueError, match="tau"):
        thrusts_from_wrench(p, q, np.zeros(10))
