"""Liveliness: which other tfbus nodes are alive, and which topics they publish.

Every running :class:`~tfbus.transports.zenoh.ZenohTransport` declares a Zenoh
liveliness token for itself and one per topic it has published
(:class:`~tfbus.transports.zenoh.keys.KeySpace`). Zenoh drops the tokens of a node
that closes, crashes or is killed (its TCP link closes; a silent partition is noticed
after the lease, ``transport/link/tx/lease``, 10 s by default). :class:`PeerTable` turns
those token events into :class:`PeerInfo` entries and :class:`PeerEvent` messages, which
the transport delivers on the local bus topic :data:`PEERS_TOPIC` (those three are
defined in :mod:`tfbus.transports._base`, shared with the command line's
:class:`~tfbus.transports._base.PeerAware` check).
"""

from __future__ import annotations

from tfbus.transports._base import PEERS_TOPIC, PeerEvent, PeerInfo
from tfbus.transports.zenoh.keys import KeySpace

__all__ = ["MAX_NODE_ID_LENGTH", "PEERS_TOPIC", "PeerEvent", "PeerInfo", "PeerTable"]

MAX_NODE_ID_LENGTH = 64
"""Longest node id accepted in a liveliness key, in characters (a Zenoh session id is
at most 32 hexadecimal digits)."""


class PeerTable:
    """The live remote nodes of one transport, updated from liveliness key events.

    The table is bounded whatever remote peers declare: at most ``max_peers`` nodes and
    ``max_topics`` topics per node are tracked; a token beyond either bound, or with a
    node id longer than :data:`MAX_NODE_ID_LENGTH`, is ignored and counted in
    :attr:`over_limit` (it is never queried for latched messages). A node's entry goes
    when its node token goes, freeing its place.

    Args:
        keys: the bus's key space (liveliness keys of other buses are ignored).
        latched: the latched topics: a node that appears, or starts publishing one of
            them, should be asked for its latched messages.
        max_peers: most remote nodes tracked at once.
        max_topics: most topics tracked per node.

    Raises:
        ValueError: if ``max_peers`` or ``max_topics`` is less than 1.
    """

    def __init__(
        self,
        keys: KeySpace,
        latched: frozenset[str],
        *,
        max_peers: int = 4096,
        max_topics: int = 256,
    ) -> None:
        if max_peers < 1:
            raise ValueError(f"max_peers must be at least 1, got {max_peers!r}")
        if max_topics < 1:
            raise ValueError(f"max_topics must be at least 1, got {max_topics!r}")
        self._keys = keys
        self._latched = latched
        self._max_peers = max_peers
        self._max_topics = max_topics
        self._peers: dict[str, PeerInfo] = {}
        self.own_id = ""
        """This node's id (its own tokens are ignored)."""
        self.refused = 0
        """Liveliness events ignored because their key is not one of the bus's keys in
        its one spelling (:meth:`~tfbus.transports.zenoh.keys.KeySpace.parse_alive`)."""
        self.over_limit = 0
        """Liveliness tokens ignored because they would pass ``max_peers`` or
        ``max_topics``, or name a node id longer than :data:`MAX_NODE_ID_LENGTH`."""
        self.version = 0
        """Counts the changes of the table (:meth:`update` applied, :meth:`clear`): what
        a reader derived from :meth:`alive` or :meth:`broadcasters` holds while it is
        the same."""

    def update(self, alive: bool, key: str) -> tuple[PeerEvent, bool] | None:
        """Apply one liveliness event: ``(event, query_latched)`` or None to ignore it.

        ``query_latched`` is True when the transport should query that node's latched
        topics (it just appeared, or just started publishing a latched topic).
        """
        parsed = self._keys.parse_alive(key)
        if parsed is None:
            self.refused += 1
            return None
        if parsed.node_id == self.own_id:
            return None
        node_id, name, topic = parsed
        info = self._peers.get(node_id)
        query = False
        if alive:
            if info is None:
                if len(node_id) > MAX_NODE_ID_LENGTH or len(self._peers) >= self._max_peers:
                    self.over_limit += 1
                    return None
                info = PeerInfo(node_id, name)
            if topic and topic not in info.topics and len(info.topics) >= self._max_topics:
                self.over_limit += 1
                return None
            if topic:
                info = PeerInfo(node_id, name, info.topics | {topic})
            self._peers[node_id] = info
            query = not topic or self._keys.robot_topic(topic) in self._latched
        elif not topic:
            self._peers.pop(node_id, None)
        elif info is not None:
            self._peers[node_id] = PeerInfo(node_id, info.name, info.topics - {topic})
        self.version += 1
        return PeerEvent(alive, node_id, name, topic), query

    def alive(self) -> dict[str, PeerInfo]:
        """The live nodes by node id (a snapshot)."""
        return dict(self._peers)

    def broadcasters(self) -> dict[str, PeerInfo]:
        """The live nodes that have published ``/tf`` or ``/tf_static``."""
        return {k: v for k, v in self._peers.items() if v.is_broadcaster}

    def clear(self) -> None:
        """Forget every node (the transport stopped; ``refused`` is kept)."""
        self._peers.clear()
        self.own_id = ""
        self.version += 1

    def __len__(self) -> int:
        """The number of live nodes."""
        return len(self._peers)
