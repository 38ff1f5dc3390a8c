"""One recording's identification: rest phases, latencies, calibrations and noise, from plain arrays.

:class:`TrialData` is what every fit needs (a log reader adapts its file to it); :func:`identify_trial`
runs, in order: rest phases (found, or the user's), each sensor's latency against the truth
(:mod:`.timing`), the gyro's calibration, the accelerometer's with the gyro's mounting, the
magnetometer's, each sensor's noise over the rest phases (:mod:`.noise`), and the accelerometer's
offset in the movement against at rest (:mod:`.handling`) and its lever arm from the truth's reference
point (:mod:`.lever_arm`, with a position track).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics.earth import earth_rate_enu

from .calibration import AccelCalibration, GyroCalibration, MagCalibration, fit_accel, fit_gyro, fit_mag
from .handling import HandlingOffset, handling_offset
from .lever_arm import LeverArmFit, fit_lever_arm
from .noise import SensorNoise, sensor_noise
from .rest import RestPhase, find_rest_phases, phases_from_intervals
from .timing import LatencyEstimate, accel_latency, gyro_latency, mag_latency

__all__ = ["TrialData", "TrialSettings", "TrialIdentification", "identify_trial"]


@dataclass(frozen=True, eq=False)
class TrialData:
    """A recording as plain arrays (SI).

    Attributes
    ----------
    name : what the reports call it (the file's name).
    t : (N,) s, sample stamps. gyro (N, 3) rad/s, accel (N, 3) m/s², mag (N, 3) tesla or None.
    truth_t : (M,) s; q_wb : (M, 4) w, x, y, z, NaN rows where unknown; pos_w : (M, 3) m or None.
    movement : (N,) bool, the working-volume samples, or None (then: every sample not at rest).
    valid : (N,) bool, the samples the calibrations and latencies may use, or None (all).
    latitude_rad : the site's latitude, rad, when the recording says it (a gyroemu log's site), or None.
    """

    name: str
    t: NDArray[np.float64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    mag: NDArray[np.float64] | None
    truth_t: NDArray[np.float64]
    q_wb: NDArray[np.float64]
    pos_w: NDArray[np.float64] | None = None
    movement: NDArray[np.bool_] | None = None
    valid: NDArray[np.bool_] | None = None
    latitude_rad: float | None = None

    @property
    def dt(self) -> float:
        """Median sample interval, s."""
        return float(np.median(np.diff(self.t)))


@dataclass(frozen=True)
class TrialSettings:
    """Settings of :func:`identify_trial`.

    rest_intervals : [(t_start, t_stop), …] s, or None to find the rest phases.
    gravity_m_s2 : local gravity (a scale-factor error and a gravity error are one thing to the fit).
    earth_rate_w : (3,) rad/s in world axes for every recording, or None: each recording's own from its
        ``latitude_rad``, and where it has none Earth's rate is ignored (15 °/h at most, a note says so).
    window_s : averaging window of the calibrations, s.
    mag_tau_min_s : shortest τ of the magnetometer's Allan fit (module notes of :mod:`.noise`).
    """

    rest_intervals: Sequence[tuple[float, float]] | None = None
    gravity_m_s2: float = 9.81
    earth_rate_w: tuple[float, float, float] | None = None
    window_s: float = 0.1
    mag_tau_min_s: float = 0.1
    search_s: float = 0.06


@dataclass(frozen=True, eq=False)
class TrialIdentification:
    """What :func:`identify_trial` found in one recording (None: the sensor is absent)."""

    name: str
    samples: int
    rate_hz: float
    rest: list[RestPhase]
    gyro_latency: LatencyEstimate
    accel_latency: LatencyEstimate
    mag_latency: LatencyEstimate | None
    gyro: GyroCalibration
    accel: AccelCalibration
    mag: MagCalibration | None
    gyro_noise: SensorNoise | None
    accel_noise: SensorNoise | None
    mag_noise: SensorNoise | None
    notes: list[str] = field(default_factory=list)
    handling: HandlingOffset | None = None  # None: no rest phase, or too few slow movement windows
    lever_arm: LeverArmFit | None = None  # None: no position track, or too few movement windows


def identify_trial(data: TrialData, settings: TrialSettings | None = None) -> TrialIdentification:
    """Identify one recording (module notes). Raises ``ValueError`` when a fit has nothing to work on."""
    settings = settings if settings is not None else TrialSettings()
    notes: list[str] = []
    if settings.rest_intervals:
        rest = phases_from_intervals(data.t, settings.rest_intervals)
    else:
        rest = find_rest_phases(data.t, data.gyro, data.accel)
    if not rest:
        notes.append("no rest phase found: noise terms not identified (give rest intervals)")
    has_mag = data.mag is not None and bool(np.isfinite(data.mag).any())
    kw = {"search_s": settings.search_s, "mask": data.valid}
    lat_g = gyro_latency(data.t, data.gyro, data.truth_t, data.q_wb, **kw)
    lat_a = accel_latency(data.t, data.accel, data.truth_t, data.q_wb, data.pos_w, settings.gravity_m_s2, **kw)
    lat_m = mag_latency(data.t, data.mag, data.truth_t, data.q_wb, **kw) if data.mag is not None and has_mag else None
    for what, lat in (("gyro", lat_g), ("accelerometer", lat_a), ("magnetometer", lat_m)):
        if lat is not None and lat.at_edge:
            notes.append(f"{what} latency at the edge of the ±{settings.search_s:g} s search: a bound, not a fit")
    earth = None if settings.earth_rate_w is None else np.asarray(settings.earth_rate_w)
    if earth is None and data.latitude_rad is not None:  # the recording's own site
        earth = earth_rate_enu(data.latitude_rad)
    if earth is None:
        notes.append("the site's latitude is not known (give it): the gyro bias holds the Earth's rate, up to 15 °/h")
    gyro = fit_gyro(
        data.t,
        data.gyro,
        data.truth_t,
        data.q_wb,
        lat_g.latency_s,
        window_s=settings.window_s,
        earth_rate_w=earth,
        mask=data.valid,
    )
    accel = fit_accel(
        data.t,
        data.accel,
        data.truth_t,
        data.q_wb,
        lat_a.latency_s,
        pos_w=data.pos_w,
        gravity_m_s2=settings.gravity_m_s2,
        c_sb=gyro.c_sb,
        window_s=settings.window_s,
        mask=data.valid,
    )
    mag = None
    if has_mag:
        assert data.mag is not None and lat_m is not None
        mag = fit_mag(
            data.t,
            data.mag,
            data.truth_t,
            data.q_wb,
            lat_m.latency_s,
            c_sb=gyro.c_sb,
            window_s=settings.window_s,
            mask=data.valid,
        )
    segments = [slice(p.start, p.stop) for p in rest]
    at_rest = np.zeros(len(data.t), dtype=bool)
    for seg in segments:
        at_rest[seg] = True
    valid = np.ones(len(data.t), dtype=bool) if data.valid is None else np.asarray(data.valid, dtype=bool)
    moving = np.ones(len(data.t), dtype=bool) if data.movement is None else np.asarray(data.movement, dtype=bool)
    moving = moving & ~at_rest & valid
    handling = None
    if rest:
        try:
            handling = handling_offset(
                data.t,
                data.accel,
                data.truth_t,
                data.q_wb,
                lat_a.latency_s,
                at_rest & valid,
                moving,
                pos_w=data.pos_w,
                gravity_m_s2=settings.gravity_m_s2,
                c_sb=gyro.c_sb,
                window_s=settings.window_s,
            )
        except ValueError as e:
            notes.append(f"handling offset not measured: {e}")
    lever_arm = None
    if data.pos_w is not None:
        try:
            lever_arm = fit_lever_arm(
                data.t,
                data.accel,
                data.gyro,
                data.truth_t,
                data.q_wb,
                data.pos_w,
                lat_a.latency_s,
                moving,
                gyro_bias=gyro.bias,
                c_sb=gyro.c_sb,
                gravity_m_s2=settings.gravity_m_s2,
                window_s=settings.window_s,
            )
        except ValueError as e:
            notes.append(f"lever arm not fitted: {e}")
    gyro_noise = sensor_noise([data.gyro[s] for s in segments], data.dt) if rest else None
    accel_noise = sensor_noise([data.accel[s] for s in segments], data.dt) if rest else None
    mag_noise = None
    if rest and has_mag:
        assert data.mag is not None
        mag_noise = sensor_noise([data.mag[s] for s in segments], data.dt, tau_min_s=settings.mag_tau_min_s)
    return TrialIdentification(
        name=data.name,
        samples=len(data.t),
        rate_hz=1.0 / data.dt,
        rest=rest,
        gyro_latency=lat_g,
        accel_latency=lat_a,
        mag_latency=lat_m,
        gyro=gyro,
        accel=accel,
        mag=mag,
        gyro_noise=gyro_noise,
        accel_noise=accel_noise,
        mag_noise=mag_noise,
        notes=notes,
        handling=handling,
        lever_arm=lever_arm,
    )
