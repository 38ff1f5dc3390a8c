"""The MEKF on the issue's simulated case: the consumer MEMS on the smooth manoeuvre, 6D, per seed.

    python tests/benchmarks/mekf_consumer_mems.py [--seeds 4] [--duration SECONDS]

Prints the inclination RMSE over the run (default: the scenario's own 300 s) and after its first
minute, and the error of the gyro-bias estimate across the vertical (x, y: the bias 6D can observe) at
the start, 30 s, 60 s and the end. The bias truth is ``Device.measure_held_still`` (its bias, drift,
rest bias and g-sensitivity, without what scale factor and misalignment make of the motion), averaged
over 1 s.
A script, not a test: about 5 s per seed. ``test_mekf.py`` asserts the issue's bars on seeds 0 and 1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.pipelines.estimation import Mekf, attitude_errors, rmse_deg, setup_for  # noqa: E402
from gyroemu.pipelines.mcap_io import truth_series  # noqa: E402
from gyroemu.sensors import load_device  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--duration", type=float, default=None, help="seconds (default: the scenario's)")
    args = parser.parse_args()
    scenario = load_scenario("smooth_manoeuvre")
    traj = scenario.simulate(duration=args.duration)
    print("| seed | inclination RMSE ° | after 60 s ° | bias error x,y °/s: 0 s | 30 s | 60 s | end |")
    print("|---|---|---|---|---|---|---|")
    for seed in range(args.seeds):
        device = load_device("consumer_mems", seed=seed)
        samples = device.measure(traj)
        est = Mekf(setup_for(device, scenario, use_mag=False)).process(samples.t, samples.gyro, samples.accel)
        err = attitude_errors(est.q_wb, truth_series(traj, samples).q_wb)
        bias = device.measure_held_still(traj).gyro
        half = int(0.5 * device.spec.rate_hz)

        def bias_error(k):
            k = min(max(k, half), len(samples.t) - half)
            return np.degrees(np.linalg.norm(est.gyro_bias[k, :2] - bias[k - half : k + half, :2].mean(axis=0)))

        at = [int(np.searchsorted(samples.t, s)) for s in (0.0, 30.0, 60.0, samples.t[-1])]
        print(
            f"| {seed} | {rmse_deg(err.inclination):.2f} | {rmse_deg(err.inclination[samples.t >= 60.0]):.2f} | "
            + " | ".join(f"{bias_error(k):.3f}" for k in at)
            + " |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
