"""The sensors' latencies taken out of every filter (pipelines/estimation/latency.py)."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir, read_toml
from gyroemu.dynamics.earth import EARTH_RATE
from gyroemu.dynamics.rotation import (
    quat_angle,
    quat_conjugate,
    quat_exp,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
)
from gyroemu.pipelines.estimation import (
    Estimate,
    FilterSetup,
    LatencyCompensated,
    advance_attitude,
    attitude_errors,
    rmse_deg,
    setup_for,
    turn_back,
)
from gyroemu.pipelines.estimation.registry import make_filter
from gyroemu.pipelines.formats.mcap_log import Recording, truth_series, write_mcap
from gyroemu.pipelines.jobs.bench import BenchError, LogCase, run_bench
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
    inner.process_increments = inner.process
    assert not hasattr(wrapped, "process_increments")  # it would go untimed
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


def _oscillation(L: float):
    """The 2 Hz, 5° oscillation (10 s) measured by the ideal IMU without latency and lagging by ``L``:
    the scenario and ``[(key, device, samples, truth)]``, keys ``none`` and ``late``."""
    scenario = load_scenario("oscillation")
    traj = scenario.simulate(duration=10.0)
    measured = []
    for key, device in (("none", _ideal(0.0)), ("late", _ideal(L))):
        samples = device.measure(traj)
        measured.append((key, device, samples, truth_series(traj, samples)))
    return scenario, measured


def _lag_bounds(truth, samples, L: float) -> tuple[float, float]:
    """For a 6D run lagging by L: the RMS inclination turn over L, ‖(R ω)_horizontal‖ L, and the RMS of
    what the rule leaves, ω̇ (L + T) L / 2 (T the device's sample period), both degrees."""
    omega_w = quat_rotate(truth.q_wb, truth.omega_b)
    turn = np.degrees(np.sqrt(np.mean(np.sum(omega_w[:, :2] ** 2, axis=1)))) * L
    spin_up = np.gradient(truth.omega_b, truth.t, axis=0)
    T = float(np.median(np.diff(samples.t)))
    rule = np.degrees(np.sqrt(np.mean(np.sum(spin_up**2, axis=1)))) * (L + T) * L / 2
    return float(turn), float(rule)


@pytest.mark.parametrize("name", ["mekf", "madgwick"])
def test_a_lagging_device_estimated_at_its_stamps(name):
    """An ideal IMU lagging by L = 5 ms on a 2 Hz, 5° oscillation, 6D. Uncompensated, the inclination
    error is the turn over L, ‖(R ω)_horizontal‖ L, to within the filter's own error on a device without
    latency e₀ (triangle inequality on the RMS). Compensated (the setup from the device), it is e₀ plus
    what the rule leaves, ω̇ (L + T) L / 2 (the module's notes)."""
    L = 0.005
    scenario, measured = _oscillation(L)
    runs = {}
    for key, device, samples, truth in measured:
        setup = setup_for(device, scenario, use_mag=False)
        assert (setup.gyro_latency_s, setup.mag_latency_s) == device.latencies[::2]
        for comp in (True, False):
            plain = replace(setup, gyro_latency_s=0.0, mag_latency_s=0.0)
            filt = make_filter(name, setup if comp else plain)
            assert isinstance(filt, LatencyCompensated) == (comp and key == "late")
            est = filt.process(samples.t - samples.t[0], samples.gyro, samples.accel)
            runs[key, comp] = rmse_deg(attitude_errors(est.q_wb, truth.q_wb).inclination)
    turn, rule = _lag_bounds(truth, samples, L)
    e0 = runs["none", True]
    assert runs["none", False] == e0  # no latency, no wrapper: the same filter
    assert abs(runs["late", False] - turn) <= e0
    assert turn > 5 * e0  # the latency's error is what the check sees
    assert runs["late", True] <= e0 + rule


def test_turn_back_puts_a_vector_in_the_gyros_axes():
    """A body turning at a constant ω (body axes) from a random attitude, a fixed world vector m_w read
    at t − L_s: turned back by Δ = L_s − L_g, it is m_w in the axes of the attitude at t − L_g, to
    round-off; turned the other way it is not."""
    rng = np.random.default_rng(4)
    q0 = quat_from_rotvec(rng.normal(size=3))
    omega = np.array([-1.2, 0.4, 2.5])
    t = np.linspace(0.0, 3.0, 40)
    L_g, L_s = 0.002, 0.015
    m_w = np.array([0.2, 0.35, -0.45])

    def attitude(at):
        return quat_multiply(q0, quat_exp(np.outer(at, omega) / 2))

    read = quat_rotate(quat_conjugate(attitude(t - L_s)), np.broadcast_to(m_w, (40, 3)))
    turned = quat_rotate(attitude(t - L_g), turn_back(read, np.broadcast_to(omega, (40, 3)), L_s - L_g))
    assert np.abs(turned - m_w).max() < 64 * EPS * np.linalg.norm(m_w) * (1 + np.linalg.norm(omega) * t.max())
    wrong = quat_rotate(attitude(t - L_g), turn_back(read, np.broadcast_to(omega, (40, 3)), L_g - L_s))
    assert np.abs(wrong - m_w).max() > 1e-3


def test_a_late_magnetometer_read_at_the_gyros_instant():
    """An ideal IMU on the rate table (10 °/s about the vertical), its magnetometer 50 ms late, 9D MEKF.
    The field it reads lags the body by ω Δ, and with a perfect gyro nothing contradicts it: the heading
    settles ω Δ behind, to within the filter's own error e₀ (the same IMU without latency). Told the
    latency, the error is e₀ plus what the rule leaves: it turns by the gyro's rate, which holds Earth's
    rate beside the table's, Ω_ie Δ, leaked into the heading up to (1 + tan dip) times."""
    scenario = load_scenario("rate_table_constant")
    traj = scenario.simulate(duration=60.0)
    spec = copy.deepcopy(read_toml(config_dir() / "devices" / "ideal.toml"))
    errors = {}
    for L_m in (0.0, 0.05):
        spec["magnetometer"]["latency_s"] = L_m
        device = device_from_dict(spec, name="imu0")
        samples = device.measure(traj)
        truth = truth_series(traj, samples)
        setup = setup_for(device, scenario)
        settled = samples.t - samples.t[0] > 20.0
        for comp in (True, False):
            filt = make_filter("mekf", setup if comp else replace(setup, mag_latency_s=0.0))
            est = filt.process(samples.t - samples.t[0], samples.gyro, samples.accel, samples.mag)
            errors[L_m, comp] = rmse_deg(attitude_errors(est.q_wb, truth.q_wb).heading[settled])
    e0, delta = errors[0.0, True], 0.05
    lag = 10.0 * delta  # ω Δ, degrees
    east, north, up = scenario.spec.site.magnetic_field_enu_uT
    tan_dip = abs(up) / np.hypot(east, north)
    earth = np.degrees(EARTH_RATE) * delta * (1 + tan_dip)
    assert abs(errors[0.05, False] - lag) <= e0 + earth
    assert errors[0.05, True] <= e0 + earth
    assert lag > 100 * (e0 + earth)  # the latency's error is what the check sees


def test_bench_times_a_log_by_its_device_or_as_told(tmp_path):
    """``gyroemu bench`` on logs of an ideal IMU on the 2 Hz oscillation, with and without a 5 ms
    latency: the lagging log's own device times every filter (the bound of
    ``test_a_lagging_device_estimated_at_its_stamps``, e₀ the log without latency), and told a latency
    of 0 (``LogCase.latency_s``) the error is the turn over L again."""
    L = 0.005
    scenario, measured = _oscillation(L)
    logs = {}
    for key, device, samples, truth in measured:
        logs[key] = write_mcap(
            tmp_path / f"{key}.mcap", Recording(samples, truth=truth, device=device), scenario=scenario
        )
    cases = [LogCase(logs["none"]), LogCase(logs["late"]), LogCase(logs["late"], latency_s={"gyro": 0.0})]
    report = run_bench(cases, filters=["mekf"], progress=False)
    e0, timed, untimed = (c.filters[0].runs[0].inclination_deg for c in report.cases)
    turn, rule = _lag_bounds(truth, samples, L)
    assert timed <= e0 + rule
    assert abs(untimed - turn) <= e0 and turn > 5 * e0
    assert any("latencies: gyro 5 ms" in note for note in report.cases[1].notes)
    assert not any("latencies" in note for note in report.cases[2].notes)
    with pytest.raises(BenchError, match="latency: no sensor accel"):
        run_bench([LogCase(logs["late"], latency_s={"accel": 0.001})], filters=["mekf"], progress=False)
