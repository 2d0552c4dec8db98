"""The CPU ``tfbus view`` costs following a 100 Hz x 50-frame source.

In one process, for ``--seconds`` of wall time: every 10 ms, 50 dynamic transforms (a
chain of 10 plus 40 leaves, slowly moving) go into a BufferCore and TfSummary, as the
live bus source stores them; every 1/30 s the page redraws (``draw_live``: the scene model
with 50 lookups, then viser's frame, label, line and panel updates). A browser may be
connected to the printed address meanwhile. Prints the process CPU per wall second (the
ingest alone, then ingest + view) and the mean time of one redraw.

    .venv/bin/python benchmarks/bench_view.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import math
import time

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.core import BufferCore
from tfbus.monitor import TfSummary
from tfbus.view.player import MAX_DRAW_HZ, draw_live
from tfbus.view.server import TfPage

FRAMES = 50
RATE = 100.0


def transforms(t: float) -> list[TransformStamped]:
    stamp = Time.from_sec(t)
    out = []
    for i in range(FRAMES):
        parent = "world" if i == 0 else (f"f{i - 1}" if i < 10 else f"f{i % 10}")
        a = 0.1 * t + i
        out.append(TransformStamped(
            Header(stamp, parent), f"f{i}",
            Transform(Vector3(0.5 * math.cos(a), 0.5 * math.sin(a), 0.1),
                      Quaternion(0.0, 0.0, math.sin(a / 2), math.cos(a / 2)))))
    return out


def run(seconds: float, page: TfPage | None) -> tuple[float, float, int]:
    core, stats = BufferCore(), TfSummary()
    start = time.monotonic()
    cpu0 = time.process_time()
    next_tf = next_draw = start
    draws = 0
    draw_time = 0.0
    while (now := time.monotonic()) - start < seconds:
        if now >= next_tf:
            t = time.time()
            batch = transforms(t)
            for tr in batch:
                core.set_transform(tr, "bench")
            stats.add(Time.from_sec(t), batch, "bench", static=False)
            next_tf += 1.0 / RATE
        if page is not None and now >= next_draw:
            d0 = time.perf_counter()
            draw_live(page, core, stats, Time.from_sec(time.time()))
            draw_time += time.perf_counter() - d0
            draws += 1
            next_draw += 1.0 / MAX_DRAW_HZ
        time.sleep(max(0.0, min(next_tf, next_draw if page else next_tf) - time.monotonic()))
    cpu = time.process_time() - cpu0
    return cpu / seconds, draw_time / max(draws, 1), draws


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args()
    base, _, _ = run(args.seconds, None)
    page = TfPage("127.0.0.1", 0)
    try:
        print(f"page: http://127.0.0.1:{page.port}/")
        full, per_draw, draws = run(args.seconds, page)
    finally:
        page.close()
    print(f"source {RATE:.0f} Hz x {FRAMES} frames, {args.seconds:g} s wall")
    print(f"  ingest only:        {100 * base:5.1f} % of one core")
    print(f"  ingest + view:      {100 * full:5.1f} % of one core "
          f"({draws} redraws, {draws / args.seconds:.1f}/s)")
    print(f"  view alone:         {100 * (full - base):5.1f} % of one core, "
          f"{1e3 * per_draw:.2f} ms per redraw")


if __name__ == "__main__":
    main()
