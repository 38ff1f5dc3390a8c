"""Timing shared by the benchmark scripts (they run as ``python tests/benchmarks/bench_*.py``)."""

import statistics
import time


def wall_times(run, repeats: int) -> list[float]:
    """Wall times (s) of ``repeats`` calls of ``run()``, after one warm-up call that loads or compiles
    the numba kernels and fills the caches."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return times


def best_time(run, repeats: int) -> float:
    """Best wall time (s) of ``repeats`` calls of ``run()``, after a warm-up call."""
    return min(wall_times(run, repeats))


def median_time(run, repeats: int) -> float:
    """Median wall time (s) of ``repeats`` calls of ``run()``, after a warm-up call."""
    return statistics.median(wall_times(run, repeats))
