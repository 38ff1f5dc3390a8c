"""Prescribed motions in closed form: a bench, a rate table, oscillation, coning and sculling.

Every kind here stands on the Earth at a site (the optional ``[site]`` table, :class:`~gyroemu.dynamics.earth.Site`)
and prescribes its motion *relative to the local ENU world frame* analytically: attitude ``q_wb``, body
rate ``ω_wb`` and its derivative ``α_wb`` (body axes), position, velocity and acceleration (world axes),
each a closed-form function of time evaluated on arrays of samples (vectorised, no loop over samples).
No kind integrates anything. :func:`~gyroemu.dynamics.trajectory.trajectory_from_world_motion` then adds what
the Earth contributes: Earth rate, Coriolis, gravity and the magnetic field.

Kinds
-----
``static``
    A body at rest on a bench: an ideal gyro reads the Earth rate ``R_bw Ω (0, cos φ, sin φ)``, a level
    accelerometer ``(0, 0, +g)``.
``rate-table``
    A single-axis rate table as used to calibrate gyros: constant rate, rate steps with a finite
    angular-acceleration limit, or a multi-position tumble; with a mounting rotation and a lever arm of
    the body on the table top.
``oscillation``
    Sinusoidal angular oscillation about a body axis, optionally with a linear oscillation.
``coning``
    Classical coning (Savage 1998, part 1): the body x axis sweeps a cone about a fixed axis.
``sculling``
    Angular oscillation about x in phase with linear oscillation along y (Savage 1998, part 2).

Building blocks shared with :mod:`gyroemu.dynamics.vehicles`: :class:`TimeGrid` (sinusoids on uniform grids by
angle addition), :func:`smooth_step` (a C⁵ step from 0 to 1), :func:`rotation_basis`, :class:`WorldMotion` and
:class:`EarthBoundSpec`. Each kind evaluates its closed forms in one compiled kernel (numba) that
writes every output once; the kernels share compiled pieces of these blocks (``_sines_block``,
``_phasor_block``, ``_sincos_block``, ``_smooth_step_at``; see "Speed" below).

Attitudes in config files are ``rpy_deg = [roll, pitch, yaw]`` in degrees with
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`gyroemu.dynamics.rotation.quat_from_euler_zyx`); in the ENU world,
yaw 0 points body x east, yaw 90 north.

References
----------
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 1: attitude algorithms",
J. Guidance, Control, and Dynamics 21(1), 19–28, 1998 (coning).
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 2: velocity and position
algorithms", J. Guidance, Control, and Dynamics 21(2), 208–221, 1998 (sculling).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from .config import NonNegativeReal, PositiveReal, Real, Section, Vec3
from .earth import Site
from .jit import njit
from .rotation import quat_conjugate, quat_from_euler_zyx, quat_multiply, quat_rotate, quat_to_rotvec
from .scenarios import ScenarioSpec
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = [
    "TimeGrid",
    "smooth_step",
    "quat_from_rpy_deg",
    "rotation_basis",
    "WorldMotion",
    "EarthBoundSpec",
    "Attitude",
    "StaticSpec",
    "Table",
    "ConstantRate",
    "RateSteps",
    "Tumble",
    "RateTableSpec",
    "AngularOscillation",
    "LinearOscillation",
    "OscillationSpec",
    "Coning",
    "ConingSpec",
    "Sculling",
    "ScullingSpec",
]

_EPS = np.finfo(float).eps
_E_Z = np.array([0.0, 0.0, 1.0])


# --------------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------------
#
# Speed. The kinds evaluate their closed forms in compiled kernels (numba) that write every output once,
# in place, block by block (``TimeGrid.BLOCK`` samples, whose scratch arrays stay in the CPU cache).
# Measured on 10⁶ samples: a fresh (N, 3) array costs 2–3 ns per sample in first touches of new memory,
# and written in numpy a kind needs dozens of them; a sine and cosine from the C library cost about
# 10 ns, by angle addition (TimeGrid) or from _sincos_block about 1 ns.


class TimeGrid:
    """Sample times, and sinusoids ``sin(ω t + φ)`` evaluated on them.

    Sinusoids are most of the cost of a closed-form motion: ``sin`` and ``cos`` take about
    10 ns per sample, a multiplication 0.3 ns. On a uniform grid ``t_n = t_0 + n h`` the angle-addition
    theorem removes almost all of them. With ``n = j B + i`` (block ``j`` of ``B`` samples, offset ``i``)::

        exp(i(ω t_n + φ)) = exp(i(ω t_{jB} + φ)) · exp(i ω i h)

    so ``N`` samples need ``N/B + B`` sines and cosines and one complex product each. The product adds
    a few ulp to what direct evaluation loses already in rounding ``ω t + φ`` (the tests compare both
    against long-double references). A grid counts as uniform when it deviates from
    ``t_0 + n h`` by at most 8 ulp of its largest time, which ``Scenario.times`` (``k / rate_hz``) meets;
    other grids are evaluated directly.

    The kinds' kernels take the tables of :meth:`phasor` and :meth:`sines` and evaluate block by block
    (:func:`_phasor_block`, :func:`_sines_block`).

    Parameters
    ----------
    t : array_like (N,)
        Sample times, s.
    """

    BLOCK = 1024
    """Samples per block ``B``: the offset tables and the kernels' scratch arrays."""

    def __init__(self, t):
        self.t = np.asarray(t, dtype=float)
        if self.t.ndim != 1:
            raise ValueError(f"sample times must be 1-D, got shape {self.t.shape}")
        n = len(self.t)
        self.t0 = float(self.t[0]) if n else 0.0
        self.h = float(self.t[-1] - self.t[0]) / (n - 1) if n > 1 else 0.0
        self.uniform = False
        if n >= 4 * self.BLOCK and self.h > 0:
            deviation = _grid_deviation(self.t, self.t0, self.h)  # max |t_n − (t_0 + n h)|
            self.uniform = bool(deviation <= 8 * _EPS * np.abs(self.t[[0, -1]]).max())

    def __len__(self) -> int:
        return len(self.t)

    def _offset_tables(self, omega):
        """``cos(ω i h)`` and ``sin(ω i h)`` for ``i < B``, shape ``omega.shape + (B,)``; empty (last axis
        0) on other grids, whose kernels evaluate directly."""
        omega = np.asarray(omega, dtype=float)
        if not self.uniform:
            empty = np.empty(omega.shape + (0,))
            return empty, empty
        angle = omega[..., None] * (np.arange(self.BLOCK) * self.h)
        return np.cos(angle), np.sin(angle)

    def phasor(self, omega: float, phase: float = 0.0):
        """What :func:`_phasor_block` needs for ``cos(ω t + φ)``, ``sin(ω t + φ)``: ``(ω, φ, cos table,
        sin table)``."""
        return (float(omega), float(phase)) + self._offset_tables(float(omega))

    def sines(self, amplitude, omega, phase):
        """What :func:`_sines_block` needs for ``x_c = Σ_k A_ck sin(ω_ck t + φ_ck)``: the arrays (C, K)
        broadcast from ``amplitude, omega, phase`` (any of (C, K), (C, 1), (K,), scalar) and the offset
        tables (C, K, B)."""
        a, w, p = (
            np.ascontiguousarray(x)
            for x in np.broadcast_arrays(
                *(np.atleast_2d(np.asarray(x, dtype=float)) for x in (amplitude, omega, phase))
            )
        )
        return (a, w, p) + self._offset_tables(w)

    def cos_sin(self, omega: float, phase: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``cos(ω t + φ)`` and ``sin(ω t + φ)``, each (N,); ``ω`` in rad/s, ``φ`` in rad."""
        c, s = np.empty(len(self.t)), np.empty(len(self.t))
        _cos_sin_kernel(self.t, self.uniform, self.BLOCK, self.phasor(omega, phase), c, s)
        return c, s

    def sum_of_sines(self, amplitude, omega, phase) -> np.ndarray:
        """Sums of sinusoids per channel and their first two time derivatives.

        ``x_c(t) = Σ_k A_ck sin(ω_ck t + φ_ck)``, ``ẋ_c = Σ A ω cos(…)``,
        ``ẍ_c = −Σ A ω² sin(…)``.

        Parameters
        ----------
        amplitude, omega, phase : array_like (C, K)
            Amplitudes (any unit), angular frequencies (rad/s), phases (rad) of ``K`` terms per channel.

        Returns
        -------
        ndarray (3, C, N)
            Value, first and second derivative of each channel.
        """
        sines = self.sines(amplitude, omega, phase)
        out = np.empty((3, sines[0].shape[0], len(self.t)))
        _sum_of_sines_kernel(self.t, self.uniform, self.BLOCK, sines, out)
        return out


# Sine and cosine, vectorisable. Every kind needs cos(x/2) and sin(x/2) of angles that are not linear
# in time (Euler angles, oscillation angles), up to three per sample. The C library's sin and cos are
# calls the compiler cannot vectorise, about 10 ns a pair; the same argument reduction and polynomials
# as the C library's (fdlibm, Sun Microsystems 1993: __ieee754_rem_pio2, __kernel_sin, __kernel_cos),
# written out without branches, vectorise and take about 1 ns a pair in the loops of _sincos_block.
# Error below 0.8 ulp (the library's: 0.5); results differ from the library's by one ulp in about 3 % of
# arguments. Valid for |x| ≤ _SINCOS_LIMIT, where the reduction below is exact; callers fall back to
# the library beyond it (and for NaN, inf).

_SINCOS_LIMIT = 1e6
"""|x| up to which :func:`_sincos` is accurate: ``n = round(2x/π) < 2²⁰``, so that ``n`` times the
33-bit parts of π/2 is exact."""


@njit(inline="always")
def _sincos(x):  # pragma: no cover - compiled
    """``(sin x, cos x)`` for ``|x| ≤ _SINCOS_LIMIT``, branch-free (see the comment above)."""
    # x = n π/2 + y0 + y1 with |y0 + y1| ≤ π/4: π/2 in 33-bit parts (each product with n exact) and a
    # tail, fdlibm's reduction to 118 bits (its "second iteration", here always taken).
    n = np.rint(x * 6.36619772367581382433e-01)  # 2/π
    hi = x - n * 1.57079632673412561417e00  # π/2, first 33 bits: exact
    w = n * 6.07710050630396597660e-11  # π/2, next 33 bits
    r = hi - w
    w = n * 2.02226624879595063154e-21 - ((hi - r) - w)  # π/2, the rest; and the rounding of r
    y0 = r - w
    y1 = (r - y0) - w
    # fdlibm's __kernel_sin(y0, y1) and __kernel_cos(y0, y1): minimax polynomials on [−π/4, π/4].
    z = y0 * y0
    v = z * y0
    s2, s3, s4 = 8.33333333332248946124e-03, -1.98412698298579493134e-04, 2.75573137070700676789e-06
    s5, s6 = -2.50507602534068634195e-08, 1.58969099521155010221e-10
    ps = s2 + z * (s3 + z * (s4 + z * (s5 + z * s6)))
    sin = y0 - ((z * (0.5 * y1 - v * ps) - y1) + v * 1.66666666666666324348e-01)  # S1 = −1/6 + …
    c1, c2, c3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
    c4, c5, c6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
    pc = z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * c6)))))
    hz = 0.5 * z
    one_hz = 1.0 - hz
    cos = one_hz + (((1.0 - one_hz) - hz) + (z * pc - y0 * y1))
    # Quadrant n mod 4 (as a float: no integer conversion of a NaN): sin(y + nπ/2) is sin y, cos y,
    # −sin y, −cos y for n mod 4 = 0, 1, 2, 3; cos(y + nπ/2) is cos y, −sin y, −cos y, sin y.
    quadrant = n - 4.0 * np.floor(0.25 * n)
    odd = quadrant == 1.0 or quadrant == 3.0
    s, c = (cos, sin) if odd else (sin, cos)
    return (-s if quadrant >= 2.0 else s), (-c if quadrant == 1.0 or quadrant == 2.0 else c)


@njit
def _sin_cos(x):  # pragma: no cover - compiled
    """``(sin x, cos x)`` for one argument: :func:`_sincos`, or the library beyond its range."""
    if abs(x) <= _SINCOS_LIMIT:
        return _sincos(x)
    return np.sin(x), np.cos(x)


@njit
def _sincos_block(x, count, s, c):  # pragma: no cover - compiled
    """``s[i], c[i] = sin x[i], cos x[i]`` for ``i < count``: one vectorised loop, then the library for
    arguments beyond :data:`_SINCOS_LIMIT` (and NaN)."""
    for i in range(count):
        s[i], c[i] = _sincos(x[i])
    for i in range(count):
        if not abs(x[i]) <= _SINCOS_LIMIT:
            s[i], c[i] = np.sin(x[i]), np.cos(x[i])


@njit
def _grid_deviation(t, t0, h):  # pragma: no cover - compiled
    """``max_n |t_n − (t_0 + n h)|`` in one pass (numpy would make three temporaries of N)."""
    deviation = 0.0
    for n in range(len(t)):
        deviation = max(deviation, abs(t[n] - (t0 + n * h)))
    return deviation


@njit
def _phasor_block(t, start, count, uniform, phasor, c, s):  # pragma: no cover - compiled
    """``cos(ω t + φ)``, ``sin(ω t + φ)`` at the samples ``start … start + count − 1`` into
    ``c[:count]``, ``s[:count]``; ``phasor`` from :meth:`TimeGrid.phasor`. On a uniform grid ``start``
    must begin a block (a multiple of ``B``)."""
    omega, phase, offset_cos, offset_sin = phasor
    if uniform:
        angle = omega * t[start] + phase
        cb, sb = np.cos(angle), np.sin(angle)
        for i in range(count):
            # cos(a + b) = cos a cos b − sin a sin b,  sin(a + b) = sin a cos b + cos a sin b
            c[i] = cb * offset_cos[i] - sb * offset_sin[i]
            s[i] = sb * offset_cos[i] + cb * offset_sin[i]
    else:
        for i in range(count):
            angle = omega * t[start + i] + phase
            c[i], s[i] = np.cos(angle), np.sin(angle)


@njit
def _sines_block(t, start, count, uniform, sines, out):  # pragma: no cover - compiled
    """Value, first and second derivative of the sums of sinusoids ``sines`` (:meth:`TimeGrid.sines`)
    at the samples ``start … start + count − 1`` into ``out[d, c, :count]`` (d = 0, 1, 2).

    On a uniform grid each term is ``Im(P Q_i)`` with the block phasor ``P = exp(i(ω t_start + φ))``
    and the offset phasor ``Q_i`` from the table: ``sin(P + Q) = sin P cos Q + cos P sin Q``. The loops
    over the block's samples are innermost, where the compiler vectorises them.
    """
    amplitude, omega, phase, offset_cos, offset_sin = sines
    channels, terms = amplitude.shape
    for ch in range(channels):
        value, first, second = out[0, ch], out[1, ch], out[2, ch]
        value[:count] = 0.0
        first[:count] = 0.0
        second[:count] = 0.0
        for k in range(terms):
            a, w = amplitude[ch, k], omega[ch, k]
            a1 = a * w  # ẋ = Σ A ω cos(ω t + φ)
            a2 = a1 * w  # ẍ = −Σ A ω² sin(ω t + φ)
            if uniform:
                angle = w * t[start] + phase[ch, k]
                pc, ps = np.cos(angle), np.sin(angle)
                qc, qs = offset_cos[ch, k], offset_sin[ch, k]
                for i in range(count):
                    sin = ps * qc[i] + pc * qs[i]
                    cos = pc * qc[i] - ps * qs[i]
                    value[i] += a * sin
                    first[i] += a1 * cos
                    second[i] -= a2 * sin
            else:
                for i in range(count):
                    sin, cos = _sin_cos(w * t[start + i] + phase[ch, k])
                    value[i] += a * sin
                    first[i] += a1 * cos
                    second[i] -= a2 * sin


@njit
def _cos_sin_kernel(t, uniform, block, phasor, c, s):  # pragma: no cover - compiled
    """:meth:`TimeGrid.cos_sin` block by block."""
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        _phasor_block(t, start, count, uniform, phasor, c[start:], s[start:])


@njit
def _sum_of_sines_kernel(t, uniform, block, sines, out):  # pragma: no cover - compiled
    """:meth:`TimeGrid.sum_of_sines` block by block, into ``out`` (3, C, N)."""
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        _sines_block(t, start, count, uniform, sines, out[:, :, start:])


@njit
def _smooth_step_at(u):  # pragma: no cover - compiled
    """``(S, S′, S″, S‴, I)`` of :func:`smooth_step` at one ``u``."""
    if u <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0, 0.0, 0.0, u - 0.5
    s, c = _sincos(2 * np.pi * u)
    # The harmonics of 4πu and 6πu in c = cos 2πu, s = sin 2πu, factored on (1 − c) = 2 sin² πu so
    # that the derivatives vanish exactly at the ends.
    d = 1 - c
    return (
        u - s * (22 - 9 * c + 2 * c * c) / (30 * np.pi),  # S
        0.4 * (d * d * d),  # S′ = (16/5) sin⁶ πu
        (12 * np.pi / 5) * s * (d * d),  # S″
        (24 * np.pi**2 / 5) * (d * d) * (2 + 3 * c),  # S‴
        0.5 * u * u - d * (109 - 23 * c + 4 * c * c) / (360 * np.pi**2),  # I
    )


@njit
def _smooth_step_kernel(u, out):  # pragma: no cover - compiled
    """:func:`smooth_step` of every ``u`` (N,) into ``out`` (5, N)."""
    for n in range(len(u)):
        out[0, n], out[1, n], out[2, n], out[3, n], out[4, n] = _smooth_step_at(u[n])


def smooth_step(u, derivatives: int = 3, integral: bool = False):
    """A smooth step from 0 to 1 with its derivatives, for speed changes, turns and tumble moves.

    ``S′(u) = (16/5) sin⁶(πu)`` is a bump of unit area on [0, 1], so::

        S(u) = u − (3/4π) sin 2πu + (3/20π) sin 4πu − (1/60π) sin 6πu

    held at 0 before ``u = 0`` and at 1 after ``u = 1``. Its first five derivatives vanish at both ends:
    a motion built from ``S`` is five times continuously differentiable, so ω, α and α̇ stay continuous
    even where ``S`` is composed with products (roll ∝ κ v²). The peak slope is ``S′(½) = 16/5``; the
    ``n``-th derivative of ``S′`` is at most ``(2π)ⁿ (1.5 + 0.6·2ⁿ + 0.1·3ⁿ)``.

    Parameters
    ----------
    u : array_like
        Normalised time or distance; values outside [0, 1] lie on the flat parts.
    derivatives : int
        How many derivatives to return (0 to 3).
    integral : bool
        Also return ``I(u) = ∫₀ᵘ S`` (``= u − ½`` for ``u ≥ 1``), e.g. for the distance over a speed
        change.

    Returns
    -------
    tuple of ndarray
        ``(S, S′, …, S^(derivatives))``, then ``I`` when asked for.
    """
    u = np.asarray(u, dtype=float)
    out = np.empty((5,) + u.shape)  # S, S′, S″, S‴, I
    _smooth_step_kernel(u.reshape(-1), out.reshape(5, -1))  # the kinds' kernels call _smooth_step_at
    return tuple(out[k, ...] for k in range(derivatives + 1)) + ((out[4, ...],) if integral else ())


def quat_from_rpy_deg(rpy_deg) -> np.ndarray:
    """Quaternion (4,) or (K, 4) of ``[roll, pitch, yaw]`` in degrees, ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    return quat_from_euler_zyx(np.radians(np.asarray(rpy_deg, dtype=float)))


def rotation_basis(axis, q_left=(1.0, 0.0, 0.0, 0.0), q_right=(1.0, 0.0, 0.0, 0.0)):
    """The two constant quaternions of a rotation about a fixed axis.

    ``q_left ⊗ exp(½ θ n) ⊗ q_right = cos(θ/2) A + sin(θ/2) B`` with ``A = q_left ⊗ q_right`` and
    ``B = q_left ⊗ (0, n) ⊗ q_right``: the quaternion is linear in the cosine and sine of the half angle.

    Parameters
    ----------
    axis : array_like (..., 3)
        Unit rotation axis ``n`` (in the frame between ``q_left`` and ``q_right``).
    q_left, q_right : array_like (..., 4)

    Returns
    -------
    A, B : ndarray (..., 4)
    """
    axis = np.asarray(axis, dtype=float)
    pure = np.concatenate([np.zeros(axis.shape[:-1] + (1,)), axis], axis=-1)
    return quat_multiply(q_left, q_right), quat_multiply(quat_multiply(q_left, pure), q_right)


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise ValueError(f"{what} must be a non-zero vector")
    return v / norm


@dataclass(frozen=True, eq=False)
class WorldMotion:
    """A body's motion relative to the world (ENU) frame, sampled at ``t``: what a kind prescribes.

    Attributes (N samples, SI)
    ----------
    t : ndarray (N,)
        s.
    q_wb : ndarray (N, 4)
        Attitude, body to world.
    omega_wb_b, alpha_wb_b : ndarray (N, 3)
        Angular velocity of the body relative to the world, body axes, rad/s, and its derivative, rad/s².
    pos_w, vel_w, acc_w : ndarray (N, 3)
        Position, velocity, acceleration relative to the world frame, world axes: m, m/s, m/s².
    extras : dict of str to ndarray
        Truth particular to the kind (table angle, car speed, ...), first axis N.
    """

    t: np.ndarray
    q_wb: np.ndarray
    omega_wb_b: np.ndarray
    alpha_wb_b: np.ndarray
    pos_w: np.ndarray
    vel_w: np.ndarray
    acc_w: np.ndarray
    extras: dict = field(default_factory=dict)

    @classmethod
    def rotation_only(cls, t, q_wb, omega_wb_b, alpha_wb_b, extras=None) -> WorldMotion:
        """A body that rotates about its fixed reference point at the world origin."""
        # Three calls, not copies of one: np.zeros maps zero pages lazily, copies would write them.
        n = len(t)
        pos, vel, acc = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        return cls(t, q_wb, omega_wb_b, alpha_wb_b, pos, vel, acc, extras or {})


def _motion_arrays(
    n: int, moves: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Outputs for a kind's kernel: ``q_wb`` (N, 4), ``ω_wb``, ``α_wb`` (N, 3), position, velocity,
    acceleration (N, 3). The kernel writes all of them if the body ``moves``; else position, velocity and
    acceleration are zeros (``np.zeros`` maps fresh zero pages lazily, cheaper than writing zeros; for
    arrays the kernel writes anyway ``np.empty`` spares the zeroing of reused memory)."""
    q, omega, alpha = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    new = np.empty if moves else np.zeros
    return q, omega, alpha, new((n, 3)), new((n, 3)), new((n, 3))


@njit
def _rotate(q, x, y, z):  # pragma: no cover - compiled
    """``q ⊗ (0, v) ⊗ q*`` for one vector ``v = (x, y, z)``: the formula of
    :func:`gyroemu.dynamics.rotation.quat_rotate`, ``v + 2w (u × v) + 2 u × (u × v)``."""
    w, qx, qy, qz = q[0], q[1], q[2], q[3]
    tx = 2.0 * (qy * z - qz * y)  # t = 2 u × v
    ty = 2.0 * (qz * x - qx * z)
    tz = 2.0 * (qx * y - qy * x)
    return (
        x + w * tx + (qy * tz - qz * ty),  # v + w t + u × t
        y + w * ty + (qz * tx - qx * tz),
        z + w * tz + (qx * ty - qy * tx),
    )


@njit
def _cross(ax, ay, az, bx, by, bz):  # pragma: no cover - compiled
    """``a × b`` as ``np.cross`` computes it."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit
def _segment(edges, x, k):  # pragma: no cover - compiled
    """``max(searchsorted(edges, x, side="right") − 1, 0)``: the last of the sorted ``edges`` at or
    before ``x`` (0 before the first). Tries ``k``, the previous sample's segment, first: consecutive
    samples mostly share it."""
    last = len(edges) - 1
    if (k == 0 or edges[k] <= x) and (k == last or x < edges[k + 1]):
        return k
    return max(np.searchsorted(edges, x, side="right") - 1, 0)


class EarthBoundSpec(ScenarioSpec):
    """Base of the kinds that move on the Earth at a ``[site]``: they prescribe :meth:`world_motion`."""

    site: Site = Field(default_factory=Site)

    def world_motion(self, t: np.ndarray) -> WorldMotion:
        """The motion relative to the world frame at the times ``t`` (N,), s."""
        raise NotImplementedError

    def evaluator(self):
        """A callable ``t -> WorldMotion`` with the time-independent setup (series, schedules) done once,
        for evaluating the motion piece by piece (a stream); by default :meth:`world_motion` itself."""
        return self.world_motion

    def trajectory(self, t) -> Trajectory:
        m = self.world_motion(np.asarray(t, dtype=float))
        return trajectory_from_world_motion(
            m.t,
            m.q_wb,
            m.omega_wb_b,
            m.alpha_wb_b,
            m.pos_w,
            m.vel_w,
            m.acc_w,
            self.site.environment(),
            m.extras,
        )


class Attitude(Section):
    """``[attitude]``: ``rpy_deg = [roll, pitch, yaw]``, degrees, ``R_wb = Rz(yaw) Ry(pitch) Rx(roll)``."""

    rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    def quat(self) -> np.ndarray:
        """``q_wb`` (4,)."""
        return quat_from_rpy_deg(self.rpy_deg)


# --------------------------------------------------------------------------------------------------
# static
# --------------------------------------------------------------------------------------------------


class StaticSpec(EarthBoundSpec):
    """``kind = "static"``: a body at rest on a bench, at the attitude ``[attitude] rpy_deg``.

    Relative to the (rotating) world frame nothing moves, so an ideal gyro reads the Earth rate
    ``R_bw Ω (0, cos φ, sin φ)`` and the accelerometer ``R_bw (0, 0, g(φ, h))``.
    """

    kind: Literal["static"] = "static"
    attitude: Attitude = Field(default_factory=Attitude)

    def world_motion(self, t):
        n = len(t)
        q = np.empty((n, 4))
        q[:] = self.attitude.quat()
        return WorldMotion.rotation_only(t, q, np.zeros((n, 3)), np.zeros((n, 3)))


# --------------------------------------------------------------------------------------------------
# rate-table
# --------------------------------------------------------------------------------------------------


class Table(Section):
    """``[table]``: how the table stands and how the body sits on it.

    The table top turns by the table angle ``θ`` about the z axis of its base frame, so that
    ``q_wb = q_base ⊗ Rz(θ) ⊗ q_mount``; in tumble mode the table top takes the listed attitudes
    relative to the base frame instead.

    Attributes
    ----------
    base_rpy_deg : attitude of the base frame in the world; its z axis is the table axis (default level:
        the axis points up).
    mount_rpy_deg : attitude of the body relative to the table top (the mounting rotation).
    lever_arm_m : the body's reference point relative to the point on the axis, table-top axes, m; off the
        axis the body feels the centripetal and tangential accelerations.
    """

    base_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    mount_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)


class ConstantRate(Section):
    """``[constant]``: the table turns at ``rate_deg_s`` from ``t = 0``: ``θ = θ0 + ω t``."""

    rate_deg_s: Real
    initial_angle_deg: Real = 0.0


class RateSteps(Section):
    """``[steps]``: a list of table rates, each held for its dwell time once reached.

    The table starts at rest at ``t = 0`` and changes rate at the constant angular acceleration
    ``max_accel_deg_s2`` (so the rate is continuous and the acceleration piecewise constant); the
    dwell at ``rates_deg_s[k]`` lasts ``dwell_s[k]`` after the rate is reached. After the last dwell the
    table keeps the last rate (end the list with 0 to stop it).
    """

    rates_deg_s: list[Real] = Field(min_length=1)
    dwell_s: list[PositiveReal]
    max_accel_deg_s2: PositiveReal
    initial_angle_deg: Real = 0.0

    @field_validator("dwell_s")
    @classmethod
    def _one_dwell_per_rate(cls, dwell, info: ValidationInfo):
        rates = info.data.get("rates_deg_s")
        if rates is not None and len(dwell) != len(rates):
            raise ValueError(f"needs one dwell time per rate: {len(rates)} rates, {len(dwell)} dwell times")
        return dwell

    def schedule(self):
        """Segments of constant acceleration: start time (s), angle (rad), rate (rad/s), accel (rad/s²).

        Returns four arrays (M,); segment ``m`` lasts from ``start[m]`` to ``start[m + 1]`` (the last one
        for ever). Ramps have ``accel = ±max_accel_deg_s2``, dwells 0.
        """
        max_accel = np.radians(self.max_accel_deg_s2)
        start, angle, rate, accel = [0.0], [np.radians(self.initial_angle_deg)], [0.0], []

        def run(duration, a, rate_after):
            """Close the open segment after ``duration`` at acceleration ``a``; open the next one."""
            accel.append(a)
            start.append(start[-1] + duration)
            angle.append(angle[-1] + rate[-1] * duration + 0.5 * a * duration**2)  # θ0 + ω0 τ + ½ a τ²
            rate.append(rate_after)

        for target, dwell in zip(np.radians(self.rates_deg_s), self.dwell_s):
            if target != rate[-1]:
                run(abs(target - rate[-1]) / max_accel, np.copysign(max_accel, target - rate[-1]), target)
            run(dwell, 0.0, target)
        accel.append(0.0)  # the last rate is held
        return np.array(start), np.array(angle), np.array(rate), np.array(accel)

    def angle(self, t):
        """Table angle, rate and acceleration (N,) each: piecewise quadratic, linear, constant."""
        start, angle0, rate0, accel = self.schedule()
        k = np.clip(np.searchsorted(start, t, side="right") - 1, 0, None)
        tau = t - start[k]
        a = accel[k]
        rate = rate0[k] + a * tau
        return angle0[k] + (rate0[k] + 0.5 * a * tau) * tau, rate, a


class Tumble(Section):
    """``[tumble]``: the table top dwells at each listed attitude, then turns smoothly to the next.

    ``rpy_deg`` lists table-top attitudes relative to the base frame (with the default level base and
    mount: the body's attitudes in the world; the six faces up are ``[0,0,0]``, ``[180,0,0]``,
    ``[90,0,0]``, ``[-90,0,0]``, ``[0,-90,0]``, ``[0,90,0]``: z, −z, y, −y, x, −x up). Position ``k`` is
    held from ``k (dwell_s + move_s)`` for ``dwell_s``; the move to the next takes ``move_s`` and turns
    about the fixed axis of the relative rotation (the shortest way, as a two-axis table or a hand on a
    precision cube does), with angle ``φ S(τ/move_s)`` (:func:`smooth_step`), so that the rate rises and
    falls smoothly to a peak of ``(16/5) φ / move_s``. After the last position the table stays there.
    """

    rpy_deg: list[Vec3] = Field(min_length=1)
    dwell_s: PositiveReal
    move_s: PositiveReal

    def schedule(self):
        """Positions as quaternions (K, 4) and the rotation vectors (K, 3) of the moves from each to the
        next in table-top axes (the last one zero), rad."""
        q = quat_from_rpy_deg(np.asarray(self.rpy_deg, dtype=float).reshape(-1, 3))
        moves = np.zeros((len(q), 3))
        moves[:-1] = quat_to_rotvec(quat_multiply(quat_conjugate(q[:-1]), q[1:]))
        return q, moves


class RateTableSpec(EarthBoundSpec):
    """``kind = "rate-table"``: a single-axis rate table on the bench, in one of three modes.

    Give exactly one of the tables ``[constant]``, ``[steps]`` or ``[tumble]``, and optionally
    ``[table]`` (base attitude, mounting rotation, lever arm).

    For the turning modes ``q_wb = q_base ⊗ Rz(θ) ⊗ q_mount``: the body turns about the fixed body axis
    ``u_b = R_mount^T e_z``, so ``ω_wb = θ̇ u_b`` and ``α_wb = θ̈ u_b``. A body at lever arm ``r``
    (table-top axes) from the axis moves on a circle: ``p = R_wt r``, ``v = ω × p`` and
    ``a = α × p + ω × (ω × p)`` with ``ω = θ̇ n_w``, ``α = θ̈ n_w`` about the world axis ``n_w = R_base e_z``.
    """

    kind: Literal["rate-table"] = "rate-table"
    table: Table = Field(default_factory=Table)
    constant: ConstantRate | None = None
    steps: RateSteps | None = None
    tumble: Tumble | None = None

    @field_validator("steps", "tumble")
    @classmethod
    def _one_mode(cls, value, info: ValidationInfo):
        given = [m for m in ("constant", "steps") if m != info.field_name and info.data.get(m) is not None]
        if value is not None and given:
            raise ValueError(f"give one mode table only, not both [{given[0]}] and [{info.field_name}]")
        return value

    @model_validator(mode="after")
    def _a_mode(self):
        if self.constant is None and self.steps is None and self.tumble is None:
            raise ValueError("a rate table needs one mode table: [constant], [steps] or [tumble]")
        return self

    @property
    def mode(self) -> str:
        return next(m for m in ("constant", "steps", "tumble") if getattr(self, m) is not None)

    def world_motion(self, t):
        t = np.asarray(t, dtype=float)
        q_base = quat_from_rpy_deg(self.table.base_rpy_deg)
        q_mount = quat_from_rpy_deg(self.table.mount_rpy_deg)
        if self.tumble is not None:
            return self._tumble_motion(t, q_base, q_mount)
        grid = TimeGrid(t)
        if self.constant is not None:
            # θ = θ0 + ω t: one segment of the schedule (the steps' formulas give exactly θ0 + ω t), and
            # θ/2 = θ0/2 + (ω/2) t, cosine and sine by angle addition.
            rate = np.radians(self.constant.rate_deg_s)
            initial = np.radians(self.constant.initial_angle_deg)
            schedule = tuple(np.array([x]) for x in (0.0, initial, rate, 0.0))
            half = grid.phasor(0.5 * rate, 0.5 * initial)
        else:
            schedule = self.steps.schedule()
            half = grid.phasor(0.0)  # unused: cos(θ/2), sin(θ/2) directly
        # q_wb = q_base ⊗ Rz(θ) ⊗ q_mount = cos(θ/2) A + sin(θ/2) B
        a, b = rotation_basis(_E_Z, q_base, q_mount)
        axis_b = quat_rotate(quat_conjugate(q_mount), _E_Z)  # u_b = R_mount^T e_z
        n = len(t)
        lever = np.asarray(self.table.lever_arm_m, dtype=float)
        arrays = _motion_arrays(n, moves=bool(lever.any()))
        angle, rate = np.empty(n), np.empty(n)
        _rate_table_kernel(
            t,
            grid.uniform,
            grid.BLOCK,
            schedule,
            half,
            self.constant is not None,
            a,
            b,
            axis_b,
            q_base,
            lever,
            *arrays,
            angle,
            rate,
        )
        return WorldMotion(t, *arrays, extras={"table_angle_rad": angle, "table_rate_rad_s": rate})

    def _tumble_motion(self, t, q_base, q_mount):
        tumble = self.tumble
        positions, moves = tumble.schedule()
        angles = np.linalg.norm(moves, axis=1)  # |φ_k|, rad
        axes = moves / np.where(angles > 0, angles, 1.0)[:, None]  # φ̂_k, table-top axes
        # q_wb = q_base ⊗ q_k ⊗ exp(½ S φ_k) ⊗ q_mount = cos(S|φ|/2) A_k + sin(S|φ|/2) B_k
        a, b = rotation_basis(axes, quat_multiply(q_base, positions), q_mount)
        axes_b = quat_rotate(quat_conjugate(q_mount), axes)  # R_mount^T φ̂_k
        lever = np.asarray(self.table.lever_arm_m, dtype=float)
        arrays = _motion_arrays(len(t), moves=bool(lever.any()))
        _tumble_kernel(
            t,
            tumble.dwell_s + tumble.move_s,
            tumble.dwell_s,
            tumble.move_s,
            angles,
            a,
            b,
            axes,
            axes_b,
            quat_conjugate(q_mount),
            lever,
            *arrays,
        )
        return WorldMotion(t, *arrays)


@njit
def _rate_table_kernel(
    t,
    uniform,
    block,
    schedule,
    half,
    by_phasor,
    a,
    b,
    axis_b,
    q_base,
    lever,
    q,
    omega,
    alpha,
    pos,
    vel,
    acc,
    angle_out,
    rate_out,
):  # pragma: no cover - compiled
    """:meth:`RateTableSpec.world_motion` in the turning modes, block by block.

    ``schedule``: segments of constant angular acceleration (:meth:`RateSteps.schedule`), which give the
    table angle, rate and acceleration of each sample. ``cos(θ/2)``, ``sin(θ/2)`` of the block come from
    the phasor ``half`` of ``θ/2`` (:meth:`TimeGrid.phasor`) when ``by_phasor`` (constant rate), else from
    :func:`_sincos_block`.
    """
    start_s, angle0, rate0, accel0 = schedule
    n_w = _rotate(q_base, 0.0, 0.0, 1.0)  # the table axis in the world
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    c, s, half_angle, accels = np.empty(block), np.empty(block), np.empty(block), np.empty(block)
    k = 0
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        for i in range(count):
            j = start + i
            k = _segment(start_s, t[j], k)
            tau = t[j] - start_s[k]
            accels[i] = accel0[k]
            rate_out[j] = rate0[k] + accel0[k] * tau
            angle_out[j] = angle0[k] + (rate0[k] + 0.5 * accel0[k] * tau) * tau  # θ0 + ω0 τ + ½ a τ²
            half_angle[i] = 0.5 * angle_out[j]
        if by_phasor:
            _phasor_block(t, start, count, uniform, half, c, s)
        else:
            _sincos_block(half_angle, count, s, c)
        for i in range(count):
            j = start + i
            rate, accel = rate_out[j], accels[i]
            for m in range(4):
                q[j, m] = c[i] * a[m] + s[i] * b[m]
            for m in range(3):
                omega[j, m] = rate * axis_b[m]  # ω_wb = θ̇ u_b
                alpha[j, m] = accel * axis_b[m]  # α_wb = θ̈ u_b
            if has_lever:
                # p = R_base Rz(θ) r, with cos θ = c² − s², sin θ = 2 s c from the half angle.
                cos, sin = c[i] * c[i] - s[i] * s[i], 2 * s[i] * c[i]
                px, py, pz = _rotate(q_base, lever[0] * cos - lever[1] * sin, lever[0] * sin + lever[1] * cos, lever[2])
                # v = θ̇ n × p,  a = θ̈ n × p + θ̇² n × (n × p)
                nx, ny, nz = _cross(n_w[0], n_w[1], n_w[2], px, py, pz)
                nnx, nny, nnz = _cross(n_w[0], n_w[1], n_w[2], nx, ny, nz)
                rate2 = rate * rate
                pos[j, 0], pos[j, 1], pos[j, 2] = px, py, pz
                vel[j, 0], vel[j, 1], vel[j, 2] = rate * nx, rate * ny, rate * nz
                acc[j, 0] = accel * nx + rate2 * nnx
                acc[j, 1] = accel * ny + rate2 * nny
                acc[j, 2] = accel * nz + rate2 * nnz


@njit
def _tumble_kernel(
    t, period, dwell, move, angles, a, b, axes, axes_b, q_mount_conj, lever, q, omega, alpha, pos, vel, acc
):  # pragma: no cover - compiled
    """The tumble of :meth:`RateTableSpec._tumble_motion`, one pass over the samples."""
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    last = len(angles) - 1
    for j in range(len(t)):
        k = int(min(max(np.floor(t[j] / period), 0.0), last))
        # u ≤ 0 while dwelling, 0 → 1 while moving
        u = (t[j] - k * period - dwell) / move
        step, slope, curvature, _, _ = _smooth_step_at(u)
        angle = angles[k]
        # While dwelling the half angle is 0: cos 1, sin 0; the trigonometry only for the moves.
        c, s = 1.0, 0.0
        if step * angle != 0.0:
            s, c = _sin_cos(0.5 * angle * step)
        for m in range(4):
            q[j, m] = c * a[k, m] + s * b[k, m]
        rate = angle * slope / move  # d/dt (S |φ|) = |φ| S′ / T
        accel = angle * curvature / (move * move)
        for m in range(3):
            omega[j, m] = rate * axes_b[k, m]
            alpha[j, m] = accel * axes_b[k, m]
        if has_lever:
            # Rigid lever arm on the table top:
            # p = R_wt r,  v = R_wt (ω_t × r),  a = R_wt (α_t × r + ω_t × (ω_t × r)),  q_wt = q_wb ⊗ q_mount*.
            pw, px, py, pz = q[j, 0], q[j, 1], q[j, 2], q[j, 3]
            mw, mx, my, mz = q_mount_conj[0], q_mount_conj[1], q_mount_conj[2], q_mount_conj[3]
            q_wt = (
                pw * mw - px * mx - py * my - pz * mz,
                pw * mx + px * mw + py * mz - pz * my,
                pw * my - px * mz + py * mw + pz * mx,
                pw * mz + px * my - py * mx + pz * mw,
            )
            wx, wy, wz = rate * axes[k, 0], rate * axes[k, 1], rate * axes[k, 2]
            ax, ay, az = accel * axes[k, 0], accel * axes[k, 1], accel * axes[k, 2]
            wrx, wry, wrz = _cross(wx, wy, wz, lever[0], lever[1], lever[2])
            arx, ary, arz = _cross(ax, ay, az, lever[0], lever[1], lever[2])
            wwx, wwy, wwz = _cross(wx, wy, wz, wrx, wry, wrz)
            pos[j, 0], pos[j, 1], pos[j, 2] = _rotate(q_wt, lever[0], lever[1], lever[2])
            vel[j, 0], vel[j, 1], vel[j, 2] = _rotate(q_wt, wrx, wry, wrz)
            acc[j, 0], acc[j, 1], acc[j, 2] = _rotate(q_wt, arx + wwx, ary + wwy, arz + wwz)


# --------------------------------------------------------------------------------------------------
# oscillation
# --------------------------------------------------------------------------------------------------


class AngularOscillation(Section):
    """``[angular]``: ``θ(t) = A sin(2π f t + φ)`` about the body axis ``axis_b`` (normalised)."""

    axis_b: Vec3 = (1.0, 0.0, 0.0)
    amplitude_deg: NonNegativeReal
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0

    @field_validator("axis_b")
    @classmethod
    def _nonzero(cls, axis):
        _unit(axis, "the oscillation axis")
        return axis


class LinearOscillation(Section):
    """``[linear]``: ``p(t) = a sin(2π f t + φ)`` with the amplitude vector ``a`` in world (ENU) axes."""

    amplitude_m: Vec3
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0


class OscillationSpec(EarthBoundSpec):
    """``kind = "oscillation"``: angular oscillation about a body axis, optionally a linear oscillation.

    ``q_wb = q_0 ⊗ exp(½ θ(t) n_b)`` with the mean attitude ``q_0`` (``[attitude]``): a rotation about a
    fixed body axis, so ``ω_wb = θ̇ n_b``, ``α_wb = θ̈ n_b`` exactly.
    """

    kind: Literal["oscillation"] = "oscillation"
    attitude: Attitude = Field(default_factory=Attitude)
    angular: AngularOscillation
    linear: LinearOscillation | None = None

    def world_motion(self, t):
        t = np.asarray(t, dtype=float)
        grid = TimeGrid(t)
        osc = self.angular
        axis = _unit(osc.axis_b, "axis_b")
        # Channels (amplitude, ω, φ): θ = A sin(2π f t + φ); with [linear] the position along the
        # amplitude vector a, sin(2π f_l t + φ_l).
        channels = [(np.radians(osc.amplitude_deg), 2 * np.pi * osc.frequency_hz, np.radians(osc.phase_deg))]
        directions = np.zeros((0, 3))
        if self.linear is not None:
            lin = self.linear
            channels.append((1.0, 2 * np.pi * lin.frequency_hz, np.radians(lin.phase_deg)))
            directions = np.asarray(lin.amplitude_m, dtype=float)[None, :]
        sines = grid.sines(*np.array(channels).T[:, :, None])  # each (C, 1)
        a, b = rotation_basis(axis, self.attitude.quat())
        arrays = _motion_arrays(len(t), moves=self.linear is not None)
        _axis_oscillation_kernel(t, grid.uniform, grid.BLOCK, sines, a, b, axis, directions, *arrays)
        return WorldMotion(t, *arrays)


@njit
def _axis_oscillation_kernel(
    t, uniform, block, sines, a, b, axis, directions, q, omega, alpha, pos, vel, acc
):  # pragma: no cover - compiled
    """Oscillation about a fixed body axis with linear oscillations, block by block (oscillation, sculling).

    Channel 0 of the sums of sinusoids ``sines`` is the angle θ about ``axis`` (body axes):
    ``q_wb = cos(θ/2) A + sin(θ/2) B`` (:func:`rotation_basis`), ``ω_wb = θ̇ n``, ``α_wb = θ̈ n``. Each
    further channel ``c`` moves the body along the world vector ``directions[c − 1]`` (position,
    velocity and acceleration: the channel's value and derivatives times it).
    """
    channels = sines[0].shape[0]
    buf = np.empty((3, channels, block))
    half, c, s = np.empty(block), np.empty(block), np.empty(block)
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        _sines_block(t, start, count, uniform, sines, buf)
        for i in range(count):
            half[i] = 0.5 * buf[0, 0, i]
        _sincos_block(half, count, s, c)
        for i in range(count):
            j = start + i
            for m in range(4):
                q[j, m] = c[i] * a[m] + s[i] * b[m]
            for m in range(3):
                omega[j, m] = buf[1, 0, i] * axis[m]
                alpha[j, m] = buf[2, 0, i] * axis[m]
            if channels > 1:
                for m in range(3):
                    p = v = ac = 0.0
                    for ch in range(1, channels):
                        p += buf[0, ch, i] * directions[ch - 1, m]
                        v += buf[1, ch, i] * directions[ch - 1, m]
                        ac += buf[2, ch, i] * directions[ch - 1, m]
                    pos[j, m], vel[j, m], acc[j, m] = p, v, ac


# --------------------------------------------------------------------------------------------------
# coning
# --------------------------------------------------------------------------------------------------


class Coning(Section):
    """``[coning]``: classical coning of half-angle ``half_angle_deg`` at ``frequency_hz``.

    ``reference_rpy_deg`` is the attitude of the cone's reference frame in the world; the body x axis
    sweeps the cone about the reference x axis (``[0, -90, 0]`` points that axis up).
    """

    half_angle_deg: Annotated[Real, Field(gt=0, lt=180)]
    frequency_hz: PositiveReal
    reference_rpy_deg: Vec3 = (0.0, 0.0, 0.0)


class ConingSpec(EarthBoundSpec):
    """``kind = "coning"``: classical coning motion (Savage 1998, part 1).

    The attitude relative to the reference frame is the rotation vector of constant length ``θ`` (the
    cone half-angle) whose direction turns at ``Ω`` in the reference y-z plane::

        φ(t) = θ (0, cos Ωt, sin Ωt),   q_rb = (cos θ/2, sin θ/2 (0, cos Ωt, sin Ωt))

    so the body x axis stays at the angle ``θ`` from the reference x axis. From ``ω = 2 (q* ⊗ q̇)_vec``::

        ω_b = (−Ω (1 − cos θ), −Ω sin θ sin Ωt, Ω sin θ cos Ωt)
        α_b = (0, −Ω² sin θ cos Ωt, −Ω² sin θ sin Ωt)

    The attitude returns to itself every cycle, yet ω has the constant component ``−Ω (1 − cos θ)``
    along x: its integral over a cycle is ``(−2π (1 − cos θ), 0, 0)``, not zero. Integrating the rate
    vector as if it were a rotation vector is wrong by that much per cycle; coning algorithms exist to
    account for the non-commutativity of the rotations.
    """

    kind: Literal["coning"] = "coning"
    coning: Coning

    def world_motion(self, t):
        t = np.asarray(t, dtype=float)
        cone = self.coning
        theta, omega = np.radians(cone.half_angle_deg), 2 * np.pi * cone.frequency_hz
        grid = TimeGrid(t)
        q_ref = quat_from_rpy_deg(cone.reference_rpy_deg)
        # q_wb = q_ref ⊗ q_rb = cos(θ/2) q_ref + sin(θ/2) [cos Ωt (q_ref ⊗ j) + sin Ωt (q_ref ⊗ k)]
        j, k = quat_multiply(q_ref, [0.0, 0.0, 1.0, 0.0]), quat_multiply(q_ref, [0.0, 0.0, 0.0, 1.0])
        w = omega * np.sin(theta)
        n = len(t)
        q, rate, accel = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
        _coning_kernel(
            t,
            grid.uniform,
            grid.BLOCK,
            grid.phasor(omega),
            np.sin(theta / 2) * j,
            np.sin(theta / 2) * k,
            np.cos(theta / 2) * q_ref,
            -omega * (1 - np.cos(theta)),
            w,
            -omega * w,
            q,
            rate,
            accel,
        )
        return WorldMotion.rotation_only(t, q, rate, accel)


@njit
def _coning_kernel(t, uniform, block, phasor, sj, sk, cq, rate_x, w, ow, q, rate, accel):  # pragma: no cover
    """:meth:`ConingSpec.world_motion` block by block: ``q = cos Ωt sj + sin Ωt sk + cq``,
    ``ω = (rate_x, −w sin Ωt, w cos Ωt)``, ``α = (0, ow cos Ωt, ow sin Ωt)`` with ``ow = −Ω w``."""
    c, s = np.empty(block), np.empty(block)
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        _phasor_block(t, start, count, uniform, phasor, c, s)
        for i in range(count):
            j = start + i
            for m in range(4):
                q[j, m] = (c[i] * sj[m] + s[i] * sk[m]) + cq[m]
            rate[j, 0], rate[j, 1], rate[j, 2] = rate_x, -w * s[i], w * c[i]
            accel[j, 0], accel[j, 1], accel[j, 2] = 0.0, ow * c[i], ow * s[i]


# --------------------------------------------------------------------------------------------------
# sculling
# --------------------------------------------------------------------------------------------------


class Sculling(Section):
    """``[sculling]``: angular oscillation about the reference x axis, linear along the reference y axis.

    ``θ(t) = θ0 sin Ωt`` about x; the body's acceleration along y is ``A sin(Ωt + φ)`` (displacement
    ``−A/Ω² sin(Ωt + φ)``), in phase with the angle for ``phase_deg = 0``.
    """

    angular_amplitude_deg: Annotated[Real, Field(gt=0, le=90)]
    acceleration_amplitude_m_s2: PositiveReal
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0
    reference_rpy_deg: Vec3 = (0.0, 0.0, 0.0)


class ScullingSpec(EarthBoundSpec):
    """``kind = "sculling"``: the classical sculling motion (Savage 1998, part 2).

    The body rocks about the reference x axis, ``q_wb = q_ref ⊗ exp(½ θ0 sin(Ωt) e_x)``, while its
    reference point oscillates along the (world-fixed) reference y axis with acceleration
    ``a_y = A sin(Ωt + φ)``. In body axes the non-gravitational specific force is
    ``R_x(θ)^T (0, a_y, 0) = a_y (0, cos θ, −sin θ)``: its z component
    ``−A sin(Ωt + φ) sin(θ0 sin Ωt)`` has a non-zero mean, by the Jacobi–Anger expansion
    ``sin(θ0 sin x) = 2 Σ_k J_{2k+1}(θ0) sin((2k+1)x)``::

        ⟨f_z⟩ = −A J₁(θ0) cos φ  ≈  −½ A θ0 cos φ

    This is the rectified specific force of sculling: accelerometers read a steady force although the
    body goes nowhere, and a velocity algorithm that sums body-axis velocity increments without the
    sculling term drifts by it. (Savage poses the same kinematics from the body side: pure sinusoids
    in body axes, and the rectification ``+A J₁(θ0)`` appears as a real acceleration in the navigation
    frame; here the motion stays bounded, as on a test rig.)
    """

    kind: Literal["sculling"] = "sculling"
    sculling: Sculling

    def world_motion(self, t):
        t = np.asarray(t, dtype=float)
        sc = self.sculling
        omega = 2 * np.pi * sc.frequency_hz
        theta0, accel_amp = np.radians(sc.angular_amplitude_deg), sc.acceleration_amplitude_m_s2
        grid = TimeGrid(t)
        # Channel 0: θ = θ0 sin Ωt.
        # Channel 1: displacement y = −A/Ω² sin(Ωt + φ), so that ÿ = A sin(Ωt + φ), along the reference
        # y axis.
        sines = grid.sines([[theta0], [-accel_amp / omega**2]], omega, [[0.0], [np.radians(sc.phase_deg)]])
        q_ref = quat_from_rpy_deg(sc.reference_rpy_deg)
        e_x = np.array([1.0, 0.0, 0.0])
        y_w = quat_rotate(q_ref, [0.0, 1.0, 0.0])  # the reference y axis in the world
        arrays = _motion_arrays(len(t), moves=True)
        _axis_oscillation_kernel(
            t, grid.uniform, grid.BLOCK, sines, *rotation_basis(e_x, q_ref), e_x, y_w[None, :], *arrays
        )
        return WorldMotion(t, *arrays)
