"""Throughput of the prescribed-motion kinds, in samples per second, against a per-sample baseline.

Run ``python tests/benchmarks/bench_motions.py [--samples N] [--repeats R]`` (a script, not collected by
pytest). For each built-in scenario of :mod:`gyroemu.dynamics.motions` and :mod:`gyroemu.dynamics.vehicles` it times, on
N samples at the scenario's rate, the best of R runs after a warm-up, with one BLAS thread:

``world``
    ``spec.world_motion(t)``: the kind's closed forms (attitude, ω, α, position, velocity, acceleration
    relative to the world frame).
``earth``
    :func:`gyroemu.dynamics.trajectory.trajectory_from_world_motion` on that motion (Earth rate, Coriolis,
    gravity, magnetic field), as ns per sample, and its share of world + earth.
``simulate``
    ``spec.trajectory(t)``: world + earth, what ``Scenario.simulate`` returns. Target: at least
    10 M samples/s, end to end.
``loop``
    Baseline, measured in the same run: the same closed forms evaluated one sample at a time in a Python
    loop (``spec.evaluator()(t[k:k+1])``), on ``--loop-samples`` samples.

N samples at the scenario's rate span N / rate_hz seconds, mostly past the end of the file's
``duration_s`` for 10⁶ samples (where the car has stopped and the tumble rests on its last face).
``--in-duration`` samples the file's duration instead, at the rate that gives N samples, so that every
part of the motion (turns, bumps, moves) is in the figures.

The machine is shared: figures vary by tens of percent from run to run; best-of-R damps that, the load
averages printed before and after tell how busy the machine was, and ``--rounds K`` repeats the whole
measurement K times and prints the range of ``simulate`` per scenario.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # single-core figures; set before numpy loads BLAS

import argparse  # noqa: E402
import time  # noqa: E402

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.dynamics.trajectory import trajectory_from_world_motion  # noqa: E402

SCENARIOS = [
    "bench_static",
    "rate_table_constant",
    "rate_table_steps",
    "rate_table_tumble",
    "oscillation",
    "coning",
    "sculling",
    "smooth_manoeuvre",
    "car_drive",
]
TARGET = 10e6  # samples/s end to end (simulate)


def best_time(fn, repeats: int) -> float:
    """Seconds of the fastest of ``repeats`` calls, after one warm-up call."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def loop_rate(spec, t, samples: int) -> float:
    """Samples/s of the world motion evaluated one sample at a time in a Python loop (the kind's
    time-independent setup done once, as for a whole array)."""
    evaluate = spec.evaluator()
    start = time.perf_counter()
    for k in range(samples):
        evaluate(t[k : k + 1])
    return samples / (time.perf_counter() - start)


def measure(name: str, samples: int, repeats: int, loop_samples: int, in_duration: bool = False) -> dict:
    """The figures of one built-in scenario (see the module docstring)."""
    scenario = load_scenario(name)
    spec = scenario.spec
    if in_duration:
        t = scenario.times(rate_hz=(samples - 1) / scenario.duration_s)
    else:
        t = scenario.times(duration=(samples - 1) / scenario.rate_hz)
    n = len(t)
    env = spec.site.environment()
    m = spec.world_motion(t)

    def earth_in_one_call():
        return trajectory_from_world_motion(m.t, m.q_wb, m.omega_wb_b, m.alpha_wb_b, m.pos_w, m.vel_w, m.acc_w, env)

    world = best_time(lambda: spec.world_motion(t), repeats) / n
    earth = best_time(earth_in_one_call, repeats) / n
    simulate = best_time(lambda: spec.trajectory(t), repeats) / n
    loop = loop_rate(spec, t, min(loop_samples, n))
    return {
        "name": name,
        "kind": scenario.kind,
        "world": 1 / world,  # samples/s
        "earth_ns": earth * 1e9,
        "simulate": 1 / simulate,  # samples/s
        "earth_share": earth / (world + earth),  # of the time of the two parts of simulate
        "loop": loop,  # samples/s
    }


COLUMNS = [  # title, unit, width, format of the row's value
    ("scenario", "", 20, lambda r: f"{r['name']:<20}"),
    ("kind", "", 16, lambda r: f"{r['kind']:<16}"),
    ("world", "M/s", 8, lambda r: f"{r['world'] / 1e6:>8.1f}"),
    ("earth", "ns/sample", 9, lambda r: f"{r['earth_ns']:>9.0f}"),
    ("simulate", "M/s", 8, lambda r: f"{r['simulate'] / 1e6:>8.2f}"),
    ("earth share", "world+earth", 11, lambda r: f"{100 * r['earth_share']:>10.0f}%"),
    ("loop", "k/s", 7, lambda r: f"{r['loop'] / 1e3:>7.1f}"),
    ("world/loop", "", 10, lambda r: f"{r['world'] / r['loop']:>10.0f}"),
]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=1_000_000, help="samples per run (default 10^6)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per figure, the best kept (default 3)")
    parser.add_argument("--loop-samples", type=int, default=2000, help="samples of the per-sample baseline")
    parser.add_argument("--scenarios", nargs="*", default=SCENARIOS, help="built-in scenario names")
    parser.add_argument(
        "--in-duration",
        action="store_true",
        help="sample the file's duration_s at the rate that gives N samples (every part of the motion)",
    )
    parser.add_argument(
        "--rounds", type=int, default=1, help="repeat the whole measurement; print the range of simulate"
    )
    args = parser.parse_args(argv)

    grid = "within each file's duration_s" if args.in_duration else "at each file's rate_hz"
    print(f"{args.samples:,} samples per run {grid}, best of {args.repeats}, one BLAS thread")
    print("load average (1, 5, 15 min): {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    simulate = {name: [] for name in args.scenarios}  # M samples/s of each round
    for round_ in range(args.rounds):
        print(f"\nround {round_ + 1} of {args.rounds}" if args.rounds > 1 else "")
        print(" ".join(f"{title:>{width}}" if unit else f"{title:<{width}}" for title, unit, width, _ in COLUMNS))
        print(" ".join(f"{unit:>{width}}" for _, unit, width, _ in COLUMNS))
        rows = []
        for name in args.scenarios:
            rows.append(measure(name, args.samples, args.repeats, args.loop_samples, args.in_duration))
            simulate[name].append(rows[-1]["simulate"] / 1e6)
            flag = "" if rows[-1]["simulate"] >= TARGET else "  (simulate < 10 M/s)"
            print(" ".join(cell(rows[-1]) for *_, cell in COLUMNS) + flag)

        short = [r["name"] for r in rows if r["simulate"] < TARGET]
        print(
            f"\nsimulate (end to end) at >= {TARGET / 1e6:.0f} M samples/s: "
            + (f"all but {', '.join(short)}" if short else "all")
        )
        earth = sorted(r["earth_ns"] for r in rows)
        shares = sorted(r["earth_share"] for r in rows)
        print(
            f"trajectory_from_world_motion: {earth[0]:.0f}-{earth[-1]:.0f} ns/sample, "
            f"{100 * shares[0]:.0f}-{100 * shares[-1]:.0f}% of world + earth; alone it would allow "
            f"{1e3 / earth[-1]:.0f}-{1e3 / earth[0]:.0f} M samples/s."
        )
    print("load average (1, 5, 15 min): {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    if args.rounds > 1:
        print(f"\nsimulate, M samples/s over {args.rounds} rounds (min-max):")
        for name, rates in simulate.items():
            flag = "" if min(rates) >= TARGET / 1e6 else "  (below 10 M/s in some round)"
            print(f"  {name:<20} {min(rates):6.2f}-{max(rates):6.2f}{flag}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
