"""The bench's metrics a block at a time (:mod:`gyroemu.pipelines.jobs.bench_metrics`): the same result to the
bit however a run is cut into blocks, and the definitions over the whole run (written out here with
NumPy over whole arrays, as ``bench.evaluate_run`` computed them before) to round-off.

Bounds. The RMS errors are sums of squares: summed in tiles of ``SUM_TILE`` values and the tiles added in
order, against NumPy's pairwise ``np.mean`` over all of them, each ordering's sum of n positive terms lies
within (n − 1)·ε of the exact sum relatively (the recursive bound of a naive sum, which bounds both), so
the two differ by at most 2(n − 1)·ε relatively, and the square roots by half that. The bias reference
is the same sequence of additions in both (a running sum), so the bias error differs only through its
final RMS. Everything else (convergence time, divergence, the reasons) is equal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroemu.dynamics.rotation import quat_from_euler_zyx, quat_multiply
from gyroemu.pipelines.estimation.metrics import attitude_errors, convergence_time
from gyroemu.pipelines.jobs.bench_metrics import BIAS_WINDOW_S, SUM_TILE, RunMetrics, TiledSquares

EPS = np.finfo(float).eps
RATE = 199.0  # an odd window: its centre is not halfway by symmetry


def a_run(rng: np.random.Generator, n: int, *, diverge: bool = False) -> dict:
    """A run of ``n`` samples at ``RATE``: a reference attitude, an estimate off by a few degrees that settles
    below 2° after a while (or, ``diverge``, goes 40° off over its last fifth), truth rows lost (NaN) in
    stretches, a movement mask, a bias estimate, a true rate and a gyro."""
    t = 1000.0 + np.arange(n) / RATE
    ref = quat_from_euler_zyx(rng.normal(0, 0.5, (n, 3)))
    off = np.radians(5.0) * np.exp(-(t - t[0]) / 5.0)[:, None] * rng.normal(0, 1, (n, 3))
    off += np.radians(0.3) * rng.normal(0, 1, (n, 3))
    if diverge:
        off[4 * n // 5 :, 0] += np.radians(40.0)
    est = quat_multiply(quat_from_euler_zyx(off), ref)
    est[rng.choice(n, 3, replace=False)] = np.nan  # a filter's non-finite output, here and there
    q_true = ref.copy()
    for start in rng.choice(n - 50, 4, replace=False):  # the reference lost its tracking
        q_true[start : start + int(rng.integers(1, 50))] = np.nan
    mask = np.ones(n, bool)
    mask[: n // 10] = False
    omega = rng.normal(0, 1, (n, 3))
    omega[[n - 300, n - 40]] = np.nan  # a truth rate lost: NaN carries on in the running sum to the end
    gyro = omega + 0.01 + rng.normal(0, 0.02, (n, 3))
    bias = 0.01 + rng.normal(0, 1e-3, (n, 3))
    return {"t": t, "q_est": est, "q_true": q_true, "mask": mask, "bias": bias, "omega": omega, "gyro": gyro}


def metrics_of(run: dict, edges, six_d: bool, with_bias: bool = True):
    """The result of :class:`RunMetrics` fed the run in the blocks between ``edges``."""
    n = len(run["t"])
    counted = int((run["mask"] & np.isfinite(run["q_true"]).all(axis=1)).sum())
    m = RunMetrics(
        samples=n,
        counted=counted,
        t_first=float(run["t"][0]),
        t_last=float(run["t"][-1]),
        six_d=six_d,
        threshold_deg=2.0,
        bias_window=int(round(BIAS_WINDOW_S * RATE)) if with_bias else None,
    )
    errors = []
    for a, b in zip(edges[:-1], edges[1:]):
        cols = {k: v[a:b] for k, v in run.items()}
        errors.append(
            m.add(cols["t"], cols["q_est"], cols["q_true"], cols["mask"], cols["bias"], cols["omega"], cols["gyro"])
        )
    m.wall_s = 0.5
    joined = {k: np.concatenate([e[k] for e in errors]) for k in ("total", "inclination")}
    return m.result(seed=7), joined


def whole_run_reference(run: dict, six_d: bool) -> dict:
    """The bench's definitions over whole arrays (``bench.evaluate_run`` before the metrics went blockwise)."""
    n = len(run["t"])
    finite = np.isfinite(run["q_est"]).all(axis=1) & (np.linalg.norm(run["q_est"], axis=1) > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        err = attitude_errors(np.where(finite[:, None], run["q_est"], np.nan), run["q_true"])
    counted = run["mask"] & np.isfinite(run["q_true"]).all(axis=1)

    def rms(x):
        x = x[~np.isnan(x)]
        return float(np.degrees(np.sqrt(np.mean(x**2)))) if len(x) else math.nan

    total, inclination = np.where(counted, err.total, np.nan), np.where(counted, err.inclination, np.nan)
    idx = np.flatnonzero(counted)
    tail_rms = rms(err.inclination[idx[len(idx) - max(1, int(math.ceil(0.1 * len(idx)))) :]])
    window = int(round(1.0 * RATE))  # the bench's notes: the rate's error averaged over a centred 1 s window
    omega_mean = run["omega"].copy()
    omega_mean[1:] = 0.5 * (run["omega"][1:] + run["omega"][:-1])
    c = np.cumsum(np.concatenate([np.zeros((1, 3)), run["gyro"] - omega_mean]), axis=0)
    b_true = np.full((n, 3), np.nan)
    b_true[window // 2 : window // 2 + n - window + 1] = (c[window:] - c[:-window]) / window
    diff = np.linalg.norm(run["bias"] - b_true, axis=1)
    ok = (run["t"] >= run["t"][0] + 0.5 * (run["t"][-1] - run["t"][0])) & np.isfinite(diff)
    return {
        "total": rms(total),
        "heading": rms(np.where(counted, err.heading, np.nan)),
        "inclination": rms(inclination),
        "convergence": convergence_time(run["t"], inclination if six_d else total, math.radians(2.0)),
        "tail": tail_rms,
        "bias": float(np.degrees(np.sqrt(np.mean(diff[ok] ** 2)))),
        "finite": bool(finite.all()),
        "errors": {"total": np.degrees(total), "inclination": np.degrees(inclination)},
    }


@pytest.mark.parametrize("six_d", [False, True], ids=["9D", "6D"])
@pytest.mark.parametrize("diverge", [False, True], ids=["settles", "diverges"])
def test_any_cut_gives_the_same_result_as_one_block(six_d, diverge):
    """One block, single samples, and random cuts (through tiles, bias windows and the divergence tail):
    every field of the result and every per-sample error the same to the bit."""
    rng = np.random.default_rng(3 if diverge else 4)
    n = 3 * SUM_TILE + 517
    run = a_run(rng, n, diverge=diverge)
    whole, errors = metrics_of(run, [0, n], six_d)
    cuts = [
        np.arange(n + 1),
        np.unique(np.concatenate([[0, n], rng.choice(np.arange(1, n), 60, replace=False)])),
        np.array([0, 1, SUM_TILE, SUM_TILE + 1, n - 1, n]),
    ]
    for edges in cuts:
        got, got_errors = metrics_of(run, edges, six_d)
        assert got == whole, len(edges)
        for k in errors:
            np.testing.assert_array_equal(got_errors[k], errors[k])
    assert whole.diverged == (diverge or not np.isfinite(run["q_est"]).all())


@pytest.mark.parametrize("six_d", [False, True], ids=["9D", "6D"])
@pytest.mark.parametrize("diverge", [False, True], ids=["settles", "diverges"])
def test_the_metrics_are_the_whole_run_definitions(six_d, diverge):
    """Against the whole-array definitions: RMS values within (n − 1)·ε relatively (module's notes),
    the convergence time and the per-sample errors exactly, the bias error within its RMS's bound."""
    rng = np.random.default_rng(5 if diverge else 6)
    n = 2 * SUM_TILE + 1000
    run = a_run(rng, n, diverge=diverge)
    got, errors = metrics_of(run, [0, 1500, 1501, n], six_d)
    ref = whole_run_reference(run, six_d)
    bound = (n - 1) * EPS
    for name, value in (("inclination", got.inclination_deg), ("bias", got.bias_error_deg_s)):
        assert abs(value - ref[name]) <= bound * ref[name], name
    if six_d:
        assert got.total_deg is None and got.heading_deg is None
    else:
        assert abs(got.total_deg - ref["total"]) <= bound * ref["total"]
        assert abs(got.heading_deg - ref["heading"]) <= bound * ref["heading"]
    assert got.convergence_s == ref["convergence"]
    assert got.throughput == n / got.wall_s  # samples a second, the wall time set by the caller
    assert got.diverged == (ref["tail"] > 30.0 or not ref["finite"])
    assert got.diverged == diverge or not ref["finite"]
    for k in errors:
        np.testing.assert_array_equal(errors[k], ref["errors"][k])


def test_a_run_one_bias_window_long_cut_before_its_centre():
    """About the shortest run with a bias error: one window and a sample long, so its two complete windows
    are centred on samples ``window // 2`` and the next; its first interval is 10 s long, so both are in
    the run's second half (counted by time: every sample but the first). Cut before
    the centres, or after them with the windows still open (the first samples, which have no window,
    are then compared), the running sums the first block leaves must still hold the windows' start: the
    same result as one block, to the bit."""
    rng = np.random.default_rng(9)
    window = int(round(BIAS_WINDOW_S * RATE))
    run = a_run(rng, window + 60)
    run = {k: v[: window + 1] for k, v in run.items()}
    run["omega"] = np.nan_to_num(run["omega"])
    run["t"][1:] += 10.0
    run["q_true"][:] = run["q_est"]  # every sample counted where the estimate is finite
    whole, _ = metrics_of(run, [0, window + 1], False)
    assert whole.bias_error_deg_s is not None and np.isfinite(whole.bias_error_deg_s)
    for first in (1, window // 2 - 1, window // 2 + 20, window - 1):
        assert metrics_of(run, [0, first, window + 1], False)[0] == whole, first


def test_no_bias_without_a_window_or_a_bias_in_every_block():
    """No bias error without the truth's rate (no window), nor for a filter that gave no bias in a block."""
    rng = np.random.default_rng(8)
    run = a_run(rng, 2000)
    assert metrics_of(run, [0, 2000], False, with_bias=False)[0].bias_error_deg_s is None
    m = RunMetrics(samples=2000, counted=1, t_first=0.0, t_last=1.0, six_d=False, threshold_deg=2.0, bias_window=200)
    cols = [run[k] for k in ("t", "q_est", "q_true", "mask")]
    m.add(*(c[:1000] for c in cols), run["bias"][:1000], run["omega"][:1000], run["gyro"][:1000])
    m.add(*(c[1000:] for c in cols), None, run["omega"][1000:], run["gyro"][1000:])
    assert m.result().bias_error_deg_s is None


def test_tiled_squares_do_not_depend_on_the_cut():
    """The same float for one block and for blocks of 1, 7 and 4,095 values, and the exact count."""
    rng = np.random.default_rng(9)
    x = rng.normal(0, 1, 3 * SUM_TILE + 11)
    x[::97] = np.nan
    chosen = rng.random(len(x)) < 0.8
    results = []
    for size in (len(x), 1, 7, SUM_TILE - 1):
        s = TiledSquares()
        for a in range(0, len(x), size):
            s.add(x[a : a + size], chosen[a : a + size])
        results.append((s.rms_deg(), s.count))
    assert len(set(results)) == 1
    assert results[0][1] == int((chosen & ~np.isnan(x)).sum())
