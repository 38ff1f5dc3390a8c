"""Spinning rigid bodies: the torque-free body and the symmetric heavy top (scenario kinds).

``free-rigid-body``
    A rigid body in inertial space with no torque (Euler's equations ``I ω̇ + ω × I ω = 0``): the
    world angular momentum ``L_w`` and the kinetic energy are constant. A symmetric body cones
    (the lecture's free symmetric top: ``ω`` turns about body z at ``Ω = (Izz − Ixx)/Ixx · ω_z``);
    an asymmetric one started near its intermediate axis flips over and over (Dzhanibekov effect).
``heavy-top``
    A symmetric top on a fixed frictionless pivot in uniform gravity (Lagrange top; Goldstein,
    *Classical Mechanics*, 3rd ed., §5.7): it precesses about the vertical and nutates between two
    tilts, the roots of a cubic in ``cos θ``. ``L_z`` (vertical) and ``L₃`` (spin) are constant.

Both are integrated by :mod:`gyroemu.dynamics.splitting` (exact-rotation Lie–Poisson splitting, order up to
8), which keeps those invariants to round-off. ``omega_b`` is ``I⁻¹ L_b`` and ``alpha_b`` comes
from Euler's equations ``I α = τ − ω × I ω`` at each sample, not from differences.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, field_validator

from .config import AngleRad, ConfigError, NonNegativeReal, PositiveReal, Quat, Real, Section, Vec3, as_number, at_most
from .earth import Environment
from .inertia import inertia_config, inertia_tensor
from .jit import njit
from .rotation import body_rate_from_euler_zxz, quat_from_euler_zxz, quat_rotate, quat_to_matrix
from .scenarios import ScenarioSpec
from .splitting import free_body_frequency, heavy_top_frequency, integrate_free_body, integrate_heavy_top
from .trajectory import Trajectory

__all__ = [
    "FreeBody",
    "FreeInitial",
    "FreeRigidBodySpec",
    "HeavyTopBody",
    "HeavyTopInitial",
    "HeavyTopEnvironment",
    "HeavyTopSpec",
    "free_body_motion",
    "heavy_top_attitude",
    "pivot_moments",
    "MAX_RATE_RAD_S",
    "MAX_SPLIT_FREQUENCY_RAD_S",
    "INERTIA_RANGE_KGM2",
    "MAX_TOP_MASS_KG",
    "MAX_CM_HEIGHT_M",
    "MAX_GRAVITY_M_S2",
]

STANDARD_GRAVITY = 9.80665
"""Standard gravity, m/s² (CGPM 1901): the default ``[environment] gravity_m_s2`` of a heavy top."""

_UNIT_NORM_TOL = 1e-6
_SYMMETRY_RTOL = 1e-9

MAX_RATE_RAD_S = 1.0e5
"""The fastest initial rate of either body, rad/s (each of ``omega_b`` and ``euler_zxz_rates_rad_s``;
about 955 000 rpm): twice the fastest spinning rigid bodies made, dental air turbines at some
5·10⁴ rad/s (ultracentrifuge rotors reach 1.6·10⁴, gyroscope rotors 2.5·10³), whose rims are near their
material's burst speed. It bounds the integrator's work: :mod:`gyroemu.dynamics.splitting` steps about
0.12 rad of the fastest split rotation at a time (|L|/A, up to twice the body rate), some 5–10 µs of
computing a radian: 0.3–3 s a simulated second at this limit. A spin of 10¹² rad/s asked for 10¹³ steps
a second, a run of days in a kernel no signal interrupts; 10²⁰⁰ overflowed."""

MAX_SPLIT_FREQUENCY_RAD_S = 1.0e6
"""The fastest split rotation the integrator may have to follow, rad/s
(:func:`~gyroemu.dynamics.splitting.heavy_top_frequency`, :func:`~gyroemu.dynamics.splitting.free_body_frequency`):
ten times :data:`MAX_RATE_RAD_S`, about 5–10 s of computing a simulated second. Rates within their own
limit exceed it only with an extreme body: a nearly flat asymmetric one (its spin about the thin axis
follows the others' at (ΔI/I_min)·ω), or a top whose pendulum frequency √(m g l / A) is out of reach
(a radius of gyration of nanometres)."""

INERTIA_RANGE_KGM2 = (1.0e-20, 1.0e40)
"""The range of a body's principal moments, kg m²: from a thousandth of a MEMS gyro's proof mass (a
microgram 0.1 mm across, 10⁻¹⁷ kg m²) to a hundred times the Earth (8·10³⁷ kg m², whose free wobble is a
free rigid body's). Beyond it ``|I ω|²`` leaves float64's range: 10³⁰⁰ kg m² overflowed, and at 10⁻³⁰⁰
the momentum's norm rounded to 0 and the body stood still while ``omega_b`` said it turned."""

MAX_TOP_MASS_KG = 1.0e6
"""The heaviest heavy top, kg (1000 t): ten times the rotors of the largest gyroscopes built (ship
stabilisers' rotors of about 100 t); 10³⁰⁰ kg made the integrator's step 0 (a division by zero)."""

MAX_CM_HEIGHT_M = 100.0
"""The longest pivot to centre of mass of a heavy top (or, negative, a gyroscopic pendulum), m: longer
than the longest pendulums hung (Foucault's in the Panthéon: 67 m); 10³⁰⁰ m overflowed ``m l²``."""

MAX_GRAVITY_M_S2 = 1.0e4
"""The strongest uniform gravity under a heavy top, m/s² (about 1000 g): 36 times the Sun's surface
gravity (274 m/s²); 10³⁰⁰ m/s² made the step counts overflow int64 and the top stand still."""


def _inertia_in_range(value: Vec3 | tuple[Vec3, Vec3, Vec3]) -> Vec3 | tuple[Vec3, Vec3, Vec3]:
    """Refuse principal moments outside :data:`INERTIA_RANGE_KGM2` (after :func:`inertia_config`)."""
    low, high = INERTIA_RANGE_KGM2
    moments = np.linalg.eigvalsh(inertia_tensor(value))
    if moments.max() > high:
        raise ValueError(
            f"a principal moment of {moments.max():g} kg m² is more than the limit of {high:g}: a hundred times "
            "the Earth's (8e37 kg m²)"
        )
    if moments.min() < low:
        raise ValueError(
            f"a principal moment of {moments.min():g} kg m² is less than the limit of {low:g}: a thousandth of a "
            "MEMS gyro's proof mass (1e-17 kg m²)"
        )
    return value


def _rates_at_most(value: Vec3) -> Vec3:
    """Refuse an initial rate component beyond :data:`MAX_RATE_RAD_S` in magnitude."""
    fastest = max(abs(x) for x in value)
    if fastest > MAX_RATE_RAD_S:
        raise ValueError(
            f"{fastest:g} rad/s is more than the limit of {MAX_RATE_RAD_S:g}: twice the fastest rotors made "
            "(dental turbines, 5e4 rad/s); the integrator's steps grow with the rate"
        )
    return value


Rates = Annotated[Vec3, AfterValidator(_rates_at_most)]
"""Three initial rates, rad/s, each at most :data:`MAX_RATE_RAD_S` in magnitude."""


def _split_frequency_problem(omega: float) -> str | None:
    """Why the integrator cannot follow a split rotation of ``omega`` rad/s, or None."""
    if np.isfinite(omega) and omega <= MAX_SPLIT_FREQUENCY_RAD_S:
        return None
    return (
        f"the integrator would follow a rotation of {omega:.4g} rad/s, more than the limit of "
        f"{MAX_SPLIT_FREQUENCY_RAD_S:g} (ten times the fastest rotors made; about 8 steps a radian)"
    )


# --------------------------------------------------------------------------------------------------
# free-rigid-body


class FreeBody(Section):
    """``[body]`` of a free rigid body."""

    inertia_kgm2: Vec3 | tuple[Vec3, Vec3, Vec3]
    """Three principal moments along body x, y, z, or a 3x3 tensor in body axes, about the centre
    of mass, kg m²."""

    @field_validator("inertia_kgm2", mode="before")
    @classmethod
    def _shape(cls, value: object) -> tuple[float, ...] | tuple[tuple[float, ...], ...]:
        # Sort out the two accepted shapes here, so that a wrong one gets one plain message.
        if isinstance(value, (list, tuple)) and len(value) == 3:
            rows = [isinstance(row, (list, tuple)) for row in value]
            if all(rows) and all(len(row) == 3 for row in value):
                return tuple(tuple(as_number(x) for x in row) for row in value)
            if not any(rows):
                return tuple(as_number(x) for x in value)
        raise ValueError("give 3 principal moments [Ixx, Iyy, Izz] or a 3x3 matrix [[..], [..], [..]], in kg m²")

    @field_validator("inertia_kgm2")
    @classmethod
    def _physical(cls, value: Vec3 | tuple[Vec3, Vec3, Vec3]) -> Vec3 | tuple[Vec3, Vec3, Vec3]:
        return _inertia_in_range(inertia_config(value))  # raises InertiaError (a ValueError) saying what is wrong

    def tensor(self) -> NDArray[np.float64]:
        """The inertia tensor in body axes, (3, 3), kg m²."""
        return inertia_tensor(self.inertia_kgm2)


class FreeInitial(Section):
    """``[initial]`` state of a free rigid body."""

    omega_b: Rates
    """Angular velocity, body axes, rad/s; each component at most :data:`MAX_RATE_RAD_S`."""
    q_wb: Quat = (1.0, 0.0, 0.0, 0.0)
    """Attitude (w, x, y, z), unit norm within 1e-6; stored normalised."""

    @field_validator("q_wb")
    @classmethod
    def _unit(cls, q: Quat) -> tuple[float, ...]:
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > _UNIT_NORM_TOL:
            raise ValueError(f"must be a unit quaternion (w, x, y, z), its norm is {norm:.9g}")
        return tuple(float(c) / norm for c in q)


class FreeRigidBodySpec(ScenarioSpec):
    """A torque-free rigid body in inertial space (no gravity, no field).

    The reference point is the centre of mass, at rest at the world origin: ``pos_w``, ``vel_w``,
    ``specific_force_b`` and ``mag_b`` are zero.
    """

    kind: Literal["free-rigid-body"]
    body: FreeBody
    initial: FreeInitial

    def load(self, file: str | Path | None = None) -> None:
        """Refuse a body the integrator cannot follow in reasonable time (:data:`MAX_SPLIT_FREQUENCY_RAD_S`)."""
        inertia = self.body.tensor()
        problem = _split_frequency_problem(free_body_frequency(inertia @ np.asarray(self.initial.omega_b), inertia))
        if problem is not None:
            raise ConfigError(
                f"{problem}: this rate turns about body axes whose moments (body.inertia_kgm2) differ so much",
                file=file,
                key="initial.omega_b",
            )

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        t = np.asarray(t, dtype=float)
        q_wb, omega_b, alpha_b = free_body_motion(
            t, self.body.tensor(), np.asarray(self.initial.q_wb), np.asarray(self.initial.omega_b)
        )
        n = len(t)
        # The world is inertial and field-free, so trajectory_from_world_motion would only add zeros.
        return Trajectory(
            t=t,
            q_wb=q_wb,
            omega_b=omega_b,
            alpha_b=alpha_b,
            specific_force_b=np.zeros((n, 3)),
            pos_w=np.zeros((n, 3)),
            vel_w=np.zeros((n, 3)),
            mag_b=np.zeros((n, 3)),
            environment=Environment.inertial(),
        )


def free_body_motion(
    t: ArrayLike, inertia_b: ArrayLike, q0_wb: ArrayLike, omega0_b: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Attitude and body rates of a torque-free body.

    Parameters
    ----------
    t : ndarray (N,)
        Increasing times, s, from the initial state at 0.
    inertia_b : ndarray (3, 3)
        Inertia tensor about the centre of mass in body axes, kg m².
    q0_wb : ndarray (4,)
        Initial attitude.
    omega0_b : ndarray (3,)
        Initial angular velocity, body axes, rad/s.

    Returns
    -------
    q_wb : ndarray (N, 4)
    omega_b, alpha_b : ndarray (N, 3)
        rad/s and rad/s², body axes.

    Notes
    -----
    A non-diagonal tensor is integrated in its principal axes and rotated back
    (:func:`gyroemu.dynamics.splitting.integrate_free_body`).
    """
    inertia_b = np.asarray(inertia_b, dtype=float)
    q_wb, L_b = integrate_free_body(t, q0_wb, inertia_b @ np.asarray(omega0_b, dtype=float), inertia_b)
    inv_inertia = np.linalg.inv(inertia_b)
    omega_b = np.einsum("ij,nj->ni", inv_inertia, L_b)  # ω = I⁻¹ L
    alpha_b = np.einsum("ij,nj->ni", inv_inertia, -np.cross(omega_b, L_b))  # Euler: I α = −ω × I ω
    return q_wb, omega_b, alpha_b


# --------------------------------------------------------------------------------------------------
# heavy-top


class HeavyTopBody(Section):
    """``[body]`` of a symmetric heavy top."""

    mass_kg: Annotated[PositiveReal, at_most(MAX_TOP_MASS_KG, "ten times the largest gyroscope rotors built")]
    inertia_kgm2: Vec3
    """Principal moments ``(Ixx, Iyy, Izz)`` about the centre of mass, kg m²; body z is the
    symmetry axis, so ``Ixx = Iyy``."""
    cm_height_m: Real
    """Pivot to centre of mass along body z, m (negative: the centre of mass hangs below the pivot,
    a gyroscopic pendulum); at most :data:`MAX_CM_HEIGHT_M` either way."""

    @field_validator("cm_height_m")
    @classmethod
    def _not_too_long(cls, value: float) -> float:
        if abs(value) > MAX_CM_HEIGHT_M:
            raise ValueError(
                f"{value:g} m is more than the limit of ±{MAX_CM_HEIGHT_M:g}: longer than the longest pendulums hung"
            )
        return value

    @field_validator("inertia_kgm2")
    @classmethod
    def _symmetric_top(cls, value: Vec3) -> Vec3:
        _inertia_in_range(inertia_config(value))
        ixx, iyy, _ = value
        if abs(ixx - iyy) > _SYMMETRY_RTOL * max(ixx, iyy):
            raise ValueError(
                f"a heavy top is symmetric about body z, so Ixx must equal Iyy; got Ixx = {ixx:g}, "
                f"Iyy = {iyy:g} kg m² (an asymmetric body is a 'free-rigid-body' only)"
            )
        return value


class HeavyTopInitial(Section):
    """``[initial]`` state of a heavy top, as Z-X-Z Euler angles ``R = Rz(φ) Rx(θ) Rz(ψ)``."""

    euler_zxz_rad: tuple[AngleRad, AngleRad, AngleRad]
    """(precession φ, nutation θ, spin ψ), rad; θ is the tilt of the symmetry axis from the vertical.
    Each at most :data:`gyroemu.dynamics.config.MAX_ANGLE_TURNS` turns either way (an angle far beyond
    is a unit slip, and at 10³⁰⁰ rad no digit of its sine is left)."""
    euler_zxz_rates_rad_s: Rates
    """(φ̇, θ̇, ψ̇), rad/s; each at most :data:`MAX_RATE_RAD_S`."""


class HeavyTopEnvironment(Section):
    """``[environment]`` of a heavy top: uniform gravity along world −z."""

    gravity_m_s2: Annotated[NonNegativeReal, at_most(MAX_GRAVITY_M_S2, "36 times the Sun's surface gravity")] = (
        STANDARD_GRAVITY
    )


class HeavyTopSpec(ScenarioSpec):
    """A symmetric top on a fixed frictionless pivot at the world origin, under uniform gravity.

    The world frame is treated as inertial (no Earth rotation, no magnetic field).

    The trajectory's reference point is the **centre of mass**, ``l`` along the symmetry axis from
    the pivot: ``pos_w = R (0, 0, l)``, ``vel_w = R (ω × r)``, ``a_w = R (α × r + ω × (ω × r))`` with
    ``r = (0, 0, l)`` in body axes, and ``specific_force_b = R_bw (a_w − g_w)``: what an ideal
    accelerometer at the centre of mass reads.
    """

    kind: Literal["heavy-top"]
    body: HeavyTopBody
    initial: HeavyTopInitial
    environment: HeavyTopEnvironment = HeavyTopEnvironment()

    def load(self, file: str | Path | None = None) -> None:
        """Refuse a top the integrator cannot follow in reasonable time (:data:`MAX_SPLIT_FREQUENCY_RAD_S`)."""
        body, gravity = self.body, self.environment.gravity_m_s2
        a, c = pivot_moments(body.mass_kg, body.inertia_kgm2, body.cm_height_m)
        mgl = body.mass_kg * gravity * body.cm_height_m
        euler = np.asarray(self.initial.euler_zxz_rad)
        r0 = quat_to_matrix(quat_from_euler_zxz(euler))  # numpy and scipy: listing configs loads no numba
        omega0_b = body_rate_from_euler_zxz(euler, np.asarray(self.initial.euler_zxz_rates_rad_s))
        L0_w = r0 @ (np.array([a, a, c]) * omega0_b)
        problem = _split_frequency_problem(heavy_top_frequency(r0[:, 2], L0_w, a, c, mgl))
        if problem is None:
            return
        pendulum = np.sqrt(abs(mgl) / a)
        if pendulum > MAX_SPLIT_FREQUENCY_RAD_S:  # the body, not the rates
            raise ConfigError(
                f"{problem}: the top's pendulum frequency √(m g l / A) = {pendulum:.4g} rad/s, its moments too "
                "small for its mass, cm_height_m and gravity",
                file=file,
                key="body.inertia_kgm2",
            )
        raise ConfigError(problem, file=file, key="initial.euler_zxz_rates_rad_s")

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        t = np.asarray(t, dtype=float)
        body, gravity = self.body, self.environment.gravity_m_s2
        a, c = pivot_moments(body.mass_kg, body.inertia_kgm2, body.cm_height_m)
        mgl = body.mass_kg * gravity * body.cm_height_m
        q_wb, L_w = heavy_top_attitude(
            t, a, c, mgl, np.asarray(self.initial.euler_zxz_rad), np.asarray(self.initial.euler_zxz_rates_rad_s)
        )
        n = len(t)
        omega_b, alpha_b, pos_w, vel_w, f_b = (np.empty((n, 3)) for _ in range(5))
        _heavy_top_samples(q_wb, L_w, a, c, mgl, body.cm_height_m, gravity, omega_b, alpha_b, pos_w, vel_w, f_b)
        # The world is inertial (no Earth rate, no field): what trajectory_from_world_motion would
        # add is zero, and its four extra rotations of N vectors would cost more than the physics.
        return Trajectory(
            t=t,
            q_wb=q_wb,
            omega_b=omega_b,
            alpha_b=alpha_b,
            specific_force_b=f_b,
            pos_w=pos_w,
            vel_w=vel_w,
            mag_b=np.zeros((n, 3)),
            environment=Environment.inertial(gravity),
        )


def pivot_moments(mass_kg: float, inertia_cm: Sequence[float], cm_height_m: float) -> tuple[float, float]:
    """Transverse and axial moments about the pivot: ``A = Ixx + m l²`` (Steiner), ``C = Izz``."""
    return inertia_cm[0] + mass_kg * cm_height_m**2, inertia_cm[2]


def heavy_top_attitude(
    t: ArrayLike, moment_a: float, moment_c: float, mgl: float, euler0: ArrayLike, euler_rates0: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Attitude and angular momentum of a symmetric heavy top.

    Parameters
    ----------
    t : ndarray (N,)
        Increasing times, s, from the initial state at 0.
    moment_a, moment_c : float
        Transverse and axial moments about the pivot, kg m² (:func:`pivot_moments`).
    mgl : float
        Mass × gravity × pivot-to-centre-of-mass distance, J.
    euler0, euler_rates0 : ndarray (3,)
        Initial Z-X-Z angles (φ, θ, ψ), rad, and their rates, rad/s.

    Returns
    -------
    q_wb : ndarray (N, 4)
    L_w : ndarray (N, 3)
        Angular momentum about the pivot, world axes, kg m²/s.
    """
    moments = np.array([moment_a, moment_a, moment_c])
    q0 = quat_from_euler_zxz(euler0)
    omega0_b = body_rate_from_euler_zxz(euler0, euler_rates0)
    return integrate_heavy_top(t, q0, quat_rotate(q0, moments * omega0_b), moment_a, moment_c, mgl)


@njit
def _heavy_top_samples(
    q_wb: NDArray[np.float64],
    L_w: NDArray[np.float64],
    a: float,
    c: float,
    mgl: float,
    l: float,
    g: float,
    omega_b: NDArray[np.float64],
    alpha_b: NDArray[np.float64],
    pos_w: NDArray[np.float64],
    vel_w: NDArray[np.float64],
    f_b: NDArray[np.float64],
) -> None:
    """Rates, accelerations and centre-of-mass motion at each sample, written into the (N, 3) outputs.

    Equations (body axes unless marked w; ``r = (0, 0, l)`` the centre of mass, ``up`` the world
    vertical seen from the body, ``I = diag(A, A, C)`` about the pivot)::

        L = Rᵀ L_w,   ω = I⁻¹ L
        τ = r × (−m g up) = m g l (up_y, −up_x, 0)
        α = I⁻¹ (τ − ω × L)                                 (Euler's equations about the pivot)
        v = ω × r,   a = α × r + ω × v,   f = a − Rᵀ g_w = a + g up
        pos_w = R r,   vel_w = R v
    """
    for k in range(q_wb.shape[0]):
        w, x, y, z = q_wb[k, 0], q_wb[k, 1], q_wb[k, 2], q_wb[k, 3]
        # Rotation matrix R(q) (body to world).
        r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
        r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
        r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
        lw0, lw1, lw2 = L_w[k, 0], L_w[k, 1], L_w[k, 2]
        l0 = r00 * lw0 + r10 * lw1 + r20 * lw2  # L = Rᵀ L_w
        l1 = r01 * lw0 + r11 * lw1 + r21 * lw2
        l2 = r02 * lw0 + r12 * lw1 + r22 * lw2
        w0, w1, w2 = l0 / a, l1 / a, l2 / c  # ω = I⁻¹ L
        up0, up1, up2 = r20, r21, r22  # Rᵀ ẑ
        t0, t1 = mgl * up1, -mgl * up0  # τ (τ_z = 0)
        a0 = (t0 - (w1 * l2 - w2 * l1)) / a  # α = I⁻¹ (τ − ω × L)
        a1 = (t1 - (w2 * l0 - w0 * l2)) / a
        a2 = -(w0 * l1 - w1 * l0) / c
        v0, v1 = w1 * l, -w0 * l  # v = ω × r (v_z = 0)
        acc0 = a1 * l - w2 * v1  # a = α × r + ω × v
        acc1 = -a0 * l + w2 * v0
        acc2 = w0 * v1 - w1 * v0
        omega_b[k, 0], omega_b[k, 1], omega_b[k, 2] = w0, w1, w2
        alpha_b[k, 0], alpha_b[k, 1], alpha_b[k, 2] = a0, a1, a2
        f_b[k, 0], f_b[k, 1], f_b[k, 2] = acc0 + g * up0, acc1 + g * up1, acc2 + g * up2
        pos_w[k, 0], pos_w[k, 1], pos_w[k, 2] = r02 * l, r12 * l, r22 * l  # R r
        vel_w[k, 0] = r00 * v0 + r01 * v1  # R v
        vel_w[k, 1] = r10 * v0 + r11 * v1
        vel_w[k, 2] = r20 * v0 + r21 * v1
