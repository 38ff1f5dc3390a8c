"""gyroemu: gyroscopes and IMUs emulated by their physics.

The one import root of the project. Its subpackages live in the repository's top-level folders and are
mapped under this root by ``pyproject.toml`` (``[tool.setuptools.package-dir]``):

- :mod:`gyroemu.dynamics` (``dynamics/``): the rigid-body truth simulator, ``load_scenario``;
- :mod:`gyroemu.sensors` (``sensors/``): gyro mechanisms, error terms, IMU devices, ``load_device``;
- :mod:`gyroemu.pipelines` (``pipelines/``): files, streams, estimation and the command line;
- :mod:`gyroemu.configs` (``configs/``): the built-in scenario and device files, as package data.

Importing ``gyroemu`` loads nothing heavy: each subpackage is imported when asked for.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("gyroemu")
except PackageNotFoundError:  # pragma: no cover - only a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
