"""The magnetic field a recording moved through, in the world frame, from a calibrated magnetometer.

    m_w(t) = R_wb(t − d) K⁻¹ (m_m(t) − h)            (d the magnetometer's latency; K, h its calibration)

From m_w over the samples:

- **norm** |m_w| and **dip** I = atan2(−U, √(E² + N²)) (positive down, as in the northern hemisphere),
  and the **heading** of the horizontal field ψ = atan2(E, N) (from north towards east, in the truth's
  world frame);
- the **spread** along the path: per-axis standard deviation of m_w over the movement samples
  (``raw_sigma``), and the part of it that is a function of **position** (``axis_sigma``,
  ``spatial_sigma`` = √(mean of the three variances)). With the attitude and a position track, m_w's
  deviation is fitted by least squares on the attitude (the nine elements of R_bw: what a
  magnetometer's calibration residual makes, since it turns with the sensor) and on a quadratic in
  position (the field's variation over the working volume); the spatial variance per axis is what
  the position terms explain beyond the attitude terms, ``var(r_att) − var(r_att+pos)``. On BROAD's
  undisturbed trials the attitude terms explain most of the spread (0.43–1.29 µT per axis down to
  0.23–0.48 µT) and position 0.06–0.28 µT more: a random field of the raw spread is far stronger than
  what the filters meet (README, "The twin"). Variation on scales shorter than the quadratic resolves
  is not separated from the noise, and where attitude and position go together along the path the
  attitude terms take their shared part: the split errs towards a calmer field;
- the **correlation length**: ρ(r) = ⟨δm(x)·δm(x′)⟩ / ⟨|δm|²⟩ over pairs of movement samples binned by
  their distance r = |x − x′| (δm = the position-explained part when it was fitted, else m_w − its
  mean), and the first r where ρ falls below 1/e. Without a position track the same over time lags
  gives a correlation time instead;
- the **heading offset** between the field at rest (the first rest phase) and in the working volume
  (movement samples): circular mean of ψ(t) − ψ_rest. :func:`pool_heading_offsets` turns several
  trials' offsets into a mean and a standard deviation;
- the **recordings that disagree**: one site has one field, so several recordings' fields at rest agree
  within what the field does along a path (the spread, ``raw_sigma``: the site's variation and the
  magnetometer's calibration residual). :func:`discordant_fields` names a recording whose rest field
  lies more than three of those spreads from the median of the others' (``FIELD_AGREEMENT``), with
  three recordings or more (of two, neither is the odd one): recorded elsewhere, or with iron near
  its rest. On BROAD's undisturbed trials 02, 07 and 11 lie 0.8–1.1 µT from the others (spreads
  0.8–1.0 µT); 16 lies 7.0 µT from them (spread 1.6 µT: 37.9 µT against 43.3–43.9 µT).

Without motion there is no path: when the movement samples never leave one position (or, without a
position track, never change attitude), as in a static log, the spread would be the sensor's noise
and the correlation 0/0, so the environment is not identified (a ValueError saying so, which
``identify`` turns into a note). A field that is the same all along a real path has spread 0 and
never decorrelates: its correlation length and time are ``inf``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .truth import interpolate_attitude, moving_average, rotation_bw

__all__ = [
    "FIELD_AGREEMENT",
    "DiscordantField",
    "MagneticEnvironment",
    "world_field",
    "magnetic_environment",
    "pool_heading_offsets",
    "discordant_fields",
]

_PAIR_POINTS = 2000  # points of the correlation's pair sums (N² pairs)
FIELD_AGREEMENT = 3.0
"""How many of its spreads along the path a recording's rest field may lie from the others' (module notes)."""


def world_field(
    t: NDArray[np.float64],
    mag_body: NDArray[np.float64],
    truth_t: NDArray[np.float64],
    q_wb: NDArray[np.float64],
    latency_s: float = 0.0,
) -> NDArray[np.float64]:
    """(N, 3) world-axes field of calibrated body-axes measurements ``mag_body`` (N, 3) at ``t`` (N,),
    turned by the truth attitude at t − ``latency_s``; NaN where the truth is unknown."""
    q = interpolate_attitude(truth_t, q_wb, np.asarray(t, dtype=float) - latency_s)
    # R_wb = R_bwᵀ
    field: NDArray[np.float64] = np.einsum("nji,nj->ni", rotation_bw(q), np.asarray(mag_body, dtype=float))
    return field


def _heading(m: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.arctan2(m[..., 0], m[..., 1])


@dataclass(frozen=True)
class MagneticEnvironment:
    """One recording's magnetic environment (tesla, rad, m, s).

    Attributes
    ----------
    rest_field_w : (3,) mean world field over the first rest phase (E, N, U).
    norm, dip, heading : of ``rest_field_w``: |m|, inclination (positive down), heading from north.
    axis_sigma : (3,) standard deviation of the position-explained part of m_w, per world axis (the raw
        spread without an attitude and a position track).
    spatial_sigma : √(mean of the three variances).
    raw_sigma : (3,) standard deviation of m_w over the movement samples, per world axis.
    heading_offset, heading_offset_sigma : circular mean and standard deviation of ψ(t) − ψ_rest over the
        movement samples, rad.
    correlation_length_m : first distance where the correlation falls below 1/e (None without a
        position track; ``inf`` when it never does within half the largest distance).
    correlation_time_s : the same over time lags.
    samples : movement samples used.
    """

    rest_field_w: NDArray[np.float64]
    norm: float
    dip: float
    heading: float
    axis_sigma: NDArray[np.float64]
    spatial_sigma: float
    heading_offset: float
    heading_offset_sigma: float
    correlation_length_m: float | None
    correlation_time_s: float
    samples: int
    raw_sigma: NDArray[np.float64] | None = None


def _spatial_part(
    delta: NDArray[np.float64], pos: NDArray[np.float64], r_bw: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The position-explained part of ``delta`` (N, 3) beyond the attitude's (module notes), and its
    per-axis standard deviation ``sqrt(var(r_att) − var(r_att+pos))``."""
    p = pos - pos.mean(axis=0)
    quadratic = np.column_stack([p, p**2, p[:, [0]] * p[:, [1]], p[:, [0]] * p[:, [2]], p[:, [1]] * p[:, [2]]])
    attitude = np.column_stack([r_bw.reshape(len(r_bw), 9), np.ones(len(r_bw))])
    c_att, *_ = np.linalg.lstsq(attitude, delta, rcond=None)
    r_att = delta - attitude @ c_att
    both = np.column_stack([attitude, quadratic])
    c_both, *_ = np.linalg.lstsq(both, delta, rcond=None)
    r_both = delta - both @ c_both
    spatial = quadratic @ c_both[attitude.shape[1] :]
    sigma = np.sqrt(np.clip(r_att.var(axis=0) - r_both.var(axis=0), 0.0, None))
    return spatial - spatial.mean(axis=0), sigma


def _e_folding_separation(separation: NDArray[np.float64], products: NDArray[np.float64], bins: int) -> float:
    """The separation (a distance or a lag) where the correlation ``products`` (n, n), binned by their
    pair ``separation`` (n, n) over half its range, first falls below 1/e."""
    edges = np.linspace(0.0, separation.max() / 2, bins + 1)
    which = np.digitize(separation.ravel(), edges) - 1
    inside = (which >= 0) & (which < bins)
    sums = np.bincount(which[inside], weights=products.ravel()[inside], minlength=bins)
    counts = np.bincount(which[inside], minlength=bins)
    have = counts > 0
    return _first_below(0.5 * (edges[:-1] + edges[1:])[have], sums[have] / counts[have], np.exp(-1.0))


def _first_below(x: NDArray[np.float64], rho: NDArray[np.float64], level: float) -> float:
    """First x where rho (sampled at x) falls below level, linearly interpolated; inf if never."""
    below = np.flatnonzero(rho < level)
    if not len(below):
        return float("inf")
    j = below[0]
    if j == 0:
        return float(x[0])
    return float(x[j - 1] + (x[j] - x[j - 1]) * (rho[j - 1] - level) / (rho[j - 1] - rho[j]))


def _require_motion(samples: int, pos: NDArray[np.float64] | None, r_bw: NDArray[np.float64] | None) -> None:
    """ValueError when the movement samples show no path (module notes): a position track that never
    leaves one point, or without one an attitude that never changes."""
    if pos is not None and not np.ptp(pos, axis=0).any():
        raise ValueError(
            f"no motion: the {samples} movement samples never leave one position (a static log?), so the "
            "field's variation along a path is not observable"
        )
    if pos is None and r_bw is not None and not np.ptp(r_bw.reshape(len(r_bw), 9), axis=0).any():
        raise ValueError(
            f"no motion: the {samples} movement samples keep one attitude and there is no position track "
            "(a static log?), so the field's variation along a path is not observable"
        )


def magnetic_environment(
    t: NDArray[np.float64],
    field_w: NDArray[np.float64],
    rest: slice,
    movement: NDArray[np.bool_],
    pos_w: NDArray[np.float64] | None = None,
    bins: int = 25,
    smooth_s: float = 0.25,
    r_bw: NDArray[np.float64] | None = None,
) -> MagneticEnvironment:
    """The environment (module notes) of a world field ``field_w`` (N, 3) tesla at ``t`` (N,) s.

    ``rest``: the samples of the first rest phase; ``movement`` (N,) bool: the working-volume samples;
    ``pos_w`` (N, 3) m at the same samples, or None; ``r_bw`` (N, 3, 3) the attitude R_bw the field was
    turned with, or None. The field is first averaged over ``smooth_s`` so that the sensor's white noise
    does not pass for a spatial variation.
    """
    dt = float(np.median(np.diff(t)))
    field_w = moving_average(np.asarray(field_w, dtype=float), max(1, int(round(smooth_s / dt))))
    movement = np.asarray(movement, dtype=bool) & np.all(np.isfinite(field_w), axis=1)
    if pos_w is not None:
        movement &= np.all(np.isfinite(pos_w), axis=1)
    if r_bw is not None:
        movement &= np.all(np.isfinite(np.asarray(r_bw).reshape(len(t), 9)), axis=1)
    rest_field = np.nanmean(field_w[rest], axis=0)  # smoothing does not change a mean
    m = field_w[movement]
    if len(m) < 10:
        raise ValueError(f"only {len(m)} movement samples with a known field")
    _require_motion(
        len(m),
        None if pos_w is None else np.asarray(pos_w, dtype=float)[movement],
        None if r_bw is None else np.asarray(r_bw, dtype=float)[movement],
    )
    horizontal = np.hypot(rest_field[0], rest_field[1])
    delta = m - m.mean(axis=0)
    raw_sigma = delta.std(axis=0)
    axis_sigma = raw_sigma
    if pos_w is not None and r_bw is not None:
        delta, axis_sigma = _spatial_part(delta, np.asarray(pos_w)[movement], np.asarray(r_bw)[movement])
    offsets = np.angle(np.exp(1j * (_heading(m) - _heading(rest_field))))
    mean_vec = np.mean(np.exp(1j * offsets))
    circ_sigma = float(np.sqrt(max(0.0, -2.0 * np.log(min(abs(mean_vec), 1.0)))))  # 0, not −0, for none

    idx = np.linspace(0, len(m) - 1, min(_PAIR_POINTS, len(m))).astype(int)  # evenly along the path
    d = delta[idx]
    var = float(np.mean(np.sum(d * d, axis=1)))
    length = None
    lag_t = np.asarray(t, dtype=float)[movement][idx]
    if var > 0:
        products = d @ d.T / var
        if pos_w is not None:
            x = np.asarray(pos_w, dtype=float)[movement][idx]
            length = _e_folding_separation(np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1), products, bins)
        corr_time = _e_folding_separation(np.abs(lag_t[:, None] - lag_t[None, :]), products, bins)
    else:  # the field is the same all along the path: nothing decorrelates (and its spread is 0)
        length = None if pos_w is None else float("inf")
        corr_time = float("inf")
    return MagneticEnvironment(
        rest_field_w=rest_field,
        norm=float(np.linalg.norm(rest_field)),
        dip=float(np.arctan2(-rest_field[2], horizontal)),
        heading=float(_heading(rest_field)),
        axis_sigma=axis_sigma,
        spatial_sigma=float(np.sqrt(np.mean(axis_sigma**2))),
        heading_offset=float(np.angle(mean_vec)),
        heading_offset_sigma=circ_sigma,
        correlation_length_m=length,
        correlation_time_s=corr_time,
        samples=int(len(m)),
        raw_sigma=raw_sigma,
    )


def pool_heading_offsets(environments: Sequence[MagneticEnvironment]) -> tuple[float, float]:
    """(mean, standard deviation) of the trials' heading offsets, rad: circular mean and, for two or more
    trials, their sample standard deviation (one trial: its own within-trial spread)."""
    offsets = np.array([e.heading_offset for e in environments])
    mean = float(np.angle(np.mean(np.exp(1j * offsets))))
    if len(offsets) < 2:
        return mean, float(environments[0].heading_offset_sigma)
    wrapped = np.angle(np.exp(1j * (offsets - mean)))
    return mean, float(np.std(wrapped, ddof=1))


@dataclass(frozen=True)
class DiscordantField:
    """A recording whose field at rest disagrees with the others' (:func:`discordant_fields`).

    index : its place in the sequence given; distance : |its rest field − the others' median|, T;
    allowed : :data:`FIELD_AGREEMENT` times the larger of its spread and the others' median spread, T.
    """

    index: int
    distance: float
    allowed: float


def discordant_fields(environments: Sequence[MagneticEnvironment]) -> list[DiscordantField]:
    """The recordings whose rest field lies further from the median (per axis) of the others' than
    :data:`FIELD_AGREEMENT` times the field's spread along the paths, |``raw_sigma``| (``axis_sigma``
    where it is not known), the larger of the recording's own and the others' median (module notes);
    none for fewer than three recordings."""
    if len(environments) < 3:
        return []
    fields = np.array([e.rest_field_w for e in environments])
    spreads = np.array(
        [float(np.linalg.norm(e.raw_sigma if e.raw_sigma is not None else e.axis_sigma)) for e in environments]
    )
    out = []
    for i in range(len(environments)):
        others = np.delete(np.arange(len(environments)), i)
        distance = float(np.linalg.norm(fields[i] - np.median(fields[others], axis=0)))
        allowed = FIELD_AGREEMENT * max(spreads[i], float(np.median(spreads[others])))
        if distance > allowed:
            out.append(DiscordantField(i, distance, allowed))
    return out
