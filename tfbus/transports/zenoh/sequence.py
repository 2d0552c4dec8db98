"""Per-publisher sequence numbers of the payloads a Zenoh session received: messages
lost, resets, and late-joiner replies told from news (:class:`SequenceTracker`).

The numbers themselves are written by the wire format (:mod:`tfbus.codecs.native`: every
payload carries its sender's id and its number on the topic); what a receiving session
remembers of them is the transport's state, kept here. Synchronous and free of I/O.
"""

from __future__ import annotations

__all__ = ["SequenceTracker"]


class SequenceTracker:
    """Per-publisher sequence numbers of received payloads: messages lost, and resets.

    Every ``(sender, topic)`` stream numbers its payloads 1, 2, ...; a receiver learns
    from the gaps how many the network dropped. A forged or corrupted number must not
    turn into billions of "lost" messages: a forward jump of at most
    ``max_gap`` counts as that many lost; anything else (a larger jump, a step back, a
    repeat) is a *reset* -- reported, not counted as loss -- and the stream resumes from
    the new number. The table keeps at most ``max_senders`` streams (it is cleared when
    full, which only means the next payload of each stream starts it again).

    It also tells a late-joiner reply (the sender's latched payload, which carries the
    number of the last payload it handed to Zenoh on that topic and holds what payloads
    1..n of it held) from news: a reply numbered ``n`` repeats what a stream already
    delivered when every payload 1..n of it arrived live, or when a reply numbered
    ``n`` or later was delivered (a node answers every query that reaches it, so a
    receiver that asks twice, when the node appears and when it starts publishing a
    latched topic, gets the same reply twice) (:meth:`reply_is_news`); a live payload
    numbered ``n`` or less repeats what a reply numbered ``n`` delivered
    (:meth:`live_is_news`). A reply and a live payload travel different routes, so a
    receiver that joins while a latched topic is published gets both; ROS 1 latching
    (sent on connect, then the stream) and DDS transient-local durability
    (deduplicated by writer sequence numbers) deliver such a message once. A payload
    that reached no subscriber does not count as delivered (:meth:`unseen`): a
    subscriber that came after it still gets the reply.
    """

    def __init__(self, max_gap: int = 100_000, max_senders: int = 4096) -> None:
        """Raises: ValueError: if ``max_gap`` or ``max_senders`` is less than 1."""
        if max_gap < 1 or max_senders < 1:
            raise ValueError("max_gap and max_senders must be at least 1")
        self.max_gap = max_gap
        self.max_senders = max_senders
        self.last_seq: dict[tuple[int, str], int] = {}
        """The last number received of each stream ``(sender, topic)``."""
        self._whole: set[tuple[int, str]] = set()  # streams received 1, 2, ... without a gap
        self.replied_seq: dict[tuple[int, str], int] = {}
        """The number of the last reply delivered of each stream that had one. A
        receive loop that finds a live payload numbered ``last_seq + 1`` of a stream
        whose ``replied_seq`` is lower (or absent) may store its number in ``last_seq``
        itself: what :meth:`observe` and :meth:`live_is_news` do with it."""

    def observe(self, sender: int, topic: str, seq: int) -> tuple[int, bool]:
        """Record ``seq`` of the stream ``(sender, topic)``: ``(lost, reset)``.

        ``lost`` is how many numbers were skipped since the previous one (0 when in
        order or at the stream's start); ``reset`` is True when the step is implausible.
        """
        key = (sender, topic)
        table = self.last_seq
        last = table.get(key)
        if last is None:
            if len(table) >= self.max_senders:
                self._clear()
            table[key] = seq
            if seq == 1:
                self._whole.add(key)
            return 0, False
        table[key] = seq
        step = seq - last
        if step == 1:
            return 0, False
        self._whole.discard(key)
        if 1 < step <= self.max_gap + 1:
            return step - 1, False
        self.replied_seq.pop(key, None)  # a restarted stream numbers from 1 again
        if seq == 1:
            self._whole.add(key)
        return 0, True

    def reply_is_news(self, sender: int, topic: str, seq: int) -> bool:
        """Whether a late-joiner reply numbered ``seq`` may hold something not yet
        delivered: False when payloads 1..seq all arrived live or a reply numbered
        ``seq`` or later was delivered; a reply that is news is remembered for
        :meth:`live_is_news` and the next replies."""
        key = (sender, topic)
        if key in self._whole and self.last_seq[key] >= seq:
            return False
        replied = self.replied_seq.get(key)
        if replied is not None and seq <= replied:
            return False
        if len(self.replied_seq) >= self.max_senders:
            self.replied_seq.clear()
        self.replied_seq[key] = seq
        return True

    def live_is_news(self, sender: int, topic: str, seq: int) -> bool:
        """Whether a live payload numbered ``seq`` (already :meth:`observe` d) is not
        one that a delivered reply already held (numbered ``seq`` or later)."""
        return seq > self.replied_seq.get((sender, topic), 0)

    def unseen(self, sender: int, topic: str) -> None:
        """A payload of the stream ``(sender, topic)`` reached no one (nothing was
        subscribed to ``topic`` yet): what the stream delivered no longer makes a later
        copy a duplicate, so a reply or live payload carrying it is news again."""
        key = (sender, topic)
        self._whole.discard(key)
        self.replied_seq.pop(key, None)

    def forget(self, sender: int) -> None:
        """Drop every stream of ``sender`` (e.g. when that node went away)."""
        for key in [k for k in self.last_seq if k[0] == sender]:
            del self.last_seq[key]
            self._whole.discard(key)
        for key in [k for k in self.replied_seq if k[0] == sender]:
            del self.replied_seq[key]

    def _clear(self) -> None:
        self.last_seq.clear()
        self._whole.clear()
        self.replied_seq.clear()

    def __len__(self) -> int:
        """The number of streams tracked now."""
        return len(self.last_seq)
