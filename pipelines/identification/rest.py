"""Rest phases of a recording: where the sensor lay still, found from its own gyro and accelerometer.

A window of ``window_s`` is quiet when both

    s_ω = ‖std_window(ω)‖        (the three axes' standard deviations, combined)
    s_f = ‖std_window(f)‖        (the specific force's, per axis: a tilt or a turn moves it)

are below ``factor`` times their quietest level (the 5th percentile over the recording: a recording is
assumed to rest for at least 5 % of its time, as BROAD's trials do). Quiet runs shorter than
``min_duration_s`` are dropped and each run is trimmed by ``margin_s`` at both ends (set-down and
pick-up transients). The user can give intervals in seconds instead (:func:`phases_from_intervals`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .truth import moving_average

__all__ = ["RestPhase", "find_rest_phases", "phases_from_intervals"]


@dataclass(frozen=True)
class RestPhase:
    """Samples ``start:stop`` of a recording at rest, and their span ``t_start`` … ``t_stop``, s."""

    start: int
    stop: int
    t_start: float
    t_stop: float

    @property
    def duration_s(self) -> float:
        """Length of the phase, s."""
        return self.t_stop - self.t_start

    @property
    def samples(self) -> int:
        """Number of samples."""
        return self.stop - self.start


def _moving_std(x: NDArray[np.float64], length: int) -> NDArray[np.float64]:
    """(N,) norm over axes of the centred moving standard deviation of ``x`` (N, 3)."""
    m1 = moving_average(x, length)
    m2 = moving_average(x * x, length)
    spread: NDArray[np.float64] = np.sqrt(np.sum(np.maximum(m2 - m1 * m1, 0.0), axis=1))
    return spread


def find_rest_phases(
    t: ArrayLike,
    gyro: ArrayLike,
    accel: ArrayLike,
    *,
    window_s: float = 0.5,
    min_duration_s: float = 3.0,
    margin_s: float = 0.5,
    factor: float = 3.0,
) -> list[RestPhase]:
    """Rest phases of a recording (module notes), in time order.

    Parameters
    ----------
    t : (N,) s, increasing.
    gyro : (N, 3) rad/s.
    accel : (N, 3) m/s².
    window_s, min_duration_s, margin_s : s.
    factor : how far above its quietest level a window's spread may be.
    """
    t = np.asarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    dt = float(np.median(np.diff(t)))
    length = max(3, int(round(window_s / dt)) | 1)
    s_w = _moving_std(gyro, length)
    s_f = _moving_std(accel, length)
    finite = np.isfinite(s_w) & np.isfinite(s_f)
    if not finite.any():
        return []
    quiet = finite.copy()
    quiet[finite] = (s_w[finite] <= factor * np.percentile(s_w[finite], 5)) & (
        s_f[finite] <= factor * np.percentile(s_f[finite], 5)
    )
    # A quiet window marks its whole span as still: dilate the centres by half a window.
    half = length // 2
    still = np.convolve(quiet.astype(int), np.ones(length, dtype=int), mode="same") > 0
    still &= np.convolve((~quiet).astype(int), np.ones(2 * half + 1, dtype=int), mode="same") == 0
    edges = np.diff(np.concatenate([[0], still.astype(int), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    margin = int(round(margin_s / dt))
    phases = []
    for a, b in zip(starts + margin, stops - margin):
        if b - a >= 2 and t[b - 1] - t[a] >= min_duration_s:
            phases.append(RestPhase(int(a), int(b), float(t[a]), float(t[b - 1])))
    return phases


def phases_from_intervals(t: ArrayLike, intervals: Sequence[tuple[float, float]]) -> list[RestPhase]:
    """Rest phases from user intervals ``[(t_start, t_stop), …]`` in the recording's seconds.

    Raises ``ValueError`` for an interval that is empty, reversed or holds fewer than 4 samples.
    """
    t = np.asarray(t, dtype=float)
    phases = []
    for a, b in intervals:
        if not a < b:
            raise ValueError(f"rest interval ({a:g}, {b:g}) s: start must be before stop")
        i, j = int(np.searchsorted(t, a, side="left")), int(np.searchsorted(t, b, side="right"))
        if j - i < 4:
            raise ValueError(
                f"rest interval ({a:g}, {b:g}) s holds {j - i} samples (the log spans {t[0]:g} … {t[-1]:g} s)"
            )
        phases.append(RestPhase(i, j, float(t[i]), float(t[j - 1])))
    return sorted(phases, key=lambda p: p.start)
