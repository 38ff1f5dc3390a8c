"""Offline attitude: the MEKF forward over the whole log, then a Rauch–Tung–Striebel pass backward.

A recorded log is known whole, so every sample's estimate may use its future as well as its past. The
forward pass is gyroemu's MEKF (:mod:`.mekf`; the same compiled kernels as :mod:`.batched`, so its
attitude is the online filter's); at the end of each window it stores the error-state transition's top
rows, the covariance before and after the window's updates, and the update it injected. The backward
pass is the RTS smoother on the error state (Rauch, Tung & Striebel 1965; for the multiplicative
error state and its reset see :mod:`.mekf_smoother_kernels`): its smoothed correction is applied to the
forward posterior quaternion, bias and scale/misalignment of each window, and interpolated over the
window's samples. The output carries the smoothed attitude covariance, at the updates no larger than
the forward one where every update is a Kalman update (``P_s = P_post + C (P_s⁺ − P_prior⁺) Cᵀ`` and
``P_s⁺ ≤ P_prior⁺`` by induction); the heading's gain, which never corrects the tilt, and the gravity
update's, which never corrects the considered acceleration, are not, and may raise it along some
direction; between window ends it is interpolated towards the next window's.

Memory: float64 storage of 5.5 kB a window (17 error states), about 166 MB for a 10-minute log at 1 kHz (20 ms
windows), plus the per-sample outputs (about 100 bytes a sample for the forward and smoothed states).
:class:`MekfSmoother`'s ``learn`` runs the same passes a block at a time with the storage on disk, in
memory that does not grow with the log (:mod:`.mekf_smoother_spool`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from . import mekf_kernels as kern
from . import mekf_smoother_kernels as skern
from .mekf import MekfParams, earth_rate_enu, initial_state
from .mekf_smoother_spool import SmootherSpool, spool_bytes
from .protocol import Estimate, FilterSetup

__all__ = ["SMOOTHER_DEFAULTS", "MekfSmoother", "SmootherResult", "smoother_params", "smooth_log"]

SMOOTHER_DEFAULTS: dict[str, float] = {
    # The field where the body moves may point elsewhere than where it rests (BROAD: 2–4° off in the
    # working volume, within 0.4–1.9° of the reference at rest); a pass that sees both rests anchors
    # the heading there and bridges the motion with the gyro, whose bias it knows from both ends.
    "heading_motion_factor": 10.0,
    # Misalignment prior of an unknown gyro (the online filter's 1 % lets heading disturbances leak
    # into the cross-axis states, which the backward pass then carries over the whole log).
    "misalignment_sigma": 0.003,
}
"""The smoother's own defaults, where they differ from the online filter's (:class:`MekfParams`):
one global set, chosen on the eight BROAD trials in shared (README); a device's known figures win."""


def smoother_params(setup: FilterSetup, **overrides: float) -> MekfParams:
    """:meth:`MekfParams.for_setup` with :data:`SMOOTHER_DEFAULTS` wherever the device left the
    online default in place, then ``overrides``."""
    params = MekfParams.for_setup(setup)
    online = MekfParams()
    own = {k: v for k, v in SMOOTHER_DEFAULTS.items() if getattr(params, k) == getattr(online, k)}
    return replace(params, **(own | overrides))


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """Both passes over a log of N samples.

    Attributes
    ----------
    forward, smoothed : Estimate
        ``q_wb`` (N, 4), ``gyro_bias`` (N, 3) rad/s and ``q_wb_covariance`` (N, 3, 3) rad² (world-axes
        attitude error): the forward pass's (the online filter's with the same parameters), and the
        smoother's.
    window_end : ndarray (W,)
        Index of each window's last sample (the forward updates' instants).
    scale_misalignment : ndarray (W, 3, 3)
        The smoothed gyro scale-factor and misalignment errors ``M`` at each window end.
    forward_s, backward_s : float
        Wall time of the forward pass (with its storage) and of the backward pass (the RTS recursion
        and the per-sample output), s.
    """

    forward: Estimate
    smoothed: Estimate
    window_end: np.ndarray
    scale_misalignment: np.ndarray
    forward_s: float = 0.0
    backward_s: float = 0.0


def smooth_log(
    setup: FilterSetup,
    t: ArrayLike,
    gyro: ArrayLike | None,
    accel: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    delta_angle: ArrayLike | None = None,
    params: MekfParams | None = None,
) -> SmootherResult:
    """The MEKF forward and the RTS smoother backward over one whole log.

    Parameters
    ----------
    setup : FilterSetup
    t : ndarray (N,)
        Stamps, s, increasing.
    gyro, accel : ndarray (N, 3)
        rad/s and m/s²; ``mag`` (N, 3) T or None (6D).
    delta_angle : ndarray (N, 3), optional
        The gyro's angle increments over ``[t_{k−1}, t_k]``, rad, instead of ``gyro``.
    params : MekfParams, optional
        Default: :func:`smoother_params`.
    """
    params = params if params is not None else smoother_params(setup)
    t = np.ascontiguousarray(t, dtype=float)
    n = len(t)
    accel = np.ascontiguousarray(accel, dtype=float)
    if delta_angle is not None:
        delta = np.ascontiguousarray(delta_angle, dtype=float)
        gyro = delta / np.diff(t, prepend=t[0] - 1.0 / setup.rate_hz)[:, None] if n else delta
    else:
        gyro = np.ascontiguousarray(gyro, dtype=float)
        delta = np.empty((0, 3))
    if gyro.shape != (n, 3) or accel.shape != (n, 3):
        raise ValueError(f"gyro and accel must have shape ({n}, 3), got {gyro.shape} and {accel.shape}")
    if n > 1 and not np.all(np.diff(t) > 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1
        raise ValueError(f"sample {bad}: stamp {t[bad]!r} s does not increase")
    use_mag = bool(setup.use_mag and mag is not None)
    mag = np.ascontiguousarray(mag, dtype=float) if use_mag else np.full((n, 3), np.nan)
    if n == 0:
        empty = Estimate(np.empty((0, 4)), np.empty((0, 3)), np.empty((0, 3, 3)))
        return SmootherResult(empty, empty, np.empty(0, dtype=np.int64), np.empty((0, 3, 3)))
    started = time.perf_counter()
    p = params.vector(setup)
    init = initial_state(t, gyro, accel, mag if use_mag else None, setup, params)
    q, b, slow, P = init.q.copy(), init.b.copy(), init.slow.copy(), init.P.copy()
    win = np.zeros(kern.W_SIZE)
    phi = np.zeros((3, kern.N_DRIFT))
    earth = earth_rate_enu(setup)
    q_f, b_f, cov_f = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3, 3))
    # windows: index 0 is the initial state; capacity for the expected count, grown if stamps need more,
    # and never more than the n + 1 a log can close (a window holds a sample at least: a pause in the
    # stamps closes one window, however long it is)
    expected = int((t[-1] - t[0]) / params.window_s) + n // max(1, int(p[kern.P_WINDOW_N])) // 8 + 64
    expected = min(expected, n + 1)
    chunks = []
    k, j0 = 0, 1
    first = True
    while k < n:
        cap = expected if first else max(64, (n - k) // max(1, int(p[kern.P_WINDOW_N])) + 64)
        store = skern.window_store(cap)
        if first:
            store[1][0] = slow[kern.S_SCALE : kern.S_SCALE + 9]
            store[4][0] = P
        start_j = j0 if first else 0
        k, j = skern.forward_pass(
            q, b, slow, P, win, phi, t, gyro, delta, accel, mag, earth, p, use_mag, k, q_f, b_f, cov_f, *store, start_j
        )
        chunks.append(tuple(a[:j] for a in store))
        first = False
    end_index, M_post, F_top, P_prior, P_post, x_upd = (
        np.concatenate(parts) if len(chunks) > 1 else parts[0] for parts in zip(*chunks)
    )
    forward_s = time.perf_counter() - started
    W = len(end_index)
    e_s = np.empty((W, kern.X_SIZE))
    P_s = np.empty((W, kern.X_SIZE, kern.X_SIZE))
    e_s[W - 1], P_s[W - 1] = 0.0, P_post[W - 1]  # the last window's smoothed state is its forward one
    skern.rts_backward(F_top, P_prior, P_post, x_upd, e_s, P_s)
    q_s, b_s, cov_s = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3, 3))
    skern.per_sample(t, q_f, b_f, end_index, e_s, P_s, x_upd, q_s, b_s, cov_s)
    M_s = (M_post + e_s[:, kern.X_SCALE : kern.X_SCALE + 9]).reshape(W, 3, 3)
    return SmootherResult(
        forward=Estimate(q_f, b_f, cov_f),
        smoothed=Estimate(q_s, b_s, cov_s),
        window_end=end_index[1:],
        scale_misalignment=M_s[1:],
        forward_s=forward_s,
        backward_s=time.perf_counter() - started - forward_s,
    )


class MekfSmoother:
    """The offline filter ``mekf-smooth``: :func:`smooth_log` behind the filter protocol.

    Offline. Either ``process`` takes the whole log in one call (a second call is an error: the
    backward pass needs the end; ``process_increments`` takes delta angles), or, for a log too long to
    hold, :meth:`learn` takes it a block at a time and ``process`` then gives the same blocks' smoothed
    estimates one after another (:class:`~.mekf_smoother_spool.SmootherSpool`: the same bytes, in memory
    that does not grow with the log, the storage in temporary files in the folder given to
    :meth:`spool_in` or the system's). ``learns_in_blocks`` says a filter can do the second.
    """

    name = "mekf-smooth"
    offline = True
    learns_in_blocks = True

    def __init__(self, setup: FilterSetup, params: MekfParams | None = None):
        self.setup = setup
        self.params = params if params is not None else smoother_params(setup)
        self.result: SmootherResult | None = None
        self.spool: SmootherSpool | None = None
        self._spool_folder: str | os.PathLike[str] | None = None

    def spool_in(self, folder: str | os.PathLike[str] | None) -> None:
        """Where :meth:`learn` keeps its temporary files (None: the system's temporary folder)."""
        self._spool_folder = folder

    def spool_bytes(self, samples: int, duration_s: float) -> int:
        """About how many bytes :meth:`learn` keeps in temporary files for a log of ``samples`` samples
        over ``duration_s`` s (:func:`~.mekf_smoother_spool.spool_bytes`)."""
        return spool_bytes(samples, duration_s, self.params.window_s)

    def _check_once(self) -> None:
        if self.result is not None:
            raise ValueError("mekf-smooth is offline: it takes the whole log in one process() call")

    def learn(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> None:
        """Take the log's next block into the forward pass (:meth:`SmootherSpool.learn`: the first block
        starts the filter, so give it the filter's start-up seconds); arguments as :meth:`process`'s."""
        self._check_once()
        if self.spool is None:
            self.spool = SmootherSpool(self.setup, self.params, folder=self._spool_folder)
        self.spool.learn(t, gyro, accel, mag)

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        """Smooth the whole log: ``t`` (N,) s, ``gyro`` (N, 3) rad/s, ``accel`` (N, 3) m/s², ``mag``
        (N, 3) T or None. Returns the smoothed attitude, bias and attitude covariance of each sample.
        After :meth:`learn`: the smoothed estimate of the next ``len(t)`` samples learned."""
        if self.spool is not None:
            return self.spool.process(t, gyro, accel, mag)
        self._check_once()
        self.result = smooth_log(self.setup, t, gyro, accel, mag, params=self.params)
        return self.result.smoothed

    def process_increments(
        self, t: np.ndarray, delta_angle: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None
    ) -> Estimate:
        """As :meth:`process`, with the gyro's angle increments over ``[t_{k−1}, t_k]`` (N, 3), rad (a
        whole log only)."""
        if self.spool is not None:
            raise ValueError("mekf-smooth has learned its log a block at a time: process() gives the estimates")
        self._check_once()
        self.result = smooth_log(self.setup, t, None, accel, mag, delta_angle=delta_angle, params=self.params)
        return self.result.smoothed

    def close(self) -> None:
        """Remove the temporary files of a log learned a block at a time."""
        if self.spool is not None:
            self.spool.close()
