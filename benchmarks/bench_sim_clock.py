"""Benchmark simulated time: what following ``/clock`` costs, and how late a sim-time
wake-up is.

    .venv/bin/python benchmarks/bench_sim_clock.py [--bus zenoh|ros1|ros2] [--hz 1000]
        [--seconds 5] [--quick] [--backend asyncio|trio]

A publisher process (this script, ``--role publisher``) sends ``rosgraph_msgs/Clock`` on
``/clock`` at ``--hz``, one simulated step of ``1/hz`` s per message (real time), on
absolute deadlines, over ``--bus``: Zenoh (127.0.0.1, explicit endpoints, multicast
scouting off; the default), ROS 1 (a roscore started on 127.0.0.1 with ROS_IP=127.0.0.1,
as the ROS 1 tests start it; the publisher is a tfbus ``Ros1Transport`` node sending raw
``rosgraph_msgs/Clock`` frames over TCPROS) or ROS 2 (Cyclone DDS through tfbus's
``Ros2Transport``, loopback only, a random domain id). This process follows it with a
:class:`tfbus.SimClock` on its own bus (``clock_topic="/clock"`` on ROS 1 and ROS 2) and
prints:

1. **CPU cost of /clock at HZ**: this process's CPU time (``time.process_time``: every
   thread, Zenoh's included) per second of wall time over ``--seconds``, with the
   publisher sending, minus the same with a publisher that sends nothing (the idle bus):
   the share of one core that following ``/clock`` costs. Target: under 2 % at 1 kHz.
   Over Zenoh a SimClock follows ``/clock`` newest-only (Zenoh's thread keeps the newest
   sample and wakes the event loop at a deadline, a jump back, or every 10 ms): its
   "received" rate is what the loop saw; a no-op subscriber gets every message.
2. **Sim-time wake-up lateness**: ``clock.sleep_until(d)`` for deadlines ``d`` falling
   between two ``/clock`` steps (10.5 steps ahead, then 10.25, 10.75, ...); each wake-up
   is measured as ``clock.now() - d`` in ``/clock`` steps: woken by the first message at
   or after ``d`` it is below 1 (within one ``/clock`` message of its deadline).
   Target: max below 1 step.

3. **Raw zenoh-python at HZ, in the same run** (no tfbus): a publisher process putting
   8-byte payloads at ``--hz`` and a subscriber process measuring its own CPU share the
   same way, with (a) an idle session (nothing sent), (b) a no-op Python callback per
   sample (what tfbus's transport declares), (c) a ``RingChannel`` handler polled 100
   times a second (no Python per sample at all: the cost of Zenoh's own receive
   threads), (d) (b) run in Zenoh's own thread (``Callback(..., indirect=False)``: no
   Python thread of zenoh-python's in between), (e) (b) with ``ZENOH_RUNTIME`` giving
   every Zenoh runtime one worker thread, (f) (b) with Zenoh's
   ``transport/unicast/lowlatency`` (QoS off) on both sides.
   These are the floor any zenoh-python subscriber pays; ``--no-raw`` leaves them out.
   On ROS 1 and ROS 2 the floor is instead a bare reader process of the same tfbus
   publisher, with no tfbus code per message, idle and at ``--hz``: ROS 1 a TCPROS
   subscriber made by hand (``registerSubscriber``, ``requestTopic``, the connection
   header, a ``recv`` per wake-up of a reader thread, ``struct`` per frame); ROS 2 a
   cyclonedds ``DataReader`` with the ``/clock`` QoS whose listener takes raw samples.

Figures only: nothing here asserts a timing (a loaded machine shows it in the figures).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import anyio.to_thread

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tfbus import Bus, SimClock, Time
from tfbus.messages import Clock
from tfbus.topics import CLOCK_TOPIC
from tfbus.transports.zenoh import ZenohTransport

START = Time(100)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def make_transport(bus: str, at: str, role: str, clock: bool = True) -> Any:
    """A transport on ``bus`` (``zenoh``: ``at`` is the port, the publisher listens;
    ``ros1``: ``at`` is the master URI; ``ros2``: ``at`` is the domain id), named after
    ``role``; ``clock``: it carries ``/clock`` (what a SimClock follows)."""
    if bus == "zenoh":
        side = "listen" if role == "publisher" else "connect"
        return ZenohTransport(**{side: f"tcp/127.0.0.1:{at}"}, name=f"sim_clock_{role}")
    if bus == "ros1":
        from tfbus.transports.ros1 import Ros1Transport

        return Ros1Transport(master_uri=at, host="127.0.0.1",
                             node_name=f"/sim_clock_{role}_{os.getpid()}",
                             clock_topic=CLOCK_TOPIC if clock else None)
    from tfbus.transports.ros2 import Ros2Transport

    return Ros2Transport(domain_id=int(at), clock_topic=CLOCK_TOPIC)


async def publisher(bus_kind: str, at: str, hz: float, seconds: float) -> None:
    """Publish /clock at ``hz`` (0: nothing) for ``seconds`` once a subscriber matches
    (Zenoh, ROS 1; on ROS 2 at once: best effort, a reader that matches later misses
    the first ones)."""
    transport = make_transport(bus_kind, at, "publisher", clock=False)
    async with Bus(transport=transport) as bus:
        send: Any = None
        if bus_kind == "ros1":
            from tfbus.codecs.ros1 import CLOCK_MD5SUM, CLOCK_TYPE, encode_clock

            transport.advertise_raw(CLOCK_TOPIC, CLOCK_TYPE, CLOCK_MD5SUM)

            def send(message: Clock) -> None:
                transport.send_raw_nowait(CLOCK_TOPIC, encode_clock(message))
        else:
            def send(message: Clock) -> None:
                bus.publish_nowait(CLOCK_TOPIC, message)
        print("LISTENING", flush=True)
        with anyio.fail_after(60):
            if bus_kind == "zenoh":
                await transport.wait_matching(CLOCK_TOPIC)
            elif bus_kind == "ros1":
                while transport.connections(CLOCK_TOPIC)[1] == 0:
                    await anyio.sleep(0.05)  # bounded by fail_after
        if hz <= 0:
            await anyio.sleep(seconds)
            return
        step_ns = round(1e9 / hz)
        t0 = anyio.current_time()
        for k in range(int(seconds * hz)):
            send(Clock(Time.from_ns(START.ns + k * step_ns)))
            await anyio.sleep(max(0.0, t0 + (k + 1) / hz - anyio.current_time()))


def start_publisher(bus: str, at: str, hz: float, seconds: float) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, __file__, "--role", "publisher", "--bus", bus, "--at", at,
         "--hz", str(hz), "--seconds", str(seconds)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if line.strip() != "LISTENING":
        proc.kill()
        raise RuntimeError(f"the publisher did not start: {line!r}")
    return proc


async def follow(bus_kind: str, at: str, hz: float, seconds: float, wakeups: int,
                 sim_clock: bool = True) -> dict[str, float]:
    """Follow a publisher at ``hz`` on ``bus_kind`` (``at``: :func:`make_transport`):
    CPU share over ``seconds``, then wake-up lateness (``sim_clock`` False: a no-op
    subscriber on /clock instead of the SimClock, which is the cost of receiving the
    topic alone)."""
    settle = 1.5
    extra = (wakeups * 12 / hz + 5.0) if hz > 0 else 0.0
    connect = 0.0 if bus_kind == "zenoh" else 60.0  # ROS: the first /clock is awaited
    proc = start_publisher(bus_kind, at, hz, settle + seconds + extra + connect + 2.0)
    result: dict[str, float] = {}
    try:
        transport = make_transport(bus_kind, at, "follower")
        async with Bus(transport=transport) as bus, SimClock(bus) as clock:
            counted = [0]
            if not sim_clock:
                await clock.__aexit__(None, None, None)  # unsubscribed: a no-op one instead

                def count(message: object) -> None:
                    counted[0] += 1

                bus.subscribe_callback(CLOCK_TOPIC, count)

            def received() -> int:
                return clock.received if sim_clock else counted[0]

            if hz > 0 and bus_kind != "zenoh":  # matched once the first /clock arrives
                with anyio.fail_after(connect):
                    while received() == 0:
                        await anyio.sleep(0.05)  # bounded by fail_after
            await anyio.sleep(settle)
            received0 = received()
            wall0, cpu0, threads0 = time.perf_counter(), time.process_time(), thread_times()
            await anyio.sleep(seconds)
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            threads = _shares(threads0, thread_times(), wall)
            result["cpu_share"] = cpu / wall
            result.update({f"threads_{k}": v for k, v in threads.items()})
            result["rate"] = (received() - received0) / wall
            if hz > 0 and wakeups:
                step_ns = round(1e9 / hz)
                late: list[float] = []  # at the wake-up, inside the /clock delivery
                resumed: list[float] = []  # when the sleeping task ran again
                fractions = (0.5, 0.25, 0.75, 0.1, 0.9)
                with anyio.fail_after(extra + 30):
                    for i in range(wakeups):
                        ahead = (10 + fractions[i % 5]) * step_ns / 1e9
                        deadline = clock.now_ns() + round(ahead * 1e9)
                        woke = anyio.Event()

                        def wake(deadline: int = deadline, woke: anyio.Event = woke) -> None:
                            late.append((clock.now_ns() - deadline) / step_ns)
                            woke.set()

                        clock.call_later(ahead, wake)
                        await clock.sleep_until(Time.from_ns(deadline))
                        resumed.append((clock.now_ns() - deadline) / step_ns)
                        await woke.wait()
                for name, values in (("late", late), ("resumed", resumed)):
                    result[f"{name}_median"] = statistics.median(values)
                    result[f"{name}_max"] = max(values)
                    result[f"{name}_min"] = min(values)
            result["dropped"] = clock.dropped
            result["jumps"] = clock.jumps
    finally:
        proc.kill()
        proc.wait(timeout=10)
    return result


ONE_THREAD_RUNTIME = ", ".join(
    f"{name}: (worker_threads: 1, max_blocking_threads: 1)"
    for name in ("app", "acc", "tx", "rx", "net")
)
RAW_VARIANTS: tuple[tuple[str, str, dict[str, str], str], ...] = (
    # (label, subscriber mode, environment, extra zenoh config "key=json5;...")
    ("idle session, nothing sent", "idle", {}, ""),
    ("a no-op Python callback per sample", "callback", {}, ""),
    ("RingChannel polled at 100 Hz (no Python per sample)", "ring", {}, ""),
    ("no-op callback in Zenoh's thread (indirect=False)", "direct", {}, ""),
    ("callback, ZENOH_RUNTIME one worker thread each", "callback",
     {"ZENOH_RUNTIME": f"({ONE_THREAD_RUNTIME})"}, ""),
    ("callback, transport/unicast/lowlatency", "callback", {},
     "transport/unicast/lowlatency=true;transport/unicast/qos/enabled=false"),
)


def _raw_config(port: int, listen: bool, extra: str) -> object:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    side = "listen" if listen else "connect"
    config.insert_json5(f"{side}/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    for item in filter(None, extra.split(";")):
        key, value = item.split("=", 1)
        config.insert_json5(key, value)
    return config


def raw_publisher(port: int, hz: float, seconds: float, extra: str) -> None:
    """zenoh-python alone: put 8 bytes on ``bench/clock`` at ``hz`` for ``seconds``."""
    import zenoh

    session = zenoh.open(_raw_config(port, True, extra))  # type: ignore[arg-type]
    publisher = session.declare_publisher("bench/clock")
    print("LISTENING", flush=True)
    time.sleep(1.0)
    if hz <= 0:
        time.sleep(seconds)
    t0 = time.monotonic()
    for k in range(int(seconds * hz) if hz > 0 else 0):
        publisher.put(k.to_bytes(8, "little"))
        time.sleep(max(0.0, t0 + (k + 1) / hz - time.monotonic()))
    session.close()  # type: ignore[no-untyped-call]


def raw_subscriber(port: int, mode: str, seconds: float, extra: str) -> None:
    """zenoh-python alone: receive ``bench/clock`` (``mode``: callback / ring / idle)
    and print this process's CPU share over ``seconds`` as one JSON line."""
    import threading

    import zenoh

    session = zenoh.open(_raw_config(port, False, extra))  # type: ignore[arg-type]
    count = [0]
    stop = threading.Event()
    if mode == "ring":
        subscriber: object = session.declare_subscriber(
            "bench/clock", zenoh.handlers.RingChannel(64))

        def poll() -> None:
            while not stop.wait(0.01):
                while subscriber.try_recv() is not None:  # type: ignore[attr-defined]
                    count[0] += 1

        threading.Thread(target=poll, daemon=True).start()
    else:
        def on_sample(_sample: object) -> None:
            count[0] += 1

        handler: object = on_sample
        if mode == "direct":  # no Python thread of zenoh-python's between Zenoh and us
            handler = zenoh.handlers.Callback(on_sample, indirect=False)
        subscriber = session.declare_subscriber("bench/clock", handler)  # type: ignore[call-overload]
    time.sleep(1.5)
    n0, wall0, cpu0 = count[0], time.perf_counter(), time.process_time()
    time.sleep(seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    stop.set()
    print(json.dumps({"cpu_share": cpu / wall, "rate": (count[0] - n0) / wall}), flush=True)
    os._exit(0)  # no teardown: the figure is printed


def raw(hz: float, seconds: float, mode: str, env: dict[str, str], extra: str) -> dict[str, float]:
    """One raw zenoh-python measurement: publisher and subscriber processes."""
    port = free_port()
    pub = subprocess.Popen(
        [sys.executable, __file__, "--role", "raw-publisher", "--port", str(port), "--hz",
         str(0.0 if mode == "idle" else hz), "--seconds", str(seconds + 6), "--zenoh", extra],
        stdout=subprocess.PIPE, text=True, env={**os.environ, **env},
    )  # fmt: skip
    try:
        assert pub.stdout is not None
        if pub.stdout.readline().strip() != "LISTENING":
            raise RuntimeError("the raw publisher did not start")
        sub = subprocess.run(
            [sys.executable, __file__, "--role", "raw-subscriber", "--port", str(port),
             "--mode", mode, "--seconds", str(seconds), "--zenoh", extra],
            capture_output=True, text=True, env={**os.environ, **env}, timeout=seconds + 60,
        )  # fmt: skip
        return dict(json.loads(sub.stdout.strip().splitlines()[-1]))
    finally:
        pub.kill()
        pub.wait(timeout=10)


def ros1_floor_reader(master_uri: str, busy: bool, seconds: float) -> None:
    """The ROS 1 floor (no tfbus per message): a bare TCPROS subscriber of /clock --
    ``registerSubscriber`` at the master, ``requestTopic`` at the publisher, the
    connection header, then one ``recv`` per wake-up of a reader thread and each
    8-byte ``rosgraph_msgs/Clock`` frame unpacked with ``struct``. Prints this
    process's CPU share over ``seconds`` as one JSON line (``busy``: once the first
    message arrived)."""
    import struct
    import threading
    import xmlrpc.client

    from tfbus.codecs.ros1 import CLOCK_MD5SUM, CLOCK_TYPE

    caller = f"/sim_clock_floor_{os.getpid()}"
    master = xmlrpc.client.ServerProxy(master_uri)
    deadline = time.monotonic() + 60
    while True:  # the publisher registered before us: its URI is in the answer
        _code, _status, uris = master.registerSubscriber(  # type: ignore[misc]
            caller, CLOCK_TOPIC, CLOCK_TYPE, "http://127.0.0.1:9/")
        if uris or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    for uri in reversed(uris):  # publishers of earlier runs (ended) may still be listed
        try:
            _code, _status, proto = xmlrpc.client.ServerProxy(uri).requestTopic(  # type: ignore[misc]
                caller, CLOCK_TOPIC, [["TCPROS"]])
            break
        except OSError:
            continue
    else:
        raise RuntimeError(f"no /clock publisher answers: {uris}")
    sock = socket.create_connection((proto[1], proto[2]), timeout=60)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    fields = {"callerid": caller, "topic": CLOCK_TOPIC, "type": CLOCK_TYPE,
              "md5sum": CLOCK_MD5SUM, "tcp_nodelay": "1"}
    body = b"".join(len(f).to_bytes(4, "little") + f
                    for f in (f"{k}={v}".encode() for k, v in fields.items()))
    sock.sendall(len(body).to_bytes(4, "little") + body)
    count = [-1]  # the publisher's connection header is the first frame
    first = threading.Event()
    unpack = struct.Struct("<II").unpack_from

    def read() -> None:
        buf = b""
        while data := sock.recv(65536):
            buf += data
            pos = 0
            while len(buf) - pos >= 4:
                n = int.from_bytes(buf[pos:pos + 4], "little")
                if len(buf) - pos - 4 < n:
                    break
                if count[0] >= 0:
                    unpack(buf, pos + 4)  # secs, nsecs
                    first.set()
                count[0] += 1
                pos += 4 + n
            buf = buf[pos:]

    threading.Thread(target=read, daemon=True).start()
    if busy and not first.wait(60):
        raise RuntimeError("no /clock within 60 s")
    _measure(count, seconds)


def ros2_floor_reader(domain_id: int, busy: bool, seconds: float) -> None:
    """The ROS 2 floor (no tfbus per message): a bare cyclonedds reader of ``rt/clock``
    with the ``/clock`` reader QoS (best effort, keep-last 1) whose
    ``on_data_available`` listener takes the raw samples in Cyclone's thread and
    unpacks each ``sec``/``nanosec`` with ``struct``. Prints this process's CPU share
    over ``seconds`` as one JSON line (``busy``: once the first message arrived)."""
    import struct
    import threading

    from cyclonedds import _clayer
    from cyclonedds.core import Listener
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from tfbus.transports.ros2.dds import Clock_, cyclone_config
    from tfbus.transports.ros2.transport import _ANY_STATE, CLOCK_READER_QOS

    domain = Domain(domain_id, cyclone_config())
    participant = DomainParticipant(domain_id)
    count = [0]
    first = threading.Event()
    unpack = struct.Struct("<iI").unpack_from

    def on_data(reader: Any) -> None:
        samples = _clayer.ddspy_take(reader._ref, _ANY_STATE, 64)
        if isinstance(samples, int):
            return
        for data, info in samples:
            if info.valid_data:
                unpack(data, 4)  # after the 4-byte CDR encapsulation header
                count[0] += 1
        first.set()

    topic = Topic(participant, "rt/clock", Clock_)
    reader = DataReader(participant, topic, CLOCK_READER_QOS,
                        listener=Listener(on_data_available=on_data))  # type: ignore[no-untyped-call]
    if busy and not first.wait(60):
        raise RuntimeError("no /clock within 60 s")
    _measure(count, seconds)
    del reader, domain


def zenoh_floor_reader(port: int, busy: bool, seconds: float) -> None:
    """The Zenoh floor (no tfbus per message): a raw zenoh-python session configured as
    ``ZenohTransport`` configures itself (:func:`~tfbus.transports.zenoh.config.zenoh_config`:
    peer mode, multicast scouting off, connecting to the publisher at 127.0.0.1) whose
    subscriber on the tfbus publisher's ``/clock`` key counts each sample in a no-op
    Python callback. Prints this process's CPU share over ``seconds`` as one JSON line
    (``busy``: once the first sample arrived)."""
    import threading

    import zenoh

    from tfbus.transports.zenoh.config import zenoh_config
    from tfbus.transports.zenoh.keys import KeySpace

    config, _fallback = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    session = zenoh.open(config)
    count = [0]
    first = threading.Event()

    def on_sample(_sample: object) -> None:
        count[0] += 1
        first.set()

    subscriber = session.declare_subscriber(KeySpace().data(CLOCK_TOPIC), on_sample)
    if busy and not first.wait(60):
        raise RuntimeError("no /clock within 60 s")
    _measure(count, seconds)
    del subscriber


THREAD_KINDS = ("main", "python", "middleware")
"""How :func:`thread_times` groups a process's threads: ``main`` (the main thread: a
follower's event loop; a bare reader's main thread only sleeps), ``python`` (other threads
named ``python``: the middleware's Python callback threads, a bare reader's reading
thread, anyio's worker threads) and ``middleware`` (threads the middleware named: Zenoh's
``rx-N`` / ``net-N`` / ``tx-N``, Cyclone's ``recvUC`` / ``tev`` / ...)."""


def thread_times() -> dict[str, int]:
    """This process's live threads' scheduler run time so far, in ns, by kind
    (:data:`THREAD_KINDS`; ``proc_cpu.thread_run_ns``)."""
    from proc_cpu import thread_run_ns

    pid = str(os.getpid())
    out = dict.fromkeys(THREAD_KINDS, 0)
    for tid, (comm, ns) in thread_run_ns(os.getpid()).items():
        kind = "main" if tid == pid else "python" if comm.startswith("python") else "middleware"
        out[kind] += ns
    return out


def _shares(before: dict[str, int], after: dict[str, int], wall: float) -> dict[str, float]:
    """Each thread kind's share of one core between two :func:`thread_times`."""
    return {k: (after[k] - before[k]) / 1e9 / wall for k in THREAD_KINDS}


def _measure(count: list[int], seconds: float) -> None:
    """Print this process's CPU share (and each thread kind's, :func:`thread_times`) and
    ``count``'s rate over ``seconds`` (after a 1.5 s settle) as one JSON line, and end
    the process (no teardown)."""
    time.sleep(1.5)
    n0, wall0, cpu0, threads0 = count[0], time.perf_counter(), time.process_time(), thread_times()
    time.sleep(seconds)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    threads = _shares(threads0, thread_times(), wall)
    print(json.dumps({"cpu_share": cpu / wall, "rate": (count[0] - n0) / wall,
                      "threads": threads}), flush=True)
    os._exit(0)


def floor(bus_kind: str, at: str, hz: float, seconds: float) -> dict[str, Any]:
    """One floor measurement: a tfbus publisher process at ``hz`` (0: nothing sent) and a
    bare reader process (:func:`zenoh_floor_reader`, :func:`ros1_floor_reader`,
    :func:`ros2_floor_reader`): its CPU share, rate and thread kinds' shares, as
    :func:`follower`."""
    pub = start_publisher(bus_kind, at, hz, seconds + 90)
    try:
        return _measured_child("floor-reader", bus_kind, at, hz, seconds, seconds + 90)
    finally:
        pub.kill()
        pub.wait(timeout=10)


def _measured_child(role: str, bus_kind: str, at: str, hz: float, seconds: float,
                    timeout: float) -> dict[str, Any]:
    """Run this script as ``--role role`` (bounded by ``timeout`` s) and return the JSON
    line it prints last (:func:`_measure`'s, or the ``sim-follower``'s).

    Raises:
        RuntimeError: it printed nothing (its error output's end quoted)."""
    sub = subprocess.run(
        [sys.executable, __file__, "--role", role, "--bus", bus_kind, "--at", at,
         "--hz", str(hz), "--seconds", str(seconds)],
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    lines = sub.stdout.strip().splitlines()
    if not lines:
        raise RuntimeError(f"the {role} failed: {sub.stderr[-2000:]}")
    return dict(json.loads(lines[-1]))


def follower(bus_kind: str, at: str, hz: float, seconds: float) -> dict[str, Any]:
    """One follower measurement in a process of its own (``--role sim-follower``: a
    ``SimClock`` on a bus of ``bus_kind`` and :func:`follow`'s publisher at ``hz``, 0:
    nothing sent): its CPU share over ``seconds`` and the /clock messages a second its
    event loop took (over Zenoh and ROS 2, newest-only: fewer than ``hz``), and each
    thread kind's share (``threads``, :func:`thread_times`)."""
    return _measured_child("sim-follower", bus_kind, at, hz, seconds, seconds + 150)


@dataclass
class FollowCost:
    """Per round, the share of one core that following ``/clock`` costs (busy minus
    idle, 0.01 = 1 %): ``tfbus``, a ``SimClock`` process; ``bare``, the bare reader of
    the same stream on the same middleware (:func:`floor`); and what each took a second
    while busy (``tfbus_rate`` is the event loop's, newest-only over Zenoh and ROS 2)."""

    tfbus: list[float] = field(default_factory=list)
    bare: list[float] = field(default_factory=list)
    tfbus_rate: list[float] = field(default_factory=list)
    bare_rate: list[float] = field(default_factory=list)
    tfbus_threads: list[dict[str, float]] = field(default_factory=list)
    """Per round, each thread kind's share (busy minus idle, :data:`THREAD_KINDS`)."""
    bare_threads: list[dict[str, float]] = field(default_factory=list)


def measure(bus_kind: str, at: Callable[[], str], hz: float, seconds: float,
            rounds: int) -> FollowCost:
    """``rounds`` rounds of: a ``SimClock`` process following a tfbus publisher at
    ``hz`` and at 0 Hz (:func:`follower`), and the bare reader of the same publisher at
    ``hz`` and at 0 Hz (:func:`floor`), the two sides alternated (the order reversed
    every other round); ``at()`` gives each run its port, domain id or master URI."""
    got = FollowCost()
    for r in range(rounds):
        sides = ("tfbus", "bare") if r % 2 == 0 else ("bare", "tfbus")
        for side in sides:
            run = follower if side == "tfbus" else floor
            idle = run(bus_kind, at(), 0.0, seconds)
            busy = run(bus_kind, at(), hz, seconds)
            getattr(got, side).append(busy["cpu_share"] - idle["cpu_share"])
            getattr(got, f"{side}_rate").append(busy["rate"])
            getattr(got, f"{side}_threads").append(
                {k: busy["threads"][k] - idle["threads"][k] for k in THREAD_KINDS})
    return got


def _sim_clock_cost_per_message(n: int = 100_000) -> float:
    """Seconds of CPU per /clock a SimClock spends on its own (``_on_clock``, called as
    the bus delivers it; no transport), median of 5 runs of ``n``."""
    clock = SimClock(Bus())
    messages = [Clock(Time.from_ns(START.ns + k * 1_000_000)) for k in range(n)]
    runs = []
    for _ in range(5):
        clock = SimClock(Bus())
        t0 = time.process_time()
        for m in messages:
            clock._on_clock(m)
        runs.append((time.process_time() - t0) / n)
    return statistics.median(runs)


async def main(args: argparse.Namespace) -> None:
    names = {"zenoh": "Zenoh", "ros1": "ROS 1 (TCPROS)", "ros2": "ROS 2 (Cyclone DDS)"}
    print(f"tfbus sim-clock benchmark; Python {sys.version.split()[0]}; {args.backend}; "
          f"{names[args.bus]} on 127.0.0.1; /clock at {args.hz:g} Hz, {args.seconds:g} s windows; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

    def at() -> str:  # a fresh port / domain per run; ROS 1: this run's master
        if args.bus == "zenoh":
            return str(free_port())
        if args.bus == "ros2":
            return str(random.randint(1, 100))
        return str(args.at)

    idle = await follow(args.bus, at(), 0.0, args.seconds, 0)
    plain = await follow(args.bus, at(), args.hz, args.seconds, 0, sim_clock=False)
    busy = await follow(args.bus, at(), args.hz, args.seconds, args.wakeups)
    cost = busy["cpu_share"] - idle["cpu_share"]
    own = _sim_clock_cost_per_message()
    print()
    print("CPU share of one core (process time / wall time, every thread)")
    print(f"  idle bus, no /clock                      {idle['cpu_share'] * 100:6.2f} %")
    print(f"  /clock at {args.hz:g} Hz, a no-op subscriber  "
          f"{plain['cpu_share'] * 100:6.2f} %   ({plain['rate']:.0f}/s received)")
    print(f"  /clock at {args.hz:g} Hz, a SimClock          "
          f"{busy['cpu_share'] * 100:6.2f} %   ({busy['rate']:.0f}/s received)")
    print(f"  cost of following /clock (SimClock - idle) {cost * 100:6.2f} %   "
          f"target < 2 %   [{'ok' if cost < 0.02 else 'over'}]")
    print(f"    SimClock - no-op subscriber              "
          f"{(busy['cpu_share'] - plain['cpu_share']) * 100:6.2f} %   "
          f"(in process, no transport: {own * 1e6:.2f} us per /clock = "
          f"{own * args.hz * 100:.2f} % at {args.hz:g} Hz)")
    print()
    print(f"sim-time wake-ups: clock.sleep_until(d), d between two /clock steps "
          f"({args.wakeups} wake-ups; lateness clock.now() - d, in /clock steps of "
          f"{1e3 / args.hz:g} ms)")
    print(f"  woken (in the /clock's delivery)  min {busy['late_min']:.3f}  median "
          f"{busy['late_median']:.3f}  max {busy['late_max']:.3f} steps   "
          f"target: max < 1 step   [{'ok' if busy['late_max'] < 1 else 'over'}]")
    print(f"  task resumed (+ event-loop turn)  min {busy['resumed_min']:.3f}  median "
          f"{busy['resumed_median']:.3f}  max {busy['resumed_max']:.3f} steps")
    print(f"  dropped /clock {busy['dropped']:.0f}, jumps back {busy['jumps']:.0f}")
    if args.raw and args.bus != "zenoh":
        print()
        print(f"floor on {names[args.bus]} (no tfbus per message): a bare reader process's "
              "CPU share of one core, the same publisher")
        f_idle = await anyio.to_thread.run_sync(floor, args.bus, at(), 0.0, args.seconds)
        f_busy = await anyio.to_thread.run_sync(floor, args.bus, at(), args.hz, args.seconds)
        what = ("bare TCPROS reader (a recv per wake-up, struct per frame)" if args.bus == "ros1"
                else "bare cyclonedds reader (raw take in the listener)")
        print(f"  {what}, idle      {f_idle['cpu_share'] * 100:6.2f} %")
        print(f"  {what}, /clock    {f_busy['cpu_share'] * 100:6.2f} %   "
              f"({f_busy['rate']:.0f}/s received)")
        print(f"  floor cost of /clock at {args.hz:g} Hz (busy - idle)         "
              f"{(f_busy['cpu_share'] - f_idle['cpu_share']) * 100:6.2f} %   "
              f"(tfbus SimClock: {cost * 100:.2f} %)")
    elif args.raw:
        print()
        print(f"raw zenoh-python (no tfbus), 8-byte samples at {args.hz:g} Hz: the subscriber "
              "process's CPU share of one core")
        for label, mode, env, extra in RAW_VARIANTS:
            figures = await anyio.to_thread.run_sync(raw, args.hz, args.seconds, mode, env,
                                                     extra)
            print(f"  {label:<52} {figures['cpu_share'] * 100:6.2f} %   "
                  f"({figures['rate']:.0f}/s received)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--role", default="follower",
                        choices=["follower", "publisher", "raw-publisher", "raw-subscriber",
                                 "floor-reader", "sim-follower"])
    parser.add_argument("--bus", default="zenoh", choices=["zenoh", "ros1", "ros2"],
                        help="the transport /clock travels on (ros1: a roscore on 127.0.0.1 "
                             "is started; ros2: Cyclone DDS, loopback, a random domain id)")
    parser.add_argument("--at", default="", help=argparse.SUPPRESS)
    parser.add_argument("--backend", default="asyncio", choices=["asyncio", "trio"],
                        help="the follower's event loop (the publisher runs on asyncio)")
    parser.add_argument("--mode", default="callback", help=argparse.SUPPRESS)
    parser.add_argument("--zenoh", default="", help=argparse.SUPPRESS)
    parser.add_argument("--no-raw", dest="raw", action="store_false",
                        help="leave out the raw zenoh-python figures")
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--wakeups", type=int, default=200)
    parser.add_argument("--quick", action="store_true", help="2 s windows, 50 wake-ups")
    ns = parser.parse_args()
    if ns.quick:
        ns.seconds, ns.wakeups = 2.0, 50
    if ns.role == "publisher":
        anyio.run(publisher, ns.bus, ns.at, ns.hz, ns.seconds)
    elif ns.role == "sim-follower":
        got = anyio.run(follow, ns.bus, ns.at, ns.hz, ns.seconds, 0, backend=ns.backend)
        threads = {k: got[f"threads_{k}"] for k in THREAD_KINDS}
        print(json.dumps({"cpu_share": got["cpu_share"], "rate": got["rate"],
                          "threads": threads}), flush=True)
    elif ns.role == "floor-reader":
        if ns.bus == "ros1":
            ros1_floor_reader(ns.at, ns.hz > 0, ns.seconds)
        elif ns.bus == "zenoh":
            zenoh_floor_reader(int(ns.at), ns.hz > 0, ns.seconds)
        else:
            ros2_floor_reader(int(ns.at), ns.hz > 0, ns.seconds)
    elif ns.role == "raw-publisher":
        raw_publisher(ns.port, ns.hz, ns.seconds, ns.zenoh)
    elif ns.role == "raw-subscriber":
        raw_subscriber(ns.port, ns.mode, ns.seconds, ns.zenoh)
    elif ns.bus == "ros1":
        sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "peers" / "ros1"))
        from ros1_peers import ros1_missing, start_master

        why = ros1_missing(("roscpp",))
        if why is not None:
            sys.exit(f"ROS 1 unavailable: {why}")
        with tempfile.TemporaryDirectory() as tmp:
            master = start_master(Path(tmp) / "ros_home")
            try:
                ns.at = master.uri
                anyio.run(main, ns, backend=ns.backend)
            finally:
                master.stop()
    else:
        anyio.run(main, ns, backend=ns.backend)
