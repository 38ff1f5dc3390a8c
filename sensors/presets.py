"""Device files: ``configs/devices/*.toml`` validated into a :class:`~gyroemu.sensors.imu.Device`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gyroemu.dynamics.config import config_dir, read_toml, resolve_config, validate
from gyroemu.errors import ConfigError

from .imu import Device, DeviceSpec

__all__ = ["load_device", "device_from_dict", "list_devices"]


def device_from_dict(data: dict[str, Any], name: str = "imu0", seed: int = 0, path: Path | None = None) -> Device:
    """Validate a device given as a dict (as read from TOML); errors name ``path`` or ``name``."""
    where = path if path is not None else name
    if not isinstance(data, dict):
        raise ConfigError("a device is a table of keys", file=where)
    return Device(validate(DeviceSpec, data, file=where), name=name, seed=seed, path=path)


def load_device(name_or_path: str | Path, seed: int = 0) -> Device:
    """Load a built-in device by name (``configs/devices/<name>.toml``) or a TOML file by path.

    Raises
    ------
    ConfigError
        Unknown preset, unreadable file, unknown or missing key, bad value, or a combination that
        cannot work; the message names the file and key.
    """
    path = resolve_config(name_or_path, "devices", "device")
    return device_from_dict(read_toml(path), name=path.stem, seed=seed, path=path)


def list_devices() -> list[Device]:
    """The built-in devices, loaded and validated, sorted by name."""
    return [load_device(p) for p in sorted((config_dir() / "devices").glob("*.toml"))]
