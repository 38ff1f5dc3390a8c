"""Speed of the optical gyro mechanisms (fibre-optic, ring laser) against real time, with baselines
measured in the same run.

    python tests/benchmarks/bench_optical.py [--seconds 20] [--rlg-output-hz 1000] [--fog-output-hz 2000]
                                             [--repeats 3] [--no-device]

A script, not a test (pytest does not collect it). Each mechanism runs a three-axis triad through
``respond`` on the inner grid it asks for at its output rate (:meth:`inner_rate_hz`: the output rate
itself for the FOG, the 32 kHz ``simulation_rate_hz`` for the dithered RLG, which must resolve its
dither and lock-in crossings), in chunks of ``gyroemu.sensors.device_run.BLOCK_INNER_SAMPLES`` carrying their state,
as the IMU feeds them. The truth is a manoeuvring vehicle (rates up to ~0.5 rad/s); making it is not
timed. Each figure is the best of ``--repeats`` runs after a warm-up that loads the numba kernels;
"× real time" is simulated seconds per wall-clock second. Target: 100× for every mechanism case.

Baselines, measured here over a short span and extrapolated linearly to one simulated second of a
three-axis triad:

* RLG: Adler's equation dψ/dt = K(Ω + dθ_d/dt) − KΩ_L sin ψ integrated directly, resolving the beat
  (≤ 0.1 rad of beat phase per step at the peak dither rate: ~1.6·10⁷ steps per second per axis),
  (a) by classic RK4 in a plain Python loop, (b) by ``scipy.integrate.solve_ivp`` (RK45, rtol 10⁻⁸),
  (c) by the same RK4 compiled with numba;
* FOG: the detector simulated sample by sample (16 samples per period of the 511 kHz biasing
  modulation, shot and RIN noise drawn per sample, numpy) and demodulated, which is what the closed
  forms of ``sensors/fog.py`` replace.

With ``--device`` (default), also the whole IMU (``Device.measure``: truth interpolation at the inner
rate, mechanism, error layer) on a trajectory of the same length. Everything runs on one thread.
Exit status 1 if a mechanism case misses the target.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numba  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.sensors.device_run import BLOCK_INNER_SAMPLES  # noqa: E402
from gyroemu.sensors.fog import ELEMENTARY_CHARGE, FiberOpticGyro  # noqa: E402
from gyroemu.sensors.mechanism import GyroTruth  # noqa: E402
from gyroemu.sensors.rlg import RingLaserGyro  # noqa: E402

TARGET = 100.0


def vehicle(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body rates (M, 3), rad/s, and their derivatives, of a manoeuvring vehicle."""
    omega = np.column_stack([0.3 * np.sin(1.3 * t), 0.2 * np.cos(0.7 * t), 0.05 + 0.5 * np.sin(0.31 * t)])
    alpha = np.column_stack([0.39 * np.cos(1.3 * t), -0.14 * np.sin(0.7 * t), 0.155 * np.cos(0.31 * t)])
    return omega, alpha


def truth_chunk(t: np.ndarray, dt: float) -> GyroTruth:
    omega, alpha = vehicle(t)
    zero = np.zeros_like(omega)
    return GyroTruth(
        t=t,
        dt=dt,
        omega=omega,
        alpha=alpha,
        specific_force=zero,
        q_is=np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1)),
        temperature_degC=np.full(len(t), 25.0),
    )


def run_mechanism(gyro, seconds: float, inner_hz: float) -> tuple[float, float]:
    """(wall, CPU) time of ``respond`` over ``seconds`` of truth at ``inner_hz``, in IMU-sized chunks, s."""
    dt = 1.0 / inner_hz
    total = int(round(seconds * inner_hz))
    chunks = [
        truth_chunk(np.arange(first, min(first + BLOCK_INNER_SAMPLES, total) + 1) * dt, dt)
        for first in range(0, total, BLOCK_INNER_SAMPLES)
    ]  # made before the clock starts
    rng, state = np.random.default_rng(0), {}
    start, cpu = time.perf_counter(), time.process_time()
    for chunk in chunks:
        gyro.respond(chunk, rng, state)
    return time.perf_counter() - start, time.process_time() - cpu


def best(run, repeats: int):
    """The fastest of ``repeats`` runs (after a warm-up that loads the numba kernels)."""
    run()
    return min(run() for _ in range(repeats))


# --------------------------------------------------------------------------------------------------
# Baselines: Adler's equation resolved fringe by fringe; the FOG detector sample by sample
# --------------------------------------------------------------------------------------------------


def adler_rhs(gyro: RingLaserGyro):
    """dψ/dt(t, ψ) for one axis: a constant vehicle rate and the mean sinusoidal dither."""
    K, k_lock = gyro.beat_phase_per_rad, gyro.beat_phase_per_rad * gyro.lock_in_rate
    w_d, amplitude, rate = 2 * math.pi * gyro.dither_frequency_hz, gyro.dither_amplitude, 0.2

    def rhs(t, psi):
        return K * (rate + amplitude * w_d * math.cos(w_d * t)) - k_lock * math.sin(psi)

    return rhs


def resolving_step(gyro: RingLaserGyro) -> float:
    """A step of 0.1 rad of beat phase at the peak dither rate, s."""
    return 0.1 / (gyro.beat_phase_per_rad * (gyro.dither_rate_amplitude + 0.5))


def adler_python(gyro: RingLaserGyro, span: float) -> float:
    """Wall time of classic RK4 in a plain Python loop over ``span`` s, one axis."""
    f, h = adler_rhs(gyro), resolving_step(gyro)
    psi, t = 0.0, 0.0
    start = time.perf_counter()
    for _ in range(int(span / h)):
        k1 = f(t, psi)
        k2 = f(t + h / 2, psi + h / 2 * k1)
        k3 = f(t + h / 2, psi + h / 2 * k2)
        k4 = f(t + h, psi + h * k3)
        psi += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return time.perf_counter() - start


def adler_solve_ivp(gyro: RingLaserGyro, span: float) -> float:
    """Wall time of scipy's RK45 (rtol 1e-8, atol 1e-8 rad) over ``span`` s, one axis."""
    f = adler_rhs(gyro)
    start = time.perf_counter()
    solve_ivp(lambda t, y: [f(t, y[0])], (0.0, span), [0.0], method="RK45", rtol=1e-8, atol=1e-8)
    return time.perf_counter() - start


@numba.njit(cache=True)
def _adler_rk4(K, k_lock, w_d, amplitude, rate, h, steps):
    psi, t = 0.0, 0.0
    for _ in range(steps):
        k1 = K * (rate + amplitude * w_d * math.cos(w_d * t)) - k_lock * math.sin(psi)
        k2 = K * (rate + amplitude * w_d * math.cos(w_d * (t + h / 2))) - k_lock * math.sin(psi + h / 2 * k1)
        k3 = K * (rate + amplitude * w_d * math.cos(w_d * (t + h / 2))) - k_lock * math.sin(psi + h / 2 * k2)
        k4 = K * (rate + amplitude * w_d * math.cos(w_d * (t + h))) - k_lock * math.sin(psi + h * k3)
        psi += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return psi


def adler_numba(gyro: RingLaserGyro, span: float) -> float:
    """Wall time of the same RK4 compiled with numba over ``span`` s, one axis."""
    h = resolving_step(gyro)
    args = (
        gyro.beat_phase_per_rad,
        gyro.beat_phase_per_rad * gyro.lock_in_rate,
        2 * math.pi * gyro.dither_frequency_hz,
        gyro.dither_amplitude,
        0.2,
        h,
    )
    _adler_rk4(*args, 10)  # compile
    start = time.perf_counter()
    _adler_rk4(*args, int(span / h))
    return time.perf_counter() - start


def fog_detector_samples(gyro: FiberOpticGyro, span: float, rng: np.random.Generator) -> float:
    """Wall time of simulating and demodulating the detector of three axes over ``span`` s, sample
    by sample (16 per modulation period), in blocks of 2¹⁸ samples."""
    fs = 16 * gyro.proper_frequency_hz
    n = int(span * fs)
    p0, responsivity = gyro.detector_power_uw * 1e-6, gyro.responsivity_a_per_w
    rin_sigma = math.sqrt(gyro.relative_intensity_noise_per_hz * fs / 2)
    start = time.perf_counter()
    for first in range(0, n, 1 << 18):
        t = np.arange(first, min(first + (1 << 18), n)) / fs
        carrier = np.cos(2 * math.pi * gyro.proper_frequency_hz * t)
        for axis in range(3):
            sagnac = gyro.scale_factor_s * vehicle(t[:1])[0][0, axis]
            power = 0.5 * p0 * (1 + np.cos(sagnac + gyro.modulation_depth_rad * carrier))
            power *= 1 + rin_sigma * rng.standard_normal(t.size)
            electrons = rng.poisson(responsivity * power / fs / ELEMENTARY_CHARGE)
            np.sum(electrons * carrier)  # the lock-in's first harmonic
    return time.perf_counter() - start


# --------------------------------------------------------------------------------------------------
# The whole IMU
# --------------------------------------------------------------------------------------------------


def device_run(kind: str, rate_hz: float, seconds: float, repeats: int) -> float:
    """Best wall time of ``Device.measure`` over a ``seconds``-long trajectory (made outside the clock)."""
    from gyroemu.dynamics import Environment, trajectory_from_world_motion
    from gyroemu.sensors import device_from_dict

    t = np.arange(int(round(seconds * 200)) + 1) / 200.0  # the trajectory at 200 Hz, the IMU interpolates
    omega, alpha = vehicle(t)
    zero = np.zeros_like(omega)
    traj = trajectory_from_world_motion(
        t, np.tile([1.0, 0, 0, 0], (len(t), 1)), omega, alpha, zero, zero, zero, Environment.inertial(9.81)
    )
    device = device_from_dict({"description": kind, "rate_hz": rate_hz, "gyro": {"mechanism": {"kind": kind}}})
    return best(lambda: _timed(lambda: device.measure(traj)), repeats)


def _timed(job) -> tuple[float, float]:
    start, cpu = time.perf_counter(), time.process_time()
    job()
    return time.perf_counter() - start, time.process_time() - cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per mechanism run")
    parser.add_argument("--rlg-output-hz", type=float, default=1000.0)
    parser.add_argument("--fog-output-hz", type=float, default=2000.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-device", action="store_true", help="skip the whole-IMU figures")
    args = parser.parse_args()
    seconds = args.seconds

    rlg, rlg_plain = RingLaserGyro(), RingLaserGyro(dither_amplitude_arcsec=0.0)
    fog_closed, fog_open = FiberOpticGyro(), FiberOpticGyro(loop="open")
    rlg_hz, fog_hz = rlg.inner_rate_hz(args.rlg_output_hz), fog_closed.inner_rate_hz(args.fog_output_hz)

    print(
        f"{seconds:g} s of a three-axis triad, best of {args.repeats}; × real time = simulated s / wall s "
        "(and per CPU s: on a shared machine the wall figure also counts time the process waited)"
    )
    print(f"{'case':58s} {'wall s':>9s} {'× real time':>12s} {'(CPU)':>8s}")
    failed = False

    def report(name: str, wall, simulated: float, target: bool = False):
        nonlocal failed
        wall, cpu = wall if isinstance(wall, tuple) else (wall, None)
        factor = simulated / wall
        mark = ""
        if target:
            mark = "  met" if factor >= TARGET else "  NOT met"
            failed |= factor < TARGET
        cpu_column = f"{simulated / cpu:8.1f}" if cpu else " " * 8
        print(f"{name:58s} {wall:9.3f} {factor:12.1f} {cpu_column}{mark}")
        return factor

    cases = [
        (f"RLG dithered, inner {rlg_hz / 1e3:g} kHz ({args.rlg_output_hz:g} Hz output)", rlg, rlg_hz),
        (f"RLG without dither, inner {rlg_hz / 1e3:g} kHz", rlg_plain, rlg_hz),
        (f"FOG closed loop, inner = output {fog_hz:g} Hz", fog_closed, fog_hz),
        (f"FOG open loop, inner = output {fog_hz:g} Hz", fog_open, fog_hz),
    ]
    factors = {}
    for name, gyro, hz in cases:
        wall = best(lambda gyro=gyro, hz=hz: run_mechanism(gyro, seconds, hz), args.repeats)
        factors[name] = report(name, wall, seconds, target=True)
    rlg_factor, fog_factor = factors[cases[0][0]], factors[cases[2][0]]

    print("\nbaselines (short span, extrapolated to 1 s of three axes):")
    span_py, span_ivp, span_nb, span_fog = 2e-3, 2e-3, 0.05, 0.01
    per_second = lambda wall, span: 3 * wall / span  # noqa: E731  (three axes)
    python = per_second(adler_python(rlg, span_py), span_py)
    report(f"RLG: RK4 resolving the beat, plain Python ({span_py * 1e3:g} ms)", python, 1.0)
    ivp = per_second(adler_solve_ivp(rlg, span_ivp), span_ivp)
    report(f"RLG: scipy solve_ivp RK45 rtol 1e-8 ({span_ivp * 1e3:g} ms)", ivp, 1.0)
    compiled = per_second(min(adler_numba(rlg, span_nb) for _ in range(args.repeats)), span_nb)
    report(f"RLG: RK4 resolving the beat, numba ({span_nb * 1e3:g} ms)", compiled, 1.0)
    samples = per_second(fog_detector_samples(fog_closed, span_fog, np.random.default_rng(0)), span_fog) / 3
    report(f"FOG: detector sample by sample, numpy ({span_fog * 1e3:g} ms)", samples, 1.0)
    print(
        f"\nRLG mechanism vs baselines: {rlg_factor * python:,.0f}× plain Python, {rlg_factor * ivp:,.0f}× "
        f"solve_ivp, {rlg_factor * compiled:,.0f}× compiled RK4"
    )
    print(f"FOG mechanism vs the sample-level detector: {fog_factor * samples:,.0f}×")

    if not args.no_device:
        print("\nwhole IMU (Device.measure: truth interpolation, mechanism, error layer):")
        for kind, hz in (("rlg", args.rlg_output_hz), ("fog", args.fog_output_hz)):
            try:
                report(f"{kind.upper()} device at {hz:g} Hz", device_run(kind, hz, seconds, args.repeats), seconds)
            except Exception as err:  # the IMU layer is someone else's: report, do not fail
                print(f"{kind.upper()} device at {hz:g} Hz: not measured ({type(err).__name__}: {err})")

    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
