"""Interferometric fibre-optic gyro (I-FOG): Sagnac phase, sinusoidal biasing modulation, open or
closed loop, and the photodetector noise that sets its angle random walk.

Model
-----
Light from a broadband source is split into two waves that run in opposite directions around a coil
of fibre of length L wound on a diameter D. Rotation at Ω about the coil's axis delays one against
the other by the Sagnac phase difference (Lefèvre 2014)

    Δφ = S Ω,      S = 2π L D / (λ c)                  (rad per rad/s: the Sagnac scale factor)

with λ the source's mean wavelength in vacuum (the fibre's index drops out). The waves recombine on
the detector as P = (P₀/2)(1 + cos Δφ), P₀ the power returning at zero phase difference.

Biasing modulation. Near Δφ = 0 the cosine is flat, so a phase modulator at one end of the coil is
driven at the coil's proper frequency f_p = 1/(2τ), τ = n_g L/c the transit time: each wave meets
the modulation half a period apart, and the phase difference is modulated as φ_b cos ω_m t with
φ_b = 2 φ_m (``modulation_depth_rad`` is φ_b). In Bessel functions J_k = J_k(φ_b),

    P(t) = (P₀/2) [1 + cos Δφ (J₀ − 2J₂ cos 2ω_m t + …) − sin Δφ (2J₁ cos ω_m t − 2J₃ cos 3ω_m t + …)],

and a demodulator that integrates i(t)·2cos ω_m t (i = R P the photocurrent, R the responsivity)
over each interval reads the first harmonic, R P₀ J₁ sin Δφ.

* Open loop (``loop = "open"``): the indicated rate is sin(Δφ)/S with the linearised scale factor
  (``open_loop_readout = "linear"``): it reads low by (SΩ)²/6 and folds over beyond |Δφ| = π/2.
  ``"arcsin"`` reads arcsin(·)/S instead: exact for |Δφ| < π/2, its noise amplified by 1/cos Δφ.
  With the defaults S = 0.176 s: 1 % low at 1.4 rad/s (80°/s), π/2 reached at 8.9 rad/s (512°/s).
* Closed loop (``loop = "closed"``, the default, as in navigation FOGs): a serrodyne (digital phase
  ramp) modulator adds a feedback phase difference φ_f, the ramp's step per transit time, which the
  loop servoes until the demodulated signal vanishes: φ_f = −Δφ. The output −φ_f/S = Ω is linear at
  any rate while |φ_f| ≤ ``feedback_range_rad`` (at most π: steps of φ and φ − 2π are the same to
  the light); beyond it the step saturates and the output stays at the range. The loop is taken as
  fast against the inner step (real loops close at ~10 kHz: band-limit the output with the error
  layer's ``bandwidth_hz`` where that matters).

Noise (the angle random walk)
-----------------------------
Two noises ride on the photocurrent (Lefèvre ch. 6–7):

* shot noise: white, single-sided density 2 e i(t) (e the electron charge);
* the source's excess relative intensity noise r = δP/P: a broadband source's spontaneous-emission
  beats, white up to ~Δν with single-sided density RIN = 1/Δν, where Δν = c Δλ/λ² is the spectral
  width ``spectral_width_nm`` = Δλ in frequency.

Over an interval T the demodulated output (2/T) ∫ i(t) cos ω_m t dt has, by Campbell's theorem, the
shot-noise variance (4e/T)⟨i(t) cos²ω_m t⟩; the RIN enters through every harmonic of
i(t) cos ω_m t (r at k ω_m is mixed down by the k-th harmonic of the modulated power, the DC term
with twice the weight). Working the Bessel series through, the demodulated output, in units of
sin Δφ (i.e. divided by R P₀ J₁), has variance σ²/T with

    σ² = [ (e / (R P₀)) (1 + u₀ cos Δφ)                                         shot noise
         + (RIN / 4) ((1 + u₀ cos Δφ)² + U cos²Δφ + V sin²Δφ) ] / J₁²           excess RIN

    u₀ = J₀ − J₂,   U = Σ_{m≥1} (J_{2m} − J_{2m+2})²,   V = 2J₁² + Σ_{n≥1} (J_{2n+1} − J_{2n−1})².

σ is the phase noise in rad/√Hz in this project's convention: the standard deviation of a 1 s
average, i.e. the Allan deviation at 1 s (``sensors/noise.py``). For an ideal square-wave bias at
±π/2 the same calculation gives √(2e/(R P₀)) = √(2hν/(η P₀)) (the photon-noise limit) and √(RIN/2).
The ``tests`` check the formula against a photon-by-photon simulation of the detector.

The angle random walk is N = σ(Δφ = 0)/S (a closed loop always works at Δφ = 0, an open loop at
rest): :meth:`FiberOpticGyro.intrinsic_noise_density`. For each inner step, ``respond`` takes the
step's mean of sin Δφ (exact for the cubic Hermite of sin SΩ through the nodes) and adds σ(Δφ)/√h
times a standard normal draw: the demodulator's integrate-and-dump output; the indicated angle is
the running sum of the readout times h (``GyroResponse.angle``), so the increments carry exactly the
noise above.

Not modelled: the loop's dynamics, the scale factor's drift with the source's wavelength, the
Shupe (thermal transient) and Kerr biases, polarisation non-reciprocity, detector amplifier noise:
the device's ``[gyro.errors]`` carries bias and scale-factor terms. Temperature is not used.

Defaults
--------
A compact navigation FOG in the class of the KVH DSP-1760 (datasheet ARW ≤ 0.012°/√h): 200 m of
fibre on a 65 mm coil, a 1550 nm source 30 nm wide (RIN = 2.7·10⁻¹³ /Hz), 20 µW back on an InGaAs
detector of 0.9 A/W, biased at φ_b = 1.8 rad, closed loop (range ±π: ±1024°/s). S = 0.176 s,
f_p = 511 kHz; phase noise 4.8·10⁻⁷ rad/√Hz from RIN and 1.6·10⁻⁷ from shot noise (5.0·10⁻⁷ in all),
so N = 2.87·10⁻⁶ rad/√s = 0.0099°/√h: RIN limited, as real navigation FOGs are, and just inside the
specification (the IMU adds the rest). φ_b = 1.8 rad maximises the signal J₁; over-modulating
(φ_b ≈ 2.6 rad) would lower both noises by leaving less power on the detector. The coil and source
are representative values, not KVH's design.

Random draws (from the Generator passed in): one standard normal per inner step and axis, in step
order, and nothing else, so chunking a run does not change it.

Sources: H. C. Lefèvre, "The Fiber-Optic Gyroscope", 2nd ed., Artech House, 2014 (the Sagnac effect,
proper-frequency biasing, closed-loop serrodyne and digital phase ramp; ch. 6–7 on the noise limits);
W. K. Burns (ed.), "Optical Fiber Rotation Sensing", Academic Press, 1994.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal, overload

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, ValidationInfo, field_validator

from gyroemu.dynamics.config import PositiveReal, at_least, at_most

from .mechanism import GyroMechanism, GyroResponse, GyroTruth

__all__ = [
    "FiberOpticGyro",
    "SPEED_OF_LIGHT",
    "ELEMENTARY_CHARGE",
    "COIL_LENGTH_RANGE_M",
    "COIL_DIAMETER_RANGE_M",
    "WAVELENGTH_RANGE_NM",
    "MIN_MODULATION_DEPTH_RAD",
]

SPEED_OF_LIGHT = 299_792_458.0  # m/s
ELEMENTARY_CHARGE = 1.602_176_634e-19  # C
PLANCK = 6.626_070_15e-34  # J s
#: Group index of silica fibre near 1.3–1.55 µm; only used for the transit time and proper frequency.
FIBRE_GROUP_INDEX = 1.468
#: First zero of J₁: the first-harmonic signal vanishes there, so the bias depth must stay below it.
J1_FIRST_ZERO = 3.831705970207512
COIL_LENGTH_RANGE_M = (1.0, 100_000.0)
"""The shortest and longest ``coil_length_m``, m. Real coils run from about 50 m (small tactical FOGs) to
about 5 km (strategic-grade and seismic rotation sensors): the bounds leave a factor of 20 or more either
way. The scale factor S and the noise σ/S follow the length: a coil of 10³⁰⁰ m (or 10⁻³⁰⁰ m) overflowed."""
COIL_DIAMETER_RANGE_M = (0.001, 10.0)
"""The smallest and largest ``coil_diameter_m``, m: a tenth of the tightest coils fibre survives (about
10 mm: bend loss and breakage), thirty times the largest navigation coils (about 0.3 m)."""
WAVELENGTH_RANGE_NM = (100.0, 10_000.0)
"""The shortest and longest source ``wavelength_nm``, nm: FOG sources are at 830, 1310 or 1550 nm, and
silica fibre guides light only from about 400 nm to 2 µm; the bounds leave four times that either way.
A wavelength of 10³⁰⁰ nm overflowed the RIN λ²/(c Δλ) (an OverflowError)."""
MIN_MODULATION_DEPTH_RAD = 0.1
"""The lightest bias ``modulation_depth_rad``, rad: its first-harmonic signal J₁(0.1) = 0.05 is a
twelfth of the peak J₁(1.84) = 0.58 at which real FOGs bias (1.8 rad here); at 10⁻³⁰⁰ rad the signal
vanished and the noise σ/J₁ overflowed."""
# Harmonics kept in the RIN sums (J_k(φ_b) for k > 40 is below 10⁻³⁰ for φ_b < J1_FIRST_ZERO).
_HARMONICS = 40


class FiberOpticGyro(GyroMechanism):
    """An interferometric fibre-optic gyro, open or closed loop (see the module notes).

    Keys: coil ``coil_length_m`` × ``coil_diameter_m``; source ``wavelength_nm`` and
    ``spectral_width_nm``; ``detector_power_uw`` (P₀, returning at zero phase difference) on a
    detector of ``responsivity_a_per_w``; bias ``modulation_depth_rad`` (φ_b); ``loop``; for an open
    loop ``open_loop_readout``, for a closed loop ``feedback_range_rad``.
    """

    kind: Literal["fog"] = "fog"
    reads: ClassVar[frozenset[str]] = frozenset()
    coil_length_m: Annotated[
        PositiveReal,
        at_least(COIL_LENGTH_RANGE_M[0], "a fiftieth of the shortest coils of real FOGs (about 50 m)"),
        at_most(COIL_LENGTH_RANGE_M[1], "twenty times the longest coils of real FOGs (about 5 km)"),
    ] = 200.0
    coil_diameter_m: Annotated[
        PositiveReal,
        at_least(COIL_DIAMETER_RANGE_M[0], "a tenth of the tightest coil fibre survives (about 10 mm)"),
        at_most(COIL_DIAMETER_RANGE_M[1], "thirty times the largest coils of navigation FOGs (about 0.3 m)"),
    ] = 0.065
    wavelength_nm: Annotated[
        PositiveReal,
        at_least(WAVELENGTH_RANGE_NM[0], "a quarter of the shortest light silica fibre guides (about 400 nm)"),
        at_most(WAVELENGTH_RANGE_NM[1], "five times the longest light silica fibre guides (about 2 µm)"),
    ] = 1550.0
    spectral_width_nm: PositiveReal = Field(default=30.0, validate_default=True)
    detector_power_uw: PositiveReal = 20.0
    responsivity_a_per_w: PositiveReal = Field(default=0.9, validate_default=True)
    modulation_depth_rad: Annotated[
        PositiveReal,
        at_least(MIN_MODULATION_DEPTH_RAD, "its signal J₁ would be under a twelfth of the peak real FOGs bias at"),
    ] = 1.8
    loop: Literal["closed", "open"] = "closed"
    open_loop_readout: Literal["linear", "arcsin"] = "linear"
    feedback_range_rad: PositiveReal = math.pi

    @field_validator("spectral_width_nm")
    @classmethod
    def _narrower_than_wavelength(cls, width: float, info: ValidationInfo) -> float:
        wavelength = info.data.get("wavelength_nm")
        if wavelength is not None and width >= wavelength:
            raise ValueError(f"{width:g} nm is not narrower than the wavelength {wavelength:g} nm")
        return width

    @field_validator("responsivity_a_per_w")
    @classmethod
    def _quantum_efficiency_at_most_one(cls, responsivity: float, info: ValidationInfo) -> float:
        wavelength = info.data.get("wavelength_nm")
        if wavelength is not None:
            ideal = ELEMENTARY_CHARGE * wavelength * 1e-9 / (PLANCK * SPEED_OF_LIGHT)  # η = 1
            if responsivity > ideal:
                raise ValueError(
                    f"{responsivity:g} A/W exceeds e λ/(h c) = {ideal:.4g} A/W at {wavelength:g} nm "
                    "(a quantum efficiency above 1)"
                )
        return responsivity

    @field_validator("modulation_depth_rad")
    @classmethod
    def _below_first_zero_of_j1(cls, depth: float) -> float:
        if depth >= J1_FIRST_ZERO:
            raise ValueError(
                f"{depth:g} rad is not below {J1_FIRST_ZERO:.4f} rad, the first zero of J₁ "
                "(where the first-harmonic signal vanishes)"
            )
        return depth

    @field_validator("feedback_range_rad")
    @classmethod
    def _at_most_pi(cls, value: float) -> float:
        if value > math.pi:
            raise ValueError(f"{value:g} rad exceeds π: ramp steps of φ and φ − 2π are the same to the light")
        return value

    # --- derived quantities (SI) -------------------------------------------------------------------

    @property
    def scale_factor_s(self) -> float:
        """S = 2π L D/(λ c): Sagnac phase difference per unit rate, rad per rad/s (= s)."""
        return 2 * math.pi * self.coil_length_m * self.coil_diameter_m / (self.wavelength_nm * 1e-9 * SPEED_OF_LIGHT)

    @property
    def transit_time_s(self) -> float:
        """τ = n_g L/c: time of flight through the coil, s."""
        return FIBRE_GROUP_INDEX * self.coil_length_m / SPEED_OF_LIGHT

    @property
    def proper_frequency_hz(self) -> float:
        """f_p = 1/(2τ): the biasing modulation's frequency, Hz."""
        return 0.5 / self.transit_time_s

    @property
    def relative_intensity_noise_per_hz(self) -> float:
        """RIN = 1/Δν, Δν = c Δλ/λ²: the source's excess intensity noise, single-sided, 1/Hz."""
        wavelength = self.wavelength_nm * 1e-9
        return wavelength**2 / (SPEED_OF_LIGHT * self.spectral_width_nm * 1e-9)

    @overload
    def phase_noise(self, sagnac_phase: float = 0.0, terms: Literal["total", "shot", "rin"] = "total") -> float: ...

    @overload
    def phase_noise(
        self, sagnac_phase: NDArray[np.float64], terms: Literal["total", "shot", "rin"] = "total"
    ) -> NDArray[np.float64]: ...

    def phase_noise(
        self, sagnac_phase: float | NDArray[np.float64] = 0.0, terms: Literal["total", "shot", "rin"] = "total"
    ) -> float | NDArray[np.float64]:
        """σ(Δφ): noise of the demodulated output in units of sin Δφ (= phase noise at Δφ = 0),
        rad/√Hz as the standard deviation of a 1 s average (module notes). Array in, array out.

        ``terms``: both noises, or only the shot noise or only the excess RIN.
        """
        from scipy.special import jv  # scipy where it is used: the CLI's listings skip it

        phi_b = self.modulation_depth_rad
        j = jv(np.arange(2 * _HARMONICS + 2), phi_b)  # J_0 … J_{2H+1}
        u0 = j[0] - j[2]
        u = np.sum((j[2:-2:2] - j[4::2]) ** 2)  # Σ_{m≥1} (J_{2m} − J_{2m+2})²
        v = 2 * j[1] ** 2 + np.sum((j[3:-1:2] - j[1:-3:2]) ** 2)  # 2J₁² + Σ_{n≥1} (J_{2n+1} − J_{2n−1})²
        c, s = np.cos(sagnac_phase), np.sin(sagnac_phase)
        first = 1 + u0 * c  # weight of the fundamental in i(t)·cos ω_m t
        shot = ELEMENTARY_CHARGE / (self.responsivity_a_per_w * self.detector_power_uw * 1e-6) * first
        rin = 0.25 * self.relative_intensity_noise_per_hz * (first**2 + u * c**2 + v * s**2)
        density: float | NDArray[np.float64]  # of sagnac_phase's shape (numpy's ufuncs are typed Any)
        if terms == "shot":
            density = np.sqrt(shot) / j[1]
            return density
        if terms == "rin":
            density = np.sqrt(rin) / j[1]
            return density
        density = np.sqrt(shot + rin) / j[1]
        return density

    # --- the mechanism contract --------------------------------------------------------------------

    def max_rate(self) -> float:
        """Closed loop: the feedback range over the Sagnac scale factor. Open loop: the first extremum
        of ``sin Δφ`` (Δφ = π/2), beyond which the reading folds back."""
        limit = self.feedback_range_rad if self.loop == "closed" else np.pi / 2
        return limit / self.scale_factor_s

    def intrinsic_noise_density(self) -> float:
        """N = σ(0)/S, rad/s/√Hz: the angle random walk from shot noise and excess RIN."""
        return float(self.phase_noise(0.0)) / self.scale_factor_s

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Indicated angle (M, 3) from the demodulated Sagnac phase of each inner step.

        raw: ``sagnac_phase_rad`` Δφ = SΩ at the nodes; ``detector_power_w``, the mean power on the
        detector (P₀/2)(1 + J₀ cos Δφ_r) with Δφ_r the phase left unnulled (Δφ open loop, what the
        saturated ramp misses closed loop); closed loop also ``feedback_phase_rad``, the ramp step φ_f
        of the step ending at each node (at the first node: the previous chunk's last, or −Δφ at
        power-up).
        """
        state = {} if state is None else state
        h, S = float(truth.dt), self.scale_factor_s
        omega, alpha = truth.omega, truth.alpha
        phase = S * omega  # Sagnac phase difference at the nodes, (M, 3)
        noise = rng.standard_normal((len(phase) - 1, 3))  # one draw per step and axis, in step order

        if self.loop == "open":
            # Mean of sin Δφ over each step: the corrected trapezoid rule on sin Δφ and its slope.
            y, dy = np.sin(phase), np.cos(phase) * S * alpha
            read = 0.5 * (y[1:] + y[:-1]) + (h / 12.0) * (dy[:-1] - dy[1:])
            read += self.phase_noise(0.5 * (phase[1:] + phase[:-1])) / math.sqrt(h) * noise
            if self.open_loop_readout == "arcsin":
                read = np.arcsin(np.clip(read, -1.0, 1.0))
            rate = read / S
            residual = phase
            raw: dict[str, NDArray[np.float64]] = {}
        else:
            # Mean of Δφ over each step (exact for the cubic Hermite of Ω), nulled by the ramp step.
            mean_phase = 0.5 * (phase[1:] + phase[:-1]) + (h * S / 12.0) * (alpha[:-1] - alpha[1:])
            feedback = np.clip(
                -(mean_phase + float(self.phase_noise(0.0)) / math.sqrt(h) * noise),
                -self.feedback_range_rad,
                self.feedback_range_rad,
            )
            rate = -feedback / S
            first = state.get(
                "feedback_phase_rad", np.clip(-phase[0], -self.feedback_range_rad, self.feedback_range_rad)
            )
            state["feedback_phase_rad"] = feedback[-1].copy()
            residual = phase - np.clip(phase, -self.feedback_range_rad, self.feedback_range_rad)
            raw = {"feedback_phase_rad": np.vstack([first[None, :], feedback])}

        angle = np.zeros_like(phase)
        np.cumsum(rate * h, axis=0, out=angle[1:])
        from scipy.special import jv

        power = 0.5e-6 * self.detector_power_uw * (1 + jv(0, self.modulation_depth_rad) * np.cos(residual))
        return GyroResponse(angle=angle, raw={"sagnac_phase_rad": phase, **raw, "detector_power_w": power})
