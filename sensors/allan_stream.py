"""Overlapping Allan deviation of a series fed in chunks, in memory that does not grow with its length.

:class:`OverlappingAllanAccumulator` takes rate samples ``(n, axes)`` a chunk at a time and gives, at
any point, the same :class:`~gyroemu.sensors.allan.AllanDeviation` that
:func:`~gyroemu.sensors.allan.allan_deviation` computes from the whole series (octave τ, the same
cluster counts, degrees of freedom and 68 % intervals), so :func:`~gyroemu.sensors.allan.fit_allan`
takes it unchanged.

The estimator (NIST SP 1065 eq. 11), with x the phase (angle) x_k = Δt Σ_{j<k} y_j, k = 0 … N:

    σ²(τ) = Σ_k (x_{k+2m} − 2x_{k+m} + x_k)² / (2τ²(N + 1 − 2m)),   τ = mΔt

Written with the sums S_k = Σ_{j<k} y_j instead (x = Δt·S), Δt cancels: σ²(mΔt) = Σ_k (ΔS_k)² / (2m²n),
n the number of terms; Δt only names τ.

Octaves m = 1, 2, 4, … are those ``allantools.oadev(..., taus="octave")`` gives and
``allan_deviation`` keeps: powers of two with 2m ≤ N − 1 (``oadev`` drops τ with a single term of
its N + 1 phase points; then ⌊N/m⌋ ≥ 2 holds too).

Exact and decimated octaves
---------------------------
- m ≤ ``max_exact_m`` (M₀): exact. Every term k = 0 … N − 2m is summed, as ``oadev`` does. A term
  needs the phase 2m samples back, so the last 2M₀ + 1 phase values are kept (one buffer for all
  these octaves).
- m > M₀: decimated. The phase is kept only at every s-th sample, s = m/R with R = min(``coarse_overlap``,
  M₀) (a power of two), and the terms k = 0, s, 2s, … ≤ N − 2m are summed: the overlapping estimator
  with overlap step s instead of 1 (step m would be the non-overlapping one). Each term has the same
  expectation, so the estimate is unbiased; it averages fewer, strongly correlated terms, so its
  variance is a little larger than the fully overlapping one (and no larger than the non-overlapping
  one's, of which it is the mean of R offset copies). Each such octave keeps its last 2R + 1
  decimated phase values.

Memory: (2M₀ + 1)·axes float64 for the exact octaves, and (2R + 1)·axes for each decimated octave up to
m = 2^61 (no int64 length can use more), allocated at construction: fixed, whatever the series' length
(:meth:`state_nbytes`; about 2.2 MB for three axes with the defaults). Per chunk of n samples the
temporaries are O((n + 2M₀)·axes).

Round-off
---------
The phase of a biased gyro grows without bound (1e-5 rad/s for 4e7 samples), while the terms are
differences of nearby phases. So the phase is never carried absolutely: the buffers hold phase relative
to the newest sample, re-based (one subtraction) after each chunk, and a constant offset (the first
chunk's mean, per axis) is taken off the samples; a constant offset adds a straight line to the
phase, which the second difference removes exactly, so only rounding depends on it. The magnitudes
that round are then those of the phase within one window of 2M₀ + n samples (P, at most twice the
largest running sum of the offset samples), not of the whole run. An error in a term is at most
ε·[P·(m + 2r + 3.5) + m·Y] (ε = 2⁻⁵²): ε/2·P for each of the 2m running sums inside its span, ε/2·P for
each of r re-basings of its three points (weights 1, 2, 1; r is at most the chunk boundaries within the
span), 3.5εP for the subtractions forming it, and ε/2·Y for each sample's offset removal, Y the largest
|y − offset|. The relative error of σ² is then at most 2δ/rms + (δ/rms)², δ that bound and rms the rms
of the terms (Σ|D| ≤ √(n ΣD²)); allantools' own rounding is of the same form with P its absolute
phase. The sums of squares are pairwise within a chunk and compensated (Neumaier) across chunks,
adding O(ε log n). How the data were cut into chunks changes only this rounding (the offset, r, and
the order of the additions), so two cuts agree within the sum of their two bounds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # imported where used: gyroemu.sensors.allan pulls in scipy
    from gyroemu.sensors.allan import AllanDeviation

__all__ = ["OverlappingAllanAccumulator"]

_LARGEST_LOG2_M = 61  # 2m ≤ N − 1 < 2^63: no int64 count of samples reaches m = 2^62


def _power_of_two(value: int, name: str) -> int:
    value = int(value)
    if value < 1 or value & (value - 1):
        raise ValueError(f"{name} must be a power of two >= 1, got {value}")
    return value


class OverlappingAllanAccumulator:
    """Overlapping Allan variance of rate samples fed in chunks (see the module notes).

    Parameters
    ----------
    dt : sample interval, s (names τ = mΔt; the variance itself does not depend on it).
    n_axes : number of axes (columns) of the samples.
    max_exact_m : the largest m (τ = mΔt) computed exactly, a power of two; the phase buffer holds
        2·max_exact_m + 1 values per axis.
    coarse_overlap : R, terms per τ for the decimated octaves m > ``max_exact_m`` (overlap step
        s = m/R); a power of two, capped at ``max_exact_m``.

    Examples
    --------
    ::

        acc = OverlappingAllanAccumulator(dt=0.01, n_axes=3)
        for chunk in chunks:  # each (n, 3), rad/s
            acc.update(chunk)
        x, y, z = acc.deviations()  # AllanDeviation of each axis
    """

    def __init__(self, dt: float, n_axes: int = 3, max_exact_m: int = 1 << 15, coarse_overlap: int = 256) -> None:
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt}")
        if int(n_axes) < 1:
            raise ValueError(f"n_axes must be >= 1, got {n_axes}")
        self.dt = float(dt)
        self.n_axes = int(n_axes)
        self.max_exact_m = _power_of_two(max_exact_m, "max_exact_m")
        self.coarse_overlap = min(_power_of_two(coarse_overlap, "coarse_overlap"), self.max_exact_m)
        top = self.max_exact_m.bit_length() - 1  # log2 M₀
        self._m = np.array([1 << k for k in range(_LARGEST_LOG2_M + 1)], dtype=np.int64)
        self._stride = np.where(self._m <= self.max_exact_m, 1, self._m // self.coarse_overlap)
        self._n_exact = top + 1
        a = self.n_axes
        # Phase relative to the newest sample, right-aligned; the first ``filled`` columns from the
        # right hold values. Initially S_0 = 0 alone.
        self._tail = np.zeros((a, 2 * self.max_exact_m + 1))
        self._tail_filled = 1
        n_coarse = len(self._m) - self._n_exact
        self._coarse_tail = np.zeros((n_coarse, a, 2 * self.coarse_overlap + 1))
        self._coarse_filled = np.ones(n_coarse, dtype=np.int64)
        self._sum = np.zeros((len(self._m), a))  # Σ (ΔS)², per octave and axis
        self._compensation = np.zeros((len(self._m), a))  # Neumaier's running correction of _sum
        self._terms = np.zeros(len(self._m), dtype=np.int64)
        self._offset = np.zeros(a)
        self._n = 0

    # -- what has been fed -----------------------------------------------------------------------

    @property
    def n_samples(self) -> int:
        """Samples fed so far."""
        return self._n

    @property
    def offset(self) -> NDArray[np.float64]:
        """(axes,) the constant taken off the samples before summing (the first chunk's mean), rate unit."""
        return self._offset.copy()

    @property
    def octaves(self) -> NDArray[np.int64]:
        """(L,) every m = 2^k the accumulator tracks (those with 2m ≤ N − 1 are reported)."""
        return self._m.copy()

    @property
    def strides(self) -> NDArray[np.int64]:
        """(L,) overlap step of each octave's terms: 1 for the exact ones, m/R for the decimated."""
        return self._stride.copy()

    @property
    def terms(self) -> NDArray[np.int64]:
        """(L,) second differences summed so far per octave: N + 1 − 2m exact, ⌊(N − 2m)/s⌋ + 1 decimated."""
        return self._terms.copy()

    def state_nbytes(self) -> int:
        """Bytes held between chunks (the sum of the state arrays' sizes): fixed at construction."""
        arrays = (self._tail, self._coarse_tail, self._coarse_filled, self._sum, self._compensation, self._terms)
        return int(sum(a.nbytes for a in arrays) + self._m.nbytes + self._stride.nbytes + self._offset.nbytes)

    # -- feeding ---------------------------------------------------------------------------------

    def update(self, chunk: ArrayLike) -> None:
        """Add the next ``chunk`` (n, axes) of rate samples (or (n,) for one axis), in the data's unit.

        Raises ``ValueError`` for a wrong shape or NaN/infinite samples (nothing is added then).
        """
        y = np.asarray(chunk, dtype=float)
        if y.ndim == 1 and self.n_axes == 1:
            y = y[:, None]
        if y.ndim != 2 or y.shape[1] != self.n_axes:
            raise ValueError(f"expected a chunk of shape (n, {self.n_axes}), got {y.shape}")
        n = len(y)
        if n == 0:
            return
        if not np.all(np.isfinite(y)):
            raise ValueError("the chunk has NaN or infinite samples")
        if self._n == 0:
            self._offset = y.mean(axis=0)
        # u_j = S_{K+j+1} − S_K: the phase (in sums of samples) of the new samples relative to the newest
        # old one, S_K; (axes, n) so that each axis is contiguous (pairwise sums below).
        u = np.cumsum((y - self._offset).T, axis=1)
        self._exact(u)
        self._coarse(u)
        self._n += n

    def _add(self, level: int, squares: NDArray[np.float64], count: int) -> None:
        """Σ over one chunk of one octave's squared terms (axes,), compensated (Neumaier)."""
        total = self._sum[level]
        new = total + squares
        big = np.abs(total) >= np.abs(squares)
        self._compensation[level] += np.where(big, (total - new) + squares, (squares - new) + total)
        self._sum[level] = new
        self._terms[level] += count

    @staticmethod
    def _second_differences(e: NDArray[np.float64], lo: int, lag: int) -> NDArray[np.float64]:
        """(axes, E − lo) e[i] − 2e[i − lag] + e[i − 2·lag] for i = lo … E − 1 (columns of ``e``)."""
        end = e.shape[1]
        return e[:, lo:] - 2.0 * e[:, lo - lag : end - lag] + e[:, lo - 2 * lag : end - 2 * lag]

    def _exact(self, u: NDArray[np.float64]) -> None:
        """Octaves m ≤ M₀: every term whose newest phase point is one of the chunk's."""
        size = self._tail.shape[1]
        filled = self._tail_filled
        # e[i]: S_g − S_K for g = K − filled + 1 + i; the chunk's points are i ≥ filled.
        e = np.concatenate([self._tail[:, size - filled :], u], axis=1)
        end = e.shape[1]
        for level in range(self._n_exact):
            m = int(self._m[level])
            # Newest point new (i ≥ filled), oldest at or after S_0 (i ≥ 2m while the buffer still
            # starts at S_0; once full, filled = 2M₀ + 1 > 2m).
            lo = max(filled, 2 * m)
            if lo < end:
                d = self._second_differences(e, lo, m)  # ΔS = S_{k+2m} − 2S_{k+m} + S_k
                self._add(level, np.sum(d * d, axis=1), end - lo)
        keep = min(end, size)
        self._tail[:, size - keep :] = e[:, end - keep :] - u[:, -1:]  # re-based on S_{K+n}
        self._tail_filled = keep

    def _coarse(self, u: NDArray[np.float64]) -> None:
        """Octaves m > M₀ on the phase decimated by s = m/R: terms k = 0, s, 2s, …"""
        r = self.coarse_overlap
        size = 2 * r + 1
        n = u.shape[1]
        last = u[:, -1:]
        for c in range(len(self._coarse_filled)):
            level = self._n_exact + c
            s = int(self._stride[level])
            tail = self._coarse_tail[c]
            filled = int(self._coarse_filled[c])
            first = (-(self._n + 1)) % s  # u[first] is the first new sample at a multiple of s
            if first >= n:
                tail[:, size - filled :] -= last  # no new point: re-base only
                continue
            e = np.concatenate([tail[:, size - filled :], u[:, first::s]], axis=1)
            end = e.shape[1]
            lo = max(filled, 2 * r)  # decimated lag R = m/s
            if lo < end:
                d = self._second_differences(e, lo, r)
                self._add(level, np.sum(d * d, axis=1), end - lo)
            keep = min(end, size)
            tail[:, size - keep :] = e[:, end - keep :] - last
            self._coarse_filled[c] = keep

    # -- result ----------------------------------------------------------------------------------

    def reported(self) -> NDArray[np.bool_]:
        """(L,) bool: the octaves :meth:`deviations` reports for the samples fed, 2m ≤ N − 1."""
        return 2 * self._m <= self._n - 1

    def variances(self) -> NDArray[np.float64]:
        """(M, axes) overlapping Allan variance σ²(τ) of the reported octaves, in the data's unit squared.

        σ²(mΔt) = Σ (ΔS)² / (2m²·terms)
        """
        keep = self.reported()
        total = (self._sum + self._compensation)[keep]
        m = self._m[keep].astype(float)
        return total / (2.0 * m**2 * self._terms[keep])[:, None]

    def deviations(self, dt: float | None = None) -> tuple[AllanDeviation, ...]:
        """One :class:`AllanDeviation` per axis, of the octave τ = mΔt with 2m ≤ N − 1.

        Parameters
        ----------
        dt : the sample interval to state τ in, s (default: the one given at construction).

        Raises ``ValueError`` for fewer than 4 samples (as :func:`allan_deviation` does).
        """
        from gyroemu.sensors.allan import allan_confidence

        if self._n < 4:
            raise ValueError(f"expected a series of at least 4 samples, got {self._n}")
        dt = self.dt if dt is None else float(dt)
        keep = self.reported()
        m = self._m[keep]
        tau = m * dt
        clusters = np.floor(self._n / m.astype(float))
        adev = np.sqrt(self.variances())
        return tuple(allan_confidence(tau, adev[:, axis], clusters, dt=dt) for axis in range(self.n_axes))
