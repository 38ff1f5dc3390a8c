"""What a worker runs: a bench task's rows (:func:`run_cell`) and a dataset's log (:func:`make_log`).

A bench task is one cell (scenario × device × duration × mode) × a slice of seeds. It calls
:func:`gyroemu.pipelines.jobs.bench.run_bench` on the cell, once per run of consecutive seeds, so the
batched Monte Carlo kernel (``mekf_batch``) takes the whole slice at once, and turns each (seed,
filter) result into a row of :data:`ROW_SCHEMA`.
"""

from __future__ import annotations

import datetime
import math
import os
import socket
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .spec import CellTask
from .store import arrow_schema

__all__ = ["LogTask", "ROW_COLUMNS", "consecutive", "make_log", "row_schema", "run_cell"]

ROW_COLUMNS: dict[str, str] = {
    "campaign": "string",
    "task": "string",
    "scenario": "string",
    "scenario_hash": "string",
    "device": "string",
    "device_hash": "string",
    "duration_s": "float64",
    "mode": "string",
    "case": "string",
    "rate_hz": "float64",
    "samples": "int64",
    "seed": "int64",
    "filter": "string",
    "filter_name": "string",
    "batched": "bool_",
    "total_deg": "float64",
    "heading_deg": "float64",
    "inclination_deg": "float64",
    "convergence_s": "float64",
    "converged": "bool_",
    "bias_error_deg_s": "float64",
    "throughput": "float64",
    "wall_s": "float64",
    "diverged": "bool_",
    "reason": "string",
    "threshold_deg": "float64",
    "task_wall_s": "float64",
    "worker": "string",
    "finished_utc": "string",
    "gyroemu_version": "string",
}
"""The columns of a campaign's rows (one per run × filter) and their Arrow types."""


def row_schema() -> Any:
    """:data:`ROW_COLUMNS` as a ``pyarrow.Schema``."""
    return arrow_schema(ROW_COLUMNS)


def consecutive(seeds: tuple[int, ...]) -> list[tuple[int, int]]:
    """``seeds`` (ascending) as runs of consecutive integers: (first, count) each."""
    out: list[tuple[int, int]] = []
    for s in seeds:
        if out and out[-1][0] + out[-1][1] == s:
            out[-1] = (out[-1][0], out[-1][1] + 1)
        else:
            out.append((s, 1))
    return out


def _version() -> str:
    import gyroemu

    return str(gyroemu.__version__)


def run_cell(task: CellTask) -> list[dict[str, Any]]:
    """Every filter of ``task`` on each of its seeds: one row per (seed, filter), in seed order.

    Raises what :func:`~gyroemu.pipelines.jobs.bench.run_bench` raises for a cell it cannot run (a
    duration a recorded scenario does not cover, ...); a filter that fails on a run is a diverged row.
    """
    from gyroemu.pipelines.jobs.bench import SimCase, run_bench

    started = time.perf_counter()
    c = task.cell
    rows: list[dict[str, Any]] = []
    for first, count in consecutive(task.seeds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            report = run_bench(
                [SimCase(scenario=c.scenario, device=c.device, duration=c.duration_s, six_d=c.mode == "6D")],
                filters=list(task.filters),
                runs=count,
                seed=first,
                threshold_deg=task.threshold_deg,
                batched=task.batched,
                progress=False,
            )
        (case,) = report.cases
        for fr in case.filters:
            for r in fr.runs:
                conv = r.convergence_s
                rows.append(
                    {
                        "campaign": task.campaign,
                        "task": task.key,
                        "scenario": c.scenario,
                        "scenario_hash": c.scenario_hash,
                        "device": c.device,
                        "device_hash": c.device_hash,
                        "duration_s": c.duration_s,
                        "mode": case.mode,
                        "case": case.name,
                        "rate_hz": float(case.rate_hz),
                        "samples": int(r.samples),
                        "seed": int(r.seed) if r.seed is not None else None,
                        "filter": fr.filter,
                        "filter_name": fr.name,
                        "batched": bool(fr.batched),
                        "total_deg": r.total_deg,
                        "heading_deg": r.heading_deg,
                        "inclination_deg": r.inclination_deg,
                        "convergence_s": conv,
                        "converged": conv is not None and math.isfinite(conv),
                        "bias_error_deg_s": r.bias_error_deg_s,
                        "throughput": r.throughput,
                        "wall_s": r.wall_s,
                        "diverged": bool(r.diverged),
                        "reason": r.reason,
                        "threshold_deg": task.threshold_deg,
                    }
                )
    rows.sort(key=lambda row: (row["seed"], task.filters.index(row["filter"])))
    wall = time.perf_counter() - started
    stamp = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    who = f"{socket.gethostname()}:{os.getpid()}"
    version = _version()
    for row in rows:
        row.update(task_wall_s=wall, worker=who, finished_utc=stamp, gyroemu_version=version)
    return rows


@dataclass(frozen=True)
class LogTask:
    """One log of a dataset: ``gyroemu simulate --scenario S --device D --duration T --seed N --out OUT``."""

    campaign: str
    scenario: str
    device: str
    duration_s: float
    seed: int
    scenario_hash: str
    device_hash: str
    out: str  # the log's path

    @property
    def key(self) -> str:
        """The log's identity: its file name (unique within a dataset)."""
        return Path(self.out).stem

    def command(self) -> str:
        """The ``gyroemu simulate`` command line that writes the same bytes."""
        import shlex

        return shlex.join(
            [
                "gyroemu",
                "simulate",
                "--scenario",
                self.scenario,
                "--device",
                self.device,
                "--duration",
                repr(self.duration_s),
                "--seed",
                str(self.seed),
                "--out",
                self.out,
            ]
        )


def make_log(task: LogTask) -> list[dict[str, Any]]:
    """Write ``task``'s log with :func:`~gyroemu.pipelines.jobs.simulate.run_simulate` (overwriting a
    copy a previous attempt finished: the bytes are the same) and return its index row."""
    import hashlib

    from gyroemu.pipelines.jobs.simulate import SimulateOptions, run_simulate

    summary = run_simulate(
        SimulateOptions(
            scenario=task.scenario,
            out=Path(task.out),
            device=task.device,
            duration=task.duration_s,
            seed=task.seed,
            progress=False,
            force=True,
        )
    )
    digest = hashlib.sha256()
    with open(task.out, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return [
        {
            "file": Path(task.out).name,
            "campaign": task.campaign,
            "scenario": task.scenario,
            "scenario_hash": task.scenario_hash,
            "device": task.device,
            "device_hash": task.device_hash,
            "duration_s": task.duration_s,
            "seed": task.seed,
            "samples": summary.samples,
            "truth_samples": summary.truth_samples,
            "bytes": os.path.getsize(task.out),
            "sha256": digest.hexdigest(),
            "simulate_command": task.command(),
            "gyroemu_version": _version(),
        }
    ]
