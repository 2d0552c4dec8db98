"""``tfbus lookup``: the pose of one frame in another every N seconds over a folder of
recordings, into one Parquet file (:func:`tfbus.table.recordings.poses_every`)."""

from __future__ import annotations

import glob
import os
from pathlib import Path

import click

from tfbus.cli._common import (
    MAX_SECONDS,
    FiniteFloat,
    console,
    error,
    fail,
    literal,
    seconds,
    warn,
)
from tfbus.errors import MissingExtraError

__all__ = ["command"]


def _expand(patterns: tuple[str, ...]) -> list[Path]:
    """The recordings the ``--bag`` patterns name (glob patterns, ``**`` recursive), in
    sorted order, each once."""
    found: dict[str, None] = {}
    for pattern in patterns:
        matches = sorted(glob.glob(pattern, recursive=True))
        if not matches:
            fail(f"--bag {pattern!r} matches no file or folder")
        for m in matches:
            found.setdefault(m, None)
    return [Path(m) for m in found]


MIN_STEP = 0.001
"""Shortest ``--every`` and ``--window``, seconds (one pose a millisecond: above any tf
rate; a shorter step would only multiply rows and windows without new data)."""


@click.command("lookup")
@click.option("--bag", "bags", multiple=True, required=True, metavar="GLOB",
              help="Recordings (.bag, .mcap, .db3, ROS 2 bag folders): a path or a glob "
                   "pattern ('recordings/*.mcap', '**' recursive); repeatable.")
@click.option("--target", required=True, help="Frame to express the poses in (target_frame).")
@click.option("--source", required=True, help="Frame whose pose is wanted (source_frame).")
@click.option("--every", type=FiniteFloat(min=MIN_STEP, max=MAX_SECONDS), required=True,
              metavar="SECONDS",
              help="Seconds between two stamps, on the transforms' header stamps (the "
                   "data's clock, simulated time included), from each file's first /tf "
                   "transform's stamp to its last.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Parquet file to write (replaced if it exists).")
@click.option("--window", type=FiniteFloat(min=MIN_STEP, max=MAX_SECONDS), default=60.0,
              show_default=True,
              metavar="SECONDS", help="Each file is read window by window, this wide.")
@click.option("--margin", type=seconds(zero=True), default=5.0, show_default=True,
              metavar="SECONDS",
              help="How far each window's data reaches beyond it: more than the links' "
                   "longest gap between samples.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar, no summary line.")
def command(bags: tuple[str, ...], target: str, source: str, every: float, output: Path,
            window: float, margin: float, quiet: bool) -> int:
    """Poses of SOURCE in TARGET every N seconds over many recordings, to Parquet.

    One row per stamp and file: recording, target_frame, source_frame, stamp (ns,
    the header stamps' clock), x, y, z, qx, qy, qz, qw, transform_stamp, status ("ok"
    or tf2's exception class) and message (tf2's text). A stamp tf2 cannot answer is a
    row with its status, never an abort. Files are read window by window through their
    index (memory bounded by the window, not the file); a damaged file's readable part
    is written, then a warning, and the exit status is 1. When no row is answered the
    exit status is 1, the first row's reason is printed and OUTPUT is left as it was.
    OUTPUT is written under a temporary name beside it and renamed when complete: an
    interrupted or failed run leaves no partial file.

    \b
    Examples:
      tfbus lookup --bag 'recordings/*.mcap' --target map --source base_link \\
          --every 0.1 -o poses.parquet
      tfbus lookup --bag a.bag --bag 'b/**/*.db3' --target odom --source laser \\
          --every 1 -o laser.parquet --window 30
    """
    try:
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.parquet as pq

        from tfbus.table.recordings import output_schema, poses_every
    except (ImportError, MissingExtraError):
        from tfbus._extras import extra_advice

        fail(f"tfbus lookup needs the 'pyarrow' package: {extra_advice('pyarrow', 'table')}")
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from tfbus.errors import BagError

    paths = _expand(bags)
    schema = pa.schema([("recording", pa.string()), *output_schema()])
    rows = failed_rows = 0
    first_failure: tuple[str, str] | None = None
    damaged: list[tuple[Path, int]] = []  # (recording, rows read before the damage)
    progress = Progress(
        TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
        console=console(err=True), disable=quiet, transient=False,
    )
    try:
        if output.is_dir():
            raise IsADirectoryError(21, "Is a directory")
        output.parent.mkdir(parents=True, exist_ok=True)
        # Beside OUTPUT (one file system: the rename is atomic), named by this process
        # (a file of that name is a dead run's leftover), with the permissions the
        # umask gives any new file.
        partial = output.with_name(f".{output.name}.{os.getpid()}.part")
        partial.open("wb").close()
    except OSError as err:
        fail(f"-o: cannot write {literal(output)}: {err.strerror or err}")
    try:
        with pq.ParquetWriter(partial, schema) as writer, progress:
            task = progress.add_task("recordings", total=len(paths))
            for path in paths:
                progress.update(task, description=f"lookup {literal(path.name)}")
                before = rows
                try:
                    for part in poses_every(path, target, source, every, window=window,
                                            margin=margin):
                        name_column = pa.array([str(path)] * part.num_rows, pa.string())
                        writer.write_table(
                            part.add_column(0, "recording", name_column).cast(schema))
                        rows += part.num_rows
                        failed = pc.invert(pc.equal(part.column("status"), "ok"))
                        n_failed = int(pc.sum(failed).as_py() or 0)
                        failed_rows += n_failed
                        if n_failed and first_failure is None:
                            i = int(pc.index(failed, True).as_py())
                            first_failure = (str(part.column("status")[i]),
                                             str(part.column("message")[i]))
                except BagError as err:
                    damaged.append((path, rows - before))
                    progress.console.print(
                        f"tfbus lookup: warning: {literal(err)}", markup=False,
                        highlight=False)
                progress.advance(task)
        answered = rows - failed_rows
        if answered == 0:
            partial.unlink()
        else:
            os.replace(partial, output)
    except BaseException:
        partial.unlink(missing_ok=True)  # interrupted: no partial file, OUTPUT untouched
        raise
    unread = sum(1 for _, n in damaged if n == 0)
    if not quiet:
        read = len(paths) - unread
        parts = [f"{rows} rows ({failed_rows} not answered) from {read} "
                 f"recording{'s' if read != 1 else ''}"]
        if len(damaged) > unread:
            parts.append(f"{len(damaged) - unread} of them damaged (read up to the damage)")
        if unread:
            parts.append(f"{unread} of {len(paths)} not read")
        target_note = (f" -> {literal(output)}" if answered
                       else f"; {literal(output)} not written")
        console(err=True).print(", ".join(parts) + target_note, markup=False,
                                highlight=False)
    if answered == 0:
        if first_failure is not None:
            error(f"none of the {rows} rows was answered; the first: {first_failure[0]}: "
                  f"{first_failure[1]}")
        elif unread == len(paths):
            error("no row to answer: " + ("the recording could not be read" if unread == 1
                                          else "no recording could be read"))
        elif damaged:
            error(f"no row to answer: {unread} of {len(paths)} recordings could not be "
                  "read, the others have no /tf transform with a stamp")
        else:
            error("no row to answer: no /tf transform with a stamp in "
                  f"{'the recording' if len(paths) == 1 else 'the recordings'}")
        return 1
    if damaged:
        warn(f"{len(damaged)} recording(s) could not be read whole")
        return 1
    return 0
