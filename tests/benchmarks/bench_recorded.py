"""Speed of a recorded motion: a 10-minute trajectory at 120 Hz made a 1 kHz truth.

The motion is ``smooth_manoeuvre``'s first 600 s sampled at 120 Hz, with motion-capture noise (0.1 mm
per coordinate, 0.05° per axis), written as a TUM file. Timed, each the median of ``--repeats`` runs:

- **gyroemu**: read the file, choose both smoothings by GCV, fit the splines and evaluate the
  Trajectory (attitude, rate, angular acceleration, position, velocity, specific force, field) at
  1 kHz over the whole span;
- **baseline**: scipy's own splines on the same samples, evaluated at the same instants with the same
  derivatives: ``RotationSpline`` (attitude, rate, angular acceleration; an interpolant, no smoothing)
  and ``CubicSpline`` (position and its two derivatives), after the same file reading.

The target (issue 14) is under 5 s for gyroemu.

    python tests/benchmarks/bench_recorded.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

TARGET_S = 5.0
DURATION_S, RECORD_HZ, OUT_HZ = 600.0, 120.0, 1000.0


def make_recording(folder: Path) -> Path:
    from gyroemu.dynamics import load_scenario
    from gyroemu.dynamics.rotation import quat_from_rotvec, quat_multiply
    from gyroemu.pipelines.formats.motion_files import write_tum

    truth = load_scenario("smooth_manoeuvre").simulate(duration=DURATION_S, rate_hz=RECORD_HZ)
    rng = np.random.default_rng(0)
    q = quat_multiply(truth.q_wb, quat_from_rotvec(np.radians(0.05) * rng.standard_normal((len(truth), 3))))
    p = truth.pos_w + 1e-4 * rng.standard_normal(truth.pos_w.shape)
    tum = folder / "motion.tum"
    write_tum(tum, truth.t, q, p)
    (folder / "motion.toml").write_text('kind = "recorded"\npath = "motion.tum"\nformat = "tum"\n')
    return folder / "motion.toml"


def run_gyroemu(scenario: Path) -> int:
    from gyroemu.dynamics import load_scenario

    return len(load_scenario(scenario).simulate(rate_hz=OUT_HZ))


def run_baseline(scenario: Path) -> int:
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation, RotationSpline

    from gyroemu.pipelines.formats.motion_files import read_tum

    samples = read_tum(scenario.with_suffix(".tum"))
    t = samples.t - samples.t[0]
    out = np.arange(int(round(t[-1] * OUT_HZ)) + 1) / OUT_HZ
    rotation = RotationSpline(t, Rotation.from_quat(samples.q_wb, scalar_first=True))
    rotation(out).as_quat()
    rotation(out, 1)
    rotation(out, 2)
    position = CubicSpline(t, samples.pos_w, axis=0)
    for nu in (0, 1, 2):
        position(out, nu)
    return len(out)


def median_time(fn, arg, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn(arg)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        scenario = make_recording(Path(folder))
        n = run_gyroemu(scenario)  # warm-up: numba's compilation and imports
        run_baseline(scenario)
        ours = median_time(run_gyroemu, scenario, args.repeats)
        base = median_time(run_baseline, scenario, args.repeats)
    print(f"{DURATION_S:g} s at {RECORD_HZ:g} Hz -> {n} samples at {OUT_HZ:g} Hz (median of {args.repeats})")
    print(f"  gyroemu recorded (GCV smoothing, Trajectory): {ours:6.2f} s   target < {TARGET_S:g} s")
    print(f"  baseline scipy RotationSpline + CubicSpline:  {base:6.2f} s   (interpolation, no smoothing)")
    print(f"  ratio: {ours / base:.2f}")


if __name__ == "__main__":
    main()
