"""A :class:`FilterSetup` from what gyroemu knows: a device, a scenario, or a recorded log's metadata.

A gyroemu log embeds its device and scenario configs, so a filter run on it starts from the device's
own noise figures and the site's latitude and declination. A foreign log (BROAD, a robot's bag) has
none of these: the filter's defaults apply.
"""

from __future__ import annotations

import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from .field_lag import FieldLag, estimate_field_lag
from .protocol import DeviceNoise, FilterSetup

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.dynamics.earth import Site
    from gyroemu.sensors import Device

__all__ = [
    "FIELD_LAG_FROM_LOG",
    "LATENCY_SENSORS",
    "check_latency_sensors",
    "latencies_for_log",
    "noise_from_device",
    "setup_for",
    "setup_from_metadata",
    "with_latencies",
]

LATENCY_SENSORS = ("gyro", "mag")
"""The sensors whose latency a setup holds (:mod:`.latency` says why not the accelerometer's)."""

FIELD_LAG_FROM_LOG = "auto"
"""The magnetometer's latency given as this: the gyro's plus the field's lag read from the log
(:func:`latencies_for_log`)."""


def noise_from_device(device: Device) -> DeviceNoise:
    """The noise figures of a :class:`gyroemu.sensors.Device` (the mean over its three axes), SI."""
    gyro = device.gyro_errors
    accel = device.spec.accelerometer.errors.to_si()
    mag = device.spec.magnetometer
    return DeviceNoise(
        gyro_noise_density=float(np.mean(device.gyro_noise_density)),
        # the mechanism's own rest bias (a MEMS quadrature leak, its g-sensitivity) is a bias to learn too
        gyro_bias_sigma=float(
            np.sqrt(np.mean(gyro.turn_on_bias**2 + gyro.bias**2) + device.mechanism.rest_bias() ** 2)
        ),
        gyro_bias_instability=float(np.mean(gyro.bias_instability)),
        gyro_rate_random_walk=float(np.mean(gyro.random_walk)),
        gyro_scale_sigma=float(np.sqrt(np.mean(gyro.scale_factor**2))),
        gyro_misalignment_sigma=float(np.sqrt(np.sum(gyro.cross_axis**2) / 6)),  # its six off-diagonal terms
        accel_noise_density=float(np.mean(accel.noise_density)),
        mag_noise_density=None if mag is None else mag.noise_density_uT_per_sqrt_hz * 1e-6,
    )


def _site(scenario: Scenario | None) -> Site | None:
    """The scenario's ``[site]`` (None for kinds in an inertial frame, such as the tops)."""
    site: Site | None = getattr(scenario.spec, "site", None) if scenario is not None else None
    return site


def setup_for(device: Device, scenario: Scenario | None = None, *, use_mag: bool | None = None) -> FilterSetup:
    """The setup for a filter run on ``device``'s samples of ``scenario``.

    ``use_mag`` defaults to whether the device has a magnetometer. The latitude is the site's when the
    scenario stands on a rotating Earth; the declination is that of the site's field.
    """
    site = _site(scenario)
    latitude = declination = heading_sigma = None
    mag = device.spec.magnetometer
    if site is not None:
        if site.earth_rotation:
            latitude = float(np.radians(site.latitude_deg))
        east, north, up = site.magnetic_field_enu_uT
        declination = float(np.arctan2(east, north))
        horizontal = float(np.hypot(east, north))
        if mag is not None and horizontal > 0.0:
            # the simulated field has no anomalies: only the sensor's uncompensated iron turns it, by at
            # most |hard iron| / B_h plus ‖soft iron − I‖ |B| / B_h
            soft = np.linalg.norm(np.asarray(mag.soft_iron) - np.eye(3), 2)
            heading_sigma = float(
                (np.linalg.norm(mag.hard_iron_uT) + soft * np.linalg.norm([east, north, up])) / horizontal
            )
    if use_mag is None:
        use_mag = mag is not None
    return FilterSetup(
        rate_hz=float(device.spec.rate_hz),
        use_mag=use_mag,
        noise=noise_from_device(device),
        latitude_rad=latitude,
        declination_rad=declination or 0.0,
        field_heading_sigma=heading_sigma,
        gyro_latency_s=device.latencies[0],
        mag_latency_s=device.latencies[2],
    )


def setup_from_metadata(metadata: dict[str, Any] | None, rate_hz: float, *, use_mag: bool) -> FilterSetup:
    """The setup for a recorded log: from its ``gyroemu`` metadata record when it has one (device and
    scenario configs as TOML), otherwise the defaults at ``rate_hz``. A config that no longer validates
    is ignored with a warning (the log stays usable)."""
    if metadata and metadata.get("device"):
        from gyroemu.dynamics import scenario_from_dict
        from gyroemu.sensors import device_from_dict

        try:
            device = device_from_dict(tomllib.loads(metadata["device"]), name=metadata.get("device_name", "imu0"))
            scenario = None
            if metadata.get("scenario"):
                scenario = scenario_from_dict(tomllib.loads(metadata["scenario"]))
        except Exception as exc:  # noqa: BLE001 - any bad embedded config: fall back to the defaults
            warnings.warn(
                f"the log's embedded configs do not validate ({exc}); using the filter's defaults", stacklevel=2
            )
        else:
            return replace(setup_for(device, scenario, use_mag=use_mag), rate_hz=rate_hz)
    return FilterSetup(rate_hz=rate_hz, use_mag=use_mag)


def check_latency_sensors(latency_s: Mapping[str, float | str]) -> None:
    """Raise ``ValueError`` naming any sensor of ``latency_s`` not in :data:`LATENCY_SENSORS`, or a
    value that is neither a number of seconds nor, for the magnetometer, :data:`FIELD_LAG_FROM_LOG` (a
    job checks its options with it before any work)."""
    unknown = sorted(set(latency_s) - set(LATENCY_SENSORS))
    if unknown:
        raise ValueError(f"no sensor {', '.join(unknown)} ({' or '.join(LATENCY_SENSORS)})")
    for sensor, value in latency_s.items():
        if value == FIELD_LAG_FROM_LOG and sensor != "mag":
            raise ValueError(
                f"{sensor}={FIELD_LAG_FROM_LOG}: only the magnetometer's lag behind the gyro can be read from a "
                "log; how long the gyro lags the motion needs a truth: give it in milliseconds"
            )
        if not isinstance(value, (int, float)) and value != FIELD_LAG_FROM_LOG:
            raise ValueError(f"{sensor}: expected seconds or {FIELD_LAG_FROM_LOG!r}, got {value!r}")


def with_latencies(setup: FilterSetup, latency_s: Mapping[str, float]) -> FilterSetup:
    """``setup`` with the latencies of the sensors named in ``latency_s`` (``gyro``, ``mag``: s), the
    others as they were.

    Raises
    ------
    ValueError
        A sensor not in :data:`LATENCY_SENSORS`; the message names it.
    """
    check_latency_sensors(latency_s)
    return replace(
        setup,
        gyro_latency_s=float(latency_s.get("gyro", setup.gyro_latency_s)),
        mag_latency_s=float(latency_s.get("mag", setup.mag_latency_s)),
    )


def latencies_for_log(
    setup: FilterSetup,
    latency_s: Mapping[str, float | str],
    t: np.ndarray,
    gyro: np.ndarray,
    mag: np.ndarray | None,
) -> tuple[FilterSetup, FieldLag | None]:
    """:func:`with_latencies` for one device of a log, where the magnetometer's may be
    :data:`FIELD_LAG_FROM_LOG`: then it is the gyro's latency plus the field's lag behind the gyro read
    from the samples (:func:`~.field_lag.estimate_field_lag`) where that lag is observable, else the
    setup's own.

    Parameters
    ----------
    setup : FilterSetup
        The device's setup (``use_mag`` says whether the field is used).
    latency_s : mapping
        ``gyro``, ``mag``: seconds, or ``mag``: ``"auto"``.
    t, gyro, mag : ndarray
        The device's samples: (N,) s, (N, 3) rad/s, (N, 3) any unit (NaN rows: no field) or None.

    Returns
    -------
    (FilterSetup, FieldLag or None)
        The setup, and the fit when the field's lag was read from the log (None when it was not asked for,
        or the setup uses no field).
    """
    check_latency_sensors(latency_s)
    setup = with_latencies(setup, {k: float(v) for k, v in latency_s.items() if v != FIELD_LAG_FROM_LOG})
    if latency_s.get("mag") != FIELD_LAG_FROM_LOG or not setup.use_mag or mag is None:
        return setup, None
    lag = estimate_field_lag(t, gyro, mag)
    if lag.observable:
        setup = replace(setup, mag_latency_s=setup.gyro_latency_s + lag.lag_s)
    return setup, lag
