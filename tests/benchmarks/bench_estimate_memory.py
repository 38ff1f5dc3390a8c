"""``gyroemu estimate`` on long logs: peak RSS and wall time against the log's length, read a block at a
time (the default for an online filter) and, as the baseline in the same run, read whole
(``estimate_log(..., read_whole=True)``, what every filter did before and offline filters still do).

For each duration, ``gyroemu simulate`` writes a ``consumer_mems`` log on ``smooth_manoeuvre`` at 1 kHz
(the raw observables, the truth and the pose beside /imu and /mag, as users' logs have them); then each
way of reading runs in a process of its own (``wait4``'s ``ru_maxrss``) and the two outputs are compared
byte for byte. The floor: a process that imports the estimate job and opens nothing.

    python tests/benchmarks/bench_estimate_memory.py [--durations 600 1800 7200] [--smooth] [--folder DIR]
        [--whole-up-to SECONDS]

The baseline runs for durations up to ``--whole-up-to`` (default: all; 2 hours read whole took 18 GB,
with the smoother it would not fit this machine's 24 GB).

``--smooth``: the smoother (``gyroemu estimate --smooth``), which learns the log a block at a time in one
more pass, its storage in temporary files (``mekf_smoother_spool``); read whole, it also holds its
forward pass, window storage and output in memory.

The logs go to a temporary folder (``--folder`` to choose it) and are deleted after each duration; an
hour at 1 kHz is about 1.1 GB of log and as much again of output.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_long_runs import measure, simulate_argv  # noqa: E402  (tests/benchmarks is the script folder)


def digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 24), b""):
            h.update(block)
    return h.hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--durations", type=float, nargs="+", default=[600.0, 1800.0])
    parser.add_argument("--folder", type=Path, default=None)
    parser.add_argument("--smooth", action="store_true", help="the smoother (an offline filter)")
    parser.add_argument(
        "--whole-up-to", type=float, default=float("inf"), help="read whole (the baseline) up to this duration, s"
    )
    args = parser.parse_args()
    gyroemu = [sys.executable, "-m", "gyroemu"]
    floor = measure([sys.executable, "-c", "import gyroemu.pipelines.jobs.estimate"])[1]
    print(f"floor (imports the estimate job): {floor:.2f} GB")
    print("| log | samples | a block at a time | read whole (baseline) | same bytes |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(dir=args.folder) as tmp:
        folder = Path(tmp)
        for duration in args.durations:
            log, streamed, whole = (folder / f"{name}.mcap" for name in ("log", "streamed", "whole"))
            measure(simulate_argv("consumer_mems", "smooth_manoeuvre", duration, log) + ["--rate", "1000"])
            smooth = ["--smooth"] if args.smooth else []
            s_time, s_rss = measure([*gyroemu, "estimate", str(log), "--out", str(streamed), *smooth])
            name = "mekf-smooth" if args.smooth else "mekf"
            code = (
                "from gyroemu.pipelines.jobs.estimate import estimate_log\n"
                f"estimate_log({str(log)!r}, {str(whole)!r}, filter_name={name!r}, read_whole=True)\n"
            )
            if duration <= args.whole_up_to:
                w_time, w_rss = measure([sys.executable, "-c", code])
                baseline, same = f"{w_rss:.2f} GB, {w_time:.1f} s", "yes" if digest(streamed) == digest(whole) else "NO"
            else:  # 2.6 kB a sample (3.4 with the smoother): more than this machine holds beyond a few hours
                baseline, same = "not run (`--whole-up-to`)", "—"
            print(
                f"| {duration / 60:.0f} min ({log.stat().st_size / 1e9:.2f} GB) | {int(duration * 1000):,} "
                f"| {s_rss:.2f} GB, {s_time:.1f} s | {baseline} | {same} |",
                flush=True,
            )
            for path in (log, streamed, whole):
                path.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
