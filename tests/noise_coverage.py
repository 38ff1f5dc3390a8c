"""The coverage protocol of the white-noise interval of ``gyroemu identify``, shared by
``tests/pipelines/test_identify_coverage.py`` (what it holds) and ``tests/benchmarks/identify_coverage.py``
(the table it prints): run k draws a built-in device with seed k lying still on ``bench_static``, finds
its rest phases as ``identify`` does and reads the gyro's and the accelerometer's noise from them; the
truth is the device's white noise at its output."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.identification import NoiseTerm, find_rest_phases, sensor_noise
from gyroemu.sensors import load_device

ONE_SIGMA = 0.682689492137086  # the probability a 68 % (±1σ) interval holds its truth


def rest_draws(
    device: str, seconds: float, seeds: int, noise: Callable = sensor_noise
) -> Iterator[tuple[str, str, float, NoiseTerm]]:
    """For seeds 0 … seeds−1: (sensor, axis, true N, the identified white-noise term) of ``device`` lying
    still ``seconds`` s at its own rate, its rest phases found by ``find_rest_phases`` and read by
    ``noise`` (``sensor_noise``'s signature). True N: ``Device.gyro_noise_density`` (the specified
    density at the output, the mechanism's own and the quantiser's included) and the accelerometer's
    specified density."""
    scenario = load_scenario("bench_static")
    traj = None
    for seed in range(seeds):
        dev = load_device(device, seed=seed)
        if traj is None:
            traj = scenario.simulate(duration=seconds, rate_hz=dev.spec.rate_hz)
        samples = dev.measure(traj)
        dt = 1.0 / dev.spec.rate_hz
        rest = find_rest_phases(samples.t, samples.gyro, samples.accel)
        truths = {
            "gyro": np.asarray(dev.gyro_noise_density, dtype=float),
            "accel": np.broadcast_to(dev.spec.accelerometer.errors.to_si().noise_density, (3,)),
        }
        for sensor, data in (("gyro", samples.gyro), ("accel", samples.accel)):
            result = noise([data[p.start : p.stop] for p in rest], dt)
            for i, a in enumerate(result.axes):
                yield sensor, "xyz"[i], float(truths[sensor][i]), a.noise_density


def binomial_band(runs: int, sigmas: float = 3.0) -> tuple[float, float]:
    """The fraction of ``runs`` independent runs an exact 68 % interval holds, ± ``sigmas`` binomial
    standard deviations: 0.683 ± sigmas·√(0.683·0.317/runs)."""
    spread = sigmas * math.sqrt(ONE_SIGMA * (1.0 - ONE_SIGMA) / runs)
    return ONE_SIGMA - spread, ONE_SIGMA + spread
