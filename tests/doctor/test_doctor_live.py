"""``tfbus.doctor`` live on the in-process bus: a :class:`~tfbus.listener.TransformListener`
feeds a :class:`~tfbus.doctor.DoctorSink`, time driven by ManualClock (asyncio and trio);
the sender is the message's authority, as the ROS 1 transport delivers it (its
connection's caller id)."""

from __future__ import annotations

import anyio
import pytest
from doctor_faults import EXPECTED, FAULTS

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.clock import ManualClock
from tfbus.doctor import Doctor, DoctorSink, Level
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage

T0 = 1_700_000_000 * 10**9
MS = 1_000_000


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def tf(parent: str, child: str, ns: int) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(1.0, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def from_sender(name: str) -> type[TFMessage]:
    """A TFMessage type naming its publisher, as the ROS 1 transport makes them."""
    return type("TFMessage", (TFMessage,), {"__slots__": (), "authority": name})


ODOMETRY, ROGUE, AHEAD = from_sender("/odometry"), from_sender("/rogue"), from_sender("/ahead")


async def _until(doctor: Doctor, messages: int) -> None:
    with anyio.fail_after(10):
        while doctor.messages < messages:
            await anyio.sleep(0)


@pytest.mark.anyio
async def test_faults_injected_on_the_in_process_bus() -> None:
    """2 s of odom -> base_link at 50 Hz from /odometry, /rogue sending it too at 10 Hz
    during the second second, /ahead sending map -> odom stamped 0.3 s in the future; then
    3 s of silence. Found: two broadcasters of base_link at once, /ahead's clock, and
    both links stopped; the buffer got every transform."""
    clock = ManualClock(Time.from_ns(T0))
    buffer = Buffer(cache_time=10.0, clock=clock)
    doctor = Doctor(source="memory")
    sent = 0
    async with Bus() as bus, TransformListener(DoctorSink(doctor, clock, buffer), bus,
                                               clock=clock):
        for k in range(100):
            stamp = T0 + k * 20 * MS
            await clock.set(Time.from_ns(stamp + 5 * MS))
            await bus.publish("/tf", ODOMETRY([tf("odom", "base_link", stamp)]))
            sent += 1
            if k % 5 == 0:
                await bus.publish("/tf", AHEAD([tf("map", "odom", stamp + 300 * MS)]))
                sent += 1
            if k >= 50 and k % 5 == 2:
                await bus.publish("/tf", ROGUE([tf("odom", "base_link", stamp + 3 * MS)]))
                sent += 1
            await _until(doctor, sent)
        await clock.set(Time.from_ns(T0 + 5000 * MS))
        report = doctor.report(now=clock.now())
    got = [(f.check, f.level, f.frames, f.senders) for f in report.findings]
    assert got == [
        ("clock_offset", Level.ERROR, ("odom",), ("/ahead",)),
        ("several_authorities", Level.ERROR, ("base_link", "odom"), ("/odometry", "/rogue")),
        ("stopped", Level.WARNING, ("base_link", "odom"), ("/odometry", "/rogue")),
        ("stopped", Level.WARNING, ("odom", "map"), ("/ahead",)),
    ]
    assert report.messages == sent == 100 + 20 + 10
    (ahead,) = report.by_check("clock_offset")
    assert ahead.counts["median_delay_s"] == pytest.approx(-0.295)
    (both,) = report.by_check("several_authorities")
    assert dict(both.counts) == {"/odometry": 100, "/rogue": 10}
    assert buffer.lookup_transform("map", "base_link", Time(0)).header.stamp.ns == T0 + 1980 * MS
    buffer.close()


@pytest.mark.anyio
async def test_a_clean_live_tree_has_no_finding_until_it_stops() -> None:
    """A clean 10 Hz link: no finding while it runs; 0.6 s of silence is not yet
    stale (stale_after 1 s), 1.2 s is."""
    clock = ManualClock(Time.from_ns(T0))
    doctor = Doctor()
    async with Bus() as bus, TransformListener(DoctorSink(doctor, clock), bus, clock=clock):
        for k in range(30):
            await clock.set(Time.from_ns(T0 + k * 100 * MS + MS))
            await bus.publish("/tf", ODOMETRY([tf("odom", "base_link", T0 + k * 100 * MS)]))
            await _until(doctor, k + 1)
    assert doctor.report(now=clock.now()).findings == ()
    assert doctor.report(now=Time.from_ns(T0 + 2900 * MS + 600 * MS)).findings == ()
    (stopped,) = doctor.report(now=Time.from_ns(T0 + 2900 * MS + 1200 * MS)).findings
    assert (stopped.check, stopped.senders) == ("stopped", ("/odometry",))


@pytest.mark.anyio
@pytest.mark.parametrize("check", sorted(FAULTS))
async def test_every_fault_live_as_in_its_recording(check: str) -> None:
    """Each fault's records published on the in-process bus, the clock set to each
    record's receive time first, each sender named on its messages: the same single
    finding as from the recording (doctor_faults.EXPECTED)."""
    clock = ManualClock(Time.from_ns(T0 - MS))
    doctor = Doctor()
    kinds: dict[str, type[TFMessage]] = {}
    records = sorted(FAULTS[check](), key=lambda r: r[0])
    async with Bus() as bus, TransformListener(DoctorSink(doctor, clock), bus, clock=clock):
        for n, (t, topic, sender, tfs) in enumerate(records, 1):
            kind = kinds.get(sender) or kinds.setdefault(sender, from_sender(sender))
            await clock.set(Time.from_ns(t))
            await bus.publish(topic, kind(tfs))
            await _until(doctor, n)
        report = doctor.report()
    assert [(f.check, f.level, f.frames, f.senders) for f in report.findings] == [
        (check, *EXPECTED[check])]
