"""Attitude estimation: gyroemu's Kalman filter, the peers' adapters, the filter protocol, metrics.

- :mod:`.protocol`: what a filter is (:class:`AttitudeFilter`), what it knows (:class:`FilterSetup`)
  and returns (:class:`Estimate`);
- :mod:`.mekf` (+ :mod:`.mekf_kernels`): the multiplicative Kalman filter on filterpy;
- :mod:`.batched`: the same filter over many Monte Carlo runs at once;
- :mod:`.latency`: any filter's field and attitudes in time when the sensors lag the motion;
  :mod:`.field_lag`: the magnetometer's lag behind the gyro read from a log;
- :mod:`.peers`, :mod:`.registry`: Madgwick, Mahony, EKF (``ahrs``), VQF, and filters by name;
- :mod:`.metrics`: BROAD's error definitions; :mod:`.setup`: a setup from a device or a log;
- :mod:`.mounting`: a mounted sensor's estimate turned into the body's (``q̂_ws ⊗ q_bs*``).
"""

from .field_lag import FieldLag, estimate_field_lag
from .latency import LatencyCompensated, advance_attitude, attitude_at_stamps, field_at_gyro_instant, turn_back
from .mekf import Mekf, MekfParams
from .metrics import AttitudeErrors, attitude_errors, convergence_time, rmse_deg
from .protocol import AttitudeFilter, DeviceNoise, Estimate, FilterSetup
from .setup import (
    FIELD_LAG_FROM_LOG,
    LATENCY_SENSORS,
    check_latency_sensors,
    latencies_for_log,
    noise_from_device,
    setup_for,
    setup_from_metadata,
    with_latencies,
)

__all__ = [
    "FIELD_LAG_FROM_LOG",
    "LATENCY_SENSORS",
    "AttitudeErrors",
    "AttitudeFilter",
    "DeviceNoise",
    "Estimate",
    "FieldLag",
    "FilterSetup",
    "LatencyCompensated",
    "Mekf",
    "MekfParams",
    "advance_attitude",
    "attitude_at_stamps",
    "attitude_errors",
    "check_latency_sensors",
    "convergence_time",
    "estimate_field_lag",
    "field_at_gyro_instant",
    "latencies_for_log",
    "noise_from_device",
    "rmse_deg",
    "setup_for",
    "setup_from_metadata",
    "turn_back",
    "with_latencies",
]
