"""``tfbus view``: the frames live in a browser (viser), like rviz's TF display (layer 5).

Needs the ``tfbus[view]`` extra (viser); without it the command says so in one line
(exit status 2).
"""

from __future__ import annotations

import gc
import importlib
import signal
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Final

import click

from tfbus.cli._common import HOST, FiniteFloat, bag_path, fail, seconds, use_sim_time_option
from tfbus.view.scene import DEFAULT_FRAME_TIMEOUT

if TYPE_CHECKING:
    from tfbus.cli._bus_source import BusSource
    from tfbus.doctor import Doctor
    from tfbus.view.clouds import CloudTrack
    from tfbus.view.foxglove_bridge import FoxgloveBridge
    from tfbus.view.record import RecordControl
    from tfbus.view.scans import ScanTrack

__all__ = ["command"]

NEEDS_EXTRA = "the 'viser' package is not installed: pip install 'tfbus[view]'"
CLOUD_SCHEMES = ("zenoh", "memory")
"""The ``--bus`` schemes that carry PointCloud2 (tfbus's own wire; in-process)."""

YOUNG_GC_THRESHOLD: Final = 10_000
"""The garbage collector's young-generation threshold (the first of
``gc.set_threshold``'s values: container objects allocated, less those freed, between two
collections of the young generation) while ``tfbus view`` serves, when the process's own
is lower (CPython's default is 700, 2000 from Python 3.13). A redraw of a live page makes
several hundred container objects that live until the next redraw (the scene's frame
views and poses, viser's messages): at 700 nearly every redraw set off a collection of the
young generation, which walked the scene it had just made, and they moved on to the older
generations' collections. Most of them are freed by reference counting before a
collection comes round at this threshold, so far fewer collections walk about as many
live objects each (:func:`young_gc_threshold`)."""


@contextmanager
def young_gc_threshold(threshold: int) -> Iterator[None]:
    """Raise the garbage collector's young-generation threshold to ``threshold`` for the
    body, when it is lower (a threshold of 0, the collector disabled, is left so; the
    older generations' thresholds are kept), and restore the thresholds found after it,
    however it ends (an exception leaves as itself). Cyclic garbage waits for at most
    ``threshold`` allocations more; nothing else changes (Python's ``gc`` module:
    ``gc.set_threshold``)."""
    before = gc.get_threshold()
    if 0 < before[0] < threshold:
        gc.set_threshold(threshold, *before[1:])
    try:
        yield
    finally:
        gc.set_threshold(*before)


@click.command("view")
@click.option("--bag", type=bag_path(), default=None, help="Show this bag, with a time slider.")
@click.option("--bus", "bus", metavar="SPEC", default=None,
              help="Show a live bus (default 'zenoh' without --bag).")
@click.option("--fixed-frame", default=None,
              help="Frame at the origin (default: the root of the largest tree).")
@click.option("--host", type=HOST, default="127.0.0.1", show_default=True,
              help="Address to serve on. The page answers only requests addressed to this "
                   "machine's names (localhost, 127.0.0.1, [::1]) or to --host, from its own "
                   "origin; from another machine give --token too.")
@click.option("--token", default=None, metavar="SECRET",
              help="Let a browser in from any name when it carries this secret "
                   "(http://HOST:PORT/?token=SECRET; 1-256 printable ASCII characters).")
@click.option("--port", type=click.IntRange(0, 65535), default=8080, show_default=True,
              help="TCP port of the page (0: any free port).")
@click.option("--scan", "scan_topics", multiple=True, metavar="TOPIC",
              help="Draw this topic's LaserScans (from the bag, or from the bus once their "
                   "transforms arrived), projected into the fixed frame "
                   "(tfbus.laser.LaserProjection). Repeatable.")
@click.option("--cloud", "cloud_topics", multiple=True, metavar="TOPIC",
              help="Draw this topic's PointCloud2s (x, y, z; at most 100 000 points each), "
                   "placed in the fixed frame at each cloud's stamp, from the bag or from a "
                   "zenoh bus. Repeatable.")
@click.option("--record", "record_path", default=None, metavar="PATH",
              type=click.Path(dir_okay=False, path_type=Path),
              help="Record /tf, /tf_static and the scans and clouds shown to this new MCAP "
                   "file from the start (ROS 2 CDR messages; tfbus.bag reads it).")
@click.option("--record-dir", "record_dir", default=None, metavar="DIR",
              type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Let the page start and stop recordings, to files named in the page "
                   "inside this folder only.")
@click.option("--record-max-mb", type=FiniteFloat(0.001, 1e6), default=1024.0,
              show_default=True, help="A recording ends by itself past this many MB of "
                                      "messages.")
@click.option("--record-max-seconds", type=seconds(), default=3600.0, show_default=True,
              help="A recording ends by itself past this many seconds of log time.")
@click.option("--foxglove", "foxglove_port", type=click.IntRange(0, 65535), default=None,
              metavar="PORT",
              help="Also serve the Foxglove WebSocket protocol on this port, on --host "
                   "(/tf and /tf_static as foxglove.FrameTransforms, scans as "
                   "foxglove.LaserScan, bag or clock time as server time).")
@click.option("--urdf", "urdf", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None,
              help="Draw this URDF's link geometry (boxes, cylinders, spheres, STL/OBJ/DAE "
                   "meshes) on the link frames, following the transforms "
                   "robot_state_publisher sends.")
@click.option("--mesh-dir", "mesh_dirs", multiple=True,
              type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="With --urdf: where package://PKG/... meshes are (DIR/PKG/...), before "
                   "ROS_PACKAGE_PATH's folders and those above the URDF. Repeatable.")
@click.option("--paused", is_flag=True, help="With --bag: start paused at the bag's start.")
@click.option("--rate", type=FiniteFloat(0.1, 10.0), default=1.0, show_default=True,
              help="With --bag: playback rate (x0.1-x10).")
@click.option("--frame-timeout", type=seconds(),
              default=DEFAULT_FRAME_TIMEOUT, show_default=True,
              help="Seconds without an update before a frame is hidden (it fades to grey "
                   "from a third of it, as rviz's TF display).")
@click.option("--fleet", is_flag=True,
              help="With --bag: its frames are a fleet's (robot/frame, as a namespace=* "
                   "listener prefixes them): a robot selector, one robot or all side by "
                   "side. A namespace=* bus always has it.")
@use_sim_time_option
def command(bag: Path | None, bus: str | None, fixed_frame: str | None, host: str,
            port: int, paused: bool, rate: float, frame_timeout: float,
            scan_topics: tuple[str, ...], foxglove_port: int | None,
            urdf: Path | None, mesh_dirs: tuple[Path, ...], token: str | None,
            use_sim_time: bool, cloud_topics: tuple[str, ...] = (),
            record_path: Path | None = None, record_dir: Path | None = None,
            record_max_mb: float = 1024.0, record_max_seconds: float = 3600.0,
            fleet: bool = False) -> None:
    """Serve a live 3D page of the frames (open the printed address in a browser).

    \b
    Examples:
      tfbus view --bag tests/data/webviz_turtle_tf_example.bag
      tfbus view --bus zenoh --fixed-frame odom --port 8081
      tfbus view --bag tests/data/laser/drl_guardian_3.bag --scan /scan --fixed-frame odom
      tfbus view --bus zenoh --scan /scan --foxglove 8765
      tfbus view --bag run.mcap --cloud /points --record-dir recordings
    """
    try:
        importlib.import_module("viser")
    except ImportError:
        fail(NEEDS_EXTRA)
    if bag is not None and bus is not None:
        fail("give --bag PATH or --bus SPEC, not both")
    if bag is not None and use_sim_time:
        fail("--use-sim-time applies to --bus sources only")
    if bag is not None:  # before the page opens
        from tfbus.cli._bag_source import check_bag

        check_bag(bag)
    if fleet and bag is None:
        fail("--fleet applies to --bag only (a namespace=* bus always has the robot selector)")
    if token is not None:
        from tfbus.view.guard import PageGuard

        try:
            PageGuard(host, port, token)
        except ValueError as err:
            fail(f"--token: {err}")
    if cloud_topics and bag is None:
        from tfbus.cli._bus_spec import parse_spec

        scheme = parse_spec(bus or "zenoh").scheme
        if scheme not in CLOUD_SCHEMES:
            fail(f"--cloud: PointCloud2 topics are carried by --bus "
                 f"{' and '.join(CLOUD_SCHEMES)} (and read from a --bag), not by {scheme!r}")
    both = sorted(set(cloud_topics) & set(scan_topics))
    if both:
        fail(f"--cloud and --scan name the same topic: {', '.join(map(repr, both))}")
    if bus is not None and bag is None:
        from tfbus.cli._bus_spec import check_bus_spec

        check_bus_spec(bus)
    from tfbus.view.robot import RobotModel
    from tfbus.view.scans import ScanTrack
    from tfbus.view.server import PortInUseError, TfPage

    robot = RobotModel(())
    if urdf is not None:
        from tfbus.view.robot import load_robot

        try:
            robot = load_robot(urdf, mesh_dirs)
        except ImportError:
            fail("the 'urdf_parser_py' package is not installed: pip install 'tfbus[robot]'")
        except ValueError as err:
            fail(str(err))

    tracks = []
    if bag is not None:  # (a live bus: its scans arrive once it is open)
        for topic in scan_topics:
            try:
                tracks.append(ScanTrack.read(bag, topic))
            except ValueError as err:
                fail(str(err))
    clouds = []
    if bag is not None:
        from tfbus.view.clouds import CloudTrack

        for topic in cloud_topics:
            try:
                clouds.append(CloudTrack.read(bag, topic))
            except ValueError as err:
                fail(str(err))
    from tfbus.view.record import RecordControl, RecordError, record_path_check

    if record_path is not None:
        try:
            record_path_check(record_path)
        except RecordError as err:
            fail(f"--record: {err}")
    try:
        page = TfPage(host, port, title=f"tfbus view: {bag if bag is not None else bus or 'zenoh'}",
                      token=token)
    except PortInUseError as err:
        fail(str(err))
    except OSError as err:
        fail(f"cannot serve on {host}:{port}: {err}")
    page.set_visuals(robot.visuals)
    page.set_notes(robot.notes)
    record: RecordControl | None = None
    if record_path is not None or record_dir is not None:
        try:
            record = RecordControl(
                page, directory=record_dir, path=record_path,
                max_bytes=max(1, round(record_max_mb * 1e6)), max_seconds=record_max_seconds,
                on_end=lambda rec: click.echo(f"tfbus view: {rec.describe()}", err=True))
        except RecordError as err:
            page.close()
            fail(f"--record: {err}")
    stop = threading.Event()

    def on_signal(_sig: int, _frame: FrameType | None) -> None:
        stop.set()

    # before the address is printed: a Ctrl-C any time after it ends with status 0 (a
    # live bus replaces them by run_live's own once attached, and checks ``stop`` then)
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    query = "" if token is None else "?token=" + token
    click.echo(f"tfbus view: http://{host}:{page.port}/{query}", err=True)
    bridge = None
    if foxglove_port is not None:
        from tfbus.view.foxglove_bridge import FoxgloveBridge

        try:
            bridge = FoxgloveBridge(host, foxglove_port, token=token)
        except ImportError:
            page.close()
            fail("the 'foxglove-sdk' package is not installed: pip install 'tfbus[view]'")
        except OSError as err:
            page.close()
            fail(str(err))
        click.echo(f"tfbus view: Foxglove ws://{host}:{bridge.port}", err=True)
    try:
        with young_gc_threshold(YOUNG_GC_THRESHOLD):
            if bag is not None:
                _serve_bag(page, bag, fixed_frame, frame_timeout, paused, rate, tracks, bridge,
                           stop, clouds=clouds, record=record, fleet=fleet)
            else:
                _serve_bus(page, bus or "zenoh", fixed_frame, frame_timeout, scan_topics,
                           bridge, stop, use_sim_time=use_sim_time, record=record,
                           cloud_topics=cloud_topics)
    finally:
        if record is not None:
            record.close()  # the recording in progress ends: its line is printed
        page.close()
        if bridge is not None:
            bridge.close()


def _serve_bag(page: object, bag: Path, fixed_frame: str | None, frame_timeout: float,
               paused: bool, rate: float, tracks: Sequence[ScanTrack],
               bridge: FoxgloveBridge | None, stop: threading.Event, *,
               clouds: Sequence[CloudTrack] = (), record: RecordControl | None = None,
               fleet: bool = False) -> None:
    from tfbus.cli._bag_source import BagSource
    from tfbus.view.fleet import FleetView
    from tfbus.view.player import BagPlayer
    from tfbus.view.server import TfPage
    from tfbus.view.timeline import BagTimeline

    assert isinstance(page, TfPage)
    src = BagSource(bag)
    timeline = BagTimeline.read(bag)
    player = BagPlayer(page, timeline, fixed_frame=fixed_frame, frame_timeout=frame_timeout,
                       paused=paused, rate=rate, summary=src.summary(), scans=tracks,
                       foxglove=bridge, clouds=clouds, record=record,
                       fleet=FleetView(page) if fleet else None)
    player.render()
    player.run(stop)


def page_doctor(src: BusSource, spec: str) -> Doctor:
    """The :class:`~tfbus.doctor.Doctor` whose findings a live view's page shows: fed every
    message ``src``'s monitor sink accounts (one of its observers: receive time,
    transforms, authority as attributed, whether static), as ``tfbus view --bus spec``
    wires it. Call before ``src`` is attached."""
    from tfbus.doctor import Doctor

    doctor = Doctor(source=spec)
    add = doctor.add
    src.sink.observers.append(
        lambda now, transforms, authority, static: add(now, transforms, authority,
                                                       static=static))
    return doctor


def _serve_bus(page: object, spec: str, fixed_frame: str | None, frame_timeout: float,
               scan_topics: Sequence[str], bridge: FoxgloveBridge | None,
               stop: threading.Event, *, use_sim_time: bool = False,
               record: RecordControl | None = None,
               cloud_topics: Sequence[str] = ()) -> None:
    from tfbus.cli._bus_source import BusSource
    from tfbus.cli._live_session import live, run_live
    from tfbus.view.fleet import FleetView
    from tfbus.view.live import LiveView
    from tfbus.view.server import TfPage

    assert isinstance(page, TfPage)
    src = BusSource(spec, name="tfbus-view", scan_topics=scan_topics,
                    use_sim_time=use_sim_time)
    # the doctor's findings in the page, fed by the view's listener
    doctor = None if src.is_fleet else page_doctor(src, spec)
    fleet: FleetView | None = None
    if src.is_fleet:  # a robot selector: the robots the fleet bus announces
        fleet = FleetView(page, lambda: src.fleet.robots() if src.fleet is not None else ())
    view = LiveView(page, src.buffer(), src.summary(), src.clock, fixed_frame=fixed_frame,
                    frame_timeout=frame_timeout, scan_topics=scan_topics, foxglove=bridge,
                    doctor=doctor, record=record, cloud_topics=cloud_topics, fleet=fleet)

    async def body() -> None:
        assert src.bus is not None
        if not stop.is_set():  # a signal before run_live's handlers: stop now
            await view.run(src.bus)

    code = run_live(lambda: live(src, None, body))
    if code:
        raise SystemExit(code)
