"""The gyro's latency taken out of every filter's attitudes (pipelines/estimation/latency.py)."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir, read_toml
from gyroemu.dynamics.rotation import quat_angle, quat_exp, quat_from_rotvec, quat_multiply, quat_rotate
from gyroemu.pipelines.estimation import (
    Estimate,
    FilterSetup,
    LatencyCompensated,
    advance_attitude,
    attitude_errors,
    rmse_deg,
    setup_for,
)
from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.formats.mcap_log import truth_series
from gyroemu.sensors import device_from_dict

EPS = np.finfo(float).eps


def test_advance_attitude_is_the_turn_over_the_latency():
    """A body turning at a constant rate ω (body axes) from a random attitude: q(t) = q₀ ⊗ exp(ω t). The
    attitude L earlier, turned on by the sample's rate less the bias, is q(t) to round-off (a turn on
    the world's side of q would not be); a non-finite rate keeps its attitude."""
    rng = np.random.default_rng(1)
    q0 = quat_from_rotvec(rng.normal(size=3))
    omega = np.array([0.7, -1.9, 3.1])  # rad/s
    bias = rng.normal(scale=0.01, size=(50, 3))
    t = np.linspace(0.0, 2.0, 50)
    L = 0.004
    truth = quat_multiply(q0, quat_exp(np.outer(t, omega) / 2))  # exp of the half angle: q = exp(ω t / 2)
    late = quat_multiply(q0, quat_exp(np.outer(t - L, omega) / 2))
    gyro = omega + bias
    gyro[7] = np.nan
    got = advance_attitude(late, gyro, bias, L)
    err = quat_angle(got, truth)
    keep = np.arange(50) != 7
    assert err[keep].max() < 64 * EPS * (1 + np.linalg.norm(omega) * t.max())
    assert np.array_equal(got[7], late[7])
    wrong_side = quat_multiply(quat_from_rotvec(np.outer(np.ones(50), omega) * L), late)
    assert quat_angle(wrong_side, truth)[keep].max() > 1e-4  # the order matters: the test can tell


class _Fixed:
    """A filter returning fixed attitudes, bias and covariance, for the wrapper's bookkeeping."""

    name = "fixed"
    offline = True

    def __init__(self, setup: FilterSetup):
        self.extra = "kept"

    def process(self, t, gyro, accel, mag=None):
        n = len(t)
        rng = np.random.default_rng(0)
        return Estimate(
            q_wb=quat_from_rotvec(rng.normal(size=(n, 3))),
            gyro_bias=rng.normal(scale=0.01, size=(n, 3)),
            q_wb_covariance=np.tile(np.eye(3) * 1e-4, (n, 1, 1)),
        )


def test_the_wrapper_turns_the_attitude_and_keeps_the_rest():
    inner = _Fixed(FilterSetup(rate_hz=100.0))
    wrapped = LatencyCompensated(inner, 0.003)
    assert (wrapped.name, wrapped.offline, wrapped.extra) == ("fixed", True, "kept")
    t = np.arange(20) / 100.0
    gyro = np.random.default_rng(2).normal(size=(20, 3))
    plain = inner.process(t, gyro, np.zeros((20, 3)))
    got = wrapped.process(t, gyro, np.zeros((20, 3)))
    assert np.array_equal(got.q_wb, advance_attitude(plain.q_wb, gyro, plain.gyro_bias, 0.003))
    assert np.array_equal(got.gyro_bias, plain.gyro_bias)
    assert np.array_equal(got.q_wb_covariance, plain.q_wb_covariance)


def _ideal(latency_s: float):
    """The ideal IMU whose gyro and accelerometer lag the motion by ``latency_s``."""
    spec = copy.deepcopy(read_toml(config_dir() / "devices" / "ideal.toml"))
    spec["gyro"]["latency_s"] = latency_s
    spec.setdefault("accelerometer", {})["latency_s"] = latency_s
    return device_from_dict(spec, name="imu0")


@pytest.mark.parametrize("name", ["mekf", "madgwick"])
def test_a_lagging_device_estimated_at_its_stamps(name):
    """An ideal IMU lagging by L = 5 ms on a 2 Hz, 5° oscillation, 6D. Uncompensated, the inclination
    error is the turn over L, ‖(R ω)_horizontal‖ L, to within the filter's own error on a device without
    latency e₀ (triangle inequality on the RMS). Compensated (the setup from the device), it is e₀ plus
    what the rule leaves, ω̇ (L + T) L / 2 (the module's notes)."""
    scenario = load_scenario("oscillation")
    traj = scenario.simulate(duration=10.0)
    L = 0.005
    runs = {}
    for key, device in (("none", _ideal(0.0)), ("late", _ideal(L))):
        samples = device.measure(traj)
        truth = truth_series(traj, samples)
        setup = setup_for(device, scenario, use_mag=False)
        assert setup.gyro_latency_s == device.latencies[0]
        for comp in (True, False):
            filt = make_filter(name, setup if comp else replace(setup, gyro_latency_s=0.0))
            assert isinstance(filt, LatencyCompensated) == (comp and key == "late")
            est = filt.process(samples.t - samples.t[0], samples.gyro, samples.accel)
            runs[key, comp] = rmse_deg(attitude_errors(est.q_wb, truth.q_wb).inclination)
    omega_w = quat_rotate(truth.q_wb, truth.omega_b)
    turn = np.degrees(np.sqrt(np.mean(np.sum(omega_w[:, :2] ** 2, axis=1)))) * L
    spin_up = np.gradient(truth.omega_b, truth.t, axis=0)
    T = float(np.median(np.diff(samples.t)))  # the device's sample period
    rule = np.degrees(np.sqrt(np.mean(np.sum(spin_up**2, axis=1)))) * (L + T) * L / 2
    e0 = runs["none", True]
    assert runs["none", False] == e0  # no latency, no wrapper: the same filter
    assert abs(runs["late", False] - turn) <= e0
    assert turn > 5 * e0  # the latency's error is what the check sees
    assert runs["late", True] <= e0 + rule
