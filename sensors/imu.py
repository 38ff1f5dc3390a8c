"""The IMU: a gyro triad of any kind, an accelerometer triad and an optional magnetometer.

``Device.measure(trajectory)`` runs, in this order:

1. **Clock.** The device believes it samples every ``T = 1/rate_hz``; its oscillator is off by
   ``rate_error_ppm``, so the true instants are ``τ_k = t₀ + k T (1 + ε)``. It stamps sample ``k``
   with ``t_k = k T + offset_s + jitter`` (white, σ = ``jitter_s``).
2. **Gyro mechanism.** The truth on the mechanism's inner grid (``m`` inner steps per output
   interval, ``m = ceil(inner_rate / rate_hz)``, at most ``BLOCK_INNER_SAMPLES``: a block of a run holds
   that many, so a device whose output is too slow for its mechanism is refused, naming ``rate_hz``)
   goes through :meth:`GyroMechanism.respond` in chunks
   that carry its state (:mod:`gyroemu.sensors.mechanism`), giving the indicated angle; sample ``k`` is its
   increment over ``[τ_{k−1}, τ_k]``, divided by ``T`` for a rate.
3. **Error terms** (:func:`gyroemu.sensors.errors.apply_errors`) on that rate: bias, scale factor,
   misalignment, g-sensitivity, temperature, bias instability, rate random walk, range, quantisation,
   and the part of the white noise the mechanism did not already make, ``sqrt(N_spec² − N_mech²)``.
4. **Accelerometer**: mean specific force over the same intervals at the sensor's lever arm, then its
   error terms. **Magnetometer**: the field sampled at ``τ_k``, then hard and soft iron and noise.

**Latency.** Each sensor has its own ``latency_s`` (``[gyro]``, ``[accelerometer]``,
``[magnetometer]``; default 0, ``|L| < 1 s``): the sample stamped ``t_k`` measures the motion at the
true instant ``τ_k − L``; positive, the sensor lags the truth (a real IMU's gyro lags an optical
reference by about 4 ms, its magnetometer by 9–16 ms). The gyro's sample ``k`` is then the indicated
increment over ``[τ_{k−1} − L_g, τ_k − L_g]``, the accelerometer's the mean force over
``[τ_{k−1} − L_a, τ_k − L_a]``, the magnetometer's the field at ``τ_k − L_m``. The clock, the
temperature and every error process keep running on the device's own instants ``τ_k``; only the
truth is read earlier (or later). ``t_true`` stays ``τ_k``, the instant the sample is taken.

The truth has no motion before its first sample or after its last, so a device with latency drops
the samples that would need it: its samples are the ``k`` (same indices, same stamps ``k T + offset``)
for which every sensor's shifted interval lies in the truth's span, i.e. ``K₁ ≤ k ≤ K₂`` with
``K₁ = 1 + ceil(L_max / T')`` and ``K₂ = floor((t_end − t₀ + L_min) / T')``, where
``L_max = max(0, L_g, L_a, L_m)``, ``L_min = min(0, L_g, L_a, L_m)`` and ``T'`` the true period. The
three sensors always give the same number of samples, at the same stamps; with every latency 0
this is ``1 … K``, the samples without latency, computed by the same code, bit for bit.

Random draws come from independent streams spawned from the device's seed (clock, gyro mechanism,
gyro errors, accelerometer, magnetometer), so adding a magnetometer does not change the gyro's noise.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import tomli_w
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, Field, field_validator

from gyroemu.dynamics import Trajectory
from gyroemu.dynamics.config import (
    NonNegativeReal,
    PositiveReal,
    Quat,
    Real,
    Section,
    Vec3,
    at_least,
    at_most,
    validate,
)
from gyroemu.dynamics.truth_source import SampledTruth, TruthSource
from gyroemu.errors import ConfigError

from .accelerometer import AccelerometerSpec, LatencySeconds
from .device_run import BLOCK_INNER_SAMPLES, DeviceRun, concatenate_samples
from .errors import AccelErrors, ErrorModel, GyroErrors, bandwidth_problem
from .magnetometer import MagnetometerSpec
from .mechanism import GYRO_KINDS, GyroMechanism, mechanism_class
from .samples import ImuSamples

__all__ = [
    "MAX_DEVICE_RATE_HZ",
    "MIN_DEVICE_RATE_HZ",
    "MAX_SENSOR_TEMPERATURE_DEGC",
    "DeviceSpec",
    "Device",
    "MountingSpec",
    "ClockSpec",
    "TemperatureSpec",
    "GyroSpec",
]


class MountingSpec(Section):
    """``[mounting]``: where the sensor sits on the body."""

    q_bs: Quat = (1.0, 0.0, 0.0, 0.0)
    """Unit quaternion (w, x, y, z) turning sensor-frame vectors into body axes."""
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)
    """Sensor origin from the body's reference point, body axes, m."""

    @field_validator("q_bs")
    @classmethod
    def _unit(cls, q: Quat) -> Quat:
        if abs(math.sqrt(sum(x * x for x in q)) - 1.0) > 1e-6:
            raise ValueError(
                f"must be a unit quaternion (w, x, y, z), its norm is {math.sqrt(sum(x * x for x in q)):.6g}"
            )
        return q


class ClockSpec(Section):
    """``[clock]``: the sample clock's errors."""

    rate_error_ppm: Annotated[Real, Field(gt=-1e5, lt=1e5)] = 0.0
    offset_s: Real = 0.0
    jitter_s: NonNegativeReal = 0.0

    def true_period(self, rate_hz: float) -> float:
        """The true sample interval, s, of a clock that believes it samples at ``rate_hz``: T (1 + ε)."""
        return (1.0 / rate_hz) * (1.0 + self.rate_error_ppm * 1e-6)


MAX_SENSOR_TEMPERATURE_DEGC = 1000.0
"""The hottest ``[temperature]`` ``initial_degC`` and ``final_degC``, °C: five times the hottest rating of
real inertial sensors (downhole-drilling parts, about 200 °C), below the 1414 °C at which silicon melts.
The coldest is above absolute zero. A MEMS gyro at 10³⁰⁰ °C gave NaN, at −10³⁰⁰ °C a traceback."""


def _sensor_temperature(value: float) -> float:
    if not value > -273.15:
        raise ValueError(f"{value:g} °C is at or below absolute zero (−273.15 °C)")
    if value > MAX_SENSOR_TEMPERATURE_DEGC:
        raise ValueError(
            f"{value:g} is more than the limit of {MAX_SENSOR_TEMPERATURE_DEGC:g}: five times the hottest rating "
            "of real inertial sensors (about 200 °C)"
        )
    return value


SensorTemperature = Annotated[Real, AfterValidator(_sensor_temperature)]


class TemperatureSpec(Section):
    """``[temperature]``: the sensor's temperature, a first-order warm-up from ``initial`` to ``final``."""

    initial_degC: SensorTemperature = 25.0
    final_degC: SensorTemperature = 25.0
    time_constant_s: PositiveReal = 600.0

    def at(self, t: ArrayLike) -> NDArray[np.float64]:
        """Temperature at times ``t`` (s since power-up), °C."""
        return self.final_degC + (self.initial_degC - self.final_degC) * np.exp(-np.asarray(t) / self.time_constant_s)


class GyroSpec(Section):
    """``[gyro]``: the mechanism (``[gyro.mechanism]``, with its ``kind``), the error terms and the latency."""

    mechanism: dict[Any, Any] = {"kind": "ideal"}  # dict[Any, Any]: pydantic validates it as it did a bare dict
    errors: GyroErrors = GyroErrors()
    latency_s: LatencySeconds = 0.0
    """The sample stamped ``t_k`` measures the motion at the true instant ``τ_k − latency_s``;
    positive: the sensor lags the truth. Left out of the resolved config when 0."""


MAX_DEVICE_RATE_HZ = 1e6
"""The highest ``rate_hz`` of a device, Hz: a hundred times the fastest IMU's output (a few kHz); an
.mcap sample is over a kilobyte, so a device faster than this fills a disk within seconds of motion."""

MIN_DEVICE_RATE_HZ = 0.1
"""The lowest ``rate_hz`` of a device, Hz: a tenth of the slowest outputs of real IMUs (about 1 Hz, a
consumer part's lowest-power data rate, 1.5625 Hz); a sample every 10 s already sums 10 s of motion
into one reading. At 10⁻³⁰⁰ Hz one sample lasted 10³⁰⁰ s: the white noise's per-sample variance
N²/T underflowed and the error named the noise key, or the run held no sample at all."""


class DeviceSpec(Section):
    """A device file (``configs/devices/*.toml``)."""

    description: str
    resembles: str = ""
    rate_hz: Annotated[
        PositiveReal,
        at_most(MAX_DEVICE_RATE_HZ, "a hundred times the fastest IMU's output rate"),
        at_least(MIN_DEVICE_RATE_HZ, "a tenth of the slowest IMU's output rate (about 1 Hz)"),
    ]
    output: Literal["rate", "increment"] = "rate"
    mounting: MountingSpec = MountingSpec()
    clock: ClockSpec = ClockSpec()
    temperature: TemperatureSpec = TemperatureSpec()
    gyro: GyroSpec = GyroSpec()
    accelerometer: AccelerometerSpec = AccelerometerSpec()
    magnetometer: MagnetometerSpec | None = None


def validate_mechanism(data: dict[str, Any], file: str | Path | None = None) -> GyroMechanism:
    """The typed mechanism of a ``[gyro.mechanism]`` table; errors name ``gyro.mechanism.<key>``."""
    kind = data.get("kind")
    if kind is None:
        raise ConfigError("missing required key", file=file, key="gyro.mechanism.kind")
    if not isinstance(kind, str) or kind not in GYRO_KINDS:
        raise ConfigError(
            f"unknown gyro kind {kind!r}; kinds: {', '.join(GYRO_KINDS)}", file=file, key="gyro.mechanism.kind"
        )
    return validate(mechanism_class(kind), data, file=file, prefix="gyro.mechanism")


MAX_INTRINSIC_NOISE_DENSITY = 1e6
"""The largest white noise a gyro mechanism may make, rad/s/√Hz: 10¹¹ times the noisiest real gyros
(consumer MEMS, about 10⁻⁴ rad/s/√Hz), a backstop below where its square leaves float64's range (a FOG
coil of 10⁻³⁰⁰ m made 10²⁹⁴ and an OverflowError); each mechanism's keys keep it far below."""


def _white_noise_budget(
    model: ErrorModel,
    period: float,
    intrinsic: float,
    *,
    keys: GyroErrors | AccelErrors,
    prefix: str,
    what: str,
    file: str | Path | None,
) -> tuple[ErrorModel, NDArray[np.float64]]:
    """Split a specified white-noise density between its sources, so the total at the output is it.

    A datasheet's noise density is measured at the output: it holds the mechanism's own noise
    ``N_mech`` and, for a digital output of step ``LSB`` dithered by the noise, the quantiser's white
    noise of variance ``LSB²/12`` per sample, i.e. density² ``LSB² T / 12``. The error layer adds the
    rest, ``N_add² = N_spec² − N_mech² − LSB² T / 12``; a negative rest cannot work, and neither does a
    quantiser the noise does not dither (:func:`_check_dithered`, :data:`DITHER_MIN_SIGMA_LSB`).

    ``keys``: the config the model came from, where the white noise is specified (or not) by one of
    its white-noise keys (``GyroErrors.white_noise_keys``); errors name it under ``prefix``.

    Returns the model with ``noise_density = N_add`` and the total density at the output (3,).
    """
    quantiser = (model.output_lsb**2 * period / 12.0) if model.output_lsb else 0.0
    given = keys.white_noise_key()
    if given is None:
        total = np.full(3, np.sqrt(intrinsic**2 + quantiser))
        return dataclasses.replace(model, noise_density=np.zeros(3)), total
    specified = np.asarray(model.noise_density, dtype=float)
    with np.errstate(over="ignore"):
        per_sample = specified**2 / period  # the white noise's variance per sample, (SI unit)²
    if not np.all(np.isfinite(per_sample)):
        raise ConfigError(
            f"a white noise of {specified.max():.4g} per sqrt(s) (SI) at rate_hz = {1.0 / period:g} has a per-sample "
            "variance beyond float64's range: the output would be inf or NaN (no sensor is that noisy)",
            file=file,
            key=f"{prefix}.{given}",
        )
    rest = specified**2 - intrinsic**2 - quantiser
    if np.any(rest < -1e-12 * specified**2):
        parts = []
        if intrinsic:
            parts.append(f"{what} ({intrinsic:.4g} per sqrt(s))")
        if quantiser:
            parts.append(f"the output quantiser at this rate ({np.sqrt(quantiser):.4g} per sqrt(s))")
        verb = "exceeds" if len(parts) == 1 else "exceed"
        raise ConfigError(
            f"{' and '.join(parts)} {verb} the specified white noise {specified.max():.4g} "
            "per sqrt(s) (SI): lower them or raise the specification",
            file=file,
            key=f"{prefix}.{given}",
        )
    _check_dithered(model, period, specified, keys=keys, prefix=prefix, given=given, file=file)
    return dataclasses.replace(model, noise_density=np.sqrt(np.maximum(rest, 0.0))), specified


DITHER_MIN_SIGMA_LSB = 0.5
"""The least white-noise σ ahead of an output quantiser, in LSB, for the budget's ``LSB²/12`` to hold.

For Gaussian noise of σ and mean μ ahead of a rounding quantiser of step ``q``, the error
``e = Q(x) − x`` has the Fourier series ``e = Σ_k (q/πk)(−1)^k sin(2πkx/q)``, and
``E sin(2πkx/q) = sin(2πkμ/q) exp(−2π²k²σ²/q²)`` (Widrow & Kollár, *Quantization Noise*, 2008: the
characteristic-function condition). To first order in ``ε = exp(−2π²σ²/q²)`` the output's variance is
``Var Q(x) = σ² + q²/12 − ε cos(2πμ/q) (4σ² + q²/π²)``: the ``4σ²`` from ``2 Cov(x, e)``, the
``q²/π²`` from ``E e²``. The sample-to-sample noise is white, so ADEV(1 s)² = ``T · Var Q(x)``, off
the budget's ``T (σ² + q²/12)`` by up to ``ε (4σ² + q²/π²) / (2 (σ² + q²/12))`` in ratio as the bias
moves within an LSB. At σ = q/2 that is 1.19 % (exactly, summing every level: 0.9880 … 1.0118);
at 0.47 q it is 2.1 %, at 0.36 q (``consumer_mems`` at 100 Hz) 12 %. A configuration below
σ = q/2 cannot promise its specified density whatever the bias, and is refused."""


def _check_dithered(
    model: ErrorModel,
    period: float,
    specified: NDArray[np.float64],
    *,
    keys: GyroErrors | AccelErrors,
    prefix: str,
    given: str,
    file: str | Path | None,
) -> None:
    """Refuse an output quantiser the white noise ahead of it does not dither (:data:`DITHER_MIN_SIGMA_LSB`).

    The white noise ahead of the quantiser is the specification less the quantiser's share:
    ``σ² = N_spec²/T − LSB²/12`` per sample, times the noise-power gain of the output low-pass when
    ``bandwidth_hz`` is set. Coloured terms (bias instability, random walks) are not counted: over
    a second they move the bias within an LSB rather than dither it.
    """
    lsb = model.output_lsb
    if not lsb:
        return
    sigma2 = np.asarray(specified, dtype=float) ** 2 / period - lsb**2 / 12.0
    if model.bandwidth_hz is not None and model.bandwidth_hz < 0.5 / period:
        sigma2 = sigma2 * _low_pass_noise_gain(period, model.bandwidth_hz, model.filter_order)
    ratio = float(np.sqrt(max(float(np.min(sigma2)), 0.0)) / lsb)
    if ratio >= DITHER_MIN_SIGMA_LSB:
        return
    quantum = "quantisation_rad_per_s" if isinstance(keys, GyroErrors) else "quantisation_m_per_s2"
    rate_hz = 1.0 / period
    filtered = f" after the {prefix}.bandwidth_hz low-pass" if model.bandwidth_hz is not None else ""
    raise ConfigError(
        f"the white noise ahead of the output quantiser ({prefix}.{quantum}) is {ratio:.3g} LSB per sample "
        f"at rate_hz = {rate_hz:g} with {prefix}.{given}{filtered}, below the {DITHER_MIN_SIGMA_LSB:g} LSB "
        "needed for the quantiser to add white noise of LSB²/12 whatever the bias: the output's ADEV(1 s) "
        "would depend on where the bias sits within an LSB and miss the specified density. Lower "
        f"{prefix}.{quantum}, raise rate_hz or raise {prefix}.{given}",
        file=file,
        key=f"{prefix}.{quantum}",
    )


def _low_pass_noise_gain(period: float, bandwidth_hz: float, order: int) -> float:
    """Variance out over variance in of the output low-pass (:class:`gyroemu.sensors.errors.SensorErrors`) for
    white noise: ``C P Cᵀ + D²`` with ``P`` the steady state covariance of its state-space form."""
    import scipy.linalg
    import scipy.signal

    b, a = scipy.signal.butter(order, bandwidth_hz, btype="low", fs=1.0 / period)
    A, B, C, D = scipy.signal.tf2ss(b, a)
    P = scipy.linalg.solve_discrete_lyapunov(A, B @ B.T)
    return float((C @ P @ C.T)[0, 0] + D[0, 0] ** 2)


class Device:
    """An emulated IMU, ready to measure trajectories.

    Parameters
    ----------
    spec : DeviceSpec
    name : str
    seed : int
        Seed of every random draw the device makes.
    path : Path, optional
        The file the spec was read from (named in errors).
    """

    def __init__(self, spec: DeviceSpec, name: str = "imu0", seed: int = 0, path: Path | None = None) -> None:
        self.spec = spec
        self.name = name
        self.seed = int(seed)
        self.path = path
        where = path if path is not None else name
        self.mechanism = validate_mechanism(spec.gyro.mechanism, file=where)
        self.inner_rate_hz = float(self.mechanism.inner_rate_hz(spec.rate_hz))
        if self.inner_rate_hz < spec.rate_hz:
            raise ConfigError(
                f"the output rate {spec.rate_hz:g} Hz is above the gyro mechanism's inner rate "
                f"{self.inner_rate_hz:g} Hz",
                file=where,
                key="rate_hz",
            )
        steps = math.ceil(self.inner_rate_hz / spec.rate_hz - 1e-9)  # DeviceRun's inner steps a sample
        if steps > BLOCK_INNER_SAMPLES:  # one sample's inner grid would be more than a block holds
            raise ConfigError(
                f"at {spec.rate_hz:g} Hz each sample needs {steps} steps of the gyro mechanism's inner grid "
                f"({self.inner_rate_hz:g} Hz), more than the limit of {BLOCK_INNER_SAMPLES}: a block of the run "
                "holds at most that many (its memory); raise the output rate",
                file=where,
                key="rate_hz",
            )
        self._gyro_errors = spec.gyro.errors.to_si()
        limit = self.mechanism.max_rate()
        if self._gyro_errors.full_scale is not None and self._gyro_errors.full_scale > limit * (1 + 1e-12):
            raise ConfigError(
                f"a range of {np.degrees(self._gyro_errors.full_scale):g} deg/s is beyond what the "
                f"{self.mechanism.kind} mechanism can indicate, {np.degrees(limit):.4g} deg/s",
                file=where,
                key="gyro.errors.range_deg_per_s",
            )
        accel_errors = spec.accelerometer.errors.to_si()
        true_period = spec.clock.true_period(spec.rate_hz)  # the error layers' sample interval (DeviceRun)
        # The output low-passes before the noise budget, which takes their noise gain.
        for model, prefix in ((self._gyro_errors, "gyro.errors"), (accel_errors, "accelerometer.errors")):
            problem = (
                None
                if model.bandwidth_hz is None
                else bandwidth_problem(model.bandwidth_hz, spec.rate_hz, "the output rate")
            )
            if problem is not None:
                raise ConfigError(problem, file=where, key=f"{prefix}.bandwidth_hz")
            tau_max = model.bias_instability_tau_range[1]
            if np.any(model.bias_instability) and not tau_max > true_period:
                # the flicker bank is fitted on [max(τ_min, T), τ_max] (noise.flicker_bank): empty here
                raise ConfigError(
                    f"the bias instability's range ends at {tau_max:g} s, not above the sample interval "
                    f"{true_period:g} s: a floor flat only at shorter averaging times never shows in the samples",
                    file=where,
                    key=f"{prefix}.bias_instability_tau_range_s",
                )
        self.intrinsic_noise_density = float(self.mechanism.intrinsic_noise_density())
        if not self.intrinsic_noise_density < MAX_INTRINSIC_NOISE_DENSITY:
            # a backstop: each mechanism's keys are bounded so that their noise stays far below this
            raise ConfigError(
                f"the {self.mechanism.kind} mechanism's own white noise would be {self.intrinsic_noise_density:.4g} "
                f"rad/s per sqrt(Hz), more than the limit of {MAX_INTRINSIC_NOISE_DENSITY:g}: its keys are far "
                "outside any real gyro's",
                file=where,
                key="gyro.mechanism",
            )
        period = 1.0 / spec.rate_hz
        self._gyro_errors, self._gyro_noise_density = _white_noise_budget(
            self._gyro_errors,
            period,
            self.intrinsic_noise_density,
            keys=spec.gyro.errors,
            prefix="gyro.errors",
            what=f"the {self.mechanism.kind} mechanism's own white noise",
            file=where,
        )
        self._accel_errors, _ = _white_noise_budget(
            accel_errors,
            period,
            0.0,
            keys=spec.accelerometer.errors,
            prefix="accelerometer.errors",
            what="nothing",
            file=where,
        )
        if spec.clock.jitter_s >= 0.25 / spec.rate_hz:
            raise ConfigError(
                f"jitter {spec.clock.jitter_s:g} s is not small against the sample interval {1 / spec.rate_hz:g} s",
                file=where,
                key="clock.jitter_s",
            )

    @property
    def gyro_noise_density(self) -> NDArray[np.float64]:
        """Total white rate noise of each gyro axis at the output, rad/s/√Hz: the specified ARW when
        one is given; otherwise the mechanism's own and the output quantiser's."""
        return self._gyro_noise_density

    @property
    def gyro_errors(self) -> ErrorModel:
        """The gyro error terms in SI (:class:`gyroemu.sensors.errors.ErrorModel`), white noise as added on
        top of the mechanism's own."""
        return self._gyro_errors

    @property
    def accel_errors(self) -> ErrorModel:
        """The accelerometer's error terms in SI (:class:`gyroemu.sensors.errors.ErrorModel`), white
        noise as specified less the output quantiser's share."""
        return self._accel_errors

    @property
    def latencies(self) -> tuple[float, float, float]:
        """``(L_gyro, L_accel, L_mag)``, s: each sensor's sample stamped ``t_k`` measures the motion at
        ``τ_k − L``; positive, the sensor lags the truth. ``L_mag`` is 0 without a magnetometer."""
        mag = self.spec.magnetometer
        return (
            float(self.spec.gyro.latency_s),
            float(self.spec.accelerometer.latency_s),
            0.0 if mag is None else float(mag.latency_s),
        )

    @property
    def kind(self) -> str:
        """The gyro mechanism's kind."""
        return self.mechanism.kind

    def to_toml(self) -> str:
        """The fully resolved device config (defaults filled in, mechanism included) as TOML text."""
        data = self.spec.model_dump(mode="json", exclude_none=True)
        data["gyro"]["mechanism"] = self.mechanism.model_dump(mode="json", exclude_none=True)
        return tomli_w.dumps(data)

    def __repr__(self) -> str:
        return f"Device({self.name!r}, kind={self.kind!r}, rate_hz={self.spec.rate_hz:g}, seed={self.seed})"

    # ------------------------------------------------------------------------------------------------

    def measure_held_still(self, trajectory: Trajectory) -> ImuSamples:
        """:meth:`measure` of ``trajectory`` with its rotation taken away (the same draws, attitude and
        specific force): the gyro then reads its bias alone (turn-on bias, drift, temperature and
        g-sensitivity, its mechanism's rest bias) and noise; scale factor and misalignment, which act on
        the rate, drop out. The truth a filter's bias estimate is judged against."""
        z = np.zeros_like(trajectory.omega_b)
        return self.measure(dataclasses.replace(trajectory, omega_b=z, alpha_b=z))

    def measure(self, trajectory: Trajectory) -> ImuSamples:
        """Emulate the device over ``trajectory``: one output sample per interval ``[τ_{k−1}, τ_k]``.

        Returns an :class:`ImuSamples` with ``floor(duration · rate_hz / (1 + ε))`` samples when no
        sensor has a latency; with latencies, the samples ``K₁ … K₂`` whose shifted intervals lie in
        the trajectory's span (module notes), the same for the three sensors. The run is made a block
        at a time (:class:`gyroemu.sensors.device_run.DeviceRun`), the same bytes as :meth:`run` gives.
        """
        return concatenate_samples(list(self.run(SampledTruth(trajectory)).samples()))

    def run(self, source: TruthSource) -> DeviceRun:
        """The device measuring the truth of ``source`` from power-up, as an iterator of blocks that
        carry every state (:class:`gyroemu.sensors.device_run.DeviceRun`): a run in bounded memory, or
        without end when ``source.t_end`` is None."""
        return DeviceRun(self, source)
