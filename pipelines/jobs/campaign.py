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
files (made if missing), whose report files (``bench.md``, ``bench.json``, ``.png``) are a campaign's
own (beside its ``runs/`` store, rewritten on each run) or may be overwritten (``force``).
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
    from gyroemu.pipelines.campaign import Campaign, CampaignSpec, CellTask, TaskFailure
    from gyroemu.pipelines.formats.atomic import StagedFiles
    from gyroemu.pipelines.jobs.bench import BenchReport

__all__ = [
    "CampaignError",
    "CampaignOptions",
    "CampaignSummary",
    "campaign_report",
    "check_options",
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
        Overwrite report files in ``out`` that are not a campaign's (no ``runs/`` store beside them).
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

    @property
    def runs_per_s(self) -> float:
        """Rows (run × filter) made per second of wall time in this session."""
        return self.runs_made / self.elapsed_s if self.elapsed_s > 0 else float("nan")


def check_options(options: CampaignOptions, campaign: Campaign | None = None) -> None:
    """:class:`CampaignError` naming the argument, before any work: a scheduler address that is none
    (:func:`~gyroemu.pipelines.campaign.scheduler_problem`); an ``out`` that is not a folder or cannot
    take files (read-only, not writable; where it would be made when missing); report files in ``out``
    (``bench.md``, ``bench.json``, ``.png``) without a campaign's ``runs/`` store beside them, unless
    ``force``; a report file that is an input, even with ``force``: the campaign file, and the scenario
    and device files ``campaign`` (loaded from it) names."""
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
    there = report_files_in(out)
    if there and not (out / "runs").is_dir() and not options.force:
        raise CampaignError(
            f"argument --out: {out} holds {', '.join(there)} but no campaign's runs/: the report would overwrite "
            "them (use --force to overwrite them, or another folder)"
        )
    inputs = [options.spec] if isinstance(options.spec, Path) else []
    if campaign is not None:
        inputs += [
            Path(entry) for cell in campaign.cells for entry in (cell.scenario, cell.device) if Path(entry).is_file()
        ]
    # bench.md, bench.json, and an earlier report's plots that --force removes; the new plots' names come
    # from the runs' rows, known only after the work (not checked: a .png named as a cell is no input)
    problem = report_input_problem(out, inputs, replace_earlier=options.force)
    if problem is not None:
        raise CampaignError(problem)


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
    store = PartStore(out / "runs", row_schema())
    todo = [t for t in campaign.tasks if not store.has(t.key)]
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
        cases.append(
            CaseResult(
                name=f"{first['case']}, {cell.duration_s:g} s",
                kind="simulated",
                mode=first["mode"],
                rate_hz=first["rate_hz"],
                samples=first["samples"],
                duration_s=cell.duration_s,
                runs=len(seeds),
                source={
                    "scenario": cell.scenario,
                    "device": cell.device,
                    "duration_s": cell.duration_s,
                    "scenario_hash": cell.scenario_hash,
                    "device_hash": cell.device_hash,
                    "seeds": seeds,
                },
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
    """``bench.md``, ``bench.json`` and (``plots``) one box plot per cell in ``out``; their paths. All or
    nothing: each file is written to a temporary file, and they are renamed into place only once all are
    complete; on an error (a full disk) ``out`` is left as it was, its run store untouched."""
    from gyroemu.pipelines.formats.atomic import staged_files

    paths: dict[str, Any] = {"markdown": out / "bench.md", "json": out / "bench.json", "plots": []}
    data = report.to_dict() | ({} if plots else {"plots": []})  # the names of the plots written beside it
    with staged_files(out) as stage:
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
