"""The compiled ahrs kernels (:mod:`gyroemu.pipelines.estimation.ahrs_kernels`) against the library.

Each adapter of :mod:`gyroemu.pipelines.estimation.peers` runs once through its compiled kernel and once
with ``_reference`` set, through the ``ahrs`` objects' own per-sample updates exactly as the adapter made
them before the kernels; the quaternions (and Mahony's bias) must agree to round-off.

The bound: ``|Δq_k| ≤ 1000 ε k`` at sample ``k`` (``ε`` the float64 epsilon). The kernels compute the
library's expressions in its order, except the order of a few sums (BLAS dot and matrix products) and
the EKF's inversion of ``S`` (LU here, LAPACK's ``gesv`` there): a few ulps per step. The filters
contract attitude errors (their corrections pull both towards the same measurements), so the difference
does not grow like a sum of per-step errors; the bound is that sum at 1000 ε per step, a worst case far
above what happens. Measured on 20 s at 1 kHz (the test runs 8 s): at most 26 ε (4 e-15) for every filter and
mode but the 6D EKF, 424 ε (9 e-14; its heading is unobservable, so round-off random-walks in it),
and ``max |Δq_k| / (k ε)`` ≤ 0.34: the bound holds with a margin of about 3000.

``python tests/benchmarks/bench_ahrs.py`` prints the throughput of both paths.
"""

import subprocess
import sys

import numpy as np
import pytest
from broad_trials import BROAD_DIR, needs_trial

from gyroemu.pipelines.estimation import peers
from gyroemu.pipelines.estimation.protocol import FilterSetup

EPS = np.finfo(float).eps
PER_STEP = 1e3 * EPS  # the bound per step, accumulated (module notes)
FILTERS = {"madgwick": peers.Madgwick, "mahony": peers.Mahony, "ahrs-ekf": peers.AhrsEkf}
MODES = {"9d": True, "6d": False}
TRIAL_02 = BROAD_DIR / "02_undisturbed_slow_rotation_B.hdf5"


def _simulated(duration=8.0):
    import gyroemu.dynamics as dyn
    import gyroemu.sensors as sens

    traj = dyn.load_scenario("smooth_manoeuvre").simulate(duration=duration)
    samples = sens.load_device("consumer_mems", seed=1).measure(traj)
    return samples.t, samples.gyro, samples.accel, samples.mag


@pytest.fixture(scope="module")
def motion():
    return _simulated()


def _perturbed(t, gyro, accel, mag, seed=7):
    """The motion with what the adapters must handle: missing gyro, accelerometer and magnetometer
    samples, a slower magnetometer for a while, exact zero gyro samples, uneven, repeated and missing
    stamps and a gap."""
    rng = np.random.default_rng(seed)
    t, gyro, accel, mag = (np.array(x, dtype=float) for x in (t, gyro, accel, mag))
    n = len(t)
    t = t + rng.normal(0.0, 2e-5, n)  # jitter
    t[500] = t[499]  # a repeated stamp: dt not positive -> nominal
    t[700] = np.nan  # a missing stamp: nominal, then nominal again
    t[3000:] += 0.05  # a gap of 50 ms
    gyro[rng.choice(n, 40, replace=False)] = np.nan
    gyro[rng.choice(n, 10, replace=False)] = 0.0  # the libraries' zero-gyro shortcut
    accel[rng.choice(n, 40, replace=False)] = np.nan
    accel[1200:1210] = 0.0  # all-zero: not usable
    mag[rng.choice(n, 40, replace=False)] = np.nan
    slow = np.arange(4000, 6000)
    mag[slow[slow % 10 != 0]] = np.nan  # a magnetometer at a tenth of the rate
    return t, gyro, accel, mag


def _run(cls, setup, blocks, reference):
    f = cls(setup)
    f._reference = reference
    ests = [f.process(*block) for block in blocks]
    q = np.concatenate([e.q_wb for e in ests])
    b = np.concatenate([e.gyro_bias for e in ests]) if ests[0].gyro_bias is not None else None
    return q, b


def _split(arrays, edges):
    return [tuple(x[i:j] for x in arrays) for i, j in zip(edges[:-1], edges[1:])]


def _assert_round_off(name, kernel, reference):
    """``|Δ_k| ≤ 1000 ε k`` (k counted from the first estimate), NaN exactly where the library's is NaN."""
    np.testing.assert_array_equal(np.isnan(kernel), np.isnan(reference), err_msg=name)
    rows = np.isfinite(reference).all(axis=1)
    assert rows.any(), name
    d = np.abs(kernel[rows] - reference[rows]).max(axis=1)
    k = np.arange(1, len(d) + 1)
    worst = float(np.max(d / (k * EPS)))
    print(f"{name}: max |Δ| {d.max():.3g} ({d.max() / EPS:.1f} ε), max |Δ_k|/(k ε) {worst:.3g}")
    assert np.all(d <= PER_STEP * k), (name, d.max(), worst)
    return d.max()


def _compare(name, cls, use_mag, rate_hz, blocks):
    setup = FilterSetup(rate_hz=rate_hz, use_mag=use_mag)
    q_k, b_k = _run(cls, setup, blocks, reference=False)
    q_r, b_r = _run(cls, setup, blocks, reference=True)
    _assert_round_off(name, q_k, q_r)
    if b_r is not None:
        _assert_round_off(name + " bias", b_k, b_r)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", FILTERS)
def test_kernel_reproduces_library_on_simulated_motion(motion, name, mode):
    t, gyro, accel, mag = motion
    _compare(f"{name} {mode}", FILTERS[name], MODES[mode], 1.0 / np.median(np.diff(t)), [motion])


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", FILTERS)
def test_kernel_reproduces_library_with_missing_samples_and_blocks(motion, name, mode):
    data = _perturbed(*(x[:8000] for x in motion))
    # Blocks: the state carries over from one process() call to the next, whatever the cut.
    blocks = _split(data, [0, 1, 257, 3001, 5555, 8000])
    _compare(f"{name} {mode} perturbed", FILTERS[name], MODES[mode], 1000.0, blocks)


@pytest.mark.parametrize("name", FILTERS)
def test_kernel_reproduces_library_started_without_a_field(motion, name):
    """A 9D filter whose first block has no field (the EKF then stays 6D) and a block of nothing usable."""
    t, gyro, accel, mag = (np.array(x[:3000]) for x in motion)
    mag[:1000] = np.nan
    accel[1000:1100] = np.nan
    gyro[1000:1100] = np.nan
    _compare(f"{name} late field", FILTERS[name], True, 1000.0, _split((t, gyro, accel, mag), [0, 1000, 1100, 3000]))


@needs_trial(TRIAL_02.name)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", FILTERS)
def test_kernel_reproduces_library_on_broad(name, mode):
    from gyroemu.pipelines.formats.importers import read_broad

    trial = read_broad(TRIAL_02)
    n = 10000
    g, a, m = (np.ascontiguousarray(x[:n]) for x in (trial.gyro, trial.accel, trial.mag_ut))
    t = np.arange(n) / trial.rate_hz
    _compare(f"{name} {mode} BROAD 02", FILTERS[name], MODES[mode], trial.rate_hz, [(t, g, a, m * 1e-6)])


def test_importing_the_kernels_does_not_import_numba():
    code = (
        "import sys; import gyroemu.pipelines.estimation.peers, gyroemu.pipelines.estimation.ahrs_kernels; "
        "assert 'numba' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
