"""Throughput of the attitude filters (samples per second of ``process()``), against baselines measured in
the same run.

    python tests/benchmarks/bench_filters.py [--seconds 20] [--repeats 3] [--batch-runs 1000]
                                             [--batch-seconds 2] [--filter NAME ...]

A script, not a test (pytest does not collect it). The data: smooth_manoeuvre measured by consumer_mems
(1 kHz, 9D), ``--seconds`` long. Each filter is made afresh and given the whole run in one ``process()``
call; the figure is the best of ``--repeats`` after one warm-up (numba compiles, caches fill). Baselines:

- a bare per-sample Python loop of numpy quaternion integration (``q ← q ⊗ exp(½ ω Δt)``, normalised):
  the floor of any filter written sample by sample in Python with numpy, as the ``ahrs`` filters are;
- the increments ``exp(½ ω Δt)`` of every sample computed at once with numpy (the chain of products
  itself is sequential): the ceiling of vectorised numpy work per sample.

With ``gyroemu.pipelines.estimation.batched`` present, also ``mekf_batch`` over ``--batch-runs`` runs of
``--batch-seconds`` at once (one measured run plus independent white noise per run, 0.05 °/s on the gyro),
reported as filter updates per second across runs. Targets (issue 5): the mekf ≥ 20 k samples/s
(the ahrs EKF runs about 10 k), the batched mode ≥ 1 M updates/s across 1000 runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from timing import best_time  # noqa: E402

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.dynamics.rotation import quat_exp, quat_multiply  # noqa: E402
from gyroemu.pipelines.estimation.registry import available_filters, make_filter, unavailable_filters  # noqa: E402
from gyroemu.pipelines.estimation.setup import setup_for  # noqa: E402
from gyroemu.sensors import load_device  # noqa: E402

TARGETS = {"mekf": 20e3}
BATCH_TARGET = 1e6


def python_loop_integration(t, gyro):
    """Per-sample numpy quaternion integration: the cost floor of a per-sample Python filter."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    out = np.empty((len(t), 4))
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    for k in range(len(t)):
        half = 0.5 * gyro[k] * dt[k]
        angle = np.linalg.norm(half)
        dq = np.array([np.cos(angle), *(np.sin(angle) / angle * half if angle > 0 else half)])
        w1, x1, y1, z1 = q
        w2, x2, y2, z2 = dq
        q = np.array(
            [
                w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            ]
        )
        q /= np.linalg.norm(q)
        out[k] = q
    return out


def vectorised_increments(t, gyro):
    """The per-sample increments, vectorised: the ceiling of numpy work per sample."""
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    return quat_multiply(quat_exp(0.5 * gyro * dt[:, None]), np.array([1.0, 0.0, 0.0, 0.0]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="length of the run, s (1 kHz)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--batch-runs", type=int, default=1000, help="runs at once for mekf_batch")
    parser.add_argument("--batch-seconds", type=float, default=2.0, help="length of each batched run, s")
    parser.add_argument("--filter", action="append", default=None, help="filters to time (default: all available)")
    args = parser.parse_args()

    scenario = load_scenario("smooth_manoeuvre")
    device = load_device("consumer_mems", seed=1)
    samples = device.measure(scenario.simulate(duration=args.seconds))
    setup = setup_for(device, scenario)
    t, gyro, accel, mag = samples.t, samples.gyro, samples.accel, samples.mag
    n = len(t)
    print(
        f"smooth_manoeuvre x consumer_mems: {n:,} samples at {setup.rate_hz:g} Hz (9D); best of {args.repeats}; "
        f"{os.cpu_count()} CPUs"
    )
    for name, why in unavailable_filters().items():
        print(f"  ({name} left out: {why})")

    rows = []
    loop_n = min(n, 20_000)
    seconds = best_time(lambda: python_loop_integration(t[:loop_n], gyro[:loop_n]), args.repeats)
    rows.append(("baseline: per-sample numpy integration loop", loop_n / seconds))
    seconds = best_time(lambda: vectorised_increments(t, gyro), args.repeats)
    rows.append(("baseline: vectorised increments (numpy)", n / seconds))
    loop_rate = rows[0][1]

    for name in args.filter or available_filters():

        def run():
            make_filter(name, setup).process(t, gyro, accel, mag)

        rows.append((name, n / best_time(run, args.repeats)))

    print(f"\n{'filter':48s} {'samples/s':>12s} {'x loop baseline':>16s}")
    for name, rate in rows:
        target = TARGETS.get(name)
        mark = "" if target is None else f"   target {target / 1e3:.0f} k: {'met' if rate >= target else 'MISSED'}"
        print(f"{name:48s} {rate:12,.0f} {rate / loop_rate:16.2f}{mark}")

    try:
        from gyroemu.pipelines.estimation.batched import mekf_batch
    except ImportError as exc:
        print(f"\nbatched mode: not available ({exc})")
        return 0
    r = args.batch_runs
    m = min(n, int(round(args.batch_seconds * setup.rate_hz)))
    rng = np.random.default_rng(0)
    noise = np.radians(0.05)
    g = gyro[:m] + rng.normal(0.0, noise, (r, m, 3))
    a = np.broadcast_to(accel[:m], (r, m, 3)).copy()
    b = np.broadcast_to(mag[:m], (r, m, 3)).copy()
    mekf_batch(setup, t[: min(m, 100)], g[:2, : min(m, 100)], a[:2, : min(m, 100)], b[:2, : min(m, 100)])  # warm-up
    started = time.perf_counter()
    mekf_batch(setup, t[:m], g, a, b)
    seconds = time.perf_counter() - started
    rate = r * m / seconds
    print(
        f"\nmekf_batch: {r} runs x {m:,} samples in {seconds:.2f} s = {rate:,.0f} updates/s "
        f"({rate / loop_rate:.0f}x the loop baseline); target {BATCH_TARGET / 1e6:.0f} M: "
        f"{'met' if rate >= BATCH_TARGET else 'MISSED'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
