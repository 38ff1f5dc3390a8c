"""A time series of any length reduced, as it is read, to what a plot can show: its min–max envelope.

A figure a few thousand pixels wide cannot show more than a few thousand columns of a series; a log
of hours at 1 kHz has millions of samples, which read whole would cost gigabytes and which matplotlib
would take minutes to draw. :class:`Envelope` keeps every sample while there are at most
``2 · buckets`` of them, then, per column of time, the least and the greatest value of each channel
(the min–max decimation plotting tools use: every spike stays visible) and the sum and the count for
the mean. The columns have one width, set by the first ``2 · buckets + 1`` samples and doubled whenever the
series outgrows them (two neighbours merged: their min of mins, max of maxes, sum of sums), so memory
stays ``4 · buckets`` rows whatever the length, and each column's least and greatest values are those
of its samples exactly, whichever blocks the series came in (its mean to round-off).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["Envelope"]


class Envelope:
    """The min–max envelope of a series ``values`` (N, channels) at stamps ``t`` (N,) s, fed in blocks.

    Parameters
    ----------
    channels : int
        Values per sample.
    buckets : int
        Columns of time once the series has more than ``2 · buckets`` samples (even; at least 2).

    Attributes
    ----------
    t0 : float or None
        The first stamp, s (columns are counted from it).
    width : float
        A column's width, s (0 while every sample is kept).
    """

    def __init__(self, channels: int, buckets: int = 2000) -> None:
        if buckets < 2 or buckets % 2:
            raise ValueError(f"buckets must be even and at least 2, got {buckets}")
        self.channels, self.buckets = int(channels), int(buckets)
        self.t0: float | None = None
        self.width = 0.0
        self._t: list[np.ndarray] = []  # every sample, while few
        self._v: list[np.ndarray] = []
        self._kept = 0
        self.samples = 0  # every sample taken
        self.lo = self.hi = self.total = np.empty(0)
        self.count = np.empty(0)

    @property
    def decimated(self) -> bool:
        """Whether the series is held as columns (more than ``2 · buckets`` samples came)."""
        return self.width > 0.0

    def add(self, t: np.ndarray, values: np.ndarray) -> None:
        """Take the next samples: ``t`` (n,) s, increasing (a stamp before the first goes in column 0);
        ``values`` (n, channels), NaN where there is none."""
        t = np.asarray(t, dtype=float)
        values = np.asarray(values, dtype=float).reshape(len(t), self.channels)
        if not len(t):
            return
        self.samples += len(t)
        if self.t0 is None:
            self.t0 = float(t[0])
        if not self.decimated:
            self._t.append(t)
            self._v.append(values)
            self._kept += len(t)
            if self._kept <= 2 * self.buckets:
                return
            t, values = np.concatenate(self._t), np.concatenate(self._v)
            self._t, self._v = [], []
            # from the first 2·buckets + 1 samples, however they came: the same columns for any cut
            span = float(t[2 * self.buckets]) - self.t0
            self.width = span / (self.buckets - 1) if span > 0 else 1.0
            shape = (self.buckets, self.channels)
            self.lo, self.hi, self.total = np.full(shape, np.inf), np.full(shape, -np.inf), np.zeros(shape)
            self.count = np.zeros(shape)
        index = np.maximum(np.floor((t - self.t0) / self.width), 0)
        while index.size and index.max() >= self.buckets:
            self._merge()
            index = np.maximum(np.floor((t - self.t0) / self.width), 0)
        index = index.astype(np.int64)
        finite = np.isfinite(values)
        np.minimum.at(self.lo, index, np.where(finite, values, np.inf))
        np.maximum.at(self.hi, index, np.where(finite, values, -np.inf))
        np.add.at(self.total, index, np.where(finite, values, 0.0))
        np.add.at(self.count, index, finite)

    def _merge(self) -> None:
        """Twice as wide columns: each pair of neighbours becomes one, the second half empty."""
        half = self.buckets // 2
        for name, reduce, empty in (
            ("lo", np.minimum, np.inf),
            ("hi", np.maximum, -np.inf),
            ("total", np.add, 0.0),
            ("count", np.add, 0.0),
        ):
            a = getattr(self, name)
            merged = np.full_like(a, empty)
            merged[:half] = reduce(a[0::2], a[1::2])
            setattr(self, name, merged)
        self.width *= 2.0

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(t, lo, hi, mean)``: each column's middle, s, and its least, greatest and mean values
        (m, channels), only columns with samples (NaN for a channel with none there); while every
        sample is kept, the samples themselves (``lo = hi = mean``)."""
        if not self.decimated:
            t = np.concatenate(self._t) if self._t else np.empty(0)
            v = np.concatenate(self._v) if self._v else np.empty((0, self.channels))
            return t, v, v, v
        used = np.flatnonzero(self.count.any(axis=1))
        assert self.t0 is not None
        middle = self.t0 + (used + 0.5) * self.width
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self.total[used] / self.count[used]
        some = self.count[used] > 0
        return middle, np.where(some, self.lo[used], np.nan), np.where(some, self.hi[used], np.nan), mean

    def draw(
        self,
        ax: Axes,
        *,
        channels: list[int] | None = None,
        labels: list[str] | None = None,
        colors: list[str] | None = None,
        t_offset: float = 0.0,
        lw: float = 0.8,
    ) -> None:
        """Draw ``channels`` (default: all) on the matplotlib axes ``ax`` against ``t − t_offset``, s:
        the samples as a line while they are kept, then each column's range as a band of the same
        colour (a narrow band reads as a line). ``labels`` and ``colors`` per channel drawn (default:
        none, and the cycle's ``C0``, ``C1``, …)."""
        t, lo, hi, mean = self.columns()
        t = t - t_offset
        for i, k in enumerate(range(self.channels) if channels is None else channels):
            label = labels[i] if labels else None
            color = colors[i] if colors else f"C{i}"
            if not self.decimated:
                ax.plot(t, mean[:, k], color=color, lw=lw, label=label)
            else:
                ax.fill_between(t, lo[:, k], hi[:, k], facecolor=color, edgecolor=color, linewidth=lw, label=label)

    def __len__(self) -> int:
        return self.samples
