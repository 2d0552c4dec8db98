"""The display controls of ``tfbus view``'s page (tfbus/view/server.py, player.py,
live.py), driven in headless Chromium through the DevTools protocol with real mouse and
key events: the fixed frame picked in a dropdown (the scene re-rooted: every pose equals
``lookup_transform(picked, frame)``), a regex frame filter (an invalid one shown as an
error, the previous filter kept), a labels toggle and the axis length."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("viser")

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.monitor import TfSummary
from tfbus.view.player import BagPlayer
from tfbus.view.server import TfPage
from tfbus.view.timeline import BagTimeline

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"


def until(cond: Callable[[], bool], what: str, timeout: float = 30.0,
          seen: Callable[[], object] | None = None) -> None:
    """Poll ``cond`` (the server side of the page) for at most ``timeout`` seconds; on a
    timeout the error says what ``seen`` returns then (the state that was found)."""
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            found = "" if seen is None else f" (found {seen()!r})"
            raise AssertionError(f"never: {what}{found}")
        time.sleep(0.05)


def _row(label: str) -> str:
    """JS: the GUI row of the control labelled ``label``."""
    return (f"[...document.querySelectorAll('label')].find(e => e.textContent === "
            f"{json.dumps(label)})?.closest('.mantine-Flex-root')")


def _centre(c: object, selector_js: str) -> tuple[float, float]:
    from cdp import Chromium

    assert isinstance(c, Chromium)
    # Only once the element is what a click there hits (a list still closing over it, or
    # a layout still moving, would take the click).
    r = c.wait(f"(() => {{ const e = {selector_js}; if (!e) return null; e.scrollIntoView("
               "{block: 'center'}); const b = e.getBoundingClientRect(); "
               "const x = b.x + b.width / 2, y = b.y + b.height / 2; "
               "const hit = document.elementFromPoint(x, y); "
               "return hit && (hit === e || e.contains(hit)) ? [x, y] : null; })()")
    return float(r[0]), float(r[1])


def _type_into(c: object, selector_js: str, text: str, enter: bool = False) -> None:
    from cdp import Chromium

    assert isinstance(c, Chromium)
    c.click(*_centre(c, selector_js))
    c.js(f"(() => {{ const e = {selector_js}; e.focus(); e.select(); }})()")
    c.type_text(text)
    if enter:
        c.key("Enter", "Enter", 13)


@pytest.fixture
def playing(page: TfPage) -> Iterator[BagPlayer]:
    """The turtle bag paused at 5 s, its player's loop running as ``tfbus view --bag``."""
    player = BagPlayer(page, BagTimeline.read(TURTLE), paused=True)
    player.seek(5.0)
    stop = threading.Event()
    runner = threading.Thread(target=player.run, args=(stop,), daemon=True)
    runner.start()
    try:
        yield player
    finally:
        stop.set()
        runner.join(timeout=10)


def test_controls_in_chromium_on_a_bag(chromium: str, page: TfPage, playing: BagPlayer,
                                       tmp_path: Path) -> None:
    from cdp import Chromium

    core = playing.timeline.buffer_at(playing.time())
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("document.body && document.body.innerText.includes('bag time 5.00')")
        assert c.js(f"{_row('fixed frame')}.querySelector('input').value") == "world"
        # the fixed frame picked in the dropdown: a click on it, a click on "turtle1"
        _pick(c, "fixed frame", "turtle1")
        until(lambda: page.fixed_frame_choice == "turtle1", "turtle1 picked")
        until(lambda: playing.last_scene is not None
              and playing.last_scene.fixed_frame == "turtle1", "the scene re-rooted")
        for name in ("world", "turtle1", "turtle2", "carrot"):
            ref = core.lookup_transform("turtle1", name, Time(0)).transform.translation
            assert tuple(page.frames[name].position) == pytest.approx(
                (ref.x, ref.y, ref.z), rel=1e-5, abs=1e-8)
        assert tuple(page.frames["turtle1"].position) == (0.0, 0.0, 0.0)
        assert tuple(page.frames["world"].position) != (0.0, 0.0, 0.0)
        c.wait("document.body.innerText.includes('fixed frame: turtle1')")
        # a frame filter: only the turtles drawn and listed
        _type_into(c, f"{_row('frame filter')}.querySelector('input')", "turtle")
        until(lambda: not page.frames["world"].visible, "world filtered out")
        assert [page.frames[n].visible for n in ("world", "turtle1", "turtle2", "carrot")] \
            == [False, True, True, False]
        c.wait("document.body.innerText.includes('2 of 4 frames left out by the filter')")
        assert "<td>carrot</td>" not in c.html() and "<td>turtle2</td>" in c.html()
        # an invalid one: said so, the previous filter kept, nothing broken
        _type_into(c, f"{_row('frame filter')}.querySelector('input')", "turtle(")
        c.wait("document.body.innerText.includes('frame filter: invalid regular expression')")
        assert "missing ) at position 7" in c.js("document.body.innerText")
        assert not page.frames["world"].visible and page.frames["turtle2"].visible
        # labels off
        assert page.labels["turtle1"].visible
        c.click(*_centre(c, f"{_row('labels')}.querySelector('input')"))
        until(lambda: not page.labels["turtle1"].visible, "labels hidden")
        # axis length 1 m: turtle2's x axis is 1 m long
        _type_into(c, f"{_row('axis length (m)')}.querySelector("
                      "'input.mantine-NumberInput-input')", "1", enter=True)

        def x_axis_length() -> float:
            row = page.axes_rows.get("turtle2")
            if row is None:
                return 0.0
            seg = np.asarray(page.axes.points[row], dtype=np.float64)
            return float(np.linalg.norm(seg[1] - seg[0]))

        until(lambda: abs(x_axis_length() - 1.0) < 1e-6, "1 m axes")
        shot = c.screenshot(tmp_path / "controls.png")
        assert len(shot) > 10_000


def test_filter_and_fixed_frame_live(page: TfPage) -> None:
    """Live (draw_live as LiveView.render calls it): the page's picked fixed frame and
    filter apply to the next redraw; an over-long filter is refused with an error."""
    from tfbus.view.player import draw_live
    from tfbus.view.server import MAX_FILTER_LENGTH

    clock = ManualClock(Time.from_sec(10.0))
    core, stats = BufferCore(), TfSummary()
    for child, parent, x in (("base", "odom", 1.0), ("arm", "base", 2.0)):
        t = TransformStamped(Header(clock.now(), parent), child,
                             Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
        core.set_transform(t, "bc")
        stats.add(clock.now(), [t], "bc", static=False)
    draw_live(page, core, stats, clock.now())
    assert tuple(page.frames["arm"].position) == (3.0, 0.0, 0.0)
    assert page.fixed_dropdown.options == ("arm", "base", "odom")
    assert page.fixed_dropdown.value == "odom"
    page.fixed_frame_choice = "base"
    draw_live(page, core, stats, clock.now(), fixed_frame=page.fixed_frame_choice)
    assert tuple(page.frames["arm"].position) == (2.0, 0.0, 0.0)
    assert tuple(page.frames["odom"].position) == (-1.0, 0.0, 0.0)
    assert page.fixed_dropdown.value == "base"
    assert page.set_frame_filter("^(arm|odom)$") is None
    draw_live(page, core, stats, clock.now(), fixed_frame="base")
    assert not page.frames["base"].visible and page.frames["arm"].visible
    err = page.set_frame_filter("a" * (MAX_FILTER_LENGTH + 1))
    assert err == f"frame filter: longer than {MAX_FILTER_LENGTH} characters"
    assert err in page.filter_error_html
    assert page.set_frame_filter("") is None and page.filter_error_html == ""
    draw_live(page, core, stats, clock.now(), fixed_frame="base")
    assert page.frames["base"].visible
    # a frame that appears later is offered at the next redraw, in every dropdown
    t = TransformStamped(Header(clock.now(), "arm"), "grip\x07per",
                         Transform(Vector3(0.5, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
    core.set_transform(t, "bc")
    stats.add(clock.now(), [t], "bc", static=False)
    draw_live(page, core, stats, clock.now(), fixed_frame="base")
    offered = ("arm", "base", "grip\\x07per", "odom")
    assert page.fixed_dropdown.options == offered
    assert page.trail_dropdown.options == ("", *offered)
    assert all(d.options == ("", *offered) for d in page.pair_dropdowns)
    assert page._fixed_options["grip\\x07per"] == "grip\x07per"


def test_a_filter_that_backtracks_for_ever_is_dropped_not_run(page: TfPage) -> None:
    """``(a|aa)+$`` on a long id of a's backtracks exponentially (Python's re would take
    hours on 60 characters): the search stops after FILTER_TIMEOUT, the redraw returns,
    the filter is dropped with an error line under the box, and the next redraw draws
    every frame."""
    from tfbus.view.player import draw_live
    from tfbus.view.server import FILTER_TIMEOUT

    clock = ManualClock(Time.from_sec(10.0))
    core, stats = BufferCore(), TfSummary()
    hostile = "a" * 60 + "!"
    for child, parent in (("base", "odom"), (hostile, "base")):
        t = TransformStamped(Header(clock.now(), parent), child,
                             Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))
        core.set_transform(t, "bc")
        stats.add(clock.now(), [t], "bc", static=False)
    assert page.set_frame_filter("(a|aa)+$") is None
    draw_live(page, core, stats, clock.now())
    assert page.frame_filter is None
    assert f"took longer than {FILTER_TIMEOUT * 1000:g} ms" in page.filter_error_html
    draw_live(page, core, stats, clock.now())  # the next redraw: no filter
    assert page.frames[hostile].visible and page.frames["base"].visible
    assert page.set_frame_filter("^base$") is None and page.filter_error_html == ""
    draw_live(page, core, stats, clock.now())
    assert page.frames["base"].visible and not page.frames[hostile].visible


def _pick(c: object, label: str, option: str) -> None:
    """Open the dropdown ``label`` and click its ``option`` (real mouse events)."""
    from cdp import Chromium

    assert isinstance(c, Chromium)
    inp = f"{_row(label)}.querySelector('input')"
    # the option in this dropdown's own list: the one its input names (aria-controls)
    # while open, so that a click another list took is never taken for this one's
    shown = (f"(() => {{ const i = {inp}; const l = i && i.getAttribute('aria-expanded') "
             "=== 'true' && document.getElementById(i.getAttribute('aria-controls')); "
             "return l ? [...l.querySelectorAll('[role=option]')].find(e => e.textContent "
             f"=== {json.dumps(option)} && e.getBoundingClientRect().height > 0) : null; }})()")
    # The list of the dropdown picked before may still be closing (a loaded machine): its
    # options, shown, would be clicked in place of this one's.
    closed = ("![...document.querySelectorAll('[role=option]')]"
              ".some(e => e.getBoundingClientRect().height > 0)")
    value = f"{inp}.value === {json.dumps(option)}"
    for _ in range(3):  # a click before the page settled, or on a list still moving in
        c.wait(closed, timeout=10.0)
        c.click(*_centre(c, inp))
        try:
            c.wait(f"!!({shown})", timeout=5.0)
            now = _centre(c, shown)
            for _ in range(50):  # until the list's opening transition is over
                before, now = now, _centre(c, shown)
                if now == before:
                    break
            c.click(*now)
            c.wait(value, timeout=5.0)
            return
        except TimeoutError:
            c.key("Escape", "Escape", 27)
    raise AssertionError(f"could not pick {option!r} in {label!r}")


def test_two_frames_in_chromium(chromium: str, page: TfPage, playing: BagPlayer,
                                tmp_path: Path) -> None:
    """tf_monitor turtle2 carrot in the page: the chain through world, highlighted, and
    carrot's pose in turtle2 equal to lookup_transform's."""
    from cdp import Chromium

    core = playing.timeline.buffer_at(playing.time())
    ref = core.lookup_transform("turtle2", "carrot", Time(0)).transform
    with Chromium(chromium) as c:
        c.open(f"http://127.0.0.1:{page.port}/")
        c.wait("document.body && document.body.innerText.includes('pick two frames')")
        assert page.chain is None
        _pick(c, "frame A", "turtle2")
        until(lambda: page.pair_choice == ("turtle2", None), "A picked")
        _pick(c, "frame B", "carrot")
        until(lambda: page.pair_choice == ("turtle2", "carrot"), "B picked")
        text = c.wait("(() => { const e = document.querySelector('.tfbus-pair'); "
                      "return e && e.innerText.includes('carrot in turtle2') && e.innerText; })()")
        assert "chain: turtle2 → world → turtle1 → carrot" in text
        v, q = ref.translation, ref.rotation
        assert f"translation [{v.x:.3f}, {v.y:.3f}, {v.z:.3f}] m" in text
        assert f"rotation (x y z w) [{q.x:.3f}, {q.y:.3f}, {q.z:.3f}, {q.w:.3f}]" in text
        assert "turtle1 → carrot: static" in text
        assert playing.last_scene is not None
        age = playing.last_scene.frame("turtle2").age
        assert age is not None
        assert f"world → turtle2: 0.0 Hz, age {age:.2f} s, /turtle2_tf_broadcaster" in text
        # the chain's three links drawn over the scene, from each child to its parent
        until(lambda: page.chain is not None and page.chain_count == 3, "chain drawn")
        pts = np.asarray(page.chain.points, dtype=np.float64)
        pos = {n: tuple(page.frames[n].position) for n in ("world", "turtle1", "turtle2",
                                                           "carrot")}
        for child, parent in (("turtle2", "world"), ("carrot", "turtle1"),
                              ("turtle1", "world")):
            want = np.asarray([pos[child], pos[parent]], dtype=np.float64)
            assert any(np.allclose(seg, want, rtol=0, atol=1e-5) for seg in pts), child
        c.screenshot(tmp_path / "pair.png")


def test_two_frames_in_two_trees_and_markup(page: TfPage) -> None:
    """A and B in different trees: no chain, tf2's message; ids with markup as text."""
    from tfbus.view import build_scene

    core = BufferCore()
    odd = "<b>x</b>"
    for child, parent in ((odd, "map"), ("b", "elsewhere")):
        core.set_transform(TransformStamped(
            Header(Time.from_sec(1.0), parent), child,
            Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0))), "bc")
    scene = build_scene(core, fixed_frame="map")
    page.pair_choice = (odd, "map")
    page.draw(scene, core=core)
    assert "chain: &lt;b&gt;x&lt;/b&gt; &rarr; map" in page.pair_html
    assert "map in &lt;b&gt;x&lt;/b&gt;: translation [-1.000, 0.000, 0.000] m" in page.pair_html
    assert "<b>x</b>" not in page.pair_html and page.chain_count == 1
    page.pair_choice = (odd, "b")
    page.draw(scene, core=core)
    assert "chain:" not in page.pair_html
    err = str(core.try_lookup_transform(odd, "b", Time(0)))
    assert "Could not find a connection" in err
    import html as _html

    assert _html.escape(err, quote=True) in page.pair_html
    assert not page.chain.visible


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.mark.anyio
async def test_live_controls_and_findings_in_chromium(chromium: str, page: TfPage) -> None:
    """Live, as ``tfbus view --bus`` wires it (listener -> MonitoredSink, its observer
    feeding the doctor; LiveView.render is the draw loop's tick): the fixed frame picked
    in the browser re-roots the next redraw, the two frames' pose follows, and the
    doctor's finding on a hostile id shows as text."""
    import anyio
    from cdp import Chromium

    from tfbus.broadcaster import TransformBroadcaster
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.doctor import Doctor
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink
    from tfbus.view.live import LiveView

    odd = "/<img src=x onerror=alert(1)>"
    clock = ManualClock(Time.from_sec(20.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "/bc")
    doctor = Doctor(source="test")
    sink.observers.append(lambda now, tfs, who, static: doctor.add(now, tfs, who,
                                                                   static=static))
    view = LiveView(page, buffer, stats, clock, doctor=doctor)
    async with Bus() as bus, TransformListener(sink, bus, clock=clock):
        b = TransformBroadcaster(bus)
        for child, parent, x in (("base", "odom", 1.0), ("arm", "base", 2.0),
                                 (odd, "odom", 3.0)):
            await b.send_transform(TransformStamped(
                Header(clock.now(), parent), child,
                Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0))))
        with anyio.fail_after(5):
            while stats.messages.get("/tf", 0) < 3:
                await anyio.sleep(0)
        view.render()
        assert tuple(page.frames["arm"].position) == (3.0, 0.0, 0.0)

        def browse() -> str:
            with Chromium(chromium) as c:
                c.open(f"http://127.0.0.1:{page.port}/")
                c.wait("document.body && document.body.innerText.includes('leading_slash')")
                _pick(c, "fixed frame", "base")
                until(lambda: page.fixed_frame_choice == "base", "base picked")
                # viser's control panel sends its GUI updates through one sender that
                # keeps only the latest message of a 50 ms window (its client's
                # makeThrottledMessageSender): a pick made before the previous one went
                # out replaces it, so each pick is awaited at the server.
                _pick(c, "frame A", "arm")
                until(lambda: page.pair_choice == ("arm", None), "A picked",
                      seen=lambda: (page.pair_choice, page.fixed_frame_choice))
                _pick(c, "frame B", "odom")
                until(lambda: page.pair_choice == ("arm", "odom"), "A and B picked",
                      seen=lambda: (page.pair_choice, page.fixed_frame_choice))
                return str(c.js("document.body.innerText"))

        text = await anyio.to_thread.run_sync(browse)
        assert f"frames: {odd.lstrip('/')}" in text or f"frames: {odd}" in text
        view.render()  # the draw loop's next tick
        assert tuple(page.frames["arm"].position) == (2.0, 0.0, 0.0)
        assert tuple(page.frames["odom"].position) == (-1.0, 0.0, 0.0)
        assert "odom in arm: translation [-3.000, 0.000, 0.000] m" in page.pair_html
        assert "chain: arm &rarr; base &rarr; odom" in page.pair_html
        assert "<img" not in page.findings_html
    buffer.close()
