"""Speed of the MEMS gyro's baseband model against its carrier-level model, measured in the same run.

    python tests/benchmarks/bench_mems.py [--seconds 600] [--carrier-seconds 2] [--output-rate-hz 1000]

A script, not a test (pytest does not collect it). Both models run a three-axis triad through
:meth:`MemsGyro.respond` on the inner grid the mechanism asks for at the output rate
(:meth:`MemsGyro.inner_rate_hz`: the output rate for the baseband model, whose steps are exact for
the forcing's cubic Hermite interpolant; 4 kHz at 1 kHz output for the carrier model), in chunks of
``gyroemu.sensors.device_run.BLOCK_INNER_SAMPLES`` carrying their state, as the IMU feeds them. The truth is a
tumbling, vibrating, warming sensor; making it is not timed, only ``respond``. Each figure is the best
of ``--repeats`` runs after a warm-up that loads the numba kernels. Printed: simulated seconds per
wall-clock second ("× real time") for each model, and their ratio; then the carrier model's peak
memory over one block of the IMU's (``BLOCK_INNER_SAMPLES`` inner samples, traced by ``tracemalloc``)
at the highest drive frequency it takes, stepping ``CARRIER_CYCLES_PER_PASS`` drive cycles at a time
against the whole block in one pass (as it did before 2026-11-27), in the same run.

The target is 100× real time for the baseband model; the carrier model (24 steps per drive cycle,
650 k steps per second at 27 kHz) is the baseline. Everything runs on one thread (the numba kernels
are serial; the BLAS pools are limited to one thread). Exit status 1 if the baseband model misses
the target.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.sensors import mems  # noqa: E402
from gyroemu.sensors.device_run import BLOCK_INNER_SAMPLES  # noqa: E402
from gyroemu.sensors.mechanism import GyroTruth  # noqa: E402
from gyroemu.sensors.mems import CARRIER_STEPS_PER_CYCLE, MAX_DRIVE_FREQUENCY_HZ, MemsGyro  # noqa: E402

TARGET = 100.0


def truth_chunk(t: np.ndarray, dt: float) -> GyroTruth:
    """A tumbling sensor (rates of a few rad/s), gravity plus 2 g of 150 Hz vibration, warming up."""
    omega = np.column_stack([2 * np.sin(1.3 * t), 1.5 * np.cos(0.7 * t), 0.5 + np.sin(3.1 * t)])
    alpha = np.column_stack([2.6 * np.cos(1.3 * t), -1.05 * np.sin(0.7 * t), 3.1 * np.cos(3.1 * t)])
    vibration = 2 * 9.81 * np.sin(2 * np.pi * 150 * t)
    force = np.column_stack([0.1 + 0 * t, vibration, 9.81 + 0.5 * vibration])
    temperature = 40 - 15 * np.exp(-t / 600)
    return GyroTruth(
        t=t,
        dt=dt,
        omega=omega,
        alpha=alpha,
        specific_force=force,
        q_is=np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1)),
        temperature_degC=temperature,
    )


def run(gyro: MemsGyro, seconds: float, inner_hz: float) -> float:
    """Wall time of ``respond`` over ``seconds`` of truth at ``inner_hz``, in IMU-sized chunks, s."""
    dt = 1.0 / inner_hz
    total = int(round(seconds * inner_hz))
    rng, state, elapsed = np.random.default_rng(0), {}, 0.0
    for first in range(0, total, BLOCK_INNER_SAMPLES):
        last = min(first + BLOCK_INNER_SAMPLES, total)
        truth = truth_chunk(np.arange(first, last + 1) * dt, dt)  # shares its first sample with the last chunk
        start = time.perf_counter()
        gyro.respond(truth, rng, state)
        elapsed += time.perf_counter() - start
    return elapsed


def best(gyro: MemsGyro, seconds: float, inner_hz: float, repeats: int) -> float:
    run(gyro, min(seconds, 0.01), inner_hz)  # warm-up: loads (or compiles) the kernels
    return min(run(gyro, seconds, inner_hz) for _ in range(repeats))


def block_peak_memory(gyro: MemsGyro, inner_hz: float, cycles_per_pass: int) -> tuple[float, float]:
    """Peak traced memory (MB) and wall time (s) of ``respond`` over one IMU block of truth, stepping
    ``cycles_per_pass`` drive cycles at a time."""
    dt = 1.0 / inner_hz
    truth = truth_chunk(np.arange(BLOCK_INNER_SAMPLES + 1) * dt, dt)
    default = mems.CARRIER_CYCLES_PER_PASS
    mems.CARRIER_CYCLES_PER_PASS = cycles_per_pass
    try:
        tracemalloc.start()
        start = time.perf_counter()
        gyro.respond(truth, np.random.default_rng(0), {})
        elapsed = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    finally:
        mems.CARRIER_CYCLES_PER_PASS = default
    return peak, elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="simulated time, baseband model")
    parser.add_argument("--carrier-seconds", type=float, default=2.0, help="simulated time, carrier model")
    parser.add_argument("--output-rate-hz", type=float, default=1000.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    baseband = MemsGyro()
    carrier = MemsGyro(model="carrier")
    inner_hz = baseband.inner_rate_hz(args.output_rate_hz)
    steps = CARRIER_STEPS_PER_CYCLE * baseband.drive_frequency_hz
    print(
        f"MEMS gyro triad (defaults: f_d {baseband.drive_frequency_hz:g} Hz, Δf {baseband.mode_split_hz:g} Hz), "
        f"output {args.output_rate_hz:g} Hz, inner grid {inner_hz:g} Hz, 3 axes"
    )

    t_base = best(baseband, args.seconds, inner_hz, args.repeats)
    speed_base = args.seconds / t_base
    print(
        f"  baseband: {args.seconds:g} s simulated in {t_base:.3f} s  ->  {speed_base:8.1f} x real time "
        f"({3 * args.seconds * inner_hz / t_base / 1e6:.2f} M axis-steps/s)"
    )

    t_carrier = best(carrier, args.carrier_seconds, inner_hz, args.repeats)
    speed_carrier = args.carrier_seconds / t_carrier
    print(
        f"  carrier:  {args.carrier_seconds:g} s simulated in {t_carrier:.3f} s  ->  "
        f"{speed_carrier:8.1f} x real time "
        f"({3 * args.carrier_seconds * steps / t_carrier / 1e6:.2f} M axis-steps/s, "
        f"{CARRIER_STEPS_PER_CYCLE} per drive cycle)"
    )
    print(
        f"  baseband / carrier: {speed_base / speed_carrier:.0f} x;  target {TARGET:g} x real time: "
        f"{'met' if speed_base >= TARGET else 'MISSED'}"
    )

    fastest = MemsGyro(model="carrier", drive_frequency_hz=MAX_DRIVE_FREQUENCY_HZ)
    block_hz = fastest.inner_rate_hz(args.output_rate_hz)
    print(
        f"carrier model, f_d {MAX_DRIVE_FREQUENCY_HZ:g} Hz: one block of {BLOCK_INNER_SAMPLES} inner samples "
        f"({BLOCK_INNER_SAMPLES / block_hz:g} s at {block_hz:g} Hz)"
    )
    for label, cycles in (("in passes", mems.CARRIER_CYCLES_PER_PASS), ("in one pass (before)", 1 << 62)):
        peak, elapsed = block_peak_memory(fastest, block_hz, cycles)
        print(f"  {label:<22} peak {peak:8.1f} MB traced, {elapsed:6.1f} s")
    return 0 if speed_base >= TARGET else 1


if __name__ == "__main__":
    sys.exit(main())
