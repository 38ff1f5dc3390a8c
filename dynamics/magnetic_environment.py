"""The magnetic environment of a site: a field that varies with position, and a turned working volume.

A ``[site.magnetic_environment]`` table (:class:`MagneticEnvironmentSpec`) makes the site's field
depend on where the body is, as indoors, near steel, on a bench::

    B(p) = R_z(w(p) ψ) B₀ + δ(p) + Σ_k B_dipole,k(p)                     (world axes, tesla)

* ``B₀``, the **reference field**: the site's ``magnetic_field_enu_uT``, with its norm and dip
  replaced by ``norm_uT`` and ``dip_deg`` when given, its declination kept (:func:`reference_field`).
  Dip is positive downward (a field with a negative up-component, as north of the magnetic
  equator), declination ``D = atan2(B_E, B_N)`` east of north. A purely vertical field has no
  declination: one given a dip is then put in the north-up plane (``D = 0``).
* ``ψ``, the **heading offset**: the field in the working volume is turned about the vertical (world
  +z, up; a positive ``ψ`` turns it counter-clockwise seen from above, i.e. lowers the declination
  by ``ψ``) relative to the field at the rest position ``p₀``, the trajectory's first position.
  ``ψ ~ N(heading_offset_mean_deg, heading_offset_sigma_deg²)``, drawn once per realisation. The turn
  sets in away from the rest position with the weight ``w(p) = 1 − exp(−|p − p₀|² / (2 s²))``,
  ``s = transition_m``: ``B(p₀) = B₀ + δ(p₀)`` exactly, and ``R_z(ψ) B₀ + δ(p)`` beyond a few ``s``.
* ``δ(p)``, the **spatial variation**: three independent zero-mean Gaussian random fields of
  position (one per world axis), stationary, of covariance

      E[δ_i(p) δ_j(p + d)] = σ² exp(−|d|² / (2 ℓ²)) [i = j],     σ = spatial_sigma_uT, ℓ = correlation_length_m.

* ``B_dipole,k``, **dipoles** fixed in the world (``[[site.magnetic_environment.dipoles]]``, a
  magnet near the working volume; :mod:`gyroemu.dynamics.dipole`). They draw nothing at random.

How δ is sampled: random Fourier features
-----------------------------------------
A path of 10⁶ samples rules out the N×N covariance. Following Rahimi and Recht (NIPS 2007), the
squared-exponential kernel is the characteristic function of its spectral density,
``exp(−|d|²/(2ℓ²)) = E_ω[cos(ω·d)]`` with ``ω ~ N(0, I/ℓ²)`` (rad/m), so with ``M`` wavevectors
``ω_m`` drawn once per realisation and coefficients ``a_m, c_m ~ N(0, 1)`` (per axis)::

    δ_i(p) = σ / √M · Σ_m (a_im cos(ω_m·p) + c_im sin(ω_m·p)),      M = FEATURES = 512.

Given the wavevectors, ``δ`` is exactly a Gaussian field, exactly stationary, with variance exactly
``σ²`` at every position (``cos² + sin² = 1``) and correlation at lag ``d``

    ρ̂(d) = (1/M) Σ_m cos(ω_m·d),   E ρ̂(d) = ρ(d) = exp(−|d|²/(2ℓ²)),
    std ρ̂(d) = sqrt(((1 + ρ(d)⁴)/2 − ρ(d)²) / M)        (Var cos X = (1 + E cos 2X)/2 − (E cos X)²)

so a realisation's correlation departs from the closed form by 0.020 at ``d = ℓ`` (0.031 for
``d ≫ ℓ``, where ρ = 0) at ``M = 512``; averaged over realisations it is the closed form (and the
field's covariance, over the wavevectors too, is exactly ``σ² ρ(d)``).

The sums are compiled (:func:`_features`): each position is split into the nearest point of a lattice
and a short offset, the anchor's sines and cosines come from libm once per anchor a path enters, the
offset's from a Taylor series; they agree with the direct sums to round-off (``10⁻¹⁷ T`` for
``σ = 1 µT``). Measured on two shared cores: 1.3–2.5 s for 10⁶ positions of a slow path (3–5 ns
per position and feature), against 15–34 s for the direct numpy sums; a path that enters a new
anchor cell at every sample (fast motion, short ``ℓ``) costs ``M`` libm calls per sample, ~15 µs.

The field is a function of position alone: a path that comes back to a place reads the same field
there, whatever the time (the same bits, as measured here: each position goes through the same
operations, whichever samples surround it). Every draw comes from one seeded generator (``seed``, or the caller's), in
a fixed order: ``ψ`` first, then the wavevectors and coefficients, so the heading offset of a seed
does not change with the spatial settings.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from .config import NonNegativeReal, PositiveReal, Real, Section
from .dipole import DipoleSpec, dipole_field
from .jit import njit
from .rotation import quat_conjugate, quat_from_rotvec, quat_rotate

if TYPE_CHECKING:
    from .trajectory import Trajectory

__all__ = [
    "FEATURES",
    "MagneticEnvironmentSpec",
    "MagneticRealisation",
    "reference_field",
    "draw_realisation",
    "field_along_path",
    "with_magnetic_environment",
]

FEATURES = 512
"""Random Fourier features ``M`` per realisation (correlation error std ``≈ 0.7/√M``, see the notes)."""


class MagneticEnvironmentSpec(Section):
    """``[site.magnetic_environment]``: how the site's field varies over the working volume.

    Every key is optional; the defaults leave the field uniform and unturned.
    """

    spatial_sigma_uT: NonNegativeReal = 0.0
    """Per-axis standard deviation of the smooth random spatial variation ``δ(p)``, µT."""
    correlation_length_m: PositiveReal = 1.0
    """``ℓ`` of its squared-exponential covariance ``σ² exp(−|d|²/(2ℓ²))``, m."""
    heading_offset_mean_deg: Real = 0.0
    """Mean of the turn ``ψ`` of the working volume's field about the vertical, deg."""
    heading_offset_sigma_deg: NonNegativeReal = 0.0
    """Standard deviation of ``ψ`` over realisations, deg."""
    transition_m: PositiveReal = 0.3
    """``s`` of the turn's weight ``1 − exp(−|p − p₀|²/(2s²))`` around the rest position, m."""
    seed: int = 0
    """Seed of the realisation (``ψ`` and ``δ``)."""
    norm_uT: PositiveReal | None = None
    """Replaces the norm of the site's ``magnetic_field_enu_uT`` (declination and dip kept), µT."""
    dip_deg: Annotated[Real, Field(ge=-90.0, le=90.0)] | None = None
    """Replaces its dip (inclination, positive downward; declination and norm kept), deg."""
    dipoles: tuple[DipoleSpec, ...] = ()
    """Point dipoles fixed in the world, each ``{position_m, moment_A_m2}``."""


@dataclass(frozen=True, eq=False)
class MagneticRealisation:
    """One draw of a magnetic environment: ``B(p) = R_z(w(p) ψ) B₀ + δ(p)`` (module notes).

    Attributes
    ----------
    reference_w : ndarray (3,)
        ``B₀``, tesla, world (ENU) axes.
    rest_w : ndarray (3,)
        ``p₀``, the rest position, m.
    heading_offset_rad : float
        ``ψ``, rad, about world +z.
    transition_m : float
        ``s``, m.
    wavevectors : ndarray (M, 3)
        ``ω_m``, rad/m (M = 0 when the field has no spatial variation).
    cos_weights, sin_weights : ndarray (M, 3)
        ``σ a_im / √M`` and ``σ c_im / √M``, tesla.
    dipoles : tuple of DipoleSpec
        Point dipoles fixed in the world.
    """

    reference_w: NDArray[np.float64]
    rest_w: NDArray[np.float64]
    heading_offset_rad: float
    transition_m: float
    wavevectors: NDArray[np.float64]
    cos_weights: NDArray[np.float64]
    sin_weights: NDArray[np.float64]
    dipoles: tuple[DipoleSpec, ...] = ()

    def variation(self, pos_w: ArrayLike) -> NDArray[np.float64]:
        """``δ(p)`` at positions ``pos_w`` (N, 3), m: (N, 3), tesla."""
        pos = np.asarray(pos_w, dtype=float).reshape(-1, 3)
        out = np.zeros((len(pos), 3))
        if len(self.wavevectors) == 0 or len(pos) == 0:
            return out
        w = np.ascontiguousarray(self.wavevectors)
        # Anchor lattice spacing h with |ω_m·r| ≤ max|ω| (√3/2) h = 1/2 for every offset r from the
        # nearest anchor (the Taylor series of _features converge there to round-off).
        spacing = 1.0 / (math.sqrt(3.0) * float(np.max(np.linalg.norm(w, axis=1))))
        _features(
            np.ascontiguousarray(pos),
            np.ascontiguousarray(w.T),  # (3, M): the feature loop reads each row contiguously
            np.ascontiguousarray(self.cos_weights.T),
            np.ascontiguousarray(self.sin_weights.T),
            spacing,
            out,
        )
        return out

    def turned_reference(self, pos_w: ArrayLike) -> NDArray[np.float64]:
        """``R_z(w(p) ψ) B₀`` at positions ``pos_w`` (N, 3), m: (N, 3), tesla."""
        pos = np.asarray(pos_w, dtype=float).reshape(-1, 3)
        if self.heading_offset_rad == 0.0:
            return np.broadcast_to(self.reference_w, pos.shape).copy()
        r2 = np.sum((pos - self.rest_w) ** 2, axis=1)
        weight = -np.expm1(-r2 / (2.0 * self.transition_m**2))  # w(p) = 1 − exp(−|p − p₀|²/(2s²))
        turn = quat_from_rotvec((weight * self.heading_offset_rad)[:, None] * np.array([0.0, 0.0, 1.0]))
        return quat_rotate(turn, self.reference_w)

    def field(self, pos_w: ArrayLike) -> NDArray[np.float64]:
        """``B(p)`` at positions ``pos_w`` (N, 3), m, world axes: (N, 3), tesla."""
        field = self.turned_reference(pos_w) + self.variation(pos_w)
        for d in self.dipoles:
            field += dipole_field(pos_w, d.position_m, d.moment_A_m2)
        return field


def reference_field(spec: MagneticEnvironmentSpec, field_enu_T: ArrayLike) -> NDArray[np.float64]:
    """``B₀``: the site's field (3,), tesla, with the spec's ``norm_uT`` and ``dip_deg`` put in.

    Declination kept: ``D = atan2(B_E, B_N)``; with ``F`` the norm and ``I`` the dip (positive
    down), ``B₀ = F (cos I sin D, cos I cos D, −sin I)``. Without either key, ``field_enu_T``
    itself (a copy). A field that already has the spec's norm and dip changes by round-off only.
    """
    b = np.array(field_enu_T, dtype=float).reshape(3)
    if spec.norm_uT is None and spec.dip_deg is None:
        return b
    horizontal = math.hypot(b[0], b[1])
    norm = spec.norm_uT * 1e-6 if spec.norm_uT is not None else float(np.linalg.norm(b))
    dip = math.radians(spec.dip_deg) if spec.dip_deg is not None else math.atan2(-b[2], horizontal)
    declination = math.atan2(b[0], b[1]) if horizontal > 0 else 0.0
    return norm * np.array(
        [math.cos(dip) * math.sin(declination), math.cos(dip) * math.cos(declination), -math.sin(dip)]
    )


def draw_realisation(
    spec: MagneticEnvironmentSpec,
    field_enu_T: ArrayLike,
    rest_w: ArrayLike,
    rng: np.random.Generator | None = None,
) -> MagneticRealisation:
    """Draw ``ψ`` and the random field ``δ`` of one realisation.

    Parameters
    ----------
    spec : MagneticEnvironmentSpec
    field_enu_T : array_like (3,)
        The site's field, tesla, world (ENU) axes (overrides applied here, :func:`reference_field`).
    rest_w : array_like (3,)
        The rest position ``p₀``, m.
    rng : numpy.random.Generator, optional
        Source of the draws; by default ``numpy.random.default_rng(spec.seed)``.
    """
    rng = np.random.default_rng(spec.seed) if rng is None else rng
    psi = math.radians(spec.heading_offset_mean_deg + spec.heading_offset_sigma_deg * rng.standard_normal())
    m = FEATURES if spec.spatial_sigma_uT > 0 else 0
    wavevectors = rng.standard_normal((m, 3)) / spec.correlation_length_m  # ω ~ N(0, I/ℓ²), rad/m
    scale = spec.spatial_sigma_uT * 1e-6 / math.sqrt(m) if m else 0.0
    cos_weights = scale * rng.standard_normal((m, 3))
    sin_weights = scale * rng.standard_normal((m, 3))
    return MagneticRealisation(
        reference_w=reference_field(spec, field_enu_T),
        rest_w=np.array(rest_w, dtype=float).reshape(3),
        heading_offset_rad=psi,
        transition_m=float(spec.transition_m),
        wavevectors=wavevectors,
        cos_weights=cos_weights,
        sin_weights=sin_weights,
        dipoles=tuple(spec.dipoles),
    )


def field_along_path(
    spec: MagneticEnvironmentSpec,
    field_enu_T: ArrayLike,
    pos_w: ArrayLike,
    rng: np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """The field ``B(p)`` (N, 3), tesla, world axes, at the path's positions ``pos_w`` (N, 3), m.

    One realisation (:func:`draw_realisation`) whose rest position is the path's first position.
    ``field_enu_T`` (3,) is the site's field, tesla; ``rng`` defaults to ``spec.seed``'s generator.
    """
    pos = np.asarray(pos_w, dtype=float).reshape(-1, 3)
    if len(pos) == 0:
        return np.zeros((0, 3))
    return draw_realisation(spec, field_enu_T, pos[0], rng).field(pos)


def with_magnetic_environment(
    traj: Trajectory,
    spec: MagneticEnvironmentSpec,
    field_enu_T: ArrayLike | None = None,
    rng: np.random.Generator | None = None,
) -> Trajectory:
    """``traj`` with ``mag_b = R_bw(q_wb) B(pos_w)``: the body-axes field along its path.

    ``field_enu_T`` (3,), tesla: the site's field; by default the trajectory's environment's. The
    returned trajectory's environment, if any, holds the reference field ``B₀`` (the site's, with
    the spec's norm and dip) as its ``magnetic_field_w``. ``rng`` defaults to ``spec.seed``'s.
    """
    env = traj.environment
    if field_enu_T is None:
        if env is None:
            raise ValueError("the trajectory has no environment: give the site's field_enu_T")
        field_enu_T = env.magnetic_field_w
    field_w = field_along_path(spec, field_enu_T, traj.pos_w, rng)
    mag_b = quat_rotate(quat_conjugate(traj.q_wb), field_w)  # R_bw B(p)
    if env is not None:
        env = dataclasses.replace(env, magnetic_field_w=reference_field(spec, field_enu_T))
    return dataclasses.replace(traj, mag_b=mag_b, environment=env)


# No "contract" among the fast-math flags: with fused multiply-adds a position's bits came to depend on
# whether its anchor was computed at it or before it (1 ulp); without, the same position, same bits.
@njit(fastmath={"reassoc", "arcp", "nsz"})
def _features(
    pos: NDArray[np.float64],
    w: NDArray[np.float64],
    cos_weights: NDArray[np.float64],
    sin_weights: NDArray[np.float64],
    spacing: float,
    out: NDArray[np.float64],
) -> None:  # pragma: no cover - compiled
    """``out[n] = Σ_m cos_weights[:, m] cos(ω_m·p_n) + sin_weights[:, m] sin(ω_m·p_n)``, for (N, 3) ``pos``
    and (3, M) ``w``, ``cos_weights``, ``sin_weights``.

    Each position is split as ``p = h a + r`` with ``a`` the nearest point of the integer lattice
    (``h = spacing``), so ``ω·p = ω·(h a) + ω·r`` with ``|ω·r| ≤ 1/2``:

        cos(ω·p) = cos(ω·ha) cos(ω·r) − sin(ω·ha) sin(ω·r),   sin(ω·p) = sin(ω·ha) cos(ω·r) + cos(ω·ha) sin(ω·r)

    with the anchor's terms from libm (recomputed when the anchor changes; a path moves through few)
    and ``cos``, ``sin`` of ``x = ω·r`` by their Taylor series to ``x¹⁴``, ``x¹⁵`` (remainder below
    ``0.5¹⁶/16! < 10⁻¹⁸``). Each value depends on its own position only, through the same operations:
    the same position gives the same bits.
    """
    n_pos, n_feat = pos.shape[0], w.shape[1]
    cos_a = np.empty(n_feat)
    sin_a = np.empty(n_feat)
    last = np.full(3, np.nan)
    for n in range(n_pos):
        a0 = math.floor(pos[n, 0] / spacing + 0.5)
        a1 = math.floor(pos[n, 1] / spacing + 0.5)
        a2 = math.floor(pos[n, 2] / spacing + 0.5)
        if a0 != last[0] or a1 != last[1] or a2 != last[2]:
            last[0], last[1], last[2] = a0, a1, a2
            h0, h1, h2 = a0 * spacing, a1 * spacing, a2 * spacing
            for m in range(n_feat):
                phase = w[0, m] * h0 + w[1, m] * h1 + w[2, m] * h2
                cos_a[m] = math.cos(phase)
                sin_a[m] = math.sin(phase)
        r0 = pos[n, 0] - a0 * spacing
        r1 = pos[n, 1] - a1 * spacing
        r2 = pos[n, 2] - a2 * spacing
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for m in range(n_feat):
            x = w[0, m] * r0 + w[1, m] * r1 + w[2, m] * r2
            y = x * x
            # Horner in y: cos x = Σ (−y)^k/(2k)!, sin x = x Σ (−y)^k/(2k+1)!, k = 0 … 7
            c = 1.0 - y / 2.0 * (
                1.0
                - y
                / 12.0
                * (1.0 - y / 30.0 * (1.0 - y / 56.0 * (1.0 - y / 90.0 * (1.0 - y / 132.0 * (1.0 - y / 182.0)))))
            )
            s = x * (
                1.0
                - y
                / 6.0
                * (
                    1.0
                    - y
                    / 20.0
                    * (1.0 - y / 42.0 * (1.0 - y / 72.0 * (1.0 - y / 110.0 * (1.0 - y / 156.0 * (1.0 - y / 210.0)))))
                )
            )
            cp = cos_a[m] * c - sin_a[m] * s
            sp = sin_a[m] * c + cos_a[m] * s
            s0 += cos_weights[0, m] * cp + sin_weights[0, m] * sp
            s1 += cos_weights[1, m] * cp + sin_weights[1, m] * sp
            s2 += cos_weights[2, m] * cp + sin_weights[2, m] * sp
        out[n, 0] = s0
        out[n, 1] = s1
        out[n, 2] = s2
