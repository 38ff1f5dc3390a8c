"""``gyroemu twin``: a recording with truth beside its emulated twins, through the attitude filters.

The job: its options (:class:`TwinOptions`), every one checked before any work (:class:`TwinError`,
naming the argument), and :func:`run_twin`, which loads the recordings, runs the real log and each twin
through every filter in ``workers`` processes, and returns the report. What a twin is, how it is run and
scored, and what the report holds: :mod:`gyroemu.pipelines.twin` (one module per idea). Outputs in
``--out``: ``twin.md``, ``twin.json`` and ``<trial>.png``, each written through a temporary file; an
existing non-empty folder is refused without ``force``, and a file of the report that is an input (a
recording, the device or site file) even with it.
"""

from __future__ import annotations

import datetime
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gyroemu.errors import ConfigError
from gyroemu.pipelines.formats.atomic import folder_problem, report_files_problem
from gyroemu.pipelines.formats.file_names import repeated_file, unique_stems
from gyroemu.pipelines.twin import (
    METRICS,
    RANKED_FILTERS,
    RECORDING_FORMATS,
    TAUS_S,
    TWIN_GYRO_CROSSOVER_HZ,
    TWIN_SMOOTHING,
    Handling,
    Recording,
    SiteFileError,
    TwinReport,
    format_vector,
    load_recording,
    pooled_residuals,
    read_site,
    residual_allan,
    rest_phases,
    run_one_twin,
    run_real,
    trial_result,
    twin_attitude,
    twin_scenario,
    twin_seed,
)

if TYPE_CHECKING:
    from gyroemu.dynamics.scenarios import Scenario
    from gyroemu.pipelines.estimation.protocol import FilterSetup
    from gyroemu.sensors import Device

__all__ = [
    "METRICS",
    "RANKED_FILTERS",
    "TAUS_S",
    "TWIN_GYRO_CROSSOVER_HZ",
    "TWIN_SMOOTHING",
    "TwinError",
    "TwinOptions",
    "TwinReport",
    "check_options",
    "cpu_workers",
    "report_files",
    "twin_attitude",
    "twin_seed",
    "default_site_file",
    "run_twin",
    "residual_allan",
]


class TwinError(ConfigError):
    """Bad options of ``gyroemu twin``, found before any work (the message names the argument)."""


def default_site_file() -> Path:
    """The built-in site of the BROAD lab: ``configs/sites/broad_lab.toml``."""
    from gyroemu.dynamics.config import config_dir

    return Path(config_dir()) / "sites" / "broad_lab.toml"


@dataclass(frozen=True)
class TwinOptions:
    """What ``gyroemu twin`` reads and writes.

    Attributes
    ----------
    trials : recordings with truth (BROAD ``.hdf5`` or gyroemu ``.mcap``).
    device : the emulated device (built-in name or TOML path).
    seeds : number of twins per trial (seeds 0 … seeds − 1).
    filters : filter names (default: every available built-in).
    out : folder for ``twin.md``, ``twin.json`` and the plots.
    force : write into an existing non-empty folder.
    site : TOML file whose ``[site]`` table is the twins' site (and whose optional ``[handling]`` table
        is the accelerometer's offset while carried, module notes).
    workers : processes for the runs (1: in this process).
    smoothing : the recorded scenario's ``[smoothing]`` table (default :data:`TWIN_SMOOTHING`).
    """

    trials: Sequence[Path]
    device: str = "aktos_t_broad"
    seeds: int = 5
    filters: Sequence[str] | None = None
    out: Path = Path("twin")
    force: bool = False
    site: Path = field(default_factory=default_site_file)
    workers: int = 2
    smoothing: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        if self.smoothing is None:
            object.__setattr__(self, "smoothing", dict(TWIN_SMOOTHING))
        object.__setattr__(self, "trials", tuple(Path(p) for p in self.trials))
        object.__setattr__(self, "out", Path(self.out))
        object.__setattr__(self, "site", Path(self.site))
        if self.filters is not None:
            object.__setattr__(self, "filters", tuple(dict.fromkeys(self.filters)))


def check_options(options: TwinOptions) -> tuple[list[str], dict[str, str], dict[str, Any], Handling | None, Device]:
    """:class:`TwinError` for any bad option. Returns the filters, those left out, the site table, the
    site's handling offset (None without a ``[handling]`` table) and the device (seed 0). A file of the
    report (:func:`report_files`) that is an input (a recording, the device or site file, by any path
    to it) is refused, even with ``force``."""
    from gyroemu.pipelines.estimation.protocol import FilterSetup
    from gyroemu.pipelines.estimation.registry import FilterError, available_filters, make_filter, unavailable_filters
    from gyroemu.sensors import load_device

    if not options.trials:
        raise TwinError("argument TRIAL: give at least one recording")
    for trial in options.trials:
        if not trial.is_file():
            raise TwinError(f"argument TRIAL: {trial}: no such file")
        if trial.suffix.lower() not in RECORDING_FORMATS:
            raise TwinError(f"argument TRIAL: {trial}: expected a BROAD .hdf5 trial or a gyroemu .mcap log")
    twice = repeated_file(options.trials)
    if twice is not None:  # reported twice, and its rests pooled twice
        first, again = twice
        alias = "" if str(first) == str(again) else f" (as {first})"
        raise TwinError(f"argument TRIAL: {again} is given twice{alias}: give each recording once")
    if isinstance(options.seeds, bool) or not isinstance(options.seeds, int) or options.seeds < 1:
        raise TwinError(f"argument --seeds: must be a whole number of at least 1, got {options.seeds!r}")
    if isinstance(options.workers, bool) or not isinstance(options.workers, int) or options.workers < 1:
        raise TwinError(f"argument --workers: must be a whole number of at least 1, got {options.workers!r}")
    try:
        device = load_device(options.device, seed=0)
    except ConfigError as e:
        raise TwinError(f"argument --device: {e}") from None
    unavailable: dict[str, str] = {}
    if options.filters is None:
        filters = available_filters()
        unavailable = unavailable_filters()
    else:
        filters = list(options.filters)
        if not filters:
            raise TwinError("argument --filter: give at least one filter")
        # each made once, as every run makes it (the filters' defaults at the twins' rate): a class that
        # does not import, whose constructor fails, or without a 'name' or 'process' is named here, not
        # in a note after every run failed
        probe = FilterSetup(rate_hz=float(device.spec.rate_hz))
        for spec in filters:
            try:
                make_filter(spec, probe)
            except FilterError as e:
                raise TwinError(f"argument --filter: {e}") from None
    try:
        site, handling = read_site(options.site)
    except SiteFileError as e:
        raise TwinError(f"argument --site: {e}") from None
    out = options.out
    if out.exists():
        if not out.is_dir():
            raise TwinError(f"argument --out: {out} is not a folder")
        if any(out.iterdir()) and not options.force:
            raise TwinError(f"argument --out: {out} is not empty (use --force to write into it)")
    folder = out if out.exists() else out.parent  # the report's folder, or where it is made
    problem = folder_problem(folder)
    if problem is not None:
        raise TwinError(f"argument --out: {folder}: {problem}")
    inputs = [*options.trials, options.site, *([Path(device.path)] if device.path else [])]
    problem = report_files_problem(out, report_files(options.trials), inputs)  # even with --force
    if problem is not None:
        raise TwinError(f"argument --out: {problem}")
    return filters, unavailable, site, handling, device


def report_files(trials: Sequence[Path]) -> list[str]:
    """The names of the files the report of ``trials`` writes in its folder: ``twin.json``, ``twin.md``
    and one ``<trial>.png`` per recording (:meth:`TwinReport.save`)."""
    return ["twin.json", "twin.md", *(f"{stem}.png" for stem in unique_stems([Path(t).stem for t in trials]))]


def _check_smoothing(smoothing: dict[str, Any] | None, real: Recording) -> None:
    """:class:`TwinError` naming ``--smoothing`` for a key the recorded scenario's ``[smoothing]`` does not
    take, a bad value, or a cut-off at or above the Nyquist frequency of the truth's stamps (the motion
    is fitted there), and naming ``TRIAL`` for a gap in its reference longer than ``max_gap_s`` (found
    otherwise only when the first twin fits its motion, after the real run)."""
    from pydantic import ValidationError

    from gyroemu.dynamics.smoothing_spline import contiguous_runs
    from gyroemu.pipelines.recorded_scenario import SmoothingSpec

    try:
        spec = SmoothingSpec(**(smoothing or {}))
    except ValidationError as e:
        problems = "; ".join(f"{'.'.join(map(str, err['loc']))}: {err['msg']}" for err in e.errors())
        raise TwinError(f"argument --smoothing: {problems}") from None
    from gyroemu.dynamics.smoothing_spline import lambda_for_cutoff

    # the recorded motion is fitted at the truth's stamps, which may be sparser than the samples': the
    # cut-off is checked as the fit will check it, against their median step
    truth_t = real.t[np.isfinite(real.q_true).all(axis=1)]
    # a gap as the fit finds it: a step between the truth's stamps that splits their runs
    for run in contiguous_runs(truth_t)[1:]:
        before, gap = float(truth_t[run.start - 1]), float(truth_t[run.start] - truth_t[run.start - 1])
        if gap > spec.max_gap_s:
            raise TwinError(
                f"argument TRIAL: {real.path}: a gap of {gap:.4g} s without a reference after t = {before:.6g} s "
                f"is longer than smoothing.max_gap_s = {spec.max_gap_s:g} s (--smoothing max_gap_s=SECONDS "
                "bridges it)"
            )
    step = float(np.median(np.diff(truth_t))) if len(truth_t) > 1 else 1.0 / real.rate_hz
    for key in ("position_cutoff_hz", "orientation_cutoff_hz"):
        value = getattr(spec, key)
        if value is not None:
            try:
                lambda_for_cutoff(value, step)
            except ValueError as e:
                raise TwinError(f"argument --smoothing: {key}: {real.path.name}: {e}") from None


def _trial_error(path: Path, error: Exception) -> TwinError:
    """:class:`TwinError` naming ``argument TRIAL`` and ``path`` once, for ``error`` reading or checking it:
    the readers' messages start with the file already, and the recorded scenario made of the recording
    names it (by its name) with its key ``path`` before its reader's message, which names it again."""
    text = str(error)
    for prefix in ((f"{path}: ", f"{path.name}: "), ("key 'path': ",), (f"{path}: ",)):
        text = next((text.removeprefix(p) for p in prefix if text.startswith(p)), text)
    return TwinError(f"argument TRIAL: {path}: {text}")


def run_twin(options: TwinOptions) -> TwinReport:
    """Run the real recordings and their twins through the filters (module notes) and return the report
    (:meth:`TwinReport.save` writes it).

    Raises
    ------
    TwinError
        A bad option, named, before any work (also a recording that cannot be read or has no truth).
    """
    from gyroemu.pipelines.estimation.protocol import FilterSetup
    from gyroemu.pipelines.estimation.setup import setup_from_metadata

    started = time.perf_counter()
    filters, unavailable, site, handling, device = check_options(options)
    reals: list[Recording] = []
    scenarios: list[Scenario] = []  # twin 0's, whose site (--site) every twin's filters are set up in
    for path in options.trials:
        try:
            real = load_recording(path)
            _check_smoothing(options.smoothing, real)
            scenarios.append(twin_scenario(real, site, 0, options.smoothing))  # the recorded motion reads and checks
        except TwinError:
            raise
        except Exception as e:  # noqa: BLE001 - LogError, ConfigError and friends: the file at fault
            raise _trial_error(path, e) from None
        same_name = sum(earlier.name == real.name for earlier in reals)  # their twins draw apart
        reals.append(replace(real, same_name_index=same_name))
    timings: dict[str, float] = {"load and check": time.perf_counter() - started}
    has_dev_mag = device.spec.magnetometer is not None
    plans = []
    tasks: list[tuple[Any, Any, Any]] = []
    for i, real in enumerate(reals):
        mode = "9D" if real.mag is not None and has_dev_mag else "6D"
        setup9: FilterSetup | None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if real.metadata:
                setup9 = setup_from_metadata(real.metadata, real.rate_hz, use_mag=True)
                setup6 = setup_from_metadata(real.metadata, real.rate_hz, use_mag=False)
            else:
                setup9, setup6 = FilterSetup(rate_hz=real.rate_hz, use_mag=True), FilterSetup(rate_hz=real.rate_hz)
        if mode == "6D":
            setup9 = None
        twin9, twin6 = _twin_setups(real, setup9, setup6, scenarios[i], device)
        rests, rest_info = rest_phases(real)
        plans.append((mode, rest_info))
        tasks.append(((i, None), run_real, (real, filters, setup9, setup6, rests)))
        rest_t = rest_info["intervals_s"]
        attitude_started = time.perf_counter()
        delay = device.latencies[0] + 0.5 / device.spec.rate_hz  # an interval mean lags by half a sample
        attitude = twin_attitude(
            real.t, real.q_true, real.gyro, rest_info["still_s"], delay, device.spec.mounting.q_bs
        )  # one device, one attitude: the seeds draw only the device's errors and the site
        timings["twin attitude"] = timings.get("twin attitude", 0.0) + time.perf_counter() - attitude_started
        for seed in range(options.seeds):
            tasks.append(
                (
                    (i, seed),
                    run_one_twin,
                    (
                        real,
                        site,
                        options.smoothing,
                        options.device,
                        seed,
                        filters,
                        twin9,
                        twin6,
                        rest_t,
                        attitude,
                        handling,
                    ),
                )
            )
    results: dict[tuple[int, int | None], dict[str, Any]] = {}
    run_started = time.perf_counter()
    workers = min(options.workers, len(tasks))
    if workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # Heaviest first (the real run and the twins cost alike): plain order is fine.
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork")) as pool:
            for key, out in pool.map(_task, tasks):
                results[key] = out
    else:
        for task in tasks:
            key, out = _task(task)
            results[key] = out
    timings["runs (wall)"] = time.perf_counter() - run_started
    for out in results.values():
        for k, v in out["timings"].items():
            timings[k] = timings.get(k, 0.0) + v
    trials = []
    for i, real in enumerate(reals):
        mode, rest_info = plans[i]
        twins = [results[(i, s)] for s in range(options.seeds)]
        trials.append(
            trial_result(real, results[(i, None)], twins, filters, mode, rest_info, options.seeds, device.spec.rate_hz)
        )
    timings["total"] = time.perf_counter() - started
    settings = {
        "device": options.device,
        "seeds": options.seeds,
        "filters": filters,
        "site": str(options.site),
        "workers": workers,
        "smoothing": dict(options.smoothing or {}),
        "trials": [str(p) for p in options.trials],
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    notes = [f"{name} left out: {why}" for name, why in unavailable.items()]
    if any(_knows_its_setup(real) for real in reals):
        notes.append(
            "filter setup: each side's own (a gyroemu log's from its metadata, its device in its site; its "
            "twins' from --device in --site; a recording without metadata: the filters' defaults at each "
            "side's rate, as gyroemu bench does)"
        )
    else:
        notes.append(
            "filter setup: the same for the real log and its twins (the log's gyroemu metadata, else the "
            "filters' defaults at the recording's rate, as gyroemu bench does)"
        )
    if handling is not None:
        notes.append(
            "handling: over each recording's movement mask every twin's accelerometer reads an offset drawn "
            f"from N({format_vector(handling.accel_offset)}, sd {format_vector(handling.accel_offset_sigma)}) m/s² "
            "(the site file's [handling], seeded by the twin's seed; a recording without a movement mask: none)"
        )
    timings = {k: round(v, 3) for k, v in timings.items()}
    pooled = pooled_residuals(
        [results[(i, None)] for i in range(len(reals))],
        [[results[(i, seed)] for i in range(len(reals))] for seed in range(options.seeds)],
    )
    return TwinReport(trials=trials, settings=settings, timings=timings, notes=notes, pooled_residuals=pooled)


def _knows_its_setup(real: Recording) -> bool:
    """Whether ``real`` says what sensed it: a gyroemu log's metadata holds its device (and scenario)."""
    return bool(real.metadata and real.metadata.get("device"))


def _twin_setups(
    real: Recording, setup9: FilterSetup | None, setup6: FilterSetup, scenario: Scenario, device: Device
) -> tuple[FilterSetup | None, FilterSetup]:
    """The twins' 9D (None when ``setup9`` is: the run is 6D) and 6D filter setups. The twins are
    sampled at ``device``'s rate, and their filters are told it. A log that says what sensed it
    (:func:`_knows_its_setup`) gives its own filters its device's latencies and its site's declination and
    latitude; the twins' are ``device``'s in the twins' ``scenario`` (its ``[site]``, from ``--site``), as
    :func:`~gyroemu.pipelines.estimation.setup.setup_for` gives a simulated run. Otherwise (a BROAD
    trial) both sides take the filters' defaults, ``setup9`` and ``setup6`` at the twins' rate."""
    from gyroemu.pipelines.estimation.setup import setup_for

    if _knows_its_setup(real):
        twin9 = None if setup9 is None else setup_for(device, scenario, use_mag=True)
        return twin9, setup_for(device, scenario, use_mag=False)
    rate_hz = float(device.spec.rate_hz)
    return None if setup9 is None else replace(setup9, rate_hz=rate_hz), replace(setup6, rate_hz=rate_hz)


def _task(
    payload: tuple[tuple[int, int | None], Callable[..., dict[str, Any]], tuple[Any, ...]],
) -> tuple[tuple[int, int | None], dict[str, Any]]:
    key, fn, args = payload
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        started = time.perf_counter()
        out = fn(*args)
        out["wall_s"] = time.perf_counter() - started
    return key, out


def cpu_workers() -> int:
    """Default worker count: 2, or 1 on a single core."""
    return max(1, min(2, os.cpu_count() or 1))
