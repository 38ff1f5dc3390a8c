"""gyroemu's emulated sensors: gyro mechanisms, error terms, accelerometer, magnetometer, IMU devices."""

from dynamics.config import ConfigError

__all__ = ["ConfigError"]
