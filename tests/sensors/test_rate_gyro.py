"""The spring-restrained rate gyro against its closed forms: gain, step, frequency response, cross-coupling,
output-axis acceleration, stops, the discretisation, config errors.

Tolerances come from theory. The simulation is exact for an input that is linear between samples, so
against the closed-form response to that input it agrees to round-off; against the continuous-input
forms it differs by the first-order hold's known effects (a sinusoid's amplitude times sinc²(f h), a
step's ramp over the first step). Inputs are kept small where the check is of the linear model, so
that the cos θ of the tilted input axis (1 − θ²/2) stays below round-off.
"""

import math

import numpy as np
import pytest
import scipy.optimize
import scipy.signal

from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors.mechanism import GyroTruth, mechanism_class
from gyroemu.sensors.rate_gyro import RateGyro, foh_matrices

GYRO = RateGyro()
H, J = GYRO.spin_momentum, GYRO.gimbal_inertia_kgm2
K, C = GYRO.spring_stiffness_n_m_per_rad, GYRO.damping_n_m_s_per_rad
WN = math.sqrt(K / J)
ZETA = C / (2 * math.sqrt(K * J))
WD = WN * math.sqrt(1 - ZETA**2)


def make_truth(omega, alpha, dt):
    omega, alpha = np.asarray(omega, dtype=float), np.asarray(alpha, dtype=float)
    m = len(omega)
    return GyroTruth(
        t=np.arange(m) * dt,
        dt=dt,
        omega=omega,
        alpha=alpha,
        specific_force=np.zeros((m, 3)),
        q_is=np.tile([1.0, 0.0, 0.0, 0.0], (m, 1)),
        temperature_degC=np.full(m, 25.0),
    )


def respond(omega, alpha, dt, gyro=GYRO):
    return gyro.respond(make_truth(omega, alpha, dt), np.random.default_rng(0))


def unit_ramp_response(t):
    """θ(t) for J θ'' + c θ' + K θ = t·1(t) from rest (underdamped; e.g. Ogata, Modern Control Eng., §5-3)."""
    t = np.maximum(t, 0.0)
    return (
        t
        - 2 * ZETA / WN
        + np.exp(-ZETA * WN * t) * (2 * ZETA / WN * np.cos(WD * t) + (2 * ZETA**2 - 1) / WD * np.sin(WD * t))
    ) / K


def step_from_rest(w0, dt, duration):
    """ω_IA (gyro x) = 0 at t = 0 and w0 from the next sample on: under the first-order hold, a ramp
    over [0, dt] and then constant."""
    m = int(round(duration / dt)) + 1
    omega = np.zeros((m, 3))
    omega[1:, 0] = w0
    return np.arange(m) * dt, omega


def sinusoid_fit(t, y, w):
    """(a, b) of the least-squares fit y ≈ a sin ωt + b cos ωt + const."""
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    return np.linalg.lstsq(basis, y, rcond=None)[0][:2]


# --------------------------------------------------------------------------------------------------
# Linear behaviour
# --------------------------------------------------------------------------------------------------


def test_defaults_are_the_documented_instrument():
    assert GYRO.natural_frequency_hz == pytest.approx(29.9, abs=0.05)
    assert GYRO.damping_ratio == pytest.approx(0.69, abs=0.005)
    assert math.degrees(GYRO.range_rad_per_s) == pytest.approx(104.4, abs=0.1)
    assert mechanism_class("rate-gyro") is RateGyro


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_static_gain_is_h_over_k(axis):
    """One axis at a time (a rate on another gyro's spin axis would cross-couple, see below)."""
    w = np.zeros(3)
    w[axis] = -3e-6  # θ ≈ 1e-7 rad: cos θ = 1 to round-off
    m = 2000
    r = respond(np.tile(w, (m, 1)), np.zeros((m, 3)), 1e-3)
    np.testing.assert_allclose(r.raw["gimbal_angle_rad"], np.tile(H * w / K, (m, 1)), rtol=1e-12, atol=0)
    np.testing.assert_allclose(r.rate, np.tile(w, (m, 1)), rtol=1e-12, atol=0)


def test_static_balance_with_the_tilted_input_axis():
    """A large steady rate: K θ = H ω cos θ exactly (the scale factor falls as cos θ)."""
    w = 1.5  # rad/s, θ ≈ 2.9°
    r = respond(np.tile([w, 0.0, 0.0], (100, 1)), np.zeros((100, 3)), 1e-3)
    theta = scipy.optimize.brentq(lambda th: K * th - H * w * math.cos(th), 0, 1)
    np.testing.assert_allclose(r.raw["gimbal_angle_rad"][:, 0], theta, rtol=1e-13)
    np.testing.assert_allclose(r.rate[:, 0], w * math.cos(theta), rtol=1e-13)


def test_power_up_balance_holds_near_the_cross_coupling_limit():
    """A steady rate with a large cross rate on the spin axis (H |ω|/K = 0.995 < 1, so the balance
    K θ = H (ω_IA cos θ − ω_SRA sin θ) has one root and positive stiffness K + H (ω_IA sin θ + ω_SRA cos θ)
    = 0.031 N·m/rad there): the gimbals start in that equilibrium and stay, θ constant from the first
    sample. Tolerance: the balance's round-off ε (K|θ| + H|ω|) over its stiffness, 4 times."""
    gyro = RateGyro(stop_angle_deg=85.0)
    w_ia, w_sra = 0.5, -29.7  # gyro x: IA = x, SRA = z
    m = 50
    r = respond(np.tile([w_ia, 0.0, w_sra], (m, 1)), np.zeros((m, 3)), 1e-4, gyro=gyro)
    balance = lambda th: K * th - H * (w_ia * math.cos(th) - w_sra * math.sin(th))  # noqa: E731
    theta = scipy.optimize.brentq(balance, -1.4, 1.4, xtol=1e-16, rtol=4 * np.finfo(float).eps)
    stiffness = K + H * (w_ia * math.sin(theta) + w_sra * math.cos(theta))
    assert 0 < stiffness < 0.11 * K
    tol = 4 * np.finfo(float).eps * (K * theta + H * math.hypot(w_ia, w_sra)) / stiffness
    np.testing.assert_allclose(r.raw["gimbal_angle_rad"][:, 0], theta, rtol=0, atol=tol)


def test_step_response_equals_the_closed_form_sample_by_sample():
    """Exact for the input the simulation sees (a ramp over the first step, then constant)."""
    dt, w0 = 1e-3, 1e-5
    t, omega = step_from_rest(w0, dt, 0.5)
    theta = respond(omega, np.zeros_like(omega), dt).raw["gimbal_angle_rad"][:, 0]
    expected = H * w0 / dt * (unit_ramp_response(t) - unit_ramp_response(t - dt))
    np.testing.assert_allclose(theta, expected, rtol=0, atol=1e-11 * H * w0 / K)


def test_step_response_overshoot_and_period_give_natural_frequency_and_damping():
    """Overshoot exp(−πζ/√(1−ζ²)) and damped period 2π/ω_d, read off the simulated samples.

    Errors: the hold averages the ideal step response over one step (peak lower by ≤ h²|θ''|/24) and the
    peak is read at a sample (≤ h²|θ''|/8), with |θ''| ≤ ω_n² θ_ss/√(1−ζ²); zero crossings found by linear
    interpolation move by O((ω_n h)²) of the period.
    """
    dt, w0 = 1e-5, 1e-5
    t, omega = step_from_rest(w0, dt, 0.2)
    theta = respond(omega, np.zeros_like(omega), dt).raw["gimbal_angle_rad"][:, 0]
    theta_ss = H * w0 / K
    overshoot = theta.max() / theta_ss - 1
    tol_overshoot = (WN * dt) ** 2 / (6 * math.sqrt(1 - ZETA**2))
    assert overshoot == pytest.approx(math.exp(-math.pi * ZETA / math.sqrt(1 - ZETA**2)), abs=tol_overshoot)
    e = theta - theta_ss
    i = np.nonzero(np.sign(e[:-1]) != np.sign(e[1:]))[0][:3]
    crossings = t[i] - e[i] * dt / (e[i + 1] - e[i])
    period = 2 * np.diff(crossings).mean()
    tol_period = (WN * dt) ** 2
    assert period == pytest.approx(2 * math.pi / WD, rel=tol_period)
    # And back: the parameters the measurements imply, within the propagated tolerances
    # (ζ = −L/√(π² + L²) with L = ln overshoot; ω_n = 2π/(T √(1 − ζ²))).
    log_m = math.log(overshoot)
    zeta = -log_m / math.hypot(math.pi, log_m)
    tol_zeta = math.pi**2 / (math.pi**2 + log_m**2) ** 1.5 * tol_overshoot / overshoot
    assert zeta == pytest.approx(ZETA, abs=tol_zeta)
    assert 2 * math.pi / period / math.sqrt(1 - zeta**2) == pytest.approx(
        WN, rel=tol_period + zeta * tol_zeta / (1 - zeta**2)
    )


@pytest.mark.parametrize("f_hz", [5.0, 30.0, 60.0])
def test_frequency_response_matches_the_transfer_function(f_hz):
    """Indicated rate / ω_IA = K/(K − J ω² + j c ω). The hold scales a sampled sinusoid by sinc²(f h)
    (the triangle kernel's spectrum, no phase); its images at f + k/h alias back onto f once the output
    is sampled, each weighted by |G(f + k/h)| sinc²(f h + k). So the fit equals G sinc² within that sum
    (plus 1e-11 of fitting round-off), and G within (ωh)²/12 more."""
    fs = 60000.0
    dt, w, amp = 1 / fs, 2 * math.pi * f_hz, 1e-5
    t = np.arange(int(0.25 * fs) + int(fs / 5) + 1) * dt  # settle 0.25 s (e^(−ζω_n·0.25) ≈ 1e-14), fit 0.2 s
    omega = np.zeros((t.size, 3))
    alpha = np.zeros((t.size, 3))
    omega[:, 0], alpha[:, 0] = amp * np.sin(w * t), amp * w * np.cos(w * t)
    rate = respond(omega, alpha, dt).rate[:, 0]
    keep = t >= 0.25
    a, b = sinusoid_fit(t[keep], rate[keep], w)
    measured = (a + 1j * b) / amp
    transfer = lambda f: K / (K - J * (2 * np.pi * f) ** 2 + 2j * np.pi * C * f)  # noqa: E731
    k = np.concatenate([np.arange(-200, 0), np.arange(1, 201)])
    aliased = np.sum(np.abs(transfer(f_hz + k * fs)) * np.sinc(f_hz * dt + k) ** 2)
    g = transfer(f_hz)
    assert abs(measured - g * np.sinc(f_hz * dt) ** 2) <= aliased + 1e-11
    assert abs(measured - g) <= (w * dt) ** 2 / 12 * abs(g) + aliased + 1e-11


def test_rate_ramp_lags_by_c_over_k_from_the_first_sample():
    """A steady ramp ω = a t: the gimbal starts on its particular solution, so the indicated rate is
    a (t − c/K) from t = 0 on (no start-up transient)."""
    dt, a = 1e-3, 2e-6
    t = np.arange(500) * dt
    omega = np.column_stack([a * t, 0 * t, 0 * t])
    alpha = np.column_stack([a + 0 * t, 0 * t, 0 * t])
    rate = respond(omega, alpha, dt).rate[:, 0]
    np.testing.assert_allclose(rate, a * (t - C / K), rtol=0, atol=1e-12 * a)


def test_kernel_equals_lfilter_on_the_discretised_transfer_function():
    """The recurrence is the FOH state-space model; without cross-rates it is what scipy.signal.lfilter
    does with cont2discrete's transfer function (started from rest)."""
    dt = 1e-3
    t = np.arange(3000) * dt
    w_ia = 1e-6 * (np.sin(7 * t) + 0.5 * np.sin(53 * t + 1) + 0.2 * np.sign(np.sin(3 * t))) * (t > 0)
    omega = np.column_stack([w_ia, 0 * t, 0 * t])
    theta = respond(omega, np.zeros_like(omega), dt).raw["gimbal_angle_rad"][:, 0]
    a, b = GYRO.state_space()
    sysd = scipy.signal.cont2discrete((a, b[:, None], [[1.0, 0.0]], [[0.0]]), dt, method="foh")
    num, den = scipy.signal.ss2tf(*sysd[:4])
    reference = scipy.signal.lfilter(num[0], den, H * w_ia)
    np.testing.assert_allclose(theta, reference, rtol=0, atol=1e-10 * np.abs(reference).max())
    phi, gamma0, gamma1 = foh_matrices(a, b, dt)
    np.testing.assert_allclose(phi, scipy.linalg.expm(a * dt), rtol=1e-13)


# --------------------------------------------------------------------------------------------------
# Cross-coupling, output-axis acceleration, stops
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("w_sra", [1.0, -1.0])
def test_cross_coupling_sign_and_size(w_sra):
    """Gyro x (IA x, OA y, SRA z) under ω = (ω_IA, 0, ω_SRA): K θ = H (ω_IA cos θ − ω_SRA sin θ) at rest,
    so the indicated rate errs by ≈ −(H/K) ω_IA ω_SRA, to first order in θ and (H/K) ω_SRA."""
    w_ia, dt = 0.2, 1e-3
    t, omega = step_from_rest(w_ia, dt, 1.0)
    omega[1:, 2] = w_sra
    r = respond(omega, np.zeros_like(omega), dt)
    theta_ss = scipy.optimize.brentq(lambda th: K * th - H * (w_ia * math.cos(th) - w_sra * math.sin(th)), -1, 1)
    assert r.raw["gimbal_angle_rad"][-1, 0] == pytest.approx(theta_ss, rel=1e-12)  # settled: e^(−ζω_n) ≈ 1e-56
    error = r.rate[-1, 0] - w_ia
    first_order = -(H / K) * w_ia * w_sra
    assert np.sign(error) == np.sign(first_order) == -np.sign(w_sra)
    assert error == pytest.approx(first_order, rel=(H / K) * abs(w_sra) + abs(theta_ss))


def test_output_axis_angular_acceleration_term():
    """Gyro x sees ω'_OA = α_y: its gimbal is pushed by −J α_y, an indicated-rate error −J α_y/H."""
    dt, a = 1e-3, 0.05
    t = np.arange(400) * dt
    omega = np.column_stack([0 * t, a * t, 0 * t])
    alpha = np.tile([0.0, a, 0.0], (t.size, 1))
    rate = respond(omega, alpha, dt).rate
    np.testing.assert_allclose(rate[:, 0], -J * a / H, rtol=1e-12)


def test_saturates_at_the_gimbal_stop():
    dt = 1e-4
    range_ = GYRO.range_rad_per_s
    for w0 in (1.5 * range_, -3 * range_):
        t, omega = step_from_rest(w0, dt, 0.3)
        r = respond(omega, np.zeros_like(omega), dt)
        theta = r.raw["gimbal_angle_rad"][:, 0]
        assert np.abs(theta).max() == GYRO.stop_angle_rad
        assert theta[-1] == math.copysign(GYRO.stop_angle_rad, w0)
        assert r.rate[-1, 0] == pytest.approx(math.copysign(range_, w0), rel=1e-15)
    # Within range, an overshoot that would pass the stop is cut there, and the gimbal settles inside.
    w0 = 0.98 * range_
    t, omega = step_from_rest(w0, dt, 0.3)
    theta = respond(omega, np.zeros_like(omega), dt).raw["gimbal_angle_rad"][:, 0]
    assert theta.max() == GYRO.stop_angle_rad
    settled = scipy.optimize.brentq(lambda th: K * th - H * w0 * math.cos(th), 0, 1)
    assert theta[-1] == pytest.approx(settled, rel=1e-12)


def test_a_gimbal_on_its_stop_rests_there():
    """An inelastic stop: a gimbal driven past its stop sits on it at zero velocity (the state a next
    chunk continues from), and once the input is removed it leaves the stop from rest, as the free
    loop J θ'' + c θ' + K θ = 0 from (θ_stop, 0): moving inwards, never past the stop."""
    dt = 1e-4
    t, omega = step_from_rest(1.5 * GYRO.range_rad_per_s, dt, 0.1)
    state = {}
    theta = GYRO.respond(make_truth(omega, np.zeros_like(omega), dt), np.random.default_rng(0), state).raw[
        "gimbal_angle_rad"
    ][:, 0]
    assert theta[-1] == GYRO.stop_angle_rad
    assert state["gimbal_state"][0, 0] == GYRO.stop_angle_rad and state["gimbal_state"][0, 1] == 0.0
    # Released (the rate falls to zero over the first step): from rest on the stop, the gimbal only moves in.
    off = np.zeros((200, 3))
    off[0, 0] = omega[-1, 0]
    theta = GYRO.respond(make_truth(off, np.zeros_like(off), dt), np.random.default_rng(0), state).raw[
        "gimbal_angle_rad"
    ][:, 0]
    assert theta[0] == GYRO.stop_angle_rad and np.all(np.diff(theta[:20]) < 0)


def test_inner_rate_resolves_the_natural_frequency():
    for output in (100.0, 400.0, 1000.0, 2000.0):
        inner = GYRO.inner_rate_hz(output)
        assert inner >= max(output, 20 * GYRO.natural_frequency_hz)
        assert inner / output == int(inner / output) and inner < output + 20 * GYRO.natural_frequency_hz


def test_draws_nothing_and_is_deterministic():
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    t = np.arange(300) * 1e-3
    omega = np.column_stack([np.sin(t), np.cos(3 * t), 0.3 + 0 * t])
    a = GYRO.respond(make_truth(omega, np.zeros_like(omega), 1e-3), rng)
    b = GYRO.respond(make_truth(omega, np.zeros_like(omega), 1e-3), rng)
    assert rng.bit_generator.state == state
    np.testing.assert_array_equal(a.rate, b.rate)


# --------------------------------------------------------------------------------------------------
# Long runs in chunks (the mechanism contract)
# --------------------------------------------------------------------------------------------------


def imu_angle(rate, dt):
    """The indicated angle from 0 at the first sample, as the IMU forms it from a rate: trapezoids."""
    return np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * dt * (rate[1:] + rate[:-1]), axis=0)])


def test_chunks_continue_one_run():
    """A run split into four uneven chunks that share their edge samples (one of them two samples
    long; two edges with gyro y resting on its stop, one with it free) gives the samples of one call.

    The state is the whole state (θ, θ') of the recurrence, and the torque at the shared sample is
    recomputed from the same θ and input, so the chunks repeat one call's arithmetic: the rate and
    gimbal angle agree to 1e-15 of their largest value (in fact bit for bit). The IMU's angle, the
    trapezoid sum restarted at each chunk's first sample, matches one call's sum re-based there to the
    round-off of the two sums: one rounding of a partial sum per step, n eps max|angle| for n steps.
    A fresh ``{}`` (or no state) is power-up: the gimbals start in equilibrium with that input.
    """
    dt = 1e-3
    t = np.arange(4001) * dt
    # Cross rates, an output-axis acceleration, and gyro y past its range (≈ 1.82 rad/s) at the peaks.
    omega = np.column_stack([0.3 * np.sin(3 * t) + 0.1, 2.2 * np.cos(5 * t), np.sin(0.7 * t) + 0.5])
    alpha = np.column_stack([0.9 * np.cos(3 * t), -11 * np.sin(5 * t), 0.7 * np.cos(0.7 * t)])
    whole = GYRO.respond(make_truth(omega, alpha, dt), np.random.default_rng(0), {})
    np.testing.assert_array_equal(whole.rate, respond(omega, alpha, dt).rate)  # {} and None: power-up
    theta = whole.raw["gimbal_angle_rad"]
    on_stop = np.abs(theta[:, 1]) == GYRO.stop_angle_rad
    edges = (0, 700, 701, 2700, len(t) - 1)
    assert on_stop[[700, 701]].all() and not on_stop[2700]  # the stop contact is carried across edges

    state, parts = {}, []
    for first, last in zip(edges[:-1], edges[1:]):
        cut = slice(first, last + 1)
        part = GYRO.respond(make_truth(omega[cut], alpha[cut], dt), np.random.default_rng(0), state)
        if parts:  # the shared sample repeats the previous chunk's last value
            np.testing.assert_array_equal(part.rate[0], parts[-1].rate[-1])
        # The state holds (θ, θ') of each gyro at the chunk's last sample.
        assert state["gimbal_state"].shape == (3, 2)
        np.testing.assert_array_equal(state["gimbal_state"][:, 0], part.raw["gimbal_angle_rad"][-1])
        parts.append(part)

    rate = np.concatenate([parts[0].rate] + [p.rate[1:] for p in parts[1:]])
    gimbal = np.concatenate([parts[0].raw["gimbal_angle_rad"]] + [p.raw["gimbal_angle_rad"][1:] for p in parts[1:]])
    np.testing.assert_allclose(rate, whole.rate, rtol=0, atol=1e-15 * np.abs(whole.rate).max())
    np.testing.assert_allclose(gimbal, theta, rtol=0, atol=1e-15 * np.abs(theta).max())
    angle = imu_angle(whole.rate, dt)
    for first, last, part in zip(edges[:-1], edges[1:], parts):
        rebased = angle[first : last + 1] - angle[first]
        bound = len(t) * np.finfo(float).eps * np.abs(angle).max()
        np.testing.assert_allclose(imu_angle(part.rate, dt), rebased, rtol=0, atol=bound)

    # A fresh state on a later chunk is a power-up there, not the continued run.
    cut = slice(2700, len(t))
    fresh = GYRO.respond(make_truth(omega[cut], alpha[cut], dt), np.random.default_rng(0), {})
    np.testing.assert_array_equal(fresh.rate, respond(omega[cut], alpha[cut], dt).rate)
    assert not np.allclose(fresh.rate[:100], parts[-1].rate[:100], rtol=1e-6, atol=0)


# --------------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "key, value",
    [
        ("rotor_inertia_kgm2", 0.0),
        ("spin_speed_rpm", -24000),
        ("gimbal_inertia_kgm2", -1e-6),
        ("spring_stiffness_n_m_per_rad", 0),
        ("damping_n_m_s_per_rad", -1e-3),
        ("stop_angle_deg", 90),
        ("stop_angle_deg", 0),
        ("damping_n_m_s_per_rad", "2e-3"),
        ("spring_stiffness_nm_per_rad", 0.3),
    ],
)
def test_bad_parameters_name_the_key(key, value):
    with pytest.raises(ConfigError) as err:
        validate(RateGyro, {"kind": "rate-gyro", key: value})
    assert err.value.key == key
    assert key in str(err.value)


def test_gimbal_step_solves_its_implicit_torque_equation_to_round_off():
    """Each step solves θ_{k+1} = p + g u(θ_{k+1}), u(θ) = H (ω_IA cos θ − ω_SRA sin θ) − J ω'_OA, by
    Newton from the predictor. With Φ = I, Γ₀ = 0, Γ₁ = (g, 0), p = θ_k: a strongly θ-dependent torque
    (g H = 0.5, both rates 1 rad/s, starting 1 rad off) must still leave a round-off residual."""
    from gyroemu.sensors.rate_gyro import _gimbal_recurrence

    g, h, steps = 0.5, 1.0, 20
    w = np.ones((steps, 1))
    out = np.empty((steps, 1, 2))
    _gimbal_recurrence(
        np.eye(2), np.zeros(2), np.array([g, 0.0]), np.array([[1.0, 0.0]]), h, 0.0, w, w, 0 * w, 10.0, out
    )
    theta = out[:, 0, 0]
    residual = theta[1:] - theta[:-1] - g * h * (np.cos(theta[1:]) - np.sin(theta[1:]))
    assert np.abs(residual).max() < 8 * np.finfo(float).eps
    assert abs(theta[-1] - np.pi / 4) < 1e-3  # heading for the balance cos θ = sin θ


@pytest.mark.parametrize("w_ia, torque", [(-0.43, 0.0), (-0.434, -0.0078)])
def test_static_balance_solves_a_hard_unique_balance_to_round_off(w_ia, torque):
    """K θ = H (ω_IA cos θ − ω_SRA sin θ) + torque with K > H |ω| has exactly one root; a large ω_SRA
    (H|ω| at 97 % of K, the slope down to 3 % of K near it) is the hard case for Newton, and eight
    steps from H ω_IA/K must still reach it to round-off, inside the stops."""
    from gyroemu.sensors.rate_gyro import _static_balance

    k, h, w_sra, stop = 5.57, 1.0, -5.4, 1.5
    theta = _static_balance(k, h, np.array([w_ia]), np.array([w_sra]), np.array([torque]), stop)
    assert abs(theta[0]) < stop
    residual = k * theta - h * (w_ia * np.cos(theta) - w_sra * np.sin(theta)) - torque
    assert abs(residual[0]) < 16 * np.finfo(float).eps * (k * abs(theta[0]) + h * math.hypot(w_ia, w_sra))


@pytest.mark.parametrize("damping", [1e300, 1e3])
def test_an_overdamped_gimbal_faster_than_any_real_one_is_refused_naming_the_damping(damping):
    """A damper of 1e300 N·m·s/rad made the gimbal angle and every output NaN: the overdamped gimbal's fast
    pole (c + √(c² − 4KJ))/4πJ is bounded like the natural frequency (MAX_GIMBAL_POLE_HZ)."""
    with pytest.raises(ConfigError, match="fast pole") as err:
        validate(RateGyro, {"kind": "rate-gyro", "damping_n_m_s_per_rad": damping}, prefix="gyro.mechanism")
    assert err.value.key == "gyro.mechanism.damping_n_m_s_per_rad"
    assert "real gyros" in err.value.reason


def test_a_heavily_overdamped_gimbal_within_the_limit_gives_finite_numbers():
    """ζ ≈ 1600 (c = 5 N·m·s/rad for the default J and K; its fast pole 94 kHz, inside the limit)."""
    gyro = validate(RateGyro, {"kind": "rate-gyro", "damping_n_m_s_per_rad": 5.0})
    dt = 1.0 / gyro.inner_rate_hz(200.0)
    t = np.arange(201) * dt
    omega = np.tile([0.1, -0.2, 0.3], (len(t), 1))
    response = gyro.respond(GyroTruth(t=t, dt=dt, omega=omega, alpha=np.zeros_like(omega)), np.random.default_rng(0))
    assert response.rate is not None and np.isfinite(response.rate).all()
    assert np.isfinite(response.raw["gimbal_angle_rad"]).all()
