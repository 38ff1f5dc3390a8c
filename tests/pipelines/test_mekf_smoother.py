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
    skern.rts_backward(F_top, covs_p, covs, means - means_p, e_s, P_s)
    got_x = means + e_s  # e_s is relative to each posterior; the linear "injection" is a sum
    # Round-off: n steps of O(X³) algebra on matrices of condition number κ
    kappa = max(np.linalg.cond(c) for c in covs_p)
    tol = 10 * n * X * kappa * EPS
    assert np.allclose(got_x, want_x[:, :, 0], rtol=0, atol=tol * np.abs(want_x).max())
    assert np.allclose(P_s, want_P, rtol=0, atol=tol * np.abs(want_P).max())


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
    (P_post ≤ P_prior); the heading's constrained gain (no tilt, no δM: a Schmidt "consider" update) is
    not one, and can raise P along some direction, so the ordering is held on the 6D run, whose
    updates (gravity, rest) all are."""
    setup, t, samples, mag, q_true = short_run
    params = smoother_params(setup)
    res = smooth_log(setup, t, samples.gyro, samples.accel, mag, params=params)
    online = Mekf(setup, params).process(t, samples.gyro, samples.accel, mag)
    assert np.abs(res.forward.q_wb - online.q_wb).max() < 1e-9
    ends = res.window_end
    assert np.allclose(res.forward.q_wb_covariance[ends], online.q_wb_covariance[ends], rtol=1e-9, atol=0)
    e_f = rmse_deg(attitude_errors(res.forward.q_wb, q_true).total)
    e_s = rmse_deg(attitude_errors(res.smoothed.q_wb, q_true).total)
    assert e_s < e_f, (e_s, e_f)
    six = smooth_log(replace(setup, use_mag=False), t, samples.gyro, samples.accel, None, params=params)
    ends6 = six.window_end
    diff = six.forward.q_wb_covariance[ends6] - six.smoothed.q_wb_covariance[ends6]
    lowest = np.linalg.eigvalsh(0.5 * (diff + diff.transpose(0, 2, 1))).min(axis=1)
    scale = np.trace(six.forward.q_wb_covariance[ends6], axis1=1, axis2=2)
    assert np.all(lowest >= -1e3 * EPS * scale)
    # the last window's smoothed state is the forward posterior (nothing after it)
    assert np.allclose(res.smoothed.q_wb[ends[-1]], res.forward.q_wb[ends[-1]], rtol=0, atol=1e-12)
    assert res.scale_misalignment.shape == (len(ends), 3, 3)


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
    setup = setup_from_metadata(dev.metadata, rate_of(dev.samples.t), use_mag=True)  # as estimate does
    want = MekfSmoother(setup).process(
        dev.samples.t - dev.samples.t[0], dev.samples.gyro, dev.samples.accel, dev.samples.mag
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
