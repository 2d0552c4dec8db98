"""``tfbus view --bus SPEC``: the page (and Foxglove) following a live bus.

:class:`LiveView` draws the buffer a :class:`~tfbus.listener.TransformListener` fills
(:func:`~tfbus.view.player.draw_live`) at most :data:`~tfbus.view.player.MAX_DRAW_HZ`
times a second and, from the same bus:

* each ``--scan`` topic's ``sensor_msgs/LaserScan``\\ s, held back by a
  :class:`~tfbus.filters.MessageFilter` (tf2_ros ``MessageFilter``, target: the fixed
  frame, tolerance: the scan's sweep, as rviz's LaserScan display sets it) until the
  transforms at the scan's first and last beam arrived, then projected into the fixed
  frame with :class:`~tfbus.laser.LaserProjection` (laser_geometry's
  ``transformLaserScanToPointCloud``) and drawn as a point cloud: only the newest scan that
  passed is projected per redraw, so drawing is down-sampled to the redraw rate whatever
  the scan rate;
* with ``--foxglove``: ``/tf`` and ``/tf_static`` relayed as ``foxglove.FrameTransforms``
  (log time: the receive time; the latest static transforms sent again whenever a client
  subscribes to ``/tf_static``, as a latched topic), each scan as ``foxglove.LaserScan``,
  the clock's time as the server time and tf's errors as statuses.

The frame table beside the scene is refreshed at most every :data:`TABLE_PERIOD` seconds
(sooner when frames come or go, or a control changes): a redraw that does not refresh
it reads no rates.

Drawing never lets the intake fall behind: a redraw is put off (counted in
:attr:`LiveView.deferred`) while the bus's transport still holds received messages it
has not delivered (:class:`~tfbus.transports._base.Backlogged`, Zenoh's inbound queue),
for at most :data:`MAX_DRAW_STALL` seconds. A redraw costs milliseconds per frame; on a
busy machine, redrawing at :data:`~tfbus.view.player.MAX_DRAW_HZ` regardless let the
inbound queue grow by the transforms that arrived meanwhile.

A message of another type on a scan topic (or on ``/tf``) is counted in
:attr:`ScanFeed.bad` (:attr:`LiveView.bad_tf`) and dropped; a first scan whose sweep is
not finite (it would size the filter's tolerance) in :attr:`ScanFeed.dropped`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import anyio

from tfbus.clock import every
from tfbus.filters import FilterFailureReason, MessageFilter
from tfbus.laser import LaserProjection
from tfbus.messages import TFMessage, TransformStamped
from tfbus.sensor_msgs import LaserScan
from tfbus.time import Duration, Time
from tfbus.topics import TF_STATIC_TOPIC, TF_TOPICS
from tfbus.transports._base import Backlogged, ThreadWakeup
from tfbus.view.clouds import CloudFeed
from tfbus.view.player import CLOUD_COLOUR, MAX_DRAW_HZ, draw_live
from tfbus.view.record import McapRecorder, RecordControl
from tfbus.view.scans import MAX_SCANS_BACK, project_scan
from tfbus.view.scene import DEFAULT_FRAME_TIMEOUT, Scene

if TYPE_CHECKING:
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import Clock
    from tfbus.doctor import Doctor
    from tfbus.monitor import TfSummary
    from tfbus.subscription import Subscription
    from tfbus.view.fleet import FleetView
    from tfbus.view.foxglove_bridge import FoxgloveBridge
    from tfbus.view.server import TfPage

__all__ = ["FINDINGS_PERIOD", "MAX_DRAW_STALL", "TABLE_PERIOD", "LiveView", "ScanFeed", "sweep"]

FINDINGS_PERIOD = 1.0
"""Seconds (the view's clock) between two reports of the doctor's findings live."""

TABLE_PERIOD = 0.25
"""Seconds (the view's clock) between two refreshes of the page's frame table live (its
rate, age, state and broadcaster per frame, read by a person: ``tf_monitor`` prints once
a second); the scene itself is redrawn at every tick. A new frame, a frame gone, or a
change of the page's controls refreshes the table at the next redraw."""

MAX_DRAW_STALL = 1.0
"""Seconds (the view's clock) a redraw may be put off while the transport's inbound
queue is not empty: the page still moves at least once a second under any load."""


def sweep(scan: LaserScan) -> Duration:
    """Time from a scan's first beam to its last, ``(len(ranges) - 1) * time_increment``
    (laser_geometry's end time; 0 for a scan without beams or time increment).

    Raises:
        ValueError: the sweep is infinite (``time_increment`` +inf and two beams or more).
    """
    n = len(scan.ranges)
    return Duration.from_sec(max(0.0, (n - 1) * float(scan.time_increment))) if n else \
        Duration.from_ns(0)


@dataclass
class ScanFeed:
    """One ``--scan`` topic of a live bus: counters, the scans that passed the filter
    (newest last, at most :data:`~tfbus.view.scans.MAX_SCANS_BACK`) and what is drawn."""

    topic: str
    received: int = 0
    """LaserScans received."""
    bad: int = 0
    """Messages of another type on the topic: counted and dropped."""
    passed: int = 0
    """Scans the MessageFilter let through (their transforms arrived)."""
    dropped: int = 0
    """Scans the MessageFilter dropped (queue full, too old, malformed), and first scans
    without a finite sweep (:func:`sweep`), which cannot size the filter's tolerance."""
    drawn: int = 0
    """Projections drawn (at most one per redraw)."""
    error: str | None = None
    """Why nothing is drawn now (tf2's message, no scan yet), else None."""
    ready: deque[LaserScan] = field(default_factory=lambda: deque(maxlen=MAX_SCANS_BACK))
    _shown: tuple[int, str] | None = None


class _ScanSource:
    """The LaserScans of a subscription (anything else counted as bad and dropped), one
    of them put back in front (the first, read to size the filter's tolerance)."""

    def __init__(self, sub: Subscription[Any], feed: ScanFeed, view: LiveView) -> None:
        self._sub = sub
        self._feed = feed
        self._view = view
        self._front: list[LaserScan] = []

    def push_back(self, scan: LaserScan) -> None:
        self._front.append(scan)

    def __aiter__(self) -> _ScanSource:
        return self

    async def __anext__(self) -> LaserScan:
        if self._front:
            return self._front.pop()
        while True:
            msg = await self._sub.__anext__()
            if isinstance(msg, LaserScan):
                self._feed.received += 1
                self._view._relay_scan(self._feed.topic, msg)
                return msg
            self._feed.bad += 1


class LiveView:
    """What ``tfbus view --bus`` draws, from one bus.

    Args:
        page: the page to draw on.
        buffer: the transforms (filled by a TransformListener on the same bus).
        summary: receive times and rates per frame (a MonitoredSink's).
        clock: ages, log times and the Foxglove server time.
        fixed_frame: the frame at the origin (None: the root of the largest tree).
        frame_timeout: seconds, as :func:`~tfbus.view.scene.fade`.
        scan_topics: LaserScan topics to draw.
        cloud_topics: PointCloud2 topics to draw (:class:`~tfbus.view.clouds.CloudFeed`).
        record: where ``/tf``, ``/tf_static``, the scans and the clouds received are
            recorded while a recording is in progress (None: nowhere).
        foxglove: a Foxglove server to relay ``/tf``, ``/tf_static`` and the scans to.
        doctor: a :class:`~tfbus.doctor.Doctor` fed by the same listener (one of the
            sink's ``observers``, as ``tfbus doctor --bus`` feeds one): its findings are
            listed in the page's "tf doctor" panel, reported again at most every
            :data:`FINDINGS_PERIOD` seconds of the view's clock. None: no panel.
        fleet: the robot selector of a fleet bus (``namespace=*``: frames prefixed with
            each robot's name): one robot, or all side by side
            (:class:`~tfbus.view.fleet.FleetView`).
    """

    def __init__(self, page: TfPage, buffer: Buffer, summary: TfSummary, clock: Clock,
                 *, fixed_frame: str | None = None,
                 frame_timeout: float = DEFAULT_FRAME_TIMEOUT,
                 scan_topics: Sequence[str] = (),
                 foxglove: FoxgloveBridge | None = None,
                 doctor: Doctor | None = None,
                 cloud_topics: Sequence[str] = (),
                 record: RecordControl | None = None,
                 fleet: FleetView | None = None) -> None:
        self.page = page
        self.fleet = fleet
        self.doctor = doctor
        self._reported_at: Time | None = None
        self._table_at: Time | None = None
        self._table_key: tuple[int, int] | None = None
        self.buffer = buffer
        self.summary = summary
        self.clock = clock
        self.fixed_frame = fixed_frame
        self.frame_timeout = frame_timeout
        self.foxglove = foxglove
        self.feeds = {t: ScanFeed(t) for t in dict.fromkeys(scan_topics)}
        """The scan topics' feeds, by topic."""
        self.cloud_feeds = {t: CloudFeed(t) for t in dict.fromkeys(cloud_topics)}
        """The PointCloud2 topics' feeds, by topic."""
        self.record = record
        self._rec_generation = 0
        self._rec_statics: dict[str, TransformStamped] = {}
        self.bad_tf = 0
        """Messages on /tf or /tf_static that are not TFMessages (relay only)."""
        self.relayed = 0
        """TFMessages relayed to Foxglove."""
        self.shown_fixed: str | None = None
        """The fixed frame of the last redraw (the default one once it is known)."""
        self.deferred = 0
        """Redraws put off because the transport had not delivered all it received
        (:meth:`redraw`)."""
        self.idle = 0
        """Times the draw loop went to sleep with no browser connected (nothing drawn
        until one connects; the first redraw is then immediate)."""
        self._drawn_at: Time | None = None
        self._fixed_known = anyio.Event()
        self._progress = anyio.Event()
        self._projector = LaserProjection()
        self._statics: dict[str, TransformStamped] = {}
        if foxglove is not None:  # advertised before any message arrives
            foxglove.advertise_static()
            for topic in self.feeds:
                foxglove.scan_channel(topic)

    # ---------------------------------------------------------------- bus side

    async def run(self, bus: Bus) -> None:
        """Follow ``bus`` and redraw at most :data:`MAX_DRAW_HZ` times a second
        (:meth:`redraw`: not while the intake is behind), until cancelled."""
        async with anyio.create_task_group() as tg:
            await tg.start(self.follow, bus)
            self.render()
            wakeup = ThreadWakeup()
            self.page.on_connect(wakeup.wake)
            try:
                # on the view's clock, a deadline every 1/30 s (an overrun skips ticks)
                async for _ in every(1.0 / MAX_DRAW_HZ, clock=self.clock):
                    if not self.watched():
                        # nobody looks: draw nothing until a browser connects
                        wakeup.rearm()
                        while not self.watched():
                            self.idle += 1
                            await wakeup.wait()
                            wakeup.rearm()
                    self.redraw(bus)
            finally:
                wakeup.close()

    def watched(self) -> bool:
        """Whether anyone sees the redraws: a browser on the page, or a Foxglove server
        (which cannot tell whether a client is connected, so it is always drawn for)."""
        return self.foxglove is not None or self.page.watched()

    def redraw(self, bus: Bus) -> Scene | None:
        """One tick of the draw loop: :meth:`render` and return its scene, unless
        ``bus``'s transport still holds received messages it has not delivered
        (:class:`~tfbus.transports._base.Backlogged` ``.pending > 0``) and the last
        redraw is less than :data:`MAX_DRAW_STALL` seconds old on the view's clock: then
        nothing is drawn, :attr:`deferred` counts it and None is returned (the event
        loop delivers the backlog first; a later tick draws the newer data)."""
        transport = bus.transport
        if isinstance(transport, Backlogged) and transport.pending > 0 \
                and self._drawn_at is not None:
            elapsed = self.clock.now().ns - self._drawn_at.ns
            if 0 <= elapsed < MAX_DRAW_STALL * 1e9:  # (a clock that went back: draw)
                self.deferred += 1
                return None
        return self.render()

    async def follow(self, bus: Bus, *, task_status: Any = anyio.TASK_STATUS_IGNORED) -> None:
        """Subscribe to the scan topics (and, with Foxglove, ``/tf`` and ``/tf_static``),
        report started, then feed them until cancelled."""
        async with anyio.create_task_group() as tg:
            for feed in self.feeds.values():
                sub = bus.subscribe(feed.topic, queue_size=10)
                tg.start_soon(self._follow_scans, feed, _ScanSource(sub, feed, self))
            for cfeed in self.cloud_feeds.values():
                tg.start_soon(self._follow_clouds, cfeed,
                              bus.subscribe(cfeed.topic, queue_size=10))
            if self.foxglove is not None or self.record is not None:
                for topic in TF_TOPICS:
                    tg.start_soon(self._relay_tf, bus.subscribe(topic, queue_size=1000),
                                  topic == TF_STATIC_TOPIC)
            task_status.started()

    def _changed(self) -> None:
        self._progress.set()
        self._progress = anyio.Event()

    async def wait_passed(self, topic: str, count: int) -> None:
        """Return once ``count`` scans of ``topic`` passed the filter (bound it with
        ``anyio.fail_after``)."""
        while self.feeds[topic].passed < count:
            await self._progress.wait()

    async def _follow_scans(self, feed: ScanFeed, source: _ScanSource) -> None:
        try:
            first = await source.__anext__()
        except StopAsyncIteration:
            return
        await self._fixed_known.wait()
        while True:  # the first scan with a finite sweep sizes the tolerance
            try:
                tolerance = sweep(first)
                break
            except ValueError:  # time_increment +inf: dropped, counted
                feed.dropped += 1
            try:
                first = await source.__anext__()
            except StopAsyncIteration:
                return
        source.push_back(first)
        target = self.shown_fixed
        assert target is not None

        def failed(_scan: LaserScan, _why: FilterFailureReason) -> None:
            feed.dropped += 1

        async with MessageFilter(self.buffer, target, source, queue_size=10,
                                 tolerance=tolerance, on_failure=failed) as mf:
            async for scan in mf:
                if self.shown_fixed is not None and self.shown_fixed != target:
                    target = self.shown_fixed
                    mf.set_target_frames(target)
                feed.ready.append(scan)
                feed.passed += 1
                self._changed()

    async def _follow_clouds(self, feed: CloudFeed, sub: Subscription[Any]) -> None:
        async for msg in sub:  # decoded (subsampled) on receipt; a bad one counted
            kept = feed.take(msg)
            rec = self._recorder()
            if kept is not None and rec is not None:
                rec.write_cloud(feed.topic, kept, self.clock.now().ns)
            self._changed()

    async def _relay_tf(self, sub: Subscription[Any], static: bool) -> None:
        bridge = self.foxglove
        async for msg in sub:
            if not isinstance(msg, TFMessage):
                self.bad_tf += 1
                continue
            now = self.clock.now().ns
            if self.record is not None:
                rec = self._recorder()
                if rec is not None:
                    rec.write_tf(msg.transforms, static, now)
                if static:  # the latest of each, for a recording started later
                    for t in msg.transforms:
                        self._rec_statics[t.child_frame_id] = t
            if bridge is None:
                continue
            if static:  # kept to send again; one Foxglove cannot carry is dropped once
                for t in msg.transforms:
                    if bridge.fits(t.header.stamp):
                        self._statics[t.child_frame_id] = t
            bridge.publish_transforms(msg.transforms, now, static=static)
            self.relayed += 1

    def _recorder(self) -> McapRecorder | None:
        """The recording in progress; one started since the last message first gets
        the latest static transform of each frame received so far."""
        ctl = self.record
        rec = ctl.active if ctl is not None else None
        if ctl is None or rec is None:
            return None
        if ctl.generation != self._rec_generation:
            self._rec_generation = ctl.generation
            if self._rec_statics:
                rec.write_tf(list(self._rec_statics.values()), True, self.clock.now().ns)
        return rec

    def _relay_scan(self, topic: str, scan: LaserScan) -> None:
        if self.foxglove is not None:
            self.foxglove.publish_scan(topic, scan, self.clock.now().ns)
        rec = self._recorder()
        if rec is not None:
            rec.write_scan(topic, scan, self.clock.now().ns)

    # ---------------------------------------------------------------- drawing

    def render(self) -> Scene:
        """One redraw: the frames at the buffer's latest data (in the fixed frame picked
        in the page, else ``fixed_frame``), the newest placeable scan
        of each topic (projected only when it changed), and for Foxglove the server time,
        the statuses and the static transforms a new subscriber asked for."""
        now = self.clock.now()
        self._drawn_at = now
        scene = draw_live(self.page, self.buffer, self.summary, now,
                          fixed_frame=self.page.fixed_frame_choice or self.fixed_frame,
                          frame_timeout=self.frame_timeout, fleet=self.fleet,
                          table=self._table_due(now))
        if scene.fixed_frame is not None and scene.frames:
            self.shown_fixed = scene.fixed_frame
            self._fixed_known.set()
        for feed in self.feeds.values():
            self._draw_feed(feed, self.shown_fixed)
        errors = [f.error for f in self.feeds.values() if f.error is not None]
        for cfeed in self.cloud_feeds.values():
            pts, changed = cfeed.project(self.shown_fixed, self.buffer)
            if changed:
                self.page.draw_points(cfeed.topic, pts, CLOUD_COLOUR)
            errors += [e for e in (cfeed.error, cfeed.dropped.summary(cfeed.topic)) if e]
        self._report_findings(now)
        if self.record is not None:
            self.record.show()
        if errors and scene.message is None:
            self.page.set_status(f"fixed frame: {scene.fixed_frame}"
                                 + "".join(f"   {e}" for e in errors))
        bridge = self.foxglove
        if bridge is not None:
            if bridge.take_static_request() and self._statics:
                bridge.publish_transforms(list(self._statics.values()), now.ns, static=True)
            bridge.broadcast_time(now.ns)
            bridge.publish_errors(scene)
        return scene

    def _table_due(self, now: Time) -> bool:
        """Whether this redraw refreshes the frame table (:data:`TABLE_PERIOD`): the
        first one, one :data:`TABLE_PERIOD` after the last refresh (or with a clock that
        went back), or when the number of frames or the page's controls changed."""
        key = (len(self.summary.frames), self.page.control_version)
        last = self._table_at
        if (last is not None and key == self._table_key
                and 0 <= now.ns - last.ns < TABLE_PERIOD * 1e9):
            return False
        self._table_at = now
        self._table_key = key
        return True

    def _report_findings(self, now: Time) -> None:
        if self.doctor is None:
            return
        last = self._reported_at
        if last is not None and 0 <= now.ns - last.ns < FINDINGS_PERIOD * 1e9:
            return
        self._reported_at = now
        report = self.doctor.report(now=now)
        self.page.set_findings(report.findings,
                               f"{report.messages} tf messages received diagnosed")

    def _draw_feed(self, feed: ScanFeed, fixed: str | None) -> None:
        if fixed is None or not feed.ready:
            feed.error = f"{feed.topic}: no scan yet" if not feed.received else \
                f"{feed.topic}: waiting for the transforms of {feed.received} scan(s)"
            self.page.draw_points(feed.topic, None)
            return
        key = (feed.passed, fixed)  # the newest scan that passed, and where it goes
        if key == feed._shown:
            return  # nothing new since the last redraw: nothing projected
        first_error: str | None = None
        for scan in reversed(feed.ready):
            try:
                pts = project_scan(self._projector, scan, fixed, self.buffer)
            except Exception as err:  # tf2's TransformException, or a malformed scan
                if first_error is None:
                    first_error = f"{feed.topic}: {err}"
                continue
            self.page.draw_points(feed.topic, pts)
            feed.drawn += 1
            feed.error = None
            feed._shown = key
            return
        feed.error = first_error
        feed._shown = key
        self.page.draw_points(feed.topic, None)
