"""A mounted sensor's estimate as the body's: what ``gyroemu estimate``, ``bench`` and the live filter write.

A filter knows only the samples, in the sensor's axes, so what it estimates is the sensor's attitude
``q̂_ws`` and its rate and bias in sensor axes. A device's ``[mounting] q_bs`` turns sensor vectors into
body axes (``v_b = R(q_bs) v_s``; ``interface.md``, on ``/tf_static`` as ``base_link`` → IMU), so with
``R(q_ws) = R(q_wb) R(q_bs)`` the body's estimate is::

    q̂_wb = q̂_ws ⊗ q_bs*          (the attitude: turn back out of the sensor's axes)
    ω̂_b  = R(q_bs) ω̂_s            (the bias-corrected rate, and the bias, in body axes)

The attitude covariance stays as it is: every filter's ``q_wb_covariance`` is about the world axes
(:class:`~.protocol.Estimate`; the MEKF's error is ``q_true = δq ⊗ q_est``, :mod:`.mekf_kernels`), and
``q_wb = δq ⊗ q̂_ws ⊗ q_bs* = δq ⊗ q̂_wb``: the same ``δq``, the same covariance.

An identity mounting (and an unknown one: a foreign log, which has no ``base_link`` of gyroemu's) turns
nothing: :func:`mounting_turn` gives None and the estimate is passed on as it is, to the bit.

Not applied by the twin (``gyroemu twin``, :mod:`gyroemu.pipelines.twin`): it mirrors a real recording
whose filters do not know the sensor's mounting, and compares each filter's attitude with the truth as the
real recording's is compared.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.rotation import quat_conjugate, quat_multiply, quat_rotate
from gyroemu.pipelines.formats.frames import mounting_of

from .protocol import Estimate

__all__ = ["body_attitude", "body_estimate", "body_vectors", "mounting_from_metadata", "mounting_turn"]


def mounting_turn(q_bs: ArrayLike | None) -> NDArray[np.float64] | None:
    """The mounting ``q_bs`` (4,) (w, x, y, z; sensor → body) as a unit quaternion, or None when it turns
    nothing: None given, or a rotation part exactly zero (``±(1, 0, 0, 0)``), so that an unmounted
    device's estimate is passed on bit for bit."""
    if q_bs is None:
        return None
    q = np.asarray(q_bs, dtype=float).reshape(4)
    if not np.all(np.isfinite(q)) or not np.any(q[1:] != 0.0):
        return None
    turned: NDArray[np.float64] = q / np.linalg.norm(q)
    return turned


def mounting_from_metadata(metadata: Mapping[str, str] | None) -> NDArray[np.float64] | None:
    """The turn (:func:`mounting_turn`) of a gyroemu log's device, from its ``gyroemu`` metadata record's
    embedded device config (``[mounting] q_bs``); None for a log without one (a foreign log, an import),
    an identity mounting, or a config whose mounting cannot be read (the log's filter setup warns about a
    config that does not validate)."""
    if not metadata or not metadata.get("device"):
        return None
    try:
        mounting = mounting_of(metadata["device"])
        return None if mounting is None else mounting_turn(mounting[0])
    except (tomllib.TOMLDecodeError, TypeError, ValueError):
        return None


def body_attitude(q_ws: ArrayLike, q_bs: NDArray[np.float64]) -> NDArray[np.float64]:
    """The body's attitudes ``q_wb = q_ws ⊗ q_bs*`` (N, 4) of the sensor's ``q_ws`` (N, 4), w first;
    NaN rows (no estimate) stay NaN."""
    # R(q_ws) = R(q_wb) R(q_bs)  ⇒  q_wb = q_ws ⊗ q_bs⁻¹
    return quat_multiply(np.asarray(q_ws, dtype=float), quat_conjugate(q_bs))


def body_vectors(v_s: ArrayLike, q_bs: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sensor-axes vectors ``v_s`` (N, 3) (a rate, rad/s; a bias) in body axes: ``v_b = R(q_bs) v_s``."""
    return quat_rotate(q_bs, np.asarray(v_s, dtype=float))


def body_estimate(estimate: Estimate, q_bs: NDArray[np.float64] | None) -> Estimate:
    """A filter's estimate of a sensor mounted by ``q_bs`` (:func:`mounting_turn`; None: not turned, the
    same object) as the body's: attitude ``q̂_ws ⊗ q_bs*``, gyro bias ``R(q_bs) b̂_s`` (rad/s, body axes),
    and the world-axes attitude covariance unchanged (module's notes)."""
    if q_bs is None:
        return estimate
    bias = None if estimate.gyro_bias is None else body_vectors(estimate.gyro_bias, q_bs)
    return Estimate(q_wb=body_attitude(estimate.q_wb, q_bs), gyro_bias=bias, q_wb_covariance=estimate.q_wb_covariance)
