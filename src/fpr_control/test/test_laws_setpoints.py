"""Laws (3.25)-(3.31), (4.27)-(4.29), setpoints (3.36)-(3.38), (4.38), reference (4.25)-(4.26), NC (4.32)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fpr_control.controller import DEFAULT_GAINS, gains_from_dict
from fpr_control.information import InformationTable, LocalEstimate, PeerInfo, reconstruct_state
from fpr_control.laws import (
    ImpedanceGains,
    PidMotionLaw,
    compute_model_terms,
    configuration_error,
    control_wrench,
    impedance_acceleration,
    interaction_force_selection,
    wrench_tracking_error,
)
from fpr_control.reference import CentralizedReference, TeleopReference, decentralized_reference
from fpr_control.setpoints import local_frame_attitude, saturate_thrust_vector
from fpr_model.dynamics import forward_dynamics, thrusts_from_wrench
from fpr_model.geometry import desired_uav_rotation, make_configuration
from fpr_model.kinematics import jacobian
from fpr_model.parameters import default_parameters
from fpr_model.rotations import (
    euler_rate_matrix,
    euler_zyx_to_quat,
    quat_from_axis_angle,
    quat_multiply,
    quat_to_euler_zyx,
    quat_to_rotmat,
)

PARAMS = default_parameters(3)
RNG = np.random.default_rng(7)


def _random_state():
    q = make_configuration(RNG.normal(size=3), euler_zyx_to_quat(*RNG.uniform(-0.3, 0.3, 3)),
                           RNG.uniform(0.4, 1.2, 3))
    return q, RNG.normal(scale=0.3, size=9)


def test_configuration_error_small_angle_is_half_rotation():
    q = make_configuration([0, 0, 1], [1, 0, 0, 0], [0.7] * 3)
    q_d = make_configuration([0.1, 0, 1.2], quat_from_axis_angle([1, 0, 0], 0.02), [0.8] * 3)
    error = configuration_error(q, q_d)
    assert np.allclose(error[:3], [0.1, 0.0, 0.2])
    assert error[3] == pytest.approx(math.sin(0.01), abs=1e-12)  # ε_o ≈ δφ/2 (spec §0.3)
    assert np.allclose(error[6:], 0.1)
    assert np.allclose(configuration_error(q, q_d, use_position=False)[:3], 0.0)  # (4.29)
    # sgn(q_err,0): the double cover gives the same error
    q_d2 = q_d.copy()
    q_d2[3:7] *= -1
    assert np.allclose(configuration_error(q, q_d2), error)


def test_perfect_estimate_gives_the_desired_impedance():
    """C1: τ̂ = τ_e and the same model in the plant ⇒ ν̇ = u (3.30) and (3.25) holds to 1e-9."""
    gains = gains_from_dict({}, 3).impedance_centralized
    for _ in range(5):
        q, nu = _random_state()
        q_d, _ = _random_state()
        nu_d, nu_dot_d = RNG.normal(size=9), RNG.normal(size=9)
        tau_e, tau_d = RNG.normal(size=9), RNG.normal(size=9)
        terms = compute_model_terms(PARAMS, q, nu)
        error = configuration_error(q, q_d)
        eps_tau = wrench_tracking_error(tau_e, tau_d)
        u = impedance_acceleration(gains, error, nu, nu_d, nu_dot_d, eps_tau)
        tau = control_wrench(terms, u, nu, tau_e)
        f = thrusts_from_wrench(PARAMS, q, tau)
        nu_dot = forward_dynamics(PARAMS, q, nu, jacobian(PARAMS, q).T @ f.reshape(-1), tau_e)
        assert np.allclose(nu_dot, u, atol=1e-9)
        residual = (gains.inertia * (nu_dot_d - nu_dot) + gains.damping * (nu_d - nu)
                    + gains.stiffness * error - eps_tau)
        assert np.abs(residual).max() < 1e-8


def test_interaction_force_selection():
    """S = d dᵀ along the desired interaction force, 0 without one; ε_τ keeps (3.26) outside the force rows and
    along d, and drops the estimated force across d (decentralized position rows)."""
    assert np.array_equal(interaction_force_selection(np.zeros(3)), np.zeros((3, 3)))
    normal = quat_to_rotmat(euler_zyx_to_quat(0.2, -0.1, 0.0))[:, 2]
    S = interaction_force_selection(5.0 * normal)
    assert np.allclose(S, np.outer(normal, normal)) and np.allclose(S @ S, S)
    tau_hat, tau_d = RNG.normal(size=9), np.concatenate([5.0 * normal, np.zeros(6)])
    assert np.array_equal(wrench_tracking_error(tau_hat, tau_d), -tau_hat - tau_d)  # (3.26)
    eps = wrench_tracking_error(tau_hat, tau_d, S)
    assert np.allclose(eps[3:], -tau_hat[3:])
    assert np.allclose(eps[:3], -normal * (normal @ tau_hat[:3] + 5.0))  # contact force error along the normal
    free = wrench_tracking_error(tau_hat, np.zeros(9), interaction_force_selection(np.zeros(3)))
    assert np.allclose(free[:3], 0.0) and np.allclose(free[3:], -tau_hat[3:])


def test_damping_ratios_of_the_tables():
    """C9: ζ = B/(2 sqrt(K M)) = 0.447, 0.884, 1.155 (Table 3.1)."""
    g = DEFAULT_GAINS["impedance_centralized"]
    zeta = [b / (2 * math.sqrt(k * m)) for m, b, k in zip(g["inertia"], g["damping"], g["stiffness"], strict=True)]
    assert np.allclose(zeta, [0.447, 0.884, 1.155], atol=1e-3)
    assert gains_from_dict({}, 3).impedance_centralized.stiffness[2] == 25.0
    assert isinstance(gains_from_dict({}, 4).impedance_decentralized, ImpedanceGains)


@pytest.mark.parametrize("zone", [None, [0.1, 0.02, 0.02]])
def test_pid_anti_windup(zone):
    """Saturation |K_i ∫ε| <= integral_limit always (the thesis's rule, the default); with an integral zone, an error
    outside it is not integrated at all."""
    gains = gains_from_dict({} if zone is None else {"pid_centralized": {"integral_zone": zone}}, 3).pid_centralized
    law = PidMotionLaw(gains)
    error = np.full(9, 0.01)
    for _ in range(10000):
        law.acceleration(error, np.zeros(9), np.zeros(9), np.zeros(9), 0.02)
    integral_term = gains.ki * law.integral
    assert np.all(np.abs(integral_term) <= gains.integral_limit + 1e-12)
    assert integral_term[2] == pytest.approx(2.0)  # the bound is reached
    law.reset()
    big = np.full(9, 0.5)
    law.acceleration(big, np.zeros(9), np.zeros(9), np.zeros(9), 0.02)
    if zone is None:  # integrated: the default has no zone
        assert np.all(law.integral == pytest.approx(0.5 * 0.02))
    else:  # outside the integration zone: not integrated
        assert np.all(law.integral == 0.0)


@pytest.mark.parametrize("tilt", [0.0, 0.2, 0.5])
def test_setpoint_attitude_rule(tilt):
    """C8: f_t = ‖f‖, R^d ∈ SO(3), z_b = f/‖f‖, angle(−l_⊥ -> x_b) about z_b = β."""
    beta = PARAMS.joint_offset_angle
    f = 12.0 * np.array([math.sin(tilt) * math.cos(0.4), math.sin(tilt) * math.sin(0.4), math.cos(tilt)])
    leg = np.array([math.cos(0.7), math.sin(0.7), -1.0]) / math.sqrt(2.0)
    R = desired_uav_rotation(f, leg, beta)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    z = f / np.linalg.norm(f)
    assert np.allclose(R[:, 2], z, atol=1e-12)
    perpendicular = -(leg - z * (leg @ z))
    perpendicular /= np.linalg.norm(perpendicular)
    angle = math.atan2(np.cross(perpendicular, R[:, 0]) @ z, perpendicular @ R[:, 0])
    assert angle == pytest.approx(beta, abs=1e-9)


def test_saturations():
    s = saturate_thrust_vector(np.array([0.0, 0.0, 40.0]), 25.0, math.radians(35))
    assert s.thrust_saturated and not s.tilt_saturated and np.linalg.norm(s.vector) == pytest.approx(25.0)
    s = saturate_thrust_vector(np.array([10.0, 0.0, 5.0]), 25.0, math.radians(35))
    assert s.tilt_saturated and math.degrees(math.acos(s.vector[2] / np.linalg.norm(s.vector))) == pytest.approx(35)
    assert s.vector[0] > 0 and abs(s.vector[1]) < 1e-12
    s = saturate_thrust_vector(np.array([0.0, 0.0, -5.0]), 25.0, math.radians(35))  # pointing down
    assert s.tilt_saturated and s.vector[2] > 0
    assert np.all(saturate_thrust_vector(np.array([np.nan, 0, 1]), 25.0, 0.6).vector == 0.0)


def test_yaw_reexpressed_in_local_frame():
    """(4.38): roll/pitch kept, ψ_0i = ψ_0i,meas + (ψ^d_F − ψ_F)."""
    R = quat_to_rotmat(euler_zyx_to_quat(0.1, -0.2, 0.5))
    quat = local_frame_attitude(R, uav_yaw_in_frame=0.4, uav_yaw_local=2.0)
    roll, pitch, yaw = quat_to_euler_zyx(quat)
    assert (roll, pitch) == pytest.approx((0.1, -0.2), abs=1e-12)
    assert yaw == pytest.approx(2.1, abs=1e-12)
    # equivalently: the local frame is F rotated by the yaw offset (2.0 − 0.4) about z
    offset = euler_zyx_to_quat(0.0, 0.0, -(2.0 - 0.4))
    in_frame = quat_multiply(offset, quat)
    assert np.allclose(quat_to_rotmat(in_frame), R, atol=1e-12)


def test_decentralized_reference_4_26():
    cmd = TeleopReference(np.array([0.1, 0.2, 0.0]), np.array([0.0, 0.1, 0.0]), 0.3, 0.05, 0.1, 0.02, -0.1,
                          0.03, np.full(3, 0.8), np.full(3, 0.01), 4.0)
    rotation = quat_to_rotmat(euler_zyx_to_quat(0.05, -0.08, 0.0))
    desired = decentralized_reference(cmd, 0.05, -0.08, rotation)
    D = euler_rate_matrix(0.05, -0.08)
    assert np.allclose(desired.nu[3:6], D @ [0.02, 0.03, 0.3])
    assert np.allclose(desired.nu[:3], cmd.platform_velocity) and np.allclose(desired.nu[6:], 0.01)
    assert np.allclose(desired.nu_dot[6:], 0.0)
    assert np.allclose(desired.q[:3], 0.0)
    assert quat_to_euler_zyx(desired.q[3:7]) == pytest.approx((0.1, -0.1, 0.0), abs=1e-12)
    assert np.allclose(desired.wrench[:3], rotation[:, 2] * 4.0) and np.allclose(desired.wrench[3:], 0.0)


def test_centralized_reference_integrates_velocity_and_yaw():
    ref = CentralizedReference()
    ref.reset(np.array([1.0, 2.0, 3.0]), math.pi / 2)
    cmd = TeleopReference.hold(0.0, 0.0, np.full(3, 0.8))
    cmd.platform_velocity = np.array([1.0, 0.0, 0.5])
    for _ in range(50):
        desired = ref.step(cmd, 0.02, 0.0, 0.0, np.eye(3))
    assert np.allclose(desired.q[:3], [1.0, 3.0, 3.5], atol=1e-12)  # x of F_Fp points along +y of F0


def test_information_table_ages_and_rejections():
    table = InformationTable(3, 1, 0.2)
    good = PeerInfo(2, 0.8, np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0)
    assert table.update(good, 1.0) is None
    assert not table.all_fresh(1.0)  # uav 3 never heard
    assert table.update(PeerInfo(3, 0.8, np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0), 1.05) is None
    assert not table.all_fresh(1.1)  # the own ζ_1 has not come back from the shared topic yet
    assert table.update(PeerInfo(1, 0.8, np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0), 1.1) is None
    assert table.all_fresh(1.2) and not table.all_fresh(1.21)
    assert InformationTable(3, 1, 0.2, require_own_echo=False).update(good, 1.0) is None
    assert np.allclose(table.ages(1.1), [0.0, 0.1, 0.05])
    bad = PeerInfo(3, float("nan"), np.zeros(3), np.array([1.0, 0, 0, 0]), 11.0)
    assert table.update(bad, 2.0) is not None
    assert table.ages(2.0)[2] == pytest.approx(0.95)  # not refreshed by the bad vector
    assert table.update(PeerInfo(7, 0.8, np.zeros(3), np.array([1.0, 0, 0, 0]), 1.0), 2.0) is not None


def test_nc_substitution_4_32():
    """NC: the others' leg angles = desired, their velocities = (J(q) ν^d)_j; with the own UAV also on its
    desired velocity the FKM returns ν^d exactly."""
    cmd = TeleopReference(np.array([0.1, -0.2, 0.05]), np.zeros(3), 0.2, 0.0, 0.05, 0.0, 0.02, 0.0,
                          np.array([0.7, 0.8, 0.9]), np.array([0.01, -0.02, 0.03]))
    rotation = quat_to_rotmat(euler_zyx_to_quat(0.05, 0.02, 0.0))
    desired = decentralized_reference(cmd, 0.05, 0.02, rotation)
    q = np.concatenate([np.zeros(3), euler_zyx_to_quat(0.05, 0.02, 0.0), desired.q[7:]])
    own_velocity = (jacobian(PARAMS, q) @ desired.nu).reshape(3, 3)[1]
    local = LocalEstimate(0.8, 0.05, 0.02, np.array([1.0, 0, 0, 0]), own_velocity, 0.0, 0.0)
    state = reconstruct_state(PARAMS, 2, local, None, desired.q[7:], desired.nu)
    assert np.allclose(state.nu, desired.nu, atol=1e-12)
    assert np.allclose(state.q[7:], [0.7, 0.8, 0.9])
