"""The upper bound reported for a term the fit does not resolve (:attr:`Coefficient.upper_limit`).

The detection limit alone is no bound: a true term just above it is missed about half the time and
then reported below its value. The bound reported is the larger of the limit and the curve's own
bound min_τ σ_hi(τ)/√A_j(τ), σ_hi each point's one-sided 95 % chi-squared upper limit, so on axes
where it is reported it may fall below the truth in about 5 % of them at most.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from gyroemu.sensors.allan import BOUND_CONFIDENCE, allan_deviation, fit_band_limited
from gyroemu.sensors.noise import flicker_bank, sensor_noise

UG = 9.80665e-6  # m/s² per µg


def _bounds(term: str, truth: float, dt: float, runs: list[np.ndarray]) -> list[float]:
    """upper_limit / truth of ``term`` on every axis of ``runs`` where it is not resolved."""
    ratios = []
    for y in runs:
        for axis in range(3):
            c = getattr(fit_band_limited(allan_deviation(y[:, axis] - y[:, axis].mean(), dt)), term)
            if not c.resolved:
                ratios.append(c.upper_limit / truth)
    return ratios


@pytest.mark.slow  # 90 axes of 20 min each: 8 s
def test_a_term_just_above_its_detection_limit_is_bounded():
    # A rate random walk K over white noise N (100 Hz, 20 min) and a bias instability B over white noise
    # (tactical_mems's accelerometer, 1 kHz, 20 min): both near their detection limits, which fell below
    # the truth on 16 of 60 and 12 of 24 of the axes where they were not resolved.
    dt_k, k = 1e-2, 1.5e-5
    runs_k = [
        sensor_noise(np.random.default_rng(900 + s), (120_000, 3), dt_k, white=1e-3, random_walk=k) for s in range(20)
    ]
    dt_b, b = 1e-3, 3.2 * UG
    bank = flicker_bank(b, (1.0, 1e4), dt_b, n_axes=3)
    runs_b = [
        sensor_noise(np.random.default_rng(100 + s), (1_200_000, 3), dt_b, white=0.008 / 60, flicker=bank)
        for s in range(10)
    ]
    ratios = np.array(_bounds("rrw", k, dt_k, runs_k) + _bounds("bias_instability", b, dt_b, runs_b))
    assert len(ratios) >= 50  # enough axes not resolved for the count to say something
    # An axis's bound falls below the truth only where a point's upper limit lies below its true σ
    # (5 % each) at a τ where the term makes nearly all of σ²: a few neighbouring, correlated points, so
    # about 5 % of axes. The count of such axes may reach the 95 % quantile of binomial(n, 0.05).
    allowed = binom.ppf(0.95, len(ratios), 1 - BOUND_CONFIDENCE)
    below = int(np.sum(ratios < 1))
    assert below <= allowed, (below, allowed, len(ratios))
