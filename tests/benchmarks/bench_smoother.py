"""Speed and memory of the offline MEKF (``mekf-smooth``) on a 10-minute log at 1 kHz, against the
forward pass alone, timed in the same run (issue #17: the smoother at most 3× the forward pass, the
whole log in under 10 s, its storage under ~1 GB).

    python tests/benchmarks/bench_smoother.py [--minutes 10]

The log is the smooth manoeuvre measured by the consumer MEMS (9D, 1 kHz). Timed, best of three:

- the online MEKF (``Mekf.process``, filterpy's algebra in Python per window), for reference;
- the forward pass alone, compiled: ``mekf_batch`` with one run (the same kernels, no storage);
- the smoother: its forward pass (with the per-window storage) and its backward pass (RTS recursion
  and per-sample output), from :attr:`SmootherResult.forward_s` and ``backward_s``.

Memory: the peak resident set of this process, and the smoother's per-window storage computed from
its arrays (float64).
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.pipelines.estimation import mekf_kernels as kern  # noqa: E402
from gyroemu.pipelines.estimation.batched import mekf_batch  # noqa: E402
from gyroemu.pipelines.estimation.mekf import Mekf  # noqa: E402
from gyroemu.pipelines.estimation.mekf_smoother import smooth_log, smoother_params  # noqa: E402
from gyroemu.pipelines.estimation.setup import setup_for  # noqa: E402
from gyroemu.sensors import load_device  # noqa: E402


def best_of(n: int, fn):
    walls, out = [], None
    for _ in range(n):
        started = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - started)
    return min(walls), out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--skip-online", action="store_true", help="leave out the (slow) online Mekf")
    args = parser.parse_args()
    scenario = load_scenario("smooth_manoeuvre")
    device = load_device("consumer_mems", seed=0)
    started = time.perf_counter()
    traj = scenario.simulate(duration=60.0 * args.minutes)
    samples = device.measure(traj)
    t = np.asarray(samples.t, float) - samples.t[0]
    gyro, accel, mag = samples.gyro, samples.accel, samples.mag
    n = len(t)
    print(
        f"log: {n} samples ({t[-1]:.0f} s at {n / t[-1]:.0f} Hz, 9D), "
        f"simulated in {time.perf_counter() - started:.1f} s"
    )
    setup = setup_for(device, scenario)
    params = smoother_params(setup)
    k = 2000  # compile (or load the cache) before timing
    smooth_log(setup, t[:k], gyro[:k], accel[:k], mag[:k], params=params)
    mekf_batch(setup, t[:k], gyro[None, :k], accel[None, :k], mag[None, :k], params=params)

    fwd, _ = best_of(3, lambda: mekf_batch(setup, t, gyro[None], accel[None], mag[None], params=params))
    total, res = best_of(3, lambda: smooth_log(setup, t, gyro, accel, mag, params=params))
    windows = len(res.window_end) + 1
    X = kern.X_SIZE
    storage = windows * (2 * X * X + 3 * X + X + 9 + 1) * 8
    print(f"forward pass alone (compiled, mekf_batch of one run): {fwd:.2f} s ({n / fwd / 1e6:.2f} M samples/s)")
    print(
        f"smoother: {total:.2f} s = forward with storage {res.forward_s:.2f} s + backward {res.backward_s:.2f} s "
        f"(best of 3) -> {total / fwd:.2f} x the forward pass"
    )
    print(f"per-window storage: {windows} windows, {storage / 1e6:.0f} MB (float64)")
    if not args.skip_online:
        online, _ = best_of(1, lambda: Mekf(setup, params).process(t, gyro, accel, mag))
        print(f"online Mekf.process (filterpy per window), for reference: {online:.2f} s")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident set of this process: {peak:.0f} MB")
    print(
        f"targets: smoother ≤ 3 x forward: {'met' if total <= 3 * fwd else 'MISSED'}; "
        f"under 10 s: {'met' if total < 10 else 'MISSED'}; storage under 1 GB: {'met' if storage < 1e9 else 'MISSED'}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
