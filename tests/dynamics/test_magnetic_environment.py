"""The site's magnetic environment: random field statistics, heading offset, overrides, config."""

import numpy as np
import pytest

from gyroemu.dynamics import ConfigError, Environment, Site, trajectory_from_world_motion
from gyroemu.dynamics.config import validate
from gyroemu.dynamics.magnetic_environment import (
    FEATURES,
    MagneticEnvironmentSpec,
    draw_realisation,
    field_along_path,
    reference_field,
    with_magnetic_environment,
)
from gyroemu.dynamics.rotation import quat_conjugate, quat_from_euler_zyx, quat_rotate

FIELD = np.array([1.63, 18.6, -46.4]) * 1e-6  # the default site's, tesla
SIGMA_UT, ELL = 2.0, 0.5
SPATIAL = MagneticEnvironmentSpec(spatial_sigma_uT=SIGMA_UT, correlation_length_m=ELL)


def _realisations(spec, points, count):
    """The spatial variation δ at ``points`` (P, 3) in ``count`` realisations (seeds 0 …): (count, P, 3)."""
    return np.stack(
        [
            draw_realisation(spec, FIELD, points[0], np.random.default_rng(seed)).variation(points)
            for seed in range(count)
        ]
    )


def test_variance_and_correlation_match_the_squared_exponential_covariance():
    # Over realisations, E δ_i(p)² = σ² and E δ_i(p) δ_i(p + d) = σ² exp(−d²/(2ℓ²)).
    count = 3000
    rng = np.random.default_rng(99)
    direction = rng.standard_normal(3)
    direction /= np.linalg.norm(direction)
    base = np.array([3.0, -2.0, 0.7])
    lags = np.array([0.0, 0.5, 1.0, 2.0, 4.0]) * ELL
    points = base + lags[:, None] * direction
    d = _realisations(SPATIAL, points, count) / (SIGMA_UT * 1e-6)  # in units of σ
    # Variance: δ(p)/σ is exactly N(0, 1) (given the wavevectors, cos² + sin² = 1), three independent
    # axes per realisation: the sample variance of n = 3 count draws has standard error √(2/n).
    n = 3 * count
    variance = np.mean(d[:, 0, :] ** 2)
    assert abs(variance - 1) < 5 * np.sqrt(2 / n)
    for j, lag in enumerate(lags[1:], start=1):
        rho = np.exp(-(lag**2) / (2 * ELL**2))
        products = d[:, 0, :] * d[:, j, :]
        # Var[δ(p)δ(p+d)/σ²] = 1 + E ρ̂² ≤ 1 + ρ² + Var ρ̂; the three axes share the wavevectors, whose
        # ρ̂(d) varies by Var ρ̂ = ((1 + ρ⁴)/2 − ρ²)/M between realisations (module notes).
        var_rho = ((1 + rho**4) / 2 - rho**2) / FEATURES
        se = np.sqrt((1 + rho**2 + var_rho) / n + var_rho / count)
        assert abs(products.mean() - rho) < 5 * se, (lag, products.mean(), rho, se)


def test_a_realisations_correlation_error_has_the_stated_statistics():
    # ρ̂(d) = (1/M) Σ cos(ω_m·d) per realisation: mean ρ(d), std √(((1 + ρ⁴)/2 − ρ²)/M).
    count = 400
    d = np.array([0.6, -0.5, 0.3]) * ELL
    rho = np.exp(-(d @ d) / (2 * ELL**2))
    est = np.array(
        [
            np.mean(np.cos(draw_realisation(SPATIAL, FIELD, np.zeros(3), np.random.default_rng(s)).wavevectors @ d))
            for s in range(count)
        ]
    )
    std = np.sqrt(((1 + rho**4) / 2 - rho**2) / FEATURES)
    assert abs(est.mean() - rho) < 5 * std / np.sqrt(count)
    # Sample std of n draws (near normal: a mean of 512 terms): relative standard error √(1/(2(n−1))).
    assert abs(est.std(ddof=1) / std - 1) < 5 / np.sqrt(2 * (count - 1))


def test_the_field_is_a_function_of_position():
    # A path out and back (and resting between): the same place reads the same field, whatever the time.
    t = np.linspace(0.0, 1.0, 2001)
    out = np.stack([np.sin(np.pi * t) * 2.0, 0.3 * np.sin(2 * np.pi * t), 0.1 * t * (1 - t)], -1)
    path = np.concatenate([out, np.repeat(out[-1:], 50, axis=0), out[::-1], out[5:700]])
    spec = MagneticEnvironmentSpec(
        spatial_sigma_uT=1.5, correlation_length_m=0.4, heading_offset_mean_deg=10.0, transition_m=0.2, seed=4
    )
    field = field_along_path(spec, FIELD, path)
    n = len(out)
    forward, back = field[:n], field[n + 50 : 2 * n + 50][::-1]
    np.testing.assert_allclose(back, forward, rtol=0, atol=1e-15 * np.linalg.norm(FIELD))
    np.testing.assert_allclose(field[2 * n + 50 :], forward[5:700], rtol=0, atol=1e-15 * np.linalg.norm(FIELD))
    assert np.all(field[n : n + 50] == field[n - 1])  # at rest: the very same value
    # Evaluated alone, a position reads what it reads along the path.
    alone = draw_realisation(spec, FIELD, path[0]).field(path[[1234]])
    np.testing.assert_allclose(alone[0], field[1234], rtol=0, atol=1e-15 * np.linalg.norm(FIELD))
    assert np.ptp(field, axis=0).max() > 1e-6  # and it does vary


def test_heading_offset_statistics_over_seeds_and_the_transition():
    mean_deg, sigma_deg, count = 7.0, 3.0, 2000
    spec = dict(heading_offset_mean_deg=mean_deg, heading_offset_sigma_deg=sigma_deg, transition_m=0.3)
    rest, far = np.zeros(3), np.array([5.0, 0.0, 0.0])  # w(far) = 1 − exp(−25/0.18) = 1 to round-off
    psi = np.empty(count)
    for seed in range(count):
        b = field_along_path(MagneticEnvironmentSpec(**spec, seed=seed), FIELD, np.stack([rest, far]))
        assert np.all(b[0] == FIELD)  # the rest position reads the reference field exactly
        assert b[1, 2] == pytest.approx(FIELD[2], rel=1e-15)  # a turn about the vertical
        # ψ: counter-clockwise from above (ENU), the angle from the reference's horizontal part to b's.
        psi[seed] = np.degrees(np.arctan2(b[1, 1], b[1, 0]) - np.arctan2(FIELD[1], FIELD[0]))
    # ψ ~ N(mean, sigma²): sample mean within 5 standard errors, sample std within 5 of its own.
    assert abs(psi.mean() - mean_deg) < 5 * sigma_deg / np.sqrt(count)
    assert abs(psi.std(ddof=1) / sigma_deg - 1) < 5 / np.sqrt(2 * (count - 1))
    # The weight w(p) = 1 − exp(−r²/(2s²)): at r = s the turn is (1 − e^{−1/2}) ψ.
    at_s = field_along_path(MagneticEnvironmentSpec(**spec, seed=1), FIELD, np.array([[0, 0, 0], [0, 0.3, 0]]))
    turned = np.degrees(np.arctan2(at_s[1, 1], at_s[1, 0]) - np.arctan2(FIELD[1], FIELD[0]))
    assert turned == pytest.approx((1 - np.exp(-0.5)) * psi[1], rel=1e-12)


def test_norm_and_dip_overrides_keep_the_declination():
    def norm_dip_declination(b):
        return np.linalg.norm(b), np.degrees(np.arctan2(-b[2], np.hypot(b[0], b[1]))), np.arctan2(b[0], b[1])

    _, dip0, dec0 = norm_dip_declination(FIELD)
    both = reference_field(MagneticEnvironmentSpec(norm_uT=48.0, dip_deg=-30.0), FIELD)
    norm, dip, dec = norm_dip_declination(both)
    assert norm == pytest.approx(48e-6, rel=4e-16) and dip == pytest.approx(-30.0, rel=4e-15)
    assert dec == pytest.approx(dec0, rel=4e-16)
    norm, dip, dec = norm_dip_declination(reference_field(MagneticEnvironmentSpec(norm_uT=60.0), FIELD))
    assert norm == pytest.approx(60e-6, rel=4e-16) and dip == pytest.approx(dip0, rel=4e-15)
    assert dec == pytest.approx(dec0, rel=4e-16)
    assert reference_field(MagneticEnvironmentSpec(), FIELD).tobytes() == FIELD.tobytes()
    # The site's environment holds the overridden field; a site without the table is unchanged.
    site = Site(magnetic_environment={"norm_uT": 48.0, "dip_deg": -30.0})
    assert site.environment().magnetic_field_w.tobytes() == both.tobytes()
    assert (
        Site().environment().magnetic_field_w.tobytes() == (np.asarray(Site().magnetic_field_enu_uT) * 1e-6).tobytes()
    )
    # Along a path, far from its rest position and with no variation, the overridden field it is.
    b = field_along_path(MagneticEnvironmentSpec(norm_uT=48.0, dip_deg=-30.0), FIELD, np.zeros((3, 3)))
    assert np.all(b == both)


def test_same_seed_same_bytes():
    path = np.random.default_rng(1).standard_normal((5000, 3))
    spec = MagneticEnvironmentSpec(spatial_sigma_uT=1.0, heading_offset_sigma_deg=5.0, seed=11)
    a, b = field_along_path(spec, FIELD, path), field_along_path(spec, FIELD, path)
    assert a.tobytes() == b.tobytes()
    c = field_along_path(spec.model_copy(update={"seed": 12}), FIELD, path)
    assert not np.allclose(a, c)


def test_with_magnetic_environment_turns_the_field_into_body_axes():
    t = np.linspace(0.0, 4.0, 801)
    q = quat_from_euler_zyx(np.stack([0.2 * np.sin(t), 0.1 * np.cos(2 * t), 0.8 * t], -1))
    pos = np.stack([np.cos(t), np.sin(t), 0.05 * t], -1)
    zero = np.zeros_like(pos)
    env = Environment.inertial(9.81, magnetic_field_w=FIELD)
    traj = trajectory_from_world_motion(t, q, zero, zero, pos, zero, zero, env)
    spec = MagneticEnvironmentSpec(spatial_sigma_uT=3.0, heading_offset_mean_deg=20.0, norm_uT=50.0, seed=2)
    new = with_magnetic_environment(traj, spec)
    expected = quat_rotate(quat_conjugate(q), field_along_path(spec, FIELD, pos))
    assert new.mag_b.tobytes() == expected.tobytes()
    assert new.environment.magnetic_field_w.tobytes() == reference_field(spec, FIELD).tobytes()
    assert new.omega_b is traj.omega_b and new.q_wb is traj.q_wb
    # A default table (no variation, no turn) leaves the field uniform: the original mag_b, to round-off.
    plain = with_magnetic_environment(traj, MagneticEnvironmentSpec(), FIELD)
    np.testing.assert_allclose(plain.mag_b, traj.mag_b, rtol=0, atol=1e-15 * np.linalg.norm(FIELD))


@pytest.mark.parametrize(
    "table, key",
    [
        ({"spatial_sigma_nT": 1.0}, "site.magnetic_environment.spatial_sigma_nT"),
        ({"correlation_length_m": 0.0}, "site.magnetic_environment.correlation_length_m"),
        ({"spatial_sigma_uT": -1.0}, "site.magnetic_environment.spatial_sigma_uT"),
        ({"dip_deg": 91.0}, "site.magnetic_environment.dip_deg"),
        ({"seed": "one"}, "site.magnetic_environment.seed"),
    ],
)
def test_bad_keys_are_refused_by_name(table, key):
    with pytest.raises(ConfigError) as err:
        validate(Site, {"magnetic_environment": table}, prefix="site")
    assert key in str(err.value)
    spec = validate(Site, {"magnetic_environment": {"spatial_sigma_uT": 1.0}}).magnetic_environment
    with pytest.raises(Exception):
        spec.seed = 3  # frozen


def test_dipole_field_closed_form_and_superposition():
    from gyroemu.dynamics.dipole import MU0_OVER_4PI, dipole_field

    m = np.array([0.0, 0.0, 0.5])
    r = 0.2
    on_axis = dipole_field([[0.0, 0.0, r]], [0.0, 0.0, 0.0], m)[0]
    equator = dipole_field([[r, 0.0, 0.0]], [0.0, 0.0, 0.0], m)[0]
    eps = np.finfo(float).eps
    # On the axis B = μ₀/4π · 2m/r³, on the equator −μ₀/4π · m/r³ (Jackson 5.56).
    assert np.allclose(on_axis, [0, 0, MU0_OVER_4PI * 2 * 0.5 / r**3], rtol=0, atol=8 * eps * 1e-5)
    assert np.allclose(equator, [0, 0, -MU0_OVER_4PI * 0.5 / r**3], rtol=0, atol=8 * eps * 1e-5)
    spec = MagneticEnvironmentSpec(dipoles=[{"position_m": [0, 0, 0], "moment_A_m2": list(m)}])
    b0 = np.array([1e-6, 2e-5, -4e-5])
    got = field_along_path(spec, b0, [[0.0, 0.0, r], [r, 0.0, 0.0]])
    assert np.allclose(got, b0 + np.array([on_axis, equator]), rtol=0, atol=8 * eps * 1e-4)


def test_fitted_dipole_recovers_a_synthetic_magnet():
    from gyroemu.dynamics.dipole import dipole_field
    from gyroemu.pipelines.identification.dipole import fit_dipole

    rng = np.random.default_rng(4)
    pos = np.cumsum(rng.normal(0, 0.01, (4000, 3)), axis=0) * 0.5 + [0.0, 0.0, 1.0]
    p_d, m, b0 = np.array([0.45, -0.2, 1.1]), np.array([0.3, -0.5, 0.8]), np.array([0.0, 14e-6, -40e-6])
    sigma = 0.05e-6  # T of white noise per axis
    field = b0 + dipole_field(pos, p_d, m) + sigma * rng.standard_normal(pos.shape)
    fit = fit_dipole(pos, field)
    # Each parameter within 5 of its standard uncertainties (s² (JᵀJ)⁻¹ from the same residuals).
    assert np.all(np.abs(fit.position_m - p_d) <= 5 * fit.position_sigma_m + 1e-9)
    assert np.all(np.abs(fit.moment_A_m2 - m) <= 5 * fit.moment_sigma_A_m2 + 1e-12)
    assert np.all(np.abs(fit.background_T - b0) <= 5 * fit.background_sigma_T + 1e-15)
    assert fit.rms_after == pytest.approx(sigma * np.sqrt(3), rel=0.1)  # what is left is the noise
