"""``gyroemu bench --log`` on long logs: peak RSS and wall time against the log's length, read a block at a
time (the default) and, as the baseline in the same run, read whole (``LogCase(read_whole=True)``, what
the bench did before).

For each duration, ``gyroemu simulate`` writes a ``consumer_mems`` log on ``smooth_manoeuvre`` at 1 kHz
(raw observables, truth and pose beside /imu and /mag); ``gyroemu bench --log LOG --filter mekf --filter
madgwick`` runs in a process of its own (``wait4``'s ``ru_maxrss``), the baseline in another, and the two
reports' figures are compared (every metric of every run, the notes and the curves; not the wall times).

    python tests/benchmarks/bench_log_memory.py [--durations 600 1800] [--filters mekf madgwick]
        [--whole-up-to SECONDS] [--folder DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_long_runs import measure, simulate_argv  # noqa: E402  (tests/benchmarks is the script folder)

from gyroemu.pipelines.jobs.bench import report_figures  # noqa: E402


def figures(report_json: Path) -> dict:
    """A bench.json's figures (:func:`report_figures`)."""
    return report_figures(json.loads(report_json.read_text()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", type=float, nargs="+", default=[600.0, 1800.0])
    parser.add_argument("--filters", nargs="+", default=["mekf", "madgwick"])
    parser.add_argument("--folder", type=Path, default=None)
    parser.add_argument(
        "--whole-up-to", type=float, default=float("inf"), help="read whole (the baseline) up to this duration, s"
    )
    args = parser.parse_args()
    floor = measure([sys.executable, "-c", "import gyroemu.pipelines.jobs.bench"])[1]
    print(f"floor (imports the bench job): {floor:.2f} GB; filters: {', '.join(args.filters)}")
    print("| log | samples | a block at a time | read whole (baseline) | same figures |")
    print("|---|---|---|---|---|")
    filters = [a for f in args.filters for a in ("--filter", f)]
    with tempfile.TemporaryDirectory(dir=args.folder) as tmp:
        folder = Path(tmp)
        for duration in args.durations:
            log = folder / "log.mcap"
            measure(simulate_argv("consumer_mems", "smooth_manoeuvre", duration, log) + ["--rate", "1000"])
            streamed, whole = folder / "streamed", folder / "whole"
            argv = [sys.executable, "-m", "gyroemu", "bench", "--log", str(log), *filters, "--out", str(streamed)]
            argv.append("--force")  # the previous duration's report is there
            s_time, s_rss = measure(argv)
            code = (
                "from gyroemu.pipelines.jobs.bench import LogCase, run_bench\n"
                f"run_bench([LogCase({str(log)!r}, read_whole=True)], filters={args.filters!r})"
                f".save({str(whole)!r})\n"
            )
            if duration <= args.whole_up_to:
                w_time, w_rss = measure([sys.executable, "-c", code])
                same = figures(streamed / "bench.json") == figures(whole / "bench.json")  # not the wall times
                baseline, same_text = f"{w_rss:.2f} GB, {w_time:.1f} s", "yes" if same else "NO"
            else:
                baseline, same_text = "not run (`--whole-up-to`)", "—"
            print(
                f"| {duration / 60:.0f} min ({log.stat().st_size / 1e9:.2f} GB) | {int(duration * 1000):,} "
                f"| {s_rss:.2f} GB, {s_time:.1f} s | {baseline} | {same_text} |",
                flush=True,
            )
            log.unlink()


if __name__ == "__main__":
    main()
