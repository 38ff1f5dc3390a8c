"""Where the smoother's 6D inclination loses to offlineVQF's on BROAD, timed alike: the tilt recipe, not the bias.

    python tests/benchmarks/broad_tilt_recipes.py [--trials 02 07 ...] [--tau 2 4 6]

Every attitude is turned on by the gyro's latency (``aktos_t_broad``'s, :mod:`gyroemu.pipelines.estimation.latency`),
so that what separates the estimators is their tilt, not their timing (README, "The sensors' latencies").

offlineVQF's tilt (Laidig & Seel 2023, its ``offline_vqf.cpp``) is a recipe of three steps: the gyro, its
bias removed, integrated into a pure strapdown attitude ``q₃`` (no corrections); the accelerometer
turned into ``q₃``'s frame and low-passed there with a zero-phase 2nd-order Butterworth (forward and
backward, cut-off √2 / (2π τ), τ 3 s); each attitude corrected by the shortest turn that takes the
low-passed force to the vertical. A zero-phase low-pass of the force holds a bounded-velocity model of
the motion (the mean acceleration over seconds is nil). The script runs the recipe on:

- offlineVQF's own bias: it reproduces offlineVQF (the check of this reimplementation);
- the smoother's bias, and the smoother's bias with its scale and misalignment ``(I − M̂)(ω − b̂)``: what
  the smoother's gyro states would give with offlineVQF's tilt;
- ``--tau``: the low-pass's τ besides offlineVQF's 3 s, to show where the recipe is best;
- offlineVQF's bias with the body's true acceleration taken out of the force first (an oracle: the
  optical reference point's acceleration, its positions low-passed at 5 Hz and differentiated twice,
  turned into ``q₃``'s frame by the reference attitude): what any model of the motion could at best
  gain on the recipe's bounded-velocity model.

Per trial, 6D inclination RMSE over BROAD's movement samples, degrees; the means last.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from broad_data import BROAD_DIR, trial_files  # noqa: E402  (tests/benchmarks is the script folder)

from gyroemu.dynamics.rotation import quat_from_matrix, quat_multiply  # noqa: E402
from gyroemu.pipelines.estimation.latency import advance_attitude  # noqa: E402
from gyroemu.pipelines.estimation.mekf_kernels import rotations_since_first  # noqa: E402
from gyroemu.pipelines.estimation.mekf_smoother import smooth_log  # noqa: E402
from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg  # noqa: E402
from gyroemu.pipelines.estimation.protocol import FilterSetup  # noqa: E402
from gyroemu.pipelines.formats.importers import read_broad  # noqa: E402
from gyroemu.sensors import load_device  # noqa: E402


def zero_phase_tilt(t: np.ndarray, rate: np.ndarray, accel: np.ndarray, tau_s: float) -> np.ndarray:
    """offlineVQF's tilt recipe (the module's notes): ``rate`` (N, 3) rad/s, the gyro with its errors
    removed, integrated into ``q₃``; ``accel`` (N, 3) m/s² in ``q₃``'s frame, low-passed zero-phase with
    τ ``tau_s``; returns ``q₃`` corrected (N, 4), heading free."""
    R = rotations_since_first(t, np.ascontiguousarray(rate))
    force = filtfilt(
        *butter(2, np.sqrt(2) / (2 * np.pi * tau_s), fs=1.0 / float(np.median(np.diff(t)))),
        np.einsum("nij,nj->ni", R, accel),
        axis=0,
    )
    up = force / np.linalg.norm(force, axis=1, keepdims=True)
    w = np.sqrt((up[:, 2] + 1) / 2)  # the shortest turn taking ``up`` to e_z
    turn = np.stack([w, 0.5 * up[:, 1] / w, -0.5 * up[:, 0] / w, np.zeros_like(w)], axis=1)
    return quat_multiply(turn, quat_from_matrix(R))


def true_acceleration(trial) -> np.ndarray:
    """The optical reference point's acceleration (N, 3), m/s², body axes: positions (NaN rows filled
    from the nearest valid one) low-passed at 5 Hz (zero-phase), differentiated twice, turned into the
    body by the reference attitude."""
    from gyroemu.dynamics.rotation import quat_to_matrix

    n, fs = len(trial), trial.rate_hz
    valid = np.flatnonzero(np.all(np.isfinite(trial.opt_quat), axis=1) & np.all(np.isfinite(trial.opt_pos), axis=1))
    nearest = valid[np.clip(np.searchsorted(valid, np.arange(n)), 0, len(valid) - 1)]
    position = filtfilt(*butter(2, 5.0, fs=fs), trial.opt_pos[nearest], axis=0)
    a_world = np.gradient(np.gradient(position, 1.0 / fs, axis=0), 1.0 / fs, axis=0)
    return np.einsum("nji,nj->ni", quat_to_matrix(trial.opt_quat[nearest]), a_world)


def main() -> int:
    from vqf import offlineVQF

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", nargs="+", default=None, help="trial numbers, e.g. 02 07 (default: all)")
    parser.add_argument("--tau", nargs="+", type=float, default=[2.0, 4.0, 6.0], help="low-pass τ besides 3 s")
    args = parser.parse_args()
    files = trial_files(args.trials)
    if not files:
        print(f"no BROAD trials in {BROAD_DIR}", file=sys.stderr)
        return 2
    latency = float(load_device("aktos_t_broad").spec.gyro.latency_s)
    columns = ["offlineVQF", "smoother", "recipe, its bias", "recipe, smoother's bias", "recipe, smoother's b̂, M̂"]
    columns += [f"recipe, smoother's b̂, M̂, τ {tau:g} s" for tau in args.tau]
    columns += ["recipe, its bias, the true acceleration taken out (oracle)"]
    rows = {}
    for path in files:
        trial = read_broad(path)
        t = np.arange(len(trial)) / trial.rate_hz
        gyro, accel = trial.gyro, trial.accel
        ovqf = offlineVQF(gyro, accel, None, 1.0 / trial.rate_hz)
        smooth = smooth_log(FilterSetup(rate_hz=trial.rate_hz, use_mag=False), t, gyro, accel)
        window = np.minimum(np.searchsorted(smooth.window_end, np.arange(len(t))), len(smooth.window_end) - 1)
        u = gyro - smooth.smoothed.gyro_bias
        corrected = u - np.einsum("nij,nj->ni", smooth.scale_misalignment[window], u)
        estimates = [
            ovqf["quat6D"],
            smooth.smoothed.q_wb,
            zero_phase_tilt(t, gyro - ovqf["bias"], accel, 3.0),
            zero_phase_tilt(t, u, accel, 3.0),
            zero_phase_tilt(t, corrected, accel, 3.0),
        ] + [zero_phase_tilt(t, corrected, accel, tau) for tau in args.tau]
        estimates.append(zero_phase_tilt(t, gyro - ovqf["bias"], accel - true_acceleration(trial), 3.0))
        rows[path.stem[:2]] = [
            rmse_deg(
                attitude_errors(advance_attitude(q, gyro, None, latency), trial.opt_quat).inclination, trial.movement
            )
            for q in estimates
        ]
        print(f"trial {path.stem} done", file=sys.stderr, flush=True)
    print(f"6D inclination RMSE, °, every attitude turned on by the gyro's latency ({latency * 1e3:.3f} ms)\n")
    print("| trial | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for trial, values in rows.items():
        print(f"| {trial} | " + " | ".join(f"{v:.3f}" for v in values) + " |")
    means = np.mean(list(rows.values()), axis=0)
    print(f"| **mean of {len(rows)}** | " + " | ".join(f"**{v:.3f}**" for v in means) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
