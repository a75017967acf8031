"""Tests of fpr_model.rotations: spec §4.6 X1-X6 and the public API."""

import numpy as np
import pytest

from fpr_model import rotations as rt


def _random_quats(count, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _same_attitude(a, b, tol):
    return min(np.abs(a - b).max(), np.abs(a + b).max()) <= tol


def test_elementary_rotations_match_appendix_a():
    a = 0.3
    c, s = np.cos(a), np.sin(a)
    assert np.allclose(rt.rot_x(a), [[1, 0, 0], [0, c, -s], [0, s, c]], atol=0)
    assert np.allclose(rt.rot_y(a), [[c, 0, s], [0, 1, 0], [-s, 0, c]], atol=0)
    assert np.allclose(rt.rot_z(a), [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=0)
    v, w = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -4.0])
    assert np.allclose(rt.skew(v) @ w, np.cross(v, w), atol=1e-15)


def test_x1_quaternion_rotmat_round_trip_all_four_branches():
    branch_seen = set()
    for q in _random_quats(2000):
        R = rt.quat_to_rotmat(q)
        assert abs(np.linalg.det(R) - 1.0) < 1e-12  # E17
        diag = [1 + np.trace(R), 1 + R[0, 0] - R[1, 1] - R[2, 2], 1 - R[0, 0] + R[1, 1] - R[2, 2],
                1 - R[0, 0] - R[1, 1] + R[2, 2]]
        branch_seen.add(int(np.argmax(diag)))
        q_back = rt.rotmat_to_quat(R)
        assert q_back[0] >= 0.0
        assert _same_attitude(q_back, q, 1e-12)
    assert branch_seen == {0, 1, 2, 3}
    # Exact branch representatives: identity and the three half turns.
    for q in ([1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]):
        assert _same_attitude(rt.rotmat_to_quat(rt.quat_to_rotmat(q)), np.array(q, float), 1e-15)


def test_x1_erratum_e14_q2_component_sign():
    q = rt.quat_from_axis_angle([0, 1, 0], 0.4)  # q0 dominant, q2 > 0
    R = rt.quat_to_rotmat(q)
    assert R[0, 2] - R[2, 0] > 0
    assert np.allclose(rt.rotmat_to_quat(R), q, atol=1e-15)


def test_single_matrix_path_gives_the_batched_paths_bits():
    """rotmat_to_quat of one matrix takes a plain-float path: the same bits as the array path, every branch, ties
    (the half turns and the identity: several largest diagonal sums) and non-orthonormal input included."""
    rng = np.random.default_rng(7)
    R = rt.quat_to_rotmat(_random_quats(20000, seed=5))
    exact = rt.quat_to_rotmat(np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1],
                                        [0.5, 0.5, 0.5, 0.5], [0, 0.5 ** 0.5, 0.5 ** 0.5, 0]], float))
    noisy = R[:2000] + 1e-3 * rng.normal(size=(2000, 3, 3))
    for matrices in (R, exact, noisy):
        batched = rt.rotmat_to_quat(matrices)
        single = np.array([rt.rotmat_to_quat(m) for m in matrices])
        assert np.array_equal(single, batched)
        assert np.array_equal(np.signbit(single), np.signbit(batched))


def test_batched_rotmat_and_quat():
    q = _random_quats(50, seed=3)
    R = rt.quat_to_rotmat(q)
    assert R.shape == (50, 3, 3)
    q_back = rt.rotmat_to_quat(R)
    signs = np.sign(np.sum(q_back * q, axis=1))
    assert np.abs(q_back - signs[:, None] * q).max() < 1e-12
    v = np.random.default_rng(1).normal(size=(50, 3))
    assert np.abs(rt.quat_rotate(q, v) - np.einsum("kij,kj->ki", R, v)).max() < 1e-12


def test_single_and_batched_forms_agree():
    """One quaternion / angle triple (plain-float evaluation) gives what a batch gives (numpy evaluation)."""
    q = _random_quats(20, seed=5)
    p = _random_quats(20, seed=6)
    angles = np.random.default_rng(7).uniform(-3.0, 3.0, size=(20, 3))
    batch = {
        "multiply": rt.quat_multiply(q, p), "rotmat": rt.quat_to_rotmat(q), "error": rt.quat_error(q, p),
        "attitude": rt.attitude_error_vector(q, p), "euler": rt.euler_zyx_to_quat(*angles.T),
    }
    for k in range(20):
        assert np.allclose(rt.quat_multiply(q[k], p[k]), batch["multiply"][k], atol=1e-15)
        assert np.allclose(rt.quat_to_rotmat(q[k]), batch["rotmat"][k], atol=1e-15)
        assert np.allclose(rt.quat_error(q[k], p[k]), batch["error"][k], atol=1e-15)
        assert np.allclose(rt.attitude_error_vector(q[k], p[k]), batch["attitude"][k], atol=1e-15)
        single = rt.euler_zyx_to_quat(*angles[k].tolist())
        assert single.shape == (4,) and np.allclose(single, batch["euler"][k], atol=1e-15)
        assert np.allclose(rt.quat_to_euler_zyx(single), rt.rotmat_to_euler_zyx(rt.quat_to_rotmat(single)),
                           atol=1e-15)
    assert np.allclose(rt.quat_multiply(q[0], p), rt.quat_multiply(np.tile(q[0], (20, 1)), p), atol=1e-15)
    with pytest.raises(ValueError, match="pitch"):
        rt.euler_zyx_to_quat(0.1, float("nan"), 0.2)


def test_x2_zyx_euler_round_trip():
    rng = np.random.default_rng(4)
    for _ in range(500):
        roll, yaw = rng.uniform(-np.pi, np.pi, 2)
        pitch = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3)
        q = rt.euler_zyx_to_quat(roll, pitch, yaw)
        assert np.allclose(rt.quat_to_rotmat(q), rt.euler_zyx_to_rotmat(roll, pitch, yaw), atol=1e-15)
        assert np.allclose(rt.quat_to_euler_zyx(q), (roll, pitch, yaw), atol=1e-12, rtol=0)
        assert np.allclose(rt.rotmat_to_euler_zyx(rt.euler_zyx_to_rotmat(roll, pitch, yaw)),
                           (roll, pitch, yaw), atol=1e-12, rtol=0)


def test_x2_erratum_e15_yaw_formula():
    q = rt.euler_zyx_to_quat(0.5, -0.3, 1.2)
    q0, q1, q2, q3 = q
    yaw = np.arctan2(2 * (q0 * q3 + q1 * q2), q0**2 + q1**2 - q2**2 - q3**2)
    assert abs(yaw - 1.2) < 1e-14
    assert abs(rt.quat_to_euler_zyx(q)[2] - 1.2) < 1e-14


def test_zyx_gimbal_lock_reconstructs_rotation():
    R = rt.euler_zyx_to_rotmat(0.4, np.pi / 2, 1.0)
    roll, pitch, yaw = rt.rotmat_to_euler_zyx(R)
    assert roll == 0.0
    assert np.allclose(rt.euler_zyx_to_rotmat(roll, pitch, yaw), R, atol=1e-12)


def test_x3_product_matrices():
    a, b = _random_quats(2, seed=5)
    ab = rt.quat_multiply(a, b)
    assert np.allclose(rt.quat_left_matrix(a) @ b, ab, atol=1e-15)
    assert np.allclose(rt.quat_right_matrix(b) @ a, ab, atol=1e-15)
    assert np.allclose(rt.quat_left_matrix(rt.quat_conjugate(a)) @ a, rt.quat_left_matrix(a).T @ a,
                       atol=1e-15)
    # Rotation composition: R(a ∘ b) = R(a) R(b); vector rotation (A.55).
    assert np.allclose(rt.quat_to_rotmat(ab), rt.quat_to_rotmat(a) @ rt.quat_to_rotmat(b), atol=1e-14)
    v = np.array([0.3, -1.0, 2.0])
    sandwich = rt.quat_multiply(rt.quat_multiply(a, np.r_[0.0, v]), rt.quat_conjugate(a))
    assert np.allclose(sandwich[1:], rt.quat_rotate(a, v), atol=1e-14)
    assert np.allclose(rt.quat_multiply(a, rt.quat_inverse(a)), [1, 0, 0, 0], atol=1e-15)


def test_x4_euler_rate_matrix_and_derivative():
    roll, pitch = 0.3, -0.7
    D = rt.euler_rate_matrix(roll, pitch)
    assert np.allclose(D @ rt.euler_rate_matrix_inverse(roll, pitch), np.eye(3), atol=1e-14)
    # Body rate from the rotation-matrix derivative: [ω]× = Rᵀ Ṙ (A.74).
    eta, eta_dot = np.array([roll, pitch, 1.1]), np.array([0.4, -0.2, 0.9])
    h = 1e-6
    R = rt.euler_zyx_to_rotmat(*eta)
    R_dot = (rt.euler_zyx_to_rotmat(*(eta + h * eta_dot))
             - rt.euler_zyx_to_rotmat(*(eta - h * eta_dot))) / (2 * h)
    W = R.T @ R_dot
    assert np.allclose([W[2, 1], W[0, 2], W[1, 0]], D @ eta_dot, atol=1e-9)
    # Ḋ (A.82) vs central difference of D along η̇.
    D_dot_fd = (rt.euler_rate_matrix(roll + h * 0.4, pitch - h * 0.2)
                - rt.euler_rate_matrix(roll - h * 0.4, pitch + h * 0.2)) / (2 * h)
    assert np.abs(rt.euler_rate_matrix_dot(roll, pitch, 0.4, -0.2) - D_dot_fd).max() <= 1e-8


def test_x5_quaternion_kinematics_vs_integration():
    q0 = rt.euler_zyx_to_quat(0.2, -0.1, 0.5)
    omega = np.array([0.7, -0.4, 1.3])
    # RK4 on (A.84) vs the exact exponential map.
    q, dt = q0.copy(), 1e-3
    for _ in range(1000):
        k1 = rt.quat_derivative(q, omega)
        k2 = rt.quat_derivative(q + 0.5 * dt * k1, omega)
        k3 = rt.quat_derivative(q + 0.5 * dt * k2, omega)
        k4 = rt.quat_derivative(q + dt * k3, omega)
        q = q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    exact = rt.quat_integrate(q0, omega, 1.0)
    assert np.abs(q - exact).max() <= 1e-6
    # (A.83): [0; ω] = 2 Q(q)ᵀ q̇.
    qd = rt.quat_derivative(q0, omega)
    assert np.allclose(2 * rt.quat_left_matrix(q0).T @ qd, np.r_[0.0, omega], atol=1e-15)
    # (A.85) with a constant rate: [0; ω̇] = 2 Q(q)ᵀ q̈ + 2 [‖q̇‖²; 0] = 0.
    qdd = 0.5 * rt.quat_left_matrix(qd) @ np.r_[0.0, omega]
    lhs = 2 * rt.quat_left_matrix(q0).T @ qdd + 2 * np.r_[qd @ qd, 0, 0, 0]
    assert np.abs(lhs).max() <= 1e-15


def test_x6_zxz_table_d1_round_trip():
    for angles in [(1.561, 0.708, 0.829), (-0.716, 3.136, 0.837)]:
        R = rt.euler_zxz_to_rotmat(*angles)
        assert np.allclose(rt.rotmat_to_euler_zxz(R), angles, atol=1e-8, rtol=0)
    # E16 formulas read directly from the matrix.
    R = rt.euler_zxz_to_rotmat(1.561, 0.708, 0.829)
    assert abs(np.arctan2(R[0, 2], -R[1, 2]) - 1.561) < 1e-12
    assert abs(np.arccos(R[2, 2]) - 0.708) < 1e-12
    assert abs(np.arctan2(R[2, 0], R[2, 1]) - 0.829) < 1e-12
    # Singular case keeps the rotation.
    R = rt.euler_zxz_to_rotmat(0.3, np.pi, 0.0)
    assert np.allclose(rt.euler_zxz_to_rotmat(*rt.rotmat_to_euler_zxz(R)), R, atol=1e-12)


def test_axis_angle_and_rotvec():
    q = rt.quat_from_axis_angle([0, 0, 2.0], np.pi / 3)
    assert np.allclose(q, [np.cos(np.pi / 6), 0, 0, np.sin(np.pi / 6)], atol=1e-15)
    axis, angle = rt.quat_to_axis_angle(q)
    assert np.allclose(axis, [0, 0, 1]) and abs(angle - np.pi / 3) < 1e-14
    axis, angle = rt.quat_to_axis_angle(-q)
    assert np.allclose(axis, [0, 0, 1]) and abs(angle - np.pi / 3) < 1e-14
    assert rt.quat_to_axis_angle([1, 0, 0, 0])[1] == 0.0
    rng = np.random.default_rng(7)
    for _ in range(200):
        rv = rng.normal(size=3)
        rv *= rng.uniform(0, np.pi - 1e-6) / np.linalg.norm(rv)
        assert np.allclose(rt.quat_to_rotvec(rt.quat_from_rotvec(rv)), rv, atol=1e-12)
    tiny = np.array([1e-12, -2e-12, 3e-13])
    assert np.allclose(rt.quat_to_rotvec(rt.quat_from_rotvec(tiny)), tiny, atol=1e-24, rtol=1e-10)
    # Rodrigues (E13) agrees with the quaternion rotation.
    u, th, z = np.array([0.0, 0.6, 0.8]), 0.9, np.array([1.0, 2.0, -0.5])
    rod = np.cos(th) * z + np.sin(th) * np.cross(u, z) + (1 - np.cos(th)) * (u @ z) * u
    assert np.allclose(rt.quat_rotate(rt.quat_from_axis_angle(u, th), z), rod, atol=1e-14)


def test_quat_integrate_is_body_frame_exponential():
    q0 = rt.euler_zyx_to_quat(0.0, 0.0, np.pi / 2)
    q1 = rt.quat_integrate(q0, [0.5, 0.0, 0.0], 1.0)  # roll about the *body* x axis
    expected = rt.quat_multiply(q0, rt.quat_from_axis_angle([1, 0, 0], 0.5))
    assert np.allclose(q1, expected, atol=1e-15)


def test_attitude_error_vector():
    q = rt.euler_zyx_to_quat(0.1, 0.2, 0.3)
    assert np.allclose(rt.attitude_error_vector(q, q), 0.0, atol=1e-15)
    delta = rt.quat_from_axis_angle([0, 0, 1], 0.2)
    q_des = rt.quat_multiply(q, delta)
    assert np.allclose(rt.quat_error(q, q_des), delta, atol=1e-15)
    eps = rt.attitude_error_vector(q, q_des)
    assert np.allclose(eps, [0, 0, np.sin(0.1)], atol=1e-15)
    assert np.allclose(rt.attitude_error_vector(q, -q_des), eps, atol=1e-15)  # sign-invariant


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="q"):
        rt.quat_normalize([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="q"):
        rt.quat_normalize([np.nan, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="body_rate"):
        rt.quat_integrate([1, 0, 0, 0], [np.inf, 0, 0], 0.1)
    with pytest.raises(ValueError, match="R"):
        rt.rotmat_to_quat(np.eye(2))
    with pytest.raises(ValueError, match="roll"):
        rt.euler_zyx_to_quat(np.nan, 0, 0)
    with pytest.raises(ValueError, match="axis"):
        rt.quat_from_axis_angle([0, 0, 0], 1.0)
    with pytest.raises(ValueError, match="pitch"):
        rt.euler_rate_matrix_inverse(0.0, np.pi / 2)


def test_quat_angle_is_the_rotation_angle_between_two_attitudes():
    from fpr_model.rotations import quat_angle, quat_from_axis_angle, quat_multiply

    a = quat_from_axis_angle([0.0, 0.0, 1.0], 0.3)
    b = quat_multiply(a, quat_from_axis_angle([1.0, 1.0, 0.0], 0.7))
    assert quat_angle(a, b) == pytest.approx(0.7, abs=1e-12)
    assert quat_angle(a, -2.0 * b) == pytest.approx(0.7, abs=1e-12)  # sign- and scale-invariant
    assert quat_angle(a, a) == pytest.approx(0.0, abs=1e-7)
    with pytest.raises(ValueError, match="zero quaternion"):
        quat_angle(a, [0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="q_b: contains NaN"):
        quat_angle(a, [1.0, float("nan"), 0.0, 0.0])
    with pytest.raises(ValueError, match="q_a: expected shape"):
        quat_angle([1.0, 0.0, 0.0], b)
    with pytest.raises(ValueError, match="q_a: cannot convert"):
        quat_angle("no quaternion", b)
    # the float path agrees with the array formula
    rng = np.random.default_rng(3)
    for _ in range(100):
        qa, qb = rng.normal(size=4), rng.normal(size=4)
        expected = 2.0 * np.arccos(min(1.0, abs(qa @ qb) / (np.linalg.norm(qa) * np.linalg.norm(qb))))
        assert quat_angle(qa, qb) == pytest.approx(expected, abs=1e-12)


def test_inverse_pose_composes_to_identity():
    from fpr_model.rotations import euler_zyx_to_quat, inverse_pose, quat_multiply, quat_rotate

    position, quat = np.array([0.3, -1.2, 2.0]), euler_zyx_to_quat(0.4, -0.2, 2.5)
    inv_position, inv_quat = inverse_pose(position, quat)
    # child in parent, then parent in child: identity
    assert np.allclose(quat_rotate(quat, inv_position) + position, 0.0, atol=1e-12)
    assert np.allclose(np.abs(quat_multiply(quat, inv_quat)), [1.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_quat_tilt_is_the_angle_of_body_z_from_the_vertical_scalar_and_batched():
    import math

    from fpr_model.rotations import euler_zyx_to_quat, quat_tilt

    assert quat_tilt([1.0, 0.0, 0.0, 0.0]) == 0.0
    assert math.isclose(quat_tilt(euler_zyx_to_quat(0.3, 0.0, 1.2)), 0.3, abs_tol=1e-12)  # yaw does not tilt
    batch = np.array([euler_zyx_to_quat(0.0, 0.5, 0.0), euler_zyx_to_quat(math.pi, 0.0, 0.0)])
    np.testing.assert_allclose(quat_tilt(batch), [0.5, math.pi], atol=1e-7)


def test_quat_rotate_single_vector_is_bit_identical_to_the_array_form():
    """The plain-float path of one q and one v (issue 15) gives exactly the batched numpy form's bits, also for
    non-unit quaternions and large values; inputs it does not take (lists, float32, NaN) go the array way."""
    rng = np.random.default_rng(7)
    qs = np.concatenate([rng.normal(size=(500, 4)), 1e6 * rng.normal(size=(50, 4))])
    vs = np.concatenate([rng.normal(size=(500, 3)), 1e-9 * rng.normal(size=(50, 3))])
    batched = rt.quat_rotate(qs, vs)  # the array form (not the single path: 2-D)
    for k in range(len(qs)):
        single = rt.quat_rotate(qs[k], vs[k])
        assert single.shape == (3,) and single.dtype == np.float64
        assert np.array_equal(single, batched[k]), k
    assert np.array_equal(rt.quat_rotate(list(qs[0]), list(vs[0])), batched[0])  # a list: the array path
    assert np.allclose(rt.quat_rotate(qs[0].astype(np.float32), vs[0]), batched[0], atol=1e-5)
    for bad in (np.array([np.nan, 0.0, 0.0, 1.0]), np.array([1.0, 0.0, np.inf, 0.0])):
        with pytest.raises(ValueError, match="q: contains NaN or inf"):
            rt.quat_rotate(bad, vs[0])
    with pytest.raises(ValueError, match="v: contains NaN or inf"):
        rt.quat_rotate(qs[0], np.array([0.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="v: expected shape"):
        rt.quat_rotate(qs[0], np.zeros(4))
