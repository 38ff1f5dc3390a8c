"""Runs per second of a campaign on the local Dask cluster against the one-process bench, same grid, same run.

    python tests/benchmarks/bench_campaign.py [--seeds 16] [--duration 10] [--workers N]

The grid: smooth_manoeuvre × consumer_mems, ``--duration`` s, seeds 0 … ``--seeds`` − 1, filters mekf
(batched) and madgwick. The baseline is :func:`gyroemu.pipelines.jobs.bench.run_bench` with
``batched=True`` over the same seeds in this process (what ``gyroemu bench --batched`` runs); the
campaign is :func:`gyroemu.pipelines.jobs.campaign.run_campaign` on a fresh store (no plots), its
time including the local cluster's start and the workers' imports. A run is one (seed, filter) row.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from gyroemu.pipelines.campaign import default_workers
from gyroemu.pipelines.jobs.bench import SimCase, run_bench
from gyroemu.pipelines.jobs.campaign import CampaignOptions, run_campaign

FILTERS = ["mekf", "madgwick"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16, help="Monte Carlo seeds (default 16)")
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per run (default 10)")
    parser.add_argument("--workers", type=int, default=None, help="local workers (default: one per core)")
    parser.add_argument("--seeds-per-task", type=int, default=4, help="seeds per task (default 4)")
    args = parser.parse_args()
    runs = args.seeds * len(FILTERS)
    case = SimCase(duration=args.duration)
    run_bench([SimCase(duration=1.0)], FILTERS, runs=2, seed=0, batched=True, progress=False)  # warm caches
    started = time.perf_counter()
    run_bench([case], FILTERS, runs=args.seeds, seed=0, batched=True, progress=False)
    one = time.perf_counter() - started
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "c.toml"
        spec.write_text(
            f'scenarios = ["smooth_manoeuvre"]\ndevices = ["consumer_mems"]\ndurations_s = [{args.duration}]\n'
            f"seed_range = {{ start = 0, count = {args.seeds} }}\nfilters = {FILTERS!r}\n".replace("'", '"')
            + f"seeds_per_task = {args.seeds_per_task}\n"
        )
        summary = run_campaign(CampaignOptions(spec=spec, out=Path(tmp) / "out", workers=args.workers, plots=False))
    workers = args.workers or default_workers()
    print(f"{runs} runs ({args.seeds} seeds x {len(FILTERS)} filters, {args.duration:g} s each)")
    print(f"  gyroemu bench --batched (one process): {one:7.2f} s  {runs / one:7.2f} runs/s")
    print(
        f"  campaign, local cluster of {workers}:     {summary.elapsed_s:7.2f} s  {summary.runs_per_s:7.2f} runs/s "
        f"({summary.elapsed_s and one / summary.elapsed_s:.2f}x)"
    )


if __name__ == "__main__":
    main()
