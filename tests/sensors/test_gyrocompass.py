"""Gyrocompassing: a navigation FOG at rest finds north as well as its noise allows; a MEMS gyro cannot."""

import numpy as np

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.rotation import quat_angle
from gyroemu.sensors import load_device
from gyroemu.sensors.gyrocompass import gyrocompass, heading_uncertainty


def expected_sigma(device, latitude_rad, duration_s):
    e, a = device.gyro_errors, device.spec.accelerometer.errors.to_si()
    return heading_uncertainty(
        latitude_rad,
        duration_s,
        bias=np.hypot(e.bias[0], e.turn_on_bias[0]),
        noise_density=device.gyro_noise_density[0],
        bias_instability=e.bias_instability[0],
        random_walk=e.random_walk[0],
        accel_bias=np.hypot(a.bias[0], a.turn_on_bias[0]),
    )


def test_exact_rates_give_exact_north():
    traj = load_scenario("bench_static").simulate(duration=1.0)
    found = gyrocompass(traj.omega_b, traj.specific_force_b)
    assert quat_angle(found.q_ws, traj.q_wb[0]) < 1e-9
    assert abs(found.latitude - np.radians(52.5)) < 1e-9


def test_navigation_fog_finds_north_within_its_noise():
    scenario = load_scenario("bench_static")
    duration = 600.0
    traj = scenario.simulate(duration=duration)
    lat = np.radians(scenario.spec.site.latitude_deg)
    truth_heading = gyrocompass(traj.omega_b, traj.specific_force_b).heading
    errors = []
    for seed in range(3):
        device = load_device("navigation_fog", seed=seed)
        s = device.measure(traj)
        found = gyrocompass(s.gyro, s.accel)
        errors.append(np.angle(np.exp(1j * (found.heading - truth_heading))))
    sigma = expected_sigma(load_device("navigation_fog"), lat, duration)
    assert sigma < np.radians(1.0)  # a navigation FOG can gyrocompass to a fraction of a degree
    assert np.all(np.abs(errors) < 4 * sigma), (np.degrees(errors), np.degrees(sigma))


def test_consumer_mems_cannot_gyrocompass():
    device = load_device("consumer_mems")
    sigma = expected_sigma(device, np.radians(52.5), 3600.0)
    assert sigma > np.radians(45.0)  # its bias alone is hundreds of times the horizontal Earth rate
