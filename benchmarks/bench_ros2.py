"""ROS 2 transport benchmark: rclpy -> rclpy, rclpy -> tfbus, tfbus -> tfbus (prints figures).

Every sender and receiver is its own process on 127.0.0.1, on a fresh random
ROS_DOMAIN_ID; the rclpy ones (peers/ros2/ros2_side.py) run in the ROS 2 venv built by
scripts/install/install_ros2_env.sh (rclpy + rmw_fastrtps_cpp, Fast DDS loopback profile), the
tfbus ones (this file, ``--role``) use Ros2Transport with its loopback default.

1. One-way latency: the sender publishes ``--lat-count`` TFMessages of ``--batch``
   transforms at ``--lat-rate`` Hz, each stamped with its ``time.time_ns()`` at publish;
   a receiver takes ``time.time_ns()`` when the message reaches its callback (rclpy) or
   its bus subscription (tfbus, decoded into TransformStamped tuples). Median and p99.
2. Throughput: the sender publishes as fast as it can for ``--flood-seconds``; a
   receiver counts the transforms it gets per second (first to last).

An rclpy sender feeds an rclpy and a tfbus receiver *at the same time* (the same
stream), so the ratios compare the two on identical traffic:
``rclpy->tfbus / rclpy->rclpy`` latency (target <= 1.0) and tfbus / rclpy transforms/s
(target >= 1.0). Numbers are noisy on a loaded 2-core machine; they assert nothing.

Usage: ``python benchmarks/bench_ros2.py [--batches 1 100] [--lat-count 300]
[--lat-rate 100] [--flood-seconds 3]``.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import random
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import anyio.lowlevel

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tfbus.bus import Bus  # noqa: E402
from tfbus.messages import Header, Quaternion, TFMessage, Transform, TransformStamped, Vector3  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.ros2 import Ros2Transport  # noqa: E402

ROS_PYTHON = ROOT / ".venv-ros2" / "bin" / "python"
ROS_SIDE = ROOT / "peers" / "ros2" / "ros2_side.py"
FASTDDS_LO = ROOT / "peers" / "ros2" / "fastdds_lo.xml"
WAIT = 60.0


# -- the tfbus roles (child processes) ------------------------------------------------------------


def _message(phase: str, batch: int) -> TFMessage:
    stamp = Time.from_ns(time.time_ns())
    return TFMessage(
        tuple(
            TransformStamped(
                Header(stamp, phase), f"link_{i}", Transform(Vector3(float(i)), Quaternion())
            )
            for i in range(batch)
        )
    )


async def tfbus_send(args: argparse.Namespace) -> None:
    transport = Ros2Transport(domain_id=args.domain)
    async with Bus(transport=transport) as bus, anyio.create_task_group() as tg:
        go = anyio.Event()

        async def wait_go() -> None:
            await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True)
            go.set()

        tg.start_soon(wait_go)
        print("READY", flush=True)
        while not go.is_set():
            bus.publish_nowait("/tf", _message("warm", 1))
            with anyio.move_on_after(0.05):
                await go.wait()
        period = 1.0 / args.lat_rate
        nxt = time.monotonic()
        for _ in range(args.lat_count):
            nxt += period
            bus.publish_nowait("/tf", _message("lat", args.batch))
            await anyio.sleep(max(0.0, nxt - time.monotonic()))
        sent, end = 0, time.monotonic() + args.flood_seconds
        while time.monotonic() < end:
            bus.publish_nowait("/tf", _message("tput", args.batch))
            sent += 1
            if sent % 8 == 0:
                await anyio.lowlevel.checkpoint()
        stats = transport.statistics()
        print(f"SENT {args.lat_count} {sent} dropped={stats.send_dropped}", flush=True)
        while True:
            bus.publish_nowait("/tf", _message("done", 1))
            await anyio.sleep(0.05)


async def tfbus_recv(args: argparse.Namespace) -> None:
    lat: list[int] = []
    tput, first, last, warm = 0, 0, 0, False
    transport = Ros2Transport(domain_id=args.domain)
    async with Bus(transport=transport, queue_size=100_000) as bus:
        sub = bus.subscribe("/tf")
        print("READY", flush=True)
        async for msg in sub:
            now = time.time_ns()
            if not msg.transforms:
                continue
            head = msg.transforms[0].header
            phase = head.frame_id
            if phase == "lat":
                lat.append(now - head.stamp.ns)
            elif phase == "tput":
                tput += len(msg.transforms)
                first = first or now
                last = now
            elif phase == "warm" and not warm:
                warm = True
                print("WARM", flush=True)
            elif phase == "done":
                break
    seconds = (last - first) / 1e9 if first else 0.0
    result = {"lat_ns": lat, "tput_transforms": tput, "tput_seconds": seconds,
              "malformed": transport.statistics().malformed}  # fmt: skip
    print(json.dumps(result), flush=True)


# -- orchestration ------------------------------------------------------------------------------


class Proc:
    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        self.p = subprocess.Popen(
            argv, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        self.lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.lines.put(line.strip())
        self.lines.put(None)

    def wait(self, pred: Callable[[str], bool], timeout: float = WAIT) -> str:
        end = time.monotonic() + timeout
        while (remaining := end - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=remaining)
            except queue.Empty:
                break
            if line is None:
                raise RuntimeError(f"process exited ({self.p.wait()}) while waiting")
            if pred(line):
                return line
        raise TimeoutError("no expected output in time")

    def stop(self) -> None:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            self.p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()


def _env(domain: int) -> dict[str, str]:
    if not FASTDDS_LO.is_file():  # Fast DDS would fall back to every interface
        sys.exit(f"error: {FASTDDS_LO.relative_to(ROOT)} is missing from the repository")
    env = dict(
        os.environ, ROS_DOMAIN_ID=str(domain), RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", FASTDDS_DEFAULT_PROFILES_FILE=str(FASTDDS_LO),
    )  # fmt: skip
    env.pop("CYCLONEDDS_URI", None)
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def _argv(kind: str, role: str, domain: int, args: argparse.Namespace, batch: int) -> list[str]:
    if kind == "rclpy":
        if role == "send":
            return [str(ROS_PYTHON), str(ROS_SIDE), "send", str(batch), str(args.lat_count),
                    str(args.lat_rate), str(args.flood_seconds)]  # fmt: skip
        return [str(ROS_PYTHON), str(ROS_SIDE), "recv"]
    return [sys.executable, __file__, "--role", role, "--domain", str(domain), "--batch",
            str(batch), "--lat-count", str(args.lat_count), "--lat-rate", str(args.lat_rate),
            "--flood-seconds", str(args.flood_seconds)]  # fmt: skip


def run_case(sender: str, receivers: list[str], batch: int, args: argparse.Namespace
             ) -> dict[str, dict[str, Any]]:  # fmt: skip
    domain = random.SystemRandom().randint(1, 100)
    env = _env(domain)
    procs: list[Proc] = []
    try:
        recv = {k: Proc(_argv(k, "recv", domain, args, batch), env) for k in receivers}
        procs += recv.values()
        for p in recv.values():
            p.wait(lambda s: s == "READY")
        send = Proc(_argv(sender, "send", domain, args, batch), env)
        procs.append(send)
        send.wait(lambda s: s == "READY")
        for p in recv.values():
            p.wait(lambda s: s == "WARM")
        assert send.p.stdin is not None
        send.p.stdin.write("go\n")
        send.p.stdin.flush()
        sent = send.wait(lambda s: s.startswith("SENT"), timeout=WAIT + args.flood_seconds)
        results = {k: json.loads(p.wait(lambda s: s.startswith("{"))) for k, p in recv.items()}
        for r in results.values():
            r["sent"] = sent
        return results
    finally:
        for p in reversed(procs):
            p.stop()


def _summary(r: dict[str, Any]) -> tuple[float, float, float]:
    lat = sorted(r["lat_ns"])
    med = statistics.median(lat) / 1e6 if lat else float("nan")
    p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))] / 1e6 if lat else float("nan")
    tput = r["tput_transforms"] / r["tput_seconds"] if r["tput_seconds"] else float("nan")
    return med, p99, tput


def codec_figures(batch: int = 100, rounds: int = 200) -> None:
    """Per-transform encode/decode time: this codec vs cyclonedds-python's serializer."""
    from tfbus.codecs.cdr import decode_tf, encode_tf
    from tfbus.transports.ros2.dds import TFMessage_

    msg = _message("codec", batch)
    data = encode_tf(msg.transforms)
    ref = TFMessage_.deserialize(data)

    def per_transform_us(fn: Callable[[], object]) -> float:
        t0 = time.perf_counter()
        for _ in range(rounds):
            fn()
        return (time.perf_counter() - t0) / rounds / batch * 1e6

    print(f"codec, us per transform (batch {batch}): "
          f"tfbus encode {per_transform_us(lambda: encode_tf(msg.transforms)):.2f}, "
          f"decode {per_transform_us(lambda: decode_tf(data)):.2f}; "
          f"cyclonedds serialize {per_transform_us(ref.serialize):.2f}, "
          f"deserialize {per_transform_us(lambda: TFMessage_.deserialize(data)):.2f}")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--role", choices=["send", "recv"])
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--batch", type=int, default=1)
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 100])
    ap.add_argument("--lat-count", type=int, default=300)
    ap.add_argument("--lat-rate", type=float, default=100.0)
    ap.add_argument("--flood-seconds", type=float, default=3.0)
    args = ap.parse_args()
    if args.role == "send":
        anyio.run(tfbus_send, args)
        return 0
    if args.role == "recv":
        anyio.run(tfbus_recv, args)
        return 0
    if not ROS_PYTHON.exists():
        print("the ROS 2 venv is missing: run scripts/install/install_ros2_env.sh", file=sys.stderr)
        return 2
    codec_figures()
    print(f"{'path':<16}{'batch':>6}{'lat median ms':>15}{'lat p99 ms':>12}"
          f"{'transforms/s':>14}{'lat n':>7}")  # fmt: skip
    for batch in args.batches:
        same_stream = run_case("rclpy", ["rclpy", "tfbus"], batch, args)
        tfbus_only = run_case("tfbus", ["tfbus"], batch, args)
        rows = [("rclpy->rclpy", same_stream["rclpy"]), ("rclpy->tfbus", same_stream["tfbus"]),
                ("tfbus->tfbus", tfbus_only["tfbus"])]  # fmt: skip
        figures = {}
        for name, r in rows:
            med, p99, tput = _summary(r)
            figures[name] = (med, p99, tput)
            print(f"{name:<16}{batch:>6}{med:>15.3f}{p99:>12.3f}{tput:>14,.0f}{len(r['lat_ns']):>7}"
                  f"   ({r['sent']})")  # fmt: skip
        rr, rt = figures["rclpy->rclpy"], figures["rclpy->tfbus"]
        print(f"{'':<16}{batch:>6}  ratios rclpy->tfbus / rclpy->rclpy: latency median "
              f"{rt[0] / rr[0]:.2f} (target <= 1.0), p99 {rt[1] / rr[1]:.2f}; "
              f"transforms/s {rt[2] / rr[2]:.2f} (target >= 1.0)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
