"""The :class:`Trajectory`: sampled truth of one rigid body, what every emulated sensor reads."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .earth import Environment
from .rotation import quat_conjugate, quat_rotate

__all__ = ["Trajectory", "trajectory_from_world_motion"]

_VECTORS = ("omega_b", "alpha_b", "specific_force_b", "pos_w", "vel_w", "mag_b")


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Sampled truth of a body's reference point (its centre of mass unless a scenario says otherwise).

    Attributes (N samples, SI units, see ``interface.md``)
    ----------
    t : ndarray (N,)
        Sample times, s, strictly increasing.
    q_wb : ndarray (N, 4)
        Attitude, unit quaternion (w, x, y, z), body to world.
    omega_b : ndarray (N, 3)
        Angular velocity of the body relative to inertial space, body axes, rad/s.
    alpha_b : ndarray (N, 3)
        ``d omega_b / dt`` (the derivative of the body-axes components), rad/s².
    specific_force_b : ndarray (N, 3)
        ``R_bw (a_inertial − gravitation)`` at the reference point, m/s².
    pos_w, vel_w : ndarray (N, 3)
        Position and velocity in the world frame, m and m/s.
    mag_b : ndarray (N, 3)
        Magnetic flux density in body axes, tesla.
    extras : dict of str to ndarray
        Truth that only some scenarios have, first axis N (gimbal angles, rotor momenta, ...).
    environment : Environment or None
        The fields the body moved in (gravity, world-frame rotation, magnetic field).
    """

    t: np.ndarray
    q_wb: np.ndarray
    omega_b: np.ndarray
    alpha_b: np.ndarray
    specific_force_b: np.ndarray
    pos_w: np.ndarray
    vel_w: np.ndarray
    mag_b: np.ndarray
    extras: dict = field(default_factory=dict)
    environment: Environment | None = None

    def __post_init__(self):
        n = np.shape(self.t)[0] if np.ndim(self.t) == 1 else -1
        if n < 0:
            raise ValueError(f"t must be 1-D, got shape {np.shape(self.t)}")
        if np.shape(self.q_wb) != (n, 4):
            raise ValueError(f"q_wb must have shape ({n}, 4), got {np.shape(self.q_wb)}")
        for name in _VECTORS:
            if np.shape(getattr(self, name)) != (n, 3):
                raise ValueError(f"{name} must have shape ({n}, 3), got {np.shape(getattr(self, name))}")
        for name, value in self.extras.items():
            if np.shape(value)[:1] != (n,):
                raise ValueError(f"extras[{name!r}] must have first axis {n}, got shape {np.shape(value)}")

    def __len__(self) -> int:
        return len(self.t)

    def __getitem__(self, index) -> "Trajectory":
        """Samples selected by a slice, boolean mask or index array, as a new Trajectory."""
        if isinstance(index, (int, np.integer)):
            index = slice(index, index + 1 if index != -1 else None)
        return Trajectory(
            t=self.t[index],
            q_wb=self.q_wb[index],
            **{name: getattr(self, name)[index] for name in _VECTORS},
            extras={k: v[index] for k, v in self.extras.items()},
            environment=self.environment,
        )

    @property
    def duration(self) -> float:
        """Time span from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0


def _cross(a, b) -> np.ndarray:
    """``a × b`` over the last axis, written out (``np.cross`` copies broadcast operands)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    ax, ay, az = np.moveaxis(a, -1, 0)
    bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], -1)


def trajectory_from_world_motion(
    t,
    q_wb,
    omega_wb_b,
    alpha_wb_b,
    pos_w,
    vel_w,
    acc_w,
    environment: Environment,
    extras: dict | None = None,
) -> Trajectory:
    """Build a Trajectory from motion relative to the world frame, adding what the Earth contributes.

    Parameters
    ----------
    t : ndarray (N,)
    q_wb : ndarray (N, 4)
    omega_wb_b, alpha_wb_b : ndarray (N, 3)
        Angular velocity of the body relative to the *world* frame, body axes, and its derivative.
    pos_w, vel_w, acc_w : ndarray (N, 3)
        Position, velocity and acceleration relative to the world frame, world axes.
    environment : Environment

    Notes
    -----
    With ``Ω`` the world frame's rotation relative to inertial space (world axes, constant) and
    ``g`` the gravity vector (gravitation plus centrifugal)::

        omega_b = ω_wb^b + R_bw Ω
        alpha_b = α_wb^b − ω_wb^b × (R_bw Ω)        (d/dt of R_bw Ω seen in body axes)
        f_b     = R_bw (a_w + 2 Ω × v_w − g)         (Coriolis; centrifugal sits in g)
        mag_b   = R_bw m_w
    """
    q_bw = quat_conjugate(q_wb)
    omega_wb_b = np.asarray(omega_wb_b, dtype=float)
    alpha_wb_b = np.asarray(alpha_wb_b, dtype=float)
    earth = environment.earth_rate_w
    if np.any(earth):
        earth_b = quat_rotate(q_bw, earth)
        omega_b = omega_wb_b + earth_b
        alpha_b = alpha_wb_b - _cross(omega_wb_b, earth_b)
        inertial_acc_w = acc_w + _cross(2.0 * earth, vel_w) - environment.gravity_w
    else:  # an inertial world: nothing to add (and long arrays are not copied for zeros)
        omega_b, alpha_b = omega_wb_b, alpha_wb_b
        inertial_acc_w = acc_w - environment.gravity_w
    field = environment.magnetic_field_w
    mag_b = quat_rotate(q_bw, field) if np.any(field) else np.zeros_like(omega_b)
    return Trajectory(
        t=np.asarray(t, dtype=float),
        q_wb=np.asarray(q_wb, dtype=float),
        omega_b=omega_b,
        alpha_b=alpha_b,
        specific_force_b=quat_rotate(q_bw, inertial_acc_w),
        pos_w=np.asarray(pos_w, dtype=float),
        vel_w=np.asarray(vel_w, dtype=float),
        mag_b=mag_b,
        extras=extras or {},
        environment=environment,
    )
