"""Live streams over Eclipse Zenoh: sessions, key expressions, attachments, a paced publisher, a subscriber.

What goes on the wire (``interface.md``, "Live streams: Eclipse Zenoh")
----------------------------------------------------------------------
- Key expression: ``gyroemu/<device>`` followed by the MCAP topic: ``gyroemu/imu0/imu``,
  ``gyroemu/imu0/truth/imu``, ``gyroemu/imu0/raw/fog``, ... (:func:`topic_to_key`, :func:`key_to_topic`).
- Payload: the CDR bytes of the MCAP message (:mod:`gyroemu.pipelines.formats.messages`), unchanged.
- Attachment: 33 bytes as rmw_zenoh writes them: int64 LE sequence number (from 0, per publisher),
  int64 LE source timestamp (ns since the Unix epoch, taken when the message is sent), one byte 16 (the
  length of what follows), then the 16-byte publisher id (random per publisher, one publisher per
  key expression) (:func:`pack_attachment`, :func:`unpack_attachment`).
- Beside the data, two queryables a recorder asks when it first sees a device:
  ``gyroemu/<device>/config`` (``gyroemu stream``: the device's resolved config, :class:`ConfigAnnouncer`)
  and ``gyroemu/<device>/@types`` (``gyroemu replay``: each key's message type and schema text, as the
  replayed file's channel states it, :class:`TypesAnnouncer`; a verbatim ``@`` chunk, which no
  subscriber's wildcard matches).

The default session (no --connect/--listen/--mode/--config)
-----------------------------------------------------------
Every gyroemu process opens a *peer* that

1. tries to listen on ``tcp/127.0.0.1:7447`` (the one documented loopback endpoint) -- the first
   gyroemu process on the machine gets it, the others fail to bind and carry on
   (``listen.exit_on_failure = false``);
2. also listens on an ephemeral loopback port ``tcp/127.0.0.1:0``, so that every peer is reachable;
3. connects to ``tcp/127.0.0.1:7447`` (``connect.exit_on_failure = false``, retried), i.e. to whichever
   gyroemu process holds it;
4. has *gossip* scouting on and multicast scouting off: the holder of 7447 tells each newcomer the
   ephemeral locators of the others, and the peers connect to each other directly (zenoh peers do not
   route for one another, so a full mesh is needed).

So gyroemu processes find each other in any start order with nothing else started first, nothing
leaves the loopback interface, and a plain zenoh program reaches the streams by connecting to
``tcp/127.0.0.1:7447`` (as a peer it is then linked to every gyroemu peer by gossip). Any of
``--connect``, ``--listen``, ``--mode`` or ``--config FILE.json5`` replaces this default: the config
file (if any) is loaded as is, then the flags override its ``connect/endpoints``, ``listen/endpoints``
and ``mode``; without a config file multicast scouting stays off (gossip on), so a deployment is what
the flags say, e.g. ``--connect tcp/router-host:7447`` to go through a router.

Pacing
------
:class:`PacedPublisher` sends on absolute deadlines (``t0 + k / rate``, or each message's own), never a
sleep per sample, so its error does not accumulate. How it waits for a deadline is a :class:`Timing`:
:data:`PRECISE` (the default: timer slack 1 ns, sleep to 300 us before the deadline then spin on the
clock, a 50 us GIL switch interval and the garbage collector paused while the run lasts; its notes
give the measured reasons) or :data:`SLEEP_ONLY` (the former behaviour, the benchmarks' baseline).
ROS 2 key expressions and liveliness tokens (``--ros2``) are :mod:`gyroemu.pipelines.formats.ros2_keys`'.

The live jobs
-------------
Every live job (stream, record, replay, router) takes its session as a :class:`SessionOptions`, and a
publishing job (stream, replay) its pacing as a :class:`PacingOptions`. Each runs its live stretch in
:func:`live_session`, which holds their one teardown: publisher undeclared, ROS 2 node closed,
session closed, signal handlers restored.

Sources: zenoh-python 1.x API (``zenoh.Config.insert_json5``, ``Session.declare_publisher``,
``CongestionControl.BLOCK``, ``handlers.FifoChannel``); the zenoh DEFAULT_CONFIG.json5 (listen, connect,
scouting keys); rmw_zenoh design notes (attachment layout).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import gc
import json
import math
import os
import re
import secrets
import signal
import struct
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, cast, overload

import numpy as np
import zenoh
from numpy.typing import NDArray

from gyroemu.errors import ConfigError

__all__ = [
    "DEFAULT_ENDPOINT",
    "LiveOptionError",
    "check_endpoint",
    "PROTOCOLS",
    "check_key_expr",
    "check_pacing_options",
    "MAX_WAIT_S",
    "KEY_ROOT",
    "ATTACHMENT_SIZE",
    "SessionOptions",
    "PacingOptions",
    "session_config",
    "router_config",
    "open_session",
    "port_is_free",
    "zenoh_answers",
    "connect_warning",
    "config_key",
    "ConfigAnnouncer",
    "StandingAnswer",
    "CONFIG_TOPIC",
    "config_fields",
    "TYPES_CHUNK",
    "types_key",
    "TopicType",
    "types_payload",
    "topic_types",
    "TypesAnnouncer",
    "LiveSession",
    "live_session",
    "topic_to_key",
    "key_to_topic",
    "pack_attachment",
    "unpack_attachment",
    "PacedPublisher",
    "PacingReport",
    "Timing",
    "PRECISE",
    "SLEEP_ONLY",
    "subscribe",
    "drain",
    "header_stamp_ns",
    "stop_on_signals",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
KEY_ROOT = "gyroemu"
_ATTACHMENT = struct.Struct("<qqB16s")
ATTACHMENT_SIZE = _ATTACHMENT.size  # 33
assert ATTACHMENT_SIZE == 33


# --------------------------------------------------------------------------------------------------
# Sessions.


def _zenoh_message(error: Exception) -> str:
    """zenoh's error text without its Rust source locations."""
    return re.sub(r" at /\S+\.rs:\d+\.?", "", str(error))


def _insert(config: zenoh.Config, key: str, value: object) -> None:
    config.insert_json5(key, json.dumps(value))


def _config_file_message(error: Exception) -> str:
    """zenoh's refusal of a JSON5 config file on one line: ``line L, column C: what`` from its parser's
    report (several lines: the source line, a caret, ``= what``) or its serde message, else its lines joined."""
    text = _zenoh_message(error).strip()
    parsed = re.search(r"-->\s*(\d+):(\d+).*\n\s*=\s*(.+)\Z", text, re.DOTALL)
    if parsed is not None:
        return f"line {parsed.group(1)}, column {parsed.group(2)}: {' '.join(parsed.group(3).split())}"
    serde = re.fullmatch(
        r'(?:JSON error: )?Message \{ msg: "(.*)", location: Some\(Location \{ line: (\d+), column: (\d+) \}\) \}',
        text,
        re.DOTALL,
    )
    if serde is not None:
        what = serde.group(1).replace('\\"', '"')
        return f"line {serde.group(2)}, column {serde.group(3)}: {' '.join(what.split())}"
    return " ".join(text.split())


class LiveOptionError(ConfigError):
    """A live job's bad session, key or pacing option, found before any work (the message names the argument)."""


_ENDPOINT_FORM = "an endpoint looks like PROTOCOL/ADDRESS, e.g. tcp/HOST:PORT (tcp/192.168.1.10:7447, tcp/[::1]:7447)"
_PORTED = ("tcp", "udp")  # protocols whose address is HOST:PORT
PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream")
"""The link protocols the eclipse-zenoh Python package is built with (1.x; its others, unixpipe, serial
and vsock, are not: zenoh refuses them only when the session opens, "Unicast not supported")."""


def check_endpoint(endpoint: str, argument: str) -> None:
    """:class:`LiveOptionError` naming ``argument`` (``--connect``, ``--listen``) unless zenoh's config
    takes ``endpoint`` (``PROTOCOL/ADDRESS[?METADATA][#CONFIG]``) and, for tcp and udp, its address ends
    in ``:PORT`` with PORT in 0..65535. No session is opened."""
    try:
        _insert(zenoh.Config(), "connect/endpoints", [endpoint])
    except Exception:  # zenoh.ZError: Json5Err(Message { msg: "Endpoints must be of the form ...", ... })
        raise LiveOptionError(f"argument {argument}: {endpoint!r} is not a zenoh endpoint: {_ENDPOINT_FORM}") from None
    protocol, _, rest = endpoint.partition("/")
    if protocol not in PROTOCOLS:
        raise LiveOptionError(
            f"argument {argument}: {endpoint!r}: no zenoh protocol {protocol!r} (zenoh here speaks "
            f"{', '.join(PROTOCOLS)}): {_ENDPOINT_FORM}"
        )
    if protocol in _PORTED:
        address = re.split(r"[?#]", rest, maxsplit=1)[0]
        port = re.fullmatch(r".*:(\d{1,5})", address)
        if port is None or int(port.group(1)) > 65535:
            raise LiveOptionError(
                f"argument {argument}: {endpoint!r} has no port 0..65535 after its host: {_ENDPOINT_FORM}"
            )


def session_config(
    connect: Sequence[str] | None = None,
    listen: Sequence[str] | None = None,
    mode: str | None = None,
    config_file: str | os.PathLike[str] | None = None,
) -> zenoh.Config:
    """The zenoh configuration of a gyroemu process (see the module's notes for the default session).

    Raises ``ValueError`` naming the argument at fault (mode, config file, endpoints).
    """
    if mode is not None and mode not in ("peer", "client", "router"):
        raise ValueError(f"argument --mode: expected peer, client or router, got {mode!r}")
    if config_file is None and not connect and not listen and mode is None:
        config = zenoh.Config()
        _insert(config, "mode", "peer")
        _insert(config, "listen/endpoints", [DEFAULT_ENDPOINT, "tcp/127.0.0.1:0"])
        _insert(config, "listen/exit_on_failure", False)
        _insert(config, "connect/endpoints", [DEFAULT_ENDPOINT])
        _insert(config, "connect/exit_on_failure", False)
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "scouting/gossip/enabled", True)
        return config
    if config_file is not None:
        path = Path(config_file)
        if not path.is_file():
            raise ValueError(f"argument --config: {path}: no such file")
        try:
            config = zenoh.Config.from_file(str(path))
        except Exception as e:  # zenoh.ZError and friends
            reason = _config_file_message(e)
            raise ValueError(f"argument --config: {path}: not a zenoh JSON5 config: {reason}") from None
    else:
        config = zenoh.Config()
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "scouting/gossip/enabled", True)
    for argument, endpoints in (("--connect", connect), ("--listen", listen)):
        for endpoint in endpoints or ():
            check_endpoint(endpoint, argument)  # LiveOptionError naming the option, not zenoh's Json5Err
    try:
        if mode is not None:
            _insert(config, "mode", mode)
        if connect:
            _insert(config, "connect/endpoints", list(connect))
        if listen:
            _insert(config, "listen/endpoints", list(listen))
    except Exception as e:
        raise ValueError(f"argument --connect/--listen/--mode: {_zenoh_message(e)}") from None
    return config


def router_config(
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    config_file: str | os.PathLike[str] | None = None,
) -> zenoh.Config:
    """A router's configuration: listens on ``listen``, else where ``config_file`` says, else (neither
    given, or the file leaves zenoh's default) on ``tcp/0.0.0.0:7447``."""
    config = session_config(connect=connect, listen=list(listen or []), mode="router", config_file=config_file)
    if not listen and _config_value(config, "listen/endpoints") == _config_value(zenoh.Config(), "listen/endpoints"):
        _insert(config, "listen/endpoints", ["tcp/0.0.0.0:7447"])
    return config


def _config_value(config: zenoh.Config, key: str) -> Any:
    """A value of ``config`` (None when unset or unreadable)."""
    try:
        return json.loads(config.get_json(key))
    except Exception:
        return None


def _tcp_address(endpoint: str) -> tuple[str, int] | None:
    """``(host, port)`` of a ``tcp/host:port`` endpoint (its ``#...`` config dropped); None for others."""
    match = re.fullmatch(r"tcp/\[?([^\]#]*?)\]?:(\d+)(#.*)?", endpoint)
    return (match.group(1), int(match.group(2))) if match else None


def _loopback(endpoint: str) -> str:
    """A listen endpoint as this machine connects to it: ``0.0.0.0`` and ``[::]`` as loopback."""
    return endpoint.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")


def port_is_free(endpoint: str) -> bool | None:
    """Whether a ``tcp/host:port`` endpoint could be listened on now (None: not a TCP endpoint, or not
    an address of this machine): a plain socket binds it and lets go at once."""
    address = _tcp_address(endpoint)
    if address is None or address[1] == 0:
        return None
    import socket

    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as zenoh binds: TIME_WAIT is no owner
        try:
            s.bind(address)
        except OSError as e:
            return False if e.errno == errno.EADDRINUSE else None
    return True


def zenoh_answers(endpoint: str, timeout_s: float = 1.0) -> bool:
    """Whether a zenoh router or peer answers at ``endpoint``: a client session tries to open there,
    giving up after ``timeout_s`` (a program that accepts the connection but speaks no zenoh never
    completes the handshake)."""
    config = zenoh.Config()
    try:
        _insert(config, "mode", "client")
        _insert(config, "connect/endpoints", [endpoint])
        _insert(config, "scouting/multicast/enabled", False)
        _insert(config, "transport/unicast/open_timeout", max(1, round(timeout_s * 1000)))
        _insert(config, "connect/timeout_ms", max(1, round(timeout_s * 1000)))
        probe = zenoh.open(config)
    except Exception:
        return False
    with contextlib.suppress(Exception):
        probe.close()
    return True


def _taken(endpoint: str, detail: str) -> str:
    """The message of a listen endpoint another process holds: a zenoh one or another program."""
    if zenoh_answers(endpoint):
        return (
            f"argument --listen: {endpoint} is taken by a zenoh process (a router, or another gyroemu "
            f"process): join it with --connect {endpoint}, or name a free endpoint with --listen"
        )
    return f"argument --listen: {endpoint} is taken by another program (not a zenoh router): {detail}"


def _open_error(error: Exception, listen: Sequence[str], connect: Sequence[str], mode: str) -> str:
    """zenoh's refusal to open a session as a message naming the argument at fault."""
    text = _zenoh_message(error)
    if "Address already in use" in text or "Can not create a new TCP listener" in text:
        bound = re.search(r"bound to (\S+?):? \[", text)
        endpoint = bound.group(1) if bound else (listen[0] if len(listen) == 1 else ", ".join(listen))
        detail = re.search(r"\[(?:[^\]]*: )?([^\]]*)\]", text)
        return _taken(endpoint, detail.group(1) if detail else text)
    if "Unable to connect to any of" in text:
        return (
            f"argument --connect: no zenoh router answers at {', '.join(connect) or 'the configured endpoints'} "
            f"(a {mode} cannot start without one): {text}"
        )
    unsupported = re.search(r"not supported for (\S+) protocol", text)
    if unsupported is not None:  # an endpoint of the --config file: check_endpoint refused the options' own
        return (
            f"argument --config: an endpoint of no zenoh protocol {unsupported.group(1)!r} "
            f"(zenoh here speaks {', '.join(PROTOCOLS)}): {text}"
        )
    return f"argument --connect/--listen/--config: cannot open the zenoh session: {text}"


def open_session(config: zenoh.Config) -> zenoh.Session:
    """Open a session; zenoh's errors become ``ValueError`` naming the argument at fault.

    - A listen endpoint another process holds (zenoh's "Address already in use"): ``argument --listen:
      <endpoint> is taken by another program (not a zenoh router): ...``, or, when a zenoh session
      answers there (:func:`zenoh_answers`), a message that says to ``--connect`` to it instead.
    - The default session (``tcp/127.0.0.1:7447`` listened on without ``exit_on_failure``) checks that
      endpoint first: held by a program that speaks no zenoh, gyroemu processes could not meet there, so
      it is the same ``--listen`` error (held by a zenoh process, it is the normal case: carry on).
    - A client that reaches no router (zenoh's "Unable to connect to any of"): ``argument --connect:
      no zenoh router answers at ...``. A peer or router does not fail there (zenoh keeps trying in the
      background): :func:`connect_warning` tells after the session is open.
    """
    listen = [str(e) for e in _config_value(config, "listen/endpoints") or []]
    connect = [str(e) for e in _config_value(config, "connect/endpoints") or []]
    mode = str(_config_value(config, "mode") or "peer")
    if DEFAULT_ENDPOINT in listen and _config_value(config, "listen/exit_on_failure") is False:
        if port_is_free(DEFAULT_ENDPOINT) is False and not zenoh_answers(DEFAULT_ENDPOINT):
            raise ValueError(
                f"argument --listen: {DEFAULT_ENDPOINT} (the default session's endpoint) is taken by another "
                "program (not a zenoh router): gyroemu processes cannot meet there; free it, or name the "
                "endpoints with --listen/--connect"
            )
    try:
        return zenoh.open(config)
    except Exception as e:
        raise ValueError(_open_error(e, listen, connect, mode)) from None


def connect_warning(session: zenoh.Session, connect: Sequence[str]) -> str | None:
    """After a peer or router opened with ``--connect`` endpoints: a warning when none answered (no
    router or peer linked: ``session.info`` lists none), else None. zenoh's peers and routers wait up to
    its connect timeout on open and then keep retrying in the background, so this is a warning: what
    starts later at those endpoints is still joined."""
    if not connect:
        return None
    try:
        linked = list(session.info.routers_zid()) + list(session.info.peers_zid())
    except Exception:
        return None
    if linked:
        return None
    return (
        f"warning: nothing answers at --connect {', '.join(connect)} yet (zenoh keeps trying in the "
        "background; check the endpoint if no data comes)"
    )


@dataclass(frozen=True)
class SessionOptions:
    """How a live job (stream, record, replay, router) joins zenoh: ``--connect``, ``--listen``, ``--mode``,
    ``--config``, ``--ros2``, ``--domain``. All defaults: the default session of the module's notes.

    Attributes
    ----------
    connect : tuple of str
        zenoh endpoints to connect to, e.g. ``tcp/host:7447``; empty: none given.
    listen : tuple of str
        zenoh endpoints to listen on, e.g. ``tcp/0.0.0.0:7447``; empty: none given.
    mode : str or None
        zenoh session mode, ``"peer"`` or ``"client"``; None: not given (a peer). A router's is always
        ``"router"``.
    config_file : Path or None
        A zenoh JSON5 config file, loaded as is; the three fields above then override its
        ``connect/endpoints``, ``listen/endpoints`` and ``mode``.
    ros2 : bool
        ROS 2 mode: rmw_zenoh's key expressions and the liveliness tokens of a ROS 2 node
        (:mod:`gyroemu.pipelines.formats.ros2_keys`) instead of ``gyroemu/<device>/<topic>``.
    domain : int or None
        The ROS 2 domain of ``ros2`` (0..232); None: ``$ROS_DOMAIN_ID``, else 0.

    Lists are kept as tuples and a config file name as a :class:`~pathlib.Path`.
    """

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str | None = None
    config_file: Path | None = None
    ros2: bool = False
    domain: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "connect", tuple(self.connect or ()))
        object.__setattr__(self, "listen", tuple(self.listen or ()))
        if self.config_file is not None:
            object.__setattr__(self, "config_file", Path(self.config_file))

    def config(self) -> zenoh.Config:
        """The session's zenoh configuration (:func:`session_config`; ``ValueError`` names the argument)."""
        return session_config(connect=self.connect, listen=self.listen, mode=self.mode, config_file=self.config_file)

    def beside_config(self) -> zenoh.Config:
        """The configuration of a second session of this process beside one opened with :meth:`config` (a
        live filter next to its stream): with ``listen`` endpoints it connects to them (an unspecified
        address as loopback) and listens only on an ephemeral loopback port, so the two never contend for
        a port (the second one's --listen was refused as taken by the first); otherwise :meth:`config`."""
        if not self.listen:
            return self.config()
        reachable = [_loopback(e) for e in self.listen if (_tcp_address(e) or ("", 1))[1] != 0]  # not port 0
        return session_config(
            connect=[*reachable, *self.connect],
            listen=["tcp/127.0.0.1:0"],
            mode=self.mode,
            config_file=self.config_file,
        )

    def router_config(self) -> zenoh.Config:
        """A router's configuration (:func:`router_config`): ``mode`` does not apply."""
        return router_config(listen=self.listen, connect=self.connect, config_file=self.config_file)


@contextlib.contextmanager
def stop_on_signals() -> Iterator[list[int]]:
    """For the block, SIGINT and SIGTERM append their numbers to the list it yields instead of ending the
    process (the command's loops poll it to stop cleanly); the previous handlers are back after the block."""
    stopping: list[int] = []
    previous = {s: signal.signal(s, lambda n, _: stopping.append(n)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stopping
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


# --------------------------------------------------------------------------------------------------
# Key expressions and attachments.


def topic_to_key(device: str, topic: str) -> str:
    """``gyroemu/<device>`` + topic: ``("imu0", "/imu") -> "gyroemu/imu0/imu"``."""
    if not device or "/" in device or any(c in device for c in "*$?#"):
        raise ValueError(f"device name {device!r}: one key chunk without '/', '*', '$', '?' or '#'")
    if not topic.startswith("/") or topic.endswith("/") or "//" in topic:
        raise ValueError(f"topic {topic!r} must look like /a/b")
    return f"{KEY_ROOT}/{device}{topic}"


def check_key_expr(key: str, argument: str = "--key") -> str:
    """``key`` if zenoh takes it as a key expression (as a subscriber would declare it: canon form, no
    empty chunk, no ``#`` or ``?``), else :class:`LiveOptionError` naming ``argument``, with the canon
    form when zenoh knows one (``a/**/**`` -> ``a/**``). No session is opened."""
    if not key:
        raise LiveOptionError(
            f"argument {argument}: empty: name a key expression, e.g. {KEY_ROOT}/** or {KEY_ROOT}/imu0/*"
        )
    try:
        zenoh.KeyExpr(key)
    except Exception as e:  # zenoh.ZError
        reason = _zenoh_message(e).rstrip(".")
        try:
            canon = str(zenoh.KeyExpr.autocanonize(key))
        except Exception:
            canon = None
        hint = f" (write {canon})" if canon else f" (e.g. {KEY_ROOT}/** or {KEY_ROOT}/imu0/*)"
        raise LiveOptionError(f"argument {argument}: {reason}{hint}") from None
    return key


def key_to_topic(key: str) -> tuple[str, str]:
    """``"gyroemu/imu0/raw/fog" -> ("imu0", "/raw/fog")``; ``ValueError`` for other keys."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != KEY_ROOT or not parts[1]:
        raise ValueError(f"key expression {key!r} is not gyroemu/<device>/<topic>")
    return parts[1], "/" + "/".join(parts[2:])


CONFIG_TOPIC = "/config"


def config_key(device: str) -> str:
    """``gyroemu/<device>/config``: where a stream announces its device's resolved config."""
    return topic_to_key(device, CONFIG_TOPIC)


def config_fields(payload: bytes, attachment: bytes | None = None) -> dict[str, str]:
    """The ``gyroemu`` metadata fields a config sample or reply carries (:class:`ConfigAnnouncer`).

    Parameters
    ----------
    payload : bytes
        The device's resolved config as TOML text (UTF-8).
    attachment : bytes or None
        A JSON object with ``seed`` and ``scenario`` (the scenario's TOML), strings; None: neither.

    Returns
    -------
    dict of str to str
        ``device`` and, when the attachment gives them, ``seed`` and ``scenario``.

    Raises
    ------
    ValueError
        The payload is not UTF-8 TOML.
    """
    import tomllib

    device = bytes(payload).decode("utf-8")
    tomllib.loads(device)  # TOMLDecodeError is a ValueError
    fields = {"device": device}
    if attachment:
        with contextlib.suppress(ValueError):
            extra = json.loads(bytes(attachment))
            if isinstance(extra, dict):
                fields.update({k: extra[k] for k in ("seed", "scenario") if isinstance(extra.get(k), str)})
    return fields


class StandingAnswer:
    """A queryable on ``key`` that answers every ``get`` with the same ``payload`` (and ``attachment``)
    for as long as the session lives: what a late joiner asks for (:class:`ConfigAnnouncer`,
    :class:`TypesAnnouncer`). ``queries`` counts the answers given; :meth:`close` undeclares it."""

    def __init__(self, session: zenoh.Session, key: str, payload: bytes, attachment: bytes | None = None) -> None:
        self.key = key
        self.payload = payload
        self.attachment = attachment
        self.queries = 0
        self._queryable = session.declare_queryable(key, self._reply)

    def _reply(self, query: zenoh.Query) -> None:
        try:
            if self.attachment is None:
                query.reply(self.key, self.payload)
            else:
                query.reply(self.key, self.payload, attachment=self.attachment)
            self.queries += 1
        except Exception:  # a query gone (timed out) by now: nothing to answer
            pass

    def close(self) -> None:
        """Undeclare the queryable."""
        with contextlib.suppress(Exception):
            self._queryable.undeclare()


class ConfigAnnouncer(StandingAnswer):
    """Announces a device's resolved config on ``gyroemu/<device>/config`` (:func:`config_key`).

    A queryable on the key answers every ``get`` for as long as the session lives, so a recorder that
    starts (or sees the device) at any time asks for it and gets it; :meth:`announce` also puts it once
    for plain subscribers. The payload is the device's TOML (``Device.to_toml()``), the attachment a JSON
    object ``{"seed": "0", "scenario": "<the scenario's TOML>"}`` (:func:`config_fields` reads both).

    Parameters
    ----------
    session : zenoh.Session
        The stream's session.
    device_name : str
        The device's name on the wire.
    device_toml : str
        The device's resolved config as TOML.
    seed : int or None
        The device's seed.
    scenario_toml : str
        The scenario's config as TOML ("" when not known).
    """

    def __init__(
        self, session: zenoh.Session, device_name: str, device_toml: str, seed: int | None, scenario_toml: str = ""
    ) -> None:
        extra = {"seed": "" if seed is None else str(int(seed)), "scenario": scenario_toml}
        super().__init__(session, config_key(device_name), device_toml.encode("utf-8"), json.dumps(extra).encode())
        self._session = session

    def announce(self) -> None:
        """Put the config once on the key (for subscribers; recorders ask the queryable)."""
        self._session.put(self.key, self.payload, attachment=self.attachment)


TYPES_CHUNK = "@types"
"""The last chunk of :func:`types_key`: a verbatim chunk (``@...``), which no wildcard matches."""


def types_key(device: str) -> str:
    """``gyroemu/<device>/@types``: where ``gyroemu replay`` answers with the message types of its
    device's keys (:class:`TypesAnnouncer`). A verbatim chunk: a subscriber of ``gyroemu/**`` receives
    nothing from it, and no topic's key is it (a ROS 2 name has no ``@``)."""
    return topic_to_key(device, "/" + TYPES_CHUNK)


@dataclass(frozen=True)
class TopicType:
    """A topic's message type as a file's channel states it: the schema's name (``sensor_msgs/msg/Imu``),
    encoding (``ros2msg``) and text."""

    name: str
    encoding: str
    schema: str


def types_payload(types: Mapping[str, TopicType]) -> bytes:
    """The JSON of :class:`TypesAnnouncer`'s replies: ``{"<key expr>": {"type": ..., "encoding": ...,
    "schema": ...}, ...}``, UTF-8."""
    body = {key: {"type": t.name, "encoding": t.encoding, "schema": t.schema} for key, t in types.items()}
    return json.dumps(body, sort_keys=True).encode("utf-8")


def topic_types(payload: bytes) -> dict[str, TopicType]:
    """The key expressions and their types of a :func:`types_payload` (``ValueError`` when it is not one;
    entries without a type name are left out)."""
    try:
        body = json.loads(bytes(payload).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"not the JSON of a types reply: {e}") from None
    if not isinstance(body, dict):
        raise ValueError("a types reply is a JSON object")
    out = {}
    for key, entry in body.items():
        if not isinstance(entry, dict):
            raise ValueError(f"types reply: key {key!r}: not an object")
        name, encoding, schema = entry.get("type"), entry.get("encoding"), entry.get("schema")
        if not (isinstance(name, str) and isinstance(encoding, str) and isinstance(schema, str)):
            raise ValueError(f"types reply: key {key!r}: type, encoding and schema must be strings")
        if name:
            out[key] = TopicType(name, encoding, schema)
    return out


class TypesAnnouncer(StandingAnswer):
    """Answers ``get`` on ``gyroemu/<device>/@types`` (:func:`types_key`) with the message types of the
    device's keys (:func:`types_payload`), for as long as the session lives.

    A key carries a topic's bytes, not its type: a recorder types gyroemu's own topics by their role
    (:func:`gyroemu.pipelines.formats.channels.topic_message_type`), but a replayed file's other topics
    (``/robot1/imu/data_raw``) only the file knows. ``gyroemu replay`` declares one per device before it
    publishes, and ``gyroemu record`` asks when it first sees the device, so a recording's channel gets
    the original's schema, whenever the recorder started. A queryable, not a put: nothing goes to the
    data keys' subscribers, and a late recorder still gets its answer.

    Parameters
    ----------
    session : zenoh.Session
        The publisher's session.
    device_name : str
        The device's name on the wire.
    types : mapping of str to TopicType
        Key expression (as published) -> its type.
    """

    def __init__(self, session: zenoh.Session, device_name: str, types: Mapping[str, TopicType]) -> None:
        super().__init__(session, types_key(device_name), types_payload(types))


def pack_attachment(sequence: int, source_timestamp_ns: int, publisher_id: bytes) -> bytes:
    """The 33-byte rmw_zenoh attachment."""
    if len(publisher_id) != 16:
        raise ValueError("publisher id must be 16 bytes")
    return _ATTACHMENT.pack(sequence, source_timestamp_ns, 16, publisher_id)


def unpack_attachment(data: bytes | bytearray | memoryview) -> tuple[int, int, bytes]:
    """``(sequence, source_timestamp_ns, publisher_id)`` of a 33-byte attachment (``ValueError`` otherwise)."""
    data = bytes(data)
    if len(data) != ATTACHMENT_SIZE:
        raise ValueError(f"attachment of {len(data)} bytes, expected {ATTACHMENT_SIZE}")
    sequence: int
    stamp: int
    gid: bytes
    sequence, stamp, length, gid = _ATTACHMENT.unpack(data)
    if length != 16:
        raise ValueError(f"attachment publisher-id length byte is {length}, expected 16")
    return sequence, stamp, gid


def header_stamp_ns(payload: bytes) -> int:
    """``header.stamp`` (ns) of a CDR message: int32 sec and uint32 nanosec after the 4-byte encapsulation."""
    sec: int
    nanosec: int
    sec, nanosec = struct.unpack_from("<iI", payload, 4)
    return sec * 1_000_000_000 + nanosec


# --------------------------------------------------------------------------------------------------
# Publishing.


@dataclass
class PacingReport:
    """How late each sample went out relative to its deadline (seconds): ``t0 + k / rate``
    (:meth:`PacedPublisher.run`) or the message's own (:meth:`PacedPublisher.run_schedule`)."""

    lateness_s: NDArray[np.float64]
    messages: int
    elapsed_s: float

    def percentile(self, q: float) -> float:
        return float(np.percentile(self.lateness_s, q)) if len(self.lateness_s) else 0.0

    def summary(self, against: str = "t0 + k/rate") -> str:
        if not len(self.lateness_s):
            return "pacing: no samples"
        return (
            f"pacing: {len(self.lateness_s)} samples, {self.messages} messages in {self.elapsed_s:.3f} s; "
            f"lateness vs {against}: p50 {self.percentile(50) * 1e3:.3f} ms, "
            f"p99 {self.percentile(99) * 1e3:.3f} ms, max {self.lateness_s.max() * 1e3:.3f} ms"
        )


@dataclass(frozen=True)
class Timing:
    """How a :class:`PacedPublisher` waits for its deadlines (see :data:`PRECISE` for why).

    Attributes
    ----------
    spin_s : float
        Stop sleeping this long (s) before a deadline and spin on the monotonic clock for the rest;
        0: sleep to the deadline itself.
    switch_interval_s : float or None
        Python's GIL switch interval (s) while the run lasts (``sys.setswitchinterval``): how long the
        publisher, woken up, waits for another thread to hand the GIL over. None: leave it (Python's
        default is 5 ms).
    quiet_gc : bool
        Freeze the objects alive when the run starts out of the garbage collector's reach and turn
        automatic collection off until the run ends (then collect once).
    timer_slack_ns : int or None
        Linux timer slack (ns) of the publishing thread while the run lasts (``prctl``); None: leave
        it (the kernel's default is 50 us).
    """

    spin_s: float = 300e-6
    switch_interval_s: float | None = 50e-6
    quiet_gc: bool = True
    timer_slack_ns: int | None = 1


PRECISE = Timing()
"""The default. Measured on the 2-core development machine (``tests/benchmarks/bench_replay.py``),
a publisher that simply sleeps to each deadline is late by

- ~75 us typically: ``time.sleep`` wakes up after the deadline plus the thread's timer slack (50 us by
  default) plus the scheduler's wake-up latency. A slack of 1 ns and a spin over the last 300 us on the
  clock remove that: the thread is awake and running when the deadline comes (a spin of 30 % of a
  core at 1 kHz, 0 between deadlines further apart than that).
- ~1 ms at the 99th percentile, up to 5 ms: the GIL. Another Python thread of the process (replay's
  read-ahead, decoding a chunk) holds it when the publisher wakes, and gives it up only when the
  switch interval (5 ms by default) expires. At 50 us the publisher, woken 300 us before its
  deadline, has the GIL back well before it. (The other thread can still take it back for 50 us during
  the spin. A longer interval for the spin alone would not stop that: the other thread, forced out
  as the publisher wakes, asks again at once, before the publisher could lengthen the interval, takes
  the GIL back in the spin, and the publisher would then wait out the long interval.)
- up to 0.3 s, now and then: a full garbage collection, run by whichever thread allocates (replay's
  reader allocates a tuple per message), walking every object of the process while holding the GIL.
  The hot path makes no reference cycles, so the collector is stopped for the run (the objects of the
  set-up frozen out of its reach) and run once at the end.

What remains is the machine's: a bare loop of these waits, with no other thread and no zenoh, still
sees stalls of 1-4 ms a few times a second on this VM (every 512 ms at times), and under load from
other processes (a load average above the core count) the scheduler's time slices of several ms
dominate every figure; nothing inside the process removes either.
"""

SLEEP_ONLY = Timing(spin_s=0.0, switch_interval_s=None, quiet_gc=False, timer_slack_ns=None)
"""Sleep to each deadline and change nothing in the process: gyroemu's pacing before :data:`PRECISE`
(the baseline of the pacing benchmark)."""


@dataclass(frozen=True)
class PacingOptions:
    """How a publishing job (stream, replay) starts, paces and ends its run.

    Attributes
    ----------
    wait_s : float
        Before the clock starts, wait up to this many seconds until every key has a subscriber
        (``--wait``; when it runs out the job publishes anyway); 0: do not wait.
    timing : Timing
        How the publisher waits for each deadline (:data:`PRECISE`, or :data:`SLEEP_ONLY`).
    linger_s : float
        Seconds to wait after the last message before the session closes, so that queued messages
        reach their subscribers.
    """

    wait_s: float = 10.0
    timing: Timing = PRECISE
    linger_s: float = 0.5


# The longest --wait: a day. The wait is for the subscribers of a run about to start (a recorder or a
# ROS 2 node started by hand), after which the job publishes anyway; much longer is a slip or a try at
# "forever" (which --wait cannot mean), and left a job hanging with nothing said (--wait 1e300 never ran
# out; inf and nan were taken too). A day still covers a stream left to wait overnight for its recorder.
MAX_WAIT_S = 86400.0


def check_pacing_options(options: PacingOptions, wait_arg: str = "--wait") -> None:
    """:class:`LiveOptionError` naming ``wait_arg`` unless ``options.wait_s`` is a finite number of seconds
    from 0 to :data:`MAX_WAIT_S`; done before any work."""
    wait = options.wait_s
    if (
        isinstance(wait, bool)
        or not isinstance(wait, (int, float))
        or not math.isfinite(wait)
        or not 0 <= wait <= MAX_WAIT_S
    ):
        raise LiveOptionError(
            f"argument {wait_arg}: must be a number of seconds from 0 (no wait) to {MAX_WAIT_S:g} (a day), got {wait}"
        )


_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30


def _timer_slack(ns: int | None) -> int | None:
    """Set the calling thread's timer slack (Linux); returns the previous value, None where unsupported."""
    if ns is None or not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        previous: int = libc.prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
        if previous < 0 or libc.prctl(_PR_SET_TIMERSLACK, int(ns), 0, 0, 0) != 0:
            return None
        return previous
    except (OSError, AttributeError):
        return None


@contextlib.contextmanager
def hot_loop(timing: Timing) -> Iterator[None]:
    """Apply ``timing``'s process settings (switch interval, collector, timer slack) for a block, and
    restore them after it, whatever happens."""
    interval = sys.getswitchinterval()
    gc_was_enabled = gc.isenabled()
    slack = None
    try:
        if timing.switch_interval_s is not None:
            sys.setswitchinterval(timing.switch_interval_s)
        if timing.quiet_gc:
            gc.collect()
            gc.freeze()
            gc.disable()
        slack = _timer_slack(timing.timer_slack_ns)
        yield
    finally:
        if slack is not None:
            _timer_slack(slack)
        if timing.quiet_gc:
            gc.unfreeze()
            if gc_was_enabled:
                gc.enable()
            gc.collect()
        sys.setswitchinterval(interval)


@overload
def _wait_until(deadline_ns: int, spin_ns: int, stop: None = None, poll_ns: int = ...) -> int: ...
@overload
def _wait_until(
    deadline_ns: int, spin_ns: int, stop: Callable[[], object] | None, poll_ns: int = ...
) -> int | None: ...
def _wait_until(
    deadline_ns: int, spin_ns: int, stop: Callable[[], object] | None = None, poll_ns: int = 100_000_000
) -> int | None:
    """Return the monotonic time (ns) at or after ``deadline_ns``: sleep until ``spin_ns`` before it,
    then spin on the clock. ``stop()`` is polled at least every ``poll_ns`` while sleeping; True
    returns None at once."""
    clock = time.monotonic_ns
    now = clock()
    wake = deadline_ns - spin_ns
    while now < wake:
        if stop is not None and stop():
            return None
        time.sleep(min(wake - now, poll_ns) * 1e-9)
        now = clock()
    while now < deadline_ns:  # spin: at most spin_ns, on a thread that is awake and running
        now = clock()
    return now


@dataclass
class _Topic:
    key: str
    publisher: zenoh.Publisher
    gid: bytes
    sequence: int = 0


class PacedPublisher:
    """Publishes pre-encoded message batches, one group of messages per sample, on a drift-free clock.

    Every key expression gets its own zenoh publisher (congestion control BLOCK, reliable: nothing is
    dropped; a slow subscriber slows the publisher down instead), its own random 16-byte id and its
    own sequence counter from 0. Deadlines are waited for as ``timing`` says (:class:`Timing`,
    default :data:`PRECISE`).
    """

    def __init__(self, session: zenoh.Session, keys: Sequence[str], timing: Timing | None = None):
        self._session = session
        self.timing = timing if timing is not None else PRECISE
        self._topics: dict[str, _Topic] = {}
        for key in keys:
            pub = session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE
            )
            self._topics[key] = _Topic(key, pub, secrets.token_bytes(16))

    def publisher_ids(self) -> dict[str, bytes]:
        return {key: t.gid for key, t in self._topics.items()}

    def matched(self) -> bool:
        """Whether every publisher has at least one matching subscriber."""
        return all(
            cast("zenoh.MatchingStatus", t.publisher.matching_status).matching  # the stub says bool
            for t in self._topics.values()
        )

    def wait_for_subscribers(self, timeout_s: float, stop: Callable[[], object] | None = None) -> bool:
        """Wait (up to ``timeout_s``, or until ``stop()`` is true) until every key has a subscriber;
        returns whether they all do."""
        end = time.monotonic() + timeout_s
        while not self.matched():
            if time.monotonic() >= end or (stop is not None and stop()):
                return False
            time.sleep(0.01)
        return True

    def put(self, key: str, payload: bytes) -> None:
        topic = self._topics[key]
        topic.publisher.put(payload, attachment=pack_attachment(topic.sequence, time.time_ns(), topic.gid))
        topic.sequence += 1

    def run(
        self, batches: dict[str, list[bytes]], rate_hz: float | None, stop: Callable[[], object] | None = None
    ) -> PacingReport:
        """Send sample k's messages (``batches[key][k]`` for every key, in the dict's order) at
        ``t0 + k / rate_hz``: wait for each deadline, or send at once when behind (never a sleep per
        sample that would accumulate). ``rate_hz=None``: as fast as possible. ``stop()`` returning True
        ends the run early."""
        keys = list(batches)
        topics = [self._topics[key] for key in keys]
        columns = [batches[key] for key in keys]
        n = min((len(v) for v in batches.values()), default=0)
        lateness = np.zeros(n)
        period_ns = None if rate_hz is None else 1e9 / float(rate_hz)
        spin_ns = round(self.timing.spin_s * 1e9)
        pack, time_ns = _ATTACHMENT.pack, time.time_ns
        sent = 0
        with hot_loop(self.timing if period_ns is not None else SLEEP_ONLY):
            t0 = time.monotonic_ns()
            for k in range(n):
                if period_ns is not None:
                    deadline = t0 + round(k * period_ns)
                    now = _wait_until(deadline, spin_ns)
                    lateness[k] = (now - deadline) * 1e-9
                for topic, column in zip(topics, columns):  # put() inlined: the hot path
                    topic.publisher.put(column[k], attachment=pack(topic.sequence, time_ns(), 16, topic.gid))
                    topic.sequence += 1
                sent = k + 1
                if stop is not None and k % 64 == 0 and stop():
                    break
            elapsed = (time.monotonic_ns() - t0) * 1e-9
        return PacingReport(lateness_s=lateness[:sent], messages=sent * len(keys), elapsed_s=elapsed)

    def run_schedule(
        self,
        batches: Iterable[Sequence[tuple[int, str, bytes]]],
        stop: Callable[[], object] | None = None,
        max_samples: int = 1 << 20,
    ) -> PacingReport:
        """Send messages at their own deadlines ``t0 + offset_ns`` (``t0``: when the run starts,
        monotonic clock): wait for each deadline, or send at once when behind -- the same drift-free
        rule as :meth:`run`, with deadlines given per message instead of ``k / rate``.

        ``batches`` yields lists (or tuples) of messages ``(offset_ns, key, payload)``, offsets
        non-decreasing across the whole run, keys among the publisher's (replay's read-ahead hands
        over one list per MCAP chunk; an endless generator is fine). Messages sharing a deadline go
        out back to back. ``stop()`` is polled between batches, at the first new deadline after every
        64 messages and at least every 0.1 s while waiting; True ends the run, never inside one
        deadline's group (a stopped stream's sample has all its topics or none). The report keeps the
        lateness of at most ``max_samples`` deadlines (beyond that, every other one is dropped and the
        stride doubles)."""
        lateness: list[float] = []
        stride, skip = 1, 0
        sent = polled = 0
        last_deadline = None
        spin_ns = round(self.timing.spin_s * 1e9)
        topics = self._topics
        pack, time_ns = _ATTACHMENT.pack, time.time_ns
        with hot_loop(self.timing):
            t0 = time.monotonic_ns()
            for batch in batches:
                if stop is not None and stop():
                    break
                for offset_ns, key, payload in batch:
                    deadline = t0 + offset_ns
                    if deadline != last_deadline:
                        if stop is not None and sent >= polled + 64:
                            polled = sent
                            if stop():
                                return PacingReport(np.array(lateness), sent, (time.monotonic_ns() - t0) * 1e-9)
                        last_deadline = deadline
                        now = _wait_until(deadline, spin_ns, stop)
                        if now is None:
                            return PacingReport(np.array(lateness), sent, (time.monotonic_ns() - t0) * 1e-9)
                        if skip == 0:
                            lateness.append((now - deadline) * 1e-9)
                            if len(lateness) >= max_samples:
                                lateness = lateness[::2]
                                stride *= 2
                        skip = (skip + 1) % stride
                    topic = topics[key]  # put() inlined: the hot path
                    topic.publisher.put(payload, attachment=pack(topic.sequence, time_ns(), 16, topic.gid))
                    topic.sequence += 1
                    sent += 1
            elapsed = (time.monotonic_ns() - t0) * 1e-9
        return PacingReport(lateness_s=np.array(lateness), messages=sent, elapsed_s=elapsed)

    def close(self) -> None:
        for t in self._topics.values():
            try:
                t.publisher.undeclare()
            except Exception:
                pass


# --------------------------------------------------------------------------------------------------
# A live job's session and its teardown.


class _Closable(Protocol):
    def close(self) -> None: ...


class LiveSession:
    """A live job's zenoh session and what the job declares on it, for :func:`live_session` to tear down.

    Attributes
    ----------
    session : zenoh.Session
        The job's session.
    stopping : list
        The numbers of the signals (SIGINT, SIGTERM) that have arrived (:meth:`stopped`, :meth:`stop_status`).
    publisher : PacedPublisher or None
        The job's publisher (:meth:`publish`); undeclared at the end.
    node : object with ``close()``, or None
        The job's ROS 2 node (a :class:`gyroemu.pipelines.formats.ros2_keys.Ros2Node` or
        :class:`~gyroemu.pipelines.formats.ros2_keys.Ros2Keys`), set by the job; closed at the end.
    """

    def __init__(self, session: zenoh.Session, stopping: list[int]) -> None:
        self.session = session
        self.stopping = stopping
        self.publisher: PacedPublisher | None = None
        self.node: _Closable | None = None

    def stopped(self) -> bool:
        """Whether SIGINT or SIGTERM has arrived."""
        return bool(self.stopping)

    def stop_status(self) -> int:
        """The exit status of a job the signals stopped, as the command line's for any command: 143 when
        SIGTERM arrived first, 130 for SIGINT; 0 when none has arrived."""
        if not self.stopping:
            return 0
        return 143 if self.stopping[0] == signal.SIGTERM else 130

    def publish(self, keys: Sequence[str], timing: Timing | None = None) -> PacedPublisher:
        """Declare the job's :class:`PacedPublisher` of ``keys`` on the session."""
        self.publisher = PacedPublisher(self.session, keys, timing)
        return self.publisher


@contextlib.contextmanager
def live_session(session: zenoh.Session) -> Iterator[LiveSession]:
    """The live stretch of a job on ``session``, and the one teardown of every live job.

    For the block SIGINT and SIGTERM stop the job instead of the process (:func:`stop_on_signals`:
    the job polls :meth:`LiveSession.stopped`). At its end, however it ends: the publisher is
    undeclared, the ROS 2 node closed (its liveliness tokens withdrawn), the session closed, and the
    previous signal handlers are back. Clean-up of the job's own (a reader thread, a recorder, a live
    filter) goes in a ``try``/``finally`` inside the block, so that it runs first."""
    with stop_on_signals() as stopping:
        live = LiveSession(session, stopping)
        try:
            yield live
        finally:
            if live.publisher is not None:
                live.publisher.close()
            if live.node is not None:
                live.node.close()
            session.close()


# --------------------------------------------------------------------------------------------------
# Subscribing.


def subscribe(
    session: zenoh.Session, key_expr: str = f"{KEY_ROOT}/**", capacity: int = 1 << 16
) -> zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]:
    """A subscriber whose samples queue in a FIFO channel (``capacity`` samples; when it is full zenoh
    waits, which with BLOCK publishers slows them down rather than dropping)."""
    return session.declare_subscriber(key_expr, zenoh.handlers.FifoChannel(capacity))


def drain(
    subscriber: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]], limit: int = 1 << 14
) -> list[zenoh.Sample]:
    """Up to ``limit`` samples already queued (does not wait)."""
    out = []
    for _ in range(limit):
        sample = subscriber.try_recv()
        if sample is None:
            break
        out.append(sample)
    return out
