"""What drives the page of ``tfbus view``: a bag's timeline (slider, play/pause at
x0.1-x10) or a live buffer, redrawn at most :data:`MAX_DRAW_HZ` times a second."""

from __future__ import annotations

import bisect
import threading
import time as _wall
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from tfbus.core import BufferCore
from tfbus.doctor import Doctor
from tfbus.laser import LaserProjection
from tfbus.monitor import TfSummary
from tfbus.time import Time
from tfbus.view.clouds import CloudTrack
from tfbus.view.foxglove_bridge import FoxgloveBridge
from tfbus.view.record import RecordControl
from tfbus.view.scans import ScanTrack
from tfbus.view.scene import DEFAULT_FRAME_TIMEOUT, Scene, build_scene
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

if TYPE_CHECKING:
    from tfbus.view.fleet import FleetView

__all__ = ["CLOUD_COLOUR", "MAX_DRAW_HZ", "BagPlayer", "RecentRates", "draw_live"]

CLOUD_COLOUR = (230, 60, 160)
"""Colour of a PointCloud2's points (RGB 0-255); a LaserScan's are blue."""

MAX_DRAW_HZ = 30.0
"""Drawing is down-sampled to this rate, whatever the rate of the transforms."""
FINDINGS_PERIOD = 0.5
"""Seconds between two reports of the doctor's findings while a bag plays (a seek, or
a render while paused, reports at once)."""


class BagPlayer:
    """A bag on a :class:`TfPage`: a time slider (seconds from the bag's start to its last
    tf message, scan or cloud), a "playing" checkbox and a rate slider (x0.1-x10); bag
    time advances at ``rate`` x wall time while playing and stops at the end.

    The scene at bag time ``t`` is the buffer ``tfbus replay`` would have filled by
    then (:meth:`BagTimeline.buffer_at`), looked up at its latest time (``Time(0)``, as
    rviz does), ages measured from ``t``, in the fixed frame picked in the page
    (:attr:`TfPage.fixed_frame_choice`), else ``fixed_frame``; a change of the page's
    display controls draws a paused bag again at once.

    The page's "tf doctor" panel lists ``tfbus doctor``'s findings on the bag's messages
    up to ``t`` (:meth:`diagnosis`; at the end of the slider, the whole file's, as
    ``tfbus doctor BAG`` reports them), fed to one :class:`~tfbus.doctor.Doctor` as bag
    time moves on and started again after a jump back; while playing it is reported again
    at most every :data:`FINDINGS_PERIOD` seconds of wall time.
    """

    def __init__(self, page: TfPage, timeline: BagTimeline, *, fixed_frame: str | None = None,
                 frame_timeout: float = DEFAULT_FRAME_TIMEOUT, paused: bool = False,
                 rate: float = 1.0, summary: TfSummary | None = None,
                 scans: Sequence[ScanTrack] = (),
                 foxglove: FoxgloveBridge | None = None,
                 clouds: Sequence[CloudTrack] = (),
                 record: RecordControl | None = None,
                 fleet: FleetView | None = None) -> None:
        if not 0.1 <= rate <= 10.0:
            raise ValueError(f"rate must be between 0.1 and 10, got {rate!r}")
        self.page = page
        self.timeline = timeline
        self.fixed_frame = fixed_frame
        self.frame_timeout = frame_timeout
        self.summary = summary
        self.scans = tuple(scans)
        self.clouds = tuple(clouds)
        """The PointCloud2 topics drawn (:class:`~tfbus.view.clouds.CloudTrack`)."""
        self.record = record
        """Where the bag's messages are recorded as they are played (None: nowhere)."""
        self._rec_generation = 0
        self._rec_upto = 0
        self._rec_fed = timeline.start.ns
        self._rec_scans = [0 for _ in self.scans]
        self._rec_clouds = [0 for _ in self.clouds]
        self.foxglove = foxglove
        self.fleet = fleet
        """The robot selector when the bag's frames are a fleet's (``robot/frame``)."""
        self._fg_upto = 0
        self._fg_scan_upto = [0 for _ in self.scans]
        for track in self.scans:  # advertised from the start, before any scan is due
            if foxglove is not None:
                foxglove.scan_channel(track.topic)
        self._projectors = [LaserProjection() for _ in self.scans]
        self.scan_errors: dict[str, str] = {}
        """Why a scan topic is not drawn at the bag time shown (tf2's message)."""
        self.position = 0.0
        """Seconds from the bag's start."""
        lasts = [t.times[-1] for t in self.scans if t.times] + \
            [c.times[-1] for c in self.clouds if c.times]
        end = max([timeline.end.ns, *lasts])  # a scan or cloud after the last tf
        self.duration = (end - timeline.start.ns) / 1e9
        gui = page.server.gui
        self._lock = threading.RLock()
        self.slider: Any = gui.add_slider("bag time (s)", min=0.0, max=max(self.duration, 0.01),
                                          step=0.01, initial_value=0.0)
        self.playing: Any = gui.add_checkbox("playing", initial_value=not paused)
        self.rate: Any = gui.add_slider("rate (x)", min=0.1, max=10.0, step=0.1,
                                        initial_value=rate)
        self._shown = -1.0
        self._shown_version = -1
        self._doctor = Doctor(source="bag")
        self._doctor_upto = 0
        self._reported_upto = -1
        self._reported_at = float("-inf")

        self.slider.on_update(self._on_slider)
        self.last_scene: Scene | None = None
        if timeline.times:  # the camera frames every frame the bag places by its end
            last = timeline.buffer_at(timeline.end)
            page.aim(fleet.build(last, fixed_frame=fixed_frame) if fleet is not None
                     else build_scene(last, fixed_frame=fixed_frame))

    def _on_slider(self, _event: Any) -> None:
        # a user's drag of the time slider (our own writes set the same value)
        with self._lock:
            if abs(float(self.slider.value) - self.position) > 1e-9:
                self.position = float(self.slider.value)

    def time(self) -> Time:
        """The bag time shown."""
        return Time.from_ns(self.timeline.start.ns + round(self.position * 1e9))

    def advance(self, wall_seconds: float) -> None:
        """Move bag time by ``wall_seconds`` x rate when playing (stops at the end)."""
        with self._lock:
            if self.playing.value and self.position < self.duration:
                self.position = min(self.duration,
                                    self.position + wall_seconds * float(self.rate.value))
                self.slider.value = self.position

    def seek(self, seconds: float) -> None:
        """Show bag time ``start + seconds`` (clamped to the bag)."""
        with self._lock:
            self.position = min(max(seconds, 0.0), self.duration)
            self.slider.value = self.position

    def render(self) -> Scene:
        """Draw the scene at :meth:`time` and return it."""
        t = self.time()
        core = self.timeline.buffer_at(t)
        fixed = self.page.fixed_frame_choice or self.fixed_frame
        if self.fleet is not None:
            scene = self.fleet.build(core, fixed_frame=fixed, now=t,
                                     last_update=self.timeline.last_update(t),
                                     frame_timeout=self.frame_timeout)
        else:
            scene = build_scene(core, fixed_frame=fixed, now=t,
                                last_update=self.timeline.last_update(t),
                                frame_timeout=self.frame_timeout)
        self.page.draw(scene, self.summary, core=core)
        self._report_findings(t)
        self.scan_errors.clear()
        for track, projector in zip(self.scans, self._projectors, strict=True):
            pts = None
            if scene.fixed_frame is not None:
                pts, _, why = track.project_at(t, scene.fixed_frame, core, projector)
                if why is not None:
                    self.scan_errors[track.topic] = why
            self.page.draw_points(track.topic, pts)
        for ctrack in self.clouds:
            cpts = None
            if scene.fixed_frame is not None:
                cpts, why = ctrack.project_at(t, scene.fixed_frame, core)
                if why is not None:
                    self.scan_errors[ctrack.topic] = why
            problem = ctrack.problem()
            if problem is not None:
                self.scan_errors[ctrack.topic + " (dropped)"] = problem
            self.page.draw_points(ctrack.topic, cpts, CLOUD_COLOUR)
        if scene.message is None and self.timeline.problem:
            self.page.set_status(self.timeline.problem)
        elif scene.frames:
            self.page.set_status(f"fixed frame: {scene.fixed_frame}   bag time "
                                 f"{self.position:.2f} / {self.duration:.2f} s"
                                 + "".join(f"   {e}" for e in self.scan_errors.values()))
        if self.foxglove is not None:
            self._feed_foxglove(t, scene)
        self._feed_record(t)
        if self.record is not None:
            self.record.show()
        self.last_scene = scene
        return scene

    def diagnosis(self, t: Time) -> Doctor:
        """The doctor fed with the bag's messages up to bag time ``t`` (receive time: the
        record time, as :func:`~tfbus.doctor.diagnose` reads a bag); a damaged bag's
        reason noted once every readable message is in."""
        tl = self.timeline
        n = bisect.bisect_right(tl.times, t.ns)
        if n < self._doctor_upto:  # a jump back: diagnosed again from the start
            self._doctor = Doctor(source="bag")
            self._doctor_upto = 0
        add = self._doctor.add
        for i in range(self._doctor_upto, n):
            transforms, authority, static = tl.messages[i]
            add(tl.times[i], transforms, authority, static=static)
        if n == len(tl.times) and tl.problem and self._doctor.damage is None:
            self._doctor.note_damage(tl.problem)
        self._doctor_upto = n
        return self._doctor

    def _report_findings(self, t: Time) -> None:
        doctor = self.diagnosis(t)
        now = _wall.monotonic()
        if self._doctor_upto == self._reported_upto:
            return
        if self.playing.value and now - self._reported_at < FINDINGS_PERIOD:
            return
        self._reported_upto = self._doctor_upto
        self._reported_at = now
        report = doctor.report(now=t)
        self.page.set_findings(report.findings, f"{report.messages} tf messages up to "
                               f"bag time {self.position:.2f} s diagnosed")

    def _feed_foxglove(self, t: Time, scene: Scene) -> None:
        """Send Foxglove the bag's messages up to ``t`` not sent yet (after a jump back:
        the statics again, then from ``t`` on), the scans likewise, ``t`` as the server
        time and tf's errors as statuses."""
        fg = self.foxglove
        assert fg is not None
        tl = self.timeline
        n = bisect.bisect_right(tl.times, t.ns)
        if n < self._fg_upto:
            for i in range(n):
                if tl.messages[i][2]:
                    fg.publish_transforms(tl.messages[i][0], tl.times[i])
            self._fg_upto = n
        for i in range(self._fg_upto, n):
            fg.publish_transforms(tl.messages[i][0], tl.times[i])
        self._fg_upto = n
        for k, track in enumerate(self.scans):
            m = bisect.bisect_right(track.times, t.ns)
            for i in range(self._fg_scan_upto[k], m):  # empty after a jump back
                fg.publish_scan(track.topic, track.scans[i], track.times[i])
            self._fg_scan_upto[k] = m
        fg.broadcast_time(t.ns)
        fg.publish_errors(scene)

    def _feed_record(self, t: Time) -> None:
        """Write the bag's messages up to ``t`` not written yet to the recording in
        progress, each at its record time (a jump back writes nothing again; past the
        furthest point it goes on). A recording started at ``t`` first gets the bag's
        ``/tf_static`` messages before ``t``, so that it is complete on its own, then
        every message from ``t`` on (``t``: the bag time of the previous call, shown when
        the recording was started, if earlier)."""
        ctl = self.record
        rec = ctl.active if ctl is not None else None
        fed, self._rec_fed = self._rec_fed, t.ns
        if ctl is None or rec is None:
            return
        tl = self.timeline
        n = bisect.bisect_right(tl.times, t.ns)
        if ctl.generation != self._rec_generation:
            self._rec_generation = ctl.generation
            since = min(t.ns, fed)
            first = bisect.bisect_left(tl.times, since)
            for i in range(first):
                if tl.messages[i][2]:
                    rec.write_tf(tl.messages[i][0], True, tl.times[i])
            self._rec_upto = first
            self._rec_scans = [bisect.bisect_left(s.times, since) for s in self.scans]
            self._rec_clouds = [bisect.bisect_left(c.times, since) for c in self.clouds]
        for i in range(self._rec_upto, n):
            transforms, _authority, static = tl.messages[i]
            rec.write_tf(transforms, static, tl.times[i])
        self._rec_upto = max(self._rec_upto, n)
        for k, track in enumerate(self.scans):
            m = bisect.bisect_right(track.times, t.ns)
            for i in range(self._rec_scans[k], m):
                rec.write_scan(track.topic, track.scans[i], track.times[i])
            self._rec_scans[k] = max(self._rec_scans[k], m)
        for k, ctrack in enumerate(self.clouds):
            m = bisect.bisect_right(ctrack.times, t.ns)
            for i in range(self._rec_clouds[k], m):
                rec.write_cloud(ctrack.topic, ctrack.clouds[i], ctrack.times[i])
            self._rec_clouds[k] = max(self._rec_clouds[k], m)

    def run(self, stop: threading.Event,
            clock: Callable[[], float] = _wall.monotonic) -> None:
        """Play until ``stop`` is set, drawing at most :data:`MAX_DRAW_HZ` times a second,
        and only while a browser is connected (or a Foxglove server runs): with nobody
        looking the bag's time goes on, undrawn, and the first tick after a browser
        connects draws it."""
        period = 1.0 / MAX_DRAW_HZ
        last = clock()
        while not stop.is_set():
            now = clock()
            self.advance(now - last)
            last = now
            self._feed_record(self.time())  # recorded whether or not a page looks
            watched = self.foxglove is not None or self.page.watched()
            version = self.page.control_version
            if watched and (self.position != self._shown or self.playing.value
                            or version != self._shown_version):
                self.render()
                self._shown = self.position
                self._shown_version = version
            stop.wait(period)


class RecentRates(Mapping[str, float]):
    """Each frame's recent rate in Hz, :meth:`FrameSummary.recent_rate
    <tfbus.monitor.FrameSummary.recent_rate>` at ``now``, read from ``summary`` when a
    frame's rate is asked for (the frame table and the two frames' chain read them; a
    redraw that shows neither reads none). Keys: the child frame ids of
    ``summary.frames``; a missing one raises ``KeyError``."""

    __slots__ = ("_frames", "_now")

    def __init__(self, summary: TfSummary, now: Time) -> None:
        self._frames = summary.frames
        self._now = now

    def __getitem__(self, frame_id: str) -> float:
        return self._frames[frame_id].recent_rate(self._now)

    def __iter__(self) -> Iterator[str]:
        return iter(self._frames)

    def __len__(self) -> int:
        return len(self._frames)


def draw_live(page: TfPage, core: BufferCore, summary: TfSummary, now: Time, *,
              fixed_frame: str | None = None,
              frame_timeout: float = DEFAULT_FRAME_TIMEOUT,
              fleet: FleetView | None = None, table: bool = True) -> Scene:
    """Draw a live buffer at its latest data; ages from each frame's last receive time
    (``summary``, as :class:`~tfbus.monitor.MonitoredSink` records it) to ``now``; with
    ``fleet``, the robots it picks (:meth:`~tfbus.view.fleet.FleetView.build`). The
    frame table is written only with ``table`` (:meth:`TfPage.draw`); rates are the
    frames' recent rates at ``now`` (:class:`RecentRates`)."""
    last = {name: fs.last_received
            for name, fs in summary.frames.items() if fs.last_received is not None}
    if fleet is not None:
        scene = fleet.build(core, fixed_frame=fixed_frame, now=now,
                            last_update={name: Time.from_ns(t) for name, t in last.items()},
                            frame_timeout=frame_timeout)
    else:
        scene = build_scene(core, fixed_frame=fixed_frame, now=now, last_update_ns=last,
                            frame_timeout=frame_timeout)
    page.draw(scene, summary, RecentRates(summary, now), core=core, table=table)
    return scene
