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
