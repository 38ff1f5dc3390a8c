"""Earth constants and the world-motion to IMU-truth conversion."""

import numpy as np
import pytest

from gyroemu.dynamics import EARTH_RATE, Environment, Site, earth_rate_enu, normal_gravity, trajectory_from_world_motion
from gyroemu.dynamics.rotation import quat_from_euler_zyx, quat_rotate


def test_normal_gravity_matches_wgs84_published_values():
    # NIMA TR8350.2 table 3.4: equator 9.7803253359, pole 9.8321849378 m/s².
    assert normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert normal_gravity(np.pi / 2) == pytest.approx(9.8321849378, abs=1e-10)
    # Free-air gradient near the surface at 45°: about −3.086e-6 s⁻² (TR8350.2 eq. 4-3).
    gradient = (normal_gravity(np.pi / 4, 100.0) - normal_gravity(np.pi / 4, 0.0)) / 100.0
    assert gradient == pytest.approx(-3.086e-6, rel=1e-3)


def test_earth_rate_in_enu():
    lat = np.radians(52.5)
    w = earth_rate_enu(lat)
    assert np.linalg.norm(w) == pytest.approx(EARTH_RATE, rel=1e-15)
    assert w[0] == 0 and np.arctan2(w[2], w[1]) == pytest.approx(lat, rel=1e-15)


def test_site_environment_and_bad_latitude():
    env = Site(latitude_deg=0.0, height_m=0.0).environment()
    np.testing.assert_allclose(env.gravity_w, [0, 0, -9.7803253359])
    np.testing.assert_allclose(env.earth_rate_w, [0, EARTH_RATE, 0], atol=1e-20)
    assert np.all(Site(earth_rotation=False).environment().earth_rate_w == 0)
    with pytest.raises(ValueError, match="latitude_deg"):
        Site(latitude_deg=91.0)
    for not_a_boolean in ("no", 0):  # a string or a number was taken as a boolean ("no" as true)
        with pytest.raises(ValueError, match="earth_rotation"):
            Site(earth_rotation=not_a_boolean)


def test_moving_body_feels_coriolis_and_rotating_world():
    # A body yawed 90° (nose north), moving north at 20 m/s with a yaw rate of 0.1 rad/s, at 45°N.
    env = Site(latitude_deg=45.0).environment()
    q = quat_from_euler_zyx([[0.0, 0.0, np.pi / 2]])
    omega_wb = np.array([[0.0, 0.0, 0.1]])
    vel = np.array([[0.0, 20.0, 0.0]])
    traj = trajectory_from_world_motion(
        [0.0], q, omega_wb, np.zeros((1, 3)), np.zeros((1, 3)), vel, np.zeros((1, 3)), env
    )
    earth_b = quat_rotate(q[0].copy() * [1, -1, -1, -1], env.earth_rate_w)
    np.testing.assert_allclose(traj.omega_b[0], omega_wb[0] + earth_b, rtol=1e-15)
    # α_b = −ω_wb × (R_bw Ω): the Earth rate seen from a turning body rotates.
    np.testing.assert_allclose(traj.alpha_b[0], -np.cross(omega_wb[0], earth_b), rtol=1e-15)
    coriolis_w = 2 * np.cross(env.earth_rate_w, vel[0])  # 2 Ω × v, eastward-pointing negative for northward v
    expected_w = coriolis_w - env.gravity_w
    np.testing.assert_allclose(quat_rotate(q[0], traj.specific_force_b[0]), expected_w, rtol=1e-14)


def test_inertial_environment():
    env = Environment.inertial(9.81)
    np.testing.assert_array_equal(env.gravity_w, [0, 0, -9.81])
    assert not env.earth_rate_w.any()


@pytest.mark.parametrize("height_m", [0.0, 1000.0])
def test_normal_gravity_is_somiglianas_closed_form_at_30_degrees(height_m):
    """TR8350.2 eqs. 4-1 and 4-3 with the constants computed here from the defining parameters (a, 1/f,
    GM, ω) and the published γe and k; at 30° sin²φ = 1/4 differs from sin φ = 1/2. e² and k are
    published to 14 decimals, so one unit in their last place moves γ by at most sin²φ (1 + 1/2)·1e-14
    relative; the rest is round-off."""
    a, f, gm, omega = 6378137.0, 1 / 298.257223563, 3986004.418e8, 7292115e-11
    b, e2 = a * (1 - f), f * (2 - f)
    m = omega**2 * a**2 * b / gm
    gamma_e, k = 9.7803253359, 0.00193185265241
    s2 = 0.25
    gamma0 = gamma_e * (1 + k * s2) / np.sqrt(1 - e2 * s2)
    expected = gamma0 * (1 - 2 / a * (1 + f + m - 2 * f * s2) * height_m + 3 * height_m**2 / a**2)
    tol = s2 * 1.5e-14 + 8 * np.finfo(float).eps
    assert normal_gravity(np.radians(30.0), height_m) == pytest.approx(expected, rel=tol, abs=0)
    assert normal_gravity(np.radians(-30.0), height_m) == pytest.approx(expected, rel=tol, abs=0)


def test_default_site_field_is_the_documented_one_in_tesla():
    """Site's default field (1.63, 18.6, −46.4) µT ENU (about 50 µT, inclination about 68°), in T."""
    field = Site().environment().magnetic_field_w
    np.testing.assert_allclose(field, [1.63e-6, 18.6e-6, -46.4e-6], rtol=2 * np.finfo(float).eps, atol=0)
    assert np.linalg.norm(field) == pytest.approx(50e-6, rel=0.01)
    assert np.degrees(np.arctan2(-field[2], np.hypot(field[0], field[1]))) == pytest.approx(68, abs=0.5)
