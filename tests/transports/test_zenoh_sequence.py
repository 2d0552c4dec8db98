"""The per-publisher sequence numbers a Zenoh session receives
(:class:`tfbus.transports.zenoh.sequence.SequenceTracker`): only plausible gaps count as
lost, anything else is a reset, and a late-joiner reply is told from news. No network."""

from __future__ import annotations

import pytest

pytest.importorskip("zenoh")
from tfbus.transports.zenoh.sequence import SequenceTracker


def test_sequence_tracker_counts_only_plausible_gaps() -> None:
    """A forged sequence number pushed `lost` to 9e18; a gap counts as
    lost only when plausible, anything else is a reported reset."""
    tracker = SequenceTracker(max_gap=1000)
    assert tracker.observe(7, "/tf", 1) == (0, False)
    assert tracker.observe(7, "/tf", 2) == (0, False)
    assert tracker.observe(7, "/tf", 5) == (2, False)  # two lost
    assert tracker.observe(7, "/tf", 2**63 - 1) == (0, True)  # forged: a reset
    assert tracker.observe(7, "/tf", 6) == (0, True)  # back to the real stream: a reset
    assert tracker.observe(7, "/tf", 7) == (0, False)
    assert tracker.observe(7, "/tf", 7) == (0, True)  # a repeat is not a gap either
    assert tracker.observe(8, "/tf", 10**18) == (0, False)  # first from a sender: no gap
    assert tracker.observe(7, "/other", 1) == (0, False)
    small = SequenceTracker(max_senders=2)
    for sender in range(1, 10):
        small.observe(sender, "/tf", 1)
    assert len(small) <= 2


def test_sequence_tracker_tells_a_late_joiner_reply_from_news() -> None:
    """A node that starts publishing a latched topic is queried by its peers while its
    first message is on the way: the reply (numbered as the last payload sent) and the
    live payload both arrive. Each is delivered once, and a reply that may hold what the
    stream never delivered (joined late, or a gap) is delivered."""
    tracker = SequenceTracker()
    topic = "/tf_static"
    assert tracker.observe(7, topic, 1) == (0, False)
    assert tracker.live_is_news(7, topic, 1)
    assert not tracker.reply_is_news(7, topic, 1)  # 1..1 arrived live
    assert tracker.reply_is_news(7, topic, 2)  # the reply came first this time
    assert tracker.observe(7, topic, 2) == (0, False)
    assert not tracker.live_is_news(7, topic, 2)  # the reply held it
    assert tracker.observe(7, topic, 3) == (0, False) and tracker.live_is_news(7, topic, 3)
    assert not tracker.reply_is_news(7, topic, 3)
    # Joined late: first seen at 5, so a reply numbered 5 may hold what 1..4 sent.
    assert tracker.observe(8, topic, 5) == (0, False)
    assert tracker.reply_is_news(8, topic, 5)
    # A gap: 3 was lost, so a reply numbered 4 is news.
    for n in (1, 2, 4):
        tracker.observe(9, topic, n)
    assert tracker.reply_is_news(9, topic, 4)
    # A restarted stream (a reset) numbers from 1 again: its replies start over.
    assert tracker.reply_is_news(10, topic, 50)
    assert not tracker.live_is_news(10, topic, 50)
    assert tracker.observe(10, topic, 50) == (0, False)
    assert tracker.observe(10, topic, 1) == (0, True)
    assert tracker.live_is_news(10, topic, 1) and tracker.live_is_news(10, topic, 2)
    assert tracker.observe(10, topic, 2) == (0, False)
    assert not tracker.reply_is_news(10, topic, 2)  # 1..2 since the restart arrived live
    tracker.forget(10)
    assert tracker.reply_is_news(10, topic, 2)
    # Asked twice (the node appeared, then started publishing): the same reply twice,
    # before the live payload; one delivered. An older reply after it is not news either;
    # a newer one is.
    assert tracker.reply_is_news(11, topic, 1)
    assert not tracker.reply_is_news(11, topic, 1)
    assert tracker.observe(11, topic, 1) == (0, False)
    assert not tracker.live_is_news(11, topic, 1)
    assert tracker.reply_is_news(12, topic, 3) and not tracker.reply_is_news(12, topic, 2)
    assert tracker.reply_is_news(12, topic, 4)
    # A reply numbered 0 (asked while the first message waited to be put: nothing of the
    # stream yet) is remembered as delivered too.
    assert tracker.reply_is_news(13, topic, 0) and not tracker.reply_is_news(13, topic, 0)
    assert tracker.observe(13, topic, 1) == (0, False) and tracker.live_is_news(13, topic, 1)
    small = SequenceTracker(max_senders=2)
    for sender in range(1, 10):
        assert small.reply_is_news(sender, topic, 1)
    assert len(small.replied_seq) <= 2
