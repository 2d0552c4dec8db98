"""Zenoh key expressions of a tfbus bus (pure string functions, no Zenoh import).

Key expressions (``base`` is ``prefix`` or ``prefix/namespace``)::

    {base}/{topic}                          data: "/tf" -> "tfbus/tf", "/a/b" -> "tfbus/a/b"
    {base}/@latch/{node_id}/{topic}         queryable: the node's latched topics (/tf_static)
    {base}/@alive/{node_id}/{name}          liveliness token of every running transport
    {base}/@alive/{node_id}/{name}/{topic}  ... and one per topic it has published

Topic chunks are percent-encoded where Zenoh would not accept them (``*$#?@%``, spaces,
non-ASCII, empty chunks), so any topic name maps to a valid key and back. The ``@``
chunks are Zenoh "verbatim" chunks: ``{base}/**`` never matches them.

Every topic has **one** key: a received key is read back only if it is the spelling
:func:`encode_chunk` gives (upper-case hex, nothing escaped that need not be), so an
alias such as ``tfbus/t%66`` is not taken for ``tfbus/tf`` -- a Zenoh access rule written
for ``tfbus/tf`` covers everything delivered as ``/tf`` (:func:`parse_chunk`).
"""

from __future__ import annotations

from typing import Final, NamedTuple
from urllib.parse import quote, unquote

__all__ = [
    "DEFAULT_PREFIX",
    "AliveKey",
    "KeySpace",
    "check_base_chunk",
    "decode_chunk",
    "encode_chunk",
    "key_topic",
    "parse_chunk",
    "parse_topic_key",
    "topic_key",
]

DEFAULT_PREFIX: Final = "tfbus"
"""The default first part of every key expression."""

_KEY_SAFE: Final = "-_.~+=,:!"  # besides ASCII letters and digits


def encode_chunk(chunk: str) -> str:
    """One key chunk for any text (percent-encoded; ``""`` becomes ``"%"``)."""
    return quote(chunk, safe=_KEY_SAFE) if chunk else "%"


def decode_chunk(chunk: str) -> str:
    """The text of a chunk made by :func:`encode_chunk`."""
    return "" if chunk == "%" else unquote(chunk)


def parse_chunk(chunk: str) -> str | None:
    """The text of a received key chunk, or None if the chunk is not the one spelling
    :func:`encode_chunk` gives that text (``"t%66"`` for ``"tf"``, ``"%c3%a9"`` for
    ``"%C3%A9"``, ``"%zz"``): one key per topic, so access rules on keys cannot be bypassed by a
    percent-encoded alias (RFC 3986 section 6.2.2 normalisation, made a requirement)."""
    text = decode_chunk(chunk)
    return text if encode_chunk(text) == chunk else None


def parse_topic_key(key: str) -> str | None:
    """The topic of a received key (the inverse of :func:`topic_key`), or None if any
    chunk is not canonical (:func:`parse_chunk`)."""
    chunks = []
    for chunk in key.split("/"):
        text = parse_chunk(chunk)
        if text is None:
            return None
        chunks.append(text)
    return "/" + "/".join(chunks)


def topic_key(topic: str) -> str:
    """``"/tf"`` -> ``"tf"``; ``"/a/b"`` -> ``"a/b"`` (chunks percent-encoded)."""
    return "/".join(encode_chunk(c) for c in topic.removeprefix("/").split("/"))


def key_topic(key: str) -> str:
    """The topic of a key made by :func:`topic_key` (its inverse)."""
    return "/" + "/".join(decode_chunk(c) for c in key.split("/"))


def check_base_chunk(what: str, value: str) -> None:
    """Check a prefix or namespace.

    Raises:
        ValueError: if ``value`` is not '/'-separated non-empty chunks free of Zenoh's
            special characters (the message names ``what`` and the value).
    """
    for chunk in value.split("/"):
        if not chunk or any(c in chunk for c in "*$#?@% "):
            raise ValueError(
                f"{what} {value!r} must be '/'-separated non-empty chunks "
                "without '*', '$', '#', '?', '@', '%' or spaces"
            )


class AliveKey(NamedTuple):
    """A parsed liveliness key: the node, its name, and the topic (``""`` for the node)."""

    node_id: str
    name: str
    topic: str


class KeySpace:
    """Every key expression of one bus (``prefix`` / ``namespace``), built and parsed.

    Raises:
        ValueError: if ``prefix`` or ``namespace`` is not valid (:func:`check_base_chunk`).
    """

    __slots__ = ("_alive", "_cache", "base")

    def __init__(self, prefix: str = DEFAULT_PREFIX, namespace: str = "") -> None:
        check_base_chunk("prefix", prefix)
        if namespace:
            check_base_chunk("namespace", namespace)
        self.base = f"{prefix}/{namespace}" if namespace else prefix
        """``prefix`` or ``prefix/namespace``."""
        self._alive = f"{self.base}/@alive/"
        self._cache: dict[str, str | None] = {}

    def data(self, topic: str) -> str:
        """The key a topic's messages are put on."""
        return f"{self.base}/{topic_key(topic)}"

    def all_data(self) -> str:
        """The key expression of every topic."""
        return f"{self.base}/**"

    def latch(self, node_id: str, topic: str | None = None) -> str:
        """The key of a node's latched ``topic`` (or the expression of all of them)."""
        tail = "**" if topic is None else topic_key(topic)
        return f"{self.base}/@latch/{node_id}/{tail}"

    def alive(self, node_id: str | None = None, name: str = "", topic: str = "") -> str:
        """The liveliness key of a node (and one of its topics), or with ``node_id``
        None the expression of every liveliness token."""
        if node_id is None:
            return f"{self._alive}**"
        key = f"{self._alive}{node_id}/{encode_chunk(name)}"
        return f"{key}/{topic_key(topic)}" if topic else key

    def topic_of(self, key: str, reply: bool = False) -> str | None:
        """The topic of a data key (or, with ``reply``, of a latch key); None if the key
        is not one of this bus's or not its canonical spelling (:func:`parse_topic_key`).
        Results are cached (at most 10 000 keys)."""
        cache_key = "@" + key if reply else key
        topic = self._cache.get(cache_key, "")
        if topic != "":
            return topic
        base = self.base + "/"
        rest: str | None = None
        if key.startswith(base):
            rest = key[len(base) :]
            if reply:
                parts = rest.split("/", 2)
                rest = parts[2] if len(parts) == 3 and parts[0] == "@latch" else None
        topic = None if not rest else parse_topic_key(rest)
        if len(self._cache) < 10_000:
            self._cache[cache_key] = topic
        return topic

    def robot_topic(self, topic: str) -> str:
        """The name a robot's own bus gives ``topic`` (what ``latched_topics`` lists):
        ``topic`` itself; a fleet's key space drops the namespace
        (:meth:`~tfbus.transports.zenoh.fleet_keys.FleetKeySpace.robot_topic`)."""
        return topic

    def parse_alive(self, key: str) -> AliveKey | None:
        """The node, name and topic of a liveliness key; None if it is not one of ours
        or not its canonical spelling (:func:`parse_chunk`)."""
        if not key.startswith(self._alive):
            return None
        parts = key[len(self._alive) :].split("/", 2)
        if len(parts) < 2:
            return None
        name = parse_chunk(parts[1])
        topic = parse_topic_key(parts[2]) if len(parts) == 3 else ""
        if name is None or topic is None:
            return None
        return AliveKey(parts[0], name, topic)
