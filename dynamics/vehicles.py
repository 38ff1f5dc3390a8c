"""Vehicles: a smooth random manoeuvre and a car drive, both in closed form.

``random-manoeuvre``
    Roll, pitch, yaw and the three position coordinates are each a band-limited sum of sinusoids with
    random amplitudes, frequencies and phases drawn from ``numpy.random.default_rng(seed)``, so the
    attitude, ω, α, velocity and acceleration are analytic; the same seed gives bit-identical output.
``car``
    A car on a flat road: a speed profile of legs (speed up or brake to a speed, then hold it), turns
    laid out along the road as smooth curvature pulses (continuous curvature, like the clothoid
    transitions of real roads), body roll proportional to the lateral acceleration, pitch proportional
    to the longitudinal acceleration (dive and squat), and road bumps that excite heave and pitch
    transients of the suspension (damped oscillations with a smooth onset).

Both build the attitude from roll-pitch-yaw angles ``R_wb = Rz(ψ) Ry(θ) Rx(φ)`` (body x forward,
y left, z up; ENU world) with their first two derivatives, through :func:`euler_zyx_motion`.

The car's position is the integral of its velocity along a path whose heading ``ψ(s)`` is known in
closed form but whose integral ``∫ (cos ψ, sin ψ) ds`` through a turn is not elementary. Straight
stretches are integrated exactly; through each turn the integrand, an entire function of the path
distance, is interpolated by a Chebyshev series resolved to round-off and integrated term by term: the
position through a turn of length ``L`` is exact to a few ``1e-16 L`` (checked against adaptive
quadrature; see :class:`Road`), independent of the output grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Annotated, ClassVar, Literal

import numpy as np
from numpy.polynomial import Chebyshev
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, StrictInt, field_validator

from .config import AngleDeg, AnglesDeg, NonNegativeReal, PositiveReal, Real, Section, Vec3, at_most
from .jit import njit
from .motion_kernels import (
    SinesTable,
    TimeGrid,
    segment_index,
    sin_cos,
    sincos_block,
    sines_block,
    smooth_step,
    smooth_step_at,
)
from .prescribed import EarthBoundSpec, WorldMotion, motion_arrays

__all__ = [
    "euler_zyx_motion",
    "RotationBand",
    "TranslationBand",
    "RandomManoeuvreSpec",
    "Drive",
    "Leg",
    "Turn",
    "Bump",
    "Suspension",
    "SpeedProfile",
    "Road",
    "SuspensionTransient",
    "CarSpec",
    "CarMotion",
]


def euler_zyx_motion(
    rpy: ArrayLike, rpy_rates: ArrayLike, rpy_accels: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Attitude, body rate and body angular acceleration of a roll-pitch-yaw motion.

    The same equations as :func:`gyroemu.dynamics.rotation.quat_from_euler_zyx` and
    :func:`gyroemu.dynamics.rotation.body_rate_from_euler_zyx`, sharing six sines and cosines between them
    (the full angles' from the half angles' by the double-angle formulas), one compiled pass over the
    samples (:func:`_euler_zyx_sample`, which the kinds' kernels call as well).

    Parameters
    ----------
    rpy, rpy_rates, rpy_accels : array_like (3, N)
        Roll φ, pitch θ, yaw ψ (rad) with ``R = Rz(ψ) Ry(θ) Rx(φ)``, their rates (rad/s) and
        accelerations (rad/s²).

    Returns
    -------
    q_wb : ndarray (N, 4)
    omega_b : ndarray (N, 3)
        ``[φ̇ − ψ̇ sθ, θ̇ cφ + ψ̇ cθ sφ, −θ̇ sφ + ψ̇ cθ cφ]``, rad/s.
    alpha_b : ndarray (N, 3)
        Its time derivative, rad/s².
    """
    rpy, rates, accels = (np.asarray(x, dtype=float) for x in (rpy, rpy_rates, rpy_accels))
    n = rpy.shape[1]
    q, omega, alpha = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    _euler_zyx_kernel(rpy, rates, accels, q, omega, alpha)
    return q, omega, alpha


@njit
def _euler_zyx_kernel(
    rpy: NDArray[np.float64],
    rpy_rates: NDArray[np.float64],
    rpy_accels: NDArray[np.float64],
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:func:`euler_zyx_motion`, one sample at a time, written into ``q``, ``omega``, ``alpha``."""
    for i in range(rpy.shape[1]):
        _euler_zyx_sample(
            np.cos(0.5 * rpy[0, i]),
            np.sin(0.5 * rpy[0, i]),
            np.cos(0.5 * rpy[1, i]),
            np.sin(0.5 * rpy[1, i]),
            np.cos(0.5 * rpy[2, i]),
            np.sin(0.5 * rpy[2, i]),
            rpy_rates[0, i],
            rpy_rates[1, i],
            rpy_rates[2, i],
            rpy_accels[0, i],
            rpy_accels[1, i],
            rpy_accels[2, i],
            q[i],
            omega[i],
            alpha[i],
        )


@njit
def _euler_zyx_sample(
    cr: float,
    sr: float,
    cp: float,
    sp: float,
    cy: float,
    sy: float,
    droll: float,
    dpitch: float,
    dyaw: float,
    ddroll: float,
    ddpitch: float,
    ddyaw: float,
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """One sample of :func:`euler_zyx_motion` from the cosines and sines of the half angles
    ``φ/2, θ/2, ψ/2`` and the angles' rates and accelerations, into ``q`` (4,), ``omega``, ``alpha`` (3,)."""
    # q = q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ), written out in the half-angle cosines and sines.
    cycp, sysp, cysp, sycp = cy * cp, sy * sp, cy * sp, sy * cp
    q[0] = cycp * cr + sysp * sr
    q[1] = cycp * sr - sysp * cr
    q[2] = cysp * cr + sycp * sr
    q[3] = sycp * cr - cysp * sr
    # Full angles: sin x = 2 sin(x/2) cos(x/2), cos x = cos²(x/2) − sin²(x/2).
    s_r, c_r = 2 * sr * cr, cr * cr - sr * sr
    s_p, c_p = 2 * sp * cp, cp * cp - sp * sp
    yaw_cp = dyaw * c_p  # ψ̇ cθ
    omega[0] = droll - dyaw * s_p
    omega[1] = dpitch * c_r + yaw_cp * s_r
    omega[2] = yaw_cp * c_r - dpitch * s_r
    # α: differentiate ω; d(cθ)/dt = −θ̇ sθ, d(sφ)/dt = φ̇ cφ, ...
    lateral = ddyaw * c_p - dyaw * dpitch * s_p  # d/dt (ψ̇ cθ)
    alpha[0] = ddroll - ddyaw * s_p - dyaw * dpitch * c_p
    alpha[1] = (ddpitch * c_r - dpitch * droll * s_r) + lateral * s_r + yaw_cp * droll * c_r
    alpha[2] = (-ddpitch * s_r - dpitch * droll * c_r) + lateral * c_r - yaw_cp * droll * s_r


# --------------------------------------------------------------------------------------------------
# random-manoeuvre
# --------------------------------------------------------------------------------------------------


MAX_SINE_TERMS = 1000
"""The most ``terms`` a ``[rotation]`` or ``[translation]`` band takes. A sum of that many sines of random
phase is already Gaussian band-limited motion to the eye of any filter (its amplitude distribution
converges as 1/sqrt(terms)); every term costs every sample three channels' work and its offset tables
(3 x 1024 x 16 bytes), so a million terms would take gigabytes and minutes for nothing more."""


_at_most_terms = at_most(MAX_SINE_TERMS, "more random-phase sines make the motion no more random, only slower")


def _band(value: tuple[float, float]) -> tuple[float, float]:
    low, high = value
    if not 0 < low <= high:
        raise ValueError(f"a frequency band is [low, high] with 0 < low <= high, got [{low}, {high}]")
    return value


def _non_negative(value: Vec3) -> Vec3:
    if any(v < 0 for v in value):
        raise ValueError(f"amplitudes must be >= 0, got {list(value)}")
    return value


class RotationBand(Section):
    """``[rotation]``: roll, pitch and yaw, each ``mean + Σ_k A_k sin(2π f_k t + φ_k)`` with ``terms``
    terms.

    ``amplitude_deg`` bounds each angle's excursion from its mean (the ``A_k`` of an angle add up to it);
    frequencies are drawn uniformly in ``frequency_hz = [low, high]``.
    """

    mean_rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)
    amplitude_deg: Vec3 = (20.0, 10.0, 90.0)
    frequency_hz: tuple[PositiveReal, PositiveReal] = (0.02, 0.5)
    terms: Annotated[StrictInt, Field(ge=1), _at_most_terms] = 6

    _band = field_validator("frequency_hz")(_band)
    _amplitudes = field_validator("amplitude_deg")(_non_negative)


class TranslationBand(Section):
    """``[translation]``: east, north and up position, each ``Σ_k A_k sin(2π f_k t + φ_k)`` (about the
    origin).

    ``amplitude_m`` bounds each coordinate's excursion (the ``A_k`` add up to it).
    """

    amplitude_m: Vec3 = (50.0, 50.0, 5.0)
    frequency_hz: tuple[PositiveReal, PositiveReal] = (0.005, 0.1)
    terms: Annotated[StrictInt, Field(ge=1), _at_most_terms] = 6

    _band = field_validator("frequency_hz")(_band)
    _amplitudes = field_validator("amplitude_m")(_non_negative)


def _draw_sines(
    rng: np.random.Generator, bounds: Sequence[float] | NDArray[np.float64], band: tuple[float, float], terms: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Amplitudes (C, K) summing to ``bounds`` per channel, angular frequencies uniform in the band,
    phases uniform in [0, 2π): drawn in this order, all amplitudes first."""
    u = rng.random((len(bounds), terms))
    amplitude = np.asarray(bounds, dtype=float)[:, None] * u / u.sum(axis=1, keepdims=True)
    omega = 2 * np.pi * rng.uniform(band[0], band[1], size=u.shape)
    phase = rng.uniform(0.0, 2 * np.pi, size=u.shape)
    return amplitude, omega, phase


class RandomManoeuvreSpec(EarthBoundSpec):
    """``kind = "random-manoeuvre"``: a smooth random manoeuvre, reproducible from ``seed``.

    ``rng = numpy.random.default_rng(seed)`` draws, in this order, the rotation terms then the
    translation terms (:func:`_draw_sines`). The angles and coordinates and their derivatives are exact
    sums of sinusoids; ``q_wb``, ``ω_wb``, ``α_wb`` follow from :func:`euler_zyx_motion`.
    """

    kind: Literal["random-manoeuvre"] = "random-manoeuvre"
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    seed: Annotated[StrictInt, Field(ge=0)] = 0
    rotation: RotationBand = Field(default_factory=RotationBand)
    translation: TranslationBand = Field(default_factory=TranslationBand)

    def sines(
        self,
    ) -> tuple[
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ]:
        """The drawn terms: ``(rotation, translation)``, each ``(amplitude, omega, phase)`` arrays (3, K)
        in rad or m, rad/s, rad."""
        rng = np.random.default_rng(self.seed)
        rot, tr = self.rotation, self.translation
        return (
            _draw_sines(rng, np.radians(rot.amplitude_deg), rot.frequency_hz, rot.terms),
            _draw_sines(rng, tr.amplitude_m, tr.frequency_hz, tr.terms),
        )

    def world_motion(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        grid = TimeGrid(t)
        rotation, translation = self.sines()
        arrays = motion_arrays(len(t), moves=True)
        _manoeuvre_kernel(
            t,
            grid.uniform,
            grid.BLOCK,
            grid.sines(*rotation),
            np.radians(self.rotation.mean_rpy_deg),
            grid.sines(*translation),
            *arrays,
        )
        return WorldMotion(t, *arrays)


@njit
def _manoeuvre_kernel(
    t: NDArray[np.float64],
    uniform: bool,
    block: int,
    rotation: SinesTable,
    mean: NDArray[np.float64],
    translation: SinesTable,
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    pos: NDArray[np.float64],
    vel: NDArray[np.float64],
    acc: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:meth:`RandomManoeuvreSpec.world_motion` block by block: roll, pitch, yaw (``mean`` plus the sums
    of sinusoids ``rotation``) into :func:`_euler_zyx_sample`; east, north, up from ``translation``."""
    angles, coordinates = np.empty((3, 3, block)), np.empty((3, 3, block))
    half, sin, cos = np.empty((3, block)), np.empty((3, block)), np.empty((3, block))
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        sines_block(t, start, count, uniform, rotation, angles)
        sines_block(t, start, count, uniform, translation, coordinates)
        for m in range(3):  # the half angles of roll, pitch, yaw, their sines and cosines
            for i in range(count):
                half[m, i] = 0.5 * (angles[0, m, i] + mean[m])
            sincos_block(half[m], count, sin[m], cos[m])
        for i in range(count):
            j = start + i
            _euler_zyx_sample(
                cos[0, i],
                sin[0, i],
                cos[1, i],
                sin[1, i],
                cos[2, i],
                sin[2, i],
                angles[1, 0, i],
                angles[1, 1, i],
                angles[1, 2, i],
                angles[2, 0, i],
                angles[2, 1, i],
                angles[2, 2, i],
                q[j],
                omega[j],
                alpha[j],
            )
            for m in range(3):  # east, north, up
                pos[j, m], vel[j, m], acc[j, m] = (coordinates[0, m, i], coordinates[1, m, i], coordinates[2, m, i])


# --------------------------------------------------------------------------------------------------
# car
# --------------------------------------------------------------------------------------------------


class Drive(Section):
    """``[drive]``: start heading and the peak longitudinal accelerations.

    ``initial_yaw_deg`` is the ENU yaw of the road's start (0 east, 90 north). Speed changes follow
    :func:`~gyroemu.dynamics.motion_kernels.smooth_step`, whose acceleration peaks at ``accel_m_s2`` (speeding up) or
    ``brake_m_s2`` (slowing down): a change ``Δv`` takes ``16 |Δv| / (5 a_peak)`` seconds.
    """

    initial_yaw_deg: AngleDeg = 0.0
    accel_m_s2: PositiveReal = 2.0
    brake_m_s2: PositiveReal = 3.0


class Leg(Section):
    """``[[legs]]``: change speed to ``speed_m_s``, then hold it for ``hold_s``. The car starts at rest;
    after the last leg it keeps the last speed."""

    speed_m_s: NonNegativeReal
    hold_s: NonNegativeReal


class Turn(Section):
    """``[[turns]]``: a turn by ``angle_deg`` (positive left, counter-clockwise seen from above) that
    begins ``start_m`` along the road and lasts ``length_m`` of road.

    The curvature is the smooth pulse ``κ(s) = Δψ S′(σ/L) / L`` (σ = s − start), so the heading turns
    by ``Δψ S(σ/L)``; the yaw rate is ``κ v``. The curvature peaks at ``(16/5) Δψ / L``, the lateral
    acceleration at ``(16/5) Δψ v² / L``: a 90° turn at 14 m/s needs about 200 m for 5 m/s².
    """

    start_m: NonNegativeReal
    length_m: PositiveReal
    angle_deg: Real


class Bump(Section):
    """``[[bumps]]``: a road bump met at ``at_s``: heave and pitch transients of the suspension.

    ``heave_m`` is the peak upward heave, ``nose_up_deg`` the peak nose-up pitch (the front wheels meet
    the bump first); ``rise_s`` is the time over which the wheels cross it (:class:`SuspensionTransient`).
    """

    at_s: NonNegativeReal
    heave_m: Real = 0.02
    nose_up_deg: Real = 0.5
    rise_s: PositiveReal = 0.05


class Suspension(Section):
    """``[suspension]``: how the body moves on its springs.

    ``roll_deg_per_m_s2``: roll outward in turns per m/s² of lateral acceleration (roll gradient);
    ``pitch_deg_per_m_s2``: nose-down pitch per m/s² of deceleration (dive; squat when accelerating);
    ``heave_frequency_hz``, ``pitch_frequency_hz``, ``damping_ratio``: the body modes that bumps excite.
    """

    roll_deg_per_m_s2: Real = 0.5
    pitch_deg_per_m_s2: Real = 0.3
    heave_frequency_hz: PositiveReal = 1.2
    pitch_frequency_hz: PositiveReal = 1.5
    damping_ratio: Annotated[Real, Field(gt=0, lt=1)] = 0.3


class SpeedProfile:
    """Speed along the road, piecewise in closed form: each leg changes speed along a smooth step, then
    holds it.

    Leg ``k`` starts at ``t_k`` with speed ``v_k`` and distance ``s_k`` and changes speed by ``Δv_k`` over
    ``T_k``; with ``u = (t − t_k)/T_k`` and :func:`~gyroemu.dynamics.motion_kernels.smooth_step`::

        v = v_k + Δv S(u),   s = s_k + v_k τ + Δv T I(u),
        a = Δv S′/T,         j = Δv S″/T²,               ȷ̇ = Δv S‴/T³

    and ``s = s_k + (v_k + Δv/2) T + (v_k + Δv)(τ − T)`` once the change is over. The legs are laid
    out here; :func:`_car_kernel` evaluates these formulas (:meth:`CarMotion._speed_table`).
    """

    def __init__(self, legs: list[Leg], drive: Drive):
        start, dist, speed, change, ramp, dist_end = [], [], [], [], [], []
        t = s = v = 0.0
        for leg in legs:
            dv = leg.speed_m_s - v
            duration = 16 * abs(dv) / (5 * (drive.accel_m_s2 if dv > 0 else drive.brake_m_s2))  # peak Δv S′/T = a_peak
            start.append(t)
            dist.append(s)
            speed.append(v)
            change.append(dv)
            ramp.append(duration or 1.0)
            s += (v + 0.5 * dv) * duration  # I(1) = ½
            dist_end.append(s)
            s += leg.speed_m_s * leg.hold_s
            t += duration + leg.hold_s
            v = leg.speed_m_s
        self.start, self.distance, self.speed = np.array(start), np.array(dist), np.array(speed)
        self.change, self.ramp, self.distance_after = np.array(change), np.array(ramp), np.array(dist_end)


class Road:
    """The road's heading, curvature and position as functions of the distance along it.

    Heading ``ψ(s) = ψ_k + Δψ_k S((s − s_k)/L_k)`` through turn ``k`` and constant between turns.
    Position: exact on straight stretches; through a turn the antiderivative of ``(cos ψ, sin ψ)`` is
    a Chebyshev series (``numpy.polynomial.Chebyshev``) interpolating the integrand, which is entire, so
    its coefficients decay faster than geometrically down to the round-off plateau (about 1e-15,
    the rounding of ``cos ψ`` itself); the degree is doubled until the series is resolved to that
    plateau, it is chopped there and integrated exactly. What remains is round-off: against adaptive
    quadrature the positions agree to a few 1e-16 of the distance (6e-14 m at 300 m).
    """

    ROUND_OFF = 64 * np.finfo(float).eps
    """Coefficients below this are round-off (the integrand is O(1)): chop there."""

    def __init__(self, turns: list[Turn], initial_yaw_rad: float):
        self.start = np.array([tr.start_m for tr in turns])
        self.length = np.array([tr.length_m for tr in turns])
        self.angle = np.radians([tr.angle_deg for tr in turns])
        # Heading before each turn, and after the last one.
        self.heading = initial_yaw_rad + np.concatenate([[0.0], np.cumsum(self.angle)])
        self.integrals = []
        self.begin = np.zeros((len(turns), 2))  # position where each turn begins, m
        self.end = np.zeros((len(turns), 2))  # and where it ends
        position, s = np.zeros(2), 0.0
        for k in range(len(turns)):
            straight = self.start[k] - s
            position = position + straight * np.array([np.cos(self.heading[k]), np.sin(self.heading[k])])
            fx, fy = self._antiderivative(self.heading[k], self.angle[k], self.length[k])
            self.integrals.append((fx, fy))
            self.begin[k] = position
            position = position + [fx(self.length[k]), fy(self.length[k])]
            self.end[k] = position
            s = self.start[k] + self.length[k]

    @classmethod
    def _antiderivative(cls, heading: float, angle: float, length: float) -> tuple[Chebyshev, Chebyshev]:
        """Chebyshev series of ``∫₀^σ (cos ψ, sin ψ) dσ′`` on ``[0, L]`` through one turn.

        The degree is doubled until the last quarter of the coefficients is round-off, then the series
        is chopped after its last coefficient above round-off (a plateau-detecting chop, as Chebfun's).
        """

        def psi(sigma: NDArray[np.float64]) -> NDArray[np.float64]:
            return heading + angle * smooth_step(sigma / length, derivatives=0)[0]

        for degree in (32, 64, 128, 256, 512, 1024):
            cx = Chebyshev.interpolate(lambda x: np.cos(psi(x)), degree, domain=[0.0, length])
            cy = Chebyshev.interpolate(lambda x: np.sin(psi(x)), degree, domain=[0.0, length])
            size = np.maximum(np.abs(cx.coef), np.abs(cy.coef))
            if size[-(degree // 4) :].max() < cls.ROUND_OFF:
                keep = np.flatnonzero(size >= cls.ROUND_OFF)[-1] + 1
                return cx.cutdeg(keep).integ(lbnd=0.0), cy.cutdeg(keep).integ(lbnd=0.0)
        raise ValueError(f"a turn of {np.degrees(angle):g} deg in {length:g} m is too sharp to integrate")

    def __call__(
        self, s: NDArray[np.float64]
    ) -> tuple[
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
    ]:
        """At distances ``s`` (N,), m: heading ψ (rad) with its cosine and sine, curvature κ and its
        first two derivatives along the road (1/m, 1/m², 1/m³), and the east and north position (m)."""
        if len(self.start) == 0:
            psi = np.full_like(s, self.heading[0])
            zero = np.zeros_like(s)
            cos, sin = np.cos(psi), np.sin(psi)
            return psi, cos, sin, zero, zero, zero, s * cos, s * sin
        k = np.clip(np.searchsorted(self.start, s, side="right") - 1, 0, None)
        sigma = s - self.start[k]
        u = sigma / self.length[k]
        # Straight road: from the start of turn k (before the first turn) or from its end (after it).
        after = u >= 1.0
        heading = np.where(after, self.heading[k + 1], self.heading[k])
        psi, cos, sin = heading, np.cos(self.heading)[k + after], np.sin(self.heading)[k + after]
        run = np.where(after, sigma - self.length[k], sigma)
        x = np.where(after, self.end[k, 0], self.begin[k, 0]) + run * cos
        y = np.where(after, self.end[k, 1], self.begin[k, 1]) + run * sin
        kappa, dkappa, ddkappa = np.zeros_like(s), np.zeros_like(s), np.zeros_like(s)
        # In turn j: ψ = ψ_j + Δψ S(σ/L), κ = Δψ S′/L, …; the position from the Chebyshev antiderivative.
        for j, (fx, fy) in enumerate(self.integrals):
            inside = np.flatnonzero((k == j) & (u > 0.0) & ~after)
            if not len(inside):
                continue
            length, angle = self.length[j], self.angle[j]
            step, slope, curve, jolt = smooth_step(u[inside], derivatives=3)
            psi[inside] = self.heading[j] + angle * step
            cos[inside], sin[inside] = np.cos(psi[inside]), np.sin(psi[inside])
            kappa[inside], dkappa[inside], ddkappa[inside] = (
                angle * slope / length,
                angle * curve / length**2,
                angle * jolt / length**3,
            )
            x[inside] = self.begin[j, 0] + fx(sigma[inside])
            y[inside] = self.begin[j, 1] + fy(sigma[inside])
        return psi, cos, sin, kappa, dkappa, ddkappa, x, y


class SuspensionTransient:
    """A damped oscillation of the body with a smooth onset, scaled to a peak of 1.

    ``g(τ) = Im[(1 − e^{−τ/τ_r})³ e^{λτ}] / peak`` for ``τ ≥ 0`` (0 before), with
    ``λ = ω_n (−ζ + i √(1 − ζ²))``: the free oscillation of a body mode of natural frequency ``ω_n`` and
    damping ratio ``ζ``, switched on over the rise time ``τ_r`` in which the wheels cross the bump. The
    onset factor makes ``g`` and its first three derivatives vanish at ``τ = 0``, so position and
    attitude are C³ there. Expanding the cube, ``g = Im Σ_m c_m e^{μ_m τ}`` with ``c = (1, −3, 3, −1)``
    and ``μ_m = λ − m/τ_r``, and the derivatives are ``Im Σ c_m μ_m^d e^{μ_m τ}``. After ``duration`` the
    envelope is below 1e-17 and ``g`` is taken as 0.
    """

    def __init__(self, frequency_hz: float, damping_ratio: float, rise_s: float):
        wn = 2 * np.pi * frequency_hz
        lam = wn * complex(-damping_ratio, np.sqrt(1 - damping_ratio**2))
        self._mu = lam - np.arange(4) / rise_s
        self._c = np.array([1.0, -3.0, 3.0, -1.0])
        self.peak = 1.0
        grid = np.linspace(0.0, 4 * rise_s + 2 * np.pi / wn, 20001)  # the first peak lies within
        self.peak = float(np.abs(self(grid, derivatives=0)[0]).max())
        self.duration = np.log(1e17 / self.peak) / (damping_ratio * wn) + 4 * rise_s

    def __call__(self, tau: ArrayLike, derivatives: int = 2) -> tuple[NDArray[np.float64], ...]:
        """``g``, ``ġ``, ``g̈`` (per s, s²) at ``τ`` (N,), s, for ``0 ≤ τ``."""
        exps = np.exp(np.multiply.outer(tau, self._mu))  # (N, 4)
        return tuple(np.imag(exps @ (self._c * self._mu**d)) / self.peak for d in range(derivatives + 1))


class CarSpec(EarthBoundSpec):
    """``kind = "car"``: a car drive with speed legs, turns and road bumps.

    Along the road distance ``s(t)`` with speed ``v``, acceleration ``a`` and jerk ``j``
    (:class:`SpeedProfile`) and the road's heading ``ψ(s)`` and curvature ``κ(s)`` (:class:`Road`)::

        yaw   ψ,                 ψ̇ = κ v,             ψ̈ = κ′ v² + κ a
        roll  φ = k_r κ v²       (outward, proportional to the lateral acceleration κ v²)
              φ̇ = k_r (κ′ v³ + 2 κ v a),  φ̈ = k_r (κ″ v⁴ + 5 κ′ v² a + 2 κ (a² + v j))
        pitch θ = −k_p a + bump transients (nose-down positive: y points left)
        heave z = bump transients
        v_w = (v cos ψ, v sin ψ, ż),  a_w = (a cos ψ − v ψ̇ sin ψ, a sin ψ + v ψ̇ cos ψ, z̈)

    ``′`` is d/ds. The body x axis points along the road (no side slip); the reference point is on the
    road surface's path plus heave.
    """

    kind: Literal["car"] = "car"
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    drive: Drive = Field(default_factory=Drive)
    legs: list[Leg] = Field(min_length=1)
    turns: list[Turn] = Field(default_factory=list)
    bumps: list[Bump] = Field(default_factory=list)
    suspension: Suspension = Field(default_factory=Suspension)

    @field_validator("turns")
    @classmethod
    def _turns_in_order(cls, turns: list[Turn]) -> list[Turn]:
        for k in range(1, len(turns)):
            end = turns[k - 1].start_m + turns[k - 1].length_m
            if turns[k].start_m < end:
                raise ValueError(
                    f"turns[{k}] starts at {turns[k].start_m:g} m, before turns[{k - 1}] ends at {end:g} m; "
                    "list turns in order along the road, without overlap"
                )
        return turns

    def evaluator(self) -> CarMotion:
        """The car's closed forms with the road series and transients set up once."""
        return CarMotion(self)

    def world_motion(self, t: NDArray[np.float64]) -> WorldMotion:
        return self.evaluator()(t)


# The road's series and the transients' peaks take milliseconds to set up: as much as evaluating 10⁶
# samples. Both are pure functions of a few numbers (turns are frozen, hashable sections), so each is
# built once per process and shared by every CarMotion that needs it.


@lru_cache(maxsize=64)
def _road(turns: tuple[Turn, ...], initial_yaw_rad: float) -> Road:
    return Road(list(turns), initial_yaw_rad)


@lru_cache(maxsize=64)
def _suspension_transient(frequency_hz: float, damping_ratio: float, rise_s: float) -> SuspensionTransient:
    return SuspensionTransient(frequency_hz, damping_ratio, rise_s)


_SpeedTable = tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]
"""The legs as :meth:`CarMotion._speed_table` lays them out for :func:`_car_kernel`."""

_RoadTable = tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.intp],
    NDArray[np.float64],
]
"""The turns as :meth:`CarMotion._road_table` lays them out for :func:`_car_kernel`."""

_BumpTable = tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.complex128],
    NDArray[np.complex128],
]
"""The bumps as :meth:`CarMotion._bump_table` lays them out for :func:`_car_kernel`."""


class CarMotion:
    """The equations of :class:`CarSpec`, evaluated at any times: ``CarMotion(spec)(t) -> WorldMotion``.

    The setup gathers the speed profile, the road (with its Chebyshev series) and the bump transients
    into arrays; :func:`_car_kernel` then evaluates the samples block by block, compiled, with the
    formulas of :class:`SpeedProfile`, :meth:`Road.__call__`, :class:`SuspensionTransient` and
    :class:`CarSpec`.
    """

    def __init__(self, spec: CarSpec):
        sus = spec.suspension
        self.speed = SpeedProfile(spec.legs, spec.drive)
        self.road = _road(tuple(spec.turns), float(np.radians(spec.drive.initial_yaw_deg)))
        self.k_roll, self.k_pitch = np.radians(sus.roll_deg_per_m_s2), np.radians(sus.pitch_deg_per_m_s2)
        self.bumps = []  # (time, heave, nose-up, heave transient, pitch transient)
        modes = {}  # rise time → transients
        for bump in spec.bumps:
            if bump.rise_s not in modes:
                modes[bump.rise_s] = tuple(
                    _suspension_transient(f, sus.damping_ratio, bump.rise_s)
                    for f in (sus.heave_frequency_hz, sus.pitch_frequency_hz)
                )
            self.bumps.append((bump.at_s, bump.heave_m, np.radians(bump.nose_up_deg), *modes[bump.rise_s]))
        self._rise = np.array([bump.rise_s for bump in spec.bumps])
        tables = self._speed_table(), self._road_table(), self._bump_table()
        self._tables = (*tables, self.k_roll, self.k_pitch)  # the arguments of _car_kernel after t, block

    def _speed_table(self) -> _SpeedTable:
        """The legs (:class:`SpeedProfile`): start time, distance and speed, speed change Δv, its
        duration T with T² and T³, and the distance where the change ends."""
        sp = self.speed
        ramp = sp.ramp
        return sp.start, sp.distance, sp.speed, sp.change, ramp, ramp**2, ramp**3, sp.distance_after

    def _road_table(self) -> _RoadTable:
        """The turns (:class:`Road`): start, length L with L² and L³, angle; the headings with their
        cosines and sines; where each turn begins and ends; the Chebyshev coefficients of the x and y
        antiderivatives, (2, turns, size) zero-padded, with their sizes (2, turns), and the map of
        [0, L] onto [−1, 1] (numpy's ``mapparms``: ``off + scl σ``) per turn."""
        road = self.road
        turns = len(road.integrals)
        sizes = np.zeros((2, turns), dtype=np.intp)
        coef = np.zeros((2, turns, max([len(f.coef) for pair in road.integrals for f in pair], default=1)))
        maps = np.zeros((turns, 2))
        for j, pair in enumerate(road.integrals):
            for axis, series in enumerate(pair):
                sizes[axis, j] = len(series.coef)
                coef[axis, j, : sizes[axis, j]] = series.coef
            maps[j] = pair[0].mapparms()  # both series share the domain [0, L]
        headings = road.heading, np.cos(road.heading), np.sin(road.heading)
        lengths = road.length, road.length**2, road.length**3
        return (road.start, *lengths, road.angle, *headings, road.begin, road.end, coef, sizes, maps)

    def _bump_table(self) -> _BumpTable:
        """The bumps: time, rise time τ_r; per mode (heave, pitch): scale (height, nose-up angle), end of
        the transient (``at + duration``), peak, λ = μ_0 and the weights ``w_dm = c_m μ_m^d``
        (d = 0, 1, 2) of :class:`SuspensionTransient`."""
        m = len(self.bumps)
        at, scale, end, peak = np.zeros(m), np.zeros((m, 2)), np.zeros((m, 2)), np.ones((m, 2))
        lam, weights = np.zeros((m, 2), dtype=complex), np.zeros((m, 2, 3, 4), dtype=complex)
        for b, (time, height, nose_up, *bump_modes) in enumerate(self.bumps):
            at[b], scale[b] = time, (height, nose_up)
            for k, mode in enumerate(bump_modes):
                end[b, k], peak[b, k], lam[b, k] = time + mode.duration, mode.peak, mode._mu[0]
                weights[b, k] = [mode._c * mode._mu**d for d in range(3)]
        return at, self._rise, scale, end, peak, lam, weights

    def __call__(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        n = len(t)
        arrays = motion_arrays(n, moves=True)
        speed, distance = np.empty(n), np.empty(n)
        _car_kernel(t, TimeGrid.BLOCK, *self._tables, *arrays, speed, distance)
        return WorldMotion(t, *arrays, extras={"speed_m_s": speed, "distance_m": distance})


@njit
def _chebval(coef: NDArray[np.float64], size: int, x: float) -> float:  # pragma: no cover - compiled
    """``numpy.polynomial.chebyshev.chebval(x, coef[:size])`` for one ``x``, by the same Clenshaw
    recurrence."""
    value: float
    if size == 1:
        value = coef[0] + 0.0 * x
        return value
    if size == 2:
        value = coef[0] + coef[1] * x
        return value
    x2 = 2 * x
    c0, c1 = coef[size - 2], coef[size - 1]
    for i in range(3, size + 1):
        c0, c1 = coef[size - i] - c1, c0 + c1 * x2
    value = c0 + c1 * x
    return value


@njit
def _chebval_block(
    coef: NDArray[np.float64],
    size: int,
    x: NDArray[np.float64],
    count: int,
    b0: NDArray[np.float64],
    b1: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:func:`_chebval` at ``x[:count]`` into ``out``: the same recurrence with the samples innermost,
    where it vectorises (one sample's recurrence is a chain of ``size`` dependent steps)."""
    if size <= 2:
        for i in range(count):
            out[i] = _chebval(coef, size, x[i])
        return
    for i in range(count):
        b0[i], b1[i] = coef[size - 2], coef[size - 1]
    for k in range(3, size + 1):
        ck = coef[size - k]
        for i in range(count):
            b0[i], b1[i] = ck - b1[i], b0[i] + b1[i] * (2 * x[i])
    for i in range(count):
        out[i] = b0[i] + b1[i] * x[i]


@njit
def _transients_block(
    t: NDArray[np.float64],
    start: int,
    count: int,
    at: float,
    rise: float,
    end: float,
    lam: complex,
    weights: NDArray[np.complex128],
    peak: float,
    scale: float,
    sign: float,
    out0: NDArray[np.float64],
    out1: NDArray[np.float64],
    out2: NDArray[np.float64],
    work: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """Adds ``sign · scale · g⁽ᵈ⁾(t − at)`` (:class:`SuspensionTransient`, d = 0, 1, 2) to ``out0``,
    ``out1``, ``out2`` at the samples ``start … start + count − 1`` with ``at ≤ t < end``.

    The ``μ_m = λ − m/τ_r`` differ by real shifts: ``e^{μ_m τ} = e^{λτ} ρ^m`` with ``ρ = e^{−τ/τ_r}``,
    so ``Σ_m w_dm e^{μ_m τ}`` (``w_dm = c_m μ_m^d``) is ``e^{λτ}`` times a cubic in ρ: two exponentials,
    a cosine and a sine per sample instead of four complex exponentials.
    """
    tau, rho, envelope, arg, sin, cos = work[0], work[1], work[2], work[3], work[4], work[5]
    inside = np.zeros(count, np.bool_)
    for i in range(count):  # the exponentials (library calls) where the transient runs
        if at <= t[start + i] < end:
            inside[i] = True
            tau[i] = t[start + i] - at
            rho[i], envelope[i] = np.exp(-tau[i] / rise), np.exp(lam.real * tau[i])
        else:
            tau[i] = rho[i] = envelope[i] = 0.0
        arg[i] = lam.imag * tau[i]
    if not inside.any():
        return
    sincos_block(arg, count, sin, cos)
    w = weights
    for i in range(count):
        er, ei, r = envelope[i] * cos[i], envelope[i] * sin[i], rho[i]  # e^{λτ}, ρ
        # Σ_m w_dm ρ^m = w_d0 + ρ (w_d1 + ρ (w_d2 + ρ w_d3)), real and imaginary parts;
        # g⁽ᵈ⁾ = Im(e^{λτ} Σ_m w_dm ρ^m) / peak
        pr = w[0, 0].real + r * (w[0, 1].real + r * (w[0, 2].real + r * w[0, 3].real))
        pi = w[0, 0].imag + r * (w[0, 1].imag + r * (w[0, 2].imag + r * w[0, 3].imag))
        g0 = (er * pi + ei * pr) / peak
        pr = w[1, 0].real + r * (w[1, 1].real + r * (w[1, 2].real + r * w[1, 3].real))
        pi = w[1, 0].imag + r * (w[1, 1].imag + r * (w[1, 2].imag + r * w[1, 3].imag))
        g1 = (er * pi + ei * pr) / peak
        pr = w[2, 0].real + r * (w[2, 1].real + r * (w[2, 2].real + r * w[2, 3].real))
        pi = w[2, 0].imag + r * (w[2, 1].imag + r * (w[2, 2].imag + r * w[2, 3].imag))
        g2 = (er * pi + ei * pr) / peak
        # (selects, not branches: the loop vectorises)
        out0[i] = out0[i] + sign * (scale * g0) if inside[i] else out0[i]
        out1[i] = out1[i] + sign * (scale * g1) if inside[i] else out1[i]
        out2[i] = out2[i] + sign * (scale * g2) if inside[i] else out2[i]


@njit
def _car_kernel(
    t: NDArray[np.float64],
    block: int,
    speed_table: _SpeedTable,
    road_table: _RoadTable,
    bump_table: _BumpTable,
    k_roll: float,
    k_pitch: float,
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    pos: NDArray[np.float64],
    vel: NDArray[np.float64],
    acc: NDArray[np.float64],
    speed_out: NDArray[np.float64],
    distance_out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The car (:class:`CarSpec`), block by block.

    Sample by sample: the speed profile, the road and the Euler angles with their derivatives. Then for
    the block at once, in loops that vectorise: the positions in turns (Chebyshev series), the bump
    transients (heave and pitch), the half angles' sines and cosines and the attitude.
    """
    t_leg, s_leg, v_leg, dv_leg, ramp_leg, ramp2_leg, ramp3_leg, s_after_leg = speed_table
    (s_turn, length, length2, length3, turn_angle, heading, cos_heading, sin_heading, begin, end, coef, sizes, maps) = (
        road_table
    )
    bump_at, bump_rise, bump_scale, bump_end, bump_peak, bump_lam, bump_weights = bump_table
    turns = len(s_turn)
    # Scratch for a block (separate arrays: rows unpacked from one array compile to slower,
    # non-contiguous views). Per sample: roll, pitch, yaw, their rates and accelerations; heave z, ż,
    # z̈; the half angles, their sines and cosines.
    angles = np.empty((3, block))
    rates = np.empty((3, block))
    accels = np.empty((3, block))
    heave = np.empty((3, block))
    half = np.empty(block)
    sin_half = np.empty((3, block))
    cos_half = np.empty((3, block))
    work = np.empty((6, block))  # for _transients_block
    # The samples in turns: index, turn, argument of the series; scratch for their evaluation.
    series_sample = np.empty(block, np.intp)
    series_turn = np.empty(block, np.intp)
    series_arg = np.empty(block)
    samples = np.empty(block, np.intp)
    args = np.empty(block)
    values = np.empty(block)
    b0 = np.empty(block)
    b1 = np.empty(block)
    leg = turn = 0
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        in_turns = 0
        for i in range(count):
            j = start + i
            # Speed profile (SpeedProfile): leg k changes speed by Δv along S(τ/T), then holds it.
            leg = segment_index(t_leg, t[j], leg)
            tau = t[j] - t_leg[leg]
            ramp, dv, v0 = ramp_leg[leg], dv_leg[leg], v_leg[leg]
            if tau >= ramp:  # after the change (S = 1, S′ = S″ = S‴ = 0): s = s_end + v (τ − T), exactly
                s = s_after_leg[leg] + (v0 + dv) * (tau - ramp)
                v, a, jerk, djerk = v0 + dv, 0.0, 0.0, 0.0
            else:
                step, slope, curve, jolt, area = smooth_step_at(tau / ramp)
                s = s_leg[leg] + v0 * tau + dv * ramp * area
                v = v0 + dv * step
                a = dv * slope / ramp
                jerk = dv * curve / ramp2_leg[leg]
                djerk = dv * jolt / ramp3_leg[leg]
            # Road (Road.__call__): heading, curvature and position at the distance s.
            kappa = dkappa = ddkappa = 0.0
            if turns == 0:
                psi, cos, sin = heading[0], cos_heading[0], sin_heading[0]
                x, y = s * cos, s * sin
            else:
                turn = segment_index(s_turn, s, turn)
                sigma = s - s_turn[turn]
                u = sigma / length[turn]
                if u >= 1.0:  # straight road after turn k (from its end)
                    psi, cos, sin = heading[turn + 1], cos_heading[turn + 1], sin_heading[turn + 1]
                    x = end[turn, 0] + (sigma - length[turn]) * cos
                    y = end[turn, 1] + (sigma - length[turn]) * sin
                elif u > 0.0:  # in turn k: ψ = ψ_k + Δψ S(σ/L), κ = Δψ S′/L, …; position from the series
                    step_t, slope_t, curve_t, jolt_t, _ = smooth_step_at(u)
                    angle = turn_angle[turn]
                    psi = heading[turn] + angle * step_t
                    sin, cos = sin_cos(psi)
                    kappa = angle * slope_t / length[turn]
                    dkappa = angle * curve_t / length2[turn]
                    ddkappa = angle * jolt_t / length3[turn]
                    # x = x_k + X(σ) with the series X evaluated for the whole block (below).
                    x, y = begin[turn, 0], begin[turn, 1]
                    series_sample[in_turns], series_turn[in_turns] = j, turn
                    series_arg[in_turns] = maps[turn, 0] + maps[turn, 1] * sigma  # σ mapped onto [−1, 1]
                    in_turns += 1
                else:  # straight road before turn k (before the first turn: from its start, backwards)
                    psi, cos, sin = heading[turn], cos_heading[turn], sin_heading[turn]
                    x = begin[turn, 0] + sigma * cos
                    y = begin[turn, 1] + sigma * sin
            # Attitude (CarSpec): roll ∝ lateral acceleration κ v², pitch ∝ −a, yaw ψ; their derivatives.
            v2 = v * v
            yaw_rate = kappa * v
            angles[0, i] = k_roll * kappa * v2
            rates[0, i] = k_roll * (dkappa * v2 * v + 2 * kappa * v * a)
            accels[0, i] = k_roll * (ddkappa * v2 * v2 + 5 * dkappa * v2 * a + 2 * kappa * (a * a + v * jerk))
            angles[1, i], rates[1, i], accels[1, i] = -k_pitch * a, -k_pitch * jerk, -k_pitch * djerk
            angles[2, i], rates[2, i], accels[2, i] = psi, yaw_rate, dkappa * v2 + kappa * a
            along, across = a, v * yaw_rate  # tangential and centripetal acceleration
            pos[j, 0], pos[j, 1] = x, y
            vel[j, 0], vel[j, 1] = v * cos, v * sin
            acc[j, 0], acc[j, 1] = along * cos - across * sin, along * sin + across * cos
            speed_out[j], distance_out[j] = v, s
            heave[0, i] = heave[1, i] = heave[2, i] = 0.0
        if in_turns:
            # Turn by turn (a block of a sorted grid meets one or two), both series at the turn's samples.
            for tj in range(series_turn[:in_turns].min(), series_turn[:in_turns].max() + 1):
                m = 0
                for k in range(in_turns):
                    if series_turn[k] == tj:
                        args[m], samples[m] = series_arg[k], series_sample[k]
                        m += 1
                for axis in range(2):
                    _chebval_block(coef[axis, tj], sizes[axis, tj], args, m, b0, b1, values)
                    for k in range(m):
                        pos[samples[k], axis] += values[k]
        # Bumps: heave z, ż, z̈ and nose-up pitch transients (pitch is nose-down positive), for the
        # bumps whose transients overlap the block's time span.
        t_min, t_max = t[start : start + count].min(), t[start : start + count].max()
        for b in range(len(bump_at)):
            if t_max < bump_at[b] or t_min >= max(bump_end[b, 0], bump_end[b, 1]):
                continue
            _transients_block(
                t,
                start,
                count,
                bump_at[b],
                bump_rise[b],
                bump_end[b, 0],
                bump_lam[b, 0],
                bump_weights[b, 0],
                bump_peak[b, 0],
                bump_scale[b, 0],
                1.0,
                heave[0],
                heave[1],
                heave[2],
                work,
            )
            _transients_block(
                t,
                start,
                count,
                bump_at[b],
                bump_rise[b],
                bump_end[b, 1],
                bump_lam[b, 1],
                bump_weights[b, 1],
                bump_peak[b, 1],
                bump_scale[b, 1],
                -1.0,
                angles[1],
                rates[1],
                accels[1],
                work,
            )
        for i in range(count):
            pos[start + i, 2], vel[start + i, 2], acc[start + i, 2] = heave[0, i], heave[1, i], heave[2, i]
        for m in range(3):
            for i in range(count):
                half[i] = 0.5 * angles[m, i]
            sincos_block(half, count, sin_half[m], cos_half[m])
        for i in range(count):
            _euler_zyx_sample(
                cos_half[0, i],
                sin_half[0, i],
                cos_half[1, i],
                sin_half[1, i],
                cos_half[2, i],
                sin_half[2, i],
                rates[0, i],
                rates[1, i],
                rates[2, i],
                accels[0, i],
                accels[1, i],
                accels[2, i],
                q[start + i],
                omega[start + i],
                alpha[start + i],
            )
