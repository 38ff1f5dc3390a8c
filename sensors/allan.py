"""Allan deviation of a sensor's output, and a fit of the IEEE Std 952 noise terms to it.

The overlapping Allan deviation (NIST SP 1065, eq. 11) of the rate (or specific-force) samples is our
own: at octave-spaced averaging times τ = Δt, 2Δt, 4Δt, … it is the streamed accumulator
(:class:`~gyroemu.sensors.allan_stream.OverlappingAllanAccumulator`) fed the whole series as one chunk,
every octave exact; at τ given explicitly it is summed in numpy from the phase. Both equal
``allantools.oadev`` to round-off (the tests hold them against it; allantools is a test dependency only).

The fit uses the model of IEEE Std 952-1997 Annex C, where the independent terms add in variance:

    σ²(τ) = 3Q²/τ²  +  N²/τ  +  (2 ln2/π) B²  +  K² τ/3  +  R² τ²/2
            quant.     ARW      bias instab.     RRW        rate ramp
    slope   −1         −½       0                +½         +1         (of σ on a log-log plot)

so N is the −½ line read at τ = 1 s, K the +½ line read at τ = 3 s, and B the flat floor divided by
√(2 ln2/π) ≈ 0.664. Q is the rms angle error, LSB/√12 for a quantiser of step LSB.

The model is linear in the coefficients c = (Q², N², B², K², R²), so they are found by non-negative
weighted least squares of σ²(τ) itself. Each point is weighted by the standard deviation of its own
Allan variance estimate, σ²(τ)·√(2/ν), with ν the equivalent degrees of freedom of the chi-squared
distribution of the estimate. We take ν = ⌊n/m⌋ − 1 for n samples and clusters of m samples: the
number of independent clusters less one, IEEE 952 Annex C's count, which gives the familiar relative
uncertainty 1/√(2(n/m − 1)) of σ(τ) (conservative for the overlapping estimator of white noise beyond
τ = Δt, where ν is 3n/(2m)·4m²/(4m² + 5), NIST SP 1065 Table 5; at τ = Δt itself that is 2n/3, below
the count). Weighting by the model's σ² rather than the noisy estimate (iterated a few times) keeps
the fit from favouring points that happen to be low; relative weights make it a fit of the log curve.

A band limit (``band_limit=True``). White noise smoothed before it is sampled (an anti-alias or
digital low-pass, a MEMS gyro's demodulator filter) loses Allan variance at short τ. For a filter of
impulse response h (unit gain) whose memory is shorter than τ, the second difference of the phase
gives

    σ²(τ) = N²/τ − (3/2) N² ⟨|s|⟩ / τ²,      ⟨|s|⟩ = ∫ |s| R_h(s) ds,  R_h(s) = ∫ h(u) h(u + s) du

(the Wiener phase's second difference has covariance N²(2τ − 3|s|) at lag |s| ≤ τ); for a first-order
low-pass of time constant T, ⟨|s|⟩ = T, the first terms of IEEE 952 Annex C's exponentially correlated
noise, σ² = (N²/τ)(1 − (T/2τ)(3 − 4e^(−τ/T) + e^(−2τ/T))). That is the quantisation column 3/τ² with
the opposite sign: the Allan curve alone cannot part a quantiser from a low-pass, only their sum. A
fit that holds Q² ≥ 0 meets the sag by lowering N, which is then read below the device's (by 2 % for
``consumer_mems`` at 150 s, whose demodulator filters a ninth of its white noise's variance: ten
half-widths of the one-point interval), and even without a filter, clipping the scatter of Q² at 0
biases N low (0.2–0.4 % for ``aktos_t_broad`` at 240 s, against a half-width of 0.27 %). With
``band_limit=True`` the τ⁻² coefficient takes either sign (its column is projected out and the others
found by NNLS in the rest: Lawson and Hanson, *Solving Least Squares Problems*, 1974, ch. 23); a
positive one is read as Q, a negative one is :attr:`AllanFit.band_limit` = −3c_Q = (3/2) N² ⟨|s|⟩ and
Q is reported not found.

The low-pass's reach (:func:`fit_band_limited`). The τ⁻² form holds where the filter has forgotten its
input, τ ≫ its memory; for a first-order low-pass it leaves out (N²/τ)(T/2τ)(4e^(−τ/T) − e^(−2τ/T)),
which at τ ≈ T is most of the curve (Allan variance that rises from the first octave, then falls as
white noise). Behind a low-pass at a tenth of the sample rate (T = 1.6 Δt) the fit over every octave
read N 26 % low, and at a fortieth it found none (300 s at 100 Hz, 20 runs; 0.3 % low without a
low-pass). So the fit is made from the first τ where the low-pass it finds leaves every point it keeps
within half a standard deviation √(2/ν)/2 of the τ⁻² form, the first-order low-pass of the fit's T
standing for the filter (a model: other filters forget in other shapes). The shortest τ are left out one
at a time, each fit judged by its own T, until one holds; a fit without white noise resolved holds
unless the curve rises significantly from its first point and falls significantly after its first top
(two standard deviations of the difference, :data:`RESOLVE_SIGMAS`): smoothed noise, not a random walk,
which rises and never falls. Over the same runs N then reads 0.5 % and 0.0 % low behind the two
low-passes, 3 and 5 octaves left out, the 68 % interval holding N in 13 and 15 of 20 runs
(``tests/sensors/test_allan_low_pass_reach.py``). Butterworth low-passes, the same runs (cut-off at a
quarter, a tenth and a fortieth of the rate; N over every octave, then from where the fit starts): 2nd
order +4.2 → +0.6 %, −40 → −0.4 %, −100 → +0.1 %; 4th order +6.1 → +1.0 % (its interval holding N in 8
of 20: its sag near τ ≈ T is not the first-order shape), −49 → −1.0 %, −100 → −0.5 %. A MEMS demodulator
(T = 0.02 ms against a Δt of 1 ms) leaves nothing out, and neither does unfiltered noise.

Each coefficient's 68 % confidence interval is the chi-squared interval of √c_j (:func:`chi2_interval`,
as allantools' ``confidence_interval``) with the smaller of two degrees of freedom, so the wider of
two intervals:

* read off one point, as IEEE 952 reads the coefficient itself: at the τ where the term is best
  determined (largest share s_i = c_j A_ij / σ²(τ_i) for its ν_i), ν_i s_i² degrees of freedom;
* from the fit as a whole, which carries what the term trades with its neighbours (N against the
  quantisation or band limit, whose columns 3/τ² and 1/τ are nearly collinear over the short
  octaves; the floor against N and K): the sandwich covariance of the weighted least squares over the
  fitted terms (those not held at 0 by the bound), with X the design A divided row-wise by each
  point's standard deviation d_i = σ²_model(τ_i)·√(2/ν_i), the fit's weights (Huber 1967; White 1980),

      cov(c) = (XᵀX)⁻¹ Xᵀ D⁻¹ Σ D⁻¹ X (XᵀX)⁻¹,       ν_j = 2 c_j² / cov(c)_jj

  (Satterthwaite's equivalent degrees of freedom: a chi-squared of ν degrees of freedom scaled to mean
  c has variance 2c²/ν), D = diag(d). Σ is the covariance of the Allan variance estimates, which the
  weights misstate for the white noise that pins N: octave points of one record share its data, and
  the count ν is not white noise's. So Σ takes the white part W(τ) = N²/τ (with a band limit, less
  band_limit/τ²) exactly, and the rest as the weights do, independent, with the scatter ε:

      Σ_ab = ρ_ab W_a W_b √((2/ν_w,a)(2/ν_w,b))  +  δ_ab ((2/ν_a − ε²)(σ⁴_a − W_a²) + ε² σ⁴_a)

  ν_w = (3/2)(n/m)·4m²/(4m² + 5) is the overlapping estimator's for white noise (NIST SP 1065
  Table 5; :func:`white_edf`, with n/m the count; the count itself when Δt is not known), and ρ the
  correlation of its estimates at τ_a and τ_b (:func:`white_correlation`), from the second differences'
  spectrum 4 sin⁴(πfτ)/(πf)² (Parseval, and ∫ Σ c_k cos(ω_k u)/u⁴ du = (π/6) Σ c_k |ω_k|³ for
  Σ c_k = Σ c_k ω_k² = 0) in the large-sample, continuous-time limit,

      ρ(τ_a, τ_b) = J(τ_a, τ_b) / √(J(τ_a, τ_a) J(τ_b, τ_b)),
      J(a, b) = Σ_{i,k=0..2} α_i α_k (|i a + k b|³ + |i a − k b|³),   α = (3, −4, 1),

  which for τ_b ≥ 2τ_a is (3/2)(τ_a/τ_b)^(3/2): 0.53 for neighbouring octaves, 0.19 two apart (the
  sampled estimator's at τ = Δt, 2Δt is 0.46). Counted as independent with the count's ν, N's variance
  was three quarters of its scatter over draws of white noise (tests/sensors/test_allan_covariance.py).
  The rest of Σ keeps the weights' count, cautious for flicker, and no correlation between octaves,
  which random walk and flicker have more of than white noise: for B and K the one-point interval, the
  other candidate, is often the wider.

Simulated at rest (``tests/benchmarks/identify_coverage.py``: 100 runs each of ``consumer_mems`` for
150 s and ``aktos_t_broad`` for 240 s, the gyro's and the accelerometer's axes), the white noise's 68 %
interval holds the device's N in 403 and 406 of 600 (0.672, 0.677; an exact 68 % interval holds
0.626–0.740, three binomial standard deviations); with τ⁻² ≥ 0 and the one-point interval alone it
held it in 166 and 315 (the gyro of ``consumer_mems`` in 10 of 300).

A term is *resolved* when the data show it: at some τ its share of σ² exceeds :data:`RESOLVE_SIGMAS` (2)
times the relative standard deviation √(2/ν) of the Allan variance estimate there, i.e. the
chi-squared degrees of freedom ν·share² of its interval exceed 2·RESOLVE_SIGMAS² = 8 (a two-sigma
detection; ν is the conservative cluster count, so more cautious still). Equivalently its value exceeds
its detection limit (:attr:`Coefficient.limit`): the smallest value that would make that share at the
τ where the term shows most. A term below it is reported as not resolved. The limit is no upper bound:
a term just above it is often missed, and then lies above the limit. So the bound reported
(:attr:`Coefficient.upper_limit`) is the larger of the limit and the curve's own bound: every term adds
a non-negative c_j A_j(τ) to the Allan variance, so c_j ≤ σ²(τ)/A_j(τ) at every τ fitted, and with σ_hi
the one-sided 95 % chi-squared upper limit of each point (:data:`BOUND_CONFIDENCE`),
√c_j ≤ min_τ σ_hi(τ)/√A_j(τ) (:attr:`Coefficient.bound`). On simulated runs with a rate random walk or
a bias instability near its limit, the limit was below the truth on 28 of the 84 axes where the term
was not resolved, the bound on 1 (``tests/sensors/test_allan_upper_bound.py``). Why two sigma: the
fit puts a spare term wherever the scatter leaves room, and the octaves are many. Of 100 simulated
10-min runs of white noise and bias instability at 100 Hz, none had its random walk resolved by this
test, while a one-sigma test (ν·share² > 2) resolved it in 4 of 40; a random walk that dominates the
last octaves is resolved in every run. The τ⁻² term fitted with either sign (``band_limit=True``) trades with N over
the short octaves, which one point does not see: its limit is also at least √(2 sd), sd the standard
deviation of its coefficient from the fit's covariance, so it is resolved (as quantisation, or by its
magnitude as a band limit) only beyond two of those. Simulated at rest for 150 s (50 runs of
``navigation_fog``, whose gyro has neither a quantiser nor a low-pass), the one-point test resolved it on
58 of 150 axes, the fit's two standard deviations on 13 (two-sided, an exact test would on 7; its
coefficient over the sd scattered with standard deviation 1.08).

Units: for a gyro Q in rad, N in rad/√s, B in rad/s, K in rad/s/√s, R in rad/s²; for an accelerometer
m/s, m/s/√s, m/s², m/s²/√s, m/s³. Convert with N[deg/√h] = N·(180/π)·60, B[deg/h] = B·(180/π)·3600,
K[deg/h/√h] = K·(180/π)·3600·60.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.sensors.allan_stream import OverlappingAllanAccumulator

__all__ = [
    "AllanDeviation",
    "Coefficient",
    "AllanFit",
    "allan_deviation",
    "allan_confidence",
    "chi2_interval",
    "fit_allan",
    "fit_band_limited",
    "fit_covariance",
    "read_coefficient",
    "smoothing_time_constant",
    "coefficient_dof",
    "weighted_fit",
    "white_correlation",
    "white_edf",
    "TERMS",
    "RESOLVE_SIGMAS",
    "BOUND_CONFIDENCE",
]

#: The IEEE 952 terms in the order of the fit's coefficients.
TERMS = ("quantisation", "arw", "bias_instability", "rrw", "rate_ramp")

#: A term is resolved when its share of σ² at some τ exceeds this many relative standard deviations of
#: the Allan variance estimate there (module notes).
RESOLVE_SIGMAS = 2.0

#: The one-sided confidence of the upper bound reported for a term not resolved (module notes): each
#: Allan point's chi-squared upper limit at this level.
BOUND_CONFIDENCE = 0.95

_ONE_SIGMA = 0.682689492137086  # probability within ±1σ of a normal distribution
_TAU_KEYWORDS = ("octave", "all", "decade", "log10")


def chi2_interval(
    dev: float | NDArray[np.float64], edf: float | NDArray[np.float64], ci: float = _ONE_SIGMA
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Chi-squared confidence interval of a deviation estimated with ``edf`` degrees of freedom.

    With α = 1 − ``ci`` (NIST SP 1065 eq. 45; what ``allantools.confidence_interval`` gives)::

        low  = dev·√(edf / χ²_ppf(1 − α/2, edf)),   high = dev·√(edf / χ²_ppf(α/2, edf))

    Parameters
    ----------
    dev : deviation(s) σ, any unit.
    edf : equivalent degrees of freedom ν > 0, broadcast against ``dev``.
    ci : probability the interval holds, 0 < ci < 1 (default 0.6827, one sigma).

    Returns
    -------
    (low, high) : arrays of the broadcast shape of ``dev`` and ``edf`` (0-d for scalars).
    """
    from scipy.stats import chi2  # about 0.2 s to import: only when an interval is asked for

    tail = min(abs(ci), abs(ci - 1)) / 2  # α/2
    dev = np.asarray(dev, dtype=float)
    edf = np.asarray(edf, dtype=float)
    variance = dev * dev
    low = np.sqrt(edf * variance / chi2.ppf(1 - tail, edf))
    high = np.sqrt(edf * variance / chi2.ppf(tail, edf))
    return low, high


def _keyword_taus(keyword: str, n: int, dt: float) -> NDArray[np.float64]:
    """The τ list allantools' keywords name, for n samples (n + 1 phase points) at Δt."""
    points = n + 1
    if keyword == "all":
        return dt * np.linspace(1.0, points, points)
    if keyword == "log10":
        top = np.log10(points)
        return dt * np.logspace(0, top, int(10 * top), base=10.0)
    if keyword == "decade":
        return dt * np.array([f * 10.0**k for k in range(int(np.floor(np.log10(points))) + 1) for f in (1.0, 2.0, 4.0)])
    top = int(np.floor(np.log2(points)))  # "octave"
    return dt * np.logspace(0, top, top + 1, base=2.0)


def _explicit_oadev(
    data: NDArray[np.float64], dt: float, taus: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(τ, σ(τ)) at the given τ, overlapping estimator (NIST SP 1065 eq. 11) from the phase.

    x_k = Δt Σ_{j<k} (y_j − ȳ), k = 0 … n, and σ²(τ) = Σ_k (x_{k+2m} − 2x_{k+m} + x_k)² / (2τ²(n + 1 − 2m)),
    τ = mΔt with m = round(τ/Δt). As ``allantools.oadev``: m sorted and unique, 0 < m ≤ n, and τ with
    fewer than two terms (2m > n − 1) dropped.
    """
    x = np.concatenate([[0.0], np.cumsum(data - data.mean()) * dt])
    m = np.round(np.asarray(taus, dtype=float).ravel() / dt)
    m = np.unique(m[(m > 0) & (m < len(x)) & (len(x) - 2 * m > 1)]).astype(np.int64)
    adev = np.empty(len(m))
    for i, mj in enumerate(m):
        d = x[2 * mj :] - 2 * x[mj:-mj] + x[: -2 * mj]
        adev[i] = np.sqrt(np.sum(d * d) / (2.0 * len(d))) / (mj * dt)
    return m * dt, adev


@dataclass(frozen=True)
class AllanDeviation:
    """An overlapping Allan deviation with its confidence.

    Attributes
    ----------
    tau : (M,) averaging times, s.
    adev : (M,) Allan deviation σ(τ), in the data's unit.
    clusters : (M,) number of independent (non-overlapping) clusters ⌊n/m⌋.
    edf : (M,) chi-squared equivalent degrees of freedom, ν = clusters − 1 (less where a relative
        scatter beyond the sampling error was added: 2/ν = 2/(clusters − 1) + scatter²).
    low, high : (M,) 68 % confidence interval of σ(τ).
    dt : the sample interval, s, so τ = mΔt (NaN when not known: a curve from σ(τ) alone).
    scatter : the relative scatter ε of the Allan variance about a model beyond its sampling error that
        ``edf`` holds (:func:`gyroemu.pipelines.identification.noise.with_model_scatter`); 0 for none.
    """

    tau: NDArray[np.float64]
    adev: NDArray[np.float64]
    clusters: NDArray[np.float64]
    edf: NDArray[np.float64]
    low: NDArray[np.float64]
    high: NDArray[np.float64]
    dt: float = math.nan
    scatter: float = 0.0

    def slope(self) -> NDArray[np.float64]:
        """(M−1,) local log-log slope between neighbouring points (−1 quantisation … +1 ramp)."""
        return np.diff(np.log(self.adev)) / np.diff(np.log(self.tau))

    def without_first(self, count: int) -> AllanDeviation:
        """The curve without its ``count`` shortest τ."""
        return replace(
            self,
            tau=self.tau[count:],
            adev=self.adev[count:],
            clusters=self.clusters[count:],
            edf=self.edf[count:],
            low=self.low[count:],
            high=self.high[count:],
        )


def allan_deviation(data: ArrayLike, dt: float, taus: str | NDArray[np.float64] = "octave") -> AllanDeviation:
    """Overlapping Allan deviation of rate samples ``data`` (n,) taken every ``dt`` seconds.

    Parameters
    ----------
    data : (n,) rate, rad/s (or specific force, m/s²), finite.
    dt : sample interval, s.
    taus : "octave" (τ = Δt·2^k, the default), "all", "decade" or "log10" (allantools' τ lists), or an
        array of τ in s (each rounded to a multiple m of Δt; repeats merged, sorted).

    Keeps the τ with at least two terms of the estimator (2m ≤ n − 1), hence at least two independent
    clusters (ν ≥ 1); an explicit τ list none of whose τ qualifies gives an empty result.

    Raises
    ------
    ValueError
        For fewer than 4 samples, a series that is not 1-D, NaN or infinite samples, a ``dt`` that is not
        a positive number, or an unknown ``taus`` keyword.
    """
    data = np.asarray(data, dtype=float)
    if data.ndim != 1 or data.size < 4:
        raise ValueError(f"expected a 1-D series of at least 4 samples, got shape {data.shape}")
    if not np.all(np.isfinite(data)):
        raise ValueError("the series has NaN or infinite samples")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt}")
    if isinstance(taus, str) and taus not in _TAU_KEYWORDS:
        raise ValueError(f"unknown taus {taus!r}; expected one of {', '.join(_TAU_KEYWORDS)} or an array of τ")
    if isinstance(taus, str) and taus == "octave":
        # One chunk, every octave exact (max_exact_m ≥ the largest reported m, n/2).
        exact = 1 << max(0, (data.size // 2).bit_length())
        acc = OverlappingAllanAccumulator(dt, n_axes=1, max_exact_m=exact, coarse_overlap=1)
        acc.update(data[:, None])
        (allan,) = acc.deviations()
        return allan
    tau, adev = _explicit_oadev(data, dt, _keyword_taus(taus, data.size, dt) if isinstance(taus, str) else taus)
    clusters = np.floor(data.size / np.round(tau / dt))
    return allan_confidence(tau, adev, clusters, dt=dt)


def allan_confidence(tau: ArrayLike, adev: ArrayLike, clusters: ArrayLike, dt: float = math.nan) -> AllanDeviation:
    """An :class:`AllanDeviation` from σ(τ) computed elsewhere (a streamed estimate), with the confidence
    :func:`allan_deviation` gives: ν = clusters − 1 and the 68 % chi-squared interval of σ(τ).

    Parameters
    ----------
    tau : (M,) averaging times, s.
    adev : (M,) Allan deviation σ(τ), in the data's unit.
    clusters : (M,) independent clusters ⌊n/m⌋ of each τ = mΔt, each at least 2.
    dt : the sample interval Δt, s (NaN: not known; the fit's covariance then counts white noise's
        points as the others', module notes).
    """
    tau, adev = np.asarray(tau, dtype=float), np.asarray(adev, dtype=float)
    clusters = np.asarray(clusters, dtype=float)
    if np.any(clusters < 2):
        raise ValueError("every τ needs at least two independent clusters (ν ≥ 1)")
    edf = clusters - 1
    low, high = chi2_interval(adev, edf)
    return AllanDeviation(tau=tau, adev=adev, clusters=clusters, edf=edf, low=low, high=high, dt=float(dt))


@dataclass(frozen=True)
class Coefficient:
    """A fitted noise coefficient and its 68 % confidence interval (value 0: the term was not found,
    ``high`` is then a one-sigma upper limit).

    ``limit`` is the detection limit :func:`fit_allan` sets (NaN for a coefficient built elsewhere):
    the smallest value the data would resolve (module notes; for the τ⁻² term of either sign, at least
    √(2 sd) of its coefficient from the fit's covariance). A term is :attr:`resolved` when its value
    exceeds it. ``bound``: the curve's own one-sided upper bound on the coefficient,
    min_τ σ_hi(τ)/√A_j(τ) (module notes; NaN when not computed); a term not resolved is bounded by
    the larger of the two (:attr:`upper_limit`).
    """

    value: float
    low: float
    high: float
    limit: float = math.nan
    bound: float = math.nan

    @property
    def resolved(self) -> bool:
        """Whether the data resolve the term: its value exceeds its detection limit (without a limit:
        its interval excludes 0)."""
        if math.isnan(self.limit):
            return self.value > 0 and self.low > 0
        return self.value > 0 and self.value > self.limit

    @property
    def upper_limit(self) -> float:
        """The bound to report for a term not resolved: the larger of the detection limit and the curve's
        :attr:`bound` (``high`` without a limit; the value itself for a term resolved), in the
        coefficient's unit."""
        if math.isnan(self.limit):
            return self.high
        if self.resolved:
            return self.value
        return self.limit if math.isnan(self.bound) else max(self.limit, self.bound)


@dataclass(frozen=True)
class AllanFit:
    """IEEE 952 coefficients fitted to an Allan deviation (units in the module notes).

    ``band_limit`` (unit²·s², ≥ 0): the Allan variance a low-pass takes off, band_limit/τ², when the fit
    let the τ⁻² coefficient fall below 0 (``fit_allan(..., band_limit=True)``; module notes); 0 otherwise.
    ``skipped``: how many of ``allan``'s shortest τ the fit left out (``fit_allan(..., skip=)``: a
    low-pass's memory reaches them, :func:`fit_band_limited`); the coefficients describe the rest.
    """

    quantisation: Coefficient  # Q, slope −1
    arw: Coefficient  # N, slope −½, σ(1 s)
    bias_instability: Coefficient  # B, floor 0.664 B
    rrw: Coefficient  # K, slope +½, σ(3 s)
    rate_ramp: Coefficient  # R, slope +1
    allan: AllanDeviation
    band_limit: float = 0.0
    skipped: int = 0

    def model(self, tau: ArrayLike) -> NDArray[np.float64]:
        """The fitted σ(τ) at ``tau``, s."""
        tau = np.asarray(tau, dtype=float)
        c = np.array([getattr(self, name).value for name in TERMS]) ** 2
        sigma: NDArray[np.float64] = np.sqrt(np.maximum(_basis(tau) @ c - self.band_limit / tau**2, 0.0))
        return sigma


def _basis(tau: NDArray[np.float64]) -> NDArray[np.float64]:
    """(…, 5) Allan variance of each term per unit coefficient²: 3/τ², 1/τ, 2 ln2/π, τ/3, τ²/2."""
    floor = np.full_like(tau, 2 * np.log(2) / np.pi)
    return np.stack([3 / tau**2, 1 / tau, floor, tau / 3, tau**2 / 2], axis=-1)


def white_correlation(tau: ArrayLike) -> NDArray[np.float64]:
    """(M, M) correlation ρ of the overlapping Allan variance estimates at ``tau`` (M,) for white noise,
    in the large-sample, continuous-time limit (module notes):

        ρ = J(τ_a, τ_b) / √(J(τ_a, τ_a) J(τ_b, τ_b)),  J(a, b) = Σ_{i,k=0..2} α_i α_k (|ia + kb|³ + |ia − kb|³),

    α = (3, −4, 1); for τ_b ≥ 2τ_a that is (3/2)(τ_a/τ_b)^(3/2), taken in that form (the sum cancels
    to J = 24a³ there, losing digits as τ_b/τ_a grows).
    """
    tau = np.asarray(tau, dtype=float)
    short = np.minimum.outer(tau, tau)
    ratio = np.maximum.outer(tau, tau) / short  # ≥ 1; J is homogeneous of degree 3: J(a, b) = a³ J(1, b/a)
    alpha = (3.0, -4.0, 1.0)
    j = sum(
        alpha[i] * alpha[k] * (np.abs(i + k * ratio) ** 3 + np.abs(i - k * ratio) ** 3)
        for i in range(3)
        for k in range(3)
    )
    j_self = 16.0  # J(1, 1): the sum at ratio 1 (J(a, a) = 16 a³)
    near = j / np.sqrt(j_self * j_self * ratio**3)
    rho: NDArray[np.float64] = np.where(ratio >= 2.0, 1.5 * ratio**-1.5, near)
    return rho


def _off_at_round_off(
    design: NDArray[np.float64], target: NDArray[np.float64], c: NDArray[np.float64]
) -> NDArray[np.float64]:
    """NNLS's ``c`` with every coefficient whose column adds less than round-off to the fit (``|A_j c_j|``
    within 16 ε ‖target‖∞) set to 0: a term the solution leaves out. scipy's NNLS (1.17) leaves such a
    term at 10⁻³⁰ of the variance where earlier versions gave 0, and a report would call it found."""
    contribution = np.abs(design * c).max(axis=0)
    return np.where(contribution <= 16 * np.finfo(float).eps * np.abs(target).max(), 0.0, c)


def _constrained_lsq(
    design: NDArray[np.float64], target: NDArray[np.float64], free: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """min ‖design·c − target‖ with c_j ≥ 0 except where ``free`` (J,) is True: the free columns are
    projected out, the others found by NNLS in what is left, and the free ones by least squares on the
    rest (Lawson and Hanson 1974, ch. 23). Without free columns, plain NNLS."""
    from scipy.optimize import nnls  # about 0.3 s to import: only when a curve is fitted

    if not free.any():
        fitted: NDArray[np.float64] = _off_at_round_off(design, target, nnls(design, target)[0])  # scipy: untyped
        return fitted
    q, _ = np.linalg.qr(design[:, free])  # orthonormal basis of the free columns

    def rest(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return v - q @ (q.T @ v)

    c = np.zeros(design.shape[1])
    bounded = ~free
    if bounded.any():
        kept = rest(design[:, bounded])
        c[bounded] = _off_at_round_off(kept, rest(target), nnls(kept, rest(target))[0])
    c[free] = np.linalg.lstsq(design[:, free], target - design[:, bounded] @ c[bounded], rcond=None)[0]
    return c


def weighted_fit(
    allan: AllanDeviation, basis: NDArray[np.float64], free: ArrayLike | None = None, iterations: int = 5
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Coefficients of ``basis`` (M, J) fitted to the Allan variance of ``allan`` (module notes): every
    point weighted by σ²·√(2/ν), from the data first and then from the model, ``iterations`` times;
    non-negative but where ``free`` (J,) is True. Returns (coefficients (J,), model σ² (M,), weighted
    residual χ²)."""
    free = np.zeros(basis.shape[1], dtype=bool) if free is None else np.asarray(free, dtype=bool)
    avar = allan.adev**2
    relative_sd = np.sqrt(2 / allan.edf)
    model = avar  # weights from the data first, then from the model
    c = np.zeros(basis.shape[1])
    fitted = avar
    for _ in range(iterations):
        sd = model * relative_sd
        c = _constrained_lsq(basis / sd[:, None], avar / sd, free)
        fitted = basis @ c
        model = np.where(fitted > 0, fitted, avar)  # where no term reaches (none fitted): the data's weight
    chi2 = float(np.sum(((avar - fitted) / (model * relative_sd)) ** 2))  # the fit's own misfit, even where ≤ 0
    return c, model, chi2


def white_edf(allan: AllanDeviation) -> NDArray[np.float64]:
    """(M,) degrees of freedom of ``allan``'s Allan variance estimates for white noise (module notes):
    the overlapping estimator's, 3n/(2m)·4m²/(4m² + 5) for n samples (NIST SP 1065, Table 5), with n/m
    taken as the count: ν_w = (3/2) ν_count 4m²/(4m² + 5), ν_count = 2/(2/ν − ε²) the count ν without the
    scatter ε, m = τ/Δt. Where Δt is not known (NaN), the count itself."""
    count = 2.0 / np.maximum(2.0 / allan.edf - allan.scatter**2, np.finfo(float).tiny)
    if not (np.isfinite(allan.dt) and allan.dt > 0):
        return count
    m = np.maximum(np.round(allan.tau / allan.dt), 1.0)
    edf: NDArray[np.float64] = 1.5 * count * 4 * m * m / (4 * m * m + 5)
    return edf


def fit_covariance(
    allan: AllanDeviation,
    basis: NDArray[np.float64],
    coefficients: ArrayLike,
    model: NDArray[np.float64],
    free: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """(J, J) sandwich covariance of the coefficients of :func:`weighted_fit` over the fitted terms
    (non-zero, or ``free``; 0 for terms held at 0), module notes:

        cov(c) = (XᵀX)⁻¹ Xᵀ V X (XᵀX)⁻¹,   X = basis / d row-wise,  d = σ²_model √(2/ν),  V = D⁻¹ Σ D⁻¹,
        Σ_ab = ρ_ab W_a W_b √(2/ν_w,a · 2/ν_w,b) + δ_ab ((2/ν_a − ε²)(σ⁴_a − W_a²) + ε² σ⁴_a)

    with ``basis``'s first two columns the τ⁻² and τ⁻¹ terms (:data:`TERMS`' order), W the white noise
    with its band limit (c₁/τ + min(c₀, 0)·3/τ², at least 0), ν_w :func:`white_edf`, ρ
    :func:`white_correlation` and ε ``allan.scatter``. A term the points cannot part from the others
    (X of lower rank than the fitted terms) gets an infinite variance."""
    j = basis.shape[1]
    free = np.zeros(j, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    coefficients = np.asarray(coefficients, dtype=float)
    fitted = (coefficients != 0) | free
    covariance = np.zeros((j, j))
    if not fitted.any():
        return covariance
    sd = model * np.sqrt(2 / allan.edf)
    x = basis[:, fitted] / sd[:, None]
    scale = np.linalg.norm(x, axis=0)  # columns to unit length: their sizes span many decades
    if not np.all(scale > 0):
        covariance[np.ix_(fitted, fitted)] = np.inf
        return covariance
    u, s, vt = np.linalg.svd(x / scale, full_matrices=False)
    if x.shape[0] < x.shape[1] or s[-1] <= s[0] * 1e-10:  # fewer points than terms, or collinear
        covariance[np.ix_(fitted, fitted)] = np.inf
        return covariance
    # The points' covariance Σ, each in units of its own standard deviation d.
    eps2 = allan.scatter**2
    white = np.zeros_like(model)
    if j >= 2:  # N²/τ, less a band limit (the τ⁻² term below 0)
        white = np.clip(basis[:, 1] * coefficients[1] + basis[:, 0] * min(coefficients[0], 0.0), 0.0, model)
    w = white * np.sqrt(2.0 / white_edf(allan))
    rest = np.maximum(2.0 / allan.edf - eps2, 0.0) * (model**2 - white**2) + eps2 * model**2
    points = (white_correlation(allan.tau) * np.outer(w, w) + np.diag(rest)) / np.outer(sd, sd)
    p = (vt.T / s) @ u.T  # (XᵀX)⁻¹Xᵀ of the scaled columns
    covariance[np.ix_(fitted, fitted)] = (p @ points @ p.T) / np.outer(scale, scale)
    return covariance


def coefficient_dof(
    j: int,
    coefficients: NDArray[np.float64],
    basis: NDArray[np.float64],
    model: NDArray[np.float64],
    allan: AllanDeviation,
    covariance: NDArray[np.float64],
) -> float:
    """Degrees of freedom of the chi-squared interval of the coefficient √c_j (module notes): the smaller
    of the one-point ν_i s_i² at its best τ and the fit's 2c_j²/cov(c)_jj. ``coefficients`` > 0 at j."""
    relative_sd = np.sqrt(2 / allan.edf)
    share = coefficients[j] * basis[:, j] / model
    best = np.argmin(relative_sd / share)
    one_point = allan.edf[best] * share[best] ** 2
    variance = covariance[j, j]
    from_fit = 2 * coefficients[j] ** 2 / variance if variance > 0 else np.inf
    return float(min(one_point, from_fit))


def smoothing_time_constant(band_limit: float, noise_density: float) -> float:
    """T (s) of the first-order low-pass over all of the white noise N (``noise_density``, unit·√s) that
    takes the Allan variance ``band_limit``/τ² off it (unit²·s²): band_limit = (3/2) N² T (module notes,
    "A band limit"); 0 without a band limit or without white noise to smooth."""
    if not (band_limit > 0 and noise_density > 0):
        return 0.0
    return 2.0 * band_limit / (3.0 * noise_density**2)


def fit_allan(
    allan: AllanDeviation,
    terms: Sequence[str] = TERMS,
    iterations: int = 5,
    *,
    band_limit: bool = False,
    skip: int = 0,
) -> AllanFit:
    """Fit the IEEE 952 terms named in ``terms`` (a subset of :data:`TERMS`) to ``allan``.

    Leave out terms known to be absent (a static test has no rate ramp): a spare term soaks up some
    of the scatter of its neighbours. Returns every term; those left out are 0. ``band_limit``: let
    the τ⁻² coefficient take either sign (quantisation when positive, a low-pass's sag
    :attr:`AllanFit.band_limit` when negative; module notes); it needs ``quantisation`` in ``terms``.
    The quantisation's detection limit is then at least √(2 sd), sd the standard deviation of the τ⁻²
    coefficient from the fit's covariance (module notes), which also bounds a band limit: it is resolved
    when band_limit/3 exceeds the limit². ``skip``: leave out the curve's ``skip`` shortest τ (the
    returned fit keeps the whole curve, with :attr:`AllanFit.skipped`). A curve that is 0 everywhere (a
    constant series: a saturated axis, a noiseless device) gives every term 0 with the interval [0, 0];
    one that is 0 at some τ only, ``ValueError``.
    """
    whole, allan = allan, allan.without_first(skip) if skip else allan
    if not np.any(allan.adev > 0):  # a constant (a saturated axis, a noiseless device): every term 0
        zero = Coefficient(0.0, 0.0, 0.0, 0.0)
        return AllanFit(zero, zero, zero, zero, zero, allan=whole, skipped=skip)
    if not np.all(allan.adev > 0):
        at = allan.tau[np.flatnonzero(~(allan.adev > 0))[0]]
        raise ValueError(f"σ(τ) is 0 at τ = {at:g} s but not everywhere: no noise model has that curve")
    unknown = set(terms) - set(TERMS)
    if unknown:
        raise ValueError(f"unknown terms {sorted(unknown)}; known: {', '.join(TERMS)}")
    used = np.array([name in terms for name in TERMS])
    if band_limit and "quantisation" not in terms:
        raise ValueError("band_limit=True fits the τ⁻² term of either sign: include 'quantisation' in terms")
    free = used & (np.arange(len(TERMS)) == 0) if band_limit else np.zeros(len(TERMS), dtype=bool)
    basis = _basis(allan.tau) * used  # (M, 5): a term left out has a zero column
    c, model, _ = weighted_fit(allan, basis[:, used], free[used], iterations)
    coefficients = np.zeros(len(TERMS))
    coefficients[used] = c
    covariance = fit_covariance(allan, basis, coefficients, model, free)
    fitted = {
        name: read_coefficient(j, coefficients, basis, model, allan, covariance) if use else Coefficient(0.0, 0.0, 0.0)
        for j, (name, use) in enumerate(zip(TERMS, used))
    }
    if free[0]:  # the τ⁻² term of either sign: resolved only beyond two standard deviations of the fit's too
        q = fitted["quantisation"]
        floor = float(np.sqrt(RESOLVE_SIGMAS * np.sqrt(covariance[0, 0])))
        fitted["quantisation"] = replace(q, limit=max(q.limit, floor))
    return AllanFit(allan=whole, band_limit=float(max(0.0, -3.0 * coefficients[0])), skipped=skip, **fitted)


def fit_band_limited(allan: AllanDeviation, terms: Sequence[str] = TERMS, iterations: int = 5) -> AllanFit:
    """:func:`fit_allan` with the τ⁻² term of either sign (``band_limit=True``) from the first τ where
    the low-pass it finds has forgotten its input (module notes, "The low-pass's reach"): the fit of the
    whole curve when that holds there (a low-pass whose memory is short against Δt, or none), else of
    the curve without its shortest τ, one more at a time, until it holds for the fit of what is left
    (:attr:`AllanFit.skipped` says how many). While fewer than two points more than the terms would be
    left, or when no start holds, the fit of the whole curve."""
    points = len(allan.tau) - (len(set(terms)) + 2)
    first = fit_allan(allan, terms, iterations, band_limit=True)
    for skip in range(points + 1):
        fit = first if skip == 0 else fit_allan(allan, terms, iterations, band_limit=True, skip=skip)
        if _low_pass_forgotten(allan.without_first(skip), fit):
            return fit
    return first


def _low_pass_forgotten(allan: AllanDeviation, fit: AllanFit) -> bool:
    """Whether ``allan``'s points (those ``fit`` was fitted to) lie where the low-pass ``fit`` finds has
    forgotten its input (module notes, "The low-pass's reach"): with white noise N and a band limit
    resolved, the first-order low-pass of T = :func:`smoothing_time_constant` leaves at most half a
    standard deviation of every point beyond the τ⁻² form; without white noise resolved, the curve does
    not both rise significantly from its first point and fall significantly after its first top (the
    rise and fall of smoothed noise)."""
    sd = np.sqrt(2 / allan.edf)
    avar = allan.adev**2
    if fit.arw.resolved:
        if not fit.band_limit / 3 > fit.quantisation.limit**2:  # no band limit resolved (fit_allan's test)
            return True
        t = smoothing_time_constant(fit.band_limit, fit.arw.value)
        x = allan.tau / t
        beyond = (0.5 / x) * (4 * np.exp(-x) - np.exp(-2 * x))  # (T/2τ)(4e^(−τ/T) − e^(−2τ/T))
        return bool(np.all(beyond <= 0.5 * sd))
    if len(avar) < 2:
        return True

    def below(i: int, k: int) -> bool:  # point i below point k by more than 2 sd of their difference
        return bool(avar[k] - avar[i] > RESOLVE_SIGMAS * np.hypot(sd[i] * avar[i], sd[k] * avar[k]))

    peak = int(np.argmax(np.diff(avar) <= 0)) if np.any(np.diff(avar) <= 0) else len(avar) - 1  # first top
    rises = below(0, 1)
    falls = any(below(k, peak) for k in range(peak + 1, len(avar)))
    return not (rises and falls)


def read_coefficient(
    j: int,
    c: NDArray[np.float64],
    basis: NDArray[np.float64],
    model: NDArray[np.float64],
    allan: AllanDeviation,
    covariance: NDArray[np.float64],
) -> Coefficient:
    """Coefficient j of a fit (``c`` (J,) over ``basis`` (M, J), ``model`` its σ², ``covariance`` its
    :func:`fit_covariance`) with its confidence (:func:`coefficient_dof`: the wider of the one-point and the
    whole fit's interval). A term not found (c_j ≤ 0) gets the upper limit at which it would have made
    one standard deviation where it shows most; a term found but pinned by less than one degree of
    freedom is undetermined, with the interval (0, ∞). Every term gets its detection limit and the
    curve's upper bound (:class:`Coefficient`).
    """
    relative_sd = np.sqrt(2 / allan.edf)
    detectable = np.min(model * relative_sd / basis[:, j])  # c_j making one sd where it shows most
    limit = float(np.sqrt(RESOLVE_SIGMAS * detectable))  # ... RESOLVE_SIGMAS sd: the detection limit
    bound = _curve_bound(allan, basis[:, j])
    if c[j] <= 0:
        return Coefficient(0.0, 0.0, float(np.sqrt(detectable)), limit, bound)
    value = np.sqrt(c[j])
    dof = coefficient_dof(j, c, basis, model, allan, covariance)
    if dof < 1.0:  # the term is not pinned by one degree of freedom: undetermined
        return Coefficient(float(value), 0.0, float("inf"), limit, bound)
    low, high = chi2_interval(value, dof)
    return Coefficient(float(value), float(low), float(high), limit, bound)


def _curve_bound(allan: AllanDeviation, basis: NDArray[np.float64]) -> float:
    """min_τ σ_hi(τ)/√A(τ): a one-sided upper bound, at :data:`BOUND_CONFIDENCE` per point, on the
    coefficient of a term of basis ``A`` (M,) (unit²/coefficient²) under ``allan``'s points, from the
    curve alone: the term's c·A(τ) is one non-negative part of σ²(τ) (module notes)."""
    _, high = chi2_interval(allan.adev, allan.edf, ci=2 * BOUND_CONFIDENCE - 1)  # two-sided 2p − 1: one-sided p
    shows = basis > 0
    return float(np.sqrt(np.min(high[shows] ** 2 / basis[shows]))) if shows.any() else math.inf
