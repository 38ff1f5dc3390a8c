"""Gyrocompassing: finding north from a static IMU's sensing of Earth's rotation.

A sensor at rest reads the specific force ``f_s = R_sw (0, 0, g)`` and the Earth rate
``ω_s = R_sw Ω (0, cos φ, sin φ)`` (ENU). Up is ``f_s/|f_s|``; the Earth rate's component
perpendicular to up points north, with magnitude ``Ω cos φ``. That fixes the sensor's whole
attitude, heading included (Titterton & Weston, *Strapdown Inertial Navigation Technology*, 2nd ed.,
§10.3, analytic coarse alignment).

A gyro error ``δω`` across the north direction turns the found north by ``δω / (Ω cos φ)``: at 52.5°
latitude ``Ω cos φ`` is 9.2 deg/h, so a heading to 1° needs horizontal gyro errors below 0.16 deg/h.
Over an averaging time ``T`` the error is the root-sum-square of the residual bias, the white noise
``N/√T``, the bias instability floor ``0.664 B`` and the rate random walk ``K √(T/3)``. A navigation
FOG or RLG (bias and instability of hundredths of a degree per hour) finds north to a fraction of a
degree; a MEMS gyro (degrees per hour) cannot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gyroemu.dynamics.earth import EARTH_RATE
from gyroemu.dynamics.rotation import quat_from_matrix

__all__ = ["Alignment", "gyrocompass", "heading_uncertainty"]


@dataclass(frozen=True)
class Alignment:
    """Attitude found by gyrocompassing.

    Attributes
    ----------
    q_ws : ndarray (4,)
        Sensor attitude (sensor to ENU world), unit quaternion (w, x, y, z).
    heading : float
        Yaw of the sensor's x axis, rad, from east counter-clockwise (ENU, REP-103), in (−π, π].
    horizontal_earth_rate : float
        The measured ``Ω cos φ``, rad/s.
    latitude : float
        The latitude implied by the measured Earth rate, rad.
    """

    q_ws: NDArray[np.float64]
    heading: float
    horizontal_earth_rate: float
    latitude: float


def gyrocompass(gyro: ArrayLike, accel: ArrayLike) -> Alignment:
    """Align from static samples: ``gyro`` (N, 3) rad/s and ``accel`` (N, 3) m/s², sensor axes."""
    w = np.mean(np.atleast_2d(gyro), axis=0)
    f = np.mean(np.atleast_2d(accel), axis=0)
    up = f / np.linalg.norm(f)
    horizontal = w - (w @ up) * up
    north = horizontal / np.linalg.norm(horizontal)
    east = np.cross(north, up)
    r_ws = np.stack([east, north, up])  # rows: the world axes in sensor coordinates
    return Alignment(
        q_ws=quat_from_matrix(r_ws),
        heading=float(np.arctan2(north[0], east[0])),
        horizontal_earth_rate=float(np.linalg.norm(horizontal)),
        latitude=float(np.arctan2(w @ up, np.linalg.norm(horizontal))),
    )


def heading_uncertainty(
    latitude_rad: float,
    duration_s: float,
    *,
    bias: float = 0.0,
    noise_density: float = 0.0,
    bias_instability: float = 0.0,
    random_walk: float = 0.0,
    accel_bias: float = 0.0,
    gravity: float = 9.81,
) -> float:
    """Standard uncertainty of a gyrocompass heading, rad, from the sensors' error terms (SI).

    ``bias`` is the gyro's residual (uncalibrated) bias, rad/s; ``noise_density``, ``bias_instability``
    and ``random_walk`` are its IEEE 952 coefficients N (rad/√s), B (rad/s), K (rad/s/√s).
    ``accel_bias`` (m/s²) tilts the found vertical by ``accel_bias/g``, which turns the vertical
    Earth rate into the horizontal plane: a heading error of ``tilt · tan φ``. Returns ``inf`` at the
    poles, where north is undefined.
    """
    horizontal = EARTH_RATE * np.cos(latitude_rad)
    if horizontal <= 1e-12 * EARTH_RATE:
        return float("inf")
    rate_error = np.sqrt(
        bias**2 + noise_density**2 / duration_s + (0.664 * bias_instability) ** 2 + random_walk**2 * duration_s / 3.0
    )
    levelling = accel_bias / gravity * np.tan(latitude_rad)
    return float(np.hypot(rate_error / horizontal, levelling))
