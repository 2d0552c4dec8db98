"""``tfbus doctor``'s findings in the page of ``tfbus view`` (tfbus/view/server.py
``set_findings``, player.py, live.py): on a bag up to the slider's time (the whole file's
at its end, as ``tfbus doctor BAG``), live from the view's listener, ids and senders with
markup kept as text; in headless Chromium driven through the DevTools protocol."""

from __future__ import annotations

import html
import threading
from pathlib import Path

import pytest

pytest.importorskip("viser")

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.doctor import Doctor, diagnose
from tfbus.view.player import BagPlayer
from tfbus.view.server import MAX_FINDINGS_SHOWN, TfPage
from tfbus.view.timeline import BagTimeline

T0 = 1_700_000_000 * 10**9
MS = 1_000_000
HOSTILE_FRAME = "/<img src=x onerror=alert(1)>"
"""A frame id that is markup and starts with '/' (the doctor's ``leading_slash``)."""
HOSTILE_SENDER = "/<script>rogue</script>"
"""A caller id that is markup: it also sends ``world -> base`` (``several_authorities``)."""


def tf(parent: str, child: str, stamp_ns: int, x: float = 1.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def hostile_bag(path: Path) -> Path:
    """6 s: ``/base_bc`` sends ``world -> base`` at 10 Hz throughout; from 3 s on
    :data:`HOSTILE_SENDER` sends it too and ``/arm_bc`` sends ``base ->``
    :data:`HOSTILE_FRAME` (a ROS 1 bag, one connection per caller id)."""
    from rosbags.rosbag1 import Writer

    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore, to_rosbags

    records: list[tuple[int, str, list[TransformStamped]]] = []
    for k in range(60):
        t = T0 + k * 100 * MS
        records.append((t + 1000, "/base_bc", [tf("world", "base", t)]))
        if k >= 30:
            records.append((t + 3 * MS, HOSTILE_SENDER, [tf("world", "base", t + 2 * MS)]))
            records.append((t + 4 * MS, "/arm_bc", [tf("base", HOSTILE_FRAME, t + 2 * MS)]))
    store = tf_typestore(ros1=True)
    with Writer(path) as writer:
        conns: dict[str, object] = {}
        for t, caller, tfs in sorted(records, key=lambda r: r[0]):
            conn = conns.get(caller)
            if conn is None:
                conn = conns[caller] = writer.add_connection(
                    "/tf", ROSBAGS_TF_TYPE, typestore=store, callerid=caller)
            writer.write(conn, t, store.serialize_ros1(to_rosbags(store, tfs, ros1=True),
                                                       ROSBAGS_TF_TYPE))
    return path


def _checks(page: TfPage) -> list[str]:
    import re

    return re.findall(r"<code>(\w+)</code>", page.findings_html)


def test_bag_findings_follow_the_slider(page: TfPage, tmp_path: Path) -> None:
    bag = hostile_bag(tmp_path / "hostile.bag")
    player = BagPlayer(page, BagTimeline.read(bag), paused=True)
    player.seek(2.0)
    player.render()
    assert "no findings" in page.findings_html
    assert "21 tf messages up to bag time 2.00 s diagnosed" in page.findings_html
    player.seek(5.0)
    player.render()
    assert sorted(_checks(page)) == ["leading_slash", "several_authorities"]
    # ids and senders with markup are text: escaped, never an element
    assert "<img" not in page.findings_html and "<script>" not in page.findings_html
    assert f"frames: {html.escape(HOSTILE_FRAME)}" in page.findings_html
    assert html.escape(HOSTILE_SENDER) in page.findings_html
    assert "drop the leading &#x27;/&#x27;" in page.findings_html  # the advice
    player.seek(1.0)  # a jump back: diagnosed again from the start
    player.render()
    assert "no findings" in page.findings_html and not _checks(page)
    player.seek(player.duration)  # the end: the whole file's diagnosis
    player.render()
    whole = diagnose(bag)
    assert _checks(page) == [f.check for f in whole.findings]
    assert f"{whole.messages} tf messages up to bag time" in page.findings_html


def test_findings_shown_at_most(page: TfPage) -> None:
    doctor = Doctor()
    for k in range(MAX_FINDINGS_SHOWN + 7):  # one leading_slash finding per frame
        doctor.add(T0 + k, [tf("world", f"/f{k}", T0)], "/bc", static=False)
    findings = doctor.report().findings
    assert len(findings) >= MAX_FINDINGS_SHOWN + 7
    page.set_findings(findings)
    assert page.findings_html.count("class='tfbus-finding'") == MAX_FINDINGS_SHOWN
    assert f"and {len(findings) - MAX_FINDINGS_SHOWN} more" in page.findings_html
    page.set_findings(None)
    assert page.findings_html == ""


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.mark.anyio
async def test_live_findings_from_the_views_listener(page: TfPage) -> None:
    """As ``tfbus view --bus`` wires it: the MonitoredSink's observer feeds the doctor,
    the LiveView reports its findings at most once per second of its clock."""
    import anyio

    from tfbus.broadcaster import TransformBroadcaster
    from tfbus.buffer import Buffer
    from tfbus.bus import Bus
    from tfbus.clock import ManualClock
    from tfbus.listener import TransformListener
    from tfbus.monitor import MonitoredSink, TfSummary
    from tfbus.view.live import LiveView

    clock = ManualClock(Time.from_sec(50.0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: HOSTILE_SENDER)
    doctor = Doctor(source="test")
    sink.observers.append(lambda now, tfs, who, static: doctor.add(now, tfs, who,
                                                                   static=static))
    view = LiveView(page, buffer, stats, clock, doctor=doctor)
    async with Bus() as bus, TransformListener(sink, bus, clock=clock):
        b = TransformBroadcaster(bus)

        async def send(child: str) -> None:
            before = stats.messages.get("/tf", 0)
            await b.send_transform(tf("odom", child, clock.now().ns))
            with anyio.fail_after(5):
                while stats.messages.get("/tf", 0) < before + 1:
                    await anyio.sleep(0)

        await send("base_link")
        view.render()
        assert "no findings" in page.findings_html
        assert "1 tf messages received diagnosed" in page.findings_html
        await send(HOSTILE_FRAME)
        view.render()  # within a second of the last report: not reported again
        assert "no findings" in page.findings_html
        await clock.advance(1.0)
        view.render()
        assert _checks(page) == ["leading_slash"]
        assert f"frames: {html.escape(HOSTILE_FRAME)}" in page.findings_html
        assert f"senders: {html.escape(HOSTILE_SENDER)}" in page.findings_html
        assert "<img" not in page.findings_html
    buffer.close()


# ---------------------------------------------------------------- in headless Chromium


def _panel_text(c: object) -> str:
    from cdp import Chromium

    assert isinstance(c, Chromium)
    return str(c.js("document.body ? document.body.innerText : ''"))


def test_bag_findings_in_chromium(chromium: str, page: TfPage, tmp_path: Path) -> None:
    """The slider's number box typed into (real key events through CDP) moves bag time;
    the doctor's panel follows; the hostile id shows as its text, no element made."""
    from cdp import Chromium

    bag = hostile_bag(tmp_path / "hostile.bag")
    player = BagPlayer(page, BagTimeline.read(bag), paused=True)
    player.seek(2.0)
    stop = threading.Event()
    runner = threading.Thread(target=player.run, args=(stop,), daemon=True)
    runner.start()
    try:
        with Chromium(chromium) as c:
            c.open(f"http://127.0.0.1:{page.port}/")
            c.wait("document.body && document.body.innerText.includes('no findings')")
            assert "21 tf messages up to bag time 2.00 s diagnosed" in _panel_text(c)
            # type 5 into the number box beside the "bag time (s)" slider, then Enter
            c.js("(() => { const l = [...document.querySelectorAll('label')].find("
                 "e => e.textContent === 'bag time (s)'); const box = l.closest("
                 "'.mantine-Flex-root').parentElement.querySelector("
                 "'input.mantine-NumberInput-input'); box.focus(); box.select(); })()")
            c.type_text("5")
            c.key("Enter", "Enter", 13)
            c.wait("document.body.innerText.includes('leading_slash')")
            text = _panel_text(c)
            assert player.position == pytest.approx(5.0)
            assert "several_authorities" in text
            assert f"frames: {HOSTILE_FRAME}" in text  # shown as the id's own text
            assert HOSTILE_SENDER in text
            assert c.js("document.querySelectorAll('img[src=x]').length") == 0
            assert c.js("[...document.scripts].some(s => s.textContent === 'rogue')") is False
            c.screenshot(tmp_path / "doctor.png")
            assert (tmp_path / "doctor.png").stat().st_size > 10_000
    finally:
        stop.set()
        runner.join(timeout=10)
