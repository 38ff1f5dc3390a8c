"""Finite-difference checks of sampled kinematics, shared by the motion and vehicle tests.

Tolerances are the central-difference truncation bounds

    |(f(t+h) − f(t−h))/2h − f′(t)| ≤ h²/6 · max|f‴|
    |(f(t+h) − 2f(t) + f(t−h))/h² − f″(t)| ≤ h²/12 · max|f⁗|

with ``max|f‴|``, ``max|f⁗|`` bounded from each motion's amplitudes and frequencies, plus round-off
(:func:`roundoff`). Test grids are ``t0 + k h`` with ``h`` a power of two and ``t0`` an integer, so the
times themselves are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyroemu.dynamics import EARTH_RATE
from gyroemu.dynamics.rotation import body_rate_from_quat_derivative, quat_conjugate, quat_rotate

EPS = np.finfo(float).eps


@dataclass
class DerivativeBounds:
    """Bounds over the tested span, from theory: ``q3 ≥ |d³q_wb/dt³|`` (1/s³), ``w3 ≥ |d³ω_b/dt³|``
    (rad/s⁴), ``p3 ≥ |d³p/dt³|`` (m/s³), ``p4 ≥ |d⁴p/dt⁴|`` (m/s⁴)."""

    q3: float
    w3: float
    p3: float = 0.0
    p4: float = 0.0


def rotation_bounds(w1, w2, w3, w4, p3=0.0, p4=0.0) -> DerivativeBounds:
    """Bounds from ``w1..w4 ≥ |ω_wb|, |α_wb|, |α̇_wb|, |α̈_wb|``.

    ``q̇ = ½ q ω`` gives ``q̈ = ½ (q̇ ω + q α)`` and ``q⃛ = ½ (q̈ ω + 2 q̇ α + q α̇)``, so
    ``|q⃛| ≤ w1³/8 + 3 w1 w2/4 + w3/2``. ``ω_b = ω_wb + e`` with the Earth term ``e = R_bw Ω``,
    ``ė = −ω × e``, whence ``|e⃛| ≤ Ω (w3 + 3 w1 w2 + w1³)``.
    """
    return DerivativeBounds(
        q3=w1**3 / 8 + 0.75 * w1 * w2 + 0.5 * w3,
        w3=w4 + EARTH_RATE * (w3 + 3 * w1 * w2 + w1**3),
        p3=p3,
        p4=p4,
    )


def roundoff(value, rate, t_max):
    """Round-off of one closed-form sample: a few ulp of the value plus the rounding of the time argument
    (``ulp(t) · |ḟ|``); 16 ulp covers the chains of a dozen operations in the kinds."""
    return 16 * EPS * (value + t_max * rate)


def uniform_times(t0: float, span: float, h: float = 2.0**-10) -> np.ndarray:
    """Exact binary grid ``t0 + k h`` covering ``span`` seconds."""
    return t0 + h * np.arange(int(span / h) + 1)


def assert_kinematics(traj, bounds: DerivativeBounds, breakpoints=(), sharp: float = 1e-4):
    """ω_b against the differenced attitude, α_b against the differenced ω_b, velocity against the
    differenced position, specific force against the second difference of position.

    ``breakpoints`` are times where the motion is less smooth than the bounds assume (e.g. the corners
    of an acceleration-limited rate step); stencils that straddle one are left out. Each bound must also
    be ``sharp`` relative to the quantity it checks (when that is not zero), so no test passes vacuously.
    """
    t = traj.t
    h = t[1] - t[0]
    assert np.all(np.diff(t) == h), "checks need an exactly uniform grid"
    t_max = np.abs(t).max()
    keep = np.ones(len(t) - 2, dtype=bool)
    for b in breakpoints:
        keep &= ~((t[:-2] < b) & (b < t[2:]))
    env = traj.environment
    q, w, p = traj.q_wb, traj.omega_b, traj.pos_w
    q_bw = quat_conjugate(q)
    earth_b = quat_rotate(q_bw, env.earth_rate_w)
    w_max, a_max = np.abs(w).max() + EARTH_RATE, np.linalg.norm(traj.alpha_b, axis=1).max()

    def check(name, residual, bound, scale):
        worst = np.linalg.norm(residual, axis=-1)[keep].max()
        assert worst <= bound, f"{name}: residual {worst:.3e} exceeds its bound {bound:.3e}"
        if scale > 0:
            assert bound <= sharp * scale, f"{name}: bound {bound:.3e} is not sharp against {scale:.3e}"

    # ω_b = 2 (q* ⊗ q̇)_vec + R_bw Ω;  |Δω| ≤ 2 |Δq̇|.
    dq = (q[2:] - q[:-2]) / (2 * h)
    w_fd = body_rate_from_quat_derivative(q[1:-1], dq) + earth_b[1:-1]
    bound = 2 * (h**2 / 6 * bounds.q3 + roundoff(1.0, w_max, t_max) / h)
    check("omega_b vs quaternion differences", w_fd - w[1:-1], bound, w_max)

    dw = (w[2:] - w[:-2]) / (2 * h)
    bound = h**2 / 6 * bounds.w3 + roundoff(w_max, a_max, t_max) / h
    check("alpha_b vs omega_b differences", dw - traj.alpha_b[1:-1], bound, a_max)

    p_max, v_max = np.abs(p).max(), np.abs(traj.vel_w).max()
    dp = (p[2:] - p[:-2]) / (2 * h)
    bound = h**2 / 6 * bounds.p3 + roundoff(p_max, v_max, t_max) / h
    check("vel_w vs position differences", dp - traj.vel_w[1:-1], bound, v_max)

    # f_b = R_bw (p̈ + 2 Ω × v − g)
    ddp = (p[2:] - 2 * p[1:-1] + p[:-2]) / h**2
    f_fd = quat_rotate(q_bw[1:-1], ddp + 2 * np.cross(env.earth_rate_w, traj.vel_w[1:-1]) - env.gravity_w)
    f_max = np.abs(traj.specific_force_b).max()
    bound = h**2 / 12 * bounds.p4 + 4 * roundoff(p_max, v_max, t_max) / h**2 + 16 * EPS * f_max
    check("specific_force_b vs second differences", f_fd - traj.specific_force_b[1:-1], bound, f_max)


# Derivative bounds of the smooth step: S′ = 1 − 1.5 cos 2πu + 0.6 cos 4πu − 0.1 cos 6πu, so
# |S^(n+1)| ≤ (2π)ⁿ (1.5 + 0.6·2ⁿ + 0.1·3ⁿ).
def step_bound(n: int) -> float:
    """Bound on the n-th derivative of the smooth step S (n ≥ 1)."""
    m = n - 1
    return 3.2 if m == 0 else (2 * np.pi) ** m * (1.5 + 0.6 * 2**m + 0.1 * 3**m)
