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
uncertainty 1/√(2(n/m − 1)) of σ(τ) (conservative for the overlapping estimator). Weighting by the
model's σ² rather than the noisy estimate (iterated a few times) keeps the fit from favouring points
that happen to be low; relative weights make it a fit of the log curve. Each coefficient's 68 %
confidence interval is read as IEEE 952 reads the coefficient itself, off one point of the curve: the τ
where that term is best determined (largest share of σ² for its ν), as a chi-squared interval
(:func:`chi2_interval`, as allantools' ``confidence_interval``) with ν·share² degrees of freedom.
Octave points share data (and for random-walk noise are strongly correlated), so combining them as
independent would overstate the confidence; the one-point interval is on the cautious side.

A term is *resolved* when the data show it: at some τ its share of σ² exceeds :data:`RESOLVE_SIGMAS` (2)
times the relative standard deviation √(2/ν) of the Allan variance estimate there, i.e. the
chi-squared degrees of freedom ν·share² of its interval exceed 2·RESOLVE_SIGMAS² = 8 (a two-sigma
detection; ν is the conservative cluster count, so more cautious still). Equivalently its value exceeds
its detection limit (:attr:`Coefficient.limit`): the smallest value that would make that share at the
τ where the term shows most. A term below it is reported as not resolved, with the limit as its upper
bound: a larger term would have stood out of the curve's scatter. Why two sigma: the fit puts a spare
term wherever the scatter leaves room, and the octaves are many. Of 100 simulated 10-min runs of white
noise and bias instability at 100 Hz, none had its random walk resolved by this test, while a
one-sigma test (ν·share² > 2) resolved it in 4 of 40; a random walk that dominates the last octaves
is resolved in every run.

Units: for a gyro Q in rad, N in rad/√s, B in rad/s, K in rad/s/√s, R in rad/s²; for an accelerometer
m/s, m/s/√s, m/s², m/s²/√s, m/s³. Convert with N[deg/√h] = N·(180/π)·60, B[deg/h] = B·(180/π)·3600,
K[deg/h/√h] = K·(180/π)·3600·60.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroemu.sensors.allan_stream import OverlappingAllanAccumulator

__all__ = [
    "AllanDeviation",
    "Coefficient",
    "AllanFit",
    "allan_deviation",
    "allan_confidence",
    "chi2_interval",
    "fit_allan",
    "TERMS",
    "RESOLVE_SIGMAS",
]

#: The IEEE 952 terms in the order of the fit's coefficients.
TERMS = ("quantisation", "arw", "bias_instability", "rrw", "rate_ramp")

#: A term is resolved when its share of σ² at some τ exceeds this many relative standard deviations of
#: the Allan variance estimate there (module notes).
RESOLVE_SIGMAS = 2.0

_ONE_SIGMA = 0.682689492137086  # probability within ±1σ of a normal distribution
_TAU_KEYWORDS = ("octave", "all", "decade", "log10")


def chi2_interval(
    dev: float | np.ndarray, edf: float | np.ndarray, ci: float = _ONE_SIGMA
) -> tuple[np.ndarray, np.ndarray]:
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


def _keyword_taus(keyword: str, n: int, dt: float) -> np.ndarray:
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


def _explicit_oadev(data: np.ndarray, dt: float, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    edf : (M,) chi-squared equivalent degrees of freedom, ν = clusters − 1.
    low, high : (M,) 68 % confidence interval of σ(τ).
    """

    tau: np.ndarray
    adev: np.ndarray
    clusters: np.ndarray
    edf: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def slope(self) -> np.ndarray:
        """(M−1,) local log-log slope between neighbouring points (−1 quantisation … +1 ramp)."""
        return np.diff(np.log(self.adev)) / np.diff(np.log(self.tau))


def allan_deviation(data: np.ndarray, dt: float, taus: str | np.ndarray = "octave") -> AllanDeviation:
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
    return allan_confidence(tau, adev, clusters)


def allan_confidence(tau: np.ndarray, adev: np.ndarray, clusters: np.ndarray) -> AllanDeviation:
    """An :class:`AllanDeviation` from σ(τ) computed elsewhere (a streamed estimate), with the confidence
    :func:`allan_deviation` gives: ν = clusters − 1 and the 68 % chi-squared interval of σ(τ).

    Parameters
    ----------
    tau : (M,) averaging times, s.
    adev : (M,) Allan deviation σ(τ), in the data's unit.
    clusters : (M,) independent clusters ⌊n/m⌋ of each τ = mΔt, each at least 2.
    """
    tau, adev = np.asarray(tau, dtype=float), np.asarray(adev, dtype=float)
    clusters = np.asarray(clusters, dtype=float)
    if np.any(clusters < 2):
        raise ValueError("every τ needs at least two independent clusters (ν ≥ 1)")
    edf = clusters - 1
    low, high = chi2_interval(adev, edf)
    return AllanDeviation(tau=tau, adev=adev, clusters=clusters, edf=edf, low=low, high=high)


@dataclass(frozen=True)
class Coefficient:
    """A fitted noise coefficient and its 68 % confidence interval (value 0: the term was not found,
    ``high`` is then a one-sigma upper limit).

    ``limit`` is the detection limit :func:`fit_allan` sets (NaN for a coefficient built elsewhere):
    the smallest value the data would resolve (module notes). A term is :attr:`resolved` when its value
    exceeds it; one that is not is bounded by it.
    """

    value: float
    low: float
    high: float
    limit: float = math.nan

    @property
    def resolved(self) -> bool:
        """Whether the data resolve the term: its value exceeds its detection limit (without a limit:
        its interval excludes 0)."""
        if math.isnan(self.limit):
            return self.value > 0 and self.low > 0
        return self.value > 0 and self.value > self.limit

    @property
    def upper_limit(self) -> float:
        """The bound to report for a term not resolved: the detection limit (or ``high`` without one)."""
        return self.high if math.isnan(self.limit) else max(self.limit, self.value)


@dataclass(frozen=True)
class AllanFit:
    """IEEE 952 coefficients fitted to an Allan deviation (units in the module notes)."""

    quantisation: Coefficient  # Q, slope −1
    arw: Coefficient  # N, slope −½, σ(1 s)
    bias_instability: Coefficient  # B, floor 0.664 B
    rrw: Coefficient  # K, slope +½, σ(3 s)
    rate_ramp: Coefficient  # R, slope +1
    allan: AllanDeviation

    def model(self, tau) -> np.ndarray:
        """The fitted σ(τ) at ``tau``, s."""
        c = np.array([getattr(self, name).value for name in TERMS]) ** 2
        return np.sqrt(_basis(np.asarray(tau, dtype=float)) @ c)


def _basis(tau: np.ndarray) -> np.ndarray:
    """(…, 5) Allan variance of each term per unit coefficient²: 3/τ², 1/τ, 2 ln2/π, τ/3, τ²/2."""
    floor = np.full_like(tau, 2 * np.log(2) / np.pi)
    return np.stack([3 / tau**2, 1 / tau, floor, tau / 3, tau**2 / 2], axis=-1)


def fit_allan(allan: AllanDeviation, terms=TERMS, iterations: int = 5) -> AllanFit:
    """Fit the IEEE 952 terms named in ``terms`` (a subset of :data:`TERMS`) to ``allan``.

    Leave out terms known to be absent (a static test has no rate ramp): a spare term soaks up some
    of the scatter of its neighbours. Returns every term; those left out are 0.
    """
    unknown = set(terms) - set(TERMS)
    if unknown:
        raise ValueError(f"unknown terms {sorted(unknown)}; known: {', '.join(TERMS)}")
    used = np.array([name in terms for name in TERMS])
    basis = _basis(allan.tau) * used  # (M, 5): a term left out has a zero column
    avar = allan.adev**2
    relative_sd = np.sqrt(2 / allan.edf)  # sd of an Allan variance estimate, per unit variance

    from scipy.optimize import nnls  # about 0.3 s to import: only when a curve is fitted

    model = avar  # weights from the data first, then from the model
    for _ in range(iterations):
        sd = model * relative_sd
        c, _ = nnls(basis[:, used] / sd[:, None], avar / sd)
        coefficients = np.zeros(len(TERMS))
        coefficients[used] = c
        model = np.maximum(basis @ coefficients, np.finfo(float).tiny)

    fitted = {
        name: _read(j, coefficients, basis, model, allan) if use else Coefficient(0.0, 0.0, 0.0)
        for j, (name, use) in enumerate(zip(TERMS, used))
    }
    return AllanFit(allan=allan, **fitted)


def _read(j: int, c: np.ndarray, basis: np.ndarray, model: np.ndarray, allan: AllanDeviation) -> Coefficient:
    """Coefficient j with its confidence, read where the data pin it best.

    At τ_i, term j makes the share s_i = c_j A_ij / σ²(τ_i) of the Allan variance, so τ_i alone would
    give c_j with a relative standard deviation √(2/ν_i) / s_i: the chi-squared of ν_i s_i² degrees of
    freedom. We take the best τ_i (adjacent octaves share data, so they are not combined). A term not
    found gets the upper limit at which it would have made one standard deviation where it shows most;
    a term found but never holding enough of the variance for one degree of freedom is undetermined,
    with the interval (0, ∞).
    """
    relative_sd = np.sqrt(2 / allan.edf)
    detectable = np.min(model * relative_sd / basis[:, j])  # c_j making one sd where it shows most
    limit = float(np.sqrt(RESOLVE_SIGMAS * detectable))  # ... RESOLVE_SIGMAS sd: the detection limit
    if c[j] <= 0:
        return Coefficient(0.0, 0.0, float(np.sqrt(detectable)), limit)
    share = c[j] * basis[:, j] / model
    best = np.argmin(relative_sd / share)
    value = np.sqrt(c[j])
    dof = allan.edf[best] * share[best] ** 2
    if dof < 1.0:  # the term never holds enough of the variance to be pinned: undetermined
        return Coefficient(float(value), 0.0, float("inf"), limit)
    low, high = chi2_interval(value, dof)
    return Coefficient(float(value), float(low), float(high), limit)
