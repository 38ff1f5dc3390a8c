"""The MEKF smoother over a log read a block at a time, its storage on disk: memory that does not grow
with the log.

:func:`~.mekf_smoother.smooth_log` holds the whole log, the forward pass's window storage (5.5 kB a
20 ms window) and the per-sample outputs in memory: about 0.8 kB a sample, 3 GB an hour at 1 kHz.
:class:`SmootherSpool` runs the same three steps with the same kernels
(:mod:`.mekf_smoother_kernels`) in bounded memory:

1. :meth:`SmootherSpool.learn`, a block at a time: the forward pass (block by block it gives the same
   bytes as over the whole log: the filter's state carries over), its window storage appended to one
   temporary file, each sample's stamp, forward attitude and bias to another;
2. the first :meth:`SmootherSpool.process`: the Rauch–Tung–Striebel recursion backward over the window
   file, a stretch of :data:`SEGMENT_WINDOWS` windows at a time (the recursion carries one window's
   smoothed error and covariance from a stretch to the one before it), each window's smoothed error
   and attitude covariance, with its last sample and update, written to a third file (0.3 kB a window);
3. :meth:`SmootherSpool.process`, a block at a time in the learned order: each sample's smoothed
   attitude, bias and covariance, made a stretch of windows at a time from the sample and smoothed
   files.

Each step does what :func:`~.mekf_smoother.smooth_log` does, in the same order, so the results are the
same to the bit (``tests/pipelines/test_smoother_spool.py``). Memory: a stretch of windows (22 MB) and
the caller's blocks. Disk: 5.8 kB a window and 64 bytes a sample, 1.3 GB an hour at 1 kHz with 20 ms
windows, in nameless temporary files (:func:`tempfile.TemporaryFile`, in ``folder`` or the system's
temporary folder: ``$TMPDIR``), gone when the spool is closed or the process ends.
"""

from __future__ import annotations

import math
import os
import tempfile
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from . import mekf_kernels as kern
from . import mekf_smoother_kernels as skern
from .mekf import MekfParams, earth_rate_enu, initial_state
from .protocol import Estimate, FilterSetup

__all__ = ["SEGMENT_WINDOWS", "SmootherSpool", "spool_bytes"]

X = kern.X_SIZE

SEGMENT_WINDOWS = 4096
"""Windows held in memory at once by each step (5.5 kB each: 22 MB; 82 s of a log with 20 ms windows)."""

WINDOW_RECORD = np.dtype(
    [
        ("end", "<i8"),  # the window's last sample, counted from the log's first
        ("F_top", "<f8", (5, X)),
        ("P_prior", "<f8", (X, X)),
        ("P_post", "<f8", (X, X)),
        ("x_upd", "<f8", (X,)),
    ]
)
"""One window of the forward pass's storage (:func:`.mekf_smoother_kernels.forward_pass`), as the
backward pass reads it (``M_post``, which only :func:`~.mekf_smoother.smooth_log` reports, is not filed)."""
FILED = {"end": 0, "F_top": 2, "P_prior": 3, "P_post": 4, "x_upd": 5}
"""Each filed field's place in :func:`.mekf_smoother_kernels.window_store`'s tuple."""

SAMPLE_RECORD = np.dtype([("t", "<f8"), ("q", "<f8", (4,)), ("b", "<f8", (3,))])
"""One sample of the forward pass: its stamp (s, the filter's), attitude and bias."""

SMOOTHED_RECORD = np.dtype([("end", "<i8"), ("x_upd", "<f8", (X,)), ("e", "<f8", (X,)), ("P3", "<f8", (3, 3))])
"""What the per-sample output needs of a window: its last sample and update (as filed), its smoothed
error state and smoothed attitude covariance."""


def _read(f: BinaryIO, dtype: np.dtype, first: int, count: int) -> np.ndarray:
    """Records ``first … first + count − 1`` of ``dtype`` from ``f``."""
    f.seek(first * dtype.itemsize)
    out = np.fromfile(f, dtype=dtype, count=count)
    if len(out) != count:
        raise OSError(f"the smoother's spool ends at record {first + len(out)}, {first + count} expected")
    return out


def _write(f: BinaryIO, records: np.ndarray, first: int) -> None:
    """``records`` at record ``first`` of ``f`` (a full disk raises OSError ENOSPC; numpy's ``tofile``
    would say only how much it wrote)."""
    f.seek(first * records.dtype.itemsize)
    f.write(np.ascontiguousarray(records).data)


def spool_bytes(samples: int, duration_s: float, window_s: float) -> int:
    """How many bytes of temporary files a :class:`SmootherSpool` keeps for a log of ``samples`` samples
    over ``duration_s`` s with windows of ``window_s`` s: each sample's record, and each window's storage
    and smoothed record. A window ends once its samples span ``window_s`` or count one more than that span
    holds (:func:`.mekf_kernels.window_due`), so at a steady rate each spans at least ``window_s``: at
    most a window every ``window_s``, and window 0 (the initial state). A gap in the stamps adds one."""
    windows = min(samples, math.ceil(duration_s / window_s) + 1)
    return samples * SAMPLE_RECORD.itemsize + windows * (WINDOW_RECORD.itemsize + SMOOTHED_RECORD.itemsize)


class SmootherSpool:
    """The forward MEKF and the RTS smoother of :func:`~.mekf_smoother.smooth_log`, over a log given a
    block at a time, twice: :meth:`learn` every block in time order, then :meth:`process` the same
    blocks in the same order for their smoothed estimates (see the module's notes).

    Parameters
    ----------
    setup : FilterSetup
    params : MekfParams
        The smoother's parameters (:func:`~.mekf_smoother.smoother_params`).
    folder : path-like, optional
        Where the temporary files go (default: the system's temporary folder).
    segment_windows : int
        Windows per stretch of the backward pass and the output (:data:`SEGMENT_WINDOWS`).
    """

    def __init__(
        self,
        setup: FilterSetup,
        params: MekfParams,
        *,
        folder: str | os.PathLike[str] | None = None,
        segment_windows: int = SEGMENT_WINDOWS,
    ) -> None:
        if segment_windows < 2:
            raise ValueError(f"segment_windows must be at least 2, got {segment_windows}")
        self.setup, self.params = setup, params
        self.segment = int(segment_windows)
        self._p = params.vector(setup)
        self._earth = earth_rate_enu(setup)
        self._files = [tempfile.TemporaryFile(dir=folder) for _ in range(3)]
        self._windows, self._samples, self._smoothed = self._files
        self._state: tuple[NDArray[np.float64], ...] | None = None  # q, b, slow, P, win, phi of the forward pass
        self._store = skern.window_store(self.segment)
        self._stored = 0  # windows in the store
        self.windows = 0  # windows filed
        self.samples = 0  # samples learned
        self._use_mag = False
        self._backward_done = False
        self._served = 0  # samples given out by process
        self._next_window = 1  # the first window whose samples are not yet made
        # samples made: stamps, attitudes, biases, covariances; those from ``_at`` on not yet given out
        self._made: tuple[NDArray[np.float64], ...] = (
            np.empty(0),
            np.empty((0, 4)),
            np.empty((0, 3)),
            np.empty((0, 3, 3)),
        )
        self._at = 0

    @property
    def disk_bytes(self) -> int:
        """Bytes in its temporary files now (:func:`spool_bytes` says about how many a log will take)."""
        return sum(os.fstat(f.fileno()).st_size for f in self._files)

    def close(self) -> None:
        """Remove the temporary files."""
        for f in self._files:
            f.close()

    def __enter__(self) -> SmootherSpool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # 1. forward ---------------------------------------------------------------------------------------

    def learn(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> None:
        """Run the forward pass over the log's next block: ``t`` (n,) s, increasing across blocks;
        ``gyro`` (n, 3) rad/s; ``accel`` (n, 3) m/s²; ``mag`` (n, 3) T or None. The first block starts the
        filter (:func:`~.mekf.initial_state` reads its first ``init_s`` seconds, and ``gyrocompass_s`` at
        rest where a 6D filter finds north from Earth's rate): the result is :func:`~.mekf_smoother.smooth_log`'s
        when the first block holds those (``gyroemu estimate`` and ``bench`` give the first minute)."""
        if self._backward_done:
            raise ValueError("the smoother has been asked for its estimates: it learns no more")
        t = np.ascontiguousarray(t, dtype=float)
        n = len(t)
        gyro = np.ascontiguousarray(gyro, dtype=float)
        accel = np.ascontiguousarray(accel, dtype=float)
        if gyro.shape != (n, 3) or accel.shape != (n, 3):
            raise ValueError(f"gyro and accel must have shape ({n}, 3), got {gyro.shape} and {accel.shape}")
        if n == 0:
            return
        if self._state is None:
            self._use_mag = bool(self.setup.use_mag and mag is not None)
        mag = np.ascontiguousarray(mag, dtype=float) if self._use_mag else np.full((n, 3), np.nan)
        if mag.shape != (n, 3):
            raise ValueError(f"mag must have shape ({n}, 3), got {mag.shape}")
        if self._state is None:
            init = initial_state(t, gyro, accel, mag if self._use_mag else None, self.setup, self.params)
            self._state = (init.q.copy(), init.b.copy(), init.slow.copy(), init.P.copy(), np.zeros(kern.W_SIZE))
            self._state += (np.zeros((3, kern.N_DRIFT)),)
            self._store[1][0] = init.slow[kern.S_SCALE : kern.S_SCALE + 9]
            self._store[4][0] = init.P
            self._stored = 1  # window 0: the initial state
        elif not t[0] > self._state[2][kern.S_T]:
            raise ValueError(f"stamp {t[0]!r} s does not follow the previous block's {self._state[2][kern.S_T]!r} s")
        q, b, slow, P, win, phi = self._state
        q_f, b_f, cov_f = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3, 3))
        k = 0
        while k < n:
            j0 = self._stored
            k, self._stored = skern.forward_pass(
                q, b, slow, P, win, phi, t, gyro, np.empty((0, 3)), accel, mag, self._earth, self._p,
                self._use_mag, k, q_f, b_f, cov_f, *self._store, j0,
            )  # fmt: skip
            self._store[0][j0 : self._stored] += self.samples  # the block's sample index -> the log's
            if self._stored == self.segment:
                self._file_store()
        records = np.empty(n, SAMPLE_RECORD)
        records["t"], records["q"], records["b"] = t, q_f, b_f
        _write(self._samples, records, self.samples)
        self.samples += n

    def _file_store(self) -> None:
        """Append the stored windows to the window file."""
        j = self._stored
        records = np.empty(j, WINDOW_RECORD)
        for name, column in FILED.items():
            records[name] = self._store[column][:j]
        _write(self._windows, records, self.windows)
        self.windows += j
        self._stored = 0
        self._store[0][:] = -1

    # 2. backward --------------------------------------------------------------------------------------

    def _backward(self) -> None:
        """The RTS recursion over the window file, a stretch at a time from the end."""
        self._file_store()
        W = self.windows
        e_next, P_next = np.zeros(X), None  # the smoothed state of the stretch's last window
        hi = W - 1  # the stretch's last window, smoothed already (the log's last: its forward state)
        while True:
            lo = max(0, hi - self.segment + 1)
            rec = _read(self._windows, WINDOW_RECORD, lo, hi - lo + 1)
            P_post = np.ascontiguousarray(rec["P_post"])
            e_s, P_s = np.empty((len(rec), X)), np.empty((len(rec), X, X))
            e_s[-1], P_s[-1] = e_next, P_post[-1] if P_next is None else P_next
            skern.rts_backward(
                np.ascontiguousarray(rec["F_top"]), np.ascontiguousarray(rec["P_prior"]), P_post,
                np.ascontiguousarray(rec["x_upd"]), e_s, P_s,
            )  # fmt: skip
            out = np.empty(len(rec), SMOOTHED_RECORD)
            out["end"], out["x_upd"], out["e"], out["P3"] = rec["end"], rec["x_upd"], e_s, P_s[:, 0:3, 0:3]
            _write(self._smoothed, out, lo)
            if lo == 0:
                break
            e_next, P_next, hi = e_s[0].copy(), P_s[0].copy(), lo
        self._backward_done = True

    # 3. the smoothed samples --------------------------------------------------------------------------

    def process(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None = None) -> Estimate:
        """The smoothed estimate of the next ``len(t)`` learned samples (``t`` as learned; the other
        arguments are not read): ``q_wb`` (n, 4), ``gyro_bias`` (n, 3) rad/s, ``q_wb_covariance``
        (n, 3, 3) rad². Raises ``ValueError`` for samples other than those learned."""
        if self._state is None:
            raise ValueError("the smoother has learned no samples")
        if not self._backward_done:
            self._backward()
        t = np.asarray(t, dtype=float)
        n = len(t)
        if self._served + n > self.samples:
            raise ValueError(f"{self._served + n} samples asked for, {self.samples} learned")
        while len(self._made[0]) - self._at < n:  # a stretch at a time: each sample copied once more
            made = self._make_stretch()
            self._made = tuple(np.concatenate((old[self._at :], new)) for old, new in zip(self._made, made))
            self._at = 0
        stamps, q, b, cov = (a[self._at : self._at + n].copy() for a in self._made)
        if not np.array_equal(stamps, t):
            raise ValueError(f"the stamps of samples {self._served}… are not those learned")
        self._at += n
        self._served += n
        return Estimate(q, b, cov)

    def _make_stretch(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The smoothed samples of the next stretch of windows (:func:`.mekf_smoother_kernels.per_sample`
        over it, the window before it as its window 0): stamps, attitudes, biases, covariances."""
        W = self.windows
        j1 = min(W, self._next_window + self.segment - 1)  # windows j0 … j1 − 1, and the tail after the last
        j0 = self._next_window - 1
        smoothed = _read(self._smoothed, SMOOTHED_RECORD, j0, j1 - j0)
        end = smoothed["end"]
        first = int(end[0])  # the sample before the stretch (−1: none); row 0 of the arrays below
        last = self.samples - 1 if j1 == W else int(end[-1])
        lo = max(first, 0)
        samples = _read(self._samples, SAMPLE_RECORD, lo, last - lo + 1)
        m = len(samples)
        q_s, b_s, cov_s = np.empty((m, 4)), np.empty((m, 3)), np.empty((m, 3, 3))
        skern.per_sample(
            np.ascontiguousarray(samples["t"]), np.ascontiguousarray(samples["q"]), np.ascontiguousarray(samples["b"]),
            end - lo, np.ascontiguousarray(smoothed["e"]), np.ascontiguousarray(smoothed["P3"]),
            np.ascontiguousarray(smoothed["x_upd"]), q_s, b_s, cov_s,
        )  # fmt: skip
        skip = 1 if first >= 0 else 0  # the sample before the stretch: the stretch before made it
        self._next_window = j1
        return samples["t"][skip:], q_s[skip:], b_s[skip:], cov_s[skip:]
