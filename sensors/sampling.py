"""The truth a mounted sensor sees, at any instant within a trajectory's span.

A :class:`~gyroemu.dynamics.Trajectory` is sampled at the scenario's rate; sensors need their truth at their
own instants (an inner rate for the physics, the output instants of a clock that runs fast or slow).
:class:`SensorTruth` interpolates splines (scipy's, compiled bit for bit by
:mod:`gyroemu.dynamics.cubic`), each built once, when first needed:

* ``ω_b`` by the cubic Hermite spline through the samples of ``ω_b`` with slopes ``α_b``, so
  ``ω`` and ``α`` are continuous and exact at the samples;
* ``f_b`` and ``m_b`` by cubic splines;
* ``q_wb`` by spherical linear interpolation (:func:`~gyroemu.dynamics.rotation.quat_interpolate`,
  scipy's ``Slerp`` compiled: a sample instant gives the sample itself).

It then applies the mounting: the sensor frame ``s`` is turned by ``q_bs`` from the body axes and its
origin sits at the lever arm ``r`` (body axes) from the body's reference point::

    ω_s = R_sb ω_b,   α_s = R_sb α_b,   m_s = R_sb m_b
    f_s = R_sb (f_b + α_b × r + ω_b × (ω_b × r))       (rigid-body acceleration of a point)
    q_is = q_iw(t) ⊗ q_wb ⊗ q_bs,   q_iw(t) = exp(Ω_w t / 2)    (world frame turning at Ω_w)
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics import Trajectory
from gyroemu.dynamics.cubic import HermiteCubic, not_a_knot
from gyroemu.dynamics.rigid_body import point_acceleration
from gyroemu.dynamics.rotation import (
    quat_conjugate,
    quat_from_rotvec,
    quat_interpolate,
    quat_multiply,
    quat_normalize,
    quat_rotate,
)

__all__ = ["SensorTruth"]


class SensorTruth:
    """Interpolated truth of a sensor mounted on the body of ``trajectory``.

    Parameters
    ----------
    trajectory : Trajectory
        At least two samples.
    q_bs : array_like (4,)
        Unit quaternion that turns sensor-frame vectors into body axes.
    lever_arm_b : array_like (3,)
        Sensor origin from the body's reference point, body axes, m.
    """

    def __init__(
        self,
        trajectory: Trajectory,
        q_bs: ArrayLike = (1.0, 0.0, 0.0, 0.0),
        lever_arm_b: ArrayLike = (0.0, 0.0, 0.0),
    ) -> None:
        if len(trajectory) < 2:
            raise ValueError("a sensor needs a trajectory of at least two samples")
        t = trajectory.t
        self._trajectory = trajectory
        self.t_start, self.t_end = float(t[0]), float(t[-1])
        self.q_bs = quat_normalize(np.asarray(q_bs, dtype=float))
        self.q_sb = quat_conjugate(self.q_bs)
        self.lever_arm_b = np.asarray(lever_arm_b, dtype=float)
        self._omega = HermiteCubic(t, trajectory.omega_b, trajectory.alpha_b)
        self._alpha = self._omega.derivative()
        self._force = not_a_knot(t, trajectory.specific_force_b)
        env = trajectory.environment
        self._earth_rate_w = np.zeros(3) if env is None else np.asarray(env.earth_rate_w, dtype=float)

    # Built on first use: most devices read neither the angle (only a rate-integrating gyro) nor the
    # field (only a magnetometer).

    @cached_property
    def _angle(self) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        from scipy.interpolate import CubicHermiteSpline  # scipy where used: the CLI's listings skip it

        trajectory = self._trajectory
        # scipy's PPoly (untyped): called with times, it gives the (M, 3) antiderivative
        angle: Callable[[NDArray[np.float64]], NDArray[np.float64]] = CubicHermiteSpline(
            trajectory.t, trajectory.omega_b, trajectory.alpha_b, axis=0
        ).antiderivative()
        return angle

    @cached_property
    def _mag(self) -> Callable[[ArrayLike], NDArray[np.float64]]:
        return not_a_knot(self._trajectory.t, self._trajectory.mag_b)

    def _attitude(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return quat_interpolate(self._trajectory.t, self._trajectory.q_wb, t)

    def _check(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        span = self.t_end - self.t_start
        if t.size and (t.min() < self.t_start - 1e-9 * span or t.max() > self.t_end + 1e-9 * span):
            raise ValueError(
                f"times {t.min():g}..{t.max():g} s leave the trajectory's span {self.t_start:g}..{self.t_end:g} s"
            )
        clipped: NDArray[np.float64] = np.clip(t, self.t_start, self.t_end)
        return clipped

    def omega_alpha(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Sensor-axes ``ω_s`` (rad/s) and ``α_s`` (rad/s²) at times ``t`` (M,): two (M, 3) arrays."""
        t = self._check(t)
        return quat_rotate(self.q_sb, self._omega(t)), quat_rotate(self.q_sb, self._alpha(t))

    def mean_omega(self, instants: ArrayLike) -> NDArray[np.float64]:
        """Sensor-axes mean angular velocity over each interval between consecutive ``instants``
        (K+1,), rad/s, (K, 3): what an ideal gyro reports on the strapdown sampling convention."""
        t = self._check(instants)
        return quat_rotate(self.q_sb, np.diff(self._angle(t), axis=0) / np.diff(t)[:, None])

    def specific_force(self, t: ArrayLike) -> NDArray[np.float64]:
        """Sensor-axes specific force at the sensor's origin, m/s², (M, 3)."""
        t = self._check(t)
        f = self._force(t)
        if np.any(self.lever_arm_b):
            f = point_acceleration(f, self._omega(t), self._alpha(t), self.lever_arm_b)
        return quat_rotate(self.q_sb, f)

    def magnetic_field(self, t: ArrayLike) -> NDArray[np.float64]:
        """Sensor-axes magnetic flux density, tesla, (M, 3)."""
        return quat_rotate(self.q_sb, self._mag(self._check(t)))

    def attitude_inertial(self, t: ArrayLike) -> NDArray[np.float64]:
        """``q_is``: the sensor's attitude relative to the inertial frame that is the world frame at
        ``t = 0``, (M, 4)."""
        t = self._check(t)
        q_wb = self._attitude(t)
        q_iw = quat_from_rotvec(t[:, None] * self._earth_rate_w)
        return quat_multiply(quat_multiply(q_iw, q_wb), self.q_bs)

    def attitude_world(self, t: ArrayLike) -> NDArray[np.float64]:
        """``q_wb`` of the body (not the sensor) at ``t``, (M, 4): what ``/truth/imu`` reports."""
        return self._attitude(self._check(t))

    def body_truth(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Body-frame truth at ``t`` as ``(q_wb, omega_b, specific_force_b)``, for truth channels."""
        t = self._check(t)
        return self._attitude(t), self._omega(t), self._force(t)

    def body_rates(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Body-frame ``(omega_b, specific_force_b)`` at ``t``: :meth:`body_truth` without the attitude
        (for a caller that has it from :meth:`attitude_world` already)."""
        t = self._check(t)
        return self._omega(t), self._force(t)
