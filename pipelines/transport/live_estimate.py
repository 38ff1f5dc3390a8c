"""A live attitude filter on a zenoh stream: subscribe to a device's ``/imu`` (and ``/mag``), filter
the samples as they arrive, publish ``/estimate/imu`` at the same stamps.

:class:`LiveEstimator` runs on its own zenoh session and thread, so it sees the stream exactly as any
other subscriber does (``gyroemu stream --estimate`` runs one next to its publisher; the demo too).
Messages queue in FIFO channels; the worker drains them, pairs each ``/imu`` sample with the ``/mag``
sample of the same stamp (when the filter is 9D; a field that has not arrived when a later sample's
has is taken as missing), feeds the block to the filter (whose state carries over between blocks) and
publishes one ``/estimate/imu`` message per sample, BLOCK congestion control, rmw_zenoh attachment.
With a ``tf_rate_hz`` it also puts ``map`` → ``body_estimate`` (the estimated attitude, at the world's
origin: a live filter knows no position) on the device's ``/tf`` key, thinned to that rate as the
stream thins its own ``/tf`` (:class:`~gyroemu.pipelines.formats.frames.TfThinning`), so a tf listener
sees the estimate beside the truth's ``map`` → ``base_link``.
The filter's first block is held until it spans what the filter reads to start
(:func:`~gyroemu.pipelines.estimation.protocol.start_span_s`: the MEKF's 0.5 s, or 10 s where it may
find north from the Earth's rate), so that it starts as it does on the recorded log: the same seed
gives the same estimates, those ``gyroemu estimate`` writes (a first block of whatever one poll held
started it elsewhere: 1.8° and 5.3° apart on two runs of one stream).
The estimate is the body's (``base_link``): with the device's mounting given (``q_bs``), the filter's
sensor-frame attitude and rate are turned into the body's as ``gyroemu estimate`` turns them
(:mod:`gyroemu.pipelines.estimation.mounting`). Topics and the encoding of the estimate are the channel
vocabulary's (:mod:`gyroemu.pipelines.formats.channels`),
so the live estimate holds the bytes ``gyroemu estimate`` writes into a file.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from gyroemu.pipelines.estimation.mounting import mounting_turn
from gyroemu.pipelines.estimation.protocol import start_span_s
from gyroemu.pipelines.estimation.series import estimate_series
from gyroemu.pipelines.formats.channels import (
    ESTIMATE_FRAME,
    ESTIMATE_ROLE,
    IMU_ROLE,
    MAG_ROLE,
    WORLD_FRAME,
    encode_series,
    role_topic,
)
from gyroemu.pipelines.formats.frames import TF_TOPIC, TfThinning
from gyroemu.pipelines.formats.messages import IMU, MAGNETIC_FIELD
from gyroemu.pipelines.formats.tf_messages import encode_tf
from gyroemu.pipelines.transport.zenoh_io import PacedPublisher, drain, subscribe, topic_to_key

if TYPE_CHECKING:
    import zenoh

    from gyroemu.pipelines.estimation.protocol import AttitudeFilter

__all__ = ["LiveEstimator"]


class LiveEstimator:
    """Filter ``device``'s live stream on ``session`` with ``flt`` (an AttitudeFilter).

    Parameters
    ----------
    session : zenoh.Session
    device : str
        The stream's device name (keys ``gyroemu/<device>/imu``, ...).
    flt : AttitudeFilter
        Made for the stream's rate; ``flt.setup.use_mag`` (when present) says 9D.
    use_mag : bool
        Pair ``/mag`` samples with ``/imu`` samples (9D).
    tf_rate_hz : float or None
        Also put ``map`` → ``body_estimate`` on ``/tf`` at this rate (None: not).
    q_bs : ndarray (4,) or None
        The device's mounting (w, x, y, z; sensor → body): the estimate published is the body's,
        ``q̂_ws ⊗ q_bs*`` and ``R(q_bs) ω̂_s``. None or an identity: the filter's as it is.

    Attributes
    ----------
    published : int
        Estimates sent so far.
    """

    def __init__(
        self,
        session: zenoh.Session,
        device: str,
        flt: AttitudeFilter,
        use_mag: bool,
        tf_rate_hz: float | None = None,
        q_bs: NDArray[np.float64] | None = None,
    ) -> None:
        self.flt = flt
        self.q_bs = mounting_turn(q_bs)  # None: nothing to turn (unmounted), the filter's bytes as they are
        self.use_mag = use_mag
        self.published = 0
        self._imu = subscribe(session, topic_to_key(device, role_topic(IMU_ROLE)))
        self._mag = subscribe(session, topic_to_key(device, role_topic(MAG_ROLE))) if use_mag else None
        self.key = topic_to_key(device, role_topic(ESTIMATE_ROLE))
        self.tf_key = topic_to_key(device, TF_TOPIC) if tf_rate_hz is not None else None
        self._thinning = TfThinning(tf_rate_hz) if tf_rate_hz is not None else None
        self._last_tf: NDArray[np.uint8] | None = None
        self._out = PacedPublisher(session, [self.key] if self.tf_key is None else [self.key, self.tf_key])
        self._pending: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]] = []  # (stamp ns, gyro, accel)
        self._fields: dict[int, NDArray[np.float64]] = {}
        self._t0_ns: int | None = None
        self._start_ns = round(start_span_s(flt) * 1e9)  # the span its first block must hold, ns
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="gyroemu-live-estimate", daemon=True)

    def start(self) -> LiveEstimator:
        self._thread.start()
        return self

    def ready(self) -> bool:
        """Whether the stream's publishers have reached this estimator's subscribers (and a subscriber
        waits for the estimates)."""
        return self._out.matched()

    def close(self, drain_s: float = 1.0) -> None:
        """Process what is still queued (for up to ``drain_s``), then stop."""
        end = time.monotonic() + drain_s
        while time.monotonic() < end and self.poll(final=True):
            pass
        if self._thinning is not None and self._thinning.last() and self._last_tf is not None:
            self._out.put(str(self.tf_key), self._last_tf.tobytes())  # the run's last sample, as /tf ends
        self._stop.set()
        self._thread.join(timeout=5)
        self._out.close()
        for sub in (self._imu, self._mag):
            if sub is not None:
                sub.undeclare()

    @staticmethod
    def _tf_rows(stamp_ns: NDArray[np.int64], q_wb: NDArray[np.float64]) -> NDArray[np.uint8]:
        """``map`` -> ``body_estimate`` TFMessages at ``stamp_ns`` (N,): rotations ``q_wb`` (N, 4), w first."""
        return encode_tf(stamp_ns, [(WORLD_FRAME, ESTIMATE_FRAME)], np.zeros(3), q_wb[:, None, [1, 2, 3, 0]])

    def _loop(self) -> None:
        while not self._stop.is_set():
            if not self.poll():
                time.sleep(0.001)

    def poll(self, final: bool = False) -> bool:
        """Take in what has arrived and filter the samples that are complete (``final``: every sample
        held, the end of the stream); False when idle. The worker thread polls every millisecond; a
        caller that runs no thread (a test) may poll itself."""
        imu = drain(self._imu)
        mag = drain(self._mag) if self._mag is not None else []
        if mag:
            batch = MAGNETIC_FIELD.decode([bytes(s.payload.to_bytes()) for s in mag])
            for stamp, field in zip(batch.stamp_ns, batch["magnetic_field"]):
                self._fields[int(stamp)] = field
        if imu:
            batch = IMU.decode([bytes(s.payload.to_bytes()) for s in imu])
            self._pending.extend(zip(batch.stamp_ns.tolist(), batch["angular_velocity"], batch["linear_acceleration"]))
        if not self._pending:
            return bool(mag)
        # 9D: a sample is complete when its field is here, or a later sample's is (then it has none).
        ready = len(self._pending)
        if self.use_mag and not final:
            newest_field = max(self._fields, default=-1)
            ready = 0
            while ready < len(self._pending) and self._pending[ready][0] <= newest_field:
                ready += 1
        if ready == 0:
            return bool(imu or mag)
        if self._t0_ns is None and not final and self._pending[ready - 1][0] - self._pending[0][0] < self._start_ns:
            return bool(imu or mag)  # the first block: held until it spans the filter's start
        block, self._pending = self._pending[:ready], self._pending[ready:]
        stamp_ns = np.array([s for s, _, _ in block], dtype=np.int64)
        gyro = np.array([g for _, g, _ in block])
        accel = np.array([a for _, _, a in block])
        field = None
        if self.use_mag:
            field = np.array([self._fields.pop(int(s), (np.nan, np.nan, np.nan)) for s in stamp_ns])
            for old in [s for s in self._fields if s < stamp_ns[-1]]:
                del self._fields[old]
        if self._t0_ns is None:
            self._t0_ns = int(stamp_ns[0])
        t_rel = (stamp_ns - self._t0_ns) * 1e-9
        estimate = self.flt.process(t_rel, gyro, accel, field)
        series = estimate_series(stamp_ns * 1e-9, estimate, gyro, self.q_bs)  # the body's, in base_link
        rows = encode_series(stamp_ns, series)
        tf_at = {}
        if self._thinning is not None and series.q_wb is not None:  # an attitude filter gives q_wb
            keep = self._thinning.keep(stamp_ns)
            tf_at = dict(zip(keep.tolist(), self._tf_rows(stamp_ns[keep], series.q_wb[keep])))
            self._last_tf = self._tf_rows(stamp_ns[-1:], series.q_wb[-1:])[0]
        for i, row in enumerate(rows):
            self._out.put(self.key, row.tobytes())
            if i in tf_at:
                self._out.put(str(self.tf_key), tf_at[i].tobytes())
        self.published += len(rows)
        return True
