"""The motion toolkit: compiled building blocks of the closed-form motions.

The prescribed motions (:mod:`gyroemu.dynamics.motions`, :mod:`gyroemu.dynamics.vehicles`) evaluate their
closed forms in compiled kernels (numba, :func:`gyroemu.dynamics.jit.njit`) assembled from the pieces here:

* :class:`TimeGrid`: sample times, and sinusoids ``sin(ω t + φ)`` on them, by angle addition on uniform
  grids; its tables feed :func:`phasor_block` (one sinusoid) and :func:`sines_block` (sums of sinusoids
  with their first two derivatives), which evaluate a block of samples at a time;
* :func:`sin_cos` and :func:`sincos_block`: sine and cosine of arbitrary angles, branch-free and
  vectorisable up to :data:`SINCOS_LIMIT`;
* :func:`smooth_step` (arrays) and :func:`smooth_step_at` (one sample, compiled): a C⁵ step from 0 to 1
  with its derivatives and integral;
* :func:`segment_index`: which segment of a piecewise schedule a sample falls in;
* :func:`quat_rotate_xyz`, :func:`cross_xyz`: one rotation and one cross product on scalar components;
* :func:`rotation_basis`: the two constant quaternions of a rotation about a fixed axis, which the kernels
  combine with the cosine and sine of the half angle.

The compiled functions are called from other compiled functions; import them by name
(``from .motion_kernels import sines_block``), so that :mod:`gyroemu.dynamics.jit` finds them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .jit import njit
from .rotation import quat_multiply

__all__ = [
    "TimeGrid",
    "SINCOS_LIMIT",
    "sin_cos",
    "sincos_block",
    "phasor_block",
    "sines_block",
    "smooth_step_at",
    "smooth_step",
    "segment_index",
    "quat_rotate_xyz",
    "cross_xyz",
    "rotation_basis",
]

_EPS = np.finfo(float).eps

PhasorTable = tuple[float, float, NDArray[np.float64], NDArray[np.float64]]
"""What :meth:`TimeGrid.phasor` gives and :func:`phasor_block` takes: ``(ω, φ, cos table, sin table)``."""

SinesTable = tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]
]
"""What :meth:`TimeGrid.sines` gives and :func:`sines_block` takes: amplitudes, angular frequencies and
phases (C, K), and the offset tables (C, K, B)."""

# --------------------------------------------------------------------------------------------------
# Time grids and sinusoids
# --------------------------------------------------------------------------------------------------
#
# Speed. The kinds evaluate their closed forms in compiled kernels (numba) that write every output once,
# in place, block by block (``TimeGrid.BLOCK`` samples, whose scratch arrays stay in the CPU cache).
# Measured on 10⁶ samples: a fresh (N, 3) array costs 2–3 ns per sample in first touches of new memory,
# and written in numpy a kind needs dozens of them; a sine and cosine from the C library cost about
# 10 ns, by angle addition (TimeGrid) or from sincos_block about 1 ns.


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
    (:func:`phasor_block`, :func:`sines_block`).

    Parameters
    ----------
    t : array_like (N,)
        Sample times, s.
    """

    BLOCK = 1024
    """Samples per block ``B``: the offset tables and the kernels' scratch arrays."""

    def __init__(self, t: ArrayLike) -> None:
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

    def _offset_tables(self, omega: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``cos(ω i h)`` and ``sin(ω i h)`` for ``i < B``, shape ``omega.shape + (B,)``; empty (last axis
        0) on other grids, whose kernels evaluate directly."""
        omega = np.asarray(omega, dtype=float)
        if not self.uniform:
            empty = np.empty(omega.shape + (0,))
            return empty, empty
        angle = omega[..., None] * (np.arange(self.BLOCK) * self.h)
        return np.cos(angle), np.sin(angle)

    def phasor(self, omega: float, phase: float = 0.0) -> PhasorTable:
        """What :func:`phasor_block` needs for ``cos(ω t + φ)``, ``sin(ω t + φ)``: ``(ω, φ, cos table,
        sin table)``, ``ω`` in rad/s, ``φ`` in rad, the tables (B,) (empty on a grid that is not uniform)."""
        return (float(omega), float(phase)) + self._offset_tables(float(omega))

    def sines(self, amplitude: ArrayLike, omega: ArrayLike, phase: ArrayLike) -> SinesTable:
        """What :func:`sines_block` needs for ``x_c = Σ_k A_ck sin(ω_ck t + φ_ck)``: the arrays (C, K)
        broadcast from ``amplitude, omega, phase`` (any of (C, K), (C, 1), (K,), scalar; any unit, rad/s,
        rad) and the offset tables (C, K, B) (empty last axis on a grid that is not uniform)."""
        a, w, p = (
            np.ascontiguousarray(x)
            for x in np.broadcast_arrays(
                *(np.atleast_2d(np.asarray(x, dtype=float)) for x in (amplitude, omega, phase))
            )
        )
        return (a, w, p) + self._offset_tables(w)

    def cos_sin(self, omega: float, phase: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``cos(ω t + φ)`` and ``sin(ω t + φ)``, each (N,); ``ω`` in rad/s, ``φ`` in rad."""
        c, s = np.empty(len(self.t)), np.empty(len(self.t))
        _cos_sin_kernel(self.t, self.uniform, self.BLOCK, self.phasor(omega, phase), c, s)
        return c, s

    def sum_of_sines(self, amplitude: ArrayLike, omega: ArrayLike, phase: ArrayLike) -> NDArray[np.float64]:
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
# written out without branches, vectorise and take about 1 ns a pair in the loops of sincos_block.
# Error below 0.8 ulp (the library's: 0.5); results differ from the library's by one ulp in about 3 % of
# arguments. Valid for |x| ≤ SINCOS_LIMIT, where the reduction below is exact; callers fall back to
# the library beyond it (and for NaN, inf).

SINCOS_LIMIT = 1e6
"""|x| up to which :func:`_sincos_branchless` is accurate: ``n = round(2x/π) < 2²⁰``, so that ``n`` times the
33-bit parts of π/2 is exact."""


@njit(inline="always")
def _sincos_branchless(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """``(sin x, cos x)`` for ``|x| ≤ SINCOS_LIMIT``, branch-free (see the comment above)."""
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
def sin_cos(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """``(sin x, cos x)`` of one angle ``x`` (rad, float): :func:`_sincos_branchless` for
    ``|x| ≤ SINCOS_LIMIT``, the C library beyond (and for NaN, inf). Returns two floats."""
    if abs(x) <= SINCOS_LIMIT:
        pair: tuple[float, float] = _sincos_branchless(x)
        return pair
    return np.sin(x), np.cos(x)


@njit
def sincos_block(
    x: NDArray[np.float64], count: int, s: NDArray[np.float64], c: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """``s[i], c[i] = sin x[i], cos x[i]`` for ``i < count``: one vectorised loop, then the library for
    arguments beyond :data:`SINCOS_LIMIT` (and NaN).

    ``x`` (≥ count,) angles, rad; ``s``, ``c`` (≥ count,) float arrays written in place; returns nothing.
    """
    for i in range(count):
        s[i], c[i] = _sincos_branchless(x[i])
    for i in range(count):
        if not abs(x[i]) <= SINCOS_LIMIT:
            s[i], c[i] = np.sin(x[i]), np.cos(x[i])


@njit
def _grid_deviation(t: NDArray[np.float64], t0: float, h: float) -> float:  # pragma: no cover - compiled
    """``max_n |t_n − (t_0 + n h)|`` in one pass (numpy would make three temporaries of N)."""
    deviation = 0.0
    for n in range(len(t)):
        deviation = max(deviation, abs(t[n] - (t0 + n * h)))
    return deviation


@njit
def phasor_block(
    t: NDArray[np.float64],
    start: int,
    count: int,
    uniform: bool,
    phasor: PhasorTable,
    c: NDArray[np.float64],
    s: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``cos(ω t + φ)``, ``sin(ω t + φ)`` at the samples ``start … start + count − 1`` into
    ``c[:count]``, ``s[:count]``; ``phasor`` from :meth:`TimeGrid.phasor`. On a uniform grid ``start``
    must begin a block (a multiple of ``B``).

    ``t`` (N,) sample times, s; ``uniform`` :attr:`TimeGrid.uniform`; ``c``, ``s`` (≥ count,) float
    arrays written in place; returns nothing.
    """
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
def sines_block(
    t: NDArray[np.float64], start: int, count: int, uniform: bool, sines: SinesTable, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """Value, first and second derivative of the sums of sinusoids ``sines`` (:meth:`TimeGrid.sines`)
    at the samples ``start … start + count − 1`` into ``out[d, c, :count]`` (d = 0, 1, 2).

    ``t`` (N,) sample times, s; ``uniform`` :attr:`TimeGrid.uniform`; ``out`` (3, C, ≥ count) float array
    written in place (units: the amplitudes', per s, per s²); returns nothing. On a uniform grid ``start``
    must begin a block (a multiple of ``B``).

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
                    sin, cos = sin_cos(w * t[start + i] + phase[ch, k])
                    value[i] += a * sin
                    first[i] += a1 * cos
                    second[i] -= a2 * sin


@njit
def _cos_sin_kernel(
    t: NDArray[np.float64],
    uniform: bool,
    block: int,
    phasor: PhasorTable,
    c: NDArray[np.float64],
    s: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:meth:`TimeGrid.cos_sin` block by block."""
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        phasor_block(t, start, count, uniform, phasor, c[start:], s[start:])


@njit
def _sum_of_sines_kernel(
    t: NDArray[np.float64], uniform: bool, block: int, sines: SinesTable, out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """:meth:`TimeGrid.sum_of_sines` block by block, into ``out`` (3, C, N)."""
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        sines_block(t, start, count, uniform, sines, out[:, :, start:])


# --------------------------------------------------------------------------------------------------
# Smooth steps
# --------------------------------------------------------------------------------------------------


@njit
def smooth_step_at(u: float) -> tuple[float, float, float, float, float]:  # pragma: no cover - compiled
    """``(S, S′, S″, S‴, I)`` of :func:`smooth_step` at one ``u`` (float, normalised time or distance):
    five floats, derivatives with respect to ``u``."""
    if u <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0, 0.0, 0.0, u - 0.5
    s, c = _sincos_branchless(2 * np.pi * u)
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
def _smooth_step_kernel(u: NDArray[np.float64], out: NDArray[np.float64]) -> None:  # pragma: no cover - compiled
    """:func:`smooth_step` of every ``u`` (N,) into ``out`` (5, N)."""
    for n in range(len(u)):
        out[0, n], out[1, n], out[2, n], out[3, n], out[4, n] = smooth_step_at(u[n])


def smooth_step(u: ArrayLike, derivatives: int = 3, integral: bool = False) -> tuple[NDArray[np.float64], ...]:
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
    tuple of ndarray, each of the shape of ``u``
        ``(S, S′, …, S^(derivatives))``, then ``I`` when asked for.
    """
    u = np.asarray(u, dtype=float)
    out = np.empty((5,) + u.shape)  # S, S′, S″, S‴, I
    _smooth_step_kernel(u.reshape(-1), out.reshape(5, -1))  # the kinds' kernels call smooth_step_at
    return tuple(out[k, ...] for k in range(derivatives + 1)) + ((out[4, ...],) if integral else ())


# --------------------------------------------------------------------------------------------------
# Rotations about fixed axes, vectors and schedules
# --------------------------------------------------------------------------------------------------


def rotation_basis(
    axis: ArrayLike, q_left: ArrayLike = (1.0, 0.0, 0.0, 0.0), q_right: ArrayLike = (1.0, 0.0, 0.0, 0.0)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
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


@njit
def quat_rotate_xyz(
    q: NDArray[np.float64] | tuple[float, float, float, float], x: float, y: float, z: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``q ⊗ (0, v) ⊗ q*`` for one vector ``v = (x, y, z)``: the formula of
    :func:`gyroemu.dynamics.rotation.quat_rotate`, ``v + 2w (u × v) + 2 u × (u × v)``.

    ``q`` (4,) unit quaternion ``(w, u)``; ``x, y, z`` floats (any unit); returns the rotated vector as
    three floats (the same unit).
    """
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
def cross_xyz(
    ax: float, ay: float, az: float, bx: float, by: float, bz: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``a × b`` as ``np.cross`` computes it, for vectors given as three floats each; returns three floats."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit
def segment_index(edges: NDArray[np.float64], x: float, k: int) -> int:  # pragma: no cover - compiled
    """``max(searchsorted(edges, x, side="right") − 1, 0)``: the last of the sorted ``edges`` at or
    before ``x`` (0 before the first). Tries ``k``, the previous sample's segment, first: consecutive
    samples mostly share it.

    ``edges`` (M,) sorted segment starts, ``x`` a float in their unit (s, m), ``k`` an int in
    ``[0, M)``; returns the segment's index, an int.
    """
    last = len(edges) - 1
    if (k == 0 or edges[k] <= x) and (k == last or x < edges[k + 1]):
        return k
    return max(int(np.searchsorted(edges, x, side="right")) - 1, 0)
