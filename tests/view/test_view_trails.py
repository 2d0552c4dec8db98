"""The trail of a chosen frame in ``tfbus view`` (tfbus/view/trails.py, server.py): its
origin's path in the fixed frame over the last N seconds, looked up in the buffer at
sampled stamps, checked against hand-computed geometry (a frame on a circle of radius
2 m at 0.5 rad/s, sent at 50 Hz: tf2 interpolates the translation linearly between two
samples), live, on a bag following the slider, and picked in headless Chromium."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.core import BufferCore
from tfbus.messages import TFMessage
from tfbus.view.trails import MAX_TRAIL_POINTS, TrailSampler

R = 2.0
"""Radius of the circle, metres."""
W = 0.5
"""Angular speed, rad/s."""
HZ = 50
STEP_NS = 1_000_000_000 // HZ


def circle(ns: int) -> tuple[float, float, float]:
    """Where ``robot`` is sent at stamp ``ns``."""
    a = W * ns / 1e9
    return (R * math.cos(a), R * math.sin(a), 0.3)


def expected(ns: int) -> tuple[float, float, float]:
    """tf2's answer at stamp ``ns``: the two samples around it, interpolated linearly
    (the samples are at multiples of ``STEP_NS``)."""
    t0 = ns // STEP_NS * STEP_NS
    u = (ns - t0) / STEP_NS
    p0, p1 = circle(t0), circle(t0 + STEP_NS)
    return (p0[0] + u * (p1[0] - p0[0]), p0[1] + u * (p1[1] - p0[1]), 0.3)


def sample(ns: int, frame: str = "robot") -> TransformStamped:
    a = W * ns / 1e9
    return TransformStamped(Header(Time.from_ns(ns), "world"), frame,
                            Transform(Vector3(*circle(ns)),
                                      Quaternion(0.0, 0.0, math.sin(a / 2), math.cos(a / 2))))


def feed(core: BufferCore, first_s: float, last_s: float, frame: str = "robot") -> None:
    for k in range(round(first_s * HZ), round(last_s * HZ) + 1):
        core.set_transform(sample(k * STEP_NS, frame), "test")


def assert_on_circle(stamps: np.ndarray, points: np.ndarray) -> None:
    assert len(stamps) == len(points) > 1
    for ns, p in zip(stamps.tolist(), points, strict=True):
        assert tuple(p) == pytest.approx(expected(ns), abs=1e-9)
    # and on the circle within the chord's sag, R (1 - cos(W / HZ / 2)) = 2.5e-5 m
    radius = np.hypot(points[:, 0], points[:, 1])
    assert np.all(np.abs(radius - R) <= R * (1 - math.cos(W / HZ / 2)) + 1e-12)


def test_trail_points_are_lookups_on_the_circle_at_grid_stamps() -> None:
    core = BufferCore(cache_time=30.0)
    feed(core, 1.0, 21.0)
    sampler = TrailSampler(max_points=201)
    trail = sampler.sample(core, "world", "robot", 5.0)
    assert trail.error is None
    # 5 s / 200 = 25 ms grid, from 16 s to the end, the latest data (21 s)
    assert trail.stamps[0] == 16_000_000_000 and trail.stamps[-1] == 21_000_000_000
    assert len(trail.stamps) == 201
    assert set(np.diff(trail.stamps).tolist()) == {25_000_000}
    assert_on_circle(trail.stamps, trail.points)
    assert sampler.lookups == 201
    seg = trail.segments()
    assert seg.shape == (200, 2, 3)
    assert np.array_equal(seg[:, 0], trail.points[:-1])
    assert np.array_equal(seg[:, 1], trail.points[1:])

    # a second later: only the new stamps are looked up (40 grid stamps + the end)
    feed(core, 21.02, 22.0)
    trail = sampler.sample(core, "world", "robot", 5.0)
    assert sampler.lookups == 201 + 41
    assert trail.stamps[0] == 17_000_000_000 and trail.stamps[-1] == 22_000_000_000
    assert len(trail.stamps) == 201
    assert_on_circle(trail.stamps, trail.points)


def test_trail_is_bounded_by_the_buffer_and_max_points() -> None:
    core = BufferCore(cache_time=30.0)
    feed(core, 1.0, 21.0)
    sampler = TrailSampler()
    trail = sampler.sample(core, "world", "robot", 600.0)
    # 600 s asked of 20 s of data: the stamps the buffer cannot answer give no point
    assert trail.error is None
    assert trail.stamps[0] >= 1_000_000_000 and trail.stamps[-1] == 21_000_000_000
    step = math.ceil(600e9 / (MAX_TRAIL_POINTS - 1))
    assert len(trail.stamps) == (21_000_000_000 - 1) // step - 1_000_000_000 // step + 1
    assert sampler.lookups <= MAX_TRAIL_POINTS
    assert_on_circle(trail.stamps, trail.points)


def test_trail_errors_static_and_bad_durations() -> None:
    core = BufferCore(cache_time=30.0)
    feed(core, 1.0, 3.0)
    core.set_transform_static(TransformStamped(
        Header(Time(0), "world"), "mast",
        Transform(Vector3(4.0, 5.0, 6.0), Quaternion(0.0, 0.0, 0.0, 1.0))), "test")
    sampler = TrailSampler()
    still = sampler.sample(core, "world", "mast", 5.0)
    assert still.error is None and still.points.tolist() == [[4.0, 5.0, 6.0]]
    assert still.segments().shape == (0, 2, 3)
    missing = sampler.sample(core, "world", "nowhere", 5.0)
    assert missing.points.shape == (0, 3)
    assert missing.error is not None and '"nowhere"' in missing.error
    for bad in (0.1, 601.0, float("nan")):
        with pytest.raises(ValueError, match=r"trail seconds must be between 0\.5 and 600"):
            sampler.sample(core, "world", "robot", bad)
    for bad_points in (1, MAX_TRAIL_POINTS + 1):
        with pytest.raises(ValueError, match="max_points"):
            TrailSampler(max_points=bad_points)


pytest.importorskip("viser")

from tfbus.view.server import TRAIL_COLOUR, TfPage  # noqa: E402


def test_trail_drawn_live_on_the_page(page: TfPage) -> None:
    from tfbus.monitor import TfSummary
    from tfbus.view.player import draw_live

    core = BufferCore(cache_time=30.0)
    feed(core, 1.0, 21.0)
    hostile = "<img src=x onerror=alert(1)>\x1b"
    feed(core, 1.0, 21.0, frame=hostile)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    assert page.trail is None and page.trail_line is None  # none by default
    assert page.trail_dropdown.options == ("", "<img src=x onerror=alert(1)>\\x1b",
                                           "robot", "world")
    page.set_trail("robot", 5.0)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    trail = page.trail
    assert trail is not None and trail.fixed_frame == "world"
    assert trail.stamps[-1] == 21_000_000_000
    assert trail.stamps[0] >= 16_000_000_000 and len(trail.stamps) <= MAX_TRAIL_POINTS
    assert_on_circle(trail.stamps, trail.points)
    drawn = np.asarray(page.trail_line.points, dtype=np.float64)
    assert drawn.shape == (len(trail.points) - 1, 2, 3)
    assert np.allclose(drawn, trail.segments(), rtol=0, atol=1e-6)  # (float32 on the wire)
    assert page.trail_line.visible
    assert f"trail of robot in world: {len(trail.points)} points over 5.00 s" \
        in page.trail_html
    assert TRAIL_COLOUR == (0, 170, 200)
    # the hostile id: its trail drawn, its name as text
    page.set_trail(hostile)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    assert page.trail is not None and len(page.trail.points) == len(trail.points)
    assert "trail of &lt;img src=x onerror=alert(1)&gt;\\x1b in world" in page.trail_html
    assert "<img" not in page.trail_html
    page.set_trail(None)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    assert page.trail is None and not page.trail_line.visible and page.trail_html == ""
    with pytest.raises(ValueError, match="trail seconds"):
        page.set_trail("robot", 0.0)


def test_a_redraw_never_shows_no_trail_while_one_is_drawn(page: TfPage) -> None:
    """``page.trail`` is read from other threads (the page's, an embedding app's): while a
    redraw samples the trail again, it is still the trail drawn before, and then the new
    one; never None in between."""
    from tfbus.monitor import TfSummary
    from tfbus.view.player import draw_live

    core = BufferCore(cache_time=30.0)
    feed(core, 1.0, 21.0)
    page.set_trail("robot", 5.0)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    before = page.trail
    assert before is not None and before.error is None
    seen: list[object] = []
    sample = page._trails.sample

    def watched(*args: object, **kwargs: object) -> object:
        seen.append(page.trail)  # what another thread would read during the sampling
        return sample(*args, **kwargs)  # type: ignore[arg-type]

    page._trails.sample = watched  # type: ignore[method-assign]
    page.set_trail("robot", 3.0)
    draw_live(page, core, TfSummary(), Time.from_sec(21.0))
    assert seen == [before]
    after = page.trail
    assert after is not None and after is not before
    assert after.stamps[-1] == 21_000_000_000 and after.stamps[0] >= 18_000_000_000


def _bag(path: Path) -> Path:
    from tfbus.bag.formats import BagMessage
    from tfbus.bag.writer import write_bag

    start = 100 * 1_000_000_000
    msgs = [BagMessage(Time.from_ns(start + k * STEP_NS), "/tf",
                       TFMessage([sample(start + k * STEP_NS)]), "/mover")
            for k in range(20 * HZ + 1)]
    write_bag(path, msgs)
    return path


def test_trail_follows_the_bag_slider(page: TfPage, tmp_path: Path) -> None:
    from tfbus.view.player import BagPlayer
    from tfbus.view.timeline import BagTimeline

    player = BagPlayer(page, BagTimeline.read(_bag(tmp_path / "circle.bag")), paused=True)
    page.set_trail("robot", 2.0)
    for at in (10.0, 15.0, 5.0):  # (5 s: a jump back, the bag's buffer made again)
        player.seek(at)
        player.render()
        trail = page.trail
        assert trail is not None and trail.error is None, at
        end = 100_000_000_000 + round(at * 1e9)
        assert trail.stamps[-1] == end  # the slider's time: the latest data then
        assert trail.stamps[0] >= end - 2_000_000_000
        assert len(trail.stamps) == MAX_TRAIL_POINTS  # 2 s of 50 Hz data fill the grid
        assert_on_circle(trail.stamps, trail.points)
        assert np.allclose(np.asarray(page.trail_line.points, dtype=np.float64),
                           trail.segments(), rtol=0, atol=1e-5)


class Circling:
    """The circle drawn on ``page`` by a thread as ``tfbus view`` draws it: a bag's player
    paused at 10 s (its loop as ``--bag`` runs it), or a live buffer holding 1-21 s
    redrawn 30 times a second (``draw_live``, as ``LiveView.render``)."""

    def __init__(self, page: TfPage, kind: str, bag: Path) -> None:
        from tfbus.view.player import BagPlayer
        from tfbus.view.timeline import BagTimeline

        self.kind = kind
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.core = BufferCore(cache_time=30.0)
        self.end_ns = 110_000_000_000 if kind == "bag" else 21_000_000_000
        if kind == "bag":
            player = BagPlayer(page, BagTimeline.read(_bag(bag)), paused=True)
            player.seek(10.0)
            self.thread = threading.Thread(target=player.run, args=(self.stop,), daemon=True)
            self.ready = "bag time 10.00"
        else:
            feed(self.core, 1.0, 21.0)
            self.thread = threading.Thread(target=self._live, args=(page,), daemon=True)
            self.ready = "fixed frame: world"

    def _live(self, page: TfPage) -> None:
        from tfbus.monitor import TfSummary
        from tfbus.view.player import draw_live

        while not self.stop.is_set():
            with self.lock:
                draw_live(page, self.core, TfSummary(), Time.from_ns(self.end_ns))
            self.stop.wait(1 / 30)

    def more(self) -> None:
        """Live: one more second of the circle (the trail must follow)."""
        with self.lock:
            feed(self.core, 21.02, 22.0)
            self.end_ns = 22_000_000_000


@pytest.fixture(params=["bag", "live"])
def circling(request: pytest.FixtureRequest, page: TfPage, tmp_path: Path
             ) -> Iterator[Circling]:
    run = Circling(page, request.param, tmp_path / "circle.bag")
    run.thread.start()
    try:
        yield run
    finally:
        run.stop.set()
        run.thread.join(timeout=10)


def test_trail_picked_in_chromium(chromium: str, page: TfPage, circling: Circling,
                                  tmp_path: Path) -> None:
    from cdp import Chromium
    from test_view_controls import _pick, _row, _type_into, until

    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait(f"document.body && document.body.innerText.includes({circling.ready!r})")
        # the panel filled (the frame tree last): the controls no longer move
        c.wait("document.body.innerHTML.includes('<td>robot</td><td>world</td>')")
        assert page.trail_line is None
        _pick(c, "trail frame", "robot")
        until(lambda: page.trail_choice == "robot", "robot picked")
        c.wait("document.body.innerText.includes('trail of robot in world: 2000 points "
               "over 10.00 s')")
        _type_into(c, f"{_row('trail seconds')}.querySelector('input')", "3", enter=True)
        until(lambda: page.trail_seconds == 3.0, "3 s typed")
        c.wait("document.body.innerText.includes('trail of robot in world: 2000 points "
               "over 3.00 s')")
        trail = page.trail
        assert trail is not None and trail.stamps[-1] == circling.end_ns
        assert_on_circle(trail.stamps, trail.points)
        until(lambda: page.trail_line is not None and page.trail_line.visible
              and len(page.trail_line.points) == 1999, "the trail drawn")
        shot = c.screenshot(tmp_path / f"trail-{circling.kind}.png")
        assert len(shot) > 10_000
        if circling.kind == "live":  # a second more: the trail ends at the new data
            circling.more()
            until(lambda: page.trail is not None
                  and page.trail.stamps[-1] == 22_000_000_000, "the trail followed")
            trail = page.trail
            assert trail is not None and trail.stamps[0] >= 19_000_000_000
            assert_on_circle(trail.stamps, trail.points)
