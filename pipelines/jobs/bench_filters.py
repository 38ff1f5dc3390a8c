"""One filter as ``gyroemu bench`` runs it: warmed up untimed first, what its ``process`` returns checked,
and, for a mounted device, turned into the body's axes before it is compared with the body's truth."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from gyroemu.pipelines.estimation.mounting import body_attitude, body_vectors
from gyroemu.pipelines.estimation.protocol import Estimate, FilterSetup, estimate_problem
from gyroemu.pipelines.estimation.registry import make_filter

__all__ = ["WARM_UP_SAMPLES", "check_estimate", "in_body_axes", "warm_up"]

WARM_UP_SAMPLES = 200
"""Samples of the untimed first call."""


def check_estimate(est: object, n: int, label: str) -> tuple[np.ndarray, np.ndarray | None]:
    """The attitudes (n, 4) and gyro biases (n, 3) of a filter's return value, or None for a bias it does
    not give (or gives in another shape); ``TypeError``/``ValueError`` naming ``label`` for attitudes that
    are not one per sample (the message says how many more or fewer, the same for the whole run and for a
    block of it: :func:`~gyroemu.pipelines.estimation.protocol.estimate_problem`)."""
    problem = estimate_problem(est, n, extras=False)
    if problem is not None:
        not_estimate = not isinstance(est, Estimate) and not hasattr(est, "q_wb")
        raise (TypeError if not_estimate else ValueError)(f"{label}.process() returned {problem}")
    q = np.asarray(cast(Any, est).q_wb, dtype=float)
    b = getattr(est, "gyro_bias", None)
    if b is not None:
        b = np.asarray(b, dtype=float)
        if b.shape != (n, 3):
            b = None
    return q, b


def warm_up(
    spec: str, setup: FilterSetup, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None
) -> None:
    """A short untimed call first on the first samples, so that the timed ones measure the filter, not its
    first-call costs (numba compiling or loading its cache, lazy imports); its failures are the timed
    run's to report."""
    k = min(len(t), WARM_UP_SAMPLES)
    try:
        make_filter(spec, setup).process(t[:k], gyro[:k], accel[:k], None if mag is None else mag[:k])
    except Exception:  # noqa: BLE001 - the timed run reports it
        pass


def in_body_axes(
    q: np.ndarray, b: np.ndarray | None, gyro: np.ndarray, q_bs: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """A filter's attitudes ``q`` (n, 4), biases ``b`` (n, 3) rad/s or None, and the samples' ``gyro``
    (n, 3) rad/s, of a sensor mounted by ``q_bs`` (4,) (sensor → body;
    :func:`~gyroemu.pipelines.estimation.mounting.mounting_turn`), as the body's: ``q ⊗ q_bs*``,
    ``R(q_bs) b``, ``R(q_bs) ω_m``, so that the errors against the body's truth (``q_wb``, ``ω_b``) are
    the filter's and not the mounting. The bias error ``|b̂ − (ω_m − ω)|`` is the same in either axes; the
    attitude error is not. ``q_bs`` None (unmounted): the arrays as they are."""
    if q_bs is None:
        return q, b, gyro
    # q_wb = q_ws ⊗ q_bs*;  v_b = R(q_bs) v_s
    return body_attitude(q, q_bs), None if b is None else body_vectors(b, q_bs), body_vectors(gyro, q_bs)
