"""What the tf tree costs ``gyroemu simulate`` (issue #20): wall time and file size of 300 s of
``consumer_mems`` on ``smooth_manoeuvre`` with ``/tf`` + ``/tf_static`` (the default) against the same
run without them (the baseline, measured in the same process, runs alternating).

    python tests/benchmarks/bench_tf_cost.py [--duration 300] [--runs 3]

Target: the tree adds at most 10 % to the time.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from gyroemu.pipelines.formats import mcap_log
from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate


class _NoTree(mcap_log.McapLogWriter):
    """The writer without /tf and /tf_static (the baseline)."""

    def __init__(self, path, **kwargs):
        kwargs["tf_rate_hz"] = None
        super().__init__(path, **kwargs)
        self._no_static = True

    def _encode_tf(self, device, recording, stamp_ns):
        return []


def _run(out: Path, duration: float, tree: bool) -> tuple[float, int]:
    original = mcap_log.McapLogWriter
    if not tree:
        mcap_log.McapLogWriter = _NoTree  # type: ignore[misc]
    try:
        started = time.perf_counter()
        run_simulate(
            SimulateOptions(
                scenario="smooth_manoeuvre", device="consumer_mems", duration=duration, out=out, seed=1, force=True
            )
        )
        return time.perf_counter() - started, out.stat().st_size
    finally:
        mcap_log.McapLogWriter = original  # type: ignore[misc]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "run.mcap"
        _run(out, 5.0, True)  # imports, compilation
        times: dict[bool, list[float]] = {True: [], False: []}
        sizes: dict[bool, int] = {}
        for _ in range(args.runs):
            for tree in (False, True):
                elapsed, size = _run(out, args.duration, tree)
                times[tree].append(elapsed)
                sizes[tree] = size
    base, tree = statistics.median(times[False]), statistics.median(times[True])
    print(f"simulate {args.duration:g} s of consumer_mems on smooth_manoeuvre, median of {args.runs} runs:")
    print(f"  without /tf (baseline): {base:.2f} s, {sizes[False] / 1e6:.2f} MB  (runs {times[False]})")
    print(f"  with /tf + /tf_static:  {tree:.2f} s, {sizes[True] / 1e6:.2f} MB  (runs {times[True]})")
    print(f"  cost: {100 * (tree / base - 1):+.1f} % time, {100 * (sizes[True] / sizes[False] - 1):+.2f} % size")


if __name__ == "__main__":
    main()
