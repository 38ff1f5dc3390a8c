"""Identification of a device (and its site's magnetic environment) from recordings with a truth.

One module per idea: :mod:`.rest` (rest phases), :mod:`.noise` (Allan noise terms from them),
:mod:`.truth` (kinematics of the truth track), :mod:`.timing` (latencies), :mod:`.calibration`
(gyro, accelerometer, magnetometer errors), :mod:`.handling` (the accelerometer carried against at
rest), :mod:`.lever_arm` (the accelerometer's offset from the truth's reference point),
:mod:`.magnetic_environment`, :mod:`.dipole` (a magnet beside the path), :mod:`.trial` (one
recording) and :mod:`.result` (pooling, device and site TOML). Every fit takes plain arrays.
"""

from .calibration import AccelCalibration, GyroCalibration, MagCalibration, fit_accel, fit_gyro, fit_mag
from .dipole import DipoleFit, fit_dipole
from .handling import HandlingOffset, handling_offset, pool_handling_offsets
from .lever_arm import LeverArmFit, fit_lever_arm
from .magnetic_environment import (
    DiscordantField,
    MagneticEnvironment,
    discordant_fields,
    magnetic_environment,
    pool_heading_offsets,
    world_field,
)
from .noise import AxisNoise, NoiseTerm, SensorNoise, pooled_allan, sensor_noise
from .rest import RestPhase, find_rest_phases, phases_from_intervals
from .result import Identification, Pooled, identify, pool_estimates, pool_random_effects
from .timing import LatencyEstimate, accel_latency, estimate_latency, gyro_latency, mag_latency
from .trial import TrialData, TrialIdentification, TrialSettings, identify_trial
from .truth import truth_angular_velocity

__all__ = [
    "AccelCalibration",
    "AxisNoise",
    "DipoleFit",
    "DiscordantField",
    "GyroCalibration",
    "HandlingOffset",
    "Identification",
    "LatencyEstimate",
    "LeverArmFit",
    "MagCalibration",
    "MagneticEnvironment",
    "NoiseTerm",
    "Pooled",
    "RestPhase",
    "SensorNoise",
    "TrialData",
    "TrialIdentification",
    "TrialSettings",
    "accel_latency",
    "estimate_latency",
    "find_rest_phases",
    "discordant_fields",
    "fit_dipole",
    "fit_accel",
    "fit_gyro",
    "fit_lever_arm",
    "fit_mag",
    "gyro_latency",
    "handling_offset",
    "identify",
    "identify_trial",
    "mag_latency",
    "magnetic_environment",
    "phases_from_intervals",
    "pool_estimates",
    "pool_random_effects",
    "pool_handling_offsets",
    "pool_heading_offsets",
    "pooled_allan",
    "sensor_noise",
    "truth_angular_velocity",
    "world_field",
]
