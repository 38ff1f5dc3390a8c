"""The compiled parts of the MEKF smoother (:mod:`.mekf_smoother`): a forward pass that stores what the
Rauch–Tung–Striebel recursion needs, the backward recursion, and the per-sample output.

Forward (:func:`forward_pass`): the very filter of :mod:`.batched` (the same kernels of
:mod:`.mekf_kernels` and the same Joseph-form algebra), which at the end of each window ``j`` also
stores

* ``F_top[j]`` (5, X_SIZE): the rows of the window's error-state transition that are not the identity's:
  the attitude's three and the acceleration's two (``δb``, ``δM`` are random walks, ``δa`` Gauss–Markov,
  :func:`.mekf_kernels.transition`);
* ``P_prior[j]``: the error covariance before the window's updates (the prediction's);
* ``P_post[j]``: after the updates; and ``x_upd[j]``, the update itself (what was injected into the
  nominal state: the error of the prior nominal state as the filter saw it).

(numba caches this file's functions by its content alone: a change to :mod:`.mekf_kernels` needs
a change here, such as the layout noted here: ``P_SIZE = 35``, ``P_BIAS_RW_VERTICAL`` the last; ``X_SIZE = 17``,
``S_SIZE = 110``; ``gravity_adapt`` with no gate; ``body_vertical`` in the transition and the heading gain;
``P_ACC_GM_PROCESS``, δa's own process noise.)

Index 0 is the initial state (``P_post[0] = P₀``, no update). Float64: 5,520 bytes a window, 166 MB for a
10-minute log at 1 kHz with 20 ms windows (30 000 windows; per-sample storage would be 50× that).

Backward (:func:`rts_backward`), the RTS smoother on the error state (Rauch, Tung & Striebel, AIAA J.
3(8), 1965; the multiplicative form as in Markley & Crassidis, *Fundamentals of Spacecraft Attitude
Determination and Control*, §6.2.5 and Crassidis & Junkins, *Optimal Estimation of Dynamic Systems*,
2nd ed., §5.3, with the reset handled as in Solà, *Quaternion kinematics for the error-state Kalman
filter*, 2017, §7). The forward posterior error is zero (it has been injected) and so is the next
prior's; the smoothed error ``e_j`` is relative to the posterior nominal state of window ``j``, so
relative to the prior nominal state of window ``j+1`` the smoothed error is ``e_{j+1} + x_upd[j+1]``:

    C_j  = P_post[j] F_{j+1}ᵀ P_prior[j+1]⁻¹
    e_j  = C_j (e_{j+1} + x_upd[j+1])
    P_s[j] = P_post[j] + C_j (P_s[j+1] − P_prior[j+1]) C_jᵀ

starting from ``e_W = 0``, ``P_s[W] = P_post[W]``. The smoothed state is the forward posterior
nominal state with ``e_j`` injected (``q ← exp(δθ) ⊗ q``, ``b ← b + δb``, ``M̂ ← M̂ + δM``).

``e_{j+1} + x_upd[j+1]`` is the first order of the reset; the recursion takes it whole
(:func:`reset_composition`): the attitude error relative to the prior is ``log(exp(e) ⊗ exp(u))``, and
the acceleration estimate was turned with the attitude by the injection. A sum is right for small
updates, but the first heading a 6D filter finds from the Earth's rate may turn the nominal state by
a hundred degrees in one window, and the smoothed tilt correction must then turn with it: summed, it
points along the old axes (a car drive in 6D, consumer MEMS: smoothed inclination 0.61°, 0.72°, 0.75°
on seeds 0–2 against the forward pass's 0.32°, 0.59°, 0.70°; composed 0.27°, 0.57°, 0.42°). The
covariances keep the forward pass's convention, whose injection leaves ``P`` as it is (the reset's
Jacobian taken as I, as in the forward filter), so the recursion of ``P_s`` is as written above.

Between window ends (:func:`per_sample`) the sample's nominal attitude is the strapdown from the
previous posterior; its error runs from ``e_j`` at the window's start to ``e_{j+1}`` composed with
``x_upd[j+1]`` at its end, taken linear in time over the window (20 ms), and so is the covariance.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.jit import njit
from gyroemu.dynamics.rotation import half_turn, hamilton_product, set_product

from . import mekf_kernels as kern
from .batched import kalman_predict, kalman_update

X = kern.X_SIZE

WindowStore = tuple[
    NDArray[np.int64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]
"""What :func:`window_store` gives and :func:`forward_pass` takes, in that order: ``end_index``, ``M_post``,
``F_top``, ``P_prior``, ``P_post``, ``x_upd``."""


@njit
def _store_window(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
    P: NDArray[np.float64],
    x: NDArray[np.float64],
    earth: NDArray[np.float64],
    params: NDArray[np.float64],
    use_mag: bool,
    F_top: NDArray[np.float64],
    P_prior: NDArray[np.float64],
    P_post: NDArray[np.float64],
    x_upd: NDArray[np.float64],
    j: int,
) -> None:
    """One window of :func:`.batched._window` (prediction, gravity, rest, heading, injection), storing
    its transition's top rows, the covariance before and after the updates and the update, at ``j``."""
    F = np.empty((X, X))
    Q = np.empty((X, X))
    kern.transition(win, phi, q, earth, params, F, Q)
    kalman_predict(P, F, Q)
    z, H, R = np.empty(2), np.empty((2, X)), np.empty((2, 2))
    F_top[j, 0:3] = F[0:3, :]
    F_top[j, 3:] = F[kern.X_ACC :, :]
    P_prior[j] = P
    if kern.gravity_measurement(win, slow, params, z, H, R):
        kern.gravity_adapt(P, z, H, R, slow, params)
        kern.gravity_update(x, P, z, H, R)
    if kern.rest_due(win, slow, params):
        z3, H3, R3 = np.empty(3), np.empty((3, X)), np.empty((3, 3))
        kern.rest_measurement(win, q, b, earth, params, z3, H3, R3, P)
        if kern.rest_gate(win, slow, params):
            kalman_update(x, P, z3, H3, R3)
    if use_mag:
        kern.heading_update(x, P, q, win, slow, params)
    x_upd[j] = x
    P_post[j] = P
    kern.inject(x, q, b, slow, win, phi)


def window_store(cap: int) -> WindowStore:
    """Empty storage for ``cap`` windows of :func:`forward_pass`, in the order it takes them:
    ``end_index`` (cap,) int64 (−1), ``M_post`` (cap, 9), ``F_top`` (cap, 5, X_SIZE), ``P_prior`` and
    ``P_post`` (cap, X_SIZE, X_SIZE), ``x_upd`` (cap, X_SIZE)."""
    return (
        np.full(cap, -1, dtype=np.int64),
        np.zeros((cap, 9)),
        np.zeros((cap, 5, X)),
        np.zeros((cap, X, X)),
        np.zeros((cap, X, X)),
        np.zeros((cap, X)),
    )


@njit
def forward_pass(
    q: NDArray[np.float64],
    b: NDArray[np.float64],
    slow: NDArray[np.float64],
    P: NDArray[np.float64],
    win: NDArray[np.float64],
    phi: NDArray[np.float64],
    t: NDArray[np.float64],
    gyro: NDArray[np.float64],
    delta: NDArray[np.float64],
    accel: NDArray[np.float64],
    mag: NDArray[np.float64],
    earth: NDArray[np.float64],
    params: NDArray[np.float64],
    use_mag: bool,
    start: int,
    q_out: NDArray[np.float64],
    b_out: NDArray[np.float64],
    cov_out: NDArray[np.float64],
    end_index: NDArray[np.int64],
    M_post: NDArray[np.float64],
    F_top: NDArray[np.float64],
    P_prior: NDArray[np.float64],
    P_post: NDArray[np.float64],
    x_upd: NDArray[np.float64],
    j0: int,
) -> tuple[int, int]:
    """Run the filter from sample ``start`` until the samples end or the window storage (``F_top`` …,
    length ``cap``) fills. ``q``, ``b``, ``slow``, ``P``, ``win``, ``phi`` carry the filter's state.
    Writes ``q_out``, ``b_out`` (n, 3) and ``cov_out`` (n, 3, 3: the forward attitude covariance);
    window ``j`` ends at sample ``end_index[j]`` (the last sample it holds), with ``M̂`` ``M_post[j]``
    after its injection. Returns ``(next sample, windows stored)``, windows numbered from ``j0``."""
    n = len(t)
    x = np.zeros(X)
    k = start
    j = j0
    cap = F_top.shape[0]
    while k < n and j < cap:
        end = kern.strapdown(q, b, slow, win, phi, t, gyro, delta, accel, mag, earth, params, k, q_out)
        for i in range(k, end):  # as Mekf: each sample with the state it was propagated with
            b_out[i, :] = b
            cov_out[i] = P[0:3, 0:3]
        if kern.window_due(win, params):
            _store_window(q, b, slow, win, phi, P, x, earth, params, use_mag, F_top, P_prior, P_post, x_upd, j)
            q_out[end - 1, :] = q
            b_out[end - 1, :] = b
            cov_out[end - 1] = P[0:3, 0:3]
            end_index[j] = end - 1
            for e in range(9):
                M_post[j, e] = slow[kern.S_SCALE + e]
            j += 1
        k = end
    return k, j


@njit
def reset_composition(e: NDArray[np.float64], u: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """The smoothed error ``e`` (X_SIZE,) of a window's posterior nominal state as an error of its prior
    nominal state, into which the forward pass injected the update ``u`` (:func:`.mekf_kernels.inject`):
    ``out`` (X_SIZE,).

    * attitude, world axes: ``exp(out) = exp(e) ⊗ exp(u)``, so ``out = log(exp(e) ⊗ exp(u))``, which is
      ``e + u`` to first order only: a large ``u`` turns the axes of ``e``;
    * the acceleration estimate ``â`` (world axes as estimated): inject adds ``u`` and turns it with the
      attitude, ``â⁺ = T (â⁻ + u)`` (``T`` the 2 × 2 horizontal block of ``R(exp(u))``), so the error of
      ``â⁻`` is ``u + T⁻¹ e``;
    * the bias, scale and misalignment states are added: ``e + u``."""
    for i in range(len(e)):
        out[i] = e[i] + u[i]
    aw, ax, ay, az = half_turn(e[0], e[1], e[2])
    turn = np.empty(4)
    turn[0], turn[1], turn[2], turn[3] = half_turn(u[0], u[1], u[2])
    w, x, y, z = hamilton_product(aw, ax, ay, az, turn[0], turn[1], turn[2], turn[3])
    if w < 0.0:  # the shorter of the two rotation vectors
        w, x, y, z = -w, -x, -y, -z
    sine = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(sine, w) / sine if sine > 1e-300 else 2.0 / w
    out[0], out[1], out[2] = x * scale, y * scale, z * scale
    # T⁻¹, T the horizontal block of R(exp(u)), as inject turns â
    r = np.empty((3, 3))
    kern.quat_to_matrix(turn, r)
    t00, t01, t10, t11 = r[0, 0], r[0, 1], r[1, 0], r[1, 1]
    det = t00 * t11 - t01 * t10
    i0, i1 = kern.X_ACC, kern.X_ACC + 1
    out[i0] = u[i0] + (t11 * e[i0] - t01 * e[i1]) / det
    out[i1] = u[i1] + (t00 * e[i1] - t10 * e[i0]) / det


@njit
def rts_backward(
    F_top: NDArray[np.float64],
    P_prior: NDArray[np.float64],
    P_post: NDArray[np.float64],
    x_upd: NDArray[np.float64],
    e_s: NDArray[np.float64],
    P_s: NDArray[np.float64],
    multiplicative: bool = True,
) -> None:
    """The RTS recursion of the module's notes over windows ``0 … W−1``: ``e_s`` (W, X_SIZE) the
    smoothed errors, ``P_s`` (W, X_SIZE, X_SIZE) their covariances, from ``e_s[W−1]`` and ``P_s[W−1]``
    as given (at the log's last window 0 and ``P_post[W−1]``; a stretch of windows ends with the next
    stretch's first). ``F P_post`` differs from ``P_post`` in the attitude's and acceleration's rows only
    (``F_top``; the other rows of ``F`` are the identity's). A singular ``P_prior`` (the ideal device has
    no process noise) takes its pseudo-inverse. The reset is the filter's, :func:`reset_composition`;
    ``multiplicative=False`` sums instead, the reset of a linear system (for a check against one)."""
    W = F_top.shape[0]
    FP = np.empty((X, X))
    prior_error = np.empty(X)
    for j in range(W - 2, -1, -1):
        FP[:, :] = P_post[j]
        FP[0:3, :] = F_top[j + 1, 0:3] @ P_post[j]
        FP[kern.X_ACC :, :] = F_top[j + 1, 3:] @ P_post[j]
        # C = P_post Fᵀ P_prior⁻¹  ⇔  Cᵀ = P_prior⁻¹ F P_post (both covariances symmetric)
        try:
            Ct = np.ascontiguousarray(np.linalg.solve(P_prior[j + 1], FP))
        except Exception:  # noqa: BLE001 - a singular prior (a noiseless gyro: no process noise)
            Ct = np.ascontiguousarray(np.linalg.pinv(P_prior[j + 1]) @ FP)  # the pseudo-inverse's gain
        C = np.ascontiguousarray(Ct.T)
        if multiplicative:
            reset_composition(e_s[j + 1], x_upd[j + 1], prior_error)
        else:
            prior_error[:] = e_s[j + 1] + x_upd[j + 1]
        e_s[j] = C @ prior_error
        Pj = P_post[j] + C @ (P_s[j + 1] - P_prior[j + 1]) @ Ct
        P_s[j] = 0.5 * (Pj + Pj.T)


@njit
def per_sample(
    t: NDArray[np.float64],
    q_fwd: NDArray[np.float64],
    b_fwd: NDArray[np.float64],
    end_index: NDArray[np.int64],
    e_s: NDArray[np.float64],
    P_s: NDArray[np.float64],
    x_upd: NDArray[np.float64],
    q_out: NDArray[np.float64],
    b_out: NDArray[np.float64],
    cov_out: NDArray[np.float64],
) -> None:
    """The smoothed attitude, bias and attitude covariance of every sample (module's notes). Window
    ``j ≥ 1`` holds the samples ``end_index[j−1]+1 … end_index[j]`` (``end_index[0] = −1``: the
    initial state before the first sample); samples after the last window end keep its smoothed error."""
    n = len(t)
    W = e_s.shape[0]
    e = np.empty(X)
    prior_error = np.empty(X)
    for j in range(1, W + 1):
        lo = end_index[j - 1] + 1
        hi = end_index[j] if j < W else n - 1
        t0 = t[lo - 1] if lo > 0 else t[0] - (t[min(1, n - 1)] - t[0])
        t1 = t[hi]
        span = t1 - t0 if t1 > t0 else 1.0
        if j < W:  # the window's end relative to the strapdown's nominal state, before its update
            reset_composition(e_s[j], x_upd[j], prior_error)
        for k in range(lo, hi + 1):
            if j == W:
                e[:] = e_s[W - 1]
                P3 = P_s[W - 1, 0:3, 0:3]
                f = 0.0
            elif k == hi:
                e[:] = e_s[j]
                f = 1.0
                P3 = P_s[j, 0:3, 0:3]
            else:
                f = (t[k] - t0) / span
                e[:] = (1.0 - f) * e_s[j - 1] + f * prior_error
                P3 = (1.0 - f) * P_s[j - 1, 0:3, 0:3] + f * P_s[j, 0:3, 0:3]
            q = q_fwd[k]
            cw, cx, cy, cz = half_turn(e[0], e[1], e[2])  # q_out ← exp(δθ/2) ⊗ q, world axes
            set_product(q_out[k], cw, cx, cy, cz, q[0], q[1], q[2], q[3])
            for i in range(3):
                b_out[k, i] = b_fwd[k, i] + e[kern.X_BIAS + i]
            for a in range(3):
                for c in range(3):
                    cov_out[k, a, c] = 0.5 * (P3[a, c] + P3[c, a])
