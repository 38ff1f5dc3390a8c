"""ROS 2 messages as CDR bytes, encoded and decoded whole arrays at a time.

gyroemu records and streams ``sensor_msgs/msg/Imu``, ``sensor_msgs/msg/MagneticField`` and its own
raw-observable messages (``gyroemu_msgs/msg/<Kind>Raw``, one per gyro kind) in the serialisation ROS 2
puts on the wire and in bags: **XCDR1 (plain CDR), little endian**. The same bytes go into MCAP files
(:mod:`gyroemu.pipelines.formats.mcap_log`) and zenoh payloads (``interface.md``).

Byte layout
-----------
Every serialised message starts with the 4-byte encapsulation header ``00 01 00 00`` (representation
identifier ``CDR_LE`` = 0x0001, big endian; then two option bytes). Alignment is relative to the first
byte *after* that header (the "payload"): a primitive of size s (1, 2, 4 or 8 bytes) starts at a payload
offset that is a multiple of s, padding bytes are zero. Fixed-size arrays (``float64[9]``) carry no
length, their elements follow each other; nested messages are their fields in order. A ``string`` is a
``uint32`` byte count that includes the terminating NUL, then the bytes and the NUL. No padding follows
the last field. Payload offsets, with ``L = len(frame_id) + 1``::

    0        int32   header.stamp.sec
    4        uint32  header.stamp.nanosec           (0 <= nanosec < 10^9; sec = floor(t))
    8        uint32  L
    12       char[L] header.frame_id, NUL-terminated
    a        ...     the body: a = 12 + L rounded up to the alignment of the first body field

``sensor_msgs/msg/Imu`` body (float64, a = 8-aligned): ``orientation`` x, y, z, w; ``orientation_covariance``
[9]; ``angular_velocity`` x, y, z; ``angular_velocity_covariance`` [9]; ``linear_acceleration`` x, y, z;
``linear_acceleration_covariance`` [9] -- 296 bytes, so with ``frame_id = "imu0"`` (L = 5, a = 24) a message
is 4 + 24 + 296 = 324 bytes. ``sensor_msgs/msg/MagneticField``: ``magnetic_field`` x, y, z and
``magnetic_field_covariance`` [9]. The raw types are listed in :data:`RAW_MESSAGE_TYPES`.
``gyroemu_msgs/msg/Flag`` (:data:`FLAG`) is a header and one ``bool data`` (one byte, no padding): with
``frame_id = "imu0"`` a message is 4 + 17 + 1 = 22 bytes.

With one ``frame_id`` per batch every message of a type has the same length and the same field offsets,
so a batch is a numpy structured array (explicit offsets, zeroed padding) viewed as an ``(N, size)``
``uint8`` array: one row per message, no Python loop. Decoding views received bytes the same way; a batch
with several frame-id lengths is split into groups of equal layout.

Readers accept up to 3 trailing bytes after the last field: XTypes (DDS-XTypes 1.3, 7.4.3.4) lets a
writer pad the serialised size to a multiple of 4 and count the padding in the low two bits of the
option bytes (Cyclone DDS does).

Message definitions
-------------------
The schema texts are the ROS 2 Humble ``.msg`` files (common_interfaces: sensor_msgs, geometry_msgs,
std_msgs; rcl_interfaces: builtin_interfaces) verbatim. In an MCAP file (schema encoding ``ros2msg``)
a type's text is followed by its dependencies the way rosbag2 concatenates them
(``rosbag2_cpp::LocalMessageDefinitionSource``): depth first, each type once, the dependencies of a
type in sorted order, each preceded by ``"\\n" + "=" * 80 + "\\nMSG: <package>/<Type>\\n"``.

Sources: OMG CORBA 3.4 Part 2, 9.3 (CDR transfer syntax); OMG DDS-XTypes 1.3, 7.4.3 (XCDR1,
encapsulation identifiers and options); the MCAP specification appendix (``ros2msg`` schema encoding,
``ros2`` profile); ROS 2 interface definitions (https://docs.ros.org/en/humble/Concepts/Basic/About-Interfaces.html).
"""

from __future__ import annotations

import re
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypedDict, Unpack, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ENCAPSULATION_CDR_LE",
    "FieldSpec",
    "MessageType",
    "not_cdr",
    "DecodedBatch",
    "IMU",
    "MAGNETIC_FIELD",
    "FLAG",
    "POSE_STAMPED",
    "RAW_MESSAGE_TYPES",
    "MESSAGE_TYPES",
    "message_type",
    "schema_text",
    "stamps_to_ns",
    "ns_to_stamps",
    "seconds_since",
    "split_payloads",
    "raw_fields",
    "raw_observables",
    "ROS_DEFINITIONS",
    "starts_with_header",
    "shift_header_stamp",
    "CLOCK_TYPE",
    "encode_clock",
]

ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"
"""Representation identifier CDR_LE (0x0001) and zero options: what ROS 2 writes."""

_HEADER_FIXED = 12
"""Payload bytes of a Header before the frame_id's characters: sec, nanosec, string length."""

# --------------------------------------------------------------------------------------------------
# Message definitions (.msg texts). ROS 2 Humble, verbatim.

ROS_DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/Time": """\
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 10e9).
uint32 nanosec
""",
    "std_msgs/Header": """\
# Standard metadata for higher-level stamped data types.
# This is generally used to communicate timestamped data
# in a particular coordinate frame.

# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
""",
    "geometry_msgs/Quaternion": """\
# This represents an orientation in free space in quaternion form.

float64 x 0
float64 y 0
float64 z 0
float64 w 1
""",
    "geometry_msgs/Point": """\
# This contains the position of a point in free space
float64 x
float64 y
float64 z
""",
    "geometry_msgs/Pose": """\
# A representation of pose in free space, composed of position and orientation.

Point position
Quaternion orientation
""",
    "geometry_msgs/PoseStamped": """\
# A Pose with reference coordinate frame and timestamp

std_msgs/Header header
Pose pose
""",
    "geometry_msgs/Vector3": """\
# This represents a vector in free space.

# This is semantically different than a point.
# A vector is always anchored at the origin.
# When a transform is applied to a vector, only the rotational component is applied.

float64 x
float64 y
float64 z
""",
    "sensor_msgs/Imu": """\
# This is a message to hold data from an IMU (Inertial Measurement Unit)
#
# Accelerations should be in m/s^2 (not in g's), and rotational velocity should be in rad/sec
#
# If the covariance of the measurement is known, it should be filled in (if all you know is the
# variance of each measurement, e.g. from the datasheet, just put those along the diagonal)
# A covariance matrix of all zeros will be interpreted as "covariance unknown", and to use the
# data a covariance will have to be assumed or gotten from some other source
#
# If you have no estimate for one of the data elements (e.g. your IMU doesn't produce an
# orientation estimate), please set element 0 of the associated covariance matrix to -1
# If you are interpreting this message, please check for a value of -1 in the first element of each
# covariance matrix, and disregard the associated estimate.

std_msgs/Header header

geometry_msgs/Quaternion orientation
float64[9] orientation_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance # Row major x, y z
""",
    "sensor_msgs/MagneticField": """\
# Measurement of the Magnetic Field vector at a specific location.
#
# If the covariance of the measurement is known, it should be filled in.
# If all you know is the variance of each measurement, e.g. from the datasheet,
# just put those along the diagonal.
# A covariance matrix of all zeros will be interpreted as "covariance unknown",
# and to use the data a covariance will have to be assumed or gotten from some
# other source.

std_msgs/Header header               # timestamp is the time the
                                     # field was measured
                                     # frame_id is the location and orientation
                                     # of the field measurement

geometry_msgs/Vector3 magnetic_field # x, y, and z components of the
                                     # field vector in Tesla
                                     # If your sensor does not output 3 axes,
                                     # put NaNs in the components not reported.

float64[9] magnetic_field_covariance # Row major about x, y, z axes
                                     # 0 is interpreted as variance unknown
""",
    # gyroemu's own messages: the physical observables of each gyro kind (sensors/<kind>.py respond()).
    "gyroemu_msgs/RlgRaw": """\
# Raw observables of a dithered ring laser gyro triad (gyroemu gyro kind "rlg").
# Each array holds the sensor's x, y and z axes in that order.

std_msgs/Header header

int64[3] fringe_count        # fringes counted since power-up: floor(beat_phase_rad / (2 pi))
float64[3] beat_phase_rad    # Sagnac beat phase since power-up, rad
float64[3] dither_angle_rad  # dither pick-off angle, rad
""",
    "gyroemu_msgs/FogRaw": """\
# Raw observables of an interferometric fibre-optic gyro triad (gyroemu gyro kind "fog").
# Each array holds the sensor's x, y and z axes in that order.

std_msgs/Header header

float64[3] sagnac_phase_rad    # Sagnac phase difference S * omega, rad
float64[3] feedback_phase_rad  # closed loop: the serrodyne ramp step of the last interval, rad; NaN open loop
float64[3] detector_power_w    # mean optical power on the detector, W
bool closed_loop               # whether feedback_phase_rad holds values
""",
    "gyroemu_msgs/MemsRaw": """\
# Raw observables of a MEMS Coriolis vibratory gyro triad (gyroemu gyro kind "mems").
# Each array holds the sensor's x, y and z axes in that order.

std_msgs/Header header

float64[3] sense_in_phase_v    # demodulated rate (in-phase) channel after the demodulator filter, V
float64[3] sense_quadrature_v  # demodulated quadrature channel after the demodulator filter, V
""",
    "gyroemu_msgs/RateGyroRaw": """\
# Raw observables of a spring-restrained single-degree-of-freedom rate gyro triad
# (gyroemu gyro kind "rate-gyro"). Each array holds the sensor's x, y and z axes in that order.

std_msgs/Header header

float64[3] gimbal_angle_rad  # gimbal deflection against the spring, rad
""",
    "gyroemu_msgs/RateIntegratingGyroRaw": """\
# Raw observables of a floated rate-integrating gyro triad with torque rebalance
# (gyroemu gyro kind "rate-integrating"). Each array holds the sensor's x, y and z axes in that order.

std_msgs/Header header

float64[3] gimbal_angle_rad   # float (gimbal) angle at the pick-off, rad
float64[3] torquer_current_a  # rebalance torquer current, A (zero without rebalance loop)
""",
    "gyroemu_msgs/FreeGyroRaw": """\
# Raw observables of a pair of two-gimbal free gyros (gyroemu gyro kind "free-gyro").

std_msgs/Header header

float64[4] gimbal_angle_rad  # inner and outer gimbal angles of gyro 1, then of gyro 2, rad
float64[3] attitude_xyz_rad  # indicated attitude (x-y-z Euler angles) since uncaging, rad
bool gimbal_lock             # an inner gimbal is within the lock margin of 90 degrees
""",
    "gyroemu_msgs/Flag": """\
# A stamped yes/no per sample, e.g. an imported dataset's mask of the samples over which errors are
# computed (gyroemu's /movement topic: BROAD's `movement` array).

std_msgs/Header header

bool data  # the flag at this stamp
""",
}

_DELIMITER = "\n" + "=" * 80 + "\n"
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
        "time",
        "duration",
    }
)
_FIELD_TYPE = re.compile(r"^\s*(?:([A-Za-z0-9_]+)/)?([A-Za-z0-9_]+)", re.MULTILINE)


def _short(name: str) -> str:
    """``pkg/msg/Type`` -> ``pkg/Type`` (the key of :data:`ROS_DEFINITIONS` and the MSG: line form)."""
    parts = name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 and parts[1] == "msg" else name


def _dependencies(name: str, text: str) -> list[str]:
    """Message types a definition's fields use, sorted (``std::set`` order, as rosbag2 lists them)."""
    package = name.split("/")[0]
    deps: set[str] = set()
    for m in _FIELD_TYPE.finditer(text):
        pkg, typ = m.group(1), m.group(2)
        if pkg is None and typ in _PRIMITIVES:
            continue
        deps.add(f"{pkg or package}/{typ}")
    return sorted(deps)


def schema_text(name: str, definitions: Mapping[str, str] = ROS_DEFINITIONS) -> str:
    """The ``ros2msg`` schema of message type ``name`` (``sensor_msgs/msg/Imu``): its ``.msg`` text,
    then each dependency once, depth first, as rosbag2 writes them into MCAP files."""
    root = _short(name)
    out = [definitions[root]]
    seen = {root}

    def visit(type_name: str) -> None:
        for dep in _dependencies(type_name, definitions[type_name]):
            if dep not in seen:
                seen.add(dep)
                out.append(f"{_DELIMITER}MSG: {dep}\n{definitions[dep]}")
                visit(dep)

    visit(root)
    return "".join(out)


# --------------------------------------------------------------------------------------------------
# Time stamps.


def stamps_to_ns(t: ArrayLike) -> NDArray[np.int64]:
    """Times in seconds (float) to integer nanoseconds, rounded to nearest: (N,) int64."""
    t = np.asarray(t, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError("time stamps must be finite")
    return np.rint(t * 1e9).astype(np.int64)


def ns_to_stamps(ns: ArrayLike) -> NDArray[np.float64]:
    """Integer nanoseconds to seconds, float64 (correctly rounded: ``ns / 10^9``)."""
    return np.asarray(ns, dtype=np.int64) / 1e9


def seconds_since(ns: ArrayLike, first_ns: int) -> NDArray[np.float64]:
    """Integer nanosecond stamps ``ns`` as seconds from the stamp ``first_ns``, float64: the clock the
    filters run on. The difference is taken in integers, so a step of 1,000,000 ns is 0.001 s within a unit
    in the last place at the span (the product by 1e-9 is not the correctly rounded quotient), where float
    seconds since the epoch resolve 0.24 µs today (a 1 kHz log's steps read 0.99993, 1.00017 or 1.0004 ms)."""
    # numpy's stubs type an integer array times a float as floating[Any]; it is float64
    return cast("NDArray[np.float64]", (np.asarray(ns, dtype=np.int64) - np.int64(first_ns)) * 1e-9)


def _split_ns(ns: ArrayLike) -> tuple[NDArray[np.int32], NDArray[np.uint32]]:
    """``builtin_interfaces/Time`` fields of nanosecond stamps: ``sec = floor(ns / 1e9)``, ``nanosec >= 0``."""
    sec, nanosec = np.divmod(np.asarray(ns, dtype=np.int64), 1_000_000_000)
    if sec.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("time stamps beyond the int32 seconds of builtin_interfaces/Time")
    return sec.astype(np.int32), nanosec.astype(np.uint32)


# --------------------------------------------------------------------------------------------------
# Message layouts.


@dataclass(frozen=True)
class FieldSpec:
    """One fixed-size body field after the ``std_msgs/Header``.

    Attributes
    ----------
    name : str
        Flattened field name: a nested message of equal primitives is one array
        (``orientation`` = Quaternion x, y, z, w as 4 float64).
    dtype : str
        Little-endian numpy type of the elements (``<f8``, ``<i8``, ``?``).
    count : int
        Elements (1 for a scalar; the array shape of a batch is then (N,), else (N, count)).
    default : float
        Value of elements not given to :meth:`MessageType.encode`.
    present_flag : str or None
        Name of a bool field that says whether this field holds values (encoders fill it in).
    """

    name: str
    dtype: str
    count: int = 1
    default: float = 0.0
    present_flag: str | None = None

    @property
    def itemsize(self) -> int:
        return np.dtype(self.dtype).itemsize

    def shape(self, n: int) -> tuple[int, ...]:
        """The array shape of ``n`` messages' values: (n,) for a scalar, else (n, count)."""
        return (n,) if self.count == 1 else (n, self.count)


@dataclass(frozen=True)
class DecodedBatch:
    """Decoded messages of one type, all fields as arrays.

    Attributes
    ----------
    stamp_ns : ndarray (N,) int64
        ``header.stamp`` as nanoseconds.
    frame_id : ndarray (N,) str
    fields : dict of str to ndarray
        Body fields by :class:`FieldSpec` name, shape (N,) or (N, count).
    """

    stamp_ns: NDArray[np.int64]
    frame_id: NDArray[np.str_]
    fields: dict[str, NDArray[Any]]

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def __getitem__(self, name: str) -> NDArray[Any]:
        return self.fields[name]


_COMPRESSED = {b"\x28\xb5\x2f\xfd": "zstd", b"\x04\x22\x4d\x18": "lz4"}  # the frames' magic numbers


def not_cdr(head: bytes) -> str:
    """What a payload whose first four bytes ``head`` are no little-endian plain CDR encapsulation is, in
    words: a zstd or lz4 frame (rosbag2's per-message compression), or another encapsulation."""
    packed = _COMPRESSED.get(head[:4])
    if packed is not None:
        return (
            f"is {packed}-compressed on its own (rosbag2's 'message' compression mode): write the bag "
            "uncompressed or with file or chunk compression, e.g. 'ros2 bag convert', and read that"
        )
    return f"is not little-endian plain CDR (encapsulation {head[:4].hex(' ')}; expected 00 01 00 00)"


@dataclass(frozen=True)
class MessageType:
    """A ROS 2 message type of a ``std_msgs/Header`` followed by fixed-size fields.

    Attributes
    ----------
    name : str
        ROS type name, ``package/msg/Type``.
    body : tuple of FieldSpec
        Fields after the header, in order.
    kind : str or None
        The gyro kind whose raw observables the type carries (raw types only).
    """

    name: str
    body: tuple[FieldSpec, ...]
    kind: str | None = None
    _layouts: dict[tuple[int, int | None], np.dtype[np.void]] = field(default_factory=dict, repr=False, compare=False)

    @property
    def schema(self) -> str:
        """The ``ros2msg`` schema text (definition and dependencies), as stored in MCAP."""
        return schema_text(self.name)

    def layout(self, frame_id_length: int, size: int | None = None) -> np.dtype[np.void]:
        """The structured dtype of one serialised message (encapsulation header included) whose
        frame_id has ``frame_id_length`` bytes before its NUL; ``size`` (at least the minimum) lets
        trailing padding count in the itemsize."""
        key = (frame_id_length, size)
        cached = self._layouts.get(key)
        if cached is not None:
            return cached
        length = frame_id_length + 1
        names = ["encapsulation", "sec", "nanosec", "frame_id_length"]
        formats = [("u1", (4,)), "<i4", "<u4", "<u4"]
        offsets = [0, 4, 8, 12]
        names.append("frame_id")
        formats.append(f"S{length}")
        offsets.append(4 + _HEADER_FIXED)
        position = _HEADER_FIXED + length  # payload offset
        for spec in self.body:
            align = spec.itemsize
            position = -(-position // align) * align
            names.append(spec.name)
            formats.append(spec.dtype if spec.count == 1 else (spec.dtype, (spec.count,)))
            offsets.append(4 + position)
            position += spec.itemsize * spec.count
        minimum = 4 + position
        if size is not None and size < minimum:
            raise ValueError(f"{size} bytes is shorter than a {self.name} message ({minimum} bytes)")
        dtype = np.dtype(
            {"names": names, "formats": formats, "offsets": offsets, "itemsize": minimum if size is None else size}
        )
        self._layouts[key] = dtype
        return dtype

    def message_size(self, frame_id: str) -> int:
        """Bytes of one serialised message with this ``frame_id``."""
        return self.layout(len(frame_id.encode())).itemsize

    # ---------------------------------------------------------------------------------------------

    def encode(
        self,
        stamp_ns: ArrayLike,
        frame_id: str,
        fields: Mapping[str, ArrayLike] | None = None,
    ) -> NDArray[np.uint8]:
        """Serialise N messages at once.

        Parameters
        ----------
        stamp_ns : array_like (N,) int
            ``header.stamp`` in nanoseconds.
        frame_id : str
            ``header.frame_id`` of every message.
        fields : mapping of str to array_like
            Body fields by name, each broadcastable to (N,) or (N, count); fields not given take their
            :attr:`FieldSpec.default`. A field with a ``present_flag`` that is not given is filled with
            its default and its flag set False (True when given).

        Returns
        -------
        ndarray (N, size) uint8
            Row k is the complete CDR serialisation of message k (encapsulation header first).
        """
        fields = dict(fields or {})
        known = {spec.name for spec in self.body}
        unknown = set(fields) - known
        if unknown:
            raise ValueError(
                f"{self.name} has no field(s) {', '.join(sorted(unknown))}; "
                f"fields: {', '.join(s.name for s in self.body)}"
            )
        frame = frame_id.encode()
        if b"\x00" in frame:
            raise ValueError("frame_id must not contain NUL characters")
        stamp_ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
        n = len(stamp_ns)
        dtype = self.layout(len(frame))
        out = np.zeros(n, dtype=dtype)  # zeroed padding
        out["encapsulation"] = np.frombuffer(ENCAPSULATION_CDR_LE, np.uint8)
        out["sec"], out["nanosec"] = _split_ns(stamp_ns)
        out["frame_id_length"] = len(frame) + 1
        out["frame_id"] = frame
        for spec in self.body:
            if spec.present_flag is not None:
                out[spec.present_flag] = spec.name in fields
            if spec.name in fields:
                values = np.asarray(fields[spec.name])
                target = spec.shape(n)
                try:
                    out[spec.name] = np.broadcast_to(values, target)
                except ValueError:
                    raise ValueError(f"{self.name}.{spec.name}: shape {values.shape} does not fit {target}") from None
            elif spec.default != 0:
                out[spec.name] = spec.default
        return out.view(np.uint8).reshape(n, dtype.itemsize)

    def decode(self, payloads: NDArray[np.uint8] | Iterable[bytes]) -> DecodedBatch:
        """Deserialise a batch of messages of this type.

        Parameters
        ----------
        payloads : ndarray (N, size) uint8, or sequence of bytes-like
            Serialised messages. Rows of a 2-D array all have the same length; a sequence may mix
            lengths (frame ids of several lengths), it is decoded in groups of equal layout.

        Returns
        -------
        DecodedBatch
            In the order given.

        Raises
        ------
        ValueError
            A message that is not little-endian CDR, is too short for its type, or whose frame id
            runs past its end.
        """
        if isinstance(payloads, np.ndarray) and payloads.ndim == 2:
            return self._decode_block(np.ascontiguousarray(payloads, dtype=np.uint8), 0)
        payloads = list(payloads)
        lengths = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
        parts = []
        for length in np.unique(lengths):
            index = np.flatnonzero(lengths == length)
            block = np.frombuffer(b"".join(payloads[i] for i in index), dtype=np.uint8)
            parts.append((index, self._decode_block(block.reshape(len(index), int(length)), int(index[0]))))
        return self._merge(parts, len(payloads))

    def _merge(self, parts: list[tuple[NDArray[np.intp], DecodedBatch]], n: int) -> DecodedBatch:
        """One batch of ``n`` messages from decoded parts ``(index, batch)``."""
        if len(parts) == 1 and np.array_equal(parts[0][0], np.arange(n)):
            return parts[0][1]
        stamp_ns = np.empty(n, dtype=np.int64)
        frame_id = np.empty(n, dtype=object)
        fields = {spec.name: np.empty(spec.shape(n), dtype=spec.dtype) for spec in self.body}
        for index, batch in parts:
            stamp_ns[index] = batch.stamp_ns
            frame_id[index] = batch.frame_id
            for name, values in batch.fields.items():
                fields[name][index] = values
        return DecodedBatch(stamp_ns=stamp_ns, frame_id=frame_id.astype(str) if n else np.empty(0, str), fields=fields)

    def _decode_block(self, rows: NDArray[np.uint8], first: int) -> DecodedBatch:
        """Decode equal-length messages, rows of (M, size) uint8; ``first`` numbers them in errors."""
        m, size = rows.shape
        if m == 0:
            return DecodedBatch(
                np.empty(0, np.int64),
                np.empty(0, str),
                {spec.name: np.empty(spec.shape(0), spec.dtype) for spec in self.body},
            )
        if size < 4 + _HEADER_FIXED + 1:
            raise ValueError(f"a {size}-byte message is too short for a {self.name}")
        bad = (rows[:, 0] != 0) | (rows[:, 1] != 1)
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(f"message {first + k} {not_cdr(bytes(rows[k, :4]))}")
        string_length = rows[:, 4 + 8 : 4 + 12].copy().view("<u4")[:, 0]
        if np.all(string_length == string_length[0]):
            return self._decode_layout(rows, int(string_length[0]), first)
        parts = []
        for length in np.unique(string_length):
            index = np.flatnonzero(string_length == length)
            parts.append((index, self._decode_layout(rows[index], int(length), first + int(index[0]))))
        return self._merge(parts, m)

    def _decode_layout(self, rows: NDArray[np.uint8], string_length: int, first: int) -> DecodedBatch:
        """Decode rows that share one layout (their frame ids have ``string_length - 1`` bytes)."""
        m, size = rows.shape
        frame_len = string_length - 1
        if frame_len < 0:
            raise ValueError(f"message {first}: a CDR string length of 0 (no NUL terminator)")
        if 4 + _HEADER_FIXED + string_length > size:  # checked first: a corrupt length can be huge
            raise ValueError(
                f"message {first}: {size} bytes, but its frame_id's {string_length}-byte CDR string runs past the end"
            )
        minimum = self.layout(frame_len).itemsize
        if not minimum <= size <= minimum + 3:
            raise ValueError(
                f"message {first}: {size} bytes, but a {self.name} with a {frame_len}-byte frame_id has {minimum}"
            )
        view = rows.view(self.layout(frame_len, size))[:, 0]
        stamp_ns = view["sec"].astype(np.int64) * 1_000_000_000 + view["nanosec"]
        frames = rows[:, 4 + _HEADER_FIXED : 4 + _HEADER_FIXED + frame_len]
        if frame_len == 0:
            frame_id = np.full(m, "")
        elif np.all(frames == frames[0]):
            frame_id = np.full(m, bytes(frames[0]).rstrip(b"\x00").decode("utf-8"))
        else:
            frame_id = np.char.decode(view["frame_id"], "utf-8")
        fields = {spec.name: np.array(view[spec.name]) for spec in self.body}
        return DecodedBatch(stamp_ns=stamp_ns, frame_id=frame_id, fields=fields)


def split_payloads(rows: NDArray[np.uint8]) -> list[bytes]:
    """One ``bytes`` object per row of an encoded batch (for per-message transports such as zenoh)."""
    rows = np.ascontiguousarray(rows)
    data = rows.tobytes()
    size = rows.shape[1]
    return [data[i : i + size] for i in range(0, len(data), size)]


# --------------------------------------------------------------------------------------------------
# The types gyroemu uses.


class _FieldOptions(TypedDict, total=False):
    """The keyword fields of :class:`FieldSpec` that :func:`_f8` passes on."""

    default: float
    present_flag: str | None


def _f8(name: str, count: int = 1, **kw: Unpack[_FieldOptions]) -> FieldSpec:
    return FieldSpec(name, "<f8", count, **kw)


IMU = MessageType(
    "sensor_msgs/msg/Imu",
    (
        _f8("orientation", 4),  # x, y, z, w
        _f8("orientation_covariance", 9),
        _f8("angular_velocity", 3),
        _f8("angular_velocity_covariance", 9),
        _f8("linear_acceleration", 3),
        _f8("linear_acceleration_covariance", 9),
    ),
)
"""``sensor_msgs/msg/Imu``: ``orientation`` is (x, y, z, w), covariances are row-major (9,)."""

MAGNETIC_FIELD = MessageType(
    "sensor_msgs/msg/MagneticField",
    (
        _f8("magnetic_field", 3),
        _f8("magnetic_field_covariance", 9),
    ),
)
"""``sensor_msgs/msg/MagneticField``: ``magnetic_field`` in tesla."""

RAW_MESSAGE_TYPES: dict[str, MessageType] = {
    "rlg": MessageType(
        "gyroemu_msgs/msg/RlgRaw",
        (FieldSpec("fringe_count", "<i8", 3), _f8("beat_phase_rad", 3), _f8("dither_angle_rad", 3)),
        kind="rlg",
    ),
    "fog": MessageType(
        "gyroemu_msgs/msg/FogRaw",
        (
            _f8("sagnac_phase_rad", 3),
            _f8("feedback_phase_rad", 3, default=np.nan, present_flag="closed_loop"),
            _f8("detector_power_w", 3),
            FieldSpec("closed_loop", "?"),
        ),
        kind="fog",
    ),
    "mems": MessageType(
        "gyroemu_msgs/msg/MemsRaw", (_f8("sense_in_phase_v", 3), _f8("sense_quadrature_v", 3)), kind="mems"
    ),
    "rate-gyro": MessageType("gyroemu_msgs/msg/RateGyroRaw", (_f8("gimbal_angle_rad", 3),), kind="rate-gyro"),
    "rate-integrating": MessageType(
        "gyroemu_msgs/msg/RateIntegratingGyroRaw",
        (_f8("gimbal_angle_rad", 3), _f8("torquer_current_a", 3)),
        kind="rate-integrating",
    ),
    "free-gyro": MessageType(
        "gyroemu_msgs/msg/FreeGyroRaw",
        (_f8("gimbal_angle_rad", 4), _f8("attitude_xyz_rad", 3), FieldSpec("gimbal_lock", "?")),
        kind="free-gyro",
    ),
}
"""Gyro kind -> its raw-observable message type. Field names are the names of ``ImuSamples.raw[kind]``
(the ``ideal`` kind has no raw observables); FOG's ``closed_loop`` says whether ``feedback_phase_rad``
(NaN otherwise) was present."""

FLAG = MessageType("gyroemu_msgs/msg/Flag", (FieldSpec("data", "?"),))
"""``gyroemu_msgs/msg/Flag``: one ``bool data`` per stamp (the ``/movement`` mask of imported datasets)."""

POSE_STAMPED = MessageType("geometry_msgs/msg/PoseStamped", (_f8("position", 3), _f8("orientation", 4)))
"""``geometry_msgs/msg/PoseStamped``: ``position`` (m) and ``orientation`` (x, y, z, w)."""

MESSAGE_TYPES: dict[str, MessageType] = {
    t.name: t for t in (IMU, MAGNETIC_FIELD, FLAG, POSE_STAMPED, *RAW_MESSAGE_TYPES.values())
}
"""Every type this module encodes and decodes, by ROS name (``package/msg/Type``)."""


def message_type(name: str) -> MessageType | None:
    """The type called ``name`` (``pkg/msg/Type`` or ``pkg/Type``), or None when unknown."""
    parts = name.split("/")
    if len(parts) == 2:
        name = f"{parts[0]}/msg/{parts[1]}"
    return MESSAGE_TYPES.get(name)


def raw_fields(kind: str, raw: Mapping[str, NDArray[Any]]) -> tuple[MessageType, dict[str, NDArray[Any]], list[str]]:
    """The raw message type of gyro ``kind`` and the fields to encode from ``ImuSamples.raw[kind]``.

    Returns ``(type, fields, ignored)``: ``ignored`` lists observables the message has no field for.
    Raises ``KeyError`` for a kind without a message type and ``ValueError`` when a required field is
    missing.
    """
    mtype = RAW_MESSAGE_TYPES[kind]
    names = {spec.name for spec in mtype.body}
    flags = {spec.present_flag for spec in mtype.body if spec.present_flag}
    missing = [
        spec.name
        for spec in mtype.body
        if spec.name not in raw and spec.present_flag is None and spec.name not in flags
    ]
    if missing:
        raise ValueError(f"raw observables of kind {kind!r} lack {', '.join(missing)} (message {mtype.name})")
    fields = {name: value for name, value in raw.items() if name in names and name not in flags}
    ignored = sorted(set(raw) - names)
    return mtype, fields, ignored


def raw_observables(mtype: MessageType, batch: DecodedBatch) -> dict[str, NDArray[Any]]:
    """``ImuSamples.raw[kind]`` from decoded raw messages: presence flags removed, a flagged field kept
    only when its flag is set in every message."""
    flags = {spec.present_flag for spec in mtype.body if spec.present_flag}
    out = {}
    for spec in mtype.body:
        if spec.name in flags:
            continue
        if spec.present_flag is not None and not (len(batch) and np.all(batch[spec.present_flag])):
            continue
        out[spec.name] = batch[spec.name]
    return out


# --------------------------------------------------------------------------------------------------
# Header stamps of serialised messages of any type.

_FIRST_FIELD = re.compile(r"^\s*([A-Za-z0-9_/]+)(?:\[[^\]]*\])?\s+[A-Za-z_]", re.MULTILINE)


def starts_with_header(name: str, schema: str = "") -> bool:
    """True when messages of type ``name`` start with a ``std_msgs/Header`` (so their CDR bytes carry
    the header stamp right after the encapsulation header): every type of :data:`MESSAGE_TYPES`, and a
    type whose ``ros2msg`` ``schema`` text has ``std_msgs/Header`` (or ``Header``) as its first field."""
    if message_type(name) is not None:
        return True
    text = schema.split(_DELIMITER, 1)[0]
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        match = _FIRST_FIELD.match(line)
        return match is not None and match.group(1) in ("std_msgs/Header", "std_msgs/msg/Header", "Header")
    return False


def shift_header_stamp(payload: bytes, shift_ns: int) -> bytes:
    """``payload`` (a CDR message that starts with a ``std_msgs/Header``) with ``header.stamp`` moved by
    ``shift_ns`` nanoseconds; the other bytes unchanged.

    The stamp is ``int32 sec, uint32 nanosec`` right after the 4-byte encapsulation header, in the
    byte order it names (``00 01``: little endian, ``00 00``: big endian). A payload too short, of
    another encapsulation, or whose shifted stamp leaves the int32 seconds, is returned unchanged.
    """
    if not shift_ns or len(payload) < 12 or payload[0] != 0 or payload[1] not in (0, 1):
        return payload
    order = "<" if payload[1] == 1 else ">"
    sec, nanosec = struct.unpack_from(order + "iI", payload, 4)
    sec, nanosec = divmod(sec * 1_000_000_000 + nanosec + int(shift_ns), 1_000_000_000)
    if not -(2**31) <= sec < 2**31:
        return payload
    out = bytearray(payload)
    struct.pack_into(order + "iI", out, 4, sec, nanosec)
    return bytes(out)


# --------------------------------------------------------------------------------------------------
# rosgraph_msgs/msg/Clock (``gyroemu replay --clock``).

ROS_DEFINITIONS["rosgraph_msgs/Clock"] = """\
# This message communicates the current time.
#
# For more information, see https://design.ros2.org/articles/clock_and_time.html.
builtin_interfaces/Time clock
"""

CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
"""The type of ROS 2's ``/clock`` topic: one ``builtin_interfaces/Time clock`` (no header)."""


def encode_clock(stamp_ns: int) -> bytes:
    """A ``rosgraph_msgs/msg/Clock`` message at ``stamp_ns``: the encapsulation header, ``int32 sec``,
    ``uint32 nanosec`` (12 bytes)."""
    sec, nanosec = _split_ns(np.array([stamp_ns]))
    return ENCAPSULATION_CDR_LE + struct.pack("<iI", int(sec[0]), int(nanosec[0]))
