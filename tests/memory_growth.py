"""Memory that does not grow with a log: the check the streamed reads share (``estimate``, ``bench --log``).

``run(minutes, whole)`` handles a log of 2 and then 8 minutes, read whole or a block at a time, while
tracemalloc (which sees NumPy's buffers) records Python's peak allocation. Read whole, the peak holds
every sample, so the 4× longer log peaks above 3× (4×, less the floor that does not grow); a block at a
time, the peak is the chunks' and blocks' buffers, the same for both logs within 15 %, and below a third
of the whole read's.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable


def assert_flat_when_streamed(run: Callable[[int, bool], object]) -> None:
    """Run ``run(minutes, whole)`` for 2 and 8 minutes, each read a block at a time then whole, and assert
    the peaks above (module notes)."""
    peaks = {}
    for minutes in (2, 8):
        for whole in (False, True):
            tracemalloc.start()
            run(minutes, whole)
            peaks[minutes, whole] = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
    assert peaks[8, True] > 3.0 * peaks[2, True], peaks  # the whole read holds every sample
    assert peaks[8, False] < 1.15 * peaks[2, False], peaks  # a block at a time: nothing of the extra minutes
    assert peaks[8, False] < peaks[8, True] / 3, peaks
