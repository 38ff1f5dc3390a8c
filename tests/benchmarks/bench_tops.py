"""Benchmark: one hour of truth at 1 kHz (3.6 M samples) for the free tops and the heavy top.

Run: ``python tests/benchmarks/bench_tops.py`` (not collected by pytest). For each scenario it prints

* the wall time and samples/s of ``Scenario.simulate(duration=3600)`` (after a short warm-up that
  loads numba's compiled kernels), against the budget of 10 s on one core;
* a baseline measured in the same run: ``scipy.integrate.solve_ivp`` with DOP853 on the same
  equations (quaternion kinematics and Euler's equations, 7 states) over a short span, at the loosest
  tolerance whose error is no larger than the splitting integrator's on that span (or the tightest
  tried, 1e-13), extrapolated to the hour (its cost is linear in the span). It counts the ODE solve
  and its dense output only, where the splitting figure is the whole Trajectory (rates,
  accelerations, specific force), so the ratio understates the gain;
* both errors on that span: against the lecture's closed-form body rates (free symmetric top,
  relative), against the Jacobi-elliptic ``cos θ(t)`` (heavy top, Goldstein §5.7), and for the
  asymmetric body near its separatrix, whose flip times are ill-conditioned, the drift of the
  energy and of the world angular momentum (relative). :func:`jacobi_rates` gives that body's
  elliptic solution for comparison.

Everything runs on one thread (numba kernels are serial; the BLAS pools are limited to one thread);
the process is not pinned, so that on a shared machine the scheduler can give it the idler core.
Exit status 1 if a simulation takes more than 10 s.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.special import ellipj, ellipk, ellipkinc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from gyroemu.dynamics import load_scenario  # noqa: E402
from gyroemu.dynamics.rotation import body_rate_from_euler_zxz, quat_from_euler_zxz, quat_rotate  # noqa: E402
from gyroemu.dynamics.tops import pivot_moments  # noqa: E402

HOUR_S = 3600.0
BUDGET_S = 10.0
BASELINE_SPAN_S = 10.0
BASELINE_RTOLS = (1e-9, 1e-10, 1e-11, 1e-12, 1e-13)


# --------------------------------------------------------------------------------------------------
# Closed forms (references for both integrators)


def symmetric_top_rates(inertia, omega0, t):
    """Lecture 11: ``ω_x + i ω_y`` turns at ``Ω = (Izz − Ixx)/Ixx ω_z`` about body z."""
    ixx, izz = inertia[0], inertia[2]
    big_omega = (izz - ixx) / ixx * omega0[2]
    c, s = np.cos(big_omega * t), np.sin(big_omega * t)
    return np.stack([omega0[0] * c - omega0[1] * s, omega0[0] * s + omega0[1] * c, np.full_like(t, omega0[2])], -1)


def jacobi_rates(inertia, omega0, t):
    """Euler's equations' solution in Jacobi functions (Landau & Lifshitz §37) from ``omega0``.

    With the moments sorted ``I1 < I2 < I3`` and ``L² > 2E I2`` (the motion circles the major axis)::

        ω1 = a cn(τ, m),  ω2 = s b sn(τ, m),  ω3 = s c dn(τ, m),  τ = λ t + τ0,  s = sign ω3

    The other case is the same after the proper rotation ``(1, 2, 3) → (3, −2, 1)`` of the axes, where
    ``I3 − I2 < 0`` turns the sign of ``ω2`` (Euler's first equation: ``s2 s3 ∝ I3 − I2``).
    """
    order = np.argsort(inertia)
    i = np.asarray(inertia, float)[order]
    w = np.asarray(omega0, float)[order]
    e2, l2 = np.sum(i * w**2), np.sum((i * w) ** 2)
    flip = l2 < e2 * i[1]
    if flip:
        i, w = i[::-1], w[::-1] * np.array([1.0, -1.0, 1.0])
    i1, i2, i3 = i
    lam = np.sqrt((i3 - i2) * (l2 - e2 * i1) / (i1 * i2 * i3))
    m = (i2 - i1) * (e2 * i3 - l2) / ((i3 - i2) * (l2 - e2 * i1))
    a = np.sqrt((e2 * i3 - l2) / (i1 * (i3 - i1)))
    b = np.sqrt((e2 * i3 - l2) / (i2 * (i3 - i2)))
    c = np.sqrt((l2 - e2 * i1) / (i3 * (i3 - i1)))
    s3 = np.sign(w[2])
    s2 = s3 * np.sign(i3 - i2)
    phi = np.arctan2(w[1] / (s2 * b), w[0] / a)  # amplitude at t = 0
    tau0 = np.sign(phi) * ellipkinc(abs(phi), m)
    sn, cn, dn, _ = ellipj(lam * t + tau0, m)
    rates = np.stack([a * cn, s2 * b * sn, s3 * c * dn], -1)
    if flip:
        rates = rates[:, ::-1] * np.array([1.0, -1.0, 1.0])
    out = np.empty_like(rates)
    out[:, order] = rates
    return out


def lagrange_cos_nutation(a_pivot, c_pivot, mgl, u0, l3, lz, energy, t):
    """``u = cos θ = u1 + (u2 − u1) sn²(λ t + τ0, m)`` of a heavy top released with θ̇ = 0 at u0 = u2."""
    a, b = l3 / a_pivot, lz / a_pivot
    alpha, beta = 2 * (energy - l3**2 / (2 * c_pivot)) / a_pivot, 2 * mgl / a_pivot
    u1, u2, u3 = np.sort(np.roots([beta, -(alpha + a * a), 2 * a * b - beta, alpha - b * b]).real)
    m = (u2 - u1) / (u3 - u1)
    lam = 0.5 * np.sqrt(beta * (u3 - u1))
    return u1 + (u2 - u1) * ellipj(lam * t + ellipk(m), m)[0] ** 2


# --------------------------------------------------------------------------------------------------
# The same problems for solve_ivp: y = (q_wb (4), L_b (3)).


def _quat_rate(q, w):
    """``q̇ = ½ q ⊗ (0, ω)``."""
    return 0.5 * np.array(
        [
            -q[1] * w[0] - q[2] * w[1] - q[3] * w[2],
            q[0] * w[0] + q[2] * w[2] - q[3] * w[1],
            q[0] * w[1] - q[1] * w[2] + q[3] * w[0],
            q[0] * w[2] + q[1] * w[1] - q[2] * w[0],
        ]
    )


def free_body_rhs(moments):
    def rhs(_, y):
        q, L = y[:4], y[4:]
        w = L / moments
        return np.concatenate([_quat_rate(q, w), np.cross(L, w)])  # L̇_b = L_b × ω

    return rhs


def heavy_top_rhs(moments, mgl):
    def rhs(_, y):
        q, L = y[:4], y[4:]
        w = L / moments
        up = np.array(  # Rᵀ ẑ, the world vertical in body axes
            [2 * (q[1] * q[3] - q[0] * q[2]), 2 * (q[2] * q[3] + q[0] * q[1]), 1 - 2 * (q[1] ** 2 + q[2] ** 2)]
        )
        torque = mgl * np.array([up[1], -up[0], 0.0])  # (l e_z) × (−m g up)
        return np.concatenate([_quat_rate(q, w), np.cross(L, w) + torque])

    return rhs


# --------------------------------------------------------------------------------------------------


def setup(name):
    """Scenario, RHS, initial state, moments and an error function of (t, q_wb, ω_b) for ``name``."""
    scenario = load_scenario(name)
    spec = scenario.spec
    if scenario.kind == "free-rigid-body":
        moments = np.asarray(spec.body.inertia_kgm2, float)
        omega0, q0 = np.asarray(spec.initial.omega_b), np.asarray(spec.initial.q_wb)
        if moments[0] == moments[1]:

            def error(t, q, w):
                return np.abs(w - symmetric_top_rates(moments, omega0, t)).max() / np.linalg.norm(omega0)

        else:
            # Near the separatrix the flip times hang on the energy so sharply (dT/dE ∝ 1/(L² − 2E I2))
            # that any method's 1e-13 energy error moves them by ~1e-8: compare the invariants instead.
            energy0, L0_w = 0.5 * omega0 @ (moments * omega0), quat_rotate(q0, moments * omega0)

            def error(t, q, w):
                energy = 0.5 * np.sum(w * w * moments, axis=1)
                L_w = quat_rotate(q, w * moments)
                return max(np.abs(energy / energy0 - 1).max(), np.abs(L_w - L0_w).max() / np.linalg.norm(L0_w))

        return scenario, free_body_rhs(moments), np.concatenate([q0, moments * omega0]), moments, error

    body, g = spec.body, spec.environment.gravity_m_s2
    a, c = pivot_moments(body.mass_kg, body.inertia_kgm2, body.cm_height_m)
    moments, mgl = np.array([a, a, c]), body.mass_kg * g * body.cm_height_m
    euler, rates = np.asarray(spec.initial.euler_zxz_rad), np.asarray(spec.initial.euler_zxz_rates_rad_s)
    q0, w0 = quat_from_euler_zxz(euler), body_rate_from_euler_zxz(euler, rates)
    L0_w = quat_rotate(q0, moments * w0)
    u0 = np.cos(euler[1])
    energy = 0.5 * w0 @ (moments * w0) + mgl * u0

    def error(t, q, w):
        u = 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2)
        return np.abs(u - lagrange_cos_nutation(a, c, mgl, u0, moments[2] * w0[2], L0_w[2], energy, t)).max()

    return scenario, heavy_top_rhs(moments, mgl), np.concatenate([q0, moments * w0]), moments, error


def baseline_run(rhs, y0, t, error, target, moments):
    """DOP853 at the loosest rtol of :data:`BASELINE_RTOLS` whose error on ``t`` is at most ``target``
    (or the tightest): returns rtol, wall time, error, RHS calls."""
    for rtol in BASELINE_RTOLS:
        started = time.perf_counter()
        sol = solve_ivp(rhs, (0.0, t[-1]), y0, method="DOP853", t_eval=t, rtol=rtol, atol=rtol * np.abs(y0).max())
        elapsed = time.perf_counter() - started
        q = sol.y[:4].T
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        err = error(t, q, sol.y[4:].T / moments)
        if err <= target or rtol == BASELINE_RTOLS[-1]:
            return rtol, elapsed, err, sol.nfev
    raise AssertionError("unreachable")


def main() -> int:
    ok = True
    for name in ("free_symmetric_top", "intermediate_axis_flip", "heavy_top"):
        scenario, rhs, y0, moments, error = setup(name)
        scenario.simulate(duration=1.0)  # warm-up: load the cached numba kernels
        started = time.perf_counter()
        traj = scenario.simulate(duration=HOUR_S, rate_hz=1000.0)
        wall = time.perf_counter() - started
        n = len(traj)
        span = traj.t <= BASELINE_SPAN_S
        ours = error(traj.t[span], traj.q_wb[span], traj.omega_b[span])
        del traj

        t = np.arange(int(BASELINE_SPAN_S * 1000) + 1) / 1000.0
        rtol, base_wall, base_err, nfev = baseline_run(rhs, y0, t, error, ours, moments)
        extrapolated = base_wall * HOUR_S / BASELINE_SPAN_S
        ok &= wall < BUDGET_S
        print(
            f"{name:24s} {n:,} samples in {wall:5.2f} s = {n / wall / 1e6:5.2f} M samples/s "
            f"({'ok' if wall < BUDGET_S else 'OVER'} < {BUDGET_S:g} s); error over {BASELINE_SPAN_S:g} s {ours:.1e}\n"
            f"{'':24s} DOP853 rtol={rtol:g}: {BASELINE_SPAN_S:g} s in {base_wall:.2f} s ({nfev} RHS calls), "
            f"error {base_err:.1e}{' (tightest tried, still less accurate)' if base_err > ours else ''}; "
            f"an hour ≈ {extrapolated:,.0f} s, {extrapolated / wall:,.0f}x slower",
            flush=True,
        )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
