"""Prescribed motions in closed form: a bench, a rate table, oscillation, coning and sculling.

Every kind here stands on the Earth at a site (the optional ``[site]`` table, :class:`~gyroemu.dynamics.earth.Site`)
and prescribes its motion *relative to the local ENU world frame* analytically: attitude ``q_wb``, body
rate ``ω_wb`` and its derivative ``α_wb`` (body axes), position, velocity and acceleration (world axes),
each a closed-form function of time evaluated on arrays of samples (vectorised, no loop over samples).
No kind integrates anything. :func:`~gyroemu.dynamics.trajectory.trajectory_from_world_motion` then adds what
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

Each kind is an :class:`~gyroemu.dynamics.prescribed.EarthBoundSpec` that returns a
:class:`~gyroemu.dynamics.prescribed.WorldMotion` (the prescribed-motion base, shared with
:mod:`gyroemu.dynamics.vehicles`), and evaluates its closed forms in one compiled kernel (numba) that writes
every output once, block by block, from the compiled building blocks of :mod:`gyroemu.dynamics.motion_kernels`
(:class:`~gyroemu.dynamics.motion_kernels.TimeGrid` and its ``phasor_block``, ``sines_block``; ``sin_cos``,
``sincos_block``, ``smooth_step_at``, ``rotation_basis``; see "Speed" there).

Attitudes in config files are ``rpy_deg = [roll, pitch, yaw]`` in degrees with
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`gyroemu.dynamics.rotation.quat_from_euler_zyx`); in the ENU world,
yaw 0 points body x east, yaw 90 north.

References
----------
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 1: attitude algorithms",
J. Guidance, Control, and Dynamics 21(1), 19–28, 1998 (coning).
P. G. Savage, "Strapdown inertial navigation integration algorithm design, part 2: velocity and position
algorithms", J. Guidance, Control, and Dynamics 21(2), 208–221, 1998 (sculling).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, ValidationInfo, field_validator, model_validator

from .config import AngleDeg, AnglesDeg, NonNegativeReal, PositiveReal, Real, Section, Vec3
from .jit import njit
from .motion_kernels import (
    PhasorTable,
    SinesTable,
    TimeGrid,
    cross_xyz,
    phasor_block,
    quat_rotate_xyz,
    rotation_basis,
    segment_index,
    sin_cos,
    sincos_block,
    sines_block,
    smooth_step_at,
)
from .prescribed import Attitude, EarthBoundSpec, WorldMotion, motion_arrays, quat_from_rpy_deg
from .rotation import quat_conjugate, quat_multiply, quat_rotate, quat_to_rotvec

__all__ = [
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

_E_Z = np.array([0.0, 0.0, 1.0])


def _unit(v: ArrayLike, what: str) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=float)
    norm = np.linalg.norm(v)
    if not norm > 0:
        raise ValueError(f"{what} must be a non-zero vector")
    unit: NDArray[np.float64] = v / norm
    return unit


# --------------------------------------------------------------------------------------------------
# static
# --------------------------------------------------------------------------------------------------


class StaticSpec(EarthBoundSpec):
    """``kind = "static"``: a body at rest on a bench, at the attitude ``[attitude] rpy_deg``.

    Relative to the (rotating) world frame nothing moves, so an ideal gyro reads the Earth rate
    ``R_bw Ω (0, cos φ, sin φ)`` and the accelerometer ``R_bw (0, 0, g(φ, h))``.
    """

    kind: Literal["static"] = "static"
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    attitude: Attitude = Field(default_factory=Attitude)

    def world_motion(self, t: NDArray[np.float64]) -> WorldMotion:
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

    base_rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)
    mount_rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)


class ConstantRate(Section):
    """``[constant]``: the table turns at ``rate_deg_s`` from ``t = 0``: ``θ = θ0 + ω t``."""

    rate_deg_s: Real
    initial_angle_deg: AngleDeg = 0.0


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
    initial_angle_deg: AngleDeg = 0.0

    @field_validator("dwell_s")
    @classmethod
    def _one_dwell_per_rate(cls, dwell: list[float], info: ValidationInfo) -> list[float]:
        rates = info.data.get("rates_deg_s")
        if rates is not None and len(dwell) != len(rates):
            raise ValueError(f"needs one dwell time per rate: {len(rates)} rates, {len(dwell)} dwell times")
        return dwell

    def schedule(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Segments of constant acceleration: start time (s), angle (rad), rate (rad/s), accel (rad/s²).

        Returns four arrays (M,); segment ``m`` lasts from ``start[m]`` to ``start[m + 1]`` (the last one
        for ever). Ramps have ``accel = ±max_accel_deg_s2``, dwells 0.
        """
        max_accel = np.radians(self.max_accel_deg_s2)
        start, angle, rate, accel = [0.0], [np.radians(self.initial_angle_deg)], [0.0], []

        def run(duration: float, a: float, rate_after: float) -> None:
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

    def angle(self, t: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
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

    def schedule(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
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
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    table: Table = Field(default_factory=Table)
    constant: ConstantRate | None = None
    steps: RateSteps | None = None
    tumble: Tumble | None = None

    @field_validator("steps", "tumble")
    @classmethod
    def _one_mode(cls, value: RateSteps | Tumble | None, info: ValidationInfo) -> RateSteps | Tumble | None:
        given = [m for m in ("constant", "steps") if m != info.field_name and info.data.get(m) is not None]
        if value is not None and given:
            raise ValueError(f"give one mode table only, not both [{given[0]}] and [{info.field_name}]")
        return value

    @model_validator(mode="after")
    def _a_mode(self) -> RateTableSpec:
        if self.constant is None and self.steps is None and self.tumble is None:
            raise ValueError("a rate table needs one mode table: [constant], [steps] or [tumble]")
        return self

    @property
    def mode(self) -> str:
        return next(m for m in ("constant", "steps", "tumble") if getattr(self, m) is not None)

    def world_motion(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        q_base = quat_from_rpy_deg(self.table.base_rpy_deg)
        q_mount = quat_from_rpy_deg(self.table.mount_rpy_deg)
        if self.tumble is not None:
            return self._tumble_motion(t, q_base, q_mount)
        grid = TimeGrid(t)
        if self.constant is not None:
            # θ = θ0 + ω t: one segment of the schedule (the steps' formulas give exactly θ0 + ω t), and
            # θ/2 = θ0/2 + (ω/2) t, cosine and sine by angle addition.
            rate = np.radians(self.constant.rate_deg_s)
            initial = np.radians(self.constant.initial_angle_deg)
            schedule = tuple(np.array([x]) for x in (0.0, initial, rate, 0.0))
            half = grid.phasor(0.5 * rate, 0.5 * initial)
        else:
            assert self.steps is not None  # neither tumble nor constant: the steps (_a_mode holds one mode)
            schedule = self.steps.schedule()
            half = grid.phasor(0.0)  # unused: cos(θ/2), sin(θ/2) directly
        # q_wb = q_base ⊗ Rz(θ) ⊗ q_mount = cos(θ/2) A + sin(θ/2) B
        a, b = rotation_basis(_E_Z, q_base, q_mount)
        axis_b = quat_rotate(quat_conjugate(q_mount), _E_Z)  # u_b = R_mount^T e_z
        n = len(t)
        lever = np.asarray(self.table.lever_arm_m, dtype=float)
        arrays = motion_arrays(n, moves=bool(lever.any()))
        angle, rate = np.empty(n), np.empty(n)
        _rate_table_kernel(
            t,
            grid.uniform,
            grid.BLOCK,
            schedule,
            half,
            self.constant is not None,
            a,
            b,
            axis_b,
            q_base,
            lever,
            *arrays,
            angle,
            rate,
        )
        return WorldMotion(t, *arrays, extras={"table_angle_rad": angle, "table_rate_rad_s": rate})

    def _tumble_motion(
        self, t: NDArray[np.float64], q_base: NDArray[np.float64], q_mount: NDArray[np.float64]
    ) -> WorldMotion:
        tumble = self.tumble
        assert tumble is not None  # world_motion calls this in tumble mode only
        positions, moves = tumble.schedule()
        angles = np.linalg.norm(moves, axis=1)  # |φ_k|, rad
        axes = moves / np.where(angles > 0, angles, 1.0)[:, None]  # φ̂_k, table-top axes
        # q_wb = q_base ⊗ q_k ⊗ exp(½ S φ_k) ⊗ q_mount = cos(S|φ|/2) A_k + sin(S|φ|/2) B_k
        a, b = rotation_basis(axes, quat_multiply(q_base, positions), q_mount)
        axes_b = quat_rotate(quat_conjugate(q_mount), axes)  # R_mount^T φ̂_k
        lever = np.asarray(self.table.lever_arm_m, dtype=float)
        arrays = motion_arrays(len(t), moves=bool(lever.any()))
        _tumble_kernel(
            t,
            tumble.dwell_s + tumble.move_s,
            tumble.dwell_s,
            tumble.move_s,
            angles,
            a,
            b,
            axes,
            axes_b,
            quat_conjugate(q_mount),
            lever,
            *arrays,
        )
        return WorldMotion(t, *arrays)


@njit
def _rate_table_kernel(
    t: NDArray[np.float64],
    uniform: bool,
    block: int,
    schedule: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    half: PhasorTable,
    by_phasor: bool,
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    axis_b: NDArray[np.float64],
    q_base: NDArray[np.float64],
    lever: NDArray[np.float64],
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    pos: NDArray[np.float64],
    vel: NDArray[np.float64],
    acc: NDArray[np.float64],
    angle_out: NDArray[np.float64],
    rate_out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """:meth:`RateTableSpec.world_motion` in the turning modes, block by block.

    ``schedule``: segments of constant angular acceleration (:meth:`RateSteps.schedule`), which give the
    table angle, rate and acceleration of each sample. ``cos(θ/2)``, ``sin(θ/2)`` of the block come from
    the phasor ``half`` of ``θ/2`` (:meth:`TimeGrid.phasor`) when ``by_phasor`` (constant rate), else from
    :func:`sincos_block`.
    """
    start_s, angle0, rate0, accel0 = schedule
    n_w = quat_rotate_xyz(q_base, 0.0, 0.0, 1.0)  # the table axis in the world
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    c, s, half_angle, accels = np.empty(block), np.empty(block), np.empty(block), np.empty(block)
    k = 0
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        for i in range(count):
            j = start + i
            k = segment_index(start_s, t[j], k)
            tau = t[j] - start_s[k]
            accels[i] = accel0[k]
            rate_out[j] = rate0[k] + accel0[k] * tau
            angle_out[j] = angle0[k] + (rate0[k] + 0.5 * accel0[k] * tau) * tau  # θ0 + ω0 τ + ½ a τ²
            half_angle[i] = 0.5 * angle_out[j]
        if by_phasor:
            phasor_block(t, start, count, uniform, half, c, s)
        else:
            sincos_block(half_angle, count, s, c)
        for i in range(count):
            j = start + i
            rate, accel = rate_out[j], accels[i]
            for m in range(4):
                q[j, m] = c[i] * a[m] + s[i] * b[m]
            for m in range(3):
                omega[j, m] = rate * axis_b[m]  # ω_wb = θ̇ u_b
                alpha[j, m] = accel * axis_b[m]  # α_wb = θ̈ u_b
            if has_lever:
                # p = R_base Rz(θ) r, with cos θ = c² − s², sin θ = 2 s c from the half angle.
                cos, sin = c[i] * c[i] - s[i] * s[i], 2 * s[i] * c[i]
                px, py, pz = quat_rotate_xyz(
                    q_base, lever[0] * cos - lever[1] * sin, lever[0] * sin + lever[1] * cos, lever[2]
                )
                # v = θ̇ n × p,  a = θ̈ n × p + θ̇² n × (n × p)
                nx, ny, nz = cross_xyz(n_w[0], n_w[1], n_w[2], px, py, pz)
                nnx, nny, nnz = cross_xyz(n_w[0], n_w[1], n_w[2], nx, ny, nz)
                rate2 = rate * rate
                pos[j, 0], pos[j, 1], pos[j, 2] = px, py, pz
                vel[j, 0], vel[j, 1], vel[j, 2] = rate * nx, rate * ny, rate * nz
                acc[j, 0] = accel * nx + rate2 * nnx
                acc[j, 1] = accel * ny + rate2 * nny
                acc[j, 2] = accel * nz + rate2 * nnz


@njit
def _tumble_kernel(
    t: NDArray[np.float64],
    period: float,
    dwell: float,
    move: float,
    angles: NDArray[np.float64],
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    axes: NDArray[np.float64],
    axes_b: NDArray[np.float64],
    q_mount_conj: NDArray[np.float64],
    lever: NDArray[np.float64],
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    pos: NDArray[np.float64],
    vel: NDArray[np.float64],
    acc: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The tumble of :meth:`RateTableSpec._tumble_motion`, one pass over the samples."""
    has_lever = lever[0] != 0.0 or lever[1] != 0.0 or lever[2] != 0.0
    last = len(angles) - 1
    for j in range(len(t)):
        k = int(min(max(np.floor(t[j] / period), 0.0), last))
        # u ≤ 0 while dwelling, 0 → 1 while moving
        u = (t[j] - k * period - dwell) / move
        step, slope, curvature, _, _ = smooth_step_at(u)
        angle = angles[k]
        # While dwelling the half angle is 0: cos 1, sin 0; the trigonometry only for the moves.
        c, s = 1.0, 0.0
        if step * angle != 0.0:
            s, c = sin_cos(0.5 * angle * step)
        for m in range(4):
            q[j, m] = c * a[k, m] + s * b[k, m]
        rate = angle * slope / move  # d/dt (S |φ|) = |φ| S′ / T
        accel = angle * curvature / (move * move)
        for m in range(3):
            omega[j, m] = rate * axes_b[k, m]
            alpha[j, m] = accel * axes_b[k, m]
        if has_lever:
            # Rigid lever arm on the table top:
            # p = R_wt r,  v = R_wt (ω_t × r),  a = R_wt (α_t × r + ω_t × (ω_t × r)),  q_wt = q_wb ⊗ q_mount*.
            pw, px, py, pz = q[j, 0], q[j, 1], q[j, 2], q[j, 3]
            mw, mx, my, mz = q_mount_conj[0], q_mount_conj[1], q_mount_conj[2], q_mount_conj[3]
            q_wt = (
                pw * mw - px * mx - py * my - pz * mz,
                pw * mx + px * mw + py * mz - pz * my,
                pw * my - px * mz + py * mw + pz * mx,
                pw * mz + px * my - py * mx + pz * mw,
            )
            wx, wy, wz = rate * axes[k, 0], rate * axes[k, 1], rate * axes[k, 2]
            ax, ay, az = accel * axes[k, 0], accel * axes[k, 1], accel * axes[k, 2]
            wrx, wry, wrz = cross_xyz(wx, wy, wz, lever[0], lever[1], lever[2])
            arx, ary, arz = cross_xyz(ax, ay, az, lever[0], lever[1], lever[2])
            wwx, wwy, wwz = cross_xyz(wx, wy, wz, wrx, wry, wrz)
            pos[j, 0], pos[j, 1], pos[j, 2] = quat_rotate_xyz(q_wt, lever[0], lever[1], lever[2])
            vel[j, 0], vel[j, 1], vel[j, 2] = quat_rotate_xyz(q_wt, wrx, wry, wrz)
            acc[j, 0], acc[j, 1], acc[j, 2] = quat_rotate_xyz(q_wt, arx + wwx, ary + wwy, arz + wwz)


# --------------------------------------------------------------------------------------------------
# oscillation
# --------------------------------------------------------------------------------------------------


class AngularOscillation(Section):
    """``[angular]``: ``θ(t) = A sin(2π f t + φ)`` about the body axis ``axis_b`` (normalised)."""

    axis_b: Vec3 = (1.0, 0.0, 0.0)
    amplitude_deg: NonNegativeReal
    frequency_hz: PositiveReal
    phase_deg: AngleDeg = 0.0

    @field_validator("axis_b")
    @classmethod
    def _nonzero(cls, axis: Vec3) -> Vec3:
        _unit(axis, "the oscillation axis")
        return axis


class LinearOscillation(Section):
    """``[linear]``: ``p(t) = a sin(2π f t + φ)`` with the amplitude vector ``a`` in world (ENU) axes."""

    amplitude_m: Vec3
    frequency_hz: PositiveReal
    phase_deg: AngleDeg = 0.0


class OscillationSpec(EarthBoundSpec):
    """``kind = "oscillation"``: angular oscillation about a body axis, optionally a linear oscillation.

    ``q_wb = q_0 ⊗ exp(½ θ(t) n_b)`` with the mean attitude ``q_0`` (``[attitude]``): a rotation about a
    fixed body axis, so ``ω_wb = θ̇ n_b``, ``α_wb = θ̈ n_b`` exactly.
    """

    kind: Literal["oscillation"] = "oscillation"
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    attitude: Attitude = Field(default_factory=Attitude)
    angular: AngularOscillation
    linear: LinearOscillation | None = None

    def world_motion(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        grid = TimeGrid(t)
        osc = self.angular
        axis = _unit(osc.axis_b, "axis_b")
        # Channels (amplitude, ω, φ): θ = A sin(2π f t + φ); with [linear] the position along the
        # amplitude vector a, sin(2π f_l t + φ_l).
        channels = [(np.radians(osc.amplitude_deg), 2 * np.pi * osc.frequency_hz, np.radians(osc.phase_deg))]
        directions = np.zeros((0, 3))
        if self.linear is not None:
            lin = self.linear
            channels.append((1.0, 2 * np.pi * lin.frequency_hz, np.radians(lin.phase_deg)))
            directions = np.asarray(lin.amplitude_m, dtype=float)[None, :]
        sines = grid.sines(*np.array(channels).T[:, :, None])  # each (C, 1)
        a, b = rotation_basis(axis, self.attitude.quat())
        arrays = motion_arrays(len(t), moves=self.linear is not None)
        _axis_oscillation_kernel(t, grid.uniform, grid.BLOCK, sines, a, b, axis, directions, *arrays)
        return WorldMotion(t, *arrays)


@njit
def _axis_oscillation_kernel(
    t: NDArray[np.float64],
    uniform: bool,
    block: int,
    sines: SinesTable,
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    axis: NDArray[np.float64],
    directions: NDArray[np.float64],
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    pos: NDArray[np.float64],
    vel: NDArray[np.float64],
    acc: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """Oscillation about a fixed body axis with linear oscillations, block by block (oscillation, sculling).

    Channel 0 of the sums of sinusoids ``sines`` is the angle θ about ``axis`` (body axes):
    ``q_wb = cos(θ/2) A + sin(θ/2) B`` (:func:`rotation_basis`), ``ω_wb = θ̇ n``, ``α_wb = θ̈ n``. Each
    further channel ``c`` moves the body along the world vector ``directions[c − 1]`` (position,
    velocity and acceleration: the channel's value and derivatives times it).
    """
    channels = sines[0].shape[0]
    buf = np.empty((3, channels, block))
    half, c, s = np.empty(block), np.empty(block), np.empty(block)
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        sines_block(t, start, count, uniform, sines, buf)
        for i in range(count):
            half[i] = 0.5 * buf[0, 0, i]
        sincos_block(half, count, s, c)
        for i in range(count):
            j = start + i
            for m in range(4):
                q[j, m] = c[i] * a[m] + s[i] * b[m]
            for m in range(3):
                omega[j, m] = buf[1, 0, i] * axis[m]
                alpha[j, m] = buf[2, 0, i] * axis[m]
            if channels > 1:
                for m in range(3):
                    p = v = ac = 0.0
                    for ch in range(1, channels):
                        p += buf[0, ch, i] * directions[ch - 1, m]
                        v += buf[1, ch, i] * directions[ch - 1, m]
                        ac += buf[2, ch, i] * directions[ch - 1, m]
                    pos[j, m], vel[j, m], acc[j, m] = p, v, ac


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
    reference_rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)


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
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    coning: Coning

    def world_motion(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        cone = self.coning
        theta, omega = np.radians(cone.half_angle_deg), 2 * np.pi * cone.frequency_hz
        grid = TimeGrid(t)
        q_ref = quat_from_rpy_deg(cone.reference_rpy_deg)
        # q_wb = q_ref ⊗ q_rb = cos(θ/2) q_ref + sin(θ/2) [cos Ωt (q_ref ⊗ j) + sin Ωt (q_ref ⊗ k)]
        j, k = quat_multiply(q_ref, [0.0, 0.0, 1.0, 0.0]), quat_multiply(q_ref, [0.0, 0.0, 0.0, 1.0])
        w = omega * np.sin(theta)
        n = len(t)
        q, rate, accel = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
        _coning_kernel(
            t,
            grid.uniform,
            grid.BLOCK,
            grid.phasor(omega),
            np.sin(theta / 2) * j,
            np.sin(theta / 2) * k,
            np.cos(theta / 2) * q_ref,
            -omega * (1 - np.cos(theta)),
            w,
            -omega * w,
            q,
            rate,
            accel,
        )
        return WorldMotion.rotation_only(t, q, rate, accel)


@njit
def _coning_kernel(
    t: NDArray[np.float64],
    uniform: bool,
    block: int,
    phasor: PhasorTable,
    sj: NDArray[np.float64],
    sk: NDArray[np.float64],
    cq: NDArray[np.float64],
    rate_x: float,
    w: float,
    ow: float,
    q: NDArray[np.float64],
    rate: NDArray[np.float64],
    accel: NDArray[np.float64],
) -> None:  # pragma: no cover
    """:meth:`ConingSpec.world_motion` block by block: ``q = cos Ωt sj + sin Ωt sk + cq``,
    ``ω = (rate_x, −w sin Ωt, w cos Ωt)``, ``α = (0, ow cos Ωt, ow sin Ωt)`` with ``ow = −Ω w``."""
    c, s = np.empty(block), np.empty(block)
    for start in range(0, len(t), block):
        count = min(block, len(t) - start)
        phasor_block(t, start, count, uniform, phasor, c, s)
        for i in range(count):
            j = start + i
            for m in range(4):
                q[j, m] = (c[i] * sj[m] + s[i] * sk[m]) + cq[m]
            rate[j, 0], rate[j, 1], rate[j, 2] = rate_x, -w * s[i], w * c[i]
            accel[j, 0], accel[j, 1], accel[j, 2] = 0.0, ow * c[i], ow * s[i]


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
    phase_deg: AngleDeg = 0.0
    reference_rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)


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
    pointwise: ClassVar[bool] = True  # the truth is a closed form in t
    sculling: Sculling

    def world_motion(self, t: ArrayLike) -> WorldMotion:
        t = np.asarray(t, dtype=float)
        sc = self.sculling
        omega = 2 * np.pi * sc.frequency_hz
        theta0, accel_amp = np.radians(sc.angular_amplitude_deg), sc.acceleration_amplitude_m_s2
        grid = TimeGrid(t)
        # Channel 0: θ = θ0 sin Ωt.
        # Channel 1: displacement y = −A/Ω² sin(Ωt + φ), so that ÿ = A sin(Ωt + φ), along the reference
        # y axis.
        sines = grid.sines([[theta0], [-accel_amp / omega**2]], omega, [[0.0], [np.radians(sc.phase_deg)]])
        q_ref = quat_from_rpy_deg(sc.reference_rpy_deg)
        e_x = np.array([1.0, 0.0, 0.0])
        y_w = quat_rotate(q_ref, [0.0, 1.0, 0.0])  # the reference y axis in the world
        arrays = motion_arrays(len(t), moves=True)
        _axis_oscillation_kernel(
            t, grid.uniform, grid.BLOCK, sines, *rotation_basis(e_x, q_ref), e_x, y_w[None, :], *arrays
        )
        return WorldMotion(t, *arrays)
