"""Where echo, monitor and frames get their transforms: a bag or a live bus.

:class:`BagSource` reads a recording; :class:`BusSource` is a
:class:`~tfbus.listener.TransformListener` feeding a :class:`~tfbus.buffer.Buffer` and
:class:`~tfbus.monitor.TfSummary` at once (:class:`~tfbus.monitor.MonitoredSink`), plus
over Zenoh the liveliness of broadcasters. Both offer :meth:`TfSource.buffer` and
:meth:`TfSource.summary`.
"""

from __future__ import annotations

import contextlib
import logging
import signal
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from tfbus.cli._common import SafeLogFormatter, error, fail, one_line
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPIC, TF_TOPICS
from tfbus.transports._base import PeerAware
from tfbus.transports.spec import BUS_HELP, DEFAULT_BUS, schemes  # DEFAULT_BUS: no --bus

if TYPE_CHECKING:
    import anyio

    from tfbus.buffer import Buffer
    from tfbus.bus import Bus, Subscription, Transport
    from tfbus.core import BufferCore
    from tfbus.fleet import FleetBuffer
    from tfbus.listener import TransformListener
    from tfbus.monitor import TfSummary
    from tfbus.transports._base import PeerEvent, PeerInfo
    from tfbus.transports.spec import BusSpec

__all__ = ["DEFAULT_BUS", "BagSource", "BusSource", "TfSource",
           "is_bus_error", "live", "run_live", "source", "source_options"]

F = TypeVar("F", bound=Callable[..., Any])


class TfSource:
    """Where echo / monitor / frames get their transforms.

    :class:`BagSource` reads a recording; :class:`BusSource` listens to a live bus (other
    processes, over Zenoh) and fills the same two structures while it is attached.
    """

    label: str = ""

    def buffer(self) -> BufferCore:
        """A BufferCore holding the transforms (for lookups and the frame tree)."""
        raise NotImplementedError

    def summary(self) -> TfSummary:
        """tf_monitor's per-frame and per-broadcaster tables (:mod:`tfbus.monitor`)."""
        raise NotImplementedError

    @property
    def problem(self) -> str | None:
        """A one-line warning when the data was incomplete (a damaged bag)."""
        return None


def check_bag(path: Path) -> None:
    """A usage error (one line) unless ``path`` is a bag of a known format."""
    from tfbus.bag import BagError, detect_format

    try:
        detect_format(path)
    except BagError as err:
        fail(str(err))


class BagSource(TfSource):
    """Transforms from a bag file, loaded once (``tfbus.bag``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.label = str(path)
        self._buffer: BufferCore | None = None
        self._summary: TfSummary | None = None
        self._problem: str | None = None
        self.chain: list[str] | None = None
        """``[source, target]``: the chain whose net delay :meth:`summary` measures
        (set it, then :meth:`reset_summary`)."""
        check_bag(path)

    def buffer(self) -> BufferCore:
        from tfbus.bag import BagReadError, load_buffer

        if self._buffer is None:
            try:
                self._buffer = load_buffer(self.path)
            except BagReadError as err:
                self._problem = one_line(str(err))
                self._buffer = err.partial
        assert self._buffer is not None
        return self._buffer

    def summary(self) -> TfSummary:
        from tfbus.bag import BagReadError, read_messages
        from tfbus.monitor import TfSummary

        if self._summary is None:
            stats = TfSummary()
            if self.chain is not None:
                stats.watch_chain(self.chain[0], self.chain[1])
            try:
                for rec in read_messages(self.path):
                    stats.add(rec.time, rec.message.transforms, rec.authority,
                              static=rec.is_static)
            except BagReadError as err:
                self._problem = one_line(str(err))
            self._summary = stats
        return self._summary

    def reset_summary(self) -> None:
        """Forget the summary: the next :meth:`summary` reads the bag again."""
        self._summary = None

    @property
    def problem(self) -> str | None:
        return self._problem


_UNKNOWN_AUTHORITY = "unknown"
_SHARED_AUTHORITY = "unattributed"


def parse_spec(spec: str, *, name: str = "tfbus-cli") -> BusSpec:
    """``--bus SPEC`` parsed by the scheme table (:mod:`tfbus.transports.spec`: ``zenoh``,
    ``ros2``, ``ros1``, ``memory``, ...), or a one-line usage error (exit status 2).

    Option values are checked here too, before anything runs: a transport is built from
    the spec (not opened: no socket, no thread) and dropped, so a value its factory or
    constructor refuses (``zenoh?port=abc``, ``ros2:domain=999``, ``ros1:name=bad name``,
    an unreadable ``ros2:config`` file, ...) is the same one-line usage error. A missing
    extra raises :class:`~tfbus.errors.MissingExtraError` naming it (the ``tfbus`` group
    prints it on one line, exit status 2).
    """
    from tfbus.errors import TransportError
    from tfbus.transports.spec import parse_bus_spec, schemes

    try:
        parsed = parse_bus_spec(spec)
    except ValueError as err:
        fail(str(err))
    scheme = schemes().get(parsed.scheme)
    if scheme is not None:  # a missing extra: named now, as every one (exit status 2)
        from tfbus._extras import require

        require(f"the {parsed.scheme!r} bus", *scheme.requires, extra=scheme.extra or None)
    try:
        open_spec_transport(parsed, name=name)
    except ValueError as err:
        fail(f"--bus {spec!r}: {err}")
    except TransportError:
        pass  # the transport refused its configuration: said when the bus is opened
    return parsed


def open_spec_transport(
    spec: BusSpec, *, name: str, scan_topics: Sequence[str] = (), use_sim_time: bool = False
) -> Transport:
    """A new transport for ``spec``; ``name`` is this node's name unless the spec gives
    one (:func:`tfbus.transports.spec.open_transport`'s ``default_name``); ``scan_topics``
    are the LaserScan topics it must carry (``tfbus view --scan``); ``use_sim_time``: it
    must carry ``/clock`` too (a ROS 1 node or a ROS 2 participant subscribes to it by
    type: the transport's ``clock_topic``, where the scheme table says it takes one;
    Zenoh and memory carry every topic).

    Raises:
        TransportError: the scheme's extra is not installed (named), or the transport
            rejects its configuration.
        ValueError: an option value the transport does not understand.
    """
    from tfbus.transports.spec import open_transport, schemes

    scheme = schemes().get(spec.scheme)
    if use_sim_time and scheme is not None and scheme.clock_topic:
        from tfbus.topics import CLOCK_TOPIC

        return open_transport(spec, default_name=name, scan_topics=scan_topics,
                              clock_topic=CLOCK_TOPIC)
    return open_transport(spec, default_name=name, scan_topics=scan_topics)


def check_bus_spec(bus: str | None) -> None:
    """A bad ``--bus`` is a one-line usage error here, before anything runs."""
    if bus is not None:
        parse_spec(bus)


class BusSource(TfSource):
    """Transforms from a live bus (``--bus SPEC``: Zenoh, ROS 2, ROS 1, ...).

    While :meth:`attach` is open, a :class:`~tfbus.listener.TransformListener` stores every
    ``/tf`` and ``/tf_static`` message other processes broadcast in :meth:`buffer` (a
    :class:`~tfbus.buffer.Buffer`, so lookups can be awaited) through a
    :class:`~tfbus.monitor.MonitoredSink`, which accounts it in :meth:`summary`
    (receive time = wall clock, delay = receive time - header stamp, as tf_monitor), and
    over Zenoh, liveliness changes of broadcasters are tracked (:attr:`gone`).

    Authority: the wire format does not say which node sent a message, so a message is
    attributed to the one live broadcaster publishing its topic; when several publish it,
    to the one its frames were attributed to while it was alone (tf_monitor's frame ->
    authority map, kept), and ``"unattributed"`` only when that does not decide. Before
    any is known a message is ``"unknown"``, and accounted to the broadcaster once its
    liveliness arrives (no row of its own). Transports without liveliness
    (:attr:`has_liveliness` False) name every sender ``"unknown_publisher"`` on ROS 1,
    as tf_monitor does there, else ``"unknown"``.

    Args:
        spec: a ``--bus`` value (:func:`tfbus.transports.spec.parse_bus_spec`).
        name: this node's name unless ``spec`` gives one (``zenoh?name=...``).
        cache_time: seconds of history the buffer keeps.
        scan_topics: ``sensor_msgs/LaserScan`` topics the transport must also carry
            (``tfbus view --scan``; :func:`tfbus.transports.spec.open_transport`).
        use_sim_time: the clock (:attr:`clock`: receive times, timers, lookups) is a
            :class:`~tfbus.clock.SimClock` following ``/clock`` on the bus once attached
            (ROS's ``use_sim_time``), instead of the wall clock.
    """

    def __init__(self, spec: str, *, name: str = "tfbus-cli", cache_time: float = 10.0,
                 scan_topics: Sequence[str] = (), use_sim_time: bool = False) -> None:
        from tfbus.buffer import Buffer
        from tfbus.clock import Clock, SimClock, SystemClock
        from tfbus.monitor import MonitoredSink, TfSummary

        self.spec = spec
        self.bus_spec = parse_spec(spec, name=name)
        self.name = name
        self.scan_topics = tuple(scan_topics)
        self.label = f"the bus {spec!r}"
        self.use_sim_time = use_sim_time
        self.sim_clock: SimClock | None = SimClock() if use_sim_time else None
        """The simulated clock with ``use_sim_time`` (entered while attached), else None."""
        self.clock: Clock = self.sim_clock if self.sim_clock is not None else SystemClock()
        self._buffer: Buffer = Buffer(cache_time=cache_time, clock=self.clock)
        self._summary = TfSummary()
        self.sink = MonitoredSink(self._buffer, self._summary, self.clock,
                                  attribute=self._attribute)
        self.transport: Transport | None = None
        self.bus: Bus | None = None
        """The open bus while attached (other topics can be subscribed on it)."""
        self.listener: TransformListener | None = None
        self.broadcasters_seen: dict[str, PeerInfo] = {}
        """Every broadcaster heard of through liveliness, by node id."""
        self.gone: dict[str, PeerInfo] = {}
        """Broadcasters whose liveliness went away (exited, killed or unreachable)."""
        self._problem: str | None = None
        self.fleet: FleetBuffer | None = None
        """The robots of a fleet bus (``namespace=*``) while attached."""
        self._scheme = schemes().get(self.bus_spec.scheme)
        self._peer_aware = self._scheme is not None and self._scheme.peer_aware

    def buffer(self) -> Buffer:
        return self._buffer

    def summary(self) -> TfSummary:
        return self._summary

    @property
    def invalid(self) -> int:
        """Transforms the buffer rejected (NaN, bad quaternion, bad frame ids)."""
        return self.listener.statistics().invalid if self.listener is not None else 0

    @property
    def problem(self) -> str | None:
        return self._problem

    def report_problem(self, message: str) -> None:
        """Record a one-line warning (printed at the end, exit status 1)."""
        self._problem = message

    @property
    def is_fleet(self) -> bool:
        """Whether the bus is a fleet bus (its scheme's
        :meth:`~tfbus.transports.spec.TransportScheme.is_fleet`: Zenoh's ``namespace=*``):
        every robot's frames, prefixed ``robot/`` (:class:`~tfbus.fleet.FleetBuffer`)."""
        return self._scheme is not None and self._scheme.is_fleet(self.bus_spec)

    @property
    def has_liveliness(self) -> bool:
        """Whether the transport tells which nodes broadcast (it is
        :class:`~tfbus.transports._base.PeerAware`: Zenoh's liveliness): the scheme
        table's word until attached, then the transport's own."""
        return self._peer_aware

    def alive_broadcasters(self) -> dict[str, PeerInfo]:
        """The live broadcasters now (a :class:`~tfbus.transports._base.PeerAware`
        transport's ``broadcasters()``); empty when detached or on a transport without
        liveliness."""
        transport = self.transport
        return dict(transport.broadcasters()) if isinstance(transport, PeerAware) else {}

    @contextlib.asynccontextmanager
    async def attach(
        self, on_peer: Callable[[str, PeerInfo], None] | None = None
    ) -> AsyncIterator[BusSource]:
        """Open the bus and collect until the block ends.

        ``on_peer(what, info)`` is called with ``what`` = ``"alive"`` when a node starts
        broadcasting (its first ``/tf`` or ``/tf_static``) and ``"gone"`` when a known
        broadcaster's liveliness disappears.

        Raises:
            TransportError, OSError: the transport cannot be opened (endpoint in use,
                bad config, extra not installed).
        """
        import anyio

        from tfbus.bus import Bus
        from tfbus.listener import TransformListener

        transport = open_spec_transport(self.bus_spec, name=self.name,
                                        scan_topics=self.scan_topics,
                                        use_sim_time=self.use_sim_time)
        peer_aware = transport if isinstance(transport, PeerAware) else None
        self._peer_aware = peer_aware is not None
        with _literal_logging():
            async with Bus(transport=transport, queue_size=10_000) as bus, \
                    self._following_clock(bus):
                self.transport = transport
                self.bus = bus
                if self.is_fleet:
                    from tfbus.fleet import FleetBuffer
                    from tfbus.monitor import MonitoredSink

                    # every robot's frames, robot/-prefixed, accounted to its broadcaster
                    sink = MonitoredSink(self._buffer, self._summary, self.clock)
                    self.fleet = FleetBuffer(bus, merged=True, sink=sink)
                    self.listener = None
                    receiver: Any = self.fleet
                else:
                    receiver = self.listener = TransformListener(self.sink, bus, clock=self.clock)
                async with receiver, anyio.create_task_group() as tg:
                    if peer_aware is not None:
                        peers = bus.subscribe(peer_aware.peers_topic, queue_size=1000)
                        tg.start_soon(self._watch, peers, on_peer)
                    try:
                        yield self
                    finally:
                        tg.cancel_scope.cancel()
        self.transport = None
        self.bus = None

    def _following_clock(self, bus: Bus) -> contextlib.AbstractAsyncContextManager[object]:
        """The simulated clock attached to ``bus`` and entered (``use_sim_time``), else
        nothing to enter."""
        if self.sim_clock is None:
            return contextlib.nullcontext()
        return self.sim_clock.attach(bus)

    def _authority(self, static: bool) -> str:
        if not self.has_liveliness:
            named = self._scheme.unknown_authority if self._scheme is not None else None
            return named or _UNKNOWN_AUTHORITY
        topic = TF_STATIC_TOPIC if static else TF_TOPIC
        names = {p.name for p in self.alive_broadcasters().values() if topic in p.topics}
        if len(names) == 1:
            return names.pop()
        return _SHARED_AUTHORITY if names else _UNKNOWN_AUTHORITY

    def _attribute(self, static: bool, transforms: Sequence[object]) -> str:
        name = self._authority(static)
        if name != _SHARED_AUTHORITY:
            return name
        topic = TF_STATIC_TOPIC if static else TF_TOPIC
        names = {p.name for p in self.alive_broadcasters().values() if topic in p.topics}
        frames = self._summary.frames
        owners = set()
        for ts in transforms:
            child = getattr(ts, "child_frame_id", None)
            fs = frames.get(child) if isinstance(child, str) else None
            if fs is not None and fs.authority in names:
                owners.add(fs.authority)
        return owners.pop() if len(owners) == 1 else _SHARED_AUTHORITY

    def _attribute_unknown(self) -> None:
        """What arrived before any broadcaster was known goes to the broadcaster, when
        exactly one is known now (a single "unknown" row would otherwise stay)."""
        names = {p.name for p in self.broadcasters_seen.values()}
        if len(names) == 1 and _UNKNOWN_AUTHORITY in self._summary.authorities:
            self._summary.rename_authority(_UNKNOWN_AUTHORITY, names.pop())

    async def _watch(
        self, sub: Subscription[Any], on_peer: Callable[[str, PeerInfo], None] | None
    ) -> None:
        from tfbus.transports._base import PeerInfo

        async for event in sub:
            ev: PeerEvent = event
            known = self.broadcasters_seen.get(ev.node_id)
            if ev.alive and ev.topic.endswith(TF_TOPICS):
                topics = (known.topics if known else frozenset()) | {ev.topic}
                info = PeerInfo(ev.node_id, ev.name, topics)
                self.broadcasters_seen[ev.node_id] = info
                self.gone.pop(ev.node_id, None)
                self._attribute_unknown()
                if known is None and on_peer is not None:
                    on_peer("alive", info)
            elif (
                not ev.alive and not ev.topic and known is not None
                and ev.node_id not in self.gone
            ):
                self.gone[ev.node_id] = known
                if on_peer is not None:
                    on_peer("gone", known)


@contextlib.contextmanager
def _literal_logging() -> Any:
    """While attached, tfbus's log lines (a peer's bad transform, ...) go to stderr with
    control characters escaped, instead of Python's raw last-resort handler."""
    log = logging.getLogger("tfbus")
    handler = logging.StreamHandler()
    handler.setFormatter(SafeLogFormatter("%(name)s: %(levelname)s: %(message)s"))
    previous = log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.propagate = previous


def source_options(f: F) -> F:
    """``--bag PATH`` and ``--bus SPEC``: the transform source of echo/monitor/frames."""
    from tfbus.cli._common import bag_path

    f = click.option(
        "--bus", "bus", metavar="SPEC", default=None,
        help="The live bus to listen to (default, without --bag: 'zenoh', this machine, "
             "where the publishing commands publish by default): 'zenoh', "
             "'zenoh:tcp/HOST:7448', 'zenoh?connect=...&namespace=...', 'ros2' "
             "(ROS 2 over DDS, 'ros2:domain=7'), 'ros1' (a ROS 1 master, "
             "'ros1:http://127.0.0.1:11311').",
    )(f)
    return click.option("--bag", type=bag_path(), help="Read transforms from this bag.")(f)


def source(bag: Path | None, bus: str | None = None, *, name: str = "tfbus-cli",
           use_sim_time: bool = False) -> TfSource:
    """The source the options name: the bag, else the ``--bus`` spec, else the default
    bus (:data:`DEFAULT_BUS`, where the publishing commands publish); a usage error for
    both, and for ``--use-sim-time`` with a bag (a bag has its own times)."""
    if bus is not None and bag is not None:
        fail("give --bag PATH or --bus SPEC, not both")
    if bag is not None:
        if use_sim_time:
            fail("--use-sim-time applies to --bus sources only")
        return BagSource(bag)
    return BusSource(bus if bus is not None else DEFAULT_BUS, name=name,
                     use_sim_time=use_sim_time)


def live_only(src: TfSource, **options: object) -> None:
    """Options that only mean something on a live bus: an error with --bag."""
    if not isinstance(src, BusSource):
        for name, value in options.items():
            if value is not None:
                fail(f"--{name.replace('_', '-')} applies to --bus sources only")


def is_bus_error(err: BaseException) -> bool:
    """An error opening or using a transport: :class:`~tfbus.errors.TransportError` (every
    transport maps its middleware's errors to it) or an ``OSError``."""
    from tfbus.errors import TransportError

    return isinstance(err, (OSError, TransportError))


def _bus_error_in(err: BaseException) -> BaseException | None:
    """The transport error in ``err`` or in an exception group around it."""
    if is_bus_error(err):
        return err
    for inner in getattr(err, "exceptions", ()):
        found = _bus_error_in(inner)
        if found is not None:
            return found
    return None


def run_live(main: Callable[[], Awaitable[None]], *, backend: str = "asyncio") -> int | None:
    """``anyio.run(main)``; None when it ran, 1 (after a one-line error) when the bus
    could not be opened, 130 on a Ctrl-C before the signal handler was installed."""
    import anyio

    try:
        anyio.run(main, backend=backend)
    except KeyboardInterrupt:  # Ctrl-C while the session was still opening
        return 130
    except Exception as err:
        found = _bus_error_in(err)
        if found is None:
            raise
        error(f"cannot open the bus: {found}")
        return 1
    return None


async def cancel_on_signal(scope: anyio.CancelScope, *, task_status: Any = None) -> None:
    """Cancel ``scope`` at the first SIGINT or SIGTERM (``await tg.start(...)`` returns
    once the handler is installed)."""
    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        if task_status is not None:
            task_status.started()
        async for _ in signals:
            scope.cancel()
            return


async def live(
    src: BusSource,
    duration: float | None,
    body: Callable[[], Awaitable[None]],
    *,
    on_peer: Callable[[str, PeerInfo], None] | None = None,
    finish: Callable[[], None] | None = None,
) -> None:
    """Attach ``src`` and run ``body`` until it returns, ``duration`` seconds have
    passed (None: no limit) or SIGINT/SIGTERM arrives; then call ``finish`` while still
    attached (so liveliness is current) and detach."""
    import anyio

    async with src.attach(on_peer), anyio.create_task_group() as tg:
        with anyio.CancelScope() as scope:
            if duration is not None:
                scope.deadline = anyio.current_time() + duration
            await tg.start(cancel_on_signal, scope)
            await body()
        if finish is not None:
            finish()
        tg.cancel_scope.cancel()


def publish_options(f: F) -> F:
    """``--bus SPEC`` and ``--local``: where static-transform and replay publish."""
    f = click.option("--local", is_flag=True,
                     help="Publish on a private in-process bus instead (nobody else sees "
                          "it: for trying the command out).")(f)
    return click.option("--bus", "bus", metavar="SPEC", default=None, help=BUS_HELP)(f)


def publish_bus(bus: str | None, local: bool, *, name: str,
                use_sim_time: bool = False) -> Callable[[], Any]:
    """A factory of the (unopened) bus the options name: in-process with ``--local``, else
    the ``--bus`` spec (default ``zenoh``). Bad options are a one-line usage error now.
    ``use_sim_time``: the transport carries ``/clock`` too (:func:`open_spec_transport`)."""
    from tfbus.bus import Bus

    if local:
        if bus is not None:
            fail("give --bus SPEC or --local, not both")
        return Bus
    chosen = parse_spec(bus if bus is not None else DEFAULT_BUS, name=name)

    def open_bus() -> Bus:
        return Bus(transport=open_spec_transport(chosen, name=name, use_sim_time=use_sim_time))

    return open_bus
