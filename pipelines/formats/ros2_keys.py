"""ROS 2 on zenoh as rmw_zenoh writes it: type hashes, data key expressions and liveliness tokens.

``gyroemu stream --ros2``, ``gyroemu replay --ros2`` and ``gyroemu record --ros2`` speak the wire
protocol of ``rmw_zenoh_cpp`` (the ROS 2 Jazzy RMW on Eclipse Zenoh), so that a ROS 2 node on
rmw_zenoh subscribes to gyroemu's streams, and gyroemu records a ROS 2 node's topics. Everything
ROS-2-specific lives in this module; the transport (sessions, the paced publisher, the 33-byte
attachment) is :mod:`gyroemu.pipelines.transport.zenoh_io`'s.

Type hashes (REP-2011, "RIHS01")
--------------------------------
A ROS 2 type is identified on the wire by ``RIHS01_<sha256 hex>`` of its *type description*: the
type's fields and, sorted by name, every type it references (recursively), as the JSON of
``type_description_interfaces/msg/TypeDescription``::

    {"type_description": {"type_name": "sensor_msgs/msg/Imu", "fields": [
        {"name": "header", "type": {"type_id": 1, "capacity": 0, "string_capacity": 0,
                                    "nested_type_name": "std_msgs/msg/Header"}}, ...]},
     "referenced_type_descriptions": [{"type_name": "builtin_interfaces/msg/Time", ...}, ...]}

serialised by Python's ``json.dumps`` with its default separators (``", "`` and ``": "``), keys in
that order, ASCII only; field default values are left out, comments and constants are not part of
it. ``type_id`` is the ``FieldType`` constant of the element type (bool 15, byte 16, char and uint8 3,
float32 10, float64 11, int8..uint64 2..9, string 17, wstring 18, bounded string 21, bounded wstring
22, nested type 1) plus 48 for a fixed array ``T[N]`` (capacity N), 96 for a bounded sequence
``T[<=N]`` (capacity N), 144 for an unbounded sequence ``T[]``; ``string_capacity`` is N of
``string<=N``. A type without fields gets rosidl's placeholder ``uint8
structure_needs_at_least_one_member``. :func:`type_hash` computes it from ``.msg`` texts (gyroemu's
own definitions, :data:`gyroemu.pipelines.formats.messages.ROS_DEFINITIONS`, or an MCAP file's ``ros2msg`` schema).

Key expressions (rmw_zenoh ``TopicInfo``)
-----------------------------------------
A message of ROS topic ``/a/b`` of type ``pkg/msg/T`` in domain ``D`` goes on::

    D/a/b/pkg::msg::dds_::T_/RIHS01_<hash>

(the topic without its leading slash, then the DDS type name, then the type hash), with the payload
the CDR bytes and the 33-byte attachment of :func:`gyroemu.pipelines.transport.zenoh_io.pack_attachment`.

gyroemu's topics (:mod:`gyroemu.pipelines.formats.channels`) become ROS topics by the same rule as its own keys
(``interface.md``): device
``imu0``'s ``/imu`` is ``/imu0/imu``, ``/raw/fog`` is ``/imu0/raw/fog``; a replayed file's ``/a/b``
is ``/<device>/a/b``. ROS 2 names allow only letters, digits and ``_`` (a token not starting with a
digit), so ``-`` becomes ``_`` in every token, by the rule gyroemu's own topics follow
(:func:`gyroemu.pipelines.formats.channels.topic_token`): kind ``rate-gyro``'s raw topic is
``/raw/rate_gyro`` in files and on every key, ``/imu0/raw/rate_gyro`` here, and a replayed older log's
``/raw/rate-gyro`` goes out under that name too. The recorder records ROS 2 topic ``/<device>/<rest>``
on ``/<rest>``.

Liveliness tokens (rmw_zenoh's graph)
-------------------------------------
ROS 2 tools (``ros2 node list``, ``ros2 topic list/echo/info``) learn the graph from zenoh liveliness
tokens. Each gyroemu process is one node, ``gyroemu_<command>_<pid>`` in namespace ``/``, and
declares::

    @ros2_lv/<domain>/<zid>/<nid>/<id>/NN/<enclave>/<namespace>/<node>
    @ros2_lv/<domain>/<zid>/<nid>/<id>/MP/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>

(``MS`` for the recorder's subscriptions), where ``zid`` is the zenoh session id (hex), ``nid`` the
node's id and ``id`` the entity's (a counter per process: the node is 0, its publishers 1, 2, ...),
names have every ``/`` replaced by ``%`` (namespace and enclave ``/`` are ``%``, ``/imu0/imu`` is
``%imu0%imu``), and ``qos`` is ``reliability:durability:history,depth:deadline_s,deadline_ns:
lifespan_s,lifespan_ns:liveliness,lease_s,lease_ns`` with each value left empty when it equals
rmw_zenoh's default (reliable, volatile, keep-last, depth 42, infinite durations, automatic
liveliness). gyroemu's publishers block rather than drop (zenoh congestion control BLOCK), which is
what rmw_zenoh does for a *reliable keep-all* publisher, so that is what they advertise:
``::2,:,:,:,,``.

Sources: REP-2011 (Evolving Message Types) and ``rosidl_generator_type_description``
(``calculate_type_hash``, ``FIELD_TYPE_NAME_TO_ID``, ``field_type_capacity``); ``rmw_zenoh_cpp``
``src/detail/liveliness_utils.cpp`` (``TopicInfo``, ``KeyexprIndex``, ``qos_to_keyexpr``,
``mangle_name``) and ``src/detail/qos.cpp`` (the defaults); ``rmw/types.h`` (QoS enum values).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, TextIO, TypedDict

from gyroemu.pipelines.formats.channels import topic_token
from gyroemu.pipelines.formats.messages import ROS_DEFINITIONS

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "ADMIN_SPACE",
    "Ros2Error",
    "full_type_name",
    "parse_definitions",
    "type_description",
    "type_hash",
    "is_type_hash",
    "dds_type_name",
    "ros_type_name",
    "ros_topic",
    "gyroemu_topic",
    "data_key",
    "parse_data_key",
    "domain_id",
    "qos_keyexpr",
    "node_token",
    "entity_token",
    "Ros2Node",
    "Ros2Keys",
    "node_name",
    "DataKey",
    "GLOBAL_TOPICS",
    "TF_QOS",
    "TF_STATIC_QOS",
    "topic_qos",
]

ADMIN_SPACE = "@ros2_lv"
MAX_DOMAIN_ID = 232  # the largest ROS_DOMAIN_ID ROS 2 accepts (DDS port arithmetic; rmw_zenoh takes it too)


class Ros2Error(ValueError):
    """A name, type or definition that has no ROS 2 form (the message says which and why)."""


# --------------------------------------------------------------------------------------------------
# .msg definitions -> type descriptions -> RIHS01 hashes.

# FieldType.msg (type_description_interfaces): element type ids; + 48 array, + 96 bounded, + 144 sequence.
_TYPE_IDS = {
    "nested": 1,
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "char": 3,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
    "bounded_string": 21,
    "bounded_wstring": 22,
}
"""``.msg`` primitive -> FieldType id. ``char`` is ``uint8`` and ``byte`` is ``octet`` in ROS 2
(rosidl_adapter's ``MSG_TYPE_TO_IDL``)."""
_ARRAY, _BOUNDED_SEQUENCE, _SEQUENCE = 48, 96, 144
_ALIASES = {
    "time": "builtin_interfaces/msg/Time",
    "duration": "builtin_interfaces/msg/Duration",
    "Header": "std_msgs/msg/Header",
}
"""ROS 1 spellings some bags' schemas still use (rosbags writes ``time``; ROS 1 ``Header``)."""
_TYPE = re.compile(
    r"^(?P<base>[A-Za-z][A-Za-z0-9_/]*)(?:<=(?P<strcap>\d+))?"
    r"(?:\[(?P<bounded><=)?(?P<size>\d*)\])?$"
)
_MSG_SECTION = re.compile(r"^MSG: (\S+)\s*$", re.MULTILINE)


class _FieldType(TypedDict):
    """``type_description_interfaces/msg/FieldType``, as REP-2011 hashes it."""

    type_id: int
    capacity: int
    string_capacity: int
    nested_type_name: str


class _Field(TypedDict):
    """``type_description_interfaces/msg/Field`` (without its default value, which is not hashed)."""

    name: str
    type: _FieldType


class _IndividualTypeDescription(TypedDict):
    """``type_description_interfaces/msg/IndividualTypeDescription``."""

    type_name: str
    fields: list[_Field]


class _TypeDescription(TypedDict):
    """The hashed part of ``type_description_interfaces/msg/TypeDescription``."""

    type_description: _IndividualTypeDescription
    referenced_type_descriptions: list[_IndividualTypeDescription]


def full_type_name(name: str, package: str | None = None) -> str:
    """``pkg/Type``, ``pkg/msg/Type`` or (inside ``package``) ``Type`` -> ``pkg/msg/Type``."""
    parts = name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return name
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 1 and package:
        return f"{package}/msg/{name}"
    raise Ros2Error(f"type name {name!r}: expected pkg/msg/Type or pkg/Type")


def _strip_comment(line: str) -> str:
    """The line without its ``#`` comment (a ``#`` inside a string default is cut too: defaults do
    not enter the hash, so that is harmless here)."""
    return line.split("#", 1)[0].strip()


def _field_type(token: str, package: str) -> _FieldType:
    """The ``FieldType`` dict of a ``.msg`` type token such as ``float64[9]``, ``string<=8[<=3]``, ``Header``."""
    m = _TYPE.match(token)
    if not m:
        raise Ros2Error(f"field type {token!r} is not a ROS 2 .msg type")
    base, strcap = m.group("base"), m.group("strcap")
    nested = ""
    string_capacity = 0
    if base in ("string", "wstring") and strcap is not None:
        element = _TYPE_IDS[f"bounded_{base}"]
        string_capacity = int(strcap)
    elif strcap is not None:
        raise Ros2Error(f"field type {token!r}: only string and wstring take '<='")
    elif base in _TYPE_IDS and base not in ("nested", "bounded_string", "bounded_wstring"):
        element = _TYPE_IDS[base]
    else:
        element = _TYPE_IDS["nested"]
        nested = _ALIASES.get(base) or full_type_name(base, package)
    capacity = 0
    if m.group(0).endswith("]"):
        size = m.group("size")
        if m.group("bounded"):
            if not size:
                raise Ros2Error(f"field type {token!r}: a bounded sequence needs its bound")
            element, capacity = element + _BOUNDED_SEQUENCE, int(size)
        elif size:
            element, capacity = element + _ARRAY, int(size)
        else:
            element += _SEQUENCE
    return {"type_id": element, "capacity": capacity, "string_capacity": string_capacity, "nested_type_name": nested}


def _fields(name: str, text: str) -> list[_Field]:
    """The fields (``{"name", "type"}``) of ``.msg`` text ``text`` of type ``name`` (``pkg/msg/Type``);
    constants (``TYPE NAME=value``) are not fields; no field: rosidl's placeholder member."""
    package = name.split("/")[0]
    fields: list[_Field] = []
    for raw in text.splitlines():
        line = _strip_comment(raw)
        if not line:
            continue
        type_token, _, rest = line.partition(" ")
        rest = rest.strip()
        if not rest:
            raise Ros2Error(f"{name}: line {raw.strip()!r} has a type but no name")
        if "=" in rest:  # a constant (rosidl_adapter: '=' after the type means a constant)
            continue
        field_name = rest.split()[0]
        if not re.match(r"^[a-z][a-z0-9_]*$", field_name):
            raise Ros2Error(f"{name}: field name {field_name!r} is not a ROS 2 field name")
        fields.append({"name": field_name, "type": _field_type(type_token, package)})
    if not fields:
        fields.append(
            {
                "name": "structure_needs_at_least_one_member",
                "type": {"type_id": _TYPE_IDS["uint8"], "capacity": 0, "string_capacity": 0, "nested_type_name": ""},
            }
        )
    return fields


def parse_definitions(schema: str, name: str) -> dict[str, str]:
    """Split a ``ros2msg`` schema (type ``name``'s ``.msg`` text, then ``MSG: pkg/Type`` sections
    separated by lines of ``=``, as rosbag2 and gyroemu write them into MCAP files) into
    ``{pkg/msg/Type: .msg text}``."""
    out: dict[str, str] = {}
    sections = re.split(r"^=+\s*$", schema, flags=re.MULTILINE)
    out[full_type_name(name)] = sections[0]
    for section in sections[1:]:
        m = _MSG_SECTION.search(section)
        if not m:
            if section.strip():
                raise Ros2Error(f"schema of {name}: a section without its 'MSG: pkg/Type' line")
            continue
        out[full_type_name(m.group(1))] = section[m.end() :]
    return out


def type_description(name: str, definitions: Mapping[str, str] = ROS_DEFINITIONS) -> _TypeDescription:
    """The hashed part of ``type_description_interfaces/msg/TypeDescription`` of ``name``, as a dict
    in the key order REP-2011 hashes: the type's fields, then each referenced type, sorted by name.

    ``definitions`` maps type names (``pkg/msg/Type`` or ``pkg/Type``) to ``.msg`` texts; raises
    :class:`Ros2Error` when a referenced type is missing or a definition does not parse."""
    texts = {full_type_name(k): v for k, v in definitions.items()}
    root = full_type_name(name)
    described: dict[str, _IndividualTypeDescription] = {}
    pending = [root]
    while pending:
        current = pending.pop()
        if current in described:
            continue
        if current not in texts:
            raise Ros2Error(f"type {current} (used by {root}) has no definition")
        fields = _fields(current, texts[current])
        described[current] = {"type_name": current, "fields": fields}
        pending.extend(f["type"]["nested_type_name"] for f in fields if f["type"]["nested_type_name"])
    return {
        "type_description": described.pop(root),
        "referenced_type_descriptions": [described[k] for k in sorted(described)],
    }


def type_hash(name: str, definitions: Mapping[str, str] = ROS_DEFINITIONS) -> str:
    """``RIHS01_<sha256 hex>`` of type ``name`` by REP-2011 (see the module's notes)."""
    text = json.dumps(
        type_description(name, definitions),
        ensure_ascii=True,
        allow_nan=False,
        separators=(", ", ": "),
        sort_keys=False,
    )
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


_RIHS01 = re.compile(r"^RIHS01_[0-9a-f]{64}$")


def is_type_hash(text: str) -> bool:
    """Whether ``text`` is an RIHS01 hash string."""
    return bool(_RIHS01.match(text or ""))


# --------------------------------------------------------------------------------------------------
# Names.

_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def dds_type_name(name: str) -> str:
    """``sensor_msgs/msg/Imu`` -> ``sensor_msgs::msg::dds_::Imu_`` (the type name rmw_zenoh puts in keys)."""
    package, _, typ = full_type_name(name).split("/")
    return f"{package}::msg::dds_::{typ}_"


def ros_type_name(dds_name: str) -> str:
    """``sensor_msgs::msg::dds_::Imu_`` -> ``sensor_msgs/msg/Imu`` (:class:`Ros2Error` for other forms)."""
    m = re.match(r"^([A-Za-z0-9_]+)::(msg|srv|action)::dds_::([A-Za-z0-9_]+)_$", dds_name)
    if not m:
        raise Ros2Error(f"{dds_name!r} is not a DDS type name pkg::msg::dds_::Type_")
    return f"{m.group(1)}/{m.group(2)}/{m.group(3)}"


GLOBAL_TOPICS = ("/tf", "/tf_static")
"""Topics that are the ROS 2 graph's, not a device's: tf2 listens on ``/tf`` and ``/tf_static`` only, so a
gyroemu device's tree goes there (``gyroemu/<device>/tf`` on gyroemu's own keys)."""


def ros_topic(device: str, topic: str) -> str:
    """The ROS 2 topic of gyroemu ``topic`` of ``device``: ``("imu0", "/raw/rate_gyro")`` ->
    ``/imu0/raw/rate_gyro``, every token by :func:`~gyroemu.pipelines.formats.channels.topic_token`
    (``-`` -> ``_``: an older log's ``/raw/rate-gyro`` gives the same); a topic of :data:`GLOBAL_TOPICS`
    stays itself (``("imu0", "/tf")`` -> ``/tf``); :class:`Ros2Error` when a token is still not a ROS name."""
    if topic in GLOBAL_TOPICS:
        return topic
    name = "/" + device + topic
    tokens = [topic_token(t) for t in name.strip("/").split("/")]
    for t in tokens:
        if not _TOKEN.match(t):
            raise Ros2Error(
                f"{name!r}: {t!r} cannot be part of a ROS 2 topic name (letters, digits and '_', "
                "not starting with a digit)"
            )
    return "/" + "/".join(tokens)


def gyroemu_topic(topic: str) -> tuple[str, str]:
    """``(device, topic)`` of ROS 2 topic ``/<device>/<rest>`` (``/imu0/raw/rate_gyro`` ->
    ``("imu0", "/raw/rate_gyro")``, gyroemu's own name of kind ``rate-gyro``'s raw topic); a topic of
    :data:`GLOBAL_TOPICS` has no device: ``("", "/tf")``."""
    if topic in GLOBAL_TOPICS:
        return "", topic
    tokens = topic.strip("/").split("/")
    if len(tokens) < 2 or not all(tokens):
        raise Ros2Error(f"ROS 2 topic {topic!r} is not /<device>/<topic>")
    return tokens[0], "/" + "/".join(tokens[1:])


def data_key(domain: int, topic: str, type_name: str, hash_: str) -> str:
    """``<domain>/<topic without its leading slash>/<DDS type name>/<RIHS01 hash>``."""
    return f"{int(domain)}/{topic.strip('/')}/{dds_type_name(type_name)}/{hash_}"


@dataclass(frozen=True)
class DataKey:
    """A parsed rmw_zenoh data key expression."""

    domain: int
    topic: str  # /a/b
    type_name: str  # pkg/msg/Type
    type_hash: str  # RIHS01_... (or whatever the publisher put there, e.g. TypeHashNotSupported)


def parse_data_key(key: str) -> DataKey:
    """The parts of ``<domain>/<a>/<b>/<pkg::msg::dds_::T_>/<hash>``; :class:`Ros2Error` otherwise."""
    parts = str(key).split("/")
    if len(parts) < 4 or not parts[0].isdigit() or not all(parts):
        raise Ros2Error(f"key expression {key!r} is not <domain>/<topic>/<type>/<hash>")
    return DataKey(int(parts[0]), "/" + "/".join(parts[1:-2]), ros_type_name(parts[-2]), parts[-1])


def domain_id(value: int | None = None, environ: Mapping[str, str] = os.environ) -> int:
    """The ROS domain: ``value`` (``--domain``) if given, else ``ROS_DOMAIN_ID``, else 0; in 0..232.
    :class:`Ros2Error` names the argument or the variable at fault."""
    if value is not None:
        what, text = "argument --domain", str(value)
    else:
        what, text = "environment variable ROS_DOMAIN_ID", environ.get("ROS_DOMAIN_ID", "").strip()
        if not text:
            return 0
    try:
        number = int(text)
    except ValueError:
        raise Ros2Error(f"{what}: expected an integer 0..{MAX_DOMAIN_ID}, got {text!r}") from None
    if not 0 <= number <= MAX_DOMAIN_ID:
        raise Ros2Error(f"{what}: expected an integer 0..{MAX_DOMAIN_ID}, got {number}")
    return number


# --------------------------------------------------------------------------------------------------
# Liveliness tokens.

# rmw/types.h enum values and rmw_zenoh's defaults (qos.cpp).
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2
_DEFAULT_QOS = {"reliability": RELIABLE, "durability": VOLATILE, "history": KEEP_LAST, "depth": 42}


def qos_keyexpr(
    reliability: int = RELIABLE, durability: int = VOLATILE, history: int = KEEP_ALL, depth: int = 0
) -> str:
    """rmw_zenoh's QoS chunk, each value empty when it is the default; deadline, lifespan and lease
    are infinite (the defaults) and liveliness automatic. ``depth`` 0 means the default depth.
    Default arguments: reliable keep-all (what a BLOCK publisher is): ``::2,:,:,:,,``."""

    def part(key: str, value: int) -> str:
        return "" if value == _DEFAULT_QOS[key] else str(value)

    depth = depth or _DEFAULT_QOS["depth"]
    return (
        f"{part('reliability', reliability)}:{part('durability', durability)}:"
        f"{part('history', history)},{part('depth', depth)}:,:,:,,"
    )


TF_QOS = qos_keyexpr(history=KEEP_LAST, depth=100)
"""``/tf``'s QoS chunk: tf2's ``DynamicBroadcasterQoS`` (reliable, volatile, keep-last 100)."""
TF_STATIC_QOS = qos_keyexpr(durability=TRANSIENT_LOCAL, history=KEEP_LAST, depth=1)
"""``/tf_static``'s QoS chunk: tf2's ``StaticBroadcasterQoS`` (reliable, transient local, keep-last 1)."""


def topic_qos(ros_topic: str) -> str:
    """The QoS chunk gyroemu advertises for ``ros_topic``: tf2's for ``/tf`` and ``/tf_static``
    (:data:`TF_QOS`, :data:`TF_STATIC_QOS`), else reliable keep-all (:func:`qos_keyexpr`'s default)."""
    return {"/tf": TF_QOS, "/tf_static": TF_STATIC_QOS}.get(ros_topic, qos_keyexpr())


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def node_token(domain: int, zid: str, node_id: int, node: str, namespace: str = "/", enclave: str = "/") -> str:
    """``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>`` (a node's own id is its nid)."""
    return (
        f"{ADMIN_SPACE}/{int(domain)}/{zid}/{node_id}/{node_id}/NN/{_mangle(enclave)}/"
        f"{_mangle(namespace)}/{_mangle(node)}"
    )


def entity_token(
    kind: str,
    domain: int,
    zid: str,
    node_id: int,
    entity_id: int,
    node: str,
    topic: str,
    type_name: str,
    hash_: str,
    qos: str | None = None,
    namespace: str = "/",
    enclave: str = "/",
) -> str:
    """A publisher's (``kind="MP"``) or subscription's (``"MS"``) token (see the module's notes)."""
    if kind not in ("MP", "MS"):
        raise ValueError(f"entity kind {kind!r}: MP or MS")
    return (
        f"{ADMIN_SPACE}/{int(domain)}/{zid}/{node_id}/{entity_id}/{kind}/{_mangle(enclave)}/"
        f"{_mangle(namespace)}/{_mangle(node)}/{_mangle(topic)}/{dds_type_name(type_name)}/{hash_}/"
        f"{qos if qos is not None else qos_keyexpr()}"
    )


class Ros2Node:
    """One ROS 2 node of a gyroemu process on a zenoh session: its ``NN`` token, and an ``MP``/``MS``
    token per publisher/subscription added (:meth:`publisher`, :meth:`subscription`). The tokens live
    until :meth:`close` (or the session's end: zenoh withdraws them then, so ROS tools see the node go)."""

    def __init__(self, session: zenoh.Session, domain: int, name: str, namespace: str = "/") -> None:
        if not _TOKEN.match(name):
            raise Ros2Error(f"node name {name!r} is not a ROS 2 name")
        self.session, self.domain, self.name, self.namespace = session, int(domain), name, namespace
        self.zid = str(session.zid())
        self.node_id = 0
        self._next_id = 1
        self.keys: list[str] = []
        self._tokens: list[zenoh.LivelinessToken] = []
        self._declare(node_token(self.domain, self.zid, self.node_id, name, namespace))

    def _declare(self, key: str) -> None:
        self._tokens.append(self.session.liveliness().declare_token(key))
        self.keys.append(key)

    def _entity(self, kind: str, topic: str, type_name: str, hash_: str, qos: str | None = None) -> str:
        key = entity_token(
            kind,
            self.domain,
            self.zid,
            self.node_id,
            self._next_id,
            self.name,
            topic,
            type_name,
            hash_,
            qos,
            namespace=self.namespace,
        )
        self._next_id += 1
        self._declare(key)
        return key

    def publisher(self, topic: str, type_name: str, hash_: str, qos: str | None = None) -> str:
        """Declare a publisher of ``type_name`` on ``topic`` (``qos``: its QoS chunk; None: the topic's,
        :func:`topic_qos`); returns its token's key expression."""
        return self._entity("MP", topic, type_name, hash_, topic_qos(topic) if qos is None else qos)

    def subscription(self, topic: str, type_name: str, hash_: str) -> str:
        """Declare a subscription (the topic's QoS, :func:`topic_qos`); returns its token's key expression."""
        return self._entity("MS", topic, type_name, hash_, topic_qos(topic))

    def close(self) -> None:
        for token in self._tokens:
            try:
                token.undeclare()
            except Exception:
                pass
        self._tokens = []


def node_name(command: str) -> str:
    """The node name of a gyroemu process: ``gyroemu_<command>_<pid>`` (unique on the machine)."""
    return f"gyroemu_{command}_{os.getpid()}"


class Ros2Keys:
    """Keys and graph tokens of a ROS 2 mode publisher (``stream --ros2``, ``replay --ros2``): one ROS 2
    node per process, a publisher token per key. :meth:`key` gives a topic's rmw_zenoh key and keeps
    its topic, type and hash; :meth:`declare` declares the tokens.

    ``domain`` None: ``$ROS_DOMAIN_ID``, else 0 (:func:`domain_id`: :class:`Ros2Error` names
    ``--domain`` or ``ROS_DOMAIN_ID``); ``command`` names the node (:func:`node_name`)."""

    def __init__(self, domain: int | None, command: str) -> None:
        self.domain = domain_id(domain)
        self.node_name = node_name(command)
        self.node: Ros2Node | None = None
        self.publishers: dict[str, tuple[str, str, str]] = {}  # key -> (ROS topic, type, hash)

    def key(self, ros_topic: str, type_name: str, hash_: str | None = None) -> str:
        """The data key of ``ros_topic`` (``hash_`` None: the type's hash from gyroemu's definitions)."""
        hash_ = hash_ or type_hash(type_name)
        key = data_key(self.domain, ros_topic, type_name, hash_)
        self.publishers[key] = (ros_topic, type_name, hash_)
        return key

    def declare(self, session: zenoh.Session, out: TextIO) -> None:
        """Declare the node's and the publishers' liveliness tokens on ``session`` and print them to ``out``."""
        self.node = Ros2Node(session, self.domain, self.node_name)
        print(f"  ROS 2 domain {self.domain}, node /{self.node_name}; liveliness tokens:", file=out)
        print(f"    {self.node.keys[0]}", file=out)
        for ros_topic, type_name, type_hash in self.publishers.values():
            print(f"    {self.node.publisher(ros_topic, type_name, type_hash)}", file=out)

    def close(self) -> None:
        """Withdraw the tokens (if declared)."""
        if self.node is not None:
            self.node.close()
