"""``tf2_msgs/msg/TFMessage`` as CDR bytes, encoded whole arrays at a time, and decoded back.

A TFMessage is a sequence of ``geometry_msgs/msg/TransformStamped``, so unlike the types of
:mod:`gyroemu.pipelines.formats.messages` it does not start with a ``std_msgs/Header``: its payload (after
the 4-byte encapsulation header ``00 01 00 00``) is a ``uint32`` count ``K``, then ``K`` transforms, each::

    int32   header.stamp.sec        (4-aligned)
    uint32  header.stamp.nanosec
    uint32  len(frame_id) + 1, then the frame id's bytes and a NUL
    uint32  len(child_frame_id) + 1, then its bytes and a NUL    (4-aligned)
    float64 translation x, y, z; rotation x, y, z, w               (8-aligned)

with alignment relative to the payload's first byte and zero padding (XCDR1, little endian; OMG CORBA
3.4 Part 2, 9.3). With the frame names fixed per batch every message has the same length and field
offsets, so a batch is a numpy structured array viewed as ``(N, size)`` bytes, as for the other types.

A transform from ``frame_id`` (parent) to ``child_frame_id`` holds the child's pose in the parent:
``rotation`` turns child-frame vectors into parent axes and ``translation`` is the child's origin in
the parent (REP 103; tf2's ``lookupTransform(parent, child)``). Definitions: ROS 2 Humble's
``tf2_msgs/TFMessage``, ``geometry_msgs/TransformStamped``, ``Transform``.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.pipelines.formats.messages import ENCAPSULATION_CDR_LE, ROS_DEFINITIONS, ns_to_stamps, schema_text

__all__ = [
    "TF_MESSAGE_TYPE",
    "TF_DEFINITIONS",
    "tf_schema",
    "encode_tf",
    "decode_tf",
    "Transforms",
    "shift_tf_stamps",
    "tf_stamp_ns",
]

TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
"""The ROS type of ``/tf`` and ``/tf_static``."""

TF_DEFINITIONS: dict[str, str] = {
    **ROS_DEFINITIONS,
    "tf2_msgs/TFMessage": """\
geometry_msgs/TransformStamped[] transforms
""",
    "geometry_msgs/TransformStamped": """\
# This expresses a transform from coordinate frame header.frame_id
# to the coordinate frame child_frame_id at the time of header.stamp
#
# This message is mostly used by the
# <a href="https://docs.ros.org/en/rolling/p/tf2/">tf2</a> package.
# See its documentation for more information.
#
# The child_frame_id is necessary in addition to the frame_id
# in the Header to communicate the full reference for the transform
# in a self contained message.

# The frame id in the header is used as the reference frame of this transform.
std_msgs/Header header

# The frame id of the child frame to which this transform points.
string child_frame_id

# Translation and rotation in 3-dimensions of child_frame_id from header.frame_id.
Transform transform
""",
    "geometry_msgs/Transform": """\
# This represents the transform between two coordinate frames in free space.

Vector3 translation
Quaternion rotation
""",
}
"""ROS 2 Humble ``.msg`` texts of the tf types and their dependencies (with those of
:data:`~gyroemu.pipelines.formats.messages.ROS_DEFINITIONS`)."""


def tf_schema() -> str:
    """The ``ros2msg`` schema of ``tf2_msgs/msg/TFMessage`` as rosbag2 stores it in MCAP."""
    return schema_text(TF_MESSAGE_TYPE, TF_DEFINITIONS)


def _layout(pairs: Sequence[tuple[str, str]]) -> np.dtype[np.void]:
    """The structured dtype of a TFMessage of ``len(pairs)`` transforms ``(frame_id, child_frame_id)``."""
    names: list[str] = ["encapsulation", "count"]
    formats: list[str | tuple[str, tuple[int]]] = [("u1", (4,)), "<u4"]
    offsets = [0, 4]
    position = 4  # payload offset
    for k, (frame, child) in enumerate(pairs):
        f, c = frame.encode(), child.encode()
        position = -(-position // 4) * 4
        for name, fmt, size in (
            (f"sec{k}", "<i4", 4),
            (f"nanosec{k}", "<u4", 4),
            (f"frame_len{k}", "<u4", 4),
            (f"frame{k}", f"S{len(f) + 1}", len(f) + 1),
        ):
            names.append(name)
            formats.append(fmt)
            offsets.append(4 + position)
            position += size
        position = -(-position // 4) * 4
        for name, fmt, size in ((f"child_len{k}", "<u4", 4), (f"child{k}", f"S{len(c) + 1}", len(c) + 1)):
            names.append(name)
            formats.append(fmt)
            offsets.append(4 + position)
            position += size
        position = -(-position // 8) * 8
        names += [f"translation{k}", f"rotation{k}"]
        formats += [("<f8", (3,)), ("<f8", (4,))]
        offsets += [4 + position, 4 + position + 24]
        position += 56
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": 4 + position})


def encode_tf(
    stamp_ns: ArrayLike,
    pairs: Sequence[tuple[str, str]],
    translation: ArrayLike,
    rotation_xyzw: ArrayLike,
) -> NDArray[np.uint8]:
    """Serialise N TFMessages of K transforms each, all at once.

    Parameters
    ----------
    stamp_ns : array_like (N,) int
        ``header.stamp`` of every transform of message n, ns.
    pairs : sequence of K (frame_id, child_frame_id)
        The transforms' frames, the same in every message.
    translation : array_like (N, K, 3)
        The child's origin in the parent frame, m (broadcast from (K, 3) or (3,)).
    rotation_xyzw : array_like (N, K, 4)
        Unit quaternions (x, y, z, w) turning child vectors into the parent frame.

    Returns
    -------
    ndarray (N, size) uint8
        Row n is message n's complete CDR serialisation (encapsulation header first).
    """
    for frame, child in pairs:
        if "\x00" in frame or "\x00" in child:
            raise ValueError("frame ids must not contain NUL characters")
    stamp_ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
    n, k = len(stamp_ns), len(pairs)
    translation = np.broadcast_to(np.asarray(translation, dtype=float), (n, k, 3))
    rotation_xyzw = np.broadcast_to(np.asarray(rotation_xyzw, dtype=float), (n, k, 4))
    sec, nanosec = np.divmod(stamp_ns, 1_000_000_000)
    if n and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("time stamps beyond the int32 seconds of builtin_interfaces/Time")
    dtype = _layout(pairs)
    out = np.zeros(n, dtype=dtype)  # zeroed padding
    out["encapsulation"] = np.frombuffer(ENCAPSULATION_CDR_LE, np.uint8)
    out["count"] = k
    for j, (frame, child) in enumerate(pairs):
        out[f"sec{j}"], out[f"nanosec{j}"] = sec, nanosec
        out[f"frame_len{j}"], out[f"frame{j}"] = len(frame.encode()) + 1, frame.encode()
        out[f"child_len{j}"], out[f"child{j}"] = len(child.encode()) + 1, child.encode()
        out[f"translation{j}"] = translation[:, j]
        out[f"rotation{j}"] = rotation_xyzw[:, j]
    return out.view(np.uint8).reshape(n, dtype.itemsize)


@dataclass(frozen=True, eq=False)
class Transforms:
    """Transforms decoded from TFMessages, one row per TransformStamped, in message order.

    Attributes
    ----------
    stamp_ns : ndarray (M,) int64
        ``header.stamp``, ns.
    frame_id, child_frame_id : ndarray (M,) str
    translation : ndarray (M, 3)
        The child's origin in the parent frame, m.
    q : ndarray (M, 4)
        Rotation child -> parent as (w, x, y, z) (scalar first, gyroemu's order).
    """

    stamp_ns: NDArray[np.int64]
    frame_id: NDArray[np.str_]
    child_frame_id: NDArray[np.str_]
    translation: NDArray[np.float64]
    q: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @property
    def t(self) -> NDArray[np.float64]:
        """Stamps, s (float64)."""
        return ns_to_stamps(self.stamp_ns)

    def select(self, frame_id: str, child_frame_id: str) -> Transforms:
        """The transforms from ``frame_id`` to ``child_frame_id``, in stamp order."""
        keep = np.flatnonzero((self.frame_id == frame_id) & (self.child_frame_id == child_frame_id))
        keep = keep[np.argsort(self.stamp_ns[keep], kind="stable")]
        return Transforms(
            self.stamp_ns[keep], self.frame_id[keep], self.child_frame_id[keep], self.translation[keep], self.q[keep]
        )


def _string(data: bytes, position: int) -> tuple[str, int]:
    """A CDR string at payload ``position`` (4-aligned): its text and the position after it."""
    position = -(-position // 4) * 4
    (length,) = struct.unpack_from("<I", data, 4 + position)
    if length < 1 or 4 + position + 4 + length > len(data):
        raise ValueError("a CDR string runs past the end of the message")
    text = data[4 + position + 4 : 4 + position + 4 + length - 1].decode("utf-8")
    return text, position + 4 + length


def decode_tf(payloads: Sequence[bytes]) -> Transforms:
    """Every TransformStamped of little-endian CDR TFMessages (``ValueError`` for a malformed one)."""
    stamps: list[int]
    frames: list[str]
    children: list[str]
    vectors: list[tuple[float, ...]]
    stamps, frames, children, vectors = [], [], [], []
    for index, data in enumerate(payloads):
        data = bytes(data)
        if len(data) < 8 or data[0] != 0 or data[1] != 1:
            raise ValueError(f"TFMessage {index} is not little-endian plain CDR")
        (count,) = struct.unpack_from("<I", data, 4)
        position = 4
        try:
            for _ in range(count):
                position = -(-position // 4) * 4
                sec, nanosec = struct.unpack_from("<iI", data, 4 + position)
                frame, position = _string(data, position + 8)
                child, position = _string(data, position)
                position = -(-position // 8) * 8
                vectors.append(struct.unpack_from("<7d", data, 4 + position))
                position += 56
                stamps.append(sec * 1_000_000_000 + nanosec)
                frames.append(frame)
                children.append(child)
        except struct.error:
            raise ValueError(f"TFMessage {index} is shorter than its {count} transforms") from None
    values = np.array(vectors, dtype=float).reshape(-1, 7)
    return Transforms(
        stamp_ns=np.array(stamps, dtype=np.int64),
        frame_id=np.array(frames, dtype=str),
        child_frame_id=np.array(children, dtype=str),
        translation=values[:, :3].copy(),
        q=values[:, [6, 3, 4, 5]].copy(),
    )


def shift_tf_stamps(payload: bytes, shift_ns: int) -> bytes:
    """``payload`` (a little-endian CDR TFMessage) with every transform's ``header.stamp`` moved by
    ``shift_ns`` ns, the other bytes unchanged; returned unchanged when it is not such a message or a
    shifted stamp would leave the int32 seconds (as
    :func:`~gyroemu.pipelines.formats.messages.shift_header_stamp` does for header-first types)."""
    if not shift_ns or len(payload) < 8 or payload[0] != 0 or payload[1] != 1:
        return payload
    out = bytearray(payload)
    try:
        (count,) = struct.unpack_from("<I", payload, 4)
        position = 4
        for _ in range(count):
            position = -(-position // 4) * 4
            sec, nanosec = struct.unpack_from("<iI", payload, 4 + position)
            sec, nanosec = divmod(sec * 1_000_000_000 + nanosec + int(shift_ns), 1_000_000_000)
            if not -(2**31) <= sec < 2**31:
                return payload
            struct.pack_into("<iI", out, 4 + position, sec, nanosec)
            _, position = _string(payload, position + 8)
            _, position = _string(payload, position)
            position = -(-position // 8) * 8 + 56
            if 4 + position > len(payload):
                return payload
    except (struct.error, ValueError):
        return payload
    return bytes(out)


def tf_stamp_ns(payload: bytes) -> int:
    """The ``header.stamp`` (ns) of a little-endian CDR TFMessage's first transform: the message's time
    (a log's ``log_time``); -1 for a message without transforms or not such a message."""
    if len(payload) < 16 or payload[0] != 0 or payload[1] != 1:
        return -1
    (count,) = struct.unpack_from("<I", payload, 4)
    if count < 1:
        return -1
    sec: int
    nanosec: int
    sec, nanosec = struct.unpack_from("<iI", payload, 8)
    return sec * 1_000_000_000 + nanosec
