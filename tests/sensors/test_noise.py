"""The noise generators against the IEEE 952 closed forms, within bounds from the sample count.

An Allan deviation from n samples with clusters of m samples has a relative standard deviation of
about 1/√(2(n/m − 1)) (IEEE 952 Annex C); a sample standard deviation of n independent samples,
1/√(2n). Every statistical check allows SIGMAS of these.
"""

import numpy as np
import pytest

from gyroemu.sensors import noise
from gyroemu.sensors.allan import allan_deviation

SIGMAS = 4


def adev_tolerance(n: int, tau: float, dt: float, axes: int = 1) -> float:
    """SIGMAS relative standard deviations of an Allan deviation at ``tau`` (averaged over ``axes``)."""
    return SIGMAS / np.sqrt(2 * (n / (tau / dt) - 1)) / np.sqrt(axes)


def adev(x: np.ndarray, dt: float, taus) -> np.ndarray:
    """Allan deviation of each column of ``x`` (n, A) at ``taus``: (A, len(taus))."""
    return np.array([allan_deviation(x[:, a], dt, taus=np.asarray(taus, float)).adev for a in range(x.shape[1])])


def white_numpy(rng, shape, dt, n_density):
    return noise.white_noise(rng, shape, dt, n_density)


def white_kernel(rng, shape, dt, n_density):
    return noise.sensor_noise(rng, shape, dt, white=n_density)


def walk_numpy(rng, shape, dt, k_density):
    return noise.random_walk(rng, shape, dt, k_density)


def walk_kernel(rng, shape, dt, k_density):
    return noise.sensor_noise(rng, shape, dt, random_walk=k_density)


@pytest.mark.parametrize("generate", [white_numpy, white_kernel])
def test_white_noise_has_sigma_n_over_sqrt_dt_and_adev_n_at_1s(generate):
    dt, density, n = 0.01, 2e-3, 400_000
    x = generate(np.random.default_rng(1), (n, 3), dt, density)

    sigma = density / np.sqrt(dt)  # per-sample σ = N / √Δt
    assert np.all(np.abs(x.std(axis=0) / sigma - 1) < SIGMAS / np.sqrt(2 * n))
    assert np.all(np.abs(adev(x, dt, [1.0])[:, 0] / density - 1) < adev_tolerance(n, 1.0, dt))


def test_the_kernel_draws_the_same_numbers_as_numpy():
    a = noise.white_noise(np.random.default_rng(7), (1000, 3), 0.01, [1.0, 2.0, 3.0])
    b = noise.sensor_noise(np.random.default_rng(7), (1000, 3), 0.01, white=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("generate", [walk_numpy, walk_kernel])
def test_rate_random_walk_has_adev_k_at_3s(generate):
    dt, k_density, n = 0.01, 1e-3, 1_000_000
    x = generate(np.random.default_rng(2), (n, 3), dt, k_density)

    steps = np.diff(x, axis=0)  # increments σ = K √Δt
    assert np.all(np.abs(steps.std(axis=0) / (k_density * np.sqrt(dt)) - 1) < SIGMAS / np.sqrt(2 * n))
    assert np.all(np.abs(adev(x, dt, [3.0])[:, 0] / k_density - 1) < adev_tolerance(n, 3.0, dt))


def test_flicker_floor_is_0664_b_over_three_decades():
    dt, b, n = 0.1, 1e-4, 2**20
    x = noise.flicker_noise(np.random.default_rng(3), (n, 3), dt, b, tau_range=(0.2, 300.0))

    taus = dt * 2.0 ** np.arange(1, 12)  # 0.2 … 205 s
    assert np.log10(taus[-1] / taus[0]) >= 3
    assert adev_tolerance(n, taus[-1], dt, axes=3) < 0.10  # the run is long enough to judge 10 %
    floor = adev(x, dt, taus).mean(axis=0) / (noise.FLICKER_FLOOR * b)
    assert np.all(np.abs(floor - 1) < 0.10), floor


@pytest.mark.parametrize("tau_range, dt", [((1.0, 1e4), None), ((0.5, 1000.0), 0.1), ((0.01, 1e5), 0.01)])
def test_flicker_bank_is_flat_in_theory(tau_range, dt):
    bank = noise.flicker_bank(1.0, tau_range, dt)
    tau = np.geomspace(max(tau_range[0], dt or 0), tau_range[1], 300)
    floor = np.sqrt(bank.avar(tau, dt)[:, 0]) / noise.FLICKER_FLOOR
    assert np.all(np.abs(floor - 1) < 0.015)
    assert noise.FLICKER_FLOOR == pytest.approx(0.664, abs=5e-4)


def test_quantisation_noise_has_slope_minus_one_and_sqrt3_q_over_tau():
    dt, lsb, n = 0.01, 1e-5, 1_000_000
    x = noise.quantisation_noise(np.random.default_rng(4), n, dt, lsb)

    q = lsb / np.sqrt(12)  # rms angle error
    allan = allan_deviation(x, dt)
    keep = allan.tau <= 10.0
    tau, measured = allan.tau[keep], allan.adev[keep]
    bound = np.array([adev_tolerance(n, t, dt) for t in tau])
    assert np.all(np.abs(measured / (np.sqrt(3) * q / tau) - 1) < bound)
    slope = np.polyfit(np.log(tau), np.log(measured), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.02)


def test_quantise_angle_counts_whole_quanta_and_loses_no_angle():
    dt, lsb, n = 0.01, 1e-5, 400_000
    rng = np.random.default_rng(5)
    rate = 50 * lsb / dt * rng.standard_normal((n, 2))  # the angle moves ~50 LSB a sample
    y = noise.quantise_angle(rate, dt, lsb, rng)

    counts = y * dt / lsb
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    angle_error = np.cumsum(y - rate, axis=0) * dt
    assert np.max(np.abs(angle_error)) < lsb * (1 + 1e-6)

    # The rate error is then IEEE 952's quantisation noise: √3 Q/τ, Q = LSB/√12.
    taus = [0.01, 0.1, 1.0]
    measured = adev(y - rate, dt, taus)
    expected = np.sqrt(3) * lsb / np.sqrt(12) / np.array(taus)
    bound = np.array([adev_tolerance(n, t, dt) for t in taus])
    assert np.all(np.abs(measured / expected - 1) < bound)


def test_gauss_markov_variance_and_autocorrelation():
    dt, sigma, tau_c, n = 0.01, 2.0, 0.5, 1_000_000
    x = noise.gauss_markov(np.random.default_rng(6), (n, 2), dt, sigma, tau_c)

    phi = np.exp(-dt / tau_c)
    # Sample variance of an AR(1) sequence: relative sd √(2(1+φ²) / (n(1−φ²))).
    var_sd = np.sqrt(2 * (1 + phi**2) / (n * (1 - phi**2)))
    assert np.all(np.abs(x.var(axis=0) / sigma**2 - 1) < SIGMAS * var_sd)

    # Autocorrelation at lag τ_c is e⁻¹; Bartlett's variance of r_k for AR(1).
    lag = round(tau_c / dt)
    r = np.mean(x[:-lag] * x[lag:], axis=0) / x.var(axis=0)
    r_sd = np.sqrt(((1 + phi**2) * (1 - phi ** (2 * lag)) / (1 - phi**2) - 2 * lag * phi ** (2 * lag)) / n)
    assert np.all(np.abs(r - np.exp(-1)) < SIGMAS * r_sd)


def test_gauss_markov_is_stationary_from_the_first_sample():
    sigma, tau_c, dt, m = 3.0, 1.0, 0.1, 200_000
    x = noise.gauss_markov(np.random.default_rng(8), (2, m), dt, sigma, tau_c)  # m independent processes
    assert np.all(np.abs(x.std(axis=1) / sigma - 1) < SIGMAS / np.sqrt(2 * m))
    assert np.corrcoef(x[0], x[1])[0, 1] == pytest.approx(np.exp(-dt / tau_c), abs=SIGMAS / np.sqrt(m))


def test_gauss_markov_allan_variance_closed_forms():
    sigma, tau_c, dt = 1.5, 0.3, 0.1
    phi = np.exp(-dt / tau_c)
    for m in (1, 2, 5, 20):
        # Sampled: ½ E[(mean of block 2 − mean of block 1)²] from the covariance σ² φ^|i−j|.
        i = np.arange(2 * m)
        cov = sigma**2 * phi ** np.abs(i[:, None] - i[None, :])
        w = np.r_[-np.ones(m), np.ones(m)] / m
        assert noise.gauss_markov_avar(m * dt, sigma, tau_c, dt) == pytest.approx(0.5 * w @ cov @ w, rel=1e-12)
    # Continuous: random walk K² τ/3 with K² = 2σ²/τ_c for τ ≪ τ_c; white 2σ²τ_c/τ for τ ≫ τ_c.
    assert noise.gauss_markov_avar(1e-7, sigma, tau_c) == pytest.approx(2 * sigma**2 / tau_c * 1e-7 / 3, rel=1e-6)
    assert noise.gauss_markov_avar(1e4, sigma, tau_c) == pytest.approx(2 * sigma**2 * tau_c / 1e4, rel=1e-4)


def test_rate_ramp_is_r_times_t():
    y = noise.rate_ramp((4, 2), 0.5, [1.0, -2.0])
    np.testing.assert_array_equal(y, np.arange(4)[:, None] * 0.5 * np.array([1.0, -2.0]))


def test_same_seed_same_bits_and_other_seeds_independent():
    dt, n = 0.01, 200_000
    bank = noise.flicker_bank(1e-3, (0.1, 1000.0), dt, n_axes=3)

    def run(seed):
        rng = np.random.default_rng(seed)
        return noise.sensor_noise(rng, (n, 3), dt, white=1e-2, random_walk=1e-4, flicker=bank)

    np.testing.assert_array_equal(run(11), run(11))
    # White noise dominates each sample, so the samples of two seeds are independent pairs.
    a, b = run(11), run(12)
    for axis in range(3):
        assert abs(np.corrcoef(a[:, axis], b[:, axis])[0, 1]) < 4 / np.sqrt(n)


def test_shapes_and_per_axis_coefficients():
    rng = np.random.default_rng(0)
    assert noise.white_noise(rng, 10, 0.1, 1.0).shape == (10,)
    assert noise.gauss_markov(rng, (10, 2), 0.1, [1.0, 2.0], [1.0, 3.0]).shape == (10, 2)
    assert noise.flicker_noise(rng, 1, 0.1, 1.0, (1.0, 10.0)).shape == (1,)
    with pytest.raises(ValueError, match="density"):
        noise.white_noise(rng, 10, 0.1, -1.0)
    with pytest.raises(ValueError, match="tau_range"):
        noise.flicker_bank(1.0, (10.0, 1.0))


def test_a_slow_component_is_linear_between_its_knots():
    # One Gauss–Markov component of τ_c = 1024 Δt is simulated every L = τ_c / (16 Δt) = 64 samples and
    # interpolated: the output is a straight line between knots (second differences vanish but at the
    # knots, to round-off of the values).
    dt, step = 0.01, 64
    bank = noise.FlickerBank(tau_c=np.array([16 * step * dt]), sigma=np.array([[1.0, 2.0]]), tau_range=(1.0, 10.0))
    n = 10 * step + 17
    whole = noise.SensorNoise(np.random.default_rng(3), 2, dt, flicker=bank).add_into(np.zeros((n, 2)))
    curvature = np.diff(whole, 2, axis=0)  # row i is centred on sample i + 1
    off_knot = (np.arange(1, n - 1) % step) != 0
    bound = 8 * np.finfo(float).eps * np.abs(whole).max()
    assert np.all(np.abs(curvature[off_knot]) <= bound)
    assert np.all(np.abs(curvature[~off_knot]).max(axis=0) > 1e3 * bound)  # the knots do bend it


def test_any_division_into_calls_continues_one_run_in_a_few_knots():
    # White noise, a random walk and a flicker bank with fast and three slow levels: the state carries
    # across calls, each slow level draws from its own stream, so the numbers do not depend on where
    # the calls divide the run, and the slow levels hold two knots each at most between calls.
    dt = 0.01
    bank = noise.flicker_bank([1e-3, 2e-3, 3e-3], (0.05, 200.0), dt, n_axes=3)
    assert len(bank.tau_c) >= 6 and bank.tau_c.max() / (16 * dt) >= 4 * 64  # fast and slow components
    n = 5000

    def generator():
        return noise.SensorNoise(np.random.default_rng(11), 3, dt, white=0.1, random_walk=0.01, flicker=bank)

    whole = generator().add_into(np.zeros((n, 3)))
    gen, parts, made = generator(), [], 0
    levels = int(np.sum(np.unique(np.floor(np.log2(np.maximum(bank.tau_c / (16 * dt), 1.0)))) > 0))
    for size in (1, 63, 64, 65, 1000, 3, 2 * n):
        size = min(size, n - made)
        parts.append(gen.add_into(np.zeros((size, 3))))
        made += size
        assert gen.held_knots <= 2 * levels
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_sensor_noise_gauss_markov_row_matches_its_allan_closed_form():
    """A Gauss–Markov term in SensorNoise (one more AR(1) row, φ = e^{−Δt/τ_c}, stationary start): its
    Allan deviation is ``gauss_markov_avar`` of the sampled process, at every octave τ from Δt to 20 τ_c,
    within SIGMAS relative standard deviations of the estimate (1/√(2(n/m − 1)) per axis, IEEE 952 Annex
    C; averaged over the axes of equal σ and τ_c). A term that is off draws nothing."""
    dt, n, sigma, tau_c = 0.01, 2**20, 2e-3, 0.5
    gen = noise.SensorNoise(np.random.default_rng(21), 3, dt, markov=(sigma, tau_c))
    x = gen.add_into(np.zeros((n, 3)))
    taus = dt * 2.0 ** np.arange(0, 11)  # 0.01 … 10.24 s
    measured = adev(x, dt, taus).mean(axis=0)
    expected = np.sqrt(noise.gauss_markov_avar(taus, sigma, tau_c, dt))
    tolerance = np.array([adev_tolerance(n, tau, dt, axes=3) for tau in taus])
    assert np.all(np.abs(measured / expected - 1) < tolerance), (measured / expected - 1, tolerance)
    # The variance σ² (AR(1) sample variance: relative sd √(2(1+φ²)/(n(1−φ²))), per axis).
    phi = np.exp(-dt / tau_c)
    var_sd = np.sqrt(2 * (1 + phi**2) / (n * (1 - phi**2)))
    assert np.all(np.abs(x.var(axis=0) / sigma**2 - 1) < SIGMAS * var_sd)

    # Off (None, or σ = 0 on every axis): the same numbers as without the keyword, the same draws.
    bank = noise.flicker_bank(1e-3, (0.1, 100.0), dt, n_axes=3)
    runs = []
    for markov in (None, (0.0, 1.0), ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])):
        rng = np.random.default_rng(5)
        out = noise.SensorNoise(rng, 3, dt, white=1e-2, random_walk=1e-4, flicker=bank, markov=markov)
        runs.append((out.add_into(np.zeros((4096, 3))), rng.bit_generator.state))
    for values, state in runs[1:]:
        np.testing.assert_array_equal(values, runs[0][0])
        assert state == runs[0][1]
    # On one axis only: the others get nothing from it.
    y = noise.SensorNoise(np.random.default_rng(6), 3, dt, markov=([0.0, sigma, 0.0], [0.0, tau_c, 0.0]))
    y = y.add_into(np.zeros((1000, 3)))
    np.testing.assert_array_equal(y[:, [0, 2]], 0.0)
    assert y[:, 1].std() > 0
    with pytest.raises(ValueError, match="tau_c"):
        noise.SensorNoise(np.random.default_rng(0), 3, dt, markov=(sigma, 0.0))
