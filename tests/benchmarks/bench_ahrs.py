"""Throughput of the ``ahrs`` library's Madgwick, Mahony and EKF behind gyroemu's adapters: the library's
own per-sample updates (the baseline, in the same run) against the compiled per-block kernels of
:mod:`gyroemu.pipelines.estimation.ahrs_kernels` (which ``tests/pipelines/test_ahrs_kernels.py`` holds to
the library's output within round-off).

    python tests/benchmarks/bench_ahrs.py [--duration 20]

The motion is ``smooth_manoeuvre`` measured by ``consumer_mems`` (seed 1) at 1 kHz; the compiled code is
loaded from numba's cache (or compiled) before timing.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.estimation import peers
from gyroemu.pipelines.estimation.protocol import FilterSetup
from gyroemu.sensors import load_device

FILTERS = {"madgwick": peers.Madgwick, "mahony": peers.Mahony, "ahrs-ekf": peers.AhrsEkf}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="seconds of motion at 1 kHz (default 20)")
    args = parser.parse_args()
    samples = load_device("consumer_mems", seed=1).measure(
        load_scenario("smooth_manoeuvre").simulate(duration=args.duration)
    )
    t, gyro, accel, mag = samples.t, samples.gyro, samples.accel, samples.mag
    rate = 1.0 / np.median(np.diff(t))
    for name, cls in FILTERS.items():
        for mode, use_mag in (("9D", True), ("6D", False)):
            setup = FilterSetup(rate_hz=rate, use_mag=use_mag)
            cls(setup).process(t[:10], gyro[:10], accel[:10], mag[:10])  # compile, or load the cache
            rates = []
            for reference in (True, False):
                f = cls(setup)
                f._reference = reference  # the library's own per-sample loop (the adapters' reference path)
                start = time.perf_counter()
                f.process(t, gyro, accel, mag)
                rates.append(len(t) / (time.perf_counter() - start))
            library, compiled = rates[0] / 1e3, rates[1] / 1e6
            print(
                f"{name:9s} {mode}: library {library:7.1f} k samples/s, compiled {compiled:6.2f} M samples/s, ", end=""
            )
            print(f"x{rates[1] / rates[0]:.0f}")


if __name__ == "__main__":
    main()
