"""Campaigns: many bench runs or many logs over a grid of configs, on Dask distributed.

- :mod:`.spec`: the campaign file (TOML) validated into a :class:`Campaign` of cells and tasks;
- :mod:`.store`: Parquet part files, one per finished task, written atomically (resume, no duplicates);
- :mod:`.engine`: the tasks on a Dask scheduler or a local cluster, with their faults;
- :mod:`.tasks`: what a worker runs (a bench cell's rows, a dataset's log);
- :mod:`.progress`: the bar of runs done, total, rate and time left (on a terminal only).

The jobs are :mod:`gyroemu.pipelines.jobs.campaign` (``gyroemu bench --campaign``) and
:mod:`gyroemu.pipelines.jobs.generate` (``gyroemu generate``). dask and pyarrow are imported only when
a campaign runs.
"""

from .engine import SchedulerLostError, TaskFailure, default_workers, run_tasks, scheduler_problem
from .progress import RunsProgress
from .spec import Campaign, CampaignSpec, Cell, CellTask, SeedRange, campaign_from_spec, config_hash, load_campaign
from .store import PartStore, StoreWarning, readable
from .tasks import ROW_COLUMNS, LogTask, consecutive, make_log, row_schema, run_cell

__all__ = [
    "ROW_COLUMNS",
    "Campaign",
    "CampaignSpec",
    "Cell",
    "CellTask",
    "LogTask",
    "PartStore",
    "RunsProgress",
    "SchedulerLostError",
    "SeedRange",
    "StoreWarning",
    "TaskFailure",
    "campaign_from_spec",
    "config_hash",
    "consecutive",
    "default_workers",
    "load_campaign",
    "make_log",
    "readable",
    "row_schema",
    "run_cell",
    "run_tasks",
    "scheduler_problem",
]
