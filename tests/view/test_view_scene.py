"""The scene model of ``tfbus view`` (tfbus/view/scene.py): poses in the fixed frame by
hand and equal to lookup_transform at a bag's times, rviz's fade (ManualClock), tf2's
message for a frame that cannot be placed, ids kept as text."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.clock import ManualClock
from tfbus.core import BufferCore
from tfbus.view import build_scene, default_fixed_frame, fade

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
BAG = DATA / "webviz_turtle_tf_example.bag"
S2 = math.sqrt(0.5)


def tf(parent: str, child: str, sec: float, xyz: tuple[float, float, float],
       q: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> TransformStamped:
    return TransformStamped(Header(Time.from_sec(sec), parent), child,
                            Transform(Vector3(*xyz), Quaternion(*q)))


def chain_core() -> BufferCore:
    """world -> a (1,0,0) -> b (0,0,0, yaw +90°) -> c (1,0,0); a static world -> s (0,0,2);
    an unconnected tree other -> lone."""
    core = BufferCore()
    for t in (1.0, 2.0):
        core.set_transform(tf("world", "a", t, (1.0, 0.0, 0.0)), "bc_a")
        core.set_transform(tf("a", "b", t, (0.0, 0.0, 0.0), (0.0, 0.0, S2, S2)), "bc_b")
        core.set_transform(tf("b", "c", t, (1.0, 0.0, 0.0)), "bc_c")
        core.set_transform(tf("other", "lone", t, (5.0, 0.0, 0.0)), "bc_lone")
    core.set_transform_static(tf("world", "s", 0.0, (0.0, 0.0, 2.0)), "static_bc")
    return core


def test_fade_follows_rviz_thirds() -> None:
    assert fade(0.0) == 1.0
    assert fade(5.0) == 1.0          # first third of 15 s: full colour
    assert fade(10.0) == pytest.approx(0.5)   # half way from 5 s to 15 s
    assert fade(15.0) == 0.0         # grey at the timeout
    assert fade(15.001) is None      # hidden beyond it
    assert fade(None) == 1.0
    assert fade(2.0, timeout=3.0) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="frame timeout"):
        fade(1.0, timeout=0.0)


def test_default_fixed_frame_is_root_of_largest_tree() -> None:
    core = chain_core()
    assert default_fixed_frame(core) == "world"   # 5 frames vs 2
    assert default_fixed_frame(BufferCore()) is None


def test_poses_by_hand() -> None:
    core = chain_core()
    scene = build_scene(core, time=Time.from_sec(1.5))
    assert scene.fixed_frame == "world" and scene.message is None
    c = scene.frame("c")
    assert c.parent == "b" and not c.static and c.error is None
    assert c.pose is not None
    tr, rot = c.pose.transform.translation, c.pose.transform.rotation
    assert (tr.x, tr.y, tr.z) == pytest.approx((1.0, 1.0, 0.0))
    assert (rot.x, rot.y, rot.z, rot.w) == pytest.approx((0.0, 0.0, S2, S2))
    w = scene.frame("world")
    assert w.parent is None and w.pose is not None
    assert w.pose.transform.translation == Vector3(0.0, 0.0, 0.0)
    s = scene.frame("s")
    assert s.static and s.authority == "static_bc"
    assert s.pose is not None and s.pose.transform.translation.z == 2.0
    assert scene.frame("a").authority == "bc_a"


def test_unplaceable_frame_carries_the_cores_message() -> None:
    core = chain_core()
    scene = build_scene(core, time=Time.from_sec(1.5))
    lone = scene.frame("lone")
    assert lone.pose is None and not lone.visible
    with pytest.raises(Exception) as exc:
        core.lookup_transform("world", "lone", Time.from_sec(1.5))
    assert lone.error == str(exc.value)
    assert "lone" in lone.error and "world" in lone.error
    # out of the data's time: an extrapolation message, the core's own
    late = build_scene(core, time=Time.from_sec(9.0)).frame("a")
    with pytest.raises(Exception) as exc2:
        core.lookup_transform("world", "a", Time.from_sec(9.0))
    assert late.pose is None and late.error == str(exc2.value)
    assert "extrapolation" in late.error.lower()


def test_chosen_fixed_frame_moves_the_origin() -> None:
    core = chain_core()
    scene = build_scene(core, fixed_frame="c", time=Time.from_sec(1.0))
    w = scene.frame("world").pose
    assert w is not None
    tr = w.transform.translation
    # world seen from c: c sits at (1,1,0) rotated +90° about z, so world is at (-1, 1, 0)
    assert (tr.x, tr.y, tr.z) == pytest.approx((-1.0, 1.0, 0.0))
    missing = build_scene(core, fixed_frame="nowhere")
    assert missing.message == "fixed frame [nowhere] does not exist"
    assert all(f.pose is None and f.error for f in missing.frames)


def test_stale_and_hidden_with_manual_clock() -> None:
    clock = ManualClock(Time.from_sec(100.0))
    core = chain_core()
    last = {"a": clock.now(), "b": clock.now(), "c": clock.now(), "lone": clock.now()}
    scene = build_scene(core, now=clock.now(), last_update=last)
    assert [f.colour for f in scene.frames if f.frame_id in last] == [1.0] * 4
    clock.advance_nowait(4.0)
    last["a"] = clock.now()                  # a's broadcaster keeps going, the rest stop
    clock.advance_nowait(6.0)                # b, c silent 10 s; a 6 s
    scene = build_scene(core, now=clock.now(), last_update=last)
    assert scene.frame("a").colour == pytest.approx(1.0 - 1.0 / 10.0)  # 6 s: fading
    assert scene.frame("c").colour == pytest.approx(0.5) and scene.frame("c").stale
    assert scene.frame("s").colour == 1.0 and not scene.frame("s").stale  # static
    clock.advance_nowait(5.5)                # b, c silent 15.5 s: hidden
    scene = build_scene(core, now=clock.now(), last_update=last)
    assert scene.frame("c").colour is None and not scene.frame("c").visible
    assert scene.frame("a").colour == pytest.approx((15.0 - 11.5) / 10.0)
    # a shorter timeout: configurable
    short = build_scene(core, now=clock.now(), last_update=last, frame_timeout=20.0)
    assert short.frame("c").colour == pytest.approx((20.0 - 15.5) / (20.0 * 2 / 3))


def test_receive_times_in_nanoseconds_give_the_same_scene() -> None:
    """``last_update_ns`` (a live view's integer receive times) is read as ``last_update``
    is: the same ages, fades and hidden frames, frame for frame; a frame missing from it
    has no age."""
    clock = ManualClock(Time.from_sec(100.0))
    core = chain_core()
    last = {"a": clock.now(), "b": Time.from_sec(92.5), "c": Time.from_sec(84.0)}
    clock.advance_nowait(1.25)
    by_time = build_scene(core, now=clock.now(), last_update=last)
    by_ns = build_scene(core, now=clock.now(),
                        last_update_ns={name: t.ns for name, t in last.items()})
    assert by_ns == by_time
    ages = {f.frame_id: f.age for f in by_ns.frames}
    assert ages == {"world": None, "a": 1.25, "b": 8.75, "c": 17.25, "other": None,
                    "lone": None, "s": None}
    assert by_ns.frame("c").colour is None and by_ns.frame("lone").age is None
    # given both, the nanoseconds are read
    assert build_scene(core, now=clock.now(), last_update={"a": Time.from_sec(0.0)},
                       last_update_ns={"a": last["a"].ns}).frame("a").age == 1.25


def test_frame_view_is_a_frozen_dataclass() -> None:
    """The view of a frame keeps the dataclass's contract however it is built: fields
    by position or keyword (``authority`` defaults to None), equality and hash by value,
    no attribute can be set."""
    import dataclasses

    from tfbus.view import FrameView

    by_position = FrameView("b", "a", False, None, "no pose", 2.0, 1.0)
    by_keyword = FrameView(frame_id="b", parent="a", static=False, pose=None,
                           error="no pose", age=2.0, colour=1.0, authority=None)
    assert by_position == by_keyword and hash(by_position) == hash(by_keyword)
    assert dataclasses.astuple(by_position) == ("b", "a", False, None, "no pose", 2.0, 1.0,
                                                None)
    assert by_position != dataclasses.replace(by_position, authority="x")
    assert repr(by_position).startswith("FrameView(frame_id='b', parent='a'")
    with pytest.raises(dataclasses.FrozenInstanceError):
        by_position.age = 3.0  # type: ignore[misc]
    assert not by_position.visible and by_position.stale is False


def test_markup_and_control_characters_kept_as_text() -> None:
    core = BufferCore()
    odd = "<b>x</b>\x1b[31m*bold*\n[link](javascript:alert(1))"
    core.set_transform(tf("world", odd, 1.0, (1.0, 2.0, 3.0)), "<script>")
    scene = build_scene(core)
    f = scene.frame(odd)
    assert f.frame_id == odd and f.authority == "<script>" and f.parent == "world"
    assert f.pose is not None and f.pose.transform.translation == Vector3(1.0, 2.0, 3.0)


def test_empty_buffer_says_so() -> None:
    scene = build_scene(BufferCore())
    assert scene.frames == () and scene.message is not None and "no transforms" in scene.message


def test_bag_poses_equal_lookup_transform() -> None:
    from tfbus.bag import load_buffer

    core = load_buffer(BAG)
    fixed = default_fixed_frame(core)
    assert fixed is not None
    infos = [i for i in core.frame_info() if not i.is_static and i.samples > 1]
    lo = max(i.oldest_ns for i in infos)
    hi = min(i.newest_ns for i in infos)
    assert hi > lo
    checked = 0
    for k in range(11):
        t = Time.from_ns(lo + (hi - lo) * k // 10)
        scene = build_scene(core, fixed_frame=fixed, time=t)
        for f in scene.frames:
            ref = core.try_lookup_transform(fixed, f.frame_id, t)
            if isinstance(ref, TransformStamped):
                assert f.pose == ref
                checked += 1
            else:
                assert f.pose is None and f.error == str(ref)
    assert checked >= 11 * 3
