"""A recorded motion as truth: sampled attitude and position, smoothed into a Trajectory with analytic
derivatives.

A motion capture, a dataset's ground truth or a log's truth channel gives the body's attitude
``q_wb`` and (often) its position ``p_w`` at stamps ``t_i``, with noise. An IMU reads derivatives of
them (the rate is a first derivative of the attitude, the specific force a second derivative of the
position), which differentiation of noisy samples would drown in noise. :class:`RecordedMotion` fits
cubic smoothing splines (:mod:`gyroemu.dynamics.smoothing_spline`) with the smoothing chosen from the
data, and differentiates the splines analytically:

* **Position**: the three world coordinates share one λ (the smoothing does not depend on how the
  world's axes point): ``v_w = ṗ``, ``a_w = p̈``.
* **Attitude**: the four quaternion components, made sign-continuous, share one λ, so the smoothing
  commutes with a constant turn of the world or of the body (both act on the components as an
  orthogonal 4 × 4 matrix). The spline ``s(t)`` is not of unit norm; with ``q = s / |s|`` and
  ``q̇ = ½ q ⊗ (0, ω)`` (body rate relative to the world)::

      ω_wb = 2 vec(s̄ ⊗ ṡ) / |s|²                          (the scalar part of s̄ ṡ is ½ d|s|²/dt)
      α_wb = 2 vec(s̄ ⊗ s̈) / |s|² − ω_wb · (2 s·ṡ) / |s|²   (vec(ṡ̄ ⊗ ṡ) = 0)

  Then :func:`gyroemu.dynamics.trajectory.trajectory_from_world_motion` adds the Earth's rotation and
  gravity of the site.

**Smoothing.** λ minimises generalised cross-validation by default; a stated noise level
(``position_noise_m``, ``orientation_noise_rad``) selects the unbiased-risk λ instead; a cut-off
(``position_cutoff_hz``, ``orientation_cutoff_hz``) or a λ can be given outright. GCV assumes noise
that is white at the sampling rate; a reference that was filtered or resampled before it was
recorded (an optical track at 120 Hz resampled to an IMU's 286 Hz) has coloured noise that GCV takes
for motion, and wants a stated cut-off. :attr:`RecordedMotion.position_cutoff_hz` and
:attr:`orientation_cutoff_hz` report where the spline's gain falls to one half. Natural end
conditions hold the second derivative at zero at the first and last sample, so within about one
cut-off period of the ends the acceleration (and the angular acceleration) are pulled towards zero.

**Gaps.** Rows with NaN, dropped frames and uneven stamps are bridged by the spline (it is fitted on
the valid samples' own stamps). A step between valid samples longer than 1.5 times the median step
is a gap; :class:`GapReport` lists them. A gap longer than ``max_gap_s`` raises
:class:`RecordedMotionError` naming the source and the time. NaN rows before the first and after the
last valid sample only shorten the span.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .earth import Environment
from .smoothing_spline import (
    SmoothingSpline,
    choose_lambda,
    contiguous_runs,
    cutoff_hz,
    lambda_for_cutoff,
    smoothing_spline,
)
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = [
    "MIN_SAMPLES",
    "RecordedMotionError",
    "MotionSamples",
    "SmoothingOptions",
    "GapReport",
    "RecordedMotion",
]

MIN_SAMPLES = 8
"""Fewest valid samples a recorded motion may have."""

_UNIT_TOLERANCE = 1e-3
"""Largest |‖q‖ − 1| a recorded quaternion may have (a file's rounding to 6 digits is 1e-6)."""


class RecordedMotionError(ValueError):
    """A recorded motion that cannot become a truth; the message names the source and the time or row,
    and ``key`` the smoothing option at fault, when one is (``max_gap_s``, a cut-off)."""

    def __init__(self, message: str, *, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True, eq=False)
class MotionSamples:
    """A recorded motion as sampled, before smoothing.

    Attributes
    ----------
    t : ndarray (N,)
        Stamps, s, from ``origin_s``, strictly increasing (the motion's time starts at the first valid one).
    q_wb : ndarray (N, 4)
        Attitude (w, x, y, z), body to world ENU; NaN rows where tracking was lost.
    pos_w : ndarray (N, 3) or None
        Position of the body's reference point, world ENU, m; NaN rows where lost; None: not recorded
        (the body is held at the origin).
    source : str
        Where the samples came from (a file's name), for messages.
    lines : ndarray (N,) int or None
        The text file's line of each sample, for messages (None: messages name rows from 0).
    origin_s : float
        The recording's clock at ``t = 0``, s: sample ``k`` was stamped ``origin_s + t[k]``. Readers of
        epoch stamps (1.7·10⁹ s, where a double resolves 0.24 µs) keep the whole seconds here, so that
        ``t`` holds the stamps' digits and their steps exactly.
    """

    t: NDArray[np.float64]
    q_wb: NDArray[np.float64]
    pos_w: NDArray[np.float64] | None = None
    source: str = "<samples>"
    lines: NDArray[np.integer[Any]] | None = None
    origin_s: float = 0.0

    def __post_init__(self) -> None:
        n = len(self.t)
        if np.shape(self.t) != (n,) or np.shape(self.q_wb) != (n, 4):
            raise RecordedMotionError(
                f"{self.source}: t must be (N,) and q_wb (N, 4), got {np.shape(self.t)} and {np.shape(self.q_wb)}"
            )
        if self.pos_w is not None and np.shape(self.pos_w) != (n, 3):
            raise RecordedMotionError(f"{self.source}: pos_w must be ({n}, 3), got {np.shape(self.pos_w)}")

    def __len__(self) -> int:
        return len(self.t)

    def valid(self) -> NDArray[np.bool_]:
        """Rows whose stamp, attitude and position (when recorded) are all finite, (N,) bool."""
        ok = np.isfinite(self.t) & np.isfinite(self.q_wb).all(axis=1)
        if self.pos_w is not None:
            ok &= np.isfinite(self.pos_w).all(axis=1)
        return ok

    def where(self, i: int) -> str:
        """``line L`` or ``row i`` of sample ``i``, for messages."""
        return f"line {int(self.lines[i])}" if self.lines is not None else f"row {i}"

    def check(self) -> None:
        """:class:`RecordedMotionError` naming the row for too few samples, non-monotonic stamps, and
        zero or non-unit quaternions."""
        if not np.all(np.isfinite(self.t)):
            i = int(np.flatnonzero(~np.isfinite(self.t))[0])
            raise RecordedMotionError(f"{self.source}: {self.where(i)}: the stamp is not a number")
        steps = np.diff(self.t)
        if np.any(steps <= 0):
            i = int(np.flatnonzero(steps <= 0)[0]) + 1
            stamp, before = (self.origin_s + float(self.t[j]) for j in (i, i - 1))
            raise RecordedMotionError(
                f"{self.source}: {self.where(i)}: stamp {stamp!r} s does not follow "
                f"{before!r} s (stamps must increase strictly)"
            )
        norm = np.linalg.norm(self.q_wb, axis=1)
        bad = np.isfinite(norm) & (np.abs(norm - 1.0) > _UNIT_TOLERANCE)
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            what = "all zero" if norm[i] == 0 else f"of norm {norm[i]:.6g}"
            raise RecordedMotionError(
                f"{self.source}: {self.where(i)}: the quaternion is {what}, not a unit quaternion "
                f"(tolerance {_UNIT_TOLERANCE:g})"
            )
        valid = int(self.valid().sum())
        if valid < MIN_SAMPLES:
            raise RecordedMotionError(
                f"{self.source}: {valid} valid samples (of {len(self)}); a recorded motion needs at least {MIN_SAMPLES}"
            )


@dataclass(frozen=True)
class SmoothingOptions:
    """How a recorded motion is smoothed (the ``[smoothing]`` table of a ``recorded`` scenario).

    Attributes
    ----------
    position_noise_m, orientation_noise_rad : float or None
        The recording's noise (standard deviation per coordinate; per axis of the attitude error); None:
        choose λ by generalised cross-validation.
    position_cutoff_hz, orientation_cutoff_hz : float or None
        The frequency where the spline's gain is 1/2 (:func:`~gyroemu.dynamics.smoothing_spline.lambda_for_cutoff`
        at the median step); overrides the noise level.
    position_lambda, orientation_lambda : float or None
        λ outright (s³; the orientation's on quaternion components); overrides the rest.
    max_gap_s : float
        Longest gap bridged, s.
    """

    position_noise_m: float | None = None
    orientation_noise_rad: float | None = None
    position_lambda: float | None = None
    orientation_lambda: float | None = None
    max_gap_s: float = 0.25
    position_cutoff_hz: float | None = None
    orientation_cutoff_hz: float | None = None


@dataclass(frozen=True)
class GapReport:
    """What smoothing bridged.

    Attributes
    ----------
    invalid_rows : int
        Rows dropped for NaN (inside the span and at its ends).
    gaps : tuple of (float, float)
        ``(start_s, length_s)`` of each gap, motion time (from the first valid sample).
    median_step_s : float
        The recording's median sample step, s.
    """

    invalid_rows: int
    gaps: tuple[tuple[float, float], ...]
    median_step_s: float

    @property
    def longest_s(self) -> float:
        """The longest gap, s (0 when there is none)."""
        return max((length for _, length in self.gaps), default=0.0)

    def __str__(self) -> str:
        if not self.gaps:
            return f"no gaps; {self.invalid_rows} rows without values dropped"
        start, length = max(self.gaps, key=lambda g: g[1])
        return (
            f"{len(self.gaps)} gap(s) bridged, the longest {length:.4g} s at t = {start:.6g} s; "
            f"{self.invalid_rows} rows without values dropped"
        )


class RecordedMotion:
    """Smoothing splines through a recorded motion (see the module's notes).

    Parameters
    ----------
    samples : MotionSamples
    options : SmoothingOptions

    Attributes
    ----------
    t0 : float
        The stamp of the first valid sample, in the samples' clock: motion time 0.
    duration : float
        From the first to the last valid sample, s.
    rate_hz : float
        The median sample rate, Hz.
    gaps : GapReport
    position_lambda, orientation_lambda : float
        The λ used (s³); position's is nan without a position.
    has_position : bool

    Raises
    ------
    RecordedMotionError
        For the problems :meth:`MotionSamples.check` finds and a gap longer than ``options.max_gap_s``.
    """

    def __init__(self, samples: MotionSamples, options: SmoothingOptions | None = None):
        options = options or SmoothingOptions()
        samples.check()
        valid = samples.valid()
        rows = np.flatnonzero(valid)
        t = samples.t[rows]
        self.source = samples.source
        self.t0 = samples.origin_s + float(t[0])
        tm = t - t[0]
        steps = np.diff(tm)
        median = float(np.median(steps))
        runs = contiguous_runs(tm)
        gaps = tuple((float(tm[r.start - 1]), float(tm[r.start] - tm[r.start - 1])) for r in runs[1:])
        self.gaps = GapReport(invalid_rows=int(len(samples) - len(rows)), gaps=gaps, median_step_s=median)
        for start, length in gaps:
            if length > options.max_gap_s:
                raise RecordedMotionError(
                    f"{samples.source}: a gap of {length:.4g} s without valid samples after t = {start:.6g} s "
                    f"(stamp {float(start + self.t0)!r} s) is longer than max_gap_s = {options.max_gap_s:g} s",
                    key="max_gap_s",
                )
        self.duration = float(tm[-1])
        self.rate_hz = 1.0 / median
        self.t_knots = tm

        q = np.array(samples.q_wb[rows], dtype=float)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        # q and −q are one attitude: choose signs so that neighbours lie on the same side.
        flips = np.cumsum(np.einsum("ij,ij->i", q[1:], q[:-1]) < 0) % 2
        q[1:][flips == 1] *= -1.0
        # A small turn δ (rad, per axis: variance σ² about each of three axes) moves the quaternion by
        # ½ δ within the three directions at right angles to q: 3σ²/4 in all, spread over its four
        # components, which the unbiased risk counts alike: σ √3 / 4 each.
        self.orientation_lambda = self._lambda(
            tm,
            q,
            options.orientation_lambda,
            options.orientation_cutoff_hz,
            options.orientation_noise_rad,
            "orientation_cutoff_hz",
            scale=math.sqrt(3.0) / 4.0,
        )
        self._q: SmoothingSpline = smoothing_spline(tm, q, self.orientation_lambda)
        self.has_position = samples.pos_w is not None
        self._p: SmoothingSpline | None = None
        self.position_lambda = float("nan")
        if samples.pos_w is not None:
            p = np.asarray(samples.pos_w[rows], dtype=float)
            self.position_lambda = self._lambda(
                tm,
                p,
                options.position_lambda,
                options.position_cutoff_hz,
                options.position_noise_m,
                "position_cutoff_hz",
            )
            self._p = smoothing_spline(tm, p, self.position_lambda)

    def _lambda(
        self,
        t: NDArray[np.float64],
        y: NDArray[np.float64],
        lam: float | None,
        cutoff: float | None,
        noise: float | None,
        cutoff_key: str,
        scale: float = 1.0,
    ) -> float:
        if lam is not None:
            return float(lam)
        if cutoff is not None:
            try:
                return lambda_for_cutoff(cutoff, self.gaps.median_step_s)
            except ValueError as e:
                raise RecordedMotionError(f"{self.source}: {e}", key=cutoff_key) from None
        return choose_lambda(t, y, None if noise is None else noise * scale)

    @property
    def position_cutoff_hz(self) -> float:
        """Where the position spline's gain is 1/2, Hz (nan without a position)."""
        return cutoff_hz(self.position_lambda, 1.0 / self.rate_hz) if self.has_position else float("nan")

    @property
    def orientation_cutoff_hz(self) -> float:
        """Where the attitude spline's gain is 1/2, Hz."""
        return cutoff_hz(self.orientation_lambda, 1.0 / self.rate_hz)

    def _times(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        span = self.duration
        if t.size and (t.min() < -1e-9 * span or t.max() > span * (1 + 1e-12) + 1e-12):
            raise RecordedMotionError(
                f"{self.source}: times {t.min():.6g}..{t.max():.6g} s leave the recording's span 0..{span:.6g} s"
            )
        clipped: NDArray[np.float64] = np.clip(t, 0.0, span)
        return clipped

    def attitude(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``q_wb`` (M, 4), ``ω_wb`` and ``α_wb`` (M, 3, body axes, relative to the world) at times ``t``
        (M,), s from the first valid sample."""
        t = self._times(t)
        s, ds, dds = self._q(t), self._q(t, 1), self._q(t, 2)
        n2 = np.einsum("ij,ij->i", s, s)[:, None]
        u = _vec_conj_product(s, ds)  # vec(s̄ ⊗ ṡ)
        du = _vec_conj_product(s, dds)  # d/dt vec(s̄ ⊗ ṡ) = vec(s̄ ⊗ s̈)
        omega = 2.0 * u / n2
        alpha = 2.0 * du / n2 - omega * (2.0 * np.einsum("ij,ij->i", s, ds)[:, None]) / n2
        return s / np.sqrt(n2), omega, alpha

    def position(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``p_w``, ``v_w``, ``a_w`` (M, 3; m, m/s, m/s²) at times ``t`` (M,); zeros without a position."""
        t = self._times(t)
        if self._p is None:
            zero = np.zeros((len(t), 3))
            return zero, zero.copy(), zero.copy()
        return self._p(t), self._p(t, 1), self._p(t, 2)

    def trajectory(self, t: ArrayLike, environment: Environment) -> Trajectory:
        """The truth at times ``t`` (M,), s from the first valid sample, in ``environment``."""
        t = self._times(t)
        q, omega, alpha = self.attitude(t)
        p, v, a = self.position(t)
        return trajectory_from_world_motion(t, q, omega, alpha, p, v, a, environment)


def _vec_conj_product(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Vector part of ``ā ⊗ b`` for (M, 4) quaternion arrays (w, x, y, z): ``a_w b_v − b_w a_v − a_v × b_v``."""
    return a[:, :1] * b[:, 1:] - b[:, :1] * a[:, 1:] - np.cross(a[:, 1:], b[:, 1:])
