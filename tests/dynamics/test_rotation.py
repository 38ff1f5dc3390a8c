"""Quaternion algebra and Euler-angle kinematics against scipy and finite differences."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyroemu.dynamics.rotation import (
    body_rate_from_euler_zxz,
    body_rate_from_euler_zyx,
    body_rate_from_quat_derivative,
    euler_zxz_from_quat,
    euler_zyx_from_quat,
    quat_angle,
    quat_conjugate,
    quat_exp,
    quat_from_euler_zxz,
    quat_from_euler_zyx,
    quat_from_matrix,
    quat_from_rotvec,
    quat_log,
    quat_multiply,
    quat_normalize,
    quat_positive,
    quat_rotate,
    quat_slerp,
    quat_to_matrix,
    quat_to_rotvec,
    skew,
)

EPS = np.finfo(float).eps


@pytest.fixture
def quats():
    rng = np.random.default_rng(7)
    return quat_normalize(rng.normal(size=(200, 4))), quat_normalize(rng.normal(size=(200, 4)))


def scipy_rot(q):
    return Rotation.from_quat(q, scalar_first=True)


def test_product_and_rotation_match_scipy(quats):
    p, q = quats
    expected = (scipy_rot(p) * scipy_rot(q)).as_quat(canonical=True, scalar_first=True)
    np.testing.assert_allclose(quat_positive(quat_multiply(p, q)), expected, atol=8 * EPS)
    v = np.random.default_rng(1).normal(size=(200, 3))
    np.testing.assert_allclose(quat_rotate(p, v), scipy_rot(p).apply(v), atol=16 * EPS)
    np.testing.assert_allclose(quat_to_matrix(p) @ v[..., None], quat_rotate(p, v)[..., None], atol=16 * EPS)
    np.testing.assert_allclose(quat_positive(quat_from_matrix(quat_to_matrix(p))), quat_positive(p), atol=8 * EPS)


def test_conjugate_is_inverse_and_hamilton_convention(quats):
    p, _ = quats
    identity = quat_multiply(p, quat_conjugate(p))
    np.testing.assert_allclose(identity, np.broadcast_to([1.0, 0, 0, 0], identity.shape), atol=4 * EPS)
    # Hamilton: i ⊗ j = k.
    np.testing.assert_array_equal(quat_multiply([0, 1, 0, 0], [0, 0, 1, 0]), [0, 0, 0, 1])


def test_exp_log_and_rotvec_are_inverses(quats):
    p, _ = quats
    np.testing.assert_allclose(quat_exp(quat_log(p)), quat_positive(p), atol=8 * EPS)
    np.testing.assert_allclose(quat_to_rotvec(p), scipy_rot(p).as_rotvec(), atol=16 * EPS)
    phi = np.array([[1e-12, 0, 0], [0, 0, 0], [0, 3.0, 0]])
    np.testing.assert_allclose(quat_to_rotvec(quat_from_rotvec(phi)), phi, atol=16 * EPS)


def test_slerp_is_uniform_along_the_arc(quats):
    p, q = quats
    s = np.linspace(0, 1, 11)
    path = quat_slerp(p[0], q[0], s)
    np.testing.assert_allclose(quat_positive(path[[0, -1]]), quat_positive(np.stack([p[0], q[0]])), atol=8 * EPS)
    steps = quat_angle(path[1:], path[:-1])
    np.testing.assert_allclose(steps, quat_angle(q[0], p[0]) / 10, atol=64 * EPS)


def test_euler_angles_round_trip_and_match_scipy():
    rng = np.random.default_rng(3)
    zxz = np.column_stack([rng.uniform(-np.pi, np.pi, 50), rng.uniform(0.1, 3.0, 50), rng.uniform(-np.pi, np.pi, 50)])
    np.testing.assert_allclose(euler_zxz_from_quat(quat_from_euler_zxz(zxz)), zxz, atol=1e-12)
    rpy = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)])
    np.testing.assert_allclose(euler_zyx_from_quat(quat_from_euler_zyx(rpy)), rpy, atol=1e-12)
    # R = Rz(yaw) Ry(pitch) Rx(roll): the body x axis of a pure yaw of 90° points north (world y).
    np.testing.assert_allclose(quat_rotate(quat_from_euler_zyx([0, 0, np.pi / 2]), [1, 0, 0]), [0, 1, 0], atol=4 * EPS)


def test_skew_is_cross_product():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(2, 10, 3))
    np.testing.assert_allclose((skew(a) @ b[..., None])[..., 0], np.cross(a, b), atol=8 * EPS)


@pytest.mark.parametrize(
    "to_quat, to_rate",
    [(quat_from_euler_zxz, body_rate_from_euler_zxz), (quat_from_euler_zyx, body_rate_from_euler_zyx)],
)
def test_body_rates_from_euler_rates_match_differentiated_attitude(to_quat, to_rate):
    # Angles are polynomials and sines of t with third derivatives below 10 (rad/s³) on [0, 1].
    def angles(t):
        return np.stack([0.3 + 1.1 * t + 0.2 * t**2, 0.7 + 0.4 * np.sin(2 * t), -0.2 + 3 * t - 0.5 * t**3], -1)

    def rates(t):
        return np.stack([1.1 + 0.4 * t, 0.8 * np.cos(2 * t), 3 - 1.5 * t**2], -1)

    def accels(t):
        return np.stack([0.4 + 0 * t, -1.6 * np.sin(2 * t), -3 * t], -1)

    t, h = np.linspace(0.05, 0.95, 19), 1e-4
    omega, alpha = to_rate(angles(t), rates(t), accels(t))
    q_dot = (to_quat(angles(t + h)) - to_quat(angles(t - h))) / (2 * h)
    omega_fd = body_rate_from_quat_derivative(to_quat(angles(t)), q_dot)
    alpha_fd = (to_rate(angles(t + h), rates(t + h)) - to_rate(angles(t - h), rates(t - h))) / (2 * h)
    # Central difference: truncation h²/6·max|f'''| (|f'''| of q and ω stay below ~10³ here: rates ≤ 4 rad/s,
    # cubed, times the accelerations' growth) plus round-off ~ eps/h.
    bound = h**2 / 6 * 1e3 + 10 * EPS / h
    np.testing.assert_allclose(omega, omega_fd, atol=bound)
    np.testing.assert_allclose(alpha, alpha_fd, atol=bound)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="length 4"):
        quat_multiply([1, 0, 0], [1, 0, 0, 0])
    with pytest.raises(ValueError, match="zero quaternion"):
        quat_normalize([0, 0, 0, 0])


def test_quat_exp_of_a_vector_too_small_for_its_norm_is_one_plus_the_vector():
    """exp(0, v) = (cos|v|, sin|v| v/|v|) → (1, v) as v → 0, even where |v|² underflows and the norm
    reads 0: the rotation is tiny, not absent."""
    for v in ([1e-170, -2e-170, 0.0], [0.0, 3e-200, 5e-190]):
        q = quat_exp(np.array(v))
        assert q[0] == 1.0
        np.testing.assert_allclose(q[1:], v, rtol=2 * EPS, atol=0)


def test_interpolate_follows_a_constant_rate_rotation_exactly():
    """Slerp is exact for a rotation about a fixed axis at a constant rate: q(t) = exp(ω t / 2)."""
    from gyroemu.dynamics.rotation import quat_exp, quat_interpolate

    omega = np.array([0.3, -1.1, 0.7])  # rad/s; 0.1 s samples turn 0.136 rad each
    t = np.linspace(0.0, 5.0, 51)
    t_query = np.random.default_rng(3).uniform(0.0, 5.0, 1000)
    got = quat_interpolate(t, quat_exp(0.5 * t[:, None] * omega), t_query)
    want = quat_exp(0.5 * t_query[:, None] * omega)
    assert np.abs(got - want).max() <= 64 * np.finfo(float).eps  # round-off of ~50 chained operations
    # Turns of 1e-9 rad per sample take the series for sin(s·θ/2)/|d_v|: the fraction s of each turn, to
    # round-off (the rotation vector is 1e-9 of the quaternion's unit scalar part).
    slow = np.array([2e-9, -1e-9, 3e-9])
    got = quat_interpolate(t, quat_exp(0.5 * t[:, None] * slow), t_query)
    assert np.allclose(got[:, 1:] / (0.5 * t_query[:, None] * slow), 1.0, rtol=0.0, atol=1e-6)
    assert np.abs(got - quat_exp(0.5 * t_query[:, None] * slow)).max() <= 4 * np.finfo(float).eps
    still = np.tile(quat_exp([0.1, 0.2, -0.3]), (len(t), 1))  # no turn at all: |d_v| = 0
    assert np.array_equal(quat_interpolate(t, still, t_query), np.tile(still[0], (len(t_query), 1)))


def test_interpolate_is_scipys_slerp_and_gives_the_samples_themselves():
    from scipy.spatial.transform import Rotation, Slerp

    from gyroemu.dynamics.rotation import quat_interpolate

    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, 2000))
    q = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.05, size=(2000, 3)), axis=0)).as_quat(scalar_first=True)
    q[::5] *= -1.0  # the same rotations, some written with the other sign
    t_query = np.sort(np.concatenate([rng.uniform(t[0], t[-1], 5000), t[::3], t[-1:]]))
    got = quat_interpolate(t, q, t_query)
    want = Slerp(t, Rotation.from_quat(q, scalar_first=True))(t_query).as_quat(scalar_first=True)
    # the same formula in another order: each output within a few ulps of a unit quaternion's parts
    assert np.abs(got - want).max() <= 8 * np.finfo(float).eps
    k = np.searchsorted(t, t_query)
    on = t[k] == t_query
    assert on.sum() == len(t[::3]) + 1
    # the sample itself, with the sign scipy gives it (that of the shorter arc from the sample before)
    assert np.array_equal(np.abs(got[on]), np.abs(q[k[on]]))
    assert np.all(np.einsum("ij,ij->i", got[on], want[on]) > 0)
    with pytest.raises(ValueError, match="leave the samples' span"):
        quat_interpolate(t, q, [t[-1] + 1e-3])
