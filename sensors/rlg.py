"""Ring laser gyro (RLG): Sagnac beat of two counter-propagating laser modes, lock-in, body dither.

Model
-----
Rotation at Ω about the ring's normal splits the frequencies of the clockwise and counter-clockwise
modes of a ring laser of enclosed area A and perimeter P by the Sagnac beat (Aronowitz 1971)

    Δf = 4 A Ω / (λ P),

so the phase ψ of the beat between them advances by K = 2π·4A/(λP) = 8πA/(λP) radians per radian of
rotation. A detector counts the beat's fringes; each fringe (2π of ψ) is one output pulse of

    q = 2π / K = λ P / (4 A)                       (rad of rotation per pulse)

which quantises the indicated angle (2.26″ for the defaults: the ±1 count of every reading).

Lock-in. Light scattered back by the mirrors couples the two modes, and their phase difference obeys
Adler's equation (Adler 1946; Aronowitz 1971, §III):

    dψ/dt = K Ω − K Ω_L sin ψ                       (Ω_L: the lock-in rate, rad/s)

For |Ω| < Ω_L it has a stable fixed point, sin ψ* = Ω/Ω_L: the modes lock, no fringes pass and the
gyro reads zero (the dead band). Above it ψ slips, non-uniformly, at the mean rate

    <dψ/dt> = K √(Ω² − Ω_L²)                        (sign of Ω),

so the scale factor recovers only far from the dead band (by Ω_L²/(2Ω²)).

Mechanical dither. The block is rocked about the sensing axis, θ_d(t) = A(t) sin(2π f_d t), so the
input rate sweeps through the dead band twice per cycle at |dΩ/dt| ≈ Ω_d ω_d (Ω_d = A ω_d the peak
dither rate, ω_d = 2π f_d) and spends almost no time in it. Each pass still leaves a phase error:
near the turn-around the ideal phase is stationary, ψ ≈ ψ_c + ½ a (t − t_c)² with a = K Ω_d ω_d,
and the lock-in term integrates (stationary phase) to

    δψ = −K Ω_L ∫ sin ψ dt ≈ −K Ω_L √(2π/a) sin(ψ_c ± π/4).

If ψ_c is random from pass to pass these errors add as a random walk. Hence the dither amplitude is
randomised from cycle to cycle (log-normal, relative spread ``dither_amplitude_noise_fraction``;
A(t) goes linearly from one cycle's value to the next, as a resonant dither's envelope would):
that moves ψ_c by K·σ_A ≫ 2π between passes. Without it the kicks add coherently: averaged over
the dither, Adler's equation keeps its form with Ω_L replaced by Ω_L |J_n(Kθ₀)| around each rate
n f_d q (dynamic lock-in; n = 0 is a residual dead band, 1.8 % of Ω_L for the defaults). With the
random amplitude, 2 f_d passes per second and rms angle error
Ω_L √(π/a) per pass, the dither-induced angle random walk is (Killpatrick 1967; Aronowitz 1971)

    N = Ω_L / √(K Ω_d)                              (rad/√s; :meth:`RingLaserGyro.dither_random_walk`)

which is what :meth:`~RingLaserGyro.intrinsic_noise_density` reports (0 without dither). The
simulation does not use this formula: it integrates Adler's equation through every pass, and the
tests compare the two.

Dither removal. The output subtracts the dither pick-off (an ideal angle sensor between block and
case), as most strapdown RLGs do: indicated angle = q·(fringe count) − θ_d. The counts themselves
are available as ``raw["fringe_count"]``. (The other common scheme, reading the counter once per
dither cycle, gives the same angle at those instants but an output rate tied to f_d.)

Integrating Adler's equation
----------------------------
At the peak dither rate the beat runs at K Ω_d ≈ 1.5·10⁶ rad/s (a 240 kHz beat), far above a step
that 3 axes × hours can afford, but the lock-in term only acts where the phase is slow. Write
ψ = Φ + χ, with Φ = K θ_in the ideal Sagnac phase of the input angle (vehicle plus dither) and χ
the lock-in's deviation, which is slow (|dχ/dt| ≤ K Ω_L ≈ 560 s⁻¹):

    dχ/dt = −k Im(e^{iχ} E(t)),   E = e^{iΦ(t)},   k = K Ω_L.

Over a step [t_a, t_a + h], two Picard iterations give, to O((k h)³),

    Δχ = −k Im(e^{iψ_a} I) + (k²/2) Im(e^{2iψ_a} I²/2 − M),
    I = ∫₀ʰ e^{i(Φ−Φ_a)} ds,   M = ∫₀ʰ e^{i(Φ−Φ_a)} conj(I(s)) ds,   I(s) = ∫₀ˢ e^{i(Φ−Φ_a)}.

The second-order term carries the frequency pulling where the beat is fast (it reproduces
K√(Ω² − Ω_L²) ≈ KΩ − KΩ_L²/(2Ω)), the first the lock-in kicks at the turn-arounds. Within a step
Φ is the cubic Hermite through its values and rates at the step's ends (the vehicle's rate and the
dither's, exact at the nodes). I and M are oscillatory integrals of that known phase: on each
sub-interval the phase is replaced by its chord and integrated exactly (Filon's method: exact
whatever the phase advance, ~50 rad per 31 µs step at the peak dither rate), plus the first-order
correction for the chord's curvature. Steps close to a turn-around (phase rate within 10 √|Φ''| of
zero) are cut into sub-intervals with |Φ''| h_s² ≤ 0.5 rad. One numba kernel
(:func:`_adler_kernel`) does this in ~60 ns per step and axis (1.5 sub-intervals per step on average
with the default dither; the benchmark is ``tests/benchmarks/bench_optical.py``); against a brute-force
RK4 that resolves every fringe, χ agrees to ~10⁻⁴ rad (0.5 % of one turn-around's kick), and without
dither the dropped (kh)³/6 term of each step acts as a lock-in rate off by at most (kh)²/6 (5·10⁻⁵
at the default step; ``tests/sensors/test_rlg.py``). The step must resolve the dither (≥ 50 steps per
cycle) and the lock-in time 1/(KΩ_L) (k h ≤ 0.05): ``simulation_rate_hz`` is checked against both.

Defaults
--------
A navigation-grade RLG of the GG1320AN class (Honeywell; datasheet: ARW < 0.0035°/√h, bias stability
< 0.0035°/h, scale-factor stability < 5 ppm): an equilateral triangular He-Ne cavity of 0.10 m sides
(P = 0.30 m, A = 43.3 cm², λ = 632.8 nm: K = 5.73·10⁵, q = 2.26″), lock-in 200°/h, dither 437 Hz ×
200″ (peak dither rate 153°/s) randomised by 5 % per cycle. The dither random walk is then
0.0027°/√h, inside the 0.0035°/√h specification (the IMU adds the rest). The bias instability and
scale-factor terms are not the mechanism's: give them in the device's ``[gyro.errors]``. (The cavity
dimensions are representative, not Honeywell's.) The dither frequency is deliberately not a simple
fraction of common output rates: output samples in step with the dither (400 Hz at 1 kHz: every
fifth sample at the same dither phase) see correlated fringe-quantisation errors, a real effect but
not the white IEEE 952 quantisation term.

The three axes are three identical gyros, each dithered about its own axis by the same drive clock
(same frequency and phase) with independent random amplitudes. Temperature is not used.

Random draws (from the Generator passed in, in this order): at power-up the initial beat phase of
each axis (uniform) and the amplitudes of the first two dither cycles; then, chunk by chunk, the
amplitudes of each new dither cycle (cycle by cycle, axis by axis). Nothing else is random, so
chunking a run does not change it.

Sources: R. Adler, Proc. IRE 34, 351 (1946); J. E. Killpatrick, "The laser gyro", IEEE Spectrum 4(10),
44 (1967); F. Aronowitz, "The laser gyro", in Laser Applications vol. 1 (M. Ross, ed., Academic
Press, 1971), pp. 133–200; W. W. Chow et al., "The ring laser gyro", Rev. Mod. Phys. 57, 61 (1985);
L. N. G. Filon, Proc. R. Soc. Edinburgh 49, 38 (1928) for the oscillatory quadrature.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, ValidationInfo, field_validator

from gyroemu.dynamics.config import NonNegativeReal, PositiveReal, at_least, at_most
from gyroemu.dynamics.jit import njit

from .mechanism import GyroMechanism, GyroResponse, GyroTruth

__all__ = [
    "RingLaserGyro",
    "MAX_DITHER_FREQUENCY_HZ",
    "MAX_DITHER_AMPLITUDE_ARCSEC",
    "MAX_PERIMETER_M",
    "MAX_SIMULATION_RATE_HZ",
    "WAVELENGTH_RANGE_NM",
]

_ARCSEC = math.pi / (180 * 3600)  # rad per arcsecond
_DEG_PER_H = math.pi / 180 / 3600  # rad/s per °/h

#: Smallest number of integration steps per dither cycle (the cubic phase model within a step).
STEPS_PER_DITHER_CYCLE = 50
#: Largest lock-in phase rate K Ω_L times the step (the two-term Picard step is exact to O((kh)³)).
MAX_LOCK_IN_PER_STEP = 0.05
MAX_DITHER_FREQUENCY_HZ = 10_000.0
"""The highest ``dither_frequency_hz``, Hz: ten times the fastest body dither of real RLGs (300 Hz to
about 1 kHz: a dithered block on its springs is a mechanical resonator); the integrator takes at least
:data:`STEPS_PER_DITHER_CYCLE` steps a cycle, so this needs a ``simulation_rate_hz`` of 5·10⁵ Hz."""
MAX_DITHER_AMPLITUDE_ARCSEC = 3600.0
"""The largest ``dither_amplitude_arcsec``, arcsec (1°): about ten times the body dither of real RLGs (a
few arcminutes; 200″ here: the block rocks on a flexure, a small oscillation). With the fastest dither
(:data:`MAX_DITHER_FREQUENCY_HZ`) the peak dither rate is then 1100 rad/s and its beat 6·10⁸ rad/s for the
default cavity; a dither of 10³⁰⁰″ made the beat phase inf: all-NaN ``beat_phase_rad``, INT64_MIN fringe
counts."""
MAX_PERIMETER_M = 1000.0
"""The largest ``perimeter_m``, m: eight times the largest ring laser built (the geodetic UG-2 at
Christchurch, 21 m × 39.7 m, 121 m around); navigation RLGs are 0.1–0.5 m around. (The enclosed area is
at most P²/4π, which a perimeter of 10²⁰⁰ m took beyond float64's range.)"""
MAX_SIMULATION_RATE_HZ = 1_000_000.0
"""The highest ``simulation_rate_hz`` (the mechanism's inner rate), Hz: twice what the fastest dither
(:data:`MAX_DITHER_FREQUENCY_HZ`) needs, and 30 times the default, which resolves the dither and the
lock-in time of a navigation RLG; at about 60 ns a step and axis, 0.2 s of computing a simulated second
(a 10¹² Hz rate asked for 10¹² steps a second)."""
WAVELENGTH_RANGE_NM = (100.0, 10_000.0)
"""The shortest and longest laser ``wavelength_nm``, nm: ring laser gyros lase at He-Ne's 632.8 nm (a
few at 543 nm or 1.15 µm, the longest He-Ne line used 3.39 µm); the bounds leave a factor of three
beyond the extremes either way. A wavelength of 10³⁰⁰ nm made the beat phase per radian K vanish, and
the error blamed the ARW (the dither random walk Ω_L/√(K Ω_d) exceeded it); at 10⁻³⁰⁰ nm K overflowed
and ``simulation_rate_hz`` was asked for "at least inf Hz"."""
# A step is near a turn-around when its phase rate is within _NEAR·√|Φ''| of zero at either end (or
# changes sign); there it is cut into sub-intervals of phase curvature |Φ''| h_s² ≤ _CURVATURE rad.
_NEAR = 10.0
_CURVATURE = 0.5
# The kernels may fuse multiply-adds and multiply by reciprocals (15 % faster; ψ changes by ~10⁻⁹ rad),
# but not reassociate: the Cody–Waite reduction in _sincos relies on the order of its subtractions.
_FAST = {"contract", "arcp", "nsz"}


class RingLaserGyro(GyroMechanism):
    """A mechanically dithered ring laser gyro counting beat fringes (see the module notes).

    Keys: cavity ``perimeter_m`` and enclosed ``area_m2``, laser ``wavelength_nm``,
    ``lock_in_rate_deg_per_h``, body dither ``dither_frequency_hz`` × ``dither_amplitude_arcsec``
    (0: no dither) randomised per cycle by ``dither_amplitude_noise_fraction``, and the rate
    ``simulation_rate_hz`` at which Adler's equation is integrated (the IMU's inner rate).
    """

    kind: Literal["rlg"] = "rlg"
    reads: ClassVar[frozenset[str]] = frozenset()
    perimeter_m: Annotated[
        PositiveReal, at_most(MAX_PERIMETER_M, "eight times the largest ring laser built (121 m around)")
    ] = 0.30
    area_m2: PositiveReal = Field(
        default=0.25 * math.sqrt(3.0) * 0.10**2,  # triangle of 0.10 m sides
        validate_default=True,
    )
    wavelength_nm: Annotated[
        PositiveReal,
        at_least(WAVELENGTH_RANGE_NM[0], "a fifth of the shortest laser line of ring laser gyros (543 nm)"),
        at_most(WAVELENGTH_RANGE_NM[1], "three times the longest He-Ne line (3.39 µm)"),
    ] = 632.8
    lock_in_rate_deg_per_h: NonNegativeReal = 200.0
    dither_frequency_hz: Annotated[
        PositiveReal, at_most(MAX_DITHER_FREQUENCY_HZ, "ten times the fastest body dither of real RLGs (about 1 kHz)")
    ] = 437.0
    dither_amplitude_arcsec: Annotated[
        NonNegativeReal, at_most(MAX_DITHER_AMPLITUDE_ARCSEC, "1°, ten times the body dither of real RLGs")
    ] = 200.0
    dither_amplitude_noise_fraction: NonNegativeReal = Field(default=0.05, le=0.5)
    simulation_rate_hz: Annotated[
        PositiveReal,
        at_most(
            MAX_SIMULATION_RATE_HZ,
            "twice the 50 steps a cycle of a 10 kHz dither, twenty times what a real RLG's 1 kHz dither needs",
        ),
    ] = Field(default=32_000.0, validate_default=True)

    @field_validator("area_m2")
    @classmethod
    def _isoperimetric(cls, area: float, info: ValidationInfo) -> float:
        perimeter = info.data.get("perimeter_m")
        if perimeter is not None and area > perimeter**2 / (4 * math.pi) * (1 + 1e-12):
            raise ValueError(
                f"{area:g} m² is more than a ring of perimeter {perimeter:g} m can enclose "
                f"(at most P²/4π = {perimeter**2 / (4 * math.pi):.4g} m², a circle)"
            )
        return area

    @field_validator("simulation_rate_hz")
    @classmethod
    def _resolves_dither_and_lock_in(cls, rate: float, info: ValidationInfo) -> float:
        d = info.data
        if d.get("dither_amplitude_arcsec", 0.0) > 0 and "dither_frequency_hz" in d:
            needed = STEPS_PER_DITHER_CYCLE * d["dither_frequency_hz"]
            if rate < needed:
                raise ValueError(
                    f"{rate:g} Hz does not resolve the {d['dither_frequency_hz']:g} Hz dither: "
                    f"at least {needed:g} Hz ({STEPS_PER_DITHER_CYCLE} steps per cycle) is needed"
                )
        if all(key in d for key in ("perimeter_m", "area_m2", "wavelength_nm", "lock_in_rate_deg_per_h")):
            k_lock = (
                8
                * math.pi
                * d["area_m2"]
                / (d["wavelength_nm"] * 1e-9 * d["perimeter_m"])
                * d["lock_in_rate_deg_per_h"]
                * _DEG_PER_H
            )
            if rate < k_lock / MAX_LOCK_IN_PER_STEP:
                raise ValueError(
                    f"{rate:g} Hz does not resolve the lock-in time 1/(K Ω_L) = {1 / k_lock:.3g} s: "
                    f"at least {k_lock / MAX_LOCK_IN_PER_STEP:.4g} Hz is needed"
                )
        return rate

    # --- derived quantities (SI) -----------------------------------------------------------------

    @property
    def beat_phase_per_rad(self) -> float:
        """K = 8πA/(λP): beat phase, rad, per radian of rotation (2π × the Sagnac beat per rad/s)."""
        return 8 * math.pi * self.area_m2 / (self.wavelength_nm * 1e-9 * self.perimeter_m)

    @property
    def fringe_angle_rad(self) -> float:
        """q = λP/(4A): rotation angle of one fringe, i.e. of one output pulse, rad."""
        return 2 * math.pi / self.beat_phase_per_rad

    @property
    def lock_in_rate(self) -> float:
        """Ω_L, rad/s."""
        return self.lock_in_rate_deg_per_h * _DEG_PER_H

    @property
    def dither_amplitude(self) -> float:
        """Mean (median) dither angle amplitude, rad."""
        return self.dither_amplitude_arcsec * _ARCSEC

    @property
    def dither_rate_amplitude(self) -> float:
        """Ω_d = A ω_d: peak dither rate, rad/s."""
        return self.dither_amplitude * 2 * math.pi * self.dither_frequency_hz

    def dither_random_walk(self) -> float:
        """The dither-induced angle random walk N = Ω_L/√(K Ω_d), rad/√s (0 without dither or lock-in).

        From the stationary-phase kick at each of the 2 f_d turn-arounds per second (module notes).
        """
        if self.dither_rate_amplitude == 0:
            return 0.0
        return self.lock_in_rate / math.sqrt(self.beat_phase_per_rad * self.dither_rate_amplitude)

    # --- the mechanism contract --------------------------------------------------------------------

    def inner_rate_hz(self, output_rate_hz: float) -> float:
        return max(self.simulation_rate_hz, float(output_rate_hz))

    def intrinsic_noise_density(self) -> float:
        return self.dither_random_walk()

    def output_angle_quantum(self) -> float:
        """q, rad: the output counts whole fringes (module notes, "Dither removal")."""
        return self.fringe_angle_rad

    def respond(self, truth: GyroTruth, rng: np.random.Generator, state: dict[str, Any] | None = None) -> GyroResponse:
        """Fringe-counted angle (dither removed) on the inner grid, with the beat's raw observables.

        raw: ``fringe_count`` (M, 3) int64 since power-up, ``beat_phase_rad`` (M, 3) ψ since power-up,
        ``dither_angle_rad`` (M, 3) the dither pick-off θ_d.
        """
        state = {} if state is None else state
        h = float(truth.dt)
        if h > 1.05 / self.simulation_rate_hz:
            raise ValueError(
                f"inner step {h:g} s is coarser than 1/simulation_rate_hz = "
                f"{1 / self.simulation_rate_hz:g} s: give the RLG its inner rate"
            )
        K = self.beat_phase_per_rad
        if "beat_phase_rad" not in state:  # power-up: the beat starts at an arbitrary phase
            state["t_power_up"] = float(truth.t[0])
            state["beat_phase_rad"] = 2 * math.pi * rng.random(3)
            state["dither_cycle"] = 0
            state["dither_amplitude_rad"] = self._cycle_amplitudes(rng, 2)  # cycles 0 and 1

        dither, dither_rate = self._dither(truth.t, rng, state)
        psi = np.empty_like(dither)
        _adler_kernel(
            truth.omega,
            truth.alpha,
            dither,
            dither_rate,
            h,
            K,
            K * self.lock_in_rate,
            np.asarray(state["beat_phase_rad"], dtype=float),
            psi,
        )
        state["beat_phase_rad"] = psi[-1].copy()

        count = np.floor(psi / (2 * math.pi)).astype(np.int64)
        angle = self.fringe_angle_rad * (count - count[0]) - (dither - dither[0])
        return GyroResponse(angle=angle, raw={"fringe_count": count, "beat_phase_rad": psi, "dither_angle_rad": dither})

    # --- dither ------------------------------------------------------------------------------------

    def _cycle_amplitudes(self, rng: np.random.Generator, cycles: int) -> NDArray[np.float64]:
        """(cycles, 3) dither amplitudes, rad: log-normal about the mean amplitude (no draw if fixed)."""
        spread = self.dither_amplitude_noise_fraction
        if self.dither_amplitude == 0 or spread == 0:
            return np.full((cycles, 3), self.dither_amplitude)
        return self.dither_amplitude * np.exp(spread * rng.standard_normal((cycles, 3)))

    def _dither(
        self, t: NDArray[np.float64], rng: np.random.Generator, state: dict[str, Any]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Dither angle θ_d and rate (M, 3) at times ``t``; draws the amplitudes of new cycles.

        With u = f_d (t − t_power_up), θ_d = A(u) sin 2πu, the amplitude going linearly from A_n to
        A_{n+1} over cycle n = ⌊u⌋ (a resonant dither's amplitude cannot jump): angle and rate are
        continuous. ``state`` holds the cycle of the last node and the amplitudes of it and the next.
        """
        if self.dither_amplitude == 0:
            return np.zeros((len(t), 3)), np.zeros((len(t), 3))
        elapsed = np.ascontiguousarray(t - state["t_power_up"], dtype=float)
        known, last = state["dither_cycle"], int(np.floor(self.dither_frequency_hz * elapsed[-1]))
        if np.floor(self.dither_frequency_hz * elapsed[0]) < known:
            raise ValueError("a chunk must start where the previous one ended (times went backwards)")
        table = np.vstack(
            [
                state["dither_amplitude_rad"],  # amplitudes of cycles known … last + 1
                self._cycle_amplitudes(rng, last - known),
            ]
        )
        angle, rate = np.empty((len(t), 3)), np.empty((len(t), 3))
        _dither_nodes(elapsed, self.dither_frequency_hz, table, known, angle, rate)
        state["dither_cycle"] = last
        state["dither_amplitude_rad"] = table[-2:].copy()
        return angle, rate


# --------------------------------------------------------------------------------------------------
# Adler's equation, step by step (module notes, "Integrating Adler's equation")
# --------------------------------------------------------------------------------------------------


@njit(error_model="numpy", fastmath=_FAST)
def _adler_kernel(
    omega: NDArray[np.float64],
    alpha: NDArray[np.float64],
    dither: NDArray[np.float64],
    dither_rate: NDArray[np.float64],
    h: float,
    K: float,
    k_lock: float,
    psi0: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Integrate dψ/dt = K (ω + dθ_d/dt) − k sin ψ over the nodes of a uniform grid (all axes at once).

    omega, alpha : (M, A) vehicle rate, rad/s, and its derivative, rad/s².
    dither, dither_rate : (M, A) dither angle θ_d, rad, and rate, rad/s.
    h : step, s.   K : beat phase per rad.   k_lock : k = K Ω_L, rad/s.
    psi0 : (A,) ψ at the first node.   out : (M, A) ψ at every node (written).

    The ideal phase Φ gains over a step K × (the exact integral of the vehicle's cubic Hermite rate
    + the dither's angle change); its rate at the nodes is K (ω + dθ_d/dt). e^{iψ} is carried along
    as a phasor (e^{iψ_b} = e^{iψ_a} e^{iΔΦ} e^{iΔχ}, with e^{iΔΦ} from the last sub-interval), so a
    step where the phase is fast costs one sine-cosine pair.
    """
    n_nodes, n_axes = omega.shape
    psi = psi0.copy()
    e = np.empty(n_axes, dtype=np.complex128)  # e^{iψ} of each axis
    for a in range(n_axes):
        s, c = _sincos(psi[a])
        e[a] = complex(c, s)
        out[0, a] = psi[a]
    for j in range(n_nodes - 1):
        for a in range(n_axes):
            vehicle = 0.5 * h * (omega[j, a] + omega[j + 1, a]) + (h * h / 12.0) * (alpha[j, a] - alpha[j + 1, a])
            gain = K * (vehicle + dither[j + 1, a] - dither[j, a])
            rate0 = K * (omega[j, a] + dither_rate[j, a])
            rate1 = K * (omega[j + 1, a] + dither_rate[j + 1, a])
            big_i, big_m, e_gain = _step_integrals(gain, rate0, rate1, h)
            ei = e[a] * big_i
            d_chi = -k_lock * ei.imag + 0.5 * k_lock * k_lock * (0.5 * (ei * ei).imag - big_m.imag)
            psi[a] += gain + d_chi
            out[j + 1, a] = psi[a]
            d2 = d_chi * d_chi  # e^{iΔχ} by its Taylor series (|Δχ| ≤ k h ≤ 0.05: error < 10⁻¹⁰)
            ea = e[a] * e_gain * complex(1.0 - d2 / 2.0 + d2 * d2 / 24.0, d_chi * (1.0 - d2 / 6.0 + d2 * d2 / 120.0))
            e[a] = ea * (1.5 - 0.5 * (ea.real * ea.real + ea.imag * ea.imag))  # keep |e| = 1 against round-off


@njit(error_model="numpy", fastmath=_FAST)
def _step_integrals(gain: float, rate0: float, rate1: float, h: float) -> tuple[complex, complex, complex]:
    """I = ∫₀ʰ e^{iφ(s)} ds, M = ∫₀ʰ e^{iφ(s)} conj(I(s)) ds and e^{iφ(h)} for the cubic Hermite phase
    φ with φ(0) = 0, φ(h) = ``gain``, φ'(0) = ``rate0``, φ'(h) = ``rate1``.

    Chord-wise Filon quadrature with a first-order curvature correction, on one sub-interval, or on
    several where the phase is near stationary (see the module notes).
    """
    inv_h = 1.0 / h
    c2 = (3.0 * gain * inv_h - 2.0 * rate0 - rate1) * inv_h  # φ(s) = rate0 s + c2 s² + c3 s³
    c3 = (rate0 + rate1 - 2.0 * gain * inv_h) * inv_h * inv_h
    curvature = max(abs(2.0 * c2), abs(2.0 * c2 + 6.0 * c3 * h))
    slowest = min(abs(rate0), abs(rate1))
    n = 1
    near = rate0 * rate1 <= 0.0 or slowest * slowest < _NEAR * _NEAR * curvature
    if near and curvature * h * h > _CURVATURE:
        n = int(math.ceil(h * math.sqrt(curvature / _CURVATURE)))
    if n == 1:  # the usual case: one chord over the whole step
        s, c = _sincos(gain)
        e_gain = complex(c, s)
        f, g, self_term = _filon_weights(e_gain, gain)
        bend = c2 + 3.0 * c3 * h  # φ'' at the middle, halved
        return h * (f - 1j * bend * h * h * g), h * h * self_term, e_gain

    hs = h / n
    big_i = 0j
    big_m = 0j
    phase0 = 0.0
    e0 = 1.0 + 0j
    for i in range(n):
        phase1 = gain
        if i < n - 1:
            s1 = (i + 1) * hs
            phase1 = s1 * (rate0 + s1 * (c2 + s1 * c3))
        s, c = _sincos(phase1)
        e1 = complex(c, s)
        x = phase1 - phase0  # the chord's phase advance
        f, g, self_term = _filon_weights(e1 * e0.conjugate(), x)
        bend = 2.0 * c2 + 6.0 * c3 * (i + 0.5) * hs  # φ'' at the sub-interval's middle
        # φ = chord − ½ φ'' u (h_s − u): e^{iφ} ≈ e^{i chord} (1 − ½ i φ'' u (h_s − u))
        piece = hs * e0 * (f - 0.5j * bend * hs * hs * g)
        big_m += piece * big_i.conjugate() + hs * hs * self_term
        big_i += piece
        phase0 = phase1
        e0 = e1
    return big_i, big_m, e0


@njit(error_model="numpy", fastmath=_FAST)
def _filon_weights(ex: complex, x: float) -> tuple[complex, complex, complex]:
    """Weights of a sub-interval whose phase advances linearly by ``x`` (``ex`` = e^{ix}), per unit
    length (u = s/h_s ∈ [0, 1]):

    f = ∫ e^{ixu} du = (e^{ix} − 1)/(ix),
    g = ∫ u(1 − u) e^{ixu} du = −(e^{ix} + 1)/x² − 2i(e^{ix} − 1)/x³,
    m = ∫ e^{ixu} conj(∫₀ᵘ e^{ixv} dv) du = [(1 − cos x) + i(x − sin x)]/x²,

    by their Taylor series where the closed forms cancel (|x| < 0.05; truncation < 10⁻⁹).
    """
    if abs(x) < 0.05:
        x2 = x * x
        f = complex(1.0 - x2 / 6.0 + x2 * x2 / 120.0, x / 2.0 - x * x2 / 24.0)
        g = complex(1.0 / 6.0 - x2 / 40.0 + x2 * x2 / 1008.0, x / 12.0 - x * x2 / 180.0)
        m = complex(0.5 - x2 / 24.0 + x2 * x2 / 720.0, x / 6.0 - x * x2 / 120.0 + x * x2 * x2 / 5040.0)
        return f, g, m
    r = 1.0 / x
    r2 = r * r
    f = (ex - 1.0) * complex(0.0, -r)
    g = -(ex + 1.0) * r2 - (ex - 1.0) * complex(0.0, 2.0 * r2 * r)
    m = complex(1.0 - ex.real, x - ex.imag) * r2
    return f, g, m


@njit(error_model="numpy")
def _dither_nodes(
    elapsed: NDArray[np.float64],
    frequency_hz: float,
    table: NDArray[np.float64],
    first_cycle: int,
    angle: NDArray[np.float64],
    rate: NDArray[np.float64],
) -> None:
    """Dither angle θ_d = A(u) sin 2πu and rate dθ_d/dt at u = f_d × ``elapsed`` (M,), written to
    ``angle``, ``rate`` (M, 3). A(u) = A_n + (A_{n+1} − A_n)(u − n), n = ⌊u⌋, with A_n = ``table[n −
    first_cycle]`` (a row of 3 amplitudes per cycle)."""
    for j in range(elapsed.shape[0]):
        u = frequency_hz * elapsed[j]
        n = math.floor(u)
        s, c = _sincos(2.0 * math.pi * (u - n))
        row = int(n) - first_cycle
        for a in range(angle.shape[1]):
            slope = table[row + 1, a] - table[row, a]  # dA/du
            amplitude = table[row, a] + slope * (u - n)
            angle[j, a] = amplitude * s
            rate[j, a] = frequency_hz * (slope * s + 2.0 * math.pi * amplitude * c)


# Cody–Waite split of π/2 (fdlibm): PIO2_1 has 33 significant bits, so k·PIO2_1 is exact for |k| < 2²⁰.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624879595063154e-21


@njit(error_model="numpy", inline="always")
def _sincos(x: float) -> tuple[float, float]:
    """(sin x, cos x), three times faster than two libm calls here (the kernel's main cost).

    x = k π/2 + r with |r| ≤ π/4 (Cody–Waite reduction), then the Taylor series of sin r and cos r to
    r¹⁵ and r¹⁶ (truncation < 10⁻¹⁶); the quadrant k mod 4 swaps and signs them. Error ≤ 2.2·10⁻¹⁶
    for |x| < 10⁶, growing as ε|x| beyond (6·10⁻⁸ at 10⁹, below the rounding of x itself).
    """
    k = math.floor(x * (2.0 / math.pi) + 0.5)
    r = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_3
    r2 = r * r
    s = r * (
        1.0
        + r2
        * (
            -1.0 / 6
            + r2
            * (
                1.0 / 120
                + r2
                * (
                    -1.0 / 5040
                    + r2
                    * (1.0 / 362880 + r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800 + r2 * (-1.0 / 1307674368000))))
                )
            )
        )
    )
    c = 1.0 + r2 * (
        -0.5
        + r2
        * (
            1.0 / 24
            + r2
            * (
                -1.0 / 720
                + r2
                * (
                    1.0 / 40320
                    + r2
                    * (
                        -1.0 / 3628800
                        + r2 * (1.0 / 479001600 + r2 * (-1.0 / 87178291200 + r2 * (1.0 / 20922789888000)))
                    )
                )
            )
        )
    )
    quadrant = int(k) & 3
    if quadrant == 0:
        return s, c
    if quadrant == 1:
        return c, -s
    if quadrant == 2:
        return -s, -c
    return -c, s
