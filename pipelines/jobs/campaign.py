"""``gyroemu bench --campaign SPEC.toml``: a bench over a grid of cells and seeds, on Dask distributed.

The campaign file (:mod:`gyroemu.pipelines.campaign.spec`) makes cells (scenario × device × duration ×
mode) and seeds; a task is one cell × a slice of seeds (``seeds_per_task``) and runs every filter on
each, through :func:`gyroemu.pipelines.jobs.bench.run_bench` (the batched mekf over the whole slice).
Tasks run on the scheduler ``scheduler`` or, by default, on a local cluster of one single-threaded
worker process per core (:mod:`gyroemu.pipelines.campaign.engine`).

Outputs in ``out``:

- ``runs/part-<task>.parquet``: one row per run × filter (:data:`~gyroemu.pipelines.campaign.ROW_COLUMNS`),
  one part per finished task, written atomically as it finishes (``pyarrow.dataset.dataset(out /
  "runs")`` or ``pandas.read_parquet`` read the folder as one table). Started again, the campaign
  runs only the tasks without a part: nothing twice, nothing lost.
- ``bench.md``, ``bench.json`` (the format of ``gyroemu bench``, plus a ``campaign`` section), and one
  box plot per cell (the per-run RMSE of each filter), all drawn from the stored rows; all or none of
  them (:func:`save_campaign_report`).

A task that raises is reported (``bench.md``, ``bench.json``, :attr:`CampaignSummary.failures`) and the
others complete; a lost scheduler raises :class:`~gyroemu.pipelines.campaign.SchedulerLostError`
after the finished tasks are stored.

Before any work (:func:`check_options`): the scheduler's address, and ``out``: a folder that can take
files (made if missing), whose ``runs`` is a folder if there, and whose report files (``bench.md``,
``bench.json``, ``.png``) are this campaign's own (beside its ``runs/`` store, rewritten on each run) or
may be overwritten (``force``).

Which campaign ``out`` holds is its ``bench.json``'s ``settings.campaign`` ``name`` and ``file`` (the
campaign file as given, None for ``gyroemu bench --scheduler``'s flags), or, before a first report, the
``campaign`` column of a part in ``runs/``: the name labels every row, and the file tells two campaigns of
one name apart; an edited file is the same campaign (it resumes: more seeds add tasks). Another
campaign's ``out`` is refused without ``force``; with it, that campaign's report and every part of
``runs/`` are moved to ``out/superseded/<UTC time>/`` (as ``bench.json``, ``bench.md``, its plots and
``runs/``), not deleted and not counted. Of this campaign's own ``runs/``, the parts of tasks it no
longer has (an edit changed its seeds, configs or ``seeds_per_task``) are moved there too, so that
``runs/`` always reads as this campaign's rows, each run once.
"""

from __future__ import annotations

import datetime
import json
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gyroemu.errors import ConfigError

if TYPE_CHECKING:
    from gyroemu.pipelines.campaign import Campaign, CampaignSpec, CellTask, PartStore, TaskFailure
    from gyroemu.pipelines.formats.atomic import StagedFiles
    from gyroemu.pipelines.jobs.bench import BenchReport

__all__ = [
    "BATCHED_THROUGHPUT",
    "SUPERSEDED",
    "CampaignError",
    "CampaignOptions",
    "CampaignSummary",
    "campaign_report",
    "check_options",
    "other_campaign",
    "run_campaign",
    "save_campaign_report",
    "spec_from_bench_flags",
]


class CampaignError(ConfigError):
    """Bad options of ``gyroemu bench --campaign`` (the message names the argument)."""


@dataclass(frozen=True)
class CampaignOptions:
    """What ``gyroemu bench --campaign`` runs, where, and where it writes.

    Attributes
    ----------
    spec : Path or CampaignSpec
        The campaign file (TOML), or a spec made in code (:func:`spec_from_bench_flags`).
    out : Path
        Folder of the store (``runs/``) and the report (made if missing).
    scheduler : str or None
        A Dask scheduler's address (``tcp://host:8786``); None: a local cluster.
    workers : int or None
        Worker processes of the local cluster (default: one per core).
    processes : bool
        Local workers as processes (default); False: threads of this process (tests).
    progress : bool or None
        A bar on stderr (runs done, total, rate, time left); None: when stderr is a terminal.
    plots : bool
        Write the per-cell plots.
    force : bool
        Overwrite report files in ``out`` that are not a campaign's (no ``runs/`` store beside them); move
        another campaign's report and parts there to ``out/superseded/<UTC time>/`` (see the module's notes).
    """

    spec: Path | CampaignSpec
    out: Path = Path("bench")
    scheduler: str | None = None
    workers: int | None = None
    processes: bool = True
    progress: bool | None = None
    plots: bool = True
    force: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.spec, (str, Path)):
            object.__setattr__(self, "spec", Path(self.spec))
        object.__setattr__(self, "out", Path(self.out))


@dataclass
class CampaignSummary:
    """What a campaign did: tasks run now, found in the store, failed; rows stored; the report's files."""

    campaign: Campaign
    store: Path
    tasks: int
    resumed: int
    ran: int
    failures: list[TaskFailure[CellTask]]
    rows: int
    elapsed_s: float
    report: BenchReport
    runs_made: int = 0
    paths: dict[str, Any] = field(default_factory=dict)
    superseded: Path | None = None
    """Where the parts (and report) not of this campaign were moved before the work, or None: none were."""

    @property
    def runs_per_s(self) -> float:
        """Rows (run × filter) made per second of wall time in this session."""
        return self.runs_made / self.elapsed_s if self.elapsed_s > 0 else float("nan")


SUPERSEDED = "superseded"
"""The folder in ``out`` that parts and a report not of the campaign are moved to (see the module's notes)."""


def check_options(options: CampaignOptions, campaign: Campaign | None = None) -> None:
    """:class:`CampaignError` naming the argument, before any work: a scheduler address that is none
    (:func:`~gyroemu.pipelines.campaign.scheduler_problem`); an ``out`` that is not a folder or cannot
    take files (read-only, not writable; where it would be made when missing), or whose ``runs`` is not
    a folder (even with ``force``: it is not a report file); report files in ``out`` (``bench.md``,
    ``bench.json``, ``.png``) without a campaign's ``runs/`` store beside them, unless ``force``; the
    results of another campaign than ``campaign`` (:func:`other_campaign`), unless ``force``; a report
    file that is an input, even with ``force``: the campaign file, and the scenario and device files
    ``campaign`` (loaded from it) names."""
    from gyroemu.pipelines.campaign import scheduler_problem
    from gyroemu.pipelines.formats.atomic import output_folder_problem
    from gyroemu.pipelines.jobs.bench import report_files_in, report_input_problem

    if options.scheduler is not None:
        problem = scheduler_problem(options.scheduler)
        if problem is not None:
            raise CampaignError(f"argument --scheduler: {problem}")
    out = options.out
    problem = output_folder_problem(out)
    if problem is not None:
        raise CampaignError(f"argument --out: {problem}")
    runs = out / "runs"
    if (runs.exists() or runs.is_symlink()) and not runs.is_dir():
        raise CampaignError(
            f"argument --out: {runs} is not a folder: a campaign stores its rows there (move it, or use another folder)"
        )
    there = report_files_in(out)
    if there and not runs.is_dir() and not options.force:
        raise CampaignError(
            f"argument --out: {out} holds {', '.join(there)} but no campaign's runs/: the report would overwrite "
            "them (use --force to overwrite them, or another folder)"
        )
    if campaign is not None and not options.force:
        other = other_campaign(out, campaign)
        if other is not None:
            raise CampaignError(
                f"argument --out: {out} holds the results of another campaign ({other}): use another folder, or "
                f"--force to run this one there (the other's report and parts are moved to {out / SUPERSEDED}/)"
            )
    inputs = [options.spec] if isinstance(options.spec, Path) else []
    if campaign is not None:
        inputs += [
            Path(entry) for cell in campaign.cells for entry in (cell.scenario, cell.device) if Path(entry).is_file()
        ]
    # bench.md, bench.json, and the earlier report's plots, removed whatever the campaign (its own, or
    # another's with --force); the new plots' names come from the runs' rows, known only after the work
    # (not checked: a .png named as a cell is no input)
    problem = report_input_problem(out, inputs, replace_earlier=True)
    if problem is not None:
        raise CampaignError(problem)


def other_campaign(out: Path, campaign: Campaign) -> str | None:
    """How the campaign whose results ``out`` holds differs from ``campaign`` (``"campaign 'a', not 'b'"``,
    ``"from a.toml, not b.toml"``), or None when it is ``campaign`` or ``out`` holds no campaign's
    ``runs/`` store. Which campaign that is: its ``bench.json``'s ``settings.campaign`` ``name`` and
    ``file`` (a report that is no campaign's differs), or, before its first report (a first run stopped),
    the ``campaign`` column of a part in ``runs/`` (the name only). Files compare by the path as given or
    the file it names (:func:`~gyroemu.pipelines.formats.file_names.same_file`)."""
    from gyroemu.pipelines.campaign import PartStore

    if not (out / "runs").is_dir():
        return None
    here_file = None if campaign.path is None else str(campaign.path)
    report = out / "bench.json"
    if report.exists() or report.is_symlink():
        try:
            earlier = json.loads(report.read_text(encoding="utf-8"))["settings"]["campaign"]
            name, file, store = earlier["name"], earlier["file"], earlier.get("store")
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError):
            return f"{report} is no campaign's report"
        if not isinstance(name, str) or not all(v is None or isinstance(v, str) for v in (file, store)):
            return f"{report} is no campaign's report"
        differs = []
        if name != campaign.name:
            differs.append(f"campaign {name!r}, not {campaign.name!r}")
        if not _same_campaign_file(file, store, out, campaign.path):
            differs.append(f"from {file or 'bench flags'}, not {here_file or 'bench flags'}")
        return "; ".join(differs) or None
    name = _a_part_campaign(PartStore(out / "runs"))
    if name is not None and name != campaign.name:
        return f"rows of campaign {name!r} in {out / 'runs'}, not {campaign.name!r}"
    return None


def _same_campaign_file(earlier: str | None, store: str | None, out: Path, here: Path | None) -> bool:
    """Whether the campaign file ``earlier`` (as the report in ``out`` names it, beside its ``store``) is
    ``here``: both none (bench flags), the same path as given, or the same file
    (:func:`~gyroemu.pipelines.formats.file_names.same_file`), a relative ``earlier`` taken from this
    folder or from the one the earlier run was started in (where its relative ``store``, ``out/runs`` as
    given then, names ``out``'s ``runs``: the campaign run again from another folder is the same one)."""
    import os

    from gyroemu.pipelines.formats.file_names import same_file

    if earlier is None or here is None:
        return earlier is None and here is None
    if earlier == str(here) or same_file(earlier, here):
        return True
    given = Path(os.path.normpath(store)) if store is not None else None
    if Path(earlier).is_absolute() or given is None or given.is_absolute() or ".." in given.parts:
        return False
    runs = Path(os.path.abspath(out / "runs"))
    if runs.parts[-len(given.parts) :] != given.parts:
        return False
    started_in = Path(*runs.parts[: -len(given.parts)])
    return same_file(started_in / earlier, here)


def _a_part_campaign(store: PartStore) -> str | None:
    """The ``campaign`` of the first row of one part of ``store``, or None: no part, or none readable."""
    import pyarrow.parquet as pq

    for key in sorted(store.keys())[:1]:
        try:
            values = pq.read_table(store.path(key), columns=["campaign"]).column("campaign").to_pylist()
        except Exception:  # any reader's complaint: a part that tells nothing
            return None
        return str(values[0]) if values and values[0] is not None else None
    return None


def _supersede(out: Path, keep: list[str], whole: bool) -> Path | None:
    """Move what in ``out`` is not this campaign's to ``out/superseded/<UTC time>/`` before the work: with
    ``whole`` (another campaign's results, ``--force``) its report (``bench.json``, ``bench.md``, the plots
    its ``bench.json`` names) and every part of ``runs/``; else the parts whose keys are not ``keep``.
    Returns that folder, or None when nothing was moved."""
    import os

    from gyroemu.pipelines.campaign import PartStore
    from gyroemu.pipelines.jobs.bench import REPORT_FILES, earlier_plots

    store = PartStore(out / "runs")
    report = ([out / name for name in REPORT_FILES if (out / name).is_file()] + earlier_plots(out)) if whole else []
    if not report and not (store.keys() - set(() if whole else keep)):
        return None
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%SZ")
    where = out / SUPERSEDED / stamp
    n = 1
    while where.exists():
        n += 1
        where = out / SUPERSEDED / f"{stamp}-{n}"
    where.mkdir(parents=True)
    store.set_aside(() if whole else keep, where / "runs")
    for path in report:
        os.replace(path, where / path.name)
    return where


def run_campaign(options: CampaignOptions) -> CampaignSummary:
    """Run the campaign ``options.spec`` (see the module's notes) and write its report.

    Raises
    ------
    gyroemu.errors.ConfigError
        A bad campaign file (names the file and key), before any work; :class:`CampaignError` for bad
        options (:func:`check_options`).
    gyroemu.pipelines.campaign.SchedulerLostError
        The scheduler unreachable or lost; the finished tasks are stored, and a new run resumes.
    """
    from gyroemu.pipelines.campaign import (
        PartStore,
        campaign_from_spec,
        load_campaign,
        row_schema,
        run_cell,
        run_tasks,
    )
    from gyroemu.pipelines.campaign.progress import RunsProgress

    if isinstance(options.spec, Path):
        campaign = load_campaign(options.spec)
    else:
        campaign = campaign_from_spec(options.spec)
    check_options(options, campaign)
    out = options.out
    keys = [t.key for t in campaign.tasks]
    superseded = _supersede(out, keys, whole=other_campaign(out, campaign) is not None)
    store = PartStore(out / "runs", row_schema())
    for tmp in store.temporaries(keys):  # a part's write a killed run left: never to be completed
        tmp.unlink(missing_ok=True)
    missing = store.missing(keys)
    todo = [t for t in campaign.tasks if t.key in missing]
    resumed = len(campaign.tasks) - len(todo)
    ran: list[CellTask] = []
    started = time.perf_counter()
    done_before = campaign.runs - sum(t.runs for t in todo)
    with RunsProgress(campaign.runs, done_before, label=f"campaign {campaign.name}", enabled=options.progress) as bar:

        def stored(task: CellTask, rows: list[dict[str, Any]]) -> None:
            store.write(task.key, rows)
            ran.append(task)
            bar.advance(task.runs)

        failures = run_tasks(
            todo,
            run_cell,
            stored,
            scheduler=options.scheduler,
            workers=options.workers,
            processes=options.processes,
            label=lambda t: f"{t.cell.label} seeds {t.seeds[0]}",
        )
    elapsed = time.perf_counter() - started
    table = store.read(t.key for t in campaign.tasks)
    report = campaign_report(campaign, table, failures, store=store.folder)
    summary = CampaignSummary(
        campaign=campaign,
        store=store.folder,
        tasks=len(campaign.tasks),
        resumed=resumed,
        ran=len(ran),
        failures=failures,
        rows=table.num_rows,
        elapsed_s=elapsed,
        report=report,
        runs_made=sum(t.runs for t in ran),
        superseded=superseded,
    )
    summary.paths = save_campaign_report(report, table, out, plots=options.plots)
    return summary


def spec_from_bench_flags(
    scenarios: list[str] | None = None,
    devices: list[str] | None = None,
    *,
    duration: float = 60.0,
    runs: int = 3,
    seed: int = 0,
    filters: list[str] | None = None,
    six_d: bool = False,
    threshold_deg: float = 2.0,
    batched: bool = False,
) -> CampaignSpec:
    """The campaign ``gyroemu bench``'s flags describe (``--scheduler`` without ``--campaign``): each
    scenario × each device, ``duration`` s, seeds ``seed … seed + runs − 1``; names checked later, by
    :func:`~gyroemu.pipelines.campaign.campaign_from_spec`. :class:`~gyroemu.errors.ConfigError` names the
    key (``seed_range.start``) of a value a campaign cannot hold."""
    from gyroemu.dynamics.config import validate
    from gyroemu.pipelines.campaign import CampaignSpec

    data = {
        "name": "bench",
        "scenarios": list(scenarios or ["smooth_manoeuvre"]),
        "devices": list(devices or ["consumer_mems"]),
        "durations_s": [duration],
        "seed_range": {"start": seed, "count": runs},
        "modes": ["6D" if six_d else "9D"],
        "threshold_deg": threshold_deg,
        "batched": batched,
    }
    if filters:
        data["filters"] = list(filters)
    return validate(CampaignSpec, data)


def _num(v: Any) -> Any:
    return None if v is None else float(v)


def campaign_report(
    campaign: Campaign, table: Any, failures: list[TaskFailure[CellTask]] | None = None, *, store: Path | None = None
) -> BenchReport:
    """The campaign's stored rows (a ``pyarrow.Table`` of :data:`ROW_COLUMNS`) as a
    :class:`~gyroemu.pipelines.jobs.bench.BenchReport`: a case per cell, runs in seed order; the
    campaign's own facts (store, tasks, failures) in ``settings["campaign"]`` and the notes."""
    from gyroemu.pipelines.campaign import consecutive
    from gyroemu.pipelines.jobs.bench import BenchReport, CaseResult, FilterResult, RunResult

    failures = list(failures or [])
    by_task = {t.key: t for t in campaign.tasks}
    rows_by_cell: dict[Any, list[dict[str, Any]]] = defaultdict(list)
    for row in table.to_pylist():
        task = by_task.get(row["task"])
        if task is not None:
            rows_by_cell[task.cell].append(row)
    cases = []
    notes = []
    for cell in campaign.cells:
        rows = sorted(rows_by_cell.get(cell, []), key=lambda r: (r["seed"], campaign.filters.index(r["filter"])))
        if not rows:
            continue
        filters: dict[str, FilterResult] = {}
        for r in rows:
            fr = filters.get(r["filter"])
            if fr is None:
                fr = filters[r["filter"]] = FilterResult(
                    filter=r["filter"], name=r["filter_name"], batched=r["batched"], runs=[]
                )
            fr.runs.append(
                RunResult(
                    seed=r["seed"],
                    samples=r["samples"],
                    total_deg=_num(r["total_deg"]),
                    heading_deg=_num(r["heading_deg"]),
                    inclination_deg=_num(r["inclination_deg"]),
                    convergence_s=_num(r["convergence_s"]),
                    bias_error_deg_s=_num(r["bias_error_deg_s"]),
                    throughput=float(r["throughput"]),
                    wall_s=float(r["wall_s"]),
                    diverged=bool(r["diverged"]),
                    reason=r["reason"] or "",
                )
            )
        seeds = sorted({r["seed"] for r in rows})
        first = rows[0]
        source: dict[str, Any] = {
            "scenario": cell.scenario,
            "device": cell.device,
            "duration_s": cell.duration_s,
            "scenario_hash": cell.scenario_hash,
            "device_hash": cell.device_hash,
            "seeds": seeds,
        }
        if any(fr.batched for fr in filters.values()):  # mekf_batch ran each task's consecutive seeds at once
            stored = {by_task[r["task"]] for r in rows}
            source["runs_at_once"] = sorted({n for t in stored for _, n in consecutive(t.seeds)})
        cases.append(
            CaseResult(
                name=f"{first['case']}, {cell.duration_s:g} s",
                kind="simulated",
                mode=first["mode"],
                rate_hz=first["rate_hz"],
                samples=first["samples"],
                duration_s=cell.duration_s,
                runs=len(seeds),
                source=source,
                filters=[filters[f] for f in campaign.filters if f in filters],
            )
        )
        if len(seeds) < len(campaign.seeds):
            notes.append(f"{cases[-1].name}: {len(seeds)} of {len(campaign.seeds)} seeds stored")
    seeds = list(campaign.seeds)
    if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        notes.append(f"device seeds: {', '.join(map(str, seeds))}")
    settings = {
        "runs": len(seeds),
        "seed": seeds[0],
        "threshold_deg": float(campaign.spec.threshold_deg),
        "batched": campaign.spec.batched,
        "filters": list(campaign.filters),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "cases": [
            {
                "type": "SimCase",
                "scenario": c.scenario,
                "device": c.device,
                "duration": c.duration_s,
                "six_d": c.mode == "6D",
            }
            for c in campaign.cells
        ],
        "campaign": {
            "name": campaign.name,
            "file": None if campaign.path is None else str(campaign.path),
            "store": None if store is None else str(store),
            "cells": len(campaign.cells),
            "seeds": seeds,
            "tasks": len(campaign.tasks),
            "rows_expected": campaign.runs,
            "rows_stored": table.num_rows,
            "failures": [
                {"cell": f.task.cell.label, "seeds": list(f.task.seeds), "task": f.task.key, "error": f.error}
                for f in failures
            ],
        },
    }
    return BenchReport(cases=cases, settings=settings, notes=notes, unavailable=dict(campaign.unavailable))


BATCHED_THROUGHPUT = (
    "batched: filter updates/s across the runs one task ran at once (its consecutive seeds, at most "
    "seeds_per_task; the case's source.runs_at_once), not across all the runs of the case"
)
"""A campaign report's definition of a batched row's throughput (``bench.json``'s ``definitions``)."""


def _markdown(report: BenchReport) -> str:
    c = report.settings["campaign"]
    head = [
        f"# gyroemu bench campaign: {c['name']}",
        "",
        f"{c['cells']} cell(s) × {len(c['seeds'])} seed(s) × {len(report.settings['filters'])} filter(s): "
        f"{c['rows_stored']} of {c['rows_expected']} rows stored in {c['store']} (Parquet, one row per run × "
        f"filter); {c['tasks']} task(s), {len(c['failures'])} failed.",
    ]
    if c["failures"]:
        head += ["", "Failed cells (run the campaign again to retry them):"]
        head += [f"- {f['cell']}, seeds {f['seeds'][0]}…{f['seeds'][-1]}: {f['error']}" for f in c["failures"]]
    body = report.to_markdown().split("\n", 1)[1]  # bench's own text, without its title
    return "\n".join(head) + "\n" + body


def save_campaign_report(report: BenchReport, table: Any, out: Path, *, plots: bool = True) -> dict[str, Any]:
    """``bench.md``, ``bench.json`` and (``plots``) one box plot per cell in ``out``; their paths. The
    earlier report's plots there (those its ``bench.json`` names, :func:`~gyroemu.pipelines.jobs.bench.earlier_plots`)
    are removed. All or nothing: each file is written to a temporary file, and they are renamed into place
    (and the earlier plots removed) only once all are complete; on an error (a full disk) ``out`` is left
    as it was, its run store untouched. A report with a batched row defines its throughput as a campaign
    runs it (:data:`BATCHED_THROUGHPUT`)."""
    from gyroemu.pipelines.formats.atomic import staged_files
    from gyroemu.pipelines.jobs.bench import earlier_plots

    paths: dict[str, Any] = {"markdown": out / "bench.md", "json": out / "bench.json", "plots": []}
    data = report.to_dict() | ({} if plots else {"plots": []})  # the names of the plots written beside it
    if any(fr.batched for case in report.cases for fr in case.filters):
        data["definitions"]["throughput"] = f"samples/s of process() wall time; {BATCHED_THROUGHPUT}"
    with staged_files(out) as stage:
        for plot in earlier_plots(out):  # the earlier report's (this campaign's, or the one --force replaces)
            stage.remove(plot)
        stage.write_text(paths["json"], json.dumps(data, indent=1, ensure_ascii=False, allow_nan=False))
        stage.write_text(paths["markdown"], _markdown(report))
        if plots:
            paths["plots"] = _box_plots(report, out, stage)
    return paths


def _box_plots(report: BenchReport, out: Path, stage: StagedFiles) -> list[Path]:
    """One PNG per case: each filter's per-run RMSE (9D: total, 6D: inclination) as a box over the runs
    that did not diverge, every run a dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from gyroemu.pipelines.jobs.bench import plot_names

    written = []
    for case, name in zip(report.cases, plot_names([c.name for c in report.cases])):
        metric = "total_deg" if case.mode == "9D" else "inclination_deg"
        data, labels = [], []
        for fr in case.filters:
            values = [getattr(r, metric) for r in fr.runs if not r.diverged and getattr(r, metric) is not None]
            data.append(np.asarray(values, float))
            labels.append(fr.label + (f" ({fr.diverged_runs} diverged)" if fr.diverged_runs else ""))
        fig, ax = plt.subplots(figsize=(max(5.0, 1.4 * len(data) + 2), 3.6))
        ax.boxplot([d if len(d) else [np.nan] for d in data], showfliers=False)
        for i, d in enumerate(data, start=1):
            ax.plot(np.full(len(d), i) + np.linspace(-0.15, 0.15, len(d)), d, ".", ms=3, alpha=0.5)
        ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel(f"{metric.split('_')[0]} RMSE, deg")
        ax.set_title(f"{case.name} ({case.mode}), {case.runs} runs", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        written.append(stage.write_figure(fig, out / name, dpi=110))
    return written
