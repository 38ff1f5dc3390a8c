"""A campaign's progress as a tqdm bar on stderr, on a terminal only: runs done of the campaign's total
(those stored before this session counted as done from the start), runs per second of this session, and
the time left at that rate. Piped or redirected stderr, CI logs and the tests see nothing."""

from __future__ import annotations

from typing import TextIO

from gyroemu.pipelines.jobs.progress import CountProgress

__all__ = ["RunsProgress"]


class RunsProgress(CountProgress):
    """``total`` runs, ``done`` of them already stored; :meth:`advance` as tasks finish. ``enabled``
    forces the bar on or off (default: whether ``stream``, stderr by default, is a terminal)."""

    def __init__(
        self,
        total: int,
        done: int = 0,
        *,
        label: str = "",
        unit: str = "runs",
        stream: TextIO | None = None,
        enabled: bool | None = None,
    ) -> None:
        super().__init__(total, label=label, unit=unit, stream=stream, enabled=enabled, initial=done, unit_scale=False)

    def __enter__(self) -> RunsProgress:
        return self
