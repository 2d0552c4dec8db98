"""``tfbus lookup``: the pose of one frame in another every N seconds over a folder of
recordings, into one Parquet file (:func:`tfbus.table.recordings.poses_every`)."""

from __future__ import annotations

import glob
from pathlib import Path

import click

from tfbus.cli._common import MAX_SECONDS, FiniteFloat, console, fail, literal, seconds, warn
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
              help="Seconds between two stamps (from each file's first /tf message).")
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

    One row per stamp and file: recording, target_frame, source_frame, stamp (ns),
    x, y, z, qx, qy, qz, qw, transform_stamp, status ("ok" or tf2's exception class)
    and message (tf2's text). A stamp tf2 cannot answer is a row with its status, never
    an abort. Files are read window by window through their index (memory bounded by
    the window, not the file); a damaged file's readable part is written, then a
    warning, and the exit status is 1.

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
    problems = 0
    progress = Progress(
        TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
        console=console(err=True), disable=quiet, transient=False,
    )
    try:
        if output.is_dir():
            raise IsADirectoryError(21, "Is a directory")
        output.parent.mkdir(parents=True, exist_ok=True)
        opened = pq.ParquetWriter(output, schema)
    except OSError as err:
        fail(f"-o: cannot write {literal(output)}: {err.strerror or err}")
    with opened as writer, progress:
        task = progress.add_task("recordings", total=len(paths))
        for path in paths:
            progress.update(task, description=f"lookup {literal(path.name)}")
            try:
                for part in poses_every(path, target, source, every, window=window,
                                        margin=margin):
                    name = pa.array([str(path)] * part.num_rows, pa.string())
                    writer.write_table(part.add_column(0, "recording", name).cast(schema))
                    rows += part.num_rows
                    failed_rows += part.num_rows - int(
                        pc.sum(pc.equal(part.column("status"), "ok")).as_py() or 0)
            except BagError as err:
                problems += 1
                progress.console.print(
                    f"tfbus lookup: warning: {literal(err)}", markup=False, highlight=False)
            progress.advance(task)
    if not quiet:
        console(err=True).print(
            f"{rows} rows ({failed_rows} not answered) from {len(paths) - problems} of "
            f"{len(paths)} recordings -> {literal(output)}")
    if problems:
        warn(f"{problems} recording(s) could not be read whole")
        return 1
    return 0
