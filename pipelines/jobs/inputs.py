"""The files a job reads, which its outputs never write over or remove, even with ``--force``.

A scenario or device is named on the command line by a built-in name or by a file, and the config
resolver (:func:`gyroemu.dynamics.config.resolve_config`) reads any path it is given as TOML, whatever
its suffix: :func:`given_config_files` finds those before anything is loaded. Once loaded, a scenario or
device knows the file it was read from, and a recorded scenario its motion file: :func:`loaded_files`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario
    from gyroemu.sensors import Device

__all__ = ["given_config_files", "loaded_files"]


def given_config_files(*names: str | Path | None) -> list[Path]:
    """The files among ``names`` (``--scenario``, ``--device``, as given) that the config resolver takes
    as paths: a name ending in ``.toml``, with a folder in it, or a path there is; built-in names and
    None are none. The rule restates the resolver's, whose import would load the dynamics (130 ms)."""
    files = []
    for name in names:
        if name:
            text = str(name)
            if text.endswith(".toml") or "/" in text or Path(text).exists():
                files.append(Path(text))
    return files


def loaded_files(*loaded: Scenario | Device | None) -> list[Path]:
    """The files loaded scenarios and devices were read from, and a recorded scenario's motion file."""
    from gyroemu.dynamics import Scenario as LoadedScenario  # loaded already when there is one

    files: list[Path] = []
    for item in loaded:
        if item is not None and item.path:
            files.append(Path(item.path))
        motion = getattr(item.spec, "path", None) if isinstance(item, LoadedScenario) else None
        if isinstance(motion, (str, Path)):
            files.append(Path(motion))
    return files
