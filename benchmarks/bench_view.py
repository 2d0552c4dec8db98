"""The CPU ``tfbus view --bus`` costs following a live 100 Hz x 100-frame source, with no
browser connected, with one page, and with ``--scan``.

In one process, on an in-process bus, for ``--seconds`` of wall time per phase: a
broadcaster sends ``--frames`` dynamic transforms (a chain of 10, the rest leaves, slowly
moving) as
one ``/tf`` message every 10 ms, a laser sends a 720-beam scan (frame ``f3``, a 25 ms
sweep, stamped at its first beam) on ``/scan`` at 40 Hz, and a TransformListener stores
the transforms through a MonitoredSink (Buffer + TfSummary), as ``tfbus view --bus``
does. Phases:

1. the source and the listener alone;
2. plus the view with no browser connected (``LiveView.run``: nothing drawn);
3. plus one browser page: the view redraws at most 30 times a second (the scene model
   with one lookup per frame, then viser's frame, label, line and panel updates);
4. plus ``--scan /scan`` (a MessageFilter on the fixed frame, tolerance the sweep; the
   newest scan projected with LaserProjection per redraw and drawn as a point cloud).

The view draws only while a browser is connected: phase 2 runs with none (the draw loop
sleeps), phases 3 and 4 again with one headless Chromium page connected (started here
in a session of its own, ended by that id; skipped without ``chromium`` on PATH), whose CPU is not
counted (it is another process). Prints the process CPU per wall second of each phase, the
redraws a second and the mean time of one redraw, and the scans received, passed and
drawn. Every phase runs with the garbage collector's young-generation threshold ``tfbus
view`` serves with (:func:`tfbus.cli.view.young_gc_threshold`).

    .venv/bin/python benchmarks/bench_view.py [--seconds 5] [--frames 100]
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import anyio
import numpy as np

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.buffer import Buffer
from tfbus.bus import Bus
from tfbus.cli.view import YOUNG_GC_THRESHOLD, young_gc_threshold
from tfbus.clock import SystemClock, every
from tfbus.listener import TransformListener
from tfbus.messages import TFMessage
from tfbus.monitor import MonitoredSink, TfSummary
from tfbus.sensor_msgs import LaserScan
from tfbus.view.live import LiveView
from tfbus.view.server import TfPage

FRAMES = 100
RATE = 100.0
SCAN_RATE = 40.0
BEAMS = 720


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


def scan(first_beam_ns: int) -> LaserScan:
    inc = 2 * math.pi / BEAMS
    return LaserScan(
        header=Header(Time.from_ns(first_beam_ns), "f3"), angle_min=-math.pi,
        angle_max=-math.pi + (BEAMS - 1) * inc, angle_increment=inc,
        time_increment=1.0 / SCAN_RATE / BEAMS, scan_time=1.0 / SCAN_RATE, range_min=0.1,
        range_max=30.0, ranges=np.full(BEAMS, 4.0, dtype=np.float32))


@dataclass
class Phase:
    cpu: float = 0.0
    """Process CPU seconds per wall second."""
    redraws: int = 0
    redraw_time: float = 0.0
    received: int = 0
    passed: int = 0
    drawn: int = 0


CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--window-size=1280,800", "--remote-debugging-port=0"]


@contextmanager
def browser(page: TfPage | None) -> Iterator[bool]:
    """One headless Chromium showing ``page`` while inside (True), ended by its session id; False
    (nothing started) without a page or without ``chromium`` on PATH."""
    exe = shutil.which("chromium")
    if page is None or exe is None:
        yield False
        return
    with tempfile.TemporaryDirectory(prefix="tfbus-bench-view-",
                                     ignore_cleanup_errors=True) as profile:
        proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                 f"http://127.0.0.1:{page.port}/"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            deadline = time.monotonic() + 60
            while not page.watched() and time.monotonic() < deadline:
                time.sleep(0.1)
            yield page.watched()
        finally:  # the browser this started, and its renderers (its own session)
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)


async def phase(seconds: float, page: TfPage | None, with_scan: bool,
                watched: bool = False) -> Phase:
    clock = SystemClock()
    buffer = Buffer(cache_time=10.0, clock=clock)
    stats = TfSummary()
    sink = MonitoredSink(buffer, stats, clock, lambda static: "bench")
    out = Phase()
    sweep_ns = round(1e9 / SCAN_RATE)
    async with Bus(queue_size=10_000) as bus, TransformListener(sink, bus, clock=clock), \
            anyio.create_task_group() as tg:

        async def tf_source() -> None:
            async for _ in every(1.0 / RATE, clock=clock):
                await bus.publish("/tf", TFMessage(transforms(time.time())))

        async def laser() -> None:
            async for _ in every(1.0 / SCAN_RATE, clock=clock):
                await bus.publish("/scan", scan(time.time_ns() - sweep_ns))

        tg.start_soon(tf_source)
        tg.start_soon(laser)
        view = None
        if page is not None:
            view = LiveView(page, buffer, stats, clock,
                            scan_topics=["/scan"] if with_scan else ())
            render = view.render

            def timed() -> object:
                t0 = time.perf_counter()
                try:
                    return render()
                finally:
                    out.redraw_time += time.perf_counter() - t0
                    out.redraws += 1

            view.render = timed  # type: ignore[method-assign]
            tg.start_soon(view.run, bus)
            if watched:
                with anyio.fail_after(60):
                    while not page.watched():
                        await anyio.sleep(0.05)
        await anyio.sleep(0.5)  # settle (the first scans wait for the fixed frame)
        out.redraws = 0
        out.redraw_time = 0.0
        cpu0 = time.process_time()
        await anyio.sleep(seconds)
        out.cpu = (time.process_time() - cpu0) / seconds
        if view is not None and with_scan:
            feed = view.feeds["/scan"]
            out.received, out.passed, out.drawn = feed.received, feed.passed, feed.drawn
        tg.cancel_scope.cancel()
    buffer.close()
    return out


def _page_phase(s: float, with_scan: bool) -> tuple[Phase, bool]:
    page = TfPage("127.0.0.1", 0)
    try:
        with browser(page) as shown:
            return anyio.run(phase, s, page, with_scan, shown), shown
    finally:
        page.close()


def _line(label: str, p: Phase, s: float, scans: bool = False) -> str:
    text = (f"  {label:<26}{100 * p.cpu:5.1f} % of one core ({p.redraws / s:.1f} "
            f"redraws/s, {1e3 * p.redraw_time / max(p.redraws, 1):.2f} ms per redraw")
    if scans:
        text += f"; scans received {p.received}, passed {p.passed}, drawn {p.drawn}"
    return text + ")"


def main() -> None:
    global FRAMES
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--frames", type=int, default=FRAMES)
    args = ap.parse_args()
    FRAMES = args.frames
    s = args.seconds
    # every phase with the garbage collector's thresholds the command serves with
    with young_gc_threshold(YOUNG_GC_THRESHOLD):
        base = anyio.run(phase, s, None, False)
        page = TfPage("127.0.0.1", 0)
        try:
            idle = anyio.run(phase, s, page, False)
        finally:
            page.close()
        view, shown = _page_phase(s, False)
        scans, _ = _page_phase(s, True)
    print(f"live source {RATE:.0f} Hz x {FRAMES} frames + {SCAN_RATE:.0f} Hz x {BEAMS}-beam "
          f"scans on an in-process bus, {s:g} s wall per phase")
    print(f"  source + listener:        {100 * base.cpu:5.1f} % of one core")
    print(_line("+ view, no browser:", idle, s))
    if not shown:
        print("  (no chromium on PATH: the page phases ran with no browser)")
    print(_line("+ view, one page:", view, s))
    print(_line("+ view --scan, one page:", scans, s, scans=True))
    print(f"  view alone:               {100 * (idle.cpu - base.cpu):5.1f} % of one core "
          f"idle; {100 * (view.cpu - base.cpu):5.1f} % with one page, "
          f"{100 * (scans.cpu - base.cpu):5.1f} % with --scan")


if __name__ == "__main__":
    main()
