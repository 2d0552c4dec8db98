"""The CPU of the real ``tfbus view --bus zenoh`` process following a live 100 Hz x
100-frame source in another process, with no browser and with one page, beside a bare
``TransformListener`` process on the same stream (the receive every follower pays).

Processes, all on 127.0.0.1 (Zenoh with explicit endpoints, multicast scouting off, as
``ZenohTransport`` configures itself):

* ``source``: a ``Bus(ZenohTransport(listen=...))`` publishing ``bench_view``'s 100
  moving frames (a chain of 10, the rest leaves) as one ``/tf`` message every 10 ms;
* ``listener``: a ``Bus(ZenohTransport(connect=...))`` with a ``TransformListener`` into a
  ``Buffer`` and nothing else: the floor of any process that follows this stream;
* ``accounting``: the view's own receive path with no page server: ``tfbus view``'s
  :class:`~tfbus.cli._bus_source.BusSource` (a ``TransformListener`` into a ``Buffer``
  through a :class:`~tfbus.monitor.MonitoredSink` keeping ``tfbus monitor``'s tables,
  broadcasters attributed) and a :class:`~tfbus.doctor.Doctor` fed by it, wired by the
  view's own ``tfbus.cli.view.page_doctor``: what the view pays for the
  tables and checks its page shows, before any drawing;
* ``raw``: a raw zenoh-python session configured as ``ZenohTransport`` configures itself
  (``tfbus.transports.zenoh.config.zenoh_config``) whose subscriber on the source's ``/tf``
  key hands each sample to a Python callback that only marks the first one heard: the
  floor of any zenoh-python subscriber of this stream, before any decode (no tfbus code
  per message);
* ``viser``: a bare viser server (:func:`viser_floor`) drawing the page the view draws
  for these frames (a label per frame moved, the axes and the links as one line-segments
  node each) 30 times a second while a browser is connected, its poses made by numpy:
  the floor of any viser program showing this page, with no tfbus code;
* ``view``: the command line a user runs, ``tfbus view --bus zenoh?connect=... --port P``
  (``python -m tfbus.cli``), which also keeps ``tfbus monitor``'s tables and ``tfbus
  doctor``'s checks for its page.

Each one's CPU (its threads' scheduler run time in ns, ``benchmarks/proc_cpu.py``) is read
over ``--rounds`` windows of ``--seconds`` with no browser (after the view has settled),
then again with one headless Chromium page open on the view (started here in a session
of its own, ended by that id; the page counts as connected once a TCP connection to the
view's port is established), then with one page open on the viser floor instead (the
view idle again). Prints each process's share of one core per window (min / median /
max), the view over the listener floor, and the view with a page against the listener
floor plus the viser floor. Figures only; nothing is asserted. Needs ``chromium`` on PATH
for the page phases.

``--baseline TREE`` also runs a listener and a view imported from another checkout's
tfbus (its compiled modules built in place) on the same source, in the same windows
(``listener@base``, ``view@base``; the page opens on this tree's view only, so
``view@base`` is printed with no browser): a change's effect measured side by side,
free of the machine's drift between runs.

    .venv/bin/python benchmarks/bench_view_process.py [--seconds 8] [--rounds 3]
        [--baseline /tmp/old-tree]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from proc_cpu import cpu_seconds  # noqa: E402

RATE = 100.0
"""/tf messages a second from the source."""

CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--window-size=1280,800", "--remote-debugging-port=0",
]  # fmt: skip


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def source(port: int) -> None:
    """The child that publishes the frames (until SIGINT/SIGTERM)."""
    import anyio
    import bench_view

    from tfbus.bus import Bus
    from tfbus.clock import every
    from tfbus.messages import TFMessage
    from tfbus.transports.zenoh import ZenohTransport

    async def main() -> None:
        transport = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="view-source")
        async with Bus(transport=transport) as bus:
            print("READY", flush=True)
            with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async with anyio.create_task_group() as tg:

                    async def publish() -> None:
                        async for _ in every(1.0 / RATE):
                            await bus.publish("/tf", TFMessage(bench_view.transforms(time.time())))

                    tg.start_soon(publish)
                    async for _ in signals:
                        tg.cancel_scope.cancel()

    anyio.run(main)


def listener(port: int) -> None:
    """The floor child: a TransformListener into a Buffer (until SIGINT/SIGTERM)."""
    import anyio

    from tfbus import Buffer, Bus, TransformListener
    from tfbus.transports.zenoh import ZenohTransport

    async def main() -> None:
        transport = ZenohTransport(connect=f"tcp/127.0.0.1:{port}", name="view-floor")
        async with Bus(transport=transport) as bus, TransformListener(Buffer(), bus):
            print("READY", flush=True)
            with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async for _ in signals:
                    return

    anyio.run(main)


def accounting(port: int) -> None:
    """The accounting floor child: ``tfbus view``'s bus source and doctor, no page (until
    SIGINT/SIGTERM)."""
    import anyio

    from tfbus.cli._bus_source import BusSource
    from tfbus.cli._live_session import live, run_live
    from tfbus.cli.view import page_doctor

    spec = f"zenoh?connect=tcp/127.0.0.1:{port}"
    src = BusSource(spec, name="view-accounting")
    page_doctor(src, spec)

    async def body() -> None:
        print("READY", flush=True)
        await anyio.sleep_forever()

    run_live(lambda: live(src, None, body))


def raw(port: int) -> None:
    """The raw Zenoh floor child: a no-op subscriber of the source's ``/tf`` key (until
    SIGINT/SIGTERM)."""
    import threading

    import zenoh

    from tfbus.topics import TF_TOPIC
    from tfbus.transports.zenoh.config import zenoh_config
    from tfbus.transports.zenoh.keys import KeySpace

    config, _fallback = zenoh_config(connect=f"tcp/127.0.0.1:{port}")
    session = zenoh.open(config)
    first = threading.Event()
    stop = threading.Event()

    def on_sample(_sample: object) -> None:
        first.set()

    subscriber = session.declare_subscriber(KeySpace().data(TF_TOPIC), on_sample)
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    if not first.wait(60):
        raise SystemExit("bench_view_process: the raw subscriber heard nothing in 60 s")
    print("READY", flush=True)
    stop.wait()
    subscriber.undeclare()
    session.close()


DRAW_HZ = 30.0
"""Redraws a second of the viser floor (the view's own most: ``MAX_DRAW_HZ``)."""
FRAMES = 100
"""Frames the viser floor draws (the source's)."""
AXIS = 0.25
"""Length of each drawn axis of the viser floor, metres (the view's default)."""


def viser_floor(port: int) -> None:
    """The drawing floor child (until SIGINT/SIGTERM): a bare viser server on 127.0.0.1
    ``port`` with the scene nodes the view makes for 100 frames (a grid, a hidden frame
    node and a label per frame, one line-segments node of every frame's x y z axes and one
    of the links), redrawn :data:`DRAW_HZ` times a second while a browser is connected,
    every frame moving: each redraw sends the same messages a redraw of the view sends
    (a position per label, queued as the view queues it, without viser's setters' check
    of each value; the axes' and the links' points and colours, one message each) inside
    ``server.atomic()``, the poses made by numpy from the time: what any viser program
    pays to show this page, with no tfbus code."""
    import asyncio
    import logging

    import numpy as np
    import viser

    try:
        from viser import _messages
    except ImportError:
        _messages = None
    # a probe of the port (no HTTP request) is not worth a traceback on stderr
    logging.getLogger("websockets").setLevel(logging.CRITICAL)
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    server.scene.add_grid("/grid", width=20.0, height=20.0, cell_size=1.0)
    labels = [server.scene.add_label(f"/tf/l{i}", f"f{i}") for i in range(FRAMES)]
    for i in range(FRAMES):
        server.scene.add_frame(f"/tf/f{i}", show_axes=False)
    queue = getattr(getattr(labels[0]._impl, "api", None), "_queue_scene_message", None)
    set_position = getattr(_messages, "SetPositionMessage", None)
    axis_colours = np.array([[(230, 30, 30)] * 2, [(30, 190, 30)] * 2, [(40, 80, 240)] * 2],
                            dtype=np.uint8)  # fmt: skip
    segments: dict[str, Any] = {}
    stop = asyncio.Event()

    def draw(t: float) -> None:
        a = 0.1 * t + np.arange(FRAMES)
        xyz = np.stack([0.5 * np.cos(a), 0.5 * np.sin(a), np.full(FRAMES, 0.1)], -1)
        c, s = np.cos(a), np.sin(a)  # each frame turned by a about z
        cols = np.stack([np.stack([c, s, 0 * a], -1), np.stack([-s, c, 0 * a], -1),
                         np.broadcast_to([0.0, 0.0, 1.0], (FRAMES, 3))], 1)  # fmt: skip
        starts = np.broadcast_to(xyz[:, None, :], cols.shape)
        axes = np.stack([starts, starts + AXIS * cols], 2).reshape(-1, 2, 3).astype(np.float32)
        links = np.stack([xyz[1:], xyz[:-1]], 1).astype(np.float32)
        with server.atomic():
            for label, p in zip(labels, xyz.tolist(), strict=True):
                if queue is None or set_position is None:
                    label.position = p
                    continue
                label._impl.position[:] = p
                queue(set_position(label._impl.name, tuple(p)))
            for name, pts, colours, width in (
                ("/axes", axes, np.tile(axis_colours, (FRAMES, 1, 1)), 4.0),
                ("/links", links, np.full((len(links), 2, 3), 200, dtype=np.uint8), 2.0),
            ):
                handle = segments.get(name)
                if handle is None:
                    segments[name] = server.scene.add_line_segments(
                        name, pts, colours, thickness=width, thickness_units="screen")
                else:
                    handle.points = pts
                    handle.colors = colours

    async def main() -> None:
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGINT, stop.set)
        loop.add_signal_handler(signal.SIGTERM, stop.set)
        print("READY", flush=True)
        deadline = loop.time()
        while not stop.is_set():
            deadline = max(deadline + 1.0 / DRAW_HZ, loop.time())
            await asyncio.sleep(deadline - loop.time())
            if server.get_clients():
                draw(time.time())

    asyncio.run(main())
    server.stop()


def established(port: int) -> int:
    """Established TCP connections to local ``port`` (``/proc/net/tcp``, ``tcp6``)."""
    n = 0
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if int(fields[1].rsplit(":", 1)[1], 16) == port and fields[3] == "01":
                n += 1
    return n


@dataclasses.dataclass
class Measured:
    """Per phase (``idle``: no browser; ``page``: a page on the view; ``floor``: a page
    on the viser floor) and process (``source``, ``listener``, ``accounting``, ``raw``,
    ``viser``, ``view``): its share of one core in each window (0.01 = 1 %);
    ``page_shown``: whether a page connected to the view (False without chromium, or when
    none connected within 120 s)."""

    share: dict[str, dict[str, list[float]]]
    page_shown: bool
    load: float
    why: str = ""
    """Why no page was measured, when none was."""


def _wait_line(proc: subprocess.Popen[str], want: Callable[[str], bool], what: str) -> str:
    assert proc.stdout is not None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if want(line):
            return line
    raise SystemExit(f"bench_view_process: {what} did not start within 60 s")


def measure(rounds: int, seconds: float, baseline: Path | None = None) -> Measured:
    """Start the processes, then read their CPU over ``rounds`` windows of ``seconds``
    with no browser, with one page on the view, and with one page on the viser floor
    (see the module docstring);
    with ``baseline``, also a listener and a view of that checkout's tfbus."""
    zport, vport, fport = _free_port(), _free_port(), _free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}  # fmt: skip
    procs: dict[str, subprocess.Popen[str]] = {}
    share: dict[str, dict[str, list[float]]] = {"idle": {}, "page": {}, "floor": {}}
    shown = False
    why = ""
    try:
        for name, port in (("source", zport), ("listener", zport), ("accounting", zport),
                           ("raw", zport), ("viser", fport)):  # fmt: skip
            procs[name] = subprocess.Popen(
                [sys.executable, __file__, f"--{name}", str(port)], env=env,
                stdout=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
            _wait_line(procs[name], lambda line: line.startswith("READY"), name)
        views = [("view", ROOT, env, vport)]
        if baseline is not None:
            base_env = {**os.environ, "PYTHONPATH": str(baseline)}
            procs["listener@base"] = subprocess.Popen(
                [sys.executable, __file__, "--listener", str(zport)], env=base_env,
                stdout=subprocess.PIPE, text=True, start_new_session=True, cwd=baseline,
            )  # fmt: skip
            _wait_line(procs["listener@base"], lambda line: line.startswith("READY"),
                       "listener@base")
            views.append(("view@base", baseline, base_env, _free_port()))
        for name, tree, view_env, port in views:  # ``-c`` puts the cwd first on sys.path
            procs[name] = subprocess.Popen(
                [sys.executable, "-c", "from tfbus.cli import main; main()", "view", "--bus",
                 f"zenoh?connect=tcp/127.0.0.1:{zport}", "--port", str(port)],
                env=view_env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, text=True,
                start_new_session=True, cwd=tree)  # fmt: skip
        deadline = time.monotonic() + 60
        while (not all(_listening(port) for *_, port in views)
               and time.monotonic() < deadline):
            time.sleep(0.1)
        time.sleep(3.0)  # the view connected to the source and past its first messages

        def windows(phase: str) -> None:
            for _ in range(rounds):
                before = {n: cpu_seconds(p.pid) for n, p in procs.items()}
                t0 = time.monotonic()
                time.sleep(seconds)
                wall = time.monotonic() - t0
                for n, p in procs.items():
                    share[phase].setdefault(n, []).append((cpu_seconds(p.pid) - before[n]) / wall)

        windows("idle")
        exe = shutil.which("chromium")
        if exe is None:
            why = "no chromium on PATH"
        else:
            why = _with_page(exe, vport, lambda: windows("page"),
                             lambda: procs["view"].poll() is None)  # fmt: skip
            shown = not why
            if shown:  # the same page drawn by viser alone, the view idle again
                floor_why = _with_page(exe, fport, lambda: windows("floor"),
                                       lambda: procs["viser"].poll() is None)  # fmt: skip
                if floor_why:
                    why = f"viser floor: {floor_why}"
        return Measured(share, shown, os.getloadavg()[0], why)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=20)


def _with_page(exe: str, port: int, measure: Callable[[], None],
               alive: Callable[[], bool]) -> str:
    """Open one headless Chromium page on 127.0.0.1 ``port`` (a session of its own,
    ended by that id), wait (at most 120 s) until it holds a TCP connection to the port
    and 3 s more (the page loaded, its websocket drawing), call ``measure``, close the
    browser; "" when measured, else why not (``alive``: whether the server still runs)."""
    with tempfile.TemporaryDirectory(prefix="tfbus-bench-view-",
                                     ignore_cleanup_errors=True) as profile:
        browser = subprocess.Popen(
            [exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"http://127.0.0.1:{port}/"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            deadline = time.monotonic() + 120
            connected = False
            while browser.poll() is None and time.monotonic() < deadline:
                connected = established(port) > 0
                if connected:
                    break
                time.sleep(0.1)
            if not connected:
                return (f"no page connected within 120 s (chromium "
                        f"{'running' if browser.poll() is None else 'exited'}, server "
                        f"{'running' if alive() else 'exited'}, "
                        f"port {'open' if _listening(port) else 'closed'})")
            time.sleep(3.0)  # the page loaded and drawing at its rate
            measure()
            return ""
        finally:  # the browser this started, and its renderers (its own session)
            os.killpg(browser.pid, signal.SIGKILL)
            browser.wait(timeout=30)


def _listening(port: int) -> bool:
    """Whether something accepts TCP connections on 127.0.0.1:``port``."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return True
    except OSError:
        return False


def _spread(values: list[float]) -> str:
    return (f"{100 * min(values):5.1f} / {100 * statistics.median(values):5.1f} / "
            f"{100 * max(values):5.1f} %")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=8.0, help="seconds a window")
    parser.add_argument("--rounds", type=int, default=3, help="windows a phase")
    parser.add_argument("--baseline", type=Path, metavar="TREE",
                        help="also a listener and a view of this checkout's tfbus")
    parser.add_argument("--source", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--listener", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--accounting", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--raw", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--viser", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.raw is not None:
        raw(args.raw)
        return
    if args.accounting is not None:
        accounting(args.accounting)
        return
    if args.viser is not None:
        viser_floor(args.viser)
        return
    if args.source is not None:
        source(args.source)
        return
    if args.listener is not None:
        listener(args.listener)
        return
    got = measure(args.rounds, args.seconds, args.baseline)
    print(f"tfbus view --bus zenoh following {RATE:.0f} Hz x 100 frames from another process; "
          f"{args.rounds} windows of {args.seconds:g} s a phase; share of one core "
          "min / median / max")  # fmt: skip
    for phase, label in (("idle", "no browser"), ("page", "one page")):
        if not got.share[phase]:
            print(f"  {label:<11} not measured: {got.why}")
            continue
        for name in ("view", "listener", "accounting", "raw", "source", "view@base",
                     "listener@base"):
            if name in got.share[phase] and (phase == "idle" or name != "view@base"):
                print(f"  {label:<11} {name:<13} {_spread(got.share[phase][name])}")
        over = [v - f for v, f in zip(got.share[phase]["view"], got.share[phase]["listener"],
                                      strict=True)]  # fmt: skip
        print(f"  {label:<11} view - listener floor {_spread(over)}")
        own = [v - a for v, a in zip(got.share[phase]["view"], got.share[phase]["accounting"],
                                     strict=True)]  # fmt: skip
        print(f"  {label:<11} view - accounting floor {_spread(own)}")
    floor = got.share["floor"].get("viser")
    if floor:
        print(f"  viser page  viser floor   {_spread(floor)}")
        page = statistics.median(got.share["page"]["view"])
        both = (statistics.median(got.share["page"]["listener"]) + statistics.median(floor))
        print(f"  one page    view {100 * page:.1f} % vs listener + viser floor "
              f"{100 * both:.1f} % (medians): {page / both:.2f}x")
    print(f"load {got.load:.2f} (1 min) at the end")


if __name__ == "__main__":
    main()
