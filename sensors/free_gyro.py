"""The free two-gimbal gyro: a rotor that holds its direction in inertial space, read by its gimbals.

The instrument (Lecture 11, "free gyroscope"; Savet; Lawrence)
----------------------------------------------------------------
A rotor spins about its axis s with angular momentum H = I_s ω_s inside an *inner gimbal*, which turns
about an axis perpendicular to s inside an *outer gimbal*, which turns about an axis fixed in the case.
With frictionless bearings no torque reaches the rotor, so s stays fixed in inertial space while the
carrier turns around it, and the two gimbal angles read the carrier's attitude relative to the rotor.
This module's gyro 1 is the lecture's: spin axis along the sensor's x, inner gimbal about y, outer
gimbal about z (the case's z). Its gimbal angles are signed as the rotation of the case relative to
each gimbal (positive when the case turns positively about the gimbal axis while the gimbal holds
still), so that with the rotor direction s in case axes

    s = Rz(−ψ₁) Ry(−θ₁) e_x = (cos ψ₁ cos θ₁, −sin ψ₁ cos θ₁, sin θ₁):
    θ₁ = atan2(s_z, √(s_x² + s_y²)),   ψ₁ = atan2(−s_y, s_x).                                      (1)

One rotor fixes only a direction, so it reads two angles. Writing the carrier's attitude relative to
the rotor frame (the sensor's attitude when the rotor was uncaged at t[0]) as X-Y-Z Euler angles,
R = Rx(φ) Ry(θ) Rz(ψ) (intrinsic: roll about x, then pitch about the new y, then yaw about the newest
z), gives s = Rᵀ e_x = Rz(−ψ) Ry(−θ) e_x: **gyro 1's inner gimbal reads the pitch θ and its outer
gimbal the yaw ψ, exactly**; roll about the spin axis is invisible to it.

The mechanism is therefore **a pair**: gyro 2, spin axis along the sensor's y, inner gimbal about x,
outer gimbal about z, s₂ = Rz(−ψ₂) Rx(−θ₂) e_y, reads roll (θ₂ = φ exactly when θ = 0). The device
combines the two: undoing gyro 1's yaw and pitch from gyro 2's rotor direction leaves the roll,

    v = Ry(θ) Rz(ψ) s₂ = Rx(−φ) e_y = (0, cos φ, −sin φ):   φ = atan2(−v_z, v_y).                  (2)

**Indicated rate.** The device differentiates the attitude angles (φ, θ, ψ) in time (fourth-order
central differences on the inner grid, one-sided at the ends; error ≈ h⁴/30 · d⁵(angle)/dt⁵) and maps
the Euler rates to body rates:

    ω = (φ' cos θ cos ψ + θ' sin ψ,  −φ' cos θ sin ψ + θ' cos ψ,  φ' sin θ + ψ').                  (3)

**Gimbal lock.** When an inner gimbal nears ±90° its rotor's axis lines up with the outer gimbal axis:
the gimbals lose a degree of freedom (a real instrument's inner gimbal hits its stops there and the
case torques the rotor, which tumbles), and (3) is singular at θ = ±90°. The model keeps the rotor
ideal, flags every sample with an inner gimbal within ``gimbal_lock_margin_deg`` of 90° (raw
``gimbal_lock``), and then either **warns** (:class:`GimbalLockWarning`, the default:
``on_gimbal_lock = "warn"``) or **raises** :class:`GimbalLockError` (``"raise"``). Flagged samples'
angles and rates are not what the instrument would show.

Bearing friction and drift
--------------------------
Friction in a gimbal bearing torques the rotor, which precesses: the spin axis moves towards the
torque at the rate torque/H. A bearing turns at the gimbal's rate relative to its mount; as the
carrier turns about a rotor that holds still, the inner bearing turns at w_i = −ω·a_i and the outer
at w_o = −ω·m/cos²θ, where a_o is the outer axis (case z), a_i = a_o × s/|a_o × s| the inner one and
m = a_o − (a_o·s) s. Each bearing resists with a viscous and a Coulomb torque on its gimbal,
τ = −(b w + τ_c sign w). The inner gimbal carries the rotor and passes on the outer bearing's torque;
with massless gimbals and the spin speed held by its motor, the torque the rotor receives is
T = τ_i a_i + τ_o m/cos²θ (its component along a_o is τ_o, along a_i is τ_i, and it is ⊥ s), so

    H ds/dt = τ_i a_i + τ_o (a_o − (a_o·s) s) / (1 − (a_o·s)²).                                   (4)

Outer-bearing friction thus tilts the spin axis about the inner gimbal axis at τ_o/(H cos θ) (for
gyro 1, sin θ₁ grows at τ_o/H), and inner-bearing friction turns it about the outer axis, ψ₁' =
−τ_i/(H cos θ₁): the lecture's "drift due to friction". The bearing rates that set the friction are
the carrier-driven ones above; the drift's own contribution (≲ τ/H ~ 10⁻⁵ rad/s) is left out: it is
cross-coupled (an inner-bearing torque moves the outer bearing and vice versa) and small beside the
carrier's rate while the carrier turns, and leaving it out keeps Coulomb friction from chattering on
a carrier at rest. (4) is integrated in the inertial frame by Heun's method with renormalisation, in
a numba kernel; inside the gimbal-lock band the 1/cos²θ factor is held at its value at the band's edge.

**Pre-sliding (Dahl).** The sign law above is rate-independent: a bearing turning at Earth rate
(~5·10⁻⁵ rad/s on a bench) already gets the full τ_c. That is what ball bearings do once they have
turned through more than their pre-sliding displacement: their friction depends on the displacement,
not the speed (P. R. Dahl, "A solid friction model", Aerospace Corp. TOR-0158(3107-18)-1, 1968, from
ball-bearing measurements; B. Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, Automatica 30(7),
1083, 1994: pre-sliding displacement, then sliding). With
``presliding_displacement_rad`` θ_d > 0 the Coulomb part z of each bearing's torque follows Dahl's
model (exponent 1), dz/dx = (τ_c/θ_d)(1 − z sgn(ẋ)/τ_c) in the bearing's angle x, integrated
exactly over each step's displacement Δx (trapezoid of the bearing rate):
z ← τ_c sgn Δx + (z − τ_c sgn Δx) e^{−|Δx|/θ_d}. From an unloaded bearing (z = 0 at uncaging) turning
steadily at w, z = τ_c sgn w (1 − e^{−|w| t/θ_d}): the sign law after a transient of θ_d/|w| (a few
seconds at Earth rate for θ_d ~ 10⁻⁴ rad), a stiffness τ_c/θ_d for small reversals (vibration). The
default θ_d = 0 is the rigid limit, the sign law itself. A static bench turns the bearings through
~3·10⁻² rad in 10 min, far past any ball bearing's θ_d: either law then drifts τ_c/H ≈ 4.4 °/h off
the Earth-rate components (yaw Ω sin φ − τ_c/H, pitch Ω cos φ + τ_c/H, roll −τ_c/H), as a real
directional gyro with such bearings would. Dahl's law differs where a bearing turns through less than
θ_d: the first θ_d/|w| after uncaging or a reversal, and bearings the carrier turns only through a
geometric coupling (on the bench gyro 2's inner one, at ~Ω² t: the sign law gives it the full τ_c).

Chunks
------
A long run comes in chunks that share their edge sample (:mod:`gyroemu.sensors.mechanism`). The state carries
what ties the chunks into one run:

* ``state["q_uncage"]`` (4,): q_is at the run's first sample, the attitude in which the rotors were set
  (the rotor frame); every chunk's attitude is taken relative to it.
* ``state["spins"]`` (2, 3): the rotor directions in the rotor frame at the chunk's last sample, where
  (4) continues by the same Heun steps. With the sign law the friction torques are memoryless (set by
  the carrier-driven bearing rates of each sample), so the rotor directions are all the friction drift
  carries; with Dahl's law ``state["bearing_torque"]`` (2, 2) carries each gyro's (inner, outer)
  Coulomb-part torque z, N·m, at the last sample.
* ``state["attitude_tail"]`` (≤ 5, 3): the unwrapped (φ, θ, ψ) of the last five samples so far (the
  shared sample last). The next chunk's angles are unwrapped on from it, and its differences reach
  back into it: from its second sample on, the central and end formulas see the samples a single
  call would see.
* ``state["rate"]`` (3,): the indicated rate at the last sample, which the next chunk's first sample
  repeats; ``state["lock_reported"]``: gimbal lock was already reported in this run (once, as one call).

The differences need two samples beyond a sample, which a chunk does not have at its end: there the
rate is the one-sided estimate, as for a single call ending at that sample. So a chunked run equals one
call to round-off except at the last two samples of each chunk but the final one, whose Euler rates
differ from the central estimates by at most the two truncation errors, h⁴ max|y⁽⁵⁾| (1/5 + 1/30)
(the same order as a single call's own error at its ends). The gimbal angles, the attitude and the
lock flags are the same samples as in one call.

Neglected: nutation of the rotor in its gimbals (at H/√(J_i J_o), hundreds of Hz, and damped), gimbal
inertia, rotor mass unbalance (g-dependent drift; the IMU's error layer has g-sensitivity), erection
systems. The intrinsic noise density is 0. :meth:`FreeGyro.inner_rate_hz` is the output rate: the
model has no dynamics of its own to resolve.

Defaults
--------
An electrically driven aircraft attitude/directional gyro: a 400-Hz induction-motor rotor of
I_s = 6·10⁻⁵ kg·m² at 22 500 rpm (H ≈ 0.14 N·m·s); ball-bearing gimbal pivots with Coulomb friction
3·10⁻⁶ N·m and viscous friction 2·10⁻⁶ N·m·s/rad each, a drift of ≈ 4.4 °/h from Coulomb friction
while the carrier turns (a few °/h, as such instruments drift); gimbal freedom ±85° (margin 5°).

Sources
-------
* Lecture 11, "Angular momentum, tops and gyroscopes" (``/work/shared/seeds``): the two-gimbal free
  gyro, two gyros for three Euler angles, drift from friction at the joints.
* P. H. Savet (ed.), *Gyroscopes: Theory and Design*, McGraw-Hill 1961 (free gyros, gimbal errors).
* A. Lawrence, *Modern Inertial Technology*, 2nd ed., Springer 1998, ch. 5–7.
"""

from __future__ import annotations

import math
import warnings
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal, Real
from gyroemu.dynamics.jit import njit
from gyroemu.dynamics.rotation import quat_conjugate, quat_multiply, quat_rotate

from .mechanism import GyroMechanism, GyroResponse, GyroTruth
from .rate_gyro import RPM

__all__ = [
    "FreeGyro",
    "GimbalLockWarning",
    "GimbalLockError",
    "gimbal_angles",
    "euler_xyz_from_spins",
    "body_rate_from_euler_xyz",
    "time_derivative",
]

#: Rotor directions at uncaging, in the sensor's axes at t[0]: gyro 1 along x, gyro 2 along y.
SPIN_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


class GimbalLockWarning(RuntimeWarning):
    """An inner gimbal of a free gyro came within the lock margin of ±90°."""


class GimbalLockError(RuntimeError):
    """An inner gimbal of a free gyro came within the lock margin of ±90° (``on_gimbal_lock = "raise"``)."""


class FreeGyro(GyroMechanism):
    """A pair of free two-gimbal gyros reading the carrier's attitude (see the module notes).

    Parameters (config keys)
    ------------------------
    rotor_inertia_kgm2 : each rotor about its spin axis, kg·m².
    spin_speed_rpm : rotor speed, rpm.
    outer_viscous_friction_n_m_s_per_rad, outer_coulomb_friction_n_m : outer gimbal bearing.
    inner_viscous_friction_n_m_s_per_rad, inner_coulomb_friction_n_m : inner gimbal bearing.
    presliding_displacement_rad : Dahl's pre-sliding displacement θ_d = τ_c/σ₀ of every bearing, rad;
        0 (the default): the rigid limit, Coulomb's sign law.
    gimbal_lock_margin_deg : an inner gimbal within this of ±90° is locked.
    on_gimbal_lock : ``"warn"`` (default) or ``"raise"``.
    """

    kind: Literal["free-gyro"] = "free-gyro"
    reads: ClassVar[frozenset[str]] = frozenset({"q_is"})
    rotor_inertia_kgm2: PositiveReal = 6.0e-5
    spin_speed_rpm: PositiveReal = 22500.0
    outer_viscous_friction_n_m_s_per_rad: NonNegativeReal = 2.0e-6
    outer_coulomb_friction_n_m: NonNegativeReal = 3.0e-6
    inner_viscous_friction_n_m_s_per_rad: NonNegativeReal = 2.0e-6
    inner_coulomb_friction_n_m: NonNegativeReal = 3.0e-6
    presliding_displacement_rad: NonNegativeReal = 0.0
    gimbal_lock_margin_deg: Annotated[Real, Field(gt=0, lt=90)] = 5.0
    on_gimbal_lock: Literal["warn", "raise"] = "warn"

    @property
    def spin_momentum(self) -> float:
        """H = I_s ω_s, N·m·s."""
        return self.rotor_inertia_kgm2 * self.spin_speed_rpm * RPM

    @property
    def frictionless(self) -> bool:
        """No bearing friction at all: the rotors hold still and the gimbal angles are exact."""
        return not any(
            (
                self.outer_viscous_friction_n_m_s_per_rad,
                self.outer_coulomb_friction_n_m,
                self.inner_viscous_friction_n_m_s_per_rad,
                self.inner_coulomb_friction_n_m,
            )
        )

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        """The output rate: the model has no dynamics of its own to resolve."""
        return output_rate_hz

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Indicated rate (M, 3), rad/s, from the gimbal angles. Draws nothing.

        Raw: ``gimbal_angle_rad`` (M, 4) = (θ₁ inner, ψ₁ outer, θ₂ inner, ψ₂ outer); ``attitude_xyz_rad``
        (M, 3) = (φ, θ, ψ), the attitude the pair indicates relative to the run's first sample;
        ``gimbal_lock`` (M,) bool.

        ``state`` (empty or None at power-up, when the rotors are uncaged at t[0]): ``q_uncage``,
        ``spins``, ``attitude_tail``, ``rate`` and ``lock_reported``, as in the module notes.
        """
        state = {} if state is None else state
        # Attitude relative to the uncaging attitude at power-up, in which the rotors were set.
        q_is = np.asarray(truth.q_is, dtype=float)
        q_uncage = state.get("q_uncage", q_is[0])
        q_rel = quat_multiply(quat_conjugate(q_uncage), q_is)
        spins = self._spins(
            q_rel, np.asarray(truth.omega, dtype=float), truth.dt, state.get("spins", SPIN_AXES), state
        )  # (M, 2, 3) rotor frame
        spins_case = quat_rotate(quat_conjugate(q_rel)[:, None, :], spins)  # (M, 2, 3) case axes

        gimbals = gimbal_angles(spins_case)
        attitude = euler_xyz_from_spins(spins_case, gimbals)
        locked = np.abs(gimbals[:, [0, 2]]).max(axis=1) > math.radians(90.0 - self.gimbal_lock_margin_deg)
        if np.any(locked) and not state.get("lock_reported", False):
            state["lock_reported"] = True
            self._report_lock(truth.t, gimbals, locked)

        # Unwrap and differentiate on from the previous samples: the tail's last sample is this chunk's
        # first (the same angles, up to the turns the tail has unwrapped), so it is left out here.
        tail = state.get("attitude_tail")
        history = attitude if tail is None else np.concatenate([tail, attitude[1:]])
        unwrapped_history = np.unwrap(history, axis=0)
        skip = 0 if tail is None else len(tail) - 1
        unwrapped = unwrapped_history[skip:]
        rate = body_rate_from_euler_xyz(unwrapped, time_derivative(unwrapped_history, truth.dt)[skip:])
        if "rate" in state:
            rate[0] = state["rate"]  # the shared sample repeats the previous chunk's last (one-sided) value

        state["q_uncage"] = np.array(q_uncage, dtype=float)
        state["spins"] = np.array(spins[-1])
        state["attitude_tail"] = unwrapped_history[-5:].copy()  # enough for the end formulas' five points
        state["rate"] = rate[-1].copy()
        return GyroResponse(
            rate=rate, raw={"gimbal_angle_rad": gimbals, "attitude_xyz_rad": attitude, "gimbal_lock": locked}
        )

    def _spins(
        self,
        q_rel: NDArray[np.float64],
        omega: NDArray[np.float64],
        dt: float,
        spins0: ArrayLike = SPIN_AXES,
        state: dict[str, Any] | None = None,
    ) -> NDArray[np.float64]:
        """Rotor directions (M, 2, 3) in the rotor (inertial) frame from ``spins0`` at the first sample:
        fixed, or drifting by (4). With Dahl's law the bearing torques continue from
        ``state["bearing_torque"]`` (unloaded without it) and are stored back there."""
        spins0 = np.ascontiguousarray(spins0, dtype=float)
        if self.frictionless:
            return np.broadcast_to(spins0, (len(q_rel), 2, 3))
        out = np.empty((len(q_rel), 2, 3))
        min_cos2 = math.sin(math.radians(self.gimbal_lock_margin_deg)) ** 2
        if self.presliding_displacement_rad > 0:
            state = {} if state is None else state
            z = np.array(state.get("bearing_torque", np.zeros((2, 2))), dtype=float)
            _drift_dahl(
                np.ascontiguousarray(q_rel),
                np.ascontiguousarray(omega),
                dt,
                self.spin_momentum,
                self.outer_viscous_friction_n_m_s_per_rad,
                self.outer_coulomb_friction_n_m,
                self.inner_viscous_friction_n_m_s_per_rad,
                self.inner_coulomb_friction_n_m,
                min_cos2,
                self.presliding_displacement_rad,
                spins0,
                z,
                out,
            )
            state["bearing_torque"] = z
            return out
        _drift(
            np.ascontiguousarray(q_rel),
            np.ascontiguousarray(omega),
            dt,
            self.spin_momentum,
            self.outer_viscous_friction_n_m_s_per_rad,
            self.outer_coulomb_friction_n_m,
            self.inner_viscous_friction_n_m_s_per_rad,
            self.inner_coulomb_friction_n_m,
            min_cos2,
            spins0,
            out,
        )
        return out

    def _report_lock(self, t: NDArray[np.float64], gimbals: NDArray[np.float64], locked: NDArray[np.bool_]) -> None:
        first = int(np.argmax(locked))
        which = 1 + int(abs(gimbals[first, 2]) > abs(gimbals[first, 0]))
        worst = math.degrees(np.abs(gimbals[:, [0, 2]]).max())
        message = (
            f"free gyro {which}'s inner gimbal is within {self.gimbal_lock_margin_deg:g}° of 90° "
            f"(gimbal lock) from t = {t[first]:.6g} s, {int(locked.sum())} samples flagged in raw "
            f"'gimbal_lock', largest inner gimbal angle {worst:.3f}°; angles and rates there are not "
            "what the instrument shows"
        )
        if self.on_gimbal_lock == "raise":
            raise GimbalLockError(message)
        warnings.warn(message, GimbalLockWarning, stacklevel=3)


# --------------------------------------------------------------------------------------------------
# Gimbal geometry
# --------------------------------------------------------------------------------------------------


def gimbal_angles(spins_case: NDArray[np.float64]) -> NDArray[np.float64]:
    """Gimbal angles (..., 4) = (θ₁, ψ₁, θ₂, ψ₂), rad, from the rotor directions (..., 2, 3) in case axes.

    Gyro 1 (spin x, inner y, outer z): s = Rz(−ψ₁) Ry(−θ₁) e_x, equation (1).
    Gyro 2 (spin y, inner x, outer z): s = Rz(−ψ₂) Rx(−θ₂) e_y = (sin ψ₂ cos θ₂, cos ψ₂ cos θ₂, −sin θ₂).
    """
    (x1, y1, z1), (x2, y2, z2) = np.moveaxis(spins_case[..., 0, :], -1, 0), np.moveaxis(spins_case[..., 1, :], -1, 0)
    return np.stack(
        [np.arctan2(z1, np.hypot(x1, y1)), np.arctan2(-y1, x1), np.arctan2(-z2, np.hypot(x2, y2)), np.arctan2(x2, y2)],
        axis=-1,
    )


def euler_xyz_from_spins(
    spins_case: NDArray[np.float64], gimbals: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """Attitude (..., 3) = (φ, θ, ψ), rad, with R = Rx(φ) Ry(θ) Rz(ψ), from the rotor directions (..., 2, 3).

    θ and ψ are gyro 1's gimbal angles (``gimbals``, their :func:`gimbal_angles` when already at
    hand); φ comes from gyro 2 by (2).
    """
    if gimbals is None:
        gimbals = gimbal_angles(spins_case)
    theta, psi, s2 = gimbals[..., 0], gimbals[..., 1], spins_case[..., 1, :]
    cp, sp, ct, st = np.cos(psi), np.sin(psi), np.cos(theta), np.sin(theta)
    a = cp * s2[..., 0] - sp * s2[..., 1]  # Rz(ψ) s₂, x
    v_y = sp * s2[..., 0] + cp * s2[..., 1]  # Rz(ψ) s₂, y (Ry(θ) leaves it)
    v_z = -st * a + ct * s2[..., 2]  # Ry(θ) Rz(ψ) s₂, z
    return np.stack([np.arctan2(-v_z, v_y), theta, psi], axis=-1)


def body_rate_from_euler_xyz(angles: NDArray[np.float64], rates: NDArray[np.float64]) -> NDArray[np.float64]:
    """Body angular velocity (..., 3) of R = Rx(φ) Ry(θ) Rz(ψ) from (φ, θ, ψ) and their rates, equation (3)."""
    phi_dot, theta_dot, psi_dot = np.moveaxis(rates, -1, 0)
    theta, psi = angles[..., 1], angles[..., 2]
    ct, st, cp, sp = np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
    return np.stack(
        [phi_dot * ct * cp + theta_dot * sp, -phi_dot * ct * sp + theta_dot * cp, phi_dot * st + psi_dot], axis=-1
    )


def time_derivative(y: ArrayLike, h: float) -> NDArray[np.float64]:
    """dy/dt along axis 0 of uniform samples ``y`` (M, ...), by fourth-order finite differences.

    Interior: (y_{k−2} − 8 y_{k−1} + 8 y_{k+1} − y_{k+2}) / 12h, error h⁴ y⁽⁵⁾/30; the two samples at
    each end use the one-sided five-point formulas (errors h⁴ y⁽⁵⁾/5 and /20). Fewer than five
    samples: ``numpy.gradient``.
    """
    y = np.asarray(y, dtype=float)
    if len(y) < 2:
        return np.zeros_like(y)
    if len(y) < 5:
        gradient: NDArray[np.float64] = np.gradient(y, h, axis=0)
        return gradient
    d = np.empty_like(y)
    d[2:-2] = y[:-4] - 8 * y[1:-3] + 8 * y[3:-1] - y[4:]
    d[0] = -25 * y[0] + 48 * y[1] - 36 * y[2] + 16 * y[3] - 3 * y[4]
    d[1] = -3 * y[0] - 10 * y[1] + 18 * y[2] - 6 * y[3] + y[4]
    d[-1] = 25 * y[-1] - 48 * y[-2] + 36 * y[-3] - 16 * y[-4] + 3 * y[-5]
    d[-2] = 3 * y[-1] + 10 * y[-2] - 18 * y[-3] + 6 * y[-4] - y[-5]
    return d / (12 * h)


# --------------------------------------------------------------------------------------------------
# Friction drift, equation (4)
# --------------------------------------------------------------------------------------------------


@njit
def _rotate(q: NDArray[np.float64], v: NDArray[np.float64], conjugate: bool) -> NDArray[np.float64]:
    """q ⊗ v ⊗ q* (or q* ⊗ v ⊗ q with ``conjugate``) for one quaternion (4,) and vector (3,)."""
    w = q[0]
    ux, uy, uz = (-q[1], -q[2], -q[3]) if conjugate else (q[1], q[2], q[3])
    tx, ty, tz = 2 * (uy * v[2] - uz * v[1]), 2 * (uz * v[0] - ux * v[2]), 2 * (ux * v[1] - uy * v[0])
    return np.array(
        [v[0] + w * tx + uy * tz - uz * ty, v[1] + w * ty + uz * tx - ux * tz, v[2] + w * tz + ux * ty - uy * tx]
    )


@njit
def _spin_rate(
    q: NDArray[np.float64],
    omega: NDArray[np.float64],
    s: NDArray[np.float64],
    h: float,
    b_o: float,
    c_o: float,
    b_i: float,
    c_i: float,
    min_cos2: float,
) -> NDArray[np.float64]:
    """ds/dt (3,) in the rotor frame by (4), for rotor direction ``s`` and the carrier at ``q``, ``omega``."""
    sc = _rotate(q, s, True)  # s in case axes; the outer axis a_o is case z
    cos2 = max(1.0 - sc[2] * sc[2], min_cos2)  # cos²θ of the inner gimbal
    cos = math.sqrt(cos2)
    a_i = np.array([-sc[1] / cos, sc[0] / cos, 0.0])  # a_o × s / |a_o × s|
    m = np.array([-sc[2] * sc[0], -sc[2] * sc[1], 1.0 - sc[2] * sc[2]])  # a_o − (a_o·s) s
    w_i = -(omega[0] * a_i[0] + omega[1] * a_i[1])  # bearing rates, carrier-driven
    w_o = -(omega[0] * m[0] + omega[1] * m[1] + omega[2] * m[2]) / cos2
    tau_i = -(b_i * w_i + c_i * np.sign(w_i))
    tau_o = -(b_o * w_o + c_o * np.sign(w_o))
    torque = tau_i * a_i + (tau_o / cos2) * m
    rate: NDArray[np.float64] = _rotate(q, torque, False) / h
    return rate


@njit
def _drift(
    q_rel: NDArray[np.float64],
    omega: NDArray[np.float64],
    dt: float,
    h: float,
    b_o: float,
    c_o: float,
    b_i: float,
    c_i: float,
    min_cos2: float,
    spins0: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Integrate (4) for each rotor by Heun's method with renormalisation; fills ``out`` (M, 2, 3)."""
    n = q_rel.shape[0]
    for g in range(spins0.shape[0]):
        s = spins0[g].copy()
        out[0, g] = s
        for k in range(1, n):
            f0 = _spin_rate(q_rel[k - 1], omega[k - 1], s, h, b_o, c_o, b_i, c_i, min_cos2)
            guess = s + dt * f0
            guess /= math.sqrt(guess[0] ** 2 + guess[1] ** 2 + guess[2] ** 2)
            f1 = _spin_rate(q_rel[k], omega[k], guess, h, b_o, c_o, b_i, c_i, min_cos2)
            s = s + 0.5 * dt * (f0 + f1)
            s /= math.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
            out[k, g] = s


# Dahl's law (``presliding_displacement_rad`` > 0). Separate kernels, so that the sign law's path stays
# the same arithmetic as before.


@njit
def _bearings(
    q: NDArray[np.float64], omega: NDArray[np.float64], s: NDArray[np.float64], min_cos2: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float, float]:
    """Inner axis a_i, m = a_o − (a_o·s) s (case axes), cos²θ and the carrier-driven bearing rates."""
    sc = _rotate(q, s, True)
    cos2 = max(1.0 - sc[2] * sc[2], min_cos2)
    cos = math.sqrt(cos2)
    a_i = np.array([-sc[1] / cos, sc[0] / cos, 0.0])
    m = np.array([-sc[2] * sc[0], -sc[2] * sc[1], 1.0 - sc[2] * sc[2]])
    w_i = -(omega[0] * a_i[0] + omega[1] * a_i[1])
    w_o = -(omega[0] * m[0] + omega[1] * m[1] + omega[2] * m[2]) / cos2
    return a_i, m, cos2, w_i, w_o


@njit
def _dahl(z: float, coulomb: float, displacement: float, theta_d: float) -> float:
    """Dahl's model over a bearing displacement: z relaxes towards τ_c sgn Δx as e^{−|Δx|/θ_d}."""
    if displacement == 0.0:
        return z
    target = coulomb if displacement > 0.0 else -coulomb
    return target + (z - target) * math.exp(-abs(displacement) / theta_d)


@njit
def _drift_dahl(
    q_rel: NDArray[np.float64],
    omega: NDArray[np.float64],
    dt: float,
    h: float,
    b_o: float,
    c_o: float,
    b_i: float,
    c_i: float,
    min_cos2: float,
    theta_d: float,
    spins0: NDArray[np.float64],
    z: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Heun's method for (4) with Dahl's Coulomb part; ``z`` (2, 2) = (inner, outer) per gyro, in and out."""
    n = q_rel.shape[0]
    for g in range(spins0.shape[0]):
        s = spins0[g].copy()
        z_i, z_o = z[g, 0], z[g, 1]
        out[0, g] = s
        for k in range(1, n):
            a_i, m, cos2, w_i0, w_o0 = _bearings(q_rel[k - 1], omega[k - 1], s, min_cos2)
            torque = -(b_i * w_i0 + z_i) * a_i - ((b_o * w_o0 + z_o) / cos2) * m
            f0 = _rotate(q_rel[k - 1], torque, False) / h
            guess = s + dt * f0
            guess /= math.sqrt(guess[0] ** 2 + guess[1] ** 2 + guess[2] ** 2)
            a_i, m, cos2, w_i1, w_o1 = _bearings(q_rel[k], omega[k], guess, min_cos2)
            z_i = _dahl(z_i, c_i, 0.5 * dt * (w_i0 + w_i1), theta_d)
            z_o = _dahl(z_o, c_o, 0.5 * dt * (w_o0 + w_o1), theta_d)
            torque = -(b_i * w_i1 + z_i) * a_i - ((b_o * w_o1 + z_o) / cos2) * m
            f1 = _rotate(q_rel[k], torque, False) / h
            s = s + 0.5 * dt * (f0 + f1)
            s /= math.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2)
            out[k, g] = s
        z[g, 0], z[g, 1] = z_i, z_o
