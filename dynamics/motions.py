"""Prescribed motions in closed form: a bench, a rate table, oscillation, coning and sculling.

Every kind here stands on the Earth at a site (the optional ``[site]`` table, :class:`~dynamics.earth.Site`)
and prescribes its motion *relative to the local ENU world frame* analytically: attitude ``q_wb``, body
rate ``ω_wb`` and its derivative ``α_wb`` (body axes), position, velocity and acceleration (world axes),
each a closed-form function of time evaluated on arrays of samples (vectorised, no loop over samples).
No kind integrates anything. :func:`~dynamics.trajectory.trajectory_from_world_motion` then adds what
the Earth contributes: Earth rate, Coriolis, gravity and the magnetic field.

Kinds
-----
``static``
    A body at rest on a bench: an ideal gyro reads the Earth rate ``R_bw Ω (0, cos φ, sin φ)``, a level
    accelerometer ``(0, 0, +g)``.
``rate-table``
    A single-axis rate table as used to calibrate gyros: constant rate, rate steps with a finite
    angular-acceleration limit, or a multi-position tumble; with a mounting rotation and a lever arm of
    the body on the table top.
``oscillation``
    Sinusoidal angular oscillation about a body axis, optionally with a linear oscillation.
``coning``
    Classical coning (Savage 1998, part 1): the body x axis sweeps a cone about a fixed axis.
``sculling``
    Angular oscillation about x in phase with linear oscillation along y (Savage 1998, part 2).

Building blocks shared with :mod:`dynamics.vehicles`: :class:`TimeGrid` (sinusoids on uniform grids by
angle addition), :func:`smooth_step` (a C⁵ step from 0 to 1), :func:`rotation_basis` and
:func:`axis_rotation` (quaternions of a rotation about a fixed axis), :class:`WorldMotion` and
:class:`EarthBoundSpec`.

Attitudes in config files are ``rpy_deg = [roll, pitch, yaw]`` in degrees with
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`dynamics.rotation.quat_from_euler_zyx`); in the ENU world,
yaw 0 points body x east, yaw 90 north.

References
----------
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 1: attitude algorithms",
J. Guidance, Control, and Dynamics 21(1), 19–28, 1998 (coning).
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 2: velocity and position
algorithms", J. Guidance, Control, and Dynamics 21(2), 208–221, 1998 (sculling).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from .config import NonNegativeReal, PositiveReal, Real, Section, Vec3
from .earth import Site
from .rotation import quat_conjugate, quat_from_euler_zyx, quat_multiply, quat_rotate, quat_to_rotvec
from .scenarios import ScenarioSpec
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = [
    "TimeGrid",
    "smooth_step",
    "quat_from_rpy_deg",
    "rotation_basis",
    "axis_rotation",
    "outer",
    "half_angle_combination",
    "WorldMotion",
    "CHUNK",
    "in_chunks",
    "EarthBoundSpec",
    "Attitude",
    "StaticSpec",
    "Table",
    "ConstantRate",
    "RateSteps",
    "Tumble",
    "RateTableSpec",
    "AngularOscillation",
    "LinearOscillation",
    "OscillationSpec",
    "Coning",
    "ConingSpec",
    "Sculling",
    "ScullingSpec",
]

_EPS = np.finfo(float).eps
_E_Z = np.array([0.0, 0.0, 1.0])


# --------------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------------


class TimeGrid:
    """Sample times, and sinusoids ``sin(ω t + φ)`` evaluated on them.

    Sinusoids are most of the cost of a closed-form motion: numpy's ``sin`` and ``cos`` take about
    10 ns per sample, a multiplication 0.3 ns. On a uniform grid ``t_n = t_0 + n h`` the angle-addition
    theorem removes almost all of them. With ``n = j B + i`` (block ``j`` of ``B`` samples, offset ``i``)::

        exp(i(ω t_n + φ)) = exp(i(ω t_{jB} + φ)) · exp(i ω i h)

    so ``N`` samples need ``N/B + B`` sines and cosines and one complex product each. The product adds
    a few ulp to what direct evaluation loses already in rounding ``ω t + φ`` (the tests compare both
    against long-double references). A grid counts as uniform when it deviates from
    ``t_0 + n h`` by at most 8 ulp of its largest time, which ``Scenario.times`` (``k / rate_hz``) meets;
    other grids are evaluated directly, in chunks.

    Parameters
    ----------
    t : array_like (N,)
        Sample times, s.
    """

    BLOCK = 1024
    """Samples per block ``B`` on uniform grids."""

    _CHUNK = 8192
    """Samples per chunk of direct evaluation (bounds the (C, K, chunk) temporaries)."""

    def __init__(self, t):
        self.t = np.asarray(t, dtype=float)
        if self.t.ndim != 1:
            raise ValueError(f"sample times must be 1-D, got shape {self.t.shape}")
        n = len(self.t)
        self.t0 = float(self.t[0]) if n else 0.0
        self.h = float(self.t[-1] - self.t[0]) / (n - 1) if n > 1 else 0.0
        self.uniform = False
        if n >= 4 * self.BLOCK and self.h > 0:
            deviation = np.abs(self.t - (self.t0 + np.arange(n) * self.h)).max()
            self.uniform = bool(deviation <= 8 * _EPS * np.abs(self.t[[0, -1]]).max())
        self.sorted = self.uniform or bool(np.all(np.diff(self.t) >= 0))

    def __len__(self) -> int:
        return len(self.t)

    def window(self, start: float, stop: float):
        """The samples with ``start <= t < stop``: a slice on sorted grids, else an index array."""
        if self.sorted:
            return slice(*np.searchsorted(self.t, [start, stop]))
        return np.flatnonzero((self.t >= start) & (self.t < stop))

    def _blocks(self):
        """Block start times ``t_{jB}`` (J,), taken from the samples themselves, and in-block offsets
        ``i h`` (B,)."""
        return self.t[:: self.BLOCK], np.arange(self.BLOCK) * self.h

    def cos_sin(self, omega: float, phase: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``cos(ω t + φ)`` and ``sin(ω t + φ)``, each (N,); ``ω`` in rad/s, ``φ`` in rad."""
        if not self.uniform:
            angle = omega * self.t + phase
            return np.cos(angle), np.sin(angle)
        starts, offsets = self._blocks()
        cb, sb = np.cos(omega * starts + phase), np.sin(omega * starts + phase)
        co, so = np.cos(omega * offsets), np.sin(omega * offsets)
        # cos(a + b) = cos a cos b − sin a sin b,  sin(a + b) = sin a cos b + cos a sin b
        c = np.multiply.outer(cb, co)
        c -= np.multiply.outer(sb, so)
        s = np.multiply.outer(sb, co)
        s += np.multiply.outer(cb, so)
        n = len(self.t)
        return c.reshape(-1)[:n], s.reshape(-1)[:n]

    def sum_of_sines(self, amplitude, omega, phase) -> np.ndarray:
        """Sums of sinusoids per channel and their first two time derivatives.

        ``x_c(t) = Σ_k A_ck sin(ω_ck t + φ_ck)``, ``ẋ_c = Σ A ω cos(…)``,
        ``ẍ_c = −Σ A ω² sin(…)``.

        Parameters
        ----------
        amplitude, omega, phase : array_like (C, K)
            Amplitudes (any unit), angular frequencies (rad/s), phases (rad) of ``K`` terms per channel.

        Returns
        -------
        ndarray (3, C, N)
            Value, first and second derivative of each channel.

        Notes
        -----
        On a uniform grid the sum is a matrix product: with block phasors ``P_jk = exp(i(ω_k t_j + φ_k))``
        and offset phasors ``Q_ki = exp(i ω_k i h)``, ``x[j B + i] = Σ_k A_k Im(P_jk Q_ki)``
        ``= Σ_k A_k (Im P_jk Re Q_ki + Re P_jk Im Q_ki)``, one ``(3J × 2K) · (2K × B)`` BLAS product per
        channel for the value and both derivatives.
        """
        a, w, p = np.broadcast_arrays(
            *(np.atleast_2d(np.asarray(x, dtype=float)) for x in (amplitude, omega, phase))
        )
        if not self.uniform:
            return self._sum_of_sines_direct(a, w, p)
        channels, terms = a.shape
        n = len(self.t)
        starts, offsets = self._blocks()
        block_phase = w[..., None] * starts + p[..., None]  # (C, K, J)
        pc, ps = np.cos(block_phase), np.sin(block_phase)
        offset_phase = w[..., None] * offsets  # (C, K, B)
        right = np.concatenate([np.cos(offset_phase), np.sin(offset_phase)], axis=1)  # (C, 2K, B)
        a0 = a[..., None]
        a1 = a0 * w[..., None]
        a2 = a1 * w[..., None]
        left = np.stack(
            [
                np.concatenate([a0 * ps, a0 * pc], axis=1),  # Σ A Im(PQ)        value
                np.concatenate([a1 * pc, -a1 * ps], axis=1),  # Σ A ω Re(PQ)      first derivative
                np.concatenate([-a2 * ps, -a2 * pc], axis=1),  # −Σ A ω² Im(PQ)   second derivative
            ],
            axis=1,
        )  # (C, 3, 2K, J)
        left = left.transpose(0, 1, 3, 2).reshape(channels, 3 * len(starts), 2 * terms)
        out = (left @ right).reshape(channels, 3, -1)[:, :, :n]
        return out.transpose(1, 0, 2)

    def _sum_of_sines_direct(self, a, w, p) -> np.ndarray:
        out = np.empty((3, a.shape[0], len(self.t)))
        a1, a2 = a * w, -a * w * w
        for start in range(0, len(self.t), self._CHUNK):
            chunk = slice(start, start + self._CHUNK)
            phase = w[..., None] * self.t[chunk] + p[..., None]  # (C, K, n)
            s, c = np.sin(phase), np.cos(phase)
            out[0, :, chunk] = np.einsum("ck,ckn->cn", a, s)
            out[1, :, chunk] = np.einsum("ck,ckn->cn", a1, c)
            out[2, :, chunk] = np.einsum("ck,ckn->cn", a2, s)
        return out


def smooth_step(u, derivatives: int = 3, integral: bool = False):
    """A smooth step from 0 to 1 with its derivatives, for speed changes, turns and tumble moves.

    ``S′(u) = (16/5) sin⁶(πu)`` is a bump of unit area on [0, 1], so::

        S(u) = u − (3/4π) sin 2πu + (3/20π) sin 4πu − (1/60π) sin 6πu

    held at 0 before ``u = 0`` and at 1 after ``u = 1``. Its first five derivatives vanish at both ends:
    a motion built from ``S`` is five times continuously differentiable, so ω, α and α̇ stay continuous
    even where ``S`` is composed with products (roll ∝ κ v²). The peak slope is ``S′(½) = 16/5``; the
    ``n``-th derivative of ``S′`` is at most ``(2π)ⁿ (1.5 + 0.6·2ⁿ + 0.1·3ⁿ)``.

    Parameters
    ----------
    u : array_like
        Normalised time or distance; values outside [0, 1] lie on the flat parts.
    derivatives : int
        How many derivatives to return (0 to 3).
    integral : bool
        Also return ``I(u) = ∫₀ᵘ S`` (``= u − ½`` for ``u ≥ 1``), e.g. for the distance over a speed
        change.

    Returns
    -------
    tuple of ndarray
        ``(S, S′, …, S^(derivatives))``, then ``I`` when asked for.
    """
    u = np.asarray(u, dtype=float)
    # On the flat parts S is 0 or 1 and its derivatives 0: evaluate the trigonometry where 0 < u < 1 only.
    rising = (u > 0.0) & (u < 1.0)
    out = [(u >= 1.0).astype(float)] + [np.zeros_like(u) for _ in range(derivatives)]
    if integral:
        out.append(np.where(u >= 1.0, u - 0.5, 0.0))
    if not rising.any():
        return tuple(out)
    where = slice(None) if rising.all() else np.flatnonzero(rising)
    x = u[where]
    c, s = np.cos(2 * np.pi * x), np.sin(2 * np.pi * x)
    # The harmonics of 4πu and 6πu in c = cos 2πu, s = sin 2πu, factored on (1 − c) = 2 sin² πu so
    # that the derivatives vanish exactly at the ends.
    out[0][where] = x - s * (22 - 9 * c + 2 * c * c) / (30 * np.pi)  # S
    if derivatives >= 1:
        out[1][where] = 0.4 * (1 - c) ** 3  # S′ = (16/5) sin⁶ πu
    if derivatives >= 2:
        out[2][where] = (12 * np.pi / 5) * s * (1 - c) ** 2  # S″
    if derivatives >= 3:
        out[3][where] = (24 * np.pi**2 / 5) * (1 - c) ** 2 * (2 + 3 * c)  # S‴
    if integral:
        out[-1][where] = 0.5 * x * x - (1 - c) * (109 - 23 * c + 4 * c * c) / (360 * np.pi**2)  # I
    return tuple(out)


def quat_from_rpy_deg(rpy_deg) -> np.ndarray:
    """Quaternion (4,) or (K, 4) of ``[roll, pitch, yaw]`` in degrees, ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    return quat_from_euler_zyx(np.radians(np.asarray(rpy_deg, dtype=float)))


def rotation_basis(axis, q_left=(1.0, 0.0, 0.0, 0.0), q_right=(1.0, 0.0, 0.0, 0.0)):
    """The two constant quaternions of a rotation about a fixed axis.

    ``q_left ⊗ exp(½ θ n) ⊗ q_right = cos(θ/2) A + sin(θ/2) B`` with ``A = q_left ⊗ q_right`` and
    ``B = q_left ⊗ (0, n) ⊗ q_right``: the quaternion is linear in the cosine and sine of the half angle.

    Parameters
    ----------
    axis : array_like (..., 3)
        Unit rotation axis ``n`` (in the frame between ``q_left`` and ``q_right``).
    q_left, q_right : array_like (..., 4)

    Returns
    -------
    A, B : ndarray (..., 4)
    """
    axis = np.asarray(axis, dtype=float)
    pure = np.concatenate([np.zeros(axis.shape[:-1] + (1,)), axis], axis=-1)
    return quat_multiply(q_left, q_right), quat_multiply(quat_multiply(q_left, pure), q_right)


def axis_rotation(angle, axis, q_left=(1.0, 0.0, 0.0, 0.0), q_right=(1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
    """Quaternions ``q_left ⊗ exp(½ θ n) ⊗ q_right`` (N, 4) for angles ``θ`` (N,), rad, about a unit
    axis ``n``."""
    half = 0.5 * np.asarray(angle, dtype=float)
    return half_angle_combination(np.cos(half), np.sin(half), *rotation_basis(axis, q_left, q_right))


def outer(x, v) -> np.ndarray:
    """``x[:, None] * v`` (N, k) for ``x`` (N,) and ``v`` (k,) or (N, k), filled column by column.

    Numpy broadcasting with a trailing axis of 3 or 4 runs its inner loop 3 or 4 elements long and is
    about six times slower than these k passes over N elements.
    """
    v = np.asarray(v, dtype=float)
    out = np.empty((len(x), v.shape[-1]))
    for i in range(v.shape[-1]):
        np.multiply(x, v[..., i], out=out[:, i])
    return out


def half_angle_combination(c, s, a, b) -> np.ndarray:
    """``c A + s B`` (N, 4): the quaternions of :func:`rotation_basis` from the half-angle cosines and
    sines ``c, s`` (N,); ``A, B`` are (4,) or, gathered per sample, (N, 4)."""
    q = outer(c, a)
    q += outer(s, b)
    return q


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise ValueError(f"{what} must be a non-zero vector")
    return v / norm


@dataclass(frozen=True, eq=False)
class WorldMotion:
    """A body's motion relative to the world (ENU) frame, sampled at ``t``: what a kind prescribes.

    Attributes (N samples, SI)
    ----------
    t : ndarray (N,)
        s.
    q_wb : ndarray (N, 4)
        Attitude, body to world.
    omega_wb_b, alpha_wb_b : ndarray (N, 3)
        Angular velocity of the body relative to the world, body axes, rad/s, and its derivative, rad/s².
    pos_w, vel_w, acc_w : ndarray (N, 3)
        Position, velocity, acceleration relative to the world frame, world axes: m, m/s, m/s².
    extras : dict of str to ndarray
        Truth particular to the kind (table angle, car speed, ...), first axis N.
    """

    t: np.ndarray
    q_wb: np.ndarray
    omega_wb_b: np.ndarray
    alpha_wb_b: np.ndarray
    pos_w: np.ndarray
    vel_w: np.ndarray
    acc_w: np.ndarray
    extras: dict = field(default_factory=dict)

    @classmethod
    def rotation_only(cls, t, q_wb, omega_wb_b, alpha_wb_b, extras=None) -> "WorldMotion":
        """A body that rotates about its fixed reference point at the world origin."""
        zeros = np.zeros((len(t), 3))
        return cls(t, q_wb, omega_wb_b, alpha_wb_b, zeros, zeros.copy(), zeros.copy(), extras or {})


CHUNK = 8192
"""Samples per part in :func:`in_chunks`: the temporaries (64 KiB each) stay in the CPU cache, which
makes closed forms with dozens of intermediate arrays (Euler angles, the car) 1.5–2 times faster on
10⁶ samples than one pass over the whole arrays, whose every temporary is fresh memory."""

_MOTION_ARRAYS = ("q_wb", "omega_wb_b", "alpha_wb_b", "pos_w", "vel_w", "acc_w")


def in_chunks(t, evaluate, chunk: int = CHUNK) -> WorldMotion:
    """``evaluate(t_part) -> WorldMotion`` on consecutive parts of ``t``, assembled into one WorldMotion.

    For closed forms with many intermediate arrays (Euler angles, the car); ``evaluate`` must hold
    everything that does not depend on time (schedules, series, transients) so that each call is cheap.
    """
    t = np.asarray(t, dtype=float)
    if len(t) <= chunk:
        return evaluate(t)
    out = extras = None
    for start in range(0, len(t), chunk):
        part = slice(start, start + chunk)
        m = evaluate(t[part])
        if out is None:
            out = {name: np.empty((len(t),) + getattr(m, name).shape[1:]) for name in _MOTION_ARRAYS}
            extras = {k: np.empty((len(t),) + v.shape[1:], dtype=v.dtype) for k, v in m.extras.items()}
        for name, array in out.items():
            array[part] = getattr(m, name)
        for k, array in extras.items():
            array[part] = m.extras[k]
    return WorldMotion(t, **out, extras=extras)


class EarthBoundSpec(ScenarioSpec):
    """Base of the kinds that move on the Earth at a ``[site]``: they prescribe :meth:`world_motion`."""

    site: Site = Field(default_factory=Site)

    def world_motion(self, t: np.ndarray) -> WorldMotion:
        """The motion relative to the world frame at the times ``t`` (N,), s."""
        raise NotImplementedError

    def evaluator(self):
        """A callable ``t -> WorldMotion`` with the time-independent setup (series, schedules) done once,
        for evaluating the motion piece by piece (a stream); by default :meth:`world_motion` itself."""
        return self.world_motion

    def trajectory(self, t) -> Trajectory:
        m = self.world_motion(np.asarray(t, dtype=float))
        return trajectory_from_world_motion(
            m.t,
            m.q_wb,
            m.omega_wb_b,
            m.alpha_wb_b,
            m.pos_w,
            m.vel_w,
            m.acc_w,
            self.site.environment(),
            m.extras,
        )


class Attitude(Section):
    """``[attitude]``: ``rpy_deg = [roll, pitch, yaw]``, degrees, ``R_wb = Rz(yaw) Ry(pitch) Rx(roll)``."""

    rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    def quat(self) -> np.ndarray:
        """``q_wb`` (4,)."""
        return quat_from_rpy_deg(self.rpy_deg)


# --------------------------------------------------------------------------------------------------
# static
# --------------------------------------------------------------------------------------------------


class StaticSpec(EarthBoundSpec):
    """``kind = "static"``: a body at rest on a bench, at the attitude ``[attitude] rpy_deg``.

    Relative to the (rotating) world frame nothing moves, so an ideal gyro reads the Earth rate
    ``R_bw Ω (0, cos φ, sin φ)`` and the accelerometer ``R_bw (0, 0, g(φ, h))``.
    """

    kind: Literal["static"] = "static"
    attitude: Attitude = Field(default_factory=Attitude)

    def world_motion(self, t):
        n = len(t)
        q = np.empty((n, 4))
        q[:] = self.attitude.quat()
        return WorldMotion.rotation_only(t, q, np.zeros((n, 3)), np.zeros((n, 3)))


# --------------------------------------------------------------------------------------------------
# rate-table
# --------------------------------------------------------------------------------------------------


class Table(Section):
    """``[table]``: how the table stands and how the body sits on it.

    The table top turns by the table angle ``θ`` about the z axis of its base frame, so that
    ``q_wb = q_base ⊗ Rz(θ) ⊗ q_mount``; in tumble mode the table top takes the listed attitudes
    relative to the base frame instead.

    Attributes
    ----------
    base_rpy_deg : attitude of the base frame in the world; its z axis is the table axis (default level:
        the axis points up).
    mount_rpy_deg : attitude of the body relative to the table top (the mounting rotation).
    lever_arm_m : the body's reference point relative to the point on the axis, table-top axes, m; off the
        axis the body feels the centripetal and tangential accelerations.
    """

    base_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    mount_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)


class ConstantRate(Section):
    """``[constant]``: the table turns at ``rate_deg_s`` from ``t = 0``: ``θ = θ0 + ω t``."""

    rate_deg_s: Real
    initial_angle_deg: Real = 0.0

    def angle(self, t):
        """Table angle, rate and acceleration (N,) each: rad, rad/s, rad/s²."""
        rate = np.radians(self.rate_deg_s)
        return np.radians(self.initial_angle_deg) + rate * t, np.full(len(t), rate), np.zeros(len(t))


class RateSteps(Section):
    """``[steps]``: a list of table rates, each held for its dwell time once reached.

    The table starts at rest at ``t = 0`` and changes rate at the constant angular acceleration
    ``max_accel_deg_s2`` (so the rate is continuous and the acceleration piecewise constant); the
    dwell at ``rates_deg_s[k]`` lasts ``dwell_s[k]`` after the rate is reached. After the last dwell the
    table keeps the last rate (end the list with 0 to stop it).
    """

    rates_deg_s: list[Real] = Field(min_length=1)
    dwell_s: list[PositiveReal]
    max_accel_deg_s2: PositiveReal
    initial_angle_deg: Real = 0.0

    @field_validator("dwell_s")
    @classmethod
    def _one_dwell_per_rate(cls, dwell, info: ValidationInfo):
        rates = info.data.get("rates_deg_s")
        if rates is not None and len(dwell) != len(rates):
            raise ValueError(f"needs one dwell time per rate: {len(rates)} rates, {len(dwell)} dwell times")
        return dwell

    def schedule(self):
        """Segments of constant acceleration: start time (s), angle (rad), rate (rad/s), accel (rad/s²).

        Returns four arrays (M,); segment ``m`` lasts from ``start[m]`` to ``start[m + 1]`` (the last one
        for ever). Ramps have ``accel = ±max_accel_deg_s2``, dwells 0.
        """
        max_accel = np.radians(self.max_accel_deg_s2)
        start, angle, rate, accel = [0.0], [np.radians(self.initial_angle_deg)], [0.0], []

        def run(duration, a, rate_after):
            """Close the open segment after ``duration`` at acceleration ``a``; open the next one."""
            accel.append(a)
            start.append(start[-1] + duration)
            angle.append(angle[-1] + rate[-1] * duration + 0.5 * a * duration**2)  # θ0 + ω0 τ + ½ a τ²
            rate.append(rate_after)

        for target, dwell in zip(np.radians(self.rates_deg_s), self.dwell_s):
            if target != rate[-1]:
                run(abs(target - rate[-1]) / max_accel, np.copysign(max_accel, target - rate[-1]), target)
            run(dwell, 0.0, target)
        accel.append(0.0)  # the last rate is held
        return np.array(start), np.array(angle), np.array(rate), np.array(accel)

    def angle(self, t):
        """Table angle, rate and acceleration (N,) each: piecewise quadratic, linear, constant."""
        start, angle0, rate0, accel = self.schedule()
        k = np.clip(np.searchsorted(start, t, side="right") - 1, 0, None)
        tau = t - start[k]
        a = accel[k]
        rate = rate0[k] + a * tau
        return angle0[k] + (rate0[k] + 0.5 * a * tau) * tau, rate, a


class Tumble(Section):
    """``[tumble]``: the table top dwells at each listed attitude, then turns smoothly to the next.

    ``rpy_deg`` lists table-top attitudes relative to the base frame (with the default level base and
    mount: the body's attitudes in the world; the six faces up are ``[0,0,0]``, ``[180,0,0]``,
    ``[90,0,0]``, ``[-90,0,0]``, ``[0,-90,0]``, ``[0,90,0]``: z, −z, y, −y, x, −x up). Position ``k`` is
    held from ``k (dwell_s + move_s)`` for ``dwell_s``; the move to the next takes ``move_s`` and turns
    about the fixed axis of the relative rotation (the shortest way, as a two-axis table or a hand on a
    precision cube does), with angle ``φ S(τ/move_s)`` (:func:`smooth_step`), so that the rate rises and
    falls smoothly to a peak of ``(16/5) φ / move_s``. After the last position the table stays there.
    """

    rpy_deg: list[Vec3] = Field(min_length=1)
    dwell_s: PositiveReal
    move_s: PositiveReal

    def schedule(self):
        """Positions as quaternions (K, 4) and the rotation vectors (K, 3) of the moves from each to the
        next in table-top axes (the last one zero), rad."""
        q = quat_from_rpy_deg(np.asarray(self.rpy_deg, dtype=float).reshape(-1, 3))
        moves = np.zeros((len(q), 3))
        moves[:-1] = quat_to_rotvec(quat_multiply(quat_conjugate(q[:-1]), q[1:]))
        return q, moves


class RateTableSpec(EarthBoundSpec):
    """``kind = "rate-table"``: a single-axis rate table on the bench, in one of three modes.

    Give exactly one of the tables ``[constant]``, ``[steps]`` or ``[tumble]``, and optionally
    ``[table]`` (base attitude, mounting rotation, lever arm).

    For the turning modes ``q_wb = q_base ⊗ Rz(θ) ⊗ q_mount``: the body turns about the fixed body axis
    ``u_b = R_mount^T e_z``, so ``ω_wb = θ̇ u_b`` and ``α_wb = θ̈ u_b``. A body at lever arm ``r``
    (table-top axes) from the axis moves on a circle: ``p = R_wt r``, ``v = ω × p`` and
    ``a = α × p + ω × (ω × p)`` with ``ω = θ̇ n_w``, ``α = θ̈ n_w`` about the world axis ``n_w = R_base e_z``.
    """

    kind: Literal["rate-table"] = "rate-table"
    table: Table = Field(default_factory=Table)
    constant: ConstantRate | None = None
    steps: RateSteps | None = None
    tumble: Tumble | None = None

    @field_validator("steps", "tumble")
    @classmethod
    def _one_mode(cls, value, info: ValidationInfo):
        given = [m for m in ("constant", "steps") if m != info.field_name and info.data.get(m) is not None]
        if value is not None and given:
            raise ValueError(f"give one mode table only, not both [{given[0]}] and [{info.field_name}]")
        return value

    @model_validator(mode="after")
    def _a_mode(self):
        if self.constant is None and self.steps is None and self.tumble is None:
            raise ValueError("a rate table needs one mode table: [constant], [steps] or [tumble]")
        return self

    @property
    def mode(self) -> str:
        return next(m for m in ("constant", "steps", "tumble") if getattr(self, m) is not None)

    def world_motion(self, t):
        q_base = quat_from_rpy_deg(self.table.base_rpy_deg)
        q_mount = quat_from_rpy_deg(self.table.mount_rpy_deg)
        if self.tumble is not None:
            return self._tumble_motion(t, q_base, q_mount)
        mode = getattr(self, self.mode)
        angle, rate, accel = mode.angle(t)
        if self.constant is not None:  # θ/2 = θ0/2 + (ω/2) t: cosine and sine by angle addition
            c, s = TimeGrid(t).cos_sin(
                0.5 * np.radians(mode.rate_deg_s), 0.5 * np.radians(mode.initial_angle_deg)
            )
        else:
            c, s = np.cos(0.5 * angle), np.sin(0.5 * angle)
        # q_wb = q_base ⊗ Rz(θ) ⊗ q_mount
        q = half_angle_combination(c, s, *rotation_basis(_E_Z, q_base, q_mount))
        axis_b = quat_rotate(quat_conjugate(q_mount), _E_Z)  # u_b = R_mount^T e_z
        motion = WorldMotion.rotation_only(
            t,
            q,
            outer(rate, axis_b),
            outer(accel, axis_b),
            extras={"table_angle_rad": angle, "table_rate_rad_s": rate},
        )
        lever = np.asarray(self.table.lever_arm_m, dtype=float)
        if not lever.any():
            return motion
        # p = R_base Rz(θ) r, with cos θ = c² − s², sin θ = 2 s c from the half angle.
        cos, sin = c * c - s * s, 2 * s * c
        p_base = np.stack(
            [lever[0] * cos - lever[1] * sin, lever[0] * sin + lever[1] * cos, np.full_like(cos, lever[2])],
            -1,
        )
        pos = quat_rotate(q_base, p_base)
        n_w = quat_rotate(q_base, _E_Z)
        n_x_p = np.cross(n_w, pos)
        vel = outer(rate, n_x_p)  # v = θ̇ n × p
        # a = θ̈ n × p + θ̇² n × (n × p)
        acc = outer(accel, n_x_p) + outer(rate * rate, np.cross(n_w, n_x_p))
        return WorldMotion(t, q, motion.omega_wb_b, motion.alpha_wb_b, pos, vel, acc, motion.extras)

    def _tumble_motion(self, t, q_base, q_mount):
        tumble = self.tumble
        positions, moves = tumble.schedule()
        angles = np.linalg.norm(moves, axis=1)  # |φ_k|, rad
        axes = moves / np.where(angles > 0, angles, 1.0)[:, None]  # φ̂_k, table-top axes
        # q_wb = q_base ⊗ q_k ⊗ exp(½ S φ_k) ⊗ q_mount = cos(S|φ|/2) A_k + sin(S|φ|/2) B_k
        a, b = rotation_basis(axes, quat_multiply(q_base, positions), q_mount)
        axes_b = quat_rotate(quat_conjugate(q_mount), axes)  # R_mount^T φ̂_k
        period = tumble.dwell_s + tumble.move_s
        lever = np.asarray(self.table.lever_arm_m, dtype=float)

        def evaluate(t):
            k = np.clip(np.floor(t / period), 0, len(positions) - 1).astype(np.intp)
            # u ≤ 0 while dwelling, 0 → 1 while moving
            u = (t - k * period - tumble.dwell_s) / tumble.move_s
            step, slope, curvature = smooth_step(u, derivatives=2)
            angle = angles[k]
            # While dwelling the half angle is 0: cos 1, sin 0; the trigonometry only for the moves.
            c, s = np.ones_like(t), np.zeros_like(t)
            moving = np.flatnonzero(step * angle)
            half = 0.5 * angle[moving] * step[moving]
            c[moving], s[moving] = np.cos(half), np.sin(half)
            q = half_angle_combination(c, s, a[k], b[k])
            rate = angle * slope / tumble.move_s  # d/dt (S |φ|) = |φ| S′ / T
            accel = angle * curvature / tumble.move_s**2
            motion = WorldMotion.rotation_only(t, q, outer(rate, axes_b[k]), outer(accel, axes_b[k]))
            if not lever.any():
                return motion
            # Rigid lever arm on the table top:
            # p = R_wt r,  v = R_wt (ω_t × r),  a = R_wt (α_t × r + ω_t × (ω_t × r)).
            q_wt = quat_multiply(q, quat_conjugate(q_mount))
            omega_t, alpha_t = outer(rate, axes[k]), outer(accel, axes[k])
            w_x_r = np.cross(omega_t, lever)
            pos = quat_rotate(q_wt, lever)
            vel = quat_rotate(q_wt, w_x_r)
            acc = quat_rotate(q_wt, np.cross(alpha_t, lever) + np.cross(omega_t, w_x_r))
            return WorldMotion(t, q, motion.omega_wb_b, motion.alpha_wb_b, pos, vel, acc)

        return in_chunks(t, evaluate)


# --------------------------------------------------------------------------------------------------
# oscillation
# --------------------------------------------------------------------------------------------------


class AngularOscillation(Section):
    """``[angular]``: ``θ(t) = A sin(2π f t + φ)`` about the body axis ``axis_b`` (normalised)."""

    axis_b: Vec3 = (1.0, 0.0, 0.0)
    amplitude_deg: NonNegativeReal
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0

    @field_validator("axis_b")
    @classmethod
    def _nonzero(cls, axis):
        _unit(axis, "the oscillation axis")
        return axis


class LinearOscillation(Section):
    """``[linear]``: ``p(t) = a sin(2π f t + φ)`` with the amplitude vector ``a`` in world (ENU) axes."""

    amplitude_m: Vec3
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0


class OscillationSpec(EarthBoundSpec):
    """``kind = "oscillation"``: angular oscillation about a body axis, optionally a linear oscillation.

    ``q_wb = q_0 ⊗ exp(½ θ(t) n_b)`` with the mean attitude ``q_0`` (``[attitude]``): a rotation about a
    fixed body axis, so ``ω_wb = θ̇ n_b``, ``α_wb = θ̈ n_b`` exactly.
    """

    kind: Literal["oscillation"] = "oscillation"
    attitude: Attitude = Field(default_factory=Attitude)
    angular: AngularOscillation
    linear: LinearOscillation | None = None

    def world_motion(self, t):
        grid = TimeGrid(t)
        osc = self.angular
        axis = _unit(osc.axis_b, "axis_b")
        angle, rate, accel = grid.sum_of_sines(
            np.radians(osc.amplitude_deg), 2 * np.pi * osc.frequency_hz, np.radians(osc.phase_deg)
        )[:, 0]
        q = axis_rotation(angle, axis, q_left=self.attitude.quat())
        motion = WorldMotion.rotation_only(t, q, outer(rate, axis), outer(accel, axis))
        if self.linear is None:
            return motion
        lin = self.linear
        amplitude = np.asarray(lin.amplitude_m, dtype=float)[:, None]
        # Each world axis: a_i sin(2π f t + φ); one channel per axis, (3 derivatives, 3 axes, N).
        pos, vel, acc = grid.sum_of_sines(amplitude, 2 * np.pi * lin.frequency_hz, np.radians(lin.phase_deg))
        return WorldMotion(
            t, q, motion.omega_wb_b, motion.alpha_wb_b, pos.T.copy(), vel.T.copy(), acc.T
        )


# --------------------------------------------------------------------------------------------------
# coning
# --------------------------------------------------------------------------------------------------


class Coning(Section):
    """``[coning]``: classical coning of half-angle ``half_angle_deg`` at ``frequency_hz``.

    ``reference_rpy_deg`` is the attitude of the cone's reference frame in the world; the body x axis
    sweeps the cone about the reference x axis (``[0, -90, 0]`` points that axis up).
    """

    half_angle_deg: Annotated[Real, Field(gt=0, lt=180)]
    frequency_hz: PositiveReal
    reference_rpy_deg: Vec3 = (0.0, 0.0, 0.0)


class ConingSpec(EarthBoundSpec):
    """``kind = "coning"``: classical coning motion (Savage 1998, part 1).

    The attitude relative to the reference frame is the rotation vector of constant length ``θ`` (the
    cone half-angle) whose direction turns at ``Ω`` in the reference y-z plane::

        φ(t) = θ (0, cos Ωt, sin Ωt),   q_rb = (cos θ/2, sin θ/2 (0, cos Ωt, sin Ωt))

    so the body x axis stays at the angle ``θ`` from the reference x axis. From ``ω = 2 (q* ⊗ q̇)_vec``::

        ω_b = (−Ω (1 − cos θ), −Ω sin θ sin Ωt, Ω sin θ cos Ωt)
        α_b = (0, −Ω² sin θ cos Ωt, −Ω² sin θ sin Ωt)

    The attitude returns to itself every cycle, yet ω has the constant component ``−Ω (1 − cos θ)``
    along x: its integral over a cycle is ``(−2π (1 − cos θ), 0, 0)``, not zero. Integrating the rate
    vector as if it were a rotation vector is wrong by that much per cycle; coning algorithms exist to
    account for the non-commutativity of the rotations.
    """

    kind: Literal["coning"] = "coning"
    coning: Coning

    def world_motion(self, t):
        cone = self.coning
        theta, omega = np.radians(cone.half_angle_deg), 2 * np.pi * cone.frequency_hz
        cos_t, sin_t = TimeGrid(t).cos_sin(omega)
        q_ref = quat_from_rpy_deg(cone.reference_rpy_deg)
        # q_wb = q_ref ⊗ q_rb = cos(θ/2) q_ref + sin(θ/2) [cos Ωt (q_ref ⊗ j) + sin Ωt (q_ref ⊗ k)]
        j, k = quat_multiply(q_ref, [0.0, 0.0, 1.0, 0.0]), quat_multiply(q_ref, [0.0, 0.0, 0.0, 1.0])
        q = half_angle_combination(cos_t, sin_t, np.sin(theta / 2) * j, np.sin(theta / 2) * k)
        q += np.cos(theta / 2) * q_ref
        w = omega * np.sin(theta)
        rate = np.empty((len(t), 3))
        rate[:, 0] = -omega * (1 - np.cos(theta))
        rate[:, 1] = -w * sin_t
        rate[:, 2] = w * cos_t
        accel = np.empty((len(t), 3))
        accel[:, 0] = 0.0
        accel[:, 1] = -omega * w * cos_t
        accel[:, 2] = -omega * w * sin_t
        return WorldMotion.rotation_only(t, q, rate, accel)


# --------------------------------------------------------------------------------------------------
# sculling
# --------------------------------------------------------------------------------------------------


class Sculling(Section):
    """``[sculling]``: angular oscillation about the reference x axis, linear along the reference y axis.

    ``θ(t) = θ0 sin Ωt`` about x; the body's acceleration along y is ``A sin(Ωt + φ)`` (displacement
    ``−A/Ω² sin(Ωt + φ)``), in phase with the angle for ``phase_deg = 0``.
    """

    angular_amplitude_deg: Annotated[Real, Field(gt=0, le=90)]
    acceleration_amplitude_m_s2: PositiveReal
    frequency_hz: PositiveReal
    phase_deg: Real = 0.0
    reference_rpy_deg: Vec3 = (0.0, 0.0, 0.0)


class ScullingSpec(EarthBoundSpec):
    """``kind = "sculling"``: the classical sculling motion (Savage 1998, part 2).

    The body rocks about the reference x axis, ``q_wb = q_ref ⊗ exp(½ θ0 sin(Ωt) e_x)``, while its
    reference point oscillates along the (world-fixed) reference y axis with acceleration
    ``a_y = A sin(Ωt + φ)``. In body axes the non-gravitational specific force is
    ``R_x(θ)^T (0, a_y, 0) = a_y (0, cos θ, −sin θ)``: its z component
    ``−A sin(Ωt + φ) sin(θ0 sin Ωt)`` has a non-zero mean, by the Jacobi–Anger expansion
    ``sin(θ0 sin x) = 2 Σ_k J_{2k+1}(θ0) sin((2k+1)x)``::

        ⟨f_z⟩ = −A J₁(θ0) cos φ  ≈  −½ A θ0 cos φ

    This is the rectified specific force of sculling: accelerometers read a steady force although the
    body goes nowhere, and a velocity algorithm that sums body-axis velocity increments without the
    sculling term drifts by it. (Savage poses the same kinematics from the body side: pure sinusoids
    in body axes, and the rectification ``+A J₁(θ0)`` appears as a real acceleration in the navigation
    frame; here the motion stays bounded, as on a test rig.)
    """

    kind: Literal["sculling"] = "sculling"
    sculling: Sculling

    def world_motion(self, t):
        sc = self.sculling
        omega = 2 * np.pi * sc.frequency_hz
        theta0, accel_amp = np.radians(sc.angular_amplitude_deg), sc.acceleration_amplitude_m_s2
        grid = TimeGrid(t)
        # Channel 0: θ = θ0 sin Ωt.
        # Channel 1: displacement y = −A/Ω² sin(Ωt + φ), so that ÿ = A sin(Ωt + φ).
        (angle, y), (rate, vy), (accel, ay) = grid.sum_of_sines(
            [[theta0], [-accel_amp / omega**2]], omega, [[0.0], [np.radians(sc.phase_deg)]]
        )
        q_ref = quat_from_rpy_deg(sc.reference_rpy_deg)
        e_x = np.array([1.0, 0.0, 0.0])
        q = axis_rotation(angle, e_x, q_left=q_ref)
        y_w = quat_rotate(q_ref, [0.0, 1.0, 0.0])  # the reference y axis in the world
        return WorldMotion(
            t, q, outer(rate, e_x), outer(accel, e_x), outer(y, y_w), outer(vy, y_w), outer(ay, y_w)
        )
