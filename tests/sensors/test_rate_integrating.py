"""The rate-integrating gyro against its closed forms: integral response, corner frequency, the
torque-rebalance loop's steady current, bandwidth and frequency response, stops, config errors.

Tolerances come from theory, as in ``test_rate_gyro.py``: exact (round-off) against the closed-form
response to the piecewise-linear input the simulation sees; the first-order hold's sinc²(f h) and
one-step ramp against continuous-input forms. Small inputs keep cos θ = 1 to round-off where the
linear model is checked.
"""

import math
import warnings

import numpy as np
import pytest

from gyroemu.dynamics.config import ConfigError, validate
from gyroemu.sensors.mechanism import GyroTruth, mechanism_class
from gyroemu.sensors.rate_integrating import RateIntegratingGyro

LOOP = RateIntegratingGyro()
OPEN = RateIntegratingGyro(torque_rebalance=False)
H, J, C = LOOP.spin_momentum, LOOP.gimbal_inertia_kgm2, LOOP.damping_n_m_s_per_rad
KT = LOOP.torquer_scale_n_m_per_a


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


def respond(gyro, omega, alpha, dt):
    return gyro.respond(make_truth(omega, alpha, dt), np.random.default_rng(0))


def step_from_rest(w0, dt, duration, axis=0):
    """ω (M, 3): 0 at t = 0, ``w0`` (scalar or 3-vector on ``axis``) from the next sample on."""
    m = int(round(duration / dt)) + 1
    omega = np.zeros((m, 3))
    omega[1:, axis] = w0
    return np.arange(m) * dt, omega


def sinusoid(f_hz, amp, fs, settle_s, fit_periods, axis=0):
    """t, ω, α for ω_axis = amp sin 2πft, over a settling time and then whole periods; and the fit mask."""
    w = 2 * math.pi * f_hz
    m = int(round((settle_s + fit_periods / f_hz) * fs)) + 1
    t = np.arange(m) / fs
    omega, alpha = np.zeros((m, 3)), np.zeros((m, 3))
    omega[:, axis], alpha[:, axis] = amp * np.sin(w * t), amp * w * np.cos(w * t)
    keep = t >= settle_s
    keep[-1] = False  # whole periods: [settle, settle + n/f)
    return t, omega, alpha, keep


def complex_amplitude(t, y, w):
    """c such that y ≈ Im(c e^{jωt}) + const: the phasor of the sin-referenced sinusoid."""
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(basis, y, rcond=None)[0]
    return a + 1j * b


def alias_bound(transfer, f_hz, fs):
    """Σ_{k≠0} |G(f + k fs)| sinc²((f + k fs)/fs): what the first-order hold's images of a sampled
    sinusoid add back at f once the output is sampled (G: continuous transfer function, relative to the
    true output's amplitude)."""
    k = np.concatenate([np.arange(-200, 0), np.arange(1, 201)])
    f = f_hz + k * fs
    return float(np.sum(np.abs(transfer(f)) * np.sinc(f / fs) ** 2))


def unit_ramp_response(t):
    """θ(t) for J θ'' + c θ' = t·1(t) from rest: t²/2c − (J/c²)(t − (J/c)(1 − e^{−ct/J}))."""
    t = np.maximum(t, 0.0)
    return t * t / (2 * C) - J / C**2 * (t - J / C * (1 - np.exp(-C * t / J)))


# --------------------------------------------------------------------------------------------------
# Open loop: the integrating gimbal
# --------------------------------------------------------------------------------------------------


def test_defaults():
    assert H / C == pytest.approx(1.0053, rel=1e-4)
    assert OPEN.corner_frequency_hz == pytest.approx(79.577, rel=1e-4)
    np.testing.assert_allclose(
        np.sort_complex(np.roots(LOOP.loop_polynomial)), [-200 - 200j, -200 + 200j, -100], rtol=1e-9
    )
    assert LOOP.loop_bandwidth_hz == pytest.approx(60.86, abs=0.01)
    assert mechanism_class("rate-integrating") is RateIntegratingGyro


def test_integral_response_to_a_step_matches_the_closed_form():
    """Exactly the response to the held input (a ramp over the first step), and within (H/c) ω h/2 of
    θ(t) = (H/c) ω [t − (J/c)(1 − e^{−ct/J})] for an ideal step (the ramp loses ω h/2 of input angle,
    and the float's response to an angle impulse is (H/c)(1 − e^{−ct/J}) ≤ H/c)."""
    dt, w0 = 1e-4, 1e-7
    t, omega = step_from_rest(w0, dt, 0.2, axis=1)
    r = respond(OPEN, omega, np.zeros_like(omega), dt)
    theta = r.raw["gimbal_angle_rad"][:, 1]
    exact = H * w0 / dt * (unit_ramp_response(t) - unit_ramp_response(t - dt))
    np.testing.assert_allclose(theta, exact, rtol=0, atol=1e-11 * np.abs(exact).max())
    ideal = H / C * w0 * (t - J / C * (1 - np.exp(-C * t / J)))
    assert np.abs(theta - ideal).max() <= H / C * w0 * dt / 2 * (1 + 1e-9)
    # The indicated angle (c/H) θ approaches the input angle, lagging it by ω J/c.
    np.testing.assert_allclose(r.angle[:, 1], C / H * theta, rtol=1e-15)
    assert r.angle[-1, 1] == pytest.approx(w0 * (t[-1] - dt / 2 - J / C), rel=1e-10)
    np.testing.assert_array_equal(r.raw["torquer_current_a"], 0.0)


@pytest.mark.parametrize("ratio", [0.1, 1.0, 10.0])
def test_corner_frequency(ratio):
    """Indicated angle / input angle = 1/(1 + jω J/c): at the corner c/J, 1/√2 at −45°. The fit equals
    it times the hold's sinc²(f h) within the images' alias bound (plus 1e-11 of fitting round-off)."""
    f = ratio * OPEN.corner_frequency_hz
    w, fs = 2 * math.pi * f, 100 * f * max(1.0, 10 / ratio)
    t, omega, alpha, keep = sinusoid(f, 1e-6, fs, settle_s=30 * J / C, fit_periods=4)
    angle = respond(OPEN, omega, alpha, 1 / fs).angle[:, 0]
    measured = complex_amplitude(t[keep], angle[keep], w)
    true_angle = -1e-6 / w * 1j  # ∫ A sin ωt dt = −(A/ω) cos ωt = Im(−j A/ω · e^{jωt})
    ratio_measured = measured / true_angle
    expected = 1 / (1 + 1j * w * J / C)
    # Output per unit true angle at frequency g: the lag times ω_IA → angle (1/jωg), over 1/jω.
    aliased = alias_bound(lambda g: w / np.abs(2 * np.pi * g) / np.abs(1 + 2j * np.pi * g * J / C), f, fs)
    assert abs(ratio_measured - expected * np.sinc(f / fs) ** 2) <= aliased + 1e-11
    if ratio == 1.0:
        assert abs(ratio_measured) == pytest.approx(2**-0.5, abs=(w / fs) ** 2 / 12 + aliased + 1e-11)
        assert np.angle(ratio_measured) == pytest.approx(-math.pi / 4, abs=2 * (aliased + 1e-11))


def test_open_loop_stops_warn_and_hold_the_angle():
    dt = 1e-4
    t, omega = step_from_rest(1.0, dt, 0.1)  # 0.1 rad of input angle > (c/H)·2° = 0.035 rad
    with pytest.warns(RuntimeWarning, match="stops"):
        r = respond(OPEN, omega, np.zeros_like(omega), dt)
    theta = r.raw["gimbal_angle_rad"][:, 0]
    assert np.abs(theta).max() == OPEN.stop_angle_rad
    assert r.angle[-1, 0] == pytest.approx(OPEN.stop_angle_rad / OPEN.gimbal_gain, rel=1e-15)


def test_open_loop_starts_in_balance_so_a_steady_rate_reads_exactly():
    """A steady rate from t[0]: the float starts on the particular solution θ' = H ω/c of
    J θ'' + c θ' = H ω, so the indicated angle is ω t from the first sample (no lag J/c to settle
    into, which would cost ω J/c = 2e-3 of ω t at 1 s). One axis: θ ≈ 1e-7 rad keeps cos θ = 1 to
    5e-15 and, with no rate on any spin axis, there is no cross-coupling."""
    dt = 1e-3
    w = 1e-7
    t = np.arange(1001) * dt
    omega = np.zeros((t.size, 3))
    omega[:, 0] = w
    r = respond(OPEN, omega, np.zeros_like(omega), dt)
    np.testing.assert_allclose(r.angle[:, 0], w * t, rtol=1e-12, atol=1e-12 * w * dt)
    np.testing.assert_array_equal(r.angle[:, 1:], 0.0)


# --------------------------------------------------------------------------------------------------
# Torque rebalance
# --------------------------------------------------------------------------------------------------


def test_steady_current_is_h_omega_over_kt_and_the_gimbal_is_nulled():
    """From rest, a rate step on all three gyros: after the loop settles (slowest pole 100 s⁻¹,
    0.4 s ≈ e^{−40}), i = H ω/k_t, θ = 0, and the indicated angle is the input angle ∫ω = ω (t − h/2)
    up to the cross-coupling −ω_SRA ∫θ dt collected while the gimbal was deflected: ∫θ dt ends at
    the integrator's charge i/k_i, so the error is −ω_SRA H ω_IA/(k_t k_i), to within the next terms of
    ω_IA cos θ − ω_SRA sin θ: |ω_IA| ∫θ²/2 dt + |ω_SRA| ∫|θ|³/6 dt."""
    dt = 1e-4
    w = np.array([0.3, -0.2, 0.1])
    t, omega = step_from_rest(0.0, dt, 0.4)
    omega[1:] = w
    r = respond(LOOP, omega, np.zeros_like(omega), dt)
    np.testing.assert_allclose(r.raw["torquer_current_a"][-1], H * w / KT, rtol=1e-12)
    assert np.abs(r.raw["gimbal_angle_rad"][-1]).max() < 1e-15
    w_sra = w[[2, 0, 1]]
    cross = -w_sra * H * w / (KT * LOOP.loop_integral_a_per_rad_s)
    theta = r.raw["gimbal_angle_rad"]
    remainder = (np.abs(w) * (theta**2 / 2).sum(0) + np.abs(w_sra) * (np.abs(theta) ** 3 / 6).sum(0)) * dt
    assert np.all(np.abs(r.angle[-1] - (w * (t[-1] - dt / 2) + cross)) <= remainder + 1e-12 * np.abs(w))
    assert np.all(remainder < 0.01 * np.abs(cross))  # the first-order term is what is checked


def test_starts_in_balance_so_a_steady_rate_reads_exactly():
    """A steady rate from t[0]: current H ω/k_t and indicated angle ω t from the first sample, with no
    cross-coupling (θ = 0 throughout)."""
    dt = 1e-3
    w = np.array([0.5, 1.0, -2.0])
    t = np.arange(1000) * dt
    r = respond(LOOP, np.tile(w, (t.size, 1)), np.zeros((t.size, 3)), dt)
    np.testing.assert_allclose(r.raw["torquer_current_a"], np.tile(H * w / KT, (t.size, 1)), rtol=1e-12)
    # Nulled, to round-off: the loop's states carry the integrated rate (up to |ω| t of angle), and θ is
    # what is left when they cancel, so its round-off is a few ε of that angle. A start out of balance
    # would leave a transient of order H|ω|/(k_t k_p), 8e-3 rad here.
    roundoff = 8 * np.finfo(float).eps * np.abs(w).max() * t[-1]
    assert np.abs(r.raw["gimbal_angle_rad"]).max() <= roundoff
    np.testing.assert_allclose(r.angle, np.outer(t, w), rtol=1e-12, atol=1e-15)


def test_proportional_loop_starts_in_balance_on_a_ramping_rate():
    """With k_i = 0 the loop is proportional only: for ω = ω₀ + β t (u = H ω) the particular solution
    is θ = u/(k_t k_p) − c u'/(k_t k_p)², θ' = u'/(k_t k_p), and the gyro starts on it, so θ follows
    it from the first sample to round-off (the first-order hold is exact for the ramp). The rate is
    kept tiny so that cos θ = 1 to round-off."""
    gyro = RateIntegratingGyro(loop_integral_a_per_rad_s=0.0)
    gain = KT * gyro.loop_proportional_a_per_rad
    dt, w0, beta = 1e-3, 1e-6, 2e-6
    t = np.arange(500) * dt
    omega, alpha = np.zeros((t.size, 3)), np.zeros((t.size, 3))
    omega[:, 0], alpha[:, 0] = w0 + beta * t, beta
    r = respond(gyro, omega, alpha, dt)
    want = H * (w0 + beta * t) / gain - C * H * beta / gain**2
    theta = r.raw["gimbal_angle_rad"][:, 0]
    np.testing.assert_allclose(theta, want, rtol=64 * np.finfo(float).eps, atol=0)
    np.testing.assert_allclose(r.raw["torquer_current_a"][:, 0], gyro.loop_proportional_a_per_rad * want, rtol=1e-13)


def test_bandwidth_formula():
    """|T(j ω_b)| = 1/√2 for ω_b from the cubic (5); and the J → 0 second-order formula is close
    when the float is much faster than the loop."""
    assert abs(LOOP.loop_response(LOOP.loop_bandwidth_hz)) == pytest.approx(2**-0.5, rel=1e-12)
    f = np.linspace(0.01, 0.999, 2000) * LOOP.loop_bandwidth_hz
    assert np.all(abs(LOOP.loop_response(f)) > 2**-0.5)  # the first crossing
    fast = RateIntegratingGyro(gimbal_inertia_kgm2=1e-8)  # float corner 80 kHz (MAX_GIMBAL_POLE_HZ: 100 kHz)
    wn2, two_zeta_wn = KT * fast.loop_integral_a_per_rad_s / C, KT * fast.loop_proportional_a_per_rad / C
    q = 1 + 2 * (two_zeta_wn**2 / (4 * wn2))
    second_order = math.sqrt(wn2 * (q + math.sqrt(q * q + 1))) / (2 * math.pi)
    assert fast.loop_bandwidth_hz == pytest.approx(second_order, rel=1e-3)


@pytest.mark.parametrize("f_hz", [10.0, LOOP.loop_bandwidth_hz, 150.0])
def test_closed_loop_frequency_response(f_hz):
    """Indicated rate k_t i/H over ω_IA = (4) times the hold's sinc²(f h), within the images' alias
    bound; at the bandwidth its magnitude is 1/√2 within (ωh)²/12 more."""
    fs = 20000.0
    w = 2 * math.pi * f_hz
    t, omega, alpha, keep = sinusoid(f_hz, 1e-5, fs, settle_s=0.4, fit_periods=max(1, round(f_hz / 10)))
    r = respond(LOOP, omega, alpha, 1 / fs)
    rate = KT * r.raw["torquer_current_a"][:, 0] / H
    measured = complex_amplitude(t[keep], rate[keep], w) / 1e-5
    expected = LOOP.loop_response(f_hz)
    aliased = alias_bound(LOOP.loop_response, f_hz, fs)
    assert abs(measured - expected * np.sinc(f_hz / fs) ** 2) <= aliased + 1e-11
    if f_hz == LOOP.loop_bandwidth_hz:
        assert abs(measured) == pytest.approx(2**-0.5, abs=(w / fs) ** 2 / 12 + aliased + 1e-11)


def test_rebalance_removes_the_cross_coupling():
    """A steady rate on the spin axis changes nothing in balance (θ = 0), where the open-loop gimbal
    angle would carry the −ω_SRA sin θ term."""
    dt = 1e-3
    t = np.arange(500) * dt
    omega = np.tile([0.4, 0.0, 3.0], (t.size, 1))  # gyro x: IA = x, SRA = z
    r = respond(LOOP, omega, np.zeros_like(omega), dt)
    np.testing.assert_allclose(r.angle[:, 0], 0.4 * t, rtol=1e-12)


def test_inner_rate_resolves_the_fastest_pole():
    assert LOOP.inner_rate_hz(1000.0) == 1000.0  # poles at |−200 ± 200j| = 45 Hz: 20 × 45 < 1000
    assert LOOP.inner_rate_hz(100.0) == 1000.0
    assert OPEN.inner_rate_hz(1000.0) == 2000.0  # corner 79.6 Hz → ≥ 1592 Hz
    assert RateIntegratingGyro(torque_rebalance=False).inner_rate_hz(400.0) == 1600.0


# --------------------------------------------------------------------------------------------------
# Long runs in chunks (the mechanism contract)
# --------------------------------------------------------------------------------------------------


def wandering(dt, scale, duration=4.0):
    """ω, α: cross rates and an output-axis acceleration on every gyro, times ``scale`` (0.005: the open
    loop stays off its stops)."""
    t = np.arange(int(round(duration / dt)) + 1) * dt
    omega = scale * np.column_stack([0.3 * np.sin(3 * t) + 0.1, 2.2 * np.cos(5 * t), np.sin(0.7 * t) + 0.5])
    alpha = scale * np.column_stack([0.9 * np.cos(3 * t), -11 * np.sin(5 * t), 0.7 * np.cos(0.7 * t)])
    return t, omega, alpha


@pytest.mark.parametrize("gyro, dt, scale", [(LOOP, 1e-3, 1.0), (OPEN, 5e-4, 0.005)], ids=["loop", "open"])
def test_chunks_continue_one_run(gyro, dt, scale):
    """A run split into four uneven chunks sharing their edge samples (one two samples long) gives one
    call's samples, the indicated angle re-based at each chunk's first sample as the IMU does.

    The state is the recurrence's whole state x (θ, θ', and closed-loop ∫θ dt, ∫i dt), and the torque
    at the shared sample is recomputed from the same numbers, so the gimbal angle and current agree to
    1e-15 of their largest value (in fact bit for bit). The chunk's angle (k_t/H)(∫i − ∫i₀), or
    (c/H)(θ − θ₀), and one call's re-based (k_t/H)∫i − (k_t/H)∫i₀ differ by the rounding of the
    products and the difference, ≤ 4 eps max|angle|. A fresh ``{}`` (or no state) is power-up.
    """
    t, omega, alpha = wandering(dt, scale)
    whole = gyro.respond(make_truth(omega, alpha, dt), np.random.default_rng(0), {})
    np.testing.assert_array_equal(whole.angle, respond(gyro, omega, alpha, dt).angle)  # {} and None: power-up
    n = len(t) - 1
    edges = (0, n // 5, n // 5 + 1, (3 * n) // 4, n)
    state, parts = {}, []
    for first, last in zip(edges[:-1], edges[1:]):
        cut = slice(first, last + 1)
        part = gyro.respond(make_truth(omega[cut], alpha[cut], dt), np.random.default_rng(0), state)
        assert part.angle[0].tolist() == [0.0, 0.0, 0.0]  # the angle restarts at the chunk's first sample
        if parts:  # the shared sample repeats the previous chunk's last value
            for name in part.raw:
                np.testing.assert_array_equal(part.raw[name][0], parts[-1].raw[name][-1])
        # The state holds x of each gyro at the chunk's last sample.
        assert state["gimbal_state"].shape == (3, 4 if gyro.torque_rebalance else 2)
        np.testing.assert_array_equal(state["gimbal_state"][:, 0], part.raw["gimbal_angle_rad"][-1])
        parts.append(part)

    for name, values in whole.raw.items():
        joined = np.concatenate([parts[0].raw[name]] + [p.raw[name][1:] for p in parts[1:]])
        np.testing.assert_allclose(joined, values, rtol=0, atol=1e-15 * np.abs(values).max())
    bound = 4 * np.finfo(float).eps * np.abs(whole.angle).max()
    for first, last, part in zip(edges[:-1], edges[1:], parts):
        np.testing.assert_allclose(part.angle, whole.angle[first : last + 1] - whole.angle[first], rtol=0, atol=bound)

    # A fresh state on a later chunk is a power-up there, not the continued run.
    cut = slice(edges[-2], len(t))
    fresh = gyro.respond(make_truth(omega[cut], alpha[cut], dt), np.random.default_rng(0), {})
    np.testing.assert_array_equal(fresh.angle, respond(gyro, omega[cut], alpha[cut], dt).angle)
    assert not np.allclose(fresh.raw["gimbal_angle_rad"], parts[-1].raw["gimbal_angle_rad"], rtol=1e-6, atol=0)


def test_open_loop_warns_of_its_stops_once_per_run():
    dt = 1e-4
    t, omega = step_from_rest(1.0, dt, 0.1)  # on the stops from ≈ 0.035 s
    state = {}
    with pytest.warns(RuntimeWarning, match="stops") as record:
        for first, last in ((0, 400), (400, 700), (700, len(t) - 1)):
            cut = slice(first, last + 1)
            OPEN.respond(make_truth(omega[cut], np.zeros_like(omega[cut]), dt), np.random.default_rng(0), state)
    assert len([w for w in record if "stops" in str(w.message)]) == 1 and state["stop_warned"]


# --------------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "data, key",
    [
        ({"gimbal_inertia_kgm2": 0}, "gimbal_inertia_kgm2"),
        ({"damping_n_m_s_per_rad": -5e-3}, "damping_n_m_s_per_rad"),
        ({"rotor_inertia_kgm2": -2e-6}, "rotor_inertia_kgm2"),
        ({"spin_speed_rpm": 0}, "spin_speed_rpm"),
        ({"stop_angle_deg": 95}, "stop_angle_deg"),
        ({"torquer_scale_n_m_per_a": 0}, "torquer_scale_n_m_per_a"),
        ({"loop_proportional_a_per_rad": 0}, "loop_proportional_a_per_rad"),
        ({"loop_integral_a_per_rad_s": -1}, "loop_integral_a_per_rad_s"),
        ({"loop_integral_a_per_rad_s": 30000}, "loop_integral_a_per_rad_s"),  # k_i ≥ c k_p/J = 30000
        ({"loop_proportional_a_per_rad": 5}, "loop_integral_a_per_rad_s"),  # the default k_i is now unstable
        ({"loop_integral_a_per_rad_s": 1e-300}, "loop_integral_a_per_rad_s"),  # an integral corner of 3e-303 Hz
        ({"loop_integral_a_per_rad_s": 0.37}, "loop_integral_a_per_rad_s"),  # 0.98 mHz: below MIN_INTEGRAL_CORNER_HZ
        ({"torque_rebalance": "yes"}, "torque_rebalance"),
        ({"damping_n_m_s_per_rad_per_degC": 1}, "damping_n_m_s_per_rad_per_degC"),
    ],
)
def test_bad_parameters_name_the_key(data, key):
    with pytest.raises(ConfigError) as err:
        validate(RateIntegratingGyro, {"kind": "rate-integrating", **data})
    assert err.value.key == key


def test_the_slowest_integral_corner_is_taken_and_runs_finite():
    """k_i at the 1 mHz corner (k_p 60: k_i = 0.377) and k_i = 0, a proportional loop, are taken; a
    rebalanced gyro with the slow corner reads finite rates (k_i = 1e-300 read NaN)."""
    import tomllib

    from gyroemu.dynamics import load_scenario
    from gyroemu.dynamics.config import config_dir
    from gyroemu.sensors import device_from_dict
    from gyroemu.sensors.rate_integrating import MIN_INTEGRAL_CORNER_HZ

    k_i = 60 * 2 * np.pi * MIN_INTEGRAL_CORNER_HZ * (1 + 1e-12)
    for value in (k_i, 0.0):
        validate(RateIntegratingGyro, {"kind": "rate-integrating", "loop_integral_a_per_rad_s": value})
    table = tomllib.loads((config_dir() / "devices" / "floated_rig.toml").read_text())
    table["gyro"]["mechanism"]["loop_integral_a_per_rad_s"] = k_i
    samples = device_from_dict(table).measure(load_scenario("smooth_manoeuvre").simulate(duration=0.5))
    assert np.isfinite(samples.gyro).all()


def test_unstable_gains_are_fine_with_the_loop_open():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gyro = validate(RateIntegratingGyro, {"torque_rebalance": False, "loop_proportional_a_per_rad": 5})
    assert not gyro.torque_rebalance
