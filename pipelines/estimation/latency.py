"""The sensors' latencies taken out of an attitude estimate: the field at the gyro's instant, every
attitude at its own stamp.

A sensor whose sample stamped ``t_k`` measures the motion at ``t_k − L`` (its latency, a device's
``latency_s``: a MEMS gyro's digital low-pass and its bus delay it by milliseconds, a magnetometer by
more) misleads every filter the same way, whatever the filter.

The gyro. Its sample is the mean rate over ``[t_{k−1} − L_g, t_k − L_g]``, so the attitude integrated
to it is the body's at ``t_k − L_g``: in a turn at rate ω the estimate trails the body by ω L_g
(BROAD's IMU, ``aktos_t_broad``: L_g = 2.4 ms, 0.5° at 200 °/s). Knowing L_g, the attitude at the stamp
is the estimate turned on by the rate over the last L_g:

    q(t_k) = q̂_k ⊗ exp((ω_k − b̂_k) L_g)              (a body-frame increment, ω_k the sample's rate)

It leaves ω̇ (L_g + T) L_g / 2 (ω_k is the rate around ``t_k − L_g − T/2`` where the rate around
``t_k − L_g/2`` is wanted; T the sample period): 3·10⁻⁴ rad at 50 rad/s² on BROAD.

The magnetometer. A filter turns sample k's field into the world with the attitude it integrated to
sample k, the body's at ``t_k − L_g``; the field was read at ``t_k − L_m``, in the body's axes of then,
``R(t_k − L_m) = R(t_k − L_g) exp(−[ω×] Δ)`` with ``Δ = L_m − L_g``. So each field sample is first
turned back into the gyro's instant,

    m'_k = exp(−ω_k Δ) m_k                              (BROAD: Δ = 13 ms, 2.6° at 200 °/s)

with the raw rate: the filter's bias is not known before it runs (b Δ is below 10⁻⁴ rad for any gyro
gyroemu models), nor is Earth's rate taken off (the body turns against the Earth at ω − Ω_ie: Ω_ie Δ,
10⁻⁶ rad).

The accelerometer is not moved. Its sample is the mean force over its interval, which every filter
pairs with the attitude at the interval's end, T/2 later: an offset of the filters' own, there with no
latency at all. Moving the samples by the latencies' difference alone, ``L_a − L_g``, leaves that
offset where it was; on BROAD, where it nearly cancels the latencies' difference (T/2 = 1.75 ms, L_g −
L_a = 1.5 ms), it doubled the misalignment and every estimator's 6D error rose (the smoother's 0.304°
→ 0.317°, offlineVQF's 0.265° → 0.29°); the full correction, ``L_a + T/2 − L_g`` (0.24 ms there),
moves them by under 1 %. Setting it right means pairing the force with the interval's middle in the
filters themselves, for devices without latency too.

Every rule is causal and needs no state, so it serves an online filter block by block as it serves a
whole log, and it is the same for every filter (a comparison stays fair). A filter's covariance holds
as it is: the error ``δθ`` of ``q = exp(δθ) ⊗ q̂`` is about the world axes, and a turn on the body's
side of ``q̂`` leaves it where it was (the increment's own noise, N² L_g, is below 10⁻¹⁰ rad² for any
gyro gyroemu models, and is not added).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, cast

import numpy as np

from gyroemu.dynamics.rotation import quat_from_rotvec, quat_multiply, quat_rotate

from .protocol import AttitudeFilter, BlockLearner, Estimate

__all__ = ["LatencyCompensated", "advance_attitude", "attitude_at_stamps", "field_at_gyro_instant", "turn_back"]


def _turns(gyro: np.ndarray, gyro_bias: np.ndarray | None, seconds: float) -> np.ndarray:
    """``exp((ω_k − b_k) seconds)`` (..., 4); a non-finite rate turns nothing."""
    rate = np.asarray(gyro, dtype=float)
    if gyro_bias is not None:
        rate = rate - np.asarray(gyro_bias, dtype=float)
    return quat_from_rotvec(np.where(np.isfinite(rate).all(axis=-1, keepdims=True), rate * seconds, 0.0))


def advance_attitude(q_wb: np.ndarray, gyro: np.ndarray, gyro_bias: np.ndarray | None, latency_s: float) -> np.ndarray:
    """The attitudes ``q_wb`` turned on by each sample's rate over ``latency_s`` (see the module's notes).

    Parameters
    ----------
    q_wb : ndarray (..., N, 4)
        Estimated attitudes, unit quaternions (w, x, y, z), body to world, one per sample (leading axes:
        runs).
    gyro : ndarray (..., N, 3)
        The samples' rates, rad/s, body axes. A non-finite row turns nothing (its attitude is kept).
    gyro_bias : ndarray (..., N, 3) or None
        The filter's bias estimate, rad/s, taken off the rate (None: none).
    latency_s : float
        How long the gyro lags the motion, s.

    Returns
    -------
    ndarray (..., N, 4)
        ``q_wb[k] ⊗ exp((gyro[k] − gyro_bias[k]) latency_s)``.
    """
    return quat_multiply(np.asarray(q_wb, dtype=float), _turns(gyro, gyro_bias, latency_s))


def turn_back(vectors: np.ndarray, gyro: np.ndarray, delay_s: float) -> np.ndarray:
    """Body vectors measured ``delay_s`` before the gyro's instant, in the body's axes at that instant.

    Parameters
    ----------
    vectors : ndarray (..., N, 3)
        A sensor's samples (specific force, field), body axes; NaN rows stay NaN.
    gyro : ndarray (..., N, 3)
        The samples' rates, rad/s, body axes. A non-finite row turns nothing.
    delay_s : float
        How much longer the sensor lags the motion than the gyro, ``L_s − L_g``, s.

    Returns
    -------
    ndarray (..., N, 3)
        ``exp(−gyro[k] delay_s) vectors[k]``.
    """
    return quat_rotate(_turns(gyro, None, -delay_s), np.asarray(vectors, dtype=float))


def field_at_gyro_instant(
    mag: np.ndarray | None, gyro: np.ndarray, gyro_latency_s: float, mag_latency_s: float
) -> np.ndarray | None:
    """The field samples ``mag`` (..., N, 3) turned back to the gyro's instant (:func:`turn_back` by
    ``mag_latency_s − gyro_latency_s``); as they are when the latencies are equal or there is no field."""
    if mag is None or mag_latency_s == gyro_latency_s:
        return mag
    return turn_back(mag, gyro, mag_latency_s - gyro_latency_s)


def attitude_at_stamps(
    q_wb: np.ndarray, gyro: np.ndarray, gyro_bias: np.ndarray | None, gyro_latency_s: float
) -> np.ndarray:
    """A filter's attitudes (..., N, 4) turned on to their stamps (:func:`advance_attitude`); as they are
    when the gyro has no latency."""
    return q_wb if gyro_latency_s == 0.0 else advance_attitude(q_wb, gyro, gyro_bias, gyro_latency_s)


class LatencyCompensated:
    """A filter fed the field at the gyro's instant and whose attitudes are turned on to their stamps.

    The magnetometer's samples are turned back by its latency beyond the gyro's
    (:func:`field_at_gyro_instant`), the estimate's attitudes on by the gyro's (:func:`attitude_at_stamps`). It
    obeys the filter protocol of :mod:`.protocol` as the filter it wraps does: same ``name``, same
    ``offline``, blocks in time order; every other attribute is the wrapped filter's, but for
    ``process_increments`` (it would go untimed: a timed filter takes rates).

    Parameters
    ----------
    inner : AttitudeFilter
        The filter to feed.
    gyro_latency_s, mag_latency_s : float
        The gyro's and the magnetometer's latencies, s (``FilterSetup``'s).
    """

    def __init__(self, inner: AttitudeFilter, gyro_latency_s: float, mag_latency_s: float = 0.0) -> None:
        self.inner = inner
        self.latencies = (float(gyro_latency_s), float(mag_latency_s))
        self.name: str = inner.name
        self.offline: bool = bool(getattr(inner, "offline", False))

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        """The wrapped filter's estimate of the block, its inputs and outputs moved as the class says."""
        gyro_l, mag_l = self.latencies
        est = self.inner.process(t, gyro, accel, field_at_gyro_instant(mag, gyro, gyro_l, mag_l))
        return replace(est, q_wb=attitude_at_stamps(est.q_wb, gyro, est.gyro_bias, gyro_l))

    def learn(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> None:
        """Feed an offline filter that learns a log a block at a time (``learns_in_blocks``) the block,
        its field moved as :meth:`process` moves it."""
        gyro_l, mag_l = self.latencies
        learner = cast(BlockLearner, self.inner)  # an AttributeError for one that does not learn
        learner.learn(t, gyro, accel, field_at_gyro_instant(mag, gyro, gyro_l, mag_l))

    def __getattr__(self, name: str) -> Any:
        # "inner" before it is set (a copy being made): no recursion; "process_increments" would feed the
        # wrapped filter untimed, so a timed filter takes rates only
        if name in ("inner", "process_increments"):
            raise AttributeError(name)
        return getattr(self.inner, name)
