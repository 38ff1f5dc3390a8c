"""The accelerometer's offset against the truth while the device is carried, relative to at rest.

A device lying still and the same device carried through the working volume need not read gravity
alike against the truth: the housing is gripped (package stress moves a MEMS offset), or the sensor
sits differently in its holder under the hand's forces than on the table, which turns the sensor
against the truth's markers. Either way the accelerometer's residual against the truth,

    d = f_m − C R_bw (a_w + g e_z)      (C: the gyro's mounting, sensor ← body; a_w from the position)

has one mean in the rest phases and another in the movement. A filter is scored in the movement, so
the step between them is what it sees: a tilt of Δd_y / g about x and −Δd_x / g about y (rad).

:func:`handling_offset` measures Δ = mean_movement(d) − mean_rest(d) over non-overlapping windows of
``window_s`` (window means, as :mod:`.calibration` uses), on both sides only where the truth turns
slower than ``max_rate_rad_s``: the centripetal force at the sensor's lever arm r from the truth's
reference point, ω²r, stays below 2.5 mm/s² at 0.5 rad/s and r = 1 cm (BROAD's sensor sits about
8 mm from its markers' origin, :mod:`.lever_arm`), and the tangential α × r averages out over many windows.
Its uncertainty is the standard error of each side's mean over blocks of ``block_s`` (windows within
a second of each other share the motion's errors, so the window scatter alone is optimistic).
Across recordings of one device the offsets are pooled as a distribution (mean and standard deviation
between recordings): each handling of the device is one draw.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .calibration import paired_windows, truth_specific_force_body, window_means
from .truth import interpolate_vectors, truth_angular_velocity

__all__ = ["HandlingOffset", "handling_offset", "pool_handling_offsets"]

_G0 = 9.80665  # m/s², standard gravity: only to express an offset as a tilt


@dataclass(frozen=True)
class HandlingOffset:
    """One recording's accelerometer offset, movement minus rest (sensor axes).

    Attributes
    ----------
    offset, offset_sigma : (3,) m/s², Δ and its standard uncertainty.
    rest_mean, movement_mean : (3,) m/s², each side's mean residual d.
    rest_windows, movement_windows : windows used on each side.
    """

    offset: NDArray[np.float64]
    offset_sigma: NDArray[np.float64]
    rest_mean: NDArray[np.float64]
    movement_mean: NDArray[np.float64]
    rest_windows: int
    movement_windows: int

    @property
    def tilt_deg(self) -> NDArray[np.float64]:
        """(2,) the step as a tilt of the sensor about its x and y axes, degrees (small angles)."""
        return np.degrees(np.array([self.offset[1], -self.offset[0]]) / _G0)


def _block_mean(d: NDArray[np.float64], block: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean of ``d`` (k, 3) and its standard error over consecutive blocks of ``block`` rows."""
    k = len(d)
    n = max(1, k // block)
    if n < 2:
        return d.mean(axis=0), np.full(3, np.inf)
    means = d[: n * block].reshape(n, block, 3).mean(axis=1)
    return d.mean(axis=0), means.std(axis=0, ddof=1) / np.sqrt(n)


def handling_offset(
    t: NDArray[np.float64],
    accel: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float,
    rest: NDArray[np.bool_],
    movement: NDArray[np.bool_],
    *,
    pos_w: NDArray[np.float64] | None = None,
    gravity_m_s2: float = 9.81,
    c_sb: NDArray[np.float64] | None = None,
    window_s: float = 0.1,
    block_s: float = 2.0,
    max_rate_rad_s: float = 0.5,
    min_windows: int = 20,
) -> HandlingOffset:
    """Δ of the module notes. ``accel`` (N, 3) m/s² at ``t`` (N,) s; truth ``q_wb`` (M, 4) and
    ``pos_w`` (M, 3) m at ``truth_t``; ``rest`` and ``movement`` (N,) bool; ``c_sb`` (3, 3) body →
    sensor (None: identity). Raises ``ValueError`` when a side has fewer than ``min_windows`` windows."""
    times = np.asarray(t, dtype=float) - latency_s
    c = np.eye(3) if c_sb is None else np.asarray(c_sb, dtype=float)
    force_b = truth_specific_force_body(t, truth_t, q_wb, latency_s, pos_w, gravity_m_s2)
    force_s = np.einsum("ij,nj->ni", c, force_b)
    omega = interpolate_vectors(truth_t, truth_angular_velocity(truth_t, q_wb), times)
    sides = []
    for name, mask in (("rest", rest), ("movement", movement)):
        w_true, w_meas, length = paired_windows(t, force_s, accel, np.asarray(mask, dtype=bool), window_s)
        rate = np.linalg.norm(np.nan_to_num(window_means(omega, length), nan=np.inf), axis=1)
        ok = np.all(np.isfinite(w_true), axis=1) & np.all(np.isfinite(w_meas), axis=1) & (rate < max_rate_rad_s)
        if ok.sum() < min_windows:
            raise ValueError(f"only {int(ok.sum())} usable {name} windows for the handling offset")
        block = max(1, int(round(block_s / window_s)))
        mean, sem = _block_mean((w_meas - w_true)[ok], block)
        sides.append((mean, sem, int(ok.sum())))
    (m_r, s_r, n_r), (m_m, s_m, n_m) = sides
    return HandlingOffset(
        offset=m_m - m_r,
        offset_sigma=np.hypot(s_r, s_m),
        rest_mean=m_r,
        movement_mean=m_m,
        rest_windows=n_r,
        movement_windows=n_m,
    )


def pool_handling_offsets(offsets: Sequence[HandlingOffset]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(mean, standard deviation) (3,) m/s² of the recordings' offsets: each handling is one draw
    (the standard deviation is 0 with one recording)."""
    x = np.array([o.offset for o in offsets], dtype=float)
    if not len(x):
        raise ValueError("no handling offsets to pool")
    return x.mean(axis=0), (x.std(axis=0, ddof=1) if len(x) > 1 else np.zeros(3))
