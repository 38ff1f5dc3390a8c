"""The metrics of one filter run of ``gyroemu bench``, accumulated a block of samples at a time.

:class:`RunMetrics` takes a run's samples in order, in blocks of any size (the whole run as one block, or
a log read a block at a time), and gives the same :class:`RunResult`, to the bit, however the run is cut:

- the RMS errors are sums of squares over tiles of :data:`SUM_TILE` samples counted from the run's
  first, each tile summed by one ``np.sum`` and the tiles added in order, so no block boundary enters a
  sum (an RMS over the whole run as one ``np.mean`` would round differently from one summed a block at a
  time);
- the gyro bias's reference, the measured rate minus the true rate averaged over a centred window of
  :data:`BIAS_WINDOW_S`, is the difference of a running sum carried from block to block (the same
  sequence of additions as ``np.cumsum`` over the whole run), each sample's compared once its window's
  last sample has come;
- the convergence time and the divergence test keep what they need: the last sample above the threshold
  and the first valid one after it; the inclination error of the last :data:`DIVERGED_FINAL_FRACTION` of
  the counted samples, whose count the caller gives first.

What each metric means: :mod:`gyroemu.pipelines.jobs.bench`'s notes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gyroemu.pipelines.estimation.metrics import attitude_errors

__all__ = [
    "BIAS_WINDOW_S",
    "DIVERGED_FINAL_FRACTION",
    "DIVERGED_INCLINATION_DEG",
    "SUM_TILE",
    "RunMetrics",
    "RunResult",
    "TiledSquares",
    "json_number",
]

DIVERGED_FINAL_FRACTION = 0.10
DIVERGED_INCLINATION_DEG = 30.0
BIAS_WINDOW_S = 1.0
SUM_TILE = 4096
"""Samples summed at once by :class:`TiledSquares` (counted from the run's first sample)."""


def json_number(v: object) -> object:
    """A number as JSON has it: a float (None when not finite), an int, a bool; anything else as it is."""
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


@dataclass
class RunResult:
    """One filter on one run. Angles in degrees; None where not defined (a 6D heading, no bias)."""

    seed: int | None
    samples: int
    total_deg: float | None
    heading_deg: float | None
    inclination_deg: float | None
    convergence_s: float | None  # inf: never converged
    bias_error_deg_s: float | None
    throughput: float  # samples/s (batched: updates/s across runs)
    wall_s: float
    diverged: bool
    reason: str = ""

    def to_json(self) -> dict[str, Any]:
        d = {k: json_number(v) for k, v in self.__dict__.items()}
        d["converged"] = self.convergence_s is not None and math.isfinite(self.convergence_s)
        return d


class TiledSquares:
    """The sum of squares and the count of the chosen, non-NaN values of a run's samples, given in order
    a block at a time: each tile of :data:`SUM_TILE` samples (counted from the run's first, chosen or
    not) is summed at once when it is complete, and the tiles' sums are added in order, so the result
    does not depend on how the samples were cut into blocks."""

    def __init__(self) -> None:
        self.total = 0.0
        self.count = 0
        self._parts: list[np.ndarray] = []
        self._filled = 0  # samples of the current tile seen

    def add(self, x: np.ndarray, chosen: np.ndarray | None = None) -> None:
        """The next ``len(x)`` samples' values ``x`` (n,), of which ``chosen`` (n,) bool count (all: None)."""
        n, at = len(x), 0
        while at < n:
            take = min(SUM_TILE - self._filled, n - at)
            part = x[at : at + take] if chosen is None else x[at : at + take][chosen[at : at + take]]
            self._parts.append(part[~np.isnan(part)])
            self._filled += take
            at += take
            if self._filled == SUM_TILE:
                self._close_tile()

    def _close_tile(self) -> None:
        values = np.concatenate(self._parts) if self._parts else np.empty(0)
        if len(values):
            self.total += float(np.sum(values**2))
            self.count += len(values)
        self._parts, self._filled = [], 0

    def rms_deg(self) -> float:
        """The root mean square of the values counted so far (radians in, degrees out); NaN for none. Call
        it once the run's last sample has been added (it closes the last, partial tile)."""
        self._close_tile()
        return math.degrees(math.sqrt(self.total / self.count)) if self.count else math.nan


class _Convergence:
    """:func:`~gyroemu.pipelines.estimation.metrics.convergence_time` over samples given a block at a time."""

    def __init__(self, threshold_rad: float) -> None:
        self.threshold = threshold_rad
        self.any_valid = False  # a non-NaN error was seen
        self.any_above = False
        self.settled_t: float | None = None  # the first valid sample after the last one above
        self._waiting = False  # above seen, no valid sample after it yet

    def add(self, t: np.ndarray, e: np.ndarray) -> None:
        valid = ~np.isnan(e)
        self.any_valid = self.any_valid or bool(valid.any())
        above = np.flatnonzero(valid & (e > self.threshold))
        if len(above):
            self.any_above = True
            after = np.flatnonzero(valid[above[-1] + 1 :])
            self._waiting = not len(after)
            self.settled_t = None if self._waiting else float(t[above[-1] + 1 + after[0]])
        elif self._waiting and valid.any():
            self.settled_t, self._waiting = float(t[int(np.argmax(valid))]), False

    def time(self, t_first: float) -> float:
        if not self.any_valid:
            return math.nan
        if not self.any_above:
            return 0.0
        return math.inf if self.settled_t is None else self.settled_t - t_first


class _BiasError:
    """The gyro-bias error's squares: ``|b_est − b_true|`` over the run's second half, ``b_true`` the gyro
    minus the true rate's interval mean, averaged over a centred window (bench's notes). A sample is
    compared once the window around it is complete; the run's last ``window − window // 2 − 1`` samples
    and its first ``window // 2`` have no complete window (NaN: not counted, as over the whole run)."""

    def __init__(self, samples: int, window: int, half_from: float) -> None:
        self.samples, self.window, self.half_from = samples, window, half_from
        self.start = window // 2  # sample start + i has the mean of samples i … i + window − 1
        self.squares = TiledSquares()
        self._seen = 0  # samples given
        self._c = np.zeros((1, 3))  # running sums c[m] = Σ_{k<m} x_k, from c[_c_from] on
        self._c_from = 0
        self._omega_last: np.ndarray | None = None
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []  # (b_est, in the second half) not yet compared
        self._pending_n = 0
        self._compared = 0  # samples compared (fed to squares)

    def add(self, t: np.ndarray, b_est: np.ndarray, omega: np.ndarray, gyro: np.ndarray) -> None:
        # sample k is the mean rate over [t_{k−1}, t_k]: the true rate's mean over the same interval
        before = omega[:1] if self._omega_last is None else self._omega_last[None, :]
        omega_mean = 0.5 * (omega + np.concatenate((before, omega[:-1])))
        if self._omega_last is None:
            omega_mean[0] = omega[0]
        self._omega_last = omega[-1].copy()
        x = gyro - omega_mean
        self._c = np.concatenate((self._c, np.cumsum(np.concatenate((self._c[-1:], x)), axis=0)[1:]))
        self._seen += len(t)
        self._pending.append((b_est, t >= self.half_from))
        self._pending_n += len(t)
        # sample k's window ends with c[k − start + window]: compare every sample whose c is here
        ready = min(self._seen - self.window + self.start + 1, self._seen) - self._compared
        self._compare(max(ready, 0))

    def _compare(self, count: int) -> None:
        if not count:
            return
        b_est = np.concatenate([b for b, _ in self._pending])
        half = np.concatenate([h for _, h in self._pending])
        k = np.arange(self._compared, self._compared + count)
        i = k - self.start  # the window's first sample
        fits = (i >= 0) & (i <= self.samples - self.window)
        b_true = np.full((count, 3), np.nan)
        lo, hi = i[fits] - self._c_from, i[fits] + self.window - self._c_from
        b_true[fits] = (self._c[hi] - self._c[lo]) / self.window
        diff = np.linalg.norm(b_est[:count] - b_true, axis=1)
        self.squares.add(diff, half[:count] & np.isfinite(diff))
        self._compared += count
        self._pending = [(b_est[count:], half[count:])]
        self._pending_n -= count
        keep = max(0, self._compared - self.start) - self._c_from  # c rows no later sample reads
        if keep > 0:
            self._c, self._c_from = self._c[keep:], self._c_from + keep

    def rms_deg(self) -> float | None:
        self._compare(self._pending_n)  # the last samples: no complete window
        rms = self.squares.rms_deg()
        return rms if self.squares.count else None


class RunMetrics:
    """One filter's metrics over a run given a block of samples at a time (the module's notes).

    Parameters
    ----------
    samples, counted : int
        The run's samples, and those counted (in ``mask`` with a finite reference): needed first, for
        the tail of the divergence test.
    t_first, t_last : float
        The run's first and last stamps, s.
    six_d : bool
        Inclination only (the heading is arbitrary).
    threshold_deg : float
        Convergence threshold.
    bias_window : int or None
        Samples in the bias reference's window (``BIAS_WINDOW_S`` at the rate), None: no bias error
        (the truth has no rate).
    """

    def __init__(
        self,
        *,
        samples: int,
        counted: int,
        t_first: float,
        t_last: float,
        six_d: bool,
        threshold_deg: float,
        bias_window: int | None,
    ) -> None:
        self.samples, self.counted, self.six_d = samples, counted, six_d
        self.t_first = t_first
        self.total, self.heading, self.inclination, self.tail = (TiledSquares() for _ in range(4))
        self.tail_from = counted - max(1, int(math.ceil(DIVERGED_FINAL_FRACTION * counted)))
        self.convergence = _Convergence(math.radians(threshold_deg))
        half_from = t_first + 0.5 * (t_last - t_first)
        self.bias = None if bias_window is None else _BiasError(samples, bias_window, half_from)
        self._bias_given = True  # every block so far had a bias
        self._finite = True
        self._counted_seen = 0
        self.wall_s = 0.0

    def add(
        self,
        t: np.ndarray,
        q_est: np.ndarray,
        q_true: np.ndarray,
        mask: np.ndarray,
        bias_est: np.ndarray | None = None,
        omega_true: np.ndarray | None = None,
        gyro: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """The next block: stamps ``t`` (n,) s, estimate ``q_est`` and reference ``q_true`` (n, 4), ``mask``
        (n,) bool (the samples that count), the filter's ``bias_est`` (n, 3) rad/s or None, the true rate
        ``omega_true`` and the gyro (n, 3) rad/s for the bias error. Returns the block's errors, degrees,
        NaN outside the counted samples: ``{"total": ..., "inclination": ...}``."""
        if not len(t):
            return {"total": np.empty(0), "inclination": np.empty(0)}
        finite_est = np.isfinite(q_est).all(axis=1) & (np.linalg.norm(q_est, axis=1) > 0)
        self._finite = self._finite and bool(finite_est.all())
        with np.errstate(invalid="ignore", divide="ignore"):
            err = attitude_errors(np.where(finite_est[:, None], q_est, np.nan), q_true)
        counted = mask & np.isfinite(q_true).all(axis=1)
        total = np.where(counted, err.total, np.nan)
        inclination = np.where(counted, err.inclination, np.nan)
        self.total.add(total)
        self.heading.add(np.where(counted, err.heading, np.nan))
        self.inclination.add(inclination)
        ordinal = self._counted_seen + np.cumsum(counted) - 1
        self.tail.add(err.inclination, counted & (ordinal >= self.tail_from))
        self._counted_seen += int(counted.sum())
        self.convergence.add(t, inclination if self.six_d else total)
        if self.bias is not None and omega_true is not None and gyro is not None:
            if bias_est is None or np.shape(bias_est) != (len(t), 3):
                self._bias_given = False
            if self._bias_given:
                b, omega = np.asarray(bias_est, dtype=float), np.asarray(omega_true, dtype=float)
                self.bias.add(t, b, omega, np.asarray(gyro, dtype=float))
        return {"total": np.degrees(total), "inclination": np.degrees(inclination)}

    def result(self, *, seed: int | None = None, reason: str = "", throughput: float | None = None) -> RunResult:
        """The run's :class:`RunResult` once every sample has been added; ``reason``: why the filter failed
        (it then counts as diverged), ``throughput`` samples per second if not ``samples / wall_s``."""
        diverged = not self._finite
        why = reason or ("non-finite quaternions in the output" if diverged else "")
        if self.counted:
            tail_rms = self.tail.rms_deg()
            if tail_rms > DIVERGED_INCLINATION_DEG or (math.isnan(tail_rms) and not diverged):
                diverged = True
                why = why or (
                    f"inclination error RMS {tail_rms:.1f}° over the last {DIVERGED_FINAL_FRACTION:.0%}"
                    if not math.isnan(tail_rms)
                    else "no finite output over the last samples"
                )
        if reason:
            diverged = True
        bias = self.bias.rms_deg() if self.bias is not None and self._bias_given else None
        wall = float(self.wall_s)
        return RunResult(
            seed=seed,
            samples=self.samples,
            total_deg=None if self.six_d else self.total.rms_deg(),
            heading_deg=None if self.six_d else self.heading.rms_deg(),
            inclination_deg=self.inclination.rms_deg(),
            convergence_s=self.convergence.time(self.t_first),
            bias_error_deg_s=bias,
            throughput=float(throughput) if throughput is not None else (self.samples / wall if wall > 0 else math.nan),
            wall_s=wall,
            diverged=bool(diverged),
            reason=why if diverged else "",
        )
