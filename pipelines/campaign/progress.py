"""A campaign's progress as a tqdm bar on stderr, on a terminal only: runs done of the campaign's total
(those stored before this session counted as done from the start), runs per second of this session, and
the time left at that rate. Piped or redirected stderr, CI logs and the tests see nothing."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["RunsProgress"]


class RunsProgress:
    """``total`` runs, ``done`` of them already stored; :meth:`advance` as tasks finish. ``enabled``
    forces the bar on or off (default: whether ``stream``, stderr by default, is a terminal)."""

    def __init__(
        self,
        total: int,
        done: int = 0,
        *,
        label: str = "",
        unit: str = "runs",
        stream: Any = None,
        enabled: bool | None = None,
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty and isatty())
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(
                total=total,
                initial=done,
                desc=label or None,
                unit=f" {unit}",
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
                mininterval=0.5,
            )

    def advance(self, count: int) -> None:
        """Count ``count`` more runs done."""
        if self.bar is not None:
            self.bar.update(count)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> RunsProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
