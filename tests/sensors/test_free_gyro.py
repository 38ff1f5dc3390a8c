"""The free two-gimbal gyro pair: gimbal angles are the carrier's Euler angles, the indicated rate is the
body rate, friction drifts the rotors at τ/H, gimbal lock is flagged, warned or raised; config errors.

Tolerances come from theory: round-off where the model is exact (a frictionless rotor holds still, so
the gimbal angles are a change of coordinates); the finite differences' h⁴ remainder for the rate; the
closed-form precession of (4) for friction.
"""

import math
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.dynamics.rotation import body_rate_from_euler_zyx, quat_from_euler_zyx
from gyroemu.sensors.free_gyro import (
    FreeGyro,
    GimbalLockError,
    GimbalLockWarning,
    body_rate_from_euler_xyz,
    time_derivative,
)
from gyroemu.sensors.mechanism import GyroTruth, mechanism_class

FRICTIONLESS = FreeGyro(
    outer_viscous_friction_n_m_s_per_rad=0,
    outer_coulomb_friction_n_m=0,
    inner_viscous_friction_n_m_s_per_rad=0,
    inner_coulomb_friction_n_m=0,
)


def friction(outer=(0.0, 0.0), inner=(0.0, 0.0)):
    """A gyro with (viscous N·m·s/rad, Coulomb N·m) in each bearing."""
    return FreeGyro(
        outer_viscous_friction_n_m_s_per_rad=outer[0],
        outer_coulomb_friction_n_m=outer[1],
        inner_viscous_friction_n_m_s_per_rad=inner[0],
        inner_coulomb_friction_n_m=inner[1],
    )


def make_truth(q_is, omega, dt):
    m = len(q_is)
    return GyroTruth(
        t=np.arange(m) * dt,
        dt=dt,
        omega=np.asarray(omega, dtype=float),
        alpha=np.zeros((m, 3)),
        specific_force=np.zeros((m, 3)),
        q_is=np.asarray(q_is, dtype=float),
        temperature_degC=np.full(m, 25.0),
    )


def respond(gyro, q_is, omega, dt):
    return gyro.respond(make_truth(q_is, omega, dt), np.random.default_rng(0))


def wrap(a):
    return np.angle(np.exp(1j * a))


def tumbling_zyx(t):
    """A carrier rolling, pitching (to ±40°) and turning: q_is and ω_b from the Z-Y-X helpers of
    gyroemu.dynamics.rotation, starting from a non-trivial attitude."""
    rpy = np.stack(
        [0.3 + 1.2 * np.sin(0.7 * t), 0.2 + 0.5 * np.sin(0.45 * t + 0.3), 2.5 * np.sin(0.2 * t) + 0.3 * t], -1
    )
    rates = np.stack(
        [1.2 * 0.7 * np.cos(0.7 * t), 0.5 * 0.45 * np.cos(0.45 * t + 0.3), 0.5 * np.cos(0.2 * t) + 0.3], -1
    )
    return quat_from_euler_zyx(rpy), body_rate_from_euler_zyx(rpy, rates)


def rotation_about(axis, rate, t):
    """q_is and ω_b of a steady rotation at ``rate`` about the body axis ``axis`` from the identity."""
    q = np.zeros((t.size, 4))
    q[:, 0], q[:, 1 + axis] = np.cos(rate * t / 2), np.sin(rate * t / 2)
    omega = np.zeros((t.size, 3))
    omega[:, axis] = rate
    return q, omega


# --------------------------------------------------------------------------------------------------
# Frictionless: the gimbals read the attitude
# --------------------------------------------------------------------------------------------------


def test_gimbal_angles_are_the_euler_angles_of_the_carrier():
    """Relative to the attitude at t[0], R = Rx(φ) Ry(θ) Rz(ψ): gyro 1 reads (θ, ψ), the pair gives φ,
    to round-off, for an arbitrary tumbling from an arbitrary initial attitude."""
    dt = 1e-2
    t = np.arange(3001) * dt
    q, omega = tumbling_zyx(t)
    r = respond(FRICTIONLESS, q, omega, dt)
    relative = Rotation.from_quat(q[0], scalar_first=True).inv() * Rotation.from_quat(q, scalar_first=True)
    phi, theta, psi = relative.as_euler("XYZ").T
    gimbals = r.raw["gimbal_angle_rad"]
    assert np.abs(wrap(gimbals[:, 0] - theta)).max() < 1e-14
    assert np.abs(wrap(gimbals[:, 1] - psi)).max() < 1e-14
    assert np.abs(wrap(r.raw["attitude_xyz_rad"] - np.stack([phi, theta, psi], -1))).max() < 1e-14
    assert not r.raw["gimbal_lock"].any()
    assert mechanism_class("free-gyro") is FreeGyro


def test_gyro_two_reads_roll_and_yaw_when_pitch_is_zero():
    """Gyro 2 (spin y, inner x, outer z): with θ = 0, its inner gimbal reads φ and its outer ψ."""
    dt = 1e-2
    t = np.arange(1000) * dt
    phi, psi = 1.3 * np.sin(0.9 * t), 2.0 * np.sin(0.3 * t)
    q = Rotation.from_euler("XYZ", np.stack([phi, 0 * t, psi], -1)).as_quat(scalar_first=True)
    gimbals = respond(FRICTIONLESS, q, np.zeros((t.size, 3)), dt).raw["gimbal_angle_rad"]
    assert np.abs(wrap(gimbals[:, 2] - phi)).max() < 1e-14
    assert np.abs(wrap(gimbals[:, 3] - psi)).max() < 1e-14


def test_euler_rate_map_is_the_body_rate():
    """(3) against the body rate of R(t) = Rx(φ) Ry(θ) Rz(ψ) by central differences of the rotation,
    log(R(t−δ)ᵀ R(t+δ))/2δ (error δ²/6 |ω''| + ε/δ ≈ 1e-9)."""
    rng = np.random.default_rng(3)
    angles, rates = rng.uniform(-1.4, 1.4, (50, 3)), rng.uniform(-2, 2, (50, 3))
    delta = 1e-5
    rotation = lambda s: Rotation.from_euler("XYZ", angles + s * rates)  # noqa: E731
    numeric = (rotation(-delta).inv() * rotation(delta)).as_rotvec() / (2 * delta)
    np.testing.assert_allclose(body_rate_from_euler_xyz(angles, rates), numeric, rtol=0, atol=1e-8)


def test_indicated_rate_is_the_body_rate_within_the_finite_difference_error():
    """Euler angles φ, θ, ψ = A_i sin(w_i t + p_i): the fourth-order differences err by at most
    h⁴/5 max|y⁽⁵⁾| = h⁴ A w⁵/5 (one-sided ends; h⁴/30 inside), and each body-rate component sums at
    most two Euler rates with coefficients ≤ 1 in size."""
    dt = 2e-3
    t = np.arange(5001) * dt
    amp, w = np.array([1.0, 0.9, 2.0]), np.array([1.1, 0.8, 0.5])
    angles = amp * np.sin(np.outer(t, w))  # zero at t[0], where the rotors are set: R(0) = I
    rates = amp * w * np.cos(np.outer(t, w))
    q = Rotation.from_euler("XYZ", angles).as_quat(scalar_first=True)
    truth_rate = body_rate_from_euler_xyz(angles, rates)  # checked against the rotation above
    r = respond(FRICTIONLESS, q, truth_rate, dt)
    bound = 2 * dt**4 * np.max(amp * w**5) / 5
    assert np.abs(r.rate - truth_rate).max() <= bound
    interior = slice(2, -2)
    assert np.abs(r.rate[interior] - truth_rate[interior]).max() <= 2 * dt**4 * np.max(amp * w**5) / 30


def test_time_derivative_is_fourth_order():
    t = np.arange(200) * 0.01
    for h_factor in (1, 2):
        h = 0.01 * h_factor
        y = np.sin(3 * t[::h_factor])
        err = np.abs(time_derivative(y, h) - 3 * np.cos(3 * t[::h_factor]))
        assert err.max() <= h**4 * 3**5 / 5
        assert err[2:-2].max() <= h**4 * 3**5 / 30


# --------------------------------------------------------------------------------------------------
# Friction drift
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("viscous, coulomb, rate", [(4e-6, 0.0, 0.5), (0.0, 3e-6, 0.5), (4e-6, 3e-6, -0.8)])
def test_outer_bearing_friction_tilts_the_rotor_at_tau_over_h(viscous, coulomb, rate):
    """The carrier turns about z (the outer gimbal axis) at r: the outer bearing turns at −r and its
    friction torque τ_o = b r + τ_c sign r about z precesses the rotor: sin θ₁ = τ_o t / H exactly by (4).
    Heun's step with renormalisation errs by ≤ (h τ_o/(H cos²θ))² per step."""
    gyro = friction(outer=(viscous, coulomb))
    dt = 1e-3
    t = np.arange(100001) * dt
    q, omega = rotation_about(2, rate, t)
    r = respond(gyro, q, omega, dt)
    tau = viscous * rate + coulomb * np.sign(rate)
    drift = tau / gyro.spin_momentum
    sin_theta1 = np.sin(r.raw["gimbal_angle_rad"][:, 0])
    assert np.abs(sin_theta1 - drift * t).max() <= t.size * (dt * drift) ** 2 / 0.99 + 1e-13
    # Gyro 2's rotor (y) tilts up too: the rotor frame turns rigidly at ω_d = (τ_o/H)(1, −1, 0) in
    # inertial axes, and the pair indicates ω − Rᵀ ω_d, Rᵀ = Rz(−r t), to first order in the drift angle.
    c, s = np.cos(rate * t), np.sin(rate * t)
    expected = omega - drift * np.column_stack([c - s, -(s + c), 0 * t])
    sigma = np.abs(drift * t)[:, None]
    assert np.all(np.abs(r.rate - expected) <= 2 * sigma * abs(drift) + 1e-12)
    # The outer gimbal still reads the yaw.
    assert np.abs(wrap(r.raw["gimbal_angle_rad"][:, 1] - rate * t)).max() < 1e-9


@pytest.mark.parametrize("viscous, coulomb, rate", [(4e-6, 0.0, 0.3), (0.0, 3e-6, -0.3)])
def test_inner_bearing_friction_turns_the_rotor_at_tau_over_h(viscous, coulomb, rate):
    """The carrier pitches about y (gyro 1's inner gimbal axis) at q for 3 s (to ±52°): the inner bearing
    turns at −q, τ_i = b q + τ_c sign q about y, and the rotor turns towards y at τ_i/H inertially:
    s_y = −sin ψ₁ cos θ₁ = sin(τ_i t/H), the outer gimbal reading ψ₁ = −τ_i t/(H cos qt) to first order.
    The inner axis leaves y only at second order in the drift angle σ ≈ 4e-5 (relative σ²/cos² < 1e-8)."""
    gyro = friction(inner=(viscous, coulomb))
    dt = 1e-3
    t = np.arange(3001) * dt
    q, omega = rotation_about(1, rate, t)
    r = respond(gyro, q, omega, dt)
    tau = viscous * rate + coulomb * np.sign(rate)
    sigma = tau * t / gyro.spin_momentum
    theta1, psi1 = r.raw["gimbal_angle_rad"][:, 0], r.raw["gimbal_angle_rad"][:, 1]
    np.testing.assert_allclose(theta1, rate * t, rtol=0, atol=1e-8)
    np.testing.assert_allclose(-np.sin(psi1) * np.cos(theta1), np.sin(sigma), rtol=1e-7, atol=1e-15)
    np.testing.assert_allclose(psi1, -sigma / np.cos(rate * t), rtol=1e-7, atol=1e-15)


def test_a_still_carrier_does_not_drift():
    """Friction needs bearing motion: no drift at all while the carrier is at rest."""
    dt = 1e-3
    q = np.tile([1.0, 0.0, 0.0, 0.0], (5000, 1))
    r = respond(FreeGyro(), q, np.zeros((5000, 3)), dt)
    assert np.abs(r.raw["gimbal_angle_rad"]).max() == 0.0
    assert np.abs(r.rate).max() == 0.0


def test_default_drift_is_a_few_degrees_per_hour():
    gyro = FreeGyro()
    deg_per_h = math.degrees(gyro.outer_coulomb_friction_n_m / gyro.spin_momentum) * 3600
    assert 1.0 < deg_per_h < 10.0


def test_friction_rotation_kernel_is_the_quaternion_rotation():
    """The friction model's kernel turns vectors by q ⊗ v ⊗ q* (case to rotor) and q* ⊗ v ⊗ q (back):
    against scipy's rotation matrix, for a generic rotation and vector, to a few ε of |v|."""
    from gyroemu.sensors.free_gyro import _rotate

    q = np.array([0.36, -0.48, 0.64, 0.48])  # unit, scalar first; no component zero
    v = np.array([0.3, -1.7, 2.9])
    rotation = Rotation.from_quat(np.roll(q, -1))
    tol = 8 * np.finfo(float).eps * np.linalg.norm(v)
    np.testing.assert_allclose(_rotate(q, v, False), rotation.apply(v), rtol=0, atol=tol)
    np.testing.assert_allclose(_rotate(q, v, True), rotation.inv().apply(v), rtol=0, atol=tol)


# --------------------------------------------------------------------------------------------------
# Gimbal lock
# --------------------------------------------------------------------------------------------------


def pitch_to(max_deg, dt=1e-3, duration=2.0):
    """Pitch about y from 0 to ``max_deg`` and back: θ(t) = θ_max sin(π t/T)."""
    t = np.arange(int(duration / dt) + 1) * dt
    amp = math.radians(max_deg)
    theta = amp * np.sin(np.pi * t / duration)
    q = np.zeros((t.size, 4))
    q[:, 0], q[:, 2] = np.cos(theta / 2), np.sin(theta / 2)
    omega = np.zeros((t.size, 3))
    omega[:, 1] = amp * np.pi / duration * np.cos(np.pi * t / duration)
    return t, theta, q, omega


def test_gimbal_lock_is_flagged_and_warned():
    t, theta, q, omega = pitch_to(88.0)
    with pytest.warns(GimbalLockWarning, match="free gyro 1's inner gimbal"):
        r = respond(FRICTIONLESS, q, omega, 1e-3)
    np.testing.assert_array_equal(r.raw["gimbal_lock"], np.abs(theta) > math.radians(85.0))
    assert r.raw["gimbal_lock"].sum() > 0


def test_gimbal_lock_of_the_roll_gyro():
    t = np.arange(2001) * 1e-3
    phi = math.radians(87.0) * np.sin(np.pi * t / 2)
    q = Rotation.from_euler("XYZ", np.stack([phi, 0 * t, 0 * t], -1)).as_quat(scalar_first=True)
    with pytest.warns(GimbalLockWarning, match="free gyro 2's inner gimbal"):
        r = respond(FRICTIONLESS, q, np.zeros((t.size, 3)), 1e-3)
    np.testing.assert_array_equal(r.raw["gimbal_lock"], np.abs(phi) > math.radians(85.0))


def test_gimbal_lock_can_raise():
    t, theta, q, omega = pitch_to(89.5)
    with pytest.raises(GimbalLockError, match="gimbal lock"):
        respond(FreeGyro(on_gimbal_lock="raise", gimbal_lock_margin_deg=2.0), q, omega, 1e-3)


def test_no_lock_no_warning():
    t, theta, q, omega = pitch_to(84.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = respond(FreeGyro(), q, omega, 1e-3)
    assert not r.raw["gimbal_lock"].any()


# --------------------------------------------------------------------------------------------------
# Long runs in chunks (the mechanism contract)
# --------------------------------------------------------------------------------------------------


def imu_angle(rate, dt):
    """The indicated angle from 0 at the first sample, as the IMU forms it from a rate: trapezoids."""
    return np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * dt * (rate[1:] + rate[:-1]), axis=0)])


@pytest.mark.parametrize("gyro", [FRICTIONLESS, FreeGyro()], ids=["frictionless", "friction"])
def test_chunks_continue_one_run(gyro):
    """A run split into four uneven chunks sharing their edge samples (one two samples long), at a
    typical output rate (100 Hz), from a non-trivial attitude, yawing through several turns.

    * Gimbal angles, attitude and lock flags are one call's samples (1e-14 rad: a few ulp of π, for
      vectorised arctan2 paths; in fact bit for bit): the state carries the uncaging attitude and the
      rotor directions, which (4) continues by the same steps.
    * The rate is one call's everywhere but at the last two samples of each chunk but the final one,
      to the round-off of the differences: the unwrapped angles (≤ Ψ ≈ 15 rad) may differ by the
      rounding of the turns added, an ulp of Ψ, and the differences' coefficients sum to ≤ 128/12
      over h, two Euler rates per component: 2 (128/12) ulp(Ψ)/h ≈ 4e-12 rad/s (2e-12 of the largest rate).
    * At those two samples the differences would need the next chunk's samples: the rate is what a
      run ending there shows (one-sided formulas), equal to a call on the truth up to there to the same
      round-off, and off the central estimate by at most the two truncation errors, 2 h⁴ max|y⁽⁵⁾|
      (1/5 + 1/30) (Euler angles A sin ωt plus a steady turn; checked without friction, whose
      Coulomb kinks y⁽⁵⁾ does not bound). A chunk's first sample repeats the previous chunk's last.
    * A fresh ``{}`` (or no state) is power-up: the rotors are set at that chunk's first attitude.
    """
    dt = 1e-2
    t = np.arange(2001) * dt
    amp, w, turn = np.array([1.0, 0.9, 2.0]), np.array([1.1, 0.8, 0.5]), np.array([0.0, 0.0, 0.8])
    angles = amp * np.sin(np.outer(t, w)) + np.outer(t, turn)
    rates = amp * w * np.cos(np.outer(t, w)) + turn
    q_start = Rotation.from_rotvec([0.4, -0.3, 2.0])  # the uncaging attitude: not the identity
    q = (q_start * Rotation.from_euler("XYZ", angles)).as_quat(scalar_first=True)
    omega = body_rate_from_euler_xyz(angles, rates)
    whole = gyro.respond(make_truth(q, omega, dt), np.random.default_rng(0), {})
    unwrapped = np.unwrap(whole.raw["attitude_xyz_rad"], axis=0)
    assert np.abs(np.diff(np.floor(unwrapped[:, 2] / (2 * np.pi) + 0.5))).sum() >= 2  # ψ passes ±π twice
    roundoff = 2 * (128 / 12) * np.spacing(np.abs(unwrapped).max()) / dt
    # {} and None: both power-up, the same computation (bit for bit on numpy 2; numpy 1.26's vectorised
    # loops round by the arrays' alignment, so to the differences' round-off).
    np.testing.assert_allclose(whole.rate, respond(gyro, q, omega, dt).rate, rtol=0, atol=roundoff)

    n = len(t) - 1
    edges = (0, 737, 738, 1500, n)
    state, parts = {}, []
    for first, last in zip(edges[:-1], edges[1:]):
        cut = slice(first, last + 1)
        part = gyro.respond(make_truth(q[cut], omega[cut], dt), np.random.default_rng(0), state)
        if parts:  # the shared sample repeats the previous chunk's last value
            np.testing.assert_array_equal(part.rate[0], parts[-1].rate[-1])
            for name in part.raw:
                np.testing.assert_array_equal(part.raw[name][0], parts[-1].raw[name][-1])
        np.testing.assert_array_equal(state["q_uncage"], q[0])
        assert state["spins"].shape == (2, 3) and state["attitude_tail"].shape == (5, 3)
        parts.append(part)
        if last < n:  # a chunk ends as a run ending there: the one-sided formulas, not the next samples
            alone = gyro.respond(make_truth(q[: last + 1], omega[: last + 1], dt), np.random.default_rng(0), {})
            own = slice(max(last - 1, first + 1) - first, None)
            np.testing.assert_allclose(part.rate[own], alone.rate[first + own.start :], rtol=0, atol=roundoff)

    for name, values in whole.raw.items():
        joined = np.concatenate([parts[0].raw[name]] + [p.raw[name][1:] for p in parts[1:]])
        np.testing.assert_allclose(joined.astype(float), values, rtol=0, atol=1e-14)
    rate = np.concatenate([parts[0].rate] + [p.rate[1:] for p in parts[1:]])
    ends = np.zeros(len(t), bool)
    ends[[e + k for e in edges[1:-1] for k in (-1, 0)]] = True
    np.testing.assert_allclose(rate[~ends], whole.rate[~ends], rtol=0, atol=roundoff)
    truncation = 2 * dt**4 * np.max(amp * w**5) * (1 / 5 + 1 / 30)
    if gyro.frictionless:
        assert np.abs(rate[ends] - whole.rate[ends]).max() <= truncation + roundoff
    # As the IMU integrates it, each chunk's angle from 0 is one call's re-based there, but for the end
    # samples' differences (each in at most two trapezoids of h/2, both chunks around an edge).
    angle = imu_angle(whole.rate, dt)
    bound = len(t) * np.finfo(float).eps * np.abs(angle).max() + 2 * dt * np.abs(rate[ends] - whole.rate[ends]).max()
    for first, last, part in zip(edges[:-1], edges[1:], parts):
        np.testing.assert_allclose(imu_angle(part.rate, dt), angle[first : last + 1] - angle[first], rtol=0, atol=bound)

    # A fresh state on a later chunk is a power-up there: the rotors are set at its first attitude.
    fresh = gyro.respond(make_truth(q[edges[-2] :], omega[edges[-2] :], dt), np.random.default_rng(0), {})
    np.testing.assert_array_equal(fresh.rate, respond(gyro, q[edges[-2] :], omega[edges[-2] :], dt).rate)
    np.testing.assert_allclose(fresh.raw["attitude_xyz_rad"][0], 0.0, rtol=0, atol=1e-15)
    assert np.abs(parts[-1].raw["attitude_xyz_rad"][0]).max() > 0.1


def test_gimbal_lock_is_reported_once_per_run():
    t, theta, q, omega = pitch_to(88.0)
    state, locked = {}, []
    with pytest.warns(GimbalLockWarning) as record:  # locked from ≈ 0.83 s to 1.17 s: in every chunk
        for first, last in ((0, 900), (900, 1000), (1000, len(t) - 1)):
            part = FRICTIONLESS.respond(
                make_truth(q[first : last + 1], omega[first : last + 1], 1e-3), np.random.default_rng(0), state
            )
            locked.append(part.raw["gimbal_lock"][1 if locked else 0 :])
    assert len(record) == 1 and state["lock_reported"]
    np.testing.assert_array_equal(np.concatenate(locked), np.abs(theta) > math.radians(85.0))


# --------------------------------------------------------------------------------------------------
# Interface and config
# --------------------------------------------------------------------------------------------------


def test_inner_rate_is_the_output_rate_and_nothing_is_drawn():
    assert FreeGyro().inner_rate_hz(250.0) == 250.0
    rng = np.random.default_rng(1)
    state = rng.bit_generator.state
    t = np.arange(100) * 1e-2
    q, omega = tumbling_zyx(t)
    FreeGyro().respond(make_truth(q, omega, 1e-2), rng)
    assert rng.bit_generator.state == state


@pytest.mark.parametrize(
    "key, value",
    [
        ("rotor_inertia_kgm2", 0.0),
        ("spin_speed_rpm", -1.0),
        ("outer_viscous_friction_n_m_s_per_rad", -1e-6),
        ("outer_coulomb_friction_n_m", -1e-6),
        ("inner_viscous_friction_n_m_s_per_rad", -1e-6),
        ("inner_coulomb_friction_n_m", "3e-6"),
        ("gimbal_lock_margin_deg", 0),
        ("gimbal_lock_margin_deg", 90),
        ("on_gimbal_lock", "ignore"),
        ("friction_n_m", 1e-6),
    ],
)
def test_bad_parameters_name_the_key(key, value):
    with pytest.raises(ConfigError) as err:
        validate(FreeGyro, {"kind": "free-gyro", key: value})
    assert err.value.key == key


def test_euler_angles_from_the_spins_alone():
    """Without the gimbal angles at hand, the attitude R = Rx(φ) Ry(θ) Rz(ψ) comes back from the rotor
    directions in case axes (rows of R: the rotors hold e_x and e_y) to round-off."""
    from gyroemu.sensors.free_gyro import euler_xyz_from_spins

    angles = np.array([[0.3, -0.7, 2.1], [-2.5, 1.2, -0.4], [1.0, 0.1, 3.0]])
    spins = Rotation.from_euler("XYZ", angles).as_matrix()[:, :2, :]
    assert np.abs(euler_xyz_from_spins(spins) - angles).max() < 8 * np.finfo(float).eps * np.pi


def test_inner_bearing_friction_ignores_a_turn_about_the_outer_axis():
    """Rotor along case y: the inner axis is a_o × s = −x. Turning the case about z (the outer axis) does
    not turn the inner bearing, so viscous inner friction alone gives no drift; turning it about x at
    ω does, and the drift is b_i ω a_i × (1/H) in magnitude: (b_i ω / H) along x."""
    from gyroemu.sensors.free_gyro import _spin_rate

    q, s, h, b_i = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 2.0, 1.0
    assert np.all(_spin_rate(q, np.array([0.0, 0.0, 1.0]), s, h, 0.0, 0.0, b_i, 0.0, 1e-12) == 0.0)
    rate = _spin_rate(q, np.array([1.0, 0.0, 0.0]), s, h, 0.0, 0.0, b_i, 0.0, 1e-12)
    assert np.allclose(rate, [b_i / h, 0.0, 0.0], rtol=0, atol=4 * np.finfo(float).eps)


# --------------------------------------------------------------------------------------------------
# The static bench: Earth rate, and friction at Earth-rate bearing speeds (issue 18 item 6)
# --------------------------------------------------------------------------------------------------

EARTH_RATE = 7.292115e-5  # rad/s
LATITUDE = math.radians(52.5)  # bench_static's site
# Sensor axes on the bench (yaw 0): x east, y north, z up, so the carrier turns at (0, Ω cos φ, Ω sin φ):
# 9.16 °/h about y (pitch) and 11.93 °/h about z (yaw).
BENCH_OMEGA = EARTH_RATE * np.array([0.0, math.cos(LATITUDE), math.sin(LATITUDE)])


def bench(gyro, duration=60.0, dt=0.01):
    """The pair on a static bench: the case turns with the Earth about a fixed axis at BENCH_OMEGA."""
    t = np.arange(round(duration / dt) + 1) * dt
    angle = EARTH_RATE * t
    axis = BENCH_OMEGA / EARTH_RATE
    q = np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * axis])
    return t, respond(gyro, q, np.tile(BENCH_OMEGA, (len(t), 1)), dt)


def test_frictionless_bench_reads_the_earth_rate_components():
    """Without friction the rotors hold still: the pair indicates (0, Ω cos φ, Ω sin φ) (9.16, 11.93 °/h)
    to round-off and the differences' h⁴ remainder (nil for this rotation about a fixed axis)."""
    t, r = bench(FRICTIONLESS)
    np.testing.assert_allclose(r.rate, np.tile(BENCH_OMEGA, (len(t), 1)), rtol=0, atol=1e-12)
    assert math.degrees(BENCH_OMEGA[2]) * 3600 == pytest.approx(11.93, abs=0.005)
    assert math.degrees(BENCH_OMEGA[1]) * 3600 == pytest.approx(9.16, abs=0.005)


def bench_closed_form(gyro, z_inner, z_outer):
    """Indicated rate on the bench to first order in the angles, for Coulomb-part torques z (N·m).

    Gyro 1 (spin x): its inner bearing (y) turns at w_i = −Ω cos φ, its outer (z) at w_o = −Ω sin φ; the
    torques τ = −(b w + z) push s along +y at τ_i/H (a drift about z) and along +z at τ_o/H (about −y).
    Gyro 2 (spin y): its inner bearing (x) does not turn, its outer one (z) turns at −Ω sin φ and tilts s₂
    towards +z (a drift about x). The pair indicates ω − ω_drift."""
    h = gyro.spin_momentum
    tau_i = gyro.inner_viscous_friction_n_m_s_per_rad * BENCH_OMEGA[1] + z_inner
    tau_o = gyro.outer_viscous_friction_n_m_s_per_rad * BENCH_OMEGA[2] + z_outer
    return np.column_stack([-tau_o / h, BENCH_OMEGA[1] + tau_o / h, BENCH_OMEGA[2] - tau_i / h])


def bench_tolerance(t, drift):
    """First-order closed form: its neglected terms are products of an angle (case turn plus drift,
    ≤ (Ω + τ/H) T) and a rate (≤ Ω + τ/H) in (1)–(4), two of them at most per component (e.g. θ' sin ψ
    in (3)); plus the Heun steps' and the differences' round-off."""
    return 2 * (EARTH_RATE + drift) ** 2 * t[-1] + 1e-12


def test_coulomb_bench_drift_is_tau_over_h_off_the_earth_rate():
    """The sign law (default, θ_d = 0) slides at τ_c at Earth-rate bearing speeds: yaw reads
    Ω sin φ − τ_c/H = 11.93 − 4.38 = 7.56 °/h, pitch Ω cos φ + τ_c/H = 9.16 + 4.38 = 13.53 °/h."""
    gyro = FreeGyro()
    t, r = bench(gyro)
    expected = bench_closed_form(gyro, gyro.inner_coulomb_friction_n_m, gyro.outer_coulomb_friction_n_m)
    drift = gyro.inner_coulomb_friction_n_m / gyro.spin_momentum
    assert np.abs(r.rate - expected).max() <= bench_tolerance(t, drift)
    deg_h = np.degrees(r.rate.mean(axis=0)) * 3600
    assert deg_h[2] == pytest.approx(7.56, abs=0.02)  # not 11.93
    assert deg_h[1] == pytest.approx(13.53, abs=0.02)  # not 9.16


@pytest.mark.parametrize("theta_d", [2e-4, 1e-3])
def test_dahl_bench_drift_grows_over_the_presliding_displacement(theta_d):
    """Dahl's law from unloaded bearings: at a steady bearing rate w the Coulomb part is
    z = τ_c (1 − e^{−|w| t/θ_d}) (sign of −w), so the indicated rate moves from the Earth-rate components
    to the sign law's values with time constants θ_d/(Ω cos φ) (yaw) and θ_d/(Ω sin φ) (pitch, roll)."""
    gyro = FreeGyro(presliding_displacement_rad=theta_d)
    t, r = bench(gyro, 30.0)
    c_i, c_o = gyro.inner_coulomb_friction_n_m, gyro.outer_coulomb_friction_n_m
    z_i = c_i * -np.expm1(-BENCH_OMEGA[1] * t / theta_d)
    z_o = c_o * -np.expm1(-BENCH_OMEGA[2] * t / theta_d)
    expected = bench_closed_form(gyro, z_i, z_o)
    drift = c_i / gyro.spin_momentum
    # The exact displacement update leaves the trapezoid of w's O(dt² × drift) change per step; the
    # differences see z's curvature, h⁴ z⁽⁵⁾/30 ≪ the angles' term for these time constants (≥ 2.7 s).
    assert np.abs(r.rate[2:-2] - expected[2:-2]).max() <= bench_tolerance(t, drift)


def test_dahl_bench_mean_drift_closed_form():
    """Mean indicated yaw rate over T: Ω sin φ − (τ_c/H)(1 − (θ_d/(wT))(1 − e^{−wT/θ_d})), w = Ω cos φ."""
    theta_d, duration = 1e-3, 60.0
    gyro = FreeGyro(presliding_displacement_rad=theta_d)
    t, r = bench(gyro, duration)
    w = BENCH_OMEGA[1]
    x = w * duration / theta_d
    drift = gyro.inner_coulomb_friction_n_m / gyro.spin_momentum
    viscous = gyro.inner_viscous_friction_n_m_s_per_rad * w / gyro.spin_momentum
    expected = BENCH_OMEGA[2] - drift * (1 - (1 - math.exp(-x)) / x) - viscous
    mean = 0.5 * np.mean(r.rate[1:, 2] + r.rate[:-1, 2])  # trapezoid mean over [0, T]
    # trapezoid mean of the rate: exact for the ends' angles up to the differences' one-sided ends
    assert mean == pytest.approx(expected, abs=bench_tolerance(t, drift))


def test_dahl_keeps_high_rate_behaviour():
    """At 0.5 rad/s a bearing passes θ_d = 1e-4 rad in 0.2 ms: after the first step the drift is the
    sign law's (the outer-bearing test's closed form), the transient costing ≤ τ_c θ_d/(H w) of angle."""
    rate, dt, m = 0.5, 1e-3, 2000
    t = np.arange(m) * dt
    q = np.column_stack([np.cos(rate * t / 2), 0 * t, 0 * t, np.sin(rate * t / 2)])
    omega = np.tile([0.0, 0.0, rate], (m, 1))
    coulomb = respond(friction(outer=(0.0, 3e-6)), q, omega, dt)
    gyro = FreeGyro(
        outer_viscous_friction_n_m_s_per_rad=0.0,
        outer_coulomb_friction_n_m=3e-6,
        inner_viscous_friction_n_m_s_per_rad=0.0,
        inner_coulomb_friction_n_m=0.0,
        presliding_displacement_rad=1e-4,
    )
    dahl = respond(gyro, q, omega, dt)
    lag = 3e-6 / gyro.spin_momentum * (1e-4 / rate + dt)  # the transient's angle, at most
    diff = np.abs(dahl.raw["gimbal_angle_rad"] - coulomb.raw["gimbal_angle_rad"]).max()
    assert 0 < diff <= lag


def test_dahl_chunks_continue_one_run():
    """The bearing torques carry across chunks: a bench run in two chunks sharing their edge sample
    gives one call's rotor directions (to round-off)."""
    gyro = FreeGyro(presliding_displacement_rad=1e-3)
    t, whole = bench(gyro, 30.0)
    angle = EARTH_RATE * t
    axis = BENCH_OMEGA / EARTH_RATE
    q = np.column_stack([np.cos(angle / 2), np.sin(angle / 2)[:, None] * axis])
    omega = np.tile(BENCH_OMEGA, (len(t), 1))
    state: dict = {}
    parts = []
    for a, b in [(0, 1001), (1000, len(t))]:
        truth = make_truth(q[a:b], omega[a:b], 0.01)
        parts.append(gyro.respond(truth, np.random.default_rng(0), state).raw["gimbal_angle_rad"])
    chunked = np.concatenate([parts[0], parts[1][1:]])
    np.testing.assert_allclose(chunked, whole.raw["gimbal_angle_rad"], rtol=0, atol=1e-15)
    assert state["bearing_torque"].shape == (2, 2)
