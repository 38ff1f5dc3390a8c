"""What ``gyroemu bench`` is asked to run: its cases, and the errors and warnings it raises about them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from gyroemu.dynamics import ConfigError

__all__ = ["PLOT_POINTS", "BenchError", "BenchWarning", "LogCase", "SimCase"]

PLOT_POINTS = 4000
"""Samples of a run's error curve kept for the plot (every n // PLOT_POINTS-th)."""


class BenchError(ConfigError):
    """A case or option the bench cannot run (a log without IMU or truth, bad stamps, ...); names the file
    or argument (a :class:`gyroemu.dynamics.ConfigError`, so the command line exits with status 2)."""


class BenchWarning(UserWarning):
    """Data the bench can still use, with a caveat (NaN samples, a log without a movement mask's hits)."""


@dataclass(frozen=True)
class SimCase:
    """A simulated case: ``scenario`` (built-in name or TOML path) measured by ``device``."""

    scenario: str = "smooth_manoeuvre"
    device: str = "consumer_mems"
    duration: float | None = 60.0
    six_d: bool = False


@dataclass(frozen=True)
class LogCase:
    """An MCAP log with a truth channel; ``device`` picks one device (default: each with truth);
    ``latency_s`` the gyro's and the magnetometer's latencies, s (``{"gyro": …, "mag": …}``, ``"mag":
    "auto"`` to read the field's lag from the log; default: a gyroemu log's device's, else 0;
    :func:`gyroemu.pipelines.estimation.setup.latencies_for_log`). The log is read a block at a time
    (:mod:`.bench_log`), in memory that does not grow with it, unless one pass cannot pair its topics
    or ``read_whole`` (the same results)."""

    path: str | Path
    device: str | None = None
    six_d: bool = False
    latency_s: dict[str, float | str] | None = None
    read_whole: bool = False
