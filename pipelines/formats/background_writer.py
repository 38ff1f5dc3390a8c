"""A writer on a thread of its own, so that writing a block overlaps computing the next.

:class:`BackgroundWriter` hands each item given to :meth:`~BackgroundWriter.put` to a ``write``
function on one worker thread, in order, through a queue of ``depth`` items: the producer blocks when
the writer falls ``depth`` items behind, so memory stays that of a few blocks. An exception in
``write`` stops the worker and is raised again in the producer, at its next ``put`` or at
:meth:`~BackgroundWriter.close`. The overlap comes from what releases the GIL: numpy's copies and
zstd's compression on the writer's side, gyroemu's compiled kernels (``nogil``) on the producer's.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Generic, TypeVar, cast

__all__ = ["BackgroundWriter"]

T = TypeVar("T")

_DONE = object()


class BackgroundWriter(Generic[T]):
    """Call ``write(item)`` for every item :meth:`put`, in order, on a worker thread.

    Parameters
    ----------
    write : callable
        Consumes one item; runs on the worker thread only.
    depth : int
        Items queued at most before :meth:`put` waits.

    As a context manager: :meth:`close` on leaving the block normally (waits for the writes and raises
    the writer's exception, if any); on an exception, the queued items are dropped and the worker is
    stopped before the exception goes on.
    """

    def __init__(self, write: Callable[[T], None], depth: int = 2) -> None:
        self._write = write
        self._queue: queue.Queue[object] = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="writer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _DONE or self._stop.is_set():
                return
            try:
                self._write(cast(T, item))  # not _DONE: an item given to put()
            except BaseException as e:  # handed to the producer
                self._error = e
                self._stop.set()
                return

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def put(self, item: T) -> None:
        """Queue ``item`` for writing (waits while ``depth`` items are queued)."""
        while True:
            self._raise()
            if self._stop.is_set():
                raise RuntimeError("the writer has stopped")
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def close(self) -> None:
        """Wait until every queued item is written; raise the writer's exception, if any."""
        if self._thread.is_alive():
            while not self._stop.is_set():
                try:
                    self._queue.put(_DONE, timeout=0.1)
                    break
                except queue.Full:
                    continue
            self._thread.join()
        self._raise()

    def abort(self) -> None:
        """Stop the worker after the item it is writing; drop the rest."""
        self._stop.set()
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        try:
            self._queue.put_nowait(_DONE)
        except queue.Full:
            pass
        self._thread.join()

    def __enter__(self) -> BackgroundWriter[T]:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
