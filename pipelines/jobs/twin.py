"""``gyroemu twin``: a recording with truth beside its emulated twins, through the attitude filters.

A **twin** of a recording is its own recorded motion sensed by an emulated device in the modelled
field of a site. The motion is the recording's truth as the ``recorded`` scenario kind smooths it
(:mod:`gyroemu.pipelines.recorded_scenario`), its attitude first refined by the recording's own gyro
above :data:`TWIN_GYRO_CROSSOVER_HZ` and held still in the rest phases (:func:`twin_attitude`); the
twins are scored against the recording's truth, as the recording is. Twin ``i`` of a recording draws
its device, its magnetic environment and its handling offset from :func:`twin_seed` of ``i`` and the
recording's file name, so that the twins of different recordings draw independently (with seed ``i``
alone, twin ``i`` of every recording had the same noise at the same time from power-up, and pooling
their rests pooled one draw).

Inputs: a BROAD trial (``.hdf5``: IMU, magnetometer in µT, optical attitude and position, ``movement``
mask) or a gyroemu MCAP log (one device with ``/imu``, ``/truth/imu`` and usually ``/truth/pose``; its
``/movement`` mask when it has one, otherwise every sample counts).

Times. The recorded scenario's time 0 is the recording's first valid truth sample, at stamp ``t0``
(``scenario.spec.motion().t0``) in the recording's clock (BROAD: ``k / sampling_rate``; MCAP: the stamps
less the first truth stamp). A twin sample taken at true instant ``t`` corresponds to the real time
``t + t0``; the real trial's movement mask and rest phase are carried over to the twin by the nearest
real sample.

Handling. The site file's optional ``[handling]`` table (``accel_offset_m_s2``,
``accel_offset_sigma_m_s2``; written by ``gyroemu identify --site-out``,
:mod:`gyroemu.pipelines.identification.handling`) is the accelerometer's offset against the truth while
the device is carried, relative to at rest. Each twin draws one offset, mean + sd · N(0, 1) per axis
from its own generator (``[twin seed, HANDLING_STREAM]``, so the device's draws are the same with or without
it), and adds it to its accelerometer over the recording's movement mask; a recording without a
movement mask gets none.

Filters. Each filter runs 9D (with the magnetometer, when both the recording and the device have one)
and 6D, with the **same** :class:`FilterSetup` on the real log and on its twins: what ``gyroemu bench``
uses for the real log (``setup_from_metadata`` of an MCAP log; the defaults at the file's rate for a
BROAD trial, as ``tests/benchmarks/broad_filters.py``). Magnetometers go to the filters in tesla (BROAD's
µT × 1e-6). Errors are BROAD's (:mod:`gyroemu.pipelines.estimation.metrics`): RMSE, degrees, over the
movement samples with a finite reference.

Residuals. Measured minus truth, over the rest phases of the real recording
(:func:`gyroemu.pipelines.identification.find_rest_phases`, each trimmed to the reference; else the
samples before the first movement sample), pooled: real gyro and accelerometer minus the log's truth
rate and specific force when it has them (an MCAP log), else minus 0 and the still body's ``R_bw (0, 0, g)`` (BROAD);
twin gyro and accelerometer minus the trajectory's truth at the instants they measured (the sample's
instant minus the sensor's latency). Their Allan deviations per axis at τ from
0.01 to 10 s (those a phase holds twice; the phases' Allan variances weighted by their clusters), the
twin's (RMS over seeds) over the real's per τ, and Welch spectra (averaged over the phases). (At rest
the real body is still: its truth is taken as ω = 0 and the phase's mean of ``R_bw (0, 0, g)``; the
optical attitude sample by sample is dominated by its noise there: several °/s differentiated, and
an Allan bump near τ = 1 s seen through gravity.)

Outputs in ``--out``: ``twin.md``, ``twin.json`` and ``<trial>.png`` (Allan deviations and spectra, real
against twin), each written through a temporary file. An existing non-empty folder is refused without
``force``. Every option is checked before any work (:class:`TwinError`, naming the argument); the runs
(the real log and each twin, every filter) go to ``workers`` processes.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import time
import tomllib
import warnings
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from gyroemu.errors import ConfigError

__all__ = [
    "METRICS",
    "RANKED_FILTERS",
    "TAUS_S",
    "TwinError",
    "TwinOptions",
    "TwinReport",
    "check_options",
    "twin_attitude",
    "twin_seed",
    "default_site_file",
    "run_twin",
    "residual_allan",
]

METRICS = ("total_9d", "heading_9d", "inclination_9d", "inclination_6d")
RANKED_FILTERS = ("mekf", "vqf", "madgwick", "mahony")
TAUS_S = np.logspace(-2, 1, 16)
GRAVITY_M_S2 = 9.81
_SUFFIXES = {".hdf5": "broad", ".h5": "broad", ".mcap": "mcap"}


class TwinError(ConfigError):
    """Bad options of ``gyroemu twin``, found before any work (the message names the argument)."""


TWIN_SMOOTHING = {"orientation_cutoff_hz": 20.0, "position_cutoff_hz": 10.0}
"""The twins' smoothing of the recorded motion, one setting for every trial. The attitude the twins
sense is the reference refined by the recording's own gyro above :data:`TWIN_GYRO_CROSSOVER_HZ`
(:func:`twin_attitude`), whose noise is far below the reference's, so its cut-off can sit at 20 Hz:
the real gyro sees the motion's 5–15 Hz content (on trial 02, 20.7 °/s RMS in movement). The
position's is 10 Hz: an optical reference resampled to the IMU's rate has noise that is not white at
that rate, so GCV leaves it almost unsmoothed (143 Hz on BROAD's trial 07) and the twins' accelerometer
would sense the noise as motion (0.5–9 m/s²); the real accelerometer's movement power reaches 7–20 Hz
(99 %), and at 3 Hz the twins lose the linear acceleration that the accelerometer-led filters suffer.
README, "The twin", lists the settings tried."""
TWIN_GYRO_CROSSOVER_HZ = 1.0
"""Below it the twins' attitude follows the optical reference, above it the recording's gyro
(:func:`gyroemu.dynamics.attitude_fusion.complementary_attitude`); the figures sit on a plateau from
0.5 to 2 Hz (README, "The twin")."""
HANDLING_STREAM = 0x68616E64  # the handling offset's generator: [seed, this] ("hand")


def default_site_file() -> Path:
    """The built-in site of the BROAD lab: ``configs/sites/broad_lab.toml``."""
    from gyroemu.dynamics.config import config_dir

    return Path(config_dir()) / "sites" / "broad_lab.toml"


@dataclass(frozen=True)
class TwinOptions:
    """What ``gyroemu twin`` reads and writes.

    Attributes
    ----------
    trials : recordings with truth (BROAD ``.hdf5`` or gyroemu ``.mcap``).
    device : the emulated device (built-in name or TOML path).
    seeds : number of twins per trial (seeds 0 … seeds − 1).
    filters : filter names (default: every available built-in).
    out : folder for ``twin.md``, ``twin.json`` and the plots.
    force : write into an existing non-empty folder.
    site : TOML file whose ``[site]`` table is the twins' site (and whose optional ``[handling]`` table
        is the accelerometer's offset while carried, module notes).
    workers : processes for the runs (1: in this process).
    smoothing : the recorded scenario's ``[smoothing]`` table (default :data:`TWIN_SMOOTHING`).
    """

    trials: Sequence[Path]
    device: str = "aktos_t_broad"
    seeds: int = 5
    filters: Sequence[str] | None = None
    out: Path = Path("twin")
    force: bool = False
    site: Path = field(default_factory=default_site_file)
    workers: int = 2
    smoothing: dict | None = None

    def __post_init__(self) -> None:
        if self.smoothing is None:
            object.__setattr__(self, "smoothing", dict(TWIN_SMOOTHING))
        object.__setattr__(self, "trials", tuple(Path(p) for p in self.trials))
        object.__setattr__(self, "out", Path(self.out))
        object.__setattr__(self, "site", Path(self.site))
        if self.filters is not None:
            object.__setattr__(self, "filters", tuple(dict.fromkeys(self.filters)))


# ==================================================================================================
# Checking and loading (before any work)


@dataclass
class _Real:
    """A real recording, as the filters and the residuals need it (times in the motion's clock)."""

    name: str
    path: Path
    format: str
    t: np.ndarray  # (N,) s, recording clock (BROAD k/fs; MCAP stamps − first truth stamp)
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray | None  # tesla
    q_true: np.ndarray  # (N, 4), NaN rows without reference
    mask: np.ndarray  # (N,) bool: samples that count
    rate_hz: float
    metadata: dict | None
    counted: str
    omega_true: np.ndarray | None = None  # (N, 3) rad/s, a log's /truth/imu rate
    force_true: np.ndarray | None = None  # (N, 3) m/s², a log's /truth/imu specific force


def check_options(options: TwinOptions) -> tuple[list[str], dict, dict, _Handling | None, Any]:
    """:class:`TwinError` for any bad option. Returns the filters, those left out, the site table, the
    site's handling offset (None without a ``[handling]`` table) and the device (seed 0)."""
    from gyroemu.pipelines.estimation.registry import FilterError, available_filters, filter_class, unavailable_filters
    from gyroemu.sensors import load_device

    if not options.trials:
        raise TwinError("argument TRIAL: give at least one recording")
    for trial in options.trials:
        if not trial.is_file():
            raise TwinError(f"argument TRIAL: {trial}: no such file")
        if trial.suffix.lower() not in _SUFFIXES:
            raise TwinError(f"argument TRIAL: {trial}: expected a BROAD .hdf5 trial or a gyroemu .mcap log")
    if isinstance(options.seeds, bool) or not isinstance(options.seeds, int) or options.seeds < 1:
        raise TwinError(f"argument --seeds: must be a whole number of at least 1, got {options.seeds!r}")
    if isinstance(options.workers, bool) or not isinstance(options.workers, int) or options.workers < 1:
        raise TwinError(f"argument --workers: must be a whole number of at least 1, got {options.workers!r}")
    unavailable: dict = {}
    if options.filters is None:
        filters = available_filters()
        unavailable = unavailable_filters()
    else:
        filters = list(options.filters)
        if not filters:
            raise TwinError("argument --filter: give at least one filter")
        for spec in filters:
            try:
                filter_class(spec)
            except FilterError as e:
                raise TwinError(f"argument --filter: {e}") from None
    try:
        device = load_device(options.device, seed=0)
    except ConfigError as e:
        raise TwinError(f"argument --device: {e}") from None
    site, handling = _read_site(options.site)
    out = options.out
    if out.exists():
        if not out.is_dir():
            raise TwinError(f"argument --out: {out} is not a folder")
        if any(out.iterdir()) and not options.force:
            raise TwinError(f"argument --out: {out} is not empty (use --force to write into it)")
    elif not out.parent.is_dir() and out.parent != Path(""):
        raise TwinError(f"argument --out: {out.parent} is not a folder")
    return filters, unavailable, site, handling, device


def _check_smoothing(smoothing: dict | None, real: _Real) -> None:
    """:class:`TwinError` naming ``--smoothing`` for a key the recorded scenario's ``[smoothing]`` does not
    take, a bad value, or a cut-off at or above the Nyquist frequency of the truth's stamps (the motion
    is fitted there; found otherwise only when the first twin fits its motion, after the real run)."""
    from pydantic import ValidationError

    from gyroemu.pipelines.recorded_scenario import SmoothingSpec

    try:
        spec = SmoothingSpec(**(smoothing or {}))
    except ValidationError as e:
        problems = "; ".join(f"{'.'.join(map(str, err['loc']))}: {err['msg']}" for err in e.errors())
        raise TwinError(f"argument --smoothing: {problems}") from None
    from gyroemu.dynamics.smoothing_spline import lambda_for_cutoff

    # the recorded motion is fitted at the truth's stamps, which may be sparser than the samples': the
    # cut-off is checked as the fit will check it, against their median step
    truth_t = real.t[np.isfinite(real.q_true).all(axis=1)]
    step = float(np.median(np.diff(truth_t))) if len(truth_t) > 1 else 1.0 / real.rate_hz
    for key in ("position_cutoff_hz", "orientation_cutoff_hz"):
        value = getattr(spec, key)
        if value is not None:
            try:
                lambda_for_cutoff(value, step)
            except ValueError as e:
                raise TwinError(f"argument --smoothing: {key}: {real.path.name}: {e}") from None


def _read_site(path: Path) -> tuple[dict, _Handling | None]:
    """The site file's ``[site]`` table and its optional ``[handling]`` (errors name the file and key)."""
    from gyroemu.dynamics.earth import Site

    if not path.is_file():
        raise TwinError(f"argument --site: {path}: no such file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise TwinError(f"argument --site: {path}: {e}") from None
    site = data.get("site")
    if not isinstance(site, dict):
        raise TwinError(f"argument --site: {path}: has no [site] table")
    env = site.get("magnetic_environment")
    if env is not None and not isinstance(env, dict):
        raise TwinError(f"argument --site: {path}: [site.magnetic_environment] is not a table")
    try:
        Site.model_validate(_site_with_seed(site, 0))
    except Exception as e:  # noqa: BLE001 - pydantic's ValidationError, named
        raise TwinError(f"argument --site: {path}: {e}") from None
    return site, _read_handling(data.get("handling"), path)


@dataclass(frozen=True)
class _Handling:
    """``[handling]`` of the site file: the accelerometer's offset while the device is carried (the
    recording's movement) against at rest, m/s² in sensor axes; each twin draws one (module notes)."""

    accel_offset: np.ndarray  # (3,) mean
    accel_offset_sigma: np.ndarray  # (3,) standard deviation between handlings

    def draw(self, seed: int) -> np.ndarray:
        """(3,) m/s², twin ``seed``'s offset: its own generator, so the device's draws are untouched."""
        rng = np.random.default_rng([seed, HANDLING_STREAM])
        return self.accel_offset + self.accel_offset_sigma * rng.standard_normal(3)


def _read_handling(table: object, path: Path) -> _Handling | None:
    """The site file's optional ``[handling]`` table ``table`` (errors name the file and the key)."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise TwinError(f"argument --site: {path}: [handling] is not a table")
    unknown = set(table) - {"accel_offset_m_s2", "accel_offset_sigma_m_s2"}
    if unknown:
        raise TwinError(f"argument --site: {path}: [handling] has unknown keys {sorted(unknown)}")
    values = []
    for key in ("accel_offset_m_s2", "accel_offset_sigma_m_s2"):
        v = table.get(key, [0.0, 0.0, 0.0])
        numbers = isinstance(v, list) and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ok = numbers and len(v) == 3
        arr = np.asarray(v, dtype=float) if ok else np.full(3, np.nan)
        if not ok or not np.isfinite(arr).all() or (key.endswith("sigma_m_s2") and (arr < 0).any()):
            what = "three non-negative numbers" if key.endswith("sigma_m_s2") else "three finite numbers"
            raise TwinError(f"argument --site: {path}: [handling] {key} must be {what}, got {v!r}")
        values.append(arr)
    return _Handling(values[0], values[1])


def _fmt3(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def twin_seed(seed: int, recording: str) -> int:
    """The seed of twin ``seed`` of the recording whose file is named ``recording``: the first word of
    ``SeedSequence([seed, crc32(recording)])``, the device's, the magnetic environment's and the handling
    offset's seed (each draws from its own streams of it)."""
    return int(np.random.SeedSequence([seed, zlib.crc32(recording.encode())]).generate_state(1, np.uint64)[0])


def twin_attitude(
    real_t: np.ndarray,
    q_ref: np.ndarray,
    gyro: np.ndarray,
    rests: Sequence[tuple[float, float]],
    delay_s: float,
    q_bs: Sequence[float] | np.ndarray,
    crossover_hz: float = TWIN_GYRO_CROSSOVER_HZ,
) -> np.ndarray:
    """The attitude the twins of a recording sense, (N, 4) at the recording's samples (NaN before its
    reference starts): the reference ``q_ref`` below ``crossover_hz`` and the recording's own ``gyro``
    (sensor axes, rad/s, lagging the reference by ``delay_s``: the device's latency plus half a sample,
    what its interval means add; turned into body axes by the mounting ``q_bs``) above it, each where it
    is the better measurement (:func:`gyroemu.dynamics.attitude_fusion.complementary_attitude`). In the
    ``rests`` (``(start, stop)`` stretches of ``real_t``) the body is still: held at the stretch's mean, so
    that neither the reference's noise nor the gyro's is sensed as motion there."""
    from gyroemu.dynamics.attitude_fusion import complementary_attitude
    from gyroemu.dynamics.rotation import quat_normalize, quat_rotate

    t = np.asarray(real_t, float)
    gyro = np.asarray(gyro, float)
    read = np.isfinite(gyro).all(axis=1)  # a missing gyro sample is bridged, not integrated as NaN
    omega_s = np.stack([np.interp(t + delay_s, t[read], gyro[read, c]) for c in range(3)], axis=1)
    q = complementary_attitude(t, q_ref, quat_rotate(np.asarray(q_bs, float), omega_s), crossover_hz)
    valid = np.isfinite(np.asarray(q_ref, float)).all(axis=1)
    q[~valid] = np.nan  # where the recording has no reference, neither has its motion
    for start, stop in rests:
        inside = (t >= start) & (t <= stop) & valid
        if inside.any():
            held = q[inside] * np.sign(q[inside] @ q[inside][0])[:, None]  # one hemisphere
            q[inside] = quat_normalize(held.mean(axis=0))
    return q


def _site_with_seed(site: dict, seed: int) -> dict:
    out = dict(site)
    env = dict(out.get("magnetic_environment") or {})
    if env:
        env["seed"] = seed
        out["magnetic_environment"] = env
    return out


def _scenario(real: _Real, site: dict, seed: int, smoothing: dict | None = None):
    from gyroemu.dynamics.scenarios import scenario_from_dict

    data = {"kind": "recorded", "path": str(real.path), "format": real.format, "site": _site_with_seed(site, seed)}
    if smoothing:
        data["smoothing"] = dict(smoothing)
    return scenario_from_dict(data, name=real.name)


def _load_real(path: Path) -> _Real:
    """A recording (errors name the file)."""
    fmt = _SUFFIXES[path.suffix.lower()]
    if fmt == "broad":
        from gyroemu.pipelines.formats.importers import read_broad

        trial = read_broad(path)
        t = np.arange(len(trial)) / trial.rate_hz
        mask = np.asarray(trial.movement, bool)
        return _Real(
            name=path.name,
            path=path,
            format=fmt,
            t=t,
            gyro=np.asarray(trial.gyro, float),
            accel=np.asarray(trial.accel, float),
            mag=np.asarray(trial.mag_ut, float) * 1e-6,
            q_true=np.asarray(trial.opt_quat, float),
            mask=mask if mask.any() else np.ones(len(t), bool),
            rate_hz=float(trial.rate_hz),
            metadata=None,
            counted="movement mask" if mask.any() else "every sample",
        )
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    log = read_mcap(path)
    if len(log.devices) != 1:
        raise TwinError(f"argument TRIAL: {path}: holds {len(log.devices)} devices; a twin needs exactly one")
    dev = log.device
    if dev.truth is None or dev.truth.q_wb is None:
        raise TwinError(f"argument TRIAL: {path}: has no /truth/imu attitude")
    s = dev.samples
    tt = np.asarray(dev.truth.t, float)
    t = np.asarray(s.t, float)
    # the motion file's clock (read_mcap_motion): from the first truth stamp, exactly where the truth is
    # at the samples' stamps (float seconds since the epoch resolve 0.24 µs: a 1 kHz log read 1000.07 Hz)
    clock = dev.seconds_from_first() if np.array_equal(tt, t) else t - tt[0]
    dt = float(np.median(np.diff(clock)))
    j = np.clip(np.searchsorted(tt, t), 1, len(tt) - 1)
    j = np.where(np.abs(tt[j - 1] - t) <= np.abs(tt[j] - t), j - 1, j)
    hit = np.abs(tt[j] - t) <= 0.25 * dt
    q_true = np.full((len(t), 4), np.nan)
    q_true[hit] = dev.truth.q_wb[j[hit]]
    extra = {}
    for key, attr in (("omega_true", "omega_b"), ("force_true", "specific_force_b")):
        v = getattr(dev.truth, attr, None)
        if v is not None and np.isfinite(v).any():
            extra[key] = np.full((len(t), 3), np.nan)
            extra[key][hit] = np.asarray(v, float)[j[hit]]
    movement = getattr(dev, "movement", None)
    has_mask = movement is not None and np.asarray(movement, bool).any()
    mag = np.asarray(s.mag, float)
    return _Real(
        name=path.name,
        path=path,
        format=fmt,
        t=clock,
        gyro=np.asarray(s.gyro, float),
        accel=np.asarray(s.accel, float),
        mag=mag if np.isfinite(mag).all(axis=1).any() else None,
        q_true=q_true,
        mask=np.asarray(movement, bool) if has_mask else np.ones(len(t), bool),
        rate_hz=1.0 / dt,
        metadata=dev.metadata,
        counted="movement mask" if has_mask else "every sample",
        **extra,
    )


# ==================================================================================================
# One run: the real log or one twin, every filter, and its residuals at rest


def _filter_errors(filters, setup9, setup6, t, gyro, accel, mag, q_true, mask, timings) -> dict:
    """{filter: {metric: RMSE deg or None}} and wall times in ``timings``."""
    from gyroemu.pipelines.estimation.metrics import attitude_errors, rmse_deg
    from gyroemu.pipelines.estimation.registry import make_filter

    counted = mask & np.isfinite(q_true).all(axis=1)
    out: dict[str, dict] = {}
    for spec in filters:
        row: dict[str, Any] = dict.fromkeys(METRICS)
        row["error"] = None
        for mode, setup in (("9d", setup9), ("6d", setup6)):
            if setup is None:
                continue
            started = time.perf_counter()
            try:
                est = make_filter(spec, setup).process(t, gyro, accel, mag if mode == "9d" else None)
                q = np.asarray(est.q_wb, float)
                if q.shape != (len(t), 4):
                    raise ValueError(f"returned q_wb of shape {q.shape}")
            except Exception as exc:  # noqa: BLE001 - a failing filter is reported, not fatal
                row["error"] = f"{mode}: {type(exc).__name__}: {exc}"
                continue
            finally:
                timings[f"filter {spec} {mode}"] = timings.get(f"filter {spec} {mode}", 0.0) + (
                    time.perf_counter() - started
                )
            with np.errstate(invalid="ignore", divide="ignore"):
                err = attitude_errors(q, q_true)
            if mode == "9d":
                row["total_9d"] = rmse_deg(err.total, counted)
                row["heading_9d"] = rmse_deg(err.heading, counted)
                row["inclination_9d"] = rmse_deg(err.inclination, counted)
            else:
                row["inclination_6d"] = rmse_deg(err.inclination, counted)
        out[spec] = row
    return out


def residual_allan(segments: list[np.ndarray], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(len(TAUS_S), 3) Allan deviation per axis at TAUS_S, pooled over the segments (each (n_i, 3)): the
    Allan variances weighted by their clusters, as :func:`gyroemu.pipelines.identification.pooled_allan`
    does (NaN where every segment is shorter than 2 τ); and the clusters behind each value."""
    from gyroemu.sensors.allan import allan_deviation

    avar = np.zeros((len(TAUS_S), 3))
    clusters = np.zeros((len(TAUS_S), 3))
    for x in segments:
        taus = TAUS_S[(TAUS_S >= dt) & (TAUS_S <= 0.5 * len(x) * dt)]
        if len(x) < 8 or not len(taus):
            continue
        for axis in range(3):
            a = allan_deviation(x[:, axis] - np.mean(x[:, axis]), dt, taus=taus)
            for tau, adev, n in zip(a.tau, a.adev, a.clusters):
                i = int(np.argmin(np.abs(np.log(TAUS_S / tau))))
                if abs(math.log(TAUS_S[i] / tau)) < 0.1:
                    avar[i, axis] += n * adev**2
                    clusters[i, axis] += n
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(clusters > 0, np.sqrt(avar / np.maximum(clusters, 1)), np.nan), clusters


def _spectrum(segments: list[np.ndarray], fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch spectrum per axis averaged over the segments, weighted by their lengths."""
    from scipy.signal import welch

    shortest = min(len(x) for x in segments)
    nper = int(min(shortest, 2 ** int(math.log2(max(8.0, 2.0 * fs)))))
    total, weight, f = None, 0, np.zeros(0)
    for x in segments:
        f, p = welch(x - x.mean(axis=0), fs=fs, nperseg=nper, axis=0)
        total = p * len(x) if total is None else total + p * len(x)
        weight += len(x)
    return f, (total / weight if total is not None else np.zeros((0, 3)))


def _residuals(gyro_res: list[np.ndarray], accel_res: list[np.ndarray], fs: float) -> dict:
    """Allan deviations, spectra and standard deviations of the residuals over the rest segments."""
    gs, acs = [], []
    for g, a in zip(gyro_res, accel_res):
        ok = np.isfinite(g).all(axis=1) & np.isfinite(a).all(axis=1)
        if ok.sum() >= 16:
            gs.append(g[ok])
            acs.append(a[ok])
    out: dict[str, Any] = {"samples": int(sum(len(x) for x in gs))}
    for key, xs in (("gyro", gs), ("accel", acs)):
        out[f"{key}_adev"], out[f"{key}_clusters"] = residual_allan(xs, 1.0 / fs)
        if xs:
            out[f"{key}_psd_f"], out[f"{key}_psd"] = _spectrum(xs, fs)
            out[f"{key}_std"] = np.std(np.concatenate([x - x.mean(axis=0) for x in xs]), axis=0)
        else:
            out[f"{key}_psd_f"], out[f"{key}_psd"] = np.zeros(0), np.zeros((0, 3))
            out[f"{key}_std"] = np.full(3, np.nan)
    return out


def _run_real(real: _Real, filters, setup9, setup6, rests: list[slice]) -> dict:
    from gyroemu.pipelines.identification.truth import rotation_bw

    timings: dict[str, float] = {}
    errors = _filter_errors(
        filters, setup9, setup6, real.t, real.gyro, real.accel, real.mag, real.q_true, real.mask, timings
    )
    started = time.perf_counter()
    # At rest the body is still: the truth is ω = 0 (Earth's rate, ≤ 0.0042 °/s, is constant: no Allan
    # or spectral content) and a constant f, R_bw (0, 0, g) averaged over the phase. The optical
    # attitude sample by sample would be its noise: differentiated, several °/s; seen through gravity,
    # 2.9·10⁻³ m/s² at τ ≈ 1 s on y, an Allan bump the raw accelerometer does not have (README, "The
    # twin"). A log's own truth rate and specific force are used when it has them.
    gyro_res, accel_res = [], []
    for rest in rests:
        q = real.q_true[rest]
        omega = np.zeros((len(q), 3)) if real.omega_true is None else real.omega_true[rest]
        if real.force_true is None:
            gravity_b = np.einsum("nij,j->ni", rotation_bw(q), np.array([0.0, 0.0, GRAVITY_M_S2]))
            force = np.broadcast_to(np.nanmean(gravity_b, axis=0), gravity_b.shape)
        else:
            force = real.force_true[rest]
        gyro_res.append(real.gyro[rest] - omega)
        accel_res.append(real.accel[rest] - force)
    res = _residuals(gyro_res, accel_res, real.rate_hz)
    timings["residuals"] = time.perf_counter() - started
    return {"errors": errors, "residuals": res, "timings": timings}


def _run_twin(
    real: _Real,
    site: dict,
    smoothing,
    device_name: str,
    seed: int,
    filters,
    setup9,
    setup6,
    rest_t,
    attitude=None,
    handling=None,
) -> dict:
    from gyroemu.sensors import load_device
    from gyroemu.sensors.sampling import SensorTruth

    timings: dict[str, float] = {}
    started = time.perf_counter()
    seed = twin_seed(seed, real.name)
    scenario = _scenario(real, site, seed, smoothing)
    device = load_device(device_name, seed=seed)
    if attitude is not None:  # the recording's twin attitude (:func:`twin_attitude`), the same for every seed
        scenario.spec.replace_attitude(real.t, attitude)
    t0 = float(scenario.spec.motion().t0)
    timings["scenario (load, fit)"] = time.perf_counter() - started
    started = time.perf_counter()
    traj = scenario.simulate(rate_hz=device.spec.rate_hz)
    timings["simulate"] = time.perf_counter() - started
    started = time.perf_counter()
    samples = device.measure(traj)
    timings["measure"] = time.perf_counter() - started
    started = time.perf_counter()
    body = SensorTruth(traj)  # the trajectory's interpolants, for the truth at τ and at τ − latency
    instants = np.asarray(samples.t_true if samples.t_true is not None else samples.t, float)
    timings["truth"] = time.perf_counter() - started
    # The real trial's mask, by the nearest real sample to each twin instant (real time = t + t0).
    real_time = instants + t0
    k = np.clip(np.searchsorted(real.t, real_time), 1, len(real.t) - 1)
    k = np.where(np.abs(real.t[k - 1] - real_time) <= np.abs(real.t[k] - real_time), k - 1, k)
    inside = (real_time >= real.t[0] - 0.5 / real.rate_hz) & (real_time <= real.t[-1] + 0.5 / real.rate_hz)
    mask = real.mask[k] & inside
    t = np.asarray(samples.t, float)
    # Carried, the accelerometer reads against the truth otherwise than at rest ([handling] of the site
    # file, identified between the rest phases and the movement): the offset applies over the recording's
    # movement mask (a recording without one does not say when the device was carried: none).
    accel = np.asarray(samples.accel, float)
    offset = None
    if handling is not None and real.counted == "movement mask":
        offset = handling.draw(seed)
        accel = accel + np.where(mask[:, None], offset, 0.0)
    mag: np.ndarray | None = np.asarray(samples.mag, float) if samples.mag is not None else None
    if mag is not None and not np.isfinite(mag).all(axis=1).any():
        mag = None
    # Scored as the real log is, against the recording's reference (the nearest sample): its noise is in
    # the real errors, so it is in the twins' (their motion is the reference refined by the gyro).
    reference = np.where(inside[:, None], real.q_true[k], np.nan)
    errors = _filter_errors(
        filters,
        setup9 if mag is not None else None,
        setup6,
        t,
        samples.gyro,
        accel,
        mag,
        reference,
        mask,
        timings,
    )
    started = time.perf_counter()
    # The sensor's error: measured minus the truth at the instant each sensor measured, τ − latency (at
    # rest the real truth is still, and so is the twins' motion, held at its mean there).
    lat_gyro, lat_accel, _ = device.latencies
    span = (float(traj.t[0]), float(traj.t[-1]))
    omega_at = body.body_truth(np.clip(instants - lat_gyro, *span))[1]
    force_at = body.body_truth(np.clip(instants - lat_accel, *span))[2]
    gyro_res, accel_res = [], []
    for start, stop in rest_t:
        at_rest = (real_time >= start) & (real_time <= stop)
        gyro_res.append(samples.gyro[at_rest] - omega_at[at_rest])
        accel_res.append(samples.accel[at_rest] - force_at[at_rest])
    res = _residuals(gyro_res, accel_res, float(device.spec.rate_hz))
    timings["residuals"] = time.perf_counter() - started
    return {
        "errors": errors,
        "residuals": res,
        "timings": timings,
        "t0": t0,
        "samples": len(t),
        "counted": int(mask.sum()),
        "handling_offset": None if offset is None else [float(x) for x in offset],
    }


def _task(payload: tuple) -> tuple[tuple, dict]:
    key, fn, args = payload
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        started = time.perf_counter()
        out = fn(*args)
        out["wall_s"] = time.perf_counter() - started
    return key, out


# ==================================================================================================
# Report


def _finite(x) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _list(a: np.ndarray, digits: int = 6) -> list:
    return [_list(v, digits) if np.ndim(v) else _finite(float(f"{v:.{digits}g}")) for v in np.asarray(a)]


@dataclass
class TrialResult:
    """One recording beside its twins."""

    name: str
    source: dict
    mode: str
    rate_hz: float
    twin_rate_hz: float
    t0_s: float
    rest: dict
    filters: list[dict]
    ranking: dict
    residuals: dict
    curves: dict  # for the plot: real and twin Allan deviations and spectra
    notes: list[str] = field(default_factory=list)


@dataclass
class TwinReport:
    """What :func:`run_twin` found."""

    trials: list[TrialResult]
    settings: dict
    timings: dict
    notes: list[str] = field(default_factory=list)
    pooled_residuals: dict | None = None

    def to_dict(self) -> dict:
        return {
            "gyroemu_twin": 1,
            "settings": self.settings,
            "definitions": {
                "errors": "BROAD: q_err = q_est ⊗ conj(q_true); total 2 acos|w|, heading 2 atan|z/w|, "
                "inclination 2 acos sqrt(w²+z²); RMSE in degrees over the movement samples with a finite "
                "reference (twins: the real mask at the nearest real sample, real time = twin time + t0)",
                "twin": "mean, std (ddof 1), n over the seeds whose run gave a finite value; values per seed",
                "ratio": "twin mean / real",
                "ranking": f"order of {', '.join(RANKED_FILTERS)} by 9D total RMSE, real and twin mean; "
                "unresolved: pairs whose paired seed differences are not significant (Student t, 5 %); "
                "same_within_spread: every pair the twin swaps is unresolved",
                "residuals": "measured − truth over the rest phases, pooled; Allan deviation per axis (x, y, z) "
                "at tau_s, twin: RMS over seeds; ratio twin/real per tau and axis; psd_ratio: median over "
                "1 Hz … rate/4 of the twin's mean Welch spectrum over the real's, per axis",
            },
            "timings_s": self.timings,
            "notes": self.notes,
            "residuals_pooled": None
            if self.pooled_residuals is None
            else {
                k: (_list(v) if k == "tau_s" else {name: _list(arr) for name, arr in v.items()})
                for k, v in self.pooled_residuals.items()
            },
            "trials": [
                {
                    "name": tr.name,
                    "source": tr.source,
                    "mode": tr.mode,
                    "rate_hz": tr.rate_hz,
                    "twin_rate_hz": tr.twin_rate_hz,
                    "t0_s": tr.t0_s,
                    "rest": tr.rest,
                    "filters": tr.filters,
                    "ranking": tr.ranking,
                    "residuals": tr.residuals,
                    "notes": tr.notes,
                }
                for tr in self.trials
            ],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, ensure_ascii=False, allow_nan=False)

    def to_markdown(self) -> str:
        s = self.settings
        lines = [
            "# gyroemu twin",
            "",
            f"Device `{s['device']}`, {s['seeds']} twin(s) per recording (twin i's device, magnetic environment "
            f"and handling seeded by twin_seed(i, file name), i = 0…{s['seeds'] - 1}), site `{s['site']}`. "
            "Twin: mean ± standard deviation over the seeds; "
            "ratio: twin mean / real. RMSE in degrees (BROAD's definitions) over the movement samples.",
            "",
        ]
        for tr in self.trials:
            lines += [f"## {tr.name} ({tr.mode})", ""]
            lines.append(
                "| filter | 9D total real | 9D total twin | ratio | 9D heading real | 9D heading twin | ratio "
                "| 9D inclination real | 9D inclination twin | ratio | 6D inclination real | 6D inclination twin "
                "| ratio |"
            )
            lines.append("|---|" + "---|" * 12)
            for fr in tr.filters:
                cells = [fr["filter"]]
                for m in METRICS:
                    real = fr["real"][m]
                    tw = fr["twin"][m]
                    cells.append("—" if real is None else f"{real:.2f}")
                    if tw["mean"] is None:
                        cells.append("—")
                    else:
                        cells.append(f"{tw['mean']:.2f} ± {tw['std']:.2f}" if tw["n"] > 1 else f"{tw['mean']:.2f}")
                    cells.append("—" if fr["ratio"][m] is None else f"{fr['ratio'][m]:.2f}")
                lines.append("| " + " | ".join(cells) + " |")
            lines.append("")
            rk = tr.ranking
            if rk["same"] is None:
                lines.append(f"Ranking by 9D total: not available ({rk.get('why', '')}).")
            else:
                if rk["same"]:
                    verdict = "**same**."
                elif rk["same_within_spread"]:
                    verdict = "**differs** within the seeds' spread (every swapped pair unresolved at 5 %)."
                else:
                    verdict = "**differs** beyond the seeds' spread."
                lines.append(
                    f"Ranking by 9D total: real {' < '.join(rk['real'])}; twin {' < '.join(rk['twin'])} — " + verdict
                )
            rest = tr.rest
            lines.append("")
            spans = ", ".join(f"{a:.2f}…{b:.2f}" for a, b in rest["intervals_s"])
            lines.append(
                f"Residuals at rest ({rest['source']}: {spans} s of the recording, "
                f"{rest['real_samples']} real samples):"
            )
            lines.append("")
            lines.append(
                "| sensor | real std (x, y, z) | twin std (x, y, z) | Allan ratio twin/real min … max "
                "| PSD ratio (x, y, z) |"
            )
            lines.append("|---|---|---|---|---|")
            for key, unit in (("gyro", "°/s"), ("accel", "m/s²")):
                r = tr.residuals[key]
                scale = math.degrees(1.0) if key == "gyro" else 1.0

                def fmt(v, scale=scale):
                    return "—" if v is None else f"{v * scale:.3g}"

                ratio = (
                    "—"
                    if r["ratio_min"] is None
                    else f"{r['ratio_min']:.2f} … {r['ratio_max']:.2f} (τ {r['tau_min_s']:.2g}…{r['tau_max_s']:.2g} s)"
                )
                psd = ", ".join("—" if v is None else f"{v:.2f}" for v in r["psd_ratio"])
                lines.append(
                    f"| {key} | {', '.join(fmt(v) for v in r['real_std'])} {unit} | "
                    f"{', '.join(fmt(v) for v in r['twin_std'])} {unit} | {ratio} | {psd} |"
                )
            for n in tr.notes:
                lines.append(f"- {n}")
            lines.append("")
        if self.pooled_residuals is not None and len(self.trials) > 1:
            lines += [f"## Residuals at rest, pooled over the {len(self.trials)} recordings", ""]
            lines += [
                "| sensor | Allan ratio twin/real min … max, τ 0.01…10 s | real clusters at 10 s |",
                "|---|---|---|",
            ]
            for key in ("gyro", "accel"):
                r = self.pooled_residuals[key]
                pooled_ratio = np.asarray(r["ratio"], dtype=float)
                kept = pooled_ratio[np.isfinite(pooled_ratio)]
                span = f"{kept.min():.2f} … {kept.max():.2f}" if kept.size else "—"
                lines.append(f"| {key} | {span} | {int(np.min(r['real_clusters'][-1]))} |")
            lines.append("")
        lines.append(
            "Timings (s, summed over processes): " + ", ".join(f"{k} {v:.1f}" for k, v in self.timings.items())
        )
        if self.notes:
            lines += ["", "Notes:"] + [f"- {n}" for n in self.notes]
        return "\n".join(lines) + "\n"

    def save_plots(self, directory) -> list[Path]:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from gyroemu.pipelines.formats.atomic import write_figure_atomic
        from gyroemu.pipelines.formats.file_names import unique_stems

        directory = Path(directory)
        written = []
        for tr, stem in zip(self.trials, unique_stems([Path(t.name).stem for t in self.trials])):
            fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
            colours = ("C0", "C1", "C2")
            for col, (key, unit, scale) in enumerate((("gyro", "°/s", math.degrees(1.0)), ("accel", "m/s²", 1.0))):
                c = tr.curves[key]
                ax = axes[0, col]
                for axis in range(3):
                    ax.loglog(
                        TAUS_S, c["real_adev"][:, axis] * scale, "-", color=colours[axis], label=f"real {'xyz'[axis]}"
                    )
                    ax.loglog(
                        TAUS_S, c["twin_adev"][:, axis] * scale, "--", color=colours[axis], label=f"twin {'xyz'[axis]}"
                    )
                ax.set_title(f"{key} residual at rest: Allan deviation")
                ax.set_xlabel("τ, s")
                ax.set_ylabel(unit)
                ax.grid(True, which="both", alpha=0.3)
                ax.legend(fontsize=7, ncol=2)
                ax = axes[1, col]
                for axis in range(3):
                    if len(c["real_f"]):
                        ax.semilogy(c["real_f"], c["real_psd"][:, axis] * scale**2, "-", color=colours[axis], lw=0.8)
                    if len(c["twin_f"]):
                        ax.semilogy(c["twin_f"], c["twin_psd"][:, axis] * scale**2, "--", color=colours[axis], lw=0.8)
                ax.set_title(f"{key} residual at rest: spectrum (solid real, dashed twin)")
                ax.set_xlabel("Hz")
                ax.set_ylabel(f"({unit})²/Hz")
                ax.grid(True, which="both", alpha=0.3)
            fig.suptitle(f"{tr.name}: real vs twin ({self.settings['device']}, {self.settings['seeds']} seeds)")
            fig.tight_layout()
            path = directory / f"{stem}.png"
            written.append(write_figure_atomic(fig, path, dpi=100))
        return written

    def save(self, directory) -> dict:
        """``twin.md``, ``twin.json`` and the plots in ``directory`` (made if missing); their paths."""
        from gyroemu.pipelines.formats.atomic import write_text_atomic

        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        paths: dict[str, Any] = {"markdown": directory / "twin.md", "json": directory / "twin.json"}
        write_text_atomic(paths["json"], self.to_json())
        write_text_atomic(paths["markdown"], self.to_markdown())
        paths["plots"] = self.save_plots(directory)
        return paths


def _summary(values: list) -> dict:
    finite = [float(v) for v in values if v is not None and math.isfinite(v)]
    return {
        "mean": float(np.mean(finite)) if finite else None,
        "std": float(np.std(finite, ddof=1)) if len(finite) > 1 else None,  # ddof 1: none for one value
        "n": len(finite),
        "values": [_finite(v) for v in values],
    }


def _rank(values: dict) -> list[str]:
    return sorted(values, key=lambda f: values[f])


def _discordant_pairs(real: list[str], twin: list[str]) -> list[list[str]]:
    """Pairs ``[a, b]`` (``a`` before ``b`` on the real ranking) that the twin ranking orders the other way."""
    return [[a, b] for i, a in enumerate(real) for b in real[i + 1 :] if twin.index(a) > twin.index(b)]


def _unresolved_pairs(real: list[str], means: dict, seeds: dict) -> list[list[str]]:
    """Pairs of filters whose twin mean 9D totals the seeds cannot tell apart: the seeds share their
    data, so the paired differences ``d_s`` are tested, ``|mean d| < t_{0.975, n−1} · sd(d)/√n``
    (Student's t, two-sided 5 %). Listed in the real ranking's order."""
    from scipy.stats import t as student_t

    out = []
    for i, a in enumerate(real):
        for b in real[i + 1 :]:
            d = np.array([x - y for x, y in zip(seeds[a], seeds[b], strict=True) if x is not None and y is not None])
            if len(d) < 2:
                out.append([a, b])  # one seed cannot order them
                continue
            bound = float(student_t.ppf(0.975, len(d) - 1)) * float(np.std(d, ddof=1)) / np.sqrt(len(d))
            if abs(float(np.mean(d))) < bound:
                out.append([a, b])
    return out


def _trial_result(real: _Real, real_run: dict, twins: list[dict], filters, mode, rest, seeds, twin_rate) -> TrialResult:
    rows = []
    for spec in filters:
        r = real_run["errors"][spec]
        tw = {m: _summary([tr["errors"][spec][m] for tr in twins]) for m in METRICS}
        ratio = {
            m: (tw[m]["mean"] / r[m] if tw[m]["mean"] is not None and _finite(r[m]) and r[m] > 0 else None)
            for m in METRICS
        }
        errs = [e for e in [r.get("error")] + [tr["errors"][spec].get("error") for tr in twins] if e]
        rows.append(
            {
                "filter": spec,
                "real": {m: _finite(r[m]) for m in METRICS},
                "twin": tw,
                "ratio": ratio,
                "errors": errs,
            }
        )
    ranked = [f for f in RANKED_FILTERS if f in filters]
    ranking: dict[str, Any] = {
        "filters": ranked,
        "real": None,
        "twin": None,
        "same": None,
        "same_within_spread": None,
        "unresolved": [],
    }
    if mode != "9D":
        ranking["why"] = "6D only"
    elif len(ranked) < 2:
        ranking["why"] = f"fewer than two of {', '.join(RANKED_FILTERS)}"
    else:
        by = {row["filter"]: row for row in rows}
        real_v = {f: by[f]["real"]["total_9d"] for f in ranked}
        twin_v = {f: by[f]["twin"]["total_9d"]["mean"] for f in ranked}
        if any(v is None for v in real_v.values()) or any(v is None for v in twin_v.values()):
            ranking["why"] = "a filter without a 9D total"
        else:
            ranking.update(real=_rank(real_v), twin=_rank(twin_v))
            ranking["same"] = ranking["real"] == ranking["twin"]
            seeds_9d = {f: by[f]["twin"]["total_9d"]["values"] for f in ranked}
            ranking["unresolved"] = _unresolved_pairs(ranking["real"], twin_v, seeds_9d)
            discordant = _discordant_pairs(ranking["real"], ranking["twin"])
            ranking["same_within_spread"] = all(pair in ranking["unresolved"] for pair in discordant)
    residuals: dict[str, Any] = {"tau_s": _list(TAUS_S, 4)}
    curves: dict[str, Any] = {}
    rr = real_run["residuals"]
    for key in ("gyro", "accel"):
        real_adev = rr[f"{key}_adev"]
        twin_adev = _rms_over_seeds([t["residuals"][f"{key}_adev"] for t in twins])
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = twin_adev / real_adev
        ok = np.isfinite(ratio)
        taus_ok = TAUS_S[ok.any(axis=1)]
        psd_ratio: list[float | None] = [None, None, None]
        f_real, p_real = rr[f"{key}_psd_f"], rr[f"{key}_psd"]
        twin_p = [t["residuals"][f"{key}_psd"] for t in twins if len(t["residuals"][f"{key}_psd_f"])]
        f_twin = twins[0]["residuals"][f"{key}_psd_f"]
        p_twin = np.mean(np.stack(twin_p), axis=0) if twin_p and all(len(p) == len(twin_p[0]) for p in twin_p) else None
        if len(f_real) and p_twin is not None:
            band = (f_real >= 1.0) & (f_real <= min(real.rate_hz, twin_rate) / 4)  # within both Nyquists
            if band.any():
                interp = np.stack([np.interp(f_real[band], f_twin, p_twin[:, a]) for a in range(3)], axis=1)
                with np.errstate(invalid="ignore", divide="ignore"):
                    psd_ratio = [_finite(v) for v in np.median(interp / p_real[band], axis=0)]
        residuals[key] = {
            "unit": "rad/s" if key == "gyro" else "m/s²",
            "real_adev": _list(real_adev),
            "twin_adev": _list(twin_adev),
            "ratio": _list(ratio, 4),
            "ratio_min": _finite(np.min(ratio[ok])) if ok.any() else None,
            "ratio_max": _finite(np.max(ratio[ok])) if ok.any() else None,
            "tau_min_s": _finite(taus_ok.min()) if len(taus_ok) else None,
            "tau_max_s": _finite(taus_ok.max()) if len(taus_ok) else None,
            "real_std": _list(rr[f"{key}_std"]),
            "twin_std": _list(np.mean(np.stack([t["residuals"][f"{key}_std"] for t in twins]), axis=0)),
            "psd_ratio": psd_ratio,
        }
        curves[key] = {
            "real_adev": real_adev,
            "twin_adev": twin_adev,
            "real_f": f_real,
            "real_psd": p_real,
            "twin_f": f_twin if p_twin is not None else np.zeros(0),
            "twin_psd": p_twin if p_twin is not None else np.zeros((0, 3)),
        }
    rest = dict(rest)
    rest["real_samples"] = int(rr["samples"])
    rest["twin_samples"] = [int(t["residuals"]["samples"]) for t in twins]
    notes = [
        f"real: {int(real.mask.sum())} samples counted ({real.counted}); twins: "
        + ", ".join(str(t["counted"]) for t in twins)
    ]
    drawn = [t.get("handling_offset") for t in twins]
    if any(d is not None for d in drawn):
        notes.append(
            "handling offsets over the movement, m/s² (x, y, z) per seed: "
            + "; ".join("none" if d is None else _fmt3(np.asarray(d)) for d in drawn)
        )
    for row in rows:
        for e in row["errors"]:
            notes.append(f"{row['filter']} failed: {e}")
    return TrialResult(
        name=real.name,
        source={
            "path": str(real.path),
            "format": real.format,
            "seeds": list(range(seeds)),
            "twin_seeds": [twin_seed(i, real.name) for i in range(seeds)],
        },
        mode=mode,
        rate_hz=real.rate_hz,
        twin_rate_hz=twin_rate,
        t0_s=float(twins[0]["t0"]),
        rest=rest,
        filters=rows,
        ranking=ranking,
        residuals=residuals,
        curves=curves,
        notes=notes,
    )


def _rest_phases(real: _Real) -> tuple[list[slice], dict]:
    """The rest phases of the real recording with a reference (each trimmed to it, at least 64 samples):
    (their samples, a description). The rest detector's threshold is relative to the recording's
    quietest stretch, so in a recording with a movement mask a phase is also trimmed to its longest run
    outside the mask (a recording that moves throughout has quiet motion, not rest). Without any, the
    samples before the first movement sample stand in for the residuals (``intervals_s``), but only
    phases found still are held still in the twins (``still_s``). A recording that moves from its first
    sample has none: its residuals are then taken over the whole recording if it has its own truth rate
    and specific force (a simulated log: the sensor's output less the truth, in motion as at rest, the
    real side at the stamp, so a latency L adds ω̇ L there), and not at all otherwise (rest's truth,
    ω = 0 and constant gravity, would be the motion itself)."""
    from gyroemu.pipelines.identification import find_rest_phases

    valid = np.isfinite(real.q_true).all(axis=1)
    if real.counted == "movement mask":
        valid &= ~real.mask
    rests = []
    for p in find_rest_phases(real.t, real.gyro, real.accel):
        run = _longest_run(valid[p.start : p.stop])  # the phase's span with a reference (and still)
        if run is not None and run[1] - run[0] >= 64:
            rests.append(slice(p.start + run[0], p.start + run[1]))
    if rests:
        intervals = [(float(real.t[r.start]), float(real.t[r.stop - 1])) for r in rests]
        return rests, {"source": f"{len(rests)} rest phase(s)", "intervals_s": intervals, "still_s": intervals}
    first = np.flatnonzero(real.mask)
    stop = int(first[0]) if len(first) else len(real.t)
    source = "samples before the first movement sample"
    if stop == 0:
        if real.omega_true is None or real.force_true is None:
            return [], {"source": "none: the recording moves from its first sample", "intervals_s": [], "still_s": []}
        stop, source = len(real.t), "the whole recording, less its own truth (it moves from its first sample)"
    idx = np.flatnonzero(np.isfinite(real.q_true).all(axis=1)[:stop])
    if not len(idx):
        return [], {"source": "none: no reference before the first movement sample", "intervals_s": [], "still_s": []}
    start = int(idx[0])
    return [slice(start, stop)], {
        "source": source,
        "intervals_s": [(float(real.t[start]), float(real.t[stop - 1]))],
        "still_s": [],  # not found still: the twins' motion is not held there
    }


def _longest_run(flags: np.ndarray) -> tuple[int, int] | None:
    """(start, stop) of the longest run of True in ``flags`` (the first of equal ones); None without any."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], flags.astype(np.int8), [0]))))
    if not len(edges):
        return None
    starts, stops = edges[0::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])


def run_twin(options: TwinOptions) -> TwinReport:
    """Run the real recordings and their twins through the filters (module notes) and return the report
    (:meth:`TwinReport.save` writes it).

    Raises
    ------
    TwinError
        A bad option, named, before any work (also a recording that cannot be read or has no truth).
    """
    from gyroemu.pipelines.estimation.protocol import FilterSetup
    from gyroemu.pipelines.estimation.setup import setup_from_metadata

    started = time.perf_counter()
    filters, unavailable, site, handling, device = check_options(options)
    reals: list[_Real] = []
    for path in options.trials:
        try:
            real = _load_real(path)
            _check_smoothing(options.smoothing, real)
            _scenario(real, site, 0, options.smoothing)  # the recorded motion reads and checks
        except TwinError:
            raise
        except ConfigError as e:
            raise TwinError(f"argument TRIAL: {e}") from None
        except Exception as e:  # noqa: BLE001 - LogError and friends: the file at fault
            raise TwinError(f"argument TRIAL: {path}: {e}") from None
        reals.append(real)
    timings: dict[str, float] = {"load and check": time.perf_counter() - started}
    has_dev_mag = device.spec.magnetometer is not None
    plans = []
    tasks: list[tuple[Any, Any, Any]] = []
    for i, real in enumerate(reals):
        mode = "9D" if real.mag is not None and has_dev_mag else "6D"
        setup9: FilterSetup | None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if real.metadata:
                setup9 = setup_from_metadata(real.metadata, real.rate_hz, use_mag=True)
                setup6 = setup_from_metadata(real.metadata, real.rate_hz, use_mag=False)
            else:
                setup9, setup6 = FilterSetup(rate_hz=real.rate_hz, use_mag=True), FilterSetup(rate_hz=real.rate_hz)
        if mode == "6D":
            setup9 = None
        # the twins are sampled at the device's rate: their filters are told it (the same setup otherwise)
        twin9 = None if setup9 is None else replace(setup9, rate_hz=float(device.spec.rate_hz))
        twin6 = replace(setup6, rate_hz=float(device.spec.rate_hz))
        rests, rest_info = _rest_phases(real)
        plans.append((mode, rest_info))
        tasks.append(((i, None), _run_real, (real, filters, setup9, setup6, rests)))
        rest_t = rest_info["intervals_s"]
        attitude_started = time.perf_counter()
        delay = device.latencies[0] + 0.5 / device.spec.rate_hz  # an interval mean lags by half a sample
        attitude = twin_attitude(
            real.t, real.q_true, real.gyro, rest_info["still_s"], delay, device.spec.mounting.q_bs
        )  # one device, one attitude: the seeds draw only the device's errors and the site
        timings["twin attitude"] = timings.get("twin attitude", 0.0) + time.perf_counter() - attitude_started
        for seed in range(options.seeds):
            tasks.append(
                (
                    (i, seed),
                    _run_twin,
                    (
                        real,
                        site,
                        options.smoothing,
                        options.device,
                        seed,
                        filters,
                        twin9,
                        twin6,
                        rest_t,
                        attitude,
                        handling,
                    ),
                )
            )
    results: dict[tuple, dict] = {}
    run_started = time.perf_counter()
    workers = min(options.workers, len(tasks))
    if workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # Heaviest first (the real run and the twins cost alike): plain order is fine.
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as pool:
            for key, out in pool.map(_task, tasks):
                results[key] = out
    else:
        for task in tasks:
            key, out = _task(task)
            results[key] = out
    timings["runs (wall)"] = time.perf_counter() - run_started
    for out in results.values():
        for k, v in out["timings"].items():
            timings[k] = timings.get(k, 0.0) + v
    trials = []
    for i, real in enumerate(reals):
        mode, rest_info = plans[i]
        twins = [results[(i, s)] for s in range(options.seeds)]
        trials.append(
            _trial_result(real, results[(i, None)], twins, filters, mode, rest_info, options.seeds, device.spec.rate_hz)
        )
    timings["total"] = time.perf_counter() - started
    settings = {
        "device": options.device,
        "seeds": options.seeds,
        "filters": filters,
        "site": str(options.site),
        "workers": workers,
        "smoothing": dict(options.smoothing or {}),
        "trials": [str(p) for p in options.trials],
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    notes = [f"{name} left out: {why}" for name, why in unavailable.items()]
    notes.append(
        "filter setup: the same for the real log and its twins (the log's gyroemu metadata, else the "
        "filters' defaults at the recording's rate, as gyroemu bench does)"
    )
    if handling is not None:
        notes.append(
            "handling: over each recording's movement mask every twin's accelerometer reads an offset drawn "
            f"from N({_fmt3(handling.accel_offset)}, sd {_fmt3(handling.accel_offset_sigma)}) m/s² "
            "(the site file's [handling], seeded by the twin's seed; a recording without a movement mask: none)"
        )
    timings = {k: round(v, 3) for k, v in timings.items()}
    pooled = _pooled_residuals(
        [results[(i, None)] for i in range(len(reals))],
        [[results[(i, seed)] for i in range(len(reals))] for seed in range(options.seeds)],
    )
    return TwinReport(trials=trials, settings=settings, timings=timings, notes=notes, pooled_residuals=pooled)


def _pool_adev(runs: list[dict], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Allan deviation (len(TAUS_S), 3) pooled over runs (their variances weighted by clusters), clusters."""
    avar = np.zeros((len(TAUS_S), 3))
    clusters = np.zeros((len(TAUS_S), 3))
    for run in runs:
        adev, n = run["residuals"][f"{key}_adev"], run["residuals"][f"{key}_clusters"]
        ok = np.isfinite(adev)
        avar[ok] += n[ok] * adev[ok] ** 2
        clusters += np.where(ok, n, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(clusters > 0, np.sqrt(avar / np.maximum(clusters, 1)), np.nan), clusters


def _rms_over_seeds(values: list[np.ndarray]) -> np.ndarray:
    """The RMS over the seeds (the list) of the finite values, element by element; NaN where no seed has
    one (a recording without rest: no residuals), as ``nanmean`` but without its warning."""
    squares = np.stack(values) ** 2
    finite = np.isfinite(squares)
    count = finite.sum(axis=0)
    mean = np.where(finite, squares, 0.0).sum(axis=0) / np.maximum(count, 1)
    return np.where(count > 0, np.sqrt(mean), np.nan)


def _pooled_residuals(real_runs: list[dict], twin_runs_by_seed: list[list[dict]]) -> dict:
    """The residual Allan deviations at rest pooled over every recording's rest phases, real and twin
    (RMS over seeds), their ratio per τ and axis, and the real clusters behind each τ."""
    out: dict[str, Any] = {"tau_s": TAUS_S}
    for key in ("gyro", "accel"):
        real, clusters = _pool_adev(real_runs, key)
        twins = [_pool_adev(runs, key)[0] for runs in twin_runs_by_seed]
        twin = _rms_over_seeds(twins) if twins else np.full_like(real, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = twin / real
        out[key] = {"real_adev": real, "twin_adev": twin, "ratio": ratio, "real_clusters": clusters}
    return out


def cpu_workers() -> int:
    """Default worker count: 2, or 1 on a single core."""
    return max(1, min(2, os.cpu_count() or 1))
