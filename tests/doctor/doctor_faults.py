"""Recordings with exactly one fault each, for ``tfbus doctor``'s tests (the style of
``scripts/data/make_test_bags.py``: constants, one function per recording, deterministic).

The clean robot (:func:`clean`), 10 s of a REP 105 tree, each link its own node's:

* ``/robot_state_publisher``: one ``/tf_static`` message at the start, ``base_link ->
  laser`` and ``base_link -> base_footprint``;
* ``/amcl``: ``map -> odom`` at 10 Hz, stamped :data:`AMCL_DELAY_NS` before it is received;
* ``/odometry``: ``odom -> base_link`` at 50 Hz, stamped :data:`ODOM_DELAY_NS` before.

Each fault (:data:`FAULTS`) changes that robot in one way; :func:`write_ros1` writes the
records as a ROS 1 bag with one connection per (topic, caller id), so the doctor reads
each message's sender from the bag as it would from ``rosbag record``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.doctor import Level

T0 = 1_700_000_000 * 10**9
"""Receive time (ns) of the first message."""
MS = 1_000_000
DURATION_NS = 10 * 10**9
AMCL_PERIOD_NS = 100 * MS
ODOM_PERIOD_NS = 20 * MS
AMCL_DELAY_NS = 20 * MS
ODOM_DELAY_NS = 5 * MS

Record = tuple[int, str, str, list[TransformStamped]]
"""(receive time ns, topic, caller id, transforms)."""


def tf(parent: str, child: str, stamp_ns: int, x: float = 1.0) -> TransformStamped:
    """``parent -> child`` stamped ``stamp_ns``, ``x`` metres along x."""
    return TransformStamped(Header(Time.from_ns(stamp_ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def statics(laser_parent: str = "base_link", footprint_parent: str = "base_link") -> Record:
    """The robot_state_publisher's one /tf_static message."""
    return (T0, "/tf_static", "/robot_state_publisher",
            [tf(laser_parent, "laser", T0, 0.2), tf(footprint_parent, "base_footprint", T0, 0.0)])


def periodic(parent: str, child: str, caller: str, period: int, delay: int, *,
             start: int = 0, stop: int = DURATION_NS, offset: int = 0) -> list[Record]:
    """``parent -> child`` every ``period`` ns from ``start`` to ``stop`` (ns after
    :data:`T0`), received ``delay`` ns after its stamp (negative: stamped ahead)."""
    out = []
    for t in range(start + offset, stop, period):
        stamp = T0 + t
        out.append((stamp + max(delay, 0) + 1000, "/tf", caller,
                    [tf(parent, child, stamp - min(delay, 0))]))
    return out


def amcl(**kw: int) -> list[Record]:
    """``map -> odom`` from ``/amcl`` (10 Hz, 20 ms late)."""
    kw.setdefault("delay", AMCL_DELAY_NS)
    return periodic("map", "odom", "/amcl", AMCL_PERIOD_NS, **kw)


def odometry(child: str = "base_link", parent: str = "odom", **kw: int) -> list[Record]:
    """``odom -> base_link`` from ``/odometry`` (50 Hz, 5 ms late)."""
    kw.setdefault("delay", ODOM_DELAY_NS)
    return periodic(parent, child, "/odometry", ODOM_PERIOD_NS, **kw)


def clean() -> list[Record]:
    """The robot with nothing wrong."""
    return [statics(), *amcl(), *odometry()]


def several_authorities() -> list[Record]:
    """``/rogue`` also sends ``odom -> base_link`` (10 Hz, stamps 3 ms after
    ``/odometry``'s) from 3 s to 6 s, while ``/odometry`` sends it."""
    rogue = periodic("odom", "base_link", "/rogue", 100 * MS, ODOM_DELAY_NS,
                     start=3 * 10**9, stop=6 * 10**9, offset=3 * MS)
    return [*clean(), *rogue]


def static_and_dynamic() -> list[Record]:
    """``/laser_driver`` sends ``base_link -> laser`` on /tf at 10 Hz, which
    ``/robot_state_publisher`` sends on /tf_static."""
    return [*clean(), *periodic("base_link", "laser", "/laser_driver", 100 * MS, 5 * MS)]


def parent_change() -> list[Record]:
    """``/camera_node`` sends ``camera`` below ``base_link`` for 5 s, then below ``laser``."""
    first = periodic("base_link", "camera", "/camera_node", 100 * MS, 5 * MS,
                     stop=5 * 10**9)
    then = periodic("laser", "camera", "/camera_node", 100 * MS, 5 * MS, start=5 * 10**9)
    return [*clean(), *first, *then]


def loop() -> list[Record]:
    """``/bad_node`` sends ``arm_base -> tool`` and ``tool -> arm_base`` (10 Hz): a loop of
    two frames."""
    return [*clean(),
            *periodic("arm_base", "tool", "/bad_node", 100 * MS, 5 * MS),
            *periodic("tool", "arm_base", "/bad_node", 100 * MS, 5 * MS, offset=MS)]


def rep105() -> list[Record]:
    """``/odometry`` sends ``map -> base_link`` (not ``odom -> base_link``): odom and
    base_link are siblings below map."""
    return [statics(), *amcl(), *odometry(parent="map")]


def base_footprint() -> list[Record]:
    """``base_footprint`` below ``laser`` (not next to ``base_link``)."""
    return [statics(footprint_parent="laser"), *amcl(), *odometry()]


def leading_slash() -> list[Record]:
    """``/odometry`` names its child ``/base_link``."""
    return [statics(), *amcl(), *odometry(child="/base_link")]


def stopped() -> list[Record]:
    """``odom -> base_link`` stops at 7 s (of 10 s)."""
    return [statics(), *amcl(), *odometry(stop=7 * 10**9)]


def gap() -> list[Record]:
    """``odom -> base_link`` is silent from 4 s to 5 s."""
    return [statics(), *amcl(), *odometry(stop=4 * 10**9), *odometry(start=5 * 10**9)]


def rate_drop() -> list[Record]:
    """``odom -> base_link`` at 50 Hz until 5 s, then 20 Hz."""
    slow = periodic("odom", "base_link", "/odometry", 50 * MS, ODOM_DELAY_NS,
                    start=5 * 10**9)
    return [statics(), *amcl(), *odometry(stop=5 * 10**9), *slow]


REPEATED = 50
"""Messages :func:`repeated_stamps` sends twice."""


def repeated_stamps() -> list[Record]:
    """From 4 s to 5 s every ``odom -> base_link`` message is sent twice (1 ms apart)."""
    twice = [(t + MS, topic, caller, tfs) for t, topic, caller, tfs in
             odometry(start=4 * 10**9, stop=5 * 10**9)]
    return [*clean(), *twice]


SWAPPED = 25
"""Pairs of messages :func:`out_of_order` sends in the wrong order."""


def out_of_order() -> list[Record]:
    """From 4 s to 5 s each pair of ``odom -> base_link`` stamps is sent newest first."""
    recs = odometry()
    lo, hi = 4 * 10**9 // ODOM_PERIOD_NS, 5 * 10**9 // ODOM_PERIOD_NS
    for k in range(lo, hi, 2):
        (ta, to, ca, a), (tb, _, cb, b) = recs[k], recs[k + 1]
        recs[k], recs[k + 1] = (ta, to, ca, b), (tb, to, cb, a)
    return [statics(), *amcl(), *recs]


CLOCK_AHEAD_NS = 300 * MS
LAG_NS = 400 * MS


def clock_offset() -> list[Record]:
    """``/odometry``'s clock runs 0.3 s ahead: its stamps are 0.3 s after their receive
    time."""
    return [statics(), *amcl(), *odometry(delay=-CLOCK_AHEAD_NS)]


def latency() -> list[Record]:
    """``/amcl`` stamps 0.4 s before it is received (its clock is behind)."""
    return [statics(), *amcl(delay=LAG_NS), *odometry()]


def disconnected() -> list[Record]:
    """The laser hangs below ``laser_mount``, which nothing links to the robot."""
    return [statics(laser_parent="laser_mount"), *amcl(), *odometry()]


FAULTS: dict[str, Callable[[], list[Record]]] = {
    "several_authorities": several_authorities,
    "static_and_dynamic": static_and_dynamic,
    "parent_change": parent_change,
    "loop": loop,
    "rep105": rep105,
    "base_footprint": base_footprint,
    "leading_slash": leading_slash,
    "stopped": stopped,
    "gap": gap,
    "rate_drop": rate_drop,
    "repeated_stamps": repeated_stamps,
    "out_of_order": out_of_order,
    "clock_offset": clock_offset,
    "latency": latency,
    "disconnected": disconnected,
}
"""Each check's recording, by the check's name."""


EXPECTED: dict[str, tuple[Level, tuple[str, ...], tuple[str, ...]]] = {
    # check: (level, frames, senders)
    "several_authorities": (Level.ERROR, ("base_link", "odom"), ("/odometry", "/rogue")),
    "static_and_dynamic": (Level.ERROR, ("laser", "base_link"),
                           ("/laser_driver", "/robot_state_publisher")),
    "parent_change": (Level.WARNING, ("camera", "base_link", "laser"), ("/camera_node",)),
    "loop": (Level.ERROR, ("arm_base", "tool"), ("/bad_node",)),
    "rep105": (Level.ERROR, ("odom", "base_link"), ("/amcl", "/odometry")),
    "base_footprint": (Level.WARNING, ("base_footprint", "base_link"),
                       ("/odometry", "/robot_state_publisher")),
    "leading_slash": (Level.ERROR, ("/base_link",), ("/odometry",)),
    "stopped": (Level.WARNING, ("base_link", "odom"), ("/odometry",)),
    "gap": (Level.WARNING, ("base_link", "odom"), ("/odometry",)),
    "rate_drop": (Level.WARNING, ("base_link", "odom"), ("/odometry",)),
    "repeated_stamps": (Level.WARNING, ("base_link", "odom"), ("/odometry",)),
    "out_of_order": (Level.WARNING, ("base_link", "odom"), ("/odometry",)),
    "clock_offset": (Level.ERROR, ("base_link",), ("/odometry",)),
    "latency": (Level.WARNING, ("odom",), ("/amcl",)),
    "disconnected": (Level.WARNING, ("map", "laser_mount"), ("/robot_state_publisher",)),
}
"""What the doctor finds on each fault's recording, alone: (level, frames, senders)."""


def write_ros1(path: Path, records: list[Record]) -> Path:
    """Write ``records`` (in receive-time order) as a ROS 1 bag, one connection per
    (topic, caller id), /tf_static latched."""
    from rosbags.rosbag1 import Writer

    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore, to_rosbags

    store = tf_typestore(ros1=True)
    with Writer(path) as writer:
        conns: dict[tuple[str, str], object] = {}
        for t, topic, caller, tfs in sorted(records, key=lambda r: r[0]):
            conn = conns.get((topic, caller))
            if conn is None:
                conn = conns[(topic, caller)] = writer.add_connection(
                    topic, ROSBAGS_TF_TYPE, typestore=store, callerid=caller,
                    latching=1 if topic == "/tf_static" else 0)
            raw = store.serialize_ros1(to_rosbags(store, tfs, ros1=True), ROSBAGS_TF_TYPE)
            writer.write(conn, t, raw)
    return path
