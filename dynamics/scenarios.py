"""Scenario files: TOML validated into a typed spec per ``kind``, and :func:`load_scenario`.

Every scenario file has ``kind``, ``duration_s``, ``rate_hz`` and an optional ``description``; the
rest is the kind's own tables, defined by the kind's spec class (a :class:`ScenarioSpec` subclass in
the module of its physics). :data:`KINDS` maps each kind to that class by import path, so that a
kind's module is imported only when a scenario of that kind is loaded.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Annotated, Any, ClassVar

import numpy as np
import tomli_w
from numpy.typing import NDArray

from .config import ConfigError, PositiveReal, Section, at_most, config_dir, read_toml, resolve_config, validate
from .trajectory import Trajectory, concatenate_trajectories

__all__ = [
    "ScenarioSpec",
    "Scenario",
    "MAX_DURATION_S",
    "MAX_RATE_HZ",
    "Duration",
    "Rate",
    "KINDS",
    "SEGMENT_SAMPLES",
    "segment_bounds",
    "segment_index",
    "segment_count",
    "load_scenario",
    "scenario_from_dict",
    "list_scenarios",
]

KINDS: dict[str, str] = {
    "free-rigid-body": "gyroemu.dynamics.tops:FreeRigidBodySpec",
    "heavy-top": "gyroemu.dynamics.tops:HeavyTopSpec",
    "static": "gyroemu.dynamics.motions:StaticSpec",
    "rate-table": "gyroemu.dynamics.motions:RateTableSpec",
    "oscillation": "gyroemu.dynamics.motions:OscillationSpec",
    "coning": "gyroemu.dynamics.motions:ConingSpec",
    "sculling": "gyroemu.dynamics.motions:ScullingSpec",
    "random-manoeuvre": "gyroemu.dynamics.vehicles:RandomManoeuvreSpec",
    "car": "gyroemu.dynamics.vehicles:CarSpec",
    "ship": "gyroemu.dynamics.vessels:ShipSpec",
    "spacecraft-cmg": "gyroemu.dynamics.vessels:SpacecraftSpec",
    "drop": "gyroemu.dynamics.impact:DropSpec",
    "recorded": "gyroemu.pipelines.recorded_scenario:RecordedSpec",
}
"""Scenario kind → ``"module:SpecClass"``."""


MAX_DURATION_S = 1e7
"""The longest ``duration_s`` of a scenario file, s (about 116 days; ``gyroemu simulate --duration``'s limit
too): longer runs are more samples than any disk holds at a useful rate, and a float64 clock of seconds
resolves 2 ns there."""

MAX_RATE_HZ = 1e6
"""The highest ``rate_hz`` of a scenario file, Hz (``gyroemu simulate --rate``'s limit too): a hundred times
the fastest IMU's output; every sample of the truth is 184 bytes, so a higher rate fills memory in seconds."""

Duration = Annotated[PositiveReal, at_most(MAX_DURATION_S, "about 116 days, more samples than a disk holds")]
"""A scenario's span, s: positive, at most :data:`MAX_DURATION_S`."""
Rate = Annotated[PositiveReal, at_most(MAX_RATE_HZ, "a hundred times the fastest IMU's output rate")]
"""A scenario's truth rate, Hz: positive, at most :data:`MAX_RATE_HZ`."""


class ScenarioSpec(Section):
    """Keys common to every scenario file. A kind subclasses this and implements :meth:`trajectory`."""

    kind: str
    duration_s: Duration
    rate_hz: Rate
    description: str = ""

    pointwise: ClassVar[bool] = False
    """Whether the truth at ``t`` depends on ``t`` alone (a closed form, or a fitted spline): then
    :meth:`Scenario.simulate` evaluates it in segments of :data:`SEGMENT_SAMPLES` (:meth:`Scenario.segment`)
    and a long run reads those segments one at a time (:mod:`gyroemu.dynamics.truth_source`), never the
    whole. Kinds that integrate equations of motion need the whole past and are not."""

    def trajectory(self, t: NDArray[np.float64]) -> Trajectory:
        """Truth sampled at the times ``t`` (s, uniform from 0 at ``rate_hz``)."""
        raise NotImplementedError

    def span_s(self) -> float:
        """Seconds simulated when the caller names none: ``duration_s`` (a kind may compute it)."""
        return self.duration_s

    def default_rate_hz(self) -> float:
        """Truth rate when the caller names none: ``rate_hz`` (a kind may compute it)."""
        return self.rate_hz

    def max_span_s(self) -> float | None:
        """The longest span the kind can simulate, s (None: any)."""
        return None

    def report(self) -> str:
        """What the user should know of the last simulation beyond its size (empty: nothing)."""
        return ""

    @classmethod
    def prepare(cls, data: dict[str, Any], path: Path | None) -> dict[str, Any]:
        """The file's table before validation, given the file's ``path`` (a kind may resolve relative paths)."""
        return data

    def load(self, file: str | Path | None = None) -> None:
        """Read what the scenario refers to, raising :class:`ConfigError` now rather than mid-run."""


class Scenario:
    """A validated scenario, ready to simulate.

    Attributes
    ----------
    spec : ScenarioSpec
        The typed config of the scenario's kind.
    name : str
        The built-in name or the file's stem.
    path : Path or None
        The file it was read from.
    """

    def __init__(self, spec: ScenarioSpec, name: str, path: Path | None = None):
        self.spec = spec
        self.name = name
        self.path = path

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def duration_s(self) -> float:
        return self.spec.span_s()

    @property
    def rate_hz(self) -> float:
        return self.spec.default_rate_hz()

    @property
    def description(self) -> str:
        return self.spec.description

    def times(self, duration: float | None = None, rate_hz: float | None = None) -> NDArray[np.float64]:
        """Sample times ``k / rate_hz`` for ``k = 0 … round(duration · rate_hz)``, s (rounded down where the
        kind's span is bounded, :meth:`ScenarioSpec.max_span_s`)."""
        duration = self.spec.span_s() if duration is None else float(duration)
        rate_hz = self.spec.default_rate_hz() if rate_hz is None else float(rate_hz)
        if not duration > 0:
            raise ConfigError(f"duration must be positive, got {duration}", key="duration")
        if not rate_hz > 0:
            raise ConfigError(f"rate must be positive, got {rate_hz}", key="rate_hz")
        count = int(round(duration * rate_hz))
        if count / rate_hz > duration and self.spec.max_span_s() is not None:
            count = int(np.floor(duration * rate_hz * (1 + 1e-12)))  # a bounded span (a recording): stay inside
        return np.arange(count + 1) / rate_hz

    def simulate(self, duration: float | None = None, rate_hz: float | None = None) -> Trajectory:
        """Simulate the truth; ``duration`` (s) and ``rate_hz`` override the file's values.

        A pointwise kind (:attr:`ScenarioSpec.pointwise`) is evaluated segment by segment
        (:meth:`segment`, on every core at once), the same bytes as a run that reads the segments one at
        a time. A
        ``[site.magnetic_environment]`` replaces the uniform field by the field along the path
        (:func:`gyroemu.dynamics.magnetic_environment.with_magnetic_environment`)."""
        t = self.times(duration, rate_hz)
        if self.spec.pointwise and len(t) > SEGMENT_SAMPLES:
            rate = self.spec.default_rate_hz() if rate_hz is None else float(rate_hz)
            last = len(t) - 1
            count = segment_count(last)
            from concurrent.futures import ThreadPoolExecutor  # where used: the CLI's listings skip it

            # Segments are closed forms in t, independent of each other: made on every core at once (their
            # kernels release the GIL), in order.
            with ThreadPoolExecutor(max_workers=min(count, os.cpu_count() or 1)) as pool:
                traj = concatenate_trajectories(list(pool.map(lambda j: self.segment(j, rate, last), range(count))))
        else:
            traj = self.spec.trajectory(t)
        site = getattr(self.spec, "site", None)
        if site is not None and site.magnetic_environment is not None:
            from .magnetic_environment import with_magnetic_environment

            traj = with_magnetic_environment(traj, site.magnetic_environment)
        return traj

    def segment(self, index: int, rate_hz: float, last: int | None) -> Trajectory:
        """Segment ``index`` of a pointwise kind's run at ``rate_hz`` whose last sample is ``last`` (None:
        a run without end): the samples ``k`` of :func:`segment_bounds`, at ``t_k = k / rate_hz``."""
        lo, hi = segment_bounds(index, last)
        return self.spec.trajectory(np.arange(lo, hi) / rate_hz)  # Scenario.times's t_k

    def to_toml(self) -> str:
        """The fully resolved config (defaults filled in) as TOML text."""
        return tomli_w.dumps(self.spec.model_dump(mode="json", exclude_none=True))

    def __repr__(self) -> str:
        return f"Scenario({self.name!r}, kind={self.kind!r}, duration_s={self.duration_s}, rate_hz={self.rate_hz})"


SEGMENT_SAMPLES = 1 << 16
"""Samples per segment of a pointwise kind's truth (:meth:`Scenario.segment`)."""


def segment_count(last: int) -> int:
    """Segments of a run whose last sample is ``last``."""
    return max(1, (last + 1) // SEGMENT_SAMPLES)


def segment_index(k: int, last: int | None) -> int:
    """The segment holding sample ``k`` of a run whose last sample is ``last`` (None: without end)."""
    index = k // SEGMENT_SAMPLES
    return index if last is None else min(index, segment_count(last) - 1)


def segment_bounds(index: int, last: int | None) -> tuple[int, int]:
    """Samples ``lo … hi − 1`` of segment ``index``: every :data:`SEGMENT_SAMPLES` from 0, the last
    segment of a bounded run taking the remainder (so none is shorter than a segment, bar a run's only one)."""
    lo = index * SEGMENT_SAMPLES
    hi = lo + SEGMENT_SAMPLES
    if last is not None and index == segment_count(last) - 1:
        hi = last + 1
    return lo, hi


def _spec_class(kind: str) -> type[ScenarioSpec]:
    module, cls = KINDS[kind].split(":")
    spec_class: type[ScenarioSpec] = getattr(importlib.import_module(module), cls)
    return spec_class


def scenario_from_dict(data: dict[str, Any], name: str = "<dict>", path: Path | None = None) -> Scenario:
    """Validate a scenario given as a dict (as read from TOML); errors name ``path`` or ``name``."""
    where = path if path is not None else name
    if not isinstance(data, dict):
        raise ConfigError("a scenario is a table of keys", file=where)
    kind = data.get("kind")
    if kind is None:
        raise ConfigError("missing required key", file=where, key="kind")
    if not isinstance(kind, str) or kind not in KINDS:
        raise ConfigError(f"unknown kind {kind!r}; kinds: {', '.join(KINDS)}", file=where, key="kind")
    spec_class = _spec_class(kind)
    spec = validate(spec_class, spec_class.prepare(data, path), file=where)
    spec.load(where)
    return Scenario(spec, name=name, path=path)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name (``configs/scenarios/<name>.toml``) or a TOML file by path.

    Raises
    ------
    ConfigError
        Unknown name, unreadable file, unknown or missing key, bad value; the message names the file
        and key.
    """
    path = resolve_config(name_or_path, "scenarios", "scenario")
    return scenario_from_dict(read_toml(path), name=path.stem, path=path)


def list_scenarios() -> list[Scenario]:
    """The built-in scenarios, loaded and validated, sorted by name."""
    return [load_scenario(p) for p in sorted((config_dir() / "scenarios").glob("*.toml"))]
