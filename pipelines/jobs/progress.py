"""A progress bar over the phases of an offline run, on a terminal only.

``gyroemu simulate`` runs in up to three phases: ``truth`` (the scenario's trajectory), ``measure``
(the device's samples) and ``write`` (the .mcap or .npz file). Each is one call into the library that
reports nothing while it runs, so the bar counts phases (``2/3``) and names the current one, and a
small thread redraws it twice a second so that its elapsed time keeps moving during a long phase.

The bar goes to stderr and only when stderr is a terminal (``isatty``): piped or redirected output,
CI logs and the tests see nothing, and then no tqdm object and no thread exist at all. Cost when shown:
one redraw per phase plus two per second, nothing per sample.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Iterator
from typing import TextIO

__all__ = ["PhaseProgress", "CountProgress"]


def _shown(stream: TextIO, enabled: bool | None) -> bool:
    """Whether a bar goes on ``stream``: ``enabled`` when given, else whether ``stream`` is a terminal."""
    if enabled is not None:
        return enabled
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


class PhaseProgress:
    """Phases of a run as a tqdm bar on ``stream`` (default stderr), shown only on a terminal.

    Use :meth:`phase` as a context manager around each phase, then :meth:`close` (or use the object
    itself as a context manager). ``enabled`` forces the bar on or off (default: ``stream.isatty()``).
    """

    REDRAW_S = 0.5  # seconds between redraws within a phase

    def __init__(
        self, phases: list[str], *, label: str = "", stream: TextIO | None = None, enabled: bool | None = None
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        enabled = _shown(self.stream, enabled)
        self.phases = list(phases)
        self.label = label
        self.bar = None
        self._stop = threading.Event()
        self._thread = None
        if enabled and self.phases:
            from tqdm import tqdm

            self.bar = tqdm(
                total=len(self.phases),
                desc=label or None,
                unit="phase",
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
                bar_format="{desc} {bar} {n_fmt}/{total_fmt} phases [{elapsed}]",
            )
            self._thread = threading.Thread(target=self._redraw, name="progress", daemon=True)
            self._thread.start()

    def _redraw(self) -> None:
        while not self._stop.wait(self.REDRAW_S):
            bar = self.bar
            if bar is not None:
                bar.refresh()

    @contextlib.contextmanager
    def phase(self, name: str) -> Iterator[None]:
        """Show ``name`` as the current phase for the block; count it done when the block ends."""
        if self.bar is None:
            yield
            return
        self.bar.set_description_str(f"{self.label}: {name}" if self.label else name, refresh=True)
        yield
        self.bar.update(1)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> PhaseProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CountProgress:
    """A run's progress in samples as a tqdm bar on ``stream`` (default stderr), on a terminal only.

    ``total`` None: a run without end (the bar counts up). Call :meth:`advance` as samples are made;
    use the object as a context manager (or call :meth:`close`). ``enabled`` as :class:`PhaseProgress`;
    ``initial``: the count done before the bar starts; ``unit_scale``: counts as 1.2M rather than 1200000.
    """

    def __init__(
        self,
        total: int | None,
        *,
        label: str = "",
        unit: str = "samples",
        stream: TextIO | None = None,
        enabled: bool | None = None,
        initial: int = 0,
        unit_scale: bool = True,
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        enabled = _shown(self.stream, enabled)
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(
                total=total,
                initial=initial,
                desc=label or None,
                unit=f" {unit}",
                unit_scale=unit_scale,
                file=self.stream,
                leave=False,
                dynamic_ncols=True,
                mininterval=0.5,
            )

    def advance(self, count: int) -> None:
        """Count ``count`` more samples made."""
        if self.bar is not None:
            self.bar.update(count)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self) -> CountProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
