"""The standard error terms of inertial sensors, shared by every gyro and accelerometer kind.

One vectorised function, :func:`apply_errors` (:class:`SensorErrors` chunk by chunk), turns the true
signal of a three-axis sensor (angular rate ω in rad/s, or specific force f in m/s²) into what the
sensor outputs, following the models of
IEEE Std 952-1997 (fibre-optic gyros; its Annex C gives the Allan-variance terms), IEEE Std 647-2006
(ring-laser gyros) and IEEE Std 1431-2004 (Coriolis vibratory gyros); accelerometers take the same
terms in their own units (IEEE Std 1293-2018). For each axis i, with ΔT = T − T_ref:

    u_i = Σ_j (δ_ij + s_i + M_ij) x_j        scale factor s (ppm; s + s_on, s_on random per power-up)
                                             and misalignment / cross-axis M
        + k_i x_i²                           quadratic scale-factor nonlinearity
        + s_T,i ΔT x_i + b_T,i ΔT            temperature sensitivity of scale factor and bias
        + Σ_j G_ij f_j                        g-sensitivity (gyro only; f = specific force, m/s²)
        + b_i + b_on,i + R_i t               fixed bias, turn-on bias (random per power-up), ramp
        + n_i(t)                             ARW/VRW white noise + bias instability (flicker) + RRW
                                             + Gauss–Markov (exponentially correlated) noise

    y = Q( clip( LPF(u), ±range ) )          bandwidth (Butterworth low-pass), saturation, quantisation

The small terms act on the true input (first order in the errors). The noise n is made by
:func:`gyroemu.sensors.noise.sensor_noise`; the module notes of :mod:`gyroemu.sensors.noise` define the noise density
N (the Allan deviation at τ = 1 s, σ = N/√Δt per sample: IEEE 952's ARW coefficient, whose two-sided
PSD is N² and one-sided PSD 2N²; a datasheet's one-sided spectral density √S₁ is √2·N, which is how
MATLAB's ``imuSensor`` reads its ``NoiseDensity``) and the flicker model. Quantisation is either of the
integrated output (``quantisation_rad`` / ``quantisation_m_per_s``: a pulse-counting sensor that never loses angle) or
of the output itself (``quantisation_rad_per_s`` / ``quantisation_m_per_s2``: a rate ADC, which adds
white noise of σ = LSB/√12 per sample when the signal spans many LSBs). The pulse counter gives IEEE
952's quantisation term (Allan slope −1, σ(τ) = √3 Q/τ, Q = LSB/√12) when the angle moves by an LSB or
more between samples (a dithered ring-laser gyro, a vehicle in motion); on a quiet static sensor its
angle error is correlated from sample to sample, as a real counter's is, and the −1 line is fainter.

Config keys carry their datasheet unit (``bias_deg_per_h``, ``vrw_m_per_s_per_sqrt_h``), so a key in
the wrong unit is an unknown key. Per-axis keys take one number for all axes or a list of three (x, y,
z). ``g`` in a key name is the unit g₀ = 9.80665 m/s², not local gravity. :class:`GyroErrors` and
:class:`AccelErrors` convert to one SI :class:`ErrorModel`, which is all :func:`apply_errors` needs.

Randomness: every draw comes from the Generator passed in (and from generators spawned from it for the
slow flicker levels, :class:`gyroemu.sensors.noise.SensorNoise`), in a fixed order: at power-up the
turn-on bias, the turn-on scale factor, the noise's stationary starts and the pulse counter's initial
fraction, then the noise sample by sample; a term that is off draws nothing. :func:`apply_errors` is
one power-up over all its samples; :class:`SensorErrors` is one power-up applied chunk after chunk,
any division of the run giving the same numbers (the IMU layer's blocks, :mod:`gyroemu.sensors.device_run`).

Implementation: numpy prepares, and three small numba kernels make one pass each over the samples
(the deterministic response, the noise recurrences, the filter; the quantiser is a fourth), so the
layer costs about 2½ times numpy's own white-noise draw (``tests/benchmarks/bench_errors.py``). A
plain ``x @ M.T`` would be shorter but goes through multithreaded BLAS, which on a shared machine
ran 40 times slower than the loop.

Left to the IMU layer: the sample clock (rate error, jitter, time offset), sensor lever arms, and the
choice of which truth array feeds which sensor. The sample times given here must be uniform.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Literal, TypeGuard, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BeforeValidator, Field, ValidationInfo, field_validator

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal, Real, Section, at_least, at_most
from gyroemu.dynamics.jit import njit
from gyroemu.errors import ConfigError

from . import noise

__all__ = [
    "GyroErrors",
    "AccelErrors",
    "ErrorModel",
    "apply_errors",
    "SensorErrors",
    "STANDARD_GRAVITY",
    "MAX_RATE_LSB_RAD_PER_S",
    "MAX_ACCEL_LSB_M_PER_S2",
    "MAX_ANGLE_LSB_RAD",
    "MAX_VELOCITY_LSB_M_PER_S",
    "MIN_LSB",
    "MIN_BANDWIDTH_FRACTION",
    "bandwidth_problem",
]

#: The unit g₀ in key names (``_per_g``, ``_ug``), m/s²; not the local gravity of a scenario.
STANDARD_GRAVITY = 9.80665

_DEG = np.pi / 180  # rad per degree
_HOUR = 3600.0  # s per hour
_SQRT_HOUR = 60.0  # √s per √h
_SQRT2 = float(np.sqrt(2.0))  # one-sided PSD amplitude √S₁ per density N (Allan deviation at 1 s)
_PPM = 1e-6
_MRAD = 1e-3
_UG = 1e-6 * STANDARD_GRAVITY  # m/s² per µg


# --------------------------------------------------------------------------------------------------
# Config value types
# --------------------------------------------------------------------------------------------------


MAX_RATE_LSB_RAD_PER_S = 1000.0
"""The coarsest ``quantisation_rad_per_s`` (a rate output's LSB), rad/s (57 000 °/s): twice the whole
range of the widest gyros (about ±30 000 °/s, for spinning projectiles), so one count would hold every
rate a gyro reads; the quantiser's white noise LSB² T / 12 of a coarser one leaves float64's range."""

MAX_ACCEL_LSB_M_PER_S2 = 1.0e7
"""The coarsest ``quantisation_m_per_s2`` (an acceleration output's LSB), m/s² (about 10⁶ g): five times
the whole range of the widest shock accelerometers (about ±200 000 g, 2·10⁶ m/s²), so one count would
hold every acceleration one reads; the quantiser's white noise LSB² T / 12 of a coarser one leaves
float64's range."""

MAX_ANGLE_LSB_RAD = 0.1
"""The coarsest ``quantisation_rad`` (an integrating output's angle per count), rad (5.7°): over 250 times
the coarsest counts of real integrating outputs (a 16-bit delta-angle word over ±720°, 3.8·10⁻⁴ rad; a
ring laser's fringe is 10⁻⁵ rad). A count of 10³⁰⁰ rad was taken and every output sample read 0."""

MAX_VELOCITY_LSB_M_PER_S = 1.0
"""The coarsest ``quantisation_m_per_s`` (an integrating accelerometer's velocity per count), m/s: over 150
times the coarsest counts of real delta-velocity outputs (a 16-bit word over ±200 m/s, 6·10⁻³ m/s;
pulse-rebalanced accelerometers count 10⁻⁴ m/s). A count of 10³⁰⁰ m/s was taken and every output
sample read 0."""

MIN_LSB = 1e-12
"""The finest quantisation of every kind (``quantisation_rad``, ``quantisation_rad_per_s``,
``quantisation_m_per_s``, ``quantisation_m_per_s2``), in the key's SI unit: over a thousand times finer
than the finest words of real outputs (32 bits over ±720° per sample is 5.9·10⁻⁹ rad, over ±450 °/s
3.7·10⁻⁹ rad/s, over ±200 m/s 9.3·10⁻⁸ m/s, over ±40 g 1.8·10⁻⁷ m/s²), and about float64's step of a
counted angle or velocity within an hour (ulp(6283 rad, a thousand turns) = 9.1·10⁻¹³ rad; ulp(9807 m/s,
1 g for 1000 s) = 1.8·10⁻¹² m/s), so a finer count would not be resolved. A count of 10⁻³²⁰ (subnormal)
was taken and every output sample read NaN."""

MIN_BANDWIDTH_FRACTION = 1e-4
"""The narrowest output low-pass (``bandwidth_hz``), as a fraction of the sample rate: a hundred times
narrower than the output filters of real IMUs (which sit within about a hundredth of the output rate);
at 10⁻⁶ of the rate the second-order Butterworth's coefficients have lost their digits in float64 (its
noise gain came out 60 % off), and at 10⁻³⁰⁰ Hz its matrices were singular (a LinAlgError)."""


def bandwidth_problem(bandwidth_hz: float, rate_hz: float, rate: str = "") -> str | None:
    """Why an output low-pass of ``bandwidth_hz`` cannot filter samples at ``rate_hz`` (at or above the
    Nyquist frequency, or narrower than :data:`MIN_BANDWIDTH_FRACTION` of the rate), or None; ``rate``
    names the rate in the message (default: "the <rate_hz> Hz sample rate")."""
    rate = rate or f"the {rate_hz:g} Hz sample rate"
    if not bandwidth_hz < rate_hz / 2:
        return f"{bandwidth_hz:g} Hz is not below the Nyquist frequency {rate_hz / 2:g} Hz of {rate}"
    if bandwidth_hz < MIN_BANDWIDTH_FRACTION * rate_hz:
        return (
            f"{bandwidth_hz:g} Hz is less than the limit of {MIN_BANDWIDTH_FRACTION:g} of {rate} "
            f"({MIN_BANDWIDTH_FRACTION * rate_hz:g} Hz): a hundred times narrower than the output filters of real "
            "IMUs, and a low-pass whose coefficients float64 cannot hold"
        )
    return None


_FINEST = at_least(MIN_LSB, "over a thousand times finer than the finest words of real outputs")
_RateLsb = Annotated[
    PositiveReal,
    _FINEST,
    at_most(MAX_RATE_LSB_RAD_PER_S, "one count would be more than the widest gyro's whole range"),
]
_AccelLsb = Annotated[
    PositiveReal,
    _FINEST,
    at_most(MAX_ACCEL_LSB_M_PER_S2, "one count would be more than the widest accelerometer's range"),
]
_AngleLsb = Annotated[
    PositiveReal,
    _FINEST,
    at_most(MAX_ANGLE_LSB_RAD, "over 250 times the coarsest angle count of real integrating outputs"),
]
_VelocityLsb = Annotated[
    PositiveReal,
    _FINEST,
    at_most(MAX_VELOCITY_LSB_M_PER_S, "over 150 times the coarsest velocity count of real integrating outputs"),
]

_V = TypeVar("_V")


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _axes(value: object) -> object:
    """One number for all three axes, or a list of three."""
    if _is_number(value):
        return (value, value, value)
    if isinstance(value, (list, tuple)) and len(value) != 3:
        raise ValueError(f"expected one number or 3 (x, y, z), got {len(value)} values")
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"expected one number or a list of 3, got {type(value).__name__} {value!r}")
    return value


def _axes_nonnegative(value: object) -> object:
    if _is_number(value) and value < 0:
        raise ValueError(f"must be >= 0 (a noise or uncertainty magnitude), got {value}")
    return _axes(value)


PerAxis = Annotated[tuple[Real, Real, Real], BeforeValidator(_axes)]
PerAxisNonNegative = Annotated[
    tuple[NonNegativeReal, NonNegativeReal, NonNegativeReal], BeforeValidator(_axes_nonnegative)
]
Matrix3 = tuple[tuple[Real, Real, Real], tuple[Real, Real, Real], tuple[Real, Real, Real]]
#: Six small angles (xy, xz, yx, yz, zx, zy): sensing axis x tilted towards y by xy, and so on.
Angles6 = tuple[Real, Real, Real, Real, Real, Real]
_ZERO = (0.0, 0.0, 0.0)


class _CommonErrors(Section):
    """Keys without a unit that depends on the sensor, and the checks that relate keys."""

    scale_factor_ppm: PerAxis = _ZERO
    turn_on_scale_factor_ppm: PerAxisNonNegative = _ZERO
    scale_factor_temperature_ppm_per_degC: PerAxis = _ZERO
    reference_temperature_degC: Real = 25.0
    misalignment_mrad: Angles6 | None = None
    cross_axis_matrix: Matrix3 | None = None
    bias_instability_tau_range_s: tuple[PositiveReal, PositiveReal] = (1.0, 1.0e4)
    bandwidth_hz: PositiveReal | None = None
    filter_order: Literal[1, 2] = 2

    @field_validator("cross_axis_matrix")
    @classmethod
    def _one_misalignment(cls, value: Matrix3 | None, info: ValidationInfo) -> Matrix3 | None:
        if value is not None and info.data.get("misalignment_mrad") is not None:
            raise ValueError("give either misalignment_mrad or cross_axis_matrix, not both")
        if value is not None and any(value[i][i] != 0 for i in range(3)):
            raise ValueError("the diagonal must be 0 (scale factor errors go in scale_factor_ppm)")
        return value

    @field_validator("bias_instability_tau_range_s")
    @classmethod
    def _ascending(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not value[0] < value[1]:
            raise ValueError(f"expected (min, max) with min < max, got {value}")
        return value

    white_noise_keys: ClassVar[tuple[str, ...]]
    """The alternative keys of the white noise (its datasheet forms); a config gives at most one."""

    def white_noise_key(self) -> str | None:
        """Which of :attr:`white_noise_keys` the config gives (None: neither, no white noise)."""
        return next((key for key in self.white_noise_keys if getattr(self, key) is not None), None)

    markov_keys: ClassVar[tuple[str, str]]
    """The Gauss–Markov term's keys (σ in the sensor's unit, τ_c in s), both given or neither."""

    def _markov_si(self, unit: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(σ, τ_c) of the Gauss–Markov term in SI, σ given in ``unit`` (zeros when off)."""
        sigma_key, tau_key = self.markov_keys
        sigma, tau = getattr(self, sigma_key), getattr(self, tau_key)
        if sigma is None:
            return np.zeros(3), np.zeros(3)
        return np.array(sigma, dtype=float) * unit, np.array(tau, dtype=float)

    def _cross_axis(self) -> NDArray[np.float64]:
        if self.cross_axis_matrix is not None:
            return np.array(self.cross_axis_matrix, dtype=float)
        m = np.zeros((3, 3))
        if self.misalignment_mrad is not None:
            xy, xz, yx, yz, zx, zy = np.array(self.misalignment_mrad) * _MRAD
            m = np.array([[0, xy, xz], [yx, 0, yz], [zx, zy, 0]])
        return m


def _exclusive(*earlier: str) -> classmethod[Any, Any, Any]:
    """A validator for the last of alternative keys: refuse it when one of the ``earlier`` keys (declared
    before it) is given too, naming both."""

    def check(cls: type[_CommonErrors], value: _V, info: ValidationInfo) -> _V:
        if value is not None:
            for first in earlier:
                if info.data.get(first) is not None:
                    raise ValueError(f"give either {first} or {info.field_name}, not both")
        return value

    return classmethod(check)


def _markov_pair(sigma_key: str) -> classmethod[Any, Any, Any]:
    """A validator for ``markov_tau_s`` (validated even when absent): the Gauss–Markov term takes both
    keys or neither, and τ_c > 0 wherever σ > 0."""

    def check(
        cls: type[_CommonErrors], value: tuple[float, float, float] | None, info: ValidationInfo
    ) -> tuple[float, float, float] | None:
        if sigma_key not in info.data:  # σ itself was refused: its own error says why
            return value
        sigma = info.data[sigma_key]
        if (sigma is None) != (value is None):
            raise ValueError(f"give both {sigma_key} and {info.field_name} (a Gauss–Markov term), or neither")
        # value is not None where sigma is not (checked just above): the cast only tells mypy so
        taus = cast("tuple[float, float, float]", value)
        if sigma is not None and any(s > 0 and not t > 0 for s, t in zip(sigma, taus)):
            raise ValueError(f"must be > 0 on every axis where {sigma_key} is > 0")
        return value

    return classmethod(check)


def _needs_range(range_key: str) -> classmethod[Any, Any, Any]:
    """A validator for the nonlinearity: it is in ppm of full scale, so the range must be given."""

    def check(
        cls: type[_CommonErrors], value: tuple[float, float, float], info: ValidationInfo
    ) -> tuple[float, float, float]:
        if any(value) and info.data.get(range_key) is None:
            raise ValueError(f"is in ppm of full scale: give {range_key} too")
        return value

    return classmethod(check)


class GyroErrors(_CommonErrors):
    """A gyro's error terms, each key in the datasheet unit its name says. All default to off.

    White noise, one key at most, converted to the density N (the Allan deviation at τ = 1 s; module
    notes of :mod:`gyroemu.sensors.noise`): ``arw_deg_per_sqrt_h`` (IEEE 952 ARW, N in °/√h) or
    ``noise_density_deg_per_s_per_sqrt_hz`` (the same N in °/s/√Hz: an Allan/ARW-style density, as
    Kalibr's ``gyroscope_noise_density``) or ``psd_one_sided_deg_per_s_per_sqrt_hz`` (the amplitude √S₁
    of a one-sided power spectral density, as MATLAB's ``imuSensor`` reads a datasheet; N = √S₁/√2).
    Others: ``bias_instability_deg_per_h`` (flicker floor 0.664 B, flat over
    ``bias_instability_tau_range_s``), ``rrw_deg_per_h_per_sqrt_h``. Gauss–Markov (exponentially
    correlated) noise: ``markov_sigma_deg_per_h`` (its standard deviation σ) with ``markov_tau_s`` (its
    correlation time τ_c), both or neither; Allan variance :func:`gyroemu.sensors.noise.gauss_markov_avar`.
    Quantisation: ``quantisation_rad`` (angle per count of an integrating output) or
    ``quantisation_rad_per_s`` (rate LSB).
    ``g_sensitivity_deg_per_h_per_g``: 3x3, row i = output axis, column j = specific-force axis.
    """

    bias_deg_per_h: PerAxis = _ZERO
    turn_on_bias_deg_per_h: PerAxisNonNegative = _ZERO
    bias_temperature_deg_per_h_per_degC: PerAxis = _ZERO
    range_deg_per_s: PositiveReal | None = None
    scale_factor_nonlinearity_ppm: PerAxis = _ZERO
    g_sensitivity_deg_per_h_per_g: Matrix3 | None = None
    arw_deg_per_sqrt_h: PerAxisNonNegative | None = None
    noise_density_deg_per_s_per_sqrt_hz: PerAxisNonNegative | None = None
    psd_one_sided_deg_per_s_per_sqrt_hz: PerAxisNonNegative | None = None
    bias_instability_deg_per_h: PerAxisNonNegative = _ZERO
    rrw_deg_per_h_per_sqrt_h: PerAxisNonNegative = _ZERO
    markov_sigma_deg_per_h: PerAxisNonNegative | None = None
    markov_tau_s: PerAxisNonNegative | None = Field(default=None, validate_default=True)
    rate_ramp_deg_per_h_per_h: PerAxis = _ZERO
    quantisation_rad: _AngleLsb | None = None
    quantisation_rad_per_s: _RateLsb | None = None

    white_noise_keys = (
        "arw_deg_per_sqrt_h",
        "noise_density_deg_per_s_per_sqrt_hz",
        "psd_one_sided_deg_per_s_per_sqrt_hz",
    )
    markov_keys = ("markov_sigma_deg_per_h", "markov_tau_s")
    _nonlinearity = field_validator("scale_factor_nonlinearity_ppm")(_needs_range("range_deg_per_s"))
    _density = field_validator("noise_density_deg_per_s_per_sqrt_hz")(_exclusive("arw_deg_per_sqrt_h"))
    _psd = field_validator("psd_one_sided_deg_per_s_per_sqrt_hz")(_exclusive(*white_noise_keys[:2]))
    _quantum = field_validator("quantisation_rad_per_s")(_exclusive("quantisation_rad"))
    _markov = field_validator("markov_tau_s")(_markov_pair("markov_sigma_deg_per_h"))

    def to_si(self) -> ErrorModel:
        """The same terms in SI units (rad, rad/s, s, m/s²)."""
        deg_per_h = _DEG / _HOUR  # rad/s per deg/h
        if self.noise_density_deg_per_s_per_sqrt_hz is not None:
            density = np.array(self.noise_density_deg_per_s_per_sqrt_hz) * _DEG
        elif self.psd_one_sided_deg_per_s_per_sqrt_hz is not None:
            density = np.array(self.psd_one_sided_deg_per_s_per_sqrt_hz) * _DEG / _SQRT2
        else:
            density = np.array(self.arw_deg_per_sqrt_h or _ZERO) * _DEG / _SQRT_HOUR
        full_scale = None if self.range_deg_per_s is None else self.range_deg_per_s * _DEG
        g_sens = self.g_sensitivity_deg_per_h_per_g
        markov_sigma, markov_tau = self._markov_si(deg_per_h)
        return ErrorModel(
            bias=np.array(self.bias_deg_per_h) * deg_per_h,
            turn_on_bias=np.array(self.turn_on_bias_deg_per_h) * deg_per_h,
            bias_temperature=np.array(self.bias_temperature_deg_per_h_per_degC) * deg_per_h,
            scale_factor=np.array(self.scale_factor_ppm) * _PPM,
            turn_on_scale_factor=np.array(self.turn_on_scale_factor_ppm) * _PPM,
            scale_factor_temperature=np.array(self.scale_factor_temperature_ppm_per_degC) * _PPM,
            reference_temperature_degC=self.reference_temperature_degC,
            nonlinearity=_quadratic(self.scale_factor_nonlinearity_ppm, full_scale),
            cross_axis=self._cross_axis(),
            g_sensitivity=None if g_sens is None else np.array(g_sens) * deg_per_h / STANDARD_GRAVITY,
            noise_density=density,
            bias_instability=np.array(self.bias_instability_deg_per_h) * deg_per_h,
            bias_instability_tau_range=self.bias_instability_tau_range_s,
            random_walk=np.array(self.rrw_deg_per_h_per_sqrt_h) * deg_per_h / _SQRT_HOUR,
            ramp=np.array(self.rate_ramp_deg_per_h_per_h) * deg_per_h / _HOUR,
            integral_lsb=self.quantisation_rad,
            output_lsb=self.quantisation_rad_per_s,
            full_scale=full_scale,
            bandwidth_hz=self.bandwidth_hz,
            filter_order=self.filter_order,
            markov_sigma=markov_sigma,
            markov_tau_s=markov_tau,
        )


class AccelErrors(_CommonErrors):
    """An accelerometer's error terms, each key in the datasheet unit its name says. All default to off.

    White noise, one key at most, converted to the density N (the Allan deviation at τ = 1 s; module
    notes of :mod:`gyroemu.sensors.noise`): ``vrw_m_per_s_per_sqrt_h`` (velocity random walk, N in
    m/s/√h) or ``noise_density_ug_per_sqrt_hz`` (the same N in µg/√Hz: an Allan/VRW-style density, as
    Kalibr's ``accelerometer_noise_density``) or ``psd_one_sided_ug_per_sqrt_hz`` (the amplitude √S₁ of
    a one-sided power spectral density, as MATLAB's ``imuSensor`` reads a datasheet; N = √S₁/√2).
    Others: ``bias_instability_ug`` (flicker floor 0.664 B over
    ``bias_instability_tau_range_s``), ``random_walk_ug_per_sqrt_h`` (the accelerometer's rate random
    walk), ``markov_sigma_ug`` with ``markov_tau_s`` (Gauss–Markov noise: standard deviation σ and
    correlation time τ_c, both or neither). Quantisation: ``quantisation_m_per_s`` (velocity per count
    of an integrating output) or ``quantisation_m_per_s2`` (acceleration LSB). µg is written ``ug``.
    """

    bias_ug: PerAxis = _ZERO
    turn_on_bias_ug: PerAxisNonNegative = _ZERO
    bias_temperature_ug_per_degC: PerAxis = _ZERO
    range_g: PositiveReal | None = None
    scale_factor_nonlinearity_ppm: PerAxis = _ZERO
    vrw_m_per_s_per_sqrt_h: PerAxisNonNegative | None = None
    noise_density_ug_per_sqrt_hz: PerAxisNonNegative | None = None
    psd_one_sided_ug_per_sqrt_hz: PerAxisNonNegative | None = None
    bias_instability_ug: PerAxisNonNegative = _ZERO
    random_walk_ug_per_sqrt_h: PerAxisNonNegative = _ZERO
    markov_sigma_ug: PerAxisNonNegative | None = None
    markov_tau_s: PerAxisNonNegative | None = Field(default=None, validate_default=True)
    ramp_ug_per_h: PerAxis = _ZERO
    quantisation_m_per_s: _VelocityLsb | None = None
    quantisation_m_per_s2: _AccelLsb | None = None

    white_noise_keys = ("vrw_m_per_s_per_sqrt_h", "noise_density_ug_per_sqrt_hz", "psd_one_sided_ug_per_sqrt_hz")
    markov_keys = ("markov_sigma_ug", "markov_tau_s")
    _nonlinearity = field_validator("scale_factor_nonlinearity_ppm")(_needs_range("range_g"))
    _density = field_validator("noise_density_ug_per_sqrt_hz")(_exclusive("vrw_m_per_s_per_sqrt_h"))
    _psd = field_validator("psd_one_sided_ug_per_sqrt_hz")(_exclusive(*white_noise_keys[:2]))
    _quantum = field_validator("quantisation_m_per_s2")(_exclusive("quantisation_m_per_s"))
    _markov = field_validator("markov_tau_s")(_markov_pair("markov_sigma_ug"))

    def to_si(self) -> ErrorModel:
        """The same terms in SI units (m/s, m/s², s)."""
        if self.noise_density_ug_per_sqrt_hz is not None:
            density = np.array(self.noise_density_ug_per_sqrt_hz) * _UG
        elif self.psd_one_sided_ug_per_sqrt_hz is not None:
            density = np.array(self.psd_one_sided_ug_per_sqrt_hz) * _UG / _SQRT2
        else:
            density = np.array(self.vrw_m_per_s_per_sqrt_h or _ZERO) / _SQRT_HOUR
        full_scale = None if self.range_g is None else self.range_g * STANDARD_GRAVITY
        markov_sigma, markov_tau = self._markov_si(_UG)
        return ErrorModel(
            bias=np.array(self.bias_ug) * _UG,
            turn_on_bias=np.array(self.turn_on_bias_ug) * _UG,
            bias_temperature=np.array(self.bias_temperature_ug_per_degC) * _UG,
            scale_factor=np.array(self.scale_factor_ppm) * _PPM,
            turn_on_scale_factor=np.array(self.turn_on_scale_factor_ppm) * _PPM,
            scale_factor_temperature=np.array(self.scale_factor_temperature_ppm_per_degC) * _PPM,
            reference_temperature_degC=self.reference_temperature_degC,
            nonlinearity=_quadratic(self.scale_factor_nonlinearity_ppm, full_scale),
            cross_axis=self._cross_axis(),
            g_sensitivity=None,
            noise_density=density,
            bias_instability=np.array(self.bias_instability_ug) * _UG,
            bias_instability_tau_range=self.bias_instability_tau_range_s,
            random_walk=np.array(self.random_walk_ug_per_sqrt_h) * _UG / _SQRT_HOUR,
            ramp=np.array(self.ramp_ug_per_h) * _UG / _HOUR,
            integral_lsb=self.quantisation_m_per_s,
            output_lsb=self.quantisation_m_per_s2,
            full_scale=full_scale,
            bandwidth_hz=self.bandwidth_hz,
            filter_order=self.filter_order,
            markov_sigma=markov_sigma,
            markov_tau_s=markov_tau,
        )


def _quadratic(ppm_of_full_scale: ArrayLike, full_scale: float | None) -> NDArray[np.float64]:
    """k of the quadratic term k·x², from a nonlinearity in ppm of full scale: k·FS² = ppm·1e-6·FS."""
    ppm = np.array(ppm_of_full_scale, dtype=float)
    return np.zeros(3) if full_scale is None else ppm * _PPM / full_scale


# --------------------------------------------------------------------------------------------------
# The SI model and the error function
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ErrorModel:
    """Error terms in SI units. "unit" below is rad/s for a gyro, m/s² for an accelerometer.

    Attributes
    ----------
    bias, turn_on_bias : (3,) unit
        Fixed bias b, and the standard deviation of the bias drawn once per power-up.
    bias_temperature : (3,) unit per K
    scale_factor, scale_factor_temperature : (3,) dimensionless, and per K
    turn_on_scale_factor : (3,) dimensionless
        Standard deviation of the scale factor drawn once per power-up (repeatability), added to
        ``scale_factor``; 0 (the default) draws nothing.
    reference_temperature_degC : float
        Temperature at which the temperature terms vanish, °C.
    nonlinearity : (3,) 1/unit
        k in k·x².
    cross_axis : (3, 3) dimensionless, zero diagonal
        M: sensing axis i responds to M[i, j]·x_j.
    g_sensitivity : (3, 3) unit per m/s², or None
    noise_density : (3,) unit·√s
        N: white noise, Allan deviation at 1 s.
    bias_instability : (3,) unit; bias_instability_tau_range : (τ_min, τ_max), s
    random_walk : (3,) unit/√s
        K, rate random walk.
    ramp : (3,) unit/s
    integral_lsb : float or None
        Quantum of the integrated output (rad or m/s).
    output_lsb : float or None
        Quantum of the output (unit).
    full_scale : float or None
        Saturation limit (unit).
    bandwidth_hz : float or None; filter_order : 1 or 2
    markov_sigma : (3,) unit; markov_tau_s : (3,) s
        Gauss–Markov noise: standard deviation σ and correlation time τ_c (> 0 where σ > 0); σ = 0
        (the default) is off and draws nothing.
    """

    bias: NDArray[np.float64]
    turn_on_bias: NDArray[np.float64]
    bias_temperature: NDArray[np.float64]
    scale_factor: NDArray[np.float64]
    scale_factor_temperature: NDArray[np.float64]
    reference_temperature_degC: float
    nonlinearity: NDArray[np.float64]
    cross_axis: NDArray[np.float64]
    g_sensitivity: NDArray[np.float64] | None
    noise_density: NDArray[np.float64]
    bias_instability: NDArray[np.float64]
    bias_instability_tau_range: tuple[float, float]
    random_walk: NDArray[np.float64]
    ramp: NDArray[np.float64]
    integral_lsb: float | None
    output_lsb: float | None
    full_scale: float | None
    bandwidth_hz: float | None
    filter_order: int
    markov_sigma: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    markov_tau_s: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    turn_on_scale_factor: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))


def _turn_on(sigma: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64] | float:
    """A power-up's draw of a term with standard deviation ``sigma`` (3,): σ·z, z three normal draws;
    0.0, drawing nothing, when the term is off."""
    return sigma * rng.standard_normal(3) if np.any(sigma) else 0.0


def apply_errors(
    truth: ArrayLike,
    t: ArrayLike,
    spec: GyroErrors | AccelErrors | ErrorModel,
    rng: np.random.Generator,
    *,
    temperature_degC: ArrayLike | None = None,
    specific_force: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """What a three-axis sensor with the error terms ``spec`` outputs for the true input ``truth``.

    One power-up, all samples at once: :class:`SensorErrors` with the interval of ``t``, applied once.

    Parameters
    ----------
    truth : (N, 3)
        True angular rate ω_b (rad/s) for a gyro, true specific force f_b (m/s²) for an accelerometer,
        in the sensor's axes.
    t : (N,)
        Sample times, s, uniformly spaced (N ≥ 2); the rate ramp is R·t, so t = 0 is power-up.
    spec : GyroErrors, AccelErrors or ErrorModel
    rng : numpy.random.Generator
        Source of every random draw (see the module notes for the order).
    temperature_degC : float or (N,), optional
        Sensor temperature, °C (per-°C sensitivities are per kelvin). None: the reference temperature.
    specific_force : (N, 3), optional
        Specific force at the sensor, m/s², for the gyro's g-sensitivity (required when it is set).

    Returns
    -------
    (N, 3) float64: the measured rate (rad/s) or specific force (m/s²).
    """
    x = np.asarray(truth, dtype=float)
    t = np.asarray(t, dtype=float)
    n = x.shape[0]
    if x.shape != (n, 3) or t.shape != (n,) or n < 2:
        raise ValueError(f"expected truth (N, 3) and t (N,) with N >= 2, got {x.shape} and {t.shape}")
    dt = (t[-1] - t[0]) / (n - 1)
    if not dt > 0 or np.max(np.abs(np.diff(t) - dt)) > 1e-6 * dt:
        raise ValueError("sample times must be uniform and increasing (clock jitter is the IMU layer's)")
    errors = SensorErrors(spec, dt, rng)
    return errors.apply(x, t, temperature_degC=temperature_degC, specific_force=specific_force)


class SensorErrors:
    """The error terms of one sensor triad over one power-up, applied chunk after chunk.

    Construction is the power-up: it draws the turn-on bias, the turn-on scale factor, the noise's
    stationary starts and the pulse counter's initial fraction, in that order (a term that is off
    draws nothing). Each :meth:`apply` then continues the run with
    the next samples: the noise recurrences (:class:`gyroemu.sensors.noise.SensorNoise`), the
    low-pass filter's state and the pulse counter's angle carry from one call to the next.

    Parameters
    ----------
    spec : GyroErrors, AccelErrors or ErrorModel
    dt : float
        Sample interval, s.
    rng : numpy.random.Generator
        Source of every random draw.
    """

    def __init__(self, spec: GyroErrors | AccelErrors | ErrorModel, dt: float, rng: np.random.Generator) -> None:
        m = spec if isinstance(spec, ErrorModel) else spec.to_si()
        problem = None if m.bandwidth_hz is None else bandwidth_problem(m.bandwidth_hz, 1 / dt)
        if problem is not None:
            raise ConfigError(problem, key="bandwidth_hz")
        self.model = m
        self.dt = float(dt)
        self._bias = m.bias + _turn_on(m.turn_on_bias, rng)
        self._gain = np.eye(3) + np.diag(m.scale_factor + _turn_on(m.turn_on_scale_factor, rng)) + m.cross_axis
        flicker = None
        if np.any(m.bias_instability):
            flicker = noise.flicker_bank(m.bias_instability, m.bias_instability_tau_range, dt, n_axes=3)
        markov = (m.markov_sigma, m.markov_tau_s) if np.any(m.markov_sigma) else None
        self._noise = noise.SensorNoise(
            rng, 3, dt, white=m.noise_density, random_walk=m.random_walk, flicker=flicker, markov=markov
        )
        self._filter: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        self._filter_state: NDArray[np.float64] | None = None  # set from the first sample
        if m.bandwidth_hz is not None:
            import scipy.signal  # here, not at the top: it costs 0.5 s to import, and few devices need it

            self._filter = scipy.signal.butter(m.filter_order, m.bandwidth_hz, btype="low", fs=1.0 / dt)
        self._counter_angle = None if m.integral_lsb is None else rng.random(3) * m.integral_lsb

    @property
    def bias(self) -> NDArray[np.float64]:
        """The power-up's bias b + b_on (3,), unit."""
        return np.array(self._bias, dtype=float) * np.ones(3)

    def apply(
        self,
        truth: ArrayLike,
        t: ArrayLike,
        *,
        temperature_degC: ArrayLike | None = None,
        specific_force: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """The output for the run's next samples: ``truth`` (n, 3) at times ``t`` (n,), s since power-up
        (read only by the rate ramp); other parameters as :func:`apply_errors`. Returns (n, 3)."""
        m = self.model
        x = np.asarray(truth, dtype=float)
        t = np.asarray(t, dtype=float)
        n = x.shape[0]
        if x.shape != (n, 3) or t.shape != (n,):
            raise ValueError(f"expected truth (n, 3) and t (n,), got {x.shape} and {t.shape}")
        # Deterministic response: (I + S + M) x + k x² + (b_T + s_T x) ΔT + G f + b + b_on + R t.
        if temperature_degC is None:
            temperature_degC = m.reference_temperature_degC
        dT = np.broadcast_to(np.asarray(temperature_degC, dtype=float) - m.reference_temperature_degC, (n,))
        g_sensitivity, f = np.zeros((3, 3)), np.broadcast_to(np.zeros(3), (n, 3))
        if m.g_sensitivity is not None:
            if specific_force is None:
                raise ValueError("this gyro has a g-sensitivity: pass the specific force (N, 3), m/s²")
            g_sensitivity, f = m.g_sensitivity, np.asarray(specific_force, dtype=float)
            if f.shape != (n, 3):
                raise ValueError(f"expected specific_force of shape {(n, 3)}, got {f.shape}")
        y = np.empty((n, 3))
        if n == 0:
            return y
        bias = np.asarray(self._bias, dtype=float) * np.ones(3)
        _response(
            x,
            t,
            dT,
            f,
            self._gain,
            m.nonlinearity,
            m.bias_temperature,
            m.scale_factor_temperature,
            g_sensitivity,
            bias,
            m.ramp,
            y,
        )

        # Noise: white, flicker and rate random walk, added in place.
        self._noise.add_into(y)

        # Output stage: bandwidth, saturation, quantisation.
        if self._filter is not None:
            b, a = self._filter
            if self._filter_state is None:  # in steady state at the first sample: no start-up transient
                import scipy.signal

                self._filter_state = scipy.signal.lfilter_zi(b, a)[:, None] * y[0]
            _lfilter_into(b, a, self._filter_state, y)
        if m.full_scale is not None:
            np.clip(y, -m.full_scale, m.full_scale, out=y)
        if self._counter_angle is not None:  # set exactly when m.integral_lsb is: the cast only tells mypy so
            lsb = cast(float, m.integral_lsb)
            noise.quantise_angle(y, self.dt, lsb, None, out=y, angle=self._counter_angle)
        if m.output_lsb is not None:
            np.round(y / m.output_lsb, out=y)
            y *= m.output_lsb
        return y


@njit
def _response(
    x: NDArray[np.float64],
    t: NDArray[np.float64],
    dT: NDArray[np.float64],
    f: NDArray[np.float64],
    gain: NDArray[np.float64],
    k: NDArray[np.float64],
    b_T: NDArray[np.float64],
    s_T: NDArray[np.float64],
    G: NDArray[np.float64],
    bias: NDArray[np.float64],
    ramp: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """The deterministic terms, written out per sample k and axis i (shapes as in apply_errors)."""
    for n in range(x.shape[0]):
        for i in range(3):
            out[n, i] = (
                gain[i, 0] * x[n, 0]
                + gain[i, 1] * x[n, 1]
                + gain[i, 2] * x[n, 2]  # (I + S + M) x
                + k[i] * x[n, i] * x[n, i]  # quadratic nonlinearity
                + (b_T[i] + s_T[i] * x[n, i]) * dT[n]  # temperature: bias and scale factor
                + G[i, 0] * f[n, 0]
                + G[i, 1] * f[n, 1]
                + G[i, 2] * f[n, 2]  # g-sensitivity
                + bias[i]
                + ramp[i] * t[n]  # fixed and turn-on bias, rate ramp
            )


@njit
def _lfilter_into(
    b: NDArray[np.float64], a: NDArray[np.float64], z: NDArray[np.float64], y: NDArray[np.float64]
) -> None:
    """``scipy.signal.lfilter(b, a, y, axis=0, zi=z)`` written into ``y`` (n, A), with the final
    state ``zf`` written into ``z`` (order, A); a[0] = 1.

    The same direct form II transposed: out = b₀x + z₀; z_j = b_{j+1}x − a_{j+1}out + z_{j+1}.
    """
    n, n_axes = y.shape
    order = a.shape[0] - 1
    for k in range(n):
        for i in range(n_axes):
            x = y[k, i]
            out = b[0] * x + z[0, i]
            for j in range(order - 1):
                z[j, i] = b[j + 1] * x - a[j + 1] * out + z[j + 1, i]
            z[order - 1, i] = b[order] * x - a[order] * out
            y[k, i] = out
