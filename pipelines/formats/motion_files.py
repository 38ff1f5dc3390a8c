"""Recorded motions on disk: read as :class:`~gyroemu.dynamics.recorded.MotionSamples`, and written.

Four formats (the ``format`` key of a ``recorded`` scenario):

``mcap``
    A log in the contract's profile: the attitude from ``/truth/imu`` and the position from
    ``/truth/pose`` (``geometry_msgs/msg/PoseStamped``) when the log has it, else none (the body held
    at the origin). A log with several devices is refused (name one with ``gyroemu info``; a later
    key may choose). Stamps are the messages' header stamps.
``broad``
    A BROAD trial (HDF5): ``opt_quat`` and ``opt_pos`` at ``t_k = k / sampling_rate``
    (:func:`gyroemu.pipelines.formats.importers.read_broad`).
``tum``
    The TUM RGB-D benchmark's trajectory format, which TUM-VI's ground truth uses and EuRoC's converts
    to: one pose per line, ``timestamp tx ty tz qx qy qz qw`` separated by spaces (``#`` starts a
    comment). The timestamp is in seconds; ``t`` is the position of the body's origin in the world
    frame (m) and ``q`` (scalar last) turns body vectors into the world frame. The world frame is
    ENU unless the scenario gives ``world_to_enu_quat``, the rotation that turns the file's world axes
    into ENU (for a z-up world whose x points north, a turn of +90° about z).
``csv``
    Comma-separated values with a header row naming the columns: ``t_s, qw, qx, qy, qz`` and,
    optionally, ``px_m, py_m, pz_m`` (position, m), in any order; world ENU (or ``world_to_enu_quat``),
    ``q`` body to world, scalar first as everywhere in gyroemu. Blank lines and lines starting with
    ``#`` are skipped. An empty cell of the attitude or the position (an occluded frame, as Vicon and
    OptiTrack exports write it: ``1.25,,,,,,,``) reads as NaN, as a ``nan`` cell does: the row is
    invalid and the recorded motion bridges it as a gap, refused when longer than
    ``smoothing.max_gap_s`` (:mod:`gyroemu.dynamics.recorded`). An empty stamp is an error.

Every reader raises :class:`MotionFileError` (a ``ConfigError``) naming the file and the line (and
column), dataset or topic at fault. :func:`write_tum` and :func:`write_csv` write the text formats (through a temporary
file renamed at the end).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.recorded import MotionSamples
from gyroemu.dynamics.rotation import quat_multiply, quat_rotate
from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.atomic import write_text_atomic

__all__ = [
    "MOTION_FORMATS",
    "CSV_COLUMNS",
    "MotionFileError",
    "read_motion",
    "read_tum",
    "read_csv",
    "read_broad_motion",
    "read_mcap_motion",
    "write_tum",
    "write_csv",
]

CSV_COLUMNS = ("t_s", "px_m", "py_m", "pz_m", "qw", "qx", "qy", "qz")
"""The columns of a motion CSV file (position optional)."""


class MotionFileError(ConfigError):
    """A motion file that cannot be read; ``file`` names it, the reason names the line or item."""


def _text_lines(path: Path) -> list[str]:
    if not path.is_file():
        raise MotionFileError("no such file" if not path.exists() else "is not a file", file=path)
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()  # a leading BOM (spreadsheets write one) dropped
    except UnicodeDecodeError:
        raise MotionFileError("not a text file (not UTF-8)", file=path) from None
    except OSError as e:
        raise MotionFileError(f"cannot read: {e.strerror or e}", file=path) from None


def _numbers(
    path: Path, rows: list[tuple[int, list[str]]], columns: Sequence[str], layout: str, stamp: int | None = None
) -> NDArray[np.float64]:
    """The rows' fields as an (N, len(columns)) float array; errors name the line and the column.

    With ``stamp`` (the stamp's column), an empty field elsewhere reads as NaN: a frame in which the
    tracking lost the body, as motion-capture exports write it, which the recorded motion bridges as a
    gap (up to ``smoothing.max_gap_s``); an empty stamp is an error."""
    width = len(columns)
    for line, fields in rows:
        if len(fields) != width:
            raise MotionFileError(f"line {line}: {len(fields)} fields, expected {width} ({layout})", file=path)
    try:
        return np.array([fields for _, fields in rows], dtype=float).reshape(len(rows), width)
    except ValueError:
        pass
    data = np.empty((len(rows), width))
    for i, (line, fields) in enumerate(rows):
        for j, value in enumerate(fields):
            if stamp is not None and not value:
                if j == stamp:
                    raise MotionFileError(
                        f"line {line}: column {columns[j]!r} is empty: every row needs its stamp (an empty "
                        "attitude or position cell is a gap, bridged up to smoothing.max_gap_s)",
                        file=path,
                    )
                data[i, j] = np.nan
                continue
            try:
                data[i, j] = float(value)
            except ValueError:
                raise MotionFileError(
                    f"line {line}: column {columns[j]!r}: {value!r} is not a number ({layout})", file=path
                ) from None
    return data


def read_tum(path: str | os.PathLike[str]) -> MotionSamples:
    """Read a TUM trajectory (module notes); stamps as in the file, world frame as in the file."""
    path = Path(path)
    rows = [
        (i + 1, text.split())
        for i, text in enumerate(_text_lines(path))
        if text.strip() and not text.lstrip().startswith("#")
    ]
    if not rows:
        raise MotionFileError("holds no poses (lines 'timestamp tx ty tz qx qy qz qw')", file=path)
    layout = "timestamp tx ty tz qx qy qz qw"
    data = _numbers(path, rows, layout.split(), layout)
    origin, t = _exact_stamps(rows, 0, data[:, 0])
    return _samples(path, t, data[:, [7, 4, 5, 6]], data[:, 1:4], [line for line, _ in rows], origin)


def read_csv(path: str | os.PathLike[str]) -> MotionSamples:
    """Read a motion CSV (module notes)."""
    path = Path(path)
    lines = [
        (i + 1, text) for i, text in enumerate(_text_lines(path)) if text.strip() and not text.lstrip().startswith("#")
    ]
    if not lines:
        raise MotionFileError(f"is empty; expected a header row of {', '.join(CSV_COLUMNS)}", file=path)
    header_line, header = lines[0]
    names = [name.strip() for name in header.split(",")]
    unknown = [name for name in names if name not in CSV_COLUMNS]
    if unknown:
        raise MotionFileError(
            f"line {header_line}: unknown column {unknown[0]!r}; columns: {', '.join(CSV_COLUMNS)} (position optional)",
            file=path,
        )
    if len(set(names)) != len(names):
        raise MotionFileError(f"line {header_line}: a column is named twice", file=path)
    missing = [name for name in ("t_s", "qw", "qx", "qy", "qz") if name not in names]
    position = [name for name in ("px_m", "py_m", "pz_m") if name in names]
    if missing or len(position) not in (0, 3):
        absent = missing or [name for name in ("px_m", "py_m", "pz_m") if name not in names]
        raise MotionFileError(f"line {header_line}: missing column {absent[0]!r}", file=path)
    rows = [(line, [f.strip() for f in text.split(",")]) for line, text in lines[1:]]
    if not rows:
        raise MotionFileError("holds a header and no rows", file=path)
    data = _numbers(path, rows, names, ", ".join(names), stamp=names.index("t_s"))
    col = {name: data[:, names.index(name)] for name in names}
    q = np.column_stack([col["qw"], col["qx"], col["qy"], col["qz"]])
    pos = np.column_stack([col["px_m"], col["py_m"], col["pz_m"]]) if position else None
    origin, t = _exact_stamps(rows, names.index("t_s"), col["t_s"])
    return _samples(path, t, q, pos, [line for line, _ in rows], origin)


def _exact_stamps(
    rows: list[tuple[int, list[str]]], column: int, parsed: NDArray[np.float64]
) -> tuple[float, NDArray[np.float64]]:
    """``(origin, t)``: the stamps as written, ``origin + t``, with the first stamp's whole seconds in
    ``origin`` and ``t`` computed from the digits exactly (one rounding, at the end).

    Epoch stamps (1.7·10⁹ s) parsed as doubles resolve 0.24 µs: exact 10 ms steps would read 9.99999
    to 10.00023 ms, jitter the smoothing takes for motion (3.5 °/h of rate on a noise-free 100 Hz
    file). ``parsed`` are the same fields as doubles, already checked to be numbers."""
    first = next((float(v) for v in parsed if math.isfinite(v)), 0.0)
    whole = math.floor(first)
    if whole == 0:
        return 0.0, parsed
    t = np.empty(len(rows))
    origin = Decimal(whole)
    for i, (_, fields) in enumerate(rows):
        try:
            t[i] = float(Decimal(fields[column]) - origin) if math.isfinite(parsed[i]) else parsed[i]
        except InvalidOperation:  # a spelling float takes and Decimal does not: the double, less the origin
            t[i] = parsed[i] - whole
    return float(whole), t


def _samples(
    path: Path,
    t: NDArray[np.float64],
    q: NDArray[np.float64],
    pos: NDArray[np.float64] | None,
    lines: list[int],
    origin_s: float = 0.0,
) -> MotionSamples:
    return MotionSamples(t=t, q_wb=q, pos_w=pos, source=str(path), lines=np.asarray(lines), origin_s=origin_s)


def read_broad_motion(path: str | os.PathLike[str]) -> MotionSamples:
    """The optical reference of a BROAD trial: ``opt_quat`` and ``opt_pos`` at ``k / sampling_rate``."""
    from gyroemu.pipelines.formats.importers import read_broad

    trial = read_broad(path)
    t = np.arange(len(trial)) / trial.rate_hz
    return MotionSamples(t=t, q_wb=trial.opt_quat, pos_w=trial.opt_pos, source=str(path))


def read_mcap_motion(path: str | os.PathLike[str]) -> MotionSamples:
    """The truth of a gyroemu log: ``/truth/imu``'s attitude and ``/truth/pose``'s position (when present)."""
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    path = Path(path)
    log = read_mcap(path)
    if len(log.devices) != 1:
        raise MotionFileError(f"holds {len(log.devices)} devices ({', '.join(log.devices)}); one is needed", file=path)
    device = log.device
    truth = device.truth
    q_wb = None if truth is None else truth.q_wb
    if truth is None or q_wb is None:
        raise MotionFileError("has no /truth/imu attitude to drive a recorded motion", file=path)
    pos = None
    if device.pose is not None:
        pose = device.pose
        if len(pose) != len(truth) or not np.array_equal(pose.t, truth.t):
            raise MotionFileError("its /truth/pose and /truth/imu stamps differ", file=path)
        pos = pose.pos_w
    t = truth.t - truth.t[0]
    if np.array_equal(truth.t, device.samples.t):  # the truth at the samples' stamps, as gyroemu writes it:
        t = device.seconds_from_first()  # exactly (the smoothing would read float seconds' steps as jitter)
    return MotionSamples(t=t, q_wb=q_wb, pos_w=pos, source=str(path))


MOTION_FORMATS: dict[str, Callable[[str | os.PathLike[str]], MotionSamples]] = {
    "mcap": read_mcap_motion,
    "broad": read_broad_motion,
    "tum": read_tum,
    "csv": read_csv,
}
"""Format name -> reader."""


def read_motion(path: str | os.PathLike[str], format: str, world_to_enu_quat: ArrayLike | None = None) -> MotionSamples:
    """Read ``path`` as ``format`` (:data:`MOTION_FORMATS`) and turn its world frame into ENU.

    ``world_to_enu_quat`` (w, x, y, z) turns the file's world axes into ENU:
    ``q_wb ← q_ew ⊗ q_wb``, ``p ← R_ew p``.
    """
    if format not in MOTION_FORMATS:
        raise MotionFileError(f"unknown format {format!r}; formats: {', '.join(MOTION_FORMATS)}", file=Path(path))
    samples = MOTION_FORMATS[format](path)
    if world_to_enu_quat is None:
        return samples
    q_ew = np.asarray(world_to_enu_quat, dtype=float)
    q_ew = q_ew / np.linalg.norm(q_ew)
    return MotionSamples(
        t=samples.t,
        q_wb=np.asarray(quat_multiply(q_ew, samples.q_wb)),
        pos_w=None if samples.pos_w is None else quat_rotate(q_ew, samples.pos_w),
        source=samples.source,
        lines=samples.lines,
        origin_s=samples.origin_s,
    )


def write_tum(path: str | os.PathLike[str], t: ArrayLike, q_wb: ArrayLike, pos_w: ArrayLike) -> Path:
    """Write a TUM trajectory: ``t`` (N,) s, ``q_wb`` (N, 4) w-first, ``pos_w`` (N, 3) m; full precision."""
    t, q, p = (np.asarray(a, dtype=float) for a in (t, q_wb, pos_w))
    data = np.column_stack([t, p, q[:, 1:], q[:, :1]])
    lines = ["# timestamp tx ty tz qx qy qz qw"] + [" ".join(repr(float(v)) for v in row) for row in data]
    return write_text_atomic(path, "\n".join(lines) + "\n")


def write_csv(path: str | os.PathLike[str], t: ArrayLike, q_wb: ArrayLike, pos_w: ArrayLike | None = None) -> Path:
    """Write a motion CSV (``t_s, px_m, py_m, pz_m, qw, qx, qy, qz``; no position columns without ``pos_w``)."""
    t, q = np.asarray(t, dtype=float), np.asarray(q_wb, dtype=float)
    columns = [t[:, None]] + ([np.asarray(pos_w, dtype=float)] if pos_w is not None else []) + [q]
    names = CSV_COLUMNS if pos_w is not None else ("t_s", "qw", "qx", "qy", "qz")
    data = np.column_stack(columns)
    lines = [", ".join(names)] + [", ".join(repr(float(v)) for v in row) for row in data]
    return write_text_atomic(path, "\n".join(lines) + "\n")
