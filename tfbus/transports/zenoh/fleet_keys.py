"""The fleet key space: one transport that sees every robot's namespace (``namespace=*``).

A robot's bus runs with ``namespace="robot7"``: its keys are ``tfbus/robot7/tf``,
``tfbus/robot7/@latch/...`` and ``tfbus/robot7/@alive/...`` (:class:`KeySpace`). A fleet
listener runs with ``namespace="*"``: it subscribes to ``tfbus/*/**`` and to every
robot's liveliness, and sees each robot's topics **prefixed by the robot's namespace**::

    key tfbus/robot7/tf                         <->  topic /robot7/tf
    key tfbus/robot7/@latch/<node>/tf_static    ->   topic /robot7/tf_static (late joiner)
    key tfbus/robot7/@alive/<node>/<name>       ->   node <node> named "robot7/<name>"
    key tfbus/robot7/@alive/<node>/<name>/tf    ->   ... publishing /robot7/tf

A fleet bus publishing on ``/robot7/tf`` puts on ``tfbus/robot7/tf`` (robot7's bus
receives it as ``/tf``); a topic of one chunk (``/tf``) goes to the root namespace
(``tfbus/tf``). The fleet listener's own liveliness token is in the root namespace, so
robots do not list it. Namespaces of a fleet are one key chunk (``*`` matches one chunk).

A namespace has one spelling: the chunk a robot's bus puts on, which
:func:`~tfbus.transports.zenoh.keys.check_base_chunk` allows (no ``%``, ``*``, ``$``,
``#``, ``?``, ``@`` or space). A key whose namespace chunk is anything else -- the
percent-encoded alias ``tfbus/r%31/tf`` of ``tfbus/r1/tf`` -- is refused (None), so a
Zenoh access rule for ``tfbus/r1/**`` covers everything the fleet stores as robot
``r1``'s; topic chunks after it are held to :func:`~tfbus.transports.zenoh.keys.parse_chunk`.
"""

from __future__ import annotations

from typing import Final

from tfbus.transports.zenoh.keys import (
    DEFAULT_PREFIX,
    AliveKey,
    KeySpace,
    check_base_chunk,
    encode_chunk,
    parse_chunk,
    parse_topic_key,
    topic_key,
)

__all__ = ["FLEET_NAMESPACE", "FleetKeySpace", "key_space", "namespace_chunk", "namespace_of"]

FLEET_NAMESPACE: Final = "*"
"""The namespace that makes a transport a fleet listener (every robot's namespace)."""


def key_space(prefix: str = DEFAULT_PREFIX, namespace: str = "") -> KeySpace:
    """The key space of a transport: :class:`FleetKeySpace` for ``namespace="*"``, else a
    plain :class:`KeySpace`.

    Raises:
        ValueError: an invalid prefix or namespace (named with its value).
    """
    if namespace == FLEET_NAMESPACE:
        return FleetKeySpace(prefix)
    return KeySpace(prefix, namespace)


def namespace_chunk(chunk: str) -> str | None:
    """``chunk`` if it is a namespace a robot's bus can have (one chunk that
    :func:`~tfbus.transports.zenoh.keys.check_base_chunk` accepts), else None."""
    if not chunk or "/" in chunk or any(c in chunk for c in "*$#?@% "):
        return None
    return chunk


class FleetKeySpace(KeySpace):
    """Every robot namespace under ``prefix``: keys <-> namespaced topics (module doc).

    Raises:
        ValueError: if ``prefix`` is not valid (:func:`check_base_chunk`).
    """

    __slots__ = ("_prefix",)

    def __init__(self, prefix: str = DEFAULT_PREFIX) -> None:
        check_base_chunk("prefix", prefix)
        super().__init__(prefix)
        self._prefix = prefix
        self.base = f"{prefix}/{FLEET_NAMESPACE}"

    def _split(self, topic: str) -> tuple[str, str]:
        """``"/robot7/tf"`` -> ``("robot7", "/tf")``; ``"/tf"`` -> ``("", "/tf")``."""
        parts = topic.removeprefix("/").split("/", 1)
        if len(parts) == 1:
            return "", "/" + parts[0]
        return parts[0], "/" + parts[1]

    def _ns_base(self, namespace: str) -> str:
        if not namespace:
            return self._prefix
        # a robot's own spelling; a name no robot can have is escaped (reaches no robot)
        return f"{self._prefix}/{namespace_chunk(namespace) or encode_chunk(namespace)}"

    def data(self, topic: str) -> str:
        """The key of a namespaced topic (``/robot7/tf`` -> ``tfbus/robot7/tf``)."""
        namespace, rest = self._split(topic)
        return f"{self._ns_base(namespace)}/{topic_key(rest)}"

    def all_data(self) -> str:
        """Every topic of every robot: ``prefix/*/**``."""
        return f"{self._prefix}/*/**"

    def latch(self, node_id: str, topic: str | None = None) -> str:
        """Every latched topic of a node in any namespace, or the key of one namespaced
        latched topic."""
        if topic is None:
            return f"{self._prefix}/*/@latch/{node_id}/**"
        namespace, rest = self._split(topic)
        return f"{self._ns_base(namespace)}/@latch/{node_id}/{topic_key(rest)}"

    def alive(self, node_id: str | None = None, name: str = "", topic: str = "") -> str:
        """Every robot's liveliness tokens (``node_id`` None); this node's own token (in
        the root namespace); or its token for a namespaced topic."""
        if node_id is None:
            return f"{self._prefix}/*/@alive/**"
        if not topic:
            return f"{self._prefix}/@alive/{node_id}/{encode_chunk(name)}"
        namespace, rest = self._split(topic)
        return (
            f"{self._ns_base(namespace)}/@alive/{node_id}/{encode_chunk(name)}/"
            f"{topic_key(rest)}"
        )

    def robot_topic(self, topic: str) -> str:
        """``/robot7/tf_static`` -> ``/tf_static``: the name robot7's own bus gives a
        namespaced topic, so that a fleet's ``latched_topics`` (``/tf_static``) covers
        every robot's (``/robot7/tf_static``) as each robot's bus latches its own."""
        return self._split(topic)[1]

    def topic_of(self, key: str, reply: bool = False) -> str | None:
        """``tfbus/robot7/tf`` -> ``/robot7/tf`` (with ``reply``: a latch key's topic,
        namespaced); None for a key that is not one of the fleet's or not its one
        spelling (module doc: ``tfbus/r%31/tf`` is refused)."""
        head = self._prefix + "/"
        if not key.startswith(head):
            return None
        parts = key[len(head) :].split("/", 1)
        if len(parts) != 2 or not parts[0] or parts[0].startswith("@"):
            return None
        namespace: str | None
        namespace, rest = parts
        namespace = namespace_chunk(namespace)
        if namespace is None:
            return None
        if reply:
            latch = rest.split("/", 2)
            if len(latch) != 3 or latch[0] != "@latch" or not latch[2]:
                return None
            rest = latch[2]
        elif rest.startswith("@"):
            return None
        topic = parse_topic_key(rest)
        return None if topic is None else "/" + namespace + topic

    def parse_alive(self, key: str) -> AliveKey | None:
        """A robot's liveliness key: the node, ``"robot7/<name>"`` and the namespaced
        topic (``""`` for the node itself); None if it is not a fleet key or not its one
        spelling (module doc)."""
        head = self._prefix + "/"
        if not key.startswith(head):
            return None
        parts = key[len(head) :].split("/", 4)
        if len(parts) < 4 or parts[1] != "@alive" or parts[0].startswith("@"):
            return None
        namespace = namespace_chunk(parts[0])
        name = parse_chunk(parts[3])
        topic = parse_topic_key(parts[4]) if len(parts) == 5 else ""
        if namespace is None or name is None or topic is None:
            return None
        return AliveKey(parts[2], f"{namespace}/{name}", f"/{namespace}{topic}" if topic else "")


def namespace_of(name_or_topic: str) -> str:
    """The robot of a fleet node name (``"robot7/talker"``) or topic (``"/robot7/tf"``)."""
    return name_or_topic.removeprefix("/").split("/", 1)[0]
