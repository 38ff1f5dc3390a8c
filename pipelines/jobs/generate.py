"""``gyroemu generate SPEC.toml --out-dir D``: a dataset of MCAP logs over a campaign's grid, on Dask.

The campaign file is the bench's (:mod:`gyroemu.pipelines.campaign.spec`); ``generate`` uses its
``scenarios``, ``devices``, ``durations_s`` and seeds (``filters``, ``modes``, ``threshold_deg``,
``batched`` are the bench's and ignored here). Each (scenario, device, duration, seed) is one task and
one log, ``<scenario>__<device>__<duration>s__seed<seed>.mcap`` (the duration as :func:`duration_name`
writes it: distinct durations, distinct names), written by
:func:`gyroemu.pipelines.jobs.simulate.run_simulate`: the log carries its scenario and device configs
and its seed in its ``gyroemu`` metadata, and ``gyroemu simulate`` with the arguments of its index row
(``simulate_command``) writes the same bytes.

Workers write the logs straight into ``out_dir`` (on a cluster: a folder every worker sees at the same
path); each log appears whole (a temporary file and a rename). Each finished log's index row is stored
as a Parquet part in ``out_dir/.index/``; at the end ``index.parquet`` and ``index.csv`` list every log
of the campaign with its parameters, config hashes, sample count, size and SHA-256. Started again, the
job makes only the logs that are missing.

Other people's files are never replaced (:func:`check_options`, before any work): a file at a log's
path is kept when it is that log (its ``gyroemu`` metadata: the task's scenario and device configs, by
their hashes, and its seed), and otherwise refused; so is an ``index.parquet`` or ``index.csv`` that is
not an index ``generate`` wrote (its columns, :data:`INDEX_COLUMNS`). A log of the task without its
index part (a run stopped between the two) is made again: the same bytes. Before the work, the temporary
files a killed run left of this campaign's logs and index (``.<name>.<8 characters>.tmp``,
:func:`gyroemu.pipelines.formats.atomic.temporaries`) are removed; no other file. Two ``generate`` runs
into one folder at once are not supported.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyroemu.errors import ConfigError

if TYPE_CHECKING:
    from gyroemu.pipelines.campaign import Campaign, LogTask, TaskFailure

__all__ = [
    "GenerateError",
    "GenerateOptions",
    "GenerateSummary",
    "INDEX_COLUMNS",
    "check_options",
    "duration_name",
    "index_schema",
    "log_tasks",
    "run_generate",
]

INDEX_COLUMNS: dict[str, str] = {
    "file": "string",
    "campaign": "string",
    "scenario": "string",
    "scenario_hash": "string",
    "device": "string",
    "device_hash": "string",
    "duration_s": "float64",
    "seed": "int64",
    "samples": "int64",
    "truth_samples": "int64",
    "bytes": "int64",
    "sha256": "string",
    "simulate_command": "string",
    "gyroemu_version": "string",
}
"""The columns of ``index.parquet`` / ``index.csv`` and their Arrow types."""


class GenerateError(ConfigError):
    """Bad options of ``gyroemu generate`` (the message names the argument and the file at fault)."""


@dataclass(frozen=True)
class GenerateOptions:
    """What ``gyroemu generate`` writes, where, and on which cluster.

    Attributes
    ----------
    spec : Path
        The campaign file (TOML).
    out_dir : Path
        Folder of the logs and the index (made if missing).
    scheduler : str or None
        A Dask scheduler's address; None: a local cluster.
    workers : int or None
        Worker processes of the local cluster (default: one per core).
    processes : bool
        Local workers as processes (default); False: threads of this process (tests).
    progress : bool or None
        A bar on stderr (logs done, total, rate, time left); None: when stderr is a terminal.
    """

    spec: Path
    out_dir: Path
    scheduler: str | None = None
    workers: int | None = None
    processes: bool = True
    progress: bool | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "spec", Path(self.spec))
        object.__setattr__(self, "out_dir", Path(self.out_dir))


@dataclass
class GenerateSummary:
    """What a generate run did."""

    campaign: Campaign
    logs: int
    resumed: int
    made: int
    failures: list[TaskFailure[LogTask]]
    index: Path
    elapsed_s: float


def _stem(entry: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in Path(entry).stem)


def duration_name(duration: float) -> str:
    """``duration`` (seconds) as a log's name writes it: as ``:g`` does (``3``, ``0.5``, ``1e+06``, the
    names of every dataset made so far) where that reads back as ``duration`` exactly, else the shortest
    text that does (``repr``: ``3.000001``, where ``:g`` says ``3``). The name reads back as the duration,
    so two durations never share one."""
    short = f"{duration:g}"
    return short if float(short) == duration else repr(float(duration))


def log_tasks(campaign: Campaign, out_dir: Path) -> list[LogTask]:
    """One :class:`~gyroemu.pipelines.campaign.LogTask` per (scenario, device, duration, seed), in the
    grid's order; :class:`~gyroemu.errors.ConfigError` naming the key (``scenarios``, ``devices``, or
    ``durations_s``) whose two entries would share a file name."""
    from gyroemu.errors import ConfigError
    from gyroemu.pipelines.campaign import LogTask

    out_dir = out_dir.resolve()
    tasks: dict[str, LogTask] = {}
    seen = dict.fromkeys((c.scenario, c.device, c.duration_s, c.scenario_hash, c.device_hash) for c in campaign.cells)
    for scenario, device, duration, sc_hash, dev_hash in seen:
        for seed in campaign.seeds:
            name = f"{_stem(scenario)}__{_stem(device)}__{duration_name(duration)}s__seed{seed}.mcap"
            if name in tasks:
                other = tasks[name]
                pairs = (
                    ("scenarios", other.scenario, scenario, "give scenario files distinct names"),
                    ("devices", other.device, device, "give device files distinct names"),
                    ("durations_s", other.duration_s, duration, "give durations that differ in their names"),
                )
                key, a, b, fix = next((p for p in pairs if p[1] != p[2]), pairs[0])
                raise ConfigError(f"{a!r} and {b!r} make the same log name {name}: {fix}", file=campaign.path, key=key)
            tasks[name] = LogTask(
                campaign.name, scenario, device, duration, seed, sc_hash, dev_hash, str(out_dir / name)
            )
    return list(tasks.values())


def index_schema() -> Any:
    """:data:`INDEX_COLUMNS` as a ``pyarrow.Schema``."""
    from gyroemu.pipelines.campaign.store import arrow_schema

    return arrow_schema(INDEX_COLUMNS)


def _log_mismatch(task: LogTask) -> str | None:
    """Why the file at ``task``'s path is not that log (None when it is): not an MCAP file, no ``gyroemu``
    metadata, or another scenario, device or seed."""
    from mcap.reader import make_reader

    from gyroemu.pipelines.campaign import config_hash

    try:
        with open(task.out, "rb") as f:
            if f.read(8) != b"\x89MCAP0\r\n":
                return "not an MCAP file"
            f.seek(0)
            records = [m.metadata for m in make_reader(f).iter_metadata() if m.name == "gyroemu"]
    except Exception as exc:  # any reader's complaint: not a log of ours
        return f"an MCAP file that cannot be read ({type(exc).__name__})"
    if len(records) != 1:
        return "not a gyroemu log of one device"
    meta = records[0]
    if meta.get("seed") != str(task.seed):
        return f"the log of seed {meta.get('seed') or '(none)'}, not {task.seed}"
    for what, text, digest in (
        ("scenario", meta.get("scenario", ""), task.scenario_hash),
        ("device", meta.get("device", ""), task.device_hash),
    ):
        if config_hash(text) != digest:
            return f"a log of another {what} config"
    return None


def _foreign_index(path: Path) -> bool:
    """Whether ``path`` (an existing ``index.parquet`` or ``index.csv``) is not an index ``generate`` wrote."""
    if path.is_dir():
        return True
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq

            foreign: bool = pq.read_schema(path).names != list(INDEX_COLUMNS)  # pyarrow ships no types
            return foreign
        with open(path, encoding="utf-8") as f:
            header = f.readline().rstrip("\r\n")
    except Exception:  # unreadable, or not Parquet / UTF-8 text: not ours
        return True
    return header != ",".join(f'"{name}"' for name in INDEX_COLUMNS)


def check_options(options: GenerateOptions, tasks: list[LogTask]) -> None:
    """:class:`GenerateError` naming the argument (and the file at fault), before any work: a scheduler
    address that is none; an ``out_dir`` that is not a folder or cannot take files (read-only, not
    writable; where it would be made when missing); a file at a log's path that is not that log
    (:func:`_log_mismatch`); an ``index.parquet``, ``index.csv`` or ``.index`` there that is not
    ``generate``'s."""
    from gyroemu.pipelines.campaign import scheduler_problem
    from gyroemu.pipelines.formats.atomic import output_folder_problem

    if options.scheduler is not None:
        problem = scheduler_problem(options.scheduler)
        if problem is not None:
            raise GenerateError(f"argument --scheduler: {problem}")
    out = options.out_dir
    problem = output_folder_problem(out)
    if problem is not None:
        raise GenerateError(f"argument --out-dir: {problem}")
    if not out.is_dir():
        return
    keep = "generate replaces no file of anyone else's: move it away, or choose another --out-dir"
    for task in tasks:
        path = out / Path(task.out).name  # task.out made absolute
        if path.is_dir():
            raise GenerateError(f"argument --out-dir: {path} is a folder where a log goes: {keep}")
        if path.exists() or path.is_symlink():
            why = _log_mismatch(task) if path.is_file() else "not a file"
            if why is not None:
                raise GenerateError(f"argument --out-dir: {path} is not this campaign's log ({why}): {keep}")
    for name in ("index.parquet", "index.csv"):
        if (out / name).exists() and _foreign_index(out / name):
            raise GenerateError(f"argument --out-dir: {out / name} is not an index 'gyroemu generate' wrote: {keep}")
    if (out / ".index").exists() and not (out / ".index").is_dir():
        raise GenerateError(f"argument --out-dir: {out / '.index'} is not a folder: {keep}")


def run_generate(options: GenerateOptions) -> GenerateSummary:
    """Write the campaign's logs and their index (see the module's notes).

    Raises
    ------
    gyroemu.errors.ConfigError
        A bad campaign file (names the file and key), before any work; :class:`GenerateError` for bad
        options or files in ``out_dir`` it would replace (:func:`check_options`).
    gyroemu.pipelines.campaign.SchedulerLostError
        The scheduler unreachable or lost; the finished logs and their index parts are kept, and a new
        run makes the missing logs and writes the index.
    """
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    from gyroemu.pipelines.campaign import PartStore, load_campaign, make_log, readable, run_tasks
    from gyroemu.pipelines.campaign.progress import RunsProgress
    from gyroemu.pipelines.formats.atomic import temporaries, write_atomic

    campaign = load_campaign(options.spec)
    out = options.out_dir
    if out.exists() and not out.is_dir():
        raise GenerateError(f"argument --out-dir: {out} is not a folder")
    tasks = log_tasks(campaign, out)
    check_options(options, tasks)
    out.mkdir(parents=True, exist_ok=True)
    store = PartStore(out / ".index", index_schema())
    keys = [t.key for t in tasks]
    # what a killed run was writing (a worker's log, an index part, the index): never to be completed
    stale = temporaries(out, [Path(t.out).name for t in tasks] + ["index.parquet", "index.csv"])
    for tmp in stale + store.temporaries(keys):
        tmp.unlink(missing_ok=True)
    missing = store.missing(keys)
    todo = [t for t in tasks if t.key in missing or not Path(t.out).is_file()]
    resumed = len(tasks) - len(todo)
    made = 0
    started = time.perf_counter()
    with RunsProgress(len(tasks), resumed, label="generate", unit="logs", enabled=options.progress) as bar:

        def stored(task: LogTask, rows: list[dict[str, Any]]) -> None:
            nonlocal made
            store.write(task.key, rows)
            made += 1
            bar.advance(1)

        failures = run_tasks(
            todo,
            make_log,
            stored,
            scheduler=options.scheduler,
            workers=options.workers,
            processes=options.processes,
            label=lambda t: t.key,
        )
    table = store.read(t.key for t in tasks)
    index = out / "index.parquet"
    readable(write_atomic(index, lambda f: pq.write_table(table, f)))
    readable(write_atomic(out / "index.csv", lambda f: pacsv.write_csv(table, f)))
    return GenerateSummary(
        campaign=campaign,
        logs=len(tasks),
        resumed=resumed,
        made=made,
        failures=failures,
        index=index,
        elapsed_s=time.perf_counter() - started,
    )
