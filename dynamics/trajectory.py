"""The :class:`Trajectory`: sampled truth of one rigid body, what every emulated sensor reads."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .earth import Environment
from .jit import njit

__all__ = ["Trajectory", "trajectory_from_world_motion", "concatenate_trajectories"]

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

    t: NDArray[np.float64]
    q_wb: NDArray[np.float64]
    omega_b: NDArray[np.float64]
    alpha_b: NDArray[np.float64]
    specific_force_b: NDArray[np.float64]
    pos_w: NDArray[np.float64]
    vel_w: NDArray[np.float64]
    mag_b: NDArray[np.float64]
    extras: dict[str, NDArray[Any]] = field(default_factory=dict)
    environment: Environment | None = None

    def __post_init__(self) -> None:
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

    def __getitem__(
        self, index: int | np.integer[Any] | slice | NDArray[np.bool_] | NDArray[np.integer[Any]]
    ) -> Trajectory:
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


def concatenate_trajectories(parts: list[Trajectory]) -> Trajectory:
    """One trajectory of consecutive ``parts`` (in time order, the same extras; the first's environment)."""
    first = parts[0]
    if len(parts) == 1:
        return first
    return Trajectory(
        t=np.concatenate([p.t for p in parts]),
        q_wb=np.concatenate([p.q_wb for p in parts]),
        **{name: np.concatenate([getattr(p, name) for p in parts]) for name in _VECTORS},
        extras={k: np.concatenate([p.extras[k] for p in parts]) for k in first.extras},
        environment=first.environment,
    )


@njit
def _to_body(
    q: NDArray[np.float64], v: NDArray[np.float64], out: NDArray[np.float64]
) -> None:  # pragma: no cover - compiled
    """out = R_bw v = q* ⊗ v ⊗ q (the inverse rotation of :func:`gyroemu.dynamics.rotation.quat_rotate`)."""
    w, x, y, z = q[0], -q[1], -q[2], -q[3]
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    out[0] = v[0] + w * tx + (y * tz - z * ty)
    out[1] = v[1] + w * ty + (z * tx - x * tz)
    out[2] = v[2] + w * tz + (x * ty - y * tx)


@njit
def _world_to_imu(
    q_wb: NDArray[np.float64],
    omega_wb: NDArray[np.float64],
    alpha_wb: NDArray[np.float64],
    vel_w: NDArray[np.float64],
    acc_w: NDArray[np.float64],
    earth_w: NDArray[np.float64],
    gravity_w: NDArray[np.float64],
    field_w: NDArray[np.float64],
    omega_b: NDArray[np.float64],
    alpha_b: NDArray[np.float64],
    force_b: NDArray[np.float64],
    mag_b: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """The equations of :func:`trajectory_from_world_motion`, one pass per sample."""
    earth_b = np.empty(3)
    f_w = np.empty(3)
    for i in range(q_wb.shape[0]):
        q = q_wb[i]
        _to_body(q, earth_w, earth_b)  # R_bw Ω
        w, a = omega_wb[i], alpha_wb[i]
        for j in range(3):
            omega_b[i, j] = w[j] + earth_b[j]  # ω_b = ω_wb + R_bw Ω
        # α_b = α_wb − ω_wb × (R_bw Ω)
        alpha_b[i, 0] = a[0] - (w[1] * earth_b[2] - w[2] * earth_b[1])
        alpha_b[i, 1] = a[1] - (w[2] * earth_b[0] - w[0] * earth_b[2])
        alpha_b[i, 2] = a[2] - (w[0] * earth_b[1] - w[1] * earth_b[0])
        # f_b = R_bw (a_w + 2 Ω × v_w − g)
        v = vel_w[i]
        f_w[0] = acc_w[i, 0] + 2.0 * (earth_w[1] * v[2] - earth_w[2] * v[1]) - gravity_w[0]
        f_w[1] = acc_w[i, 1] + 2.0 * (earth_w[2] * v[0] - earth_w[0] * v[2]) - gravity_w[1]
        f_w[2] = acc_w[i, 2] + 2.0 * (earth_w[0] * v[1] - earth_w[1] * v[0]) - gravity_w[2]
        _to_body(q, f_w, force_b[i])
        _to_body(q, field_w, mag_b[i])  # m_b = R_bw m_w


def trajectory_from_world_motion(
    t: ArrayLike,
    q_wb: ArrayLike,
    omega_wb_b: ArrayLike,
    alpha_wb_b: ArrayLike,
    pos_w: ArrayLike,
    vel_w: ArrayLike,
    acc_w: ArrayLike,
    environment: Environment,
    extras: dict[str, NDArray[Any]] | None = None,
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
    q_wb = np.ascontiguousarray(q_wb, dtype=float)
    n = len(q_wb)
    omega_b, alpha_b, force_b, mag_b = (np.empty((n, 3)) for _ in range(4))
    # numba reads strided (transposed, broadcast) inputs in place: no copies of long arrays.
    _world_to_imu(
        q_wb,
        np.asarray(omega_wb_b, dtype=float),
        np.asarray(alpha_wb_b, dtype=float),
        np.asarray(vel_w, dtype=float),
        np.asarray(acc_w, dtype=float),
        np.asarray(environment.earth_rate_w, dtype=float),
        np.asarray(environment.gravity_w, dtype=float),
        np.asarray(environment.magnetic_field_w, dtype=float),
        omega_b,
        alpha_b,
        force_b,
        mag_b,
    )
    return Trajectory(
        t=np.asarray(t, dtype=float),
        q_wb=q_wb,
        omega_b=omega_b,
        alpha_b=alpha_b,
        specific_force_b=force_b,
        pos_w=np.asarray(pos_w, dtype=float),
        vel_w=np.asarray(vel_w, dtype=float),
        mag_b=mag_b,
        extras=extras or {},
        environment=environment,
    )
