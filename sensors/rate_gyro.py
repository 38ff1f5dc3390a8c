"""The spring-restrained rate gyro: a spinning rotor in one gimbal held by a torsion spring.

The instrument (IEEE Std 292-1969 names its axes; Lecture 11 of the course seeds, "rate gyros")
-------------------------------------------------------------------------------------------------
A rotor of spin inertia I_s turns at ω_s about its spin reference axis (SRA), so it carries the
angular momentum H = I_s ω_s. It sits in a gimbal that may turn by a small angle θ about the output
axis (OA), fixed in the case; a torsion spring K and a damper c hold the gimbal near θ = 0, and a
pickoff reads θ. The input axis IA completes the right-handed triad IA × OA = SRA.

Turning the case about IA at ω forces the rotor's angular momentum to turn with it, which takes a
torque H ω about OA; only the spring can supply it, so the gimbal deflects until K θ = H ω. Euler's
equation for the gimbal and rotor about OA (Lawrence ch. 5–7; Savet), with the gimbal deflected
by θ, reads

    J θ'' + c θ' + K θ = H (ω_IA cos θ − ω_SRA sin θ) − J ω'_OA                                    (1)

* J: moment of inertia of gimbal and rotor about OA; ω_IA, ω_SRA, ω_OA: the case's inertial rate on the
  case-fixed axes; ω'_OA its time derivative.
* The gyroscopic torque is H ω·i(θ), where i(θ) = i₀ cos θ − s₀ sin θ is the input axis carried with
  the deflected gimbal (the spin axis turns about OA by θ, from s₀ towards i₀): a deflected gimbal
  also feels the rate about the spin axis. This *cross-coupling* reads, for small θ = H ω_IA/K, as
  an error −(H/K) ω_IA ω_SRA in the indicated rate.
* −J ω'_OA: the gimbal's own inertia resists an angular acceleration of the case about OA (the
  *output-axis angular-acceleration* error, −J ω'_OA/H in the indicated rate).
* Neglected: anisoinertia (I_SRA − I_IA) ω_IA ω_SRA of the gimbal (nil for a gimbal balanced in
  inertia), mass unbalance (g-sensitivity) and the damping fluid's temperature dependence, which the
  IMU's error layer (:mod:`gyroemu.sensors.errors`) applies on top; the Brownian torque on the gimbal,
  √(2 k_B T c)/H ≈ 4·10⁻¹⁰ rad/s/√Hz for the defaults (10⁻⁵ of any real rate gyro's noise), so
  :meth:`RateGyro.intrinsic_noise_density` is 0 and the IMU supplies the specified noise.

For a constant rate the gimbal settles at θ = H ω/K (the static gain), with natural frequency
ω_n = √(K/J) and damping ratio ζ = c/(2√(K J)); the transfer function from ω_IA to θ is
H/(J s² + c s + K). The instrument **indicates the rate K θ/H** (raw observable: the gimbal angle).
**Gimbal stops** at ±θ_stop limit the deflection, and so the range to K θ_stop/H.

Triad
-----
Three identical gyros sense the sensor's x, y, z. Gyro k has IA = e_k, OA = e_{k+1}, SRA = e_{k+2}
(indices mod 3): (IA, OA, SRA) = (x, y, z), (y, z, x), (z, x, y), each right-handed. So gyro k feels
ω_IA = ω_k, ω_SRA = ω_{k+2}, ω'_OA = α_{k+1} (:func:`sdf_axes`).

Simulation
----------
The linear part of (1), ẋ = A x + B u with x = (θ, θ') and the torque u, is discretised exactly for an
input that is linear between samples (first-order hold, ``scipy.signal.cont2discrete(method="foh")``):

    x_{k+1} = Φ x_k + Γ₀ u_k + Γ₁ u_{k+1}                                                          (2)

With u independent of θ this is the same recurrence as ``scipy.signal.lfilter`` on the discretised
transfer function (the tests check it). Here u_{k+1} = H (ω_IA cos θ_{k+1} − ω_SRA sin θ_{k+1}) − J ω'_OA
depends on the new angle, so θ_{k+1} = p + Γ₁[0] u(θ_{k+1}) is solved per step by Newton's method
(three iterations from the explicit predictor; Γ₁[0] ≈ h²/(6J) makes it converge to round-off at
once) in a numba recurrence, :func:`simulate_gimbal`: the cross-coupling is treated as implicitly
as the input itself, second order in the step. A gimbal that passes a stop is put back on it with
zero velocity (an inelastic stop) and leaves it when the net torque turns inwards; the contact time
is resolved to one step. ``rate_integrating.py`` uses the same recurrence with its own A, B.

Accuracy: the response to the held (piecewise-linear) rate is exact to round-off (the tests check it
against the closed form). The θ-dependent part of the torque is held linear over each step too, an
error second order in the step: under cross rates of 0.5 rad/s (``tests/benchmarks/bench_mechanical.py``'s
carrier) the gimbal angle is within 1·10⁻⁵ of a converged ODE solution at 20 samples per natural
period, 4·10⁻⁸ at 320.

The gimbal starts in equilibrium with the first sample's input (the instrument was running before
t[0]): on the particular solution of (1) for an input ramping at its initial slope H ω'_IA, so a
constant or steadily ramping rate gives no start-up transient. For a step response from rest, give
ω = 0 at the first sample.

Chunks (:mod:`gyroemu.sensors.mechanism`): the state of (2) at a chunk's last sample, x = (θ, θ') of each gyro,
is all the recurrence carries (the torque u_k is recomputed from θ_k and the shared sample's input,
the same numbers), so ``state["gimbal_state"]`` (3, 2) continues the run exactly: a run split into
chunks gives the same samples as one call, bit for bit. It is set at power-up (an empty state) to
the equilibrium above.

:meth:`RateGyro.inner_rate_hz` runs the simulation at an integer multiple of the output rate of at
least 20 natural frequencies.

Defaults
--------
A miniature spring-restrained rate gyro of the autopilot and missile-stabilisation kind (IEEE 292
format): a 400-Hz hysteresis-synchronous spin motor at 24 000 rpm with I_s = 4·10⁻⁶ kg·m², so
H ≈ 1.0·10⁻² N·m·s (10⁵ g·cm²/s); K = 0.3 N·m/rad and J = 8.5·10⁻⁶ kg·m² give f_n ≈ 29.9 Hz;
c = 2.2·10⁻³ N·m·s/rad gives ζ ≈ 0.69; stops at ±3.5° give a range of ≈ ±104 °/s (a "±100 °/s,
30 Hz, ζ = 0.7" datasheet).

Sources
-------
* A. Lawrence, *Modern Inertial Technology: Navigation, Guidance, and Control*, 2nd ed., Springer
  1998, ch. 5–7 (single-degree-of-freedom gyros, their equations of motion and error terms).
* P. H. Savet (ed.), *Gyroscopes: Theory and Design*, McGraw-Hill 1961.
* IEEE Std 292-1969, specification format for single-degree-of-freedom spring-restrained rate gyros.
* Lecture 11, "Angular momentum, tops and gyroscopes" (``/work/shared/seeds``): K θ = I_s ω_s ω_z.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, ValidationInfo, field_validator

from gyroemu.dynamics.config import PositiveReal, Real
from gyroemu.dynamics.jit import njit

from .mechanism import GyroMechanism, GyroResponse, GyroTruth

__all__ = [
    "RateGyro",
    "RPM",
    "StopAngle",
    "MAX_GIMBAL_POLE_HZ",
    "gimbal_pole_problem",
    "sdf_axes",
    "foh_matrices",
    "simulate_gimbal",
    "inner_rate_for",
]

#: rad/s per rpm.
RPM = 2.0 * math.pi / 60.0

#: A gimbal stop angle, degrees: positive and below 90° (at 90° the spin axis would lie on the input axis).
StopAngle = Annotated[Real, Field(gt=0, lt=90)]

# The inner step resolves the fastest pole of a gimbal loop with this many samples per period.
SAMPLES_PER_PERIOD = 20

MAX_GIMBAL_POLE_HZ = 100_000.0
"""The fastest gimbal pole a single-degree-of-freedom gyro may have (a rate gyro's natural frequency, a
floated gyro's float corner and rebalance loop), Hz: a hundred times the fastest of real ones (rate gyros
ring at tens of hertz, floats have corners up to about a kilohertz). The inner grid takes
:data:`SAMPLES_PER_PERIOD` steps a period of it: at this limit 2·10⁶ steps a simulated second (a gimbal
of 10¹² Hz asked for 2·10¹³)."""


class RateGyro(GyroMechanism):
    """Spring-restrained single-gimbal rate gyro triad (see the module notes for the model).

    Parameters (config keys)
    ------------------------
    rotor_inertia_kgm2 : moment of inertia of the rotor about its spin axis, kg·m².
    spin_speed_rpm : rotor speed relative to the gimbal, rpm.
    gimbal_inertia_kgm2 : J, gimbal and rotor about the output axis, kg·m².
    spring_stiffness_n_m_per_rad : K, the torsion spring.
    damping_n_m_s_per_rad : c, the viscous damper.
    stop_angle_deg : gimbal freedom ±θ_stop, below 90°.
    """

    kind: Literal["rate-gyro"] = "rate-gyro"
    reads: ClassVar[frozenset[str]] = frozenset()
    rotor_inertia_kgm2: PositiveReal = 4.0e-6
    spin_speed_rpm: PositiveReal = 24000.0
    gimbal_inertia_kgm2: PositiveReal = 8.5e-6
    # validate_default: the natural frequency must also be checked when only the inertia is given.
    spring_stiffness_n_m_per_rad: PositiveReal = Field(0.3, validate_default=True)
    damping_n_m_s_per_rad: PositiveReal = 2.2e-3
    stop_angle_deg: StopAngle = 3.5

    @field_validator("spring_stiffness_n_m_per_rad")
    @classmethod
    def _natural_frequency(cls, stiffness: float, info: ValidationInfo) -> float:
        inertia = info.data.get("gimbal_inertia_kgm2")
        if inertia is not None:
            frequency = math.sqrt(stiffness / inertia) / (2 * math.pi)
            problem = gimbal_pole_problem(f"the natural frequency √(K/J)/2π (J = {inertia:g} kg·m²)", frequency)
            if problem is not None:
                raise ValueError(problem)
        return stiffness

    @field_validator("damping_n_m_s_per_rad")
    @classmethod
    def _overdamped_pole(cls, damping: float, info: ValidationInfo) -> float:
        """An overdamped gimbal (ζ > 1) has a real pole faster than its natural frequency, (c + √(c² − 4KJ))/2J:
        it too must be a gimbal's (a damper of 10³⁰⁰ N·m·s/rad made the gimbal angle and every output NaN)."""
        inertia, stiffness = info.data.get("gimbal_inertia_kgm2"), info.data.get("spring_stiffness_n_m_per_rad")
        if inertia is not None and stiffness is not None:
            discriminant = damping * damping - 4 * stiffness * inertia
            if discriminant > 0:
                fast = (damping + math.sqrt(discriminant)) / (2 * inertia) / (2 * math.pi)
                what = f"the overdamped gimbal's fast pole (c + √(c² − 4KJ))/4πJ (J = {inertia:g} kg·m²)"
                problem = gimbal_pole_problem(what, fast)
                if problem is not None:
                    raise ValueError(problem)
        return damping

    # ---- derived quantities (SI) ------------------------------------------------------------------

    @property
    def spin_momentum(self) -> float:
        """H = I_s ω_s, N·m·s."""
        return self.rotor_inertia_kgm2 * self.spin_speed_rpm * RPM

    @property
    def natural_frequency_hz(self) -> float:
        """f_n = √(K/J)/2π, Hz."""
        return math.sqrt(self.spring_stiffness_n_m_per_rad / self.gimbal_inertia_kgm2) / (2 * math.pi)

    @property
    def damping_ratio(self) -> float:
        """ζ = c / (2 √(K J))."""
        k, j = self.spring_stiffness_n_m_per_rad, self.gimbal_inertia_kgm2
        return self.damping_n_m_s_per_rad / (2 * math.sqrt(k * j))

    @property
    def static_gain_s(self) -> float:
        """θ/ω = H/K in steady state, s (rad of gimbal per rad/s of input)."""
        return self.spin_momentum / self.spring_stiffness_n_m_per_rad

    @property
    def stop_angle_rad(self) -> float:
        """θ_stop, rad."""
        return math.radians(self.stop_angle_deg)

    @property
    def range_rad_per_s(self) -> float:
        """The largest indicated rate, K θ_stop/H, rad/s."""
        return self.stop_angle_rad / self.static_gain_s

    def state_space(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """A (2, 2), B (2,) of ẋ = A x + B u, x = (θ, θ'), u = gyroscopic and inertial torque, N·m."""
        j, c, k = self.gimbal_inertia_kgm2, self.damping_n_m_s_per_rad, self.spring_stiffness_n_m_per_rad
        return np.array([[0.0, 1.0], [-k / j, -c / j]]), np.array([0.0, 1.0 / j])

    # ---- the GyroMechanism interface --------------------------------------------------------------

    def max_rate(self) -> float:
        """The gimbal reaches its stop at K θ_stop/H: no larger rate can be indicated."""
        return self.range_rad_per_s

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        """An integer multiple of the output rate, at least 20 natural frequencies."""
        return inner_rate_for(self.natural_frequency_hz, output_rate_hz)

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Indicated rate K θ/H (M, 3), rad/s; raw ``gimbal_angle_rad`` θ (M, 3). Draws nothing.

        ``state["gimbal_state"]`` (3, 2): (θ, θ') of each gyro at the last sample (rad, rad/s); absent
        at power-up, when the gimbals start in equilibrium with the first sample's input.
        """
        state = {} if state is None else state
        w_ia, w_sra, a_oa = sdf_axes(truth)
        h, j, k = self.spin_momentum, self.gimbal_inertia_kgm2, self.spring_stiffness_n_m_per_rad
        c, stop = self.damping_n_m_s_per_rad, self.stop_angle_rad

        x0 = state.get("gimbal_state")
        if x0 is None:
            # Initial equilibrium: the particular solution of (1) for a torque ramping at u' = H ω'_IA,
            # θ' = u'/K and K θ = u(θ) − c θ', with u(θ) = H (ω_IA cos θ − ω_SRA sin θ) − J ω'_OA.
            theta_dot0 = h * np.asarray(truth.alpha[0], dtype=float) / k  # ω'_IA of gyro k is α_k
            theta0 = _static_balance(k, h, w_ia[0], w_sra[0], -j * a_oa[0] - c * theta_dot0, stop)
            x0 = np.column_stack([theta0, np.where(np.abs(theta0) < stop, theta_dot0, 0.0)])

        a, b = self.state_space()
        states = simulate_gimbal(a, b, truth.dt, x0, h, j, w_ia, w_sra, a_oa, stop)
        state["gimbal_state"] = states[-1].copy()  # x at the last sample: the next chunk's first
        theta = states[:, :, 0]
        return GyroResponse(rate=k * theta / h, raw={"gimbal_angle_rad": theta})


# --------------------------------------------------------------------------------------------------
# Single-degree-of-freedom machinery shared with rate_integrating.py
# --------------------------------------------------------------------------------------------------


def sdf_axes(truth: GyroTruth) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The rates each gyro of a single-degree-of-freedom triad feels, each (M, 3), column k = gyro k.

    Gyro k has IA = e_k, OA = e_{k+1}, SRA = e_{k+2}; returns (ω_IA, ω_SRA, ω'_OA) in rad/s, rad/s²:
    ``omega[:, k]``, ``omega[:, k+2]``, ``alpha[:, k+1]``.
    """
    omega, alpha = np.asarray(truth.omega, dtype=float), np.asarray(truth.alpha, dtype=float)
    return omega, omega[:, [2, 0, 1]], alpha[:, [1, 2, 0]]


def gimbal_pole_problem(what: str, frequency_hz: float) -> str | None:
    """Why a gimbal pole of ``frequency_hz`` (Hz; ``what`` names it) cannot be simulated, or None: more
    than :data:`MAX_GIMBAL_POLE_HZ`, which sets the inner rate (:func:`inner_rate_for`)."""
    if frequency_hz <= MAX_GIMBAL_POLE_HZ:
        return None
    return (
        f"{what} would be {frequency_hz:.4g} Hz, more than the limit of {MAX_GIMBAL_POLE_HZ:g} Hz: a hundred "
        f"times the fastest gimbal of real gyros (the inner grid steps {SAMPLES_PER_PERIOD} times its period)"
    )


def inner_rate_for(fastest_hz: float, output_rate_hz: float) -> float:
    """The smallest integer multiple of ``output_rate_hz`` that is at least 20 × ``fastest_hz``."""
    return output_rate_hz * max(1, math.ceil(SAMPLES_PER_PERIOD * fastest_hz / output_rate_hz))


def foh_matrices(
    a: NDArray[np.float64], b: NDArray[np.float64], dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Φ (n, n), Γ₀ (n,), Γ₁ (n,) of (2): the exact step of ẋ = A x + B u for u linear over the step.

    From ``scipy.signal.cont2discrete(method="foh")`` with C = I, D = 0, whose output is in the shifted
    state x̃ = x − Γ₁ u (so D_d = Γ₁ and B_d = Γ₀ + Φ Γ₁).
    """
    n = a.shape[0]
    import scipy.signal  # here, not at the top: it costs 0.5 s to import

    phi, bd, _, dd, _ = scipy.signal.cont2discrete((a, b[:, None], np.eye(n), np.zeros((n, 1))), dt, method="foh")
    gamma1 = dd[:, 0]
    return phi, bd[:, 0] - phi @ gamma1, gamma1


def simulate_gimbal(
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    dt: float,
    x0: ArrayLike,
    spin_momentum: float,
    gimbal_inertia: float,
    w_ia: NDArray[np.float64],
    w_sra: NDArray[np.float64],
    a_oa: NDArray[np.float64],
    stop: float,
) -> NDArray[np.float64]:
    """States of a single-degree-of-freedom gimbal loop on the inner grid, (M, 3, n).

    Parameters
    ----------
    a, b : (n, n), (n,)
        Continuous model ẋ = A x + B u whose first two states are θ (rad) and θ' (rad/s); further
        states belong to a controller. u is the torque of (1), N·m.
    dt : float
        Step, s.
    x0 : (3, n)
        Initial state of each gyro.
    spin_momentum, gimbal_inertia : float
        H (N·m·s) and J (kg·m²).
    w_ia, w_sra, a_oa : (M, 3)
        ω_IA, ω_SRA (rad/s), ω'_OA (rad/s²) of each gyro (:func:`sdf_axes`).
    stop : float
        Gimbal stop, rad (``inf`` for none).
    """
    phi, gamma0, gamma1 = foh_matrices(a, b, dt)
    out = np.empty((w_ia.shape[0], w_ia.shape[1], a.shape[0]))
    _gimbal_recurrence(
        phi,
        gamma0,
        gamma1,
        np.ascontiguousarray(x0, dtype=float),
        spin_momentum,
        gimbal_inertia,
        np.ascontiguousarray(w_ia),
        np.ascontiguousarray(w_sra),
        np.ascontiguousarray(a_oa),
        stop,
        out,
    )
    return out


@njit
def _torque(h: float, j: float, w_ia: float, w_sra: float, a_oa: float, theta: float) -> float:
    """u(θ) = H (ω_IA cos θ − ω_SRA sin θ) − J ω'_OA, N·m: the right-hand side of (1)."""
    return h * (w_ia * math.cos(theta) - w_sra * math.sin(theta)) - j * a_oa


@njit
def _gimbal_recurrence(
    phi: NDArray[np.float64],
    gamma0: NDArray[np.float64],
    gamma1: NDArray[np.float64],
    x0: NDArray[np.float64],
    h: float,
    j: float,
    w_ia: NDArray[np.float64],
    w_sra: NDArray[np.float64],
    a_oa: NDArray[np.float64],
    stop: float,
    out: NDArray[np.float64],
) -> None:
    """Recurrence (2) with the θ-dependent torque solved per step and inelastic stops; fills ``out``."""
    n_samples, n_axes = w_ia.shape
    n = phi.shape[0]
    x = np.empty(n)
    free = np.empty(n)
    g = gamma1[0]
    for axis in range(n_axes):
        for i in range(n):
            x[i] = x0[axis, i]
            out[0, axis, i] = x[i]
        u = _torque(h, j, w_ia[0, axis], w_sra[0, axis], a_oa[0, axis], x[0])
        for k in range(1, n_samples):
            wi, ws, aa = w_ia[k, axis], w_sra[k, axis], a_oa[k, axis]
            # Everything known at step k: Φ x_k + Γ₀ u_k.
            for i in range(n):
                acc = gamma0[i] * u
                for m in range(n):
                    acc += phi[i, m] * x[m]
                free[i] = acc
            # θ_{k+1} = p + g u(θ_{k+1}): Newton from the predictor with u held.
            p = free[0]
            theta = p + g * u
            for _ in range(3):
                f = theta - p - g * _torque(h, j, wi, ws, aa, theta)
                df = 1.0 + g * h * (wi * math.sin(theta) + ws * math.cos(theta))
                theta -= f / df
            u = _torque(h, j, wi, ws, aa, theta)
            for i in range(n):
                x[i] = free[i] + gamma1[i] * u
            x[0] = theta
            # Inelastic stops: back onto the stop, at rest.
            if abs(theta) > stop:
                x[0] = math.copysign(stop, theta)
                x[1] = 0.0
                u = _torque(h, j, wi, ws, aa, x[0])
            for i in range(n):
                out[k, axis, i] = x[i]


def _static_balance(
    stiffness: float,
    h: float,
    w_ia: NDArray[np.float64],
    w_sra: NDArray[np.float64],
    torque: NDArray[np.float64],
    stop: float,
    iterations: int = 8,
) -> NDArray[np.float64]:
    """θ (3,) solving K θ = H (ω_IA cos θ − ω_SRA sin θ) + torque, by Newton from H ω_IA/K, clipped to
    the stops (where the balance has no root inside them, the gimbal rests on a stop)."""
    theta = np.clip((h * w_ia + torque) / stiffness, -stop, stop)
    for _ in range(iterations):
        f = stiffness * theta - h * (w_ia * np.cos(theta) - w_sra * np.sin(theta)) - torque
        df = stiffness + h * (w_ia * np.sin(theta) + w_sra * np.cos(theta))
        theta = np.clip(theta - f / np.where(df > 0, df, stiffness), -stop, stop)
    return theta
