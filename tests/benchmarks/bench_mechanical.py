"""Benchmark: the spinning-rotor gyro mechanisms against real time, with a solve_ivp baseline.

Run: ``python tests/benchmarks/bench_mechanical.py [--seconds 60] [--output-rate-hz 1000] [--repeats 3]``
(a script, not collected by pytest). For each mechanism (rate gyro; rate-integrating gyro, rebalanced
and open-loop; free-gyro pair with bearing friction) it prints

* its inner rate at the output rate, and the wall time of ``respond`` over ``--seconds`` of a
  tumbling carrier (three-axis rates of 0.3–0.7 rad/s at 0.3–1.7 Hz), best of ``--repeats`` after a
  warm-up that loads numba's compiled kernels; then **seconds of signal per second of wall time**
  (× real time), against the target of 100;
* a baseline measured in the same run: ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-8, atol 1e-12
  of the state's scale) on the same equations of motion (the gimbal ODE with its cross-coupling
  torque for the single-gimbal gyros, the friction precession (4) of ``free_gyro.py`` for the pair),
  evaluated at the same inner samples, over a span of ``--baseline-seconds`` and extrapolated (its
  cost is linear in the span), with the largest difference between the two on that span. The
  baseline counts the ODE solve only, not the indicated outputs, so the ratio understates the gain.

Everything runs on one thread (numba kernels are serial; BLAS pools are limited to one thread).
Exit status 1 if a mechanism runs slower than 100 × real time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from timing import best_time  # noqa: E402  (tests/benchmarks is the script folder)

from gyroemu.dynamics.rotation import body_rate_from_euler_zyx, quat_conjugate, quat_from_euler_zyx, quat_multiply  # noqa: E402
from gyroemu.sensors.free_gyro import FreeGyro, _spin_rate  # noqa: E402
from gyroemu.sensors.mechanism import GyroTruth  # noqa: E402
from gyroemu.sensors.rate_gyro import RateGyro, sdf_axes, simulate_gimbal  # noqa: E402
from gyroemu.sensors.rate_integrating import RateIntegratingGyro  # noqa: E402

TARGET = 100.0  # × real time

# Carrier: roll, pitch, yaw = A sin(2π f t + p) + r t (rad), a tumbling vehicle.
AMPLITUDE = np.array([0.10, 0.06, 0.20])
FREQUENCY_HZ = np.array([1.1, 1.7, 0.3])
PHASE = np.array([0.0, 0.5, 1.0])
YAW_RATE = 0.05


def carrier(t: np.ndarray) -> GyroTruth:
    """Truth on the grid ``t``: ω and α from the Euler angles' closed-form derivatives."""
    w = 2 * np.pi * FREQUENCY_HZ
    arg = np.outer(t, w) + PHASE
    rpy = AMPLITUDE * np.sin(arg) + np.outer(t, [0.0, 0.0, YAW_RATE])
    rates = AMPLITUDE * w * np.cos(arg) + [0.0, 0.0, YAW_RATE]
    accels = -AMPLITUDE * w**2 * np.sin(arg)
    omega, alpha = body_rate_from_euler_zyx(rpy, rates, accels)
    m = t.size
    return GyroTruth(
        t=t,
        dt=float(t[1] - t[0]),
        omega=omega,
        alpha=alpha,
        specific_force=np.zeros((m, 3)),
        q_is=quat_from_euler_zyx(rpy),
        temperature_degC=np.full(m, 25.0),
    )


# --------------------------------------------------------------------------------------------------
# Baselines: the same equations of motion through solve_ivp
# --------------------------------------------------------------------------------------------------


def gimbal_baseline(gyro, truth: GyroTruth, states_ours: np.ndarray):
    """solve_ivp on ẋ = A x + B u(θ, t) for the three gyros at once (3n states), u from (1) of
    rate_gyro.py with ω, ω' linearly interpolated between samples (the hold the kernel assumes)."""
    a, b = gyro.state_space()
    n = a.shape[0]
    w_ia, w_sra, a_oa = sdf_axes(truth)
    h, j = gyro.spin_momentum, gyro.gimbal_inertia_kgm2
    t = truth.t

    def rhs(time_s, x):
        x = x.reshape(3, n)
        k = min(int(time_s / truth.dt), t.size - 2)
        s = (time_s - t[k]) / truth.dt
        wi = (1 - s) * w_ia[k] + s * w_ia[k + 1]
        ws = (1 - s) * w_sra[k] + s * w_sra[k + 1]
        aa = (1 - s) * a_oa[k] + s * a_oa[k + 1]
        u = h * (wi * np.cos(x[:, 0]) - ws * np.sin(x[:, 0])) - j * aa
        return (x @ a.T + u[:, None] * b).ravel()

    scale = np.abs(states_ours).max(axis=(0, 1)) + 1e-30
    sol = solve_ivp(
        rhs, (t[0], t[-1]), states_ours[0].ravel(), method="RK45", t_eval=t, rtol=1e-8, atol=np.tile(1e-12 * scale, 3)
    )
    theirs = sol.y.T.reshape(-1, 3, n)
    return np.abs(theirs[..., 0] - states_ours[..., 0]).max() / np.abs(states_ours[..., 0]).max()


def free_gyro_baseline(gyro: FreeGyro, truth: GyroTruth, spins_ours: np.ndarray):
    """solve_ivp on the friction precession (4) of free_gyro.py for both rotors (6 states), with the
    carrier's attitude and rate linearly interpolated between samples."""
    q_rel = quat_multiply(quat_conjugate(truth.q_is[0]), truth.q_is)
    omega, t, h = truth.omega, truth.t, gyro.spin_momentum
    args = (
        h,
        gyro.outer_viscous_friction_n_m_s_per_rad,
        gyro.outer_coulomb_friction_n_m,
        gyro.inner_viscous_friction_n_m_s_per_rad,
        gyro.inner_coulomb_friction_n_m,
        np.sin(np.radians(gyro.gimbal_lock_margin_deg)) ** 2,
    )

    def rhs(time_s, x):
        k = min(int(time_s / truth.dt), t.size - 2)
        s = (time_s - t[k]) / truth.dt
        q = (1 - s) * q_rel[k] + s * q_rel[k + 1]
        q /= np.linalg.norm(q)
        w = (1 - s) * omega[k] + s * omega[k + 1]
        return np.concatenate([_spin_rate(q, w, x[:3], *args), _spin_rate(q, w, x[3:], *args)])

    sol = solve_ivp(rhs, (t[0], t[-1]), spins_ours[0].ravel(), method="RK45", t_eval=t, rtol=1e-8, atol=1e-12)
    theirs = sol.y.T.reshape(-1, 2, 3)
    drift = np.abs(spins_ours - spins_ours[0]).max()
    return np.abs(theirs - spins_ours).max() / max(drift, 1e-30)


# --------------------------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="signal duration per run, s")
    parser.add_argument("--output-rate-hz", type=float, default=1000.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--baseline-seconds", type=float, default=2.0, help="span of the solve_ivp baseline, s")
    args = parser.parse_args()

    mechanisms = {
        "rate gyro": RateGyro(),
        "rate-integrating, rebalanced": RateIntegratingGyro(),
        "rate-integrating, open loop": RateIntegratingGyro(torque_rebalance=False, stop_angle_deg=89.0),
        "free-gyro pair, friction": FreeGyro(),
    }
    rng = np.random.default_rng(0)
    print(
        f"{args.seconds:g} s of a tumbling carrier per run, output {args.output_rate_hz:g} Hz, best of "
        f"{args.repeats}; baseline solve_ivp RK45 over {args.baseline_seconds:g} s, extrapolated\n"
    )
    print(
        f"{'mechanism':30s} {'inner Hz':>9s} {'wall s':>8s} {'x real time':>12s} {'baseline x':>11s} "
        f"{'speed-up':>9s} {'baseline diff':>14s}"
    )
    ok = True
    for name, gyro in mechanisms.items():
        inner = gyro.inner_rate_hz(args.output_rate_hz)
        truth = carrier(np.arange(int(round(args.seconds * inner)) + 1) / inner)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            seconds = best_time(lambda: gyro.respond(truth, rng), args.repeats)
        speed = args.seconds / seconds

        short = carrier(np.arange(int(round(args.baseline_seconds * inner)) + 1) / inner)
        if isinstance(gyro, FreeGyro):
            spins = gyro._spins(quat_multiply(quat_conjugate(short.q_is[0]), short.q_is), short.omega, short.dt)
            run_baseline = lambda: free_gyro_baseline(gyro, short, spins)  # noqa: E731
        else:  # the kernel's states from rest, without stops, for the comparison
            a, b = gyro.state_space()
            w_ia, w_sra, a_oa = sdf_axes(short)
            states = simulate_gimbal(
                a,
                b,
                short.dt,
                np.zeros((3, a.shape[0])),
                gyro.spin_momentum,
                gyro.gimbal_inertia_kgm2,
                w_ia,
                w_sra,
                a_oa,
                np.inf,
            )
            run_baseline = lambda: gimbal_baseline(gyro, short, states)  # noqa: E731
        start = time.perf_counter()
        difference = run_baseline()
        baseline_speed = args.baseline_seconds / (time.perf_counter() - start)

        ok &= speed >= TARGET
        print(
            f"{name:30s} {inner:9.0f} {seconds:8.3f} {speed:12.0f} {baseline_speed:11.1f} "
            f"{speed / baseline_speed:9.0f} {difference:14.1e}"
        )
    print(
        "\nbaseline diff: largest difference from solve_ivp over its span, relative to the largest gimbal angle\n"
        "(single-gimbal gyros: the kernel's second-order error in the θ-dependent cross-coupling torque) or to\n"
        "the largest rotor drift (free gyro: Heun's step across the Coulomb torque's sign changes)"
    )
    print(f"target {TARGET:g} x real time: {'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
