"""Peak memory and throughput of ``gyroemu allan`` (``allan_of_log``) on long static MCAP logs.

    python tests/benchmarks/bench_allan_stream.py [--durations 600 3600 43200] [--rate 400] [--in-memory]

A script, not a test (pytest does not collect it). For each duration it writes a static gyro log
(``/imu`` of a navigation-grade gyro at ``--rate`` Hz, device ``navigation_rlg``'s config in the
metadata): white rate noise of 0.002 deg/sqrt(h), a random walk of the rate, a bias of 1e-5 rad/s
and the earth rate on z, synthesised and written in blocks with
:class:`gyroemu.pipelines.formats.mcap_log.McapLogWriter`, so that writing does not need the whole run
in memory. Then, in a fresh Python process per measurement, it runs
:func:`gyroemu.pipelines.jobs.allan.allan_of_log` and reports the child's peak resident set
(``resource.getrusage(RUSAGE_SELF).ru_maxrss`` in the child) and the samples analysed per second
(the call only, imports excluded).

Baseline, in the same run: the peak RSS of a process that only imports ``gyroemu.pipelines.jobs.allan``.
With ``--in-memory`` also the whole-log path the command used before (``read_mcap`` and
``allan_report``), whose memory grows with the log. Flat memory: the streamed rows' RSS less the
baseline is the same for every duration.

Linux carries a process's peak RSS across ``execve`` (``ru_maxrss`` of a child is at least what its
parent had resident when it forked), so this script keeps itself small: it imports no gyroemu and
writes the logs in child processes too. Each child also reports ``VmHWM`` (``/proc/self/status``),
the peak of its own address space after ``exec``, which that carry-over cannot touch.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BLOCK = 1 << 16
EARTH_RATE = 7.292115e-5  # rad/s

CHILD = {
    "import": "import gyroemu.pipelines.jobs.allan\nn = 0",
    "streamed": (
        "from gyroemu.pipelines.jobs.allan import allan_of_log\n"
        "start = time.perf_counter()\n"
        "report = allan_of_log(path)\n"
        "elapsed = time.perf_counter() - start\n"
        "n = len(report.fits[0].allan.tau)"
    ),
    "in-memory": (
        "import numpy as np\n"
        "from gyroemu.pipelines.formats.mcap_log import read_mcap\n"
        "from gyroemu.pipelines.jobs.allan import allan_report\n"
        "start = time.perf_counter()\n"
        "samples = read_mcap(path).device.samples\n"
        "report = allan_report(samples.gyro, float(np.median(np.diff(samples.t))))\n"
        "elapsed = time.perf_counter() - start\n"
        "n = len(report.fits[0].allan.tau)"
    ),
}


def write_log(path: Path, duration: float, rate: float, seed: int = 0) -> int:
    """A static navigation-grade gyro log of ``duration`` s at ``rate`` Hz; returns its sample count."""
    import numpy as np

    from gyroemu.pipelines.formats.mcap_log import McapLogWriter, Recording
    from gyroemu.sensors import load_device
    from gyroemu.sensors.samples import ImuSamples

    device = load_device("navigation_rlg", seed=seed)
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    arw = np.radians(0.002) / 60.0  # rad/sqrt(s)
    white = arw * np.sqrt(rate)  # rad/s per sample
    walk = np.radians(0.0005) / 3600.0 / 60.0 / np.sqrt(rate)  # rad/s per step of the rate's random walk
    level = np.array([1e-5, -1e-5, 1e-5 + EARTH_RATE])
    drift = np.zeros(3)
    with McapLogWriter(path) as log:
        for start in range(0, n, BLOCK):
            k = np.arange(start, min(n, start + BLOCK))
            steps = np.cumsum(rng.normal(0.0, walk, (len(k), 3)), axis=0)
            gyro = level + drift + steps + rng.normal(0.0, white, (len(k), 3))
            drift = drift + steps[-1]
            accel = np.tile([0.0, 0.0, 9.80665], (len(k), 1))
            samples = ImuSamples(
                t=(k + 1) / rate, gyro=gyro, accel=accel, mag=np.full((len(k), 3), np.nan), device=device.name
            )
            log.write(Recording(samples, device=device))
    return n


def measure(what: str, path: Path) -> dict:
    """Run ``what`` (a key of :data:`CHILD`) in a fresh interpreter: its peak RSS (``ru_maxrss`` and
    ``VmHWM``, MiB) and time (s)."""
    code = (
        "import json, resource, sys, time\n"
        f"path = {str(path)!r}\n"
        "elapsed = 0.0\n"
        f"{CHILD[what]}\n"
        "rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024\n"
        "hwm = next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM')) / 1024\n"
        "print(json.dumps({'rss_mib': rss, 'hwm_mib': hwm, 'seconds': elapsed, 'taus': n}))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def write_in_child(path: Path, duration: float, rate: float) -> int:
    """:func:`write_log` in a child process, so that this one stays small (see the notes)."""
    done = subprocess.run(
        [sys.executable, __file__, "--write", str(path), str(duration), str(rate)],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(done.stdout.split()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--durations", type=float, nargs="+", default=[600.0, 3600.0, 43200.0], help="seconds of log")
    parser.add_argument("--rate", type=float, default=400.0, help="sample rate, Hz (default 400)")
    parser.add_argument("--in-memory", action="store_true", help="also measure read_mcap + allan_report")
    parser.add_argument("--write", nargs=3, metavar=("PATH", "DURATION", "RATE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.write:  # the child that writes a log
        print(write_log(Path(args.write[0]), float(args.write[1]), float(args.write[2])))
        return 0

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        baseline = measure("import", Path(folder) / "none.mcap")
        for duration in args.durations:
            path = Path(folder) / f"static_{duration:g}s.mcap"
            start = time.perf_counter()
            n = write_in_child(path, duration, args.rate)
            written = time.perf_counter() - start
            print(
                f"wrote {path.name}: {n} samples, {path.stat().st_size / 2**20:.1f} MiB in {written:.1f} s",
                flush=True,
            )
            for what in ("streamed", "in-memory") if args.in_memory else ("streamed",):
                result = measure(what, path)
                rows.append((what, duration, n, result))

    print()
    print(
        f"baseline (import gyroemu.pipelines.jobs.allan only): peak RSS {baseline['rss_mib']:.1f} MiB "
        f"(VmHWM {baseline['hwm_mib']:.1f} MiB)"
    )
    print()
    header = f"{'path':<10}{'duration s':>11}{'samples':>11}{'taus':>6}{'ru_maxrss MiB':>15}{'- baseline':>12}"
    header += f"{'VmHWM MiB':>11}{'time s':>9}{'samples/s':>12}"
    print(header)
    for what, duration, n, r in rows:
        over = r["rss_mib"] - baseline["rss_mib"]
        print(
            f"{what:<10}{duration:>11g}{n:>11}{r['taus']:>6}{r['rss_mib']:>15.1f}{over:>12.1f}"
            f"{r['hwm_mib']:>11.1f}{r['seconds']:>9.2f}{n / r['seconds']:>12.3g}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
