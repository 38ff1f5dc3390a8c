"""gyroemu's emulated sensors: gyro mechanisms, error terms, accelerometer, magnetometer, IMU devices.

Entry points (``interface.md``): :func:`load_device` and :meth:`Device.measure`, returning
:class:`ImuSamples`. Mechanisms implement :class:`GyroMechanism` (``gyroemu.sensors.mechanism``); the
error terms are :func:`apply_errors` (``gyroemu.sensors.errors``); Allan deviation and its fit are in
``gyroemu.sensors.allan``, the streamed Allan deviation (:class:`OverlappingAllanAccumulator`) in
``gyroemu.sensors.allan_stream``.
"""

from gyroemu.errors import ConfigError

from .allan_stream import OverlappingAllanAccumulator
from .errors import AccelErrors, GyroErrors, apply_errors
from .imu import Device, DeviceSpec
from .mechanism import GYRO_KINDS, GyroMechanism, GyroResponse, GyroTruth
from .presets import device_from_dict, list_devices, load_device
from .samples import ImuSamples

__all__ = [
    "ConfigError",
    "AccelErrors",
    "GyroErrors",
    "apply_errors",
    "Device",
    "DeviceSpec",
    "GYRO_KINDS",
    "GyroMechanism",
    "GyroResponse",
    "GyroTruth",
    "device_from_dict",
    "list_devices",
    "load_device",
    "ImuSamples",
    "OverlappingAllanAccumulator",
]
