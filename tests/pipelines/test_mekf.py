"""gyroemu's MEKF: the filterpy form against its compiled batched twin, what it must recover on
simulated data, its handling of bad samples, and the constraint of its heading update."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from broad_trials import BROAD_DIR, needs_trial
from scipy.spatial.transform import Rotation

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.earth import EARTH_RATE
from gyroemu.dynamics.rotation import quat_conjugate, quat_rotate
from gyroemu.pipelines.estimation import FilterSetup, Mekf, MekfParams, attitude_errors, rmse_deg, setup_for
from gyroemu.pipelines.estimation import mekf_kernels as kern
from gyroemu.pipelines.estimation.batched import mekf_batch
from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.formats.mcap_log import truth_series
from gyroemu.sensors import load_device
from gyroemu.sensors.gyrocompass import heading_uncertainty

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def manoeuvre():
    scenario = load_scenario("smooth_manoeuvre")
    return scenario, scenario.simulate(duration=120.0)


@pytest.mark.parametrize("latency_s", [(0.0, 0.0), (0.004, 0.015)])
def test_batched_mode_is_the_filterpy_filter(manoeuvre, latency_s):
    """Same kernels, Kalman algebra from filterpy or compiled: the same attitudes to round-off; with the
    sensors' latencies too (``mekf_batch`` times the runs as ``make_filter``'s wrapper does)."""
    scenario, traj = manoeuvre
    short = traj[:2001]
    runs = [load_device("consumer_mems", seed=s).measure(short) for s in (0, 1)]
    setup = setup_for(load_device("consumer_mems"), scenario)
    setup = replace(setup, gyro_latency_s=latency_s[0], mag_latency_s=latency_s[1])
    batch = mekf_batch(
        setup,
        runs[0].t,
        np.stack([r.gyro for r in runs]),
        np.stack([r.accel for r in runs]),
        np.stack([r.mag for r in runs]),
    )
    for i, r in enumerate(runs):
        single = make_filter("mekf", setup).process(r.t, r.gyro, r.accel, r.mag)
        assert np.abs(single.q_wb - batch.q_wb[i]).max() < 1e-9
        assert np.abs(single.gyro_bias - batch.gyro_bias[i]).max() < 1e-12


def test_consumer_mems_beats_its_accelerometer_and_learns_its_bias(manoeuvre):
    """6D on the smooth manoeuvre: the inclination error over the second minute is below the tilt that
    the non-gravitational acceleration puts on an accelerometer-only solution (its RMS, from the truth),
    and the bias error across the vertical at the end is below half the bias itself."""
    scenario, traj = manoeuvre
    device = load_device("consumer_mems", seed=0)
    samples = device.measure(traj)
    truth = truth_series(traj, samples)
    est = Mekf(setup_for(device, scenario, use_mag=False)).process(samples.t, samples.gyro, samples.accel)
    err = attitude_errors(est.q_wb, truth.q_wb)
    second_minute = samples.t >= 60.0
    # apparent tilt of the accelerometer: angle between the specific force and the true up, body axes
    up_b = quat_rotate(quat_conjugate(truth.q_wb), np.array([0.0, 0.0, 1.0]))
    f = truth.specific_force_b
    tilt = np.arccos(np.clip(np.sum(up_b * f, axis=1) / np.linalg.norm(f, axis=1), -1, 1))
    assert rmse_deg(err.inclination[second_minute]) < rmse_deg(tilt[second_minute])
    bias = device.measure_held_still(traj).gyro
    b_end = bias[-1000:].mean(axis=0)
    # 6D: only the bias across the vertical is observable (gravity says nothing about heading drift);
    # the manoeuvre tilts the body's z axis by at most ~35°, so its x and y are the observable ones
    assert np.linalg.norm(est.gyro_bias[-1, :2] - b_end[:2]) < 0.5 * np.linalg.norm(b_end[:2])


@pytest.mark.parametrize("seed", [0, 1])
def test_consumer_mems_meets_the_issue_bars_on_the_smooth_manoeuvre(seed):
    """The issue's simulated bars, 6D, over the scenario's whole run (300 s): inclination RMSE below 1°,
    and the gyro bias converged within 60 s. Converged means learnt and known: at 60 s the filter's σ
    of the bias across the vertical (body x, y: what gravity observes) is below a quarter of the
    turn-on σ, and from then on the error over that σ has an RMS within the 99.9 % χ² bound for 8
    independent samples (a floor on how many 240 s of a bias error correlated over ~30 s hold). The
    bias truth is the device run on the same trajectory held still (bias, drift, its mechanism's
    quadrature and g-sensitivity), averaged over 1 s."""
    from scipy.stats import chi2

    scenario = load_scenario("smooth_manoeuvre")
    traj = scenario.simulate()
    device = load_device("consumer_mems", seed=seed)
    samples = device.measure(traj)
    setup = setup_for(device, scenario, use_mag=False)
    mekf, block = Mekf(setup), int(device.spec.rate_hz)
    q, bias_est, sigma = [], [], []
    for k in range(0, len(samples.t), block):
        est = mekf.process(samples.t[k : k + block], samples.gyro[k : k + block], samples.accel[k : k + block])
        q.append(est.q_wb)
        bias_est.append(est.gyro_bias[-1, :2])
        sigma.append(np.sqrt(np.diag(mekf.kf.P)[kern.X_BIAS : kern.X_BIAS + 2]))
    err = attitude_errors(np.concatenate(q), truth_series(traj, samples).q_wb)
    assert rmse_deg(err.inclination) < 1.0

    still = device.measure_held_still(traj).gyro
    ends = np.minimum(np.arange(block, len(samples.t) + block, block), len(samples.t)) - 1
    bias_true = np.array([still[max(e - block // 2, 0) : e + block // 2, :2].mean(axis=0) for e in ends])
    t_end, sigma = samples.t[ends] - samples.t[0], np.array(sigma)
    at_60 = int(np.searchsorted(t_end, 60.0))
    assert np.all(sigma[at_60] < setup.noise.gyro_bias_sigma / 4)
    normalised = (np.array(bias_est) - bias_true)[at_60:] / sigma[at_60:]
    assert np.sqrt(np.mean(normalised**2)) < np.sqrt(chi2.ppf(0.999, 8) / 8)


def test_navigation_fog_finds_north_from_earth_rate():
    """6D, at rest, latitude known: the heading error is within 3σ of what the FOG's bias and noise
    allow (gyroemu.sensors.gyrocompass.heading_uncertainty), and a consumer MEMS filter does not claim it."""
    scenario = load_scenario("bench_static")
    traj = scenario.simulate(duration=60.0)
    device = load_device("navigation_fog", seed=3)
    samples = device.measure(traj)
    setup = setup_for(device, scenario)
    assert not setup.use_mag and setup.latitude_rad is not None
    est = Mekf(setup).process(samples.t, samples.gyro, samples.accel)
    err = attitude_errors(est.q_wb, truth_series(traj, samples).q_wb)
    n = setup.noise
    sigma = heading_uncertainty(setup.latitude_rad, 60.0, bias=n.gyro_bias_sigma, noise_density=n.gyro_noise_density)
    assert err.heading[-1] < 3 * sigma
    assert np.sqrt(est.q_wb_covariance[-1, 2, 2]) < 3 * sigma
    consumer = load_device("consumer_mems", seed=3)
    c_est = Mekf(setup_for(consumer, scenario, use_mag=False)).process(
        *(lambda s: (s.t, s.gyro, s.accel))(consumer.measure(traj))
    )
    assert np.sqrt(c_est.q_wb_covariance[-1, 2, 2]) > np.radians(20)  # knows it does not know


def test_nan_dropped_and_uneven_samples():
    """An ideal IMU with 5 % of samples dropped (uneven stamps) and 1 % NaN rows: the filter keeps to
    the attitude (no NaN out, inclination within the tilt its initial averaging leaves, 1°)."""
    scenario = load_scenario("rate_table_tumble")
    traj = scenario.simulate(duration=30.0)
    samples = load_device("ideal", seed=0).measure(traj)
    truth = truth_series(traj, samples)
    rng = np.random.default_rng(0)
    keep = np.sort(rng.choice(len(samples.t), size=int(0.95 * len(samples.t)), replace=False))
    keep[0] = 0
    gyro, accel = samples.gyro[keep].copy(), samples.accel[keep].copy()
    # a kept sample after a gap covers the whole gap: its rate is the mean over it (strapdown convention)
    t = samples.t[keep]
    nan = rng.choice(len(keep), size=len(keep) // 100, replace=False)
    gyro[nan] = np.nan
    accel[nan] = np.nan
    setup = FilterSetup(rate_hz=float(1 / np.median(np.diff(t))), use_mag=False)
    est = Mekf(setup).process(t, gyro, accel)
    assert np.isfinite(est.q_wb).all()
    err = attitude_errors(est.q_wb, truth.q_wb[keep])
    assert rmse_deg(err.inclination) < 1.0


def test_stamps_must_increase():
    setup = FilterSetup(rate_hz=100.0, use_mag=False)
    t = np.arange(10) / 100.0
    t[5] = t[4]
    g = np.zeros((10, 3))
    a = np.tile([0.0, 0.0, 9.81], (10, 1))
    with pytest.raises(ValueError, match="sample 5"):
        Mekf(setup).process(t, g, a)


def test_heading_update_never_touches_inclination():
    """With a covariance that couples heading to tilt, to every bias axis and to the scale factors, and
    a measurement that sees the tilt (a dipping field), the heading gain has no tilt rows, corrects the
    bias only along the body's vertical, and leaves the scale factors alone."""
    rng = np.random.default_rng(1)
    n = kern.X_SIZE
    A = rng.standard_normal((n, n))
    P = A @ A.T + n * np.eye(n)
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    K = np.empty(n)
    h = np.zeros(n)
    h[:3] = [0.8, -1.5, 1.0]  # tan(dip) n: a 60° dip
    S = kern.heading_gain(P, h, 0.01, q, K)
    assert np.isclose(S, h @ P @ h + 0.01)
    assert K[0] == 0.0 and K[1] == 0.0 and K[2] != 0.0
    r = np.empty((3, 3))
    kern.quat_to_matrix(q, r)
    vertical_b = r[2]  # world up in body axes
    bias = K[kern.X_BIAS : kern.X_BIAS + 3]
    assert np.linalg.norm(bias) > 0 and np.allclose(np.cross(bias, vertical_b), 0.0, atol=1e-15)
    assert np.all(K[kern.X_SCALE :] == 0.0)
    before = P.copy()
    kern.joseph_update(P, K, h, 0.01)
    assert np.all(np.linalg.eigvalsh(P) > 0) and np.allclose(P, P.T)
    assert P[2, 2] < before[2, 2]


def test_earth_rate_model_is_enu():
    from gyroemu.pipelines.estimation.mekf import earth_rate_enu

    w = earth_rate_enu(FilterSetup(rate_hz=1.0, latitude_rad=np.radians(52.5)))
    assert w[0] == 0.0 and np.isclose(np.linalg.norm(w), EARTH_RATE)
    assert np.isclose(np.arctan2(w[2], w[1]), np.radians(52.5))


def test_back_and_forth_translation_is_low_passed_away():
    """A body tilted 10°, still for 2 s, then shaken sideways at 0.7 Hz with 5 m/s² (half a g): the two
    low-passes of time constant τ leave ``A / (g (1 + (2π f τ)²))`` of apparent tilt (amplitude), and
    the filter, whose bandwidth is far below 0.7 Hz, must do no worse than that RMS. (A mean over a
    2 s window would leave ``A/g · |sinc(f T)|``, 3.9° RMS.)"""
    rate, f, A, g = 200.0, 0.7, 5.0, 9.81
    t = np.arange(int(60 * rate)) / rate
    q_true = np.array([np.cos(np.radians(5.0)), np.sin(np.radians(5.0)), 0.0, 0.0])  # 10° about x
    a_w = np.zeros((len(t), 3))
    a_w[:, 0] = np.where(t >= 2.0, A * np.sin(2 * np.pi * f * (t - 2.0)), 0.0)
    a_w[:, 2] = g
    accel = quat_rotate(quat_conjugate(q_true), a_w)
    setup = FilterSetup(rate_hz=rate, use_mag=False)
    est = Mekf(setup).process(t, np.zeros((len(t), 3)), accel)
    err = attitude_errors(est.q_wb, np.tile(q_true, (len(t), 1)))
    tau = Mekf(setup).params.accel_tau_s
    residual_rms = A / (g * (1 + (2 * np.pi * f * tau) ** 2)) / np.sqrt(2)
    assert rmse_deg(err.inclination) < np.degrees(residual_rms)


def test_injection_turns_the_low_passed_force_with_the_estimate():
    """The low-passed specific force is in the world frame of the estimate that turned it; when a
    correction turns the estimate by exp(δθ), the stored force turns with it (else the next gravity
    measurement would report the corrected error again)."""
    rng = np.random.default_rng(2)
    x = np.zeros(kern.X_SIZE)
    x[:3] = rng.normal(0.0, 0.05, 3)
    x[kern.X_BIAS :] = rng.normal(0.0, 0.01, kern.X_SIZE - kern.X_BIAS)  # δb, δM and δa
    q, b = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3)
    slow = np.zeros(kern.S_SIZE)
    force = rng.normal(0.0, 1.0, (2, 3)) + [0.0, 0.0, 9.81]
    lag = rng.normal(0.0, 0.5, (2, 3, kern.N_DRIFT))  # D₁, D₂: the low-passes' sensitivity to δb, δM
    slow[kern.S_GRAV_LP : kern.S_GRAV_LP + 3], slow[kern.S_GRAV_LP2 : kern.S_GRAV_LP2 + 3] = force
    slow[kern.S_LAG1 : kern.S_LAG1 + lag[0].size], slow[kern.S_LAG2 : kern.S_LAG2 + lag[1].size] = lag.reshape(2, -1)
    kern.inject(x.copy(), q, b, slow, np.zeros(kern.W_SIZE), np.zeros((3, kern.N_DRIFT)))
    # each low-pass holds the tilt as it was, δθ + D (δb, δM): it turns by that stage's correction
    drift = x[kern.X_BIAS : kern.X_BIAS + kern.N_DRIFT]
    turned = [Rotation.from_rotvec(x[:3] + lag[i] @ drift).apply(force[i]) for i in range(2)]
    assert np.allclose(slow[kern.S_GRAV_LP : kern.S_GRAV_LP + 3], turned[0], atol=1e-12)
    assert np.allclose(slow[kern.S_GRAV_LP2 : kern.S_GRAV_LP2 + 3], turned[1], atol=1e-12)
    assert np.allclose(q, np.roll(Rotation.from_rotvec(x[:3]).as_quat(), 1), atol=1e-12)
    assert np.array_equal(b, x[kern.X_BIAS : kern.X_BIAS + 3])
    assert np.array_equal(slow[kern.S_SCALE : kern.S_SCALE + 9], x[kern.X_SCALE : kern.X_SCALE + 9])
    # the acceleration estimate takes its correction, then turns with the attitude's (a world-frame vector)
    acc = Rotation.from_rotvec(x[:3]).apply([x[kern.X_ACC], x[kern.X_ACC + 1], 0.0])
    assert np.allclose(slow[kern.S_ACC_EST : kern.S_ACC_EST + 2], acc[:2], atol=1e-12)


def test_low_pass_lag_of_a_steady_drift_is_the_group_delay():
    """Turning at a steady rate ω about z, a bias error δb drifts the attitude error by −R(t) δb; the
    two cascaded low-passes of τ hold that error as it was. With the impulse responses h₁(s) =
    e^{−s/τ}/τ and h₂(s) = s e^{−s/τ}/τ², and C(s) = ∫₀ˢ R(t−v) dv the drift since t−s, the stages hold
    D = ∫ h(s) C(s) ds = ∫ R(t−v) H(v) dv with H(v) = ∫_v^∞ h: e^{−v/τ} and e^{−v/τ}(1 + v/τ). About z
    nothing turns: D₁ = τ, D₂ = 2τ (the group delays). About x, y, R(t−v) = R(t) Rz(−ωv), so
    R(t)ᵀ D is the rotation-like matrix of the Laplace transforms at iω: τ/(1+iωτ) and
    τ/(1+iωτ) + τ/(1+iωτ)². The recursion is exact to one sample: tolerance Δt/τ relative."""
    rate, tau, omega = 200.0, 1.0, 0.3
    t = np.arange(1, int(30 * rate) + 1) / rate  # 30 τ: the start is forgotten to e^{-30}
    n = len(t)
    gyro = np.tile([0.0, 0.0, omega], (n, 1))
    accel = np.tile([0.0, 0.0, 9.81], (n, 1))
    params = MekfParams(accel_tau_s=tau).vector(FilterSetup(rate_hz=rate, use_mag=False))
    q, b, slow = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(kern.S_SIZE)
    slow[kern.S_GRAV_LP : kern.S_GRAV_LP2 + 3] = np.tile([0.0, 0.0, 9.81], 2)
    win, phi, q_out = np.zeros(kern.W_SIZE), np.zeros((3, kern.N_DRIFT)), np.empty((n, 4))
    params[kern.P_WINDOW] = params[kern.P_WINDOW_N] = 1e9  # one window: only the strapdown runs
    assert (
        kern.strapdown(
            q,
            b,
            slow,
            win,
            phi,
            t,
            gyro,
            np.empty((0, 3)),
            accel,
            np.full((n, 3), np.nan),
            np.zeros(3),
            params,
            0,
            q_out,
        )
        == n
    )
    d1 = slow[kern.S_LAG1 : kern.S_LAG1 + 3 * kern.N_DRIFT].reshape(3, kern.N_DRIFT)[:, :3]
    d2 = slow[kern.S_LAG2 : kern.S_LAG2 + 3 * kern.N_DRIFT].reshape(3, kern.N_DRIFT)[:, :3]
    r_now = Rotation.from_quat(np.roll(q, -1)).as_matrix()
    tol = 1.0 / (rate * tau)
    assert np.isclose(d1[2, 2], tau, rtol=tol) and np.isclose(d2[2, 2], 2 * tau, rtol=tol)
    first = tau / (1 + 1j * omega * tau)
    for d, h in ((d1, first), (d2, first + tau / (1 + 1j * omega * tau) ** 2)):
        expected = np.array([[h.real, -h.imag], [h.imag, h.real]])
        assert np.allclose(r_now.T[:2, :2] @ d[:2, :2], expected, rtol=0, atol=tol * abs(h))
    # the scale-factor columns: at a steady rate about z, δM_az drifts like δb_a times ω
    dm = slow[kern.S_LAG2 : kern.S_LAG2 + 3 * kern.N_DRIFT].reshape(3, kern.N_DRIFT)[:, 3:]
    for a in range(3):
        assert np.allclose(dm[:, 3 * a + 2], omega * d2[:, a], rtol=1e-9, atol=1e-12)
        assert np.all(dm[:, 3 * a : 3 * a + 2] == 0.0)


@pytest.mark.slow
@needs_trial()
def test_broad_targets_with_one_parameter_set():
    """The issue's bars on the BROAD trials in shared, defaults only: mean 9D total RMSE at or below
    VQF's quoted 2.4° (and below online VQF's in the same run), mean 6D inclination RMSE at or below
    its quoted 0.7° (and below online VQF's: #17's "ahead"), both well below Madgwick's 4.96° (the
    dataset authors' best global set)."""
    from vqf import VQF

    from gyroemu.pipelines.formats.importers import read_broad

    total, inclination, vqf_total, vqf_inclination = [], [], [], []
    for path in sorted(BROAD_DIR.glob("*.hdf5")):
        trial = read_broad(path)
        fs, gyro, accel, ref, movement = trial.rate_hz, trial.gyro, trial.accel, trial.opt_quat, trial.movement
        t = np.arange(len(trial)) / fs
        e9 = attitude_errors(Mekf(FilterSetup(rate_hz=fs)).process(t, gyro, accel, trial.mag_ut * 1e-6).q_wb, ref)
        e6 = attitude_errors(Mekf(FilterSetup(rate_hz=fs, use_mag=False)).process(t, gyro, accel).q_wb, ref)
        total.append(rmse_deg(e9.total, movement))
        inclination.append(rmse_deg(e6.inclination, movement))
        v = VQF(1.0 / fs).updateBatch(gyro, accel, np.ascontiguousarray(trial.mag_ut))
        vqf_total.append(rmse_deg(attitude_errors(v["quat9D"], ref).total, movement))
        vqf_inclination.append(rmse_deg(attitude_errors(v["quat6D"], ref).inclination, movement))
    assert np.mean(total) <= 2.4 and np.mean(total) < np.mean(vqf_total)
    assert np.mean(inclination) <= 0.7 and np.mean(inclination) < np.mean(vqf_inclination)


def test_simulated_field_heading_error_is_the_sensors_iron():
    """On a simulated site the field has no anomalies: the heading error the filter is told is what
    the magnetometer's hard iron makes of the horizontal field (|h| / B_h), none for a calibrated one;
    a log with no device (BROAD) leaves it unknown, to the filter's default."""
    import tomllib

    from gyroemu.sensors import device_from_dict

    scenario = load_scenario("smooth_manoeuvre")
    assert setup_for(load_device("consumer_mems"), scenario).field_heading_sigma == 0.0
    config = tomllib.loads(
        (Path(__file__).resolve().parents[2] / "configs" / "devices" / "consumer_mems.toml").read_text()
    )
    config["magnetometer"]["hard_iron_uT"] = [2.0, 0.0, 0.0]
    setup = setup_for(device_from_dict(config, name="iron"), scenario)
    east, north, _ = scenario.spec.site.magnetic_field_enu_uT
    assert np.isclose(setup.field_heading_sigma, 2.0 / np.hypot(east, north))
    assert Mekf(setup).params.heading_sigma == setup.field_heading_sigma
    assert FilterSetup(rate_hz=100.0).field_heading_sigma is None


def test_gravity_noise_is_white_noise_through_the_double_low_pass():
    """White noise of density N, in the project's convention (a per-sample σ of N/√Δt,
    ``sensors.noise.white_noise``: a two-sided PSD N²), through the strapdown's two low-passes of τ has
    the variance N² ∫₀^∞ h² dt, h(t) = t e^(−t/τ)/τ²: N²/(4τ) (``double_lowpass_variance``; ∫h² checked
    by quadrature), and the gravity measurement's R at rest is the sensor's and the motion's
    densities so, times its correlation factor 4τ/T, over g²: (N_a² + N_m²)/(T g²). Until 2026-11-27
    it took N²/(8τ) (the one-sided PSD's figure), which fails here by a factor 2.

    Monte Carlo, the kernel's own low-passes (``strapdown``, level and still, noise on the force): the
    world-frame force after them, read every D = 20τ (correlation (1 + D/τ) e^(−D/τ) < 10⁻⁷ between
    reads, and the start forgotten), on both horizontal axes, gives m independent draws y_i ~ N(0, v).
    Their mean square s has E s = v and Var s = 2v²/m (χ²_m/m), so s lies within 5 v √(2/m) of v
    (5σ: false alarm below 10⁻⁶); v is the closed form up to the exact discretisation's own variance,
    (N²/Δt) α⁴ (1 + a²)/(1 − a²)³ (impulse response α² (k+1) aᵏ, a = e^(−Δt/τ), α = 1 − a), within
    10⁻⁴ of it at Δt/τ = 0.02: added to the bound."""
    from scipy.integrate import quad

    from gyroemu.sensors.noise import white_noise

    rate, tau, density = 1000.0, 0.05, 0.3
    dt = 1.0 / rate
    closed = density**2 / (4.0 * tau)
    assert np.isclose(kern.double_lowpass_variance(density, tau), closed, rtol=4 * EPS, atol=0)
    integral, _ = quad(lambda t: (t * np.exp(-t / tau) / tau**2) ** 2, 0.0, np.inf)
    assert np.isclose(integral, 1.0 / (4.0 * tau), rtol=1e-8, atol=0)
    # the default motion density is the 0.4 chosen under N²/(8τ), restated: the motion's share as it was
    motion = kern.double_lowpass_variance(MekfParams().motion_accel_density, tau)
    assert np.isclose(motion, 0.4**2 / (8.0 * tau), rtol=4 * EPS, atol=0)

    # the measurement at rest (|ā| = g: no motion term), the window of the defaults
    params = MekfParams(accel_noise_density=0.05, accel_tau_s=tau)
    p = params.vector(FilterSetup(rate_hz=rate, use_mag=False))
    g, T = 9.81, params.window_s
    win, slow = np.zeros(kern.W_SIZE), np.zeros(kern.S_SIZE)
    win[kern.W_ACC_N], win[kern.W_T] = 20.0, T
    slow[kern.S_GRAVITY] = g
    slow[kern.S_GRAV_LP2 : kern.S_GRAV_LP2 + 3] = [0.0, 0.0, g]
    z, H, R = np.empty(2), np.empty((2, kern.X_SIZE)), np.empty((2, 2))
    assert kern.gravity_measurement(win, slow, p, z, H, R)
    want = (params.accel_noise_density**2 + params.motion_accel_density**2) / (T * g * g)
    assert np.allclose(np.diag(R), want, rtol=16 * EPS, atol=0) and R[0, 1] == R[1, 0] == 0.0

    draws, span = 2000, int(round(20 * tau * rate))  # reads, samples between reads
    p = MekfParams(accel_tau_s=tau).vector(FilterSetup(rate_hz=rate, use_mag=False))
    p[kern.P_WINDOW], p[kern.P_WINDOW_N] = span * dt * (1 - 1e-9), span + 0.5  # a window per read
    q, b, slow = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(kern.S_SIZE)
    slow[kern.S_GRAV_LP : kern.S_GRAV_LP2 + 3] = np.tile([0.0, 0.0, g], 2)
    slow[kern.S_T] = -dt
    gyro, mag, no_delta = np.zeros((span, 3)), np.full((span, 3), np.nan), np.empty((0, 3))
    phi, q_out = np.zeros((3, kern.N_DRIFT)), np.empty((span, 4))
    rng = np.random.default_rng(5)
    y = np.empty((draws, 2))
    for i in range(draws):
        t = (i * span + np.arange(span)) * dt
        accel = white_noise(rng, (span, 3), dt, density) + [0.0, 0.0, g]
        win = np.zeros(kern.W_SIZE)
        assert kern.strapdown(q, b, slow, win, phi, t, gyro, no_delta, accel, mag, np.zeros(3), p, 0, q_out) == span
        y[i] = slow[kern.S_GRAV_LP2 : kern.S_GRAV_LP2 + 2]
    assert np.array_equal(q, [1.0, 0.0, 0.0, 0.0])  # still: the world frame is the body's
    m = y.size
    s = np.mean(y**2)
    a = np.exp(-dt / tau)
    discrete = density**2 / dt * (1 - a) ** 4 * (1 + a * a) / (1 - a * a) ** 3
    v = kern.double_lowpass_variance(density, tau)
    assert abs(discrete - closed) < 1e-4 * closed
    assert abs(s - v) <= 5 * v * np.sqrt(2.0 / m) + abs(discrete - closed)


def test_gravity_noise_takes_what_a_sustained_acceleration_shows():
    """Innovation-based adaptive estimation (``gravity_adapt``): a gravity innovation held at 14° (a car
    speeding up at 2.5 m/s²) drives the mean square of the innovation per axis to |z|²/2 (a low-pass
    rising over τ_r = ``accel_adapt_rise_s``: after n windows of T it is within e^(−nT/τ_r) of it, to
    round-off), and R then carries what exceeds the
    expected variance tr(H P Hᵀ)/2 + R₀ T/(4τ), with the correlation factor 4τ/T: closed form. An
    innovation within the expected spread adds nothing (below Suh's threshold, ``accel_gate``)."""
    setup = FilterSetup(rate_hz=100.0, use_mag=False)
    params = MekfParams()
    p = params.vector(setup)
    tau, T = params.accel_tau_s, params.window_s
    corr = 4.0 * tau / T
    H = np.zeros((2, kern.X_SIZE))
    H[0, 1], H[1, 0], H[0, kern.X_ACC], H[1, kern.X_ACC + 1] = -1.0, 1.0, 1.0, 1.0
    P = np.diag(np.full(kern.X_SIZE, 1e-6))
    r0 = 1e-4 * corr  # a single window's base variance of 1e-4 rad², scaled as gravity_measurement does
    hph = 0.5 * np.trace(H @ P @ H.T)
    for tilt, adds in ((np.radians(14.0), True), (0.5 * np.sqrt(hph + 1e-4), False)):
        slow = np.zeros(kern.S_SIZE)
        z = np.array([tilt, 0.0])
        n = 2000  # 40 s of windows: e^(−40) of the start is left
        for _ in range(n):
            slow[kern.S_ACC_CORR] = corr
            R = np.eye(2) * r0
            kern.gravity_adapt(P, z, H, R, slow, p)
        ms = 0.5 * tilt**2
        # round-off: ε·ms per step, summed by the low-pass with gain 1/β (β = 1 − e^(−T/τ_r)), twice over
        tau_r = params.accel_adapt_rise_s
        beta = 1.0 - np.exp(-T / tau_r)
        assert abs(slow[kern.S_ACC_MS] - ms) <= ms * np.exp(-n * T / tau_r) + 2 * EPS * ms / beta
        want = r0 + ((ms - hph - r0 / corr) * corr if adds else 0.0)
        assert np.allclose(np.diag(R), want, rtol=1e-12, atol=0)
        assert R[0, 1] == R[1, 0] == 0.0


def test_rest_rate_threshold_comes_from_the_gyro():
    """A known gyro's rest-rate threshold is five times what its noise through the rest low-pass and its
    bias leave in the low-passed rate, 5 √(N²/(2τ) + σ_b²), at most the default (2 °/s)."""
    for name in ("tactical_mems", "consumer_mems"):
        device = load_device(name)
        setup = setup_for(device, load_scenario("car_drive"))
        params = MekfParams.for_setup(setup)
        n, sb = setup.noise.gyro_noise_density, setup.noise.gyro_bias_sigma
        want = min(np.radians(2.0), 5 * np.sqrt(n**2 / (2 * params.rest_tau_s) + sb**2))
        assert params.rest_rate == pytest.approx(want, rel=1e-12)
    assert MekfParams.for_setup(FilterSetup(rate_hz=100.0)).rest_rate == np.radians(2.0)


WINDOW_S = 0.02
"""The window of the transition tests, s."""


def _transition(params: MekfParams, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(F, Q)`` of one window of :data:`WINDOW_S` at attitude ``q``, no drift accumulated, no Earth rate."""
    win = np.zeros(kern.W_SIZE)
    win[kern.W_T] = WINDOW_S
    F, Q = np.empty((kern.X_SIZE, kern.X_SIZE)), np.empty((kern.X_SIZE, kern.X_SIZE))
    vector = params.vector(FilterSetup(rate_hz=1.0 / WINDOW_S))
    kern.transition(win, np.zeros((3, kern.N_DRIFT)), q, np.zeros(3), vector, F, Q)
    return F, Q


def test_bias_random_walk_splits_along_the_body_vertical():
    """The window's bias process noise is q_h (I − v vᵀ) + q_v v vᵀ, v = Rᵀ e_z the body vertical (round-off
    of the closed form); a known gyro's random walk is the same along every axis, and then the block is
    q I to the bit (the split adds an exact zero), as it was before the split existed."""
    rng = np.random.default_rng(5)
    T = WINDOW_S
    params = MekfParams.for_setup(FilterSetup(rate_hz=100.0))
    assert params.gyro_bias_random_walk > params.gyro_bias_random_walk_vertical  # an unknown gyro's split
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        _, Q = _transition(params, q)
        v = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()[2]  # third row of R: e_z in body axes
        qh, qv = params.gyro_bias_random_walk**2 * T, params.gyro_bias_random_walk_vertical**2 * T
        want = qh * (np.eye(3) - np.outer(v, v)) + qv * np.outer(v, v)
        block = Q[kern.X_BIAS : kern.X_BIAS + 3, kern.X_BIAS : kern.X_BIAS + 3]
        assert np.allclose(block, want, rtol=0, atol=16 * np.finfo(float).eps * qh)
        assert v @ block @ v == pytest.approx(qv, rel=1e-12, abs=16 * np.finfo(float).eps * qh)
    known = MekfParams.for_setup(setup_for(load_device("consumer_mems"), load_scenario("car_drive")))
    assert known.gyro_bias_random_walk_vertical == known.gyro_bias_random_walk
    _, Q = _transition(known, q)
    block = Q[kern.X_BIAS : kern.X_BIAS + 3, kern.X_BIAS : kern.X_BIAS + 3]
    assert np.array_equal(block, known.gyro_bias_random_walk**2 * T * np.eye(3))


def test_process_noise_of_each_state_is_its_own():
    """The window's process noise, state by state, is what each model says (closed forms, round-off): the
    attitude N² T, the scale and misalignment states σ_M² T, and the acceleration δa, Gauss–Markov,
    σ_p² (1 − e^(−2T/τ_a)) with the decay e^(−T/τ_a) on its diagonal of F; nothing off the diagonal but
    the bias block (its vertical split). Until 2026-11-26 the scale states' loop ran on over δa and
    overwrote its noise with theirs."""
    T = WINDOW_S
    params = MekfParams.for_setup(FilterSetup(rate_hz=100.0), accel_gm_process_sigma=0.05)  # unlike any other
    F, Q = _transition(params, np.array([1.0, 0.0, 0.0, 0.0]))
    eps = 16 * np.finfo(float).eps
    g = 9.80665
    decay = np.exp(-T / params.accel_gm_tau_s)
    q_acc = (params.accel_gm_process_sigma / g) ** 2 * (1 - decay**2)
    acc = slice(kern.X_ACC, kern.X_ACC + 2)
    assert np.allclose(np.diag(Q)[acc], q_acc, rtol=eps, atol=0)
    assert np.allclose(np.diag(F)[acc], decay, rtol=eps, atol=0)
    scale = slice(kern.X_SCALE, kern.X_SCALE + 9)
    assert np.allclose(np.diag(Q)[scale], params.scale_factor_random_walk**2 * T, rtol=eps, atol=0)
    assert np.allclose(np.diag(Q)[0:3], params.gyro_noise_density**2 * T, rtol=eps, atol=0)
    off = Q - np.diag(np.diag(Q))
    off[kern.X_BIAS : kern.X_BIAS + 3, kern.X_BIAS : kern.X_BIAS + 3] = 0.0
    assert not off.any()


def test_rest_gate_rejects_a_rate_that_leaves_its_stretch():
    """``rest_gate``: the first window of a stretch at rest is accepted and starts the stretch's mean; a
    window whose mean rate differs from that mean by d is accepted when |d|² is within ``rest_gate`` times
    the white noise's variance N²/Δt (1/n_w + 1/n_s), and then joins the mean (sums exact); beyond it,
    rejected, and the mean is left alone (a turn is not learnt as bias). A rate the filter's bias
    estimate would call wrong, but which stays put, is accepted: the test does not use the bias."""
    setup = FilterSetup(rate_hz=100.0, use_mag=False)
    params = MekfParams(gyro_noise_density=1e-3)
    p = params.vector(setup)
    n_w, dt = 2.0, 0.01
    sigma2 = params.gyro_noise_density**2 / dt  # a sample's white-noise variance, (rad/s)²

    def window(rate):
        win = np.zeros(kern.W_SIZE)
        win[kern.W_T], win[kern.W_N], win[kern.W_REST_N] = n_w * dt, n_w, n_w
        win[kern.W_REST_G : kern.W_REST_G + 3] = n_w * np.asarray(rate)
        return win

    slow = np.zeros(kern.S_SIZE)
    offset = np.array([0.3, -0.2, 0.1])  # 17 °/s: far from any bias the filter holds, but stationary
    assert kern.rest_gate(window(offset), slow, p)
    assert slow[kern.S_REST_N] == n_w and np.array_equal(slow[kern.S_REST_SUM : kern.S_REST_SUM + 3], n_w * offset)
    var = sigma2 * (1.0 / n_w + 1.0 / n_w)
    inside = offset + np.array([0.0, 0.0, 0.9 * np.sqrt(params.rest_gate * var)])
    assert kern.rest_gate(window(inside), slow, p)
    assert slow[kern.S_REST_N] == 2 * n_w
    mean = slow[kern.S_REST_SUM : kern.S_REST_SUM + 3] / slow[kern.S_REST_N]
    var = sigma2 * (1.0 / n_w + 1.0 / (2 * n_w))
    before = slow.copy()
    outside = mean + np.array([1.1 * np.sqrt(params.rest_gate * var), 0.0, 0.0])
    assert not kern.rest_gate(window(outside), slow, p)
    assert np.array_equal(slow, before)


def test_gravity_update_considers_the_acceleration_without_estimating_it():
    """``gravity_update`` is the Schmidt (consider) update: the gain's δa rows are zero, so δa keeps its
    value, the other states take the optimal gain, and P is the Joseph form of that gain (an independent
    computation here, to round-off). Without the δa columns in H and without cross-covariance it is the
    ordinary Kalman update."""
    rng = np.random.default_rng(7)
    n = kern.X_SIZE
    A = rng.standard_normal((n, n)) * 1e-2
    P0 = A @ A.T + np.eye(n) * 1e-6
    H = np.zeros((2, n))
    H[0, 1], H[1, 0], H[0, kern.X_ACC], H[1, kern.X_ACC + 1] = -1.0, 1.0, 1.0, 1.0
    H[:, kern.X_BIAS : kern.X_BIAS + 3] = rng.standard_normal((2, 3)) * 0.1
    R = np.eye(2) * 1e-4
    z = np.array([3e-3, -2e-3])
    x0 = rng.standard_normal(n) * 1e-3
    x, P = x0.copy(), P0.copy()
    kern.gravity_update(x, P, z, H, R)
    K = P0 @ H.T @ np.linalg.inv(H @ P0 @ H.T + R)
    K[kern.X_ACC :] = 0.0
    assert np.array_equal(x[kern.X_ACC :], x0[kern.X_ACC :])
    assert np.allclose(x, x0 + K @ (z - H @ x0), rtol=0, atol=100 * EPS * np.abs(x0).max())
    IKH = np.eye(n) - K @ H
    want = IKH @ P0 @ IKH.T + K @ R @ K.T
    assert np.allclose(P, want, rtol=0, atol=100 * n * EPS * np.abs(P0).max())
    # no δa in H, no cross-covariance: the ordinary update, P_post = P − K S Kᵀ
    H[:, kern.X_ACC :] = 0.0
    P0[kern.X_ACC :, : kern.X_ACC] = 0.0
    P0[: kern.X_ACC, kern.X_ACC :] = 0.0
    x, P = x0.copy(), P0.copy()
    kern.gravity_update(x, P, z, H, R)
    S = H @ P0 @ H.T + R
    K = P0 @ H.T @ np.linalg.inv(S)
    assert np.allclose(P, P0 - K @ S @ K.T, rtol=0, atol=100 * n * EPS * np.abs(P0).max())
