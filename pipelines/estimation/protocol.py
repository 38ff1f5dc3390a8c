"""What an attitude filter is to gyroemu: the small protocol that ours, the peers and a user's obey.

A filter is made from a :class:`FilterSetup` (what is known about the data before it starts) and then
fed blocks of samples in time order; its state carries over from block to block, so the same object
serves a whole log at once (``gyroemu estimate``, ``gyroemu bench``) and a live stream block by block
(``gyroemu stream --estimate``). A user's filter is any class with this shape::

    class MyFilter:
        name = "my-filter"                      # how the report names it

        def __init__(self, setup: FilterSetup): # rate, 6D/9D, what is known of the device
            ...

        def process(self, t, gyro, accel, mag=None) -> Estimate:
            # t (N,) s; gyro (N, 3) rad/s; accel (N, 3) m/s²; mag (N, 3) tesla or None (6D)
            # return q_wb (N, 4), world ENU, scalar first, one per sample
            ...

and is named on the command line as ``module:Class`` (``gyroemu bench --filter mypkg.filters:MyFilter``).
An offline filter (``offline = True``) takes the whole log in one ``process`` call; one that can also
take a log too long to hold (:class:`BlockLearner`: ``learns_in_blocks = True``) is given every block
by ``learn`` first, then asked by ``process`` for the same blocks' estimates in the same order.
A filter that starts from more than its first sample (the MEKF: its first ``init_s``, and the first
``gyrocompass_s`` where it may find north from the Earth's rate) says how many seconds its first
``process`` call reads with ``start_s`` (:func:`start_span_s`; absent: 0). A live run holds its first
samples until they span it, so that the filter starts as it does on the recorded log, whatever the
stream's blocks.
Frames and units follow ``interface.md``: ``q_wb`` turns body vectors into the ENU world frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeGuard, cast, runtime_checkable

import numpy as np

__all__ = [
    "PROCESS_PROTOCOL",
    "AttitudeFilter",
    "BlockLearner",
    "DeviceNoise",
    "Estimate",
    "FilterSetup",
    "estimate_problem",
    "learns_in_blocks",
    "start_span_s",
]


@dataclass(frozen=True)
class DeviceNoise:
    """A device's noise figures, SI, as far as they are known (None: unknown, use the defaults).

    Attributes
    ----------
    gyro_noise_density : float
        White rate noise (angle random walk coefficient N), rad/s/√Hz.
    gyro_bias_sigma : float
        Standard deviation of the gyro's turn-on bias, rad/s.
    gyro_bias_instability : float
        Bias instability B, rad/s.
    gyro_rate_random_walk : float
        Rate random walk K, rad/s/√s.
    gyro_scale_sigma : float
        Scale-factor error of each axis (RMS over the axes), relative.
    gyro_misalignment_sigma : float
        Misalignment of each axis towards each other one (RMS over the six), rad.
    accel_noise_density : float
        White specific-force noise, m/s²/√Hz.
    mag_noise_density : float
        White magnetometer noise, T/√Hz.
    """

    gyro_noise_density: float | None = None
    gyro_bias_sigma: float | None = None
    gyro_bias_instability: float | None = None
    gyro_rate_random_walk: float | None = None
    gyro_scale_sigma: float | None = None
    gyro_misalignment_sigma: float | None = None
    accel_noise_density: float | None = None
    mag_noise_density: float | None = None


@dataclass(frozen=True)
class FilterSetup:
    """What a filter may know before its first sample.

    Attributes
    ----------
    rate_hz : float
        The nominal sample rate, Hz (stamps may still be uneven).
    use_mag : bool
        9D (True: correct heading with the magnetometer) or 6D (False: ignore it).
    noise : DeviceNoise
        The device's noise figures, where known (from a gyroemu device config, or a datasheet).
    latitude_rad : float or None
        Latitude of the site, rad, when known: lets a filter take Earth's rotation out of the gyro
        (and find north from it, with a gyro good enough). None: Earth's rotation is not modelled.
    declination_rad : float
        Magnetic declination, rad, east positive: the azimuth of magnetic north in the ENU frame.
    field_heading_sigma : float or None
        Heading error of the measured field's direction, rad, when known: on a simulated site, where the
        field is the model's, what the magnetometer's uncompensated hard and soft iron make of it. None:
        unknown (a real site's anomalies, a moving sensor's surroundings).
    gyro_latency_s, mag_latency_s : float
        How long the gyro's and the magnetometer's samples lag the motion, s (a device's ``latency_s``):
        the sample stamped t measures the motion at t − L. Either non-zero, :func:`~.registry.make_filter`
        feeds every filter the field at the gyro's instant and turns its attitudes on to their stamps
        (:mod:`.latency`; the accelerometer is not moved, as it says why), and so does
        :func:`~.batched.mekf_batch`; a filter class made directly takes the samples as they are. 0: the
        stamps are the motion's.
    """

    rate_hz: float
    use_mag: bool = True
    noise: DeviceNoise = field(default_factory=DeviceNoise)
    latitude_rad: float | None = None
    declination_rad: float = 0.0
    field_heading_sigma: float | None = None
    gyro_latency_s: float = 0.0
    mag_latency_s: float = 0.0


@dataclass(frozen=True, eq=False)
class Estimate:
    """A filter's output for N samples.

    Attributes
    ----------
    q_wb : ndarray (N, 4)
        Attitude, unit quaternion (w, x, y, z), body to ENU world.
    gyro_bias : ndarray (N, 3) or None
        Estimated gyro bias, rad/s, body axes (None: the filter has none).
    q_wb_covariance : ndarray (N, 3, 3) or None
        Attitude error covariance, rad², about the world axes (ROS ``orientation_covariance``).
    """

    q_wb: np.ndarray
    gyro_bias: np.ndarray | None = None
    q_wb_covariance: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.q_wb)

    @staticmethod
    def concatenate(parts: list[Estimate]) -> Estimate:
        """Blocks joined in order (a field is kept only when every block has it)."""

        def join(name: str) -> np.ndarray | None:
            values = [getattr(p, name) for p in parts]
            return None if any(v is None for v in values) else np.concatenate(values)

        q_wb = join("q_wb")
        assert q_wb is not None  # every block has its attitude
        return Estimate(q_wb=q_wb, gyro_bias=join("gyro_bias"), q_wb_covariance=join("q_wb_covariance"))


@runtime_checkable
class AttitudeFilter(Protocol):
    """The protocol (see the module's docstring): a ``name`` and ``process`` over blocks."""

    name: str

    def process(
        self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None
    ) -> Estimate: ...


@runtime_checkable
class BlockLearner(AttitudeFilter, Protocol):
    """An offline filter that takes a log a block at a time (see the module's docstring): ``learn``
    every block in time order, then ``process`` the same blocks in the same order; ``spool_in`` names
    the folder for what it keeps (:class:`~.mekf_smoother.MekfSmoother`: temporary files), and
    ``spool_bytes`` says about how much that is for a log of ``samples`` samples over ``duration_s``
    seconds (checked against the folder's free space before the work); ``close`` frees it."""

    learns_in_blocks: bool

    def learn(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> None: ...

    def spool_in(self, folder: str | os.PathLike[str] | None) -> None: ...

    def spool_bytes(self, samples: int, duration_s: float) -> int: ...

    def close(self) -> None: ...


def start_span_s(flt: object) -> float:
    """Seconds of samples a filter's first ``process`` call reads to start (its ``start_s``; 0 for a
    filter that starts from its first sample, or says nothing)."""
    span = getattr(flt, "start_s", 0.0)
    return float(span) if isinstance(span, (int, float)) and span > 0 else 0.0


def learns_in_blocks(filter_or_class: object) -> TypeGuard[BlockLearner]:
    """Whether a filter, or a filter class, learns a log a block at a time: it says so
    (``learns_in_blocks = True``) and has :class:`BlockLearner`'s methods."""
    methods = ("process", "learn", "spool_in", "spool_bytes", "close")
    return bool(getattr(filter_or_class, "learns_in_blocks", False)) and all(
        callable(getattr(filter_or_class, m, None)) for m in methods
    )


PROCESS_PROTOCOL = (
    "process(t, gyro, accel, mag=None) must return an Estimate: q_wb (N, 4), one attitude a sample given, "
    "gyro_bias (N, 3) or None, q_wb_covariance (N, 3, 3) or None"
)
"""What the protocol asks of ``process``'s return value, in words (an error about a filter that breaks it
says so)."""


def estimate_problem(est: object, n: int, *, extras: bool = True) -> str | None:
    """What is wrong with ``est`` as ``process``'s return value for ``n`` samples, or None: the words
    that follow "process() returned" (``NoneType, not an Estimate``; ``q_wb of shape (3,), not one (4,)
    quaternion a sample``; ``2 attitudes fewer than the samples it was given``, said without the count,
    which is a block's where a log is read in blocks). An object with a ``q_wb`` passes for an Estimate.
    With ``extras``, also ``gyro_bias`` and ``q_wb_covariance`` when not None: (n, 3) and (n, 3, 3)."""
    if not isinstance(est, Estimate) and not hasattr(est, "q_wb"):
        return f"{type(est).__name__}, not an Estimate"
    try:
        q = np.asarray(cast(Any, est).q_wb, dtype=float)
    except (TypeError, ValueError) as e:
        return f"q_wb that is no array of numbers ({e})"
    if q.ndim != 2 or q.shape[1] != 4:
        return f"q_wb of shape {q.shape}, not one (4,) quaternion a sample"
    if len(q) != n:
        d = len(q) - n
        many = f"{abs(d)} attitude{'s' if abs(d) != 1 else ''} {'more' if d > 0 else 'fewer'}"
        return f"{many} than the samples it was given"
    if not extras:
        return None
    for name, shape in (("gyro_bias", (n, 3)), ("q_wb_covariance", (n, 3, 3))):
        value = getattr(est, name, None)
        if value is None:
            continue
        try:
            got = np.asarray(value, dtype=float).shape
        except (TypeError, ValueError) as e:
            return f"{name} that is no array of numbers ({e})"
        if got != shape:
            return f"{name} of shape {got}, not {shape} (one {shape[1:]} a sample) or None"
    return None
