"""A device's samples read from a log a block at a time, as :func:`~gyroemu.pipelines.formats.mcap_log.read_mcap`
has them whole: for commands that filter a log of any length in bounded memory (``gyroemu estimate``).

:func:`read_mcap` pairs a device's topics by header stamp over the whole file: a sample is kept where
every ``/raw/<kind>`` topic has a message at its stamp (the others are dropped, with a warning per
topic), takes the latest ``/mag`` message since the sample before (:func:`match_latest`: at its stamp in
gyroemu's logs, within a sample interval before it on a field's own clock; NaN without one) and the
``/movement`` flag (False,
with a warning, without one); ``/truth/pose`` pairs with the samples by index. :class:`DeviceStream`
does the same as the file's chunks go by (:meth:`feed` a :class:`RawMessages` batch, :meth:`take` the
samples that are complete), which a single pass can do when, in log-time order,

- each topic's messages come in log-time order from chunk to chunk (chunks that do not overlap in
  time, as writers that log as they go produce: gyroemu's, rosbags', ros2 bag's), and
- the IMU's and every paired topic's header stamps increase,

so that a sample is complete once every paired topic has gone past its stamp. A log that breaks either
raises :class:`NotStreamable` (the caller reads it whole, with the same result), as does a paired
topic that falls more than :data:`MAX_PENDING` samples behind (it would have to be held in memory).

A command that needs the whole log's figures before it starts reads the log three times, in bounded
memory each: :func:`scan_devices` validates every message and finds the devices (the same errors and
warnings as :func:`read_mcap`); :func:`count_samples` makes each device's :class:`DeviceCensus` (how
many samples, their rate, whether any has a field, whether the pose pairs; the warnings of the samples
dropped) and keeps its first samples; the third pass is the command's own, with a :class:`DeviceStream`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.pipelines.formats.channels import IMU_ROLE, MAG_ROLE, MOVEMENT_ROLE, POSE_ROLE, TRUTH_ROLE, raw_kind
from gyroemu.pipelines.formats.mcap_log import (
    LogWarning,
    announce_scan,
    device_name,
    dropped_samples,
    group_devices,
    match_latest,
    match_stamps,
    no_imu_error,
    unflagged_samples,
    unpaired_field,
)
from gyroemu.pipelines.formats.mcap_records import McapRecordWalk, McapScan, RawMessages
from gyroemu.pipelines.formats.messages import DecodedBatch, MessageType, ns_to_stamps, stamps_to_ns

__all__ = [
    "FIRST_BLOCK_S",
    "MAX_PENDING",
    "POSE_MATCH_NS",
    "TRUTH_FIELDS",
    "DeviceBlock",
    "DeviceCensus",
    "DeviceStream",
    "NearestTruth",
    "NotStreamable",
    "RateCounter",
    "Counted",
    "StreamDevice",
    "count_samples",
    "nearest",
    "read_topic",
    "scan_devices",
    "truth_values",
    "not_increasing_since",
    "warn_drops",
]

FIRST_BLOCK_S = 60.0
"""Seconds of a device's first samples :func:`count_samples` keeps for the commands that read a log a
block at a time (``gyroemu estimate``, ``bench --log``): a filter starts from its first block (the MEKF
reads at most its first 10 s, to find north from the Earth's rate: its ``start_s``), so every filter is
given its first minute at once, read in the counting pass, and the copy need not hold it back."""

MAX_PENDING = 1 << 20
"""Samples a stream may hold while a paired topic catches up, before it gives up (:class:`NotStreamable`)."""

POSE_MATCH_NS = 1000
"""How far a ``/truth/pose`` stamp may lie from its sample's for the pose to be the sample's, ns."""


class NotStreamable(Exception):
    """A log whose messages a single pass cannot pair as :func:`read_mcap` does (the module's notes)."""


@dataclass(frozen=True)
class DeviceBlock:
    """A device's next complete samples, as :func:`read_mcap`'s :class:`DeviceLog` has them.

    Attributes
    ----------
    stamp_ns : ndarray (n,) int64
        Header stamps.
    gyro, accel : ndarray (n, 3)
        rad/s and m/s².
    mag : ndarray (n, 3)
        The field, T: the latest ``/mag`` message since the sample before (:func:`match_latest`); NaN rows
        where ``/mag`` has none (and without a ``/mag``).
    pose_ns, pose_pos : ndarray (m,) int64 and (m, 3), m ≤ n
        ``/truth/pose`` stamps (as :func:`pose_from_batch` has them, through seconds) and positions, m,
        paired by index with the first m samples (empty unless the stream pairs poses).
    through_ns : int or None
        Every IMU message up to this stamp is decided: a sample of this block or an earlier one, or
        dropped (None: the block took no message).
    movement : ndarray (n,) bool or None
        The ``/movement`` flags at the samples' stamps (False where a sample has none), as
        :attr:`DeviceLog.movement`; None without a ``/movement`` topic.
    truth : NearestTruth or None
        The ``/truth/imu`` message nearest each sample's stamp (None unless the stream pairs it).
    """

    stamp_ns: NDArray[np.int64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    mag: NDArray[np.float64]
    pose_ns: NDArray[np.int64]
    pose_pos: NDArray[np.float64]
    through_ns: int | None
    movement: NDArray[np.bool_] | None = None
    truth: NearestTruth | None = None

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @staticmethod
    def concatenate(blocks: list[DeviceBlock]) -> DeviceBlock:
        """Consecutive blocks of one stream joined."""
        through = [b.through_ns for b in blocks if b.through_ns is not None]
        movement = [b.movement for b in blocks if b.movement is not None]
        truths = [b.truth for b in blocks if b.truth is not None]  # a stream pairs the truth in every block or none
        return DeviceBlock(
            **{
                name: np.concatenate([getattr(b, name) for b in blocks])
                for name in ("stamp_ns", "gyro", "accel", "mag", "pose_ns", "pose_pos")
            },
            through_ns=through[-1] if through else None,
            movement=np.concatenate(movement) if movement else None,
            truth=NearestTruth.concatenate(truths) if truths else None,
        )

    def after(self, stamp_ns: int | None) -> DeviceBlock:
        """The samples later than ``stamp_ns`` (all when None), their poses with them."""
        k = 0 if stamp_ns is None else int(np.searchsorted(self.stamp_ns, stamp_ns, side="right"))
        if k == 0:
            return self
        m = max(0, len(self.pose_ns) - k) if len(self.pose_ns) == len(self) else 0
        return DeviceBlock(
            stamp_ns=self.stamp_ns[k:],
            gyro=self.gyro[k:],
            accel=self.accel[k:],
            mag=self.mag[k:],
            pose_ns=self.pose_ns[len(self.pose_ns) - m :],
            pose_pos=self.pose_pos[len(self.pose_pos) - m :],
            through_ns=self.through_ns,
            movement=None if self.movement is None else self.movement[k:],
            truth=None if self.truth is None else self.truth.rows(slice(k, None)),
        )


@dataclass(frozen=True)
class NearestTruth:
    """Each sample's nearest ``/truth/imu`` message (by header stamp; of two as near, the earlier), as
    ``gyroemu bench`` pairs a log's truth with its samples over the whole log.

    Attributes
    ----------
    q_wb : ndarray (n, 4)
        Its attitude, scalar first; NaN where the message has none (covariance −1) or there is no truth.
    omega_b : ndarray (n, 3)
        Its body rate, rad/s; NaN likewise.
    gap_s : ndarray (n,)
        ``|t_truth − t|`` in seconds (both as ``ns_to_stamps`` has them); inf where there is no truth.
    """

    q_wb: NDArray[np.float64]
    omega_b: NDArray[np.float64]
    gap_s: NDArray[np.float64]

    def rows(self, index: slice | NDArray[np.intp]) -> NearestTruth:
        """The samples ``index``."""
        return NearestTruth(self.q_wb[index], self.omega_b[index], self.gap_s[index])

    @staticmethod
    def concatenate(parts: list[NearestTruth]) -> NearestTruth:
        """Consecutive samples' truths joined."""
        return NearestTruth(*(np.concatenate([getattr(p, n) for p in parts]) for n in ("q_wb", "omega_b", "gap_s")))


TRUTH_FIELDS = ("orientation", "orientation_covariance", "angular_velocity", "angular_velocity_covariance")
"""The ``/truth/imu`` fields :class:`DeviceStream` reads to pair the truth."""


def truth_values(values: Mapping[str, NDArray[Any]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Attitudes (m, 4), scalar first, and body rates (m, 3) of decoded ``/truth/imu`` messages, NaN where
    a message says it has none (its covariance's first element −1), as :func:`series_from_batch` reads
    them."""
    q = values["orientation"][:, [3, 0, 1, 2]]
    q[values["orientation_covariance"][:, 0] == -1.0] = np.nan
    omega = values["angular_velocity"].copy()
    omega[values["angular_velocity_covariance"][:, 0] == -1.0] = np.nan
    return q, omega


def nearest(t: NDArray[np.float64], tt: NDArray[np.float64]) -> NDArray[np.intp]:
    """Index into ``tt`` (sorted, not empty) of the stamp nearest each of ``t``, the earlier of two as
    near (``gyroemu bench``'s rule: both neighbours' distances computed in float64 seconds)."""
    if len(tt) < 2:
        return np.zeros(len(t), dtype=np.int64)
    j = np.clip(np.searchsorted(tt, t), 1, len(tt) - 1)
    return np.where(np.abs(tt[j - 1] - t) <= np.abs(tt[j] - t), j - 1, j)


def read_topic(
    batch: RawMessages, channel_id: int, mtype: MessageType, after_log_time: int, after_stamp: int | None = None
) -> tuple[DecodedBatch, int] | None:
    """A topic's messages in one chunk, decoded in :func:`read_mcap`'s order (log time, then file order),
    and the last one's log time; None when the chunk has none. :class:`NotStreamable` when they go back
    in log time from ``after_log_time``, the previous chunk's last (the whole read would sort them), or,
    given ``after_stamp`` (the previous chunk's last header stamp, ns), when their header stamps do not
    increase from it."""
    index = np.flatnonzero(batch.channel_id == channel_id)
    if not len(index):
        return None
    index = index[np.argsort(batch.log_time[index], kind="stable")]
    log_time = batch.log_time[index]
    if int(log_time[0]) < after_log_time:
        raise NotStreamable("a topic's messages go back in log time from one chunk to the next")
    decoded = mtype.decode(batch.payloads(index))
    if after_stamp is not None and np.any(np.diff(np.concatenate(([after_stamp], decoded.stamp_ns))) <= 0):
        raise NotStreamable("header stamps that do not increase")
    return decoded, int(log_time[-1])


@dataclass
class _Pending:
    """One topic's decoded messages not yet paired."""

    channel_id: int
    mtype: MessageType
    stamp_ns: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    values: dict[str, NDArray[Any]] = field(default_factory=dict)
    last_log_time: int = -1
    seen: int = -(1 << 62)  # the largest stamp read so far
    count: int | None = None  # the topic's messages in the log (None: not known)
    read: int = 0  # messages read so far

    @property
    def through(self) -> int:
        """The stamp up to which the topic has shown all it will: the largest read, or beyond any once
        every message of the topic has been read (a topic that ends early holds nothing back)."""
        return (1 << 62) if self.count is not None and self.read >= self.count else self.seen

    def append(self, batch: RawMessages, names: tuple[str, ...], increasing: bool) -> None:
        got = read_topic(batch, self.channel_id, self.mtype, self.last_log_time, self.seen if increasing else None)
        if got is None:
            return
        decoded, self.last_log_time = got
        self.read += len(decoded.stamp_ns)
        self.seen = max(self.seen, int(decoded.stamp_ns.max()))
        self.stamp_ns = np.concatenate((self.stamp_ns, decoded.stamp_ns))
        for name in names:
            old = self.values.get(name)
            self.values[name] = decoded[name] if old is None else np.concatenate((old, decoded[name]))
        if len(self.stamp_ns) > MAX_PENDING:
            raise NotStreamable(f"more than {MAX_PENDING} messages held while the device's topics catch up")

    def drop(self, upto: int | None, everything: bool) -> None:
        """Forget the messages at or before stamp ``upto`` (all of them when ``everything``)."""
        count = (
            len(self.stamp_ns)
            if everything
            else (0 if upto is None else int(np.searchsorted(self.stamp_ns, upto, side="right")))
        )
        self.pop(count)

    def pop(self, count: int) -> tuple[NDArray[np.int64], dict[str, NDArray[Any]]]:
        out = self.stamp_ns[:count], {k: v[:count] for k, v in self.values.items()}
        self.stamp_ns = self.stamp_ns[count:]
        self.values = {k: v[count:] for k, v in self.values.items()}
        return out


class DeviceStream:
    """A device's samples a block at a time (the module's notes).

    Parameters
    ----------
    channels : mapping
        Role (``imu``, ``mag``, ``movement``, ``truth/pose``, ``raw/<kind>``; others are ignored) to
        ``(channel id, message type)``, in the order :func:`read_mcap` groups them (the raw topics drop
        samples in that order, which their warnings count).
    pair_pose : bool
        Pair ``/truth/pose`` with the samples by index: a sample is then complete once its pose has been
        read too, until the pose topic has given every message ``messages`` counts (without the counts, a
        pose topic with fewer messages than the samples stalls the stream until :class:`NotStreamable`).
        False: the pose topic is not read.
    pair_truth : bool
        Give each sample its nearest ``/truth/imu`` message (:class:`NearestTruth`): a sample is then
        complete once the truth has gone past its stamp (its header stamps must increase). False: the
        truth topic is not read.
    messages : mapping, optional
        Role to the number of the topic's messages in the log (:attr:`StreamDevice.messages`): a paired
        topic that has given them all holds no sample back (without it, a topic that ends early, a
        field that stops, would hold every later sample, and the chunks with them, to the file's end).

    Attributes
    ----------
    raw_dropped : dict
        Raw role to the samples it dropped so far (no message at their stamp).
    movement_missing : int
        Samples without a ``/movement`` message at their stamp so far.
    truth_attitudes, truth_rates : int
        ``/truth/imu`` messages read so far with an attitude, and with a finite rate (``pair_truth``).
    """

    def __init__(
        self,
        channels: Mapping[str, tuple[int, MessageType]],
        pair_pose: bool = False,
        pair_truth: bool = False,
        messages: Mapping[str, int] | None = None,
    ) -> None:
        roles = dict(channels)
        counts = dict(messages or {})

        def pending(role: str) -> _Pending:
            return _Pending(*roles[role], count=counts.get(role))

        self._imu = pending(IMU_ROLE)
        self._imu.values = {name: np.empty((0, 3)) for name in ("angular_velocity", "linear_acceleration")}
        self._mag = pending(MAG_ROLE) if MAG_ROLE in roles else None
        self._movement = pending(MOVEMENT_ROLE) if MOVEMENT_ROLE in roles else None
        self._pose = pending(POSE_ROLE) if pair_pose and POSE_ROLE in roles else None
        self._pair_truth = pair_truth
        self._truth = pending(TRUTH_ROLE) if pair_truth and TRUTH_ROLE in roles else None
        self.truth_attitudes = 0
        self.truth_rates = 0
        self._raw = {role: pending(role) for role in roles if raw_kind(role) is not None}
        self.raw_dropped = dict.fromkeys(self._raw, 0)
        self.movement_missing = 0
        self.field_used = 0
        self._previous_ns: int | None = None  # the last sample taken (its field's interval ends there)

    def feed(self, batch: RawMessages) -> int | None:
        """Take in the device's messages of one chunk (in file order, as the walk hands them out).
        Returns the largest IMU stamp among them (None: the chunk holds none)."""
        before = self._imu.seen
        self._imu.append(batch, ("angular_velocity", "linear_acceleration"), increasing=True)
        for pending in self._raw.values():
            pending.append(batch, (), increasing=True)
        if self._mag is not None:
            self._mag.append(batch, ("magnetic_field",), increasing=True)
        if self._movement is not None:
            self._movement.append(batch, ("data",), increasing=True)
        if self._pose is not None:
            self._pose.append(batch, ("position",), increasing=False)
        if self._truth is not None:
            read = len(self._truth.stamp_ns)
            self._truth.append(batch, TRUTH_FIELDS, increasing=True)
            if len(self._truth.stamp_ns) > read:  # the chunk held truth messages
                new = {k: v[read:] for k, v in self._truth.values.items()}
                self.truth_attitudes += int((new["orientation_covariance"][:, 0] != -1.0).sum())
                self.truth_rates += int(np.isfinite(truth_values(new)[1]).any(axis=1).sum())
        return None if self._imu.seen == before else self._imu.seen

    def take(self, final: bool = False) -> DeviceBlock:
        """The samples every paired topic has gone past (all that are left when ``final``: the file has
        ended), taken out of the stream."""
        paired = [*self._raw.values(), *(p for p in (self._mag, self._movement, self._truth) if p is not None)]
        stamps = self._imu.stamp_ns
        n = len(stamps)
        if not final and paired:
            n = int(np.searchsorted(stamps, min(p.through for p in paired), side="right"))
        if self._pose is not None and not final and self._pose.through < (1 << 62):  # poses still to come
            keep = _kept(stamps[:n], self._raw.values())
            if len(keep) > len(self._pose.stamp_ns):  # up to the first kept sample whose pose is not read yet
                n = int(keep[len(self._pose.stamp_ns)])
        stamp_ns, values = self._imu.pop(n)
        last = int(stamp_ns[-1]) if n else None
        keep = np.arange(n)
        for role, pending in self._raw.items():  # read_mcap's order: each raw topic drops from what is left
            hit = match_stamps(stamp_ns[keep], pending.stamp_ns)[0]
            self.raw_dropped[role] += len(keep) - len(hit)
            keep = keep[hit]
            pending.drop(last, final)
        stamp_ns = stamp_ns[keep]
        mag = np.full((len(keep), 3), np.nan)
        if self._mag is not None:
            i, j = match_latest(stamp_ns, self._mag.stamp_ns, self._previous_ns)
            if len(i):
                mag[i] = self._mag.values["magnetic_field"][j]
            self.field_used += len(i)
            # What the last sample's interval held is used; later messages wait for the next samples.
            self._mag.drop(int(stamp_ns[-1]) if len(stamp_ns) else None, final)
        if len(stamp_ns):
            self._previous_ns = int(stamp_ns[-1])
        movement = None
        if self._movement is not None:
            i, j = match_stamps(stamp_ns, self._movement.stamp_ns)
            movement = np.zeros(len(keep), dtype=bool)
            if len(i):
                movement[i] = self._movement.values["data"][j]
            self.movement_missing += len(keep) - len(i)
            self._movement.drop(last, final)
        truth = self._nearest_truth(stamp_ns, last) if self._pair_truth else None
        pose_ns, pose_pos = np.empty(0, np.int64), np.empty((0, 3))
        if self._pose is not None:
            pose_stamps, pose_values = self._pose.pop(min(len(keep), len(self._pose.stamp_ns)))
            if len(pose_stamps):
                pose_ns, pose_pos = stamps_to_ns(ns_to_stamps(pose_stamps)), pose_values["position"]
        return DeviceBlock(
            stamp_ns=stamp_ns,
            gyro=values["angular_velocity"][keep],
            accel=values["linear_acceleration"][keep],
            mag=mag,
            pose_ns=pose_ns,
            pose_pos=pose_pos,
            through_ns=last,
            movement=movement,
            truth=truth,
        )

    def _nearest_truth(self, stamp_ns: NDArray[np.int64], last: int | None) -> NearestTruth:
        """The samples' nearest truth messages (every truth stamp later than each sample's has been read, or
        the file has ended); the truth before ``last`` is then forgotten but its last message, the earlier
        neighbour of the samples to come."""
        n = len(stamp_ns)
        q, omega, gap = np.full((n, 4), np.nan), np.full((n, 3), np.nan), np.full(n, np.inf)
        pending = self._truth
        if pending is None or not len(pending.stamp_ns):
            return NearestTruth(q, omega, gap)
        if n:
            t, tt = ns_to_stamps(stamp_ns), ns_to_stamps(pending.stamp_ns)
            j = nearest(t, tt)
            q_all, omega_all = truth_values(pending.values)
            q, omega, gap = q_all[j], omega_all[j], np.abs(tt[j] - t)
        if last is not None:
            pending.pop(max(0, int(np.searchsorted(pending.stamp_ns, last, side="right")) - 1))
        return NearestTruth(q, omega, gap)

    def pose_left(self) -> int:
        """``/truth/pose`` messages read and not yet paired with a sample."""
        return 0 if self._pose is None else len(self._pose.stamp_ns)


def _kept(stamp_ns: NDArray[np.int64], raw: Iterable[_Pending]) -> NDArray[np.intp]:
    """Indices of the samples every raw topic has a message at."""
    keep = np.arange(len(stamp_ns))
    for pending in raw:
        keep = keep[match_stamps(stamp_ns[keep], pending.stamp_ns)[0]]
    return keep


class RateCounter:
    """The median interval of a series of integer stamps (ns) fed a block at a time, as
    :func:`~gyroemu.pipelines.estimation.series.median_step_ns` and
    :func:`~gyroemu.pipelines.estimation.series.rate_of` find it over the whole series (the same floats):
    from the integer steps, not from float seconds since the epoch (0.24 µs apart today: a 1 kHz log's
    rate 72 ppm off). The distinct intervals are counted, so the memory is that of how many distinct
    intervals the series has (one for a clocked log), not of its length. A block's intervals wait until
    they outnumber the distinct ones counted, then are merged in: each interval is sorted O(log N) times
    in all, however many distinct values a jittered clock gives."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._values = np.empty(0, np.int64)
        self._counts = np.empty(0, np.int64)
        self._waiting: list[NDArray[np.int64]] = []
        self._waiting_n = 0

    def add(self, stamp_ns: ArrayLike) -> None:
        """The next stamps, integer ns (a block's ``stamp_ns``); TypeError for others (float seconds)."""
        stamp_ns = np.asarray(stamp_ns)
        if not np.issubdtype(stamp_ns.dtype, np.integer):
            raise TypeError(f"stamps must be integer nanoseconds, got {stamp_ns.dtype}")
        if not len(stamp_ns):
            return
        stamp_ns = stamp_ns.astype(np.int64, copy=False)
        steps = np.diff(stamp_ns) if self._last is None else np.diff(stamp_ns, prepend=self._last)
        self._last = int(stamp_ns[-1])
        self._waiting.append(steps)
        self._waiting_n += len(steps)
        if self._waiting_n > max(len(self._values), 1 << 16):
            self._merge()

    def _merge(self) -> None:
        if not self._waiting:
            return
        merged = np.concatenate((self._values, *self._waiting))
        weights = np.concatenate((self._counts, np.ones(self._waiting_n, np.int64)))
        self._values, inverse = np.unique(merged, return_inverse=True)
        self._counts = np.bincount(inverse, weights=weights).astype(np.int64)
        self._waiting, self._waiting_n = [], 0

    def median_ns(self) -> float:
        """The median interval, ns: the mean of the two middle integer steps (the middle one for an odd
        count), as :func:`~gyroemu.pipelines.estimation.series.median_step_ns`. ValueError without one."""
        self._merge()
        total = int(self._counts.sum())
        if total == 0:
            raise ValueError("no intervals")
        cumulative = np.cumsum(self._counts)
        lower = int(self._values[int(np.searchsorted(cumulative, (total - 1) // 2, side="right"))])
        upper = int(self._values[int(np.searchsorted(cumulative, total // 2, side="right"))])
        return (lower + upper) / 2

    def median(self) -> float:
        """The median interval, s (:meth:`median_ns` / 1e9)."""
        return self.median_ns() / 1e9

    def rate(self) -> float:
        """``1e9 / median_ns``, Hz; 1.0 for fewer than two stamps (as ``rate_of``)."""
        self._merge()
        return 1e9 / self.median_ns() if int(self._counts.sum()) else 1.0


@dataclass
class DeviceCensus:
    """What a first pass learns of a device's samples (:meth:`add` each block of :meth:`DeviceStream.take`).

    Attributes
    ----------
    count, finite : int
        Samples, and those whose gyro and accelerometer rows are finite.
    has_mag : bool
        Whether any sample has a field value that is not NaN (``ImuSamples.has_mag``).
    first_ns, last_ns : int or None
        The first and the last sample's stamps.
    field_rows : bool
        Whether any sample has a whole field (three finite components).
    flagged : bool
        Whether any sample's ``/movement`` flag is set.
    not_increasing : tuple or None
        The first sample whose stamp, in float seconds (as the filters take them), does not follow the one
        before it (two stamps a nanosecond apart at today's epoch are one float): ``(index, t, t_before,
        how many such steps)``; :func:`~gyroemu.pipelines.estimation.series.not_increasing_error` says it.
    pose_matches : bool
        Whether ``/truth/pose`` pairs with the samples by index within :data:`POSE_MATCH_NS` so far
        (:meth:`pose_pairs` once the stream has ended).
    rate : RateCounter
        The samples' intervals, from their integer stamps: the median (``rate.median()``, s) and the rate.
    """

    count: int = 0
    finite: int = 0
    has_mag: bool = False
    field_rows: bool = False
    flagged: bool = False
    first_ns: int | None = None
    last_ns: int | None = None
    not_increasing: tuple[int, float, float, int] | None = None
    pose_matches: bool = True
    pose_count: int = 0
    rate: RateCounter = field(default_factory=RateCounter)

    def add(self, block: DeviceBlock) -> None:
        """Count one block."""
        n = len(block)
        if not n:
            return
        self.not_increasing = not_increasing_since(block.stamp_ns, self.last_ns, self.count, self.not_increasing)
        if self.first_ns is None:
            self.first_ns = int(block.stamp_ns[0])
        self.last_ns = int(block.stamp_ns[-1])
        self.count += n
        self.finite += int((np.isfinite(block.gyro).all(axis=1) & np.isfinite(block.accel).all(axis=1)).sum())
        self.has_mag = self.has_mag or not np.all(np.isnan(block.mag))
        self.field_rows = self.field_rows or bool(np.isfinite(block.mag).all(axis=1).any())
        self.flagged = self.flagged or bool(block.movement is not None and block.movement.any())
        self.rate.add(block.stamp_ns)
        m = len(block.pose_ns)
        self.pose_count += m
        if m < n or np.abs(block.pose_ns - block.stamp_ns[:m]).max(initial=0) > POSE_MATCH_NS:
            self.pose_matches = False

    def pose_pairs(self, stream: DeviceStream) -> bool:
        """Whether ``/truth/pose`` gives every sample its position (``read_mcap``'s pose of as many
        messages as samples, each within :data:`POSE_MATCH_NS` of its sample's stamp)."""
        return self.pose_matches and self.pose_count == self.count and stream.pose_left() == 0


def warn_drops(path: Path, stream: DeviceStream, topics: Mapping[str, str], messages: Mapping[str, int]) -> None:
    """The warnings :func:`read_mcap` gives for the samples a device's paired topics dropped or left
    unflagged, and for field messages no sample takes (``topics``: role to topic; ``messages``: role to its
    messages in the log), once the stream has ended."""
    for role, dropped in stream.raw_dropped.items():
        if dropped:
            warnings.warn(dropped_samples(path, dropped, topics[IMU_ROLE], topics[role]), LogWarning, stacklevel=2)
    total = messages.get(MAG_ROLE, 0)
    if MAG_ROLE in topics and stream.field_used < total:
        unused = unpaired_field(path, total - stream.field_used, total, topics[IMU_ROLE], topics[MAG_ROLE])
        warnings.warn(unused, LogWarning, stacklevel=2)
    if stream.movement_missing:
        warnings.warn(
            unflagged_samples(path, stream.movement_missing, topics[IMU_ROLE], topics[MOVEMENT_ROLE]),
            LogWarning,
            stacklevel=2,
        )


def not_increasing_since(
    stamp_ns: NDArray[np.int64],
    last_ns: int | None,
    counted: int,
    so_far: tuple[int, float, float, int] | None,
) -> tuple[int, float, float, int] | None:
    """The tally of samples whose stamp, in float seconds (as the filters take them: two stamps a
    nanosecond apart at today's epoch are one float), does not follow the one before it, a block at a
    time: ``stamp_ns`` (n,) the block's stamps, ``last_ns`` the sample's before it (None: the first
    block), ``counted`` the samples before it, ``so_far`` the tally until then. Returns ``(index, t,
    t_before, count)`` of the first such sample and how many there are
    (:func:`~gyroemu.pipelines.estimation.series.not_increasing_error` says it), or None for none."""
    t = ns_to_stamps(stamp_ns)
    # each sample's stamp against the one before it (the previous block's last for the first)
    skip = 0 if last_ns is not None else 1
    before = t[:-1] if skip else np.concatenate((ns_to_stamps(np.array([last_ns])), t[:-1]))
    bad = np.flatnonzero(~(t[skip:] > before))
    if not len(bad):
        return so_far
    i = int(bad[0])
    first = so_far or (counted + i + skip, float(t[i + skip]), float(before[i]), 0)
    return (first[0], first[1], first[2], first[3] + len(bad))


@dataclass
class _Channel:
    """A channel of a type gyroemu decodes, with messages (what :func:`group_devices` groups)."""

    channel_id: int
    topic: str
    mtype: MessageType


@dataclass(frozen=True)
class StreamDevice:
    """A device of a log found without reading its samples: :class:`DeviceLog`'s header, and its
    channels for :class:`DeviceStream`.

    Attributes
    ----------
    name : str
    topics : dict
        Role to topic.
    metadata : dict or None
        The device's ``gyroemu`` metadata record.
    channels : dict
        Role to ``(channel id, message type)``, in :func:`read_mcap`'s order.
    messages : dict
        Role to the number of its messages in the log.
    """

    name: str
    topics: dict[str, str]
    metadata: dict[str, str] | None
    channels: dict[str, tuple[int, MessageType]]
    messages: dict[str, int] = field(default_factory=dict)


def scan_devices(path: Path) -> tuple[dict[str, StreamDevice], McapScan]:
    """The log's devices as :func:`read_mcap` finds them (name to device) and the scan, from one pass of
    bounded memory that decodes every message and drops it: the same :class:`LogError` for a corrupt
    file, the same warnings. :class:`NotStreamable` when a device's topic has several channels."""
    scan = McapScan(path)
    counts = scan.check()
    skipped = announce_scan(path, scan)
    typed = [
        _Channel(channel_id, data.channel.topic, data.mtype)
        for channel_id, data in scan.data.items()
        if data.mtype is not None and counts.get(channel_id)
    ]
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    devices = {}
    for prefix, group in group_devices(path, typed, skipped).items():
        name, meta = device_name(prefix, metadata)
        devices[name] = StreamDevice(
            name=name,
            topics={role: c.topic for role, c in group.items()},
            metadata=meta,
            channels={role: (c.channel_id, c.mtype) for role, c in group.items()},
            messages={role: counts[c.channel_id] for role, c in group.items()},
        )
    if not devices:
        raise no_imu_error(scan, path)
    topics = [c.topic for c in scan.channels.values()]
    if any(topics.count(t) > 1 for d in devices.values() for t in d.topics.values()):
        raise NotStreamable("a device's topic on several channels")
    return devices, scan


@dataclass(frozen=True)
class Counted:
    """What :func:`count_samples` found of a device.

    Attributes
    ----------
    census : DeviceCensus
    pose_pairs : bool
        ``/truth/pose`` gives each sample its position (asked for one device only).
    first : DeviceBlock or None
        The device's first samples, from its first one to at least ``first_s`` later (all of them for a
        shorter log), where they were asked for.
    truth_attitudes, truth_rates : int
        Its ``/truth/imu`` messages with an attitude, and with a finite rate (when asked for).
    """

    census: DeviceCensus
    pose_pairs: bool
    first: DeviceBlock | None
    truth_attitudes: int = 0
    truth_rates: int = 0


def count_samples(
    path: Path,
    devices: dict[str, StreamDevice],
    pose_of: str | None,
    first_of: set[str],
    first_s: float,
    truth: bool = False,
) -> dict[str, Counted]:
    """Per device, the figures of its samples, whether ``/truth/pose`` gives each of them its position
    (asked for the device ``pose_of`` only) and, for the devices ``first_of``, its first ``first_s``
    seconds of samples, from one pass over the log; the warnings :func:`read_mcap` gives for samples
    dropped or unflagged. ``truth``: pair each sample with its nearest ``/truth/imu`` message too (the
    first samples have it) and count the truth's attitudes and rates."""
    streams = {
        name: DeviceStream(
            d.channels, pair_pose=name == pose_of and POSE_ROLE in d.channels, pair_truth=truth, messages=d.messages
        )
        for name, d in devices.items()
    }
    census = {name: DeviceCensus() for name in devices}
    first: dict[str, list[DeviceBlock]] = {name: [] for name in first_of}
    filling = set(first_of)

    def add(name: str, block: DeviceBlock) -> None:
        counted = census[name]
        counted.add(block)
        if name in filling:
            first[name].append(block)
            if len(block) and counted.first_ns is not None and block.stamp_ns[-1] - counted.first_ns >= first_s * 1e9:
                filling.discard(name)

    for batch in McapRecordWalk(path).batches():
        for name, stream in streams.items():
            stream.feed(batch)
            add(name, stream.take())
    out = {}
    for name, stream in streams.items():
        add(name, stream.take(final=True))
        warn_drops(path, stream, devices[name].topics, devices[name].messages)
        out[name] = Counted(
            census=census[name],
            pose_pairs=pose_of == name and census[name].pose_pairs(stream),
            first=DeviceBlock.concatenate(first[name]) if name in first else None,
            truth_attitudes=stream.truth_attitudes,
            truth_rates=stream.truth_rates,
        )
    return out
