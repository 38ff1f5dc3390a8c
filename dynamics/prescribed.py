"""The prescribed-motion base: what a kind that moves on the Earth prescribes, and how it becomes a Trajectory.

A kind of :class:`EarthBoundSpec` stands on the Earth at a site (the optional ``[site]`` table,
:class:`~gyroemu.dynamics.earth.Site`) and prescribes its motion *relative to the local ENU world frame* as a
:class:`WorldMotion`: attitude ``q_wb``, body rate ``ω_wb`` and its derivative ``α_wb`` (body axes),
position, velocity and acceleration (world axes). :meth:`EarthBoundSpec.trajectory` hands it to
:func:`~gyroemu.dynamics.trajectory.trajectory_from_world_motion`, which adds what the Earth contributes:
Earth rate, Coriolis, gravity and the magnetic field. The kinds live in :mod:`gyroemu.dynamics.motions`
(bench, rate table, oscillation, coning, sculling) and :mod:`gyroemu.dynamics.vehicles` (random
manoeuvre, car); their compiled building blocks in :mod:`gyroemu.dynamics.motion_kernels`.

Attitudes in config files are ``rpy_deg = [roll, pitch, yaw]`` in degrees with
``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`gyroemu.dynamics.rotation.quat_from_euler_zyx`); in the ENU world,
yaw 0 points body x east, yaw 90 north.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from .config import AnglesDeg, Section
from .earth import Site
from .rotation import quat_from_euler_zyx
from .scenarios import ScenarioSpec
from .trajectory import Trajectory, trajectory_from_world_motion

__all__ = ["quat_from_rpy_deg", "WorldMotion", "motion_arrays", "EarthBoundSpec", "Attitude"]


def quat_from_rpy_deg(rpy_deg: ArrayLike) -> NDArray[np.float64]:
    """Quaternion (4,) or (K, 4) of ``[roll, pitch, yaw]`` in degrees, ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    return quat_from_euler_zyx(np.radians(np.asarray(rpy_deg, dtype=float)))


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

    t: NDArray[np.float64]
    q_wb: NDArray[np.float64]
    omega_wb_b: NDArray[np.float64]
    alpha_wb_b: NDArray[np.float64]
    pos_w: NDArray[np.float64]
    vel_w: NDArray[np.float64]
    acc_w: NDArray[np.float64]
    extras: dict[str, NDArray[Any]] = field(default_factory=dict)

    @classmethod
    def rotation_only(
        cls,
        t: NDArray[np.float64],
        q_wb: NDArray[np.float64],
        omega_wb_b: NDArray[np.float64],
        alpha_wb_b: NDArray[np.float64],
        extras: dict[str, NDArray[Any]] | None = None,
    ) -> WorldMotion:
        """A body that rotates about its fixed reference point at the world origin."""
        # Three calls, not copies of one: np.zeros maps zero pages lazily, copies would write them.
        n = len(t)
        pos, vel, acc = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        return cls(t, q_wb, omega_wb_b, alpha_wb_b, pos, vel, acc, extras or {})


def motion_arrays(
    n: int, moves: bool
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]:
    """Outputs for a kind's kernel: ``q_wb`` (N, 4), ``ω_wb``, ``α_wb`` (N, 3), position, velocity,
    acceleration (N, 3). The kernel writes all of them if the body ``moves``; else position, velocity and
    acceleration are zeros (``np.zeros`` maps fresh zero pages lazily, cheaper than writing zeros; for
    arrays the kernel writes anyway ``np.empty`` spares the zeroing of reused memory)."""
    q, omega, alpha = np.empty((n, 4)), np.empty((n, 3)), np.empty((n, 3))
    new = np.empty if moves else np.zeros
    return q, omega, alpha, new((n, 3)), new((n, 3)), new((n, 3))


class EarthBoundSpec(ScenarioSpec):
    """Base of the kinds that move on the Earth at a ``[site]``: they prescribe :meth:`world_motion`."""

    site: Site = Field(default_factory=Site)

    def world_motion(self, t: NDArray[np.float64]) -> WorldMotion:
        """The motion relative to the world frame at the times ``t`` (N,), s."""
        raise NotImplementedError

    def evaluator(self) -> Callable[[NDArray[np.float64]], WorldMotion]:
        """A callable ``t -> WorldMotion`` with the time-independent setup (series, schedules) done once,
        for evaluating the motion piece by piece (a stream); by default :meth:`world_motion` itself."""
        return self.world_motion

    def trajectory(self, t: ArrayLike) -> Trajectory:
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

    rpy_deg: AnglesDeg = (0.0, 0.0, 0.0)

    def quat(self) -> NDArray[np.float64]:
        """``q_wb`` (4,)."""
        return quat_from_rpy_deg(self.rpy_deg)
