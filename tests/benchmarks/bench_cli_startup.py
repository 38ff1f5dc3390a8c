"""Start-up time of the command line: ``gyroemu --help``, ``--version``, ``scenarios`` and ``presets``.

Each command runs ``--repeats`` times as a whole process (the ``gyroemu`` console script of the running
interpreter's environment, run from a temporary folder so a checkout on the path cannot count), and
the median wall time is printed with ``python -c pass`` measured in the same run as the baseline.
The target (issue: a fast command line) is 0.5 s for ``--help``, ``scenarios`` and ``presets``.

    python tests/benchmarks/bench_cli_startup.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 0.5


def wall_times(command: list[str], repeats: int, cwd: str) -> list[float]:
    """Wall time of each of ``repeats`` runs of ``command`` (one untimed warm-up run first)."""
    subprocess.run(command, cwd=cwd, capture_output=True, check=True)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, cwd=cwd, capture_output=True, check=True)
        times.append(time.perf_counter() - start)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15, help="timed runs per command (default: 15)")
    args = parser.parse_args()
    script = str(Path(sys.executable).with_name("gyroemu"))
    cases = [
        ("python -c pass (baseline)", [sys.executable, "-c", "pass"], None),
        ("gyroemu --help", [script, "--help"], TARGET_S),
        ("gyroemu --version", [script, "--version"], None),
        ("gyroemu scenarios", [script, "scenarios"], TARGET_S),
        ("gyroemu presets", [script, "presets"], TARGET_S),
    ]
    print(f"{'command':<28} {'median':>8} {'min':>8} {'max':>8}  target")
    with tempfile.TemporaryDirectory() as cwd:
        for label, command, target in cases:
            t = wall_times(command, args.repeats, cwd)
            verdict = (
                "" if target is None else ("met" if statistics.median(t) < target else "MISSED") + f" (< {target} s)"
            )
            print(f"{label:<28} {statistics.median(t):7.3f}s {min(t):7.3f}s {max(t):7.3f}s  {verdict}")


if __name__ == "__main__":
    main()
