"""``tfbus static-transform``: static_transform_publisher (layer 5)."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence

import click

from tfbus.cli._common import console, fail, literal
from tfbus.cli._sources import cancel_on_signal, publish_bus, publish_options, run_live
from tfbus.messages import Header, Quaternion, Transform, TransformStamped, Vector3
from tfbus.time import Time

__all__ = ["command", "parse_static_args"]


def parse_static_args(args: Sequence[str], stamp: Time | None = None) -> TransformStamped:
    """Parse static_transform_publisher's positional arguments into a TransformStamped.

    ``x y z yaw pitch roll parent child`` (angles in radians, applied as tf2's
    ``setRPY(roll, pitch, yaw)``: fixed axes X, Y, Z) or ``x y z qx qy qz qw parent
    child`` (normalised). A trailing ROS 1 ``period_in_ms`` is accepted and ignored.

    Raises:
        ValueError: wrong count, a non-number, a zero quaternion or parent == child.
    """
    from tfbus.geometry import quaternion_from_euler

    items = list(args)
    if len(items) in (9, 10) and _is_number(items[-1]) and not _is_number(items[-2]):
        items = items[:-1]  # ROS 1 period_in_ms
    if len(items) not in (8, 9):
        raise ValueError(
            f"expected 8 arguments (x y z yaw pitch roll parent child) or 9 "
            f"(x y z qx qy qz qw parent child), got {len(args)}"
        )
    *numbers, parent, child = items
    values = []
    for text in numbers:
        try:
            v = float(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{text!r} is not a finite number")
        values.append(v)
    if not parent or not child:
        raise ValueError("frame ids must not be empty")
    if parent.lstrip("/") == child.lstrip("/"):
        raise ValueError(f"parent and child frame are both {parent!r}")
    x, y, z = values[:3]
    if len(values) == 6:
        yaw, pitch, roll = values[3:]
        qx, qy, qz, qw = (float(c) for c in quaternion_from_euler(roll, pitch, yaw, "sxyz"))
    else:
        qx, qy, qz, qw = values[3:]
        norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        if norm == 0.0 or not math.isfinite(norm):
            raise ValueError(f"quaternion ({qx}, {qy}, {qz}, {qw}) is not a rotation")
        qx, qy, qz, qw = qx / norm, qy / norm, qz / norm, qw / norm
    return TransformStamped(
        Header(stamp if stamp is not None else Time(0), parent),
        child,
        Transform(Vector3(x, y, z), Quaternion(qx, qy, qz, qw)),
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

    \b
    Examples:
      tfbus static-transform 0.1 0 0.2 0 0 0 base_link base_laser
      tfbus static-transform 0 0 1 0 0 0.7071068 0.7071068 world camera --once
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
