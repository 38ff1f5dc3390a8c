"""The tf tree of gyroemu's logs and streams: frames, the mounting, the start time, and which stamps carry /tf.

The tree (REP 103 axes, REP 105 names)::

    map ──/tf──> base_link ──/tf_static──> <imu frame>        (the device's name, or --frame-id)
     └───/tf──> body_estimate                                 (where a log has /estimate/imu)

- ``map`` → ``base_link``: the true pose of the body (``/truth/pose``'s position, zero without one;
  ``/truth/imu``'s attitude ``q_wb``), the world ENU.
- ``map`` → ``body_estimate``: a filter's attitude (``/estimate/imu``), placed at the true position
  where the log has one (the filters estimate no position), so a viewer draws both bodies together.
- ``base_link`` → IMU: the device's mounting (``[mounting] q_bs``, ``lever_arm_m``), on ``/tf_static``
  once, at the device's first stamp.

**Rate of /tf in logs** (:data:`TF_LOG_RATE_HZ`): tf2 interpolates between a frame's stamps (slerp for
the rotation, linear for the translation) and refuses lookups outside them. Writing the first sample
of every ``1/TF_LOG_RATE_HZ`` bin of IMU stamps, and the last sample of the run, keeps every IMU stamp
inside the tree's span, and the interpolation error between stamps ``h`` apart is at most
``h²/8 · max|r''|`` with ``r'' = ω̇ + O(h |ω| (|ω̇| + |ω|²))`` (the linear interpolant's error of the
rotation vector of ``q(t₀)⁻¹ q(t)``): at 100 Hz and 1 rad/s², 1.3·10⁻⁵ rad (7·10⁻⁴ °), below any
filter's error and any display (measured on ``aktos_t_broad`` through ``smooth_manoeuvre``: 8.0·10⁻⁵ rad
at worst, against the bound's 1.2·10⁻⁴; ``tests/pipelines/test_ros2_conventions.py``). Writing /tf at
every IMU sample instead would add one message per sample (+20 % messages in a five-channel log)
for nothing tf2 uses; thinned, the tree adds 1.2 % to the file.
Live streams (``gyroemu stream``) thin /tf the same way to a display's rate (:data:`TF_STREAM_RATE_HZ`,
``--tf-rate``), and send ``/tf_static`` at their first sample and again every :data:`TF_STATIC_REPEAT_S`.

**Start time** (:func:`parse_start_time`): stamps are absolute (ROS time, ns since the Unix epoch).
``simulate`` starts at :data:`SIMULATE_EPOCH_NS` (2025-01-01T00:00:00Z) unless told otherwise, so the
same seed gives the same bytes; ``stream`` at the wall clock.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from datetime import UTC, datetime
from decimal import Decimal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.pipelines.formats.channels import BODY_FRAME, ESTIMATE_FRAME, WORLD_FRAME

__all__ = [
    "TF_LOG_RATE_HZ",
    "TF_STREAM_RATE_HZ",
    "TF_STATIC_REPEAT_S",
    "SIMULATE_EPOCH_NS",
    "TF_TOPIC",
    "TF_STATIC_TOPIC",
    "parse_start_time",
    "format_stamp",
    "mounting_of",
    "check_frame_id",
    "TfThinning",
    "tf_indices",
]

TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"

TF_LOG_RATE_HZ = 100.0
"""/tf messages per second of a log (at most; every sample below it): see the module's notes."""

TF_STREAM_RATE_HZ = 30.0
"""/tf messages per second of a live stream by default (``gyroemu stream --tf-rate``): a display's frame
rate (the Foxglove view's default too), thinned as logs are (:class:`TfThinning`)."""

TF_STATIC_REPEAT_S = 1.0
"""A live stream re-publishes its ``/tf_static`` (the same bytes) every this many seconds of its sample
clock: zenoh keeps no latched sample for late subscribers, as ROS 2's transient-local durability does."""

SIMULATE_EPOCH_NS = 1_735_689_600_000_000_000
"""``simulate``'s default start time: 2025-01-01T00:00:00Z as ns since the Unix epoch."""

_EPOCH_LIMIT_NS = (2**31 - 1) * 1_000_000_000  # builtin_interfaces/Time's int32 seconds
_DECIMAL = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")  # what Decimal reads exactly


def parse_start_time(text: str | float | int, argument: str = "--start-time") -> int:
    """A start time as ns since the Unix epoch, from ISO 8601 (``2025-01-01T12:00:00Z``; a time without
    a zone is UTC) or epoch seconds (``1735689600.5``). ``ValueError`` naming ``argument`` otherwise,
    or when it lies before 1970 or after 2038-01-19 (the int32 seconds of ``builtin_interfaces/Time``)."""
    ns: int
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        seconds = float(text)
        if not math.isfinite(seconds):
            raise ValueError(f"argument {argument}: must be finite, got {text}")
        ns = round(seconds * 1e9)
    else:
        value = str(text).strip()
        try:
            if not math.isfinite(float(value)):
                raise ValueError(f"argument {argument}: must be finite, got {value}")
            # From the digits (a double of 1.7·10⁹ s resolves 0.24 µs: ".123456789" read 21 ns off).
            ns = round(Decimal(value) * 1_000_000_000) if _DECIMAL.match(value) else round(float(value) * 1e9)
        except ValueError as e:
            if "finite" in str(e):
                raise
            try:
                when = datetime.fromisoformat(value.replace("Z", "+00:00").replace("z", "+00:00"))
            except ValueError:
                raise ValueError(
                    f"argument {argument}: expected ISO 8601 (2025-01-01T00:00:00Z) or epoch seconds, got {value!r}"
                ) from None
            if when.tzinfo is None:
                when = when.replace(tzinfo=UTC)
            delta = when - datetime(1970, 1, 1, tzinfo=UTC)
            ns = (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
    if not 0 <= ns <= _EPOCH_LIMIT_NS:
        raise ValueError(f"argument {argument}: {text} is outside 1970-01-01 .. 2038-01-19 (ROS time's int32 seconds)")
    return ns


def format_stamp(ns: int) -> str:
    """``ns`` since the Unix epoch as ISO 8601 UTC with microseconds (``2025-01-01T00:00:00.000000Z``)."""
    when = datetime.fromtimestamp(ns // 1_000_000_000, tz=UTC)
    return when.strftime("%Y-%m-%dT%H:%M:%S") + f".{(ns % 1_000_000_000) // 1000:06d}Z"


def check_frame_id(frame_id: str) -> str:
    """``frame_id`` when it can name the IMU's frame: not empty, no NUL, no leading ``/`` (tf2 refuses
    it), and none of the tree's other frames (``map``, ``base_link``, ``body_estimate``); else
    ``ValueError`` saying why."""
    if not frame_id or "\x00" in frame_id or frame_id.startswith("/") or frame_id != frame_id.strip():
        raise ValueError(f"{frame_id!r} is not a tf frame name (non-empty, no leading '/', no spaces around it)")
    if frame_id in (WORLD_FRAME, BODY_FRAME, ESTIMATE_FRAME):
        raise ValueError(
            f"{frame_id!r} is already a frame of the tf tree ({WORLD_FRAME}, {BODY_FRAME}, {ESTIMATE_FRAME})"
        )
    return frame_id


def mounting_of(device: object) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """``(q_bs (4,) w, x, y, z; lever_arm_m (3,))`` of a device (a ``Device``, or its resolved config as
    TOML text); identity and zero where the config has no ``[mounting]``; None when ``device`` is None
    or text that is not a device config."""
    if device is None:
        return None
    if isinstance(device, str):
        if not device.strip():
            return None
        try:
            mounting = tomllib.loads(device).get("mounting", {})
        except tomllib.TOMLDecodeError:
            return None
        q = mounting.get("q_bs", (1.0, 0.0, 0.0, 0.0))
        lever = mounting.get("lever_arm_m", (0.0, 0.0, 0.0))
    else:
        spec = getattr(getattr(device, "spec", None), "mounting", None)
        if spec is None:
            return None
        q, lever = spec.q_bs, spec.lever_arm_m
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q), np.asarray(lever, dtype=float)


@dataclass
class TfThinning:
    """Which samples of a series go on /tf: the first of every ``1/rate_hz`` bin of stamps (bins counted
    from the series' first stamp, so the choice does not depend on how the series is cut into blocks),
    and, through :meth:`last`, the series' final sample.

    Attributes
    ----------
    rate_hz : float
        /tf messages per second, at most.
    """

    rate_hz: float
    _origin: int | None = field(default=None, repr=False)
    _bin: int = field(default=-1, repr=False)
    _last_kept: int | None = field(default=None, repr=False)
    _last_seen: int | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.rate_hz > 0:
            raise ValueError(f"a /tf rate must be positive, got {self.rate_hz}")
        self._period = max(1, round(1e9 / self.rate_hz))

    def keep(self, stamp_ns: ArrayLike) -> NDArray[np.intp]:
        """Indices into ``stamp_ns`` (N,) int64, the next block of the series, to put on /tf."""
        stamp_ns = np.asarray(stamp_ns, dtype=np.int64)
        if not len(stamp_ns):
            return np.empty(0, np.int64)
        if self._origin is None:
            self._origin = int(stamp_ns[0])
        bins = (stamp_ns - self._origin) // self._period
        previous = np.concatenate(([self._bin], bins[:-1]))
        index = np.flatnonzero(bins != previous)
        self._bin = int(bins[-1])
        self._last_seen = int(stamp_ns[-1])
        if len(index):
            self._last_kept = int(stamp_ns[index[-1]])
        return index

    def last(self) -> bool:
        """Whether the series' final sample (the last given to :meth:`keep`) still needs a /tf message."""
        return self._last_seen is not None and self._last_seen != self._last_kept


def tf_indices(stamp_ns: NDArray[np.int64], rate_hz: float) -> NDArray[np.intp]:
    """Indices of a whole series' stamps (N,) that go on /tf: :class:`TfThinning`'s, and the last."""
    thinning = TfThinning(rate_hz)
    index = thinning.keep(stamp_ns)
    if thinning.last():
        index = np.append(index, len(stamp_ns) - 1)
    return index
