"""``gyroemu identify``: fit a device config (and a site's magnetic environment and handling offset) to
recordings.

Each log is adapted to :class:`gyroemu.pipelines.identification.TrialData` (plain arrays):

- ``.mcap``: its device's ``/imu``, ``/mag`` (tesla) and ``/truth/imu`` attitude, the ``/movement``
  flags when present, and the ``/truth/pose`` position when the log has it; otherwise position is
  unavailable;
- ``.hdf5``: a BROAD trial, read directly, with its ``opt_pos`` (m) as the position track.

The logs are identified together (:func:`gyroemu.pipelines.identification.identify`) and the device
TOML (and with ``site_out`` the site snippet) written atomically: through a temporary file in the same
folder renamed at the end (:mod:`gyroemu.pipelines.formats.atomic`), never over an existing file
without ``force``. Every option is checked
before any work (:class:`IdentifyError`, naming the argument).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.atomic import output_file_problem, write_text_atomic
from gyroemu.pipelines.formats.file_names import repeated_file, same_file

if TYPE_CHECKING:
    from gyroemu.pipelines.identification import Identification, TrialData

__all__ = [
    "GRAVITY_RANGE_M_S2",
    "IdentifyError",
    "IdentifyOptions",
    "IdentifySummary",
    "check_options",
    "read_trial",
    "run_identify",
]

_SUFFIXES = (".mcap", ".hdf5", ".h5")

GRAVITY_RANGE_M_S2 = (9.7, 9.9)
"""The ``gravity_m_s2`` :func:`check_options` takes: gravity anywhere a recording is made on Earth, with
room. Normal gravity is 9.780 at the equator and 9.832 at the poles; height lowers it 0.003 per km
(9.77 on Everest's summit, 9.74 at an airliner's 12 km, 9.70 at 25 km), anomalies move it by
0.003 at most. The fit takes a gravity error for the accelerometers' scale factor (``TrialSettings``),
so a value outside is a slip (98.1, 0.981, 1 in g, 32.2 in ft/s²) that would scale every accelerometer
figure written by the ratio; gyroemu's sites are the Earth's (WGS 84 normal gravity), so another
planet's is refused as well."""


class IdentifyError(ConfigError):
    """Bad options of ``gyroemu identify``, found before any work (the message names the argument)."""


@dataclass(frozen=True)
class IdentifyOptions:
    """What ``gyroemu identify`` reads and writes.

    Attributes
    ----------
    logs : the recordings (.mcap with a /truth/imu attitude, or BROAD .hdf5), one device, pooled.
    out : the device TOML to write.
    site_out : the site TOML snippet to write (magnetic environment, handling offset), or None.
    force : overwrite existing outputs.
    rest_intervals : [(t_start, t_stop), …] s of every log (from its first sample), or None to find the
        rest phases.
    gravity_m_s2 : local gravity, m/s² (:data:`GRAVITY_RANGE_M_S2`).
    latitude_deg : the site's latitude of every log, for the Earth's rate the gyro measures with the
        motion, or None: each log's own site's (a gyroemu log's), else unknown (that log's gyro bias then
        holds the Earth's rate, 15 °/h at most, and a note says so).
    """

    logs: Sequence[Path]
    out: Path
    site_out: Path | None = None
    force: bool = False
    rest_intervals: Sequence[tuple[float, float]] | None = None
    gravity_m_s2: float = 9.81
    latitude_deg: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "logs", tuple(Path(p) for p in self.logs))
        object.__setattr__(self, "out", Path(self.out))
        if self.site_out is not None:
            object.__setattr__(self, "site_out", Path(self.site_out))


@dataclass(frozen=True)
class IdentifySummary:
    """What an identify run did: the files written, the pooled figures, and the seconds it took."""

    out: Path
    site_out: Path | None
    logs: tuple[str, ...]
    gyro_latency_ms: float | None  # None: at the search's edge in every log (a bound, not written)
    mag_latency_ms: float | None  # None: no field, or at the search's edge
    gyro_noise_density_deg_per_s_per_sqrt_hz: tuple[float, ...] | None
    elapsed_s: float
    notes: list[str] = field(default_factory=list)


def _check_out(path: Path, argument: str, force: bool, logs: Sequence[Path]) -> None:
    if path.suffix != ".toml":
        raise IdentifyError(f"argument {argument}: {path}: write a .toml file (got '{path.suffix}')")
    problem = output_file_problem(path, force=force, inputs=logs)
    if problem is not None:
        raise IdentifyError(f"argument {argument}: {problem}")


def check_options(options: IdentifyOptions) -> None:
    """:class:`IdentifyError` for a missing or unreadable log, an output that cannot be written or would
    be overwritten without ``force``, bad rest intervals."""
    if not options.logs:
        raise IdentifyError("argument LOG: give at least one log")
    for log in options.logs:
        if not log.is_file():
            raise IdentifyError(f"argument LOG: {log}: {'not a file' if log.exists() else 'no such file'}")
        if log.suffix not in _SUFFIXES:
            raise IdentifyError(f"argument LOG: {log}: expected an .mcap log or a BROAD .hdf5 trial")
    twice = repeated_file(options.logs)
    if twice is not None:  # pooled as two, one recording's noise would count twice (every σ / sqrt(2))
        first, again = twice
        alias = "" if str(first) == str(again) else f" (as {first})"
        raise IdentifyError(f"argument LOG: {again} is given twice{alias}: give each recording once")
    _check_out(options.out, "--out", options.force, options.logs)
    if options.site_out is not None:
        _check_out(options.site_out, "--site-out", options.force, options.logs)
        if same_file(options.site_out, options.out):
            raise IdentifyError("argument --site-out: the same file as --out")
    for a, b in options.rest_intervals or ():
        if not (math.isfinite(a) and math.isfinite(b)):
            raise IdentifyError(f"argument --rest: {a:g}:{b:g}: expected finite seconds")
        if not a < b:
            raise IdentifyError(f"argument --rest: {a:g}:{b:g}: start must be before stop")
    low, high = GRAVITY_RANGE_M_S2
    if not low <= options.gravity_m_s2 <= high:
        raise IdentifyError(
            f"argument --gravity: local gravity in m/s^2, from {low:g} to {high:g} (the Earth's, 9.78 at the "
            f"equator to 9.83 at the poles, less with height), got {options.gravity_m_s2:g}"
        )
    if options.latitude_deg is not None and not -90.0 <= options.latitude_deg <= 90.0:
        raise IdentifyError(f"argument --latitude: must lie in [-90, 90] degrees, got {options.latitude_deg:g}")


def _check_samples(count: int, path: Path) -> None:
    """``LogError`` naming ``path`` for a recording of fewer than two samples: no sample interval, so
    every fit would divide by NaN."""
    if count < 2:
        from gyroemu.errors import LogError

        raise LogError(f"holds {count} sample(s): identify needs a recording of many", file=path)


def read_trial(path: Path) -> TrialData:
    """A log as :class:`TrialData` (module notes). Raises ``LogError``/``ConfigError`` naming the file."""
    import numpy as np

    from gyroemu.errors import LogError
    from gyroemu.pipelines.identification import TrialData

    path = Path(path)
    if path.suffix in (".hdf5", ".h5"):
        import h5py

        from gyroemu.pipelines.formats.importers import read_broad

        trial = read_broad(path)
        _check_samples(len(trial), path)
        t = np.arange(len(trial)) / trial.rate_hz
        with h5py.File(path, "r") as f:
            pos = np.asarray(f["opt_pos"][()], dtype=float) if "opt_pos" in f else None
        return TrialData(
            name=path.name,
            t=t,
            gyro=trial.gyro,
            accel=trial.accel,
            mag=trial.mag_ut * 1e-6,
            truth_t=t,
            q_wb=trial.opt_quat,
            pos_w=pos,
            movement=trial.movement,
        )
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    try:
        log = read_mcap(path).device
    except ValueError as e:  # its message may name the file already
        reason = str(e).removeprefix(f"{path}: ")
        raise LogError(reason, file=path) from None
    truth = log.truth
    if truth is None or truth.q_wb is None:
        raise LogError("has no /truth/imu attitude to identify against", file=path)
    s = log.samples
    _check_samples(len(s.t), path)
    from gyroemu.pipelines.estimation.series import check_samples

    check_samples(path, log.name, s.t, s.gyro, s.accel)  # stamps that do not increase, or NaN everywhere
    mag = s.mag if s.mag is not None and np.isfinite(s.mag).any() else None
    # Seconds from the log's first sample: the samples' exactly (float seconds since the epoch resolve
    # 0.24 µs, which would skew the rate written), the truth's and pose's to 0.24 µs.
    t = log.seconds_from_first()
    origin = float(s.t[0])
    pos, truth_t, q = None, truth.t - origin, truth.q_wb
    if log.pose is not None:  # /truth/pose, at its own stamps
        from gyroemu.pipelines.identification.truth import interpolate_vectors

        pos = interpolate_vectors(log.pose.t - origin, log.pose.pos_w, truth_t)
    latitude = None
    if log.metadata:
        from gyroemu.pipelines.estimation.setup import setup_from_metadata

        latitude = setup_from_metadata(log.metadata, 1.0 / float(np.median(np.diff(t))), use_mag=False).latitude_rad
    return TrialData(
        name=path.name,
        t=t,
        gyro=s.gyro,
        accel=s.accel,
        mag=mag,
        truth_t=truth_t,
        q_wb=q,
        pos_w=pos,
        movement=log.movement,
        latitude_rad=latitude,
    )


def identify_logs(options: IdentifyOptions) -> Identification:
    """Read and identify the logs of ``options`` (no files written)."""
    from gyroemu.dynamics.earth import earth_rate_enu
    from gyroemu.pipelines.identification import TrialSettings, identify

    trials = [read_trial(p) for p in options.logs]
    # --latitude for every log; without it each log's own site's (a gyroemu log), or none (identify_trial)
    earth = None if options.latitude_deg is None else tuple(earth_rate_enu(math.radians(options.latitude_deg)))
    settings = TrialSettings(
        rest_intervals=options.rest_intervals, gravity_m_s2=options.gravity_m_s2, earth_rate_w=earth
    )
    try:
        return identify(trials, settings)
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"cannot identify: {e}", file=", ".join(str(p) for p in options.logs)) from None


def run_identify(options: IdentifyOptions) -> IdentifySummary:
    """Identify the logs and write ``options.out`` (and ``site_out``). Raises :class:`IdentifyError` before
    any work for bad options; ``LogError``/``ConfigError`` for a log that cannot be used."""
    check_options(options)
    started = time.perf_counter()
    result = identify_logs(options)
    site = result.site_toml() if options.site_out is not None else None
    write_text_atomic(options.out, result.device_toml())
    notes = list(result.notes)
    if options.site_out is not None:
        if site is None:
            notes.append("no magnetometer environment: --site-out not written")
        else:
            write_text_atomic(options.site_out, site)
    gyro, mag = (None if s in result.latency_bounds else result.latency.get(s) for s in ("gyro", "magnetometer"))
    noise = result.gyro_noise
    return IdentifySummary(
        out=options.out,
        site_out=options.site_out if site is not None else None,
        logs=tuple(str(p) for p in options.logs),
        gyro_latency_ms=None if gyro is None else float(gyro.value) * 1e3,
        mag_latency_ms=None if mag is None else float(mag.value) * 1e3,
        gyro_noise_density_deg_per_s_per_sqrt_hz=None
        if noise is None
        else tuple(float(v) * 57.29577951308232 for v in noise.values("noise_density")),
        elapsed_s=time.perf_counter() - started,
        notes=notes,
    )
