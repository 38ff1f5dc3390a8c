"""Throughput of the error-term layer with every term on, against baselines measured in the same run.

    python tests/benchmarks/bench_errors.py [--samples 2000000] [--rate-hz 200] [--repeats 5]

A script, not a test (pytest does not collect it). Each figure is the best of ``--repeats`` runs,
after one warm-up run that compiles the numba kernels. Two counts are printed, because "samples per
second per axis" can be read two ways:

- per axis: three-axis samples per second, N / t (each axis's stream runs at this rate);
- axis values: scalar values per second, 3N / t (what one axis alone would run at).

The target is 20 M per second per axis.
"""

from __future__ import annotations

import argparse

import numpy as np
from timing import best_time  # noqa: E402  (tests/benchmarks is the script folder)

from gyroemu.sensors import noise
from gyroemu.sensors.errors import GyroErrors, apply_errors

TARGET = 20e6

ALL_TERMS = dict(
    bias_deg_per_h=[1.0, -2.0, 3.0],
    turn_on_bias_deg_per_h=10.0,
    bias_temperature_deg_per_h_per_degC=0.1,
    scale_factor_ppm=100,
    scale_factor_temperature_ppm_per_degC=5,
    range_deg_per_s=400,
    scale_factor_nonlinearity_ppm=50,
    misalignment_mrad=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
    g_sensitivity_deg_per_h_per_g=[[1, 0.1, 0], [0, 1, 0.1], [0.1, 0, 1]],
    arw_deg_per_sqrt_h=0.15,
    bias_instability_deg_per_h=1.0,
    rrw_deg_per_h_per_sqrt_h=0.1,
    rate_ramp_deg_per_h_per_h=0.01,
    quantisation_rad=1e-7,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=2_000_000, help="three-axis samples per run")
    parser.add_argument("--rate-hz", type=float, default=200.0, help="sample rate")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    n, dt = args.samples, 1.0 / args.rate_hz
    rng = np.random.default_rng(0)
    t = np.arange(n) * dt
    omega = 0.1 * rng.standard_normal((n, 3))
    force = np.array([0.0, 0.0, 9.81]) + rng.standard_normal((n, 3))
    temperature = 25 + 5 * np.sin(t / 600)
    spec = GyroErrors(**ALL_TERMS, bandwidth_hz=args.rate_hz / 4)
    model = spec.to_si()
    other = rng.standard_normal((n, 3))

    cases = {
        "error layer, all terms": lambda: apply_errors(
            omega, t, model, rng, temperature_degC=temperature, specific_force=force
        ),
        "baseline: white noise (numpy)": lambda: noise.white_noise(rng, (n, 3), dt, 1e-3),
        "baseline: white noise (kernel)": lambda: noise.sensor_noise(rng, (n, 3), dt, white=1e-3),
        "baseline: numpy add of two arrays": lambda: omega + other,
    }
    print(f"{n:,} three-axis samples at {args.rate_hz:g} Hz, every error term on, best of {args.repeats}")
    print(f"{'case':36s} {'ms':>8s} {'ns/value':>9s} {'M/s per axis':>13s} {'M values/s':>11s}")
    results = {}
    for name, run in cases.items():
        seconds = best_time(run, args.repeats)
        results[name] = seconds
        print(
            f"{name:36s} {seconds * 1e3:8.1f} {seconds / (3 * n) * 1e9:9.2f} "
            f"{n / seconds / 1e6:13.1f} {3 * n / seconds / 1e6:11.1f}"
        )

    seconds = results["error layer, all terms"]
    per_axis, values = n / seconds, 3 * n / seconds
    verdict = lambda rate: "met" if rate >= TARGET else "NOT met"  # noqa: E731
    print(f"\ntarget {TARGET / 1e6:g} M/s per axis:")
    print(f"  counting axis values (3N/t):    {values / 1e6:5.1f} M/s  {verdict(values)}")
    print(f"  counting 3-axis samples (N/t):  {per_axis / 1e6:5.1f} M/s  {verdict(per_axis)}")
    baseline = results["baseline: white noise (numpy)"]
    print(f"  all terms cost {seconds / baseline:.1f}x numpy white noise alone")


if __name__ == "__main__":
    main()
