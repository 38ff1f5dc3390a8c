"""Noise generators for inertial sensors: the stochastic terms of IEEE Std 952-1997, Annex B/C.

Every generator takes a seeded :class:`numpy.random.Generator` (every random draw comes from it, so the
same seed gives bit-identical output), a sample count ``n`` or a shape ``(n, axes)`` with time along
axis 0, the sample interval ``dt`` in seconds, and the term's coefficient in SI units (a scalar, or one
value per axis). Outputs are rate-like: rad/s for a gyro, m/s² for an accelerometer. The units below
are the gyro's; for an accelerometer read m/s for rad and m/s² for rad/s.

The terms and their Allan deviations σ(τ) (IEEE 952 Annex C, Table C.1):

========================  =====================================  ==============================  =====
term                      coefficient (SI)                       σ(τ)                            slope
========================  =====================================  ==============================  =====
quantisation              Q, rad (angle; Q = LSB/√12)            √3 Q / τ                        −1
angle random walk (ARW)   N, rad/s/√Hz ≡ rad/√s                  N / √τ                          −½
bias instability          B, rad/s                               B √(2 ln2 / π) ≈ 0.664 B        0
rate random walk (RRW)    K, rad/s²/√Hz ≡ rad/s/√s               K √(τ / 3)                      +½
rate ramp                 R, rad/s²                              R τ / √2                        +1
Gauss–Markov              σ, rad/s; correlation time τ_c, s      see :func:`gauss_markov_avar`   +½…−½
========================  =====================================  ==============================  =====

Noise density
    N is the coefficient of IEEE 952's angle random walk (velocity random walk for an accelerometer):
    the white noise's Allan deviation is N/√τ, so N is its Allan deviation at τ = 1 s, and white noise
    sampled every Δt has per-sample standard deviation σ = N/√Δt. Its power spectral density is N²
    two-sided (over −Fs/2 … Fs/2: σ²Δt = N²; IEEE 952 Annex C writes S_Ω = N² with
    σ²(τ) = 4 ∫₀^∞ S_Ω(f) sin⁴(πfτ)/(πfτ)² df) and 2N² one-sided (over 0 … Fs/2). So N is not the
    amplitude of a one-sided spectral density: that amplitude is √S₁ = √2·N. The same N is Kalibr's
    continuous-time noise density (``gyroscope_noise_density`` / ``accelerometer_noise_density``,
    σ_d = σ_c/√Δt) and imusim's; Kalibr's ``*_random_walk`` (σ_bd = σ_b √Δt) is K here. MATLAB's
    ``imuSensor`` reads ``NoiseDensity`` (of ``gyroparams``/``accelparams``) as a one-sided amplitude √S₁
    and draws σ = NoiseDensity·√(Fs/2) = √S₁/√(2Δt): to reproduce a MATLAB model use
    N = NoiseDensity/√2, to get our noise in MATLAB set ``NoiseDensity = √2·N``.

    A datasheet's figure in unit/√Hz may be either reading. An ARW/VRW figure (°/√h, m/s/√h), or a
    density read off an Allan plot, is N. A "noise (spectral) density" measured as a spectrum is, by
    the usual electronics convention, the one-sided amplitude √S₁, √2 above N, unless the datasheet says
    otherwise. The device keys name the reading (:class:`gyroemu.sensors.errors.GyroErrors`,
    :class:`~gyroemu.sensors.errors.AccelErrors`): ``arw_deg_per_sqrt_h``, ``vrw_m_per_s_per_sqrt_h``,
    ``noise_density_deg_per_s_per_sqrt_hz`` and ``noise_density_ug_per_sqrt_hz`` give N;
    ``psd_one_sided_deg_per_s_per_sqrt_hz`` and ``psd_one_sided_ug_per_sqrt_hz`` give √S₁ (N = √S₁/√2).
    Datasheet units: N[rad/√s] = N[deg/√h]·(π/180)/60; K[rad/s/√s] = K[deg/h/√h]·(π/180)/3600/60.

How each term is made
    Every stochastic term is a first-order autoregression x_k = φ x_{k−1} + c w_k with w_k ~ N(0, 1),
    drawn by one small numba kernel (:func:`_ar1_sum_into`): white noise is φ = 0, c = N/√Δt; a random
    walk is φ = 1, c = K√Δt; a Gauss–Markov process is φ = exp(−Δt/τ_c), c = σ√(1−φ²), started from its
    stationary distribution. numba's ``Generator.standard_normal`` draws the same numbers as numpy's,
    from the same stream, so the kernel is reproducible exactly like plain numpy code.

    Bias instability is flicker (1/f) noise, which no finite recurrence makes exactly. It is made as a
    sum of Gauss–Markov processes whose correlation times are spread two per decade over the range of τ
    where the flat Allan floor must hold (plus half a decade each side), with variances fitted by
    non-negative least squares so that the sum's Allan variance equals (2 ln2/π) B² across that range
    (:func:`flicker_bank`; flat within ±0.5 % in theory, ±1.5 % when the range reaches down to Δt).
    The fit uses the Allan variance of the *sampled* processes, which for correlation times of a few Δt
    or less is not the continuous-time formula (a component with τ_c ≲ Δt is nearly white, and would
    otherwise leak into the ARW). Below τ_min the bank's Allan deviation falls off like a random walk,
    above τ_max like white noise; in a real sensor ARW and RRW dominate there anyway. Slow components
    are simulated exactly at a coarser step h ≤ τ_j/16 (a power-of-two multiple of Δt) and linearly
    interpolated to the sample grid. That smooths a component only on time scales below τ_j/16, where
    its Allan variance is a tenth of its peak or less and faster components carry the floor: simulated
    floors stay flat within 1 % (with h ≤ τ_j/4 they sag by 2.5 %), at a cost of well under one draw
    per sample for the slow part.

Sources: IEEE Std 952-1997 (R2008), Annex B (PSD) and Annex C (Allan variance); W. Riley, NIST SP 1065
(2008) for Allan-variance estimation; N. J. Kasdin, Proc. IEEE 83(5), 1995, for flicker noise as a sum
of relaxation processes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.jit import njit

__all__ = [
    "FLICKER_FLOOR",
    "FlickerBank",
    "white_noise",
    "random_walk",
    "rate_ramp",
    "gauss_markov",
    "gauss_markov_avar",
    "flicker_bank",
    "flicker_noise",
    "quantisation_noise",
    "quantise_angle",
    "sensor_noise",
    "SensorNoise",
]

#: Allan deviation of flicker noise per unit bias instability B: σ(τ) = B·√(2 ln2/π) ≈ 0.664 B.
FLICKER_FLOOR = float(np.sqrt(2 * np.log(2) / np.pi))

# Flicker bank design: correlation times per decade, and the margin (in decades) beyond tau_range.
_PER_DECADE = 2
_MARGIN_DECADES = 0.5
# A slow component with correlation time τ_j is simulated at a step of at most τ_j / _STEPS_PER_TAU.
_STEPS_PER_TAU = 16


# --------------------------------------------------------------------------------------------------
# The one recurrence behind every stochastic term
# --------------------------------------------------------------------------------------------------


@njit
def _ar1_sum_into(
    rng: np.random.Generator,
    phi: NDArray[np.float64],
    c: NDArray[np.float64],
    state: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Add Σ_j x_j to ``out``, where x_j[k] = φ_j x_j[k−1] + c_j w, w ~ N(0, 1) from ``rng``.

    ``phi``, ``c``, ``state``: (J, A), one row per term and a column per axis; ``state`` holds x_j[−1]
    on entry and the last value on exit. ``out``: (n, A), added to in place. Draws are made in the order
    sample, axis, term, and only for terms with c ≠ 0.
    """
    n, n_axes = out.shape
    n_terms = phi.shape[0]
    for k in range(n):
        for a in range(n_axes):
            total = 0.0
            for j in range(n_terms):
                x = phi[j, a] * state[j, a]
                if c[j, a] != 0.0:
                    x += c[j, a] * rng.standard_normal()
                state[j, a] = x
                total += x
            out[k, a] += total


def _shape2d(shape: int | tuple[int, ...]) -> tuple[tuple[int, ...], tuple[int, int]]:
    """The requested shape and the (n, axes) shape the kernels work on."""
    given: Any = shape  # n or (n, axes): np.ndim tells them apart, which mypy cannot follow
    shape = (int(given),) if np.ndim(given) == 0 else tuple(int(s) for s in given)
    if len(shape) not in (1, 2) or shape[0] < 1:
        raise ValueError(f"shape must be n or (n, axes) with n >= 1, got {shape}")
    return shape, (shape[0], shape[1] if len(shape) == 2 else 1)


def _per_axis(value: ArrayLike, n_axes: int, name: str, *, nonnegative: bool = True) -> NDArray[np.float64]:
    """A coefficient as an (axes,) float array: a scalar applies to every axis."""
    v = np.broadcast_to(np.asarray(value, dtype=float), (n_axes,)).copy()
    if nonnegative and np.any(v < 0):
        given: object = value  # as given (ArrayLike admits bytes, which mypy will not format)
        raise ValueError(f"{name} must be >= 0, got {given}")
    return v


# --------------------------------------------------------------------------------------------------
# Single terms
# --------------------------------------------------------------------------------------------------


def white_noise(
    rng: np.random.Generator, shape: int | tuple[int, ...], dt: float, density: ArrayLike
) -> NDArray[np.float64]:
    """White rate noise (angle or velocity random walk) of noise density ``density``.

    Parameters
    ----------
    density : float or (axes,)
        N in rad/s/√Hz ≡ rad/√s (gyro) or m/s²/√Hz ≡ m/s/√s (accelerometer); N is the Allan deviation
        at τ = 1 s (two-sided PSD N², one-sided 2N²: see the module notes).

    Returns
    -------
    ndarray of ``shape``: samples with standard deviation σ = N / √Δt.
    """
    shape, (_, n_axes) = _shape2d(shape)
    sigma = _per_axis(density, n_axes, "density") / np.sqrt(dt)  # per-sample σ = N / √Δt
    noise: NDArray[np.float64] = (rng.standard_normal(shape).reshape(-1, n_axes) * sigma).reshape(shape)
    return noise


def random_walk(
    rng: np.random.Generator, shape: int | tuple[int, ...], dt: float, density: ArrayLike
) -> NDArray[np.float64]:
    """Rate random walk: the running sum of white increments of σ = K √Δt, starting from 0.

    Parameters
    ----------
    density : float or (axes,)
        K in rad/s²/√Hz ≡ rad/s/√s; the Allan deviation is K √(τ/3), so K is read at τ = 3 s.

    Returns
    -------
    ndarray of ``shape``, rad/s.
    """
    shape, (n, n_axes) = _shape2d(shape)
    step = _per_axis(density, n_axes, "density") * np.sqrt(dt)  # increment σ = K √Δt
    return np.cumsum(rng.standard_normal((n, n_axes)) * step, axis=0).reshape(shape)


def rate_ramp(shape: int | tuple[int, ...], dt: float, ramp: ArrayLike) -> NDArray[np.float64]:
    """Rate ramp R·t at the sample times t_k = k Δt (deterministic: no Generator).

    Parameters
    ----------
    ramp : float or (axes,)
        R in rad/s² (signed); the Allan deviation is R τ / √2.
    """
    shape, (n, n_axes) = _shape2d(shape)
    slope = _per_axis(ramp, n_axes, "ramp", nonnegative=False)
    return (np.arange(n)[:, None] * dt * slope).reshape(shape)


def gauss_markov(
    rng: np.random.Generator, shape: int | tuple[int, ...], dt: float, sigma: ArrayLike, tau_c: ArrayLike
) -> NDArray[np.float64]:
    """First-order Gauss–Markov (exponentially correlated) noise, stationary from the first sample.

    x_k = φ x_{k−1} + σ √(1 − φ²) w_k, φ = exp(−Δt/τ_c): the exact discretisation of
    dx/dt = −x/τ_c + white noise, with variance σ² and autocorrelation σ² exp(−|lag|/τ_c).

    Parameters
    ----------
    sigma : float or (axes,)
        Standard deviation σ, rad/s.
    tau_c : float or (axes,)
        Correlation time τ_c > 0, s.
    """
    shape, (n, n_axes) = _shape2d(shape)
    sigma = _per_axis(sigma, n_axes, "sigma")
    tau_c = _per_axis(tau_c, n_axes, "tau_c")
    if np.any(tau_c <= 0):
        raise ValueError(f"tau_c must be > 0, got {tau_c}")
    phi, c, x0 = _gauss_markov_rows(rng, sigma[None, :], tau_c[None, :], dt)  # x_{-1} from the stationary law
    out = np.zeros((n, n_axes))
    _ar1_sum_into(rng, phi, c, x0, out)
    return out.reshape(shape)


def gauss_markov_avar(
    tau: ArrayLike, sigma: ArrayLike, tau_c: ArrayLike, dt: float | None = None
) -> NDArray[np.float64]:
    """Allan variance of a Gauss–Markov process of standard deviation σ and correlation time τ_c.

    Continuous time (``dt`` None), the process averaged over each τ:
        σ²(τ) = σ² (τ_c/τ)² [2τ/τ_c − 3 + 4 e^{−τ/τ_c} − e^{−2τ/τ_c}]
    (→ (2/3) σ² τ/τ_c, a random walk, for τ ≪ τ_c; → 2 σ² τ_c/τ, white noise, for τ ≫ τ_c).

    Sampled every ``dt`` (what :func:`gauss_markov` makes), clusters of m = τ/Δt samples, φ = e^{−Δt/τ_c}:
        σ²(τ) = σ² [m (1+φ)/(1−φ) − (2φ(1−φ^m) + φ(1−φ^m)²) / (1−φ)²] / m²
    which differs from the continuous form where τ_c or τ is within a few Δt (for τ_c ≤ Δt the samples
    are nearly white, of variance σ², not 2σ²τ_c/Δt). For τ_c > 1000 Δt the two agree to < 0.1 %
    wherever the component matters, and the continuous form is used (the sampled one loses precision).
    """
    tau = np.asarray(tau, dtype=float)
    sigma, tau_c = np.asarray(sigma, dtype=float), np.asarray(tau_c, dtype=float)
    x = tau / tau_c
    # 2x − 3 + 4e^{−x} − e^{−2x} = (2/3)x³ − (1/2)x⁴ + (7/30)x⁵ − …: use the series where terms cancel.
    with np.errstate(over="ignore", invalid="ignore"):
        exact = (2 * x + 4 * np.expm1(-x) - np.expm1(-2 * x)) / x**2
    series = x * (2 / 3 - x / 2 + 7 * x**2 / 30)
    avar: NDArray[np.float64] = sigma**2 * np.where(x < 1e-3, series, exact)
    if dt is None:
        return avar
    m = tau / dt
    one_minus_phi = -np.expm1(-dt / tau_c)
    phi = 1 - one_minus_phi
    u = -np.expm1(-m * dt / tau_c)  # 1 − φ^m
    with np.errstate(divide="ignore", invalid="ignore"):
        sampled = sigma**2 * (m * (1 + phi) / one_minus_phi - (2 * phi * u + phi * u**2) / one_minus_phi**2) / m**2
    chosen: NDArray[np.float64] = np.where(tau_c > 1000 * dt, avar, sampled)
    return chosen


# --------------------------------------------------------------------------------------------------
# Flicker (bias instability)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FlickerBank:
    """Gauss–Markov components whose sum has a flat Allan floor 0.664 B over ``tau_range``.

    Attributes
    ----------
    tau_c : (J,) correlation times, s, ascending.
    sigma : (J, A) standard deviation of each component on each axis (rad/s or m/s²).
    tau_range : (τ_min, τ_max), s: where the floor is flat.
    """

    tau_c: NDArray[np.float64]
    sigma: NDArray[np.float64]
    tau_range: tuple[float, float]

    def avar(self, tau: ArrayLike, dt: float | None = None) -> NDArray[np.float64]:
        """The bank's Allan variance at ``tau`` (..., A): the sum of its components' (closed form,
        of the sampled components when ``dt`` is given)."""
        tau = np.asarray(tau, dtype=float)[..., None, None]
        total: NDArray[np.float64] = np.sum(gauss_markov_avar(tau, self.sigma, self.tau_c[:, None], dt), axis=-2)
        return total


def flicker_bank(
    bias_instability: ArrayLike, tau_range: tuple[float, float], dt: float | None = None, n_axes: int = 1
) -> FlickerBank:
    """Design the Gauss–Markov sum for flicker noise of bias instability B, flat over ``tau_range``.

    Correlation times τ_j are spaced two per decade from τ_min/√10 to τ_max·√10; their variances are
    the non-negative least-squares fit of Σ_j σ_j² A(τ; τ_j) = (2 ln2/π) B² on 200 log-spaced τ in
    ``tau_range`` (A = :func:`gauss_markov_avar` of a unit process), relative error weighting. Given
    the sample interval ``dt``, the fit uses the Allan variance of the sampled components, so the floor
    is flat for the samples themselves down to τ = Δt (τ_min is raised to Δt if below).

    Parameters
    ----------
    bias_instability : float or (axes,)
        B, rad/s (gyro) or m/s² (accelerometer): the flat Allan deviation is 0.664 B.
    tau_range : (τ_min, τ_max)
        Averaging times, s, over which the floor must be flat; τ_max > τ_min > 0.
    dt : float or None
        Sample interval, s, of the noise the bank will make (None: designed in continuous time).
    """
    b = _per_axis(bias_instability, n_axes, "bias_instability")
    tau_min, tau_max = float(tau_range[0]), float(tau_range[1])
    if not 0 < tau_min < tau_max:
        raise ValueError(f"tau_range must be (min, max) with 0 < min < max, got {tau_range}")
    if dt is not None:
        tau_min = max(tau_min, dt)
        if not tau_min < tau_max:
            raise ValueError(f"tau_range {tau_range} lies below the sample interval {dt} s")
    lo, hi = np.log10(tau_min) - _MARGIN_DECADES, np.log10(tau_max) + _MARGIN_DECADES
    tau_c = np.logspace(lo, hi, int(np.ceil((hi - lo) * _PER_DECADE)) + 1)
    tau = np.geomspace(tau_min, tau_max, 200)
    design = gauss_markov_avar(tau[:, None], 1.0, tau_c[None, :], dt)  # (τ, component), unit variances
    from scipy.optimize import nnls  # here, not at the top: scipy.optimize costs 0.3 s to import

    weights, _ = nnls(design / FLICKER_FLOOR**2, np.ones(tau.size))  # σ_j² per unit B²
    keep = weights > 0
    sigma = np.sqrt(weights[keep])[:, None] * b[None, :]
    return FlickerBank(tau_c=tau_c[keep], sigma=sigma, tau_range=(tau_min, tau_max))


def flicker_noise(
    rng: np.random.Generator,
    shape: int | tuple[int, ...],
    dt: float,
    bias_instability: ArrayLike,
    tau_range: tuple[float, float],
) -> NDArray[np.float64]:
    """Flicker (1/f) bias-instability noise: Allan deviation flat at 0.664 B over ``tau_range``.

    Parameters
    ----------
    bias_instability : float or (axes,)
        B, rad/s.
    tau_range : (τ_min, τ_max), s
        Where the floor must hold (see :func:`flicker_bank`).
    """
    shape, (n, n_axes) = _shape2d(shape)
    out = np.zeros((n, n_axes))
    bank = flicker_bank(bias_instability, tau_range, dt, n_axes)
    sensor_noise(rng, out.shape, dt, flicker=bank, out=out)
    return out.reshape(shape)


# --------------------------------------------------------------------------------------------------
# Quantisation
# --------------------------------------------------------------------------------------------------


def quantisation_noise(
    rng: np.random.Generator, shape: int | tuple[int, ...], dt: float, lsb: ArrayLike
) -> NDArray[np.float64]:
    """Rate noise of an angle quantiser of step ``lsb`` (IEEE 952's quantisation noise, alone).

    The quantised angle differs from the true one by e_k, uniform on [−LSB/2, LSB/2) and independent
    from sample to sample (a signal that moves over many LSBs); the rate error is (e_k − e_{k−1})/Δt.
    Its Allan deviation is √3 Q/τ with Q = LSB/√12 (the rms angle error): a −1 slope.

    Parameters
    ----------
    lsb : float or (axes,)
        Angle quantum, rad (velocity quantum, m/s, for an accelerometer).
    """
    shape, (n, n_axes) = _shape2d(shape)
    q = _per_axis(lsb, n_axes, "lsb")
    e = (rng.random((n + 1, n_axes)) - 0.5) * q  # angle errors e_{-1} … e_{n-1}
    return (np.diff(e, axis=0) / dt).reshape(shape)


def quantise_angle(
    rate: ArrayLike,
    dt: float,
    lsb: ArrayLike,
    rng: np.random.Generator | None,
    out: NDArray[np.float64] | None = None,
    *,
    angle: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Quantise the integrated angle of ``rate`` (n,) or (n, A), as a pulse-counting gyro does.

    The angle θ_k = θ₀ + Δt Σ_{i≤k} rate_i is counted in whole quanta, c_k = ⌊θ_k / LSB⌋, and the
    output rate is (c_k − c_{k−1})·LSB/Δt, so no angle is ever lost (the error stays below one LSB).
    The counter's initial fraction θ₀ is drawn uniform on [0, LSB) from ``rng``. When the angle moves
    over many quanta the rate error behaves as :func:`quantisation_noise`: Allan deviation √3 Q/τ,
    Q = LSB/√12.

    Parameters
    ----------
    rate : ndarray (n,) or (n, A), rad/s
    lsb : float or (A,), rad per count (> 0)
    out : ndarray like ``rate`` (C-contiguous float64), optional
        Where to write the result; may be ``rate`` itself.
    angle : ndarray (A,) float64, optional
        The counter's running angle θ, rad, to continue a run: read as θ₀ (then ``rng`` is not used and
        may be None) and left holding the angle after the last sample.
    """
    rate = np.asarray(rate, dtype=float)
    rate2 = np.ascontiguousarray(rate.reshape(rate.shape[0], -1))
    q = _per_axis(lsb, rate2.shape[1], "lsb")
    if np.any(q <= 0):
        given: object = lsb  # as given (ArrayLike admits bytes, which mypy will not format)
        raise ValueError(f"lsb must be > 0, got {given}")
    if angle is None:
        if rng is None:
            raise ValueError("quantise_angle needs a Generator for the counter's initial fraction, or its angle")
        angle = rng.random(rate2.shape[1]) * q
    elif angle.shape != (rate2.shape[1],) or angle.dtype != np.float64:
        raise ValueError(f"angle must be a float64 array of shape ({rate2.shape[1]},)")
    theta0 = angle
    if out is None:
        out = np.empty(rate.shape)
    if out.shape != rate.shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape {rate.shape}")
    _count_quanta(rate2, dt, q, theta0, out.reshape(rate2.shape))
    return out


@njit
def _count_quanta(
    rate: NDArray[np.float64],
    dt: float,
    lsb: NDArray[np.float64],
    theta0: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Write to ``out`` the rate of whole quanta counted from the running angle θ₀ + Δt Σ rate
    (see quantise_angle); ``out`` may be ``rate``. ``theta0`` (A,) is left holding the final angle,
    where a next call continues the count."""
    n, n_axes = rate.shape
    for a in range(n_axes):
        theta = theta0[a]
        count = np.floor(theta / lsb[a])
        for k in range(n):
            theta += rate[k, a] * dt
            new_count = np.floor(theta / lsb[a])
            out[k, a] = (new_count - count) * (lsb[a] / dt)
            count = new_count
        theta0[a] = theta


# --------------------------------------------------------------------------------------------------
# All stochastic terms in one pass (what the error layer uses)
# --------------------------------------------------------------------------------------------------


def sensor_noise(
    rng: np.random.Generator,
    shape: int | tuple[int, ...],
    dt: float,
    *,
    white: ArrayLike = 0.0,
    random_walk: ArrayLike = 0.0,
    flicker: FlickerBank | None = None,
    out: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """White noise + rate random walk + flicker, generated together in one pass over the samples.

    Statistically the sum of :func:`white_noise`, :func:`random_walk` and :func:`flicker_noise`
    (not the same numbers: the draws interleave). One call of :meth:`SensorNoise.add_into` on a fresh
    :class:`SensorNoise`: see there for the draw order.

    Parameters
    ----------
    shape : (n, A)
    white : float or (A,)
        Noise density N, rad/√s (the Allan deviation at τ = 1 s; one-sided PSD 2N²).
    random_walk : float or (A,)
        Rate random walk K, rad/s/√s (starts from 0 at the first sample).
    flicker : FlickerBank or None
        From :func:`flicker_bank`, with A axes.
    out : (n, A) float64 C-contiguous array or None
        Added to in place when given (the error layer adds the noise to its signal without a copy).

    Returns
    -------
    ``out``, or a new (n, A) array.
    """
    n, n_axes = _shape2d(shape)[1]
    if out is None:
        out = np.zeros((n, n_axes))
    if out.shape != (n, n_axes) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape {(n, n_axes)}")
    SensorNoise(rng, n_axes, dt, white=white, random_walk=random_walk, flicker=flicker).add_into(out)
    return out


@dataclass
class _SlowLevel:
    """Flicker components simulated every ``step`` samples: knots ``base, base + 1, …`` (at samples
    ``k · step``) held in ``knots``, each the level's own AR(1) sum plus the coarser levels' sum
    interpolated there; ``state`` the components' last values (J, A); ``rng`` the level's own draws."""

    step: int
    phi: NDArray[np.float64]
    c: NDArray[np.float64]
    state: NDArray[np.float64]
    rng: np.random.Generator
    base: int
    knots: NDArray[np.float64]


class SensorNoise:
    """White noise + rate random walk + flicker of one sensor triad, made chunk after chunk.

    Every term is a recurrence whose state this object carries (the AR(1) values, the random walk,
    the slow flicker levels' knots), so successive :meth:`add_into` calls continue one run.

    Draws: each slow flicker level draws from a generator of its own, spawned from ``rng``
    (``rng.spawn``), its stationary start at construction and its knots in order as calls need them;
    ``rng`` itself draws the fast components' stationary starts at construction, then every sample
    (axis by axis, term by term). So any division of a run into calls gives the same numbers.

    Slow flicker components (correlation time τ_j ≥ 32 Δt) are simulated every L_j samples, L_j the
    largest power of two ≤ τ_j / (16 Δt), and linearly interpolated (module notes). Levels sharing a
    step are summed on their own knots; each level's knots add the next coarser level's sum
    interpolated to them, and the finest slow level is interpolated onto the samples. Only the knots
    still needed are kept, so the state is a few knots per level whatever the run's length.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of every draw.
    n_axes : int
        A, the number of axes.
    dt : float
        Sample interval Δt, s.
    white, random_walk, flicker
        As :func:`sensor_noise`.
    markov : (sigma, tau_c) or None
        A first-order Gauss–Markov term (:func:`gauss_markov`): standard deviation σ (A,) or scalar,
        rad/s, and correlation time τ_c (A,) or scalar, s (> 0 where σ > 0). One more full-rate AR(1)
        row, φ = exp(−Δt/τ_c), c = σ√(1−φ²), its stationary start drawn from ``rng`` after the fast
        flicker components'. None, or σ = 0 on every axis, draws nothing (the other terms' numbers
        are unchanged).
    """

    def __init__(
        self,
        rng: np.random.Generator,
        n_axes: int,
        dt: float,
        *,
        white: ArrayLike = 0.0,
        random_walk: ArrayLike = 0.0,
        flicker: FlickerBank | None = None,
        markov: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> None:
        self._rng = rng
        self.n_axes = int(n_axes)
        self.dt = float(dt)
        self._sample = 0  # index of the next sample to make
        self._levels: list[_SlowLevel] = []
        # Full-rate terms, as AR(1) rows: white (φ = 0), random walk (φ = 1), fast flicker components.
        phi = [np.zeros(n_axes), np.ones(n_axes)]
        c = [
            _per_axis(white, n_axes, "white") / np.sqrt(dt),  # per-sample σ = N / √Δt
            _per_axis(random_walk, n_axes, "random_walk") * np.sqrt(dt),  # increment σ = K √Δt
        ]
        state = [np.zeros(n_axes), np.zeros(n_axes)]
        if flicker is not None:
            steps = np.maximum(flicker.tau_c / (_STEPS_PER_TAU * dt), 1.0)
            steps = 2 ** np.floor(np.log2(steps)).astype(np.int64)
            slow = sorted(set(steps[steps > 1].tolist()), reverse=True)
            for step, level_rng in zip(slow, rng.spawn(len(slow)), strict=True):
                j = steps == step
                phi_j, c_j, x0_j = _gauss_markov_rows(level_rng, flicker.sigma[j], flicker.tau_c[j, None], step * dt)
                self._levels.append(_SlowLevel(int(step), phi_j, c_j, x0_j, level_rng, 0, np.zeros((0, n_axes))))
            fast = steps == 1
            phi_f, c_f, x0_f = _gauss_markov_rows(rng, flicker.sigma[fast], flicker.tau_c[fast, None], dt)
            phi, c, state = phi + list(phi_f), c + list(c_f), state + list(x0_f)
        if markov is not None:
            sigma_m = _per_axis(markov[0], n_axes, "markov sigma")
            tau_m = _per_axis(markov[1], n_axes, "markov tau_c")
            if np.any((sigma_m > 0) & ~(tau_m > 0)):
                raise ValueError(f"markov tau_c must be > 0 where sigma > 0, got sigma {sigma_m}, tau_c {tau_m}")
            if np.any(sigma_m > 0):
                tau_m = np.where(sigma_m > 0, tau_m, 1.0)  # an axis without the term: c = 0, x = 0
                phi_m, c_m, x0_m = _gauss_markov_rows(rng, sigma_m[None, :], tau_m[None, :], dt)
                phi, c, state = phi + list(phi_m), c + list(c_m), state + list(x0_m)
        on = np.any(np.array(c) != 0, axis=1)
        self._phi = np.ascontiguousarray(np.array(phi)[on])
        self._c = np.ascontiguousarray(np.array(c)[on])
        self._state = np.ascontiguousarray(np.array(state)[on])

    @property
    def held_knots(self) -> int:
        """Knots the slow flicker levels hold now: the state beyond the AR(1) values, a few per level."""
        return sum(len(level.knots) for level in self._levels)

    def add_into(self, out: NDArray[np.float64]) -> NDArray[np.float64]:
        """Add the run's next ``len(out)`` samples of noise to ``out`` (n, A), C-contiguous float64."""
        n, n_axes = out.shape
        if n_axes != self.n_axes or out.dtype != np.float64 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float64 array of shape (n, {self.n_axes})")
        if n == 0:
            return out
        first = self._sample
        if self._levels:
            finest = self._levels[-1]
            self._extend(len(self._levels) - 1, (first + n - 1) // finest.step + 1)
            out += _interpolated(finest, np.arange(first, first + n, dtype=np.int64), finest.step)
            _trim(finest, (first + n) // finest.step)
        if self._phi.shape[0]:
            _ar1_sum_into(self._rng, self._phi, self._c, self._state, out)
        self._sample = first + n
        return out

    def _extend(self, i: int, last: int) -> None:
        """Make level ``i``'s knots up to index ``last``, drawing the coarser levels' first."""
        level = self._levels[i]
        made = level.base + len(level.knots)
        if last < made:
            return
        index = np.arange(made, last + 1, dtype=np.int64)
        block = np.zeros((len(index), self.n_axes))
        if i > 0:
            coarser = self._levels[i - 1]
            ratio = coarser.step // level.step
            self._extend(i - 1, -(-last // ratio))  # the coarser knot at or after the last new one
            block += _interpolated(coarser, index, ratio)
            _trim(coarser, last // ratio)
        _ar1_sum_into(level.rng, level.phi, level.c, level.state, block)
        level.knots = np.concatenate([level.knots, block])


def _interpolated(level: _SlowLevel, index: NDArray[np.int64], ratio: int) -> NDArray[np.float64]:
    """The linear interpolation of ``level``'s knots at ``index / ratio`` (knot units), (len(index), A):
    ``v_j + (r / ratio)(v_{j+1} − v_j)`` with ``j = index // ratio``, ``r = index % ratio``; on a knot, v_j."""
    out = np.empty((len(index), level.knots.shape[1]))
    _interpolate_into(np.ascontiguousarray(level.knots), level.base, np.ascontiguousarray(index), ratio, out)
    return out


@njit
def _interpolate_into(
    knots: NDArray[np.float64], base: int, index: NDArray[np.int64], ratio: int, out: NDArray[np.float64]
) -> None:
    """:func:`_interpolated`'s arithmetic sample by sample (the same bits): ``out[k] = v_j`` on a knot,
    else ``v_j + (r / ratio)(v_{j+1} − v_j)``; ``knots`` (K, A) from index ``base``, ``index`` (n,) ≥ 0."""
    n_axes = knots.shape[1]
    for k in range(index.shape[0]):
        j = index[k] // ratio
        r = index[k] - j * ratio
        row = j - base
        if r == 0:
            for a in range(n_axes):
                out[k, a] = knots[row, a]
        else:
            u = r / ratio
            for a in range(n_axes):
                lo = knots[row, a]
                out[k, a] = lo + u * (knots[row + 1, a] - lo)


def _trim(level: _SlowLevel, keep_from: int) -> None:
    """Forget ``level``'s knots before index ``keep_from`` (no later sample needs them)."""
    drop = keep_from - level.base
    if drop > 0:
        level.knots = level.knots[drop:].copy()
        level.base = keep_from


def _gauss_markov_rows(
    rng: np.random.Generator, sigma: NDArray[np.float64], tau_c: NDArray[np.float64], step: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """AR(1) rows (φ, c, stationary x_{-1}) of Gauss–Markov components sampled every ``step`` s:
    ``sigma`` (J, A), ``tau_c`` broadcastable to it (one per component, or per component and axis)."""
    phi = np.exp(-step / tau_c) * np.ones_like(sigma)
    c = sigma * np.sqrt(1 - phi**2)
    x0 = sigma * rng.standard_normal(sigma.shape)
    return phi, c, x0
