"""gyroemu's channel vocabulary: topics, their roles, message types and frame ids, and the encoding of
samples and series into message fields.

Every channel gyroemu writes, streams or reads is ``<prefix>/<role>`` (``interface.md``): the prefix is
empty, or ``/<device>`` when one file holds several devices, and the role says what the channel holds:

==================  ======================================  =================================  ===========
role                type                                    holds                              frame id
==================  ======================================  =================================  ===========
``imu``             ``sensor_msgs/msg/Imu``                 the device's ``gyro``, ``accel``   the device
``mag``             ``sensor_msgs/msg/MagneticField``       the device's ``mag`` (tesla)       the device
``truth/imu``       ``sensor_msgs/msg/Imu``                 an :class:`ImuSeries` (truth)      ``base_link``
``estimate/imu``    ``sensor_msgs/msg/Imu``                 an :class:`ImuSeries` (estimate)   ``base_link``
``raw/<token>``     ``gyroemu_msgs/msg/<Kind>Raw``          the gyro kind's raw observables    the device
``movement``        ``gyroemu_msgs/msg/Flag``               an imported dataset's sample mask  the device
``truth/pose``      ``geometry_msgs/msg/PoseStamped``       a :class:`PoseSeries` (truth)      ``map``
==================  ======================================  =================================  ===========

A pose's ``frame_id`` is the frame it is given in, the world (ENU), which REP 105 calls ``map``.

A raw role's ``<token>`` is the gyro kind with ``-`` as ``_`` (:func:`topic_token`: ``raw/rate_gyro`` for kind
``rate-gyro``), so that every topic is a valid ROS 2 name (letters, digits, ``_`` and ``/``): the one rule
by which the log writer, the live stream, the recorder and the ROS 2 names of
:mod:`gyroemu.pipelines.formats.ros2_keys` turn gyroemu's names into topics. Logs written before it name
three kinds' topics with the hyphen (``/raw/rate-gyro``, ``/raw/rate-integrating``, ``/raw/free-gyro``):
:func:`raw_kind` reads both spellings, and :func:`canonical_role` gives such a role today's name.

Live streams (:mod:`gyroemu.pipelines.transport.zenoh_io`) carry the same roles but ``movement``
(:func:`is_stream_role`); ``gyroemu stream`` does not publish ``truth/pose``, but a replayed file's
pose goes out under its device's key and a recorder stores it back.

:func:`split_topic` is the one parser of a topic into its prefix and role; the modules that name
channels (the MCAP log writer and reader :mod:`gyroemu.pipelines.formats.mcap_log`, the stream, the live
estimator, the recorder, replay and the ROS 2 names of :mod:`gyroemu.pipelines.formats.ros2_keys`) ask
it, and build topics with :func:`role_topic`.

The encoding of what a channel holds into message fields is here too, once: :func:`measured_fields`
(``/imu``), :func:`series_fields` (``/truth/imu``, ``/estimate/imu``; :func:`series_from_batch` reads it
back) and the ``encode_*`` functions that turn them into CDR rows with :meth:`MessageType.encode`
(:mod:`gyroemu.pipelines.formats.messages`), so a file, a stream and a live estimate hold the same bytes.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.pipelines.formats.messages import (
    FLAG,
    IMU,
    MAGNETIC_FIELD,
    POSE_STAMPED,
    RAW_MESSAGE_TYPES,
    DecodedBatch,
    MessageType,
    ns_to_stamps,
    raw_fields,
)

if TYPE_CHECKING:
    from gyroemu.sensors.samples import ImuSamples

__all__ = [
    "IMU_ROLE",
    "MAG_ROLE",
    "TRUTH_ROLE",
    "ESTIMATE_ROLE",
    "MOVEMENT_ROLE",
    "POSE_ROLE",
    "BODY_FRAME",
    "WORLD_FRAME",
    "ESTIMATE_FRAME",
    "RESERVED_DEVICE_NAMES",
    "topic_token",
    "raw_role",
    "raw_kind",
    "canonical_role",
    "canonical_topic",
    "role_topic",
    "split_topic",
    "absolute_topic",
    "is_device_prefix",
    "is_prefix_name",
    "is_stream_role",
    "role_message_type",
    "role_accepts",
    "topic_message_type",
    "ImuSeries",
    "PoseSeries",
    "measured_fields",
    "series_fields",
    "series_from_batch",
    "encode_measured",
    "encode_mag",
    "encode_series",
    "encode_raw",
    "encode_movement",
    "encode_pose",
    "pose_from_batch",
]

IMU_ROLE = "imu"
"""The device's measured rate and specific force (``sensor_msgs/msg/Imu``)."""
MAG_ROLE = "mag"
"""The device's measured magnetic field (``sensor_msgs/msg/MagneticField``)."""
TRUTH_ROLE = "truth/imu"
"""True body attitude, rate and specific force (``sensor_msgs/msg/Imu``)."""
ESTIMATE_ROLE = "estimate/imu"
"""An attitude filter's estimate (``sensor_msgs/msg/Imu``)."""
MOVEMENT_ROLE = "movement"
"""An imported dataset's mask of the samples that count (``gyroemu_msgs/msg/Flag``); files only."""
POSE_ROLE = "truth/pose"
"""True position and attitude in the world frame (``geometry_msgs/msg/PoseStamped``)."""
_RAW = "raw/"

BODY_FRAME = "base_link"
"""``frame_id`` of body-frame channels (``/truth/imu``, ``/estimate/imu``), REP-105's name for the body."""

WORLD_FRAME = "map"
"""``frame_id`` of world-frame channels (``/truth/pose``): the ENU world, REP-105's ``map``."""

ESTIMATE_FRAME = "body_estimate"
"""The tf frame a filter's estimated attitude places (``map`` -> ``body_estimate`` on ``/tf``, from
``/estimate/imu``): in logs (:mod:`gyroemu.pipelines.formats.frames`) and in the Foxglove view."""

RESERVED_DEVICE_NAMES = frozenset({"truth", "estimate", "raw", "imu", "mag"})
"""Names that cannot prefix topics: ``/imu/imu`` or ``/raw/imu`` would read as another device's role."""
_DEVICE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

_ROLE = re.compile(
    rf"^(?P<prefix>.*?)/(?P<role>{TRUTH_ROLE}|{POSE_ROLE}|{ESTIMATE_ROLE}|{_RAW}[^/]+|{IMU_ROLE}|{MAG_ROLE}|{MOVEMENT_ROLE})$"
)
_DEVICE_PREFIX = re.compile(r"^(/[^/]+)?$")


def topic_token(name: str) -> str:
    """``name`` as a token of a topic: ``-`` becomes ``_`` (``rate-gyro`` -> ``rate_gyro``), since ROS 2
    names hold letters, digits and ``_`` only. The one rule that turns gyroemu's names (gyro kinds) into
    topic names, in files, on live streams and in ROS 2 mode."""
    return name.replace("-", "_")


_RAW_KINDS = {topic_token(kind): kind for kind in RAW_MESSAGE_TYPES}
"""A raw role's token (either spelling, :func:`topic_token` of it) -> the gyro kind with a message type."""


def raw_role(kind: str) -> str:
    """The role of gyro ``kind``'s raw observables: ``raw/<kind with - as _>`` (``raw/rate_gyro``)."""
    return f"{_RAW}{topic_token(kind)}"


def raw_kind(role: str) -> str | None:
    """The gyro kind of a ``raw/<token>`` role, None for other roles: a kind with a message type from
    either spelling (``raw/rate_gyro`` and, as logs written before named it, ``raw/rate-gyro``:
    ``rate-gyro``), else the token itself."""
    if not role.startswith(_RAW):
        return None
    token = role[len(_RAW) :]
    return _RAW_KINDS.get(topic_token(token), token)


def canonical_role(role: str) -> str:
    """``role`` as gyroemu names it now: the raw role of a kind with a message type by :func:`raw_role`
    (``raw/rate-gyro``, an older log's, -> ``raw/rate_gyro``); any other role unchanged."""
    kind = raw_kind(role)
    return raw_role(kind) if kind is not None and kind in RAW_MESSAGE_TYPES else role


def canonical_topic(topic: str) -> str:
    """``topic`` with its role as gyroemu names it now (:func:`canonical_role`): ``/a/raw/rate-gyro`` ->
    ``/a/raw/rate_gyro``; a topic of no role unchanged."""
    prefix, role = split_topic(topic)
    return role_topic(canonical_role(role), prefix) if role else topic


def role_topic(role: str, prefix: str = "") -> str:
    """The topic of ``role`` under a device prefix (``""`` or ``/<device>``): ``("imu", "/a") -> "/a/imu"``."""
    return f"{prefix}/{role}"


def absolute_topic(topic: str) -> str:
    """A topic as given on the command line, with its leading slash (``imu_a`` -> ``/imu_a``)."""
    return topic if topic.startswith("/") else "/" + topic


def split_topic(topic: str) -> tuple[str, str]:
    """``(prefix, role)`` of a topic by gyroemu's naming (the shortest prefix that leaves a role:
    ``/a/b/raw/fog`` -> ``("/a/b", "raw/fog")``); role ``""`` (and the topic as prefix) when the topic
    does not follow it."""
    m = _ROLE.match(topic)
    if not m:
        return topic, ""
    return m.group("prefix"), m.group("role")


def is_device_prefix(prefix: str) -> bool:
    """Whether ``prefix`` is ``""`` or one name token ``/<device>`` (what the log writer puts before roles)."""
    return bool(_DEVICE_PREFIX.match(prefix))


def is_prefix_name(name: str) -> bool:
    """Whether device ``name`` can prefix topics: letters, digits and ``_``, starting with a letter, and
    none of :data:`RESERVED_DEVICE_NAMES`."""
    return bool(_DEVICE_NAME.match(name)) and name not in RESERVED_DEVICE_NAMES


def is_stream_role(role: str) -> bool:
    """Whether ``role`` goes on live streams too: every role but ``movement``."""
    return role in (IMU_ROLE, MAG_ROLE, TRUTH_ROLE, ESTIMATE_ROLE, POSE_ROLE) or raw_kind(role) is not None


def role_message_type(role: str) -> MessageType | None:
    """The message type of ``role``; None for a raw kind without a message type, or not a role."""
    kind = raw_kind(role)
    if kind is not None:
        return RAW_MESSAGE_TYPES.get(kind)
    return {
        IMU_ROLE: IMU,
        MAG_ROLE: MAGNETIC_FIELD,
        TRUTH_ROLE: IMU,
        ESTIMATE_ROLE: IMU,
        MOVEMENT_ROLE: FLAG,
        POSE_ROLE: POSE_STAMPED,
    }.get(role)


def role_accepts(role: str, mtype: MessageType) -> bool:
    """Whether a channel of type ``mtype`` can have ``role`` (a reader's check): its own type, or for a
    ``raw/<kind>`` role any raw type (the message type names the kind)."""
    if raw_kind(role) is not None:
        return mtype.kind is not None
    return mtype is role_message_type(role)


def topic_message_type(topic: str) -> MessageType | None:
    """The message type of a live-stream topic by its role (``/imu``, ``/truth/imu``: Imu; ``/mag``:
    MagneticField; ``/raw/<kind>``: the kind's raw type, any prefix), or None."""
    role = split_topic(topic)[1]
    return role_message_type(role) if is_stream_role(role) else None


# ==================================================================================================
# What channels hold, as message fields.


@dataclass(frozen=True, eq=False)
class ImuSeries:
    """The contents of a body-frame ``sensor_msgs/msg/Imu`` channel (truth or estimate), SI units.

    Attributes
    ----------
    t : ndarray (N,)
        Stamps, s.
    q_wb : ndarray (N, 4) or None
        Attitude, unit quaternion (w, x, y, z) turning body vectors into the world frame.
    omega_b : ndarray (N, 3) or None
        Angular velocity, body axes, rad/s.
    specific_force_b : ndarray (N, 3) or None
        Specific force, body axes, m/s².
    q_wb_covariance, omega_b_covariance, specific_force_b_covariance : ndarray (N, 3, 3) or None
        Covariances (orientation: rad², about the x, y, z axes). None writes zeros ("unknown").

    A quantity that is None is written as ``covariance[0] = -1`` ("no estimate"); reading gives None
    when every message says so, and NaN rows where only some do.
    """

    t: NDArray[np.float64]
    q_wb: NDArray[np.float64] | None = None
    omega_b: NDArray[np.float64] | None = None
    specific_force_b: NDArray[np.float64] | None = None
    q_wb_covariance: NDArray[np.float64] | None = None
    omega_b_covariance: NDArray[np.float64] | None = None
    specific_force_b_covariance: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        n = len(self.t)
        for name, width in (
            ("q_wb", (4,)),
            ("omega_b", (3,)),
            ("specific_force_b", (3,)),
            ("q_wb_covariance", (3, 3)),
            ("omega_b_covariance", (3, 3)),
            ("specific_force_b_covariance", (3, 3)),
        ):
            value = getattr(self, name)
            if value is not None and np.shape(value) != (n, *width):
                raise ValueError(f"{name} must have shape {(n, *width)}, got {np.shape(value)}")

    def __len__(self) -> int:
        return len(self.t)


_IMU_QUANTITIES = (
    ("q_wb", "q_wb_covariance", "orientation", "orientation_covariance"),
    ("omega_b", "omega_b_covariance", "angular_velocity", "angular_velocity_covariance"),
    ("specific_force_b", "specific_force_b_covariance", "linear_acceleration", "linear_acceleration_covariance"),
)
"""(ImuSeries attribute, its covariance, Imu field, its covariance) for each quantity of an Imu message."""

_NO_ESTIMATE = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
_NO_ESTIMATE.flags.writeable = False
"""An Imu covariance with element 0 at -1: "no estimate" of its quantity (sensor_msgs/msg/Imu)."""


@dataclass(frozen=True, eq=False)
class PoseSeries:
    """The contents of a ``geometry_msgs/msg/PoseStamped`` channel (``/truth/pose``), SI units.

    Attributes
    ----------
    t : ndarray (N,)
        Stamps, s.
    pos_w : ndarray (N, 3)
        Position of the body's reference point, world frame (ENU), m.
    q_wb : ndarray (N, 4)
        Attitude, unit quaternion (w, x, y, z) turning body vectors into the world frame.
    """

    t: NDArray[np.float64]
    pos_w: NDArray[np.float64]
    q_wb: NDArray[np.float64]

    def __post_init__(self) -> None:
        n = len(self.t)
        for name, width in (("pos_w", 3), ("q_wb", 4)):
            if np.shape(getattr(self, name)) != (n, width):
                raise ValueError(f"{name} must have shape ({n}, {width}), got {np.shape(getattr(self, name))}")

    def __len__(self) -> int:
        return len(self.t)


def encode_pose(stamp_ns: ArrayLike, pose: PoseSeries) -> NDArray[np.uint8]:
    """``/truth/pose`` rows of ``pose`` at ``stamp_ns``, frame :data:`WORLD_FRAME`."""
    q = np.asarray(pose.q_wb, dtype=float)
    return POSE_STAMPED.encode(
        stamp_ns, WORLD_FRAME, {"position": np.asarray(pose.pos_w, dtype=float), "orientation": q[:, [1, 2, 3, 0]]}
    )


def pose_from_batch(batch: DecodedBatch) -> PoseSeries:
    """A :class:`PoseSeries` from decoded PoseStamped messages (x, y, z, w to scalar-first)."""
    return PoseSeries(
        t=ns_to_stamps(batch.stamp_ns), pos_w=batch["position"].copy(), q_wb=batch["orientation"][:, [3, 0, 1, 2]]
    )


def measured_fields(
    samples: ImuSamples, gyro_variance: ArrayLike | None = None, accel_variance: ArrayLike | None = None
) -> dict[str, ArrayLike]:
    """Imu message fields of a device's samples (``/imu``): rate and specific force, no orientation
    (``orientation_covariance[0] = -1``). ``gyro_variance``, ``accel_variance`` (3,): the per-sample
    variances of the device's noise (:mod:`gyroemu.pipelines.formats.imu_covariance`), written on the
    covariances' diagonals; None leaves that covariance zero ("unknown", REP 145)."""
    fields: dict[str, ArrayLike] = {
        "orientation": (0.0, 0.0, 0.0, 1.0),
        "orientation_covariance": _NO_ESTIMATE,
        "angular_velocity": samples.gyro,
        "linear_acceleration": samples.accel,
    }
    if gyro_variance is not None:
        fields["angular_velocity_covariance"] = np.diag(np.asarray(gyro_variance, dtype=float)).reshape(9)
    if accel_variance is not None:
        fields["linear_acceleration_covariance"] = np.diag(np.asarray(accel_variance, dtype=float)).reshape(9)
    return fields


def series_fields(series: ImuSeries) -> dict[str, NDArray[np.float64] | tuple[float, ...]]:
    """Imu message fields of an :class:`ImuSeries` (scalar-first quaternions to x, y, z, w)."""
    n = len(series)
    fields: dict[str, NDArray[np.float64] | tuple[float, ...]] = {}
    for value_name, cov_name, field_name, cov_field in _IMU_QUANTITIES:
        value, cov = getattr(series, value_name), getattr(series, cov_name)
        if value is None:
            fields[cov_field] = _NO_ESTIMATE
            if field_name == "orientation":
                fields[field_name] = (0.0, 0.0, 0.0, 1.0)
            continue
        value = np.asarray(value, dtype=float)
        fields[field_name] = value[:, [1, 2, 3, 0]] if field_name == "orientation" else value
        if cov is not None:
            fields[cov_field] = np.asarray(cov, dtype=float).reshape(n, 9)
    return fields


def series_from_batch(batch: DecodedBatch) -> ImuSeries:
    """An :class:`ImuSeries` from decoded Imu messages, the inverse of :func:`series_fields` (x, y, z, w
    to scalar-first; -1 covariances to None, or NaN rows where only some messages have them)."""
    n = len(batch)
    out: dict[str, NDArray[np.float64] | None] = {}
    for value_name, cov_name, field_name, cov_field in _IMU_QUANTITIES:
        cov = batch[cov_field]
        absent = cov[:, 0] == -1.0
        if n and np.all(absent):
            out[value_name] = out[cov_name] = None
            continue
        value = batch[field_name]
        value = value[:, [3, 0, 1, 2]] if field_name == "orientation" else value.copy()
        cov = cov.reshape(n, 3, 3).copy()
        if np.any(absent):
            value[absent] = np.nan
            cov[absent] = np.nan
        out[value_name] = value
        out[cov_name] = cov if np.any(cov) else None
    return ImuSeries(t=ns_to_stamps(batch.stamp_ns), **out)


def encode_measured(
    stamp_ns: ArrayLike,
    frame_id: str,
    samples: ImuSamples,
    gyro_variance: ArrayLike | None = None,
    accel_variance: ArrayLike | None = None,
) -> NDArray[np.uint8]:
    """``/imu`` rows ``(N, size)`` of a device's samples at ``stamp_ns`` (variances: :func:`measured_fields`)."""
    return IMU.encode(stamp_ns, frame_id, measured_fields(samples, gyro_variance, accel_variance))


def encode_mag(stamp_ns: ArrayLike, frame_id: str, samples: ImuSamples) -> NDArray[np.uint8]:
    """``/mag`` rows of a device's samples (NaN fields where the device has no magnetometer)."""
    return MAGNETIC_FIELD.encode(stamp_ns, frame_id, {"magnetic_field": samples.mag})


def encode_series(stamp_ns: ArrayLike, series: ImuSeries) -> NDArray[np.uint8]:
    """``/truth/imu`` or ``/estimate/imu`` rows of ``series`` at ``stamp_ns``, frame :data:`BODY_FRAME`."""
    return IMU.encode(stamp_ns, BODY_FRAME, series_fields(series))


def encode_raw(
    stamp_ns: NDArray[np.int64], frame_id: str, kind: str, observables: Mapping[str, NDArray[Any]]
) -> tuple[MessageType, NDArray[np.uint8], list[str]]:
    """``/raw/<kind>`` rows of gyro ``kind``'s raw observables (``ImuSamples.raw[kind]``).

    Returns ``(type, rows, ignored)``, ``ignored`` the observables the message has no field for. Raises
    ``KeyError`` for a kind without a message type (:func:`role_message_type` of :func:`raw_role` is
    None) and ``ValueError`` for a missing field or one whose rows are not one per stamp.
    """
    mtype, fields, ignored = raw_fields(kind, observables)
    n = len(stamp_ns)
    for name, value in fields.items():
        if len(value) != n:
            raise ValueError(f"raw[{kind!r}][{name!r}] has {len(value)} rows for {n} samples")
    return mtype, mtype.encode(stamp_ns, frame_id, fields), ignored


def encode_movement(stamp_ns: NDArray[np.int64], frame_id: str, movement: ArrayLike) -> NDArray[np.uint8]:
    """``/movement`` rows: one ``gyroemu_msgs/msg/Flag`` per stamp (``ValueError`` unless ``movement``
    holds one boolean, or 0/1, per stamp)."""
    n = len(stamp_ns)
    movement = np.asarray(movement)
    if movement.shape != (n,) or not (movement.dtype == bool or np.isin(movement, (0, 1)).all()):
        raise ValueError(f"movement must be {n} booleans (one per sample), got {movement.dtype} {movement.shape}")
    return FLAG.encode(stamp_ns, frame_id, {"data": movement.astype(bool)})
