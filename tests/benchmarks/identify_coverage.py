"""How often does the white-noise interval of ``gyroemu identify`` hold the device's N? (a script, not a test)

    python tests/benchmarks/identify_coverage.py [--seeds 20] [--case consumer_mems:150 --case aktos_t_broad:240]

Each case is a built-in device and a rest length in seconds. Run k draws the device with seed k lying
still on ``bench_static`` for that long at its own rate, finds the rest phases as ``identify`` does
(:func:`gyroemu.pipelines.identification.find_rest_phases`) and reads the noise of the gyro and the
accelerometer from them (:func:`gyroemu.pipelines.identification.sensor_noise`). The truth is the
device's white noise at its output, N (``Device.gyro_noise_density``: the specified density, which holds
the mechanism's own and the quantiser's; the accelerometer's specified density).

Printed per device, sensor and axis: the runs, how many of them hold the true N within the 68 % interval
(``low ≤ N ≤ high``), the mean and standard deviation of the relative error est/N − 1 over the runs
(the bias, and the spread the interval should describe), the median relative half-width of the interval,
and the RMS of z = (N − est)/half-width (about 1 for an honest interval, above 1 when it is too narrow).
Then per device and over all: the fraction held against the binomial band of an exact 68 % interval,
0.683 ± 3·√(0.683·0.317/n) for n runs (axes and seeds are independent draws). The protocol is
``tests/noise_coverage.py``'s, which ``tests/pipelines/test_identify_coverage.py`` holds on a shorter
rest; the figures in the module notes of ``sensors/allan.py`` were made with ``--seeds 100``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the protocol the test holds

from noise_coverage import binomial_band, rest_draws  # noqa: E402

from gyroemu.pipelines.identification import sensor_noise  # noqa: E402

CASES = ("consumer_mems:150", "aktos_t_broad:240")


def table(cases, seeds: int, noise: Callable = sensor_noise) -> list[tuple[str, int, int]]:
    """Print the coverage table; returns (device, held, runs) per case."""
    totals = []
    print(f"{'device':16s} {'sensor':6s} axis  runs  held   bias %   sd %  halfw %  rms z")
    for case in cases:
        device, seconds = case.split(":")
        rows: dict[tuple[str, str], list] = {}
        for sensor, axis, truth, c in rest_draws(device, float(seconds), seeds, noise):
            rows.setdefault((sensor, axis), []).append((truth, c.value, c.low, c.high))
        held_all = runs_all = 0
        for (sensor, axis), values in rows.items():
            r = np.array(values)
            truth, value, low, high = r.T
            held = int(np.sum((low <= truth) & (truth <= high)))
            rel = (value / truth - 1) * 100
            half = (high - low) / 2
            z = (truth - value) / half
            print(
                f"{device:16s} {sensor:6s} {axis:4s} {len(r):5d} {held:5d} {rel.mean():+8.3f} {rel.std(ddof=1):6.3f}"
                f" {np.median(half / value) * 100:8.3f} {np.sqrt(np.mean(z * z)):6.2f}"
            )
            held_all += held
            runs_all += len(r)
        lo, hi = binomial_band(runs_all)
        print(
            f"{device} ({seconds} s rest): {held_all}/{runs_all} = {held_all / runs_all:.3f} held "
            f"(exact 68 % interval: {lo:.3f} … {hi:.3f})"
        )
        totals.append((device, held_all, runs_all))
    held = sum(t[1] for t in totals)
    runs = sum(t[2] for t in totals)
    lo, hi = binomial_band(runs)
    print(f"all: {held}/{runs} = {held / runs:.3f} held (exact 68 % interval: {lo:.3f} … {hi:.3f})")
    return totals


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="runs per case (seeds 0 … n−1)")
    parser.add_argument(
        "--case",
        action="append",
        help="DEVICE:SECONDS of rest (repeatable; default consumer_mems:150 aktos_t_broad:240)",
    )
    args = parser.parse_args()
    table(args.case or CASES, args.seeds)


if __name__ == "__main__":
    main()
