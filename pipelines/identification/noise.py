"""Noise terms of a sensor from its rest phases: pooled Allan deviations, with what they can show.

Each rest phase (its mean removed: the bias may differ between phases) gives an overlapping Allan
variance at octave τ = Δt·2^k (:func:`gyroemu.sensors.allan.allan_deviation`). Phases are pooled per τ,
weighted by their independent clusters c_i = ⌊n_i/m⌋:

    σ²(τ) = Σ c_i σ_i²(τ) / Σ c_i,        ν(τ) = Σ (c_i − 1)        (chi-squared degrees of freedom)

and the 68 % interval of σ(τ) is the chi-squared one of ν (Lesage–Audoin; NIST SP 1065 eq. 45). τ is kept
only up to a third of the longest phase (each phase contributes up to a third of its own length):
beyond it there are fewer than three independent clusters and nothing is observable. The IEEE 952
terms are fitted to the pooled curve by :func:`gyroemu.sensors.allan.fit_allan` with its τ⁻² term of
either sign (``band_limit=True``): positive it is quantisation, negative the Allan variance a low-pass
(an anti-alias or digital filter, a MEMS gyro's demodulator) takes off the white noise at short τ,
which a non-negative fit met by reading N low (1–2 % for ``consumer_mems``; the module notes of
:mod:`gyroemu.sensors.allan`). Each coefficient's 68 % interval is the wider of the one read off its
best-determined τ and the one from the whole fit's covariance, which carries what N trades with the
τ⁻² term and B with N and K (same notes). The device file's comments give a band limit as the time
constant T of the first-order low-pass that would take it off, band_limit = (3/2) N² T
(:attr:`AxisNoise.smoothing_s`). The shortest τ, where a low-pass has not yet forgotten its input, are
left out of every fit of the axis (:func:`gyroemu.sensors.allan.fit_band_limited`: behind a first-order
low-pass at a tenth of the sample rate, N read over every octave was 26 % low); BROAD's four trials and
the simulated devices leave none out.

Simulated at rest (``tests/benchmarks/identify_coverage.py``; ``tests/pipelines/test_identify_coverage.py``
holds it on 30 s), the white noise's interval holds the device's N as often as a 68 % interval should:
403 of 600 runs of ``consumer_mems`` (150 s) and 406 of 600 of ``aktos_t_broad`` (240 s), where an exact
68 % interval holds 376–444 (three binomial standard deviations); read off one τ with τ⁻² ≥ 0 it held
166 and 315.

What the rest length allows: white noise (slope −½) is always seen. Bias instability (the floor) and
random walk (+½) only when they dominate somewhere below τ_max = L_max/3 (and their interval from the
fit holds a degree of freedom); otherwise each is reported as an upper bound: every term adds variance
(a band limit takes variance off the white noise alone, whose smoothed part keeps a positive one), so
at every τ

    (2 ln2/π) B² ≤ σ²_high(τ)   and   K² τ/3 ≤ σ²_high(τ)      (σ_high: the 68 % upper limit)

and the smallest right-hand side over τ bounds the term. That is a one-sigma bound of each point, not a
fit: a floor read from another draw of the same noise can lie above it.

Gauss–Markov term (exponentially correlated noise of standard deviation σ and correlation time τ_c,
:func:`gyroemu.sensors.noise.gauss_markov_avar`, which for the sampled process at τ_c ≫ τ rises like
a random walk and for τ_c ≪ τ falls like white noise, with a bump between): for each τ_c of a grid
log-spaced over the observed τ (8 per decade, τ_0 … τ_max), its Allan variance per unit σ² is a fifth
basis function beside the four terms, and the five coefficients (non-negative but for the τ⁻² one)
are fitted by the same iterated, model-weighted least squares as
:func:`gyroemu.sensors.allan.fit_allan`. The τ_c with the least weighted residual
χ² = Σ ((σ̂² − σ²_model)/(σ²_model √(2/ν)))² is kept, and the term with it only if it is significant
by an F-test of the nested fits: with χ²₀ the four-term fit's residual, M
points and p = 6 parameters (four terms, σ, τ_c),

    F = ((χ²₀ − χ²)/2) / (χ²/(M − p))  >  F₀.₉₉(2, M − p)

(two parameters added; dividing by χ²/(M − p) scales out how far the point weights misstate the
scatter, as octave points share data), and the term is pinned (its 68 % interval, the wider of the
one-point and the five-term fit's covariance one as for the other terms, is finite). A kept term's σ
carries that interval, τ_c the range of grid τ_c whose χ² is within χ²/(M − p) of the least
(Δχ² = 1 with the scaled weights), widened by one grid step each side (the grid's resolution); the
four other terms are then those of the five-term fit. Otherwise the term is reported as not
significant, with an upper bound on σ at the best τ_c (as for the other terms, from every τ's 68 %
upper limit), and the four-term fit stands unchanged.

Scatter beyond the sampling error. The four terms are a model, and a real sensor's curve may hold
what they cannot draw: BROAD's aktos-t gyro z carries a band of 17–29 Hz at rest, which lifts σ at
τ = 14–28 ms by 9–10 %, twenty sampling standard deviations there (χ² = 773 on 8 degrees of freedom).
Weighted by the sampling error alone, the short octaves (known to 0.5 %) then outweigh the long ones
far beyond what they know about the model, and the floor came out at 11.6 °/h, 12–17 % above the
curve at 3.6 s and 7.2 s, where long runs and the twin's check lie. So, as a random-effects
meta-analysis does (DerSimonian and Laird, 1986), a relative scatter ε of the Allan variance about
the model is estimated by moments: when the fit's χ² exceeds its degrees of freedom M − J (J = 4
terms, or 5 with a kept Gauss–Markov term, whose F-test already scales the scatter out), ε solves
χ²(ε) = M − J with every point's relative variance 2/ν + ε² (ε = 0 otherwise). Each point then counts
ν_eff = 2/(2/ν + ε²) degrees of freedom, in the fit and in every interval and bound read off it
(:func:`with_model_scatter`): a curve the model draws within its sampling error is fitted as before,
bit for bit, and one it does not is fitted with its points weighted by how well the model can meet
them. On BROAD's gyro z, ε = 8.2 % (9.3 % with τ⁻² ≥ 0): the floor is not observable (below 7.6 °/h)
and the model meets the curve within 5 % from 0.9 s to 7.2 s. The price: with such a scatter a floor
that is there may be reported as an upper bound only (tests/pipelines/test_identify.py). A band's
Allan variance rises over the short octaves and falls like τ⁻² beyond its peak, which the τ⁻² term
of either sign follows in part: with a simulated 17–29 Hz band (the test's; seeds 11–16, 18 axes) N
reads 3–6.5 % high (4.6 % on average), against 3–5 % (3.8 %) with τ⁻² ≥ 0, one to two of the
interval's half-widths; on BROAD's gyro z, N moved from 6.09 to 6.21 mdps/√Hz with the band limit,
within the former interval.

An axis without noise. An axis that reads an exact constant at rest (a simulated device whose noise
terms on it are all 0; a reading whose noise stays below one step of its quantiser) has σ(τ) = 0 at
every τ, and the fits' weights σ²·√(2/ν) would all be 0. Its terms are then 0, and that is measured, not
merely unobservable: a zero estimate's chi-squared interval is [0, 0], and as every term adds variance
each is bounded by it (above), while any white noise of continuous amplitude makes σ(τ) > 0 with
probability 1. N = 0 is written (the device it describes reads the same constant), B and K 0 with the
bound 0, no Gauss–Markov term; the device file's comments say the axis read a constant, as for a
quantised sensor that is "no noise measurable at its resolution", not a proof of none.

With BROAD's rest layout (eight phases of about 33 s at 286 Hz, M = 12 octaves up to 7.2 s) and white
noise of 2.7·10⁻³ m/s²·√s, simulated: without a Gauss–Markov term, 1 axis in 45 kept one (the test's
nominal 1 %; a scanned τ_c may add to it: 3 in 120 of ``_rest_segments`` seeds 100–139, 4 with
τ⁻² ≥ 0); with σ = 5·10⁻³ m/s² at τ_c = 0.8 s, 10 in 15 found it (σ within its interval, τ_c
0.56–0.99 s; seeds 200–204: 7 in 15 with the band limit or without); at σ = 2.5·10⁻³, 1 in 15. Twelve
octave points see a bump that adds under about half the variance at its peak poorly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal, cast

import numpy as np
from numpy.typing import NDArray

from gyroemu.sensors.allan import (
    AllanDeviation,
    AllanFit,
    Coefficient,
    allan_deviation,
    chi2_interval,
    fit_allan,
    fit_band_limited,
    fit_covariance,
    read_coefficient,
    smoothing_time_constant,
    weighted_fit,
)
from gyroemu.sensors.noise import gauss_markov_avar

__all__ = [
    "NoiseTerm",
    "MarkovTerm",
    "AxisNoise",
    "SensorNoise",
    "pooled_allan",
    "sensor_noise",
    "fit_markov",
    "model_scatter",
    "with_model_scatter",
]

_ONE_SIGMA = 0.682689492137086
_FLOOR = 2.0 * np.log(2.0) / np.pi  # Allan variance of bias instability per B²
_TERMS = ("quantisation", "arw", "bias_instability", "rrw")  # the four terms fitted to rest phases
_MARKOV_PER_DECADE = 8  # grid of correlation times τ_c
_MARKOV_LEVEL = 0.99  # F-test level for keeping the Gauss–Markov term
_ITERATIONS = 5  # reweightings of the least squares, as fit_allan


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
class MarkovTerm:
    """A Gauss–Markov term fitted beside the four Allan terms (module notes).

    Attributes
    ----------
    sigma : standard deviation σ (unit); ``fitted`` when the term is kept, else ``upper_bound`` (value 0,
        high the bound at the best τ_c).
    tau_c : correlation time τ_c, s, the best of the grid, with the grid range within Δχ² = 1 (value 0
        when the term is not kept; low … high still the best grid point's neighbourhood).
    f_ratio, f_critical : the F statistic of the nested fits and its 99 % point.
    chi2_without, chi2_with : weighted residuals of the four-term fit and of the five-term fit.
    points : M, the Allan points fitted.
    """

    sigma: NoiseTerm
    tau_c: NoiseTerm
    f_ratio: float
    f_critical: float
    chi2_without: float
    chi2_with: float
    points: int

    @property
    def kept(self) -> bool:
        """Whether the term is significant and written."""
        return self.sigma.status == "fitted"


@dataclass(frozen=True)
class AxisNoise:
    """The noise of one axis: white noise density N (unit·√s = unit/√Hz), bias instability B (unit),
    random walk K (unit/√s), the Allan curve and its four-term fit, the Gauss–Markov term (None
    when not fitted), the relative scatter ε of the curve about the four-term model beyond its
    sampling error (module notes; 0 when the model meets the curve within it), and the band limit
    (unit²·s²): the Allan variance band_limit/τ² a low-pass took off the white noise at short τ, as
    the fit that gave N found it (module notes; 0 when the τ⁻² term came out positive, quantisation)."""

    noise_density: NoiseTerm
    bias_instability: NoiseTerm
    random_walk: NoiseTerm
    fit: AllanFit
    markov: MarkovTerm | None = None
    model_scatter: float = 0.0
    band_limit: float = 0.0

    @property
    def noiseless(self) -> bool:
        """Whether the axis read a constant at rest: its Allan variance is 0 at every τ (module notes)."""
        return not np.any(self.fit.allan.adev**2 > 0)

    @property
    def smoothing_s(self) -> float:
        """The band limit as the time constant T of a first-order low-pass over all of the white noise
        that would take it off, band_limit = (3/2) N² T (module notes), s; 0 without one."""
        return smoothing_time_constant(self.band_limit, self.noise_density.value)


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

    def values(self, term: str) -> NDArray[np.float64]:
        """(3,) the term's value per axis (``noise_density``, ``bias_instability``, ``random_walk``)."""
        return np.array([getattr(a, term).value for a in self.axes])

    def markov(self) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """(σ (3,), τ_c (3,) s) of the Gauss–Markov term, 0 on axes where it is not kept; None when no
        axis keeps it."""
        terms = [a.markov for a in self.axes]
        if not any(m is not None and m.kept for m in terms):
            return None
        sigma = np.array([m.sigma.value if m is not None and m.kept else 0.0 for m in terms])
        tau = np.array([m.tau_c.value if m is not None and m.kept else 0.0 for m in terms])
        return sigma, tau


def pooled_allan(segments: Sequence[NDArray[np.float64]], dt: float, tau_min_s: float = 0.0) -> AllanDeviation:
    """Allan deviation pooled over ``segments`` (each (n_i,), one axis, mean removed here), sampled every
    ``dt`` s, at octave τ from ``tau_min_s`` up to a third of the longest segment (module notes)."""
    longest = max(len(s) for s in segments)
    # float64, which numpy's stubs type as floating[Any] (a float to the power of an int array)
    octaves = cast("NDArray[np.float64]", dt * 2.0 ** np.arange(int(np.floor(np.log2(max(longest / 3, 1)))) + 1))
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
    low, high = chi2_interval(adev, edf, ci=_ONE_SIGMA)
    return AllanDeviation(tau=tau, adev=adev, clusters=clusters, edf=edf, low=low, high=high, dt=float(dt))


def _four_basis(tau: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, 4) Allan variance per unit coefficient² of quantisation, white noise, bias instability and
    random walk (IEEE 952 Annex C): 3/τ², 1/τ, 2 ln2/π, τ/3."""
    return np.column_stack([3 / tau**2, 1 / tau, np.full_like(tau, _FLOOR), tau / 3])


def _signed(basis: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(J,) which coefficients of ``basis`` may take either sign: the first, τ⁻² (quantisation or band
    limit, module notes)."""
    free = np.zeros(basis.shape[1], dtype=bool)
    free[0] = True
    return free


def _weighted_fit(
    allan: AllanDeviation, basis: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """The coefficients of ``basis`` (M, J; its first column the τ⁻² term, of either sign, the others
    non-negative) fitted to the Allan variance as ``fit_allan`` does (weights σ²·√(2/ν), from the data
    first, then from the model, iterated): (coefficients (J,), model (M,), weighted residual χ²)."""
    return weighted_fit(allan, basis, _signed(basis), _ITERATIONS)


def model_scatter(allan: AllanDeviation, basis: NDArray[np.float64]) -> float:
    """ε, the relative scatter of the Allan variance of ``allan`` about the model spanned by ``basis``
    (M, J) beyond its sampling error (module notes): 0 when the fit's χ² is within its M − J degrees of
    freedom, else the ε ≥ 0 at which the fit with every point's relative variance 2/ν + ε² has χ² = M − J."""
    from scipy.optimize import brentq

    free: int = len(allan.tau) - basis.shape[1]
    if free <= 0:
        return 0.0

    def excess(eps: float) -> float:
        return _weighted_fit(with_model_scatter(allan, eps), basis)[2] - free

    if excess(0.0) <= 0:
        return 0.0
    high = 1.0  # ε = 1 is already a 100 % scatter; χ² falls towards 0 as ε grows
    while excess(high) > 0:
        if high >= 1e3:  # a model that cannot meet the curve at any weight (a zero column): give up
            return float(high)
        high *= 2
    return float(brentq(excess, 0.0, high, xtol=1e-6))


def with_model_scatter(allan: AllanDeviation, eps: float) -> AllanDeviation:
    """``allan`` with each point's degrees of freedom ν taken down to ν_eff = 2/(2/ν + ε²), the relative
    scatter ``eps`` added to its sampling error, and its 68 % interval from ν_eff (``allan`` itself when
    ε = 0)."""
    if eps <= 0:
        return allan
    edf = 2.0 / (2.0 / allan.edf + eps**2)
    low, high = chi2_interval(allan.adev, edf, ci=_ONE_SIGMA)
    return replace(allan, edf=edf, low=low, high=high, scatter=float(np.hypot(allan.scatter, eps)))


def _read_fit(
    j: int, c: NDArray[np.float64], basis: NDArray[np.float64], model: NDArray[np.float64], allan: AllanDeviation
) -> Coefficient:
    """Coefficient j of a :func:`_weighted_fit` with its 68 % interval, read as ``fit_allan`` reads every
    term (:func:`gyroemu.sensors.allan.read_coefficient`): the wider of the one read where its term holds
    the largest share of the Allan variance and the one from the whole fit's covariance ((0, ∞) when it
    is not pinned by one degree of freedom); not found (c_j ≤ 0), 0 with the value that would have made
    one standard deviation where it shows most."""
    return read_coefficient(j, c, basis, model, allan, fit_covariance(allan, basis, c, model, _signed(basis)))


def fit_markov(
    allan: AllanDeviation, dt: float
) -> tuple[MarkovTerm, NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The Gauss–Markov term of the pooled Allan deviation ``allan`` of samples every ``dt`` s (module
    notes): the term, and when it is kept the five-term fit's coefficients² (quantisation, white noise,
    bias instability, random walk, σ²) with its model σ²(τ) (M,); else None, None."""
    from scipy.stats import f as f_distribution

    tau = allan.tau
    four = _four_basis(tau)
    _, _, chi2_without = _weighted_fit(allan, four)
    decades = np.log10(tau[-1] / tau[0])
    grid = np.geomspace(tau[0], tau[-1], int(np.ceil(decades * _MARKOV_PER_DECADE)) + 1)
    fits = []
    for tau_c in grid:
        column = gauss_markov_avar(tau, 1.0, tau_c, dt)
        fits.append((*_weighted_fit(allan, np.column_stack([four, column])), column))
    chi2 = np.array([f[2] for f in fits])
    best = int(np.argmin(chi2))
    c, model, chi2_with, column = fits[best]
    points, params = len(tau), four.shape[1] + 2
    free = points - params
    scale = chi2_with / free if free > 0 else float("inf")
    f_ratio = (chi2_without - chi2_with) / 2 / scale if free > 0 and scale > 0 else 0.0
    f_critical = float(f_distribution.ppf(_MARKOV_LEVEL, 2, free)) if free > 0 else float("inf")
    near = np.flatnonzero(chi2 <= chi2_with + scale)  # Δχ² = 1 with the weights scaled to the scatter
    lo, hi = best, best
    while lo - 1 in near:
        lo -= 1
    while hi + 1 in near:
        hi += 1
    lo, hi = max(lo - 1, 0), min(hi + 1, len(grid) - 1)  # and the grid's resolution, a step each side
    tau_c = NoiseTerm(float(grid[best]), float(grid[lo]), float(grid[hi]), "fitted")
    five = np.column_stack([four, column])
    read = _read_fit(five.shape[1] - 1, c, five, model, allan)
    if c[-1] > 0 and f_ratio > f_critical and np.isfinite(read.high):
        sigma = NoiseTerm(read.value, read.low, read.high, "fitted")
        term = MarkovTerm(sigma, tau_c, float(f_ratio), f_critical, chi2_without, chi2_with, points)
        return term, c, model
    bound = float(np.sqrt(np.min(allan.high**2 / column)))  # every term adds variance
    sigma = NoiseTerm(0.0, 0.0, bound, "upper_bound")
    tau_c = NoiseTerm(0.0, tau_c.low, tau_c.high, "upper_bound")
    return MarkovTerm(sigma, tau_c, float(f_ratio), f_critical, chi2_without, chi2_with, points), None, None


def _noiseless_axis(allan: AllanDeviation) -> AxisNoise:
    """The noise of an axis whose pooled Allan variance is 0 at every τ (module notes, "An axis without
    noise"): every term 0, its 68 % interval [0, 0], no Gauss–Markov term and no scatter."""
    zero = Coefficient(0.0, 0.0, 0.0, 0.0)
    fit = AllanFit(quantisation=zero, arw=zero, bias_instability=zero, rrw=zero, rate_ramp=zero, allan=allan)
    none = NoiseTerm(0.0, 0.0, 0.0, "upper_bound")
    return AxisNoise(NoiseTerm(0.0, 0.0, 0.0, "fitted"), none, none, fit)


def _axis_noise(allan: AllanDeviation, dt: float, markov: bool) -> AxisNoise:
    if not np.any(allan.adev**2 > 0):  # a constant: the fits' weights σ²·√(2/ν) would all be 0
        return _noiseless_axis(allan)
    allan = allan.without_first(fit_band_limited(allan, _TERMS).skipped)  # τ within a low-pass's memory: out
    four = _four_basis(allan.tau)
    gm, c5, model, five = None, None, None, None
    if markov and len(allan.tau) > len(_TERMS) + 2:  # the F-test needs a point beyond the parameters
        gm, c5, model = fit_markov(allan, dt)  # its F-test scales out the scatter itself (module notes)
    if gm is not None and c5 is not None:  # kept: the scatter is that about the five-term model
        five = np.column_stack([four, gauss_markov_avar(allan.tau, 1.0, gm.tau_c.value, dt)])
        eps = model_scatter(allan, five)
        if eps > 0:
            allan = with_model_scatter(allan, eps)
            c5, model, _ = _weighted_fit(allan, five)
            read = _read_fit(five.shape[1] - 1, c5, five, model, allan)
            if c5[-1] > 0 and np.isfinite(read.high):
                gm = replace(gm, sigma=NoiseTerm(read.value, read.low, read.high, "fitted"))
    else:
        eps = model_scatter(allan, four)
        allan = with_model_scatter(allan, eps)
    fit = fit_allan(allan, terms=_TERMS, band_limit=True)
    high2 = allan.high**2
    b_bound = float(np.sqrt(np.min(high2 / _FLOOR)))
    k_bound = float(np.sqrt(np.min(high2 * 3.0 / allan.tau)))

    def term(c: Coefficient, bound: float) -> NoiseTerm:
        if c.value > 0 and np.isfinite(c.high) and c.low > 0:
            return NoiseTerm(c.value, c.low, c.high, "fitted")
        # Not observable: the model-free bound of the module notes (every term adds variance). The fit's
        # own detection level (c.high of a term at 0) is one standard deviation at one τ, blind to what
        # the term trades with its neighbours, and would claim a tighter bound than the curve allows.
        return NoiseTerm(0.0, 0.0, bound, "upper_bound")

    arw, bias_instability, rrw = fit.arw, fit.bias_instability, fit.rrw
    band_limit = fit.band_limit
    if c5 is not None and model is not None and five is not None:  # kept: the others are the five-term fit's
        covariance = fit_covariance(allan, five, c5, model, _signed(five))
        arw, bias_instability, rrw = (read_coefficient(j, c5, five, model, allan, covariance) for j in (1, 2, 3))
        band_limit = float(max(0.0, -3.0 * c5[0]))
    if arw.value > 0 and np.isfinite(arw.high):
        white = NoiseTerm(arw.value, arw.low, arw.high, "fitted")
    else:  # white noise always shows at the shortest τ: read it there, σ(τ)·√τ (slope −½)
        s = np.sqrt(allan.tau[0])
        white = NoiseTerm(float(allan.adev[0] * s), float(allan.low[0] * s), float(allan.high[0] * s), "fitted")
    return AxisNoise(white, term(bias_instability, b_bound), term(rrw, k_bound), fit, gm, eps, band_limit)


def sensor_noise(
    segments: Sequence[NDArray[np.float64]], dt: float, tau_min_s: float = 0.0, *, markov: bool = True
) -> SensorNoise:
    """Noise of a three-axis sensor from its rest ``segments`` (each (n_i, 3), in the sensor's SI unit)
    sampled every ``dt`` s; NaN rows are dropped.

    ``tau_min_s``: shortest τ used. Raise it for a sensor sampled more slowly than it is logged (BROAD's
    magnetometer is interpolated up to the IMU's rate, which flattens its Allan curve at short τ).
    ``markov``: also fit a Gauss–Markov term per axis (module notes); False leaves it out.
    """
    segs = [np.asarray(s, dtype=float) for s in segments if len(s) >= 8]
    if not segs:
        raise ValueError("no rest phase of at least 8 samples")
    x, y, z = (_axis_noise(pooled_allan([s[:, i] for s in segs], dt, tau_min_s), dt, markov) for i in range(3))
    return SensorNoise(
        axes=(x, y, z),
        tau_max_s=float(x.fit.allan.tau[-1]),
        rest_s=float(sum(len(s) for s in segs) * dt),
        phases=len(segs),
    )
