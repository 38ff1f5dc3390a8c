"""A gyrostat: a rigid body carrying spinning rotors, fixed or on gimbals (control-moment gyros).

Model (Hughes, *Spacecraft Attitude Dynamics*, ch. 5 and 8; Wie, *Space Vehicle Dynamics and
Control*, 2nd ed., §7.3; the lecture's control-moment gyroscope and ship anti-roll gyro)
--------------------------------------------------------------------------------------------------
The body carries rotors, each an axisymmetric wheel with spin moment of inertia ``J`` spinning at
``Ω(t)`` relative to the body about its axis ``ŝ``. A rotor's angular momentum relative to the body is
``J Ω ŝ``; their sum is ``h``. The whole system's angular momentum about its centre of mass is
``H = I ω + h`` (body axes), ``I`` being the inertia of body and rotors together with the rotors
*locked*, and Euler's equation for the system reads (body axes, ``ω`` inertial)::

    d/dt (I ω + h) + ω × (I ω + h) = τ          =>   I ω̇ = τ − ω × (I ω + h) − ḣ

* **Fixed-axis rotors** (reaction or momentum wheels, spin-up): ``ŝ`` fixed in the body,
  ``h = J Ω(t) ŝ``, ``ḣ = J Ω̇(t) ŝ`` with the spin profile prescribed (:class:`SpinProfile`).
* **Gimballed rotors** (single-gimbal control-moment gyros, ship gyrostabilisers): the rotor's spin
  axis turns about the gimbal axis ``ĝ`` (fixed in the body, ``ĝ ⟂ ŝ``) by the gimbal angle ``δ``:
  ``ŝ(δ) = cos δ ŝ₀ + sin δ (ĝ × ŝ₀)``, so ``ḣ = J Ω̇ ŝ + J Ω δ̇ (ĝ × ŝ)``. The gimbal angles are
  states, driven by commanded gimbal rates ``δ̇ = u(t, y)`` (an ideal rate servo: the gimbal motor
  supplies whatever torque holds the commanded rate).

What is lumped (the usual CMG model, Wie §7.3.1):

* ``I`` is constant: each rotor-and-gimbal assembly is taken as inertially symmetric about its
  gimbal axis, so turning it leaves the system's inertia unchanged. A real CMG's transverse and spin
  inertias differ; the neglected change of ``I`` is of order ``(J_t − J) δ̇``-driven torques, about
  ``J_t/J · δ̇/Ω`` (1e-4) of the gyroscopic torque ``J Ω δ̇``.
* The assemblies' own momentum about their gimbal axes, ``J_g δ̇ ĝ``, is not in ``h`` (again about
  ``J_g δ̇ / (J Ω)``, 1e-4, of the rotor's momentum); so commanded rates may switch instantly.

Within this model everything is exact: with no external torque the total angular momentum
``R (I ω + h)`` (inertial, world axes) is constant while rotors spin up and gimbals turn, which the
tests check, and ``α_b = ω̇`` at a sample is evaluated from the equation, not differenced.

State layout, ``(..., 13 + n_gimbals)``::

    x (3) world position of the centre of mass, m      q (4) attitude q_wb
    P (3) linear momentum m v, world, kg m/s            ω (3) inertial angular velocity, body axes, rad/s
    δ (n_gimbals) gimbal angles, rad

Translation is that of :mod:`gyroemu.dynamics.rigid_body` (``ẋ = P/m``, ``Ṗ = F − 2 Ω × P``); attitude
follows ``q̇ = ½ q ⊗ (0, ω − Rᵀ Ω)``, ``Ω`` the world frame's rotation relative to inertial space.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .body_kernels import cross, pure_quat, quat_product, rotate, rotate_back, rotation_matrix, stack_state
from .inertia import check_inertia

__all__ = ["SpinProfile", "Rotor", "GimballedRotor", "Gyrostat", "X", "Q", "P", "W", "GIMBALS"]

X = slice(0, 3)
Q = slice(3, 7)
P = slice(7, 10)
W = slice(10, 13)
GIMBALS = slice(13, None)

_Load = Callable[[ArrayLike, NDArray[np.float64]], NDArray[np.float64]]
"""``f(t, y) -> (..., k)``: a force, a torque or the gimbals' commanded rates at states ``y``."""


def _gimbal_axes(
    delta: ArrayLike, spin0: NDArray[np.float64], transverse: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Spin and output axes of gimballed rotors turned by ``δ``: ``ŝ(δ) = cos δ ŝ₀ + sin δ (ĝ × ŝ₀)`` and
    ``ĝ × ŝ(δ) = dŝ/dδ = cos δ (ĝ × ŝ₀) − sin δ ŝ₀``, shapes ``δ.shape + (3,)``. ``spin0`` and
    ``transverse`` (``ŝ₀``, ``ĝ × ŝ₀``) are (3,) for one rotor or (n_gimbals, 3) stacked."""
    d = np.asarray(delta, dtype=float)[..., None]
    c, s = np.cos(d), np.sin(d)
    return c * spin0 + s * transverse, c * transverse - s * spin0


def _unit(v: ArrayLike, name: str) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=float).reshape(3)
    n = np.linalg.norm(v)
    if not n > 0:
        raise ValueError(f"{name} must be a non-zero vector")
    unit: NDArray[np.float64] = v / n
    return unit


@dataclass(frozen=True)
class SpinProfile:
    """A rotor's spin rate relative to the body: ``rate0`` until ``t_start``, then a cosine ramp to
    ``rate1`` over ``duration`` s, then ``rate1``.

    ``Ω(t) = Ω₀ + (Ω₁ − Ω₀) (1 − cos πs)/2``, ``s = (t − t_start)/duration`` in ``[0, 1]``: the spin
    acceleration ``Ω̇ = (Ω₁ − Ω₀) π/(2 T) sin πs`` is continuous and zero at both ends (a motor's
    soft start). Rates in rad/s.
    """

    rate0: float
    rate1: float | None = None
    t_start: float = 0.0
    duration: float = 0.0

    @property
    def final(self) -> float:
        return self.rate0 if self.rate1 is None else self.rate1

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times where ``Ω̈`` jumps (the solver stops there)."""
        if self.rate1 is None or self.rate1 == self.rate0:
            return ()
        return (self.t_start, self.t_start + self.duration)

    def _s(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        if self.duration <= 0:
            return np.where(t >= self.t_start, 1.0, 0.0)
        return np.clip((t - self.t_start) / self.duration, 0.0, 1.0)

    def rate(self, t: ArrayLike) -> NDArray[np.float64]:
        """``Ω(t)``, rad/s, shape of ``t``."""
        s = self._s(t)
        return self.rate0 + (self.final - self.rate0) * 0.5 * (1.0 - np.cos(np.pi * s))

    def accel(self, t: ArrayLike) -> NDArray[np.float64]:
        """``Ω̇(t)``, rad/s² (zero for a step, whose jump the solver meets at a breakpoint)."""
        if self.duration <= 0 or self.final == self.rate0:
            return np.zeros(np.shape(t))
        s = self._s(t)
        return (self.final - self.rate0) * np.pi / (2.0 * self.duration) * np.sin(np.pi * s)


@dataclass(frozen=True)
class Rotor:
    """A rotor on an axis fixed in the body.

    Attributes
    ----------
    axis_b : (3,) spin axis, body axes (normalised)
    inertia_kgm2 : float, ``J``, the rotor's moment of inertia about its spin axis
    spin : SpinProfile, spin rate relative to the body
    """

    axis_b: NDArray[np.float64]
    inertia_kgm2: float
    spin: SpinProfile

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis_b", _unit(self.axis_b, "rotor axis"))

    def momentum_b(self, t: ArrayLike) -> NDArray[np.float64]:
        """``h = J Ω(t) ŝ``, shape ``t.shape + (3,)``, N m s."""
        return (self.inertia_kgm2 * self.spin.rate(t))[..., None] * self.axis_b

    def momentum_rate_b(self, t: ArrayLike) -> NDArray[np.float64]:
        """``ḣ = J Ω̇(t) ŝ`` (relative to the body)."""
        return (self.inertia_kgm2 * self.spin.accel(t))[..., None] * self.axis_b


@dataclass(frozen=True)
class GimballedRotor:
    """A rotor on a single gimbal (a control-moment gyro).

    Attributes
    ----------
    gimbal_axis_b : (3,) gimbal axis ``ĝ``, body axes
    spin_axis_b : (3,) spin axis ``ŝ₀`` at zero gimbal angle, perpendicular to ``ĝ``
    inertia_kgm2 : float, ``J`` about the spin axis
    spin : SpinProfile
    """

    gimbal_axis_b: NDArray[np.float64]
    spin_axis_b: NDArray[np.float64]
    inertia_kgm2: float
    spin: SpinProfile

    def __post_init__(self) -> None:
        g = _unit(self.gimbal_axis_b, "gimbal axis")
        s = _unit(self.spin_axis_b, "spin axis")
        if abs(g @ s) > 1e-9:
            raise ValueError("a gimbal's spin axis must be perpendicular to its gimbal axis")
        object.__setattr__(self, "gimbal_axis_b", g)
        object.__setattr__(self, "spin_axis_b", s)

    @property
    def transverse_b(self) -> NDArray[np.float64]:
        """``ĝ × ŝ₀``: where the spin axis points at ``δ = +90°``."""
        return np.cross(self.gimbal_axis_b, self.spin_axis_b)

    def spin_axis(self, delta: ArrayLike) -> NDArray[np.float64]:
        """``ŝ(δ) = cos δ ŝ₀ + sin δ (ĝ × ŝ₀)``, shape ``δ.shape + (3,)``."""
        return _gimbal_axes(delta, self.spin_axis_b, self.transverse_b)[0]

    def torque_axis(self, delta: ArrayLike) -> NDArray[np.float64]:
        """``ĝ × ŝ(δ) = dŝ/dδ``: the direction of ``ḣ`` for a gimbal rate (the output axis)."""
        return _gimbal_axes(delta, self.spin_axis_b, self.transverse_b)[1]


@dataclass(frozen=True, eq=False)
class Gyrostat:
    """A rigid body with rotors: mass properties, rotors, and the equations of motion (module doc).

    Attributes
    ----------
    mass : float, kg (the whole system)
    inertia_b : (3, 3) inertia of body and locked rotors about the centre of mass, body axes, kg m²
    rotors : tuple of Rotor
    gimbals : tuple of GimballedRotor
    frame_rate_w : (3,) ``Ω``, the world frame's rotation relative to inertial space, rad/s
    """

    mass: float
    inertia_b: NDArray[np.float64]
    rotors: Sequence[Rotor] = ()
    gimbals: Sequence[GimballedRotor] = ()
    frame_rate_w: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    if TYPE_CHECKING:  # set by __post_init__; declared for the type checker only, not dataclass fields
        _inertia_inv: NDArray[np.float64] = field(init=False, repr=False)
        _rotating: bool = field(init=False, repr=False)
        _s0: NDArray[np.float64] = field(init=False, repr=False)
        _t0: NDArray[np.float64] = field(init=False, repr=False)
        _j: NDArray[np.float64] = field(init=False, repr=False)
        _jw_constant: NDArray[np.float64] | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.mass > 0:
            raise ValueError(f"mass must be positive, got {self.mass}")
        object.__setattr__(self, "inertia_b", check_inertia(self.inertia_b))
        object.__setattr__(self, "_inertia_inv", np.linalg.inv(self.inertia_b))
        object.__setattr__(self, "rotors", tuple(self.rotors))
        object.__setattr__(self, "gimbals", tuple(self.gimbals))
        object.__setattr__(self, "frame_rate_w", np.asarray(self.frame_rate_w, dtype=float).reshape(3))
        object.__setattr__(self, "_rotating", bool(np.any(self.frame_rate_w != 0)))
        g = self.gimbals
        # Gimbal geometry stacked (n_gimbals, 3) for vectorised evaluation.
        object.__setattr__(self, "_s0", np.array([r.spin_axis_b for r in g]).reshape(-1, 3))
        object.__setattr__(self, "_t0", np.array([r.transverse_b for r in g]).reshape(-1, 3))
        object.__setattr__(self, "_j", np.array([r.inertia_kgm2 for r in g], dtype=float))
        # Constant spins (the usual CMG) skip evaluating profiles on the hot path.
        constant = all(r.spin.rate1 is None or r.spin.rate1 == r.spin.rate0 for r in g)
        object.__setattr__(self, "_jw_constant", self._j * np.array([r.spin.rate0 for r in g]) if constant else None)

    @property
    def size(self) -> int:
        """Length of the state vector."""
        return 13 + len(self.gimbals)

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times where a spin profile's acceleration has a kink."""
        rotors: tuple[Rotor | GimballedRotor, ...] = (*self.rotors, *self.gimbals)
        return tuple(sorted({b for r in rotors for b in r.spin.breakpoints}))

    def state(
        self,
        pos_w: ArrayLike = (0, 0, 0),
        q_wb: ArrayLike = (1, 0, 0, 0),
        vel_w: ArrayLike = (0, 0, 0),
        omega_b: ArrayLike = (0, 0, 0),
        gimbal_angles: ArrayLike = (),
    ) -> NDArray[np.float64]:
        """State vector ``[x, q, P, ω, δ]`` (1-D)."""
        q = np.asarray(q_wb, dtype=float)
        delta = np.asarray(gimbal_angles, dtype=float).reshape(-1)
        if delta.size != len(self.gimbals):
            raise ValueError(f"need {len(self.gimbals)} gimbal angles, got {delta.size}")
        return np.concatenate(
            [
                np.asarray(pos_w, float),
                q / np.linalg.norm(q),
                self.mass * np.asarray(vel_w, float),
                np.asarray(omega_b, float),
                delta,
            ]
        )

    # -- rotor momentum ------------------------------------------------------------------------------

    def _gimbal_spin_rates(
        self, t: ArrayLike, shape: tuple[int, ...]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``J Ω`` and ``J Ω̇`` of each gimballed rotor, shape ``shape + (n_gimbals,)``."""
        if self._jw_constant is not None:
            return self._jw_constant, np.zeros(len(self.gimbals))
        t = np.broadcast_to(np.asarray(t, dtype=float), shape)
        jw = np.stack([r.inertia_kgm2 * r.spin.rate(t) for r in self.gimbals], axis=-1)
        jw_dot = np.stack([r.inertia_kgm2 * r.spin.accel(t) for r in self.gimbals], axis=-1)
        return jw, jw_dot

    def spin_axes(self, delta: ArrayLike) -> NDArray[np.float64]:
        """``ŝ_i(δ_i)`` of every gimballed rotor, shape ``δ.shape + (3,)``."""
        return _gimbal_axes(delta, self._s0, self._t0)[0]

    def torque_axes(self, delta: ArrayLike) -> NDArray[np.float64]:
        """``ĝ_i × ŝ_i(δ_i)``, shape ``δ.shape + (3,)``."""
        return _gimbal_axes(delta, self._s0, self._t0)[1]

    @overload
    def rotor_momentum_b(self, t: ArrayLike, y: ArrayLike, gimbal_rates: None = None) -> NDArray[np.float64]: ...

    @overload
    def rotor_momentum_b(
        self, t: ArrayLike, y: ArrayLike, gimbal_rates: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...

    def rotor_momentum_b(
        self, t: ArrayLike, y: ArrayLike, gimbal_rates: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Rotors' momentum relative to the body ``h`` and, when ``gimbal_rates`` is given, ``ḣ``.

        ``h = Σ J Ω ŝ``; ``ḣ = Σ (J Ω̇ ŝ + J Ω δ̇ (ĝ × ŝ))``. Shapes ``y.shape[:-1] + (3,)``.
        """
        y = np.asarray(y, dtype=float)
        lead = y.shape[:-1]
        h = np.zeros(lead + (3,))
        h_dot = np.zeros(lead + (3,))
        for rotor in self.rotors:  # fixed axes
            h = h + rotor.momentum_b(np.broadcast_to(t, lead))
            h_dot = h_dot + rotor.momentum_rate_b(np.broadcast_to(t, lead))
        if self.gimbals:
            delta = y[..., GIMBALS]
            jw, jw_dot = self._gimbal_spin_rates(t, lead)
            s, output = _gimbal_axes(delta, self._s0, self._t0)  # ŝ, ĝ×ŝ
            h = h + np.matmul(jw[..., None, :], s)[..., 0, :]  # Σ J Ω ŝ
            if gimbal_rates is not None:
                spin_up = np.matmul(jw_dot[..., None, :], s)[..., 0, :]  # Σ J Ω̇ ŝ
                turning = np.matmul((jw * gimbal_rates)[..., None, :], output)[..., 0, :]  # Σ J Ω δ̇ ĝ×ŝ
                h_dot = h_dot + spin_up + turning
        return (h, h_dot) if gimbal_rates is not None else h

    def gimbal_jacobian(self, t: ArrayLike, delta: ArrayLike) -> NDArray[np.float64]:
        """``A = ∂h/∂δ``, columns ``J_i Ω_i (ĝ_i × ŝ_i)``: shape ``δ.shape[:-1] + (3, n_gimbals)``, so that
        the gimbals' share of ``ḣ`` is ``A δ̇``."""
        delta = np.asarray(delta, dtype=float)
        jw, _ = self._gimbal_spin_rates(t, delta.shape[:-1])
        return np.swapaxes(jw[..., None] * self.torque_axes(delta), -1, -2)

    def angular_momentum_w(self, t: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """Total angular momentum ``R (I ω + h)``, inertial, world axes, N m s."""
        y = np.asarray(y, dtype=float)
        r = rotation_matrix(y[..., Q])
        return rotate(r, y[..., W] @ self.inertia_b.T + self.rotor_momentum_b(t, y))

    def kinetic_energy(self, t: ArrayLike, y: ArrayLike) -> float | NDArray[np.float64]:
        """Body-and-locked-rotor kinetic energy ``½ m v² + ½ ω·Iω`` (rotor spin energy excluded), J."""
        y = np.asarray(y, dtype=float)
        w = y[..., W]
        energy: float | NDArray[np.float64] = 0.5 * np.sum(y[..., P] ** 2, -1) / self.mass + 0.5 * np.einsum(
            "...i,ij,...j->...", w, self.inertia_b, w
        )
        return energy

    # -- equations of motion -----------------------------------------------------------------------

    def derivative(
        self,
        t: ArrayLike,
        y: ArrayLike,
        force_w: _Load | None = None,
        torque_b: _Load | None = None,
        gimbal_rate: _Load | None = None,
    ) -> NDArray[np.float64]:
        """``ẏ`` for states ``(..., size)``.

        Parameters
        ----------
        force_w : callable (t, y) -> (..., 3), optional
            Total external force (gravity included), world axes, N.
        torque_b : callable (t, y) -> (..., 3), optional
            External torque about the centre of mass, *body* axes, N m.
        gimbal_rate : callable (t, y) -> (..., n_gimbals), optional
            Commanded gimbal rates, rad/s (zero when omitted).
        """
        y = np.asarray(y, dtype=float)
        lead = y.shape[:-1]
        q, omega = y[..., Q], y[..., W]
        delta_dot = np.zeros(lead + (len(self.gimbals),)) if gimbal_rate is None else gimbal_rate(t, y)
        h, h_dot = self.rotor_momentum_b(t, y, delta_dot)
        tau = np.zeros(lead + (3,)) if torque_b is None else torque_b(t, y)
        f = np.zeros(lead + (3,)) if force_w is None else force_w(t, y)
        big_h = omega @ self.inertia_b.T + h  # H = I ω + h
        omega_dot = (tau - cross(omega, big_h) - h_dot) @ self._inertia_inv.T  # I ω̇ = τ − ω×H − ḣ
        omega_wb = omega - rotate_back(rotation_matrix(q), self.frame_rate_w) if self._rotating else omega  # to world
        q_dot = 0.5 * quat_product(q, pure_quat(omega_wb))  # q̇ = ½ q ⊗ ω_b
        x_dot = y[..., P] / self.mass  # ẋ = P/m
        p_dot = np.asarray(f, dtype=float)  # Ṗ = F − 2Ω×P
        if self._rotating:
            p_dot = p_dot - 2.0 * cross(self.frame_rate_w, y[..., P])
        return stack_state(lead, [x_dot, q_dot, p_dot, omega_dot, np.asarray(delta_dot, dtype=float)])
