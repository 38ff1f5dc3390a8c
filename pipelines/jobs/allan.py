"""``gyroemu allan``: fit the IEEE 952 noise terms to a static gyro log and draw the Allan plot.

:func:`allan_of_log` reads the log (an .mcap, or an .npz of ``gyroemu simulate``) and fits it;
:func:`write_allan_plot` draws the plot.

The fit is :func:`gyroemu.sensors.allan.fit_allan` over the overlapping Allan deviation, axis by axis.
:func:`allan_of_log` computes that deviation with
:class:`gyroemu.sensors.allan_stream.OverlappingAllanAccumulator`, fed the log a batch of samples at a
time, so the memory it needs does not grow with the log's length (a 12-hour run at hundreds of Hz);
:func:`allan_report` takes a record already in memory (``allan_deviation``).
The two agree to round-off for τ up to the accumulator's exact range (2^15 samples); beyond it the
streamed one is the overlapping estimator with a coarser overlap step (see that module).

The plot shows each axis's measured curve with its confidence band, the fitted model, and, when the
log carries its device's config, the specification's lines (quantisation, ARW, bias instability
floor, RRW) beside them; the accelerometer, analysed the same way, in a second panel.

The τ⁻² term is fitted with either sign (``fit_allan(..., band_limit=True)``, :func:`allan_fits`): white
noise low-passed before it is sampled (a MEMS gyro's demodulator, an anti-alias filter) loses
(3/2)N²⟨|s|⟩/τ² of Allan variance at short τ, the quantisation column with the opposite sign, and a fit
holding that term ≥ 0 read N low to make up for it (1.1 % on ``consumer_mems``, eight times the
half-width of its 68 % interval over 300 s; the module notes of :mod:`gyroemu.sensors.allan`). The curve
shows only the sum of a quantiser's 3Q² and a low-pass's sag: a positive τ⁻² term is reported as the
quantisation Q (a quantiser less any low-pass: Q² − (1/2)N²⟨|s|⟩), a negative one as the band limit, given
as the time constant T of the first-order low-pass over all of the white noise that would take it off,
band_limit = (3/2)N²T (as ``gyroemu identify`` gives it), with the quantisation not found and no upper
limit (a quantiser can hide behind the sag). The τ⁻² term of either sign is resolved when it exceeds
its detection limit, the larger of the one-point one below and two standard deviations of its
coefficient from the fit's covariance (it trades with N over the short octaves, which one point does
not see: with the one-point test alone it was resolved on 58 of 150 axes of a simulated
``navigation_fog`` gyro, which has neither a quantiser nor a low-pass; now 13).

The fit starts at the first τ where the low-pass it finds has forgotten its input
(:func:`gyroemu.sensors.allan.fit_band_limited`): behind a heavy low-pass (a first-order one at a tenth of
the sample rate read N 26 % low over every octave) the shortest τ, within the filter's memory, are left
out, and the row ``fitted from τ`` (``--json``: ``fitted_from``, s) gives where each axis's fit starts;
the plot draws the model from there.

Each term is printed with its 68 % interval, or as ``not resolved (< bound)`` when the data do not
resolve it (:attr:`gyroemu.sensors.allan.Coefficient.resolved`: its share of the Allan variance never
exceeds two standard deviations of the estimate). The bound (:attr:`~gyroemu.sensors.allan.Coefficient.upper_limit`,
also what ``--kalibr`` writes) is the larger of the detection limit and min_τ σ_hi(τ)/√A(τ), σ_hi each
point's one-sided 95 % chi-squared upper limit and A the term's Allan variance per unit coefficient²:
the limit alone is no bound, a term just above it being often missed.

Before fitting, :func:`allan_of_log` checks that the log is static (:class:`StaticCheck`, figures
accumulated batch by batch as the log streams): the accelerometer's specific force must keep its
magnitude and direction, and, when the log has ``/truth/imu`` (or ``truth/...`` arrays), the true rate
and attitude must keep still. A log in motion raises :class:`AllanMotionError` unless
``allow_motion``. :func:`kalibr_imu_yaml` gives the fit as Kalibr's (and OpenVINS's) ``imu.yaml``.

:func:`check_options` refuses, before any work, the command's bad options (:class:`AllanError`): an
output that is the log itself, a folder, in a folder that cannot take it, or that exists without ``force``
(the plot's only when one is drawn: ``--no-plot`` draws none).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gyroemu.errors import ConfigError, LogError
from gyroemu.pipelines.formats.atomic import output_file_problem, write_atomic, write_text_atomic
from gyroemu.pipelines.formats.device_stream import not_increasing_since
from gyroemu.pipelines.formats.file_names import same_file
from gyroemu.pipelines.formats.mcap_records import folder_not_mcap
from gyroemu.sensors.allan import (
    TERMS,
    AllanDeviation,
    AllanFit,
    Coefficient,
    allan_deviation,
    fit_band_limited,
    smoothing_time_constant,
)
from gyroemu.sensors.allan_stream import OverlappingAllanAccumulator
from gyroemu.sensors.errors import STANDARD_GRAVITY, ErrorModel

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "AllanError",
    "AllanLogError",
    "AllanMotionError",
    "MotionWarning",
    "AllanReport",
    "MotionFigure",
    "StaticCheck",
    "allan_report",
    "allan_of_log",
    "allan_fits",
    "BandLimit",
    "band_limit_of",
    "fitted_from",
    "check_options",
    "default_plot_path",
    "BATCH",
    "plot_allan",
    "plot_format",
    "write_allan_plot",
    "kalibr_imu_yaml",
    "write_kalibr_yaml",
    "SPEC_UNITS",
    "ACCEL_SPEC_UNITS",
    "TERM_LABELS",
    "TOLERANCE_MAGNITUDE",
    "TOLERANCE_DIRECTION",
]

_DEG = 180.0 / np.pi
SPEC_UNITS = {  # term: (SI to datasheet factor, datasheet unit)
    "quantisation": (1.0, "rad"),
    "arw": (_DEG * 60.0, "deg/sqrt(h)"),
    "bias_instability": (_DEG * 3600.0, "deg/h"),
    "rrw": (_DEG * 3600.0 * 60.0, "deg/h/sqrt(h)"),
    "rate_ramp": (_DEG * 3600.0 * 3600.0, "deg/h/h"),
}
_UG = 1e-6 * STANDARD_GRAVITY  # m/s² per µg
ACCEL_SPEC_UNITS = {  # term: (SI to datasheet factor, datasheet unit), as AccelErrors names its keys
    "quantisation": (1.0, "m/s"),
    "arw": (60.0, "m/s/sqrt(h)"),  # velocity random walk
    "bias_instability": (1.0 / _UG, "ug"),
    "rrw": (60.0 / _UG, "ug/sqrt(h)"),  # the accelerometer's bias random walk
    "rate_ramp": (3600.0 / _UG, "ug/h"),
}
TERM_LABELS = {  # sensor: term: label in the tables
    "gyro": {t: t for t in TERMS},
    "accel": {
        "quantisation": "quantisation",
        "arw": "vrw",
        "bias_instability": "bias_instability",
        "rrw": "random_walk",
        "rate_ramp": "rate_ramp",
    },
}


def _cell(c: Coefficient, factor: float) -> str:
    """``0.0123 (0.011–0.0137)``, or ``not resolved (< 0.004)``, in the datasheet unit."""
    if not c.resolved:
        return f"not resolved (< {c.upper_limit * factor:.3g})"
    return f"{c.value * factor:.3g} ({c.low * factor:.3g}–{c.high * factor:.3g})"


@dataclass(frozen=True)
class BandLimit:
    """The band limit of one axis's fit (:func:`band_limit_of`): the Allan variance ``coefficient``/τ² a
    low-pass took off the white noise at short τ (unit²·s²; 0 when the τ⁻² term came out ≥ 0), as the
    time constant T of the first-order low-pass over all of the white noise that would take it off,
    coefficient = (3/2)N²T (s), and T's detection limit (s): the quantisation's with the opposite sign,
    the T whose sag would make two standard deviations of the Allan variance estimate where it shows
    most, or two standard deviations of the τ⁻² coefficient from the fit's covariance, the larger
    (:func:`gyroemu.sensors.allan.fit_allan`)."""

    coefficient: float
    time_constant: float
    limit: float

    @property
    def found(self) -> bool:
        """Whether the τ⁻² term came out negative (the quantisation is then not found)."""
        return self.coefficient > 0

    @property
    def resolved(self) -> bool:
        """Whether the data resolve the band limit: T exceeds its detection limit."""
        return self.found and self.time_constant > self.limit

    @property
    def upper_limit(self) -> float:
        """The bound to report for a band limit not resolved (as :attr:`Coefficient.upper_limit`): the
        detection limit, or T when larger."""
        return max(self.limit, self.time_constant)

    def cell(self) -> str:
        """``0.0229`` (T in ms), ``not resolved (< 0.004)`` or ``none`` (the τ⁻² term ≥ 0)."""
        if not self.found:
            return "none"
        if not self.resolved:
            return f"not resolved (< {self.limit * 1e3:.3g})"
        return f"{self.time_constant * 1e3:.3g}"


def band_limit_of(fit: AllanFit) -> BandLimit:
    """The band limit of ``fit`` (:class:`BandLimit`): T = 2·band_limit/(3N²), and its detection limit
    2·limit_Q²/N² from the quantisation's (limit_Q² is the smallest |c| of the τ⁻² column 3c/τ² the data
    resolve, and band_limit = −3c). Without white noise (N = 0: nothing to smooth) T is 0 and its limit
    infinite, as it is when the τ⁻² term cannot be parted from the others (an infinite limit): never
    resolved."""
    n2 = fit.arw.value**2
    limit = fit.quantisation.limit
    if not n2 > 0:
        return BandLimit(fit.band_limit, 0.0, math.inf)
    time_constant = smoothing_time_constant(fit.band_limit, fit.arw.value)
    return BandLimit(fit.band_limit, time_constant, 2.0 * limit * limit / n2)


def _quantisation_cell(fit: AllanFit, factor: float) -> str:
    """The quantisation's cell: ``not found (band limit)`` when a band limit is resolved, else :func:`_cell`."""
    if band_limit_of(fit).resolved:
        return "not found (band limit)"
    return _cell(fit.quantisation, factor)


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True)
class MotionFigure:
    """One figure of the static check: how far something moved, and the most a static log shows.

    Attributes
    ----------
    name : ``accel_magnitude``, ``accel_direction``, ``truth_rate`` or ``truth_attitude``.
    what : the words before the figure, e.g. "the accelerometer's direction moves by".
    value, limit : the figure and its static limit, in ``unit``.
    unit : "m/s^2", "deg" or "deg/s".
    """

    name: str
    what: str
    value: float
    limit: float
    unit: str

    @property
    def static(self) -> bool:
        """Whether the figure is within its limit."""
        return bool(self.value < self.limit)

    def describe(self) -> str:
        """e.g. "the accelerometer's direction moves by 12.3 deg (static: < 0.5 deg)"."""
        return f"{self.what} {self.value:.3g} {self.unit} (static: < {self.limit:.3g} {self.unit})"


@dataclass(frozen=True)
class StaticCheck:
    """The figures of :func:`allan_of_log`'s static check, and what it could not check (``notes``).

    Accelerometer (always, when it has finite samples). The specific force is averaged over K blocks
    (1024 ≤ K < 2048 blocks of 2^j samples, kept as the log streams). A static sensor's block means
    differ only by noise, of standard deviation σ_b per axis; σ_b is read off the data as the Allan
    deviation at the block length, from the median of the squared steps between neighbouring block
    means (|Δ|²/(2σ_b²) is chi-squared with 3 degrees of freedom; the median ignores the few steps a
    jolt makes). The figures are the largest departure of a block's |f| from the blocks' median |f|
    (m/s²), and the largest angle between a block's f and the run's mean f (deg). Their limits: the
    largest of K draws of noise, k·σ_b with k = √(2 ln(K/10⁻⁶)) (each of |normal| and Rayleigh exceeds
    kσ with probability ≤ e^(−k²/2), so white noise alone refuses a static log with probability under
    10⁻⁶), plus a tolerance for what drifts in a static sensor beyond white noise (bias instability,
    random walk, temperature): :data:`TOLERANCE_MAGNITUDE` (0.02 m/s²) for |f| and
    :data:`TOLERANCE_DIRECTION` (0.1°) plus the noise angle k·σ_b/|f̄| for the direction. The direction
    is not checked when |f̄| < 1 m/s² (no gravity to point along).

    Truth (when the log has ``/truth/imu``, or an .npz ``truth/omega_b`` and ``truth/q_wb``): exact, so
    no noise allowance. The rate figure is max |ω_true − mean| per axis (deg/s). A motion whose rate
    stays within a of its mean adds at most √2·a to σ(τ) at any τ (a difference of two cluster means is
    at most 2a), so its limit is 0.2·σ_min, σ_min the gyro's lowest measured Allan deviation: the
    motion adds at most 8 % of σ_min² to the variance where it is smallest. The attitude figure is the
    largest rotation from the first attitude (deg); a turn by θ moves the Earth rate the gyro reads by up
    to Ω_E·θ, so its limit is the rate limit / Ω_E, at most the 0.1° tolerance.
    """

    figures: tuple[MotionFigure, ...]
    notes: tuple[str, ...] = ()

    @property
    def static(self) -> bool:
        """Whether every figure is within its limit."""
        return all(f.static for f in self.figures)

    def moving(self) -> str:
        """The figures beyond their limits, described and joined by "; " ("" when static)."""
        return "; ".join(f.describe() for f in self.figures if not f.static)

    def to_dict(self) -> dict[str, Any]:
        """The figures as plain data (JSON)."""
        return {
            "static": self.static,
            "figures": {
                f.name: {"value": _finite(f.value), "limit": _finite(f.limit), "unit": f.unit, "static": f.static}
                for f in self.figures
            },
            "notes": list(self.notes),
        }


@dataclass(frozen=True)
class AllanReport:
    """Fits of the three axes of a log's gyro (and accelerometer), and the specifications they are
    compared with.

    Attributes
    ----------
    fits : the gyro's three axes (SI: rad, rad/√s, rad/s, rad/s/√s, rad/s²).
    spec : the device's gyro error terms, when the log carries its config.
    accel_fits : the accelerometer's three axes (SI: m/s, m/s/√s, m/s², m/s²/√s, m/s³), or None
        when the log has no usable accelerometer samples.
    accel_spec : the device's accelerometer error terms, as specified.
    static : the static check's figures (None: not checked, :func:`allan_report`).
    rate_hz : the sample rate, 1/Δt (NaN: not known).
    topic : the device's IMU topic ("" for an .npz).
    """

    fits: tuple[AllanFit, AllanFit, AllanFit]
    spec: ErrorModel | None
    intrinsic_noise_density: float = 0.0
    accel_fits: tuple[AllanFit, AllanFit, AllanFit] | None = None
    accel_spec: ErrorModel | None = None
    static: StaticCheck | None = None
    rate_hz: float = math.nan
    topic: str = ""

    def table(self, sensor: str = "gyro") -> str:
        """A plain-text table of ``sensor`` ("gyro" or "accel"; "" when there is no accelerometer fit):
        each term per axis in datasheet units, ``value (low–high)`` with its 68 % interval or
        ``not resolved (< limit)``, and the specification."""
        fits, spec, units = self._sensor(sensor)
        if fits is None:
            return ""
        labels = TERM_LABELS[sensor]
        lines = [f"{sensor + ' term':<17}{'unit':<14}{'x':>30}{'y':>30}{'z':>30}{'spec':>12}"]
        specified = _spec_terms(spec) if spec is not None else {}
        for term, (factor, unit) in units.items():
            if term == "quantisation":
                cells = "".join(f"{_quantisation_cell(f, factor):>30}" for f in fits)
            else:
                cells = "".join(f"{_cell(getattr(f, term), factor):>30}" for f in fits)
            value = specified.get(term)
            spec_text = f"{value * factor:12.4g}" if value is not None else f"{'-':>12}"
            lines.append(f"{labels[term]:<17}{unit:<14}{cells}{spec_text}")
            if term == "quantisation":
                cells = "".join(f"{band_limit_of(f).cell():>30}" for f in fits)
                lines.append(f"{'band_limit T':<17}{'ms':<14}{cells}{'-':>12}")
        cells = "".join(f"{fitted_from(f) * 1e3:>30.3g}" for f in fits)
        lines.append(f"{'fitted from τ':<17}{'ms':<14}{cells}{'-':>12}")
        return "\n".join(lines)

    def tables(self) -> str:
        """The gyro's table, and the accelerometer's below it when there is one."""
        return "\n\n".join(t for t in (self.table("gyro"), self.table("accel")) if t)

    def _sensor(
        self, sensor: str
    ) -> tuple[tuple[AllanFit, AllanFit, AllanFit] | None, ErrorModel | None, dict[str, tuple[float, str]]]:
        if sensor == "gyro":
            return self.fits, self.spec, SPEC_UNITS
        if sensor == "accel":
            return self.accel_fits, self.accel_spec, ACCEL_SPEC_UNITS
        raise ValueError(f"sensor must be 'gyro' or 'accel', got {sensor!r}")

    def to_dict(self) -> dict[str, Any]:
        """The report as plain data (``gyroemu allan --json``): per sensor and term, its unit, each
        axis's value, low, high (68 %), resolved and upper_limit in that unit (null: infinite or not
        given; the quantisation's high and upper_limit are null when a band limit is resolved: a quantiser
        may hide behind it), and the spec; per sensor the band limit (``band_limit``: each axis's time
        constant T as ``value``, s, 0 when the τ⁻² term came out ≥ 0, with ``resolved``, ``upper_limit``
        (:attr:`BandLimit.upper_limit`) and ``coefficient``, the Allan variance coefficient/τ² taken off,
        in the sensor's SI unit²·s², :class:`BandLimit`); the static check's figures; the sample rate."""
        out: dict[str, Any] = {"rate_hz": _finite(self.rate_hz), "topic": self.topic}
        for sensor in ("gyro", "accel"):
            fits, spec, units = self._sensor(sensor)
            if fits is None:
                out[sensor] = None
                continue
            specified = _spec_terms(spec) if spec is not None else {}
            terms = {}
            for term, (factor, unit) in units.items():
                entry: dict[str, Any] = {"label": TERM_LABELS[sensor][term], "unit": unit}
                for axis, fit in zip("xyz", fits):
                    c = getattr(fit, term)
                    hidden = term == "quantisation" and band_limit_of(fit).resolved  # no bound: module notes
                    entry[axis] = {
                        "value": _finite(c.value * factor),
                        "low": _finite(c.low * factor),
                        "high": None if hidden else _finite(c.high * factor),
                        "resolved": c.resolved,
                        "upper_limit": None if hidden else _finite(c.upper_limit * factor),
                    }
                value = specified.get(term)
                entry["spec"] = None if value is None else _finite(value * factor)
                terms[term] = entry
            band: dict[str, Any] = {"label": "band_limit", "unit": "s"}
            for axis, fit in zip("xyz", fits):
                b = band_limit_of(fit)
                band[axis] = {
                    "value": _finite(b.time_constant),
                    "resolved": b.resolved,
                    "upper_limit": _finite(b.upper_limit),
                    "coefficient": _finite(b.coefficient),
                }
            band["spec"] = None
            terms["band_limit"] = band
            start: dict[str, Any] = {"label": "fitted from τ", "unit": "s"}
            for axis, fit in zip("xyz", fits):
                start[axis] = {"value": _finite(fitted_from(fit))}
            start["spec"] = None
            terms["fitted_from"] = start
            out[sensor] = terms
        out["static_check"] = None if self.static is None else self.static.to_dict()
        return out

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text."""
        return json.dumps(self.to_dict(), indent=2)


def _spec_terms(spec: ErrorModel) -> dict[str, Any]:
    """The specification's Allan coefficients in SI (axis x; presets give the same for all axes)."""
    q = spec.integral_lsb / np.sqrt(12) if spec.integral_lsb else None
    return {
        "quantisation": q,
        "arw": float(spec.noise_density[0]),
        "bias_instability": float(spec.bias_instability[0]),
        "rrw": float(spec.random_walk[0]),
        "rate_ramp": float(spec.ramp[0]) or None,
    }


def allan_fits(deviations: Sequence[AllanDeviation]) -> tuple[AllanFit, AllanFit, AllanFit]:
    """The fit of each of three axes' Allan deviations, as ``gyroemu allan`` fits them: every IEEE 952
    term, the τ⁻² one of either sign (quantisation when positive, a band limit when negative), from the
    first τ where the low-pass the fit finds has forgotten its input (:func:`fit_band_limited`; module
    notes)."""
    if len(deviations) != 3:
        raise ValueError(f"three axes' Allan deviations are needed, got {len(deviations)}")
    x, y, z = (fit_band_limited(d) for d in deviations)
    return x, y, z


def fitted_from(fit: AllanFit) -> float:
    """The shortest τ (s) of ``fit``'s curve that the fit used (shorter ones lie within a low-pass's
    memory: :func:`gyroemu.sensors.allan.fit_band_limited`)."""
    return float(fit.allan.tau[fit.skipped])


def allan_report(
    gyro: np.ndarray,
    dt: float,
    spec: ErrorModel | None = None,
    accel: np.ndarray | None = None,
    accel_spec: ErrorModel | None = None,
) -> AllanReport:
    """Fit each axis of a static gyro record ``gyro`` (N, 3), rad/s, sampled every ``dt`` s, and of
    the accelerometer's ``accel`` (N, 3), m/s², when given (no static check: the record is trusted)."""
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < 64:
        raise ValueError(f"an Allan analysis needs a (N, 3) gyro record with N >= 64, got shape {gyro.shape}")
    if not np.all(np.isfinite(gyro)):
        raise ValueError("the gyro record has NaN or infinite samples")
    fits = allan_fits([allan_deviation(gyro[:, i] - gyro[:, i].mean(), dt) for i in range(3)])
    accel_fits = None
    if accel is not None:
        accel = np.asarray(accel, dtype=float)
        if accel.shape != gyro.shape:
            raise ValueError(f"the accelerometer record's shape {accel.shape} is not the gyro's {gyro.shape}")
        if np.all(np.isfinite(accel)) and np.all(np.ptp(accel, axis=0) > 0):
            accel_fits = allan_fits([allan_deviation(accel[:, i] - accel[:, i].mean(), dt) for i in range(3)])
    return AllanReport(fits=fits, spec=spec, accel_fits=accel_fits, accel_spec=accel_spec, rate_hz=1.0 / dt)


class AllanError(ConfigError):
    """Bad options of ``gyroemu allan``, found before any work (the message names the argument)."""


def default_plot_path(log: str | os.PathLike[str]) -> Path:
    """The plot's path without ``--out``: the log's, with ``.allan.png`` for its suffix."""
    return Path(log).with_suffix(".allan.png")


def _check_output(path: Path, argument: str, log: Path, force: bool) -> None:
    """:class:`AllanError` naming ``argument`` when ``path`` cannot take an output (:func:`output_file_problem`)."""
    problem = output_file_problem(path, force=force, inputs=(log,))
    if problem is not None:
        raise AllanError(f"argument {argument}: {problem}")


def check_options(
    log: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    kalibr: str | os.PathLike[str] | None = None,
    force: bool = False,
    plot: bool = True,
) -> Path | None:
    """Refuse, before any work, ``gyroemu allan``'s bad options with :class:`AllanError` (the message
    names the argument): a plot format matplotlib does not write, a missing ``log``, an output (the
    plot ``out``, default :func:`default_plot_path`; the ``kalibr`` imu.yaml) that is the log itself
    (even with ``force``), a folder, in a folder that cannot take it (missing, read-only, not writable),
    or that exists without ``force`` (:func:`output_file_problem`); ``kalibr`` the same file as the plot.
    Without ``plot`` (``--no-plot``) no plot is drawn, so none is checked (an ``out`` is refused: it
    names a plot). Returns the plot's path, or None without ``plot``."""
    log = Path(log)
    if not plot and out is not None:
        raise AllanError(f"argument --no-plot: draws no plot, but --out names one ({out}): drop one of them")
    picture = Path(out) if out is not None else default_plot_path(log)
    argument = "--out" if out is not None else "--out (default: LOG with .allan.png)"
    if plot:
        try:
            plot_format(picture)
        except ValueError as e:
            raise AllanError(f"argument {argument}: {e}") from None
    if not log.is_file():
        why = folder_not_mcap(log) if log.is_dir() else "not a file" if log.exists() else "no such file"
        raise AllanError(f"argument LOG: {log}: {why}")
    if plot:
        _check_output(picture, argument, log, force)
    if kalibr is not None:
        kalibr = Path(kalibr)
        _check_output(kalibr, "--kalibr", log, force)
        if plot and same_file(kalibr, picture):
            raise AllanError(f"argument --kalibr: {kalibr} is the plot's file too ({argument})")
    return picture if plot else None


class AllanLogError(LogError):
    """A log :func:`allan_of_log` cannot analyse: missing, not a gyroemu log, no or too few gyro samples
    (a :class:`gyroemu.errors.LogError`: ``.file`` is the log, and the message starts with its name)."""


class AllanMotionError(AllanLogError):
    """A log that is not static (:class:`StaticCheck`); the message names the figures that moved."""


class MotionWarning(UserWarning):
    """A log analysed although it is not static (``allow_motion``)."""


BATCH = 1 << 16
"""Samples handed to the Allan accumulator at a time (at least: an .mcap's IMU messages are decoded a
file chunk at a time, and gathered until they reach it)."""

_MIN_SAMPLES = 64
_MAX_STEP_BINS = 1 << 16


def _shape_error(shape: tuple[int, ...]) -> str:
    return f"an Allan analysis needs a (N, 3) gyro record with N >= {_MIN_SAMPLES}, got shape {shape}"


class _StepMedian:
    """The median step between integer stamps, from a histogram of the steps fed in batches.

    Exact (as ``np.median(np.diff(stamps))``) while the steps take at most 65 536 distinct values (a
    gyroemu log's steps differ only by rounding to the nanosecond); past that the bins are merged two
    by two (as often as needed) and the median is the middle of its bin, within half a bin width. The
    histogram is bounded by the number of distinct steps, not by the number of samples.
    """

    def __init__(self) -> None:
        self.values = np.empty(0, dtype=np.int64)
        self.counts = np.empty(0, dtype=np.int64)
        self.shift = 0  # bins are [v·2^shift, (v + 1)·2^shift)

    def add(self, steps: np.ndarray) -> None:
        if not len(steps):
            return
        values, counts = np.unique(np.asarray(steps, dtype=np.int64) >> self.shift, return_counts=True)
        self._merge(np.concatenate([self.values, values]), np.concatenate([self.counts, counts]))
        while len(self.values) > _MAX_STEP_BINS:
            self.shift += 1
            self._merge(self.values >> 1, self.counts)

    def _merge(self, values: np.ndarray, counts: np.ndarray) -> None:
        self.values, index = np.unique(values, return_inverse=True)
        self.counts = np.bincount(index, weights=counts).astype(np.int64)

    def median(self) -> float:
        """The median step (NaN without steps), in the stamps' unit."""
        total = int(self.counts.sum())
        if total == 0:
            return float("nan")
        cumulative = np.cumsum(self.counts)
        middle = ((total - 1) // 2, total // 2)  # the two middle steps (the same one for an odd count)
        lower, upper = (self.values[np.searchsorted(cumulative, i, side="right")] for i in middle)
        width = 1 << self.shift
        centre = (width - 1) / 2 if self.shift else 0.0
        return (float(lower) + float(upper)) / 2 * width + centre


_BLOCKS = 1024  # the block means keep between _BLOCKS and 2·_BLOCKS blocks
_FALSE_ALARM = 1e-6  # chance that white noise alone gets a static log refused
_MIN_BLOCKS = 8
TOLERANCE_MAGNITUDE = 0.02
"""m/s² (about 2 mg): what a static accelerometer's |f| may drift beyond its noise (bias instability,
random walk and temperature drift of a MEMS accelerometer over hours stay below it)."""
TOLERANCE_DIRECTION = 0.1
"""deg: what a static accelerometer's direction (and a static truth's attitude) may drift beyond the
noise: a bench settling or a 1.7 mg change of a horizontal bias; a hand-held or vehicle log moves by
degrees."""
_MOTION_FRACTION = 0.2
_EARTH_RATE = 7.2921150e-5  # rad/s
_CHI2_3_MEDIAN = 2.365973884375338  # median of a chi-squared of 3 degrees of freedom


class _BlockMeans:
    """Means of the specific force over blocks of ``size`` samples, fed in batches, in bounded memory.

    Blocks start at one sample; when they number more than 2·1024 neighbours are merged two by two (the
    size doubles), so between 1024 and 2048 block means (and the partial last block) are kept,
    whatever the log's length. Only the last block may be partial.
    """

    def __init__(self) -> None:
        self.size = 1
        self.sums = np.zeros((0, 3))
        self.counts = np.zeros(0, dtype=np.int64)
        self.total = np.zeros(3)
        self.n = 0
        self.finite = True

    def add(self, force: np.ndarray) -> None:
        if not self.finite or not len(force):
            return
        force = np.asarray(force, dtype=float)
        if not np.all(np.isfinite(force)):
            self.finite = False  # no accelerometer (NaN rows): not checked
            return
        self.total += force.sum(axis=0)
        self.n += len(force)
        if len(self.counts) and self.counts[-1] < self.size:
            take = int(min(self.size - self.counts[-1], len(force)))
            self.sums[-1] += force[:take].sum(axis=0)
            self.counts[-1] += take
            force = force[take:]
        full = len(force) // self.size
        sums = [self.sums, force[: full * self.size].reshape(full, self.size, 3).sum(axis=1)]
        counts = [self.counts, np.full(full, self.size, dtype=np.int64)]
        if len(force) > full * self.size:
            sums.append(force[full * self.size :].sum(axis=0)[None, :])
            counts.append(np.array([len(force) - full * self.size], dtype=np.int64))
        self.sums, self.counts = np.concatenate(sums), np.concatenate(counts)
        while len(self.counts) > 2 * _BLOCKS:
            pairs = len(self.counts) // 2
            merged = self.sums[: 2 * pairs].reshape(pairs, 2, 3).sum(axis=1)
            merged_counts = self.counts[: 2 * pairs].reshape(pairs, 2).sum(axis=1)
            self.sums = np.concatenate([merged, self.sums[2 * pairs :]])
            self.counts = np.concatenate([merged_counts, self.counts[2 * pairs :]])
            self.size *= 2

    def figures(self) -> tuple[list[MotionFigure], list[str]]:
        """The magnitude and direction figures of the static check (see :class:`StaticCheck`)."""
        if not self.finite or self.n == 0:
            return [], ["the accelerometer was not checked: it has no (or non-finite) samples"]
        full = self.counts == self.size
        if full.sum() < _MIN_BLOCKS:
            return [], [f"the accelerometer was not checked: fewer than {_MIN_BLOCKS} blocks"]
        means = self.sums[full] / self.size
        k = len(means)
        steps = np.sum(np.diff(means, axis=0) ** 2, axis=1)
        sigma = float(np.sqrt(np.median(steps) / (2 * _CHI2_3_MEDIAN)))  # per axis, of one block mean
        spread = float(np.sqrt(2 * np.log(k / _FALSE_ALARM)))  # max of k Rayleigh or |normal| draws
        magnitude = np.linalg.norm(means, axis=1)
        figures = [
            MotionFigure(
                "accel_magnitude",
                "the accelerometer's magnitude moves by",
                float(np.max(np.abs(magnitude - np.median(magnitude)))),
                spread * sigma + TOLERANCE_MAGNITUDE,
                "m/s^2",
            )
        ]
        mean = self.total / self.n
        g = float(np.linalg.norm(mean))
        if g < 1.0:
            return figures, [f"the accelerometer's direction was not checked: its mean |f| is {g:.3g} m/s^2"]
        unit = mean / g
        angle = np.arctan2(np.linalg.norm(np.cross(means, unit), axis=1), means @ unit)
        figures.append(
            MotionFigure(
                "accel_direction",
                "the accelerometer's direction moves by",
                float(np.degrees(angle.max())),
                float(np.degrees(spread * sigma / g)) + TOLERANCE_DIRECTION,
                "deg",
            )
        )
        return figures, []


class _TruthStats:
    """Running figures of the true motion, fed in batches: the rate's per-axis mean, least and
    largest value, and the largest attitude change from the first attitude."""

    def __init__(self) -> None:
        self.n = 0
        self.total = np.zeros(3)
        self.low = np.full(3, np.inf)
        self.high = np.full(3, -np.inf)
        self.q0: np.ndarray | None = None
        self.angle = 0.0

    def add(self, omega: np.ndarray, q: np.ndarray) -> None:
        omega = np.asarray(omega, dtype=float)
        rows = np.all(np.isfinite(omega), axis=1)
        if rows.any():
            self.total += omega[rows].sum(axis=0)
            self.n += int(rows.sum())
            self.low = np.minimum(self.low, omega[rows].min(axis=0))
            self.high = np.maximum(self.high, omega[rows].max(axis=0))
        q = np.asarray(q, dtype=float)
        norm = np.linalg.norm(q, axis=1)
        q = q[np.isfinite(norm) & (norm > 0)] / norm[np.isfinite(norm) & (norm > 0), None]
        if not len(q):
            return
        if self.q0 is None:
            self.q0 = q[0]
        chord = np.minimum(np.linalg.norm(q - self.q0, axis=1), np.linalg.norm(q + self.q0, axis=1))
        self.angle = max(self.angle, float(4 * np.arcsin(np.clip(chord.max() / 2, 0.0, 1.0))))

    def figures(self, sigma_min: float) -> tuple[list[MotionFigure], list[str]]:
        """The rate and attitude figures; ``sigma_min`` the gyro's lowest measured Allan deviation (of its
        axes with noise; 0 for none), rad/s."""
        if self.n == 0:
            return [], ["the truth was not checked: it has no finite rates"]
        mean = self.total / self.n
        wander = float(np.max(np.maximum(self.high - mean, mean - self.low)))
        # A gyro without noise (sigma_min 0) leaves only the truth's round-off: 2¹⁰ ulps of its rate.
        rate_limit = max(_MOTION_FRACTION * sigma_min, 1024 * np.finfo(float).eps * float(np.linalg.norm(mean)))
        tilt_limit = min(np.radians(TOLERANCE_DIRECTION), rate_limit / _EARTH_RATE)
        figures = [
            MotionFigure(
                "truth_rate",
                "the true rate moves by",
                float(np.degrees(wander)),
                float(np.degrees(rate_limit)),
                "deg/s",
            )
        ]
        if self.q0 is not None:
            figures.append(
                MotionFigure(
                    "truth_attitude",
                    "the true attitude turns by",
                    float(np.degrees(self.angle)),
                    float(np.degrees(tilt_limit)),
                    "deg",
                )
            )
        return figures, []


class _GyroSeries:
    """One IMU channel fed in batches: the gyro's and the accelerometer's Allan accumulators, the
    accelerometer's block means (the static check), the steps' median, the sample count."""

    def __init__(self) -> None:
        self.allan = OverlappingAllanAccumulator(dt=1.0, n_axes=3)  # dt is given with the result
        self.accel = OverlappingAllanAccumulator(dt=1.0, n_axes=3)
        self.blocks = _BlockMeans()
        self.steps = _StepMedian()
        self.n = 0
        self.finite = True
        self.accel_usable = True  # every accelerometer sample given and finite so far
        self.last_stamp: int | None = None
        self.last_log_time: int | None = None
        self.not_increasing: tuple[int, float, float, int] | None = None  # estimate's tally (not_increasing_since)
        self._pending: list[tuple[np.ndarray, np.ndarray | None]] = []
        self._pending_n = 0

    def add(self, gyro: np.ndarray, stamps: np.ndarray | None = None, accel: np.ndarray | None = None) -> None:
        """Append samples ``gyro`` (n, 3), rad/s, with their integer stamps (n,) when known and the
        accelerometer's ``accel`` (n, 3), m/s², when there is one."""
        if not len(gyro):
            return
        if stamps is not None:
            stamps = np.asarray(stamps, dtype=np.int64)
            if self.last_stamp is None:
                self.steps.add(np.diff(stamps))
            else:
                self.steps.add(np.diff(stamps, prepend=self.last_stamp))
            self.not_increasing = not_increasing_since(stamps, self.last_stamp, self.n, self.not_increasing)
            self.last_stamp = int(stamps[-1])
        self.n += len(gyro)
        if accel is None or not np.all(np.isfinite(accel)):
            self.accel_usable = False
        if accel is not None:
            self.blocks.add(accel)
        if not self.finite:
            return
        if not np.all(np.isfinite(gyro)):
            self.finite = False  # reported after the length check, as allan_report orders them
            self._pending, self._pending_n = [], 0
            return
        self._pending.append((gyro, accel if self.accel_usable else None))
        self._pending_n += len(gyro)
        if self._pending_n >= BATCH:
            self.flush()

    def flush(self) -> None:
        if self._pending:
            gyro = [g for g, _ in self._pending]
            self.allan.update(np.concatenate(gyro) if len(gyro) > 1 else gyro[0])
            if self.accel_usable:
                accel = [a for _, a in self._pending if a is not None]  # all present while usable
                self.accel.update(np.concatenate(accel) if len(accel) > 1 else accel[0])
            self._pending, self._pending_n = [], 0

    def deviations(self, dt: float) -> tuple[AllanDeviation, ...]:
        """The three axes' Allan deviations; ``ValueError`` (allan_report's words) for a record it cannot use."""
        self.flush()
        if self.n < _MIN_SAMPLES:
            raise ValueError(_shape_error((self.n, 3)))
        if not self.finite:
            raise ValueError("the gyro record has NaN or infinite samples")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"the stamps do not increase (median step {dt:g} s)")
        return self.allan.deviations(dt)

    def accel_deviations(self, dt: float) -> tuple[AllanDeviation, ...] | None:
        """The accelerometer's three Allan deviations, or None without usable (finite, varying) samples.
        Call after :meth:`deviations`."""
        self.flush()
        if not self.accel_usable:
            return None
        deviations = self.accel.deviations(dt)
        if any(not np.all(d.adev > 0) or not np.all(np.isfinite(d.adev)) for d in deviations):
            return None  # a constant accelerometer: nothing to fit
        return deviations


def _npz_series(log: Path) -> tuple[_GyroSeries, float, str | None, _TruthStats | None]:
    """An .npz log's IMU series, its median step (s), device TOML and truth figures.

    .npz is the in-memory format (``np.load``'s ``mmap_mode`` cannot map an array inside a zip): its
    ``imu/gyro``, ``imu/accel`` and ``imu/t`` are read whole, then fed to the accumulators in batches
    like an .mcap's; ``truth/omega_b`` and ``truth/q_wb``, when present, to the truth's figures.
    """
    import zipfile
    import zlib

    from gyroemu.pipelines.formats.mcap_records import MAGIC

    try:
        with open(log, "rb") as f:
            head = f.read(len(MAGIC))
    except OSError as e:
        raise AllanLogError(f"cannot read it: {e.strerror or e}", file=log) from None
    if not head:
        raise AllanLogError("an empty file, not a gyroemu log (.mcap or .npz)", file=log)
    if head.startswith(MAGIC[:5]):
        raise AllanLogError("an MCAP log without the .mcap suffix: name it .mcap", file=log)
    if not head.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # an .npz is a zip archive, as np.load tells
        raise AllanLogError("not a gyroemu log (.mcap, or .npz: a zip of NumPy arrays)", file=log)
    accel = truth = None
    try:
        with np.load(log, allow_pickle=False) as data:
            if "imu/gyro" not in data or "imu/t" not in data:
                gyro = None
            else:
                gyro, t = data["imu/gyro"], data["imu/t"]
                device_toml = str(data["device_toml"]) if "device_toml" in data else None
                if "imu/accel" in data:
                    accel = np.asarray(data["imu/accel"], dtype=float)
                if "truth/omega_b" in data and "truth/q_wb" in data:
                    truth = _TruthStats()
                    omega, q = data["truth/omega_b"], data["truth/q_wb"]
                    for start in range(0, len(omega), BATCH):
                        truth.add(omega[start : start + BATCH], q[start : start + BATCH])
    except (zipfile.BadZipFile, EOFError, zlib.error) as e:
        raise AllanLogError(f"a truncated or corrupt .npz archive: {e}", file=log) from None
    except (OSError, ValueError) as e:
        if "allow_pickle" in str(e) or "pickled" in str(e):
            raise AllanLogError("holds object (pickled) arrays, which gyroemu does not load", file=log) from None
        raise AllanLogError(f"not a gyroemu log (.mcap or .npz): {e}", file=log) from None
    if gyro is None:
        raise AllanLogError("holds no gyro samples (write one with 'gyroemu simulate --device ...')", file=log)
    gyro = np.asarray(gyro, dtype=float)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < _MIN_SAMPLES:
        raise AllanLogError(_shape_error(gyro.shape), file=log)
    if accel is not None and accel.shape != gyro.shape:
        accel = None
    dt = float(np.median(np.diff(t)))
    series = _GyroSeries()
    for start in range(0, len(gyro), BATCH):
        series.add(gyro[start : start + BATCH], accel=None if accel is None else accel[start : start + BATCH])
    return series, dt, device_toml, truth


def _mcap_series(log: Path, topic: str | None = None) -> tuple[_GyroSeries, float, str | None, _TruthStats | None, str]:
    """An .mcap log's IMU series (its one device's IMU channel), median step (s), device TOML, the
    figures of its device's ``/truth/imu`` (None without one) and the IMU topic.

    The file is walked a record at a time (one decompressed chunk in memory), the device's IMU messages
    decoded as they come and handed on in batches of :data:`BATCH`, so memory does not grow with the
    log. The device is the one :func:`~gyroemu.pipelines.formats.mcap_log.read_mcap` finds (``/imu``,
    ``/<device>/imu``, any other Imu topic, or a lone ``/truth/imu``, ``/estimate/imu``), with the same
    errors and warnings; unlike ``read_mcap`` it keeps every sample of the channel (``read_mcap`` drops
    samples that lack a ``/raw/<kind>`` message at their stamp, which gyroemu's logs never do). Each
    chunk's messages are put in log-time order; a channel whose chunks overlap in time (so that only
    a whole-file sort would order it) is refused. A log of several devices needs ``topic``, the IMU
    topic to analyse (:class:`AllanLogError` otherwise, naming them).
    """
    from gyroemu.pipelines.estimation.series import not_increasing_error
    from gyroemu.pipelines.formats.channels import (
        ESTIMATE_ROLE,
        IMU_ROLE,
        TRUTH_ROLE,
        absolute_topic,
        role_accepts,
        split_topic,
    )
    from gyroemu.pipelines.formats.mcap_log import announce_scan, is_the_devices_estimate, no_imu_error
    from gyroemu.pipelines.formats.mcap_records import LogError, McapScan
    from gyroemu.pipelines.formats.messages import IMU

    scan = McapScan(log)
    series: dict[int, _GyroSeries] = {}  # channel id -> its samples, for every channel that may be the device's
    truths: dict[str, _TruthStats] = {}  # topic prefix -> its /truth/imu figures
    keys: dict[int, tuple[str, str, str]] = {}  # channel id -> place()

    def place(channel_id: int) -> tuple[str, str, str]:
        """``(device key, prefix, role)`` of an Imu channel, as read_mcap groups it."""
        if channel_id not in keys:
            topic = scan.data[channel_id].channel.topic
            prefix, role = split_topic(topic)
            if role and not role_accepts(role, IMU):
                role = ""  # e.g. an Imu message on a /mag topic: a plain topic, a device of its own
            keys[channel_id] = (topic if role in ("", TRUTH_ROLE, ESTIMATE_ROLE) else prefix, prefix, role)
        return keys[channel_id]

    def candidate(channel_id: int) -> bool:
        """Whether an Imu channel is (so far) a device: a truth or estimate one only while its device's
        measured /imu has no messages."""
        _, prefix, role = place(channel_id)
        if role not in (TRUTH_ROLE, ESTIMATE_ROLE):
            return True
        return not any(place(c)[2] == IMU_ROLE and place(c)[1] == prefix and s.n for c, s in series.items())

    def gather(channel_id: int) -> None:
        data = scan.data[channel_id]
        blocks = list(zip(data.order, data.header, data.payload))
        blocks += [
            (np.array([ordinal]), fields, np.frombuffer(payload, np.uint8)[None, :])
            for ordinal, fields, payload in data.loose
        ]
        for gathered in (data.order, data.header, data.payload, data.loose):
            gathered.clear()  # what the scan gathered for this channel is handed on or dropped: memory stays flat
        if not blocks or data.mtype is not IMU:
            return
        _, prefix, role = place(channel_id)
        device = candidate(channel_id)
        if not device:
            series.pop(channel_id, None)  # a truth or estimate channel beside a measured /imu
            if role != TRUTH_ROLE:
                return
        try:
            batches = [IMU.decode(rows) for _, _, rows in blocks]
        except ValueError as e:
            raise LogError(f"topic {data.channel.topic}: corrupt {IMU.name} message: {e}", file=log) from None
        order = np.concatenate([b[0] for b in blocks])
        log_time = np.concatenate([b[1]["log_time"] for b in blocks]).astype(np.int64)
        stamps = np.concatenate([b.stamp_ns for b in batches])
        gyro = np.concatenate([b["angular_velocity"] for b in batches])
        accel = np.concatenate([b["linear_acceleration"] for b in batches])
        index = np.lexsort((order, log_time))  # log-time order, file order for equal times
        stamps, gyro, accel, log_time = stamps[index], gyro[index], accel[index], log_time[index]
        if role == TRUTH_ROLE:
            truths.setdefault(prefix, _TruthStats()).add(gyro, np.concatenate([b["orientation"] for b in batches]))
        if not device:
            return
        target = series.setdefault(channel_id, _GyroSeries())
        if target.last_log_time is not None and log_time[0] < target.last_log_time:
            raise AllanLogError(
                f"the chunks of {data.channel.topic} overlap in time; "
                "rewrite the log in time order (e.g. 'mcap sort') to analyse it",
                file=log,
            )
        target.last_log_time = int(log_time[-1])
        target.add(gyro, stamps, accel)

    for _ in scan.walk():
        for channel_id, data in scan.data.items():
            if data.payload or data.loose:
                gather(channel_id)

    announce_scan(log, scan)  # a truncated file, skipped topics (not the tf tree), as read_mcap warns
    devices = {c: s for c, s in series.items() if s.n and candidate(c)}
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    records = {m.get("topic_prefix", ""): m for m in metadata}

    def meta(channel_id: int) -> dict[str, Any] | None:
        key = place(channel_id)[0]
        return records.get(key) or (metadata[0] if key == "" and len(metadata) == 1 else None)

    if not devices:
        raise no_imu_error(scan, log)
    measured = [c for c in devices if place(c)[2] not in (TRUTH_ROLE, ESTIMATE_ROLE)]
    lone = [c for c in devices if place(c)[2] == ESTIMATE_ROLE]
    own = (
        any(place(c)[2] == ESTIMATE_ROLE and place(c)[1] == place(measured[0])[1] for c in keys) if measured else False
    )
    if is_the_devices_estimate(len(measured), len(lone), own):  # the measured device's, as read_mcap has it
        del devices[lone[0]]
    topics = {scan.data[c].channel.topic: c for c in devices}
    if topic is not None:
        if absolute_topic(topic) not in topics:
            raise AllanLogError(
                f"--topic {topic}: no sensor_msgs/msg/Imu topic of that name (IMU topics: {', '.join(sorted(topics))})",
                file=log,
            )
        devices = {topics[absolute_topic(topic)]: devices[topics[absolute_topic(topic)]]}
    if len(devices) != 1:
        raise AllanLogError(
            f"{len(devices)} IMU topics ({', '.join(sorted(topics))}): choose the one to analyse with --topic",
            file=log,
        )
    channel_id, chosen = next(iter(devices.items()))
    if chosen.not_increasing is not None:  # as estimate refuses them: the samples' order is not their stamps'
        name = (meta(channel_id) or {}).get("device_name") or (keys[channel_id][0].strip("/") or "imu0")
        raise AllanLogError(not_increasing_error(None, name, chosen.not_increasing).reason, file=log)
    device_toml = (meta(channel_id) or {}).get("device") or None
    truth = truths.get(place(channel_id)[1])
    return chosen, chosen.steps.median() * 1e-9, device_toml, truth, scan.data[channel_id].channel.topic


def allan_of_log(path: str | os.PathLike[str], allow_motion: bool = False, topic: str | None = None) -> AllanReport:
    """Fit a static log's gyro and accelerometer: an .mcap (its device, with the device's config when
    the log carries it), or an .npz of ``gyroemu simulate --device`` (``imu/gyro``, ``imu/accel``,
    ``imu/t``, ``device_toml``). The sample interval is the median step of the stamps. Raises
    :class:`AllanLogError` for a log it cannot use, :class:`gyroemu.errors.LogError` for an .mcap it
    cannot read, and :class:`AllanMotionError` for a log that is not static (:class:`StaticCheck`)
    unless ``allow_motion`` (then a :class:`MotionWarning`). ``topic``: an .mcap's IMU topic to analyse,
    needed where it has several (``/imu/data_raw`` and ``/imu/data``, or several devices).

    The log is read and analysed in batches of :data:`BATCH` samples: memory is bounded by the batch
    (and, for an .npz, by the arrays, which that format holds in memory), not by the log's length.
    """
    log = Path(path)
    if not log.is_file():
        raise AllanLogError("no such file", file=log)
    if log.suffix == ".mcap":
        series, dt, device_toml, truth, topic = _mcap_series(log, topic)
    else:
        (series, dt, device_toml, truth), topic = _npz_series(log), ""
    spec = accel_spec = None
    if device_toml is not None:
        import dataclasses
        import tomllib

        from gyroemu.sensors import device_from_dict

        try:
            table = tomllib.loads(device_toml)
        except tomllib.TOMLDecodeError as e:
            raise AllanLogError(f"its embedded device config is not TOML: {e}", file=log) from None
        device = device_from_dict(table, name=log.name)
        spec = dataclasses.replace(device.gyro_errors, noise_density=device.gyro_noise_density)
        accel_spec = device.spec.accelerometer.errors.to_si()
    try:
        deviations = series.deviations(dt)
        fits = allan_fits(deviations)
    except ValueError as e:
        raise AllanLogError(str(e), file=log) from None
    accel_deviations = series.accel_deviations(dt)
    accel_fits = None
    if accel_deviations is not None:
        accel_fits = allan_fits(accel_deviations)
    noisy = [float(f.allan.adev[f.allan.adev > 0].min()) for f in fits if np.any(f.allan.adev > 0)]
    static = _static_check(series.blocks, truth, min(noisy, default=0.0))  # a constant (saturated) axis: none
    if not static.static:
        if not allow_motion:
            raise AllanMotionError(
                f"not a static log: {static.moving()}; an Allan analysis of a moving sensor "
                "mixes its motion into the noise (pass --allow-motion to analyse it anyway)",
                file=log,
            )
        warnings.warn(f"{log}: not a static log: {static.moving()}", MotionWarning, stacklevel=2)
    return AllanReport(
        fits=fits,
        spec=spec,
        accel_fits=accel_fits,
        accel_spec=accel_spec,
        static=static,
        rate_hz=1.0 / dt,
        topic=topic,
    )


def _static_check(blocks: _BlockMeans, truth: _TruthStats | None, sigma_min: float) -> StaticCheck:
    figures, notes = blocks.figures()
    if truth is None:
        notes.append("the truth was not checked: the log has none")
    else:
        more, why = truth.figures(sigma_min)
        figures += more
        notes += why
    return StaticCheck(figures=tuple(figures), notes=tuple(notes))


def plot_format(out: str | os.PathLike[str]) -> str:
    """The format matplotlib draws ``out`` in, named by its suffix (``png``, ``pdf``, ``svg``, ...);
    ``ValueError`` for a suffix matplotlib does not write."""
    from matplotlib.backend_bases import FigureCanvasBase

    suffix = Path(out).suffix.lower().lstrip(".")
    supported = FigureCanvasBase.get_supported_filetypes()
    if suffix not in supported:
        raise ValueError(
            f"{out}: cannot draw a plot as {('.' + suffix) if suffix else 'a file without a suffix'}; "
            f"name one of: {', '.join('.' + k for k in sorted(supported))}"
        )
    return suffix


def write_allan_plot(report: AllanReport, out: str | os.PathLike[str], title: str = "") -> Path:
    """:func:`plot_allan` to ``out``, in the format its suffix names (:func:`plot_format`), whole or
    not at all (a temporary file beside it, renamed over it); returns ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    fmt = plot_format(out)
    fig = _allan_figure(report, title)
    try:
        write_atomic(out, lambda f: fig.savefig(f, format=fmt))
    finally:
        plt.close(fig)
    return out


def plot_allan(report: AllanReport, out: str | Path, title: str = "") -> Path:
    """Draw the Allan plot in the format ``out``'s suffix names: measured curves with 68 % bands, fitted
    models, specification lines; the accelerometer in a second panel when the report has it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    fmt = plot_format(out)
    fig = _allan_figure(report, title)
    try:
        fig.savefig(out, format=fmt)
    finally:
        plt.close(fig)
    return out


def _allan_figure(report: AllanReport, title: str) -> Figure:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(report.fits, report.spec, _DEG * 3600.0, "Allan deviation (deg/h)", "gyro")]
    if report.accel_fits is not None:
        panels.append((report.accel_fits, report.accel_spec, 1.0 / _UG, "Allan deviation (ug)", "accelerometer"))
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 5.5 * len(panels)), dpi=110, squeeze=False)
    for ax, (fits, spec, scale, ylabel, name) in zip(axes[:, 0], panels):
        heading = title or "Allan deviation"
        _draw_panel(ax, fits, spec, scale, ylabel, heading if len(panels) == 1 else f"{heading}: {name}")
    fig.tight_layout()
    return fig


def _draw_panel(
    ax: Axes, fits: tuple[AllanFit, AllanFit, AllanFit], spec: ErrorModel | None, scale: float, ylabel: str, title: str
) -> None:
    """One sensor's curves, models and spec lines on ``ax``, in the data's unit times ``scale``."""
    for axis, (fit, colour) in enumerate(zip(fits, ("tab:red", "tab:green", "tab:blue"))):
        a = fit.allan
        ax.fill_between(a.tau, a.low * scale, a.high * scale, color=colour, alpha=0.15, lw=0)
        ax.loglog(a.tau, a.adev * scale, "o", ms=3, color=colour, label=f"measured {'xyz'[axis]}")
        fitted = a.tau[fit.skipped :]  # the model where it was fitted (shorter τ: within a low-pass's memory)
        ax.loglog(fitted, fit.model(fitted) * scale, "-", lw=1, color=colour, alpha=0.8)
    tau = fits[0].allan.tau
    if spec is not None:
        s = _spec_terms(spec)
        lines = {
            "spec quantisation": None if s["quantisation"] is None else np.sqrt(3) * s["quantisation"] / tau,
            "spec ARW": s["arw"] / np.sqrt(tau) if s["arw"] else None,
            "spec bias instability": np.full_like(tau, 0.664 * s["bias_instability"])
            if s["bias_instability"]
            else None,
            "spec RRW": s["rrw"] * np.sqrt(tau / 3) if s["rrw"] else None,
        }
        for (label, values), style in zip(lines.items(), ((0, (1, 3)), "--", "-.", ":")):
            if values is not None:
                ax.loglog(tau, values * scale, color="0.3", ls=style, lw=1.2, label=label)
    lowest = min(float(f.allan.adev.min()) for f in fits) * scale
    ax.set_ylim(bottom=lowest / 5)  # spec lines below the data would only squash the curves
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def _kalibr_term(fits: tuple[AllanFit, ...], term: str) -> tuple[float, list[str]]:
    """The largest over the axes of each axis's value (or upper limit, not resolved), and the axes
    that gave an upper limit."""
    values, limited = [], []
    for axis, fit in zip("xyz", fits):
        c = getattr(fit, term)
        values.append(c.value if c.resolved else c.upper_limit)
        if not c.resolved:
            limited.append(axis)
    return float(max(values)), limited


def _axes(names: list[str]) -> str:
    return f"axis {names[0]}" if len(names) == 1 else f"axes {', '.join(names)}"


def kalibr_imu_yaml(report: AllanReport, rostopic: str | None = None) -> str:
    """The fit as Kalibr's (and OpenVINS's) ``imu.yaml``: ``accelerometer_noise_density`` (m/s²/√Hz),
    ``accelerometer_random_walk`` (m/s³/√Hz), ``gyroscope_noise_density`` (rad/s/√Hz),
    ``gyroscope_random_walk`` (rad/s²/√Hz), ``rostopic``, ``update_rate`` (Hz).

    Kalibr's noise densities are continuous-time densities, the Allan deviation at 1 s: gyroemu's N
    (``arw``); its random walks are the bias's, K (``rrw``), in the same units as gyroemu's SI. One
    value per sensor: the largest over the axes. A term not resolved on some axis gives its upper
    limit there, and a comment says so. Raises ``ValueError`` without an accelerometer fit.
    """
    if report.accel_fits is None:
        raise ValueError("the log has no accelerometer fit: Kalibr's imu.yaml needs both sensors")
    topic = rostopic or report.topic or "/imu0"
    lines = ["# IMU noise model for Kalibr / OpenVINS, fitted by 'gyroemu allan' (IEEE 952 Allan fit)."]
    lines.append("# One value per sensor: the largest of the three axes.")
    rows = (
        ("accelerometer_noise_density", report.accel_fits, "arw", "m/s^2/sqrt(Hz) (continuous-time)"),
        ("accelerometer_random_walk", report.accel_fits, "rrw", "m/s^3/sqrt(Hz) (bias random walk)"),
        ("gyroscope_noise_density", report.fits, "arw", "rad/s/sqrt(Hz) (continuous-time)"),
        ("gyroscope_random_walk", report.fits, "rrw", "rad/s^2/sqrt(Hz) (bias random walk)"),
    )
    for key, fits, term, unit in rows:
        value, limited = _kalibr_term(fits, term)
        note = f"; upper limit: not resolved on {_axes(limited)}" if limited else ""
        lines.append(f"{key}: {value:.6e}  # {unit}{note}")
    lines.append(f"rostopic: {topic}")
    lines.append(f"update_rate: {report.rate_hz:.6g}  # Hz")
    return "\n".join(lines) + "\n"


def write_kalibr_yaml(report: AllanReport, path: str | os.PathLike[str], force: bool = False) -> Path:
    """Write :func:`kalibr_imu_yaml` to ``path`` whole or not at all; :class:`AllanError` (a ``ValueError``)
    saying why when ``path`` cannot take it (:func:`output_file_problem`: it exists and not ``force``,
    among others)."""
    path = Path(path)
    problem = output_file_problem(path, force=force)
    if problem is not None:
        raise AllanError(problem)
    return write_text_atomic(path, kalibr_imu_yaml(report))
