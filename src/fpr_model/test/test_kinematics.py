"""Tests of fpr_model.kinematics: J (2.20) vs IGM (spec M1), J̇ (2.23), FKM (2.21), (2.24), singularities
(M4)."""

import numpy as np
import pytest
from fpr_model.geometry import (
    difference_configuration,
    integrate_configuration,
    inverse_geometric_model,
    make_configuration,
)
from fpr_model.kinematics import (
    SingularConfigurationError,
    check_regular_configuration,
    forward_acceleration,
    forward_kinematics,
    jacobian,
    jacobian_at,
    jacobian_dot,
    uav_accelerations,
    uav_velocities,
)
from fpr_model.parameters import default_parameters
from fpr_model.selfcheck import reference_state

from fpr_model import kinematics


def _random_state(n, rng):
    q = make_configuration(rng.normal(size=3), rng.normal(size=4), rng.uniform(0.2, 1.4, n))
    return q, rng.normal(size=6 + n)


def _jacobian_fd(params, q, h=1e-6):
    columns = []
    for e in np.eye(6 + params.n):
        plus = inverse_geometric_model(params, integrate_configuration(q, e, h))
        minus = inverse_geometric_model(params, integrate_configuration(q, e, -h))
        columns.append((plus - minus).reshape(-1) / (2 * h))
    return np.column_stack(columns)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_m1_jacobian_central_difference(n):
    p = default_parameters(n)
    q, _ = reference_state(n)
    assert np.abs(jacobian(p, q) - _jacobian_fd(p, q)).max() <= 1e-8
    rng = np.random.default_rng(n)
    for _ in range(10):
        q, _ = _random_state(n, rng)
        assert np.abs(jacobian(p, q) - _jacobian_fd(p, q)).max() <= 1e-8


def test_m1_igm_vs_ikm_thesis_procedure():
    """Thesis §2.6: δq ~ N(0, 0.001), ν′ takes q to q + δq in unit time (quaternion renormalised, exact log
    map).

    The one-sided residual r = IGM(q+δq) − IGM(q) − J ν′ is second order in ν′: its median over draws is below
    the thesis's 1e-5 and every draw obeys the Taylor bound ‖r‖ ≤ √n (r + l) ‖ν′_rot,legs‖². The central
    residual isolates errors of J and is ≤ 1e-6 for every draw.
    """
    p = default_parameters()
    q, _ = reference_state()
    J = jacobian(p, q)
    p0 = inverse_geometric_model(p, q).reshape(-1)
    rng = np.random.default_rng(0)
    one_sided, central = [], []
    for _ in range(200):
        q1 = q + rng.normal(0.0, 0.001, 10)
        q1[3:7] /= np.linalg.norm(q1[3:7])
        nu_prime = difference_configuration(q, q1)
        forward = inverse_geometric_model(p, q1).reshape(-1)
        backward = inverse_geometric_model(p, integrate_configuration(q, nu_prime, -1.0)).reshape(-1)
        residual = np.linalg.norm(forward - p0 - J @ nu_prime)
        bound = np.sqrt(3) * (p.platform_radius + p.leg_length) * np.sum(nu_prime[3:] ** 2)
        assert residual <= bound
        one_sided.append(residual)
        central.append(np.linalg.norm(0.5 * (forward - backward) - J @ nu_prime))
    assert np.median(one_sided) <= 1e-5
    assert max(central) <= 1e-6
    # Second order: scaling δq by 1/2 divides the residual by 4.
    nu_prime = rng.normal(0.0, 0.001, 9)
    r1 = np.linalg.norm(inverse_geometric_model(p, integrate_configuration(q, nu_prime, 1.0)).reshape(-1)
                        - p0 - J @ nu_prime)
    r2 = np.linalg.norm(inverse_geometric_model(p, integrate_configuration(q, nu_prime, 0.5)).reshape(-1)
                        - p0 - J @ (0.5 * nu_prime))
    assert 3.8 < r1 / r2 < 4.2


@pytest.mark.parametrize("n", [3, 6])
def test_jacobian_dot_vs_finite_difference(n):
    p = default_parameters(n)
    rng = np.random.default_rng(10 + n)
    for _ in range(10):
        q, nu = _random_state(n, rng)
        h = 1e-6
        fd = (jacobian(p, integrate_configuration(q, nu, h))
              - jacobian(p, integrate_configuration(q, nu, -h))) / (2 * h)
        assert np.abs(jacobian_dot(p, q, nu) - fd).max() <= 1e-7


def test_m4_determinant_and_singularity():
    p = default_parameters()
    flat45 = make_configuration([0, 0, 0], [1, 0, 0, 0], np.full(3, np.pi / 4))
    assert np.linalg.det(jacobian(p, flat45)) == pytest.approx(-1.750, abs=1e-3)
    flat90 = make_configuration([0, 0, 0], [1, 0, 0, 0], np.full(3, np.pi / 2))
    assert np.linalg.det(jacobian(p, flat90)) == pytest.approx(-0.0157, abs=1e-4)
    flat0 = make_configuration([0, 0, 0], [1, 0, 0, 0], np.zeros(3))
    assert abs(np.linalg.det(jacobian(p, flat0))) < 1e-15
    with pytest.raises(SingularConfigurationError):
        forward_kinematics(p, flat0, np.zeros((3, 3)))
    with pytest.raises(SingularConfigurationError):
        forward_kinematics(p, flat0, np.zeros((3, 3)), check_leg_range=False)  # cond(J) check alone
    with pytest.raises(SingularConfigurationError, match="leg"):
        forward_kinematics(p, make_configuration([0, 0, 0], [1, 0, 0, 0], [0.5, 1.7, 0.5]), np.zeros(9))
    assert isinstance(SingularConfigurationError("x"), ValueError)
    assert check_regular_configuration(p, flat45) < 10


@pytest.mark.parametrize("n", [3, 4, 6])
def test_forward_models_invert_inverse_models(n):
    p = default_parameters(n)
    rng = np.random.default_rng(20 + n)
    for _ in range(10):
        q, nu = _random_state(n, rng)
        nu_dot = rng.normal(size=6 + n)
        v = uav_velocities(p, q, nu)
        assert v.shape == (n, 3)
        assert np.allclose(forward_kinematics(p, q, v), nu, atol=1e-10)
        assert np.allclose(forward_kinematics(p, q, v.reshape(-1)), nu, atol=1e-10)
        a = uav_accelerations(p, q, nu, nu_dot)
        assert np.allclose(forward_acceleration(p, q, nu, a), nu_dot, atol=1e-9)


def test_bad_input_names_argument():
    p = default_parameters()
    q, nu = reference_state()
    with pytest.raises(ValueError, match="nu"):
        jacobian_dot(p, q, np.r_[nu[:-1], np.inf])
    with pytest.raises(ValueError, match="uav_velocities"):
        forward_kinematics(p, q, np.zeros(8))
    with pytest.raises(ValueError, match="uav_velocities"):
        forward_kinematics(p, q, np.full(9, np.nan))
    with pytest.raises(ValueError, match="q"):
        jacobian(p, np.full(10, np.nan))


@pytest.mark.parametrize("n", [3, 4, 6])
def test_jacobian_at_pseudo_inverse(n):
    """J^† of JacobianAt: ν = J^† J ν (FKM), and the thrusts f = (J^†)ᵀ τ solve Jᵀ f = τ with the least norm
    (f in the range of J: f = J (JᵀJ)^{-1} τ, the printed (3.32) for n > 3)."""
    p = default_parameters(n)
    rng = np.random.default_rng(60 + n)
    for _ in range(10):
        q, nu = _random_state(n, rng)
        at = jacobian_at(p, q)
        J = jacobian(p, q)
        assert np.array_equal(at.matrix, J)
        assert np.allclose(at.velocity(J @ nu), nu, atol=1e-11)
        tau = rng.normal(size=6 + n)
        f = at.thrusts(tau)
        assert f.shape == (n, 3)
        assert np.allclose(J.T @ f.reshape(-1), tau, atol=1e-11)
        assert np.allclose(f.reshape(-1), J @ np.linalg.solve(J.T @ J, tau), atol=1e-10)


@pytest.mark.parametrize("n", [3, 6])
def test_singularity_test_accepts_exactly_cond_below_the_limit(n, monkeypatch):
    """The Frobenius bound ‖J‖_F ‖J^†‖_F ≥ cond(J) with the exact cond(J) as fallback accepts exactly the
    configurations with np.linalg.cond(J) ≤ CONDITION_LIMIT: with the limit moved into the range of cond(J) of
    random states, some are accepted by the bound, some only by the fallback, the rest refused."""
    p = default_parameters(n)
    rng = np.random.default_rng(70 + n)
    states = [make_configuration(rng.normal(size=3), rng.normal(size=4), np.exp(rng.uniform(-7.0, 0.4, n)))
              for _ in range(200)]  # leg angles log-uniform in [1e-3, 1.5] rad: cond(J) from about 6 to 1e4
    conditions = np.array([np.linalg.cond(jacobian(p, q)) for q in states])
    limit = float(np.median(conditions))
    monkeypatch.setattr(kinematics, "CONDITION_LIMIT", limit)
    outcomes = {"bound": 0, "fallback": 0, "refused": 0}
    for q, condition in zip(states, conditions, strict=True):
        at = jacobian_at(p, q, check_leg_range=False)
        if condition > limit:
            with pytest.raises(SingularConfigurationError, match="cond"):
                at.inverse  # noqa: B018
            outcomes["refused"] += 1
        else:
            inverse = at.inverse
            bound = np.linalg.norm(at.matrix) * np.linalg.norm(inverse)
            outcomes["bound" if bound <= limit else "fallback"] += 1
    assert min(outcomes.values()) > 0, outcomes
