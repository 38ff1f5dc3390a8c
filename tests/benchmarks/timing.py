"""Timing shared by the benchmark scripts (they run as ``python tests/benchmarks/bench_*.py``)."""

import resource
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


def median_wall_cpu(run, repeats: int) -> tuple[float, float]:
    """Median wall and CPU seconds of ``repeats`` calls of ``run()`` after a warm-up call. CPU counts
    every thread of this process and of the children it waited for (user + system): on a loaded
    machine a run on two threads loses wall time that its CPU time still shows."""
    run()
    walls, cpus = [], []
    for _ in range(repeats):
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        start, cpu = time.perf_counter(), time.process_time()
        run()
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        child = (after.ru_utime - children.ru_utime) + (after.ru_stime - children.ru_stime)
        cpus.append(time.process_time() - cpu + child)
    return statistics.median(walls), statistics.median(cpus)
