"""A producer thread that keeps a bounded queue of message batches ahead of a paced publisher.

``gyroemu replay`` (reading an MCAP file a chunk at a time) and ``gyroemu stream`` (simulating a
device a block at a time) both hand :meth:`gyroemu.pipelines.transport.zenoh_io.PacedPublisher.run_schedule`
an endless iterable of batches, lists of ``(deadline offset ns, key, payload)``. The work that makes
them runs in a :class:`ReadAheadThread`, never on the publisher's schedule: the thread queues each
batch (a bounded queue of ``depth`` batches, so memory stays bounded whatever the run's length) and
sets :attr:`ReadAheadThread.ready` once the queue is full, the moment to start the publisher's clock
(the producer's start-up, competing for the GIL with the first deadlines, would make them late).

Batches are small (:data:`BATCH` messages) because the publisher frees each spent one (a list of tuples
of bytes: one deallocation per object, holding the GIL) just after a send: 256 messages take ~50 us.

A subclass implements :meth:`ReadAheadThread.produce`; :meth:`ReadAheadThread.batches` is what the
publisher iterates.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Generator, Iterator

__all__ = ["READ_AHEAD", "BATCH", "Batch", "ReadAheadThread"]

READ_AHEAD = 64  # batches queued ahead of the publisher
BATCH = 256  # messages per batch: the publisher frees a spent batch (~50 us for 256) right after a send

Batch = list[tuple[int, str, bytes]]
"""Messages ``(deadline offset ns, key, payload)``, offsets non-decreasing."""


class ReadAheadThread(threading.Thread):
    """Runs :meth:`produce` in a daemon thread and queues the batches it yields (at most ``depth``
    waiting); the end of :meth:`produce` ends :meth:`batches`, an exception it raises is raised there.

    Parameters
    ----------
    depth : int
        Batches queued ahead of the consumer, at most.
    name : str
        The thread's name.

    Attributes
    ----------
    queue : queue.Queue
        The batches; ``None`` ends them, an exception object is raised by :meth:`batches`.
    stopping : threading.Event
        Set to make the thread stop at its next batch (it ends :meth:`produce` there).
    ready : threading.Event
        Set once the queue is full, or :meth:`produce` has ended: the moment to start the clock.
    """

    def __init__(self, depth: int = READ_AHEAD, name: str = "read-ahead") -> None:
        super().__init__(name=name, daemon=True)
        self.queue: queue.Queue[Batch | BaseException | None] = queue.Queue(depth)
        self.stopping = threading.Event()
        self.ready = threading.Event()

    def produce(self) -> Generator[Batch, None, None]:
        """The batches, in order (a generator; it may run without end). Implemented by subclasses."""
        raise NotImplementedError

    def put(self, item: Batch | BaseException | None) -> bool:
        """Queue ``item``, waiting while the queue is full; False (not queued) once :attr:`stopping` is set."""
        while not self.stopping.is_set():
            try:
                self.queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                self.ready.set()
                continue
        return False

    def run(self) -> None:
        produced = self.produce()
        try:
            for batch in produced:
                if not self.put(batch):
                    return
        except BaseException as e:  # handed to the consuming thread
            self.put(e)
        finally:
            produced.close()
            self.ready.set()
            self.put(None)

    def batches(self, stop: Callable[[], bool] = lambda: False) -> Iterator[Batch]:
        """The queued batches, in order (blocks while the producer is behind; ``stop()`` is polled every
        0.1 s meanwhile and ends them when True)."""
        while True:
            try:
                batch = self.queue.get(timeout=0.1)
            except queue.Empty:
                if stop():
                    return
                continue
            if batch is None:
                return
            if isinstance(batch, BaseException):
                raise batch
            yield batch
