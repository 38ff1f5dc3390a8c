"""A campaign file (TOML), validated at the edge into typed objects, and the grid of tasks it makes.

A campaign is the grid scenarios × devices × durations × modes (the *cells*) × seeds, each filter run
on each. The file holds these top-level keys (every other key is refused, naming the file and key)::

    name = "example"                      # optional label (default: the file's stem)
    scenarios = ["smooth_manoeuvre"]      # built-in names or TOML paths (relative to this file)
    devices = ["consumer_mems"]           # built-in names or TOML paths (relative to this file)
    durations_s = [60.0]                  # seconds per run (default [60.0]; at most 1e7, as simulate's)
    seeds = [0, 1, 2]                     # device seeds, or instead:
    seed_range = { start = 0, count = 100 }   # seeds start … start + count − 1 (default 0 … 2)
    filters = ["mekf", "madgwick"]        # default: every available built-in
    modes = ["9D", "6D"]                  # default ["9D"]; a device without magnetometer is 6D
    threshold_deg = 2.0                   # convergence threshold
    batched = true                        # the mekf over a task's seeds at once (mekf_batch)
    seeds_per_task = 25                   # seeds per task (one task: one cell × a slice of seeds)

:func:`load_campaign` reads and checks everything before any work: a bad key or value (a ``seed_range``
whose last seed passes 2**63 − 1), an unknown scenario, device or filter, one config under two names (a
built-in's name and its file's path: two cells of one task key) raise
:class:`~gyroemu.errors.ConfigError` naming the file and key. The
tasks (:class:`CellTask`) carry hashes of the resolved scenario and device configs, and their key
(:attr:`CellTask.key`) is a hash of everything that decides their rows, so a resumed campaign skips
exactly the tasks whose results are already stored.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, StrictBool, model_validator

from gyroemu.dynamics.config import ConfigError, PositiveReal, Section, at_most, read_toml, validate
from gyroemu.dynamics.scenarios import MAX_DURATION_S

__all__ = [
    "Campaign",
    "CampaignSpec",
    "Cell",
    "CellTask",
    "SeedRange",
    "campaign_from_spec",
    "config_hash",
    "load_campaign",
]

SEED_LIMIT = 2**63  # seeds are stored as int64

Seed = Annotated[int, Field(ge=0, lt=SEED_LIMIT, strict=True)]

Duration = Annotated[PositiveReal, at_most(MAX_DURATION_S, "the longest run 'gyroemu simulate --duration' takes")]


class SeedRange(Section):
    """Seeds ``start … start + count − 1``, every one of them below :data:`SEED_LIMIT`."""

    start: Seed = 0
    count: Annotated[int, Field(ge=1, le=10_000_000, strict=True)]

    @model_validator(mode="after")
    def _last_seed_fits(self) -> SeedRange:
        if self.start + self.count > SEED_LIMIT:
            raise ValueError(
                f"start + count must be at most 2**63 = {SEED_LIMIT} (seeds are stored as int64): the last seed "
                f"would be {self.start + self.count - 1}"
            )
        return self


class CampaignSpec(Section):
    """A campaign file's keys (see the module's notes)."""

    name: str | None = None
    scenarios: Annotated[list[str], Field(min_length=1)]
    devices: Annotated[list[str], Field(min_length=1)]
    durations_s: Annotated[list[Duration], Field(min_length=1)] = [60.0]
    seeds: Annotated[list[Seed], Field(min_length=1)] | None = None
    seed_range: SeedRange | None = None
    filters: Annotated[list[str], Field(min_length=1)] | None = None
    modes: Annotated[list[Literal["9D", "6D"]], Field(min_length=1)] = ["9D"]
    threshold_deg: PositiveReal = 2.0
    batched: StrictBool = True
    seeds_per_task: Annotated[int, Field(ge=1, strict=True)] = 25

    @model_validator(mode="after")
    def _one_seed_source(self) -> CampaignSpec:
        if self.seeds is not None and self.seed_range is not None:
            raise ValueError("give seeds or seed_range, not both")
        return self

    def seed_list(self) -> list[int]:
        """The device seeds, ascending, each once."""
        if self.seeds is not None:
            return sorted(set(self.seeds))
        r = self.seed_range or SeedRange(start=0, count=3)
        return list(range(r.start, r.start + r.count))


def config_hash(text: str) -> str:
    """The first 16 hex digits of the SHA-256 of a config's TOML text."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Cell:
    """One (scenario, device, duration, mode) of the grid; ``scenario`` and ``device`` as the workers
    load them (a built-in name or an absolute path), with the hashes of their resolved configs."""

    scenario: str
    device: str
    duration_s: float
    mode: str  # "9D" or "6D"
    scenario_hash: str
    device_hash: str

    @property
    def label(self) -> str:
        return f"{Path(self.scenario).stem} × {Path(self.device).stem}, {self.duration_s:g} s, {self.mode}"


@dataclass(frozen=True)
class CellTask:
    """The unit of work: one cell × a slice of seeds, every filter on each run."""

    campaign: str
    cell: Cell
    seeds: tuple[int, ...]
    filters: tuple[str, ...]
    threshold_deg: float
    batched: bool

    @property
    def key(self) -> str:
        """A hash of everything that decides the task's rows (configs by content, not by name)."""
        c = self.cell
        ident = {
            "scenario_hash": c.scenario_hash,
            "device_hash": c.device_hash,
            "duration_s": c.duration_s,
            "mode": c.mode,
            "seeds": list(self.seeds),
            "filters": list(self.filters),
            "threshold_deg": self.threshold_deg,
            "batched": self.batched,
        }
        return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:24]

    @property
    def runs(self) -> int:
        """Rows the task makes: seeds × filters."""
        return len(self.seeds) * len(self.filters)


@dataclass(frozen=True)
class Campaign:
    """A validated campaign: its spec, where it came from, its cells and tasks."""

    spec: CampaignSpec
    name: str
    path: Path | None
    filters: tuple[str, ...]
    seeds: tuple[int, ...]
    cells: tuple[Cell, ...]
    tasks: tuple[CellTask, ...]
    unavailable: dict[str, str]

    @property
    def runs(self) -> int:
        """Rows of the whole campaign: cells × seeds × filters."""
        return sum(t.runs for t in self.tasks)


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file; :class:`ConfigError` naming the file and key for anything wrong
    (a bad key or value, an unknown scenario, device or filter, one config under two names), before any
    work."""
    path = Path(path)
    spec = validate(CampaignSpec, read_toml(path), file=path)
    return campaign_from_spec(spec, path=path)


def _entry(text: str, base: Path | None) -> str:
    """A scenario or device entry as workers load it: a path made absolute (relative to the campaign
    file's folder), a built-in name as it is."""
    p = Path(text)
    if text.endswith(".toml") or "/" in text:
        if not p.is_absolute() and base is not None:
            p = base / p
        return str(p.resolve())
    return text


class _SameConfig:
    """The scenario or device entries seen so far by their configs' hashes: :meth:`check` refuses a second
    entry that is the same config under another name (the same name again is one entry, taken once)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.seen: dict[tuple[str, str], tuple[int, str]] = {}  # (key, hash) -> (index, entry)

    def check(self, key: str, i: int, entry: str, digest: str) -> None:
        """:class:`ConfigError` naming ``key[i]`` and the earlier entry when ``entry`` (``key[i]``) has the
        config ``digest`` of another entry of ``key``."""
        first = self.seen.setdefault((key, digest), (i, entry))
        if first[1] != entry:
            raise ConfigError(
                f"{entry!r} is the same config as {key}[{first[0]}] ({first[1]!r}): their runs would be one task; "
                "give each config once",
                file=self.path,
                key=f"{key}[{i}]",
            )


def campaign_from_spec(spec: CampaignSpec, *, path: Path | None = None) -> Campaign:
    """The cells and tasks of ``spec`` (``path``: its file, for messages and relative paths); loads each
    scenario, device and filter once to check it and hash its config."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.pipelines.estimation.registry import (
        FilterError,
        available_filters,
        filter_class,
        unavailable_filters,
    )
    from gyroemu.pipelines.jobs.run_span import short_run_problem
    from gyroemu.sensors import load_device

    base = None if path is None else path.parent

    def named(key: str, i: int, exc: Exception) -> ConfigError:
        if isinstance(exc, ConfigError) and exc.file is not None and exc.file != str(path):
            return exc  # a bad scenario or device file: it names its own file and key
        reason = exc.reason if isinstance(exc, ConfigError) else str(exc)
        return ConfigError(reason, file=path, key=f"{key}[{i}]")

    # A config given twice under two names (a built-in's name and its file's path, two copies of one
    # file) would make two cells of one task key, one of which is never stored: refused, naming both.
    same = _SameConfig(path)
    scenarios: dict[str, str] = {}
    truth_rates: dict[str, tuple[str, float]] = {}  # entry -> the scenario's name and truth rate
    for i, text in enumerate(spec.scenarios):
        entry = _entry(text, base)
        try:
            scenario = load_scenario(entry)
        except ConfigError as exc:
            raise named("scenarios", i, exc) from None
        digest = config_hash(scenario.to_toml())
        same.check("scenarios", i, entry, digest)
        scenarios.setdefault(entry, digest)
        truth_rates.setdefault(entry, (scenario.name, scenario.rate_hz))
    devices: dict[str, tuple[str, bool]] = {}
    device_rates: dict[str, tuple[str, float]] = {}
    for i, text in enumerate(spec.devices):
        entry = _entry(text, base)
        try:
            device = load_device(entry, seed=0)
        except ConfigError as exc:
            raise named("devices", i, exc) from None
        digest = config_hash(device.to_toml())
        same.check("devices", i, entry, digest)
        devices.setdefault(entry, (digest, device.spec.magnetometer is not None))
        device_rates.setdefault(entry, (device.name, device.spec.rate_hz))
    for i, duration in enumerate(spec.durations_s):  # two truth samples and two of every device's
        for scenario_name, truth_rate in truth_rates.values():
            for device_name, rate in device_rates.values():
                problem = short_run_problem(float(duration), scenario_name, truth_rate, device_name, rate)
                if problem is not None:
                    raise ConfigError(problem, file=path, key=f"durations_s[{i}]")
    unavailable: dict[str, str] = {}
    if spec.filters is None:
        filters = tuple(available_filters())
        unavailable = dict(unavailable_filters())
    else:
        filters = tuple(dict.fromkeys(spec.filters))
        for i, name in enumerate(spec.filters):
            try:
                filter_class(name)
            except FilterError as exc:
                raise ConfigError(str(exc), file=path, key=f"filters[{i}]") from None
    seeds = tuple(spec.seed_list())
    cells: list[Cell] = []
    for sc, sc_hash in scenarios.items():
        for dev, (dev_hash, has_mag) in devices.items():
            for duration in dict.fromkeys(spec.durations_s):
                # A device without a magnetometer is 6D whatever is asked: one cell, not two alike.
                for mode in dict.fromkeys(m if has_mag else "6D" for m in spec.modes):
                    cells.append(Cell(sc, dev, float(duration), mode, sc_hash, dev_hash))
    name = spec.name or (path.stem if path is not None else "campaign")
    step = spec.seeds_per_task
    tasks = tuple(
        CellTask(name, cell, seeds[i : i + step], filters, float(spec.threshold_deg), spec.batched)
        for cell in cells
        for i in range(0, len(seeds), step)
    )
    return Campaign(spec, name, path, filters, seeds, tuple(cells), tasks, unavailable)
