"""``tfbus static-transform``: static_transform_publisher."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence

import click

from tfbus.cli._bus_spec import publish_bus, publish_options
from tfbus.cli._common import console, fail, literal
from tfbus.cli._live_session import cancel_on_signal, run_live
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

__all__ = ["command", "parse_static_args"]


_TRANSLATION_FLAGS = ("--x", "--y", "--z")
_QUATERNION_FLAGS = ("--qx", "--qy", "--qz", "--qw")
_RPY_FLAGS = ("--roll", "--pitch", "--yaw")
_FRAME_FLAGS = ("--frame-id", "--child-frame-id")
FLAGS = _TRANSLATION_FLAGS + _QUATERNION_FLAGS + _RPY_FLAGS + _FRAME_FLAGS
"""ROS 2's ``static_transform_publisher`` flags, each followed by its value."""


def parse_static_args(args: Sequence[str], stamp: Time | None = None) -> TransformStamped:
    """Parse static_transform_publisher's arguments into a TransformStamped.

    Positional (ROS 1, and ROS 2's deprecated form): ``x y z yaw pitch roll parent
    child`` (angles in radians, applied as tf2's ``setRPY(roll, pitch, yaw)``: fixed axes
    X, Y, Z) or ``x y z qx qy qz qw parent child`` (normalised). A trailing ROS 1
    ``period_in_ms`` is accepted and ignored.

    Flags (ROS 2, tf2_ros ``static_transform_broadcaster_program.cpp``): ``--x --y --z``
    (default 0), ``--qx --qy --qz --qw`` (default 0, 0, 0, 1: a flag sets its component
    only) or ``--roll --pitch --yaw`` (default 0), and the required ``--frame-id`` and
    ``--child-frame-id``; each flag is followed by its value. As there: quaternion and
    Euler flags together, flags mixed with positional arguments, a flag without a value
    and positional arguments that are not 8 or 9 are errors. Unlike there the quaternion
    is normalised (a zero one is an error) and frames must differ.

    Raises:
        ValueError: wrong count, a non-number, a zero quaternion, a missing or empty
            frame id, or parent == child (the message names the argument).
    """
    flags: dict[str, str] = {}
    positional: list[str] = []
    items = list(args)
    i = 0
    while i < len(items):
        item = items[i]
        if item in FLAGS:
            if i + 1 == len(items) or items[i + 1] in FLAGS:
                raise ValueError(f"not enough arguments for {item} (it needs a value)")
            if item in flags:
                raise ValueError(f"{item} given twice")
            flags[item] = items[i + 1]
            i += 2
            continue
        if item.startswith("--") and not _is_number(item):
            raise ValueError(f"unknown option {item!r} (flags: {' '.join(FLAGS)})")
        positional.append(item)
        i += 1
    if flags:
        if positional:
            raise ValueError(
                "cannot give both new-style (flags) and old-style (positional) arguments: "
                f"{' '.join(positional)!r}"
            )
        return _from_flags(flags, stamp)
    return _from_positional(positional, stamp)


def _number(name: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{name}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{name}: {text!r} is not a finite number")
    return v


def _from_flags(flags: dict[str, str], stamp: Time | None) -> TransformStamped:
    quat = [f for f in _QUATERNION_FLAGS if f in flags]
    rpy = [f for f in _RPY_FLAGS if f in flags]
    if quat and rpy:
        raise ValueError(f"cannot give both quaternion ({' '.join(quat)}) and Euler "
                         f"({' '.join(rpy)}) rotations")
    x, y, z = (_number(f, flags.get(f, "0")) for f in _TRANSLATION_FLAGS)
    for f, what in zip(_FRAME_FLAGS, ("frame id", "child frame id"), strict=True):
        if not flags.get(f):
            raise ValueError(f"{f}: the {what} is required and must not be empty")
    if rpy:
        roll, pitch, yaw = (_number(f, flags.get(f, "0")) for f in _RPY_FLAGS)
        return _make(x, y, z, _rpy(roll, pitch, yaw), flags["--frame-id"],
                     flags["--child-frame-id"], stamp)
    q = tuple(_number(f, flags.get(f, "1" if f == "--qw" else "0")) for f in _QUATERNION_FLAGS)
    return _make(x, y, z, q, flags["--frame-id"], flags["--child-frame-id"], stamp)


def _from_positional(items: list[str], stamp: Time | None) -> TransformStamped:
    n = len(items)
    if n in (9, 10) and _is_number(items[-1]) and not _is_number(items[-2]):
        items = items[:-1]  # ROS 1 period_in_ms
    if len(items) not in (8, 9):
        raise ValueError(
            f"expected 8 arguments (x y z yaw pitch roll parent child) or 9 "
            f"(x y z qx qy qz qw parent child), or ROS 2's flags (--x ... --frame-id F "
            f"--child-frame-id C), got {n}"
        )
    *numbers, parent, child = items
    names = ["x", "y", "z"] + (["yaw", "pitch", "roll"] if len(numbers) == 6
                               else ["qx", "qy", "qz", "qw"])
    values = [_number(name, text) for name, text in zip(names, numbers, strict=True)]
    if not parent or not child:
        raise ValueError("frame ids must not be empty")
    x, y, z = values[:3]
    if len(values) == 6:
        yaw, pitch, roll = values[3:]
        return _make(x, y, z, _rpy(roll, pitch, yaw), parent, child, stamp)
    return _make(x, y, z, tuple(values[3:]), parent, child, stamp)


def _rpy(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """tf2's ``setRPY(roll, pitch, yaw)``: fixed axes X, Y, Z."""
    from tfbus.geometry import quaternion_from_euler

    return tuple(float(c) for c in quaternion_from_euler(roll, pitch, yaw, "sxyz"))


def _make(x: float, y: float, z: float, q: tuple[float, ...], parent: str, child: str,
          stamp: Time | None) -> TransformStamped:
    if parent.lstrip("/") == child.lstrip("/"):
        raise ValueError(f"parent and child frame are both {parent!r}")
    qx, qy, qz, qw = q
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if norm == 0.0 or not math.isfinite(norm):
        raise ValueError(f"quaternion ({qx}, {qy}, {qz}, {qw}) is not a rotation")
    return TransformStamped(
        Header(stamp if stamp is not None else Time(0), parent),
        child,
        Transform(Vector3(x, y, z), Quaternion(qx / norm, qy / norm, qz / norm, qw / norm)),
    )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


@click.command("static-transform", context_settings={"ignore_unknown_options": True})
@click.argument("args", nargs=-1, type=click.UNPROCESSED)
@publish_options
@click.option("--once", is_flag=True, help="Publish once and exit (default: until Ctrl-C).")
def command(args: tuple[str, ...], bus: str | None, local: bool, once: bool) -> int:
    """Publish a static transform on /tf_static, like static_transform_publisher.

    It is published on --bus (default 'zenoh', where 'tfbus echo --bus zenoh' and
    every other process see it; latched for late joiners) until Ctrl-C or SIGTERM.

    \b
    Arguments (static_transform_publisher's conventions):
      x y z yaw pitch roll parent child       metres, radians (yaw about Z, pitch
                                              about Y, roll about X: setRPY)
      x y z qx qy qz qw parent child          quaternion, normalised
      --x X --y Y --z Z --qx QX --qy QY --qz QZ --qw QW --roll R --pitch P --yaw Y
      --frame-id PARENT --child-frame-id CHILD
                                              ROS 2's flags: each optional (0, and
                                              qw 1) but the two frame ids

    \b
    Examples:
      tfbus static-transform 0.1 0 0.2 0 0 0 base_link base_laser
      tfbus static-transform 0 0 1 0 0 0.7071068 0.7071068 world camera --once
      tfbus static-transform --x 0.1 --z 0.2 --frame-id base_link --child-frame-id base_laser
      tfbus static-transform -1 0 0 1.5708 0 0 map odom    # negatives need no --
      tfbus static-transform 0 0 1 0 0 0 world cam --bus 'zenoh:tcp/10.0.0.2:7448'
    """
    try:
        ts = parse_static_args(args)
    except ValueError as err:
        fail(str(err))
    open_bus = publish_bus(bus, local, name="static_transform_publisher")
    code = run_live(lambda: _publish_static(open_bus, ts, once))
    return 0 if code in (None, 130) else code


def _announce(ts: TransformStamped) -> None:
    tr, q = ts.transform.translation, ts.transform.rotation
    console().print(
        f"publishing static transform {literal(ts.header.frame_id)} -> "
        f"{literal(ts.child_frame_id)}: translation ({tr.x}, {tr.y}, {tr.z}), rotation "
        f"({q.x:.9g}, {q.y:.9g}, {q.z:.9g}, {q.w:.9g})"
    )


async def _publish_static(open_bus: Callable[[], object], ts: TransformStamped,
                          once: bool) -> None:
    """Open the bus, publish ``ts`` (latched), say so, and stay until a signal."""
    import anyio

    from tfbus.broadcaster import StaticTransformBroadcaster
    from tfbus.bus import Bus

    bus = open_bus()
    assert isinstance(bus, Bus)
    async with bus, anyio.create_task_group() as tg:
        if not once:
            await tg.start(cancel_on_signal, tg.cancel_scope)
        await StaticTransformBroadcaster(bus).send_transform(ts)
        _announce(ts)
        sys.stdout.flush()
        if once:
            tg.cancel_scope.cancel()
            return
        await anyio.sleep_forever()
