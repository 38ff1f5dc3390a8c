"""One filter as ``gyroemu bench`` runs it: warmed up untimed first, and what its ``process`` returns checked."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from gyroemu.pipelines.estimation.protocol import Estimate, FilterSetup, estimate_problem
from gyroemu.pipelines.estimation.registry import make_filter

__all__ = ["WARM_UP_SAMPLES", "check_estimate", "warm_up"]

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
