"""Disk space and memory for a job: how much there is, said for people, and the error of a disk that fills.

A job that knows its output's size checks it against its folder's free space before any work
(``simulate``: samples × bytes per sample; ``estimate``: the log's copy, the estimates and the smoother's
temporary files) and refuses with a message that names the argument. A disk that fills all the same
(another process writing, a size under-estimated) raises :class:`OSError` with ``errno`` ENOSPC or EDQUOT
from wherever the write was; :func:`is_disk_full` tells the command line such an error from the others.
"""

from __future__ import annotations

import errno
import os
import shutil
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gyroemu.dynamics.scenarios import Scenario

__all__ = [
    "MCAP_RECORD_OVERHEAD",
    "free_bytes",
    "human_size",
    "is_disk_full",
    "machine_memory",
    "memory_problem",
    "whole_truth_problem",
]

MCAP_RECORD_OVERHEAD = 31 + 16
"""Bytes an MCAP message record adds to its message: its header, and its entry in the chunk's message index."""


def human_size(n_bytes: float) -> str:
    """``n_bytes`` for people: ``12.3 GB`` (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes:.0f} bytes"


def free_bytes(folder: str | os.PathLike[str]) -> int:
    """Bytes free for an unprivileged writer in ``folder``'s file system."""
    return shutil.disk_usage(folder).free


def is_disk_full(error: BaseException) -> bool:
    """Whether ``error`` is a write refused for want of space: no space left on the device (ENOSPC) or
    the user's quota used up (EDQUOT)."""
    return isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT)


def machine_memory() -> int | None:
    """The machine's physical memory, bytes (None where the system does not say)."""
    try:
        memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # not every system says
        return None
    return memory if memory > 0 else None


def memory_problem(need_bytes: float, what: str) -> str | None:
    """Why a job that holds ``need_bytes`` in memory (``what``: of what, for the message) cannot run on
    this machine (more than its physical memory), or None when it can or the machine does not say."""
    memory = machine_memory()
    if memory is None or need_bytes <= memory:
        return None
    return f"needs about {human_size(need_bytes)} of memory ({what}), more than this machine's {human_size(memory)}"


def whole_truth_problem(
    scenario: Scenario, duration: float | None, rate_hz: float | None = None, besides: tuple[float, str] | None = None
) -> str | None:
    """Why a run of ``scenario`` over ``duration`` s (None: the scenario file's ``duration_s``) at
    ``rate_hz`` (None: its own) cannot hold its truth whole on this machine (with ``besides``, bytes held
    beside it per second of the run and what they are), naming what to change (``--duration``,
    ``--rate``, or the file's key), or None when it can
    (:func:`gyroemu.dynamics.truth_source.whole_truth_bytes`)."""
    from gyroemu.dynamics.truth_source import WHOLE_TRUTH_BYTES, whole_truth_bytes

    need = whole_truth_bytes(scenario, duration, rate_hz)
    what = f"the truth held whole, {WHOLE_TRUTH_BYTES} bytes a sample"
    if besides is not None:
        need += besides[0] * float(scenario.duration_s if duration is None else duration)
        what += f", and {besides[1]}"
    problem = memory_problem(need, what)
    if problem is None:
        return None
    if duration is None:
        return f"{scenario.name}: key 'duration_s': {scenario.duration_s:g} s {problem}: give a shorter --duration"
    rate = " or lower --rate" if rate_hz is not None else ""
    return f"argument --duration: {float(duration):g} s of {scenario.name} {problem}: shorten --duration{rate}"
