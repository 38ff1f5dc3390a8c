"""The offline MEKF (forward pass + Rauch–Tung–Striebel smoother), issue #17.

Fast: the backward recursion against filterpy's ``rts_smoother`` on a linear system; on a short
simulated run the forward pass is the online filter, the smoother beats it and its covariance is never
larger; ``gyroemu estimate --smooth`` writes the smoothed estimate; the bench keeps offline estimators
apart. Slow: the BROAD targets. (The attitude NEES of item 3: ``test_mekf_nees.py``, and
``tests/benchmarks/nees_check.py``.)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.rotation import quat_angle, quat_from_rotvec, quat_multiply, quat_to_matrix
from gyroemu.pipelines.estimation import mekf_kernels as kern
from gyroemu.pipelines.estimation import mekf_smoother_kernels as skern
from gyroemu.pipelines.estimation.mekf import Mekf
from gyroemu.pipelines.estimation.mekf_smoother import MekfSmoother, smooth_log, smoother_params
from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg
from gyroemu.pipelines.estimation.protocol import FilterSetup
from gyroemu.pipelines.estimation.series import rate_of
from gyroemu.pipelines.estimation.setup import setup_for, setup_from_metadata
from gyroemu.pipelines.formats.mcap_log import truth_series
from gyroemu.sensors import load_device

from ..broad_trials import BROAD_DIR, needs_trial
from ..cli_runs import run_cli

EPS = np.finfo(float).eps
X = kern.X_SIZE


def _rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) of unit quaternions (N, 4), rad."""
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    s = np.linalg.norm(q[:, 1:], axis=1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[:, :1])
    return np.where(s > 1e-15, q[:, 1:] * angle / np.maximum(s, 1e-300), 2.0 * q[:, 1:])


def _simulated(scenario: str, device: str, seed: int, duration: float):
    scen = load_scenario(scenario)
    dev = load_device(device, seed=seed)
    traj = scen.simulate(duration=duration)
    samples = dev.measure(traj)
    mag = samples.mag if np.isfinite(samples.mag).any() else None
    return scen, dev, samples, mag, truth_series(traj, samples).q_wb


def test_rts_backward_matches_filterpy_on_a_linear_system():
    """A linear system of the error state's shape (F = I but its attitude and acceleration rows), filtered
    by filterpy; the error-state recursion (smoothed error relative to each posterior, updates as
    injected) gives filterpy's ``rts_smoother`` means and covariances to round-off."""
    from filterpy.kalman import KalmanFilter, rts_smoother

    rng = np.random.default_rng(17)
    n = 60
    Fs = np.repeat(np.eye(X)[None], n, axis=0)
    Fs[:, 0:3, 0:3] += 0.01 * rng.standard_normal((n, 3, 3))
    Fs[:, 0:3, 3:] = 0.05 * rng.standard_normal((n, 3, X - 3))
    Fs[:, kern.X_ACC :, kern.X_ACC :] *= rng.uniform(0.5, 1.0, (n, X - kern.X_ACC, 1))  # Gauss–Markov decay
    Q = np.diag(rng.uniform(0.5, 2.0, X)) * 1e-3
    H = rng.standard_normal((4, X))
    R = np.eye(4) * 0.1
    kf = KalmanFilter(dim_x=X, dim_z=4)
    kf.x = np.zeros((X, 1))
    kf.P = np.eye(X)
    kf.H, kf.R, kf.Q = H, R, Q
    x_true = rng.standard_normal(X)
    zs = []
    for k in range(n):
        x_true = Fs[k] @ x_true + rng.multivariate_normal(np.zeros(X), Q)
        zs.append(H @ x_true + rng.multivariate_normal(np.zeros(4), R))
    Fs_kf = [Fs[k] for k in range(n)]
    means, covs, means_p, covs_p = kf.batch_filter(np.array(zs)[:, :, None], Fs=Fs_kf, Qs=[Q] * n)
    means, means_p = means[:, :, 0], means_p[:, :, 0]
    # filterpy's rts_smoother wants F_k taking step k to k+1: ours propagates k−1 to k
    want_x, want_P, _, _ = rts_smoother(means[:, :, None], covs, Fs_kf[1:] + [np.eye(X)], [Q] * n)
    e_s = np.empty((n, X))
    P_s = np.empty((n, X, X))
    e_s[-1], P_s[-1] = 0.0, covs[-1]  # the last window's smoothed state is its forward one
    F_top = np.ascontiguousarray(np.concatenate([Fs[:, 0:3, :], Fs[:, kern.X_ACC :, :]], axis=1))
    skern.rts_backward(F_top, covs_p, covs, means - means_p, e_s, P_s, multiplicative=False)
    got_x = means + e_s  # e_s is relative to each posterior; the linear "injection" is a sum
    # Round-off: n steps of O(X³) algebra on matrices of condition number κ
    kappa = max(np.linalg.cond(c) for c in covs_p)
    tol = 10 * n * X * kappa * EPS
    assert np.allclose(got_x, want_x[:, :, 0], rtol=0, atol=tol * np.abs(want_x).max())
    assert np.allclose(P_s, want_P, rtol=0, atol=tol * np.abs(want_P).max())


def _injected(u: np.ndarray, rng: np.random.Generator):
    """A forward state (attitude, bias, slow states) before and after :func:`mekf_kernels.inject` of ``u``."""
    q = quat_from_rotvec(rng.normal(size=3))
    b = 1e-3 * rng.normal(size=3)
    slow = np.zeros(kern.S_SIZE)
    slow[kern.S_SCALE : kern.S_SCALE + 9] = 1e-3 * rng.normal(size=9)
    slow[kern.S_ACC_EST : kern.S_ACC_EST + 2] = 0.02 * rng.normal(size=2)
    q_post, b_post, slow_post = q.copy(), b.copy(), slow.copy()
    kern.inject(u.copy(), q_post, b_post, slow_post, np.zeros(kern.W_SIZE), np.zeros((3, kern.N_DRIFT)))
    return (q, b, slow), (q_post, b_post, slow_post)


@pytest.mark.parametrize("heading_deg", [0.3, 133.0])
def test_the_reset_composition_undoes_the_filters_injection(heading_deg):
    """The smoothed error ``e`` of a posterior nominal state, composed with the update ``u`` the forward
    pass injected (``mekf_kernels.inject``, the filter's own function), is the error of the prior nominal
    state that gives the same smoothed state: the same attitude (``exp(out) ⊗ q⁻ = exp(e) ⊗ q⁺``), bias,
    scale and misalignment, and the same acceleration estimate in the prior's axes (``T (â⁻ + out) =
    â⁺ + e``, ``T`` the turn inject gave â), to round-off: a few ε per operation on angles of a few rad.
    Both for a small update and for a first heading found in one window (133°, a 6D filter
    gyrocompassing), where the sum ``e + u`` points the tilt along the old axes."""
    rng = np.random.default_rng(int(heading_deg * 10))
    u = 0.01 * rng.normal(size=X)
    u[2] = np.radians(heading_deg)
    e = 0.01 * rng.normal(size=X)
    e[2] = 0.4  # the smoothed heading may move too
    (q, b, slow), (q_post, b_post, slow_post) = _injected(u, rng)
    out = np.empty(X)
    skern.reset_composition(e, u, out)
    tol = 64 * EPS * (1.0 + np.abs(u).sum() + np.abs(e).sum())
    smoothed = quat_multiply(quat_from_rotvec(e[:3]), q_post)
    assert quat_angle(quat_multiply(quat_from_rotvec(out[:3]), q), smoothed) < tol
    assert np.allclose(b + out[3:6], b_post + e[3:6], rtol=0, atol=tol)
    scale = slice(kern.S_SCALE, kern.S_SCALE + 9)
    assert np.allclose(slow[scale] + out[6:15], slow_post[scale] + e[6:15], rtol=0, atol=tol)
    turn = quat_to_matrix(quat_from_rotvec(u[:3]))[:2, :2]
    acc = slice(kern.S_ACC_EST, kern.S_ACC_EST + 2)
    assert np.allclose(turn @ (slow[acc] + out[kern.X_ACC :]), slow_post[acc] + e[kern.X_ACC :], rtol=0, atol=tol)
    # the guard: the sum, the composition's first order, is off by about ½ |e × u| (Baker–Campbell–
    # Hausdorff), far beyond the tolerance
    summed = quat_angle(quat_multiply(quat_from_rotvec(e[:3] + u[:3]), q), smoothed)
    assert summed > 1e6 * tol, summed


def test_per_sample_follows_the_documented_interpolation():
    """``per_sample`` against its rule, written here with scipy's rotations: in window j (samples after
    ``end_index[j−1]`` to ``end_index[j]``) the error runs linearly in time from ``e_s[j−1]`` at the window's
    start (the previous window's last stamp; the first window starts one interval before the first sample)
    to ``e_s[j]`` composed with ``x_upd[j]`` just before its end, and is ``e_s[j]`` at its last sample (the
    posterior there); after the last window end the last ``e_s``; the attitude is ``exp(δθ) ⊗ q_fwd``, the
    bias ``b_fwd + δb``, the covariance the same interpolation of ``P_s``'s attitude block, to round-off."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    n, W = 11, 3
    t = np.cumsum(rng.uniform(0.5e-3, 1.5e-3, n))
    end_index = np.array([-1, 3, 7])  # window 1: samples 0–3, window 2: 4–7, then 8–10 after the last end
    e_s = 0.05 * rng.normal(size=(W, X))
    x_upd = 0.05 * rng.normal(size=(W, X))
    x_upd[2, 2] = 2.0  # a large heading update
    A = rng.normal(size=(W, X, X))
    P_s = A @ A.transpose(0, 2, 1) + np.eye(X)
    q_fwd = quat_from_rotvec(rng.normal(size=(n, 3)))
    b_fwd = rng.normal(size=(n, 3))
    q_out, b_out, cov_out = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3, 3))
    skern.per_sample(t, q_fwd, b_fwd, end_index, e_s, P_s, x_upd, q_out, b_out, cov_out)

    def composed(e, u):
        out = e + u
        out[:3] = (Rotation.from_rotvec(e[:3]) * Rotation.from_rotvec(u[:3])).as_rotvec()
        turn = Rotation.from_rotvec(u[:3]).as_matrix()[:2, :2]
        out[kern.X_ACC :] = u[kern.X_ACC :] + np.linalg.solve(turn, e[kern.X_ACC :])
        return out

    for k in range(n):
        j = int(np.searchsorted(end_index[1:], k)) + 1  # the window holding sample k (W: after the last)
        if j == W:
            e, P = e_s[W - 1], P_s[W - 1]
        elif k == end_index[j]:
            e, P = e_s[j], P_s[j]
        else:
            lo = end_index[j - 1] + 1
            t0 = t[lo - 1] if lo > 0 else 2 * t[0] - t[1]
            f = (t[k] - t0) / (t[end_index[j]] - t0)
            e = (1 - f) * e_s[j - 1] + f * composed(e_s[j], x_upd[j])
            P = (1 - f) * P_s[j - 1] + f * P_s[j]
        want = Rotation.from_rotvec(e[:3]) * Rotation.from_quat(q_fwd[k, [1, 2, 3, 0]])
        assert quat_angle(q_out[k], want.as_quat()[[3, 0, 1, 2]]) < 64 * EPS * (1 + np.abs(e[:3]).sum()), k
        assert np.allclose(b_out[k], b_fwd[k] + e[3:6], rtol=0, atol=8 * EPS * (1 + np.abs(b_fwd[k]).max())), k
        assert np.allclose(cov_out[k], P[:3, :3], rtol=0, atol=8 * EPS * np.abs(P[:3, :3]).max()), k


@pytest.fixture(scope="module")
def short_run():
    scen, dev, samples, mag, q_true = _simulated("smooth_manoeuvre", "consumer_mems", 3, 20.0)
    setup = setup_for(dev, scen)
    t = np.asarray(samples.t, float) - samples.t[0]
    return setup, t, samples, mag, q_true


def test_forward_pass_is_the_online_filter_and_the_smoother_beats_it(short_run):
    """The forward pass is the online MEKF with the same parameters (the same kernels, Joseph-form
    algebra instead of filterpy's: attitudes agree to 1e-9 as the batched filter's do); the smoothed
    attitude is closer to the truth than the forward one; and at every update the smoothed attitude
    covariance is at most the forward posterior's (P_s = P_post − C (P_prior − P_s⁺) Cᵀ with
    P_s⁺ ≤ P_prior, by induction), to round-off. That induction needs every update to be a Kalman update
    (P_post ≤ P_prior). A gain with rows held at zero is not one: with K* the Kalman gain and K its
    estimated rows, P_prior − P_post = K* S K*ᵀ − D S Dᵀ (D = K* − K, the held rows), whose held block is
    zero and whose cross block K S Dᵀ is not, so it is indefinite. The heading's gain (no tilt, no δM)
    and the gravity update's (no δa, the considered acceleration) hold rows, so the ordering is held
    on the 6D run with the acceleration's prior and process noise at their floor (10⁻⁹ rad), where the
    gravity and rest updates are Kalman updates to below round-off."""
    setup, t, samples, mag, q_true = short_run
    params = smoother_params(setup)
    res = smooth_log(setup, t, samples.gyro, samples.accel, mag, params=params)
    mekf = Mekf(setup, params)
    online = mekf.process(t, samples.gyro, samples.accel, mag)
    assert np.abs(res.forward.q_wb - online.q_wb).max() < 1e-9
    ends = res.window_end
    assert np.allclose(res.forward.q_wb_covariance[ends], online.q_wb_covariance[ends], rtol=1e-9, atol=0)
    e_f = rmse_deg(attitude_errors(res.forward.q_wb, q_true).total)
    e_s = rmse_deg(attitude_errors(res.smoothed.q_wb, q_true).total)
    assert e_s < e_f, (e_s, e_f)
    no_acceleration = replace(params, accel_gm_sigma=0.0, accel_gm_process_sigma=0.0)
    six = smooth_log(replace(setup, use_mag=False), t, samples.gyro, samples.accel, None, params=no_acceleration)
    ends6 = six.window_end
    diff = six.forward.q_wb_covariance[ends6] - six.smoothed.q_wb_covariance[ends6]
    lowest = np.linalg.eigvalsh(0.5 * (diff + diff.transpose(0, 2, 1))).min(axis=1)
    scale = np.trace(six.forward.q_wb_covariance[ends6], axis1=1, axis2=2)
    assert np.all(lowest >= -1e3 * EPS * scale)
    # the last window's smoothed state is the forward posterior (nothing after it)
    assert np.allclose(res.smoothed.q_wb[ends[-1]], res.forward.q_wb[ends[-1]], rtol=0, atol=1e-12)
    assert res.scale_misalignment.shape == (len(ends), 3, 3)
    # ... and so are its scale and misalignment (the online filter's after the log, which learnt them)
    assert np.abs(mekf.scale_misalignment).max() > 1e-6
    assert np.allclose(res.scale_misalignment[-1], mekf.scale_misalignment, rtol=1e-9, atol=1e-15)


def test_a_heading_found_in_one_window_turns_the_smoothed_tilt_with_it():
    """The car drive in 6D with the consumer MEMS (latitude known, heading free): resting first, the
    forward pass finds a heading from the Earth's rate and turns its state by tens of degrees in one window
    (the guard). The smoothed tilt corrections of the windows before must turn with it
    (:func:`reset_composition`); summed with the update they pointed along the old axes and the smoothed
    inclination was worse than the forward pass's (0.69° against 0.54°, mean of seeds 0–2; now 0.42°).
    A smoother sees the forward pass's data and more: over three drives, its inclination error is below
    the forward pass's."""
    forward, smoothed = [], []
    for seed in range(3):
        scen, dev, samples, _, q_true = _simulated("car_drive", "consumer_mems", seed, 130.0)
        setup = replace(setup_for(dev, scen), use_mag=False)
        res = smooth_log(setup, np.asarray(samples.t, float) - samples.t[0], samples.gyro, samples.accel, None)
        jumps = quat_angle(res.forward.q_wb[1:], res.forward.q_wb[:-1])
        assert jumps.max() > np.radians(30.0), np.degrees(jumps.max())
        forward.append(rmse_deg(attitude_errors(res.forward.q_wb, q_true).inclination))
        smoothed.append(rmse_deg(attitude_errors(res.smoothed.q_wb, q_true).inclination))
    assert np.mean(smoothed) < np.mean(forward), (smoothed, forward)


def test_an_empty_log_and_a_long_pause():
    """No samples: empty estimates of the right shapes. A pause in the stamps closes one window however
    long it is, so the window storage is bounded by the samples: 2,000 samples at 100 Hz with a pause of
    1,000 s keep at most what the same samples without it keep, plus the n + 1 windows a log of n samples
    can close (it reserved 50,000 windows, 277 MB, for the pause's duration; a pause of days asked for
    tens of GB)."""
    import tracemalloc

    setup = FilterSetup(rate_hz=100.0, use_mag=False)
    empty = smooth_log(setup, np.empty(0), np.empty((0, 3)), np.empty((0, 3)), None)
    for est in (empty.forward, empty.smoothed):
        assert (est.q_wb.shape, est.gyro_bias.shape, est.q_wb_covariance.shape) == ((0, 4), (0, 3), (0, 3, 3))
    assert empty.window_end.shape == (0,)

    n = 2000
    rng = np.random.default_rng(0)
    gyro = 1e-3 * rng.normal(size=(n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + 1e-2 * rng.normal(size=(n, 3))
    t = np.arange(n) / 100.0
    paused = t + np.where(np.arange(n) >= n // 2, 1000.0, 0.0)
    smooth_log(setup, t, gyro, accel, None)  # compiled before measuring
    peaks = []
    for stamps in (t, paused):
        tracemalloc.start()
        smooth_log(setup, stamps, gyro, accel, None)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    per_window = sum(a.nbytes for a in skern.window_store(1))
    assert peaks[1] <= peaks[0] + (n + 1) * per_window, (peaks, per_window)


def test_filter_parameters_are_checked_and_the_offline_flags_agree():
    """Every MEKF parameter is a standard deviation, density, duration, gate or tolerance: a negative or
    non-finite one is refused naming it, for the smoother's defaults as for the online filter's. And two
    places say a built-in filter is offline, the registry's entry (read without importing the filter) and
    the class's ``offline`` (what the filter protocol and the latency wrapper read): they agree."""
    from gyroemu.pipelines.estimation.mekf import MekfParams
    from gyroemu.pipelines.estimation.registry import FILTERS, filter_class, unavailable_filters

    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="misalignment_sigma"):
            MekfParams(misalignment_sigma=bad)
        with pytest.raises(ValueError, match="accel_tau_s"):
            smoother_params(FilterSetup(rate_hz=100.0), accel_tau_s=bad)
    for name in ("window_s", "accel_tau_s", "accel_gm_tau_s", "mag_window_s", "rest_tau_s"):  # they divide
        with pytest.raises(ValueError, match=f"{name} = 0.0: must be more than 0"):
            MekfParams(**{name: 0.0})
    assert smoother_params(FilterSetup(rate_hz=100.0)).misalignment_sigma > 0
    for name in sorted(set(FILTERS) - set(unavailable_filters())):
        assert FILTERS[name].offline == bool(getattr(filter_class(name), "offline", False)), name


def test_offline_filters_take_the_whole_log_once(short_run):
    """An offline filter refuses a second block: its backward pass needed the end of the first."""
    setup, t, samples, mag, _ = short_run
    f = MekfSmoother(setup)
    est = f.process(t[:400], samples.gyro[:400], samples.accel[:400], mag[:400])
    assert est.q_wb.shape == (400, 4) and est.q_wb_covariance.shape == (400, 3, 3)
    with pytest.raises(ValueError, match="whole log in one process"):
        f.process(t[400:], samples.gyro[400:], samples.accel[400:], mag[400:])


def test_estimate_smooth_writes_the_smoothed_estimate(tmp_path):
    """``gyroemu estimate LOG --out OUT --smooth``: one /estimate/imu per /imu, the smoothed attitude
    and covariance; --smooth with another filter is a usage error (exit 2)."""
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    log = tmp_path / "run.mcap"
    code, _, err = run_cli(
        [
            "simulate",
            "--scenario",
            "smooth_manoeuvre",
            "--duration",
            "3",
            "--device",
            "consumer_mems",
            "--out",
            str(log),
        ]
    )
    assert code == 0, err
    out = tmp_path / "smoothed.mcap"
    code, stdout, err = run_cli(["estimate", str(log), "--out", str(out), "--smooth"])
    assert code == 0, err
    assert "mekf-smooth (9D)" in stdout
    written = read_mcap(out)
    (dev,) = written.devices.values()
    n = len(dev.samples.t)
    est = dev.estimate
    assert est is not None and len(est.t) == n
    setup = setup_from_metadata(dev.metadata, rate_of(dev.stamp_ns), use_mag=True)  # as estimate does
    want = MekfSmoother(setup).process(
        dev.seconds_from_first(),
        dev.samples.gyro,
        dev.samples.accel,
        dev.samples.mag,  # as estimate runs it
    )
    assert np.allclose(est.q_wb, want.q_wb, rtol=0, atol=1e-12)
    assert np.allclose(est.q_wb_covariance, want.q_wb_covariance, rtol=1e-12, atol=0)
    code, _, err = run_cli(["estimate", str(log), "--out", str(tmp_path / "x.mcap"), "--smooth", "--filter", "vqf"])
    assert code == 2 and "--smooth" in err


def test_bench_keeps_offline_estimators_apart(tmp_path):
    """``gyroemu bench`` with an online and an offline filter: two tables, and the JSON marks each."""
    from gyroemu.pipelines.jobs.bench import SimCase, run_bench

    report = run_bench([SimCase(duration=5.0)], filters=["mekf", "mekf-smooth"], runs=1)
    md = report.to_markdown()
    online, offline = md.index("## Online filters"), md.index("## Offline estimators")
    assert online < md.index("| mekf |") < offline < md.index("| mekf-smooth |")
    flags = {f["filter"]: f["offline"] for f in report.to_dict()["cases"][0]["filters"]}
    assert flags == {"mekf": False, "mekf-smooth": True}
    assert "## Online" not in run_bench([SimCase(duration=2.0)], filters=["mekf"], runs=1).to_markdown()


# ------------------------------------------------------------------------------------------------
# Slow tier


@pytest.mark.slow
@needs_trial()
def test_broad_smoother_targets():
    """Issue #17 on the BROAD trials in shared, one parameter set each, offlineVQF in the same run:
    the smoothed 9D total RMSE at least 10 % below offlineVQF's, and the smoother better than the
    online MEKF in 6D inclination (the 6D target, 10 % below offlineVQF, is not met: README)."""
    from vqf import offlineVQF

    from gyroemu.pipelines.formats.importers import read_broad

    s9, o9, s6, f6 = [], [], [], []
    for path in sorted(BROAD_DIR.glob("*.hdf5")):
        trial = read_broad(path)
        fs, ref, movement = trial.rate_hz, trial.opt_quat, trial.movement
        t = np.arange(len(trial)) / fs
        mag = np.ascontiguousarray(trial.mag_ut)
        q9 = MekfSmoother(FilterSetup(rate_hz=fs)).process(t, trial.gyro, trial.accel, mag * 1e-6).q_wb
        six = FilterSetup(rate_hz=fs, use_mag=False)
        q6 = MekfSmoother(six).process(t, trial.gyro, trial.accel).q_wb
        s9.append(rmse_deg(attitude_errors(q9, ref).total, movement))
        s6.append(rmse_deg(attitude_errors(q6, ref).inclination, movement))
        f6.append(
            rmse_deg(attitude_errors(Mekf(six).process(t, trial.gyro, trial.accel).q_wb, ref).inclination, movement)
        )
        o9.append(
            rmse_deg(attitude_errors(offlineVQF(trial.gyro, trial.accel, mag, 1.0 / fs)["quat9D"], ref).total, movement)
        )
    assert np.mean(s9) <= 0.9 * np.mean(o9), (np.mean(s9), np.mean(o9))
    assert np.mean(s6) < np.mean(f6), (np.mean(s6), np.mean(f6))


def test_smoothed_output_is_unit_quaternions_and_positive_covariances(short_run):
    """Every smoothed sample is a unit quaternion with a symmetric positive-definite covariance."""
    setup, t, samples, mag, _ = short_run
    est = MekfSmoother(setup).process(t, samples.gyro, samples.accel, mag)
    assert np.allclose(np.linalg.norm(est.q_wb, axis=1), 1.0, rtol=0, atol=1e-12)
    assert np.allclose(est.q_wb_covariance, est.q_wb_covariance.transpose(0, 2, 1), rtol=0, atol=0)
    assert np.all(np.linalg.eigvalsh(est.q_wb_covariance) > 0)


def test_a_noiseless_gyro_smooths_through_its_singular_prior():
    """The ideal device has no process noise, so the prior covariance is singular: the backward pass
    takes its pseudo-inverse and still returns unit quaternions, closer to the truth than forward."""
    scen, dev, samples, mag, q_true = _simulated("smooth_manoeuvre", "ideal", 0, 3.0)
    setup = setup_for(dev, scen)
    res = smooth_log(setup, np.asarray(samples.t, float) - samples.t[0], samples.gyro, samples.accel, mag)
    assert np.allclose(np.linalg.norm(res.smoothed.q_wb, axis=1), 1.0, rtol=0, atol=1e-12)
    assert np.isfinite(res.smoothed.q_wb_covariance).all()
    e_f = rmse_deg(attitude_errors(res.forward.q_wb, q_true).total)
    assert rmse_deg(attitude_errors(res.smoothed.q_wb, q_true).total) < e_f
