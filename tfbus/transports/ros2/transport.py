"""Carry a :class:`~tfbus.bus.Bus`'s ``/tf`` and ``/tf_static`` (and, on request, ``/clock``)
to and from ROS 2 over DDS.

::

    from tfbus.bus import Bus
    from tfbus.transports.ros2 import Ros2Transport

    async with Bus(transport=Ros2Transport(domain_id=0)) as bus:   # this machine only
        ...

A ROS 2 node publishing ``/tf`` or ``/tf_static`` (tf2_ros' ``TransformBroadcaster``,
``StaticTransformBroadcaster``, ``robot_state_publisher`` ...) is heard on the bus as if it
published here, and tfbus broadcasters are heard by ROS 2's ``tf2_ros.TransformListener``.
No ROS installation is needed: DDS comes from the ``cyclonedds`` wheel
(``pip install 'tfbus[ros2]'``, which bundles Cyclone DDS' C library).

**Wire.** ROS 2's names and layout exactly (names and types in
:mod:`tfbus.transports.ros2.dds`, samples coded by :mod:`tfbus.codecs.cdr`): DDS topics
``rt/tf`` and ``rt/tf_static``, type ``tf2_msgs::msg::dds_::TFMessage_``, XCDR1
little-endian, and the type hash ``RIHS01_e369d0f0...`` in the endpoints' user data as rmw
announces it. Other bus topics are not sent to ROS 2 (counted in ``not_mapped``).

**Simulated time.** With ``clock_topic="/clock"`` the transport also carries
``rosgraph_msgs/msg/Clock`` on the DDS topic ``rt/clock`` (type
``rosgraph_msgs::msg::dds_::Clock_``, type hash :data:`CLOCK_TYPE_HASH`): each sample
heard is delivered to the bus as a :class:`~tfbus.messages.Clock`, what a
:class:`~tfbus.clock.SimClock` on the bus follows (a simulator, ``ros2 bag play --clock``),
and a ``Clock`` published on the bus is written to ROS 2, where nodes with
``use_sim_time`` follow it. QoS as ROS 2's own: the reader is rclpy's ``TimeSource``
subscription (``rclpy/time_source.py``: best effort, keep-last 1, volatile), which also
matches reliable publishers; the writer is ``rclcpp::ClockQoS`` (``rclcpp/qos.cpp``: the
sensor-data profile, best effort, volatile, keep-last 1), what ``ros2 bag play --clock``
and simulators' ``/clock`` publishers use. A SimClock follows the clock topic newest-only
(:meth:`Ros2Transport.keep_newest`): Cyclone's listener thread takes and decodes each
sample and wakes the event loop only when a sleeper's deadline is reached, time steps
back, or 10 ms passed (:data:`NEWEST_MAX_DELAY`).

**QoS** (``tf2_ros/qos.hpp``: ``DynamicBroadcasterQoS``, ``StaticBroadcasterQoS``,
``DynamicListenerQoS``, ``StaticListenerQoS``):

* ``/tf``: reliable, volatile, keep-last 100 (writer and reader);
* ``/clock`` (with ``clock_topic``): best effort, volatile, keep-last 1 (writer and
  reader), as above;
* ``/tf_static``: reliable, **transient-local**, keep-last **1** on the writer and 100 on
  the reader. A listener that joins late still receives every static broadcaster's last
  message. Because the writer keeps only its *last* message, this transport, like
  tf2_ros' ``StaticTransformBroadcaster``, publishes the **full set** of the static
  transforms it has sent (the latest per child frame) in every ``/tf_static`` message.

**Stamps** that ROS 2 cannot represent (``sec`` outside int32: from 2038-01-19T03:14:08Z)
make :meth:`Ros2Transport.send_nowait` raise :class:`~tfbus.errors.WireEncodeError`
naming the transform and value; nothing of that message is sent. Received samples that do
not decode are counted in ``malformed`` and dropped; the valid ones are delivered.
(Structurally invalid CDR -- truncated, wrong lengths -- is meant never to get this far:
cyclonedds-python's sertype normalizes serialized samples against the type with
``dds_stream_normalize``; ``tests/transports/test_ros2.py`` shows it refusing them on write. What
valid CDR can carry and tfbus still refuses, and counts: frame ids that are not UTF-8,
stamps before 1970, messages over ``max_transforms``. The decoder itself is hardened
against every structural fault too.)

**Network.** By default the transport binds the loopback interface only, with multicast
off and unicast discovery to 127.0.0.1
(:func:`~tfbus.transports.ros2.dds.cyclone_config`): it reaches ROS 2 nodes on this
machine that run with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (and, with Fast DDS, a
loopback profile), and sends nothing to any other address. For a robot network pass
``interfaces=["eth0"]`` (multicast discovery on those interfaces, optional unicast
``peers=``) or a complete Cyclone XML ``config=`` (file path, ``file://`` URI or XML
text). Every generated configuration sets
``<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation>``, without which
Cyclone >= 11 never matches Fast DDS 3.x endpoints (ROS 2 Kilted's default rmw); keep it
in your own file.

**Threads.** Cyclone calls ``on_data_available`` on its receive thread; the callback only
writes one byte to a socket pair (if no wake-up is pending:
:class:`~tfbus.transports._base.ThreadWakeup`). The event loop waits on that
socket (``anyio.wait_readable``: asyncio and trio), then takes the raw samples from the
DDS readers (whose keep-last histories are the bounded queue, as in rclpy) and decodes and
delivers them with ``bus.deliver_many_nowait`` -- one wake-up per burst, at most
``max_batch`` samples per event-loop turn.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import anyio
import anyio.abc
import anyio.lowlevel
from cyclonedds import _clayer
from cyclonedds.core import DDSException, InstanceState, Listener, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from tfbus.codecs.cdr import (
    _compiled_clock,
    _decode_clock_struct,
    decode_clock,
    decode_tf,
    encode_clock,
    encode_tf,
)
from tfbus.errors import TransportError, WireDecodeError, WireEncodeError
from tfbus.messages import TFMessage, TransformStamped
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC
from tfbus.transports._base import (
    DEFAULT_MAX_WAIT,
    BusLike,
    ThreadWakeup,
    TransportStatistics,
    ros_domain_id,
)
from tfbus.transports._newest import NEWEST_MAX_DELAY as NEWEST_MAX_DELAY
from tfbus.transports._newest import NEWEST_MAX_QUEUED as NEWEST_MAX_QUEUED
from tfbus.transports._newest import ClockFollower, NewestClock
from tfbus.transports.ros2.dds import (
    TF_STATIC_TOPIC_DDS,
    TF_TOPIC_DDS,
    Clock_,
    TFMessage_,
    cyclone_config,
    dds_topic_name,
)

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.transports.ros2.action import LookupActionClient, LookupActionServer

__all__ = [
    "CLOCK_TYPE_HASH",
    "TF_TYPE_HASH",
    "Ros2Statistics",
    "Ros2Transport",
    "cyclone_config",
]

TF_TYPE_HASH: Final = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""REP-2011 type hash of ``tf2_msgs/msg/TFMessage`` (ROS 2 Jazzy and later), as rmw
puts it in the endpoints' user data (``typehash=...;``)."""
CLOCK_TYPE_HASH: Final = "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"
"""REP-2011 type hash of ``rosgraph_msgs/msg/Clock`` (``type_hashes`` of
``share/rosgraph_msgs/msg/Clock.json`` in ROS 2 Kilted's ``ros-kilted-rosgraph-msgs``)."""

_TOPICS: Final = {TF_TOPIC: TF_TOPIC_DDS, TF_STATIC_TOPIC: TF_STATIC_TOPIC_DDS}
_ANY_STATE: Final = SampleState.Any | ViewState.Any | InstanceState.Any
_XCDR1: Final = Policy.DataRepresentation(use_cdrv0_representation=True)
_USER_DATA: Final = Policy.Userdata(data=f"typehash={TF_TYPE_HASH};".encode())
# send_nowait never blocks: a reliable write that would wait for acknowledgements fails
# at once (counted in ``send_dropped``) instead of waiting up to Cyclone's 100 ms.
_RELIABLE_WRITE: Final = Policy.Reliability.Reliable(max_blocking_time=0)
_RELIABLE_READ: Final = Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100))

TF_WRITER_QOS: Final = Qos(
    _RELIABLE_WRITE, Policy.Durability.Volatile, Policy.History.KeepLast(100), _XCDR1, _USER_DATA
)
TF_READER_QOS: Final = Qos(
    _RELIABLE_READ, Policy.Durability.Volatile, Policy.History.KeepLast(100), _XCDR1,
    _USER_DATA, Policy.IgnoreLocal.Participant,
)  # fmt: skip
TF_STATIC_WRITER_QOS: Final = Qos(
    _RELIABLE_WRITE, Policy.Durability.TransientLocal, Policy.History.KeepLast(1), _XCDR1,
    _USER_DATA,
)  # fmt: skip
TF_STATIC_READER_QOS: Final = Qos(
    _RELIABLE_READ, Policy.Durability.TransientLocal, Policy.History.KeepLast(100), _XCDR1,
    _USER_DATA, Policy.IgnoreLocal.Participant,
)  # fmt: skip
_CLOCK_USER_DATA: Final = Policy.Userdata(data=f"typehash={CLOCK_TYPE_HASH};".encode())
CLOCK_WRITER_QOS: Final = Qos(
    Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(1),
    _XCDR1, _CLOCK_USER_DATA,
)  # fmt: skip
"""``/clock`` writer: ``rclcpp::ClockQoS`` (best effort, volatile, keep-last 1)."""
CLOCK_READER_QOS: Final = Qos(
    Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(1),
    _XCDR1, _CLOCK_USER_DATA, Policy.IgnoreLocal.Participant,
)  # fmt: skip
"""``/clock`` reader: rclpy ``TimeSource``'s ``QoSProfile(depth=1, reliability=BEST_EFFORT)``."""


@dataclass(slots=True)
class Ros2Statistics(TransportStatistics):
    """Counters of one :class:`Ros2Transport` (:meth:`Ros2Transport.statistics`); the
    first five are :class:`~tfbus.transports._base.TransportStatistics`'s.

    Attributes:
        sent: TFMessages (and Clocks, with ``clock_topic``) written to DDS.
        send_errors: local messages refused (not a TFMessage or Clock, stamp outside
            int32, ...).
        received: samples taken from DDS (valid data only: a writer leaving is no sample).
        delivered: TFMessages (and Clocks, with ``clock_topic``) delivered into the bus.
        malformed: received samples dropped because they did not decode.
        send_dropped: writes DDS refused (e.g. a reliable reader's window was full).
        not_connected: ``/tf`` (and clock topic) messages published while the transport
            was not running (``/tf_static`` ones are kept and written once it runs).
        not_mapped: messages on topics other than ``/tf``, ``/tf_static`` and the clock
            topic (not sent).
        batches: event-loop wake-ups that took samples.
        coalesced: clock samples replaced by a newer one before the event loop saw
            them (the clock topic followed newest-only by a
            :class:`~tfbus.clock.SimClock`: :meth:`Ros2Transport.keep_newest`), or
            dropped, oldest first, beyond :data:`NEWEST_MAX_QUEUED` waiting for it.
        kept: clock samples taken and held newest-only, not delivered (yet) when the copy
            was made: 0 or 1 (the one whose stamp the follower reads as the time). Every
            sample taken is delivered, coalesced, kept or malformed.
    """

    send_dropped: int = 0
    not_connected: int = 0
    not_mapped: int = 0
    batches: int = 0
    coalesced: int = 0
    kept: int = 0


class Ros2ClockFollower(ClockFollower):
    """One follower of a :class:`Ros2Transport`'s clock topic kept newest-only (what
    :meth:`Ros2Transport.keep_newest` returns; inert for a topic that is not the
    transport's clock topic): :attr:`newest_ns` is the stamp of the newest sample
    Cyclone's thread kept, :meth:`poke` after filing a deadline, :meth:`close` to end
    it (:class:`~tfbus.transports._newest.ClockFollower`)."""

    __slots__ = ()


# -- one Cyclone domain per (process, domain id), shared by the transports on it ------------

_domains_lock = threading.Lock()
_domains: dict[int, tuple[Domain, str, int]] = {}


def _acquire_domain(domain_id: int, config: str) -> None:
    with _domains_lock:
        entry = _domains.get(domain_id)
        if entry is not None:
            domain, known, users = entry
            if known != config:
                raise TransportError(
                    f"DDS domain {domain_id} is already open in this process with another "
                    "Cyclone configuration; all transports on one domain id share one"
                )
            _domains[domain_id] = (domain, known, users + 1)
            return
        try:
            domain = Domain(domain_id, config)
        except DDSException as exc:
            raise TransportError(
                f"cannot create DDS domain {domain_id} with this Cyclone configuration: {exc}"
            ) from None
        _domains[domain_id] = (domain, config, 1)


def _release_domain(domain_id: int) -> None:
    with _domains_lock:
        entry = _domains.get(domain_id)
        if entry is None:
            return
        domain, config, users = entry
        if users > 1:
            _domains[domain_id] = (domain, config, users - 1)
            return
        del _domains[domain_id]
    _delete(domain)


def _delete(entity: Any) -> None:
    # cyclonedds deletes an entity (and its children) in __del__; calling it here closes
    # the sockets and threads now instead of whenever the garbage collector runs.
    with contextlib.suppress(Exception):
        entity.__del__()


def _resolve_config(config: str | os.PathLike[str]) -> str:
    if isinstance(config, str) and config.lstrip().startswith("<"):
        return config
    path = os.fspath(config)
    path = path.removeprefix("file://")
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"config: cannot read the Cyclone XML file {path!r}: {exc}") from None


@dataclass(slots=True)
class _Endpoints:
    participant: DomainParticipant
    readers: dict[str, DataReader[Any]]
    writers: dict[str, DataWriter[Any]]


class Ros2Transport:
    """A :class:`~tfbus.bus.Transport` to ROS 2 over DDS (``Bus(transport=Ros2Transport())``).

    Args:
        domain_id: the ROS 2 domain (``ROS_DOMAIN_ID``); default: the ``ROS_DOMAIN_ID``
            environment variable, else 0.
        config: a complete Cyclone DDS XML configuration: file path, ``file://`` URI or
            the XML text itself. Replaces the loopback default; keep
            ``<IgnoreTypeInformation>1.15</IgnoreTypeInformation>`` in it for Fast DDS
            peers.
        interfaces: network interfaces (names like ``"eth0"`` or addresses) to use
            instead of loopback, with multicast discovery: a robot network.
        peers: unicast discovery peers (addresses), with ``interfaces``.
        topics: which of ``/tf`` and ``/tf_static`` to receive (both by default).
        max_batch: most samples delivered per event-loop turn before yielding.
        max_transforms: received messages with more transforms are malformed.
        clock_topic: a ``rosgraph_msgs/msg/Clock`` topic to carry (``"/clock"`` for
            simulated time, :data:`~tfbus.topics.CLOCK_TOPIC`; DDS topic ``rt`` + name):
            each sample heard is delivered to the bus as a
            :class:`~tfbus.messages.Clock` (:func:`~tfbus.codecs.cdr.decode_clock`; one
            that does not decode is counted in ``malformed`` and dropped), what a
            :class:`~tfbus.clock.SimClock` follows, and each ``Clock`` published on the
            bus topic of that name is written to ROS 2. Default ``None``: not carried.

    Raises:
        ValueError: if ``domain_id`` is not in 0..232, ``config`` is combined with
            ``interfaces``/``peers`` or cannot be read, a topic is not ``/tf`` or
            ``/tf_static``, ``clock_topic`` is ``/tf``, ``/tf_static`` or not a global
            ROS graph name, or a bound is less than 1.
    """

    def __init__(
        self,
        *,
        domain_id: int | None = None,
        config: str | os.PathLike[str] | None = None,
        interfaces: Sequence[str] | None = None,
        peers: Sequence[str] | None = None,
        topics: Iterable[str] = (TF_TOPIC, TF_STATIC_TOPIC),
        max_batch: int = 256,
        max_transforms: int = 100_000,
        clock_topic: str | None = None,
    ) -> None:
        domain_id = ros_domain_id(domain_id)
        if config is not None and (interfaces is not None or peers is not None):
            raise ValueError("give config= or interfaces=/peers=, not both")
        if max_batch < 1 or max_transforms < 1:
            raise ValueError("max_batch and max_transforms must be at least 1")
        self._topics = tuple(topics)
        for topic in self._topics:
            if topic not in _TOPICS:
                raise ValueError(f"topics: {topic!r} is not '/tf' or '/tf_static'")
        self._clock_dds = ""
        if clock_topic is not None:
            if clock_topic in _TOPICS:
                raise ValueError(f"clock_topic {clock_topic!r} is already carried as a tf topic")
            try:
                self._clock_dds = dds_topic_name(clock_topic)
            except ValueError as exc:
                raise ValueError(f"clock_topic: {exc}") from None
        self._clock_topic = clock_topic
        self._domain_id = domain_id
        self._config = (
            _resolve_config(config)
            if config is not None
            else cyclone_config(interfaces=interfaces, peers=peers)
        )
        self._max_batch = max_batch
        self._max_transforms = max_transforms
        self._stats = Ros2Statistics()
        self._statics: dict[str, TransformStamped] = {}
        self._endpoints: _Endpoints | None = None
        self._wakeup: ThreadWakeup | None = None
        self._newest = NewestClock()
        self._running = False
        self._closers: list[Callable[[], None]] = []

    # -- public information -----------------------------------------------------------------

    def node_label(self) -> tuple[str, str]:
        """(no name: DDS has none for tfbus, ``"ROS 2 domain N"``)
        (:class:`~tfbus.transports._base.NodeLabelled`)."""
        return "", f"ROS 2 domain {self._domain_id}"

    @property
    def domain_id(self) -> int:
        """The DDS domain id (ROS_DOMAIN_ID)."""
        return self._domain_id

    @property
    def config(self) -> str:
        """The Cyclone DDS XML configuration in use."""
        return self._config

    @property
    def clock_topic(self) -> str | None:
        """The ``rosgraph_msgs/msg/Clock`` topic carried (``None``: none)."""
        return self._clock_topic

    @property
    def running(self) -> bool:
        """True between ``run``'s ``started()`` and its end."""
        return self._running

    def matched_publishers(self, topic: str = TF_TOPIC) -> int:
        """How many DDS writers (ROS 2 publishers, other tfbus transports) on ``topic``
        (a tf topic received, or the clock topic) this transport's reader is matched
        with now (0 when not running).

        Raises:
            ValueError: if ``topic`` is not one this transport receives.
        """
        if topic not in self._topics and topic != self._clock_topic:
            raise ValueError(f"{topic!r} is not received by this transport")
        endpoints = self._endpoints
        if endpoints is None:
            return 0
        # The status's current_count, one C call: get_matched_publications() asks for the
        # count, then for that many handles, and cyclonedds' Python binding indexes past
        # its array when a writer matches in between (IndexError, seen in CI).
        reader: Any = endpoints.readers[topic]  # the status getter is not annotated
        status = reader.get_subscription_matched_status()
        return int(status.current_count)

    def statistics(self) -> Ros2Statistics:
        """A copy of the counters (see :class:`Ros2Statistics`)."""
        newest = self._newest
        with newest.lock:  # Cyclone's thread counts the clock under it: one consistent copy
            return replace(self._stats, kept=int(newest.kept is not None))

    def participant(self) -> DomainParticipant:
        """The DomainParticipant of the running transport, on which other endpoints of
        this process (the ``LookupTransform`` action) are made: one participant per
        transport.

        Raises:
            RuntimeError: the transport is not running.
        """
        endpoints = self._endpoints
        if endpoints is None:
            raise RuntimeError("the Ros2Transport is not running (open its bus first)")
        return endpoints.participant

    def on_close(self, callback: Callable[[], None]) -> None:
        """Call ``callback()`` (once) when the transport leaves the domain, before its
        participant and every endpoint made on it are deleted."""
        self._closers.append(callback)

    def keep_newest(self, topic: str, due: Callable[[int], bool]) -> Ros2ClockFollower:
        """Deliver the clock topic newest-only (rclpy's ``TimeSource`` subscribes to
        ``/clock`` keep-last 1, ``time_source.py``): Cyclone's listener thread takes and
        decodes each sample and keeps only the newest, waking the event loop when
        ``due(stamp_ns)`` (called in Cyclone's thread, must not block) is true, when a
        stamp is earlier than the previous one (a jump back: the kept sample and it are
        delivered in order), or :data:`NEWEST_MAX_DELAY` after the last wake-up while the
        bus has listeners on the topic besides the followers; every wake-up also delivers
        whatever is kept. The stamp of the newest sample kept is the follower's
        :attr:`~Ros2ClockFollower.newest_ns`, which a SimClock reads as its time.
        Samples replaced before the loop saw them are counted in ``coalesced``,
        malformed ones in ``malformed`` (dropped).
        A :class:`~tfbus.clock.SimClock` on a ROS 2 bus asks for this
        (:class:`~tfbus.clock.KeepsNewest`): the loop runs when a sleeper's deadline
        is reached, not at every ``/clock``. Several followers may keep the topic: a
        sample is due when one says so.

        Args:
            topic: the topic; any other than ``clock_topic`` gets an inert follower.
            due: ``due(stamp_ns) -> bool``, whether a sample must reach the loop now.

        Returns:
            the follower: :meth:`Ros2ClockFollower.poke` after filing a deadline,
            :meth:`Ros2ClockFollower.close` to end it.
        """
        if topic != self._clock_topic:
            return Ros2ClockFollower(None, self._wake_clock, due)
        self._newest.follow(due)
        return Ros2ClockFollower(self._newest, self._wake_clock, due)

    def serve_lookups(self, buffer: Buffer, bus: object, *, name: str = "/tf2_buffer_server",
                      max_pending: int = 1000, max_per_peer: int = 100,
                      max_wait: float = DEFAULT_MAX_WAIT,
                      result_timeout: float = 60.0) -> LookupActionServer:
        """tf2_ros ``buffer_server`` on this transport's participant: the
        ``tf2_msgs/action/LookupTransform`` action ``name`` over DDS answering from
        ``buffer`` (:class:`~tfbus.transports.ros2.action.LookupActionServer`; ``bus`` is
        the open bus this transport runs under);
        :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            ValueError: as :class:`~tfbus.transports.ros2.action.LookupActionServer`.
        """
        from tfbus.transports.ros2.action import LookupActionServer

        return LookupActionServer(self, buffer, name=name, max_pending=max_pending,
                                  max_per_peer=max_per_peer, max_wait=max_wait,
                                  result_timeout=result_timeout)

    def lookup_client(self, bus: object, *, name: str = "/tf2_buffer_server",
                      timeout_padding: float = 2.0,
                      max_wait: float = 3600.0) -> LookupActionClient:
        """tf2_ros ``BufferClient`` on this transport's participant: goals of the
        ``LookupTransform`` action ``name``
        (:class:`~tfbus.transports.ros2.action.LookupActionClient`);
        :class:`~tfbus.transports._base.LookupServing`.

        Raises:
            ValueError: as :class:`~tfbus.transports.ros2.action.LookupActionClient`.
        """
        from tfbus.transports.ros2.action import LookupActionClient

        return LookupActionClient(self, name=name, timeout_padding=timeout_padding,
                                  max_wait=max_wait)

    def __repr__(self) -> str:
        state = "running" if self._running else "stopped"
        return f"<Ros2Transport {state} domain_id={self._domain_id}>"

    # -- Transport contract -----------------------------------------------------------------

    async def run(
        self,
        bus: BusLike,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Join the DDS domain, report started, deliver ROS 2 samples until cancelled.

        Static transforms sent before it started are written once the writer exists.
        Leaves the domain (deleting this participant) on the way out.

        Raises:
            RuntimeError: if this transport is already running.
            TransportError: if Cyclone refuses the configuration or the domain.
        """
        if self._running or self._endpoints is not None:
            raise RuntimeError("this Ros2Transport is already running")
        wakeup = ThreadWakeup()
        self._wakeup = wakeup
        endpoints: _Endpoints | None = None
        if self._clock_topic is not None:
            self._newest.bus, self._newest.topic = bus, self._clock_topic
        try:
            with anyio.CancelScope(shield=True):  # a cancelled open must still be closed
                endpoints = await anyio.to_thread.run_sync(self._open)
            assert endpoints is not None
            self._endpoints = endpoints
            self._running = True
            if self._statics:
                self._write(TF_STATIC_TOPIC, encode_tf(tuple(self._statics.values())))
            task_status.started()
            await self._pump(bus, wakeup, endpoints)
        finally:
            self._running = False
            self._endpoints = None
            self._wakeup = None
            self._newest.bus = None
            closers, self._closers = self._closers, []
            for close in closers:
                close()
            if endpoints is not None:
                with anyio.CancelScope(shield=True):
                    await anyio.to_thread.run_sync(self._close, endpoints)
            wakeup.close()

    def send_nowait(self, topic: str, message: object) -> None:
        """Write a locally published ``/tf`` or ``/tf_static`` message (or a ``Clock`` on
        the clock topic) to DDS; never blocks.

        ``/tf_static``: the message's transforms are merged into the set this transport
        has sent (latest per child frame) and the whole set is written (tf2_ros'
        StaticTransformBroadcaster behaviour, needed with a keep-last-1 transient-local
        writer). Other topics are not carried to ROS 2 (counted in ``not_mapped``).
        The clock topic's messages are written when the transport runs (best effort, as
        ``rclcpp::ClockQoS``; counted in ``not_connected`` when it does not).

        Raises:
            WireEncodeError: if the message is not a ``TFMessage`` of ``TransformStamped``
                (on the clock topic: not a :class:`~tfbus.messages.Clock`) or a stamp's
                ``sec`` is outside int32 (ROS 2's ``builtin_interfaces/Time``); nothing of
                the message is sent or remembered.
        """
        if topic == self._clock_topic:
            try:
                payload = encode_clock(message)  # type: ignore[arg-type]
            except WireEncodeError:
                self._stats.send_errors += 1
                raise
            if self._endpoints is None:
                self._stats.not_connected += 1
                return
            self._write(topic, payload)
            return
        if topic not in _TOPICS:
            self._stats.not_mapped += 1
            return
        if not isinstance(message, TFMessage):
            self._stats.send_errors += 1
            raise WireEncodeError(f"{topic} carries TFMessage, not {type(message).__name__}")
        try:
            transforms = tuple(message.transforms)
            if topic == TF_STATIC_TOPIC:
                encode_tf(transforms)  # validate before merging
                merged = dict(self._statics)
                for ts in transforms:
                    merged[ts.child_frame_id] = ts
                payload = encode_tf(tuple(merged.values()))
                self._statics = merged
            else:
                payload = encode_tf(transforms)
        except (WireEncodeError, TypeError, AttributeError) as exc:
            self._stats.send_errors += 1
            if isinstance(exc, WireEncodeError):
                raise
            raise WireEncodeError(f"{topic}: not a TFMessage of TransformStamped: {exc}") from None
        if self._endpoints is None:
            if topic == TF_TOPIC:
                self._stats.not_connected += 1
            return
        self._write(topic, payload)

    # -- internals ---------------------------------------------------------------------------

    def _write(self, topic: str, payload: bytes) -> None:
        endpoints = self._endpoints
        assert endpoints is not None
        ret = _clayer.ddspy_write(endpoints.writers[topic]._ref, payload)
        if isinstance(ret, int) and ret < 0:
            self._stats.send_dropped += 1
        else:
            self._stats.sent += 1

    def _on_data(self, _reader: object) -> None:
        # Cyclone's receive thread: keep it short, never block.
        wakeup = self._wakeup
        if wakeup is not None:
            wakeup.wake()

    def _on_clock_data(self, reader: DataReader[Any]) -> None:
        # Cyclone's receive thread: followed newest-only, the samples are taken here and
        # the loop woken only when one is due (keep_newest); else as every topic.
        if self._newest.dues:
            if self._offer_clock(reader):
                self._on_data(reader)
        else:
            self._on_data(reader)

    def _offer_clock(self, reader: DataReader[Any]) -> bool:
        """Take and decode the clock samples waiting (Cyclone's thread or the loop), keep
        the newest (:class:`~tfbus.transports._newest.NewestClock`); True if the loop
        must wake. Taken under the lock: samples two threads take are offered in the
        order they were taken."""
        stats = self._stats
        wake = False
        newest = self._newest
        read = _compiled_clock
        with newest.lock:
            samples = _clayer.ddspy_take(reader._ref, _ANY_STATE, self._max_batch)
            if isinstance(samples, int) or not samples:
                return False
            for data, info in samples:
                if not info.valid_data:
                    continue  # a writer left (unregister/dispose): no data
                stats.received += 1
                # decode_clock's two readings, each asked once: the compiled one (no
                # Python frame), then the struct one for what it does not read (its answer
                # or its WireDecodeError)
                message = read(data) if read is not None else None
                if message is None:
                    try:
                        message = _decode_clock_struct(data)
                    except WireDecodeError:
                        stats.malformed += 1
                        continue
                wake = newest.offer(message, stats) or wake
        return wake

    def _wake_clock(self) -> None:
        """Wake the loop to deliver what the newest-only clock holds."""
        wakeup = self._wakeup
        if wakeup is not None:
            wakeup.wake()

    def _open(self) -> _Endpoints:
        _acquire_domain(self._domain_id, self._config)
        participant: DomainParticipant | None = None
        try:
            participant = DomainParticipant(self._domain_id)
            listener = Listener(on_data_available=self._on_data)  # type: ignore[no-untyped-call]
            readers: dict[str, DataReader[Any]] = {}
            writers: dict[str, DataWriter[Any]] = {}
            for topic, name in _TOPICS.items():
                dds_topic = Topic(participant, name, TFMessage_)
                static = topic == TF_STATIC_TOPIC
                writers[topic] = DataWriter(
                    participant, dds_topic, TF_STATIC_WRITER_QOS if static else TF_WRITER_QOS
                )
                if topic in self._topics:
                    readers[topic] = DataReader(
                        participant,
                        dds_topic,
                        TF_STATIC_READER_QOS if static else TF_READER_QOS,
                        listener=listener,
                    )
            if self._clock_topic is not None:
                clock = Topic(participant, self._clock_dds, Clock_)
                writers[self._clock_topic] = DataWriter(participant, clock, CLOCK_WRITER_QOS)
                readers[self._clock_topic] = DataReader(
                    participant,
                    clock,
                    CLOCK_READER_QOS,
                    listener=Listener(on_data_available=self._on_clock_data),  # type: ignore[no-untyped-call]
                )
            return _Endpoints(participant, readers, writers)
        except DDSException as exc:
            if participant is not None:
                _delete(participant)
            _release_domain(self._domain_id)
            raise TransportError(f"cannot join DDS domain {self._domain_id}: {exc}") from None

    def _close(self, endpoints: _Endpoints) -> None:
        _delete(endpoints.participant)
        _release_domain(self._domain_id)

    async def _pump(self, bus: BusLike, wakeup: ThreadWakeup, ep: _Endpoints) -> None:
        readers = list(ep.readers.items())

        def drain(woken: bool) -> bool:
            """Take up to ``max_batch`` samples of each reader; True if one had more."""
            if woken:
                self._stats.batches += 1
            more = False
            for topic, reader in readers:
                if self._take(bus, topic, reader):
                    more = True
            return more

        wakeup.rearm()  # what arrived before the first wake-up, then after each one
        more = drain(True)
        while more:
            await anyio.lowlevel.checkpoint()
            more = drain(False)
        await wakeup.serve(drain)

    def _take(self, bus: BusLike, topic: str, reader: DataReader[Any]) -> bool:
        """Take, decode and deliver up to ``max_batch`` samples; True if it took that many.
        The clock topic: what the newest-only follower holds first (in order), then, not
        followed newest-only, the reader's samples."""
        if topic == self._clock_topic:
            newest = self._newest
            if newest.dues:
                self._offer_clock(reader)
            with newest.lock:
                held = newest.take_all()
            if held:
                bus.deliver_many_nowait(topic, held)
                self._stats.delivered += len(held)
            if newest.dues:
                return False
        samples = _clayer.ddspy_take(reader._ref, _ANY_STATE, self._max_batch)
        if isinstance(samples, int) or not samples:
            return False
        stats = self._stats
        out: list[object] = []
        clock = topic == self._clock_topic
        for data, info in samples:
            if not info.valid_data:
                continue  # a writer left (unregister/dispose): no data
            stats.received += 1
            try:
                if clock:
                    out.append(decode_clock(data))
                else:
                    out.append(decode_tf(data, max_transforms=self._max_transforms))
            except WireDecodeError:
                stats.malformed += 1
        if out:
            bus.deliver_many_nowait(topic, out)
            stats.delivered += len(out)
        return len(samples) >= self._max_batch
