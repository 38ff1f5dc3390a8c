"""``gyroemu estimate --plot`` and ``gyroemu info --plot`` on long logs: peak RSS and wall time against the
log's length, each series reduced as the log is read (the default) and, as the baseline in the same
run, the log read whole into the same curves (``read_whole=True``; before this, the plots read the log
whole and drew every sample).

For each duration, ``gyroemu simulate`` writes a ``consumer_mems`` log on ``smooth_manoeuvre`` at 1 kHz
(raw observables, truth, pose) and ``gyroemu estimate`` adds its estimate; then each plot runs in a
process of its own, both ways (``wait4``'s ``ru_maxrss``). The floor: a process that imports the plots
and matplotlib.

    python tests/benchmarks/bench_plots.py [--durations 600 1800] [--folder DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_long_runs import measure, simulate_argv  # noqa: E402  (tests/benchmarks is the script folder)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", type=float, nargs="+", default=[600.0, 1800.0])
    parser.add_argument("--folder", type=Path, default=None)
    args = parser.parse_args()
    gyroemu = [sys.executable, "-m", "gyroemu"]
    floor = measure([sys.executable, "-c", "import gyroemu.pipelines.jobs.plots, matplotlib.pyplot"])[1]
    print(f"floor (imports the plots and matplotlib): {floor:.2f} GB")
    print("| log | plot | a chunk at a time | read whole (baseline) |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory(dir=args.folder) as tmp:
        folder = Path(tmp)
        for duration in args.durations:
            log, est = folder / "log.mcap", folder / "est.mcap"
            measure(simulate_argv("consumer_mems", "smooth_manoeuvre", duration, log) + ["--rate", "1000"])
            measure([*gyroemu, "estimate", str(log), "--out", str(est)])
            for plot, source in (("plot_estimate", est), ("plot_info", log)):
                figures = []
                for whole in (False, True):
                    code = (
                        f"from gyroemu.pipelines.jobs.plots import {plot}\n"
                        f"{plot}({str(source)!r}, {str(folder / 'p.png')!r}, read_whole={whole})\n"
                    )
                    seconds, rss = measure([sys.executable, "-c", code])
                    figures.append(f"{rss:.2f} GB, {seconds:.1f} s")
                print(f"| {duration / 60:.0f} min | {plot} | {figures[0]} | {figures[1]} |", flush=True)
            for path in (log, est):
                path.unlink()


if __name__ == "__main__":
    main()
