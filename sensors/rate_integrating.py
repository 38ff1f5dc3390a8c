"""The floated rate-integrating gyro (RIG), open-loop or in a torque-rebalance loop.

The instrument (IEEE Std 517-1974 names its axes; Lecture 11, "rate integrating gyros")
-------------------------------------------------------------------------------------------
The same single-degree-of-freedom gimbal as the rate gyro (:mod:`gyroemu.sensors.rate_gyro`: rotor angular
momentum H = I_s ω_s along the spin reference axis SRA, gimbal free to turn by θ about the output axis
OA, input axis IA with IA × OA = SRA), but with no spring: the gimbal is a sealed float in a viscous
fluid, restrained only by the damping c of the thin fluid gap, and a torquer may apply a torque T:

    J θ'' + c θ' = H (ω_IA cos θ − ω_SRA sin θ) − J ω'_OA − T                                      (1)

The cross-coupling and output-axis angular-acceleration terms are those of the rate gyro (see there,
with what is neglected). With T = 0 and small θ, (1) integrates once to J θ' + c θ = H ∫ω_IA dt:

    θ(t) ≈ (H/c) ∫ω_IA dt                  for motions slower than the float's corner c/J,

so the gimbal angle measures the *angle* turned about IA, with gain H/c. The open-loop instrument
indicates the angle (c/H) θ; its transfer function from the input angle is 1/(1 + s J/c), a first-order
lag with the corner frequency c/J. For a rate step ω from rest at t = 0,

    θ(t) = (H/c) ω [t − (J/c)(1 − e^{−c t/J})].                                                    (2)

Gimbal stops (a degree or two) bound θ, so an open-loop RIG only works where something else keeps θ
near zero: a stable platform's servo, or the torque-rebalance loop below. Passing a stop with the loop
open raises a warning.

Torque rebalance (``torque_rebalance = true``, the default: strapdown use)
-----------------------------------------------------------------------------
A PI controller drives the torquer current i from the pickoff angle, and the torquer (scale factor
k_t) applies T = k_t i about OA, nulling θ:

    i = k_p θ + k_i ∫θ dt,        T = k_t i.                                                       (3)

In steady state T balances the gyroscopic torque, so **i = H ω/k_t**, and the indicated rate is
k_t i/H. With θ held at zero the cross-coupling vanishes. From ω_IA to the indicated rate the closed
loop is

    k_t (k_p s + k_i) / (J s³ + c s² + k_t k_p s + k_t k_i),                                      (4)

stable when k_p > 0 and k_i < c k_p / J (Routh–Hurwitz; checked on the config). Its bandwidth ω_b,
where |(4)| falls through 1/√2, is the square root of the smallest positive root x of

    J² x³ + (c² − 2 J k_t k_p) x² − (k_t² k_p² + 2 c k_t k_i) x − k_t² k_i² = 0                    (5)

(:attr:`RateIntegratingGyro.loop_bandwidth_hz`). For a float much faster than the loop (J → 0) this
is a second-order loop with ω_n² = k_t k_i/c, 2ζω_n = k_t k_p/c and ω_b = ω_n [1 + 2ζ² +
√((1 + 2ζ²)² + 1)]^½.

Output
------
The instrument reports an **angle** (M, 3), cumulative from 0 at t[0]: open-loop (c/H) θ; closed-loop
(k_t/H) ∫ i dt, the torquer current read out as charge (as a voltage-to-frequency converter does), so
its derivative is the indicated rate k_t i/H. Raw: ``gimbal_angle_rad`` θ and ``torquer_current_a`` i
(zero with the loop open), each (M, 3).

Simulation
----------
As for the rate gyro: the state x = (θ, θ') open-loop, or (θ, θ', ∫θ dt, ∫i dt) closed-loop, follows
the exact first-order-hold discretisation of its linear part, with the θ-dependent torque solved
per step and inelastic stops (:func:`gyroemu.sensors.rate_gyro.simulate_gimbal`); ∫i dt is a state, so the
angle output is the exact integral of the simulated current. Each gyro starts in equilibrium with
the first sample's input (the particular solution for an input torque ramping at u' = H ω'_IA): open
loop at θ = 0 with the float drifting at θ' = u/c − J u'/c²; closed loop with the integrator charged
to carry the torque, θ = u'/(k_t k_i) (or, for k_i = 0, θ = u/(k_t k_p) − c u'/(k_t k_p)²).
:meth:`RateIntegratingGyro.inner_rate_hz` resolves the fastest pole (the float corner open-loop, the
loop's poles closed-loop) with 20 samples per period, at an integer multiple of the output rate.

Chunks (:mod:`gyroemu.sensors.mechanism`): ``state["gimbal_state"]`` (3, n) is x at a chunk's last sample, the
whole state of the recurrence (the torque is recomputed from θ and the shared sample's input, the same
numbers), so the next chunk continues the run bit for bit: the float's angle and rate, and closed-loop
the loop integrator ∫θ dt and the charge ∫i dt. The indicated angle restarts from 0 at each chunk's
first sample: open-loop (c/H)(θ − θ₀), closed-loop (k_t/H)(∫i dt − its value at the first sample),
with θ₀ and the charge carried in x (both 0 at power-up, where the output is as before).
``state["stop_warned"]`` keeps an open loop from warning about its stops again in later chunks of a run.

Defaults
--------
A size-18 floated single-degree-of-freedom RIG of the strapdown kind: a 24 000-rpm, 400-Hz
hysteresis-synchronous spin motor with I_s = 2·10⁻⁶ kg·m² (H ≈ 5.0·10⁻³ N·m·s = 5·10⁴ g·cm²/s); a float
of J = 1·10⁻⁵ kg·m² in a fluid gap of c = 5·10⁻³ N·m·s/rad, so a gimbal gain H/c ≈ 1.0 and a float time
constant J/c = 2 ms (corner 80 Hz); float freedom ±2°. Torquer k_t = 0.02 N·m/A (scale factor
k_t/H ≈ 4.0 rad/s/A ≈ 820 °/h/mA); PI gains k_p = 60 A/rad, k_i = 4000 A/(rad·s), which put the loop's
poles at −100 s⁻¹ and −200 ± 200j s⁻¹ and its bandwidth at ≈ 61 Hz. Brownian torque noise,
√(2 k_B T c)/H ≈ 10⁻⁹ rad/s/√Hz, is far below any real RIG's, so the intrinsic noise density is 0.

Sources
-------
* A. Lawrence, *Modern Inertial Technology*, 2nd ed., Springer 1998, ch. 5–7 (the floated
  rate-integrating gyro, torque-to-balance loops).
* P. H. Savet (ed.), *Gyroscopes: Theory and Design*, McGraw-Hill 1961.
* IEEE Std 517-1974, specification format and test procedure for single-degree-of-freedom
  rate-integrating gyros.
* Lecture 11 (``/work/shared/seeds``): I_s ω_s ω_z = b θ' for the rate-integrating gyro.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, ClassVar, Literal, overload

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, StrictBool, ValidationInfo, field_validator

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal

from .mechanism import GyroMechanism, GyroResponse, GyroTruth
from .rate_gyro import RPM, StopAngle, gimbal_pole_problem, inner_rate_for, sdf_axes, simulate_gimbal

__all__ = ["RateIntegratingGyro", "MIN_INTEGRAL_CORNER_HZ"]

MIN_INTEGRAL_CORNER_HZ = 1e-3
"""The slowest integral corner k_i/(2π k_p) of the rebalance loop's PI, Hz (or k_i = 0): four decades
below the default's 10.6 Hz and real loops' tens of Hz; below it the power-up state θ = u'/(k_t k_i)
overflows (k_i = 1e-300 gave NaN output)."""


class RateIntegratingGyro(GyroMechanism):
    """Floated rate-integrating gyro triad, optionally torque-rebalanced (see the module notes).

    Parameters (config keys)
    ------------------------
    rotor_inertia_kgm2 : rotor about its spin axis, kg·m².
    spin_speed_rpm : rotor speed relative to the gimbal, rpm.
    gimbal_inertia_kgm2 : J, float and rotor about the output axis, kg·m².
    damping_n_m_s_per_rad : c, viscous damping of the float.
    stop_angle_deg : float freedom ±θ_stop, below 90°.
    torque_rebalance : close the PI torque-rebalance loop (true) or read the gimbal angle (false).
    torquer_scale_n_m_per_a : k_t.
    loop_proportional_a_per_rad, loop_integral_a_per_rad_s : k_p, k_i of the PI controller.
    """

    kind: Literal["rate-integrating"] = "rate-integrating"
    reads: ClassVar[frozenset[str]] = frozenset()
    rotor_inertia_kgm2: PositiveReal = 2.0e-6
    spin_speed_rpm: PositiveReal = 24000.0
    gimbal_inertia_kgm2: PositiveReal = 1.0e-5
    # validate_default: the float's corner must also be checked when only the inertia is given.
    damping_n_m_s_per_rad: PositiveReal = Field(5.0e-3, validate_default=True)
    stop_angle_deg: StopAngle = 2.0
    torque_rebalance: StrictBool = True
    torquer_scale_n_m_per_a: PositiveReal = 0.02
    loop_proportional_a_per_rad: PositiveReal = 60.0
    # validate_default: the stability check must also run when only the other gains are given.
    loop_integral_a_per_rad_s: NonNegativeReal = Field(4000.0, validate_default=True)

    @field_validator("damping_n_m_s_per_rad")
    @classmethod
    def _float_corner(cls, c: float, info: ValidationInfo) -> float:
        j = info.data.get("gimbal_inertia_kgm2")
        if j is not None:  # the open loop's pole, and the closed loop's fastest when the float is fast
            problem = gimbal_pole_problem(f"the float's corner c/2πJ (J = {j:g} kg·m²)", c / j / (2 * math.pi))
            if problem is not None:
                raise ValueError(problem)
        return c

    @field_validator("loop_integral_a_per_rad_s")
    @classmethod
    def _stable_loop(cls, k_i: float, info: ValidationInfo) -> float:
        j, c, k_t, k_p = (
            info.data.get(key)
            for key in (
                "gimbal_inertia_kgm2",
                "damping_n_m_s_per_rad",
                "torquer_scale_n_m_per_a",
                "loop_proportional_a_per_rad",
            )
        )
        if not info.data.get("torque_rebalance") or j is None or c is None or k_p is None:
            return k_i
        corner = k_i / k_p / (2 * math.pi) if k_p > 0 else math.inf
        if 0 < corner < MIN_INTEGRAL_CORNER_HZ:
            raise ValueError(
                f"puts the loop's integral corner k_i/(2π k_p) at {corner:.3g} Hz, below the limit of "
                f"{MIN_INTEGRAL_CORNER_HZ:g} Hz (real loops put it at tens of Hz; the float's offset settles "
                "over 1/corner, and θ = u'/(k_t k_i) at power-up grows without bound): give 0 for a "
                "proportional loop"
            )
        if not k_i < c * k_p / j:
            raise ValueError(f"makes the rebalance loop unstable: it needs k_i < c k_p / J = {c * k_p / j:.6g}")
        if k_t is not None:  # the roots of J s³ + c s² + k_t k_p s + k_t k_i (loop_polynomial)
            fastest = float(np.abs(np.roots([j, c, k_t * k_p, k_t * k_i])).max()) / (2 * math.pi)
            what = "the rebalance loop's fastest pole (from J, c, k_t, k_p and k_i)"
            problem = gimbal_pole_problem(what, fastest)
            if problem is not None:
                raise ValueError(problem)
        return k_i

    # ---- derived quantities (SI) ------------------------------------------------------------------

    @property
    def spin_momentum(self) -> float:
        """H = I_s ω_s, N·m·s."""
        return self.rotor_inertia_kgm2 * self.spin_speed_rpm * RPM

    @property
    def gimbal_gain(self) -> float:
        """H/c: rad of gimbal per rad of input angle (open loop, below the corner)."""
        return self.spin_momentum / self.damping_n_m_s_per_rad

    @property
    def corner_frequency_hz(self) -> float:
        """c/(2π J), Hz: the float's corner."""
        return self.damping_n_m_s_per_rad / self.gimbal_inertia_kgm2 / (2 * math.pi)

    @property
    def stop_angle_rad(self) -> float:
        """θ_stop, rad."""
        return math.radians(self.stop_angle_deg)

    @property
    def loop_polynomial(self) -> NDArray[np.float64]:
        """Coefficients of the closed loop's characteristic polynomial J s³ + c s² + k_t k_p s + k_t k_i."""
        kt = self.torquer_scale_n_m_per_a
        return np.array(
            [
                self.gimbal_inertia_kgm2,
                self.damping_n_m_s_per_rad,
                kt * self.loop_proportional_a_per_rad,
                kt * self.loop_integral_a_per_rad_s,
            ]
        )

    @overload
    def loop_response(self, frequency_hz: float) -> complex: ...

    @overload
    def loop_response(self, frequency_hz: NDArray[np.float64]) -> NDArray[np.complex128]: ...

    def loop_response(self, frequency_hz: float | NDArray[np.float64]) -> complex | NDArray[np.complex128]:
        """Transfer function (4) from ω_IA to the indicated rate k_t i/H at ``frequency_hz`` (complex)."""
        s = 2j * np.pi * np.asarray(frequency_hz, dtype=float)
        kt, kp, ki = self.torquer_scale_n_m_per_a, self.loop_proportional_a_per_rad, self.loop_integral_a_per_rad_s
        response: complex | NDArray[np.complex128] = kt * (kp * s + ki) / np.polyval(self.loop_polynomial, s)
        return response

    @property
    def loop_bandwidth_hz(self) -> float:
        """Closed-loop −3 dB bandwidth, Hz, from (5)."""
        j, c = self.gimbal_inertia_kgm2, self.damping_n_m_s_per_rad
        kt, kp, ki = self.torquer_scale_n_m_per_a, self.loop_proportional_a_per_rad, self.loop_integral_a_per_rad_s
        roots = np.roots([j * j, c * c - 2 * j * kt * kp, -(kt * kt * kp * kp + 2 * c * kt * ki), -((kt * ki) ** 2)])
        x = roots.real[(np.abs(roots.imag) <= 1e-9 * np.abs(roots)) & (roots.real > 0)].min()
        return math.sqrt(x) / (2 * math.pi)

    def state_space(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """A, B of ẋ = A x + B u: x = (θ, θ') open-loop, (θ, θ', ∫θ dt, ∫i dt) closed-loop; u in N·m."""
        j, c = self.gimbal_inertia_kgm2, self.damping_n_m_s_per_rad
        if not self.torque_rebalance:
            return np.array([[0.0, 1.0], [0.0, -c / j]]), np.array([0.0, 1.0 / j])
        kt, kp, ki = self.torquer_scale_n_m_per_a, self.loop_proportional_a_per_rad, self.loop_integral_a_per_rad_s
        a = np.array(
            [
                [0.0, 1.0, 0.0, 0.0],  # θ' = θ'
                [-kt * kp / j, -c / j, -kt * ki / j, 0.0],  # J θ'' = u − c θ' − k_t (k_p θ + k_i ∫θ)
                [1.0, 0.0, 0.0, 0.0],  # d/dt ∫θ = θ
                [kp, 0.0, ki, 0.0],  # d/dt ∫i = i = k_p θ + k_i ∫θ
            ]
        )
        return a, np.array([0.0, 1.0 / j, 0.0, 0.0])

    # ---- the GyroMechanism interface --------------------------------------------------------------

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        """An integer multiple of the output rate with 20 samples per period of the fastest pole."""
        fastest = np.abs(np.linalg.eigvals(self.state_space()[0])).max() / (2 * math.pi)
        return inner_rate_for(fastest, output_rate_hz)

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Indicated angle (M, 3), rad, from 0 at t[0]; raw ``gimbal_angle_rad`` and ``torquer_current_a``
        (M, 3). Draws nothing.

        ``state["gimbal_state"]`` (3, n): x at the last sample, (θ, θ') open-loop (rad, rad/s) or
        (θ, θ', ∫θ dt, ∫i dt) closed-loop (also rad·s, A·s), absent at power-up (equilibrium with the
        first sample's input); ``state["stop_warned"]``: the open loop has warned of its stops.
        """
        state = {} if state is None else state
        w_ia, w_sra, a_oa = sdf_axes(truth)
        h, j, stop = self.spin_momentum, self.gimbal_inertia_kgm2, self.stop_angle_rad
        a, b = self.state_space()
        x0 = state.get("gimbal_state")
        if x0 is None:
            x0 = self._initial_state(h * w_ia[0] - j * a_oa[0], h * np.asarray(truth.alpha[0], dtype=float))
        elif np.shape(x0) != (3, a.shape[0]):
            raise ValueError(f"state['gimbal_state'] has shape {np.shape(x0)}, this loop needs (3, {a.shape[0]})")
        states = simulate_gimbal(a, b, truth.dt, x0, h, j, w_ia, w_sra, a_oa, stop)
        state["gimbal_state"] = states[-1].copy()  # x at the last sample: the next chunk's first
        theta = states[:, :, 0]

        if not self.torque_rebalance:
            if np.any(np.abs(theta) >= stop) and not state.get("stop_warned", False):
                state["stop_warned"] = True  # once per run, as one call warns once
                first = truth.t[np.argmax(np.any(np.abs(theta) >= stop, axis=1))]
                warnings.warn(
                    f"open-loop rate-integrating gyro reached its ±{self.stop_angle_deg:g}° stops at "
                    f"t = {first:.6g} s (past (c/H)·θ_stop = {math.degrees(stop / self.gimbal_gain):.3g}° "
                    "of input angle); it indicates nothing beyond them: set torque_rebalance = true",
                    RuntimeWarning,
                    stacklevel=2,
                )
            # (c/H)(θ − θ₀): from 0 at the first sample (θ₀ = 0 at power-up).
            return GyroResponse(
                angle=(theta - theta[0]) / self.gimbal_gain,
                raw={"gimbal_angle_rad": theta, "torquer_current_a": np.zeros_like(theta)},
            )

        kt, kp, ki = self.torquer_scale_n_m_per_a, self.loop_proportional_a_per_rad, self.loop_integral_a_per_rad_s
        current = kp * theta + ki * states[:, :, 2]
        charge = states[:, :, 3]  # ∫i dt since power-up, A·s
        # (k_t/H)(∫i dt − its value at the first sample): from 0 there (the charge is 0 at power-up).
        return GyroResponse(
            angle=(kt / h) * (charge - charge[0]), raw={"gimbal_angle_rad": theta, "torquer_current_a": current}
        )

    def _initial_state(self, u0: NDArray[np.float64], u_dot: NDArray[np.float64]) -> NDArray[np.float64]:
        """Equilibrium (3, n) for a torque u0 + u_dot t (3,) (the particular solution; see the notes)."""
        j, c = self.gimbal_inertia_kgm2, self.damping_n_m_s_per_rad
        zero = np.zeros_like(u0)
        if not self.torque_rebalance:
            return np.column_stack([zero, u0 / c - j * u_dot / c**2])
        kt, kp, ki = self.torquer_scale_n_m_per_a, self.loop_proportional_a_per_rad, self.loop_integral_a_per_rad_s
        if ki > 0:
            theta = u_dot / (kt * ki)
            return np.column_stack([theta, zero, (u0 / kt - kp * theta) / ki, zero])
        gain = kt * kp
        return np.column_stack([u0 / gain - c * u_dot / gain**2, u_dot / gain, zero, zero])
