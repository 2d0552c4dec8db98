"""ZenohStatistics: the counters of one :class:`~tfbus.transports.zenoh.ZenohTransport`.

Every received payload ends in exactly one of ``delivered``, ``duplicates`` or a drop
counter (``malformed``, ``wrong_version``, ``over_limit``, ``overflow``,
``refused_keys``); sequence numbers feed ``lost`` (plausible gaps) and ``resets``
(implausible jumps), never both.
"""

from __future__ import annotations

from dataclasses import dataclass

from tfbus.transports._base import TransportStatistics

__all__ = ["ZenohStatistics"]


@dataclass(slots=True)
class ZenohStatistics(TransportStatistics):
    """Counters of one :class:`ZenohTransport` (:meth:`ZenohTransport.statistics`); the
    first five are :class:`~tfbus.transports._base.TransportStatistics`'s.

    Attributes:
        sent: messages put on the network.
        send_errors: local messages that could not be sent (not encodable, Zenoh error).
        not_connected: local messages published while the transport was not running.
        received: payloads received (samples and latched replies).
        delivered: messages delivered into the bus.
        latched_replies: of ``received``, those that answered a late-joiner query.
        duplicates: payloads not delivered because the bus already had them: a
            late-joiner reply holding nothing the live stream had not delivered, or a
            live payload that a delivered reply already held (a node that starts
            publishing a latched topic is queried while its first message is on the
            way; :meth:`~tfbus.transports.zenoh.sequence.SequenceTracker.reply_is_news`).
        malformed: payloads dropped because they were not well-formed tfbus messages
            (any decode failure: bad bytes, shape, nesting, stamps, ids).
        wrong_version: payloads dropped because of another wire format version.
        over_limit: payloads dropped because they broke a bound of
            :class:`~tfbus.codecs.native.WireLimits` (sizes, counts, nesting).
        overflow: entries dropped (oldest first) because the inbound queue was full.
        lost: gaps in publishers' sequence numbers (messages the network dropped);
            only plausible gaps count (:class:`~tfbus.transports.zenoh.sequence.SequenceTracker`).
        resets: implausible jumps of a publisher's sequence numbers (forged, corrupted
            or a restarted stream): reported here, never counted in ``lost``.
        batches: event-loop wake-ups that delivered queued entries.
        refused_keys: payloads dropped because their key is not the one spelling of a
            topic of the bus (a percent-encoded alias such as ``tfbus/r%31/tf`` of
            ``tfbus/r1/tf``; :func:`~tfbus.transports.zenoh.keys.parse_chunk`).
        refused_tokens: liveliness tokens ignored for the same reason.
        peers_over_limit: liveliness tokens ignored because the table of live nodes was
            full (``max_peers``), a node had ``max_topics`` topics already, or the node
            id was longer than :data:`~tfbus.transports.zenoh.peers.MAX_NODE_ID_LENGTH`.
        send_dropped: local messages tfbus dropped from its send queue because
            ``max_send_pending`` messages were already waiting (only with
            ``congestion_control="block"``). With ``"drop"`` (the default) Zenoh may
            drop ``/tf`` under congestion without telling the sender: those are not
            counted here, only by receivers, as ``lost``.
        send_merged: latched messages (``/tf_static``) merged into the latched
            snapshot still waiting to be sent (none of their transforms is lost).
        send_queued: messages waiting in the send queue when the copy was made.
        coalesced: samples of a newest-only topic (``/clock`` followed by a
            :class:`~tfbus.clock.SimClock`: :meth:`ZenohTransport.keep_newest`) replaced
            in Zenoh's thread by a newer one before the event loop saw them (never in
            ``received``).
    """

    not_connected: int = 0
    latched_replies: int = 0
    wrong_version: int = 0
    over_limit: int = 0
    overflow: int = 0
    lost: int = 0
    resets: int = 0
    batches: int = 0
    duplicates: int = 0
    refused_keys: int = 0
    refused_tokens: int = 0
    peers_over_limit: int = 0
    send_dropped: int = 0
    send_merged: int = 0
    send_queued: int = 0
    coalesced: int = 0

    @property
    def dropped(self) -> int:
        """All inbound payloads dropped: malformed + wrong_version + over_limit + overflow
        + refused_keys."""
        return (
            self.malformed + self.wrong_version + self.over_limit + self.overflow
            + self.refused_keys
        )
