"""Each preset's noise, measured the way a lab would: a static run, its Allan deviation, the IEEE 952 fit.

A term can only be recovered where the record resolves it: the white noise N within seconds, the
bias-instability floor 0.664 B beyond τ = (N / 0.664 B)², the rate random walk K beyond
τ = 3 (0.664 B / K)² (or √3 N / K with no floor). A term is checked when it emerges before a tenth of
the record (so that ten or more independent clusters see it); the navigation FOG's rate random walk,
for one, would emerge after about 800 hours, and no static run here can tell it from zero.
Each record below is sized for its preset (output rate and hours), and each checked term is held
against the fit's own confidence interval (allantools' chi-squared interval at the τ
that determines it): where that 68 % interval is narrower than ±10/3 %, the fit must lie within 10 % of
the specification (a 3σ test); otherwise the specification must lie inside the interval widened to
about 4σ, which says the record cannot tell it apart from the specification.
"""

import dataclasses
import tomllib

import numpy as np
import pytest

from gyroemu.dynamics import load_scenario
from gyroemu.dynamics.config import config_dir
from gyroemu.pipelines.allan import allan_report
from gyroemu.sensors import device_from_dict

pytestmark = pytest.mark.slow  # long statistical or multi-process runs: `pytest -m slow`

RUNS = {  # preset: (output rate Hz, hours). The consumer part runs at its own rate: its 16-bit output
    # quantiser is only dithered by the noise (and so white, as its datasheet measures) at 1 kHz.
    "consumer_mems": (1000.0, 1.0),
    "tactical_mems": (20.0, 4.0),
    "navigation_fog": (5.0, 24.0),
    "classic_rate_gyro": (200.0, 1.0),
    "floated_rig": (10.0, 8.0),
    "free_gyro": (50.0, 0.5),
}


def static_run(name, rate_hz, hours, seed=2):
    data = tomllib.loads((config_dir() / "devices" / f"{name}.toml").read_text())
    data["rate_hz"] = rate_hz
    device = device_from_dict(data, name=name, seed=seed)
    traj = load_scenario("bench_static").simulate(duration=hours * 3600.0, rate_hz=min(rate_hz, 100.0))
    samples = device.measure(traj)
    spec = dataclasses.replace(device.gyro_errors, noise_density=device.gyro_noise_density)
    return device, samples, allan_report(samples.gyro, 1.0 / rate_hz, spec)


def check(coefficient, specified, label):
    value, low, high = coefficient.value, coefficient.low, coefficient.high
    half_width = 0.5 * (high - low) / specified
    if half_width < 0.1 / 3:
        assert abs(value / specified - 1) < 0.10, f"{label}: fitted {value:.4g}, specified {specified:.4g}"
    else:
        wide_low, wide_high = low - 3 * (value - low), high + 3 * (high - value)
        assert wide_low <= specified <= wide_high, f"{label}: {specified:.4g} outside [{wide_low:.4g}, {wide_high:.4g}]"
    return half_width < 0.1 / 3


def emergence(n, b, k):
    """τ (s) beyond which the bias-instability floor and the rate random walk rise above the terms
    before them: (N / 0.664 B)² and 3 (0.664 B / K)² (√3 N / K without a floor); inf when absent."""
    floor = 0.664 * b
    tau_b = (n / floor) ** 2 if b > 0 else np.inf
    tau_k = np.inf if k <= 0 else (3 * (floor / k) ** 2 if b > 0 else np.sqrt(3) * n / k)
    return tau_b, max(tau_k, tau_b if np.isfinite(tau_b) else 0.0)


@pytest.mark.parametrize("name", sorted(RUNS))
def test_preset_noise_terms_are_recovered_from_a_static_run(name):
    rate_hz, hours = RUNS[name]
    device, _, report = static_run(name, rate_hz, hours)
    spec, record = report.spec, hours * 3600.0
    resolved, checked = [], set()
    for axis, fit in enumerate(report.fits):
        n, b, k = spec.noise_density[axis], spec.bias_instability[axis], spec.random_walk[axis]
        tau_b, tau_k = emergence(n, b, k)
        resolved.append(check(fit.arw, n, f"{name} ARW axis {axis}"))
        if tau_b < record / 10:
            check(fit.bias_instability, b, f"{name} bias instability axis {axis}")
            checked.add("bias instability")
        if tau_k < record / 10:
            check(fit.rrw, k, f"{name} RRW axis {axis}")
            checked.add("rrw")
    assert all(resolved), "the white noise is resolved to better than 3 % in every record here"
    if np.any(spec.bias_instability > 0):
        assert "bias instability" in checked, "every record here is long enough to see its bias-instability floor"


def test_ring_laser_fringe_quantisation_shows_its_minus_one_slope():
    # 20 minutes at 100 Hz: below ~30 s the fringe quantum q (Q = q/√12) dominates the dither noise.
    device, samples, report = static_run("navigation_rlg", 100.0, 1.0 / 3.0)
    q = device.mechanism.fringe_angle_rad
    for fit in report.fits:
        short = fit.allan.tau <= 1.0
        slope = np.polyfit(np.log(fit.allan.tau[short]), np.log(fit.allan.adev[short]), 1)[0]
        assert abs(slope + 1) < 0.1, slope
        check(fit.quantisation, q / np.sqrt(12), "RLG quantisation")
        check(fit.arw, report.spec.noise_density[0], "RLG ARW")
