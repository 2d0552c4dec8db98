"""The CPU of one ``tfbus view`` page at 30 redraws a second on 100 moving frames, one
tfbus against another in the same run, alternated.

Each measurement is a child process of its own (the "view process"): it fills a Buffer
with ``--frames`` dynamic transforms (a chain of 10, the rest leaves, all moving, as
``bench_view.py`` sends them) 100 times a second and draws it at most 30 times a second
(:func:`tfbus.view.player.draw_live`, as ``tfbus view --bus`` does) on a page that one
headless Chromium (started by the child in a session of its own, ended by that id) has
open. Its process CPU over ``--seconds`` of wall time (after the page connected and
1 s of settling) is printed, with the redraws a second and the mean time of one redraw,
and the CPU of the same filling with no page (``feed only``, measured first for a third
of ``--seconds``), and the drawing's own CPU: the view process's over the feed's, per
redraw and at 30 redraws a second (a busy machine may not keep 30 a second). With
``--before PATH`` (a checkout of tfbus, e.g. ``git worktree add /tmp/before HEAD~3`` with
the compiled core copied in), children run that checkout's tfbus and this one's in turn,
``--rounds`` times each, and the means are compared.

    .venv/bin/python benchmarks/bench_view_cost.py [--seconds 10] [--rounds 3] \\
        [--frames 100] [--before /tmp/before]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RATE = 100.0
DRAW_HZ = 30.0


def child(seconds: float, frames: int) -> dict[str, float]:
    """One view process: the feed alone, then the feed drawn on a page with a browser."""
    sys.path.insert(0, str(HERE))
    import bench_view

    from tfbus.buffer import Buffer
    from tfbus.clock import SystemClock
    from tfbus.monitor import TfSummary
    from tfbus.view.player import draw_live
    from tfbus.view.server import TfPage

    bench_view.FRAMES = frames
    clock = SystemClock()
    buffer = Buffer(cache_time=10.0, clock=clock)
    summary = TfSummary()

    def run(wall: float, page: TfPage | None) -> tuple[float, int, float]:
        redraws, redraw_time = 0, 0.0
        next_draw = time.perf_counter()
        tick = time.perf_counter()
        cpu0, end = time.process_time(), time.perf_counter() + wall
        while (now := time.perf_counter()) < end:
            for t in bench_view.transforms(time.time()):
                buffer.set_transform(t, "bench")
            if page is not None and now >= next_draw:
                t0 = time.perf_counter()
                draw_live(page, buffer, summary, clock.now())
                redraw_time += time.perf_counter() - t0
                redraws += 1
                next_draw = max(next_draw + 1.0 / DRAW_HZ, t0)
            tick += 1.0 / RATE
            time.sleep(max(0.0, tick - time.perf_counter()))
        return (time.process_time() - cpu0) / wall, redraws, redraw_time

    feed, _, _ = run(seconds / 3, None)
    page = TfPage("127.0.0.1", 0)
    try:
        with bench_view.browser(page) as shown:
            if not shown:
                raise SystemExit("no chromium on PATH, or the page did not connect in 60 s")
            run(1.0, page)  # settle: every node made, the browser caught up
            cpu, redraws, redraw_time = run(seconds, page)
    finally:
        page.close()
    return {"feed": feed, "cpu": cpu, "redraws": redraws / seconds,
            "redraw_ms": 1e3 * redraw_time / max(redraws, 1)}


def measure(tree: Path, seconds: float, frames: int) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run(
        [sys.executable, __file__, "--child", "--seconds", str(seconds), "--frames",
         str(frames)], env=env, capture_output=True, text=True, timeout=seconds * 3 + 180,
        check=True)
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def _load() -> str:
    try:
        return " ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--before", type=Path, default=None,
                    help="a checkout of tfbus to compare with (run alternately)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.seconds, args.frames)))
        return
    trees = {"this": ROOT} if args.before is None else {"before": args.before.resolve(),
                                                         "after": ROOT}
    results: dict[str, list[dict[str, float]]] = {k: [] for k in trees}
    load_at_start = _load()
    for _ in range(args.rounds):
        for name, tree in trees.items():
            results[name].append(measure(tree, args.seconds, args.frames))
    print(f"one headless Chromium page, {args.frames} frames moving at {RATE:.0f} Hz, drawn "
          f"at most {DRAW_HZ:.0f} times a second; {args.rounds} x {args.seconds:g} s per "
          f"tfbus, alternated; load average {load_at_start} at start, {_load()} at end")
    for name, runs in results.items():
        cpu = statistics.fmean(r["cpu"] for r in runs)
        feed = statistics.fmean(r["feed"] for r in runs)
        each = ", ".join(f"{100 * r['cpu']:.1f}" for r in runs)
        redraws = statistics.fmean(r["redraws"] for r in runs)
        # the drawing's own CPU (over the feed) per redraw, and at 30 redraws a second
        per = (cpu - feed) / max(redraws, 1e-9)
        print(f"  {name:<7} view process {100 * cpu:5.1f} % of one core ({each}); feed only "
              f"{100 * feed:4.1f} %; {redraws:.1f} redraws/s, "
              f"{statistics.fmean(r['redraw_ms'] for r in runs):.2f} ms per redraw")
        print(f"  {'':<7} drawing: {1e3 * per:5.2f} ms of CPU per redraw, "
              f"{100 * per * DRAW_HZ:5.1f} % of one core at {DRAW_HZ:.0f} redraws/s")


if __name__ == "__main__":
    main()
