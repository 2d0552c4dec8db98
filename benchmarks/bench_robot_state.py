"""Benchmark tfbus's robot_state_publisher on the largest URDF in the data (PR2).

    .venv/bin/python benchmarks/bench_robot_state.py [--quick] [--no-ros]

Prints, on this machine:

* ``RobotStatePublisher.transforms``: joint transforms computed per second (JointState ->
  list of TransformStamped) for messages naming every movable joint (40 on PR2, mimic
  joints included) and for messages naming 5 of them; best of 5 repeats;
* ``RobotStatePublisher.static_transforms``: fixed joints per second;
* ``run()`` on an in-process bus: JointState messages in, TFMessages out on /tf, per
  second (subscription, rate-limit bookkeeping and publishing included);
* the real ROS 1 node's cost in the same run (``peers/ros1/rsp_side.py`` under
  ``/usr/bin/python3``): the node's CPU time (user + system) per joint transform it
  published, serialisation and TCP included, from identical joint states sent at a steady
  rate; and tfbus's CPU per transform for the same work, with the ratio.

* ``load_urdf`` on generated chains of 10^4 and 5x10^4 revolute joints: seconds and
  links/s (1.4 s and 18.7 s when loading was quadratic in the number of elements).

Target: at least 100 000 joint transforms/s. Figures only: nothing here
asserts a timing.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import anyio

from tfbus.bus import Bus
from tfbus.messages import Header, JointState
from tfbus.robot import RobotStatePublisher
from tfbus.time import Time

ROOT = Path(__file__).resolve().parents[1]
PR2 = ROOT / "tests" / "data" / "urdf" / "rsp_pr2.urdf"
ROS_PYTHON = "/usr/bin/python3"
ROS_SIDE = ROOT / "peers" / "ros1" / "rsp_side.py"
TARGET = 100_000


def states(rsp: RobotStatePublisher, n: int, width: int | None, seed: int = 15) -> list[JointState]:
    rng = random.Random(seed)
    movable = [j.name for j in rsp.model.joints if j.movable]
    out = []
    for k in range(n):
        names = movable if width is None else rng.sample(movable, width)
        out.append(JointState(Header(Time(1_700_000_000 + k), ""), list(names),
                              [rng.uniform(-math.pi, math.pi) for _ in names]))
    return out


def best_rate(work: Callable[[], int], repeats: int = 5) -> float:
    """Items per second of the fastest of ``repeats`` runs of ``work`` (returns items)."""
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        items = work()
        best = max(best, items / (time.perf_counter() - t0))
    return best


def bench_transforms(rsp: RobotStatePublisher, msgs: list[JointState]) -> float:
    def work() -> int:
        return sum(len(rsp.transforms(m)) for m in msgs)
    return best_rate(work)


def bench_run(rsp: RobotStatePublisher, msgs: list[JointState]) -> float:
    """JointState messages per second through run() on an in-process bus."""
    async def main() -> float:
        async with Bus(queue_size=len(msgs) + 1) as bus, anyio.create_task_group() as tg:
            tf = bus.subscribe("/tf", queue_size=len(msgs) + 1)
            await tg.start(lambda task_status: rsp.run(bus, task_status=task_status))
            t0 = time.perf_counter()
            for m in msgs:
                bus.publish_nowait("/joint_states", m)
            for _ in msgs:
                await tf.receive()
            elapsed = time.perf_counter() - t0
            tg.cancel_scope.cancel()
        return len(msgs) / elapsed

    return max(anyio.run(main) for _ in range(3))


def ros_side(msgs: list[JointState], rate: float) -> dict[str, Any] | str:
    if not Path(ROS_PYTHON).exists() or not Path(
            "/usr/lib/robot_state_publisher/robot_state_publisher").exists():
        return "ROS 1 robot_state_publisher not installed (scripts/install/install_ros1_rsp.sh)"
    scenario = {"urdf": str(PR2), "rate": rate,
                "states": [[m.header.stamp.ns, list(m.name), list(m.position)] for m in msgs]}
    try:
        done = subprocess.run([ROS_PYTHON, str(ROS_SIDE)], input=json.dumps(scenario),
                              capture_output=True, text=True, timeout=300)
    except subprocess.TimeoutExpired:
        return "the ROS side timed out"
    if done.returncode != 0:
        return f"the ROS side failed: {done.stderr.strip().splitlines()[-1:]}"
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def chain_urdf(n: int) -> str:
    """A URDF chain of ``n`` links joined by revolute joints (generated, no file)."""
    parts = ['<robot name="chain"><link name="l0"/>']
    for i in range(1, n):
        parts.append(f'<link name="l{i}"/><joint name="j{i}" type="revolute">'
                     f'<parent link="l{i - 1}"/><child link="l{i}"/>'
                     f'<origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>'
                     f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    return "".join(parts) + "</robot>"


def bench_load(sizes: Sequence[int]) -> None:
    """Print load_urdf's time on a generated chain of each size (one run each)."""
    from tfbus.robot import load_urdf

    for n in sizes:
        text = chain_urdf(n)
        t0 = time.perf_counter()
        load_urdf(text)
        seconds = time.perf_counter() - t0
        print(f"load_urdf, chain of {n:>6,} links:      {seconds:8.2f} s "
              f"({n / seconds:,.0f} links/s)", flush=True)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer messages")
    parser.add_argument("--no-ros", action="store_true", help="skip the real node")
    args = parser.parse_args(argv)
    bench_load([10_000] if args.quick else [10_000, 50_000])
    n = 300 if args.quick else 2000
    rsp = RobotStatePublisher(PR2)
    full, few = states(rsp, n, None), states(rsp, n, 5)
    print(f"tfbus robot_state_publisher on PR2 ({len(rsp.model.joints)} joints) — "
          f"Python {sys.version.split()[0]}", flush=True)
    rate_full = bench_transforms(rsp, full)
    print(f"transforms(), all {len(full[0].name)} movable joints: {rate_full:12,.0f} joint "
          f"transforms/s   (target >= {TARGET:,}: {'met' if rate_full >= TARGET else 'MISSED'})")
    print(f"transforms(), 5 joints per message:   {bench_transforms(rsp, few):12,.0f} joint "
          f"transforms/s")
    stamp = Time(1)
    static = best_rate(lambda: sum(len(rsp.static_transforms(stamp)) for _ in range(n)))
    print(f"static_transforms():                   {static:12,.0f} fixed transforms/s")
    msg_rate = bench_run(rsp, full)
    print(f"run() on an in-process bus:            {msg_rate:12,.0f} JointState msgs/s "
          f"({msg_rate * len(full[0].name):,.0f} joint transforms/s)")
    if args.no_ros:
        return
    sent = full[: min(n, 1000)]
    ros = ros_side(sent, rate=200.0)
    if isinstance(ros, str):
        print(f"\n(no comparison with the real node: {ros})")
        return
    per_ros = ros["cpu_s"] / max(ros["transforms"], 1) * 1e6
    per_ours = 1e6 / rate_full
    print(f"\nreal node (ROS 1 robot_state_publisher, C++/KDL), {ros['sent']} states at 200 Hz: "
          f"published {ros['transforms']:,} transforms in {ros['messages']} messages, "
          f"{ros['cpu_s']:.2f} s CPU")
    print(f"CPU per joint transform: real node {per_ros:.2f} µs (incl. serialisation + TCP), "
          f"tfbus transforms() {per_ours:.2f} µs  -> tfbus/node {per_ours / per_ros:.2f}")


if __name__ == "__main__":
    main()
