"""The laser_geometry differential test's plumbing, shared by ``tests/sensors/test_laser.py`` and
``scripts/data/regen_laser_ref.py``.

* The cases: every LaserScan of the real recordings in ``tests/data/laser/`` (with all
  their ``/tf``), and hand-made edge cases (NaN / inf ranges, empty scans, negative
  increments, cutoffs, channel options, a single beam, the fixed-frame overload).
* The reference: ``peers/debian/laser_geometry_ref.cpp`` (ROS 1 laser_geometry +
  tf2::BufferCore, compiled with g++ and pkg-config) reading the cases as text and printing
  each cloud's bytes.
* The record: per case the cloud's layout and a SHA-256 of its bytes (or tf2's error),
  gzip-compressed JSON lines in ``expected.jsonl.gz``. The float32 clouds must be equal
  to the byte for the test to pass, which is stricter than the 1e-9 m asked for.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import math
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tfbus import (
    BufferCore,
    Header,
    Quaternion,
    Time,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.laser import ChannelOption, LaserProjection
from tfbus.sensor_msgs import LaserScan, PointCloud2

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
DATA = ROOT / "tests" / "data" / "laser"
EXPECTED = HERE / "expected.jsonl.gz"
SCAN_TOPICS = (
    "/scan",
    "/hokuyo_back_scan",
    "/driver_laser_navigation/laser_scan",
    "/driver_laser_security/laser_scan",
)
TARGETS = {  # the frame each robot's scans are projected into
    "drl_guardian_3.bag": "odom",
    "drl_jarvis_complex_path_fast.bag": "odom",
}
ALL = int(
    ChannelOption.INTENSITY | ChannelOption.INDEX | ChannelOption.DISTANCE
    | ChannelOption.TIMESTAMP | ChannelOption.VIEWPOINT
)  # fmt: skip


@dataclass
class Case:
    """One projection to compare: mode P (projectLaser), T (transform) or F (the
    fixed-frame transform)."""

    id: str
    scan_id: str
    mode: str
    target: str
    fixed: str
    cutoff: float
    options: int


@dataclass
class Suite:
    name: str
    transforms: list[tuple[bool, TransformStamped]]
    scans: dict[str, LaserScan]
    cases: list[Case]


# --------------------------------------------------------------------------- cases


def _scan_from_ros(msg: Any) -> LaserScan:
    h = msg.header
    return LaserScan(
        header=Header(Time(h.stamp.sec, h.stamp.nanosec), h.frame_id),
        angle_min=msg.angle_min, angle_max=msg.angle_max,
        angle_increment=msg.angle_increment, time_increment=msg.time_increment,
        scan_time=msg.scan_time, range_min=msg.range_min, range_max=msg.range_max,
        ranges=np.asarray(msg.ranges, dtype=np.float32),
        intensities=np.asarray(msg.intensities, dtype=np.float32),
    )  # fmt: skip


def bag_suite(path: Path) -> Suite:
    """Every /tf transform and every scan of one recording; each scan is projected
    (mode P, default channels) and transformed into the robot's odom frame (mode T,
    default channels; every 10th scan also with all channels and a cutoff)."""
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    from tfbus.bag import read_messages

    transforms = [
        (rec.is_static, ts) for rec in read_messages(path) for ts in rec.message.transforms
    ]
    typestore = get_typestore(Stores.ROS1_NOETIC)
    scans: dict[str, LaserScan] = {}
    cases: list[Case] = []
    target = TARGETS[path.name]
    with Reader(path) as reader:
        conns = [c for c in reader.connections if c.topic in SCAN_TOPICS]
        for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
            msg = typestore.deserialize_ros1(raw, conn.msgtype)
            sid = f"{path.stem}:{conn.topic}:{k}"
            scans[sid] = _scan_from_ros(msg)
            cases.append(Case(f"{sid}:P", sid, "P", "-", "-", -1.0, int(ChannelOption.DEFAULT)))
            cases.append(Case(f"{sid}:T", sid, "T", target, "-", -1.0, int(ChannelOption.DEFAULT)))
            if k % 10 == 0:
                cases.append(Case(f"{sid}:TA", sid, "T", target, "-", 3.0, ALL))
    return Suite(path.stem, transforms, scans, cases)


def _tf(parent: str, child: str, ns: int, v: tuple[float, ...]) -> TransformStamped:
    return TransformStamped(
        Header(Time.from_ns(ns), parent), child,
        Transform(Vector3(*v[:3]), Quaternion(*v[3:])),
    )  # fmt: skip


def edge_suite() -> Suite:
    """Hand-made scans: NaN, ±inf, ranges at the limits, empty, one beam, negative
    angle and time increments, zero time_increment, cutoffs, every channel option, a
    scan beyond the tf data (tf2's extrapolation error), the fixed-frame overload."""
    transforms: list[tuple[bool, TransformStamped]] = []
    base = 1_000_000_000_000
    for j in range(201):  # odom -> base_link: a turn at 0.5 rad/s and 1 m/s, 100 Hz
        t = j * 0.01
        yaw = 0.5 * t
        transforms.append(
            (
                False,
                _tf(
                    "odom",
                    "base_link",
                    base + j * 10_000_000,
                    (
                        math.cos(yaw) * t,
                        math.sin(yaw) * t,
                        0.0,
                        0.0,
                        0.0,
                        math.sin(yaw / 2),
                        math.cos(yaw / 2),
                    ),
                ),
            )
        )
    transforms.append(
        (
            True,
            _tf(
                "base_link", "laser", 0, (0.2, 0.0, 0.15, 0.0, 0.0, math.sin(0.05), math.cos(0.05))
            ),
        )
    )
    transforms.append(
        (True, _tf("base_link", "upside_down", 0, (0.0, 0.1, 0.3, 1.0, 0.0, 0.0, 0.0)))
    )
    rng = np.random.default_rng(12)
    scans: dict[str, LaserScan] = {}
    cases: list[Case] = []

    def scan(sid: str, frame: str = "laser", stamp: int = base + 300_000_000, **kw: Any) -> None:
        n = kw.pop("n", 360)
        args: dict[str, Any] = dict(
            angle_min=-math.pi / 2,
            angle_max=math.pi / 2,
            angle_increment=math.pi / (n - 1) if n > 1 else 0.0,
            time_increment=1e-4,
            scan_time=0.1,
            range_min=0.05,
            range_max=20.0,
            ranges=rng.uniform(0.0, 25.0, n).astype(np.float32),
            intensities=rng.uniform(0, 1000, n).astype(np.float32),
        )
        args.update(kw)
        scans[sid] = LaserScan(header=Header(Time.from_ns(stamp), frame), **args)

    specials = np.array(
        [np.nan, np.inf, -np.inf, 0.05, 0.0499999, 20.0, 19.99999, -1.0, 0.0], dtype=np.float32
    )
    r = rng.uniform(0.0, 25.0, 360).astype(np.float32)
    r[::7] = np.resize(specials, r[::7].shape)
    scan("specials", ranges=r)
    scan("empty", n=0, ranges=np.zeros(0, np.float32), intensities=np.zeros(0, np.float32))
    scan(
        "one_beam", n=1, ranges=np.array([3.0], np.float32), intensities=np.array([7.0], np.float32)
    )
    scan(
        "negative_increment",
        angle_min=math.pi / 2,
        angle_max=-math.pi / 2,
        angle_increment=-math.pi / 359,
    )
    scan("negative_time_increment", time_increment=-1e-4)
    scan("zero_time_increment", time_increment=0.0)
    scan("no_intensities", intensities=np.zeros(0, np.float32))
    scan("longer_intensities", intensities=rng.uniform(0, 5, 400).astype(np.float32))
    scan("min_inf", range_min=-math.inf, ranges=np.resize(specials, 360))
    scan("upside_down", frame="upside_down")
    scan(
        "big",
        n=1440,
        angle_min=0.0,
        angle_max=6.279,
        angle_increment=6.279 / 1439,
        time_increment=8.6866e-05,
    )
    scan("future", stamp=base + 1_990_000_000)  # its last beam is after the tf data
    scan("past", stamp=base - 1)
    scan("unknown_frame", frame="nowhere")
    for sid in scans:
        cases.append(Case(f"{sid}:P", sid, "P", "-", "-", -1.0, int(ChannelOption.DEFAULT)))
        cases.append(Case(f"{sid}:PA", sid, "P", "-", "-", -1.0, ALL))
        cases.append(Case(f"{sid}:T", sid, "T", "odom", "-", -1.0, int(ChannelOption.DEFAULT)))
        cases.append(Case(f"{sid}:TA", sid, "T", "odom", "-", -1.0, ALL))
        cases.append(Case(f"{sid}:TN", sid, "T", "base_link", "-", -1.0, 0))
        cases.append(Case(f"{sid}:TC", sid, "T", "odom", "-", 7.5, int(ChannelOption.DEFAULT)))
        cases.append(Case(f"{sid}:PC", sid, "P", "-", "-", 30.0, ALL))
        cases.append(Case(f"{sid}:F", sid, "F", "base_link", "odom", -1.0, ALL))
    return Suite("edge", transforms, scans, cases)


def suites() -> Iterator[Suite]:
    yield edge_suite()
    for path in sorted(DATA.glob("*.bag")):
        yield bag_suite(path)


# --------------------------------------------------------------------------- both sides


def _hx(v: float) -> str:
    return float(v).hex()


def harness_input(suite: Suite) -> str:
    lines = []
    for is_static, ts in suite.transforms:
        (x, y, z), (qx, qy, qz, qw) = ts.transform
        ns = ts.header.stamp.ns
        lines.append(
            f"TF {int(is_static)} {ns // 1_000_000_000} {ns % 1_000_000_000} "
            f"{ts.header.frame_id} {ts.child_frame_id} "
            + " ".join(_hx(v) for v in (x, y, z, qx, qy, qz, qw))
        )
    for sid, s in suite.scans.items():
        ns = s.header.stamp.ns
        lines.append(
            f"SCAN {sid} {s.header.frame_id} {ns // 1_000_000_000} {ns % 1_000_000_000} "
            + " ".join(
                _hx(v)
                for v in (
                    s.angle_min,
                    s.angle_max,
                    s.angle_increment,
                    s.time_increment,
                    s.scan_time,
                    s.range_min,
                    s.range_max,
                )
            )
            + f" {len(s.ranges)} "
            + " ".join(_hx(v) for v in s.ranges.tolist())
            + f" {len(s.intensities)} "
            + " ".join(_hx(v) for v in s.intensities.tolist())
        )
    for c in suite.cases:
        lines.append(
            f"DO {c.id} {c.scan_id} {c.mode} {c.target} {c.fixed} {_hx(c.cutoff)} {c.options}"
        )
    return "\n".join(lines) + "\n"


def build_harness(out: Path) -> str | None:
    """Compile ``peers/debian/laser_geometry_ref.cpp`` into ``out``; returns None, or why it
    cannot be built."""
    if shutil.which("g++") is None or shutil.which("pkg-config") is None:
        return "g++ or pkg-config is missing"
    flags = subprocess.run(
        ["pkg-config", "--cflags", "--libs", "laser_geometry"],
        capture_output=True,
        text=True,
        check=False,
    )
    if flags.returncode != 0:
        return "pkg-config does not know laser_geometry (liblaser-geometry-dev missing)"
    res = subprocess.run(
        ["g++", "-O2", "-o", str(out), str(ROOT / "peers" / "debian" / "laser_geometry_ref.cpp"),
         *flags.stdout.split()],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    if res.returncode != 0:
        return f"g++ failed: {res.stderr[-2000:]}"
    return None


def run_harness(binary: Path, suite: Suite) -> dict[str, dict[str, Any]]:
    """Feed one suite to the compiled harness; returns its results as records."""
    res = subprocess.run(
        [str(binary)],
        input=harness_input(suite),
        capture_output=True,
        text=True,
        check=True,
        timeout=1200,
    )
    out: dict[str, dict[str, Any]] = {}
    for line in res.stdout.splitlines():
        kind, cid, rest = line.split(" ", 2)
        if kind == "ERR":
            etype, _, msg = rest.partition(" ")
            out[cid] = {"id": cid, "error": etype, "message": _unescape(msg)}
        else:
            width, step, fields, data = rest.split(" ")
            raw = bytes.fromhex(data) if data != "-" else b""
            out[cid] = {
                "id": cid, "width": int(width), "point_step": int(step),
                "fields": "" if fields == "-" else fields,
                "sha256": hashlib.sha256(raw).hexdigest(), "data": raw,
            }  # fmt: skip
    return out


def _unescape(s: str) -> str:
    out, i = [], 0
    while i < len(s):
        if s[i] == "\\" and i + 1 < len(s):
            out.append("\n" if s[i + 1] == "n" else s[i + 1])
            i += 2
        else:
            out.append(s[i])
            i += 1
    return "".join(out)


def cloud_record(cid: str, cloud: PointCloud2) -> dict[str, Any]:
    fields = ",".join(f"{f.name}:{f.offset}:{f.datatype}" for f in cloud.fields)
    return {
        "id": cid, "width": cloud.width, "point_step": cloud.point_step, "fields": fields,
        "sha256": hashlib.sha256(cloud.data).hexdigest(), "data": cloud.data,
    }  # fmt: skip


def run_tfbus(suite: Suite) -> dict[str, dict[str, Any]]:
    """The same cases through tfbus (one LaserProjection for all, as the harness)."""
    core = BufferCore(cache_time=100000.0)
    for is_static, ts in suite.transforms:
        if is_static:
            core.set_transform_static(ts, "harness")
        else:
            core.set_transform(ts, "harness")
    projector = LaserProjection()
    out: dict[str, dict[str, Any]] = {}
    for c in suite.cases:
        scan = suite.scans[c.scan_id]
        try:
            if c.mode == "P":
                cloud = projector.project_laser(scan, c.cutoff, c.options)
            else:
                cloud = projector.transform_laser_scan_to_point_cloud(
                    c.target, scan, core, c.cutoff, c.options,
                    fixed_frame=c.fixed if c.mode == "F" else None,
                )  # fmt: skip
        except TransformException as exc:
            out[c.id] = {"id": c.id, "error": type(exc).__name__, "message": str(exc)}
            continue
        out[c.id] = cloud_record(c.id, cloud)
    return out


def strip(record: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in record.items() if k != "data"}


def load_expected() -> dict[str, dict[str, Any]]:
    with gzip.open(EXPECTED, "rt") as f:
        return {r["id"]: r for r in map(json.loads, f)}


def save_expected(records: list[dict[str, Any]]) -> None:
    with gzip.open(EXPECTED, "wt", compresslevel=9) as f:
        for r in records:
            f.write(json.dumps(strip(r), sort_keys=True) + "\n")
