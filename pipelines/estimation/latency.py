"""The gyro's latency taken out of an attitude estimate: the attitude at each sample's own stamp.

A gyro whose sample stamped ``t_k`` measures the motion at ``t_k − L`` (its latency, the device's
``[gyro] latency_s``: a MEMS gyro's digital low-pass and its bus delay it by milliseconds) makes
every filter that integrates it estimate the attitude at ``t_k − L``, whatever the filter: in a turn at
rate ω the estimate trails the body by ω L (BROAD's IMU, ``aktos_t_broad``: L = 2.4 ms, 0.5° at
200 °/s). Knowing L, the attitude at the stamp is the estimate turned on by the rate over the last L:

    q(t_k) = q̂_k ⊗ exp((ω_k − b̂_k) L)               (a body-frame increment, ω_k the sample's rate)

What it leaves: ω_k is the rate around ``t_k − L − T/2`` where the rate around ``t_k − L/2`` is
wanted, an error ω̇ (L + T) L / 2 (T the sample period): 3·10⁻⁴ rad at 50 rad/s² on BROAD. The rule is
causal and needs no state, so it serves an online filter block by block as it serves a whole log,
and it is the same for every filter (a comparison stays fair). A filter's covariance holds as it is:
the error ``δθ`` of ``q = exp(δθ) ⊗ q̂`` is about the world axes, and a turn on the body's side of
``q̂`` leaves it where it was (the increment's own noise, N² L, is below 10⁻¹⁰ rad² for any gyro
gyroemu models, and is not added).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gyroemu.dynamics.rotation import quat_from_rotvec, quat_multiply

from .protocol import AttitudeFilter, Estimate

__all__ = ["LatencyCompensated", "advance_attitude"]


def advance_attitude(q_wb: np.ndarray, gyro: np.ndarray, gyro_bias: np.ndarray | None, latency_s: float) -> np.ndarray:
    """The attitudes ``q_wb`` turned on by each sample's rate over ``latency_s`` (see the module's notes).

    Parameters
    ----------
    q_wb : ndarray (N, 4)
        Estimated attitudes, unit quaternions (w, x, y, z), body to world, one per sample.
    gyro : ndarray (N, 3)
        The samples' rates, rad/s, body axes. A non-finite row turns nothing (its attitude is kept).
    gyro_bias : ndarray (N, 3) or None
        The filter's bias estimate, rad/s, taken off the rate (None: none).
    latency_s : float
        How long the gyro lags the motion, s.

    Returns
    -------
    ndarray (N, 4)
        ``q_wb[k] ⊗ exp((gyro[k] − gyro_bias[k]) latency_s)``.
    """
    rate = np.asarray(gyro, dtype=float)
    if gyro_bias is not None:
        rate = rate - np.asarray(gyro_bias, dtype=float)
    turn = np.where(np.isfinite(rate).all(axis=1, keepdims=True), rate * latency_s, 0.0)
    return quat_multiply(np.asarray(q_wb, dtype=float), quat_from_rotvec(turn))


class LatencyCompensated:
    """A filter whose attitudes are turned on to their samples' stamps (:func:`advance_attitude`).

    It obeys the filter protocol of :mod:`.protocol` as the filter it wraps does: same ``name``, same
    ``offline``, blocks in time order; every other attribute is the wrapped filter's.

    Parameters
    ----------
    inner : AttitudeFilter
        The filter that estimates the attitude at ``t_k − latency_s``.
    latency_s : float
        The gyro's latency, s (``FilterSetup.gyro_latency_s``).
    """

    def __init__(self, inner: AttitudeFilter, latency_s: float) -> None:
        self.inner = inner
        self.latency_s = float(latency_s)
        self.name: str = inner.name
        self.offline: bool = bool(getattr(inner, "offline", False))

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        """The wrapped filter's estimate of the block, its attitudes turned on by ``latency_s``."""
        est = self.inner.process(t, gyro, accel, mag)
        return replace(est, q_wb=advance_attitude(est.q_wb, gyro, est.gyro_bias, self.latency_s))

    def __getattr__(self, name: str):
        if name == "inner":  # not set yet (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)
