"""Geometric splitting integrators for the free rigid body and the symmetric heavy top.

Method
------
Both bodies are Lie–Poisson systems: the state is the attitude ``q_wb`` and the angular momentum
``L``, and the Hamiltonian is split into parts whose flows are *exact rotations* (McLachlan 1993,
"Explicit Lie–Poisson integration and the Euler equations", Phys. Rev. Lett. 71; Touma & Wisdom
1994, "Lie–Poisson integrators for rigid body dynamics in the solar system", Astron. J. 107;
Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. 2006, §VII.5). A flow of the form
"turn the body about a body-fixed axis ``e`` by the angle ``a``" acts as::

    q ← q ⊗ (cos a/2, sin a/2 e)          (attitude, body-fixed axis)
    L_b ← R_e(a)ᵀ L_b                     (the same world vector seen from the turned body)

and leaves the world momentum ``L_w = R L_b`` unchanged, so every sub-step keeps ``|L|``, the world
momentum (free body) and the quaternion's unit norm to round-off.

Free body, principal moments permuted so that ``(A, B, C)`` sit on the internal ``(x, y, z)`` axes::

    T = |L|²/2A  +  ½ (1/C − 1/A) L_z²  +  ½ (1/B − 1/A) L_y²
        └ H0 ┘     └──── Hz ──────┘     └──── Hy ──────┘

``H0`` is a Casimir: it commutes with everything, so its flow, a rotation of the whole body about
the fixed ``L_w`` at the rate ``|L|/A``, is applied once in closed form,
``q(t) = exp(L_w t / 2A) ⊗ q̃(t)``. Only ``Hz + Hy`` is split: ``Hz`` turns the body about its ``z``
axis at ``(1/C − 1/A) L_z``, ``Hy`` about its ``y`` axis at ``(1/B − 1/A) L_y``. The two
non-symmetric axes are chosen so that ``|1/B − 1/A|`` is the smallest of the three such
differences: for a symmetric body ``Hy = 0`` and the scheme is exact for any step.

Symmetric heavy top (moments ``A, A, C`` about the pivot, centre of mass at ``l e_z``)::

    H = |L|²/2A  +  ½ (1/C − 1/A) L₃²  +  m g l cos θ
        └ H0 ┘     └───── Hz ─────┘     └─── V ───┘

``Hz`` commutes with ``H0`` and with ``V`` (a turn about the symmetry axis leaves the axis, hence
``V``, unchanged, and gravity's torque is perpendicular to the axis), so the spin about the symmetry
axis, at the constant rate ``(1/C − 1/A) L₃``, is also applied in closed form:
``q(t) = q̃(t) ⊗ exp(e_z (1/C − 1/A) L₃ t / 2)``. The rest, ``H0 + V``, is split into the exact
rotation about ``L_w`` (``H0``) and the gravity kick ``L_w ← L_w + h m g l ẑ × n`` with the attitude
(so the symmetry axis ``n``) held fixed (``V``). Both keep ``L_z = ẑ·L_w`` and ``L₃ = n·L_w`` exactly:
the kick is perpendicular to both ``ẑ`` and ``n``, the rotation turns ``n`` about ``L_w``.

Order
-----
The Strang step ``φ_A(h/2) φ_B(h) φ_A(h/2)`` is symmetric and of order 2; it is raised to order
``p`` by the symmetric composition ``Π_i Strang(γ_i h)`` (Yoshida 1990, Phys. Lett. A 150;
Kahan & Li 1997, Math. Comp. 66, methods s9odr6a and s17odr8a; HLW §V.3.2).
Splitting keeps the invariants above whatever the step; the step only sets the (bounded, non-drifting)
energy error and the phase error, which grows linearly in time.

Step size
---------
The local error of an order-``p`` composition is ``≈ K_p (ω h)^(p+1)`` with ``ω`` the fastest
frequency the split flows turn at (heavy top: ``max(|L|_max / A, sqrt(m g l / A))``, ``|L|_max``
bounded by the energy). The step is the largest that keeps the error per radian of that motion,
``K_p (ω h)^p``, below ``tol``, made to divide each output interval exactly (steps end on the
samples); the composition (order 2, 4, 6 or 8) that needs the fewest sub-flows for that is used.
``K_p`` (Strang 5e-2, triple jump 1e-2, Kahan–Li 6: 2e-5, Kahan–Li 8: 2e-7) was measured on the
state (attitude and momentum) of both problems, asymmetric, near-flat and near-symmetric free bodies,
slow, toy, fast and precessing heavy tops, against elliptic solutions and tight runs: the largest
value seen, rounded up to keep a margin of at least 1.5. ``tests/dynamics/test_tops.py`` checks the
resulting errors against closed forms.
For the free body the error terms are nested brackets holding ``Hz`` and ``Hy`` at least once each,
so ``ω`` is ``|L| (c_max^p c_min)^(1/(p+1))`` with ``c = |1/C − 1/A|, |1/B − 1/A|``: near-symmetric
bodies need few steps and symmetric ones one per sample.

Round-off
---------
Every sub-flow updates the state as ``x ← x + (small increment)``, whose rounding is unbiased; the
textbook ``x ← cos(a) x + sin(a) y`` rounds the same way step after step and drifts by ~1e-16 per
sub-step (1e-8 after an hour at 1 kHz). The quaternion is renormalised at each sample.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .inertia import principal_axes
from .jit import njit
from .rotation import quat_conjugate, quat_from_matrix, quat_multiply, quat_rotate

__all__ = [
    "Composition",
    "COMPOSITIONS",
    "DEFAULT_TOL",
    "plan_steps",
    "integrate_free_body",
    "integrate_heavy_top",
    "free_body_frequency",
    "heavy_top_frequency",
]


@dataclass(frozen=True)
class Composition:
    """A symmetric composition ``Π_i Strang(γ_i h)`` of order ``order``.

    Attributes
    ----------
    name : str
    order : int
    gammas : ndarray (s,)
        The step fractions ``γ_i``, summing to 1.
    error_constant : float
        ``K_p`` in the local error ``K_p (ω h)^(p+1)`` of one step (measured, rounded up).
    """

    name: str
    order: int
    gammas: NDArray[np.float64]
    error_constant: float

    @property
    def stages(self) -> int:
        return len(self.gammas)

    @property
    def a(self) -> NDArray[np.float64]:
        """Fractions of the outer flow ``A`` in ``A(a_0 h) B(b_0 h) A(a_1 h) … B(b_{s-1} h) A(a_s h)``:
        ``a_0 = γ_1/2``, ``a_i = (γ_i + γ_{i+1})/2``, ``a_s = γ_s/2`` (touching half-steps merged)."""
        g = self.gammas
        fractions: NDArray[np.float64] = 0.5 * (np.concatenate([g, [0.0]]) + np.concatenate([[0.0], g]))
        return fractions

    @property
    def b(self) -> NDArray[np.float64]:
        """Fractions ``b_i = γ_{i+1}`` of the inner flow ``B``."""
        return self.gammas

    def max_phase_per_step(self, tol: float) -> float:
        """Largest ``ω h`` (rad) with error per radian ``K_p (ω h)^p`` at most ``tol``."""
        phase: float = (tol / self.error_constant) ** (1.0 / self.order)
        return phase


def _triple_jump() -> NDArray[np.float64]:
    # Yoshida (1990), Suzuki (1990): γ1 = γ3 = 1 / (2 − 2^(1/3)), γ2 = 1 − 2 γ1.
    g1 = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    return np.array([g1, 1.0 - 2.0 * g1, g1])


def _symmetric(half: list[float]) -> NDArray[np.float64]:
    """``γ_1 … γ_m … γ_1`` from ``γ_1 … γ_m``."""
    return np.array(half + half[-2::-1])


COMPOSITIONS: tuple[Composition, ...] = (
    Composition("Strang", 2, np.array([1.0]), error_constant=5e-2),
    Composition("Yoshida triple jump", 4, _triple_jump(), error_constant=1e-2),
    Composition(
        "Kahan-Li s9odr6a",
        6,
        # Kahan & Li (1997), method s9odr6a; also in HLW §V.3.2.
        _symmetric(
            [
                0.39216144400731413927925056,
                0.33259913678935943859974864,
                -0.70624617255763935980996482,
                0.08221359629355080023149045,
                0.79854399093482996339895035,
            ]
        ),
        error_constant=2e-5,
    ),
    Composition(
        "Kahan-Li s17odr8a",
        8,
        # Kahan & Li (1997), method s17odr8a; also in HLW §V.3.2.
        _symmetric(
            [
                0.13020248308889008087881763,
                0.56116298177510838456196441,
                -0.38947496264484728640807860,
                0.15884190655515560089621075,
                -0.39590389413323757733623154,
                0.18453964097831570709183254,
                0.25837438768632204729397911,
                0.29501172360931029887096624,
                -0.60550853383003451169892108,
            ]
        ),
        error_constant=2e-7,
    ),
)
"""The compositions :func:`plan_steps` chooses from, by increasing order."""


DEFAULT_TOL = 1e-14
"""Default error per radian of the fastest split rotation. A step of ``ω h ≈ 0.05`` rad then errs by
~5e-16, the round-off of the step itself; an hour of the toy top (2·10⁵ rad) stays within 2e-9."""


def plan_steps(
    t: ArrayLike,
    omega: Callable[[int], float] | float,
    tol: float,
    compositions: Sequence[Composition] = COMPOSITIONS,
) -> tuple[Composition, NDArray[np.int64]]:
    """Composition and step counts for output times ``t`` (s) and error target ``tol``.

    Parameters
    ----------
    t : ndarray (N,)
        Increasing output times, s; integration starts at 0.
    omega : callable or float
        Fastest frequency of the split flows, rad/s; a callable gets the order ``p``.
    tol : float
        Error per radian of that motion.

    Returns
    -------
    composition : Composition
        The one needing the fewest sub-flows.
    n_steps : ndarray (N,) of int64
        Steps in each interval ``[t_{k-1}, t_k]`` (``t_{-1} = 0``), at least one unless it is empty.
    """
    t = np.asarray(t, dtype=float)
    dt = np.diff(t, prepend=0.0)  # interval k runs from t[k-1] to t[k], the first from 0
    if dt.size and dt.min() < 0:
        raise ValueError("output times must be increasing and not negative")
    dt_max = float(dt.max()) if dt.size else 0.0

    def h_max(comp: Composition) -> float:
        w = omega(comp.order) if callable(omega) else float(omega)
        return comp.max_phase_per_step(tol) / w if w > 0 else np.inf

    # Sub-flows per longest interval (all intervals, for the uniform grids of scenarios).
    best = min(compositions, key=lambda comp: comp.stages * max(1.0, np.ceil(dt_max / h_max(comp))))
    n_steps = np.maximum(1.0, np.ceil(dt / h_max(best))).astype(np.int64)
    n_steps[dt == 0] = 0
    return best, n_steps


# --------------------------------------------------------------------------------------------------
# Kernels. The state lives in small arrays updated in place; each flow is an exact rotation.


@njit(inline="always")
def _turn_body_z(q: NDArray[np.float64], L: NDArray[np.float64], a: float) -> None:
    """Body turns by ``a`` about its own z axis: ``q ← q ⊗ (cos a/2, 0, 0, sin a/2)``,
    ``L_b ← R_z(a)ᵀ L_b``.

    Written as increments, ``x ← x + (small)``, whose round-off is unbiased, with
    ``1 − cos a/2 = sin² a/2 / (1 + cos a/2)`` and ``1 − cos a = 2 sin² a/2`` free of cancellation:
    ``x ← cos(a) x + …`` would round the same way step after step and drift by ~1e-16 per step.
    """
    c2 = np.cos(0.5 * a)
    s2 = np.sin(0.5 * a)
    k2 = s2 * s2 / (1.0 + c2)  # 1 − cos a/2
    w, x, y, z = q[0], q[1], q[2], q[3]
    q[0] = w - (k2 * w + s2 * z)
    q[1] = x - (k2 * x - s2 * y)
    q[2] = y - (k2 * y + s2 * x)
    q[3] = z - (k2 * z - s2 * w)
    k = 2.0 * s2 * s2  # 1 − cos a
    s = 2.0 * s2 * c2  # sin a
    lx, ly = L[0], L[1]
    L[0] = lx + (s * ly - k * lx)
    L[1] = ly - (s * lx + k * ly)


@njit(inline="always")
def _turn_body_y(q: NDArray[np.float64], L: NDArray[np.float64], a: float) -> None:
    """Body turns by ``a`` about its own y axis: ``q ← q ⊗ (cos a/2, 0, sin a/2, 0)``,
    ``L_b ← R_y(a)ᵀ L_b`` (increments as in :func:`_turn_body_z`)."""
    c2 = np.cos(0.5 * a)
    s2 = np.sin(0.5 * a)
    k2 = s2 * s2 / (1.0 + c2)
    w, x, y, z = q[0], q[1], q[2], q[3]
    q[0] = w - (k2 * w + s2 * y)
    q[1] = x - (k2 * x + s2 * z)
    q[2] = y - (k2 * y - s2 * w)
    q[3] = z - (k2 * z - s2 * x)
    k = 2.0 * s2 * s2
    s = 2.0 * s2 * c2
    lz, lx = L[2], L[0]
    L[2] = lz + (s * lx - k * lz)
    L[0] = lx - (s * lz + k * lx)


@njit(inline="always")
def _turn_world(q: NDArray[np.float64], L: NDArray[np.float64], h_over_a: float) -> None:
    """Body turns about the world vector ``L`` by ``|L| h / A``: ``q ← exp(L h / 2A) ⊗ q``."""
    norm_l = np.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2])
    if norm_l == 0.0:
        return
    half = 0.5 * norm_l * h_over_a
    c2 = np.cos(half)
    s2 = np.sin(half)
    k2 = s2 * s2 / (1.0 + c2)  # 1 − cos
    f = s2 / norm_l
    ex, ey, ez = f * L[0], f * L[1], f * L[2]
    w, x, y, z = q[0], q[1], q[2], q[3]
    # q ← (c2, e) ⊗ q = q − k2 q + (0, e) ⊗ q
    q[0] = w - (k2 * w + ex * x + ey * y + ez * z)
    q[1] = x - (k2 * x - ex * w - ey * z + ez * y)
    q[2] = y - (k2 * y - ey * w + ex * z - ez * x)
    q[3] = z - (k2 * z - ez * w - ex * y + ey * x)


@njit(inline="always")
def _kick(q: NDArray[np.float64], L: NDArray[np.float64], h_mgl: float) -> None:
    """Gravity acts for ``h`` with the attitude fixed: ``L_w ← L_w + h m g l ẑ × n``, where
    ``n = R(q) e_z`` is the symmetry axis and ``ẑ × n = (−n_y, n_x, 0)``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    nx = 2.0 * (x * z + w * y)
    ny = 2.0 * (y * z - w * x)
    L[0] -= h_mgl * ny
    L[1] += h_mgl * nx


@njit(inline="always")
def _normalise(q: NDArray[np.float64]) -> None:
    """``q ← q / |q|``."""
    norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for j in range(4):
        q[j] /= norm


@njit(inline="always")
def _quat_mul(p: NDArray[np.float64], q: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """Hamilton product ``p ⊗ q`` of two length-4 arrays, as a tuple."""
    return (
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    )


@njit
def _free_body_kernel(
    t: NDArray[np.float64],
    q0: NDArray[np.float64],
    L0: NDArray[np.float64],
    lw: NDArray[np.float64],
    cz: float,
    cy: float,
    inv_a: float,
    q_ib: NDArray[np.float64],
    m_bi: NDArray[np.float64],
    a_coef: NDArray[np.float64],
    b_coef: NDArray[np.float64],
    n_steps: NDArray[np.int64],
    q_out: NDArray[np.float64],
    L_out: NDArray[np.float64],
) -> None:
    """Torque-free body sampled at ``t``: the split flow of ``Hz + Hy``, then ``H0`` and the axes.

    ``q0`` (4,), ``L0`` (3,): attitude and body momentum at time 0 in the internal frame; ``lw`` (3,)
    the (constant) world momentum ``R(q0) L0``; ``cz = 1/C − 1/A``, ``cy = 1/B − 1/A``,
    ``inv_a = 1/A`` (1/(kg m²)); ``q_ib`` (4,) and ``m_bi`` (3, 3) turn internal axes into body axes;
    ``a_coef``, ``b_coef``: the composition's step fractions (:attr:`Composition.a`,
    :attr:`Composition.b`). Writes, at each ``t[k]``::

        q_wb = exp(L_w t / 2A) ⊗ q̃ ⊗ q_ib      (H0 in closed form, then body axes)
        L_b  = M_bi L̃
    """
    q = q0.copy()
    L = L0.copy()
    norm_lw = np.sqrt(lw[0] * lw[0] + lw[1] * lw[1] + lw[2] * lw[2])
    e = np.empty(4)
    t_prev = 0.0
    for k in range(t.shape[0]):
        n = n_steps[k]
        if n > 0:
            h = (t[k] - t_prev) / n
            # Strang(γ_i h) = Hz(γ_i h/2) Hy(γ_i h) Hz(γ_i h/2), composed over i and over the n
            # steps, with the touching Hz half-steps merged (Hz keeps L_z, so they add exactly).
            s = b_coef.shape[0]
            _turn_body_z(q, L, cz * L[2] * a_coef[0] * h)  # Hz
            for step in range(n):
                for i in range(s - 1):
                    _turn_body_y(q, L, cy * L[1] * b_coef[i] * h)  # Hy
                    _turn_body_z(q, L, cz * L[2] * a_coef[i + 1] * h)  # Hz
                _turn_body_y(q, L, cy * L[1] * b_coef[s - 1] * h)
                a_last = a_coef[s] + (a_coef[0] if step < n - 1 else 0.0)  # joins the next step's first
                _turn_body_z(q, L, cz * L[2] * a_last * h)
            _normalise(q)  # against round-off, ~1e-16 per sample
        t_prev = t[k]
        # H0 for the whole time t[k]: a turn by |L| t / A about L_w (exact, no accumulation).
        half = 0.5 * norm_lw * inv_a * t[k]
        e[0] = np.cos(half)
        f = np.sin(half) / norm_lw if norm_lw > 0.0 else 0.0
        e[1], e[2], e[3] = f * lw[0], f * lw[1], f * lw[2]
        q_out[k, :] = _quat_mul(_quat_mul(e, q), q_ib)
        for j in range(3):
            L_out[k, j] = m_bi[j, 0] * L[0] + m_bi[j, 1] * L[1] + m_bi[j, 2] * L[2]


@njit
def _heavy_top_kernel(
    t: NDArray[np.float64],
    q0: NDArray[np.float64],
    Lw0: NDArray[np.float64],
    inv_a: float,
    mgl: float,
    spin_rate: float,
    a_coef: NDArray[np.float64],
    b_coef: NDArray[np.float64],
    n_steps: NDArray[np.int64],
    q_out: NDArray[np.float64],
    Lw_out: NDArray[np.float64],
) -> None:
    """Heavy top sampled at ``t``: the split flow of ``H0 + V``, then ``Hz`` in closed form.

    ``q0`` (4,) attitude and ``Lw0`` (3,) world angular momentum about the pivot at time 0;
    ``inv_a = 1/A`` (1/(kg m²)), ``mgl = m g l`` (J), ``spin_rate = (1/C − 1/A) L₃`` (rad/s);
    ``a_coef``, ``b_coef``: the composition's step fractions. Writes, at each ``t[k]``::

        q_wb = q̃ ⊗ (cos ½ωt, 0, 0, sin ½ωt),  ω = spin_rate      (Hz in closed form)
        L_w
    """
    q = q0.copy()
    L = Lw0.copy()
    spin = np.zeros(4)
    t_prev = 0.0
    for k in range(t.shape[0]):
        n = n_steps[k]
        if n > 0:
            h = (t[k] - t_prev) / n
            # Strang(γ_i h) = V(γ_i h/2) H0(γ_i h) V(γ_i h/2), composed over i and over the n
            # steps, with the touching half-kicks merged (a kick keeps the attitude: they add exactly).
            s = b_coef.shape[0]
            _kick(q, L, a_coef[0] * h * mgl)  # V
            for step in range(n):
                for i in range(s - 1):
                    _turn_world(q, L, b_coef[i] * h * inv_a)  # H0
                    _kick(q, L, a_coef[i + 1] * h * mgl)  # V
                _turn_world(q, L, b_coef[s - 1] * h * inv_a)
                a_last = a_coef[s] + (a_coef[0] if step < n - 1 else 0.0)  # joins the next step's first
                _kick(q, L, a_last * h * mgl)
            _normalise(q)  # against round-off, ~1e-16 per sample
        t_prev = t[k]
        # Hz for the whole time t[k]: spin about the symmetry axis (exact, no accumulation).
        spin[0] = np.cos(0.5 * spin_rate * t[k])
        spin[3] = np.sin(0.5 * spin_rate * t[k])
        q_out[k, :] = _quat_mul(q, spin)
        Lw_out[k, :] = L


# --------------------------------------------------------------------------------------------------


def _internal_axes(inertia_b: ArrayLike) -> tuple[NDArray[np.float64], float, float, float]:
    """The free body's internal axes and split coefficients: ``(m_bi, 1/A, cz, cy)``, ``m_bi`` (3, 3)
    the internal axes (columns) in body coordinates, ``cz = 1/C − 1/A``, ``cy = 1/B − 1/A``."""
    inertia_b = np.asarray(inertia_b, dtype=float)
    if np.count_nonzero(inertia_b - np.diag(np.diag(inertia_b))) == 0:
        moments, axes = np.diag(inertia_b).copy(), np.eye(3)  # already principal: no round-off
    else:
        moments, axes = principal_axes(inertia_b)  # axes: a proper rotation, columns in body axes
    inv = 1.0 / moments

    # Internal axes: a cyclic shift of the principal axes (a proper rotation) that puts on z the
    # axis k whose two companions have the closest 1/I, so that the split's Hy is the smallest.
    k = int(np.argmin([abs(inv[(j + 1) % 3] - inv[(j + 2) % 3]) for j in range(3)]))
    perm = [(k + 1) % 3, (k + 2) % 3, k]  # internal x, y, z = principal axes perm[0], perm[1], perm[2]
    m_bi = axes[:, perm]  # columns: internal axes in body coordinates
    inv_a, inv_b, inv_c = inv[perm]
    return m_bi, inv_a, inv_c - inv_a, inv_b - inv_a  # numpy scalars, as the integrator always had them


def _free_body_rate(norm_l: float, cz: float, cy: float, p: int) -> float:
    """The free body's fastest split frequency for an order-``p`` composition, rad/s."""
    # Error terms are brackets holding Hz and Hy at least once each: ~ c_max^p c_min |L|^(p+1).
    c_max, c_min = max(abs(cz), abs(cy)), min(abs(cz), abs(cy))
    rate: float = norm_l * (c_max**p * c_min) ** (1.0 / (p + 1))
    return rate


def free_body_frequency(L0_b: ArrayLike, inertia_b: ArrayLike) -> float:
    """The fastest split frequency ``ω`` :func:`integrate_free_body` steps a torque-free body by, rad/s
    (module notes: its step is about 0.12 rad / ω at the default tolerance), for the highest order (the
    largest: ``c_max (c_min/c_max)^(1/(p+1))`` grows with ``p``). ``L0_b``: angular momentum, body axes,
    kg m²/s; ``inertia_b``: the (3, 3) tensor, kg m²."""
    m_bi, _, cz, cy = _internal_axes(inertia_b)
    norm_l = float(np.linalg.norm(m_bi.T @ np.asarray(L0_b, dtype=float)))
    return _free_body_rate(norm_l, cz, cy, max(comp.order for comp in COMPOSITIONS))


def integrate_free_body(
    t: ArrayLike,
    q0_wb: ArrayLike,
    L0_b: ArrayLike,
    inertia_b: ArrayLike,
    tol: float = DEFAULT_TOL,
    compositions: Sequence[Composition] = COMPOSITIONS,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Torque-free rigid body, sampled at ``t``.

    Parameters
    ----------
    t : ndarray (N,)
        Increasing output times, s; the initial state is at time 0.
    q0_wb : array_like (4,)
        Initial attitude (unit quaternion, body to world).
    L0_b : array_like (3,)
        Initial angular momentum about the centre of mass, body axes, kg m²/s.
    inertia_b : array_like (3, 3)
        Inertia tensor about the centre of mass in body axes, kg m² (any symmetric positive
        definite tensor; it is integrated in its principal axes).
    tol : float
        Integrator error per radian of the fastest split rotation (module docstring).
    compositions : sequence of Composition
        The methods to choose from (the default: all of :data:`COMPOSITIONS`).

    Returns
    -------
    q_wb : ndarray (N, 4)
    L_b : ndarray (N, 3)
        Angular momentum in body axes, kg m²/s (``ω_b = I⁻¹ L_b``).
    """
    t = np.asarray(t, dtype=float)
    m_bi, inv_a, cz, cy = _internal_axes(inertia_b)
    q_bi = quat_from_matrix(m_bi)
    q0_wi = quat_multiply(np.asarray(q0_wb, dtype=float), q_bi)
    L0_i = m_bi.T @ np.asarray(L0_b, dtype=float)
    norm_l = float(np.linalg.norm(L0_i))
    comp, n_steps = plan_steps(t, lambda p: _free_body_rate(norm_l, cz, cy, p), tol, compositions)
    q_wb = np.empty((len(t), 4))
    L_b = np.empty((len(t), 3))
    L_w = quat_rotate(q0_wi, L0_i)  # constant
    q_ib = quat_conjugate(q_bi)
    _free_body_kernel(t, q0_wi, L0_i, L_w, cz, cy, inv_a, q_ib, m_bi, comp.a, comp.b, n_steps, q_wb, L_b)
    return q_wb, L_b


def _heavy_top_rate(
    q0: NDArray[np.float64], L0_w: NDArray[np.float64], moment_a: float, moment_c: float, mgl: float
) -> tuple[float, float]:
    """The heavy top's fastest split frequency (rad/s) and its spin momentum ``L₃`` (kg m²/s)."""
    n0 = quat_rotate(q0, np.array([0.0, 0.0, 1.0]))  # symmetry axis, world
    return _heavy_top_rate_about(n0, L0_w, moment_a, moment_c, mgl)


def _heavy_top_rate_about(
    n0: NDArray[np.float64], L0_w: NDArray[np.float64], moment_a: float, moment_c: float, mgl: float
) -> tuple[float, float]:
    """:func:`_heavy_top_rate` of the top whose symmetry axis is ``n0`` (world, unit)."""
    inv_a, inv_c = 1.0 / moment_a, 1.0 / moment_c
    l3 = float(n0 @ L0_w)  # spin component, conserved

    # Energy bounds |L|: |L|²/2A = E − ½(1/C − 1/A) L₃² − m g l n_z  ≤  E − ½(1/C − 1/A) L₃² + |m g l|.
    energy = 0.5 * inv_a * (L0_w @ L0_w) + 0.5 * (inv_c - inv_a) * l3**2 + mgl * n0[2]
    l_max = np.sqrt(max(2.0 * moment_a * (energy - 0.5 * (inv_c - inv_a) * l3**2 + abs(mgl)), 0.0))
    omega = max(l_max * inv_a, np.sqrt(abs(mgl) * inv_a))  # rotation about L_w; pendulum frequency
    return float(omega), l3


def heavy_top_frequency(axis_w: ArrayLike, L0_w: ArrayLike, moment_a: float, moment_c: float, mgl: float) -> float:
    """The fastest split frequency ``ω`` :func:`integrate_heavy_top` steps a heavy top by, rad/s: the
    larger of the fastest turn about ``L_w`` the energy allows and the pendulum frequency
    ``√(|m g l|/A)`` (module notes: its step is about 0.12 rad / ω at the default tolerance). ``axis_w``:
    the top's symmetry axis at the start, world (unit; the body's z turned by ``q0_wb``); the others as
    :func:`integrate_heavy_top`'s. Plain numpy: a config is checked with it without loading numba."""
    n0 = np.asarray(axis_w, dtype=float)
    return _heavy_top_rate_about(n0, np.asarray(L0_w, dtype=float), moment_a, moment_c, mgl)[0]


def integrate_heavy_top(
    t: ArrayLike,
    q0_wb: ArrayLike,
    L0_w: ArrayLike,
    moment_a: float,
    moment_c: float,
    mgl: float,
    tol: float = DEFAULT_TOL,
    compositions: Sequence[Composition] = COMPOSITIONS,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Symmetric top on a fixed pivot under uniform gravity along −z, sampled at ``t``.

    Parameters
    ----------
    t : ndarray (N,)
        Increasing output times, s; the initial state is at time 0.
    q0_wb : array_like (4,)
        Initial attitude; body z is the symmetry axis, pointing from the pivot to the centre of mass.
    L0_w : array_like (3,)
        Initial angular momentum about the pivot, world axes, kg m²/s.
    moment_a, moment_c : float
        Transverse and axial moments of inertia about the pivot, kg m².
    mgl : float
        ``m g l``: weight times pivot-to-centre-of-mass distance, J.
    tol : float
        Integrator error per radian of the fastest split rotation (module docstring).
    compositions : sequence of Composition
        The methods to choose from (the default: all of :data:`COMPOSITIONS`).

    Returns
    -------
    q_wb : ndarray (N, 4)
    L_w : ndarray (N, 3)
        Angular momentum about the pivot, world axes, kg m²/s.
    """
    t = np.asarray(t, dtype=float)
    q0 = np.asarray(q0_wb, dtype=float)
    L0_w = np.asarray(L0_w, dtype=float)
    inv_a, inv_c = 1.0 / moment_a, 1.0 / moment_c
    omega, l3 = _heavy_top_rate(q0, L0_w, moment_a, moment_c, mgl)
    comp, n_steps = plan_steps(t, omega, tol, compositions)
    q_wb = np.empty((len(t), 4))
    L_w = np.empty((len(t), 3))
    _heavy_top_kernel(t, q0, L0_w, inv_a, mgl, (inv_c - inv_a) * l3, comp.a, comp.b, n_steps, q_wb, L_w)
    return q_wb, L_w
