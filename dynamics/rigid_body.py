"""A free rigid body: state ``[x, q, P, L]``, its equations of motion, lever arms and impulses.

Model (the scribe notes on rigid-body dynamics, ``shared/seeds/scribe-notes-rigid-body-dynamics.txt``;
Baraff, *Physically Based Modeling: Rigid Body Simulation*, SIGGRAPH course notes 2001)
--------------------------------------------------------------------------------------------------
The state of one body is 13 numbers, all in world axes::

    x  (3)  position of the centre of mass, m
    q  (4)  attitude q_wb, unit quaternion (w, x, y, z), body -> world
    P  (3)  linear momentum m v, kg m/s (v relative to the world frame)
    L  (3)  angular momentum about the centre of mass, relative to inertial space, kg m²/s

and it moves by::

    ẋ = P / m
    q̇ = ½ (0, ω_wb) ⊗ q                  ω_wb = ω − Ω, the rotation relative to the world frame
    Ṗ = F − 2 Ω × P                      (Coriolis; gravity and centrifugal are in F)
    L̇ = τ − Ω × L                        (L's components seen from world axes turning at Ω)

with ``ω = R I_b⁻¹ Rᵀ L`` the inertial angular velocity (world axes), ``I_b`` the inertia tensor in
body axes about the centre of mass, ``R = R(q)``, ``F`` the total force and ``τ`` the torque about
the centre of mass, both in world axes. ``Ω`` is the world frame's rotation relative to inertial
space: zero for an inertial world (then these are exactly the scribe notes' equations), the Earth rate
for an Earth-bound scenario, whose world frame is the local ENU frame fixed to the Earth.

Derived quantities, exact at any state (no differencing)::

    a      = Ṗ / m                                  acceleration relative to the world frame
    α_b    = I_b⁻¹ (τ_b − ω_b × I_b ω_b)            Euler's equation, τ_b = Rᵀ τ, ω_b = Rᵀ ω

``α_b`` is ``dω_b/dt``: the derivative of the body-axes components of the inertial angular velocity,
which is also the inertial angular acceleration in body axes.

Arrays: every function here takes states of shape ``(13,)`` or ``(..., 13)`` and times that broadcast
against the leading axes, so the integrator's single states and a whole sampled trajectory go
through the same code.

The small vectorised kernels these formulas use (rotation matrices, ``R v``, ``Rᵀ v``, cross and Hamilton
products) live in :mod:`gyroemu.dynamics.body_kernels`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .body_kernels import cross, pure_quat, quat_product, rotate, rotate_back, rotation_matrix, stack_state
from .earth import Environment
from .inertia import check_inertia
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = [
    "STATE_SIZE",
    "X",
    "Q",
    "P",
    "L",
    "RigidBody",
    "point_position",
    "point_velocity",
    "point_acceleration",
    "contact_mass_matrix",
    "world_motion_trajectory",
]

STATE_SIZE = 13
X = slice(0, 3)
Q = slice(3, 7)
P = slice(7, 10)
L = slice(10, 13)

ForceFn = Callable[[ArrayLike, NDArray[np.float64]], NDArray[np.float64]]
"""``force(t, y) -> (..., 3)``: world axes, newtons (or N m for a torque about the centre of mass)."""


# --------------------------------------------------------------------------------------------
# Lever arms
# --------------------------------------------------------------------------------------------


def point_position(pos: ArrayLike, r: NDArray[np.float64], lever: ArrayLike) -> NDArray[np.float64]:
    """World position of a body-fixed point: ``x + R r_b``.

    Parameters
    ----------
    pos : (..., 3) centre of mass, world, m
    r : (..., 3, 3) rotation matrices ``R(q_wb)``
    lever : (..., 3) the point in body axes from the centre of mass, m
    """
    return np.asarray(pos, dtype=float) + rotate(r, lever)


def point_velocity(vel: ArrayLike, omega: ArrayLike, lever: ArrayLike) -> NDArray[np.float64]:
    """Velocity of a body-fixed point: ``v + ω × r`` (scribe notes: ``v_p = v_cm + ω × r_i``).

    All three arguments in one set of axes, and ``ω`` relative to the frame ``v`` is measured in:
    world axes with ``ω_wb`` and world-relative ``v`` for the point's world velocity; body axes with
    ``v_b = Rᵀ v`` and the lever arm in body axes give the same vector in body axes. Shapes ``(..., 3)``
    broadcast.
    """
    return np.asarray(vel, dtype=float) + cross(omega, lever)


def point_acceleration(acc: ArrayLike, omega: ArrayLike, alpha: ArrayLike, lever: ArrayLike) -> NDArray[np.float64]:
    """Acceleration of a body-fixed point: ``a + α × r + ω × (ω × r)`` (tangential and centripetal).

    ``ω`` and ``α = dω/dt`` relative to the frame in which ``a`` is taken; all vectors in one set of
    axes. For an accelerometer at lever arm ``r_b`` (body axes): the specific force there is
    ``f_b + α_b × r_b + ω_b × (ω_b × r_b)`` with the inertial ``ω_b``, ``α_b`` of a
    :class:`~gyroemu.dynamics.trajectory.Trajectory` (``α_b``, the derivative of body components, equals the
    inertial angular acceleration in body axes). Shapes ``(..., 3)`` broadcast.
    """
    return np.asarray(acc, dtype=float) + cross(alpha, lever) + cross(omega, cross(omega, lever))


def contact_mass_matrix(mass: float, inertia_w_inv: NDArray[np.float64], lever_w: ArrayLike) -> NDArray[np.float64]:
    """``K`` with ``Δu = K J``: the change of a point's velocity under an impulse ``J`` at that point.

    ``K = (1/m) 1 − [r]× I_w⁻¹ [r]×`` (Mirtich 1996, *Impulse-based dynamic simulation of rigid body
    systems*, eq. 4.8), world axes, ``r`` the point from the centre of mass. Shapes: ``inertia_w_inv``
    ``(..., 3, 3)``, ``lever_w`` ``(..., 3)``; returns ``(..., 3, 3)``.
    """
    r = np.asarray(lever_w, dtype=float)
    rx = np.zeros(r.shape[:-1] + (3, 3))
    rx[..., 0, 1], rx[..., 0, 2], rx[..., 1, 2] = -r[..., 2], r[..., 1], -r[..., 0]
    rx[..., 1, 0], rx[..., 2, 0], rx[..., 2, 1] = r[..., 2], -r[..., 1], r[..., 0]
    return np.eye(3) / mass - rx @ inertia_w_inv @ rx


# --------------------------------------------------------------------------------------------
# The body
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RigidBody:
    """Mass properties of one rigid body and its equations of motion in the state ``[x, q, P, L]``.

    Attributes
    ----------
    mass : float
        kg.
    inertia_b : ndarray (3, 3)
        Inertia tensor about the centre of mass in body axes, kg m² (validated).
    frame_rate_w : ndarray (3,)
        ``Ω``, the world frame's rotation relative to inertial space, world axes, rad/s (zero: an
        inertial world; ``Environment.earth_rate_w`` for an Earth-bound one).
    """

    mass: float
    inertia_b: NDArray[np.float64]
    frame_rate_w: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    if TYPE_CHECKING:  # set by __post_init__; declared for the type checker only, not dataclass fields
        _inertia_inv: NDArray[np.float64] = field(init=False, repr=False)
        _rotating: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.mass > 0:
            raise ValueError(f"mass must be positive, got {self.mass}")
        object.__setattr__(self, "inertia_b", check_inertia(self.inertia_b))
        object.__setattr__(self, "frame_rate_w", np.asarray(self.frame_rate_w, dtype=float).reshape(3))
        object.__setattr__(self, "_inertia_inv", np.linalg.inv(self.inertia_b))
        object.__setattr__(self, "_rotating", bool(np.any(self.frame_rate_w != 0)))

    # -- building and reading states ---------------------------------------------------------------

    def state(
        self,
        pos_w: ArrayLike = (0, 0, 0),
        q_wb: ArrayLike = (1, 0, 0, 0),
        vel_w: ArrayLike = (0, 0, 0),
        omega_b: ArrayLike = (0, 0, 0),
    ) -> NDArray[np.float64]:
        """The state ``[x, q, P, L]`` of a body at ``pos_w`` with attitude ``q_wb``, moving at ``vel_w``
        (world-relative, m/s) and turning at ``omega_b`` (inertial, body axes, rad/s). Shapes broadcast;
        returns ``(..., 13)``."""
        pos, q, vel, omega = (np.asarray(a, dtype=float) for a in (pos_w, q_wb, vel_w, omega_b))
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        r = rotation_matrix(q)
        momentum = self.mass * vel  # P = m v
        angular_momentum = rotate(r, np.asarray(omega) @ self.inertia_b.T)  # L = R I_b ω_b
        shape = np.broadcast_shapes(pos.shape[:-1], q.shape[:-1], vel.shape[:-1], omega.shape[:-1])
        return stack_state(shape, [pos, q, momentum, angular_momentum])

    def omega_b(self, y: NDArray[np.float64], r: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Inertial angular velocity in body axes: ``ω_b = I_b⁻¹ Rᵀ L``; ``(..., 3)``."""
        r = rotation_matrix(y[..., Q]) if r is None else r
        return rotate_back(r, y[..., L]) @ self._inertia_inv.T

    def omega_wb_w(self, y: NDArray[np.float64], r: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Angular velocity relative to the world frame, world axes: ``R ω_b − Ω``; ``(..., 3)``."""
        r = rotation_matrix(y[..., Q]) if r is None else r
        return rotate(r, self.omega_b(y, r)) - self.frame_rate_w

    def velocity(self, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """World-relative velocity of the centre of mass: ``v = P / m``."""
        return y[..., P] / self.mass

    def kinetic_energy(self, y: NDArray[np.float64]) -> float | NDArray[np.float64]:
        """``½ P·P/m + ½ ω_b · I_b ω_b``, J (with world-relative ``P``, inertial ``ω``)."""
        w = self.omega_b(y)
        energy: float | NDArray[np.float64] = 0.5 * np.sum(y[..., P] ** 2, -1) / self.mass + 0.5 * np.einsum(
            "...i,ij,...j->...", w, self.inertia_b, w
        )
        return energy

    def inertia_w_inv(self, r: NDArray[np.float64]) -> NDArray[np.float64]:
        """``I_w⁻¹ = R I_b⁻¹ Rᵀ``, ``(..., 3, 3)``."""
        return r @ self._inertia_inv @ np.swapaxes(r, -1, -2)

    # -- equations of motion -----------------------------------------------------------------------

    def derivative(
        self, t: ArrayLike, y: ArrayLike, force: ForceFn | None = None, torque: ForceFn | None = None
    ) -> NDArray[np.float64]:
        """``ẏ = [ẋ, q̇, Ṗ, L̇]`` (module docstring) for states ``(..., 13)`` at times ``t``.

        ``force(t, y)`` and ``torque(t, y)`` return world-axes vectors (N, and N m about the centre of
        mass) for the same shapes; ``None`` is zero.
        """
        y = np.asarray(y, dtype=float)
        q = y[..., Q]
        omega_wb_w = self.omega_wb_w(y)  # ω − Ω (ω = R I_b⁻¹ Rᵀ L): the rotation relative to the world frame
        f = np.zeros(y.shape[:-1] + (3,)) if force is None else force(t, y)
        tau = np.zeros(y.shape[:-1] + (3,)) if torque is None else torque(t, y)
        x_dot = y[..., P] / self.mass  # ẋ = P/m
        q_dot = 0.5 * quat_product(pure_quat(omega_wb_w), q)  # q̇ = ½ ω ⊗ q
        p_dot, l_dot = np.asarray(f, dtype=float), np.asarray(tau, dtype=float)  # Ṗ = F, L̇ = τ
        if self._rotating:
            p_dot = p_dot - 2.0 * cross(self.frame_rate_w, y[..., P])  # Coriolis: − 2Ω×P
            l_dot = l_dot - cross(self.frame_rate_w, y[..., L])  # turning axes: − Ω×L
        return stack_state(y.shape[:-1], [x_dot, q_dot, p_dot, l_dot])

    def accelerations(
        self, t: ArrayLike, y: ArrayLike, force: ForceFn | None = None, torque: ForceFn | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Exact accelerations at states ``(..., 13)``.

        Returns
        -------
        acc_w : (..., 3)
            World-relative acceleration of the centre of mass, ``Ṗ/m``, m/s².
        omega_b, alpha_b : (..., 3)
            Inertial angular velocity and ``dω_b/dt = I_b⁻¹ (τ_b − ω_b × I_b ω_b)``, body axes.
        """
        y = np.asarray(y, dtype=float)
        r = rotation_matrix(y[..., Q])
        omega = self.omega_b(y, r)
        f = np.zeros(y.shape[:-1] + (3,)) if force is None else force(t, y)
        tau = np.zeros(y.shape[:-1] + (3,)) if torque is None else torque(t, y)
        acc = (f - 2.0 * cross(self.frame_rate_w, y[..., P])) / self.mass
        tau_b = rotate_back(r, tau)
        alpha = (tau_b - cross(omega, omega @ self.inertia_b.T)) @ self._inertia_inv.T  # Euler
        return acc, omega, alpha

    # -- impulses ------------------------------------------------------------------------------------

    def apply_impulse(self, y: ArrayLike, impulse_w: ArrayLike, point_w: ArrayLike) -> NDArray[np.float64]:
        """State after an impulse ``J`` (N s, world) at the world point ``point_w``:
        ``ΔP = J``, ``ΔL = r × J`` with ``r = point − x`` (scribe notes: ``τ = r × F``)."""
        y = np.array(y, dtype=float)
        j = np.asarray(impulse_w, dtype=float)
        y[..., P] += j
        y[..., L] += cross(np.asarray(point_w, dtype=float) - y[..., X], j)
        return y

    def point_velocity_w(self, y: NDArray[np.float64], lever_b: ArrayLike) -> NDArray[np.float64]:
        """World-relative velocity of the body point ``lever_b`` (body axes from the centre of mass)."""
        r = rotation_matrix(y[..., Q])
        return point_velocity(self.velocity(y), self.omega_wb_w(y, r), rotate(r, lever_b))


def world_motion_trajectory(
    t: ArrayLike,
    pos_w: ArrayLike,
    q_wb: ArrayLike,
    vel_w: ArrayLike,
    acc_w: ArrayLike,
    omega_b: NDArray[np.float64],
    alpha_b: NDArray[np.float64],
    environment: Environment,
    extras: dict[str, NDArray[Any]] | None = None,
) -> Trajectory:
    """A :class:`Trajectory` from integrated states, given the *inertial* ``omega_b`` and ``alpha_b``.

    :func:`~gyroemu.dynamics.trajectory.trajectory_from_world_motion` takes the rotation relative to the
    world frame and adds the Earth's; this converts (``ω_wb = ω − Rᵀ Ω``,
    ``α_wb = α + ω_wb × Rᵀ Ω``, the inverse of its formulas) so the sum reproduces the inertial
    values to rounding.
    """
    r = rotation_matrix(q_wb)
    frame_b = rotate_back(r, environment.earth_rate_w)
    omega_wb = omega_b - frame_b
    alpha_wb = alpha_b + cross(omega_wb, frame_b)
    q = np.asarray(q_wb, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return trajectory_from_world_motion(t, q, omega_wb, alpha_wb, pos_w, vel_w, acc_w, environment, extras)
