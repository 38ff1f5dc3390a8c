"""``gyroemu view LOG``: serve a gyroemu log to the Foxglove app, with play, pause, seek and speed.

The log's ``cdr`` channels go out as recorded (their ``ros2msg`` schemas, the recorded bytes, each
message's header stamp as its log time, or the record's log time for a type without a header), with
the live view's ``/tf`` and ``/scene`` drawn at a display rate from the log's ``/truth/imu`` and
``/estimate/imu`` (:mod:`gyroemu.pipelines.transport.foxglove_view`; a log's own ``/tf`` and
``/tf_static`` are not forwarded then: the view's take their place). A log with neither (someone
else's bag) keeps its own ``/tf`` and ``/tf_static``, forwarded as recorded
(:func:`~gyroemu.pipelines.transport.foxglove_view.replaced_topics`). A ``cdr`` channel without a
schema (``gyroemu record`` stores a topic it could not type so) is skipped with a warning naming it.

Playback control is foxglove-sdk's (0.30): the server advertises the capabilities ``PlaybackControl``
and ``Time`` and the log's time range (first and last log time), so the app shows its own play/pause
button, speed and a seek bar over the log; its requests reach :meth:`LogPlayer.control` (on the
server's thread: it only records the request, under a lock) and are answered with the
:class:`foxglove.websocket.PlaybackState`. The player (:meth:`LogPlayer.run`, the calling thread)
sends message i at ``anchor_wall + (log_time_i - anchor_log) / speed`` (anchors reset at every play,
seek and change of speed) and broadcasts the current log time with each frame. A seek reads the file
again from its start, skipping what comes before the time sought (one pass of decompression up to it:
a fraction of a second for an hour's log); the end of the log is ``Ended`` until the next seek.

The job runs until SIGINT or SIGTERM (exit status 130 or 143 from the command line), then stops the
server waiting for its clients :data:`~gyroemu.pipelines.transport.foxglove_view.STOP_TIMEOUT_S` at
most (a client that stopped reading held it forever); the file is only ever read.

From Python: ``run_view(ViewLogOptions(path=Path("run.mcap")))``.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from gyroemu.errors import LogError
from gyroemu.pipelines.formats.mcap_log import check_mcap_noting
from gyroemu.pipelines.formats.mcap_records import McapMessage, iter_mcap_batches
from gyroemu.pipelines.formats.messages import starts_with_header
from gyroemu.pipelines.transport.foxglove_view import (
    ViewOptions,
    ViewPublisher,
    check_view_options,
    log_channel_specs,
    log_mounting,
    replaced_topics,
    start_view_server,
    stop_view_server,
    unservable,
)

__all__ = ["ViewLogOptions", "LogPlayer", "run_view"]

_MIN_SPEED, _MAX_SPEED = 0.01, 100.0


@dataclass(frozen=True)
class ViewLogOptions:
    """What ``gyroemu view`` serves and how.

    Attributes
    ----------
    path : Path
        The MCAP log (only ever read).
    view : ViewOptions
        Port (``--port``, default 8765), display rate (``--rate``, default 30 Hz), host.
    speed : float
        Initial playback speed (the app can change it), > 0.
    playing : bool
        Start playing at once (else paused at the start until the app's play).
    """

    path: Path
    view: ViewOptions = field(default_factory=ViewOptions)
    speed: float = 1.0
    playing: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))


class LogPlayer:
    """Plays a log's messages into a :class:`ViewPublisher` on wall-clock deadlines, controlled from the
    app (:meth:`control`) while :meth:`run` plays.

    Parameters
    ----------
    path : Path
    topics : list of str
        The forwarded topics.
    publisher : ViewPublisher
    server : foxglove.WebSocketServer
        For ``broadcast_time`` and ``broadcast_playback_state``.
    time_range : (int, int)
        First and last log time, ns.
    rate_hz : float
        Frames a second of wall time.
    speed : float
    playing : bool

    Attributes
    ----------
    position : int
        The log time of the last message sent (the start before any), ns.
    """

    def __init__(
        self,
        path: Path,
        topics: list[str],
        publisher: ViewPublisher,
        server: Any,
        time_range: tuple[int, int],
        rate_hz: float,
        speed: float = 1.0,
        playing: bool = True,
    ) -> None:
        from foxglove.websocket import PlaybackStatus

        self._status_type = PlaybackStatus
        self.path, self.topics, self.publisher, self.server = path, topics, publisher, server
        self.time_range = time_range
        self.rate_hz = rate_hz
        self.position = time_range[0]
        self._lock = threading.Lock()
        self._speed = _clamp(speed)
        self._status = PlaybackStatus.Playing if playing else PlaybackStatus.Paused
        self._seek: int | None = time_range[0]  # the first pass opens the file
        self._changed = True  # re-anchor the clock
        self._ended_told = False
        self._messages: Iterator[McapMessage] = iter(())

    def control(self, request: Any) -> Any:
        """The server's callback for a ``PlaybackControlRequest``: record it, answer the new state."""
        from foxglove.websocket import PlaybackCommand, PlaybackState

        with self._lock:
            did_seek = request.seek_time is not None
            if did_seek:
                self._seek = min(max(int(request.seek_time), self.time_range[0]), self.time_range[1])
                self.position = self._seek
                if self._status == self._status_type.Ended:
                    self._status = self._status_type.Paused
            self._speed = _clamp(request.playback_speed)
            if request.playback_command == PlaybackCommand.Play and self._status != self._status_type.Ended:
                self._status = self._status_type.Playing
            elif request.playback_command == PlaybackCommand.Pause and self._status != self._status_type.Ended:
                self._status = self._status_type.Paused
            self._changed = True
            return PlaybackState(
                status=self._status,
                current_time=self.position,
                playback_speed=self._speed,
                did_seek=did_seek,
                request_id=request.request_id,
            )

    def _open(self, start: int) -> None:
        def messages() -> Iterator[McapMessage]:
            for batch in iter_mcap_batches(self.path, topics=self.topics):
                if batch[-1].log_time < start:
                    continue
                for m in batch:
                    if m.log_time >= start:
                        yield m

        self._messages = messages()
        self.publisher.clear()

    def run(self, stop: Callable[[], bool] = lambda: False) -> None:
        """Play until ``stop()`` is true (polled at least every 50 ms)."""
        from foxglove.websocket import PlaybackState

        playing, ended = self._status_type.Playing, self._status_type.Ended
        pending: McapMessage | None = None
        anchor_wall = anchor_log = next_frame = 0
        speed = 1.0
        while not stop():
            with self._lock:
                seek, self._seek = self._seek, None
                status, speed, changed, self._changed = self._status, self._speed, self._changed, False
                position = self.position
            if seek is not None:
                self._open(seek)
                pending = None
                next_frame = seek
            if changed:
                anchor_wall, anchor_log = time.monotonic_ns(), position
                self._ended_told = False
            if status != playing:
                if status == ended and not self._ended_told:
                    self._ended_told = True
                    self.server.broadcast_playback_state(
                        PlaybackState(
                            status=ended, current_time=position, playback_speed=speed, did_seek=False, request_id=None
                        )
                    )
                time.sleep(0.02)
                continue
            if pending is None:
                pending = next(self._messages, None)
                if pending is None:
                    with self._lock:
                        if not self._changed:
                            self._status = ended
                            self.position = self.time_range[1]
                    continue
            due = anchor_wall + (pending.log_time - anchor_log) / speed
            wait_ns = due - time.monotonic_ns()
            if wait_ns > 0:
                time.sleep(min(wait_ns * 1e-9, 0.05))
                continue
            self.publisher.message(pending.topic, pending.data, pending.log_time)
            with self._lock:
                if not self._changed:
                    self.position = pending.log_time
            if pending.log_time >= next_frame:
                self.publisher.frame()
                self.server.broadcast_time(pending.log_time)
                next_frame = pending.log_time + round(speed * 1e9 / self.rate_hz)
            pending = None


def _clamp(speed: float) -> float:
    speed = float(speed)
    return _MIN_SPEED if not speed > _MIN_SPEED else min(speed, _MAX_SPEED)


def _time_range(path: Path, topics: list[str]) -> tuple[int, int]:
    """First and last log time of ``topics`` (a pass over the file)."""
    first = last = None
    for batch in iter_mcap_batches(path, topics=topics):
        if first is None:
            first = batch[0].log_time
        last = batch[-1].log_time
    if first is None or last is None:
        raise LogError("no message to view", file=path)
    return first, last


def run_view(
    options: ViewLogOptions,
    *,
    out: TextIO = sys.stdout,
    stop: Callable[[], bool] = lambda: False,
    on_ready: Callable[[int], None] | None = None,
) -> int:
    """Serve ``options.path`` (see the module's notes) until ``stop()`` is true (from the command line:
    until SIGINT/SIGTERM, which raise out of it). ``on_ready(port)`` is called once the server listens.
    Returns 0. Raises :class:`gyroemu.errors.LogError` for a bad log and ``ValueError`` naming the
    argument at fault, before serving."""
    from foxglove.websocket import Capability, ServerListener

    path = options.path
    if not options.speed > 0:
        raise ValueError(f"argument --speed: must be positive, got {options.speed}")
    check_view_options(options.view, "--port", "--rate")
    # validation: LogError naming the file
    log = check_mcap_noting(path, lambda message: print(f"view: warning: {message}", file=out))
    channels = []
    for c in log.channels:
        if c.message_encoding != "cdr":
            continue
        why = unservable(c.schema_name, c.message_encoding)
        if why:
            print(f"view: warning: {path}: skipping topic {c.topic}: {why} (the app cannot decode it)", file=out)
        else:
            channels.append(c)
    replaced = replaced_topics(c.topic for c in channels)
    channels = [c for c in channels if c.topic not in replaced]
    topics = [c.topic for c in channels]
    stamped = [
        c.topic
        for c in channels
        if starts_with_header(
            c.schema_name, c.schema_data.decode("utf-8", "replace") if c.schema_encoding == "ros2msg" else ""
        )
    ]
    time_range = _time_range(path, topics)
    holder: dict[str, LogPlayer] = {}

    class Listener(ServerListener):
        def on_playback_control_request(self, playback_control_request: Any) -> Any:
            player = holder.get("player")
            return None if player is None else player.control(playback_control_request)

    context, server = start_view_server(
        options.view,
        f"gyroemu view {path.name}",
        capabilities=[Capability.PlaybackControl, Capability.Time],
        playback_time_range=time_range,
        server_listener=Listener(),
        port_arg="--port",
    )
    try:
        publisher = ViewPublisher(context, log_channel_specs(channels, topics, stamped), log_mounting(path))
        player = LogPlayer(
            path, topics, publisher, server, time_range, options.view.rate_hz, options.speed, options.playing
        )
        holder["player"] = player
        span = (time_range[1] - time_range[0]) * 1e-9
        host = "localhost" if options.view.host in ("127.0.0.1", "0.0.0.0") else options.view.host
        print(
            f"view: {path}: {len(topics)} topics, {span:.3f} s; open ws://{host}:{server.port} in the Foxglove "
            f"app (Ctrl-C to stop)",
            file=out,
            flush=True,
        )
        if on_ready is not None:
            on_ready(server.port)
        player.run(stop)
    finally:
        stop_view_server(server)  # bounded: a client that stopped reading no longer holds the exit
    return 0
