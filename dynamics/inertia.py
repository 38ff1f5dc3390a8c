"""Inertia tensors: from point masses and solids, composites, principal axes, validation.

All tensors are 3x3 arrays in kg m², about the centre of mass unless a function says otherwise.
Solids have their symmetry axis along z and their centre of mass at the origin.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .rotation import quat_to_matrix

__all__ = [
    "InertiaError",
    "inertia_tensor",
    "inertia_config",
    "check_inertia",
    "point_masses",
    "box",
    "sphere",
    "cylinder",
    "disc",
    "cone",
    "parallel_axis",
    "composite",
    "principal_axes",
    "world_tensor",
]


class InertiaError(ValueError):
    """A tensor that no rigid body can have; the message says which property fails."""


_Inertia = TypeVar("_Inertia", bound="ArrayLike | None")


def check_inertia(inertia: ArrayLike, *, rtol: float = 1e-9) -> NDArray[np.float64]:
    """Return ``inertia`` as a float 3x3 array, or raise :class:`InertiaError` saying what is wrong.

    A physical inertia tensor is symmetric, positive definite, and its principal moments satisfy the
    triangle inequality ``I1 + I2 >= I3`` (equality: a flat lamina; ``rtol`` of the trace absorbs
    round-off there).
    """
    i = np.asarray(inertia, dtype=float)
    if i.shape != (3, 3):
        raise InertiaError(f"an inertia tensor is 3x3, got shape {i.shape}")
    if not np.all(np.isfinite(i)):
        raise InertiaError("inertia tensor has non-finite entries")
    scale = max(np.abs(i).max(), np.finfo(float).tiny)
    if np.abs(i - i.T).max() > rtol * scale:
        raise InertiaError("inertia tensor is not symmetric")
    m = np.linalg.eigvalsh(0.5 * (i + i.T))
    if m[0] <= 0:
        raise InertiaError(f"inertia tensor is not positive definite (principal moments {m.tolist()} kg m²)")
    if m[0] + m[1] < m[2] * (1.0 - rtol) - rtol * m.sum():
        raise InertiaError(
            f"principal moments {m.tolist()} kg m² break the triangle inequality "
            f"I1 + I2 >= I3 ({m[0] + m[1]:.6g} < {m[2]:.6g}): no mass distribution has them"
        )
    symmetric: NDArray[np.float64] = 0.5 * (i + i.T)
    return symmetric


def inertia_tensor(value: ArrayLike) -> NDArray[np.float64]:
    """A validated 3x3 tensor from three principal moments ``(Ixx, Iyy, Izz)`` or a 3x3 matrix."""
    v = np.asarray(value, dtype=float)
    if v.shape == (3,):
        v = np.diag(v)
    elif v.shape != (3, 3):
        raise InertiaError(f"give 3 principal moments or a 3x3 matrix, got shape {v.shape}")
    return check_inertia(v)


def inertia_config(value: _Inertia) -> _Inertia:
    """A config file's inertia (three principal moments, a 3x3 matrix, or ``None`` for a default),
    returned unchanged once :func:`inertia_tensor` accepts it: the validator of the scenario kinds'
    ``inertia_kgm2`` keys. Raises :class:`InertiaError` (a ``ValueError``) saying what is wrong."""
    if value is not None:
        inertia_tensor(value)
    return value


def point_masses(masses: ArrayLike, positions: ArrayLike) -> NDArray[np.float64]:
    """Tensor of point masses about the origin: ``Σ m_i ((r_i·r_i) 1 − r_i r_iᵀ)``.

    Parameters
    ----------
    masses : array_like (N,), kg
    positions : array_like (N, 3), m
    """
    m = np.asarray(masses, dtype=float)
    r = np.asarray(positions, dtype=float).reshape(-1, 3)
    rr = np.einsum("i,ij,ij->", m, r, r)
    tensor: NDArray[np.float64] = rr * np.eye(3) - np.einsum("i,ij,ik->jk", m, r, r)
    return tensor


def box(mass: float, lx: float, ly: float, lz: float) -> NDArray[np.float64]:
    """Solid cuboid with edges ``lx, ly, lz`` along the axes: ``m (ly² + lz²)/12`` etc."""
    return mass / 12.0 * np.diag([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2])


def sphere(mass: float, radius: float, *, hollow: bool = False) -> NDArray[np.float64]:
    """Solid sphere ``2/5 m r²``, or thin spherical shell ``2/3 m r²``."""
    return (2.0 / 3.0 if hollow else 2.0 / 5.0) * mass * radius**2 * np.eye(3)


def cylinder(mass: float, radius: float, height: float, *, inner_radius: float = 0.0) -> NDArray[np.float64]:
    """Solid or hollow (``inner_radius > 0``) circular cylinder, axis z.

    ``Izz = m (r² + r_i²)/2``, ``Ixx = Iyy = m (3 (r² + r_i²) + h²)/12``.
    """
    r2 = radius**2 + inner_radius**2
    ixx = mass * (3.0 * r2 + height**2) / 12.0
    return np.diag([ixx, ixx, mass * r2 / 2.0])


def disc(mass: float, radius: float, *, inner_radius: float = 0.0) -> NDArray[np.float64]:
    """Thin disc or annulus in the x-y plane: a cylinder of zero height."""
    return cylinder(mass, radius, 0.0, inner_radius=inner_radius)


def cone(mass: float, radius: float, height: float) -> NDArray[np.float64]:
    """Solid right circular cone about its centre of mass (a quarter of the height above the base).

    ``Izz = 3/10 m r²``, ``Ixx = Iyy = 3/20 m r² + 3/80 m h²``.
    """
    ixx = 3.0 / 20.0 * mass * radius**2 + 3.0 / 80.0 * mass * height**2
    return np.diag([ixx, ixx, 0.3 * mass * radius**2])


def parallel_axis(inertia_cm: ArrayLike, mass: float, offset: ArrayLike) -> NDArray[np.float64]:
    """Tensor about a point displaced by ``-offset`` from the centre of mass (Steiner):
    ``I_cm + m ((d·d) 1 − d dᵀ)`` with ``d = offset`` the centre of mass seen from the new point."""
    d = np.asarray(offset, dtype=float)
    moved: NDArray[np.float64] = np.asarray(inertia_cm, dtype=float) + mass * (d @ d * np.eye(3) - np.outer(d, d))
    return moved


def composite(parts: Iterable[Sequence[ArrayLike]]) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Mass, centre of mass and tensor about it of rigidly joined parts.

    Parameters
    ----------
    parts : iterable of (mass, inertia_cm, position) or (mass, inertia_cm, position, q_part)
        Each part's mass (kg), its tensor about its own centre of mass in its own axes, the position
        of that centre in the composite's axes (m), and optionally the unit quaternion that rotates
        the part's axes into the composite's.

    Returns
    -------
    mass : float
    centre_of_mass : ndarray (3,)
    inertia : ndarray (3, 3)
        About the composite's centre of mass, in the composite's axes.
    """
    parts = [tuple(p) for p in parts]
    masses = np.array([p[0] for p in parts], dtype=float)
    positions = np.array([p[2] for p in parts], dtype=float).reshape(-1, 3)
    total = masses.sum()
    if total <= 0:
        raise InertiaError("a composite needs a positive total mass")
    cm = masses @ positions / total
    inertia = np.zeros((3, 3))
    for p, m, r in zip(parts, masses, positions):
        i_part = np.asarray(p[1], dtype=float)
        if len(p) > 3:
            i_part = world_tensor(p[3], i_part)
        inertia += parallel_axis(i_part, m, r - cm)
    return float(total), cm, inertia


def principal_axes(inertia: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Principal moments (ascending) and axes of a tensor.

    Returns
    -------
    moments : ndarray (3,)
    axes : ndarray (3, 3)
        A proper rotation (``det = +1``) whose columns are the principal axes, so that
        ``inertia == axes @ diag(moments) @ axes.T``.
    """
    moments, axes = np.linalg.eigh(check_inertia(inertia))
    if np.linalg.det(axes) < 0:
        axes[:, 2] = -axes[:, 2]
    return moments, axes


def world_tensor(q_wb: ArrayLike, inertia_b: ArrayLike) -> NDArray[np.float64]:
    """``R I_body Rᵀ`` for attitudes ``q_wb`` of shape ``(..., 4)``: shape ``(..., 3, 3)``."""
    r = quat_to_matrix(q_wb)
    turned: NDArray[np.float64] = r @ np.asarray(inertia_b, dtype=float) @ np.swapaxes(r, -1, -2)
    return turned
