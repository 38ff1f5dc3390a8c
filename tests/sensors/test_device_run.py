"""A run made a block at a time: the same bytes however it is read, in memory that does not grow."""

from __future__ import annotations

import itertools
import tracemalloc

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario, scenarios
from gyroemu.dynamics.truth_source import WINDOW_MARGIN, SampledTruth, ScenarioTruth, truth_source
from gyroemu.sensors import device_run, list_devices, load_device
from gyroemu.sensors.device_run import concatenate_samples

FIELDS = ("t", "t_true", "gyro", "accel", "mag", "temperature_degC", "delta_angle", "delta_velocity")
PRESETS = [d.name for d in list_devices()]


def assert_same_samples(a, b):
    assert len(a) == len(b)
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.raw.keys() == b.raw.keys()
    for kind in a.raw:
        assert a.raw[kind].keys() == b.raw[kind].keys()
        for name in a.raw[kind]:
            np.testing.assert_array_equal(a.raw[kind][name], b.raw[kind][name], err_msg=f"raw {kind} {name}")


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of at most 97 samples (and 4099 inner steps), truth segments of 257 samples: a short run
    has many of each."""
    monkeypatch.setattr(device_run, "BLOCK_MAX_SAMPLES", 97)
    monkeypatch.setattr(device_run, "BLOCK_INNER_SAMPLES", 4099)
    monkeypatch.setattr(scenarios, "SEGMENT_SAMPLES", 257)


@pytest.mark.parametrize("preset", PRESETS)
def test_a_run_read_window_by_window_is_the_run_made_whole(small_blocks, preset):
    # The single pass: the whole trajectory simulated, then measured. The chunked run: the truth
    # evaluated window by window from the scenario, the samples yielded block by block. Same bytes,
    # for every preset (their gyro kinds: mechanisms, error terms, clock, latency, magnetometer).
    device = load_device(preset, seed=7)
    scenario = load_scenario("smooth_manoeuvre")
    duration = 0.6 if device.spec.rate_hz > 500 else 2.0
    whole = device.measure(scenario.simulate(duration=duration))
    source = truth_source(scenario, duration)
    assert isinstance(source, ScenarioTruth)
    run = device.run(source)
    blocks = list(run.samples())
    assert len(blocks) >= 3, "the run must span several blocks"
    assert max(len(b) for b in blocks) <= 97
    assert_same_samples(concatenate_samples(blocks), whole)


def test_a_pointwise_kind_in_segments_is_its_closed_form_to_round_off(monkeypatch):
    # What segments rely on: a pointwise kind's truth at t depends on t alone. Evaluated in segments
    # of 1000 samples, every built-in scenario of a pointwise kind gives its whole-run samples to
    # round-off: a few ulp of each quantity's scale (the phasor tables of TimeGrid add a few ulp to the
    # rounding of ω t + φ; angles up to ω t ~ 10³ rad here), bounded as 64 ε × scale × (1 + max ω t).
    checked = set()
    from gyroemu.dynamics import list_scenarios

    names = ("q_wb", "omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")
    for scenario in list_scenarios():
        if not scenario.spec.pointwise:
            continue
        checked.add(scenario.kind)
        duration = min(scenario.duration_s, 30.0)
        monkeypatch.setattr(scenarios, "SEGMENT_SAMPLES", 1 << 30)
        whole = scenario.simulate(duration=duration)
        monkeypatch.setattr(scenarios, "SEGMENT_SAMPLES", 1000)
        parts = scenario.simulate(duration=duration)
        np.testing.assert_array_equal(parts.t, whole.t)
        phase = 1.0 + 2 * np.pi * 50.0 * duration  # ω t of the fastest motion here (< 50 Hz)
        for name in names:
            a, b = getattr(parts, name), getattr(whole, name)
            scale = np.abs(b).max() + np.finfo(float).tiny
            assert np.abs(a - b).max() <= 64 * np.finfo(float).eps * scale * phase, (scenario.name, name)
    kinds = {"static", "rate-table", "oscillation", "coning", "sculling", "random-manoeuvre", "car", "recorded"}
    assert checked == kinds


def test_an_endless_run_is_the_bounded_run_continued(small_blocks):
    # Without an end, a run yields the bounded run's samples, up to where the bounded run's last truth
    # segment begins (it takes the remainder of the run, so its samples are evaluated on another grid).
    device = load_device("tactical_mems", seed=3)
    scenario = load_scenario("smooth_manoeuvre")
    last = int(6.0 * scenario.rate_hz)
    bounded = concatenate_samples(list(device.run(ScenarioTruth(scenario, 6.0)).samples()))
    endless = device.run(ScenarioTruth(scenario, None))
    assert endless.count is None
    final_segment = scenarios.segment_bounds(scenarios.segment_count(last) - 1, last)[0] / scenario.rate_hz
    reach = WINDOW_MARGIN / scenario.rate_hz + 2 / device.spec.rate_hz  # a window's reach before its block
    n = int(np.searchsorted(bounded.t_true, final_segment - reach))
    assert n > len(bounded) / 2
    head = concatenate_samples(list(itertools.islice(endless.samples(), n // 97 + 1)))
    for name in ("t", "gyro", "accel", "mag"):
        np.testing.assert_array_equal(getattr(head, name)[:n], getattr(bounded, name)[:n], err_msg=name)


def test_memory_does_not_grow_with_the_run(small_blocks):
    # Peak traced memory over 40 blocks of an endless run is that over 10 blocks: nothing accumulates
    # (a block's arrays are freed when the next is made; numpy reports its buffers to tracemalloc).
    device = load_device("navigation_rlg", seed=0)
    scenario = load_scenario("bench_static")

    def peak(blocks: int) -> int:
        run = device.run(ScenarioTruth(scenario, None))
        tracemalloc.start()
        for block in itertools.islice(run, blocks):
            del block
        _, high = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return high

    short, long = peak(10), peak(40)
    # A block of 97 samples holds a few hundred kB; four times the blocks may not add one block more.
    assert long < short + 0.25 * short


def test_a_trajectory_in_memory_is_read_in_windows():
    scenario = load_scenario("heavy_top")
    traj = scenario.simulate(duration=1.0)
    source = truth_source(scenario, 1.0)
    assert isinstance(source, SampledTruth)  # an integrated kind: simulated whole
    window = source.window(0.3, 0.4)
    step = 1 / scenario.rate_hz
    assert window.t[0] <= 0.3 - (WINDOW_MARGIN - 1) * step and window.t[-1] >= 0.4 + (WINDOW_MARGIN - 1) * step
    assert len(window) <= 0.1 / step + 2 * WINDOW_MARGIN + 3
    edge = source.window(0.0, 0.01)
    assert edge.t[0] == traj.t[0]


def test_the_rate_ramp_counts_from_power_up():
    """A rate ramp R reads R (τ_k − t₀), t₀ the power-up (the trajectory's first instant): a run of the
    same device on the same motion from t = 0 and from t = 10 s reads R T at its first sample either way
    (it read R τ_k, the absolute time: 10 s later, R · 10 s more). Tolerance: the ideal gyro's interval
    mean of a constant rate, exact but for round-off of its 7·10⁻⁵ rad/s."""
    from gyroemu.sensors.presets import device_from_dict

    ramp = 3600.0  # °/h/h
    gyro = {"mechanism": {"kind": "ideal"}, "errors": {"rate_ramp_deg_per_h_per_h": ramp}}
    device = {"description": "ramp", "rate_hz": 100, "gyro": gyro}
    truth = load_scenario("bench_static").simulate(duration=20.0, rate_hz=100.0)
    r_t = np.radians(ramp) / 3600**2 * 0.01  # R T, rad/s
    for start in (0, 1000):  # power-up at t = 0 s and at t = 10 s
        gyro = device_from_dict(device).measure(truth[start:]).gyro
        assert abs(gyro[0, 0] - truth.omega_b[start, 0] - r_t) <= 1e-12


def test_the_g_sensitivity_reads_the_force_at_the_gyros_latency():
    """A gyro's g-sensitivity G reads the mean specific force over its own interval, at its latency
    (τ − L_g), not the accelerometer's: with the accelerometer 0.1 s late and the gyro on time, the term
    G f the gyro adds equals G times what an ideal accelerometer on time reads, to round-off (it read the
    force 0.1 s late: 8.6 m/s² rms off on this 1 Hz, 19.7 m/s² oscillation)."""
    from gyroemu.dynamics.scenarios import scenario_from_dict
    from gyroemu.sensors.presets import device_from_dict

    motion = {"kind": "oscillation", "duration_s": 4, "rate_hz": 200, "linear": {"amplitude_m": [0.5, 0, 0]}}
    motion["angular"] = {"amplitude_deg": 0.0, "frequency_hz": 1.0, "axis_b": [0, 0, 1]}
    motion["linear"]["frequency_hz"] = 1.0
    truth = scenario_from_dict(motion).simulate()
    g = 1000.0  # °/s/g about x from the force along x
    sensitive = {"description": "g", "rate_hz": 200, "gyro": {"mechanism": {"kind": "ideal"}}}
    sensitive["accelerometer"] = {"latency_s": 0.1}
    sensitive["gyro"]["errors"] = {"g_sensitivity_deg_per_h_per_g": [[g * 3600, 0, 0], [0, 0, 0], [0, 0, 0]]}
    plain = {"description": "plain", "rate_hz": 200, "gyro": {"mechanism": {"kind": "ideal"}}}
    a, b = device_from_dict(sensitive).measure(truth), device_from_dict(plain).measure(truth)
    same = np.isin(b.t_true, a.t_true)  # the late accelerometer's device starts 0.1 s later
    assert np.array_equal(b.t_true[same], a.t_true)
    read = (a.gyro[:, 0] - b.gyro[same, 0]) / (np.radians(g) / 9.80665)  # the force the term saw, m/s²
    force = b.accel[same, 0]  # what an ideal accelerometer on time reads over the same intervals
    assert np.abs(read - force).max() <= 1e3 * np.finfo(float).eps * np.abs(force).max()
