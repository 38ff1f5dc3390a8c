"""The MEMS Coriolis vibratory gyro: a driven proof mass whose sense mode the Coriolis force excites.

The instrument (Lecture 11 of the course seeds, "MEMS gyroscope"; IEEE Std 1431-2004 names the terms)
-------------------------------------------------------------------------------------------------------
A proof mass m on springs has two in-plane modes. The **drive mode** (along x) is kept oscillating at
its resonance ω_d with a constant amplitude x₀ by an amplitude loop (AGC) and a phase-locked loop:

    x(t) = x₀ sin θ(t),   θ̇ = ω_d,   ẋ = x₀ ω_d cos θ                                             (1)

The **sense mode** (along y, natural frequency ω_s = ω_d + 2π Δf, quality factor Q_s) feels, in the
sensor's rotating frame, the Coriolis force −2 m Ω × v of the drive motion and whatever else acts
along y. Per unit mass, for an element sensing Ω_z with drive axis x and sense axis y:

    ÿ + (ω_s/Q_s) ẏ + ω_s² y = −2 Ω_z ẋ                  Coriolis: in phase with the drive velocity
                              − (k_q/m) x                 quadrature: drive-to-sense stiffness k_q
                              − (α_z + Ω_x Ω_y) x         Euler and centrifugal forces of the motion
                              + κ y_g F_x/m               drive force leaking along y (g-sensitivity)
                              − f_y                       specific force along y (DC: rejected)
                              + n(t)                      Brownian force, one-sided PSD 4 k_B T ω_s/(m Q_s)
                                                                                                   (2)

* **Quadrature.** A stiffness coupling k_q from drive to sense (an anisoelastic suspension) pushes in
  phase with the drive *displacement*, 90° from the Coriolis force. It reads as the rate
  Ω_q = k_q/(2 m ω_d) (IEEE 1431's "quadrature"), typically far larger than the rates measured.
* **g-sensitivity.** The specific force f_y deflects the sense mode quasi-statically by
  y_g = −f_y/ω_s². That DC deflection is invisible to the demodulator, but it makes the drive
  electrodes push sideways: a comb drive whose fingers are off centre by y has a lateral force
  κ y F_x (Legtenberg et al., J. Micromech. Microeng. 6, 1996, on the lateral comb force). The
  drive force holding x₀ against damping, F_x/m = (ω_d²x₀/Q_d) cos θ, is in phase with the drive
  velocity, so this leak reads as the rate G f_y with G = κ ω_d/(2 Q_d ω_s²) (rad/s per m/s²).
* **Neglected:** the ω_s-relative terms Ω²/ω_s² (< 10⁻⁸) in the sense stiffness, the drive loop's
  own noise and errors (x₀ and the reference are exact), electronic noise of the pickoff (the IMU's
  error layer adds the rest of the specified noise), the temperature dependence of Q and of the
  springs' coupling.

A capacitive **pickoff** turns y into a voltage v = G_p y, and **phase-sensitive demodulation**
multiplies it by the drive-velocity reference 2 cos(θ + φ_ref) (rate channel, I) and by
2 sin(θ + φ_ref) (quadrature channel, Q), then low-pass filters (the demodulator filter, a Butterworth
of ``demodulator_bandwidth_hz`` and ``demodulator_filter_order``). The reference phase is set at the
calibration temperature to the phase of the Coriolis response, plus the **demodulation phase error**
φ_e, so the quadrature leaks into the rate channel as the bias −Ω_q tan φ_e. The instrument
**indicates I/SF₀**, SF₀ being the scale factor at the reference temperature (calibrated).

The sense response at the drive frequency
-----------------------------------------
With y = Re{A e^{iθ}} and each force written Re{F e^{iθ}} (F: complex amplitude per unit mass, the
Coriolis force having F = −2 x₀ ω_d Ω), a steady force gives A = H F with

    H = 1 / (ω_s² − ω_d² + i ω_d ω_s/Q_s)                                                          (3)

and the demodulated channels are I = G_p Re{A e^{−iφ_ref}}, Q = −G_p Im{A e^{−iφ_ref}}. So the
**scale factor** (rate-channel volts per rad/s) is

    SF = G_p · 2 x₀ ω_d |H| cos φ_e ≈ G_p x₀ / (2π Δf) · cos φ_e     (mode-split, |Δf| ≫ f_s/2Q_s)   (4)

**Temperature.** Both resonances drift, f(T) = f(T_ref)(1 + α (T − T_ref)) with α in ppm/°C (silicon's
Young's modulus gives about −30 ppm/°C); their mismatch moves the mode split. Equation (3) at the
drifted frequencies gives the scale factor and the phase at T; to first order in the mode-split
regime the scale factor changes by α_d − (α_s f_s − α_d f_d)/Δf − (α_s f_s + α_d f_d)/(f_s + f_d)
per °C. The moved phase of H changes the quadrature leak, −Ω_q tan(φ_e − arg(H_T/H₀)).

Two models of the same physics
------------------------------
**Carrier level** (``model = "carrier"``, for tests and short runs). The sense oscillator (2) is
integrated on a phase-locked grid of :data:`CARRIER_STEPS_PER_CYCLE` steps per drive cycle, exactly
for forcing whose complex amplitude F is linear between steps (a matrix exponential with the carrier
e^{iω_d τ} as an exosystem), with the Brownian force as the exact discrete covariance (Van Loan,
IEEE Trans. Autom. Control 23(3), 1978). The pickoff voltage is multiplied by the references and
averaged over each whole drive cycle (which removes the 2ω_d product exactly), then filtered; the
output is updated once per drive cycle and held. The temperature is held at its value at power-up.

**Baseband** (``model = "baseband"``, the default). Averaging (2) over a drive cycle (substitute
y = Re{A e^{iθ}}, drop Ä and the terms at 2ω_d) gives a first-order complex equation for the envelope:

    Ȧ = p A + b F,    p ≈ −ω_s/(2Q_s) + i (ω_s² − ω_d²)/(2ω_d),   b ≈ −i/(2ω_d)                 (5)

We place p at the sense mode's exact pole seen from the frame turning at ω_d,
p = −ω_s/(2Q_s) + i(ω_s √(1 − 1/4Q_s²) − ω_d) (≈ −ω_s/2Q_s + 2πi Δf), and fix b = −p H so that the
steady state A = −b F/p = H F is exact: the baseband and carrier scale factors, phases and quadrature
rejection agree exactly, and their rate responses differ only by the counter-rotating sideband,
a relative O(f/2f_d) at modulation frequency f. The rate response of (5) is that of a pair of poles
at p and p̄ (for φ_e = 0):

    H_rate(s) = (|p|² − s Re p) / ((s − p)(s − p̄))  ≈  1 / (1 − (f/Δf)²)                          (6)

flat at low frequency, peaking at the mode split (+3 dB at f ≈ 0.54 Δf): the classic open-loop
mode-split bandwidth (Acar & Shkel, "MEMS Vibratory Gyroscopes", Springer 2009, §2). Equation (5)
and the demodulator filter form one complex linear system, discretised exactly over each step of
the grid for F the cubic Hermite interpolant of its samples and slopes (:func:`hermite_hold`; the
slopes of the Coriolis and centrifugal terms come from α, the specific-force leak and the Euler force
x₀ α are held linear), together with the step's mean output, so the indicated angle is the exact
integral of the indicated rate; the Brownian force enters by the exact discrete covariance of the
state and that mean (less the directions that carry under 10⁻⁵ of it, which are not drawn). Nothing
in the step is then approximated but the forcing between samples, so the grid runs at the output rate
(or at the truth's own rate where that is finer): a Coriolis force cubic in time (a rate quadratic in
time) is followed exactly whatever the step. gyroemu 0.1.0 ran the same system with F linear
between samples of a grid at four times the output band (2 kHz at 100 Hz output), its rate
integrated by the trapezoid rule: 20 steps per sample where one now suffices.

Temperature in the baseband model: the pole stays at its reference value and each force is scaled by
H_T/H₀ (exact in steady state). The pole moves by (α_s f_s − α_d f_d) ΔT, about 0.09 Hz/°C for the
defaults, far inside its own half-width f_s/2Q_s = 14.5 Hz.

Brownian noise floor
--------------------
The sense mode's damping c = m ω_s/Q_s brings the thermal force of one-sided PSD 4 k_B T c
(Gabrielson, IEEE Trans. Electron Devices 40(5), 1993). Near ω_d it is n = n_c cos θ − n_s sin θ,
whose in-phase part n_c (two-sided PSD 4 k_B T ω_s/(m Q_s) per unit mass², twice the force's own)
competes with the Coriolis amplitude 2 x₀ ω_d Ω; the quadrature part n_s is rejected by the
demodulator (Leland's factor of two, IEEE Sensors J. 5(3), 2005). The rate noise is white at

    Ω_n = √(4 k_B T ω_s / (m Q_s)) / (2 x₀ ω_d)      rad/s/√Hz                                    (7)

in this repository's convention (the Allan deviation at 1 s, σ = Ω_n/√Δt per sample; see
:mod:`gyroemu.sensors.noise`), divided by cos φ_e in the calibrated output. It does not depend on the mode
split (signal and noise pass the same H). The tests check (7) against the carrier-level simulation.
Through the sense resonance the same noise also makes a peak at Δf in the demodulated output, which
the demodulator filter removes.

Defaults: a consumer part (ICM-42688-P-like)
---------------------------------------------
Drive at 27 kHz (consumer gyros drive at a few tens of kilohertz), a 2 kHz mode split (flat rate response to a few
hundred hertz), 5 µm drive amplitude, a 4 µg proof mass and Q_s = 1000 (moderate vacuum) give
Ω_n = 1.6·10⁻⁵ rad/s/√Hz = 0.92 mdps/√Hz (0.055 °/√h) at 25 °C: a third of the part's 2.8 mdps/√Hz,
so the electronics (the IMU's error layer) make the rest, as in real consumer parts. k_q = 1.5 mN/m
gives 63 °/s of quadrature, with a 1 mrad phase error a 0.06 °/s bias (well inside a ±0.5 °/s
zero-rate offset); κ = 7·10⁴ /m with Q_d = 1000 gives 0.1 °/s/g, the linear-acceleration sensitivity
InvenSense specifies for its MPU-6000 family. The demodulator filter is 4th order at 500 Hz.

Triad
-----
Three identical elements; element k senses Ω_k, drives along e_{k+1} and senses along e_{k+2} (indices
mod 3), so e_drive × e_sense = e_k and element k feels Ω_k, α_k, Ω_{k+1}Ω_{k+2} and f_{k+2}.

Raw observables (``GyroResponse.raw``): ``sense_in_phase_v`` and ``sense_quadrature_v`` (M, 3), the
demodulated rate and quadrature channels after the demodulator filter, volts.

Randomness: the power-up draw (the stationary thermal state) and then, time-major, a fixed number of
normal draws per grid step (baseband) or carrier step (carrier) and axis, so runs split into chunks
draw the same numbers.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal, NamedTuple, TypeVar, cast, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import ValidationInfo, field_validator

from gyroemu.dynamics.config import PositiveReal, Real, at_least, at_most
from gyroemu.dynamics.jit import njit

from .errors import STANDARD_GRAVITY
from .mechanism import GyroMechanism, GyroResponse, GyroTruth

__all__ = [
    "MemsGyro",
    "CycleFilter",
    "CARRIER_CYCLES_PER_PASS",
    "CARRIER_STEPS_PER_CYCLE",
    "K_BOLTZMANN",
    "MAX_DRIVE_FREQUENCY_HZ",
    "MIN_DRIVE_FREQUENCY_HZ",
    "DRIVE_AMPLITUDE_RANGE_M",
    "MAX_QUADRATURE_STIFFNESS_FRACTION",
    "MAX_REFERENCE_TEMPERATURE_DEGC",
    "element_axes",
]

K_BOLTZMANN = 1.380649e-23
"""Boltzmann constant, J/K (exact, SI 2019)."""
ZERO_CELSIUS_K = 273.15
CARRIER_STEPS_PER_CYCLE = 24
"""Steps per drive cycle of the carrier-level model (exact discretisation; ≥ 20 asked)."""
CARRIER_CYCLES_PER_PASS = 1 << 16
"""Drive cycles the carrier model steps and demodulates at a time (its per-cycle values, about 3 MB a
pass, are read down to the truth's grid before the next pass), so a block's memory does not grow
with the drive frequency."""
MAX_DRIVE_FREQUENCY_HZ = 200_000.0
"""The highest ``drive_frequency_hz``, Hz: twice the fastest drive of real MEMS Coriolis gyros, about
100 kHz (consumer parts drive at 10–50 kHz; the tuning forks, frames and rings this lumped comb-drive
model describes; bulk-acoustic-wave disks ring at megahertz in modes it does not). Every inner rate of
the model follows the drive: the carrier model steps 24 times a drive cycle and keeps one value a cycle
for a pass of ``CARRIER_CYCLES_PER_PASS`` cycles (a 20 s run at 1 kHz took 6.4 s at this limit, 25 s at
1 MHz; 10¹² Hz asked for 2.4·10¹³ steps a simulated second), and its inner grid is four times its band
(the envelope pole's or the demodulator's, at most about a quarter of the drive). The baseband model's
cost does not depend on the drive."""
MIN_DRIVE_FREQUENCY_HZ = 1000.0
"""The lowest ``drive_frequency_hz``, Hz: a third of the slowest drives of real MEMS Coriolis gyros (about
3 kHz; a drive must sit far above the motion it measures, and the sense mode within a quarter of it). At
10⁻³⁰⁰ Hz the Brownian floor √(4 k_B T ω_s/m Q_s)/(2 x₀ ω_d) overflowed (an OverflowError)."""
DRIVE_AMPLITUDE_RANGE_M = (1.0e-8, 1.0e-3)
"""The smallest and largest ``drive_amplitude_m``, m: a hundredth of the smallest drive amplitudes of real
MEMS gyros (about 1 µm), fifty times the largest (about 20 µm: comb fingers and suspensions are tens of µm
long). The Coriolis force 2 x₀ ω_d Ω and the noise's 1/x₀ follow it: 10³⁰⁰ m made every output NaN, 10⁻³⁰⁰
m overflowed."""
MAX_QUADRATURE_STIFFNESS_FRACTION = 0.1
"""The largest ``quadrature_stiffness_n_per_m`` |k_q| as a fraction of the drive mode's stiffness m ω_d²:
real couplings are 10⁻⁵ to 10⁻³ of it (the defaults: 1.3·10⁻⁵, 63 °/s of quadrature; a poorly trimmed
part some thousands of °/s), so a tenth is a hundred times the worst; beyond a fraction of the stiffness the
modes are not those of a gyro (their axes turn towards each other). The quadrature rate Ω_q = k_q/(2 m ω_d)
is then at most ω_d/20. A k_q of 10³⁰⁰ N/m made every output NaN."""
MAX_REFERENCE_TEMPERATURE_DEGC = 1000.0
"""The highest ``reference_temperature_degC``, °C: five times the hottest rating of real MEMS gyros
(downhole-drilling parts, 200 °C; consumer parts to 85 °C, automotive to 125 °C), below the 1414 °C at
which silicon melts. At 10³⁰⁰ °C the Brownian floor came out 10¹⁴⁴ rad/s/√Hz and the frequencies drifted
from it overflowed: the error blamed the noise key, or the run stopped in a LinAlgError ("Eigenvalues did
not converge")."""
_PPM = 1e-6
_NOISE_DROP = 1e-5  # baseband noise directions below this share of the variance are not drawn

#: A state-space matrix's element type: real (the carrier model's oscillator) or complex (the envelope).
_S = TypeVar("_S", np.float64, np.complex128)


def element_axes() -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(drive, sense) sensor-axis index of each element k = 0, 1, 2: (k+1) mod 3 and (k+2) mod 3."""
    return np.array([1, 2, 0]), np.array([2, 0, 1])


class CycleFilter(NamedTuple):
    """The demodulator filter discretised over one drive cycle (first-order hold of its input):
    s_{k+1} = Φ s_k + Γ₀ u_{k−1} + Γ₁ u_k, y_k = c·s_{k+1}; ``settled`` = −A_f⁻¹ B_f, its state per unit
    of a constant input."""

    phi: NDArray[np.complex128]
    gamma0: NDArray[np.complex128]
    gamma1: NDArray[np.complex128]
    c: NDArray[np.complex128]
    settled: NDArray[np.complex128]


class MemsGyro(GyroMechanism):
    """A triad of MEMS Coriolis vibratory gyros (see the module notes for the model and its sources).

    Every key is a physical parameter of one sense element, in SI units (frequencies in Hz), except
    the temperature coefficients (ppm/°C) and the reference temperature (°C).
    """

    kind: Literal["mems"] = "mems"
    reads: ClassVar[frozenset[str]] = frozenset({"specific_force", "temperature_degC"})
    model: Literal["baseband", "carrier"] = "baseband"
    """``baseband``: the averaged envelope model (fast); ``carrier``: the sense oscillator itself."""
    proof_mass_kg: PositiveReal = 4.0e-9
    drive_frequency_hz: Annotated[
        PositiveReal,
        at_most(MAX_DRIVE_FREQUENCY_HZ, "twice the fastest drive of real MEMS gyros (about 100 kHz)"),
        at_least(MIN_DRIVE_FREQUENCY_HZ, "a third of the slowest drive of real MEMS gyros (about 3 kHz)"),
    ] = 27_000.0
    drive_amplitude_m: Annotated[
        PositiveReal,
        at_least(DRIVE_AMPLITUDE_RANGE_M[0], "a hundredth of the smallest drive of real MEMS gyros (about 1 µm)"),
        at_most(DRIVE_AMPLITUDE_RANGE_M[1], "fifty times the largest drive of real MEMS gyros (about 20 µm)"),
    ] = 5.0e-6
    drive_quality_factor: PositiveReal = 1000.0
    mode_split_hz: Real = 2000.0
    """f_s − f_d: sense resonance above (> 0) or below (< 0) the drive."""
    sense_quality_factor: PositiveReal = 1000.0
    pickoff_gain_v_per_m: PositiveReal = 1.0e7
    quadrature_stiffness_n_per_m: Real = 1.5e-3
    """k_q, drive-to-sense coupling stiffness: quadrature rate Ω_q = k_q/(2 m ω_d)."""
    demodulation_phase_error_rad: Real = 1.0e-3
    drive_force_sense_coupling_per_m: Real = 7.0e4
    """κ: sideways drive force per drive force and per metre of sense deflection (g-sensitivity)."""
    drive_frequency_tc_ppm_per_degC: Real = -30.0
    sense_frequency_tc_ppm_per_degC: Real = -31.0
    reference_temperature_degC: Annotated[
        Real,
        at_most(MAX_REFERENCE_TEMPERATURE_DEGC, "five times the hottest rating of real MEMS gyros (200 °C)"),
    ] = 25.0
    """Where the frequencies above hold and the scale factor and reference phase were calibrated."""
    demodulator_bandwidth_hz: PositiveReal | None = 500.0
    """Cut-off of the Butterworth low-pass after the demodulator (None: no filter)."""
    demodulator_filter_order: Literal[1, 2, 3, 4] = 4

    @field_validator("mode_split_hz")
    @classmethod
    def _sense_mode(cls, split: float, info: ValidationInfo) -> float:
        drive = info.data.get("drive_frequency_hz")
        if drive is None:
            return split
        if drive + split <= 0:
            raise ValueError(
                f"the sense mode's frequency f_d + Δf = {drive + split:g} Hz must be positive "
                "(a negative stiffness makes the sense mode unstable)"
            )
        if abs(split) > drive / 4:
            raise ValueError(
                f"|{split:g}| Hz is more than a quarter of the drive frequency {drive:g} Hz: "
                "the sense mode must lie near the drive for the Coriolis response (and the "
                "averaged envelope model) to hold"
            )
        return split

    @field_validator("quadrature_stiffness_n_per_m")
    @classmethod
    def _coupling_small_against_the_mode(cls, k_q: float, info: ValidationInfo) -> float:
        mass, drive = info.data.get("proof_mass_kg"), info.data.get("drive_frequency_hz")
        if mass is None or drive is None:
            return k_q
        limit = MAX_QUADRATURE_STIFFNESS_FRACTION * mass * (2 * math.pi * drive) ** 2
        if abs(k_q) > limit:
            raise ValueError(
                f"|{k_q:g}| N/m is more than the limit of {limit:.4g} N/m, {MAX_QUADRATURE_STIFFNESS_FRACTION:g} of "
                f"the drive mode's stiffness m ω_d²: a hundred times the quadrature coupling of real MEMS gyros "
                "(at most about 10⁻³ of it)"
            )
        return k_q

    @field_validator("sense_quality_factor", "drive_quality_factor")
    @classmethod
    def _resonator(cls, q: float) -> float:
        if q < 5:
            raise ValueError(f"must be at least 5 (a resonator, not an overdamped mass), got {q:g}")
        return q

    @field_validator("demodulation_phase_error_rad")
    @classmethod
    def _phase(cls, phase: float) -> float:
        if not abs(phase) < math.pi / 2:
            raise ValueError(f"|{phase:g}| rad must be below π/2: at 90° the rate channel sees no rate")
        return phase

    @field_validator("reference_temperature_degC")
    @classmethod
    def _above_absolute_zero(cls, t: float) -> float:
        if not t > -ZERO_CELSIUS_K:
            raise ValueError(f"{t:g} °C is below absolute zero")
        return t

    @field_validator("demodulator_bandwidth_hz")
    @classmethod
    def _below_carrier(cls, bandwidth: float | None, info: ValidationInfo) -> float | None:
        drive = info.data.get("drive_frequency_hz")
        if bandwidth is not None and drive is not None and not bandwidth <= drive / 4:
            raise ValueError(
                f"{bandwidth:g} Hz must be at most a quarter of the drive frequency {drive:g} Hz "
                "(the demodulator filter must reject the product at twice the drive frequency)"
            )
        return bandwidth

    # ----------------------------------------------------------------------------------------------
    # The physics in closed form
    # ----------------------------------------------------------------------------------------------

    @overload
    def frequencies(self, temperature_degC: float | None = None) -> tuple[float, float]: ...

    @overload
    def frequencies(self, temperature_degC: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...

    def frequencies(
        self, temperature_degC: float | NDArray[np.float64] | None = None
    ) -> tuple[float | NDArray[np.float64], float | NDArray[np.float64]]:
        """(ω_d, ω_s), rad/s, at ``temperature_degC`` (scalar or array; None: the reference)."""
        dt = 0.0 if temperature_degC is None else np.asarray(temperature_degC, float) - self.reference_temperature_degC
        w_d = 2 * np.pi * self.drive_frequency_hz * (1 + self.drive_frequency_tc_ppm_per_degC * _PPM * dt)
        w_s = (
            2
            * np.pi
            * (self.drive_frequency_hz + self.mode_split_hz)
            * (1 + self.sense_frequency_tc_ppm_per_degC * _PPM * dt)
        )
        return w_d, w_s

    @overload
    def sense_response(self, temperature_degC: float | None = None) -> complex: ...

    @overload
    def sense_response(self, temperature_degC: NDArray[np.float64]) -> NDArray[np.complex128]: ...

    def sense_response(
        self, temperature_degC: float | NDArray[np.float64] | None = None
    ) -> complex | NDArray[np.complex128]:
        """H = 1/(ω_s² − ω_d² + i ω_d ω_s/Q_s), m per m/s² of force amplitude at the drive frequency (3)."""
        w_d, w_s = self.frequencies(temperature_degC)
        # complex128 where ω is an array, which numpy's stubs widen to complexfloating[Any, Any]
        return cast(
            "complex | NDArray[np.complex128]",
            1.0 / (w_s**2 - w_d**2 + 1j * w_d * w_s / self.sense_quality_factor),
        )

    @overload
    def _coriolis_amplitude(self, w_d: float) -> float: ...

    @overload
    def _coriolis_amplitude(self, w_d: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def _coriolis_amplitude(self, w_d: float | NDArray[np.float64]) -> float | NDArray[np.float64]:
        """c = −2 x₀ ω_d: complex force amplitude per unit mass per rad/s (real: drive-velocity phase)."""
        return -2.0 * self.drive_amplitude_m * w_d

    def reference_phase(self) -> float:
        """φ_ref, rad: the phase of the Coriolis response at the reference temperature plus φ_e."""
        w_d, _ = self.frequencies()
        coriolis_response = self.sense_response() * self._coriolis_amplitude(w_d)
        return float(np.angle(coriolis_response)) + self.demodulation_phase_error_rad

    @overload
    def scale_factor_v_per_rad_per_s(self, temperature_degC: float | None = None) -> float: ...

    @overload
    def scale_factor_v_per_rad_per_s(self, temperature_degC: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def scale_factor_v_per_rad_per_s(
        self, temperature_degC: float | NDArray[np.float64] | None = None
    ) -> float | NDArray[np.float64]:
        """Rate-channel output per rad/s in steady state, V/(rad/s): G_p Re{H c e^{−iφ_ref}} (4)."""
        w_d, _ = self.frequencies(temperature_degC)
        h = self.sense_response(temperature_degC) * self._coriolis_amplitude(w_d)
        scale: float | NDArray[np.float64] = self.pickoff_gain_v_per_m * np.real(
            h * np.exp(-1j * self.reference_phase())
        )
        return scale

    def envelope_pole(self) -> complex:
        """p, rad/s: the sense mode's pole seen from the frame turning at ω_d (reference temperature)."""
        w_d, w_s = self.frequencies()
        q = self.sense_quality_factor
        return complex(-w_s / (2 * q) + 1j * (w_s * math.sqrt(1 - 1 / (4 * q * q)) - w_d))

    def quadrature_rate(self) -> float:
        """Ω_q = k_q/(2 m ω_d), rad/s: the quadrature as the rate whose Coriolis force it equals."""
        return self.quadrature_stiffness_n_per_m / (2 * self.proof_mass_kg * self.frequencies()[0])

    def quadrature_bias(self) -> float:
        """Rate-channel bias from the quadrature, −Ω_q tan φ_e, rad/s (reference temperature)."""
        return -self.quadrature_rate() * math.tan(self.demodulation_phase_error_rad)

    def rest_bias(self) -> float:
        """|(−Ω_q tan φ_e, G g)|: the quadrature leak and the g-sensitivity under 1 g, rad/s."""
        return math.hypot(self.quadrature_bias(), self.g_sensitivity() * STANDARD_GRAVITY)

    def g_sensitivity(self) -> float:
        """G = κ ω_d/(2 Q_d ω_s²): indicated rate per specific force along the sense axis, rad/s per m/s²."""
        w_d, w_s = self.frequencies()
        return self.drive_force_sense_coupling_per_m * w_d / (2 * self.drive_quality_factor * w_s**2)

    @overload
    def brownian_noise_density(self, temperature_degC: float | None = None) -> float: ...

    @overload
    def brownian_noise_density(self, temperature_degC: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def brownian_noise_density(
        self, temperature_degC: float | NDArray[np.float64] | None = None
    ) -> float | NDArray[np.float64]:
        """Ω_n = √(4 k_B T ω_s/(m Q_s))/(2 x₀ ω_d), rad/s/√Hz (7), at ``temperature_degC`` (None: the
        reference)."""
        temp = self.reference_temperature_degC if temperature_degC is None else np.asarray(temperature_degC, float)
        w_d, w_s = self.frequencies(temperature_degC)
        m, q = self.proof_mass_kg, self.sense_quality_factor
        density: float | NDArray[np.float64] = np.sqrt(4 * K_BOLTZMANN * (temp + ZERO_CELSIUS_K) * w_s / (m * q)) / (
            2 * self.drive_amplitude_m * w_d
        )
        return density

    def intrinsic_noise_density(self) -> float:
        """White rate noise of the calibrated output at the reference temperature, rad/s/√Hz:
        the Brownian floor (7) over cos φ_e (the rate channel's share of the in-phase noise)."""
        return float(self.brownian_noise_density()) / math.cos(self.demodulation_phase_error_rad)

    def steady_state_rate(
        self,
        omega: ArrayLike,
        specific_force: ArrayLike | None = None,
        temperature_degC: float | NDArray[np.float64] | None = None,
        alpha: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """Indicated rate (…, 3), rad/s, once the envelope has settled on constant inputs (closed form).

        ``omega``, ``specific_force``, ``alpha``: (…, 3) in sensor axes; ``temperature_degC``: scalar
        or (…,). Exact for the physics of (2)–(3); both models must reproduce it.
        """
        omega = np.asarray(omega, float)
        zeros = np.zeros_like(omega)
        force = zeros if specific_force is None else np.asarray(specific_force, float)
        alpha = zeros if alpha is None else np.asarray(alpha, float)
        w_d, w_s = self.frequencies(temperature_degC)
        w_d, w_s = np.asarray(w_d)[..., None], np.asarray(w_s)[..., None]
        h = self.sense_response(temperature_degC)
        envelope = np.asarray(h)[..., None] * self._forcing(omega, alpha, force, w_d, w_s)
        rate: NDArray[np.float64] = self._demodulate(envelope)[0] / self.scale_factor_v_per_rad_per_s()
        return rate

    @overload
    def rate_response(self, frequency_hz: float, exact: bool = False) -> complex: ...

    @overload
    def rate_response(self, frequency_hz: NDArray[np.float64], exact: bool = False) -> NDArray[np.complex128]: ...

    def rate_response(
        self, frequency_hz: float | NDArray[np.float64], exact: bool = False
    ) -> complex | NDArray[np.complex128]:
        """Complex gain from a rate Ω cos(2π f t) about the sensing axis to the indicated rate.

        The rate's envelope force c Ω and the Euler force i x₀ Ω̇ of its angular acceleration put
        c (1 ± f/2f_d) Ω/2 on the sidebands f_d ± f. ``exact=False``: the baseband model's response to
        them, the poles p and p̄ (6); ``exact=True``: the sense oscillator's own, H at the sidebands
        over H₀ (what the carrier model follows, but for its cycle averaging and hold). Both include the
        demodulator filter. ``frequency_hz``: scalar or array, Hz.
        """
        w = 2 * np.pi * np.asarray(frequency_hz, float)
        w_d, w_s = self.frequencies()
        if exact:
            q = self.sense_quality_factor
            h0 = self.sense_response()
            upper = 1 / (w_s**2 - (w_d + w) ** 2 + 1j * (w_d + w) * w_s / q) / h0
            lower = 1 / (w_s**2 - (w_d - w) ** 2 + 1j * (w_d - w) * w_s / q) / h0
        else:
            p = self.envelope_pole()
            upper = -p / (1j * w - p)
            lower = -p / (-1j * w - p)
        upper = upper * (1 + w / (2 * w_d))  # the Euler force's share of each sideband
        lower = lower * (1 - w / (2 * w_d))
        phase = np.exp(-1j * self.demodulation_phase_error_rad)
        gain = (upper * phase + np.conj(lower * phase)) / (2 * math.cos(self.demodulation_phase_error_rad))
        response: complex | NDArray[np.complex128] = gain * self._filter_response(w)
        return response

    def _filter_response(self, w: ArrayLike) -> NDArray[np.complex128]:
        """The demodulator filter's gain at angular frequency ``w`` (1 when there is none): the product
        of its sections −p_k/(jw − p_k) over the Butterworth poles p_k."""
        w = np.asarray(w, dtype=float)
        if self.demodulator_bandwidth_hz is None:
            return np.ones_like(w, dtype=complex)
        poles = butterworth_poles(self.demodulator_filter_order) * 2 * np.pi * self.demodulator_bandwidth_hz
        gain = np.ones_like(w, dtype=complex)
        for p in poles:
            gain = gain * (-p / (1j * w - p))
        return gain

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        """The output rate for the baseband model; for the carrier model an integer multiple of it, at
        least 4× it and 4× the output's band.

        The baseband model is discretised exactly over each step, for the noise and for the forcing's
        cubic Hermite interpolant (from Ω and α at the step's ends), and it gives the exact integral of
        its rate: a finer grid would only resolve the motion, which the truth's own samples bound
        (the IMU's grid is never coarser than those). The carrier model holds its forcing linear
        between grid samples and the IMU integrates its rate by the trapezoid rule, so its grid resolves
        the band: the demodulator filter's cut-off, or the envelope pole's frequency |p|/2π (≈ |Δf|)
        without a filter.
        """
        if self.model == "baseband":
            return output_rate_hz
        band = abs(self.envelope_pole()) / (2 * np.pi)
        if self.demodulator_bandwidth_hz is not None:
            band = min(band, self.demodulator_bandwidth_hz)
        return output_rate_hz * max(4, math.ceil(4 * band / output_rate_hz))

    # ----------------------------------------------------------------------------------------------
    # Forces, demodulation
    # ----------------------------------------------------------------------------------------------

    def _forcing(
        self,
        omega: NDArray[np.float64],
        alpha: NDArray[np.float64],
        force: NDArray[np.float64],
        w_d: float | NDArray[np.float64],
        w_s: float | NDArray[np.float64],
    ) -> NDArray[np.complex128]:
        """Complex force amplitude F per unit mass on each element's sense mode, (…, 3), m/s².

        ``omega``, ``alpha``, ``force``: (…, 3) sensor axes; ``w_d``, ``w_s``: broadcastable to (…, 1).
        The real part is in phase with the drive velocity, the imaginary part with the displacement.
        """
        drive, sense = element_axes()
        x0 = self.drive_amplitude_m
        out = np.empty(np.broadcast_shapes(omega.shape, np.shape(w_d)), complex)
        # −2 Ω ẋ (Coriolis) + κ y_g F_x/m (drive force leaking sideways, y_g = −f_s/ω_s²,
        # F_x/m = ω_d² x₀/Q_d): both in phase with the drive velocity
        leak = -self.drive_force_sense_coupling_per_m * x0 * w_d**2 / (self.drive_quality_factor * w_s**2)
        out.real = self._coriolis_amplitude(w_d) * omega + leak * force[..., sense]
        # −(k_q/m + α + Ω_d Ω_s) x, with x = Re{−i x₀ e^{iθ}}: in phase with the drive displacement
        out.imag = x0 * (
            self.quadrature_stiffness_n_per_m / self.proof_mass_kg + alpha + omega[..., drive] * omega[..., sense]
        )
        return out

    def _forcing_on_grid(
        self,
        omega: NDArray[np.float64],
        alpha: NDArray[np.float64],
        force: NDArray[np.float64],
        w_d: NDArray[np.float64],
        w_s: NDArray[np.float64],
    ) -> NDArray[np.complex128]:
        """:meth:`_forcing` on the inner grid, (M, 3) complex, bit for bit: ``omega``, ``alpha``, ``force``
        (M, 3), ``w_d``, ``w_s`` (M,), in one compiled pass (no temporaries)."""
        drive, sense = element_axes()
        x0 = self.drive_amplitude_m
        out = np.empty(omega.shape, complex)
        _forcing_run(
            np.ascontiguousarray(omega, dtype=float),
            np.ascontiguousarray(alpha, dtype=float),
            np.ascontiguousarray(force, dtype=float),
            np.ascontiguousarray(w_d, dtype=float),
            np.ascontiguousarray(w_s, dtype=float),
            drive,
            sense,
            x0,
            -self.drive_force_sense_coupling_per_m * x0,
            float(self.drive_quality_factor),
            -2.0 * x0,
            self.quadrature_stiffness_n_per_m / self.proof_mass_kg,
            out,
        )
        return out

    def _demodulate(self, envelope: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(I, Q) volts of a sense envelope A (m): G_p Re{A e^{−iφ_ref}} and −G_p Im{A e^{−iφ_ref}}.

        Equal to averaging v = G_p Re{A e^{iθ}} times 2 cos(θ + φ_ref) and times 2 sin(θ + φ_ref).
        """
        phase = self.reference_phase()
        cos, sin = self.pickoff_gain_v_per_m * math.cos(phase), self.pickoff_gain_v_per_m * math.sin(phase)
        envelope = np.asarray(envelope)
        return cos * envelope.real + sin * envelope.imag, cos * -envelope.imag + sin * envelope.real

    def _filter_state_space(
        self,
    ) -> tuple[NDArray[np.complex128], NDArray[np.complex128], NDArray[np.complex128]] | None:
        """The demodulator filter as (A_f, B_f, C_f), complex, or None when there is none.

        A cascade of first-order sections −p_k/(s − p_k) over the Butterworth poles p_k (unit DC gain,
        well scaled): their product is the real Butterworth low-pass.
        """
        if self.demodulator_bandwidth_hz is None:
            return None
        poles = butterworth_poles(self.demodulator_filter_order) * 2 * np.pi * self.demodulator_bandwidth_hz
        n = len(poles)
        a = np.diag(poles).astype(complex)
        a[np.arange(1, n), np.arange(n - 1)] = -poles[1:]
        b = np.zeros(n, complex)
        b[0] = -poles[0]
        c = np.zeros(n, complex)
        c[-1] = 1.0
        return a, b, c

    def _response(self, envelope: NDArray[np.complex128]) -> GyroResponse:
        """Demodulate the (filtered) sense envelope (M, 3) and calibrate: indicated rate I/SF₀."""
        return self._calibrated(*self._demodulate(envelope))

    def _calibrated(self, in_phase: NDArray[np.float64], quadrature: NDArray[np.float64]) -> GyroResponse:
        """The indicated rate I/SF₀ of the demodulated channels (M, 3), with the channels as raw observables."""
        return GyroResponse(
            rate=in_phase / self.scale_factor_v_per_rad_per_s(),
            raw={"sense_in_phase_v": in_phase, "sense_quadrature_v": quadrature},
        )

    # ----------------------------------------------------------------------------------------------
    # Simulation
    # ----------------------------------------------------------------------------------------------

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Indicated rate (M, 3) on the inner grid and the demodulated channels, by ``self.model``."""
        state = {} if state is None else state
        if np.any(np.asarray(truth.temperature_degC) <= -ZERO_CELSIUS_K):
            raise ValueError("sensor temperature at or below absolute zero")
        if self.model == "carrier":
            return self._respond_carrier(truth, rng, state)
        return self._respond_baseband(truth, rng, state)

    def baseband_system(self) -> tuple[NDArray[np.complex128], NDArray[np.complex128], NDArray[np.complex128]]:
        """The envelope (5) and the demodulator filter as one complex system ż = A z + b F, Ã = c·z.

        Returns (A (S, S), b (S,), c (S,)), complex, S = 1 + filter order: z = (A, filter states).
        """
        p = self.envelope_pole()
        gain = -p * self.sense_response()
        filt = self._filter_state_space()
        if filt is None:
            return np.array([[p]]), np.array([gain]), np.array([1.0 + 0j])
        a_f, b_f, c_f = filt
        n = len(b_f)
        a = np.zeros((n + 1, n + 1), complex)
        a[0, 0] = p
        a[1:, 0] = b_f
        a[1:, 1:] = a_f
        b = np.zeros(n + 1, complex)
        b[0] = gain
        c = np.concatenate([[0.0], c_f])
        return a, b, c

    @overload
    def _thermal_psd(self, temperature_degC: float | None = None) -> float: ...

    @overload
    def _thermal_psd(self, temperature_degC: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def _thermal_psd(self, temperature_degC: float | NDArray[np.float64] | None = None) -> float | NDArray[np.float64]:
        """Two-sided PSD of the Brownian force per unit mass, (m/s²)²/Hz: 2 k_B T ω_s/(m Q_s)."""
        temp = self.reference_temperature_degC if temperature_degC is None else temperature_degC
        _, w_s = self.frequencies(temperature_degC)
        return 2 * K_BOLTZMANN * (temp + ZERO_CELSIUS_K) * w_s / (self.proof_mass_kg * self.sense_quality_factor)

    def _respond_baseband(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any]) -> GyroResponse:
        """The envelope system over the grid's steps, each exact for the forcing's cubic Hermite
        interpolant (see :func:`hermite_hold`); ``state["envelope_state"]`` (3, S) carries it, and
        ``state["discretisation"]`` keeps the step matrices for the next chunk of the same step.

        The rate is given at the grid's samples, and the angle as the exact integral of the indicated
        rate over each step (cumulative from 0 at ``t[0]``): what the IMU integrates.
        """
        h = truth.dt
        temperature = np.asarray(truth.temperature_degC, float)
        w_d, w_s = self.frequencies(temperature)
        ratio = self.sense_response(temperature) / self.sense_response()  # H_T/H₀: temperature, exact in steady state
        force = cast("NDArray[np.float64]", truth.specific_force)  # in self.reads: never None here
        forcing = ratio[:, None] * self._forcing_on_grid(truth.omega, truth.alpha, force, w_d, w_s)
        smooth, slope = self._smooth_forcing(truth.omega, truth.alpha, w_d, h)
        smooth *= ratio[:, None]
        slope *= ratio[:, None]
        # The complex force n_c + i n_s has two-sided PSD 4 × (the real force's), scaled to the temperature.
        noise_scale = np.abs(ratio) * np.sqrt(self._thermal_psd(temperature) / self._thermal_psd())
        a, b, c = self.baseband_system()
        psd = 4 * self._thermal_psd()
        held = state.get("discretisation")
        if held is None or held[0] != h:  # the same grid step chunk after chunk: computed once
            phi, g_state, r_mean, g_mean = hermite_hold(a, b, c, h)
            # The step's noise on the state and on the step's mean envelope together (all in metres,
            # so the covariance's small directions can be dropped, see covariance_factor).
            a_mean, b_mean = mean_augmented(a, b, c, h)
            noise = covariance_factor(discrete_noise_covariance(a_mean, b_mean, psd, h), drop=_NOISE_DROP)
            held = state["discretisation"] = (h, phi, g_state, r_mean, g_mean, noise)
        _, phi, g_state, r_mean, g_mean, noise = held
        z = state.get("envelope_state")
        if z is None:  # power-up: settled on the first input, thermal motion from its stationary law
            z = np.outer(forcing[0], np.linalg.solve(a, -b))
            stationary = covariance_factor(stationary_covariance(a, b, psd), drop=_NOISE_DROP)
            z = z + noise_scale[0] * _circular_normal(rng, (3, stationary.shape[1])) @ stationary.T
        z = np.array(z, dtype=complex)  # a copy: the kernel updates it in place
        # The kernel demodulates each envelope sample as it makes it (the arithmetic of _demodulate).
        phase = self.reference_phase()
        gain = self.pickoff_gain_v_per_m
        in_phase = np.empty(forcing.shape)
        quadrature = np.empty(forcing.shape)
        mean_in_phase = np.zeros(forcing.shape)
        _hermite_run(
            phi,
            g_state,
            r_mean,
            g_mean,
            noise,
            c,
            np.ascontiguousarray(forcing),
            smooth,
            slope,
            noise_scale,
            z,
            rng,
            gain * math.cos(phase),
            gain * math.sin(phase),
            in_phase,
            quadrature,
            mean_in_phase,
        )
        state["envelope_state"] = z
        response = self._calibrated(in_phase, quadrature)
        # ∫ rate dt over step k is h × its mean in-phase over SF₀ (the last row is no step's).
        steps = mean_in_phase[:-1] * (h / self.scale_factor_v_per_rad_per_s())
        angle = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
        return GyroResponse(angle=angle, rate=response.rate, raw=response.raw)

    def _smooth_forcing(
        self, omega: NDArray[np.float64], alpha: NDArray[np.float64], w_d: ArrayLike, h: float
    ) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
        """The part P of the forcing whose time derivative the truth gives, and h·Ṗ, (M, 3) complex.

        P = c(ω_d) Ω_k + i x₀ (k_q/m + Ω_d Ω_s), so Ṗ = c(ω_d) α_k + i x₀ (α_d Ω_s + Ω_d α_s), with ω_d
        frozen at each sample (it moves with the temperature only). The rest of F (the specific-force
        leak and the Euler force x₀ α_k) is held linear over each step (:func:`_hermite_run`).
        """
        drive, sense = element_axes()
        x0 = self.drive_amplitude_m
        coriolis = self._coriolis_amplitude(np.asarray(w_d, float))[:, None]
        quad = self.quadrature_stiffness_n_per_m / self.proof_mass_kg
        smooth = coriolis * omega + 1j * (x0 * (quad + omega[:, drive] * omega[:, sense]))
        turning = alpha[:, drive] * omega[:, sense] + omega[:, drive] * alpha[:, sense]
        slope = h * (coriolis * alpha + 1j * (x0 * turning))
        return np.ascontiguousarray(smooth), np.ascontiguousarray(slope)

    def _respond_carrier(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any]) -> GyroResponse:
        """The sense oscillators on the phase-locked carrier grid, from power-up (``state["carrier"]``
        carries grid origin and index, held temperature, oscillator, demodulator and filter)."""
        run = state.get("carrier")
        steps = CARRIER_STEPS_PER_CYCLE
        power_up = run is None
        if power_up:  # the carrier grid starts at power-up; its temperature is held from then on
            assert truth.temperature_degC is not None  # in self.reads, and respond() compared it
            run = {"t0": float(truth.t[0]), "temperature_degC": float(truth.temperature_degC[0]), "j": 0}
        assert run is not None  # given in state, or set at power-up just above
        temperature = run["temperature_degC"]
        w_d, w_s = self.frequencies(temperature)
        h = 2 * np.pi / (steps * w_d)  # carrier step: N per drive cycle, θ_j = 2π j/N
        j0 = run["j"]
        j_end = int(math.floor((truth.t[-1] - run["t0"]) / h + 1e-9))  # last carrier step in this chunk
        _, sense = element_axes()

        # The forces at the truth samples; the carrier steps see them linear in between, like the
        # baseband model. F: complex amplitude at the carrier; −f_s: the DC force (deflection y_g).
        force = cast("NDArray[np.float64]", truth.specific_force)  # in self.reads: never None here
        forcing = self._forcing(truth.omega, truth.alpha, force, w_d, w_s)
        assert truth.specific_force is not None  # in self.reads
        static = np.ascontiguousarray(-truth.specific_force[:, sense])

        # The sense oscillator (y, ẏ): ẋ = A x + b u, discretised exactly over a carrier step.
        a = np.array([[0.0, 1.0], [-(w_s**2), -w_s / self.sense_quality_factor]])
        b = np.array([0.0, 1.0])
        phi, dc0, dc1 = first_order_hold(a, b, h)
        g0, g1 = carrier_hold(a, b, w_d, h)
        psd = self._thermal_psd(temperature)
        noise = covariance_factor(discrete_noise_covariance(a, b, psd, h))
        carrier = np.exp(2j * np.pi * np.arange(steps) / steps)  # e^{iθ_j}, one drive cycle

        if power_up:  # settled on the first input (A = H F plus the static deflection), thermal motion
            settled = self.sense_response(temperature) * forcing[0]
            x = np.column_stack([settled.real + static[0] / w_s**2, (1j * w_d * settled).real])
            stationary = covariance_factor(stationary_covariance(a, b, psd))
            x = x + rng.standard_normal((3, stationary.shape[1])) @ stationary.T
            run.update(
                x=x,
                acc=2.0 * x[:, 0] + 0j,  # y_0 · 2 e^{−iθ_0}
                force_at_j=forcing[0].copy(),
                static_at_j=static[0].copy(),
                filter_state=None,
                filter_input=settled,
                held=settled,
            )
        x = np.array(run["x"], dtype=float)  # copies: the kernel updates them in place
        acc = np.array(run["acc"], dtype=complex)
        force_at_j = np.array(run["force_at_j"], dtype=complex)
        static_at_j = np.array(run["static_at_j"], dtype=float)

        # Pass by pass (CARRIER_CYCLES_PER_PASS drive cycles): step the oscillators, demodulate, filter
        # the cycle averages (one a drive cycle), and hold at each truth sample the last cycle done by
        # then; `filled` truth samples are set, the rest see `latest` until a later cycle is done.
        held = np.empty((len(truth.t), 3), complex)
        seen = truth.t + 1e-9 * h  # a cycle done at a truth sample's instant counts for it
        latest = run["held"]
        filled = 0
        cycle_filter = self._cycle_filter(steps * h)
        for j_a in range(j0, j_end, CARRIER_CYCLES_PER_PASS * steps):
            j_b = min(j_end, j_a + CARRIER_CYCLES_PER_PASS * steps)
            cycles = np.empty(((j_b - j_a) // steps + 2, 3), complex)
            done = np.empty(len(cycles), np.int64)
            count = _carrier_run(
                phi,
                dc0,
                dc1,
                g0,
                g1,
                noise,
                carrier,
                j_a,
                j_b,
                (run["t0"] - truth.t[0]) / truth.dt,
                h / truth.dt,
                forcing,
                static,
                force_at_j,
                static_at_j,
                x,
                acc,
                rng,
                cycles,
                done,
            )
            if count == 0:
                continue
            filtered = self._filter_cycles(cycles[:count], run, cycle_filter)
            times = run["t0"] + done[:count] * h
            start = int(np.searchsorted(seen, times[0], side="left"))  # the first to see this pass
            stop = int(np.searchsorted(seen, times[-1], side="left"))  # the first to see its last cycle
            held[filled:start] = latest
            held[start:stop] = filtered[np.searchsorted(times, seen[start:stop], side="right") - 1]
            latest, filled = filtered[-1], stop
        held[filled:] = latest
        run.update(j=j_end, x=x, acc=acc, force_at_j=force_at_j, static_at_j=static_at_j, held=latest)
        state["carrier"] = run
        return self._response(held)

    def _cycle_filter(self, period: float) -> CycleFilter | None:
        """The demodulator filter discretised over one drive cycle ``period`` (s), input linear between
        cycles, for :meth:`_filter_cycles`; None when there is no filter."""
        filt = self._filter_state_space()
        if filt is None:
            return None
        a_f, b_f, c_f = filt
        phi, gamma0, gamma1 = first_order_hold(a_f, b_f, period)
        settled = np.linalg.solve(a_f, -b_f).astype(complex)
        return CycleFilter(phi, gamma0, gamma1, c_f, settled)

    def _filter_cycles(
        self, cycles: NDArray[np.complex128], run: dict[str, Any], discrete: CycleFilter | None
    ) -> NDArray[np.complex128]:
        """The demodulator filter (``discrete``, from :meth:`_cycle_filter`) over per-cycle envelopes
        (K, 3); its state is kept in ``run``."""
        if discrete is None or len(cycles) == 0:
            return cycles
        if run["filter_state"] is None:  # settled on the power-up envelope
            run["filter_state"] = np.outer(run["filter_input"], discrete.settled)
        s = np.array(run["filter_state"], dtype=complex)  # copies: the kernel updates them in place
        previous = np.array(run["filter_input"], dtype=complex)
        out = np.empty_like(cycles)
        _filter_run(
            discrete.phi, discrete.gamma0, discrete.gamma1, discrete.c, np.ascontiguousarray(cycles), s, previous, out
        )
        run.update(filter_state=s, filter_input=previous)
        return out


# --------------------------------------------------------------------------------------------------
# Exact discretisation
# --------------------------------------------------------------------------------------------------


def butterworth_poles(order: int) -> NDArray[np.complex128]:
    """The analogue Butterworth prototype's poles (cut-off 1 rad/s), −exp(iπ m/2n) for
    m = −n+1, −n+3, …, n−1 (``scipy.signal.buttap``'s expression, so the same numbers; written here so
    that a device need not import scipy.signal, 0.5 s)."""
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    poles: NDArray[np.complex128] = -np.exp(1j * np.pi * m / (2 * order))
    return poles


def first_order_hold(a: NDArray[_S], b: NDArray[_S], h: float) -> tuple[NDArray[_S], NDArray[_S], NDArray[_S]]:
    """(Φ, Γ₀, Γ₁) with x_{k+1} = Φ x_k + Γ₀ u_k + Γ₁ u_{k+1}: ẋ = A x + b u exactly for u linear over
    the step.

    From one matrix exponential: d/dt (x, u, u̇) = (A x + b u, u̇, 0) over h maps (x_k, u_k, Δu/h).
    ``a`` (S, S), ``b`` (S,), real or complex; u scalar.
    """
    s = a.shape[0]
    m = np.zeros((s + 2, s + 2), dtype=np.result_type(a, b))
    m[:s, :s] = a * h
    m[:s, s] = b * h
    m[s, s + 1] = 1.0
    import scipy.linalg  # scipy where it is used: the CLI's listings skip it

    e = scipy.linalg.expm(m)
    return e[:s, :s], e[:s, s] - e[:s, s + 1], e[:s, s + 1]


def hermite_hold(
    a: NDArray[np.complex128], b: NDArray[np.complex128], c: NDArray[np.complex128], h: float
) -> tuple[NDArray[np.complex128], NDArray[np.complex128], NDArray[np.complex128], NDArray[np.complex128]]:
    """(Φ, G (S, 4), r (S,), g (4,)): one step h of ż = A z + b u, and the step's mean of y = c·z,
    exact for u the cubic Hermite interpolant of (u₀, u₁) with slopes (u̇₀, u̇₁):

        z₁ = Φ z₀ + G (u₀, u₁, h u̇₀, h u̇₁),     (1/h) ∫₀ʰ y dτ = r·z₀ + g·(u₀, u₁, h u̇₀, h u̇₁).

    In the step's own time σ = τ/h, u = Σ a_m σ^m with a₀ = u₀, a₁ = h u̇₀,
    a₂ = 3(u₁ − u₀) − 2h u̇₀ − h u̇₁, a₃ = 2(u₀ − u₁) + h u̇₀ + h u̇₁: the output of a chain of four
    integrators (the exosystem) started at (a₀, a₁, 2a₂, 6a₃). The system, the running mean
    μ' = c·z (in σ) and the chain form one linear system, whose matrix exponential over σ ∈ [0, 1]
    gives every map at once (the method of :func:`first_order_hold`, one order of hold higher).
    ``a`` (S, S), ``b``, ``c`` (S,), complex.
    """
    s = a.shape[0]
    n = s + 1 + 4  # (z, μ, the chain)
    m = np.zeros((n, n), complex)
    m[:s, :s] = a * h
    m[s, :s] = c
    m[:s, s + 1] = b * h
    for k in range(3):
        m[s + 1 + k, s + 2 + k] = 1.0
    import scipy.linalg

    e = scipy.linalg.expm(m)
    # The chain's start (a₀, a₁, 2a₂, 6a₃) from (u₀, u₁, h u̇₀, h u̇₁).
    start = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [-6.0, 6.0, -4.0, -2.0], [12.0, -12.0, 6.0, 6.0]])
    response = e[: s + 1, s + 1 :] @ start
    return e[:s, :s], response[:s], e[s, :s], response[s]


def mean_augmented(
    a: NDArray[np.complex128], b: NDArray[np.complex128], c: NDArray[np.complex128], h: float
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """(A', b') of ż = A z + b u extended by the running mean of y = c·z over a step h, μ̇ = c·z/h:
    the system whose discrete noise covariance over h (:func:`discrete_noise_covariance`) is that of
    the state and the step's mean together."""
    s = a.shape[0]
    a_mean = np.zeros((s + 1, s + 1), complex)
    a_mean[:s, :s] = a
    a_mean[s, :s] = c / h
    return a_mean, np.concatenate([b, [0.0]]).astype(complex)


def carrier_hold(
    a: NDArray[np.float64], b: NDArray[np.float64], w: float, h: float
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """(G₀, G₁), complex (S,): the response over one step of ẋ = A x + b Re{e^{iθ_k} (F_k + ΔF τ/h) e^{iwτ}}
    from x = 0 is Re{e^{iθ_k} (G₀ F_k + G₁ ΔF)}.

    The carrier is an exosystem: u₀ = e^{iwτ} (u₀' = iw u₀) and u₁ = (τ/h) e^{iwτ}
    (u₁' = iw u₁ + u₀/h); the response to each, from rest, is one column of a matrix exponential.
    """
    s = a.shape[0]
    m = np.zeros((s + 2, s + 2), complex)  # state (x, u₁, u₀)
    m[:s, :s] = a
    m[s, s] = m[s + 1, s + 1] = 1j * w
    m[s, s + 1] = 1.0 / h
    m0 = m.copy()
    m0[:s, s + 1] = b  # x driven by u₀
    m1 = m.copy()
    m1[:s, s] = b  # x driven by u₁
    import scipy.linalg

    return scipy.linalg.expm(m0 * h)[:s, s + 1], scipy.linalg.expm(m1 * h)[:s, s + 1]


def discrete_noise_covariance(a: NDArray[_S], b: NDArray[_S], psd: float, h: float) -> NDArray[_S]:
    """Q = ∫₀ʰ e^{Aσ} b S b* e^{A*σ} dσ: the covariance one step of white input (two-sided PSD S) adds.

    Van Loan's method: exp([[−A, b S b*], [0, A*]] h) = [[·, Φ⁻¹Q], [0, Φ*]]. Its e^{−Ah} grows as
    e^{σh}, σ the fastest decay rate of A, and swamps Q's digits when a step spans many of that pole's
    time constants; so where σh > 1 it is taken over h/2^k, σh/2^k ≤ 1, and doubled k times,
    Q(2τ) = Q(τ) + Φ(τ) Q(τ) Φ(τ)*: a sum of positive terms.
    """
    s = a.shape[0]
    decay = float(np.max(-np.linalg.eigvals(a).real, initial=0.0)) * h
    halvings = max(0, math.ceil(math.log2(decay))) if decay > 1 else 0
    tau = h / 2**halvings
    m = np.zeros((2 * s, 2 * s), dtype=np.result_type(a, b))
    m[:s, :s] = -a
    m[:s, s:] = psd * np.outer(b, np.conj(b))
    m[s:, s:] = np.conj(a).T
    import scipy.linalg

    e = scipy.linalg.expm(m * tau)
    phi = np.conj(e[s:, s:]).T
    q = phi @ e[:s, s:]
    for _ in range(halvings):
        q = q + phi @ q @ np.conj(phi).T
        phi = phi @ phi
    covariance: NDArray[_S] = 0.5 * (q + np.conj(q).T)
    return covariance


def stationary_covariance(a: NDArray[_S], b: NDArray[_S], psd: float) -> NDArray[_S]:
    """P with A P + P A* + b S b* = 0: the covariance white input (two-sided PSD S) settles to.

    Solved as the linear system (I ⊗ A + Ā ⊗ I) vec P = −vec(b S b*) (S ≤ 5 states here).
    """
    s = a.shape[0]
    eye = np.eye(s)
    lhs = np.kron(eye, a) + np.kron(np.conj(a), eye)
    rhs = -psd * np.outer(b, np.conj(b))
    p = np.linalg.solve(lhs, rhs.reshape(-1, order="F")).reshape(s, s, order="F")
    covariance: NDArray[_S] = 0.5 * (p + np.conj(p).T)
    return covariance


def covariance_factor(q: NDArray[_S], drop: float = 0.0) -> NDArray[_S]:
    """L (S, R) with L L* = Q, for a positive semi-definite Q, by eigen-decomposition.

    With ``drop`` > 0 the directions that carry less than ``drop`` of the total variance tr Q are left
    out (R ≤ S), which only makes sense when every state has the same unit: each costs a normal draw
    per step, and together they hold less than S·``drop`` of the variance.
    """
    values, vectors = np.linalg.eigh(q)
    values = np.clip(values, 0.0, None)
    keep = values > drop * np.sum(values) if drop > 0 else np.ones(len(values), bool)
    return np.ascontiguousarray(vectors[:, keep] * np.sqrt(values[keep]))


def _circular_normal(rng: np.random.Generator, shape: tuple[int, ...]) -> NDArray[np.complex128]:
    """Circular complex normals, E|w|² = 1, real then imaginary part drawn for each element."""
    pair = rng.standard_normal((*shape, 2))
    # complex128, which numpy's stubs type as float64 (a float64 array times 1j)
    return cast("NDArray[np.complex128]", (pair[..., 0] + 1j * pair[..., 1]) / math.sqrt(2))


# --------------------------------------------------------------------------------------------------
# Recurrences
# --------------------------------------------------------------------------------------------------


@njit
def _forcing_run(
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    force: NDArray[np.float64],
    w_d: NDArray[np.float64],
    w_s: NDArray[np.float64],
    drive: NDArray[np.int64],
    sense: NDArray[np.int64],
    x0: float,
    leak_scale: float,
    q_d: float,
    coriolis_scale: float,
    quad: float,
    out: NDArray[np.complex128],
) -> None:
    """:meth:`MemsGyro._forcing` sample by sample, the same operations in the same order (so the same
    bits): leak = (−κ x₀) ω_d² / (Q_d ω_s²), Re F = (−2 x₀) ω_d Ω_k + leak f_s,
    Im F = x₀ ((k_q/m + α_k) + Ω_d Ω_s). ``omega``, ``alpha``, ``force`` (M, 3); ``w_d``, ``w_s`` (M,)."""
    n, n_axes = omega.shape
    for k in range(n):
        wd = w_d[k]
        ws = w_s[k]
        leak = leak_scale * (wd * wd) / (q_d * (ws * ws))
        coriolis = coriolis_scale * wd
        for a in range(n_axes):
            d = drive[a]
            s = sense[a]
            re = coriolis * omega[k, a] + leak * force[k, s]
            im = x0 * ((quad + alpha[k, a]) + omega[k, d] * omega[k, s])
            out[k, a] = complex(re, im)


@njit
def _hermite_run(
    phi: NDArray[np.complex128],
    g_state: NDArray[np.complex128],
    r_mean: NDArray[np.complex128],
    g_mean: NDArray[np.complex128],
    noise: NDArray[np.complex128],
    c: NDArray[np.complex128],
    forcing: NDArray[np.complex128],
    smooth: NDArray[np.complex128],
    slope: NDArray[np.complex128],
    noise_scale: NDArray[np.float64],
    z: NDArray[np.complex128],
    rng: np.random.Generator,
    dem_cos: float,
    dem_sin: float,
    in_phase: NDArray[np.float64],
    quadrature: NDArray[np.float64],
    mean_in_phase: NDArray[np.float64],
) -> None:
    """Over each step k → k+1 and axis: u = (F_k, F_{k+1}, D_k, D_{k+1}) with the slopes
    D = h Ṗ + ΔF − ΔP (the smooth part P's own slope; the rest of F is held linear, since a Hermite
    interpolant whose slopes are the secant is the straight line), then z_{k+1} = Φ z_k + G u + s_k L_z w_k
    and the step's mean envelope μ_k = r·z_k + g·u + s_k L_μ w_k, demodulated like y.

    ``phi`` (S, S), ``g_state`` (S, 4), ``r_mean`` (S,), ``g_mean`` (4,), ``noise`` L (S + 1, R), ``c``
    (S,); ``forcing`` F, ``smooth`` P, ``slope`` h Ṗ (M, A) complex; ``noise_scale`` s (M,); ``z``
    (A, S) in/out; ``in_phase``, ``quadrature`` (M, A) at the samples; ``mean_in_phase`` (M, A): step
    k's mean in-phase in row k (row M − 1 untouched). w_k: R circular normals per axis, real then
    imaginary part, drawn step by step, axis by axis.
    """
    n, n_axes = forcing.shape
    size = phi.shape[0]
    rank = noise.shape[1]
    w = np.empty(rank, np.complex128)
    now = np.empty(size, np.complex128)
    u = np.empty(4, np.complex128)
    half = 1.0 / np.sqrt(2.0)
    for k in range(n):
        sk = noise_scale[k] * half
        for a in range(n_axes):
            y = 0j
            for i in range(size):
                now[i] = z[a, i]
                y += c[i] * now[i]
            in_phase[k, a] = dem_cos * y.real + dem_sin * y.imag
            quadrature[k, a] = dem_cos * -y.imag + dem_sin * y.real
            if k == n - 1:
                continue
            for j in range(rank):
                re = rng.standard_normal()
                im = rng.standard_normal()
                w[j] = complex(re * sk, im * sk)
            secant = (forcing[k + 1, a] - forcing[k, a]) - (smooth[k + 1, a] - smooth[k, a])
            u[0] = forcing[k, a]
            u[1] = forcing[k + 1, a]
            u[2] = slope[k, a] + secant
            u[3] = slope[k + 1, a] + secant
            mean = 0j
            for i in range(size):
                mean += r_mean[i] * now[i]
            for m in range(4):
                mean += g_mean[m] * u[m]
            for j in range(rank):
                mean += noise[size, j] * w[j]
            mean_in_phase[k, a] = dem_cos * mean.real + dem_sin * mean.imag
            for i in range(size):
                acc = 0j
                for m in range(4):
                    acc += g_state[i, m] * u[m]
                for j in range(size):
                    acc += phi[i, j] * now[j]
                for j in range(rank):
                    acc += noise[i, j] * w[j]
                z[a, i] = acc


@njit
def _carrier_run(
    phi: NDArray[np.float64],
    dc0: NDArray[np.float64],
    dc1: NDArray[np.float64],
    g0: NDArray[np.complex128],
    g1: NDArray[np.complex128],
    noise: NDArray[np.float64],
    carrier: NDArray[np.complex128],
    j0: int,
    j_end: int,
    offset: float,
    ratio: float,
    forcing: NDArray[np.complex128],
    static: NDArray[np.float64],
    force_at_j: NDArray[np.complex128],
    static_at_j: NDArray[np.float64],
    x: NDArray[np.float64],
    acc: NDArray[np.complex128],
    rng: np.random.Generator,
    cycles: NDArray[np.complex128],
    done: NDArray[np.int64],
) -> int:
    """Step the sense oscillators over carrier steps j0 → j_end and demodulate them.

    x_{j+1} = Φ x_j + Re{e^{iθ_j}(G₀ F_j + G₁ (F_{j+1} − F_j))} + Γ₀ u_j + Γ₁ u_{j+1} + L w_j: F the
    complex force amplitude, u the static force, both linear between truth samples (``forcing``,
    ``static`` (M, A); carrier step j lies at truth index ``offset + j·ratio``). ``force_at_j`` and
    ``static_at_j`` (A,) hold F and u at step j0 on entry, at j_end on exit. Each new y_j, times
    2 e^{−iθ_j}, is added to ``acc`` (A,); after the last step of a cycle (phase index N − 1) the
    average acc/N goes to ``cycles`` and its step index to ``done``. ``x`` (A, 2) is updated in place.
    w_j: two normals per step and axis, step by step. Returns the number of completed cycles.
    """
    n_truth, n_axes = forcing.shape
    period = carrier.shape[0]
    count = 0
    for j in range(j0, j_end):
        u = offset + (j + 1) * ratio
        i = min(max(int(u), 0), n_truth - 2)
        frac = u - i
        e = carrier[j % period]
        e_next = carrier[(j + 1) % period]
        for a in range(n_axes):
            f0 = force_at_j[a]
            f1 = forcing[i, a] + frac * (forcing[i + 1, a] - forcing[i, a])
            s0 = static_at_j[a]
            s1 = static[i, a] + frac * (static[i + 1, a] - static[i, a])
            w0 = rng.standard_normal()
            w1 = rng.standard_normal()
            drive0 = e * (g0[0] * f0 + g1[0] * (f1 - f0))
            drive1 = e * (g0[1] * f0 + g1[1] * (f1 - f0))
            y = (
                phi[0, 0] * x[a, 0]
                + phi[0, 1] * x[a, 1]
                + drive0.real
                + dc0[0] * s0
                + dc1[0] * s1
                + noise[0, 0] * w0
                + noise[0, 1] * w1
            )
            v = (
                phi[1, 0] * x[a, 0]
                + phi[1, 1] * x[a, 1]
                + drive1.real
                + dc0[1] * s0
                + dc1[1] * s1
                + noise[1, 0] * w0
                + noise[1, 1] * w1
            )
            x[a, 0] = y
            x[a, 1] = v
            force_at_j[a] = f1
            static_at_j[a] = s1
            acc[a] += 2.0 * y * e_next.conjugate()  # pickoff times the two references (module notes)
        if (j + 1) % period == period - 1:
            for a in range(n_axes):
                cycles[count, a] = acc[a] / period
                acc[a] = 0j
            done[count] = j + 1
            count += 1
    return count


@njit
def _filter_run(
    phi: NDArray[np.complex128],
    gamma0: NDArray[np.complex128],
    gamma1: NDArray[np.complex128],
    c: NDArray[np.complex128],
    u: NDArray[np.complex128],
    s: NDArray[np.complex128],
    previous: NDArray[np.complex128],
    out: NDArray[np.complex128],
) -> None:
    """s_{k+1} = Φ s_k + Γ₀ u_{k−1} + Γ₁ u_k, out[k] = c·s_{k+1}, per axis; ``s`` (A, S) and
    ``previous`` (A,) (the input before u[0]) are updated in place. ``u``, ``out``: (K, A)."""
    n, n_axes = u.shape
    size = phi.shape[0]
    new = np.empty(size, np.complex128)
    for k in range(n):
        for a in range(n_axes):
            for i in range(size):
                acc = gamma0[i] * previous[a] + gamma1[i] * u[k, a]
                for j in range(size):
                    acc += phi[i, j] * s[a, j]
                new[i] = acc
            y = 0j
            for i in range(size):
                s[a, i] = new[i]
                y += c[i] * new[i]
            out[k, a] = y
            previous[a] = u[k, a]
