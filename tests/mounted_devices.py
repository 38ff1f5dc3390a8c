"""The ideal IMU unmounted and mounted: device files for the tests that hold a mounted device's estimate
to be the body's (``gyroemu estimate``, ``bench``, the live filter)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

MOUNTINGS = {"x90": ((1.0, 0.0, 0.0), 90.0), "general": ((1.0, -2.0, 3.0), 130.0)}
"""Mountings ``q_bs`` (axis, degrees): a quarter turn about x, and a turn about no axis of the body."""


def q_axis(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    """The unit quaternion (4,) w, x, y, z of a turn of ``degrees`` about ``axis``."""
    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    half = np.radians(degrees) / 2
    return np.r_[np.cos(half), np.sin(half) * unit]


def mounted_ideal_configs(folder: Path, rate_hz: int = 200) -> dict[str, Path]:
    """Device files in ``folder``: the built-in ideal IMU at ``rate_hz`` (the built-in runs at 1 kHz: 5x
    the work) unmounted (``none``) and mounted as :data:`MOUNTINGS` say (lever arm 0), by name."""
    ideal = (Path(__file__).resolve().parents[1] / "configs" / "devices" / "ideal.toml").read_text()
    assert "rate_hz = 1000" in ideal
    ideal = ideal.replace("rate_hz = 1000", f"rate_hz = {rate_hz}")
    out = {}
    for name, q_bs in {"none": None, **{k: q_axis(*v) for k, v in MOUNTINGS.items()}}.items():
        out[name] = folder / f"{name}.toml"
        out[name].write_text(ideal if q_bs is None else ideal + f"\n[mounting]\nq_bs = {q_bs.tolist()}\n")
    return out
