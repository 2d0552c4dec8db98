"""Tests for tfbus/robot/state_publisher.py and tfbus/robot/urdf.py.

The reference is ROS 1's robot_state_publisher 1.15.2 (Debian): ``tests/data/rsp/*.json.gz``
were recorded from the real node by ``scripts/data/record_robot_state.py`` (layout: ``urdf``,
``static`` {stamp_ns, transforms}, ``cases`` [{label, stamp_ns, name, position, tf}],
each transform ``[stamp_ns, parent, child, [x, y, z], [qx, qy, qz, qw]]``, ``tf`` null when
the node published nothing). ``test_live_against_the_real_node`` records afresh when ROS 1
is installed (installing it with scripts/install/install_ros1_rsp.sh if needed).
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from peer_install import require

from tfbus.bus import TF_STATIC_TOPIC, TF_TOPIC, Bus
from tfbus.clock import ManualClock
from tfbus.convert import do_transform_point
from tfbus.messages import Header, JointState, Point, PointStamped, TransformStamped
from tfbus.robot import (
    JointStateError,
    RobotModel,
    RobotStatePublisher,
    URDFError,
    load_urdf,
    publish_joint_states,
    sinusoidal_joint_state,
)
from tfbus.robot.state_publisher import _quaternions
from tfbus.time import Time

pytest.importorskip("urdf_parser_py")
pytestmark = pytest.mark.anyio

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "rsp"
URDF = ROOT / "tests" / "data" / "urdf"
RECORDINGS = sorted(DATA.glob("*.json.gz"))
TOL = 1e-9

Row = list[Any]


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def urdf_path(name: str) -> Path:
    local = DATA / name
    return local if local.exists() else URDF / name


def load(path: Path) -> dict[str, Any]:
    with gzip.open(path, "rt") as f:
        data: dict[str, Any] = json.load(f)
    return data


def rows(transforms: list[TransformStamped]) -> list[Row]:
    return [[t.header.stamp.ns, t.header.frame_id, t.child_frame_id,
             list(t.transform.translation), list(t.transform.rotation)] for t in transforms]


def joint_state(case: dict[str, Any]) -> JointState:
    return JointState(Header(Time.from_ns(case["stamp_ns"]), ""), case["name"], case["position"])


def assert_same(ours: list[Row], node: list[Row], *, stamps: bool = True) -> None:
    """Same parent/child pairs in the same order, same stamps, values within TOL."""
    assert [r[1:3] for r in ours] == [r[1:3] for r in node]
    if stamps:
        assert [r[0] for r in ours] == [r[0] for r in node]
    for a, b in zip(ours, node, strict=True):
        np.testing.assert_allclose(a[3] + a[4], b[3] + b[4], rtol=0, atol=TOL,
                                   err_msg=f"{a[1]} -> {a[2]}")


def finite(node: list[Row]) -> list[Row]:
    return [r for r in node if all(math.isfinite(v) for v in r[3] + r[4])]


# --------------------------------------------------------------------------- the real node


def test_recordings_cover_every_urdf_in_the_data() -> None:
    names = {load(p)["urdf"] for p in RECORDINGS}
    in_data = {p.name for p in URDF.glob("*.urdf")}
    assert in_data == {"erd_panda.urdf", "rsp_pr2.urdf", "tb3_burger.urdf",
                       "urdf_tutorial_07-physics.urdf"}  # tests/data/SOURCES.md
    assert in_data <= names
    assert "extra_joints.urdf" in names
    for p in RECORDINGS:  # each recording was made from the file now in tests/data
        rec = load(p)
        assert hashlib.sha256(urdf_path(rec["urdf"]).read_bytes()).hexdigest() == rec["sha256"]


@pytest.mark.parametrize("recording", RECORDINGS, ids=lambda p: p.name.split(".")[0])
def test_static_transforms_match_the_real_node(recording: Path) -> None:
    data = load(recording)
    node = data["static"]["transforms"]
    stamp = Time.from_ns(data["static"]["stamp_ns"])
    ours = rows(RobotStatePublisher(urdf_path(data["urdf"])).static_transforms(stamp))
    # The node stamps each fixed joint with its own ros::Time::now() call (µs apart).
    assert_same(ours, node, stamps=False)
    assert {r[0] for r in ours} == {stamp.ns}
    assert max(r[0] for r in node) - min(r[0] for r in node) < 10**9


@pytest.mark.parametrize("recording", RECORDINGS, ids=lambda p: p.name.split(".")[0])
def test_joint_transforms_match_the_real_node(recording: Path) -> None:
    data = load(recording)
    rsp = RobotStatePublisher(urdf_path(data["urdf"]))
    compared = 0
    for case in data["cases"]:
        if case["tf"] is None:
            continue  # not published: rate limit or invalid message (test_run_* below)
        try:
            ours = rsp.transforms(joint_state(case))
        except JointStateError as err:
            assert case["label"] == "NaN and Inf positions"
            assert set(err.refused) and all(not math.isfinite(v) for v in err.refused.values())
            ours, node = err.transforms, finite(case["tf"])
            assert len(node) == len(case["tf"]) - len(err.refused)
        else:
            node = case["tf"]
        assert_same(rows(ours), node)
        compared += len(node)
    assert compared > 0


@pytest.mark.parametrize("recording", RECORDINGS, ids=lambda p: p.name.split(".")[0])
async def test_run_publishes_what_the_real_node_published(recording: Path) -> None:
    """The whole sequence through run(): rate limit, invalid messages, statics."""
    data = load(recording)
    rsp = RobotStatePublisher(urdf_path(data["urdf"]))
    clock = ManualClock(Time.from_ns(data["recorded_at_ns"]))  # the node's now: after stamps
    async with Bus() as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe(TF_TOPIC)
        await tg.start(lambda task_status: rsp.run(bus, publish_frequency=data[
            "publish_frequency"], clock=clock, task_status=task_status))
        static = bus.subscribe(TF_STATIC_TOPIC).receive_nowait()
        assert_same(rows(list(static.transforms)), data["static"]["transforms"], stamps=False)
        for case in data["cases"]:
            await bus.publish("/joint_states", joint_state(case))
            await clock.advance(0)
            got = [] if tf.statistics().queued == 0 else list(
                tf.receive_nowait().transforms)
            node = finite(case["tf"] or [])  # an empty TFMessage is not sent by tfbus
            assert_same(rows(got), node), case["label"]
        tg.cancel_scope.cancel()
    published = sum(1 for c in data["cases"] if finite(c["tf"] or []))
    assert rsp.statistics().published == published
    assert rsp.statistics().rate_limited == 2
    assert rsp.statistics().received == len(data["cases"])


# --------------------------------------------------------------------------- hand-computed

ARM = """<robot name="arm">
  <link name="base"/><link name="upper"/><link name="slide"/><link name="cam"/>
  <link name="twin"/><link name="free"/><link name="flat"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="1 0 0" rpy="0 0 0"/><axis xyz="0 0 2"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="upper"/><child link="slide"/>
    <origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="camera" type="fixed">
    <parent link="slide"/><child link="cam"/>
    <origin xyz="0.1 0 0.2" rpy="0 0 0"/>
  </joint>
  <joint name="twin" type="revolute">
    <parent link="base"/><child link="twin"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="shoulder" multiplier="-2" offset="0.5"/>
  </joint>
  <joint name="free" type="floating"><parent link="base"/><child link="free"/></joint>
  <joint name="flat" type="planar">
    <parent link="base"/><child link="flat"/><origin xyz="0 1 0"/>
  </joint>
</robot>"""

T = Time(100, 5)


def by_child(transforms: list[TransformStamped]) -> dict[str, TransformStamped]:
    return {t.child_frame_id: t for t in transforms}


def test_revolute_prismatic_fixed_and_mimic_by_hand() -> None:
    rsp = RobotStatePublisher(ARM)
    out = by_child(rsp.transforms(JointState(Header(T), ["shoulder", "rail"],
                                             [math.pi / 2, 0.25])))
    s = math.sqrt(0.5)
    up = out["upper"]
    assert (up.header.frame_id, up.header.stamp) == ("base", T)
    np.testing.assert_allclose(up.transform.translation, (1, 0, 0), atol=1e-15)
    np.testing.assert_allclose(up.transform.rotation, (0, 0, s, s), atol=1e-15)  # axis normalised
    # the rail slides along its own x, which the origin's yaw turned onto the parent's y
    np.testing.assert_allclose(out["slide"].transform.translation, (0, 0.25, 1), atol=1e-15)
    np.testing.assert_allclose(out["slide"].transform.rotation, (0, 0, s, s), atol=1e-15)
    # twin mimics shoulder: -2 * pi/2 + 0.5
    angle = -math.pi + 0.5
    # past 120 degrees KDL's GetQuaternion makes the largest component (z) positive: -q
    np.testing.assert_allclose(out["twin"].transform.rotation,
                               (0, 0, -math.sin(angle / 2), -math.cos(angle / 2)), atol=1e-15)
    assert sorted(out) == ["slide", "twin", "upper"]
    assert [t.child_frame_id for t in rsp.transforms(
        JointState(Header(T), ["twin", "shoulder"], [0.1, 0.2]))] == ["upper", "twin"]
    # the listener's way: the camera point in base goes through all three links
    statics = by_child(rsp.static_transforms(T))
    assert sorted(statics) == ["cam", "flat"]  # planar is published as fixed; floating never
    p = PointStamped(Header(T, "cam"), Point(0, 0, 0))
    for link in ("cam", "slide", "upper"):
        p = do_transform_point(p, {**out, **statics}[link])
    # slide: yaw 90 turns (0.1, 0, 0.2) into (0, 0.1, 0.2), + (0, 0.25, 1) = (0, 0.35, 1.2);
    # upper: +90 about z gives (-0.35, 0, 1.2), + (1, 0, 0)
    np.testing.assert_allclose(p.point, (0.65, 0, 1.2), atol=1e-12)


def test_frame_prefix_is_plain_concatenation() -> None:
    rsp = RobotStatePublisher(ARM, frame_prefix="r1/")
    (t,) = rsp.transforms(JointState(Header(T), ["rail"], [0.0]))
    assert (t.header.frame_id, t.child_frame_id) == ("r1/upper", "r1/slide")
    assert {(s.header.frame_id, s.child_frame_id) for s in rsp.static_transforms(T)} == {
        ("r1/slide", "r1/cam"), ("r1/base", "r1/flat")}
    with pytest.raises(TypeError, match="frame_prefix"):
        RobotStatePublisher(ARM, frame_prefix=3)  # type: ignore[arg-type]


def test_nan_and_inf_positions_are_refused_and_the_others_computed() -> None:
    rsp = RobotStatePublisher(ARM)
    msg = JointState(Header(T), ["shoulder", "rail", "ghost"], [math.nan, 0.1, math.inf])
    with pytest.raises(JointStateError, match=r"shoulder=nan") as info:
        rsp.transforms(msg)
    # the mimic of a NaN leader is NaN too; unknown names are ignored even when NaN
    assert set(info.value.refused) == {"shoulder", "twin"}
    assert [t.child_frame_id for t in info.value.transforms] == ["slide"]
    with pytest.raises(JointStateError, match="rail='x'"):
        rsp.transforms(JointState(Header(T), ["rail"], ["x"]))


def test_invalid_joint_states() -> None:
    rsp = RobotStatePublisher(ARM)
    with pytest.raises(JointStateError, match="2 names and 1 positions") as info:
        rsp.transforms(JointState(Header(T), ["shoulder", "rail"], [0.1]))
    assert info.value.transforms == [] and info.value.refused == {}
    assert rsp.transforms(JointState(Header(T), ["shoulder"], [])) == []
    assert rsp.transforms(JointState(Header(T), ["nobody", "camera", "free"], [1, 2, 3])) == []
    with pytest.raises(JointStateError, match="stamp"):
        rsp.transforms(JointState(Header(1.5, ""), ["shoulder"], [0.1]))  # type: ignore[arg-type]


# --------------------------------------------------------------------------- malformed URDF

GOOD_JOINT = ('<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>')


MALFORMED = [
    ("<robot name='r'><link name='a'>", "line 1", "not well-formed XML"),
    ("<model name='r'/>", "robot", "root element is <model>"),
    ("<robot name='r'/>", "robot", "no <link>"),
    ("<robot name='r'><link name='a'/><link name='a'/></robot>", "link 'a'", "defined twice"),
    ("<robot name='r'><link name='a'/>" + GOOD_JOINT + "</robot>", "joint 'j'",
     "child link 'b' is not defined"),
    ("<robot name='r'><link name='a'/><link name='b'/><link name='c'/>" + GOOD_JOINT
     + "</robot>", "link 'c'", "two root links, 'a' and 'c'"),
    ("<robot name='r'><link name='a'/><link name='b'/>" + GOOD_JOINT
     + GOOD_JOINT.replace('"j"', '"k"').replace('"a"', '"X"').replace('"b"', '"a"')
       .replace('"X"', '"b"') + "</robot>", "joint 'j'", "loop"),
    ("<robot name='r'><link name='a'/><link name='b'/><link name='c'/>" + GOOD_JOINT
     + GOOD_JOINT.replace('"j"', '"k"').replace('"a"', '"c"')
     + GOOD_JOINT.replace('"j"', '"m"').replace('"a"', '"X"').replace('"b"', '"c"')
       .replace('"X"', '"b"') + "</robot>", "link 'b'", "two parent joints"),
    ("<robot name='r'><link name='a'/><link name='b'/><link name='c'/>" + GOOD_JOINT
     + GOOD_JOINT.replace('"j"', '"k"').replace('"a"', '"X"').replace('"b"', '"c"')
       .replace('"X"', '"b"')
     + GOOD_JOINT.replace('"j"', '"m"').replace('"a"', '"c"').replace('"b"', '"b2"')
     .replace("<link name='c'/>", "") + "</robot>", "joint 'm'", "not defined"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("fixed", "spherical") + "</robot>", "joint 'j'",
     "unknown type 'spherical'"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("fixed", "revolute") + "</robot>", "joint 'j'", "no <limit>"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("fixed", "continuous").replace("</joint>", "<axis xyz='0 0 0'/>"
                                                         "</joint>") + "</robot>",
     "joint 'j'", "zero length"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("</joint>", "<origin xyz='0 nan 0'/></joint>") + "</robot>",
     "joint 'j'", "non-finite"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace("</joint>", "<origin xyz='0 0'/></joint>") + "</robot>",
     "joint 'j'", "invalid URDF at /robot"),
    ("<robot name='r'><link name='a'/><link name='b'/>"
     + GOOD_JOINT.replace('<parent link="a"/>', "") + "</robot>", "joint 'j'", "parent"),
]


@pytest.mark.parametrize(("text", "element", "message"), MALFORMED)
def test_malformed_urdf_gives_one_clear_error(text: str, element: str, message: str) -> None:
    with pytest.raises(URDFError, match=message) as info:
        RobotStatePublisher(text)
    assert info.value.element == element
    assert isinstance(info.value, ValueError)


def test_loop_with_two_links_and_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(URDFError, match="cannot read the URDF file") as info:
        load_urdf(tmp_path / "missing.urdf")
    assert "missing.urdf" in str(info.value)
    with pytest.raises(TypeError, match="expected URDF text"):
        load_urdf(3.5)
    bomb = ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">'
            '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><robot name="&b;"><link name="x"/>'
            '</robot>')
    model = load_urdf(bomb)  # entities are not expanded
    assert model.links == ("x",)


def test_every_urdf_in_the_data_parses(tmp_path: Path) -> None:
    counts = {}
    for path in sorted(URDF.glob("*.urdf")):
        model = load_urdf(path)
        assert load_urdf(path.read_text()) == model == load_urdf(str(path))
        assert load_urdf(model) is model
        counts[path.name] = (model.root, len(model.joints),
                             sum(j.mimic is not None for j in model.joints))
    assert counts["rsp_pr2.urdf"] == ("base_footprint", 82, 6)  # transmissions ignored
    assert counts["erd_panda.urdf"] == ("panda_link0", 12, 1)
    from urdf_parser_py import urdf

    robot = urdf.URDF.from_xml_string(ARM)
    assert isinstance(load_urdf(robot), RobotModel)
    assert RobotStatePublisher(robot).model == load_urdf(ARM)


# --------------------------------------------------------------------------- the node


def start_rsp(rsp: RobotStatePublisher, bus: Bus, clock: ManualClock, **kw: Any) -> Any:
    return lambda task_status: rsp.run(bus, clock=clock, task_status=task_status, **kw)


async def test_run_rate_limits_per_joint_and_resets_on_a_clock_jump() -> None:
    clock = ManualClock(Time(1000))
    rsp = RobotStatePublisher(ARM)
    async with Bus() as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe(TF_TOPIC)
        await tg.start(start_rsp(rsp, bus, clock, publish_frequency=10.0))
        static = bus.subscribe(TF_STATIC_TOPIC).receive_nowait()
        assert {t.header.stamp for t in static.transforms} == {Time(1000)}

        async def send(stamp_ns: int, names: list[str]) -> list[str]:
            await bus.publish("/joint_states", JointState(
                Header(Time.from_ns(stamp_ns)), names, [0.1] * len(names)))
            await clock.advance(0)
            if tf.statistics().queued == 0:
                return []
            return [t.child_frame_id for t in tf.receive_nowait().transforms]

        s = 500 * 10**9
        assert await send(s, ["shoulder"]) == ["upper", "twin"]
        assert await send(s + 99_999_999, ["shoulder"]) == []  # within 100 ms: limited
        assert await send(s + 10**8, ["shoulder"]) == ["upper", "twin"]
        assert await send(s + 10**8, ["rail"]) == ["slide"]  # another joint: its own clock
        # least recently published joint decides: rail at s+1e8, shoulder at s+1e8
        assert await send(s + 2 * 10**8 - 1, ["rail", "shoulder"]) == []
        await clock.set(Time(999))  # backwards: forget publish times
        assert await send(s + 10**8 + 1, ["shoulder"]) == ["upper", "twin"]
        await bus.publish("/joint_states", "junk")
        await bus.publish("/joint_states", JointState(Header(Time(600)), ["rail"], [0.1, 0.2]))
        assert await send(601 * 10**9, ["shoulder", "rail"]) == ["slide", "upper", "twin"]
        tg.cancel_scope.cancel()
    st = rsp.statistics()
    assert (st.received, st.published, st.rate_limited, st.invalid) == (9, 5, 2, 2)
    assert st.transforms == 2 + 2 + 1 + 2 + 3
    st.received = 0  # a snapshot: the caller's copy, not the publisher's counters
    assert rsp.statistics().received == 9


async def test_run_ignore_timestamp_and_nan(caplog: pytest.LogCaptureFixture) -> None:
    clock = ManualClock(Time(1000))
    rsp = RobotStatePublisher(ARM, ignore_timestamp=True)
    async with Bus() as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe(TF_TOPIC)
        await tg.start(start_rsp(rsp, bus, clock, joint_states_topic="/js"))
        for _ in range(3):
            await bus.publish("/js", JointState(Header(Time(5)), ["shoulder", "rail"],
                                                [math.inf, 0.2]))
        await clock.advance(0)
        msgs = [tf.receive_nowait() for _ in range(3)]
        assert all([t.child_frame_id for t in m.transforms] == ["slide"] for m in msgs)
        tg.cancel_scope.cancel()
    assert rsp.statistics().refused_positions == 6
    assert "shoulder=inf" in caplog.text


async def test_run_refuses_a_bad_frequency() -> None:
    async with Bus() as bus:
        for bad in (0.0, -1.0, math.nan, math.inf):
            with pytest.raises(ValueError, match="publish_frequency"):
                await RobotStatePublisher(ARM).run(bus, publish_frequency=bad)


async def test_joint_states_move_within_limits_and_feed_the_publisher() -> None:
    clock = ManualClock(Time(1000))
    model = load_urdf(URDF / "rsp_pr2.urdf")
    rsp = RobotStatePublisher(model)
    async with Bus() as bus, anyio.create_task_group() as tg:
        js = bus.subscribe("/joint_states")
        tf = bus.subscribe(TF_TOPIC)
        await tg.start(start_rsp(rsp, bus, clock, publish_frequency=100.0))
        await tg.start(lambda task_status: publish_joint_states(
            bus, model, rate=50.0, clock=clock, task_status=task_status))
        await clock.advance(1.0)
        tg.cancel_scope.cancel()
    states = [js.receive_nowait() for _ in range(js.statistics().queued)]
    assert len(states) == 51  # t = 0, 0.02, ..., 1.0
    assert states[1].header.stamp == Time(1000, 20_000_000)
    movable = [j for j in model.joints if j.movable and j.mimic is None]
    assert list(states[0].name) == [j.name for j in movable]
    for state in states:
        for j, q in zip(movable, state.position, strict=True):
            if j.type != "continuous":
                assert j.lower is not None and j.upper is not None
                assert j.lower - 1e-12 <= q <= j.upper + 1e-12
            else:
                assert -math.pi <= q <= math.pi
    assert tf.statistics().queued == 51
    last = tf.receive_nowait()
    assert len(last.transforms) == len(movable) + 6  # plus the mimic joints
    async with Bus() as bus:
        with pytest.raises(ValueError, match="rate"):
            await publish_joint_states(bus, model, rate=0.0)


def test_sinusoidal_joint_state_values() -> None:
    model = load_urdf(ARM)
    state = sinusoidal_joint_state(model, T, 0.0)
    assert list(state.name) == ["shoulder", "rail"]
    np.testing.assert_allclose(state.position, [math.sin(0.0), 0.25 + 0.25 * math.sin(1.0)])
    quarter = sinusoidal_joint_state(model, T, 1.0, period=4.0)
    np.testing.assert_allclose(quarter.position[0], math.sin(math.pi / 2))


# --------------------------------------------------------------------------- live, ROS 1


@pytest.fixture(scope="session")
def ros1_rsp() -> None:
    """ROS 1's robot_state_publisher, installed by scripts/install/install_ros1_rsp.sh if
    missing."""
    require("ros1-robot-state-publisher", "install_ros1_rsp.sh", timeout=2400)


def test_live_against_the_real_node(ros1_rsp: None, tmp_path: Path) -> None:
    urdfs = [URDF / "tb3_burger.urdf", DATA / "extra_joints.urdf"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "VIRTUAL_ENV"))}
    done = subprocess.run(
        ["/usr/bin/python3", str(ROOT / "scripts" / "data" / "record_robot_state.py"), "--out",
         str(tmp_path), "--seed", str(os.getpid()), *map(str, urdfs)],
        capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    for path in sorted(tmp_path.glob("*.json.gz")):
        data = load(path)
        rsp = RobotStatePublisher(urdf_path(data["urdf"]))
        stamp = Time.from_ns(data["static"]["stamp_ns"])
        assert_same(rows(rsp.static_transforms(stamp)), data["static"]["transforms"],
                    stamps=False)
        for case in data["cases"]:
            if case["tf"] is None:
                continue
            try:
                assert_same(rows(rsp.transforms(joint_state(case))), case["tf"])
            except JointStateError as err:
                assert_same(rows(err.transforms), finite(case["tf"]))
    assert len(list(tmp_path.glob("*.json.gz"))) == 2


# --------------------------------------------------------------------------- the demo

INFO = ("base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20) at time 0.00")


def demo_module() -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location("robot_state_demo",
                                                  ROOT / "demos" / "robot_state.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_demo_urdf_is_the_tutorial_robot() -> None:
    rsp = RobotStatePublisher(ROOT / "demos" / "robot.urdf")
    (laser,) = rsp.static_transforms(T)
    assert (laser.header.frame_id, laser.child_frame_id) == ("base_link", "base_laser")
    assert laser.transform.translation == (0.1, 0.0, 0.2)
    assert laser.transform.rotation == (0.0, 0.0, 0.0, 1.0)
    assert sorted((j.name, j.type) for j in rsp.model.joints if j.movable) == [
        ("left_wheel_joint", "continuous"), ("right_wheel_joint", "continuous")]


async def test_demo_listener_keeps_printing_the_tutorial_line() -> None:
    clock = ManualClock(Time(1_248_138_528))
    lines: list[str] = []

    async def run() -> Any:
        return await demo_module().run_robot_state_demo(clock=clock, duration=3.45,
                                                        out=lines.append)

    async with anyio.create_task_group() as tg:
        result: list[Any] = []
        tg.start_soon(lambda: _collect(run, result))
        await clock.advance(0)
        for _ in range(35):
            await clock.advance(0.1)
    infos = [line for line in lines if line.startswith("[ INFO] 1248138")]
    assert len(infos) == 3 and all(line.endswith(INFO) for line in infos), lines
    assert lines[-1] == ("[ INFO] summary: robot_state_publisher published 70 wheel "
                         "transforms from 35 joint states")  # 10 Hz, t = 0 .. 3.4 s
    assert result[0].rate_limited == 0


async def _collect(run: Any, result: list[Any]) -> None:
    result.append(await run())


def test_demo_script_exits_cleanly_on_ctrl_c() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, str(ROOT / "demos" / "robot_state.py")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # the listener's first line, after ~1 s
        assert first.rstrip("\n").endswith(INFO), first
        proc.send_signal(2)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, err
    assert out.strip().splitlines()[-1].startswith("[ INFO] summary: robot_state_publisher")
    assert "Traceback" not in err


# --------------------------------------------------------------------------- properties

angles = st.floats(-4.0, 4.0, allow_nan=False)
unit = st.floats(-1.0, 1.0, allow_nan=False)


def _urdf_one(kind: str, rpy: tuple[float, float, float],
              axis: tuple[float, float, float]) -> str:
    limit = '<limit lower="-5" upper="5" effort="1" velocity="1"/>'
    return (f'<robot name="p"><link name="a"/><link name="b"/><joint name="j" type="{kind}">'
            f'<parent link="a"/><child link="b"/><origin xyz="0.1 0.2 0.3" '
            f'rpy="{rpy[0]!r} {rpy[1]!r} {rpy[2]!r}"/><axis xyz="{axis[0]!r} {axis[1]!r} '
            f'{axis[2]!r}"/>{limit}</joint></robot>')


@settings(max_examples=150, deadline=None)
@given(rpy=st.tuples(angles, angles, angles), axis=st.tuples(unit, unit, unit), q=angles)
def test_joint_rotation_is_kdls_matrix_route(rpy: tuple[float, float, float],
                                             axis: tuple[float, float, float],
                                             q: float) -> None:
    """The per-joint quaternion path equals KDL's route, Rot2(M a, q) * M then
    GetQuaternion on the matrix, signs included; and it is a unit quaternion."""
    from transforms3d.axangles import axangle2mat
    from transforms3d.euler import euler2mat

    if math.hypot(*axis) < 1e-3:
        return
    (t,) = RobotStatePublisher(_urdf_one("revolute", rpy, axis)).transforms(
        JointState(Header(T), ["j"], [q]))
    m = euler2mat(*rpy, "sxyz")
    n = m @ np.asarray(axis) / math.hypot(*axis)
    expected = _quaternions((axangle2mat(n, q) @ m)[None])[0]
    got = np.asarray(t.transform.rotation)
    if np.abs(got + expected).max() < 1e-9:
        # -q is allowed only on KDL's branch boundaries (trace at 1e-12, diagonal ties),
        # where rounding in either route may pick the other branch
        r = axangle2mat(n, q) @ m
        diag = np.sort(np.diag(r))
        assert abs(np.trace(r) - 1e-12) < 1e-9 or diag[2] - diag[1] < 1e-9
    else:
        np.testing.assert_allclose(got, expected, atol=1e-12)
    assert abs(float(np.linalg.norm(got)) - 1.0) < 1e-12
    assert t.transform.translation == (0.1, 0.2, 0.3)


@functools.cache
def _pr2() -> RobotStatePublisher:
    return RobotStatePublisher(URDF / "rsp_pr2.urdf")


@settings(max_examples=50, deadline=None)
@given(q=st.lists(angles, min_size=40, max_size=40))
def test_pr2_chain_equals_direct_forward_kinematics(q: list[float]) -> None:
    """Through a BufferCore, the published links compose to the forward kinematics computed
    independently with 4x4 matrices (URDF: T = origin * joint motion)."""
    from transforms3d.axangles import axangle2mat
    from transforms3d.euler import euler2mat

    from tfbus.core import BufferCore

    rsp = _pr2()
    model = rsp.model
    movable = [j for j in model.joints if j.movable]
    positions = dict(zip((j.name for j in movable), q, strict=True))
    core = BufferCore()
    for t in rsp.static_transforms(T):
        core.set_transform_static(t, "test")
    for t in rsp.transforms(JointState(Header(T), list(positions), list(positions.values()))):
        core.set_transform(t, "test")
    parent = {j.child: j for j in model.joints}

    def fk(link: str) -> np.ndarray:
        out = np.eye(4)
        while link in parent:
            j = parent[link]
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = euler2mat(*j.rpy, "sxyz"), j.xyz
            motion = np.eye(4)
            if j.movable:
                a = np.asarray(j.axis) / math.hypot(*j.axis)
                if j.type == "prismatic":
                    motion[:3, 3] = a * positions[j.name]
                else:
                    motion[:3, :3] = axangle2mat(a, positions[j.name])
            out = m @ motion @ out
            link = j.parent
        return out

    for tip in ("r_gripper_l_finger_tip_link", "l_forearm_cam_optical_frame",
                "high_def_optical_frame", "torso_lift_link"):
        got = core.lookup_transform(model.root, tip, Time(0)).transform
        expected = fk(tip)
        np.testing.assert_allclose(got.translation, expected[:3, 3], atol=1e-9)
        qx, qy, qz, qw = got.rotation
        from transforms3d.quaternions import quat2mat

        np.testing.assert_allclose(quat2mat((qw, qx, qy, qz)), expected[:3, :3], atol=1e-9)


def test_joint_state_message_and_its_wire_form() -> None:
    pytest.importorskip("msgspec")
    from tfbus.codecs.native import WireCodec

    assert JointState()._fields == ("header", "name", "position", "velocity", "effort")
    assert JointState() == JointState(Header(), (), (), (), ())
    # registered with the wire format by default (tfbus.codecs.native), nothing to call
    msg = JointState(Header(Time(3, 4), "base"), ["a", "b"], [0.5, -1.0], [], [2.0, 3.0])
    codec = WireCodec()
    back = codec.decode(codec.encode(msg, sender=1, seq=1)).message
    assert back == JointState(Header(Time(3, 4), "base"), ["a", "b"], [0.5, -1.0], [],
                              [2.0, 3.0])


def test_urdf_text_with_a_byte_order_mark() -> None:
    assert load_urdf("\ufeff" + ARM) == load_urdf(ARM) == load_urdf(b"\xef\xbb\xbf" + ARM.encode())


def test_live_the_real_node_refuses_the_same_malformed_urdfs(ros1_rsp: None) -> None:
    """Every description tfbus refuses makes ROS 1's node exit with an error too (or
    crash: a link with two parents and a loop below it is a SIGSEGV in urdfdom 3.0),
    except a zero-length axis: the node runs (and would publish NaN transforms)."""
    texts = {f"{k}: {message}": text for k, (text, _, message) in enumerate(MALFORMED)}
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "VIRTUAL_ENV"))}
    done = subprocess.run(
        ["/usr/bin/python3", str(ROOT / "scripts" / "data" / "record_robot_state.py"),
         "--refusals"],
        input=json.dumps(texts), capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    verdicts = json.loads(done.stdout)
    for name, (status, error) in verdicts.items():
        if "zero length" in name:
            assert status == "running", (name, error)
        else:
            assert status not in (0, "running") and (error or status < 0), (name, status)
    assert len(verdicts) == len(MALFORMED)


# ------------------------------------ URDF limits and joint states that are not numbers


def _arm_with_limit(lower: str, upper: str, effort: str = "1", velocity: str = "1") -> str:
    return ARM.replace('<limit lower="-1" upper="1" effort="1" velocity="1"/>',
                       f'<limit lower="{lower}" upper="{upper}" effort="{effort}" '
                       f'velocity="{velocity}"/>', 1)


@pytest.mark.parametrize(("limit", "what"), [
    (("nan", "1"), "lower"), (("-1", "inf"), "upper"), (("-inf", "1"), "lower"),
    (("-1", "1e309"), "upper"), (("-1", "1", "nan", "1"), "effort"),
    (("-1", "1", "1", "-inf"), "velocity"),
])
def test_limits_that_are_not_finite_are_refused(limit: tuple[str, ...],
                                                               what: str) -> None:
    """<limit> values urdfdom's strToDouble cannot read (nan, inf,
    1e309, which overflows) were accepted; now a URDFError naming the joint and the
    attribute, as urdfdom's parseJointLimits refuses them."""
    with pytest.raises(URDFError, match=rf"joint 'shoulder': <limit {what}=") as err:
        load_urdf(_arm_with_limit(*limit))
    assert err.value.element == "joint 'shoulder'"


def test_huge_finite_limits_give_finite_joint_states() -> None:
    """±1e308 is a double urdfdom reads; joint-states computed (upper - lower) / 2 = inf
    and published inf / NaN positions. Every position is now finite and within limits,
    and robot_state_publisher computes finite transforms from them (a prismatic joint
    moved 1e308 m would overflow its translation: refused, named)."""
    model = load_urdf(_arm_with_limit("-1e308", "1e308").replace(
        '<limit lower="0" upper="0.5"', '<limit lower="-1.7e308" upper="1.7e308"'))
    rsp = RobotStatePublisher(model)
    shoulder = model.joint("shoulder")
    assert (shoulder.lower, shoulder.upper) == (-1e308, 1e308)
    seen = 0
    for k in range(200):
        js = sinusoidal_joint_state(model, Time(k), k * 0.37)
        assert all(math.isfinite(q) for q in js.position), js.position
        assert -1e308 <= js.position[0] <= 1e308 and -1.7e308 <= js.position[1] <= 1.7e308
        try:
            out = rsp.transforms(js)
        except JointStateError as err:
            # twin mimics shoulder: -2 x (up to 1e308) + 0.5 overflows to -inf: refused
            assert set(err.refused) == {"twin"} and abs(js.position[0]) > 8.9e307
            out = err.transforms
        for t in out:
            assert all(math.isfinite(v) for v in (*t.transform.translation,
                                                  *t.transform.rotation))
        seen += len(out)
    assert seen >= 200


def test_prismatic_translation_overflow_is_refused() -> None:
    """A finite position whose translation overflows (rail moved 1.7e308 m along x from
    an origin already 1.7e308 m along x) is refused by name, not published as inf."""
    rsp = RobotStatePublisher(ARM.replace('<origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/>',
                                          '<origin xyz="1.7e308 0 0" rpy="0 0 0"/>'))
    with pytest.raises(JointStateError, match=r"rail=1\.7e") as err:
        rsp.transforms(JointState(Header(T), ["rail", "shoulder"], [1.7e308, 0.5]))
    assert set(err.value.refused) == {"rail"}
    assert [t.child_frame_id for t in err.value.transforms] == ["upper", "twin"]


@pytest.mark.parametrize("bad", [
    JointState(None, ["shoulder"], [0.1]),  # type: ignore[arg-type]
    JointState(Header(T), None, [0.1]),  # type: ignore[arg-type]
    JointState(Header(T), ["shoulder"], None),  # type: ignore[arg-type]
    JointState(Header(5), ["shoulder"], [0.1]),  # type: ignore[arg-type]
    None,
])
def test_malformed_joint_states_are_joint_state_errors(bad: Any) -> None:
    """header=None / name=None raised AttributeError / TypeError out of transforms();
    now JointStateError (nothing computed)."""
    rsp = RobotStatePublisher(ARM)
    with pytest.raises(JointStateError) as err:
        rsp.transforms(bad)
    assert err.value.transforms == []


@pytest.mark.parametrize("value", ["0.1", True, b"0.1", None, [0.1]])
def test_positions_that_are_not_numbers_are_refused(value: Any) -> None:
    """A position given as "0.1" or True was turned into 0.1 / 1.0 by float(); a
    position is a float64: anything but a real number is refused by name, the other
    joints are computed, and a mimic of the refused joint is refused too."""
    rsp = RobotStatePublisher(ARM)
    with pytest.raises(JointStateError) as err:
        rsp.transforms(JointState(Header(T), ["shoulder", "rail"], [value, 0.25]))
    assert err.value.refused == {"shoulder": value, "twin": value}
    assert [t.child_frame_id for t in err.value.transforms] == ["slide"]
    ok = rsp.transforms(JointState(Header(T), ["shoulder", "rail"],
                                   [np.float32(0.5), np.int64(0)]))
    assert len(ok) == 3


async def test_run_counts_bad_joint_states_and_goes_on() -> None:
    """Through run(): a None header, None names, a str and a bool position are counted
    (invalid / refused_positions) and the next good message is published."""
    clock = ManualClock(Time(1000))
    rsp = RobotStatePublisher(ARM, ignore_timestamp=True)
    async with Bus() as bus, anyio.create_task_group() as tg:
        tf = bus.subscribe(TF_TOPIC)
        await tg.start(start_rsp(rsp, bus, clock))
        for bad in (JointState(None, ["shoulder"], [0.1]),  # type: ignore[arg-type]
                    JointState(Header(T), None, [0.1]),  # type: ignore[arg-type]
                    JointState(Header(T), ["rail"], ["0.1"]),
                    JointState(Header(T), ["rail"], [True])):
            await bus.publish("/joint_states", bad)
        await bus.publish("/joint_states", JointState(Header(T), ["rail"], [0.25]))
        await clock.advance(0)
        got = [m for m in iter(lambda: tf.receive_nowait() if tf.statistics().queued else None,
                                None)]
        tg.cancel_scope.cancel()
    assert [[t.child_frame_id for t in m.transforms] for m in got] == [["slide"]]
    st = rsp.statistics()
    assert (st.received, st.invalid, st.refused_positions, st.published) == (5, 2, 2, 1)


async def test_rate_limit_memory_is_bounded() -> None:
    """Every unknown joint name heard was kept for the rate limit (300 x 5 000 names:
    +175 MB). 400 messages of 500 new names each (200 000 names) now leave the memory
    traced while they are handled within 8 MB; the model's joints keep their limit."""
    import gc
    import tracemalloc

    clock = ManualClock(Time(1000))
    rsp = RobotStatePublisher(ARM)
    async with Bus() as bus, anyio.create_task_group() as tg:
        sub = bus.subscribe(TF_TOPIC)
        await tg.start(start_rsp(rsp, bus, clock, publish_frequency=10.0))
        gc.collect()
        tracemalloc.start()
        try:
            base, _ = tracemalloc.get_traced_memory()
            for k in range(400):
                names = [f"ghost_{k}_{i:04d}" for i in range(500)]
                await bus.publish("/joint_states", JointState(
                    Header(Time(2000 + k)), names, [0.0] * 500))
                await clock.advance(0)
            del names
            gc.collect()
            grown = tracemalloc.get_traced_memory()[0] - base
        finally:
            tracemalloc.stop()
        await clock.set(Time(4000))
        await bus.publish("/joint_states", JointState(Header(Time(3000)), ["rail"], [0.1]))
        await bus.publish("/joint_states", JointState(Header(Time(3000, 1)), ["rail"], [0.1]))
        await clock.advance(0)
        assert sub.statistics().queued == 1  # the second is within 100 ms: rate-limited
        tg.cancel_scope.cancel()
    assert grown < 8_000_000, grown
    assert rsp.statistics().received == 402 and rsp.statistics().rate_limited == 1


@pytest.mark.parametrize("model", [b"", b"   \n", "", "  ", b"robot"])
def test_empty_description_is_a_urdf_error(model: Any) -> None:
    """load_urdf(b"") raised TypeError ("expected URDF text, a path ..."); empty or
    non-XML bytes and blank text are now URDFError saying so."""
    with pytest.raises(URDFError, match=r"empty|not XML"):
        load_urdf(model)


def _chain(n: int) -> str:
    parts = ['<robot name="chain"><link name="l0"/>']
    for i in range(1, n):
        parts.append(f'<link name="l{i}"/><joint name="j{i}" type="revolute">'
                     f'<parent link="l{i - 1}"/><child link="l{i}"/><axis xyz="0 0 1"/>'
                     f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    return "".join(parts) + "</robot>"


def test_loading_does_not_pop_from_a_list_of_every_element(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A 5x10^4-link URDF took 18.7 s (10^4: 1.4 s): urdfdom-py's Reflection.set_from_xml
    removes each child it reads from the front of a list of the <robot>'s children
    (list.remove, O(length) each: quadratic), and a duplicate check searched a list. The
    operation count here is the length of the lists it pops from, recorded on
    urdfdom-py's Info: now bounded by one element's children, not the robot's 2n; and a
    20 000-link chain loads whole (figures: benchmarks/bench_robot_state.py)."""
    from urdf_parser_py.xml_reflection import core

    longest = [0]
    original = core.Info.__init__

    def counting(self: Any, node: Any) -> None:
        original(self, node)
        longest[0] = max(longest[0], len(self.children))

    monkeypatch.setattr(core.Info, "__init__", counting)
    model = load_urdf(_chain(20_000))
    assert longest[0] <= 4  # a joint's parent, child, axis, limit
    assert (model.root, len(model.links), len(model.joints)) == ("l0", 20_000, 19_999)
    assert model.joints[-1] == model.joint("j19999") and model.joints[-1].parent == "l19998"
    with pytest.raises(URDFError, match="link 'l7' is defined twice"):
        load_urdf(_chain(10).replace("</robot>", '<link name="l7"/></robot>'))
    with pytest.raises(URDFError, match=r"invalid URDF at /robot\[@name='chain'\]/joint"
                                        r"\[@name='j3'\]"):
        load_urdf(_chain(10).replace('<limit lower="-1" upper="1" effort="1" velocity="1"/>'
                                     '</joint><link name="l4"/>',
                                     '<limit lower="x" upper="1" effort="1" velocity="1"/>'
                                     '</joint><link name="l4"/>'))


async def test_run_a_joint_state_stamped_ahead_holds_back_the_next_ones() -> None:
    """ROS 1 parity: one JointState stamped an hour ahead of the clock rate-limits every
    later one stamped now (``min(now, last publish stamps)``); ``max_stamp_ahead`` drops
    it instead (counted in ``statistics().ahead``) and the later ones go out."""
    hour = 3600 * 10**9
    now = 1000 * 10**9

    async def published(**kw: Any) -> tuple[list[int], RobotStatePublisher]:
        clock = ManualClock(Time.from_ns(now))
        rsp = RobotStatePublisher(ARM)
        stamps = []
        async with Bus() as bus, anyio.create_task_group() as tg:
            tf = bus.subscribe(TF_TOPIC)
            await tg.start(start_rsp(rsp, bus, clock, publish_frequency=10.0, **kw))
            for k, stamp in enumerate([now, now + hour] + [now + j * 10**8 for j in (1, 2, 3)]):
                if k >= 2:
                    await clock.set(Time.from_ns(stamp))
                await bus.publish("/joint_states", JointState(
                    Header(Time.from_ns(stamp)), ["shoulder"], [0.1]))
                await clock.advance(0)
                while tf.statistics().queued:
                    stamps.append(tf.receive_nowait().transforms[0].header.stamp.ns)
            tg.cancel_scope.cancel()
        return stamps, rsp

    stamps, rsp = await published()
    assert stamps == [now, now + hour]  # every later one held back
    assert (rsp.statistics().rate_limited, rsp.statistics().ahead) == (3, 0)
    stamps, rsp = await published(max_stamp_ahead=60.0)
    assert stamps == [now, now + 10**8, now + 2 * 10**8, now + 3 * 10**8]
    assert (rsp.statistics().rate_limited, rsp.statistics().ahead) == (0, 1)
    async with Bus() as bus:
        for bad in (-1.0, math.nan, math.inf, 1e300, "5"):
            with pytest.raises(ValueError, match="max_stamp_ahead"):
                await RobotStatePublisher(ARM).run(bus, max_stamp_ahead=bad)  # type: ignore[arg-type]
