"""Fuzzing what a Zenoh peer can send: rmw_zenoh's attachments, liveliness tokens and
samples (:mod:`tfbus.transports.rmw_zenoh`), the key expressions a peer may publish on
(:mod:`tfbus.transports.zenoh.keys`), the per-sender sequence table, and -- the one live
test -- a burst of mutated payloads on ``/tf`` and on the buffer server's key of a running
:class:`~tfbus.bus.Bus` over Zenoh.

Inputs are valid ones mutated (:func:`mutate`: bits flipped, cut, extended, absurd lengths
spliced over or into them, runs swapped or repeated), driven by hypothesis
(``derandomize=True``) or, in the live test, by a seeded :class:`random.Random`.
Asserted: only the decoder's documented error escapes; receivers count every dropped
input and deliver the valid ones; tables stay bounded; after the burst the live bus still
delivers a valid transform and the server still answers a valid lookup.

The live test uses explicit 127.0.0.1 endpoints with multicast scouting off (the
transport's defaults, as ``test_zenoh.py``); every wait is bounded.
"""

from __future__ import annotations

import random
import socket
from typing import Any

import anyio
import pytest
from hypothesis import given
from hypothesis import strategies as st

zenoh = pytest.importorskip("zenoh")
msgspec = pytest.importorskip("msgspec")

from fuzz_support import fuzz, mutants, mutate  # noqa: E402

from tfbus.codecs import cdr  # noqa: E402
from tfbus.codecs import native as wire  # noqa: E402
from tfbus.errors import WireDecodeError, WireError  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.time import Time  # noqa: E402
from tfbus.transports.rmw_zenoh import wire as rmw  # noqa: E402
from tfbus.transports.zenoh.keys import KeySpace  # noqa: E402
from tfbus.transports.zenoh.sequence import SequenceTracker  # noqa: E402


def ts(parent: str, child: str, ns: int, x: float) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


# -- rmw_zenoh: attachments, tokens, received samples ---------------------------------------

GID = bytes(range(16))
_ATTACHMENTS = {
    form: rmw.encode_attachment(rmw.Attachment(7, 1_700_000_000_123_456_789, GID), form)
    for form in (rmw.ATTACHMENT_POSITIONAL, rmw.ATTACHMENT_LABELLED)
}


@fuzz(300)
@given(st.sampled_from(sorted(_ATTACHMENTS)).flatmap(lambda f: mutants(_ATTACHMENTS[f])))
def test_attachment_mutants_only_decode_errors(data: bytes) -> None:
    """Mutants of both attachment forms (33 and 77 bytes): an Attachment or a
    WireDecodeError; what decodes is written back byte for byte in its form."""
    try:
        got = rmw.decode_attachment(data)
    except WireDecodeError:
        return
    form = rmw.ATTACHMENT_POSITIONAL if len(data) == 33 else rmw.ATTACHMENT_LABELLED
    assert rmw.encode_attachment(got, form) == data
    assert len(got.gid) == rmw.GID_SIZE


_TOKENS = [
    rmw.endpoint_token(0, "aabbccdd00112233", 1, 2, "MP", "/robot1", "node", "/tf",
                       rmw.TF_QOS),
    rmw.endpoint_token(232, "ff", 12, 4_000_000_000, "MS", "/", "listener", "/tf_static",
                       rmw.TF_STATIC_LISTENER_QOS),
    rmw.node_token(7, "aabbccdd00112233", 3, "/", "robot_state_publisher"),
]
_CHUNK_JUNK = st.sampled_from(["", "*", "**", "$*", "#", "?", "%", "%%", "-1", "1" * 30,
                               "٣", "²", "NN", "MP", "SS", "SC", "ü", "\x00", " ", "a/b",
                               ":" * 5, ":::::", "x" * 3000])


@st.composite
def token_mutants(draw: st.DrawFn) -> str:
    """A valid token with chunks dropped, repeated, swapped or replaced by junk, or its
    UTF-8 bytes mutated (read back as Zenoh would: valid UTF-8, replacement characters)."""
    chunks = draw(st.sampled_from(_TOKENS)).split("/")
    if draw(st.booleans()):
        rng = draw(st.randoms(use_true_random=False))
        return mutate("/".join(chunks).encode(), rng).decode("utf-8", "replace")
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(chunks) - 1))
        op = draw(st.sampled_from(["junk", "drop", "repeat", "swap"]))
        if op == "junk":
            chunks[i] = draw(_CHUNK_JUNK)
        elif op == "drop" and len(chunks) > 1:
            del chunks[i]
        elif op == "repeat":
            chunks.insert(i, chunks[i])
        else:
            j = draw(st.integers(0, len(chunks) - 1))
            chunks[i], chunks[j] = chunks[j], chunks[i]
    return "/".join(chunks)


@fuzz(300)
@given(token_mutants())
def test_token_mutants_only_decode_errors(key: str) -> None:
    """Mutated liveliness tokens: an EndpointToken as rmw_zenoh's graph cache reads it
    (``Entity::make``: 9 chunks for a node, 13 for an endpoint, a known kind, a decimal
    domain) or a WireDecodeError, never anything else."""
    try:
        token = rmw.parse_token(key)
    except WireDecodeError:
        return
    parts = key.split("/")
    assert parts[0] == rmw.ADMIN_SPACE and token.kind in ("NN", "MP", "MS", "SS", "SC")
    assert len(parts) == (9 if token.kind == "NN" else 13)
    assert token.domain_id == int(parts[1]) and str(token.domain_id).isascii()
    assert all(parts) and not any(c in key for c in "*$?#")


class _Recorder:
    """The bus as a transport sees it (:class:`~tfbus.transports._base.BusLike`): what
    was delivered, by topic."""

    def __init__(self) -> None:
        self.delivered: list[tuple[str, object]] = []

    def deliver_nowait(self, topic: str, message: object) -> None:
        self.delivered.append((topic, message))

    def deliver_many_nowait(self, topic: str, messages: Any) -> None:
        for m in messages:
            self.deliver_nowait(topic, m)

    def reaches(self, topic: str) -> bool:
        return True


_RMW_TF = cdr.encode_tf([ts("odom", "base_link", 1_700_000_000_000_000_000, 1.0),
                         ts("map", "odom", 5, 2.0)])


@fuzz(60)
@given(st.lists(st.tuples(st.sampled_from(["sample", "attachment", "key", "token"]),
                          st.randoms(use_true_random=False)), min_size=1, max_size=30))
def test_rmw_zenoh_receiver_counts_every_bad_input(inputs: list[tuple[str, Any]]) -> None:
    """An rmw_zenoh transport's receive path (what its event loop runs for each sample and
    token Zenoh delivers) fed mutated samples, attachments, keys and tokens: every sample
    is delivered or counted once (malformed, bad_attachment, ...), a valid sample after
    them is delivered, the graph never holds more than ``max_tokens`` tokens' nodes."""
    from tfbus.transports.rmw_zenoh import RmwZenohTransport

    transport = RmwZenohTransport(connect="tcp/127.0.0.1:7447", max_tokens=8)  # never opened
    bus = _Recorder()
    key = transport.data_key("/tf")
    attachment = _ATTACHMENTS[rmw.ATTACHMENT_POSITIONAL]
    samples = 0
    for kind, rng in inputs:
        if kind == "token":
            token = mutate(_TOKENS[rng.randrange(3)].encode(), rng).decode("utf-8", "replace")
            transport._graph_update(rng.random() < 0.8, token)
            continue
        samples += 1
        transport._receive(
            bus, mutate(key.encode(), rng).decode("utf-8", "replace") if kind == "key" else key,
            mutate(_RMW_TF, rng) if kind == "sample" else _RMW_TF,
            mutate(attachment, rng) if kind == "attachment" else attachment)
    transport._receive(bus, key, _RMW_TF, attachment)
    s = transport.statistics()
    assert s.received == samples + 1
    assert s.delivered + s.malformed + s.bad_attachment + s.no_attachment == s.received
    assert bus.delivered[-1] == ("/tf", cdr.decode_tf(_RMW_TF))
    assert len(bus.delivered) == s.delivered
    assert len(transport.alive()) <= 8


# -- tfbus's Zenoh keys and sequence numbers -----------------------------------------------

_SPACE = KeySpace("tfbus", "robot1")
_KEYS = [_SPACE.data("/tf"), _SPACE.data("/tf_static"), _SPACE.data("/a b/ü"),
         _SPACE.latch("0123abcd", "/tf_static"), _SPACE.alive("0123abcd", "node", "/tf"),
         _SPACE.alive("0123abcd", "")]


@fuzz(300)
@given(st.sampled_from(_KEYS).flatmap(
    lambda k: mutants(k.encode()).map(lambda b: b.decode("utf-8", "replace"))))
def test_key_mutants_map_to_one_topic_or_none(key: str) -> None:
    """A key a peer publishes on (any valid UTF-8, as Zenoh delivers keys): its topic, read
    only from the one canonical spelling (the topic's own key is the key again), or None;
    a liveliness key likewise; never an exception."""
    topic = _SPACE.topic_of(key)
    if topic is not None:
        assert _SPACE.data(topic) == key
    latched = _SPACE.topic_of(key, reply=True)
    if latched is not None:
        node = key.split("/")[3]
        assert _SPACE.latch(node, latched) == key
    alive = _SPACE.parse_alive(key)
    if alive is not None:
        assert _SPACE.alive(alive.node_id, alive.name, alive.topic) == key


@fuzz(30)
@given(st.lists(st.tuples(st.integers(1, 2**63 - 1), st.integers(1, 2**63 - 1)),
                min_size=50, max_size=300))
def test_sequence_table_stays_bounded(streams: list[tuple[int, int]]) -> None:
    """Forged sender ids and numbers (what mutated payloads carry): the table of streams
    keeps at most ``max_senders``, a forward jump beyond ``max_gap`` is a reset and not
    billions lost."""
    seqs = SequenceTracker(max_gap=100, max_senders=16)
    lost = 0
    for sender, seq in streams:
        n, _reset = seqs.observe(sender, "/tf", seq)
        lost += n
        assert len(seqs) <= 16
    assert lost <= 100 * len(streams)


# -- live: a bus over Zenoh under a burst of mutated payloads -------------------------------


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


BURST = 300
QUERIES = 60


@pytest.mark.anyio
async def test_bus_and_buffer_server_survive_a_burst_of_mutants(anyio_backend: str) -> None:
    """A peer puts 300 mutants of valid payloads (a TFMessage, a LaserScan, a plain map)
    on ``tfbus/tf`` and sends 60 mutants of a valid request to the buffer server's key.
    Every payload the wire codec refuses is counted (malformed, wrong_version,
    over_limit: exactly the codec's verdicts), every request that is not a map is counted
    malformed and left unanswered; then a valid transform put by the peer arrives, a
    thin client's valid lookup is answered (x = 1.5), and the transport still runs."""
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.errors import WireLimitError, WireVersionError
    from tfbus.remote import BufferClient, BufferServer
    from tfbus.sensor_msgs import LaserScan
    from tfbus.transports.zenoh import ZenohTransport, zenoh_config

    rng = random.Random(20240611)
    codec = wire.WireCodec()
    import numpy as np

    scan = LaserScan(Header(Time.from_ns(5), "laser"), -1.0, 1.0, 0.5, 0.0, 0.1, 0.1, 30.0,
                     np.ones(5, dtype=np.float32), np.zeros(5, dtype=np.float32))
    valid = [codec.encode(TFMessage((ts("map", "odom", 7, 1.0),)), sender=5, seq=1),
             codec.encode(scan, sender=5, seq=2),
             codec.encode({"op": "lookup", "target": "map"}, sender=5, seq=3)]
    burst = [mutate(valid[i % 3], rng) for i in range(BURST)]
    verdict = {"malformed": 0, "wrong_version": 0, "over_limit": 0}
    for data in burst:
        try:
            codec.decode(data)
        except WireVersionError:
            verdict["wrong_version"] += 1
        except WireLimitError:
            verdict["over_limit"] += 1
        except WireError:
            verdict["malformed"] += 1
    request = codec.encode({"op": "lookup", "target": "map", "source": "base", "time": 0,
                            "timeout": 0.0, "query_timeout": 2.0}, sender=5, seq=1)
    queries = [mutate(request, rng) for _ in range(QUERIES)]
    not_maps = 0
    for data in queries:
        try:
            not_maps += not isinstance(codec.decode(data).message, dict)
        except WireError:
            not_maps += 1
    assert verdict["malformed"] > 50 and not_maps > 20  # the mutants reach the decoder

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    buffer = Buffer()
    buffer.set_transform_static(ts("map", "base", 0, 1.5), "test")
    transport = ZenohTransport(listen=endpoint, name="victim")
    cfg, _ = zenoh_config(connect=endpoint)
    async with Bus(transport=transport) as bus, \
            BufferServer(buffer, bus, max_wait=2.0) as server, \
            Bus(transport=ZenohTransport(connect=endpoint, name="thin", topics=())) as thin:
        sub = bus.subscribe("/tf")
        session = await anyio.to_thread.run_sync(zenoh.open, cfg)
        try:
            raw = session.declare_publisher("tfbus/tf",
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            with anyio.fail_after(10):
                while not raw.matching_status.matching:
                    await anyio.sleep(0.01)

            def send_all() -> int:
                for data in burst:
                    raw.put(data)
                handlers = [session.get(server.where, payload=q, timeout=5.0)
                            for q in queries]
                return sum(1 for h in handlers for _reply in h)  # each ends by 5 s

            replies = await anyio.to_thread.run_sync(send_all)
            raw.put(codec.encode(TFMessage((ts("map", "after-burst", 9, 2.0),)),
                                 sender=77, seq=1))
            with anyio.fail_after(10):
                while True:
                    message = await sub.receive()
                    # a mutant may still decode (to a TFMessage, a LaserScan, a map: the
                    # bus carries any type; TransformListener drops what is not a
                    # TFMessage): wait for the valid one
                    if isinstance(message, TFMessage) and message.transforms and \
                            message.transforms[0].child_frame_id == "after-burst":
                        break
            assert message.transforms[0].transform.translation.x == 2.0
            client = BufferClient(thin, timeout_padding=5.0)
            with anyio.fail_after(15):
                while True:  # the queryable reaches the thin client: wait for one answer
                    try:
                        answer = await client.lookup_transform("map", "base", Time(0), 0.0)
                        break
                    except Exception:
                        await anyio.sleep(0.05)
            assert answer.transform.translation.x == 1.5
        finally:
            await anyio.to_thread.run_sync(session.close)
        stats = transport.statistics()
        assert stats.overflow == 0
        assert (stats.malformed, stats.wrong_version, stats.over_limit) == (
            verdict["malformed"], verdict["wrong_version"], verdict["over_limit"])
        assert stats.received == BURST + 1
        served = server.statistics()
        assert served.malformed == not_maps
        assert replies == QUERIES - not_maps  # every map got an answer, the rest none
        assert served.pending == 0 and transport.running
