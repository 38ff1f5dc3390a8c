"""gyroemu's recorded logs: devices' samples, truth, estimates and metadata as MCAP files (profile ``ros2``).

This is the upper of the two MCAP layers: it gives the channels of :mod:`gyroemu.pipelines.formats.channels`
their meaning in a file, and leaves the records to :mod:`gyroemu.pipelines.formats.mcap_records` (the bulk
writer, the scanner). :mod:`gyroemu.pipelines.mcap_io` re-exports both layers' public names.

What a gyroemu file holds (``interface.md``)
--------------------------------------------
Schema encoding ``ros2msg``, message encoding ``cdr`` (the bytes of :mod:`gyroemu.pipelines.formats.messages`),
zstd-compressed chunks, message indexes after each chunk, and a summary (schemas, channels,
statistics, chunk and metadata indexes, summary offsets). Channels, per device:

=================  ===================================  =========================================
topic              type                                 holds
=================  ===================================  =========================================
``/imu``           ``sensor_msgs/msg/Imu``              ``gyro``, ``accel``; ``orientation_covariance[0] = -1``
``/mag``           ``sensor_msgs/msg/MagneticField``    ``mag`` (tesla), only for devices with one
``/truth/imu``     ``sensor_msgs/msg/Imu``              true ``q_wb``, ``omega_b``, ``specific_force_b``
``/estimate/imu``  ``sensor_msgs/msg/Imu``              estimated ``q_wb`` (+ covariance), rate, ...
``/raw/<token>``   ``gyroemu_msgs/msg/<Kind>Raw``       the gyro kind's physical observables
``/movement``      ``gyroemu_msgs/msg/Flag``            an imported dataset's mask of the samples that count
``/tf``            ``tf2_msgs/msg/TFMessage``           ``map`` -> ``base_link`` (truth), ``map`` -> ``body_estimate``
``/tf_static``     ``tf2_msgs/msg/TFMessage``           ``base_link`` -> the IMU's frame (the device's mounting)
=================  ===================================  =========================================

A raw topic's ``<token>`` is the gyro kind with ``-`` as ``_`` (``/raw/rate_gyro`` for kind ``rate-gyro``;
:func:`~gyroemu.pipelines.formats.channels.raw_role`), a valid ROS 2 name; logs written before named it
with the hyphen (``/raw/rate-gyro``), and every reader here takes both.

``/tf`` and ``/tf_static`` are the file's, not a device's (no prefix): :mod:`gyroemu.pipelines.formats.frames`
says which samples go on ``/tf`` (100 Hz at most, and the last) and why; :func:`read_tf` reads them.
Stamps are absolute (ns since the Unix epoch): the writer adds ``start_ns`` to float times. ``/imu``
carries the device's per-sample noise variances (:mod:`gyroemu.pipelines.formats.imu_covariance`).

With several devices the topics are prefixed: ``/<device>/imu``. Every message's ``log_time`` and
``publish_time`` are its header stamp (ns), ``sequence`` counts from 0 per channel, and messages are
in time order across channels (same stamp: the order of the table). Frame ids: the device name (or
``Recording.frame_id``) for what the sensor measures (``/imu``, ``/mag``, ``/raw/...``), ``base_link``
for body-frame truth and estimates. Each device has a metadata record ``gyroemu`` with ``version``,
``seed``, ``scenario`` (TOML), ``device`` (TOML), ``device_name`` and ``topic_prefix``
(:func:`device_metadata`), plus any keys the recording adds (an imported file: ``source``,
``source_format``, ``citation``, ...; :mod:`gyroemu.pipelines.formats.importers`).

Writing
-------
:class:`McapLogWriter` (and :func:`write_mcap`) encode every channel of a block of samples as one
``(N, size)`` array (the ``encode_*`` functions of :mod:`gyroemu.pipelines.formats.channels`) and hand the
block to :class:`~gyroemu.pipelines.formats.mcap_records.McapFileWriter`, which interleaves, chunks and
compresses it. The file is written to a temporary name in the target folder and renamed when complete,
so an interrupted write leaves no partial file under the name.

Reading
-------
:func:`read_mcap` reads any ``ros2`` MCAP file (:class:`~gyroemu.pipelines.formats.mcap_records.McapScan`)
and gathers each channel's messages into arrays. Every channel of type ``sensor_msgs/msg/Imu``
counts, whatever its topic; channels of unknown types are skipped with a :class:`LogWarning`. Each
sample takes the latest ``/mag`` message since the sample before it (:func:`match_latest`): in gyroemu's
logs the one at its own stamp, in a robot's bag the magnetometer's reading on its own clock and rate, at
most a sample interval old; a warning counts the messages no sample takes. A file
cut short (a recorder killed mid-write, no footer) yields the messages of its complete chunks, with a
warning that says so and how many were recovered. Files that are not MCAP, are corrupt, or hold no IMU
messages raise :class:`~gyroemu.pipelines.formats.mcap_records.LogError`, which names the file. The input is
opened read-only.
"""

from __future__ import annotations

import os
import secrets
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

import gyroemu
from gyroemu.pipelines.formats.channels import (
    BODY_FRAME,
    ESTIMATE_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    MAG_ROLE,
    MOVEMENT_ROLE,
    POSE_ROLE,
    RESERVED_DEVICE_NAMES,
    TRUTH_ROLE,
    WORLD_FRAME,
    ImuSeries,
    PoseSeries,
    canonical_role,
    encode_mag,
    encode_measured,
    encode_movement,
    encode_pose,
    encode_raw,
    encode_series,
    is_prefix_name,
    pose_from_batch,
    raw_kind,
    raw_role,
    role_accepts,
    role_message_type,
    role_topic,
    series_from_batch,
    split_topic,
)
from gyroemu.pipelines.formats.frames import (
    TF_LOG_RATE_HZ,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TfThinning,
    mounting_of,
)
from gyroemu.pipelines.formats.imu_covariance import measurement_variances
from gyroemu.pipelines.formats.mcap_records import (
    COMPRESSION_LEVEL,
    OFFERED_QOS_PROFILES,
    ChannelInfo,
    DecodedChannel,
    LogError,
    McapFileWriter,
    McapScan,
    iter_mcap_batches,
)
from gyroemu.pipelines.formats.messages import (
    IMU,
    MessageType,
    ns_to_stamps,
    raw_observables,
    seconds_since,
    stamps_to_ns,
)
from gyroemu.pipelines.formats.tf_messages import TF_MESSAGE_TYPE, Transforms, decode_tf, encode_tf, tf_schema
from gyroemu.sensors.samples import ImuSamples

EncodedBlock = list[tuple[int, NDArray[np.int64], NDArray[np.uint8]]]
"""A block's messages as :meth:`McapLogWriter.prepare` serialised them: ``(channel_id, stamp_ns (N,),
payloads (N, size) uint8)`` per channel, for :meth:`McapLogWriter.write_prepared`."""

if TYPE_CHECKING:
    from mcap.records import Channel

    from gyroemu.dynamics import Scenario, Trajectory
    from gyroemu.sensors.imu import Device
    from gyroemu.sensors.sampling import SensorTruth

__all__ = [
    "LogWarning",
    "ImuSeries",
    "Recording",
    "DeviceLog",
    "McapLog",
    "METADATA_KEYS",
    "device_metadata",
    "McapLogWriter",
    "write_mcap",
    "read_mcap",
    "no_imu_error",
    "truth_series",
    "truth_pose",
    "read_tf",
    "TF_STATIC_QOS_PROFILES",
    "TypedChannel",
    "group_devices",
    "device_name",
    "announce_scan",
    "EncodedBlock",
    "LogCheck",
    "check_mcap_noting",
    "dropped_samples",
    "is_the_devices_estimate",
    "match_latest",
    "match_stamps",
    "unpaired_field",
    "unflagged_samples",
]


class LogWarning(UserWarning):
    """Something in a log that was skipped or recovered: an unknown channel, a truncated file."""


# ==================================================================================================
# What goes in and comes out besides ImuSamples.


def truth_series(
    trajectory: Trajectory,
    samples: ImuSamples,
    sensor_truth: SensorTruth | None = None,
    q_wb: NDArray[np.float64] | None = None,
) -> ImuSeries:
    """Body truth at the instants the device sampled (``samples.t_true``), stamped with the device's
    stamps ``samples.t``: what ``/truth/imu`` holds. ``sensor_truth``: the trajectory's interpolants,
    when the caller has built them already; ``q_wb`` (N, 4): the attitude at those instants, when the
    caller has evaluated it already (``sensor_truth.attitude_world(instants)``, shared with
    :func:`truth_pose`)."""
    from gyroemu.sensors.sampling import SensorTruth

    instants = samples.t_true if samples.t_true is not None else samples.t
    body = sensor_truth if sensor_truth is not None else SensorTruth(trajectory)
    if q_wb is None:
        q_wb, omega_b, force_b = body.body_truth(instants)
    else:
        omega_b, force_b = body.body_rates(instants)
    return ImuSeries(t=np.asarray(samples.t, dtype=float), q_wb=q_wb, omega_b=omega_b, specific_force_b=force_b)


def truth_pose(
    trajectory: Trajectory,
    samples: ImuSamples,
    sensor_truth: SensorTruth | None = None,
    q_wb: NDArray[np.float64] | None = None,
) -> PoseSeries:
    """The body's true position and attitude in the world at the instants the device sampled, stamped
    with the device's stamps: what ``/truth/pose`` holds. The position is the cubic Hermite spline
    through the trajectory's ``pos_w`` with slopes ``vel_w``. ``sensor_truth`` and ``q_wb`` as for
    :func:`truth_series`."""
    from scipy.interpolate import CubicHermiteSpline

    from gyroemu.sensors.sampling import SensorTruth

    instants = samples.t_true if samples.t_true is not None else samples.t
    if q_wb is None:
        q_wb = (sensor_truth if sensor_truth is not None else SensorTruth(trajectory)).attitude_world(instants)
    pos_w = CubicHermiteSpline(trajectory.t, trajectory.pos_w, trajectory.vel_w, axis=0)(instants)
    return PoseSeries(t=np.asarray(samples.t, dtype=float), pos_w=pos_w, q_wb=q_wb)


@dataclass(frozen=True, eq=False)
class Recording:
    """One device's block of output for :class:`McapLogWriter`.

    Attributes
    ----------
    samples : ImuSamples
        The device's samples; ``samples.device`` names it.
    truth, estimate : ImuSeries, optional
        Written to ``/truth/imu`` and ``/estimate/imu``.
    device : Device or str, optional
        The device (or its resolved config as TOML text), for the metadata record.
    seed : int, optional
        The run's seed (default: ``device.seed`` when ``device`` is a Device).
    pose : PoseSeries, optional
        Written to ``/truth/pose``: the body's true position and attitude in the world frame.
    movement : ndarray (N,) bool, optional
        A mask aligned to ``samples`` (an imported dataset's samples over which errors are computed),
        written to ``/movement`` as ``gyroemu_msgs/msg/Flag`` at the samples' stamps.
    stamp_ns : ndarray (N,) int64, optional
        The samples' stamps exactly, ns, used instead of ``samples.t`` (which, as float seconds, does
        not resolve nanoseconds at Unix-epoch times); a truth or estimate series of the same length
        and times is stamped with them too. For rewriting a log read by :func:`read_mcap`.
    metadata : dict of str to str, optional
        Further keys of the device's ``gyroemu`` metadata record (e.g. an import's ``source``); they
        may not replace the writer's own keys (``version``, ``seed``, ``scenario``, ``device``,
        ``device_name``, ``topic_prefix``).
    frame_id : str, optional
        The IMU's frame (``frame_id`` of ``/imu``, ``/mag``, ``/raw/...``, child of ``base_link`` on
        ``/tf_static``); default the device's name. Taken from the device's first block.
    gyro_variance, accel_variance : ndarray (3,), optional
        Per-sample variances written on ``/imu``'s covariance diagonals; default, when ``device`` is a
        ``Device``, :func:`~gyroemu.pipelines.formats.imu_covariance.measurement_variances`, else
        zero covariances ("unknown"). Taken from the device's first block.
    """

    samples: ImuSamples
    truth: ImuSeries | None = None
    estimate: ImuSeries | None = None
    device: Device | str | None = None
    seed: int | None = None
    movement: NDArray[np.bool_] | None = None
    metadata: dict[str, str] | None = None
    stamp_ns: NDArray[np.int64] | None = None
    pose: PoseSeries | None = None
    frame_id: str | None = None
    gyro_variance: NDArray[np.float64] | None = None
    accel_variance: NDArray[np.float64] | None = None


@dataclass(frozen=True, eq=False)
class DeviceLog:
    """One device's channels in a log.

    Attributes
    ----------
    name : str
        ``imu0``-style device name: the topic prefix without slashes, the gyroemu metadata's
        ``device_name`` for an unprefixed file, or a foreign IMU topic without its leading slash.
    topics : dict of str to str
        Role (``imu``, ``mag``, ``truth``, ``estimate``, ``raw/<token>`` as
        :func:`~gyroemu.pipelines.formats.channels.raw_role` names it, whatever the file's spelling) to topic.
    samples : ImuSamples
    stamp_ns : ndarray (N,) int64
        The samples' header stamps exactly, ns (``samples.t`` is their float64 value in seconds, which
        resolves 0.24 us at Unix-epoch times).
    truth, estimate : ImuSeries or None
    metadata : dict of str to str or None
        The device's ``gyroemu`` metadata record, when there is one.
    movement : ndarray (N,) bool or None
        The ``/movement`` flags at the samples' stamps (False, with a warning, for samples without a
        flag at their stamp); None when the device has no ``/movement`` topic.
    pose : PoseSeries or None
        ``/truth/pose``, at its own stamps; None when the device has none.
    frame_id : str
        ``/imu``'s frame id (its first message's).
    gyro_variance, accel_variance : ndarray (3,) or None
        The diagonals of ``/imu``'s first message's covariances; None where they are zero ("unknown").
    """

    name: str
    topics: dict[str, str]
    samples: ImuSamples
    stamp_ns: NDArray[np.int64]
    truth: ImuSeries | None = None
    estimate: ImuSeries | None = None
    metadata: dict[str, str] | None = None
    movement: NDArray[np.bool_] | None = None
    pose: PoseSeries | None = None
    frame_id: str = ""
    gyro_variance: NDArray[np.float64] | None = None
    accel_variance: NDArray[np.float64] | None = None

    def seconds_from_first(self) -> NDArray[np.float64]:
        """The samples' stamps in seconds from the first, exactly from their nanoseconds (N,): the float
        seconds of ``samples.t`` resolve 0.24 µs at Unix-epoch times, which differences would read as
        jitter (:func:`~gyroemu.pipelines.formats.messages.seconds_since`)."""
        return seconds_since(self.stamp_ns, self.stamp_ns[0])


@dataclass(frozen=True, eq=False)
class McapLog:
    """What :func:`read_mcap` found.

    Attributes
    ----------
    path : Path
    devices : dict of str to DeviceLog
        Keyed by device name, in the order of their IMU channels.
    metadata : list of dict
        Every ``gyroemu`` metadata record.
    profile : str
        The MCAP header's profile.
    message_count : int
        Messages read (every channel, decoded or not).
    truncated : bool
        The file ends before its footer: only complete chunks were read.
    skipped : dict of str to str
        Topics not decoded, with the reason.
    channels : tuple of ChannelInfo
        Every channel of the file (decoded or not) with its schema, in file order.
    """

    path: Path
    devices: dict[str, DeviceLog]
    metadata: list[dict[str, str]]
    profile: str
    message_count: int
    truncated: bool = False
    skipped: dict[str, str] = field(default_factory=dict)
    channels: tuple[ChannelInfo, ...] = ()

    @property
    def device(self) -> DeviceLog:
        """The only device (``ValueError`` when the log has several: pick one from :attr:`devices`)."""
        if len(self.devices) != 1:
            raise ValueError(
                f"{self.path}: {len(self.devices)} devices ({', '.join(self.devices)}); choose one from .devices"
            )
        return next(iter(self.devices.values()))

    @property
    def samples(self) -> ImuSamples:
        """The only device's samples."""
        return self.device.samples

    @property
    def truth(self) -> ImuSeries | None:
        """The only device's truth."""
        return self.device.truth


# ==================================================================================================
# Writing.

METADATA_KEYS = ("version", "seed", "scenario", "device", "device_name", "topic_prefix")
"""The writer's own keys of a device's ``gyroemu`` metadata record (:func:`device_metadata`)."""


def device_metadata(
    device_name: str, topic_prefix: str, *, seed: str = "", scenario: str = "", device: str = ""
) -> dict[str, str]:
    """A device's ``gyroemu`` metadata record: the writer's own keys, :data:`METADATA_KEYS` (empty: not
    known; ``version`` is gyroemu's)."""
    return {
        "version": gyroemu.__version__,
        "seed": seed,
        "scenario": scenario,
        "device": device,
        "device_name": device_name,
        "topic_prefix": topic_prefix,
    }


TF_STATIC_QOS_PROFILES = OFFERED_QOS_PROFILES.replace("durability: 2", "durability: 1")
"""``/tf_static``'s channel metadata: transient local (durability 1), as tf2's static broadcaster offers
it, so ``ros2 bag play`` latches the mounting for late subscribers."""


@dataclass
class _DeviceChannels:
    name: str
    prefix: str
    channels: dict[str, int]  # role -> channel id
    frame_id: str
    warned: set[str] = field(default_factory=set)
    variances: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None)
    mounting: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    static_written: bool = False


@dataclass
class _TfSeries:
    """One /tf edge (``map`` -> ``child``) fed from one device's series: its thinning and last sample."""

    child: str
    thinning: TfThinning
    last: tuple[int, NDArray[np.float64], NDArray[np.float64]] | None = None  # (stamp_ns, translation, xyzw)


def _toml(value: Scenario | Device | str | None) -> str:
    """A scenario's or device's resolved config as TOML text (given as an object or as the text)."""
    if value is None:
        return ""
    return value if isinstance(value, str) else value.to_toml()


class McapLogWriter:
    """Writes a gyroemu log: devices' samples, truth and estimates as ``ros2`` MCAP channels.

    Parameters
    ----------
    path : str or Path
        The file to write; it appears (atomically) when :meth:`close` succeeds.
    scenario : Scenario or str, optional
        The scenario (or its TOML text) for the metadata records.
    prefix_topics : bool, optional
        Prefix topics with the device name (``/<device>/imu``). Default: when the first :meth:`write`
        holds more than one device.
    chunk_size : int
        Uncompressed bytes per chunk (default 1 MiB, as the ``mcap`` library).
    compression_level : int
        zstd level (default :data:`~gyroemu.pipelines.formats.mcap_records.COMPRESSION_LEVEL`, 1).
    start_ns : int
        Added to every stamp given as float seconds (``samples.t``, ``truth.t``, ...; not to
        :attr:`Recording.stamp_ns`, which is absolute): the run's start time, ns since the Unix epoch.
    tf_rate_hz : float or None
        ``/tf`` messages per second at most (:mod:`gyroemu.pipelines.formats.frames`): ``map`` ->
        ``base_link`` from the truth (``/truth/pose``, else ``/truth/imu``) and ``map`` ->
        ``body_estimate`` from ``/estimate/imu``, each of the first device that has them; None: no
        ``/tf``. ``/tf_static`` (``base_link`` -> the IMU's frame) is written for every device whose
        mounting is known (``Recording.device``).

    Use as a context manager: on an exception inside the block the temporary file is removed and
    nothing appears at ``path``::

        with McapLogWriter("run.mcap", scenario=scenario) as log:
            log.write(Recording(samples, truth=truth_series(trajectory, samples), device=device))
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        scenario: Scenario | str | None = None,
        prefix_topics: bool | None = None,
        chunk_size: int = 1 << 20,
        compression_level: int = COMPRESSION_LEVEL,
        start_ns: int = 0,
        tf_rate_hz: float | None = TF_LOG_RATE_HZ,
    ) -> None:
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise FileNotFoundError(f"{self.path.parent} is not a folder")
        self._tmp = self.path.with_name(f".{self.path.name}.{secrets.token_hex(4)}.tmp")
        fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # mode 0o666 minus umask
        self._file = os.fdopen(fd, "wb", buffering=1 << 20)
        try:
            self._mcap = McapFileWriter(self._file, chunk_size=chunk_size, compression_level=compression_level)
        except BaseException:
            self._file.close()
            self._tmp.unlink(missing_ok=True)
            raise
        self._scenario = _toml(scenario)
        self._prefix = prefix_topics
        self._devices: dict[str, _DeviceChannels] = {}
        self._last_time = -1
        self._closed = False
        self._start_ns = int(start_ns)
        self._tf_rate_hz = tf_rate_hz
        self._tf: dict[str, tuple[str, _TfSeries]] = {}  # child frame -> (device name, series)
        self._tf_channels: dict[str, int] = {}

    def __enter__(self) -> McapLogWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # ---------------------------------------------------------------------------------------------

    def _channel(self, device: _DeviceChannels, role: str) -> int:
        if role not in device.channels:
            topic = role_topic(role, device.prefix)
            device.channels[role] = self._mcap.register_ros2_channel(topic, role_message_type(role))
        return device.channels[role]

    def _device(self, recording: Recording, several: bool) -> _DeviceChannels:
        name = recording.samples.device
        if name in self._devices:
            return self._devices[name]
        if self._prefix is None:
            self._prefix = several
        if self._devices and not self._prefix:
            raise ValueError(
                f"a second device ({name!r}) in a log without topic prefixes: "
                "pass prefix_topics=True to write several devices"
            )
        if self._prefix and not is_prefix_name(name):
            raise ValueError(
                f"device name {name!r} cannot prefix topics: use letters, digits and '_', "
                f"starting with a letter, and none of {', '.join(sorted(RESERVED_DEVICE_NAMES))}"
            )
        device = recording.device
        variances = measurement_variances(device)
        entry = _DeviceChannels(
            name=name,
            prefix=f"/{name}" if self._prefix else "",
            channels={},
            frame_id=recording.frame_id or name,
            variances=(
                recording.gyro_variance if recording.gyro_variance is not None else (variances or (None, None))[0],
                recording.accel_variance if recording.accel_variance is not None else (variances or (None, None))[1],
            ),
            mounting=mounting_of(device),
        )
        self._devices[name] = entry
        seed = recording.seed if recording.seed is not None else getattr(device, "seed", None)
        record = device_metadata(
            name,
            entry.prefix,
            seed="" if seed is None else str(int(seed)),
            scenario=self._scenario,
            device=_toml(device),
        )
        extra = dict(recording.metadata or {})
        clash = sorted(set(extra) & set(record))
        if clash:
            raise ValueError(f"Recording.metadata may not set the writer's own key(s) {', '.join(clash)}")
        self._mcap.add_metadata("gyroemu", {**record, **extra})
        return entry

    def write(self, *recordings: Recording | ImuSamples) -> None:
        """Append a block: one :class:`Recording` (or bare :class:`ImuSamples`) per device.

        All channels of all devices in one call are interleaved in time order; successive calls must
        follow each other in time (``ValueError`` otherwise). The same as :meth:`write_prepared` of
        :meth:`prepare`.
        """
        self.write_prepared(self.prepare(*recordings))

    def write_prepared(self, encoded: EncodedBlock | None) -> None:
        """Append a block that :meth:`prepare` encoded: its channels' messages interleaved in time order
        into records, chunked, compressed and written. One thread may prepare the next block (encoding,
        registering its channels) while another writes this one; blocks are written in the order
        prepared."""
        if self._closed:
            raise ValueError(f"{self.path}: the log is closed")
        self._mcap.add_messages(encoded or [])

    def prepare(self, *recordings: Recording | ImuSamples) -> EncodedBlock | None:
        """Encode a block (see :meth:`write`): its channels registered, each channel's messages
        serialised; None when it holds no message. :meth:`write_prepared` writes it."""
        if self._closed:
            raise ValueError(f"{self.path}: the log is closed")
        block = [r if isinstance(r, Recording) else Recording(samples=r) for r in recordings]
        names = [r.samples.device for r in block]
        if len(set(names)) != len(names):
            raise ValueError(f"one block holds device {max(names, key=names.count)!r} twice")
        batches = []
        for recording in block:
            device = self._device(recording, several=len(block) > 1)
            batches += self._encode(device, recording)
        times = [stamps for _, stamps, _ in batches if len(stamps)]
        if times:
            first = min(int(stamps.min()) for stamps in times)
            if first < self._last_time:
                raise ValueError(
                    f"this block starts at {first * 1e-9:.9f} s, before the end of the previous "
                    f"block ({self._last_time * 1e-9:.9f} s): write blocks in time order"
                )
            self._last_time = max(self._last_time, max(int(stamps.max()) for stamps in times))
            return batches
        return None

    def _tf_channel(self, topic: str) -> int:
        if topic not in self._tf_channels:
            schema_id = self._mcap.register_schema(TF_MESSAGE_TYPE, "ros2msg", tf_schema().encode())
            qos = TF_STATIC_QOS_PROFILES if topic == TF_STATIC_TOPIC else OFFERED_QOS_PROFILES
            self._tf_channels[topic] = self._mcap.register_channel(
                topic, "cdr", schema_id, {"offered_qos_profiles": qos}
            )
        return self._tf_channels[topic]

    def _tf_rows(
        self,
        device: str,
        child: str,
        stamp_ns: NDArray[np.int64],
        pos: NDArray[np.float64] | None,
        q_wb: NDArray[np.float64],
    ) -> tuple[int, NDArray[np.int64], NDArray[np.uint8]] | None:
        """``/tf`` batch ``map`` -> ``child`` of one block of a series (thinned), or None."""
        if self._tf_rate_hz is None:
            return None
        owner = self._tf.get(child)
        if owner is None:
            owner = self._tf[child] = (device, _TfSeries(child, TfThinning(self._tf_rate_hz)))
        if owner[0] != device:
            return None
        series = owner[1]
        valid = np.all(np.isfinite(q_wb), axis=1)
        stamp_ns, q_wb = stamp_ns[valid], q_wb[valid]
        pos = np.zeros((len(stamp_ns), 3)) if pos is None else pos[valid]
        if not len(stamp_ns):
            return None
        index = series.thinning.keep(stamp_ns)
        xyzw = q_wb[:, [1, 2, 3, 0]]
        series.last = (int(stamp_ns[-1]), pos[-1].copy(), xyzw[-1].copy())
        if not len(index):
            return None
        rows = encode_tf(stamp_ns[index], [(WORLD_FRAME, child)], pos[index, None, :], xyzw[index, None, :])
        return (self._tf_channel(TF_TOPIC), stamp_ns[index], rows)

    def _encode_tf(self, device: _DeviceChannels, recording: Recording, stamp_ns: NDArray[np.int64]) -> EncodedBlock:
        """``/tf_static`` (once per device) and ``/tf`` batches of a recording's block."""
        batches = []
        if device.mounting is not None and not device.static_written and len(stamp_ns):
            q_bs, lever = device.mounting
            static_rows = encode_tf(
                stamp_ns[:1], [(BODY_FRAME, device.frame_id)], lever[None, None], q_bs[None, None, [1, 2, 3, 0]]
            )
            batches.append((self._tf_channel(TF_STATIC_TOPIC), stamp_ns[:1], static_rows))
            device.static_written = True
        pose, truth, estimate = recording.pose, recording.truth, recording.estimate
        position = None
        if pose is not None:
            pose_ns = self._series_stamps(recording, pose.t, "pose.t", stamp_ns)
            rows = self._tf_rows(
                device.name, BODY_FRAME, pose_ns, np.asarray(pose.pos_w, float), np.asarray(pose.q_wb, float)
            )
            position = (pose_ns, np.asarray(pose.pos_w, float))
        elif truth is not None and truth.q_wb is not None:
            truth_ns = self._series_stamps(recording, truth.t, "truth.t", stamp_ns)
            rows = self._tf_rows(device.name, BODY_FRAME, truth_ns, None, np.asarray(truth.q_wb, float))
        else:
            rows = None
        if rows is not None:
            batches.append(rows)
        if estimate is not None and estimate.q_wb is not None:
            est_ns = self._series_stamps(recording, estimate.t, "estimate.t", stamp_ns)
            pos = None
            if position is not None and len(position[0]) == len(est_ns) and np.array_equal(position[0], est_ns):
                pos = position[1]
            rows = self._tf_rows(device.name, ESTIMATE_FRAME, est_ns, pos, np.asarray(estimate.q_wb, float))
            if rows is not None:
                batches.append(rows)
        return batches

    def _series_stamps(
        self, recording: Recording, t: ArrayLike, what: str, stamp_ns: NDArray[np.int64]
    ) -> NDArray[np.int64]:
        """A truth, estimate or pose series' stamps, ns: the samples' exact stamps where they are the same."""
        series_ns = _log_stamps(t, what, self._start_ns)
        if (
            recording.stamp_ns is not None
            and len(series_ns) == len(stamp_ns)
            and np.abs(series_ns - stamp_ns).max(initial=0) <= 1000
        ):
            return stamp_ns
        return series_ns

    def _encode(self, device: _DeviceChannels, recording: Recording) -> EncodedBlock:
        """``(channel_id, stamp_ns, payloads)`` of every channel of a recording."""
        samples = recording.samples
        stamp_ns = _log_stamps(samples.t, "samples.t", self._start_ns)
        if recording.stamp_ns is not None:
            exact = np.asarray(recording.stamp_ns, dtype=np.int64)
            if exact.shape != stamp_ns.shape or np.abs(exact - stamp_ns).max(initial=0) > 1000:
                raise ValueError("stamp_ns must be the samples' stamps (samples.t) in ns")
            stamp_ns = exact
        batches = []
        rows = encode_measured(stamp_ns, device.frame_id, samples, *device.variances)
        batches.append((self._channel(device, IMU_ROLE), stamp_ns, rows))
        if samples.has_mag or MAG_ROLE in device.channels:
            rows = encode_mag(stamp_ns, device.frame_id, samples)
            batches.append((self._channel(device, MAG_ROLE), stamp_ns, rows))
        for role, what, series in (
            (TRUTH_ROLE, "truth", recording.truth),
            (ESTIMATE_ROLE, "estimate", recording.estimate),
        ):
            if series is not None:
                series_ns = self._series_stamps(recording, series.t, f"{what}.t", stamp_ns)
                rows = encode_series(series_ns, series)
                batches.append((self._channel(device, role), series_ns, rows))
        if recording.pose is not None:
            pose_ns = self._series_stamps(recording, recording.pose.t, "pose.t", stamp_ns)
            batches.append((self._channel(device, POSE_ROLE), pose_ns, encode_pose(pose_ns, recording.pose)))
        for kind, observables in samples.raw.items():
            role = raw_role(kind)
            if role_message_type(role) is None:
                if kind not in device.warned:
                    device.warned.add(kind)
                    warnings.warn(
                        f"{self.path}: no message type for the raw observables of gyro kind {kind!r}; not recorded",
                        LogWarning,
                        stacklevel=3,
                    )
                continue
            mtype, rows, ignored = encode_raw(stamp_ns, device.frame_id, kind, observables)
            if ignored and kind + "/ignored" not in device.warned:
                device.warned.add(kind + "/ignored")
                warnings.warn(
                    f"{self.path}: {mtype.name} has no field for {', '.join(ignored)}; not recorded",
                    LogWarning,
                    stacklevel=3,
                )
            batches.append((self._channel(device, role), stamp_ns, rows))
        if recording.movement is not None:
            rows = encode_movement(stamp_ns, device.frame_id, recording.movement)
            batches.append((self._channel(device, MOVEMENT_ROLE), stamp_ns, rows))
        return batches + self._encode_tf(device, recording, stamp_ns)

    def _finish_tf(self) -> None:
        """The last sample of every /tf series, where thinning left it out: tf2 cannot extrapolate, so
        the tree then reaches the last IMU stamp."""
        for _, series in self._tf.values():
            if series.last is not None and series.thinning.last():
                stamp, pos, xyzw = series.last
                rows = encode_tf([stamp], [(WORLD_FRAME, series.child)], pos[None, None], xyzw[None, None])
                self._mcap.add_messages([(self._tf_channel(TF_TOPIC), np.array([stamp], np.int64), rows)])

    def close(self) -> None:
        """Finish the file (summary, footer), flush it to disk and move it to :attr:`path`."""
        if self._closed:
            return
        try:
            self._finish_tf()
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            os.replace(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise
        self._closed = True

    def abort(self) -> None:
        """Drop the temporary file; nothing appears at :attr:`path`."""
        self._closed = True
        try:
            self._file.close()
        finally:
            self._tmp.unlink(missing_ok=True)


def _log_stamps(t: ArrayLike, what: str, start_ns: int) -> NDArray[np.int64]:
    """The log times of stamps ``t`` (s from ``start_ns``): unsigned, so none before the Unix epoch (a
    stamp before ``start_ns``, a clock that runs behind, is a valid time)."""
    stamp_ns = stamps_to_ns(t) + start_ns
    if len(stamp_ns) and stamp_ns.min() < 0:
        raise ValueError(
            f"{what} has stamps before 1970 ({stamp_ns.min() * 1e-9:g} s from the epoch): MCAP log times are unsigned"
        )
    return stamp_ns


def write_mcap(
    path: str | os.PathLike[str],
    recordings: ImuSamples | Recording | Sequence[ImuSamples | Recording],
    *,
    scenario: Scenario | str | None = None,
    prefix_topics: bool | None = None,
    chunk_size: int = 1 << 20,
    compression_level: int = COMPRESSION_LEVEL,
) -> Path:
    """Write a whole log at once: ``recordings`` is an :class:`ImuSamples`, a :class:`Recording`, or a
    list of them (one per device). Returns the path written. See :class:`McapLogWriter`."""
    if isinstance(recordings, (ImuSamples, Recording)):
        recordings = [recordings]
    with McapLogWriter(
        path, scenario=scenario, prefix_topics=prefix_topics, chunk_size=chunk_size, compression_level=compression_level
    ) as log:
        log.write(*recordings)
    return log.path


# ==================================================================================================
# Reading: from channels to devices.


def match_stamps(
    reference_ns: NDArray[np.int64], stamp_ns: NDArray[np.int64]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``(i, j)`` with ``reference_ns[i] == stamp_ns[j]`` (first match of each, in order): how a
    device's samples find their messages on its other topics."""
    if len(reference_ns) == len(stamp_ns) and np.array_equal(reference_ns, stamp_ns):
        index = np.arange(len(stamp_ns))
        return index, index
    if not len(stamp_ns):
        return np.empty(0, np.int64), np.empty(0, np.int64)
    order = np.argsort(stamp_ns, kind="stable")
    ordered = stamp_ns[order]
    position = np.minimum(np.searchsorted(ordered, reference_ns), len(ordered) - 1)
    i = np.flatnonzero(ordered[position] == reference_ns)
    return i, order[position[i]]


def match_latest(
    reference_ns: NDArray[np.int64], stamp_ns: NDArray[np.int64], previous_ns: int | None = None
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices ``(i, j)``: each sample i with the latest message j stamped in its interval
    (reference[i−1], reference[i]], how a device's samples find their field (``/mag`` on its own clock or
    at a lower rate: the newest reading when the sample is taken, at most one sample interval old).
    The first sample's interval starts at ``previous_ns`` (the sample before it, of an earlier block),
    or, without one, holds its own stamp only. A message at a sample's own stamp pairs with it, as
    :func:`match_stamps` pairs it; of several in one interval the latest (at equal stamps, the later in
    file order)."""
    if len(reference_ns) == len(stamp_ns) and np.array_equal(reference_ns, stamp_ns):
        index = np.arange(len(stamp_ns))
        return index, index
    if not len(stamp_ns) or not len(reference_ns):
        return np.empty(0, np.intp), np.empty(0, np.intp)
    order = np.argsort(stamp_ns, kind="stable")
    ordered = stamp_ns[order]
    latest = np.searchsorted(ordered, reference_ns, side="right") - 1  # the last message at or before each
    start = int(reference_ns[0]) - 1 if previous_ns is None else int(previous_ns)
    lower = np.concatenate(([start], reference_ns[:-1]))  # each interval's open end
    i = np.flatnonzero((latest >= 0) & (ordered[np.maximum(latest, 0)] > lower))
    return i, order[latest[i]]


def unpaired_field(path: Path, count: int, total: int, imu_topic: str, topic: str) -> str:
    """The warning for ``count`` of ``total`` messages on the field's ``topic`` that no sample of
    ``imu_topic`` takes (:func:`match_latest`)."""
    return (
        f"{path}: {count} of {total} messages on {topic} are not used: before the first sample of "
        f"{imu_topic}, after its last, or not the latest in a sample's interval"
    )


def no_imu_error(scan: McapScan, path: str | Path) -> LogError:
    """The error for a scanned file that holds no IMU messages: what it holds instead, and where it
    was cut off when truncated."""
    state = (
        f"; truncated at byte {scan.truncated_at}, {scan.message_count} messages recovered"
        if scan.truncated_at is not None
        else ""
    )
    return LogError(
        f"holds no sensor_msgs/msg/Imu messages ({len(scan.channels)} channels, {scan.message_count} messages{state})",
        file=path,
    )


def read_mcap(path: str | os.PathLike[str]) -> McapLog:
    """Read a ``ros2`` MCAP log: every ``sensor_msgs/msg/Imu`` channel becomes a device's samples.

    Topics named as gyroemu names them (``[/<device>]/imu``, ``/mag``, ``/truth/imu``,
    ``/estimate/imu``, ``/raw/<kind>``, ``/movement``) are grouped by device; any other Imu topic is a
    device of its own, named after the topic. Measured samples get the ``/mag`` field (NaN where absent)
    and the raw observables at their stamps (samples without raw counterparts are dropped, with a
    warning); ``/movement`` becomes :attr:`DeviceLog.movement` at the same stamps (False, with a warning,
    where a sample has none).

    Raises
    ------
    LogError
        The file cannot be opened, is not MCAP, is corrupt, or holds no IMU messages (also when it is
        truncated before the first complete chunk).

    Warns
    -----
    LogWarning
        For channels of types gyroemu does not decode (skipped), and for a truncated file (with the
        number of messages recovered).
    """
    path = Path(path)
    scan = McapScan(path).run()
    skipped = announce_scan(path, scan)
    decoded = scan.decode()
    metadata = [dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"]
    devices = _devices(path, decoded, metadata, skipped)
    if not devices:
        raise no_imu_error(scan, path)
    return McapLog(
        path=path,
        devices=devices,
        metadata=metadata,
        profile=scan.profile,
        message_count=scan.message_count,
        truncated=scan.truncated_at is not None,
        skipped=skipped,
        channels=tuple(scan.channel_info()),
    )


def announce_scan(path: Path, scan: McapScan) -> dict[str, str]:
    """Warn (:class:`LogWarning`) of a truncated file and of each topic the scan skipped, as
    :func:`read_mcap` does; returns the skipped topics and reasons (the tf tree, which
    :func:`read_tf` reads, is not skipped)."""
    skipped = dict(scan.skipped)
    if scan.truncated_at is not None:
        warnings.warn(
            f"{path}: truncated at byte {scan.truncated_at} (no MCAP footer): recovered "
            f"{scan.message_count} messages from {scan.chunks} complete chunks",
            LogWarning,
            stacklevel=3,
        )
    for topic in {c.topic for c in scan.channels.values() if _is_tf(c.topic, scan, c)}:
        skipped.pop(topic, None)
    for topic, reason in skipped.items():
        warnings.warn(f"{path}: skipping topic {topic}: {reason}", LogWarning, stacklevel=3)
    return skipped


@dataclass(frozen=True)
class LogCheck:
    """What :func:`check_mcap_noting` found in a log that it validated.

    Attributes
    ----------
    path : Path
    channels : tuple of ChannelInfo
        Every channel of the file (decoded or not) with its schema, in file order.
    metadata : list of dict
        Every ``gyroemu`` metadata record.
    message_count : int
        Messages read (every channel, decoded or not).
    truncated : bool
        The file ends before its footer: only complete chunks were read.
    """

    path: Path
    channels: tuple[ChannelInfo, ...]
    metadata: list[dict[str, str]]
    message_count: int
    truncated: bool


def check_mcap_noting(path: str | os.PathLike[str], note: Callable[[str], None]) -> LogCheck:
    """Validate a log as :func:`read_mcap` reads it, in one pass of bounded memory (a chunk at a time:
    every message of a type gyroemu decodes is decoded and dropped), for a command that serves the log's
    messages as recorded (replay, view). Its warnings but the skipped topics go to ``note`` (one line
    each): a topic such a command does not decode is no news.

    Raises :class:`LogError` where :func:`read_mcap` would for the file itself (not MCAP, corrupt, a
    message its type cannot decode, no IMU messages)."""
    path = Path(path)
    scan = McapScan(path)
    counts = scan.check()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogWarning)
        announce_scan(path, scan)
    for w in caught:
        if issubclass(w.category, LogWarning) and "skipping topic" not in str(w.message):
            note(str(w.message))
    if not any(counts.get(i) and scan.data[i].mtype is IMU for i in scan.data):
        raise no_imu_error(scan, path)
    return LogCheck(
        path=path,
        channels=tuple(scan.channel_info()),
        metadata=[dict(m.metadata) for m in scan.metadata if m.name == "gyroemu"],
        message_count=scan.message_count,
        truncated=scan.truncated_at is not None,
    )


def _is_tf(topic: str, scan: McapScan, channel: Channel) -> bool:
    schema = scan.schemas.get(channel.schema_id)
    return topic in (TF_TOPIC, TF_STATIC_TOPIC) and schema is not None and schema.name == TF_MESSAGE_TYPE


def read_tf(path: str | os.PathLike[str], static: bool | None = None) -> Transforms:
    """Every transform on ``/tf`` and ``/tf_static`` (``static`` True or False: only that topic) of a log,
    in file order; empty for a log without them (logs written before gyroemu wrote a tf tree).
    ``LogError`` for a file that is not MCAP or is corrupt; ``ValueError`` for a malformed TFMessage."""
    topics = [TF_TOPIC, TF_STATIC_TOPIC] if static is None else [TF_STATIC_TOPIC if static else TF_TOPIC]
    payloads = [m.data for batch in iter_mcap_batches(path, topics) for m in batch if m.schema == TF_MESSAGE_TYPE]
    return decode_tf(payloads)


class TypedChannel(Protocol):
    """A channel known by its topic and the message type gyroemu decodes it as."""

    topic: str
    mtype: MessageType


ChannelT = TypeVar("ChannelT", bound=TypedChannel)


def group_devices(path: Path, channels: Iterable[ChannelT], skipped: dict[str, str]) -> dict[str, dict[str, ChannelT]]:
    """Topic prefix → role → channel: the channels (anything with ``topic`` and ``mtype``, of a type
    gyroemu decodes) grouped into devices as :func:`read_mcap` groups them: by prefix (``/<device>/imu``,
    ``/<device>/mag``, ...), an IMU topic of no role (``/imu/data_raw``) a device of its own, which takes
    the field of the nearest namespace above it that has no IMU topic (``/imu/mag``, before a root
    ``/mag``; each IMU topic at most one field). An estimate without an IMU topic beside it
    (``/estimate/imu``, which ``gyroemu estimate`` writes for a foreign topic) is the estimate of the log's
    one measured device (:func:`is_the_devices_estimate`), else a device of its own, as a lone truth is.
    Topics that belong to no device go into ``skipped`` with the reason (and a :class:`LogWarning`). The
    grouping does not depend on the order the channels come in."""
    groups: dict[str, dict[str, ChannelT]] = {}
    for d in channels:
        topic, mtype = d.topic, d.mtype
        prefix, role = split_topic(topic)
        if role and not role_accepts(role, mtype):
            role = ""  # e.g. a /raw/x topic of a standard type: take it as a plain topic
        role = canonical_role(role)  # an older log's /raw/rate-gyro is role raw/rate_gyro
        if not role:
            if mtype is IMU:
                groups.setdefault(topic, {})[IMU_ROLE] = d
            else:
                skipped[topic] = f"a {mtype.name} topic that belongs to no IMU topic"
                warnings.warn(f"{path}: skipping topic {topic}: {skipped[topic]}", LogWarning, stacklevel=3)
            continue
        groups.setdefault(prefix, {})[role] = d
    measured = [key for key, g in groups.items() if IMU_ROLE in g]
    # A field with no IMU topic beside it goes to the IMU topics under its namespace that have no field
    # of their own, the nearest namespace first (a driver's /imu/data_raw takes /imu/mag, not /mag).
    fields = sorted((p for p, g in groups.items() if IMU_ROLE not in g and MAG_ROLE in g), key=len, reverse=True)
    taken: set[str] = set()
    for key in measured:
        group = groups[key]
        if MAG_ROLE not in group:
            topic = group[IMU_ROLE].topic
            nearest = next((p for p in fields if topic.startswith(p + "/")), None)
            if nearest is not None:
                group[MAG_ROLE] = groups[nearest][MAG_ROLE]
                taken.add(nearest)
    for prefix in taken:
        del groups[prefix][MAG_ROLE]
    # `estimate`'s output for a foreign IMU topic (/estimate/imu): the estimate of the log's one device.
    lone = [p for p, g in groups.items() if IMU_ROLE not in g and ESTIMATE_ROLE in g]
    if is_the_devices_estimate(len(measured), len(lone), any(ESTIMATE_ROLE in groups[k] for k in measured)):
        groups[measured[0]][ESTIMATE_ROLE] = groups[lone[0]].pop(ESTIMATE_ROLE)
    # Truth or estimate without a measured IMU: a device of its own (it holds Imu messages); what else is
    # left belongs to no device.
    for prefix in [p for p, g in groups.items() if IMU_ROLE not in g]:
        group = groups.pop(prefix)
        for role in (TRUTH_ROLE, ESTIMATE_ROLE):  # a lone /truth/pose has no Imu messages: skipped
            if role in group:
                groups[role_topic(role, prefix)] = {IMU_ROLE: group.pop(role)}
        for d in group.values():
            topic = d.topic
            skipped[topic] = "no IMU topic of the same device"
            warnings.warn(f"{path}: skipping topic {topic}: {skipped[topic]}", LogWarning, stacklevel=3)
    return groups


def is_the_devices_estimate(measured: int, lone_estimates: int, device_has_one: bool) -> bool:
    """Whether an estimate topic with no IMU topic beside it (``/estimate/imu``, as ``gyroemu estimate``
    writes it for a foreign IMU topic) is the log's measured device's: the log has one measured device
    (``measured``), one such estimate (``lone_estimates``), and the device no estimate of its own."""
    return measured == 1 and lone_estimates == 1 and not device_has_one


def device_name(prefix: str, metadata: list[dict[str, str]]) -> tuple[str, dict[str, str] | None]:
    """A device's name and its ``gyroemu`` metadata record (None without one), from its topic prefix."""
    records = {m.get("topic_prefix", ""): m for m in metadata}
    meta = records.get(prefix) or (metadata[0] if prefix == "" and len(metadata) == 1 else None)
    return (meta or {}).get("device_name") or (prefix.strip("/") or "imu0"), meta


def _devices(
    path: Path, decoded: dict[int, DecodedChannel], metadata: list[dict[str, str]], skipped: dict[str, str]
) -> dict[str, DeviceLog]:
    """Group decoded channels into devices."""
    devices = {}
    for prefix, group in group_devices(path, decoded.values(), skipped).items():
        if not len(group[IMU_ROLE].batch):
            continue
        name, meta = device_name(prefix, metadata)
        devices[name] = _device_log(path, name, group, meta)
    return devices


def dropped_samples(path: Path, count: int, imu_topic: str, topic: str) -> str:
    """The warning for ``count`` samples of ``imu_topic`` dropped for want of a message on the raw ``topic``."""
    return f"{path}: {count} samples of {imu_topic} have no message on {topic} at their stamp; dropped"


def unflagged_samples(path: Path, count: int, imu_topic: str, topic: str) -> str:
    """The warning for ``count`` samples of ``imu_topic`` without a ``/movement`` message on ``topic``."""
    return (
        f"{path}: {count} samples of {imu_topic} have no message on {topic} at their stamp; "
        "their movement flag is False"
    )


def _device_log(path: Path, name: str, group: dict[str, DecodedChannel], meta: dict[str, str] | None) -> DeviceLog:
    imu = group[IMU_ROLE]
    stamp_ns = imu.batch.stamp_ns
    keep = np.arange(len(stamp_ns))
    raw: dict[str, dict[str, NDArray[Any]]] = {}
    for role, d in group.items():
        if raw_kind(role) is not None:
            i, j = match_stamps(stamp_ns[keep], d.batch.stamp_ns)
            if len(i) < len(keep):
                warnings.warn(dropped_samples(path, len(keep) - len(i), imu.topic, d.topic), LogWarning, stacklevel=4)
                keep = keep[i]
                raw = {k: {n: v[i] for n, v in obs.items()} for k, obs in raw.items()}
            kind = cast(str, d.mtype.kind)  # a raw role's type is a raw type (role_accepts): it has a kind
            raw[kind] = {n: v[j] for n, v in raw_observables(d.mtype, d.batch).items()}
    mag = np.full((len(keep), 3), np.nan)
    if MAG_ROLE in group:
        d = group[MAG_ROLE]
        i, j = match_latest(stamp_ns[keep], d.batch.stamp_ns)
        mag[i] = d.batch["magnetic_field"][j]
        if len(i) < len(d.batch.stamp_ns):
            warnings.warn(
                unpaired_field(path, len(d.batch.stamp_ns) - len(i), len(d.batch.stamp_ns), imu.topic, d.topic),
                LogWarning,
                stacklevel=4,
            )
    movement = None
    if MOVEMENT_ROLE in group:
        d = group[MOVEMENT_ROLE]
        i, j = match_stamps(stamp_ns[keep], d.batch.stamp_ns)
        movement = np.zeros(len(keep), dtype=bool)
        movement[i] = d.batch["data"][j]
        if len(i) < len(keep):
            warnings.warn(unflagged_samples(path, len(keep) - len(i), imu.topic, d.topic), LogWarning, stacklevel=4)
    batch = imu.batch
    variances = []
    for cov_field in ("angular_velocity_covariance", "linear_acceleration_covariance"):
        first = batch[cov_field][0].reshape(3, 3) if len(batch) else np.zeros((3, 3))
        variances.append(np.diag(first).copy() if first[0, 0] > 0 else None)
    samples = ImuSamples(
        t=ns_to_stamps(stamp_ns[keep]),
        gyro=batch["angular_velocity"][keep],
        accel=batch["linear_acceleration"][keep],
        mag=mag,
        raw=raw,
        device=name,
    )
    return DeviceLog(
        name=name,
        topics={role: d.topic for role, d in group.items()},
        samples=samples,
        stamp_ns=stamp_ns[keep],
        truth=series_from_batch(group[TRUTH_ROLE].batch) if TRUTH_ROLE in group else None,
        estimate=series_from_batch(group[ESTIMATE_ROLE].batch) if ESTIMATE_ROLE in group else None,
        metadata=meta,
        movement=movement,
        pose=pose_from_batch(group[POSE_ROLE].batch) if POSE_ROLE in group else None,
        frame_id=str(batch.frame_id[0]) if len(batch) else "",
        gyro_variance=variances[0],
        accel_variance=variances[1],
    )
