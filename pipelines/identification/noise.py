"""Noise terms of a sensor from its rest phases: pooled Allan deviations, with what they can show.

Each rest phase (its mean removed: the bias may differ between phases) gives an overlapping Allan
variance at octave τ = Δt·2^k (:func:`gyroemu.sensors.allan.allan_deviation`). Phases are pooled per τ,
weighted by their independent clusters c_i = ⌊n_i/m⌋:

    σ²(τ) = Σ c_i σ_i²(τ) / Σ c_i,        ν(τ) = Σ (c_i − 1)        (chi-squared degrees of freedom)

and the 68 % interval of σ(τ) is the chi-squared one of ν (Lesage–Audoin; ``allantools``). τ is kept
only up to a third of the longest phase (each phase contributes up to a third of its own length):
beyond it there are fewer than three independent clusters and nothing is observable. The IEEE 952
terms are fitted to the pooled curve by :func:`gyroemu.sensors.allan.fit_allan`, whose intervals are
read off the best-determined τ.

What the rest length allows: white noise (slope −½) is always seen. Bias instability (the floor) and
random walk (+½) only when they dominate somewhere below τ_max = L_max/3; otherwise each is reported
as an upper bound: every term adds variance, so at every τ

    (2 ln2/π) B² ≤ σ²_high(τ)   and   K² τ/3 ≤ σ²_high(τ)      (σ_high: the 68 % upper limit)

and the smallest right-hand side over τ bounds the term.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gyroemu.sensors.allan import AllanDeviation, AllanFit, allan_deviation, fit_allan

__all__ = ["NoiseTerm", "AxisNoise", "SensorNoise", "pooled_allan", "sensor_noise"]

_ONE_SIGMA = 0.682689492137086
_FLOOR = 2.0 * np.log(2.0) / np.pi  # Allan variance of bias instability per B²


@dataclass(frozen=True)
class NoiseTerm:
    """One noise coefficient (SI) and how far the data pin it.

    status : ``fitted`` (value with its 68 % interval low … high), or ``upper_bound`` (value 0, high
    the bound: the term is not observable from the rest phases).
    """

    value: float
    low: float
    high: float
    status: Literal["fitted", "upper_bound"]


@dataclass(frozen=True)
class AxisNoise:
    """The noise of one axis: white noise density N (unit·√s = unit/√Hz), bias instability B (unit),
    random walk K (unit/√s), the Allan curve and its fit."""

    noise_density: NoiseTerm
    bias_instability: NoiseTerm
    random_walk: NoiseTerm
    fit: AllanFit


@dataclass(frozen=True)
class SensorNoise:
    """A three-axis sensor's noise from its rest phases.

    Attributes
    ----------
    axes : three :class:`AxisNoise`, x, y, z.
    tau_max_s : longest averaging time observed, s (a third of the longest phase).
    rest_s : total rest time used, s.
    phases : number of rest phases pooled.
    """

    axes: tuple[AxisNoise, AxisNoise, AxisNoise]
    tau_max_s: float
    rest_s: float
    phases: int

    def values(self, term: str) -> np.ndarray:
        """(3,) the term's value per axis (``noise_density``, ``bias_instability``, ``random_walk``)."""
        return np.array([getattr(a, term).value for a in self.axes])


def pooled_allan(segments: Sequence[np.ndarray], dt: float, tau_min_s: float = 0.0) -> AllanDeviation:
    """Allan deviation pooled over ``segments`` (each (n_i,), one axis, mean removed here), sampled every
    ``dt`` s, at octave τ from ``tau_min_s`` up to a third of the longest segment (module notes)."""
    longest = max(len(s) for s in segments)
    octaves = dt * 2.0 ** np.arange(int(np.floor(np.log2(max(longest / 3, 1)))) + 1)
    avar = np.zeros(len(octaves))
    clusters = np.zeros(len(octaves))
    edf = np.zeros(len(octaves))
    for seg in segments:
        seg = np.asarray(seg, dtype=float)
        seg = seg[np.isfinite(seg)]
        if len(seg) < 8:
            continue
        usable = octaves[(octaves <= len(seg) * dt / 3 * (1 + 1e-9)) & (octaves >= tau_min_s * (1 - 1e-9))]
        if not len(usable):
            continue
        a = allan_deviation(seg - seg.mean(), dt, taus=usable)
        idx = np.round(np.log2(a.tau / dt)).astype(int)
        avar[idx] += a.clusters * a.adev**2
        clusters[idx] += a.clusters
        edf[idx] += a.edf
    keep = edf >= 1
    if keep.sum() < 2:
        raise ValueError("rest phases too short for an Allan deviation (need at least two octaves of τ)")
    tau, clusters, edf = octaves[keep], clusters[keep], edf[keep]
    adev = np.sqrt(avar[keep] / clusters)
    import allantools

    bounds = np.array([allantools.confidence_interval(s, nu, ci=_ONE_SIGMA) for s, nu in zip(adev, edf)])
    return AllanDeviation(tau=tau, adev=adev, clusters=clusters, edf=edf, low=bounds[:, 0], high=bounds[:, 1])


def _axis_noise(allan: AllanDeviation) -> AxisNoise:
    fit = fit_allan(allan, terms=("quantisation", "arw", "bias_instability", "rrw"))
    high2 = allan.high**2
    b_bound = float(np.sqrt(np.min(high2 / _FLOOR)))
    k_bound = float(np.sqrt(np.min(high2 * 3.0 / allan.tau)))

    def term(c, bound: float) -> NoiseTerm:
        if c.value > 0 and np.isfinite(c.high) and c.low > 0:
            return NoiseTerm(c.value, c.low, c.high, "fitted")
        return NoiseTerm(0.0, 0.0, min(bound, c.high) if c.high > 0 else bound, "upper_bound")

    arw = fit.arw
    if arw.value > 0 and np.isfinite(arw.high):
        white = NoiseTerm(arw.value, arw.low, arw.high, "fitted")
    else:  # white noise always shows at the shortest τ: read it there, σ(τ)·√τ (slope −½)
        s = np.sqrt(allan.tau[0])
        white = NoiseTerm(float(allan.adev[0] * s), float(allan.low[0] * s), float(allan.high[0] * s), "fitted")
    return AxisNoise(white, term(fit.bias_instability, b_bound), term(fit.rrw, k_bound), fit)


def sensor_noise(segments: Sequence[np.ndarray], dt: float, tau_min_s: float = 0.0) -> SensorNoise:
    """Noise of a three-axis sensor from its rest ``segments`` (each (n_i, 3), in the sensor's SI unit)
    sampled every ``dt`` s; NaN rows are dropped.

    ``tau_min_s``: shortest τ used. Raise it for a sensor sampled more slowly than it is logged (BROAD's
    magnetometer is interpolated up to the IMU's rate, which flattens its Allan curve at short τ).
    """
    segs = [np.asarray(s, dtype=float) for s in segments if len(s) >= 8]
    if not segs:
        raise ValueError("no rest phase of at least 8 samples")
    x, y, z = (_axis_noise(pooled_allan([s[:, i] for s in segs], dt, tau_min_s)) for i in range(3))
    return SensorNoise(
        axes=(x, y, z),
        tau_max_s=float(x.fit.allan.tau[-1]),
        rest_s=float(sum(len(s) for s in segs) * dt),
        phases=len(segs),
    )
