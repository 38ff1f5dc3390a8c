"""A box dropped on the ground: free fall with an initial tumble, contact impulses at its corners,
bounces until it comes to rest or the scenario ends (``kind = "drop"``).

Model
-----
The device is a rigid box (:class:`~gyroemu.dynamics.rigid_body.RigidBody`, state ``[x, q, P, L]``) over the
ground plane ``z = 0`` of an Earth-bound world (``[site]``: gravity, Earth rate, Coriolis). Between
contacts it falls freely. A contact happens when a corner reaches the ground moving down (located by
the solver's root finder, one event per corner); all closing corners at the ground (within ``1e-9``
m) or in it touch together, and the contact point is their mean (a flat face lands on its centre).

The contact impulse ``J`` is Newton's restitution law with Coulomb friction at the contact point
(Mirtich, *Impulse-based dynamic simulation of rigid body systems*, PhD thesis, Berkeley 1996, ch. 4;
Stronge, *Impact Mechanics*, 2000, ch. 4). With ``u`` the contact point's velocity, ``n = ẑ`` and
``K = (1/m) 1 − [r]× I_w⁻¹ [r]×`` (the point's velocity change per unit impulse)::

    sticking:  J = K⁻¹ (−e u_n n − u)                       (normal speed reversed × e, slip stopped)
    sliding:   J = j (n − μ t̂),  j = −(1 + e) u_n / (nᵀ K (n − μ t̂))   when |J_t| > μ J_n
    and then   ΔP = J,  ΔL = r × J                           (scribe notes: τ = r × F)

An impulse that would add kinetic energy (Newton's law with friction can, at some geometries; Stronge
ch. 4) is replaced by the frictionless one, which never does.

How the impulse appears in the sampled specific force
-----------------------------------------------------
* ``pulse_duration_s > 0`` (default): the impulse is delivered as a half-sine force pulse of that
  duration, ``F(t) = J π/(2 τ) sin(π (t − t_c)/τ)``, at the contacting body point, so
  ``∫ F dt = J`` exactly and the sampled specific force shows a finite shock of peak ``π/2 · J/(m τ)``,
  as an accelerometer on a real device sees it. The body moves during the pulse, so ``ΔL`` and the
  rebound differ from the ideal impulse by ``O(τ)`` (gravity takes ``g τ`` from the rebound speed: the
  pulse carries ``J``, not the weight). The truth must sample a pulse at least :data:`PULSE_SAMPLES`
  times (``rate_hz ≥ PULSE_SAMPLES / pulse_duration_s``): the sensors rebuild the force between the
  truth's samples with a cubic spline, and at 2 samples per 1 ms pulse an ideal accelerometer read
  14 % of the impulse short (Δv_z 4.55 against 5.29 m/s); at 20, 0.06 %.
  Contacts are not detected during a pulse; one pending at its end acts then.
* ``pulse_duration_s = 0``: ideal impulses; the velocities jump, the Dirac force is not in the samples
  (specific force is free fall's zero on both sides), and ``extras["contact_impulse_w"]`` holds the
  impulse applied in each sample interval ``(t_{k−1}, t_k]``, N s.

Settling
--------
Impulse-only bouncing never ends by itself (the bounces become ever shorter), and a single contact
point cannot hold a face flat. So when a contact finds a face within 5° of the ground and the energy
left in bouncing and rocking (:meth:`Drop.bounce_energy`) below that of a fall that lands at
``rest_speed_m_s`` (``½ m v²``), the bouncing is over (also when more than 100 contacts fall within a
microsecond: the resting contact that impulses cannot represent): the box is laid flat on
that face (a rotation by the remaining small tilt) on the ground, keeping its horizontal slide and its
spin about the vertical. From then on the ground carries its weight (the specific force is ``−g``:
an accelerometer reads +9.8 m/s² up) and friction brakes the slide at ``μ g`` and the spin at
``μ m g ρ̄ / I_v`` (uniform pressure on the face, ``ρ̄`` its mean distance from the face's centre,
``I_v`` the moment about the vertical); the two are braked independently (Coulomb friction couples
them; this overestimates the braking of a box that slides and spins at once), each until it stops.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
import pydantic
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from .body_kernels import cross, quat_product, rotate, rotation_matrix
from .config import AnglesDeg, ConfigError, NonNegativeReal, PositiveReal, Real, Section, Vec3
from .earth import Environment, Site
from .inertia import box, inertia_config
from .integrate import Event, Jump, Jumped, Solution, integrate
from .rigid_body import L, P, Q, RigidBody, X, contact_mass_matrix, world_motion_trajectory
from .rotation import quat_from_euler_zyx, quat_from_rotvec
from .scenarios import ScenarioSpec
from .trajectory import Trajectory

__all__ = ["DropBody", "DropInitial", "Contact", "DropSpec", "Drop", "contact_impulse"]

TIE_M = 1e-9
"""Corners this close to the lowest one touch together, m."""


# ================================================================================================
# Config
# ================================================================================================


class DropBody(Section):
    """``[body]``: the dropped device, a box."""

    mass_kg: PositiveReal = 0.2
    size_m: tuple[PositiveReal, PositiveReal, PositiveReal] = (0.12, 0.07, 0.02)
    """Edge lengths along body x, y, z; the centre of mass is at the box's centre."""
    inertia_kgm2: Annotated[Vec3 | None, pydantic.AfterValidator(inertia_config)] = None
    """Principal moments about the box's axes; default: a uniform box."""


class DropInitial(Section):
    """``[initial]``: release state."""

    height_m: PositiveReal = 1.0
    """Height of the centre of mass above the ground."""
    rpy_deg: AnglesDeg = (20.0, -10.0, 30.0)
    omega_b: Vec3 = (4.0, -3.0, 2.0)
    """Tumble, body axes, rad/s (relative to the Earth)."""
    vel_w: Vec3 = (0.0, 0.0, 0.0)


class Contact(Section):
    """``[contact]``: the ground contact law."""

    restitution: Annotated[Real, Field(ge=0.0, le=1.0)] = 0.4
    friction: NonNegativeReal = 0.3
    pulse_duration_s: Annotated[Real, Field(ge=0.0, le=0.05)] = 0.001
    """Half-sine contact pulse duration (0: ideal impulses)."""
    rest_speed_m_s: NonNegativeReal = 0.05
    """Bouncing ends when its energy is below that of a landing at this speed."""


PULSE_SAMPLES = 20
"""Truth samples per contact pulse, at least (module notes): the rebuilt impulse within 0.1 %."""


def pulse_rate_problem(rate_hz: float, pulse_duration_s: float) -> str | None:
    """Why a truth at ``rate_hz`` cannot show contact pulses of ``pulse_duration_s`` (None: it can)."""
    if pulse_duration_s > 0 and rate_hz * pulse_duration_s < PULSE_SAMPLES * (1 - 1e-9):
        return (
            f"{rate_hz:g} Hz samples a {pulse_duration_s * 1e3:g} ms contact pulse {rate_hz * pulse_duration_s:.3g} "
            f"times; the sensors need {PULSE_SAMPLES} (at least {PULSE_SAMPLES / pulse_duration_s:g} Hz) to "
            "read its impulse, or set contact.pulse_duration_s = 0 (ideal impulses)"
        )
    return None


class DropSpec(ScenarioSpec):
    """``kind = "drop"``: a box dropped with a tumble onto the ground."""

    kind: Literal["drop"]
    site: Site = Site()
    body: DropBody = DropBody()
    initial: DropInitial = DropInitial()
    contact: Contact = Contact()

    @pydantic.model_validator(mode="after")
    def _starts_above_ground(self) -> DropSpec:
        corners = _corners(self.body.size_m)
        # The corners' heights: the third row of R = Rz(yaw) Ry(pitch) Rx(roll) (quat_from_euler_zyx's
        # convention), (−sin θ, sin φ cos θ, cos φ cos θ), in closed form so that validating a file
        # needs no scipy.
        roll, pitch, _ = np.radians(self.initial.rpy_deg)
        up = np.array([-np.sin(pitch), np.sin(roll) * np.cos(pitch), np.cos(roll) * np.cos(pitch)])
        lowest = self.initial.height_m + np.min(corners @ up)
        if lowest <= 0:
            raise ValueError(f"initial.height_m: the box's lowest corner starts {-lowest:.3g} m below the ground")
        return self

    @pydantic.model_validator(mode="after")
    def _samples_its_pulses(self) -> DropSpec:
        problem = pulse_rate_problem(self.rate_hz, self.contact.pulse_duration_s)
        if problem is not None:
            raise ValueError(f"rate_hz: {problem}")
        return self

    def model(self) -> Drop:
        return Drop.from_spec(self)

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        if len(t) > 1:  # a rate asked for in place of the file's (Scenario.simulate's rate_hz)
            problem = pulse_rate_problem(1.0 / float(t[1] - t[0]), self.contact.pulse_duration_s)
            if problem is not None:
                raise ConfigError(problem, key="rate_hz")
        return self.model().trajectory(t)


def _corners(size: ArrayLike) -> NDArray[np.float64]:
    """The 8 corners of a box centred at the origin, (8, 3)."""
    half = 0.5 * np.asarray(size, dtype=float)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    return signs * half


# ================================================================================================
# Contact law
# ================================================================================================


def contact_impulse(
    mass: float,
    inertia_w_inv: NDArray[np.float64],
    lever_w: ArrayLike,
    velocity_w: ArrayLike,
    restitution: float,
    friction: float,
    normal: ArrayLike = (0.0, 0.0, 1.0),
) -> NDArray[np.float64]:
    """Impulse ``J`` (N s, world) on the body at a contact point (module docstring).

    Parameters
    ----------
    mass : float, kg
    inertia_w_inv : (3, 3) ``I_w⁻¹``, world axes
    lever_w : (3,) contact point from the centre of mass, world, m
    velocity_w : (3,) the contact point's velocity before the impact (closing: ``u·n < 0``), m/s
    restitution, friction : ``e`` and ``μ``
    normal : (3,) the ground's unit normal, pointing into the body's side
    """
    n = np.asarray(normal, dtype=float)
    u = np.asarray(velocity_w, dtype=float)
    k = contact_mass_matrix(mass, inertia_w_inv, lever_w)
    un = u @ n
    frictionless: NDArray[np.float64] = -(1.0 + restitution) * un / (n @ k @ n) * n
    if friction == 0.0:
        return frictionless
    j = np.linalg.solve(k, -restitution * un * n - u)  # sticking: u⁺ = −e u_n n
    jn = j @ n
    jt = j - jn * n
    if np.linalg.norm(jt) > friction * jn:
        ut = u - un * n
        if np.linalg.norm(ut) == 0.0:
            return frictionless
        d = n - friction * ut / np.linalg.norm(ut)  # sliding: friction opposes the slip
        j = -(1.0 + restitution) * un / (n @ k @ d) * d
    # Newton's law with friction may add energy at some geometries: then fall back to frictionless.
    energy_change = j @ (u + 0.5 * k @ j)  # ΔT = J·(u⁻ + u⁺)/2
    return j if energy_change <= 0.0 and j @ n > 0.0 else frictionless


# ================================================================================================
# The drop
# ================================================================================================


@dataclass(frozen=True)
class Settling:
    """The box lying on a face from ``t``: in-plane slide and spin braked by Coulomb friction."""

    t: float
    slide_direction_w: NDArray[np.float64]  # unit, horizontal (zero if not sliding)
    slide_decel: float  # μ g, m/s²
    slide_end: float  # when the slide stops, s
    spin_decel: float  # signed ṡ, rad/s² (opposes the spin)
    spin_end: float
    tilt: float  # the small rotation that laid the box flat, rad


@dataclass(eq=False)
class Drop:
    """The drop's body, contact law and contact history (filled while integrating)."""

    body: RigidBody
    size: NDArray[np.float64]
    environment: Environment
    y0: NDArray[np.float64]
    restitution: float
    friction: float
    pulse_duration: float
    rest_speed: float
    settle_tilt: float = np.radians(5.0)
    # (t_c, J_w, lever_b), in time order, never overlapping
    pulses: list[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=list)
    impulses: list[tuple[float, NDArray[np.float64]]] = field(default_factory=list)  # ideal mode: (t_c, J_w)
    settling: Settling | None = None
    recent_contacts: list[float] = field(default_factory=list)  # times of the contacts within the last microsecond
    # The pulses stacked into arrays for _pulse (start times, impulses, levers), rebuilt when one is added.
    _pulse_table: tuple[NDArray[np.float64], ...] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self.corners_b = _corners(self.size)  # (8, 3), body axes

    @classmethod
    def from_spec(cls, spec: DropSpec) -> Drop:
        b, ini, c = spec.body, spec.initial, spec.contact
        env = spec.site.environment()
        inertia = box(b.mass_kg, *b.size_m) if b.inertia_kgm2 is None else np.diag(b.inertia_kgm2)
        body = RigidBody(b.mass_kg, inertia, frame_rate_w=env.earth_rate_w)
        q = quat_from_euler_zyx(np.radians(ini.rpy_deg))
        omega = np.asarray(ini.omega_b) + rotate(rotation_matrix(q).T, env.earth_rate_w)  # inertial rate
        y0 = body.state((0.0, 0.0, ini.height_m), q, ini.vel_w, omega)
        return cls(
            body, np.asarray(b.size_m, float), env, y0, c.restitution, c.friction, c.pulse_duration_s, c.rest_speed_m_s
        )

    @property
    def gravity(self) -> float:
        return float(np.linalg.norm(self.environment.gravity_w))

    @property
    def settle_time(self) -> float:
        return np.inf if self.settling is None else self.settling.t

    # -- loads -----------------------------------------------------------------------------------------

    def _pulse(self, t: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The contact pulse's force at ``t`` (world, N) and its lever arm (body axes), ``t.shape + (3,)``.

        ``F = J π/(2τ) sin(π s)``, ``s = (t − t_c)/τ`` in ``[0, 1]``, so ``∫ F dt = J``. Pulses never
        overlap, so the one that may act at ``t`` is the last to start at or before it.
        """
        t = np.asarray(t, dtype=float)
        if not self.pulses:
            return np.zeros(t.shape + (3,)), np.zeros(t.shape + (3,))
        if self._pulse_table is None or len(self._pulse_table[0]) != len(self.pulses):
            self._pulse_table = tuple(np.array([p[i] for p in self.pulses]) for i in range(3))
        starts, impulses, levers = self._pulse_table
        k = np.searchsorted(starts, t, side="right") - 1
        valid = k >= 0
        kk = np.where(valid, k, 0)
        s = np.where(valid, (t - starts[kk]) / self.pulse_duration, -1.0)
        on = (s >= 0.0) & (s <= 1.0)
        shape = np.where(on, np.pi / (2.0 * self.pulse_duration) * np.sin(np.pi * np.clip(s, 0.0, 1.0)), 0.0)
        return shape[..., None] * impulses[kk], levers[kk]

    def force(
        self,
        t: ArrayLike,
        y: ArrayLike,
        pulse: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> NDArray[np.float64]:
        """Total force, world axes, N: gravity and contact pulses; once settled, gravity and the
        ground's support (holding the box on the ground against weight and Coriolis) and friction.
        ``pulse``: :meth:`_pulse` at ``t`` when the caller has it already."""
        y = np.asarray(y, dtype=float)
        t = np.asarray(t, dtype=float)
        weight = self.body.mass * self.environment.gravity_w
        flying = weight + (self._pulse(t) if pulse is None else pulse)[0]
        if self.settling is None:
            return flying
        st = self.settling
        sliding = ((t >= st.t) & (t < st.slide_end))[..., None]
        friction = np.where(sliding, -self.body.mass * st.slide_decel * st.slide_direction_w, 0.0)  # −μ m g v̂
        settled = 2.0 * cross(self.body.frame_rate_w, y[..., P]) + friction  # so that Ṗ = friction
        return np.where((t >= st.t)[..., None], settled, flying)

    def torque(
        self,
        t: ArrayLike,
        y: ArrayLike,
        pulse: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> NDArray[np.float64]:
        """Moment about the centre of mass, world axes, N m: the pulse's ``r × F``; once settled, the
        ground's moment that keeps the box flat, ``ω × L + I_w (Ω × ω) + ṡ I_w ẑ``, which makes the
        rotation relative to the world ``s ẑ`` with the spin ``s`` braked at the rate ``ṡ``.
        ``pulse``: :meth:`_pulse` at ``t`` when the caller has it already."""
        y = np.asarray(y, dtype=float)
        t = np.asarray(t, dtype=float)
        r = rotation_matrix(y[..., Q])
        pulse_w, lever_b = self._pulse(t) if pulse is None else pulse
        flying = cross(rotate(r, lever_b), pulse_w)  # τ = r × F
        if self.settling is None:
            return flying
        st = self.settling
        inertia_w = r @ self.body.inertia_b @ np.swapaxes(r, -1, -2)
        omega_w = rotate(r, self.body.omega_b(y, r))
        spin_rate = np.where((t >= st.t) & (t < st.spin_end), st.spin_decel, 0.0)
        held = (
            cross(omega_w, y[..., L])
            + rotate(inertia_w, cross(self.body.frame_rate_w, omega_w))
            + spin_rate[..., None] * inertia_w[..., :, 2]
        )  # d/dt (I_w ω) with ω = Ω + s ẑ
        return np.where((t >= st.t)[..., None], held, flying)

    def derivative(self, t: ArrayLike, y: NDArray[np.float64]) -> NDArray[np.float64]:
        pulse = self._pulse(t)  # for the force and its moment alike
        return self.body.derivative(
            t, y, lambda tt, yy: self.force(tt, yy, pulse), lambda tt, yy: self.torque(tt, yy, pulse)
        )

    # -- contacts --------------------------------------------------------------------------------------

    def _contacts_enabled(self, t: float) -> bool:
        if t >= self.settle_time:
            return False
        return not (self.pulses and self.pulses[-1][0] <= t < self.pulses[-1][0] + self.pulse_duration)

    def _corner_heights(self, y: NDArray[np.float64]) -> NDArray[np.float64]:
        r = rotation_matrix(y[Q])
        heights: NDArray[np.float64] = y[2] + self.corners_b @ r[2]  # z + (R r_i)_z
        return heights

    def _corner_condition(self, i: int) -> Callable[[float, NDArray[np.float64]], float]:
        def condition(t: float, y: NDArray[np.float64]) -> float:
            if not self._contacts_enabled(t):
                return 1.0
            height: float = self._corner_heights(y)[i]
            return height

        return condition

    def _corner_velocities(self, y: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.body.point_velocity_w(y, self.corners_b)

    def _pending(self, t: float, y: NDArray[np.float64]) -> bool:
        if not self._contacts_enabled(t):
            return False
        closing = (self._corner_heights(y) <= 0.0) & (self._corner_velocities(y)[:, 2] < 0.0)
        return bool(np.any(closing))

    def _face_down(self, r: NDArray[np.float64]) -> tuple[int, NDArray[np.float64], float]:
        """Index of the body axis most nearly vertical, the outward normal (body axes) of the face that
        points down, and the tilt of that face from horizontal, rad."""
        downness = -r[2]  # world −z component of each body axis
        k = int(np.argmax(np.abs(downness)))
        face_b = np.zeros(3)
        face_b[k] = np.sign(downness[k])
        return k, face_b, float(np.arccos(np.clip(abs(downness[k]), -1.0, 1.0)))

    def _on_contact(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64] | Jumped:
        """The contact action: settle, an ideal impulse, or the start of a pulse."""
        heights = self._corner_heights(y)
        speeds = self._corner_velocities(y)
        # Closing corners at the ground (or in it, after a pulse), or tied with the lowest one.
        touching = (heights <= max(heights.min(), 0.0) + TIE_M) & (speeds[:, 2] < 0.0)
        if not np.any(touching):
            return y
        r = rotation_matrix(y[Q])
        _, _, tilt = self._face_down(r)
        self.recent_contacts = [tc for tc in self.recent_contacts if tc > t - 1e-6] + [t]
        if tilt < self.settle_tilt and (
            self.bounce_energy(y) < self.body.mass * self.rest_speed**2 / 2.0 or len(self.recent_contacts) > 100
        ):
            return self._settle(t, y)
        lever_b = self.corners_b[touching].mean(axis=0)
        lever_w = rotate(r, lever_b)
        u = self.body.point_velocity_w(y, lever_b)  # contact point velocity (scribe notes)
        j = contact_impulse(self.body.mass, self.body.inertia_w_inv(r), lever_w, u, self.restitution, self.friction)
        if self.pulse_duration > 0.0:
            self.pulses.append((t, j, lever_b))
            return Jumped(y, breakpoints=(t + self.pulse_duration,))
        self.impulses.append((t, j))
        return self.body.apply_impulse(y, j, y[X] + lever_w)  # ΔP = J, ΔL = r × J

    def bounce_energy(self, y: NDArray[np.float64]) -> float:
        """Energy of the motion out of lying flat: ``½ m v_z² + ½ ω_hᵀ I_w ω_h + m g (z − z_face)``, with
        ``ω_h`` the horizontal part of the rotation relative to the world and ``z_face`` the height of
        the centre of mass lying on the face that points down, J."""
        r = rotation_matrix(y[Q])
        k, _, _ = self._face_down(r)
        omega_h = self.body.omega_wb_w(y, r) * np.array([1.0, 1.0, 0.0])
        inertia_w = r @ self.body.inertia_b @ r.T
        v_z = y[P][2] / self.body.mass
        return float(
            0.5 * self.body.mass * v_z**2
            + 0.5 * omega_h @ inertia_w @ omega_h
            + self.body.mass * self.gravity * (y[2] - 0.5 * self.size[k])
        )

    def _settle(self, t: float, y: NDArray[np.float64]) -> Jumped:
        """Lay the box flat on its downward face (a rotation by the small remaining tilt), on the ground,
        keeping its in-plane slide and spin, which friction then brakes at constant rates."""
        r = rotation_matrix(y[Q])
        k, face_b, tilt = self._face_down(r)
        face_w = r @ face_b
        down = np.array([0.0, 0.0, -1.0])
        axis = cross(face_w, down)
        fix = quat_from_rotvec(axis / np.linalg.norm(axis) * tilt) if tilt > 0 else np.array([1.0, 0.0, 0.0, 0.0])
        q = quat_product(fix, y[Q])
        r = rotation_matrix(q)
        spin = float(self.body.omega_wb_w(y, r)[2])  # s: rotation about the vertical, kept
        v = self.body.velocity(y) * np.array([1.0, 1.0, 0.0])  # horizontal slide, kept
        speed = float(np.linalg.norm(v))
        mu_g = self.friction * self.gravity
        # Pivoting friction: uniform pressure on the face, torque μ m g ρ̄ with ρ̄ the face's mean radius.
        sides = np.delete(self.size, k)
        grid = (np.arange(64) + 0.5) / 64 - 0.5
        # np.mean's result is a float64 already; np.float64() types it as one (numpy's stubs say floating).
        rho = np.float64(np.mean(np.hypot(*np.meshgrid(grid * sides[0], grid * sides[1]))))
        i_vertical = float(face_b @ self.body.inertia_b @ face_b)
        spin_decel = self.friction * self.body.mass * self.gravity * rho / i_vertical
        self.settling = Settling(
            t=t,
            slide_direction_w=v / speed if speed > 0 else np.zeros(3),
            slide_decel=mu_g,
            slide_end=t + (speed / mu_g if mu_g > 0 else np.inf),
            spin_decel=-np.sign(spin) * spin_decel,
            spin_end=t + (abs(spin) / spin_decel if spin_decel > 0 else np.inf),
            tilt=tilt,
        )
        pos = np.array([y[0], y[1], 0.5 * self.size[k]])
        omega_b = rotate(r.T, self.body.frame_rate_w + np.array([0.0, 0.0, spin]))
        stops = (Jump(self.settling.slide_end, self._stop_slide), Jump(self.settling.spin_end, self._stop_spin))
        return Jumped(self.body.state(pos, q, v, omega_b), jumps=stops)

    def _stop_slide(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Friction has braked the slide to zero: clear the integrator's residue (about rtol of it)."""
        y = np.array(y)
        y[P] = 0.0
        return y

    def _stop_spin(self, t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        """The spin is braked to zero: the box turns with the Earth only (clears the residue)."""
        r = rotation_matrix(y[Q])
        return self.body.state(y[X], y[Q], y[P] / self.body.mass, rotate(r.T, self.body.frame_rate_w))

    def events(self) -> list[Event]:
        """One falling-height event per corner."""
        return [
            Event(self._corner_condition(i), self._on_contact, -1.0, self._pending if i == 0 else None)
            for i in range(8)
        ]

    # -- simulation ----------------------------------------------------------------------------------

    def solve(self, t: ArrayLike, rtol: float = 1e-10) -> Solution:
        self.pulses, self.impulses, self.settling, self.recent_contacts = [], [], None, []
        self._pulse_table = None
        atol = np.concatenate([np.full(3, 1e-12), np.full(4, 1e-12), np.full(6, 1e-14)])
        return integrate(self.derivative, t, self.y0, events=self.events(), rtol=rtol, atol=atol)

    def trajectory(self, t: ArrayLike, rtol: float = 1e-10) -> Trajectory:
        t = np.asarray(t, dtype=float)
        sol = self.solve(t, rtol)
        y, y_dot = sol.y, sol.y_dot
        pulse = self._pulse(t)
        force = self.force(t, y, pulse)
        _, omega, alpha = self.body.accelerations(t, y, lambda *_: force, lambda tt, yy: self.torque(tt, yy, pulse))
        weight = self.body.mass * self.environment.gravity_w
        extras = {
            "contact_force_w": force - weight,
            "settled": t >= self.settle_time,
        }
        if self.pulse_duration == 0.0:
            impulse = np.zeros((t.size, 3))
            for t_c, j in self.impulses:
                k = min(int(np.searchsorted(t, t_c, side="left")), t.size - 1)  # interval (t_{k-1}, t_k]
                impulse[k] += j
            extras["contact_impulse_w"] = impulse
        return world_motion_trajectory(
            t,
            y[:, X],
            y[:, Q],
            y[:, P] / self.body.mass,
            y_dot[:, P] / self.body.mass,
            omega,
            alpha,
            self.environment,
            extras,
        )
