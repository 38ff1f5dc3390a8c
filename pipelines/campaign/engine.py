"""Tasks run on Dask distributed: a scheduler given by address, or a local cluster gyroemu starts itself.

:func:`run_tasks` submits each task as one Dask task and hands each result, in the order they finish,
to a callback in the calling process (which stores it). What Dask does about faults, and what this
module adds:

- a worker killed mid-task (SIGKILL, out of memory): the scheduler runs its tasks on other workers
  (up to ``distributed.scheduler.allowed-failures`` times, then the task fails with ``KilledWorker``);
  the callback sees each task's result once, whichever worker made it;
- a task that raises: :class:`TaskFailure` (the task and its error) in the list returned, and the
  other tasks go on;
- the scheduler lost (its futures are cancelled by the client): :class:`SchedulerLostError`, with how
  many tasks had finished; their results have been handed over already.

dask and distributed are imported when :func:`run_tasks` is called, not with this module.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import CancelledError
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["SchedulerLostError", "TaskFailure", "default_workers", "run_tasks", "scheduler_problem"]

T = TypeVar("T")


class SchedulerLostError(RuntimeError):
    """The Dask scheduler could not be reached, or went away while tasks were running."""


@dataclass(frozen=True)
class TaskFailure(Generic[T]):
    """A task that raised: the task, and its error as ``Type: message``."""

    task: T
    error: str


_HOST_PORT = re.compile(r"^(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>[0-9]{1,5})$")
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
"""distributed's communication backends whose addresses are ``HOST:PORT`` (and ``inproc://``, in-process)."""


def scheduler_problem(address: str) -> str | None:
    """Why ``address`` is no Dask scheduler address, or None when it is one: ``PROTOCOL://HOST:PORT`` for
    one of distributed's backends (``tcp``, ``tls``, ``ws``, ``wss``, ``ucx``; an IPv6 host in brackets),
    ``HOST:PORT`` (which Dask takes as tcp) or ``inproc://…``. Checked before a job starts anything:
    distributed itself raises a bare ``ValueError`` only on connecting."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    if scheme == "inproc" and rest:
        return None
    if scheme not in _SCHEMES:
        return f"{address!r}: no Dask protocol {scheme}:// (tcp, tls, ws, wss, ucx or inproc)"
    m = _HOST_PORT.match(rest)
    if m is None:
        return f"{address!r} is not a scheduler address like tcp://HOST:8786"
    if not 0 < int(m.group("port")) < 65536:
        return f"{address!r}: the port must be 1 to 65535"
    return None


def default_workers() -> int:
    """Worker processes of the local cluster: one per core this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not every system has sched_getaffinity
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def _quiet_distributed(level: int = logging.CRITICAL) -> Iterator[None]:
    """Raise the ``distributed`` loggers' levels for the block (reconnection tracebacks after a loss):
    ``distributed`` and each of its children with a level of its own (``distributed.client``)."""
    names = ["distributed"] + [
        name
        for name, logger in logging.root.manager.loggerDict.items()
        if name.startswith("distributed.") and isinstance(logger, logging.Logger) and logger.level
    ]
    loggers = [logging.getLogger(name) for name in names]
    before = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(level)
    try:
        yield
    finally:
        for logger, old in zip(loggers, before):
            logger.setLevel(old)


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None, processes: bool, connect_timeout_s: float) -> Iterator[Client]:
    """A ``distributed.Client`` on ``scheduler``, or on a local cluster of ``workers`` single-threaded
    workers (processes unless ``processes`` is False); everything it started is closed after."""
    from distributed import Client, LocalCluster

    cluster = None
    if scheduler is None:
        n = default_workers() if workers is None else workers
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=processes,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        client = Client(cluster)
    else:
        try:
            with _quiet_distributed():
                client = Client(scheduler, timeout=connect_timeout_s)
        except (OSError, TimeoutError) as exc:
            raise SchedulerLostError(
                f"cannot reach the Dask scheduler at {scheduler} ({type(exc).__name__}: {exc})"
            ) from None
    try:
        yield client
    finally:
        with _quiet_distributed(), contextlib.suppress(Exception):
            client.close(timeout=5)
        if cluster is not None:
            with _quiet_distributed(), contextlib.suppress(Exception):
                cluster.close(timeout=10)


def run_tasks(
    tasks: Sequence[T],
    fn: Callable[[T], Any],
    on_result: Callable[[T, Any], None],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    label: Callable[[T], str] = str,
    connect_timeout_s: float = 10.0,
) -> list[TaskFailure[T]]:
    """Run ``fn(task)`` for every task on Dask; call ``on_result(task, result)`` here as each finishes.

    Parameters
    ----------
    tasks : sequence
        Picklable task objects (``fn`` and the tasks travel to the workers).
    fn : callable
        Importable on the workers (a module-level function of an installed package).
    on_result : callable
        Called in this process once per finished task, in the order they finish.
    scheduler : str or None
        A scheduler's address (``tcp://host:8786``); None: a local cluster of ``workers``.
    workers : int or None
        Workers of the local cluster, one thread each (default: one per core).
    processes : bool
        Local workers as processes (default) or threads of this process (quick, for tests).
    label : callable
        A task's name in Dask's key (the dashboard).
    connect_timeout_s : float
        Seconds to wait for ``scheduler``.

    Returns
    -------
    list of TaskFailure
        The tasks that raised (or whose workers kept dying), with their errors.

    Raises
    ------
    SchedulerLostError
        ``scheduler`` unreachable, or the scheduler lost while tasks were running.
    Exception
        What ``on_result`` raises (an ``OSError`` of a full disk), as it is: the tasks not handed over
        yet are dropped with the cluster.
    """
    if not tasks:
        return []
    from distributed import as_completed

    failures: list[TaskFailure[T]] = []
    run = uuid.uuid4().hex[:8]
    with _client(scheduler, workers, processes, connect_timeout_s) as client:
        where = scheduler or "the local cluster"
        futures = {}
        for i, task in enumerate(tasks):
            key = f"gyroemu-{_safe(label(task))}-{run}-{i}"
            futures[client.submit(fn, task, key=key, pure=False)] = task
        done = 0

        def lost(cause: str = "") -> SchedulerLostError:
            return SchedulerLostError(
                f"lost the Dask scheduler ({where}) with {done} of {len(tasks)} tasks finished{cause}"
            )

        finished = as_completed(list(futures))
        while True:
            # Only the scheduler's calls are read as a lost connection: an error of ``on_result`` (the
            # store's full disk, its folder a file) is the caller's own and goes through as it is.
            try:
                future = next(finished, None)
                if future is None:
                    break
                task = futures.pop(future)
                status = future.status
                if status == "finished":
                    result = future.result()
                    future.release()
                elif status == "error":
                    exc = future.exception()
                    failures.append(TaskFailure(task, f"{type(exc).__name__}: {exc}"))
                    future.release()
                    continue
                elif status in ("lost", "pending"):
                    # Its worker died holding the result after ``as_completed`` had handed it over: the
                    # scheduler computes it again on a living worker, so wait for it once more.
                    futures[future] = task
                    finished.add(future)
                    continue
                else:  # cancelled: not by us, so by the client on losing the scheduler
                    raise lost()
            except CancelledError:  # the same, seen as the result is fetched (distributed's FutureCancelledError)
                raise lost() from None
            except (OSError, TimeoutError) as exc:  # the connection itself failed mid-run
                raise lost(f" ({type(exc).__name__}: {exc})") from None
            on_result(task, result)
            done += 1
    return failures


def _safe(text: str) -> str:
    """``text`` for a Dask key: letters, digits and ``._-`` only, at most 60 characters."""
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in text)[:60]
