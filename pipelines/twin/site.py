"""The twins' site: the ``[site]`` table they are sensed in, and the accelerometer's handling offset.

Handling. The site file's optional ``[handling]`` table (``accel_offset_m_s2``,
``accel_offset_sigma_m_s2``; written by ``gyroemu identify --site-out``,
:mod:`gyroemu.pipelines.identification.handling`) is the accelerometer's offset against the truth while
the device is carried, relative to at rest. Each twin draws one offset, mean + sd · N(0, 1) per axis
from its own generator (``[twin seed, HANDLING_STREAM]``, so the device's draws are the same with or without
it), and adds it to its accelerometer over the recording's movement mask; a recording without a
movement mask gets none.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gyroemu.errors import ConfigError

__all__ = ["HANDLING_STREAM", "Handling", "SiteFileError", "read_site", "site_with_seed"]

HANDLING_STREAM = 0x68616E64  # the handling offset's generator: [seed, this] ("hand")


class SiteFileError(ConfigError):
    """A site file that cannot be read or has a bad table (the message starts with the file's path)."""


def read_site(path: Path) -> tuple[dict[str, Any], Handling | None]:
    """The site file's ``[site]`` table and its optional ``[handling]`` (errors name the file and key)."""
    from gyroemu.dynamics.config import validate
    from gyroemu.dynamics.earth import Site

    if not path.is_file():
        raise SiteFileError(f"{path}: no such file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise SiteFileError(f"{path}: {e}") from None
    unknown = sorted(set(data) - {"site", "handling"})
    if unknown:
        raise SiteFileError(
            f"unknown table [{unknown[0]}] (a site file has [site] and an optional [handling])",
            file=path,
            key=unknown[0],
        )
    site = data.get("site")
    if not isinstance(site, dict):
        raise SiteFileError(f"{path}: has no [site] table")
    env = site.get("magnetic_environment")
    if env is not None and not isinstance(env, dict):
        raise SiteFileError(f"{path}: [site.magnetic_environment] is not a table")
    try:
        validate(Site, site_with_seed(site, 0), file=path, prefix="site")
    except ConfigError as e:  # every problem, on one line
        raise SiteFileError(e.reason.replace("\n  ", "; "), file=path, key=e.key) from None
    return site, _read_handling(data.get("handling"), path)


@dataclass(frozen=True)
class Handling:
    """``[handling]`` of the site file: the accelerometer's offset while the device is carried (the
    recording's movement) against at rest, m/s² in sensor axes; each twin draws one (module notes)."""

    accel_offset: np.ndarray  # (3,) mean
    accel_offset_sigma: np.ndarray  # (3,) standard deviation between handlings

    def draw(self, seed: int) -> np.ndarray:
        """(3,) m/s², twin ``seed``'s offset: its own generator, so the device's draws are untouched."""
        rng = np.random.default_rng([seed, HANDLING_STREAM])
        return self.accel_offset + self.accel_offset_sigma * rng.standard_normal(3)


def _read_handling(table: object, path: Path) -> Handling | None:
    """The site file's optional ``[handling]`` table ``table`` (errors name the file and the key)."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise SiteFileError(f"{path}: [handling] is not a table")
    unknown = set(table) - {"accel_offset_m_s2", "accel_offset_sigma_m_s2"}
    if unknown:
        raise SiteFileError(f"{path}: [handling] has unknown keys {sorted(unknown)}")
    values = []
    for key in ("accel_offset_m_s2", "accel_offset_sigma_m_s2"):
        v = table.get(key, [0.0, 0.0, 0.0])
        numbers = isinstance(v, list) and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ok = numbers and len(v) == 3
        arr = np.asarray(v, dtype=float) if ok else np.full(3, np.nan)
        if not ok or not np.isfinite(arr).all() or (key.endswith("sigma_m_s2") and (arr < 0).any()):
            what = "three non-negative numbers" if key.endswith("sigma_m_s2") else "three finite numbers"
            raise SiteFileError(f"{path}: [handling] {key} must be {what}, got {v!r}")
        values.append(arr)
    return Handling(values[0], values[1])


def site_with_seed(site: dict[str, Any], seed: int) -> dict[str, Any]:
    """``site`` with its magnetic environment (when it has one) drawn from ``seed``."""
    out = dict(site)
    env = dict(out.get("magnetic_environment") or {})
    if env:
        env["seed"] = seed
        out["magnetic_environment"] = env
    return out
