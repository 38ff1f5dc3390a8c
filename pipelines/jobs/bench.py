"""``gyroemu bench``: attitude filters side by side, on simulated truth and on logs with a truth channel.

Cases
-----
- :class:`SimCase` (a scenario × a device): the scenario's trajectory is simulated once; each Monte Carlo
  run measures it with the device seeded ``seed + run`` (``gyroemu.sensors.load_device(name, seed)``), and the
  truth is the body's attitude and rate at the instants the device sampled
  (:func:`gyroemu.pipelines.formats.mcap_log.truth_series`). Every sample counts.
- :class:`LogCase` (an MCAP log): every device of the log with a truth channel (``/truth/imu``) is a
  case with one run. The samples counted are the log's ``/movement`` mask when it has one (an imported
  BROAD trial), otherwise all; truth rows that are NaN (a reference that lost tracking) are ignored.
  The filter setup comes from the log's ``gyroemu`` metadata (:func:`setup_from_metadata`), or the
  filters' defaults for a foreign log.

A filter knows only the sensor's axes: where the device's mounting is known (a simulated device's
``[mounting] q_bs``, a gyroemu log's device's from its embedded config), each estimate is turned into
the body's before it is compared with the body's truth: ``q̂_ws ⊗ q_bs*``, and the bias and the gyro
by ``R(q_bs)`` (:func:`.bench_filters.in_body_axes`), so that a mounted device's errors are the filter's,
not the mounting. A foreign log's estimates are compared as they are.

A case is 9D when the device has a magnetometer (a log: any finite ``/mag`` sample), 6D otherwise or
with ``six_d``. Each filter is made from the case's :class:`FilterSetup` for each run and given a
simulated run in one ``process()`` call; a log's samples come a block at a time, in time order, as the
filter protocol has them (:mod:`.bench_log`: the log is read in passes of bounded memory, the smoother
learns it in blocks, another offline filter is given the device's samples at once), with the same
results as the log read whole (``LogCase(read_whole=True)``, and the fallback for a log one pass cannot
pair). The metrics of a run are accumulated a block at a time (:mod:`.bench_metrics`).

Online and offline
------------------
A filter is online (causal: each estimate from the samples up to it, as a live filter must be) or
offline (it sees the whole log: ``mekf-smooth``, ``offline-vqf``, or a class with ``offline = True``;
:func:`gyroemu.pipelines.estimation.registry.is_offline`). The offline ones run when named, and the
report keeps the two groups apart: ``bench.md`` has a table for each group (one table, as before, when
only online filters ran) and ``bench.json`` marks each filter entry ``"offline"``. An offline
estimator is compared with offline ones, an online filter with online ones.

What is reported, per (case, filter), as mean ± standard deviation over the runs that did not diverge
----------------------------------------------------------------------------------------------------
- **total, heading, inclination RMSE**, degrees, with BROAD's definitions (:mod:`.metrics`); a 6D row
  reports inclination only (its heading is arbitrary).
- **convergence time**, s: the time from the first sample after which the error (total for 9D,
  inclination for 6D) stays below ``threshold_deg`` (2° by default) until the end; "never" when it is
  still above at the end (:func:`.metrics.convergence_time`).
- **gyro-bias error**, deg/s, for filters that estimate a bias (``Estimate.gyro_bias``): the RMS of
  ``|b_est − b_true|`` over the last half of the run, with ``b_true`` the measured gyro minus the true
  rate, averaged over a centred 1 s window (it holds every slowly varying gyro error: bias, and what
  scale factor and misalignment make of the motion). Sample ``k`` is the mean rate over
  ``[t_{k−1}, t_k]``, so the true rate it is compared with is the mean of the truth at ``t_{k−1}`` and
  ``t_k``. The true rate includes Earth's rotation and
  so does the gyro, so a filter that does not model Earth's rate carries it (≤ 0.0042 °/s) in its
  bias. "—" where the truth has no rate (a log without one) or the filter no bias.
- **throughput**: samples per second of wall time spent in ``process()``; for the batched mekf, filter
  updates per second across all runs at once.
- **diverged**: a run whose output has a non-finite quaternion, or whose inclination error over the
  last 10 % of the counted samples has an RMS above 30° (a filter that raises counts as diverged, with
  the exception in the report). Diverged runs are counted in the status column and left out of the
  means; a row whose runs all diverged says so in every cell. No row is dropped.

Outputs: :meth:`BenchReport.to_markdown` (``bench.md``), :meth:`BenchReport.to_json` (``bench.json``: every
number, every run) and :meth:`BenchReport.save_plots` (one PNG per case: the error of every filter
against time, first run; ``bench.json`` lists their names). :meth:`BenchReport.save` writes all three, all
or none: each to a temporary file, renamed into place once all are complete (a full disk at the last plot
leaves the folder as it was: :func:`~gyroemu.pipelines.formats.atomic.staged_files`).
:func:`check_report_folder` refuses, before any work, a folder that cannot take
them or that holds an earlier report (``bench.md``, ``bench.json``, a ``.png``) unless told to overwrite
it; overwriting it, :meth:`BenchReport.save` first removes the earlier report's plots this one does not
write (:func:`earlier_plots`: those its ``bench.json`` names, and no other file). An input (a log, a
scenario or device file: :func:`bench_inputs`) is never overwritten or removed, even with ``--force``
(:func:`report_input_problem`): refused before any work, and again, with the plots' names known, before
:meth:`BenchReport.save` writes or removes anything.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike

from gyroemu.pipelines.estimation.protocol import Estimate, FilterSetup
from gyroemu.pipelines.estimation.registry import (
    FilterError,
    available_filters,
    filter_class,
    is_offline,
    make_filter,
    takes_whole_log,
    unavailable_filters,
)
from gyroemu.pipelines.formats.atomic import (
    StagedFiles,
    output_folder_problem,
    report_files_problem,
    staged_files,
)
from gyroemu.pipelines.formats.file_names import same_file, unique_stems
from gyroemu.pipelines.jobs.bench_cases import PLOT_POINTS, BenchError, BenchWarning, LogCase, SimCase
from gyroemu.pipelines.jobs.bench_filters import WARM_UP_SAMPLES, check_estimate, in_body_axes, warm_up
from gyroemu.pipelines.jobs.bench_log import (
    TRUTH_MATCH,
    LogDevice,
    bench_log_device,
    check_log_case,
    choose_devices,
    log_label,
    log_setup,
    mask_notes,
    no_reference_error,
    stream_log_devices,
)
from gyroemu.pipelines.jobs.bench_metrics import (
    BIAS_WINDOW_S,
    DIVERGED_FINAL_FRACTION,
    DIVERGED_INCLINATION_DEG,
    RunMetrics,
    RunResult,
    json_number,
)
from gyroemu.pipelines.jobs.inputs import given_config_files, loaded_files
from gyroemu.pipelines.jobs.run_span import short_run_problem

__all__ = [
    "BenchError",
    "BenchReport",
    "BenchWarning",
    "CaseResult",
    "FilterError",
    "FilterResult",
    "LogCase",
    "REPORT_FILES",
    "RunResult",
    "SimCase",
    "bench_inputs",
    "check_report_folder",
    "earlier_plots",
    "evaluate_run",
    "plot_names",
    "report_files_in",
    "report_figures",
    "report_input_problem",
    "run_bench",
]

# ==================================================================================================
# A run's data


@dataclass
class _Run:
    """One run's data: what the filters see and what they are judged against."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray | None
    q_true: np.ndarray
    omega_true: np.ndarray | None
    mask: np.ndarray
    seed: int | None = None
    q_bs: np.ndarray | None = None  # (4,) the device's mounting (sensor → body); None: unmounted or unknown


if TYPE_CHECKING:
    from gyroemu.dynamics import Scenario, Trajectory
    from gyroemu.sensors import Device

    _SimItem = tuple[Scenario, list[Device], FilterSetup, str, str]
    """A simulated case loaded (:func:`_sim_case`): scenario, devices per run, setup, name, mode."""
    _LogItem = tuple[str, str, FilterSetup, _Run, dict[str, Any], list[str]]
    """A log device read whole (:func:`_log_runs`): name, mode, setup, run, source, notes."""


# ==================================================================================================
# Results


@dataclass
class FilterResult:
    """One filter over all runs of a case."""

    filter: str  # as asked for (built-in name or module:Class)
    name: str  # the filter object's ``name``
    batched: bool
    runs: list[RunResult]
    curve_t: np.ndarray | None = None  # first run's error against time, for the plot
    curve_total_deg: np.ndarray | None = None
    curve_inclination_deg: np.ndarray | None = None
    note: str = ""
    offline: bool = False  # sees the whole log (acausal): its own group in the report

    @property
    def label(self) -> str:
        return f"{self.name} [batched]" if self.batched else self.name

    @property
    def diverged_runs(self) -> int:
        return sum(r.diverged for r in self.runs)

    def summary(self, metric: str) -> dict[str, Any]:
        """Mean, standard deviation (ddof 1) and count over the runs that did not diverge (finite values);
        for convergence also how many never converged."""
        values = [getattr(r, metric) for r in self.runs if not r.diverged or metric in ("throughput", "wall_s")]
        values = [v for v in values if v is not None]
        out: dict[str, float | None] = {"mean": None, "std": None, "n": 0}
        if metric == "convergence_s":
            out["never"] = sum(1 for v in values if math.isinf(v))
        finite = [v for v in values if math.isfinite(v)]
        if finite:
            out.update(
                mean=float(np.mean(finite)),
                std=float(np.std(finite, ddof=1)) if len(finite) > 1 else 0.0,
                n=len(finite),
            )
        return out


@dataclass
class CaseResult:
    name: str
    kind: str  # "simulated" or "log"
    mode: str  # "9D" or "6D"
    rate_hz: float
    samples: int
    duration_s: float
    runs: int
    source: dict[str, Any]
    filters: list[FilterResult] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


_METRICS = ("total_deg", "heading_deg", "inclination_deg", "convergence_s", "bias_error_deg_s", "throughput")


@dataclass
class BenchReport:
    """What :func:`run_bench` found."""

    cases: list[CaseResult]
    settings: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    unavailable: dict[str, str] = field(default_factory=dict)
    inputs: list[Path] = field(default_factory=list)
    """The files the bench read (:func:`bench_inputs`, :func:`~.inputs.loaded_files`), which :meth:`save` never
    overwrites or removes; not in the report."""

    # --- Markdown ---------------------------------------------------------------------------------
    def to_markdown(self) -> str:
        s = self.settings
        lines = ["# gyroemu bench", ""]
        sims = sum(c.kind == "simulated" for c in self.cases)
        parts = []
        if sims:
            seeds = f"seed {s['seed']}" if s["runs"] == 1 else f"seeds {s['seed']}…{s['seed'] + s['runs'] - 1}"
            parts.append(f"{sims} simulated case(s), {s['runs']} Monte Carlo run(s) each (device {seeds})")
        if len(self.cases) - sims:
            parts.append(f"{len(self.cases) - sims} log(s)")
        lines.append("; ".join(parts + [f"convergence threshold {s['threshold_deg']:g}°."]))
        lines.append("")
        offline_ran = any(fr.offline for case in self.cases for fr in case.filters)
        for offline in (False, True) if offline_ran else (False,):
            rows = [(case, fr) for case in self.cases for fr in case.filters if fr.offline == offline]
            if offline_ran:
                if not rows:
                    continue
                lines.append(
                    "## Offline estimators (each sees the whole log)"
                    if offline
                    else "## Online filters (causal: each estimate from the samples up to it)"
                )
                lines.append("")
            lines.append(
                "| case | filter | mode | total RMSE ° | heading RMSE ° | inclination RMSE ° | "
                "converged after s | gyro-bias error °/s | throughput samples/s | status |"
            )
            lines.append("|---|---|---|---|---|---|---|---|---|---|")
            for case, fr in rows:
                lines.append("| " + " | ".join(self._row(case, fr)) + " |")
            lines.append("")
        lines.append(
            "Mean ± standard deviation over the runs that did not diverge. Errors with BROAD's "
            "definitions: q_err = q_est ⊗ conj(q_true); total 2·acos|w|, heading 2·atan|z/w|, "
            "inclination 2·acos√(w²+z²), RMSE over the counted samples (a log's movement mask), "
            "NaN reference rows ignored. A 6D row has no heading (—)."
        )
        lines.append(
            f"Converged after: the time from the first sample after which the error (total for 9D, "
            f'inclination for 6D) stays below {s["threshold_deg"]:g}°; "never" if it is above it '
            "at the end."
        )
        lines.append(
            "Gyro-bias error: RMS of |b_est − b_true| over the last half of each run, b_true the measured "
            "gyro minus the true rate averaged over 1 s (— : the filter estimates no bias, or the "
            "truth has no rate)."
        )
        per_task = any(case.source.get("runs_at_once") for case in self.cases for fr in case.filters if fr.batched)
        lines.append(
            "Throughput: samples per second of process() wall time; "
            + (
                "[batched] rows: filter updates per second across the runs one task ran at once (its "
                "consecutive seeds, at most seeds_per_task)."
                if per_task  # a campaign's: each task batches its own seeds
                else "[batched] rows: filter updates per second across all runs at once."
            )
        )
        lines.append(
            f"Diverged: non-finite output, or inclination error RMS above "
            f"{DIVERGED_INCLINATION_DEG:g}° over the last {DIVERGED_FINAL_FRACTION:.0%} of the samples."
        )
        notes = list(self.notes)
        for name, why in self.unavailable.items():
            notes.append(f"{name} left out: {why}")
        for case in self.cases:
            notes += [f"{case.name}: {n}" for n in case.notes]
            notes += [f"{case.name}, {fr.label}: {fr.note}" for fr in case.filters if fr.note]
            for fr in case.filters:
                for i, r in enumerate(fr.runs):
                    if r.diverged and r.reason:
                        notes.append(f"{case.name}, {fr.label}, run {i} (seed {r.seed}): {r.reason}")
        if notes:
            lines.append("")
            lines.append("Notes:")
            lines += [f"- {n}" for n in notes]
        return "\n".join(lines) + "\n"

    @staticmethod
    def _row(case: CaseResult, fr: FilterResult) -> list[str]:
        n_runs = len(fr.runs)
        all_diverged = fr.diverged_runs == n_runs
        cells = [case.name, fr.label, case.mode]
        for metric, digits in (
            ("total_deg", 2),
            ("heading_deg", 2),
            ("inclination_deg", 2),
            ("convergence_s", 2),
            ("bias_error_deg_s", 4),
        ):
            if case.mode == "6D" and metric in ("total_deg", "heading_deg"):
                cells.append("—")
            elif all_diverged:
                cells.append("diverged")
            else:
                cells.append(_cell(fr.summary(metric), digits, metric))
        tp = fr.summary("throughput")
        batches = case.source.get("runs_at_once")  # a campaign's: each task's batch; bench: all the runs
        together = _runs_at_once(batches) if batches else f"({n_runs} runs at once)"
        if tp["mean"] is None:
            cells.append("—")
        else:
            cells.append(f"{_si(tp['mean'])} updates/s {together}" if fr.batched else _si(tp["mean"]))
        if fr.diverged_runs:
            cells.append(f"diverged ({fr.diverged_runs} of {n_runs} runs)" if n_runs > 1 else "diverged")
        else:
            cells.append("ok")
        return cells

    # --- JSON -------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "gyroemu_bench": 1,
            "settings": self.settings,
            "definitions": {
                "errors": "BROAD: q_err = q_est ⊗ conj(q_true); total 2 acos|w|, heading 2 atan|z/w|, "
                "inclination 2 acos sqrt(w²+z²); RMSE in degrees over the counted samples, NaN rows ignored",
                "convergence_s": f"time from the first sample after which the error (total 9D, inclination 6D) stays "
                f"below {self.settings['threshold_deg']} deg; null with converged=false: never",
                "bias_error_deg_s": "RMS of |b_est - b_true| over the last half of the run; b_true = measured gyro "
                "minus true rate, averaged over 1 s",
                "throughput": "samples/s of process() wall time; batched: filter updates/s across all runs",
                "diverged": f"non-finite output or inclination error RMS > {DIVERGED_INCLINATION_DEG} deg over the "
                f"last {DIVERGED_FINAL_FRACTION:.0%} of the counted samples",
                "summary": "mean, std (ddof 1) and n over the runs that did not diverge",
            },
            "unavailable": self.unavailable,
            "notes": self.notes,
            "cases": [
                {
                    "name": c.name,
                    "kind": c.kind,
                    "mode": c.mode,
                    "rate_hz": c.rate_hz,
                    "samples": c.samples,
                    "duration_s": c.duration_s,
                    "runs": c.runs,
                    "source": c.source,
                    "notes": c.notes,
                    "filters": [
                        {
                            "filter": fr.filter,
                            "name": fr.name,
                            "batched": fr.batched,
                            "offline": fr.offline,
                            "note": fr.note,
                            "diverged_runs": fr.diverged_runs,
                            "status": "ok"
                            if not fr.diverged_runs
                            else f"diverged in {fr.diverged_runs} of {len(fr.runs)} runs",
                            "summary": {m: {k: json_number(v) for k, v in fr.summary(m).items()} for m in _METRICS},
                            "runs": [r.to_json() for r in fr.runs],
                        }
                        for fr in c.filters
                    ],
                }
                for c in self.cases
            ],
            "plots": plot_names([c.name for c in self.cases]),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, ensure_ascii=False, allow_nan=False)

    def figures(self) -> dict[str, Any]:
        """:func:`report_figures` of this report."""
        return report_figures(self.to_dict())

    # --- Plots ------------------------------------------------------------------------------------
    def save_plots(self, directory: str | os.PathLike[str]) -> list[Path]:
        """One PNG per case, ``<case>.png`` in ``directory``: each filter's error against time (first run;
        9D: total and inclination, 6D: inclination), log scale, the convergence threshold dashed; all or
        none of them."""
        with staged_files() as stage:
            return self._stage_plots(stage, Path(directory))

    def _stage_plots(self, stage: StagedFiles, directory: Path) -> list[Path]:
        """:meth:`save_plots` through ``stage``."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        written = []
        for case, name in zip(self.cases, plot_names([c.name for c in self.cases])):
            panels = (
                [("total", "curve_total_deg"), ("inclination", "curve_inclination_deg")]
                if case.mode == "9D"
                else [("inclination", "curve_inclination_deg")]
            )
            fig, axes = plt.subplots(len(panels), 1, figsize=(9, 3.2 * len(panels)), sharex=True, squeeze=False)
            for ax, (what, attr) in zip(axes[:, 0], panels):
                for fr in case.filters:
                    y = getattr(fr, attr)
                    if y is None or fr.curve_t is None:
                        continue
                    label = fr.label + (" (diverged)" if fr.runs and fr.runs[0].diverged else "")
                    ax.plot(fr.curve_t, np.maximum(y, 1e-3), lw=0.8, label=label)
                ax.axhline(self.settings["threshold_deg"], color="0.4", ls="--", lw=0.8)
                ax.set_yscale("log")
                ax.set_ylabel(f"{what} error, deg")
                ax.grid(True, which="both", alpha=0.3)
            axes[0, 0].set_title(f"{case.name} ({case.mode}), first run")
            axes[0, 0].legend(fontsize=8, loc="upper right")
            axes[-1, 0].set_xlabel("time, s")
            fig.tight_layout()
            written.append(stage.write_figure(fig, directory / name, dpi=110))
        return written

    def save(self, directory: str | os.PathLike[str], *, replace_earlier: bool = False) -> dict[str, Any]:
        """``bench.md``, ``bench.json`` and the plots in ``directory`` (made if missing); their paths, and
        under ``"removed"`` the earlier report's plots removed. With ``replace_earlier`` (``--force``), the
        plots of an earlier report there (:func:`earlier_plots`) that this one does not write are removed
        first, before its ``bench.json`` is replaced: no other file is touched. All or nothing: every file
        is written to a temporary file first, and only once all are complete are the earlier plots removed
        and the files renamed into place; an error before (a full disk) leaves the folder as it was.
        :class:`BenchError`, before anything is written or removed, when one of those files is an input
        (:func:`report_input_problem`)."""
        directory = Path(directory)
        names = plot_names([c.name for c in self.cases])
        problem = report_input_problem(directory, self.inputs, plots=names, replace_earlier=replace_earlier)
        if problem is not None:
            raise BenchError(problem)
        paths: dict[str, Any] = {"markdown": directory / "bench.md", "json": directory / "bench.json"}
        with staged_files(directory) as stage:
            ours = set(names)
            removed = [p for p in (earlier_plots(directory) if replace_earlier else []) if p.name not in ours]
            stage.write_text(paths["json"], self.to_json())
            stage.write_text(paths["markdown"], self.to_markdown())
            paths["plots"] = self._stage_plots(stage, directory)
            for plot in removed:  # before bench.json, which names them, is replaced: a stop there leaves it naming them
                stage.remove(plot)
        paths["removed"] = removed
        return paths


REPORT_FILES = ("bench.md", "bench.json")
"""The report's files in its folder, besides one ``.png`` per case named after the case (:func:`plot_names`)."""


def plot_names(case_names: list[str]) -> list[str]:
    """The file names of a report's plots, one per case in order: ``<stem>.png``, the stem the case's name
    made safe and distinct (:func:`~gyroemu.pipelines.formats.file_names.unique_stems`). ``bench.json``
    lists them (``"plots"``)."""
    return [f"{stem}.png" for stem in unique_stems(case_names)]


def earlier_plots(folder: str | os.PathLike[str]) -> list[Path]:
    """The plots of the report in ``folder``, as its ``bench.json`` names them: its ``"plots"``, or, in a
    report written before ``bench.json`` listed them (2026-11-27), the names bench gives the plots of its
    ``"cases"`` (:func:`plot_names`, the rule since plots were named after cases). Only names that bench
    gives the plots of that report's cases, and only those there as plain files (no folder, no symbolic
    link) with a plain ``.png`` name in ``folder`` (no path, not hidden): a hand-edited ``"plots"`` cannot
    name any other file. None when
    ``folder`` holds no ``bench.json``, or one that cannot be read or is no bench report (no
    ``"gyroemu_bench"``): a ``bench.md`` alone is prose, and another file's plots are not guessed."""
    folder = Path(folder)
    try:
        data = json.loads((folder / "bench.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return []
    if not isinstance(data, dict) or "gyroemu_bench" not in data:
        return []
    cases = data.get("cases")
    given = [c.get("name") for c in cases if isinstance(c, dict)] if isinstance(cases, list) else []
    case_names = [n for n in given if isinstance(n, str)]
    if len(case_names) != len(given):
        return []
    ours = plot_names(case_names)  # what bench would have named the plots of these cases
    names = data.get("plots", ours)
    if not isinstance(names, list):
        return []
    names = [n for n in names if n in ours]  # a name bench would not give is never removed
    plain = [n for n in dict.fromkeys(names) if isinstance(n, str) and n.endswith(".png") and not n.startswith(".")]
    plots = [folder / n for n in plain if Path(n).name == n]
    return [p for p in plots if p.is_file() and not p.is_symlink()]


def report_files_in(folder: str | os.PathLike[str]) -> list[str]:
    """The names of the files in ``folder`` that a report written there may replace: ``bench.md``,
    ``bench.json`` and every ``.png`` (the plots are named after their cases, known once the logs are read)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    names = [name for name in REPORT_FILES if (folder / name).exists()]
    return names + sorted(p.name for p in folder.glob("*.png") if not p.name.startswith("."))


def check_report_folder(
    folder: str | os.PathLike[str],
    *,
    force: bool = False,
    argument: str = "--out",
    cases: Iterable[SimCase | LogCase] = (),
) -> None:
    """:class:`BenchError` naming ``argument`` for a report folder (made with its parents when missing)
    that cannot take the report: not a folder, read-only, not writable; or that holds files the report
    may replace (:func:`report_files_in`) and ``force`` is not given; or where the report would
    overwrite or remove an input of ``cases`` (:func:`bench_inputs`, :func:`report_input_problem`: the
    plots of the simulated ones, whose names are known before any work). Before any work."""
    folder = Path(folder)
    problem = output_folder_problem(folder)
    if problem is not None:
        raise BenchError(f"argument {argument}: {problem}")
    there = report_files_in(folder)
    if there and not force:
        raise BenchError(
            f"argument {argument}: {folder} holds an earlier report ({', '.join(there)}): use another folder, or "
            "--force to write this one over it (and remove the earlier report's plots its bench.json names)"
        )
    cases = list(cases)
    inputs = bench_inputs(cases)
    if not inputs or not folder.is_dir():  # a folder still to be made holds no input
        return
    names: list[str] = []
    for case in cases:
        if isinstance(case, SimCase):  # loaded again (checked already): its name, and the files it reads
            scenario, devices, _, name, _ = _sim_case(case, 1, 0)
            names.append(name)
            inputs += loaded_files(scenario, devices[0])
    # the plots' names: the simulated cases' are known before any work, when no log comes before them
    plots = plot_names(names) if all(isinstance(c, SimCase) for c in cases[: len(names)]) else []
    problem = report_input_problem(folder, inputs, plots=plots, replace_earlier=force, argument=argument)
    if problem is not None:
        raise BenchError(problem)


def bench_inputs(cases: Iterable[SimCase | LogCase]) -> list[Path]:
    """The files a bench of ``cases`` reads, as given: each log, and each scenario or device named by a
    path (:func:`~.inputs.given_config_files`). Once loaded, the files they were read from are
    :func:`~.inputs.loaded_files`."""
    inputs: list[Path] = []
    for case in cases:
        if isinstance(case, LogCase):
            inputs.append(Path(case.path))
        elif isinstance(case, SimCase):
            inputs += given_config_files(case.scenario, case.device)
    return inputs


def report_input_problem(
    folder: str | os.PathLike[str],
    inputs: Iterable[str | os.PathLike[str]],
    *,
    plots: Iterable[str] = (),
    replace_earlier: bool = False,
    argument: str = "--out",
) -> str | None:
    """Why a report written in ``folder`` would overwrite or remove one of ``inputs``, naming the argument
    (``argument`` for a file it writes: ``bench.md``, ``bench.json``, one of ``plots``; ``--force`` for an
    earlier report's plot that ``replace_earlier`` removes, :func:`earlier_plots`), or None when it
    would not. An input is never overwritten or removed, even with ``--force``."""
    folder = Path(folder)
    inputs = list(inputs)
    problem = report_files_problem(folder, (*REPORT_FILES, *plots), inputs)  # an earlier report: not here
    if problem is not None:
        return f"argument {argument}: {problem}"
    for plot in earlier_plots(folder) if replace_earlier and folder.is_dir() else []:
        if any(same_file(plot, given) for given in inputs):
            return (
                f"argument --force: {plot} is an input: it is a plot of the earlier report in {folder} (its "
                "bench.json names it), which --force removes; inputs are never removed: use another folder"
            )
    return None


def report_figures(data: dict[str, Any]) -> dict[str, Any]:
    """A report's content (``BenchReport.to_dict()`` or ``bench.json`` read) without what differs from
    one run to the next of the same bench: the settings (the date) and every wall time and throughput.
    Two benches of the same cases give equal figures (a log read a block at a time and whole do)."""
    data = json.loads(json.dumps(data, allow_nan=False))
    data.pop("settings", None)
    for case in data.get("cases", []):
        for f in case.get("filters", []):
            f.get("summary", {}).pop("throughput", None)
            for run in f.get("runs", []):
                run.pop("wall_s", None)
                run.pop("throughput", None)
    return data


def _runs_at_once(sizes: list[int]) -> str:
    """``sizes`` (ascending) of a batched row's batches as its throughput cell says them: ``(25 runs at
    once)``, ``(5–25 runs at once)`` (a campaign's tasks, ``source.runs_at_once``), ``(1 run at once)``."""
    if sizes[0] == sizes[-1]:
        return f"({sizes[0]} run{'s' if sizes[0] != 1 else ''} at once)"
    return f"({sizes[0]}–{sizes[-1]} runs at once)"


def _si(x: float) -> str:
    for scale, suffix in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if abs(x) >= scale:
            return f"{x / scale:.3g}{suffix}"
    return f"{x:.3g}"


def _cell(summary: dict[str, Any], digits: int, metric: str) -> str:
    never = summary.get("never", 0)
    if summary["mean"] is None:
        return "never" if never else "—"
    text = f"{summary['mean']:.{digits}f}"
    if summary["n"] > 1:
        text += f" ± {summary['std']:.{digits}f}"
    if never:
        text += f" ({never} never)"
    return text


# ==================================================================================================
# Evaluation of one run


def evaluate_run(
    t: ArrayLike,
    q_est: ArrayLike,
    q_true: ArrayLike,
    *,
    mask: ArrayLike | None = None,
    six_d: bool = False,
    threshold_deg: float = 2.0,
    bias_est: np.ndarray | None = None,
    omega_true: np.ndarray | None = None,
    gyro: np.ndarray | None = None,
    rate_hz: float | None = None,
    wall_s: float = float("nan"),
    throughput: float | None = None,
    seed: int | None = None,
    reason: str = "",
) -> tuple[RunResult, dict[str, Any]]:
    """The metrics of one filter run (see the module's docstring) and the per-sample errors (degrees,
    NaN outside the counted samples) as ``{"total": ..., "inclination": ...}``: :class:`RunMetrics`
    given the run as one block (a log read a block at a time gives the same to the bit)."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    q_est = np.asarray(q_est, dtype=float)
    q_true = np.asarray(q_true, dtype=float)
    mask = np.ones(n, bool) if mask is None else np.asarray(mask, dtype=bool)
    with_bias = bias_est is not None and omega_true is not None and gyro is not None and bool(rate_hz)
    metrics = RunMetrics(
        samples=n,
        counted=int((mask & np.isfinite(q_true).all(axis=1)).sum()),
        t_first=float(t[0]) if n else math.nan,
        t_last=float(t[-1]) if n else math.nan,
        six_d=six_d,
        threshold_deg=threshold_deg,
        # with_bias: rate_hz is a rate
        bias_window=max(1, int(round(BIAS_WINDOW_S * cast(float, rate_hz)))) if with_bias else None,
    )
    errors = metrics.add(t, q_est, q_true, mask, bias_est, omega_true, gyro)
    metrics.wall_s = float(wall_s)
    return metrics.result(seed=seed, reason=reason, throughput=throughput), errors


# ==================================================================================================
# Running


def _run_filter(
    spec: str, setup: FilterSetup, run: _Run, *, six_d: bool, threshold_deg: float
) -> tuple[RunResult, dict[str, np.ndarray], str]:
    """One filter on one run: (RunResult, errors, name)."""
    filt = make_filter(spec, setup)
    name = str(filt.name)
    n = len(run.t)
    started = time.perf_counter()
    try:
        est = filt.process(run.t, run.gyro, run.accel, None if six_d else run.mag)
        wall = time.perf_counter() - started
        q, b = check_estimate(est, n, name)
        reason = ""
    except Exception as exc:  # noqa: BLE001 - a filter that fails is reported, not fatal
        wall = time.perf_counter() - started
        q, b, reason = np.full((n, 4), np.nan), None, f"process() raised {type(exc).__name__}: {exc}"
    q, b, gyro = in_body_axes(q, b, run.gyro, run.q_bs)  # a mounted sensor's estimate as the body's
    result, errors = evaluate_run(
        run.t,
        q,
        run.q_true,
        mask=run.mask,
        six_d=six_d,
        threshold_deg=threshold_deg,
        bias_est=b,
        omega_true=run.omega_true,
        gyro=gyro,
        rate_hz=setup.rate_hz,
        wall_s=wall,
        seed=run.seed,
        reason=reason,
    )
    return result, errors, name


def _curve(fr: FilterResult, t: np.ndarray, errors: dict[str, Any]) -> None:
    step = max(1, len(t) // PLOT_POINTS)
    fr.curve_t = (t - t[0])[::step]
    fr.curve_total_deg = errors["total"][::step]
    fr.curve_inclination_deg = errors["inclination"][::step]


class _Progress:
    def __init__(self, total: int, enabled: bool | None) -> None:
        if enabled is None:
            enabled = sys.stderr.isatty()
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=sys.stderr, unit="run", dynamic_ncols=True, leave=False)

    def describe(self, text: str) -> None:
        """Name the step about to run."""
        if self.bar is not None:
            self.bar.set_description(text[:70])

    def step(self, n: int = 1) -> None:
        """Count steps done."""
        if self.bar is not None:
            self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _sim_case(case: SimCase, runs: int, seed: int) -> _SimItem:
    """Load a simulated case: (scenario, devices per run, setup, traj, name, mode)."""
    from gyroemu.dynamics import load_scenario
    from gyroemu.dynamics.truth_source import WHOLE_TRUTH_BYTES
    from gyroemu.pipelines.estimation.setup import setup_for
    from gyroemu.pipelines.jobs.disk_space import whole_truth_problem
    from gyroemu.sensors import load_device

    scenario = load_scenario(case.scenario)  # ConfigError: unknown name, or the file and key at fault
    devices = [load_device(case.device, seed=seed + r) for r in range(runs)]
    # a simulated case holds its truth whole, whatever its kind (the metrics compare every sample with it),
    # and each run's samples with the truth at them: (t, gyro, accel, mag) 80 bytes and a truth sample each
    per_second = runs * float(devices[0].spec.rate_hz) * (80 + WHOLE_TRUTH_BYTES)
    problem = whole_truth_problem(scenario, case.duration, besides=(per_second, f"{runs} runs' samples and truth"))
    if problem is not None:
        raise BenchError(problem)
    _check_samples(case, scenario, devices[0])
    has_mag = devices[0].spec.magnetometer is not None
    mode = "9D" if has_mag and not case.six_d else "6D"
    setup = setup_for(devices[0], scenario, use_mag=mode == "9D")
    name = f"{scenario.name} × {devices[0].name}" + (" (6D)" if case.six_d and has_mag else "")
    return scenario, devices, setup, name, mode


def _check_samples(case: SimCase, scenario: Scenario, device: Device) -> None:
    """:class:`BenchError` naming ``--duration`` (or the scenario file's ``duration_s``, when the case
    takes the scenario's) for a run too short to sample (:func:`~.run_span.short_run_problem`): found
    before any work, not as a ``ValueError`` from the sensor."""
    span = scenario.duration_s if case.duration is None else float(case.duration)
    problem = short_run_problem(span, scenario.name, scenario.rate_hz, device.name, device.spec.rate_hz)
    if problem is not None:
        where = (
            "argument --duration"
            if case.duration is not None
            else f"{scenario.path or scenario.name}: key 'duration_s'"
        )
        raise BenchError(f"{where}: {problem}")


def _sim_run(traj: Trajectory, device: Device, seed: int) -> _Run:
    """One Monte Carlo run: ``device``'s samples of ``traj``, the body's truth at them, and the device's
    mounting (its filters' estimates are turned into the body's before they are compared)."""
    from gyroemu.pipelines.estimation.mounting import mounting_turn
    from gyroemu.pipelines.formats.frames import mounting_of
    from gyroemu.pipelines.formats.mcap_log import truth_series

    samples = device.measure(traj)
    truth = truth_series(traj, samples)
    assert truth.q_wb is not None  # truth_series always gives the attitude
    mag = samples.mag if np.isfinite(samples.mag).any() else None
    mounting = mounting_of(device)
    return _Run(
        t=np.asarray(samples.t, float),
        gyro=samples.gyro,
        accel=samples.accel,
        mag=mag,
        q_true=truth.q_wb,
        omega_true=truth.omega_b,
        mask=np.ones(len(samples.t), bool),
        seed=seed,
        q_bs=None if mounting is None else mounting_turn(mounting[0]),
    )


def _log_runs(case: LogCase) -> list[_LogItem]:
    """The devices of a log to bench, the log read whole: (name, mode, setup, run, source, notes) each."""
    from gyroemu.pipelines.estimation.mounting import mounting_from_metadata
    from gyroemu.pipelines.estimation.series import check_samples, median_step_ns, rate_of
    from gyroemu.pipelines.formats.device_stream import nearest
    from gyroemu.pipelines.formats.mcap_log import read_mcap

    path = check_log_case(case)
    log = read_mcap(path)  # LogError (a ConfigError naming the file) when unreadable or without IMU messages
    chosen = choose_devices(path, log.devices, case, lambda n, d: d.truth is not None and d.truth.q_wb is not None)
    out = []
    for name, dev in chosen.items():
        assert dev.truth is not None and dev.truth.q_wb is not None  # choose_devices kept a truth attitude
        s = dev.samples
        t = np.asarray(s.t, dtype=float)
        note = check_samples(path, name, t, s.gyro, s.accel)  # LogError: too few, stamps, all NaN
        if note:
            warnings.warn(f"{path}: {note}", BenchWarning, stacklevel=3)
        has_mag = bool(np.isfinite(s.mag).all(axis=1).any())
        mode = "9D" if has_mag and not case.six_d else "6D"
        # Truth at the samples' stamps: the nearest within a quarter of a sample interval
        tt = np.asarray(dev.truth.t, dtype=float)
        dt_nominal = median_step_ns(dev.stamp_ns) / 1e9  # from the integer stamps, as the census has it
        q_true = np.full((len(t), 4), np.nan)
        omega = None
        if len(tt):
            j = nearest(t, tt)
            hit = np.abs(tt[j] - t) <= TRUTH_MATCH * dt_nominal
            q_true[hit] = dev.truth.q_wb[j[hit]]
            if dev.truth.omega_b is not None and np.isfinite(dev.truth.omega_b).any():
                omega = np.full((len(t), 3), np.nan)
                omega[hit] = dev.truth.omega_b[j[hit]]
        if not np.isfinite(q_true).all(axis=1).any():
            raise no_reference_error(path, name)
        movement = getattr(dev, "movement", None)
        flags = None if movement is None else bool(np.asarray(movement, bool).any())
        mask = np.asarray(movement, dtype=bool) if flags else np.ones(len(t), bool)
        no_ref = int((~np.isfinite(q_true).all(axis=1) & mask).sum())
        notes = mask_notes(path, name, flags, int(mask.sum()), no_ref, [note] if note else [])
        t_rel = dev.seconds_from_first()  # the filters' clock, exact from the nanoseconds (as the streamed read's)
        samples = (t_rel, np.asarray(s.gyro, float), np.asarray(s.mag, float) if mode == "9D" else None)
        setup = log_setup(dev.metadata, rate_of(dev.stamp_ns), mode, case, samples, notes)
        run = _Run(
            t=t_rel,
            gyro=np.asarray(s.gyro, float),
            accel=np.asarray(s.accel, float),
            mag=np.asarray(s.mag, float) if has_mag else None,
            q_true=q_true,
            omega_true=omega,
            mask=mask,
            q_bs=mounting_from_metadata(dev.metadata),  # a gyroemu device's: its estimates as the body's
        )
        source = {"log": str(path), "device": name}
        out.append((log_label(path, name, len(log.devices), case, has_mag), mode, setup, run, source, notes))
    return out


def _resolve_filters(filters: Iterable[str] | None) -> tuple[list[str], dict[str, str]]:
    unavailable: dict[str, str] = {}
    if filters is None:
        unavailable = unavailable_filters()
        filters = available_filters()
    filters = list(dict.fromkeys(filters))  # repeated names once
    for spec in filters:
        filter_class(spec)  # FilterError, naming it, before anything runs
    return filters, unavailable


def run_bench(
    cases: Iterable[SimCase | LogCase] | None = None,
    filters: Iterable[str] | None = None,
    runs: int = 3,
    seed: int = 0,
    *,
    threshold_deg: float = 2.0,
    batched: bool = False,
    progress: bool | None = None,
) -> BenchReport:
    """Run ``filters`` over ``cases`` and return the report.

    Parameters
    ----------
    cases : list of SimCase or LogCase
        Default: ``[SimCase()]`` (smooth_manoeuvre × consumer_mems, 60 s).
    filters : list of str
        Built-in names (``gyroemu.pipelines.estimation.registry.FILTERS``) or ``module:Class``; default every
        available built-in (one whose package is missing is left out with a note).
    runs, seed : int
        Monte Carlo runs per simulated case, device seeds ``seed … seed + runs − 1``.
    threshold_deg : float
        Convergence threshold.
    batched : bool
        Run the ``mekf`` of each simulated case over all runs at once with ``mekf_batch`` (vectorised
        across runs; stamps shared by every run, else run by run with a note) instead of run by run.
    progress : bool or None
        A tqdm bar on stderr (None: when stderr is a terminal).

    Raises
    ------
    FilterError, BenchError, gyroemu.dynamics.ConfigError
        An unknown or unusable filter, scenario, device or log (the message names it).
    """
    if runs < 1:
        raise BenchError("argument --runs: must be at least 1")
    cases = [SimCase()] if cases is None else list(cases)
    filters, unavailable = _resolve_filters(filters)
    batch_fn: Callable[..., Estimate] | None = None
    if batched and "mekf" in filters and any(isinstance(c, SimCase) for c in cases):
        try:
            from gyroemu.pipelines.estimation.batched import mekf_batch as batch_fn
        except ImportError as exc:
            raise BenchError(f"argument --batched: the batched mekf is not available ({exc})") from exc

    # Load everything first: bad names and bad logs fail before any work.
    prepared: list[tuple[str, SimCase | LogCase, Any]] = []
    inputs = bench_inputs(cases)  # never overwritten by the report (BenchReport.save)
    for case in cases:
        if isinstance(case, SimCase):
            sim = _sim_case(case, runs, seed)
            prepared.append(("sim", case, sim))
            inputs += loaded_files(sim[0], sim[1][0])
        elif isinstance(case, LogCase):
            prepared += [("log", case, item) for item in _log_items(case, filters)]
        else:
            raise TypeError(f"a case is a SimCase or a LogCase, got {type(case).__name__}")

    steps = sum((runs if kind == "sim" else 1) * len(filters) for kind, _, _ in prepared)
    bar = _Progress(steps, progress)
    results = []
    try:
        for kind, case, item in prepared:
            if kind == "sim":
                assert isinstance(case, SimCase)  # "sim" items are made from SimCases above
                results.append(_bench_sim(case, item, filters, runs, seed, threshold_deg, batch_fn, bar))
            elif isinstance(item, LogDevice):
                assert isinstance(case, LogCase)
                results.append(_bench_log_stream(Path(case.path), item, filters, threshold_deg, bar))
            else:
                results.append(_bench_log(item, filters, threshold_deg, bar))
    finally:
        bar.close()
    settings = {
        "runs": runs,
        "seed": seed,
        "threshold_deg": threshold_deg,
        "batched": bool(batched),
        "filters": filters,
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "cases": [
            {
                "type": type(c).__name__,
                **{k: v if v is None or isinstance(v, (bool, int, float)) else str(v) for k, v in c.__dict__.items()},
            }
            for c in cases
        ],
    }
    return BenchReport(cases=results, settings=settings, unavailable=unavailable, inputs=inputs)


def _bench_sim(
    case: SimCase,
    item: _SimItem,
    filters: list[str],
    runs: int,
    seed: int,
    threshold_deg: float,
    batch_fn: Callable[..., Estimate] | None,
    bar: _Progress,
) -> CaseResult:
    scenario, devices, setup, name, mode = item
    six_d = mode == "6D"
    traj = scenario.simulate(duration=case.duration)
    per_run = [f for f in filters if not (batch_fn is not None and f == "mekf")]
    results: dict[str, FilterResult | None] = {f: None for f in filters}
    kept = []  # the runs, for the batched mekf
    first: _Run | None = None
    for r, device in enumerate(devices):
        run = _sim_run(traj, device, seed + r)
        if first is None:
            first = run
        for spec in per_run:
            bar.describe(f"{name}: {spec} run {r + 1}/{runs}")
            if r == 0:
                warm_up(spec, setup, run.t, run.gyro, run.accel, None if six_d else run.mag)
            res, errors, fname = _run_filter(spec, setup, run, six_d=six_d, threshold_deg=threshold_deg)
            fr = results[spec]
            if fr is None:
                fr = results[spec] = FilterResult(
                    filter=spec, name=fname, batched=False, runs=[], offline=is_offline(spec)
                )
                _curve(fr, run.t, errors)
            fr.runs.append(res)
            bar.step()
        if batch_fn is not None:
            kept.append(run)
    if batch_fn is not None:
        bar.describe(f"{name}: mekf, {len(kept)} runs batched")
        results["mekf"] = _bench_batched(batch_fn, setup, kept, six_d, threshold_deg)
        bar.step(len(kept))
    assert first is not None  # runs >= 1: one device at least
    return CaseResult(
        name=name,
        kind="simulated",
        mode=mode,
        rate_hz=setup.rate_hz,
        samples=len(first.t),
        duration_s=float(first.t[-1] - first.t[0]),
        runs=runs,
        source={
            "scenario": case.scenario,
            "device": case.device,
            "duration_s": case.duration,
            "seeds": [seed + r for r in range(runs)],
        },
        # every filter has its result: set on the first run, or by the batched mekf
        filters=cast(list[FilterResult], [results[f] for f in filters]),
    )


def _bench_batched(
    batch_fn: Callable[..., Estimate], setup: FilterSetup, runs: list[_Run], six_d: bool, threshold_deg: float
) -> FilterResult:
    """All runs through ``mekf_batch`` at once when they share their stamps, else one by one."""
    fr = FilterResult(filter="mekf", name="mekf", batched=True, runs=[])
    shared = all(len(r.t) == len(runs[0].t) and np.array_equal(r.t, runs[0].t) for r in runs)
    groups = [runs] if shared else [[r] for r in runs]
    if not shared:
        fr.note = (
            "the runs' stamps differ (clock jitter), so each run went through mekf_batch on its own; "
            "throughput is per run"
        )
    k = min(len(runs[0].t), WARM_UP_SAMPLES)
    try:  # untimed first call (compiling or loading the kernels)
        batch_fn(
            setup,
            runs[0].t[:k],
            np.stack([r.gyro[:k] for r in runs[:2]]),
            np.stack([r.accel[:k] for r in runs[:2]]),
            # one device config: every run has a field when the first has (else np.stack raises, as before)
            None if six_d or runs[0].mag is None else np.stack([cast(np.ndarray, r.mag)[:k] for r in runs[:2]]),
        )
    except Exception:  # noqa: BLE001 - the timed call reports it
        pass
    for group in groups:
        n = len(group[0].t)
        gyro = np.stack([r.gyro for r in group])
        accel = np.stack([r.accel for r in group])
        mag = None if six_d or group[0].mag is None else np.stack([cast(np.ndarray, r.mag) for r in group])
        started = time.perf_counter()
        reason = ""
        try:
            est = batch_fn(setup, group[0].t, gyro, accel, mag)
            wall = time.perf_counter() - started
            q = np.asarray(est.q_wb, dtype=float)
            b = None if est.gyro_bias is None else np.asarray(est.gyro_bias, dtype=float)
            if q.shape != (len(group), n, 4):
                raise ValueError(f"mekf_batch returned q_wb of shape {q.shape}, expected {(len(group), n, 4)}")
        except Exception as exc:  # noqa: BLE001
            wall = time.perf_counter() - started
            q, b, reason = np.full((len(group), n, 4), np.nan), None, f"mekf_batch raised {type(exc).__name__}: {exc}"
        for i, run in enumerate(group):
            # a mounted sensor's estimate as the body's
            q_i, b_i, gyro_i = in_body_axes(q[i], None if b is None else b[i], run.gyro, run.q_bs)
            res, errors = evaluate_run(
                run.t,
                q_i,
                run.q_true,
                mask=run.mask,
                six_d=six_d,
                threshold_deg=threshold_deg,
                bias_est=b_i,
                omega_true=run.omega_true,
                gyro=gyro_i,
                rate_hz=setup.rate_hz,
                wall_s=wall,
                throughput=len(group) * n / wall if wall > 0 else float("nan"),
                seed=run.seed,
                reason=reason,
            )
            if fr.curve_t is None:
                _curve(fr, run.t, errors)
            fr.runs.append(res)
    return fr


def _log_items(case: LogCase, filters: list[str]) -> list[LogDevice] | list[_LogItem]:
    """A log case's devices: read a block at a time (:class:`LogDevice`), or whole where one pass cannot
    pair the log or the case asks for it (the tuples of :func:`_log_runs`)."""
    from gyroemu.pipelines.formats.device_stream import NotStreamable

    if not case.read_whole:
        try:
            return stream_log_devices(case, whole_samples=any(takes_whole_log(f) for f in filters))
        except NotStreamable:
            pass  # read whole, with the same results
    return _log_runs(case)


def _bench_log_stream(
    path: Path, dev: LogDevice, filters: list[str], threshold_deg: float, bar: _Progress
) -> CaseResult:
    """A log device read a block at a time (:func:`.bench_log.bench_log_device`)."""
    runs = bench_log_device(path, dev, filters, threshold_deg, bar.describe)
    results = []
    for r in runs:
        fr = FilterResult(filter=r.spec, name=r.name, batched=False, runs=[r.result], offline=is_offline(r.spec))
        fr.curve_t, fr.curve_total_deg, fr.curve_inclination_deg = r.curve_t, r.curve_total, r.curve_inclination
        results.append(fr)
        bar.step()
    duration = float(dev.t_last - dev.t_first)
    return _log_case(dev.label, dev.mode, dev.setup, dev.samples, duration, dev.source, results, dev.notes)


def _log_case(
    name: str,
    mode: str,
    setup: FilterSetup,
    samples: int,
    duration_s: float,
    source: dict[str, Any],
    filters: list[FilterResult],
    notes: list[str],
) -> CaseResult:
    """A log device's case in the report, read whole or a block at a time."""
    return CaseResult(
        name=name,
        kind="log",
        mode=mode,
        rate_hz=setup.rate_hz,
        samples=samples,
        duration_s=duration_s,
        runs=1,
        source=source,
        filters=filters,
        notes=notes,
    )


def _bench_log(item: _LogItem, filters: list[str], threshold_deg: float, bar: _Progress) -> CaseResult:
    name, mode, setup, run, source, notes = item
    results = []
    for spec in filters:
        bar.describe(f"{name}: {spec}")
        warm_up(spec, setup, run.t, run.gyro, run.accel, None if mode == "6D" else run.mag)
        res, errors, fname = _run_filter(spec, setup, run, six_d=mode == "6D", threshold_deg=threshold_deg)
        fr = FilterResult(filter=spec, name=fname, batched=False, runs=[res], offline=is_offline(spec))
        _curve(fr, run.t, errors)
        results.append(fr)
        bar.step()
    return _log_case(name, mode, setup, len(run.t), float(run.t[-1] - run.t[0]), source, results, notes)
