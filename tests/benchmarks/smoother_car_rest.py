"""What the smoother does with a car that rests, then drives: inclination RMSE of the forward pass and of
the smoother over the rest and over the drive after it (issue #17; README, the NEES section).

    python tests/benchmarks/smoother_car_rest.py [--devices consumer_mems tactical_mems navigation_fog]
        [--seeds 0 1] [--rest-s 8] [--duration 130]

``car_drive`` (it rests for its first 8 s, then speeds up) measured by each device, 6D (the tactical and
navigation devices have no magnetometer; the heading is the Earth's rate's), smoothed with the defaults.
With a good gyro the tilt is about one constant over the drive, and the smoother takes it from every
window's gravity alike, the rest's, which no acceleration disturbs, weighing no more than the drive's.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from gyroemu.dynamics import load_scenario
from gyroemu.pipelines.estimation.mekf_smoother import smooth_log
from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg
from gyroemu.pipelines.estimation.setup import setup_for
from gyroemu.pipelines.formats.mcap_log import truth_series
from gyroemu.sensors import load_device


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", nargs="+", default=["consumer_mems", "tactical_mems", "navigation_fog"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--rest-s", type=float, default=8.0, help="the scenario's rest at the start, s")
    parser.add_argument("--duration", type=float, default=130.0)
    args = parser.parse_args()
    scenario = load_scenario("car_drive")
    traj = scenario.simulate(duration=args.duration)
    print("| device | seed | at rest: forward → smoothed, ° | driving: forward → smoothed, ° |")
    print("|---|---|---|---|")
    for name in args.devices:
        for seed in args.seeds:
            device = load_device(name, seed=seed)
            samples = device.measure(traj)
            t = np.asarray(samples.t, float) - samples.t[0]
            setup = replace(setup_for(device, scenario), use_mag=False)
            res = smooth_log(setup, t, samples.gyro, samples.accel, None)
            q_true = truth_series(traj, samples).q_wb
            forward = attitude_errors(res.forward.q_wb, q_true).inclination
            smoothed = attitude_errors(res.smoothed.q_wb, q_true).inclination
            rest = t < args.rest_s
            cells = [f"{rmse_deg(forward[part]):.2f} → {rmse_deg(smoothed[part]):.2f}" for part in (rest, ~rest)]
            print(f"| {name} | {seed} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
