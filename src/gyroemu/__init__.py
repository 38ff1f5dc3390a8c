"""gyroemu: gyroscopes and IMUs emulated by their physics.

The one import root of the project. Its subpackages live in the repository's top-level folders and are
mapped under this root by ``pyproject.toml`` (``[tool.setuptools.package-dir]``):

- :mod:`gyroemu.dynamics` (``dynamics/``): the rigid-body truth simulator, ``load_scenario``;
- :mod:`gyroemu.sensors` (``sensors/``): gyro mechanisms, error terms, IMU devices, ``load_device``;
- :mod:`gyroemu.pipelines` (``pipelines/``): files, streams, estimation and the command line;
- :mod:`gyroemu.configs` (``configs/``): the built-in scenario and device files, as package data.

Importing ``gyroemu`` loads nothing: each subpackage is imported when asked for, and ``__version__``
(from the installed package's metadata) when it is first read.
"""

from typing import TYPE_CHECKING

__all__ = ["__version__"]

if TYPE_CHECKING:
    __version__: str  # served by __getattr__ below, from the installed package's metadata


def __getattr__(name: str) -> str:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("gyroemu")
        except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
            value = "0+unknown"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module 'gyroemu' has no attribute {name!r}")
