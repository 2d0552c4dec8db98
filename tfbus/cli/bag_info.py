"""``tfbus bag-info``: frames, parents, broadcasters, rates and span of a bag."""

from __future__ import annotations

from pathlib import Path

import click

from tfbus.cli._bag_source import BagSource
from tfbus.cli._common import RATE_HELP, bag_path, console, finish_status, fmt_sec, literal

__all__ = ["command"]


@click.command("bag-info", epilog=RATE_HELP)
@click.argument("path", type=bag_path())
def command(path: Path) -> int:
    """Frames, parents, broadcasters, rates and time span of a bag's tf data.

    PATH is a ROS 1 .bag, a ROS 2 bag folder, or a .db3 / .mcap file.

    \b
    Examples:
      tfbus bag-info turtle.bag
      tfbus bag-info rosbag2_2024_05_03/
      tfbus bag-info nav2.mcap
    """
    from rich.table import Table

    from tfbus.bag import detect_format

    src = BagSource(path)
    s = src.summary()
    out = console()
    out.print(f"path:       {literal(path)}")
    out.print(f"format:     {detect_format(path).value}")
    out.print(
        f"tf span:    {fmt_sec(s.start.ns if s.start else None)} .. "
        f"{fmt_sec(s.end.ns if s.end else None)} ({s.duration:.3f} s bag time)"
    )
    topics = ", ".join(f"{t} {n}" for t, n in sorted(s.messages.items())) or "none"
    out.print(f"messages:   {topics}")
    n_static = sum(1 for f in s.frames.values() if f.static)
    all_frames = set(s.frames) | {f.parent for f in s.frames.values()}
    out.print(
        f"frames:     {len(all_frames)} ({n_static} static links, "
        f"{len(s.frames) - n_static} dynamic links, {s.transform_count} transforms)"
    )
    table = Table(show_edge=False, header_style="bold")
    for col in ("frame", "parent", "kind", "broadcaster"):
        table.add_column(col, overflow="fold")
    for col in ("samples", "rate Hz", "oldest", "newest"):
        table.add_column(col, justify="right", no_wrap=True)
    for f in sorted(s.frames.values(), key=lambda f: (f.static, f.parent, f.child)):
        table.add_row(
            literal(f.child), literal(f.parent), "static" if f.static else "dynamic",
            literal(f.authority), str(f.count), "-" if f.static else f"{f.rate:.2f}",
            fmt_sec(f.first_stamp), fmt_sec(f.last_stamp),
        )
    out.print(table)
    return finish_status(src.problem)
