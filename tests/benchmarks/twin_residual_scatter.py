"""How far one draw of the twin's residual Allan deviation at rest can be trusted (issue 15's residual band).

The twin compares the real sensor's residual at rest with its twins' (``gyroemu twin``, README "The
twin"), pooled over the rest phases of the recordings. The real curve is one draw of the sensor's
noise over about 260 s of rest; this script measures what a *perfect* twin would show against it.
It draws the device (default ``aktos_t_broad``) at rest on ``bench_static``, each draw with its own
seed, cuts each draw into the real recordings' rest layout (the phases ``gyroemu twin`` finds in the
given BROAD trials, same lengths), and reads each draw as the twin reads its residuals
(:func:`gyroemu.pipelines.twin.residuals.residual_allan`). Then, over random pairings, one draw stands
for the real recording and the RMS of ``--seeds`` others for the twins, exactly the ratio the twin
reports. Printed: per τ and axis the relative standard deviation of one draw; the mean of all draws
against the device's long run (the estimator is unbiased, so they agree within the draws' scatter);
and how often a twin drawn from the very process of the "real" curve meets the band 0.8–1.25 at
τ = 10 s on all six axes, and at every τ.

Run: ``python tests/benchmarks/twin_residual_scatter.py ../shared/datasets/broad/{02,07,11,16}_*.hdf5``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.identification import find_rest_phases
from gyroemu.pipelines.jobs.identify import read_trial
from gyroemu.pipelines.twin import TAUS_S, residual_allan
from gyroemu.sensors import load_device
from gyroemu.sensors.allan import allan_deviation

BAND = (0.8, 1.25)


def rest_layout(trials: list[Path]) -> list[int]:
    """Sample counts of the rest phases found in the trials (as ``gyroemu twin`` finds them)."""
    lengths = []
    for path in trials:
        data = read_trial(path)
        lengths += [p.stop - p.start for p in find_rest_phases(data.t, data.gyro, data.accel)]
    return lengths


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="+", type=Path, help="BROAD trials whose rest layout is used")
    parser.add_argument("--device", default="aktos_t_broad")
    parser.add_argument("--draws", type=int, default=60, help="independent draws of the rest layout")
    parser.add_argument("--seeds", type=int, default=5, help="twins per comparison, as gyroemu twin --seeds")
    parser.add_argument("--pairings", type=int, default=4000)
    args = parser.parse_args()

    lengths = rest_layout(args.trials)
    scenario = load_scenario("bench_static")
    gap = 64  # samples between phases: independent stretches of one run
    adev = []
    long_run = None
    for seed in range(args.draws):
        device = load_device(args.device, seed=seed)
        rate = float(device.spec.rate_hz)
        duration = (sum(lengths) + gap * (len(lengths) + 1)) / rate
        samples = device.measure(scenario.simulate(duration=duration + 1.0))
        x = np.concatenate([samples.gyro, samples.accel], axis=1)
        segments, start = [], gap
        for n in lengths:
            segments.append(x[start : start + n])
            start += n + gap
        adev.append(
            np.concatenate(
                [
                    residual_allan([s[:, :3] for s in segments], 1 / rate)[0],
                    residual_allan([s[:, 3:] for s in segments], 1 / rate)[0],
                ],
                axis=1,
            )
        )
        if seed == 0:  # the device's own long run, for the estimator's bias
            run = device.measure(scenario.simulate(duration=3000.0))
            y = np.concatenate([run.gyro, run.accel], axis=1)
            long_run = np.array(
                [allan_deviation(y[:, j] - y[:, j].mean(), 1 / rate, taus=TAUS_S).adev for j in range(6)]
            ).T
    a = np.array(adev)  # (draws, τ, 6)
    mean = np.sqrt(np.nanmean(a**2, axis=0))
    spread = np.nanstd(a, axis=0) / mean
    print(f"{args.device}: {len(lengths)} rest phases, {sum(lengths) / rate:.1f} s; {args.draws} draws")
    print("tau s   | one draw's relative sd: gyro x y z, accel x y z | mean of draws / long run")
    for i, tau in enumerate(TAUS_S):
        sd = " ".join(f"{v:5.1%}" for v in spread[i])
        bias = " ".join(f"{v:5.2f}" for v in mean[i] / long_run[i])
        print(f"{tau:7.3g} | {sd} | {bias}")

    rng = np.random.default_rng(0)
    at_10 = everywhere = 0
    for _ in range(args.pairings):
        real = int(rng.integers(len(a)))
        twins = rng.choice(np.delete(np.arange(len(a)), real), args.seeds, replace=False)
        ratio = np.sqrt(np.mean(a[twins] ** 2, axis=0)) / a[real]
        inside = (ratio >= BAND[0]) & (ratio <= BAND[1])
        at_10 += bool(inside[-1].all())
        everywhere += bool(inside.all())
    print(
        f"a twin of the very process ({args.seeds} seeds) meets {BAND[0]}-{BAND[1]} on all six axes: "
        f"at tau {TAUS_S[-1]:g} s in {at_10 / args.pairings:.0%} of pairings, at every tau in "
        f"{everywhere / args.pairings:.0%}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
