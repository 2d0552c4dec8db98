"""``tfbus static-transform`` (static_transform_publisher): its arguments (rpy and
quaternion, ROS 2's flags), one latched publish, bad arguments."""

from __future__ import annotations

import math
import re

import pytest

pytest.importorskip("click")
pytest.importorskip("rosbags")

from cli_support import (
    assert_usage_error,
    run,
)

from tfbus.cli import parse_static_args


def test_parse_static_args_rpy_and_quaternion() -> None:
    ts = parse_static_args(["0.1", "0", "0.2", "1.5707963267948966", "0", "0", "a", "b"])
    assert ts.header.frame_id == "a" and ts.child_frame_id == "b"
    assert tuple(ts.transform.translation) == (0.1, 0.0, 0.2)
    q = ts.transform.rotation  # yaw 90 deg about Z
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    ts = parse_static_args(["0", "0", "0", "0", "0.5", "0", "a", "b"])  # pitch about Y
    assert tuple(ts.transform.rotation) == pytest.approx((0, math.sin(0.25), 0, math.cos(0.25)))
    ts = parse_static_args(["0", "0", "0", "0", "0", "0.5", "a", "b"])  # roll about X
    assert tuple(ts.transform.rotation) == pytest.approx((math.sin(0.25), 0, 0, math.cos(0.25)))
    ts = parse_static_args(["1", "2", "3", "0", "0", "0", "2", "p", "c"])  # quaternion, scaled
    assert tuple(ts.transform.rotation) == (0.0, 0.0, 0.0, 1.0)
    ts = parse_static_args(["0", "0", "0", "0", "0", "0", "p", "c", "100"])  # ROS 1 period
    assert ts.child_frame_id == "c"
    for bad in (["1", "2"], ["x", "0", "0", "0", "0", "0", "a", "b"],
                ["0", "0", "0", "0", "0", "0", "a", "a"],
                ["0", "0", "0", "0", "0", "0", "0", "a", "b"]):
        with pytest.raises(ValueError):
            parse_static_args(bad)


def test_static_transform_publishes_once() -> None:
    code, out, _ = run("static-transform", "-1", "0", "0.2", "0", "0", "0",
                       "base_link", "base_laser", "--once", "--local")
    assert code == 0
    assert "base_link -> base_laser" in out and "(-1.0, 0.0, 0.2)" in out


def test_static_transform_publishes_on_bus(monkeypatch: pytest.MonkeyPatch) -> None:
    import tfbus.cli.static_transform as tcli

    seen = []

    async def fake(open_bus: object, ts: object, once: bool) -> None:
        seen.append((ts, once))

    monkeypatch.setattr(tcli, "_publish_static", fake)
    code, _, _ = run("static-transform", "0", "0", "1", "0", "0", "0", "1", "world", "cam",
                     "--local")
    assert code == 0 and len(seen) == 1 and seen[0][1] is False


async def _published_static() -> list[object]:
    from tfbus.broadcaster import StaticTransformBroadcaster
    from tfbus.bus import Bus

    ts = parse_static_args(["0", "0", "1", "0", "0", "0", "world", "cam"])
    async with Bus() as bus:
        await StaticTransformBroadcaster(bus).send_transform(ts)
        with bus.subscribe("/tf_static") as sub:
            return list(sub.receive_nowait().transforms)


def test_static_transform_message_is_latched() -> None:
    import anyio

    (ts,) = anyio.run(_published_static)
    assert ts.child_frame_id == "cam"  # type: ignore[attr-defined]


def test_static_transform_bad_arguments() -> None:
    code, _, err = run("static-transform", "1", "2", "3")
    assert_usage_error(code, err, "expected 8 arguments")
    code, _, err = run("static-transform", "1", "2", "x", "0", "0", "0", "a", "b")
    assert_usage_error(code, err, "'x' is not a number")


def test_static_transform_takes_ros2_flags(monkeypatch: pytest.MonkeyPatch) -> None:
    """ROS 2's flag form (tf2_ros static_transform_broadcaster_program.cpp):
    every flag optional (translation 0, quaternion (0, 0, 0, 1), RPY 0) but the frame
    ids; quaternion and RPY flags together, flags mixed with positional arguments or a
    flag without its value are errors."""
    ts = parse_static_args(["--x", "0.1", "--z", "0.2", "--frame-id", "base_link",
                            "--child-frame-id", "base_laser"])
    assert (ts.header.frame_id, ts.child_frame_id) == ("base_link", "base_laser")
    assert tuple(ts.transform.translation) == (0.1, 0.0, 0.2)
    assert tuple(ts.transform.rotation) == (0.0, 0.0, 0.0, 1.0)
    ts = parse_static_args(["--yaw", "1.5707963267948966", "--y", "-1", "--frame-id", "a",
                            "--child-frame-id", "b"])
    assert tuple(ts.transform.translation) == (0.0, -1.0, 0.0)
    assert tuple(ts.transform.rotation) == pytest.approx(
        (0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    rpy = parse_static_args(["--roll", "0.3", "--pitch", "-0.2", "--yaw", "1.1",
                             "--frame-id", "a", "--child-frame-id", "b"])
    old = parse_static_args(["0", "0", "0", "1.1", "-0.2", "0.3", "a", "b"])  # yaw pitch roll
    assert rpy == old
    ts = parse_static_args(["--qz", "1", "--frame-id", "a", "--child-frame-id", "b"])
    assert tuple(ts.transform.rotation) == pytest.approx((0, 0, math.sqrt(0.5), math.sqrt(0.5)))
    for bad, needle in [
        (["--x", "1", "--frame-id", "a"], "--child-frame-id"),
        (["--child-frame-id", "b"], "--frame-id"),
        (["--qx", "1", "--roll", "1", "--frame-id", "a", "--child-frame-id", "b"],
         "both quaternion"),
        (["0", "0", "0", "0", "0", "0", "a", "b", "--x", "1"], "new-style"),
        (["--frame-id", "a", "--child-frame-id", "b", "--x"], "--x"),
        (["--x", "--frame-id", "a", "--child-frame-id", "b"], "--x"),
        (["--x", "one", "--frame-id", "a", "--child-frame-id", "b"], "--x: 'one'"),
        (["--frame-id", "a", "--child-frame-id", "a"], "both 'a'"),
    ]:
        with pytest.raises(ValueError, match=re.escape(needle)):
            parse_static_args(bad)
    import tfbus.cli.static_transform as tcli

    seen = []

    async def fake(open_bus: object, ts: object, once: bool) -> None:
        seen.append(ts)

    monkeypatch.setattr(tcli, "_publish_static", fake)
    code, _, err = run("static-transform", "--x", "0.1", "--z", "0.2", "--frame-id",
                       "base_link", "--child-frame-id", "base_laser", "--local")
    assert code == 0, err
    assert seen == [parse_static_args(["0.1", "0", "0.2", "0", "0", "0", "base_link",
                                       "base_laser"])]
    code, _, err = run("static-transform", "--x", "0.1", "--frame-id", "a", "--local")
    assert_usage_error(code, err, "--child-frame-id")
