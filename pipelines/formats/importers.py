"""Importers: recordings in other formats turned into gyroemu's MCAP contract (``gyroemu import``).

BROAD (``gyroemu import broad TRIAL.hdf5 --out trial.mcap``)
-----------------------------------------------------------
A trial of the Berlin Robust Orientation Estimation Assessment Dataset (D. Laidig, M. Caruso,
A. Cereatti, T. Seel, "BROAD - A Benchmark for Robust Inertial Orientation Estimation", Data 6(7),
2021; CC BY 4.0) is one HDF5 file holding, for N samples of a myon aktos-t IMU:

=============  =======  ==================================================================
dataset        shape    holds
=============  =======  ==================================================================
``imu_gyr``    (N, 3)   angular rate, rad/s
``imu_acc``    (N, 3)   specific force, m/s²
``imu_mag``    (N, 3)   magnetic field, µT
``opt_quat``   (N, 4)   optical reference: unit quaternion (w, x, y, z) of the IMU relative to
                        ENU, NaN rows where tracking was lost
``movement``   (N,)     bool: the samples over which the dataset's errors are computed
=============  =======  ==================================================================

and the attribute ``sampling_rate`` (Hz; 285.714 for every trial; refused outside 1 Hz … 100 kHz:
:data:`BROAD_RATE_RANGE_HZ` says why), and, in every published trial,
``opt_pos`` (N, 3), the optical reference's position of the IMU in m, NaN rows where lost (optional
here: a trial without it imports without ``/truth/pose``). The file is opened read-only and read whole
before anything is written. What is written (one device, ``imu0``, topics unprefixed):

- ``/imu``: ``imu_gyr`` and ``imu_acc`` unchanged (``orientation_covariance[0] = -1``).
- ``/mag``: ``imu_mag · 1e-6`` (tesla, the ROS unit).
- ``/truth/imu``: ``opt_quat`` as ``q_wb`` (NaN rows kept as NaN, covariance zeros = "unknown"); the
  true rate and specific force are not known, so they are written as "no estimate"
  (``covariance[0] = -1``) and read back as None (:class:`gyroemu.pipelines.formats.channels.ImuSeries`).
- ``/truth/pose``: ``opt_pos`` and ``opt_quat`` as ``geometry_msgs/msg/PoseStamped`` in the world
  frame ``map`` (ENU), NaN rows kept.
- ``/movement``: ``movement`` as ``gyroemu_msgs/msg/Flag`` (read back as ``DeviceLog.movement``).

**Time stamps.** BROAD's samples are equally spaced and carry no clock of their own, so sample k is
stamped ``t_k = k / sampling_rate`` from 0, rounded to the nearest nanosecond: ``rint(k·10⁹ / fs)``,
where ``k·10⁹`` is exact in float64 (for k < 4·10⁹) and the division correctly rounded, so each stamp
is within 0.5 ns (+ 10⁻⁴ ns) of the exact ``k / fs``. At 285.714… Hz (2000/7) the stamps are exactly
``k · 3.5 ms``. Every channel carries the same stamps.

The ``gyroemu`` metadata record holds, besides the writer's keys (``version``, ``seed`` and the
configs empty: no simulation), ``device_name`` ``imu0``, ``source`` (the file's name),
``source_format``, ``citation``, ``license``, ``sampling_rate_hz`` (the attribute, ``repr`` of the
float), ``time_stamps`` (the rule above) and ``source_info`` (the file's ``info`` attribute, when it
has one).

Bad input raises :class:`ImportInputError` (a :class:`gyroemu.dynamics.ConfigError`) naming the file and the
dataset or attribute at fault, and an output it cannot write :class:`ImportOutputError`, before the input
is read; the output is written through a temporary file renamed at the end
(:class:`gyroemu.pipelines.formats.mcap_log.McapLogWriter`), so a failure leaves nothing at ``out``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from gyroemu.dynamics import ConfigError
from gyroemu.pipelines.formats.atomic import output_file_problem
from gyroemu.pipelines.formats.channels import ImuSeries, PoseSeries
from gyroemu.pipelines.formats.mcap_log import Recording, write_mcap
from gyroemu.pipelines.formats.messages import ns_to_stamps
from gyroemu.sensors.samples import ImuSamples

if TYPE_CHECKING:
    import h5py

__all__ = [
    "ImportInputError",
    "ImportOutputError",
    "ImportSummary",
    "BroadTrial",
    "BROAD_CITATION",
    "BROAD_DATASETS",
    "BROAD_RATE_RANGE_HZ",
    "read_broad",
    "broad_stamps_ns",
    "broad_recording",
    "import_broad",
    "IMPORTERS",
]

BROAD_CITATION = (
    'D. Laidig, M. Caruso, A. Cereatti, T. Seel, "BROAD - A Benchmark for Robust Inertial '
    'Orientation Estimation", Data 6(7), 2021'
)
BROAD_LICENSE = "CC BY 4.0"
BROAD_DATASETS = {"imu_gyr": (3,), "imu_acc": (3,), "imu_mag": (3,), "opt_quat": (4,), "movement": ()}
"""The datasets an import reads, with the shape of one sample (every dataset has N rows)."""
BROAD_RATE_RANGE_HZ = (1.0, 100_000.0)
"""The ``sampling_rate`` a trial may give, Hz (BROAD's own is 285.714…, 2000/7): the rates of an IMU,
with room on both sides. Above 100 kHz no IMU samples (MEMS gyros' output rates top out at a few to
32 kHz, optical gyros' at a few kHz), and the stamps, whole nanoseconds, lose their meaning: at 100 kHz
a step is 10 µs and the stamp's rounding (≤ 0.5 ns) 5·10⁻⁵ of it, while at 10¹² Hz every step rounds to
0 and the samples share stamps no reader takes. Below 1 Hz an attitude filter integrating the gyro
over a step of more than a second of hand-held motion has nothing to follow, and the number is most
likely in another unit (a period of 0.0035 s, or 0.286 kHz, for BROAD's rate); at 10⁻⁶ Hz the stamps
``k·10⁹/fs`` overflow int64 nanoseconds after 9,223 samples. At ≥ 1 Hz they fit for 9.2·10⁹ samples
(a trial of about 1 TB read whole), so the bound also keeps every stamp in range."""


class ImportInputError(ConfigError):
    """A file an importer cannot use. ``file`` names it; ``item`` names the dataset or attribute at fault
    (``dataset 'imu_gyr'``, ``attribute 'sampling_rate'``) or is None for the file as a whole."""

    def __init__(self, reason: str, *, file: str | Path | None, item: str | None = None) -> None:
        self.item = item
        super().__init__(reason, file=file)

    def __str__(self) -> str:
        where = [w for w in (self.file, self.item) if w]
        return (": ".join(where) + ": " if where else "") + self.reason


class ImportOutputError(ConfigError):
    """An output file an importer cannot write (the message says why; the command line names ``--out``)."""


@dataclass(frozen=True)
class ImportSummary:
    """What an import wrote."""

    source: Path
    out: Path
    format: str
    samples: int
    rate_hz: float
    duration_s: float
    truth_nan_rows: int
    movement_samples: int
    sample_nan_rows: int = 0  # samples with a NaN in the gyro, accelerometer or magnetometer: dropouts, kept

    def __str__(self) -> str:
        dropouts = f", sensor NaN (dropouts, kept) in {self.sample_nan_rows} rows" if self.sample_nan_rows else ""
        return (
            f"{self.source.name} ({self.format}): {self.samples} samples at {self.rate_hz:.6g} Hz over "
            f"{self.duration_s:.6g} s, reference NaN in {self.truth_nan_rows} rows{dropouts}, movement in "
            f"{self.movement_samples} samples -> {self.out}"
        )


@dataclass(frozen=True, eq=False)
class BroadTrial:
    """A BROAD trial as stored (units of the file: µT for the magnetometer)."""

    path: Path
    gyro: NDArray[np.float64]  # (N, 3) rad/s
    accel: NDArray[np.float64]  # (N, 3) m/s²
    mag_ut: NDArray[np.float64]  # (N, 3) µT
    opt_quat: NDArray[np.float64]  # (N, 4) w, x, y, z; NaN rows
    movement: NDArray[np.bool_]  # (N,)
    rate_hz: float
    info: str = ""
    opt_pos: NDArray[np.float64] | None = None  # (N, 3) m; NaN rows

    def __len__(self) -> int:
        return len(self.gyro)


_MAX_EXPANSION = 64
"""A dataset may hold at most this many times the file's bytes (room for compression): a larger shape,
from a corrupt dataspace, would have the read allocate memory the file cannot fill."""


def _check_size(node: h5py.Dataset, path: Path, item: str) -> None:
    """Refuse a dataset whose shape asks for more bytes than the file could hold (:data:`_MAX_EXPANSION`)."""
    limit = _MAX_EXPANSION * path.stat().st_size + (1 << 20)
    if node.size * node.dtype.itemsize > limit:
        raise ImportInputError(
            f"shape {node.shape} ({node.size * node.dtype.itemsize} bytes) is more than the file could hold: "
            "a corrupt file",
            file=path,
            item=item,
        )


def read_broad(path: str | os.PathLike[str]) -> BroadTrial:
    """Read and check a BROAD trial (opened read-only). Raises :class:`ImportInputError`."""
    import h5py  # imported where used: only importers need it

    path = Path(path)
    if not path.exists():
        raise ImportInputError("no such file", file=path)
    if path.is_dir():
        raise ImportInputError("is a folder, not an HDF5 file", file=path)
    try:
        with open(path, "rb"):
            pass
    except OSError as e:
        raise ImportInputError(f"cannot open: {e.strerror or e}", file=path) from None
    if not h5py.is_hdf5(path):  # looks for the HDF5 signature at byte 0, 512, 1024, ...
        raise ImportInputError("not an HDF5 file (no HDF5 signature); a BROAD trial is an .hdf5 file", file=path)
    try:
        f = h5py.File(path, "r")
    except (OSError, KeyError, RuntimeError, TypeError, ValueError) as e:
        raise ImportInputError(f"cannot open as HDF5: {e}", file=path) from None
    # A corrupt file makes h5py raise KeyError, RuntimeError, TypeError, ValueError or OSError from
    # wherever its structure breaks (a link, a heap, an object header): all are the file's fault.
    try:
        with f:
            arrays = {}
            n = None
            for name, width in BROAD_DATASETS.items():
                item = f"dataset '{name}'"
                if name not in f:
                    raise ImportInputError(
                        f"missing (a BROAD trial holds {', '.join(BROAD_DATASETS)})", file=path, item=item
                    )
                node = f[name]
                if not isinstance(node, h5py.Dataset):
                    raise ImportInputError("is a group, not a dataset", file=path, item=item)
                if n is None:
                    n = node.shape[0] if node.ndim >= 1 else None
                expected = ("N", *width) if n is None else (n, *width)
                if node.ndim != 1 + len(width) or node.shape[1:] != width or (n is not None and node.shape[0] != n):
                    raise ImportInputError(
                        f"shape {node.shape}, expected ({', '.join(map(str, expected))})"
                        + ("" if name == "imu_gyr" else " (N from imu_gyr)"),
                        file=path,
                        item=item,
                    )
                kind = node.dtype.kind
                if name == "movement":
                    if kind not in "biu":
                        raise ImportInputError(f"type {node.dtype}, expected bool", file=path, item=item)
                elif kind not in "fiu":
                    raise ImportInputError(f"type {node.dtype}, expected numbers (float64)", file=path, item=item)
                _check_size(node, path, item)
                try:
                    arrays[name] = node[()]
                except (OSError, ValueError, TypeError) as e:
                    raise ImportInputError(f"cannot be read: {e}", file=path, item=item) from None
            if not n:
                raise ImportInputError("holds no samples", file=path, item="dataset 'imu_gyr'")
            item = "attribute 'sampling_rate'"
            if "sampling_rate" not in f.attrs:
                raise ImportInputError("missing (the sampling rate in Hz)", file=path, item=item)
            rate = np.asarray(f.attrs["sampling_rate"])
            if (
                rate.size != 1
                or rate.dtype.kind not in "fiu"
                or not np.isfinite(rate).all()
                or not float(rate.flat[0]) > 0
            ):
                raise ImportInputError(f"{rate.tolist()!r}: expected a positive number of Hz", file=path, item=item)
            low, high = BROAD_RATE_RANGE_HZ
            if not low <= float(rate.flat[0]) <= high:
                raise ImportInputError(
                    f"{float(rate.flat[0]):.6g} Hz is outside {low:g} Hz … {high / 1000:g} kHz, the rates of an IMU "
                    "(BROAD's: 285.714 Hz); a period in seconds or a rate in kHz?",
                    file=path,
                    item=item,
                )
            opt_pos = None
            if "opt_pos" in f:
                node = f["opt_pos"]
                item = "dataset 'opt_pos'"
                if not isinstance(node, h5py.Dataset) or node.shape != (n, 3) or node.dtype.kind not in "fiu":
                    shape = getattr(node, "shape", "a group")
                    raise ImportInputError(f"{shape}: expected ({n}, 3) numbers (m)", file=path, item=item)
                _check_size(node, path, item)
                try:
                    opt_pos = np.asarray(node[()], dtype=np.float64)
                except (OSError, ValueError, TypeError) as e:
                    raise ImportInputError(f"cannot be read: {e}", file=path, item=item) from None
            info = f.attrs.get("info", "")
            info = info.decode("utf-8", "replace") if isinstance(info, bytes) else str(info)
    except ImportInputError:
        raise
    except (OSError, KeyError, RuntimeError, TypeError, ValueError) as e:
        raise ImportInputError(f"corrupt HDF5 file: {e}", file=path) from None
    movement = arrays["movement"]
    if movement.dtype != bool:
        if not np.isin(movement, (0, 1)).all():
            raise ImportInputError("values other than 0 and 1; expected bool", file=path, item="dataset 'movement'")
        movement = movement.astype(bool)
    as_float = {
        name: np.asarray(arrays[name], dtype=np.float64) for name in ("imu_gyr", "imu_acc", "imu_mag", "opt_quat")
    }
    _check_values(as_float, opt_pos, path)
    return BroadTrial(
        path=path,
        gyro=as_float["imu_gyr"],
        accel=as_float["imu_acc"],
        mag_ut=as_float["imu_mag"],
        opt_quat=as_float["opt_quat"],
        movement=movement,
        rate_hz=float(rate.flat[0]),
        info=info,
        opt_pos=opt_pos,
    )


_QUAT_NORM_TOLERANCE = 0.01
"""How far from 1 the norm of an ``opt_quat`` row may be (BROAD's are unit to 1e-6): a row beyond it, a
zero row above all, is no rotation, and a reader that normalises it would make one up."""


def _rows(mask: NDArray[np.bool_]) -> str:
    """``row k`` (the first row where ``mask``, rows (N,) or (N, M)) and how many rows there are."""
    rows = np.flatnonzero(mask.reshape(len(mask), -1).any(axis=1))
    return f"row {rows[0]}" + (f" (and {len(rows) - 1} more)" if len(rows) > 1 else "")


def _check_values(arrays: dict[str, NDArray[np.float64]], opt_pos: NDArray[np.float64] | None, path: Path) -> None:
    """Refuse what is not a measurement: ±inf in any dataset, a gyro or accelerometer with NaN in every
    row (no sample any reader could use: a column never measured, or none at all), and an ``opt_quat``
    row that is no rotation (:data:`_QUAT_NORM_TOLERANCE`). NaN rows pass: the reference's are lost
    tracking (module notes), the sensors' dropouts a filter bridges (the import's summary counts them);
    so does a magnetometer or reference lost throughout (a 6D filter needs neither)."""
    named = dict(arrays) if opt_pos is None else {**arrays, "opt_pos": opt_pos}
    for name, values in named.items():
        infinite = np.isinf(values)
        if infinite.any():
            raise ImportInputError(
                f"inf at {_rows(infinite)}: not a measurement (NaN marks a missing one)",
                file=path,
                item=f"dataset '{name}'",
            )
    for name in ("imu_gyr", "imu_acc"):
        missing = np.isnan(arrays[name])
        if missing.any(axis=1).all():
            never = [axis for axis, column in zip("xyz", missing.T) if column.all()]
            where = f"column {never[0]} NaN in every row" if len(never) == 1 else "NaN in every row"
            raise ImportInputError(
                f"{where}: no sample a filter could use (a dropout is a NaN row among measured ones)",
                file=path,
                item=f"dataset '{name}'",
            )
    quat = arrays["opt_quat"]
    with np.errstate(invalid="ignore"):
        off = np.abs(np.linalg.norm(quat, axis=1) - 1.0) > _QUAT_NORM_TOLERANCE  # NaN rows compare False
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise ImportInputError(
            f"{quat[k].tolist()} at {_rows(off)} is not a unit quaternion (norm "
            f"{np.linalg.norm(quat[k]):.6g}): no rotation (a lost reference is a NaN row)",
            file=path,
            item="dataset 'opt_quat'",
        )


def broad_stamps_ns(n: int, rate_hz: float) -> NDArray[np.int64]:
    """``t_k = k / rate_hz`` for k = 0 … n−1 as integer nanoseconds, rounded to nearest: (n,) int64."""
    k = np.arange(n, dtype=np.float64)
    return np.rint(k * 1e9 / float(rate_hz)).astype(np.int64)


def broad_recording(trial: BroadTrial, device_name: str = "imu0") -> Recording:
    """The :class:`Recording` of a trial: samples (mag in tesla), reference attitude, movement mask and the
    import's metadata keys."""
    stamp_ns = broad_stamps_ns(len(trial), trial.rate_hz)
    t = ns_to_stamps(stamp_ns)
    samples = ImuSamples(t=t, gyro=trial.gyro, accel=trial.accel, mag=trial.mag_ut * 1e-6, device=device_name)
    truth = ImuSeries(t=t, q_wb=trial.opt_quat)  # omega_b, specific_force_b unknown: "no estimate"
    metadata = {
        "source": trial.path.name,
        "source_format": "BROAD",
        "citation": BROAD_CITATION,
        "license": BROAD_LICENSE,
        "sampling_rate_hz": repr(trial.rate_hz),
        "time_stamps": "t_k = k / sampling_rate_hz s from k = 0, rounded to the nearest ns",
    }
    if trial.info:
        metadata["source_info"] = trial.info
    pose = None if trial.opt_pos is None else PoseSeries(t=t, pos_w=trial.opt_pos, q_wb=trial.opt_quat)
    return Recording(samples, truth=truth, pose=pose, movement=trial.movement, metadata=metadata)


def import_broad(
    path: str | os.PathLike[str], out: str | os.PathLike[str], *, device_name: str = "imu0", force: bool = False
) -> ImportSummary:
    """Turn the BROAD trial ``path`` into the MCAP log ``out`` (see the module's notes); an existing
    ``out`` is replaced only with ``force``.

    Raises
    ------
    ImportOutputError
        ``out`` cannot take the import, before the trial is read: a folder, the input itself (even with
        ``force``), in a missing, read-only (a mount stops root too) or unwritable folder, or an existing
        file without ``force`` (:func:`~gyroemu.pipelines.formats.atomic.output_file_problem`).
    ImportInputError
        The input is missing, not HDF5, lacks a dataset or attribute, or has the wrong shapes.
    """
    path, out = Path(path), Path(out)
    problem = output_file_problem(out, force=force, inputs=(path,))
    if problem is not None:
        raise ImportOutputError(problem)
    trial = read_broad(path)
    recording = broad_recording(trial, device_name)
    write_mcap(out, recording)
    n = len(trial)
    return ImportSummary(
        source=path,
        out=out,
        format="BROAD",
        samples=n,
        rate_hz=trial.rate_hz,
        duration_s=(n - 1) / trial.rate_hz,
        truth_nan_rows=int(np.isnan(trial.opt_quat).any(axis=1).sum()),
        movement_samples=int(trial.movement.sum()),
        sample_nan_rows=int(np.isnan(np.hstack([trial.gyro, trial.accel, trial.mag_ut])).any(axis=1).sum()),
    )


IMPORTERS = {"broad": import_broad}
"""Format name (``gyroemu import FORMAT``) -> importer ``(path, out, *, force=False) -> ImportSummary``."""
