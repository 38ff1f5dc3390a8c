"""The Earth as an IMU senses it: rotation rate, normal gravity, local magnetic field.

The world frame of an Earth-bound scenario is the local ENU tangent frame fixed to the Earth at the
scenario's site (x east, y north, z up). It rotates with the Earth, so an ideal gyro at rest reads
the Earth rate ``Ω (0, cos φ, sin φ)`` in world axes, and moving bodies feel the Coriolis term.
Gravity is taken as the normal gravity of the site, uniform over the scenario (a 1 km excursion
tilts the true vertical by 0.16 mrad, which the scenarios here do not reach).

A scenario in inertial space (a free body, a top on a pivot whose frame is treated as inertial) uses
:meth:`Environment.inertial` instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, StrictBool

from .config import Real, Section, Vec3
from .magnetic_environment import MagneticEnvironmentSpec, reference_field

__all__ = [
    "EARTH_RATE",
    "WGS84_A",
    "WGS84_F",
    "normal_gravity",
    "earth_rate_enu",
    "Site",
    "Environment",
]

EARTH_RATE = 7.292115e-5
"""Earth's rotation rate relative to inertial space, rad/s (WGS 84)."""

WGS84_A = 6378137.0
"""WGS 84 semi-major axis, m."""
WGS84_F = 1.0 / 298.257223563
"""WGS 84 flattening."""

_GAMMA_E = 9.7803253359  # normal gravity at the equator, m/s²
_K_SOMIGLIANA = 0.00193185265241
_E2 = 0.00669437999013  # first eccentricity squared
_M = 0.00344978650684  # ω² a² b / GM


def normal_gravity(latitude_rad: ArrayLike, height_m: ArrayLike = 0.0) -> float | NDArray[np.float64]:
    """Magnitude of normal gravity (gravitation plus centrifugal), m/s².

    Somigliana's closed form on the WGS 84 ellipsoid, with the second-order free-air correction for
    height (NIMA TR8350.2, eqs. 4-1 and 4-3)::

        γ0 = γe (1 + k sin²φ) / sqrt(1 − e² sin²φ)
        γh = γ0 [1 − 2/a (1 + f + m − 2 f sin²φ) h + 3 h²/a²]
    """
    s2 = np.sin(latitude_rad) ** 2
    g0 = _GAMMA_E * (1.0 + _K_SOMIGLIANA * s2) / np.sqrt(1.0 - _E2 * s2)
    h = np.asarray(height_m, dtype=float)
    g: float | NDArray[np.float64] = g0 * (
        1.0 - 2.0 / WGS84_A * (1.0 + WGS84_F + _M - 2.0 * WGS84_F * s2) * h + 3.0 * h * h / WGS84_A**2
    )
    return g


def earth_rate_enu(latitude_rad: float) -> NDArray[np.float64]:
    """Earth's rotation vector in the local ENU frame, rad/s: ``Ω (0, cos φ, sin φ)``."""
    return EARTH_RATE * np.array([0.0, np.cos(latitude_rad), np.sin(latitude_rad)])


class Site(Section):
    """Where an Earth-bound scenario stands: the ``[site]`` table of a scenario file.

    The default magnetic field is WMM-2025's at the default site (Berlin: declination about 5° E,
    inclination about 68°, 50 µT), as (east, north, up) components. An optional
    ``[site.magnetic_environment]`` table (:mod:`gyroemu.dynamics.magnetic_environment`) makes it
    vary over the working volume; its ``norm_uT`` and ``dip_deg`` replace the norm and dip of
    ``magnetic_field_enu_uT`` (declination kept), and the environment's field is then that one.
    """

    latitude_deg: Annotated[Real, Field(ge=-90.0, le=90.0)] = 52.5
    longitude_deg: Real = 13.4
    height_m: Real = 34.0
    magnetic_field_enu_uT: Vec3 = (1.63, 18.6, -46.4)
    earth_rotation: StrictBool = True
    magnetic_environment: MagneticEnvironmentSpec | None = None

    def environment(self) -> Environment:
        lat = np.radians(self.latitude_deg)
        field_w = np.asarray(self.magnetic_field_enu_uT) * 1e-6
        if self.magnetic_environment is not None:
            field_w = reference_field(self.magnetic_environment, field_w)
        return Environment(
            gravity_w=np.array([0.0, 0.0, -float(normal_gravity(lat, self.height_m))]),
            earth_rate_w=earth_rate_enu(lat) if self.earth_rotation else np.zeros(3),
            magnetic_field_w=field_w,
        )


@dataclass(frozen=True)
class Environment:
    """The fields a body moves in, constant over a scenario, in world axes (SI).

    Attributes
    ----------
    gravity_w : ndarray (3,)
        Gravity (gravitation plus centrifugal in a rotating frame), m/s².
    earth_rate_w : ndarray (3,)
        Rotation of the world frame relative to inertial space, rad/s (zero for an inertial world).
    magnetic_field_w : ndarray (3,)
        Magnetic flux density, tesla.
    """

    gravity_w: NDArray[np.float64]
    earth_rate_w: NDArray[np.float64]
    magnetic_field_w: NDArray[np.float64]

    @classmethod
    def inertial(cls, gravity_m_s2: float = 0.0, magnetic_field_w: ArrayLike = (0.0, 0.0, 0.0)) -> Environment:
        """A non-rotating world with uniform gravity ``-gravity_m_s2`` along z."""
        return cls(np.array([0.0, 0.0, -gravity_m_s2]), np.zeros(3), np.asarray(magnetic_field_w, float))
