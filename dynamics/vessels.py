"""Vessels that carry gyroscopes: a ship rolling in beam seas (with an optional gyrostabiliser), and a
spacecraft slewed by control-moment gyros. Both are :class:`~gyroemu.dynamics.gyrostat.Gyrostat` models.

Ship (``kind = "ship"``)
------------------------
A ship at anchor (zero speed) in long-crested beam seas, Earth-bound (``[site]``). Body axes are
forward, port, up (x, y, z); ``heading_deg`` is the compass heading of the bow.

* **Sea**: a JONSWAP spectrum (DNV-RP-C205 §3.5.5; ``peak_enhancement = 1`` gives Pierson–Moskowitz)
  of significant height ``Hs`` and peak period ``Tp``, cut into ``components`` equal bands between
  0.5 and 3 peak frequencies, one seeded random frequency within each band and a seeded random phase:
  elevation ``η(t) = Σ ζ_k cos(ω_k t + θ_k)`` with ``ζ_k = sqrt(2 S(ω_k) Δω)``.
* **Roll** (Froude–Krylov in waves long against the beam): the wave moment is the righting moment of
  the effective wave slope, ``M(t) = r Δ g GM Σ k_k ζ_k sin(ω_k t + θ_k)`` with deep-water wave numbers
  ``k = ω²/g`` and the effective-slope factor ``r`` (IMO's weather criterion uses 0.7–1). Restoring:
  ``−Δ g GM sin φ`` (for a general attitude, the metacentric moment ``Δ g (−GM u_y, GM_L u_x, 0)`` with
  ``u`` the world's up axis in body axes, which reads ``−Δ g GM sin φ cos θ`` in roll and
  ``−Δ g GM_L sin θ`` in pitch). Linear damping ``2 ζ sqrt(C I)`` in roll, pitch and yaw.
* **Heave**: ``Δ z̈ = −ρ g A_wp (z − η) − c ż``; **yaw**: a course-keeping (anchor/autopilot) spring and
  damper; surge and sway: a mooring spring and damper. Added masses are folded into the configured
  radii of gyration (roll, pitch, yaw) and omitted in heave.
* **Gyrostabiliser** (``[stabiliser]``; the lecture's anti-roll gyro; Seakeeper-type): a rotor spinning
  about the vertical body axis, on a gimbal whose axis is athwartships (body y). Its angular momentum
  ``h = J Ω`` precesses by the gimbal angle ``δ``; ``ḣ = h δ̇ (cos δ, 0, −sin δ)`` reacts on the hull as
  the roll moment ``−h δ̇ cos δ``. The precession is actively controlled: the commanded gimbal rate is
  ``δ̇ = K p − k_c δ`` (roll rate ``p``, gain ``K``, centring rate ``k_c``), faded to zero over the last
  10° before the gimbal stops ``±δ_max``.

The simulation starts in the sea's steady state: the initial roll, pitch, gimbal and heave states are
those of the linearised model's steady response to the same wave components (no start-up transient).
:meth:`Ship.linear_model` is that linearised coupled roll–pitch–gimbal system; its transfer function at
the wave components predicts the roll RMS with and without the stabiliser (the tests compare).

Spacecraft (``kind = "spacecraft-cmg"``)
----------------------------------------
A rigid spacecraft in inertial space (no gravity: an ideal accelerometer at the centre of mass reads
zero) with four single-gimbal control-moment gyros in the standard pyramid (Wie, *Space Vehicle
Dynamics and Control*, 2nd ed., §7.3: gimbal axes on the faces of a pyramid of skew angle ``β``,
zero momentum at zero gimbal angles). It performs a rest-to-rest eigen-axis slew of ``angle_deg``
about ``axis_b`` (Wie, Weiss & Arapostathis, J. Guid. Control Dyn. 12(3), 1989) with the quaternion
feedback ``u = −k I q_e − c I ω + ω × I ω``, ``k = 2 ω_n²``, ``c = 2 ζ ω_n`` (for which
``ω̇ = −k q_e − c ω`` keeps ``ω`` on the eigen-axis and the error angle obeys
``θ̈ + c θ̇ + (k/2) sin(θ/2)/(θ/2)·θ = 0``). The CMGs deliver it: the required momentum rate
``ḣ = −u − ω × h`` is mapped to gimbal rates by the singularity-robust pseudo-inverse
``δ̇ = Aᵀ (A Aᵀ + λ 1)⁻¹ ḣ``, ``λ = λ₀ h₀² exp(−μ det(A Aᵀ)/h₀⁶)`` (Wie §7.3.4),
``A = ∂h/∂δ``,
scaled down uniformly when a rate exceeds the gimbal rate limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
import pydantic
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, StrictInt

from .body_kernels import cross, quat_product, rotate_back, rotation_matrix
from .config import AngleDeg, NonNegativeReal, PositiveReal, Quat, Real, Section, Vec3
from .earth import Environment, Site
from .gyrostat import GIMBALS, GimballedRotor, Gyrostat, P, Q, SpinProfile, W, X
from .inertia import inertia_config, inertia_tensor
from .integrate import Jump, Solution, integrate
from .rigid_body import world_motion_trajectory
from .rotation import body_rate_from_euler_zyx, euler_zyx_from_quat, quat_conjugate, quat_from_euler_zyx, quat_positive
from .scenarios import ScenarioSpec
from .trajectory import Trajectory

__all__ = [
    "jonswap",
    "WaveComponents",
    "Hull",
    "Waves",
    "Stabiliser",
    "ShipSpec",
    "Ship",
    "SpacecraftBody",
    "CmgArray",
    "Slew",
    "SpacecraftSpec",
    "Spacecraft",
    "pyramid_gimbals",
]

RHO_SEAWATER = 1025.0
"""Density of sea water, kg/m³."""

RPM = 2.0 * np.pi / 60.0
"""rad/s per revolution per minute."""


# ================================================================================================
# Sea
# ================================================================================================


def jonswap(omega: ArrayLike, significant_height: float, peak_period: float, gamma: float = 3.3) -> NDArray[np.float64]:
    """JONSWAP wave spectrum ``S(ω)``, m² s/rad (DNV-RP-C205, eqs. 3.5.3–3.5.5).

    ``S = A_γ · 5/16 Hs² ω_p⁴ ω⁻⁵ exp(−5/4 (ω/ω_p)⁻⁴) · γ^exp(−(ω − ω_p)²/(2 σ² ω_p²))``, with
    ``A_γ = 1 − 0.287 ln γ`` and ``σ = 0.07`` below the peak, ``0.09`` above; ``γ = 1`` is the
    Pierson–Moskowitz spectrum. ``∫ S dω = Hs²/16``.
    """
    omega = np.asarray(omega, dtype=float)
    wp = 2.0 * np.pi / peak_period
    pm = 5.0 / 16.0 * significant_height**2 * wp**4 * omega**-5.0 * np.exp(-1.25 * (omega / wp) ** -4.0)
    sigma = np.where(omega <= wp, 0.07, 0.09)
    peak = gamma ** np.exp(-0.5 * ((omega - wp) / (sigma * wp)) ** 2)
    spectrum: NDArray[np.float64] = (1.0 - 0.287 * np.log(gamma)) * pm * peak
    return spectrum


@dataclass(frozen=True)
class WaveComponents:
    """A sea state as a sum of regular waves ``η(t) = Σ ζ_k cos(ω_k t + θ_k)`` at the ship.

    Attributes (K components): ``omega`` rad/s, ``amplitude`` m, ``phase`` rad, ``wavenumber`` rad/m.
    """

    omega: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    phase: NDArray[np.float64]
    wavenumber: NDArray[np.float64]

    @classmethod
    def from_spectrum(
        cls,
        rng: np.random.Generator,
        significant_height: float,
        peak_period: float,
        gamma: float,
        count: int,
        g: float,
    ) -> WaveComponents:
        """Seeded components of a JONSWAP sea: one random frequency in each of ``count`` equal bands
        over ``[0.5, 3] ω_p``, amplitude ``sqrt(2 S(ω) Δω)``, phase uniform in ``[0, 2π)``."""
        wp = 2.0 * np.pi / peak_period
        edges = np.linspace(0.5 * wp, 3.0 * wp, count + 1)
        width = np.diff(edges)
        omega = edges[:-1] + width * rng.uniform(size=count)
        phase = rng.uniform(0.0, 2.0 * np.pi, size=count)
        amplitude = np.sqrt(2.0 * jonswap(omega, significant_height, peak_period, gamma) * width)
        return cls(omega, amplitude, phase, omega**2 / g)  # deep water: k = ω²/g

    def phasors(self, t: ArrayLike) -> NDArray[np.complex128]:
        """``exp(i (ω_k t + θ_k))``, shape ``t.shape + (K,)``."""
        phasors: NDArray[np.complex128] = np.exp(1j * (np.asarray(t, dtype=float)[..., None] * self.omega + self.phase))
        return phasors

    def elevation(self, t: ArrayLike) -> NDArray[np.float64]:
        """``η(t)``, m."""
        return np.cos(np.asarray(t, dtype=float)[..., None] * self.omega + self.phase) @ self.amplitude

    def slope(self, t: ArrayLike) -> NDArray[np.float64]:
        """Wave slope ``Σ k ζ sin(ω t + θ)`` across the ship, rad."""
        return np.sin(np.asarray(t, dtype=float)[..., None] * self.omega + self.phase) @ (
            self.wavenumber * self.amplitude
        )


# ================================================================================================
# Ship: config
# ================================================================================================


class Hull(Section):
    """``[ship]``: mass properties, hydrostatics and damping of the hull."""

    displacement_t: PositiveReal = 60.0
    radii_of_gyration_m: tuple[PositiveReal, PositiveReal, PositiveReal] = (2.4, 6.5, 6.5)
    """Roll, pitch, yaw radii of gyration about the centre of mass, added inertia included."""
    gm_m: PositiveReal = 1.0
    """Transverse metacentric height GM."""
    gm_long_m: PositiveReal = 30.0
    waterplane_area_m2: PositiveReal = 110.0
    roll_damping_ratio: Annotated[Real, Field(ge=0.0, lt=1.0)] = 0.07
    pitch_damping_ratio: Annotated[Real, Field(ge=0.0, lt=1.0)] = 0.2
    heave_damping_ratio: Annotated[Real, Field(ge=0.0, lt=1.0)] = 0.2
    heading_deg: AngleDeg = 0.0
    """Compass heading of the bow, degrees clockwise from north."""
    heading_hold_period_s: PositiveReal = 40.0
    mooring_period_s: PositiveReal = 120.0


class Waves(Section):
    """``[waves]``: the beam sea's spectrum and how many components represent it."""

    significant_height_m: NonNegativeReal = 1.0
    peak_period_s: PositiveReal = 7.0
    peak_enhancement: Annotated[Real, Field(ge=1.0, le=7.0)] = 3.3
    """JONSWAP γ (1: Pierson–Moskowitz)."""
    components: Annotated[StrictInt, Field(ge=1, le=1000)] = 40
    effective_slope_factor: Annotated[Real, Field(gt=0.0, le=1.5)] = 0.75


class Stabiliser(Section):
    """``[stabiliser]``: a gyroscopic anti-roll stabiliser with actively controlled precession."""

    rotor_inertia_kgm2: PositiveReal = 40.0
    spin_rpm: PositiveReal = 7000.0
    precession_gain: NonNegativeReal = 6.0
    """``K`` in ``δ̇ = K p − k_c δ``: gimbal rate per roll rate."""
    centring_rate_per_s: NonNegativeReal = 0.1
    gimbal_limit_deg: Annotated[Real, Field(gt=10.0, le=90.0)] = 70.0


class ShipSpec(ScenarioSpec):
    """``kind = "ship"``: a ship at anchor rolling in beam seas, optionally gyro-stabilised."""

    kind: Literal["ship"]
    seed: Annotated[StrictInt, Field(ge=0)] = 0
    site: Site = Site()
    ship: Hull = Hull()
    waves: Waves = Waves()
    stabiliser: Stabiliser | None = None

    def model(self) -> Ship:
        return Ship.from_spec(self)

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        return self.model().trajectory(t)


# ================================================================================================
# Ship: physics
# ================================================================================================


def _wrap(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True, eq=False)
class Ship:
    """The ship's equations (module docstring) around a :class:`Gyrostat`. SI units throughout."""

    body: Gyrostat
    environment: Environment
    waves: WaveComponents
    gm: float
    gm_long: float
    roll_moment_per_slope: float  # r Δ g GM, N m/rad
    roll_damping: float  # N m s
    pitch_damping: float
    yaw_stiffness: float  # N m/rad
    yaw_damping: float
    heave_stiffness: float  # ρ g A_wp, N/m
    heave_damping: float  # N s/m
    mooring_stiffness: float  # N/m
    mooring_damping: float
    yaw0: float  # ENU yaw of the bow, rad
    gain: float = 0.0  # K
    centring: float = 0.0  # k_c, 1/s
    gimbal_limit: float = np.pi / 2

    @classmethod
    def from_spec(cls, spec: ShipSpec) -> Ship:
        env = spec.site.environment()
        g = float(np.linalg.norm(env.gravity_w))
        hull, sea = spec.ship, spec.waves
        mass = hull.displacement_t * 1e3
        inertia = mass * np.square(hull.radii_of_gyration_m)
        c_roll, c_pitch = mass * g * hull.gm_m, mass * g * hull.gm_long_m
        c_heave = RHO_SEAWATER * g * hull.waterplane_area_m2
        k_yaw = inertia[2] * (2.0 * np.pi / hull.heading_hold_period_s) ** 2
        k_moor = mass * (2.0 * np.pi / hull.mooring_period_s) ** 2
        rng = np.random.default_rng(spec.seed)
        waves = WaveComponents.from_spectrum(
            rng, sea.significant_height_m, sea.peak_period_s, sea.peak_enhancement, sea.components, g
        )
        gimbals: tuple[GimballedRotor, ...] = ()
        extra: dict[str, Any] = {}
        if spec.stabiliser is not None:
            st = spec.stabiliser
            spin = SpinProfile(st.spin_rpm * RPM)
            # Spin axis vertical at zero gimbal angle, gimbal (precession) axis athwartships.
            gimbals = (
                GimballedRotor(np.array((0.0, 1.0, 0.0)), np.array((0.0, 0.0, 1.0)), st.rotor_inertia_kgm2, spin),
            )
            extra = dict(
                gain=st.precession_gain, centring=st.centring_rate_per_s, gimbal_limit=np.radians(st.gimbal_limit_deg)
            )
        body = Gyrostat(mass, np.diag(inertia), gimbals=gimbals, frame_rate_w=env.earth_rate_w)
        return cls(
            body=body,
            environment=env,
            waves=waves,
            gm=hull.gm_m,
            gm_long=hull.gm_long_m,
            roll_moment_per_slope=sea.effective_slope_factor * c_roll,
            roll_damping=2.0 * hull.roll_damping_ratio * np.sqrt(c_roll * inertia[0]),  # b = 2ζ sqrt(C I)
            pitch_damping=2.0 * hull.pitch_damping_ratio * np.sqrt(c_pitch * inertia[1]),
            yaw_stiffness=k_yaw,
            yaw_damping=2.0 * 0.7 * np.sqrt(k_yaw * inertia[2]),  # course keeping: damping ratio 0.7
            heave_stiffness=c_heave,
            heave_damping=2.0 * hull.heave_damping_ratio * np.sqrt(c_heave * mass),
            mooring_stiffness=k_moor,
            mooring_damping=2.0 * 0.7 * np.sqrt(k_moor * mass),  # damping ratio 0.7
            yaw0=np.radians(90.0 - hull.heading_deg),  # compass heading -> ENU yaw
            **extra,
        )

    # -- derived constants ---------------------------------------------------------------------------

    @property
    def mass(self) -> float:
        return self.body.mass

    @property
    def inertia(self) -> NDArray[np.float64]:
        return np.diag(self.body.inertia_b)

    @property
    def gravity(self) -> float:
        return float(np.linalg.norm(self.environment.gravity_w))

    @property
    def rotor_momentum(self) -> float:
        """``h = J Ω`` of the stabiliser (0 without one), N m s."""
        if not self.body.gimbals:
            return 0.0
        rotor = self.body.gimbals[0]
        return rotor.inertia_kgm2 * rotor.spin.rate0

    # -- loads ------------------------------------------------------------------------------------------

    def roll_moment(self, t: ArrayLike) -> NDArray[np.float64]:
        """Wave roll moment ``r Δ g GM · slope(t)``, N m."""
        return self.roll_moment_per_slope * self.waves.slope(t)

    def _rates_wb(self, y: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
        """Body rates relative to the world (the water), body axes."""
        return y[..., W] - rotate_back(r, self.environment.earth_rate_w)

    def force_w(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Weight, buoyancy, heave restoring and damping, mooring: world axes, N."""
        x, v = y[..., X], y[..., P] / self.mass
        weight = self.mass * self.environment.gravity_w  # m g
        buoyancy = -weight  # Archimedes at the mean waterline: ρ g ∇ = Δ g, up
        heave = -self.heave_stiffness * (x[..., 2] - self.waves.elevation(t)) - self.heave_damping * v[..., 2]
        mooring = -self.mooring_stiffness * x - self.mooring_damping * v  # surge, sway: anchor −k x − c v
        hydro = np.stack(np.broadcast_arrays(mooring[..., 0], mooring[..., 1], heave), axis=-1)  # −C (z − η) − c ż
        force: NDArray[np.float64] = weight + buoyancy + hydro
        return force

    def torque_b(
        self,
        t: ArrayLike,
        y: NDArray[np.float64],
        r: NDArray[np.float64] | None = None,
        rates: NDArray[np.float64] | None = None,
    ) -> NDArray[np.float64]:
        """Hydrostatic, damping, wave and course-keeping moments about the centre of mass, body axes.
        ``r``, ``rates``: ``R(q)`` and :meth:`_rates_wb` when the caller has them already."""
        r = rotation_matrix(y[..., Q]) if r is None else r
        up = r[..., 2, :]  # u = Rᵀ ẑ, the world's up axis in body axes
        rates = self._rates_wb(y, r) if rates is None else rates
        weight = self.mass * self.gravity
        yaw_error = _wrap(np.arctan2(r[..., 1, 0], r[..., 0, 0]) - self.yaw0)
        roll = -weight * self.gm * up[..., 1] - self.roll_damping * rates[..., 0] + self.roll_moment(t)
        pitch = weight * self.gm_long * up[..., 0] - self.pitch_damping * rates[..., 1]
        yaw = -self.yaw_stiffness * yaw_error - self.yaw_damping * rates[..., 2]
        return np.stack(np.broadcast_arrays(roll, pitch, yaw), axis=-1)

    def gimbal_rate(
        self, t: ArrayLike, y: NDArray[np.float64], rates: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Commanded precession rate ``δ̇ = K p − k_c δ``, faded out over the last 10° before a stop.
        ``rates``: :meth:`_rates_wb` when the caller has it already."""
        p = (self._rates_wb(y, rotation_matrix(y[..., Q])) if rates is None else rates)[..., 0]
        delta = y[..., GIMBALS][..., 0]
        u = self.gain * p - self.centring * delta
        margin = np.radians(10.0)
        room = np.clip((self.gimbal_limit - np.sign(u) * delta) / margin, 0.0, 1.0)  # towards the stop
        rate: NDArray[np.float64] = (u * room)[..., None]
        return rate

    def derivative(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        # R(q) and the rates relative to the water once, for the torque and the gimbal command alike.
        r = rotation_matrix(y[..., Q])
        rates = self._rates_wb(y, r)
        torque = self.torque_b(t, y, r, rates)
        gimbal = self.gimbal_rate(t, y, rates) if self.body.gimbals else None
        return self.body.derivative(
            t, y, self.force_w, lambda *_: torque, None if gimbal is None else lambda *_: gimbal
        )

    # -- linear theory -------------------------------------------------------------------------------

    def linear_model(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The linearised roll–pitch(–gimbal) system ``ẋ = A x + B M`` about upright and ``δ = 0``.

        States ``x = [φ, p, θ, q]`` (+ ``δ`` with a stabiliser), input the wave roll moment ``M``::

            I_x ṗ = −C_x φ − b_x p − h q − h δ̇ + M      (−(ω × h)_x − ḣ_x, linearised)
            I_y q̇ = −C_y θ − b_y q + h p                 (−(ω × h)_y)
            δ̇    = K p − k_c δ

        Returns ``(A, B)``.
        """
        ix, iy, _ = self.inertia
        cx, cy = self.mass * self.gravity * self.gm, self.mass * self.gravity * self.gm_long
        bx, by = self.roll_damping, self.pitch_damping
        h, k, kc = self.rotor_momentum, self.gain, self.centring
        n = 5 if self.body.gimbals else 4
        a = np.zeros((n, n))
        a[0, 1] = a[2, 3] = 1.0
        a[1, :4] = [-cx / ix, -bx / ix, 0.0, -h / ix]
        a[3, :4] = [0.0, h / iy, -cy / iy, -by / iy]
        if n == 5:
            a[1, 1] -= h * k / ix  # − h δ̇ with δ̇ = K p − k_c δ
            a[1, 4] = h * kc / ix
            a[4, 1], a[4, 4] = k, -kc
        b = np.zeros(n)
        b[1] = 1.0 / ix
        return a, b

    def roll_transfer(self, omega: ArrayLike) -> NDArray[np.complexfloating[Any, Any]]:
        """Roll angle per unit roll moment, ``H(iω) = [(iω − A)⁻¹ B]_φ``, rad/(N m), complex."""
        a, b = self.linear_model()
        omega = np.asarray(omega, dtype=float)
        m = 1j * omega[..., None, None] * np.eye(len(b)) - a
        return np.linalg.solve(m, np.broadcast_to(b, omega.shape + b.shape)[..., None])[..., 0, 0]

    def linear_response(self, t: ArrayLike) -> NDArray[np.float64]:
        """Steady-state linear response to the wave components: ``[φ, p, θ, q(, δ)]`` at ``t``,
        shape ``t.shape + (n,)``; ``x(t) = Im Σ (iω_k − A)⁻¹ B M_k e^{i(ω_k t + θ_k)}``."""
        a, b = self.linear_model()
        w = self.waves
        m_k = self.roll_moment_per_slope * w.wavenumber * w.amplitude
        x_k = np.linalg.solve(1j * w.omega[:, None, None] * np.eye(len(b)) - a, (b[None, :] * m_k[:, None])[..., None])
        return np.imag(w.phasors(t) @ x_k[..., 0])

    def heave_response(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Steady-state heave ``z`` and ``ż``: ``m z̈ = −C (z − η) − c ż``, component by component."""
        w = self.waves
        z_k = (
            self.heave_stiffness
            * w.amplitude
            / (self.heave_stiffness - self.mass * w.omega**2 + 1j * self.heave_damping * w.omega)
        )
        e = w.phasors(t)
        return np.real(e @ z_k), np.real(e @ (1j * w.omega * z_k))

    def roll_rms_theory(self) -> float:
        """Spectral roll RMS of the linear model: ``sqrt(Σ ½ |H(iω_k)|² M_k²)``, rad."""
        w = self.waves
        m_k = self.roll_moment_per_slope * w.wavenumber * w.amplitude
        return float(np.sqrt(0.5 * np.sum(np.abs(self.roll_transfer(w.omega)) ** 2 * m_k**2)))

    # -- simulation ----------------------------------------------------------------------------------

    def initial_state(self, t0: float = 0.0) -> NDArray[np.float64]:
        """The linear steady state at ``t0`` (roll, pitch, rates, gimbal angle, heave)."""
        x = self.linear_response(np.array(t0))
        z, z_dot = self.heave_response(np.array(t0))
        rpy = np.array([x[0], x[2], self.yaw0])
        q = quat_from_euler_zyx(rpy)
        omega_wb = body_rate_from_euler_zyx(rpy, np.array([x[1], x[3], 0.0]))
        omega = omega_wb + rotate_back(rotation_matrix(q), self.environment.earth_rate_w)
        delta = x[4:5] if self.body.gimbals else ()
        return self.body.state((0.0, 0.0, float(z)), q, (0.0, 0.0, float(z_dot)), omega, delta)

    def solve(self, t: NDArray[np.float64], rtol: float = 1e-10) -> Solution:
        """Integrate over the sample times ``t`` (from ``t[0]``); returns the :class:`Solution`."""
        atol = np.concatenate(
            [
                np.full(3, 1e-9),
                np.full(4, 1e-12),
                np.full(3, 1e-9 * self.mass),
                np.full(3, 1e-12),
                np.full(len(self.body.gimbals), 1e-12),
            ]
        )
        return integrate(self.derivative, t, self.initial_state(float(t[0])), rtol=rtol, atol=atol)

    def trajectory(self, t: ArrayLike, rtol: float = 1e-10) -> Trajectory:
        t = np.asarray(t, dtype=float)
        sol = self.solve(t, rtol)
        y, y_dot = sol.y, sol.y_dot
        q = y[:, Q]
        rpy = euler_zyx_from_quat(q)
        extras = {
            "roll_rad": rpy[:, 0],
            "pitch_rad": rpy[:, 1],
            "heave_m": y[:, 2].copy(),
            "wave_elevation_m": self.waves.elevation(t),
            "wave_roll_moment_Nm": self.roll_moment(t),
        }
        if self.body.gimbals:
            extras["gimbal_angle_rad"] = y[:, 13].copy()
            extras["gimbal_rate_rad_s"] = y_dot[:, 13].copy()
        return world_motion_trajectory(
            t, y[:, X], q, y[:, P] / self.mass, y_dot[:, P] / self.mass, y[:, W], y_dot[:, W], self.environment, extras
        )


# ================================================================================================
# Spacecraft
# ================================================================================================


class SpacecraftBody(Section):
    """``[spacecraft]``: mass properties and initial attitude."""

    mass_kg: PositiveReal = 500.0
    inertia_kgm2: Annotated[Vec3 | tuple[Vec3, Vec3, Vec3], pydantic.AfterValidator(inertia_config)] = (
        1200.0,
        1000.0,
        800.0,
    )
    """Principal moments or a 3x3 matrix in body axes about the centre of mass, rotors locked."""
    q_wb: Quat = (1.0, 0.0, 0.0, 0.0)

    @pydantic.field_validator("q_wb")
    @classmethod
    def _unit(cls, q: Quat) -> Quat:
        if not np.linalg.norm(q) > 0:
            raise ValueError("a quaternion must be non-zero")
        return q


class CmgArray(Section):
    """``[cmg]``: four single-gimbal CMGs in a pyramid."""

    rotor_momentum_Nms: PositiveReal = 50.0
    rotor_speed_rpm: PositiveReal = 6000.0
    skew_angle_deg: Annotated[Real, Field(gt=0.0, lt=90.0)] = 54.7356
    initial_gimbal_deg: tuple[Real, Real, Real, Real] = (0.0, 0.0, 0.0, 0.0)
    gimbal_rate_limit_deg_s: PositiveReal = 60.0
    singularity_gain: NonNegativeReal = 0.01
    """``λ₀`` of the singularity-robust inverse (in units of ``h₀²``)."""
    singularity_sharpness: NonNegativeReal = 10.0
    """``μ`` in ``λ = λ₀ h₀² exp(−μ det(A Aᵀ)/h₀⁶)``."""


class Slew(Section):
    """``[slew]``: a rest-to-rest eigen-axis slew."""

    axis_b: Vec3 = (1.0, 1.0, 0.0)
    angle_deg: Annotated[Real, Field(gt=-180.0, lt=180.0)] = 60.0
    start_s: NonNegativeReal = 5.0
    natural_frequency_rad_s: PositiveReal = 0.15
    damping_ratio: PositiveReal = 0.9

    @pydantic.field_validator("axis_b")
    @classmethod
    def _nonzero(cls, v: Vec3) -> Vec3:
        if not np.linalg.norm(v) > 0:
            raise ValueError("the slew axis must be a non-zero vector")
        return v


class SpacecraftSpec(ScenarioSpec):
    """``kind = "spacecraft-cmg"``: an eigen-axis slew by a pyramid of control-moment gyros."""

    kind: Literal["spacecraft-cmg"]
    spacecraft: SpacecraftBody = SpacecraftBody()
    cmg: CmgArray = CmgArray()
    slew: Slew = Slew()

    def model(self) -> Spacecraft:
        return Spacecraft.from_spec(self)

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        return self.model().trajectory(t)


def pyramid_gimbals(skew_angle: float, rotor_inertia: float, spin_rate: float) -> tuple[GimballedRotor, ...]:
    """Four CMGs on a pyramid of skew angle ``β`` (Wie §7.3.2): gimbal axes
    ``ĝ_i = (cos a_i sin β, sin a_i sin β, cos β)`` with ``a_i = 0°, 90°, 180°, 270°`` and spin axes at
    zero gimbal angle ``ŝ_i = ẑ × ĝ_i / |·|`` (pointing around the pyramid, summing to zero)."""
    sb, cb = np.sin(skew_angle), np.cos(skew_angle)
    rotors = []
    for a in np.radians([0.0, 90.0, 180.0, 270.0]):
        g = np.array([np.cos(a) * sb, np.sin(a) * sb, cb])
        s = np.array([-np.sin(a), np.cos(a), 0.0])
        rotors.append(GimballedRotor(g, s, rotor_inertia, SpinProfile(spin_rate)))
    return tuple(rotors)


@dataclass(frozen=True, eq=False)
class Spacecraft:
    """The spacecraft, its CMGs, the slew command, controller and steering law (module docstring)."""

    body: Gyrostat
    q0: NDArray[np.float64]
    q_target: NDArray[np.float64]
    start: float
    k: float  # 1/s²
    c: float  # 1/s
    rotor_momentum: float
    gimbal_rate_limit: float
    singularity_gain: float
    singularity_sharpness: float
    initial_gimbal: NDArray[np.float64]

    @classmethod
    def from_spec(cls, spec: SpacecraftSpec) -> Spacecraft:
        sc, cmg, slew = spec.spacecraft, spec.cmg, spec.slew
        spin = cmg.rotor_speed_rpm * RPM
        gimbals = pyramid_gimbals(np.radians(cmg.skew_angle_deg), cmg.rotor_momentum_Nms / spin, spin)
        body = Gyrostat(sc.mass_kg, inertia_tensor(sc.inertia_kgm2), gimbals=gimbals)
        q0 = np.asarray(sc.q_wb, dtype=float) / np.linalg.norm(sc.q_wb)
        axis = np.asarray(slew.axis_b, dtype=float) / np.linalg.norm(slew.axis_b)
        half = 0.5 * np.radians(slew.angle_deg)
        turn = np.concatenate([[np.cos(half)], np.sin(half) * axis])  # about a body axis: q0 ⊗ Δq
        wn, zeta = slew.natural_frequency_rad_s, slew.damping_ratio
        return cls(
            body=body,
            q0=q0,
            q_target=quat_product(q0, turn),
            start=slew.start_s,
            k=2.0 * wn**2,
            c=2.0 * zeta * wn,
            rotor_momentum=cmg.rotor_momentum_Nms,
            gimbal_rate_limit=np.radians(cmg.gimbal_rate_limit_deg_s),
            singularity_gain=cmg.singularity_gain,
            singularity_sharpness=cmg.singularity_sharpness,
            initial_gimbal=np.radians(np.asarray(cmg.initial_gimbal_deg, dtype=float)),
        )

    def commanded_attitude(self, t: ArrayLike) -> NDArray[np.float64]:
        """``q0`` before the slew starts, the target after; shape ``t.shape + (4,)``."""
        after = (np.asarray(t, dtype=float) >= self.start)[..., None]
        return np.where(after, self.q_target, self.q0)

    def attitude_error(self, t: ArrayLike, q: ArrayLike) -> NDArray[np.float64]:
        """``q_e = q_c* ⊗ q`` (body-axes error), sign chosen with ``w ≥ 0`` (the short way round)."""
        qe = quat_product(quat_conjugate(self.commanded_attitude(t)), np.asarray(q, dtype=float))
        return quat_positive(qe)

    def control_torque(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Eigen-axis slew law ``u = −k I q_e − c I ω + ω × I ω``, body axes, N m."""
        omega = y[..., W]
        i_omega = omega @ self.body.inertia_b.T
        qe = self.attitude_error(t, y[..., Q] / np.linalg.norm(y[..., Q], axis=-1, keepdims=True))
        return (-self.k * qe[..., 1:] - self.c * omega) @ self.body.inertia_b.T + cross(omega, i_omega)

    def gimbal_rate(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Singularity-robust steering: ``δ̇ = Aᵀ (A Aᵀ + λ 1)⁻¹ (−u − ω × h)``, rate-limited."""
        delta = y[..., GIMBALS]
        a = self.body.gimbal_jacobian(t, delta)  # (..., 3, 4)
        h = self.body.rotor_momentum_b(t, y)
        h_dot = -self.control_torque(t, y) - cross(y[..., W], h)  # required ḣ
        aat = a @ np.swapaxes(a, -1, -2)
        h0 = self.rotor_momentum
        lam = self.singularity_gain * h0**2 * np.exp(-self.singularity_sharpness * np.linalg.det(aat) / h0**6)
        m = aat + lam[..., None, None] * np.eye(3)
        rates = (np.swapaxes(a, -1, -2) @ np.linalg.solve(m, h_dot[..., None]))[..., 0]
        peak = np.max(np.abs(rates), axis=-1, keepdims=True)
        limited: NDArray[np.float64] = rates * np.minimum(1.0, self.gimbal_rate_limit / np.maximum(peak, 1e-300))
        return limited

    def derivative(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.body.derivative(t, y, gimbal_rate=self.gimbal_rate)

    def initial_state(self) -> NDArray[np.float64]:
        return self.body.state(q_wb=self.q0, gimbal_angles=self.initial_gimbal)

    def solve(self, t: ArrayLike, rtol: float = 1e-10) -> Solution:
        atol = np.concatenate([np.full(13, 1e-12), np.full(4, 1e-12)])
        return integrate(self.derivative, t, self.initial_state(), jumps=[Jump(self.start)], rtol=rtol, atol=atol)

    def trajectory(self, t: ArrayLike, rtol: float = 1e-10) -> Trajectory:
        t = np.asarray(t, dtype=float)
        sol = self.solve(t, rtol)
        y, y_dot = sol.y, sol.y_dot
        qe = self.attitude_error(t, y[:, Q])
        extras = {
            "gimbal_angles_rad": y[:, GIMBALS].copy(),
            "gimbal_rates_rad_s": y_dot[:, GIMBALS].copy(),
            "cmg_momentum_b": self.body.rotor_momentum_b(t, y),
            "attitude_error_rad": 2.0 * np.arctan2(np.linalg.norm(qe[:, 1:], axis=-1), qe[:, 0]),
            "angular_momentum_w": self.body.angular_momentum_w(t, y),
        }
        zeros = np.zeros((t.size, 3))
        return world_motion_trajectory(
            t, zeros, y[:, Q], zeros, zeros, y[:, W], y_dot[:, W], Environment.inertial(), extras
        )
