"""A magnetic dipole at a fixed point: the field of a magnet (or a steel part) near the working volume.

The field of a point dipole of moment ``m`` (A m²) at ``p_d``, at the position ``p`` (Jackson,
*Classical Electrodynamics*, 3rd ed., eq. 5.56)::

    B(p) = μ₀ / (4π) · (3 (m · r̂) r̂ − m) / |r|³,      r = p − p_d

It is a ``[[site.magnetic_environment.dipoles]]`` entry of a scenario (:class:`DipoleSpec`), added to
the site's field along the path (:mod:`gyroemu.dynamics.magnetic_environment`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .config import Section, Vec3

__all__ = ["MU0_OVER_4PI", "DipoleSpec", "dipole_field"]

MU0_OVER_4PI = 1e-7
"""μ₀ / 4π, T m / A (exactly 1e-7 before the 2019 SI; 1e-7 · (1 + 5.5e-10) since)."""


class DipoleSpec(Section):
    """One ``[[site.magnetic_environment.dipoles]]`` entry: a point dipole fixed in the world."""

    position_m: Vec3
    """``p_d``, world (ENU) axes, m."""
    moment_A_m2: Vec3
    """``m``, world axes, A m² (a small neodymium magnet: about 0.1 to 1 A m²)."""


def dipole_field(pos_w: ArrayLike, position_m: ArrayLike, moment_A_m2: ArrayLike) -> NDArray[np.float64]:
    """The field (N, 3), tesla, of the dipole ``moment_A_m2`` (3,) at ``position_m`` (3,), at the
    positions ``pos_w`` (N, 3), m, world axes (the equation of the module's notes)."""
    r = np.asarray(pos_w, dtype=float).reshape(-1, 3) - np.asarray(position_m, dtype=float)
    m = np.asarray(moment_A_m2, dtype=float)
    dist = np.linalg.norm(r, axis=1, keepdims=True)
    r_hat = r / dist
    field: NDArray[np.float64] = MU0_OVER_4PI * (3.0 * (r_hat @ m)[:, None] * r_hat - m) / dist**3
    return field
