"""Fleet benchmark: figures, no assertions.

1. Scale through one router: ``--robots`` robot processes (each a Zenoh client in its
   own namespace ``robotK``) publish ``--frames`` transforms per message at ``--rate`` Hz
   for ``--seconds`` through ``tfbus router`` (a separate process) to one fleet listener
   (this process: ``namespace=*`` bus + :class:`~tfbus.fleet.FleetBuffer`). Reported:
   messages received/sent, latency (receive ``time.time_ns()`` - header stamp, both
   CLOCK_REALTIME of this machine) median / p99 / max, CPU of the router and of the
   listener over the window (% of one core), RSS of each robot process, and the
   listener's memory per robot in the fleet buffer (RSS growth / robots).
2. ``--sim-robots`` simulated robots in one process (in-process bus, ``add_robot``), each
   with ``--frames`` frames and ``--history`` seconds at ``--rate`` Hz: memory per robot
   (RSS growth / robots) and ``FleetBuffer[robot].lookup_transform`` time.
3. Remote lookups on loopback (router + BufferServer + BufferClient in this process):
   round trip median / p99 vs a local ``lookup_transform``, and queries/s with
   ``--concurrency`` lookups in flight.

Usage: ``python benchmarks/bench_fleet.py [--robots 20 --frames 30 --rate 50 --seconds 10]
[--sim-robots 100] [--queries 2000]``; ``--quick`` for a short run.
Targets: 0 lost, p99 <= 20 ms for 20 x 30 x 50 Hz.
"""

from __future__ import annotations

import argparse
import os
import resource
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import anyio

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tfbus.buffer import Buffer  # noqa: E402
from tfbus.bus import Bus  # noqa: E402
from tfbus.fleet import FleetBuffer  # noqa: E402
from tfbus.messages import (  # noqa: E402
    Header,
    Quaternion,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
)
from tfbus.remote import BufferClient, BufferServer  # noqa: E402
from tfbus.time import Time  # noqa: E402
from tfbus.transports.zenoh import ZenohTransport  # noqa: E402
from tfbus.transports.zenoh.router import ZenohRouter  # noqa: E402

PAGE = os.sysconf("SC_PAGE_SIZE")
TICKS = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rss(pid: int | str = "self") -> int:
    """Resident set size of a process, bytes (/proc/PID/statm)."""
    with open(f"/proc/{pid}/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * PAGE


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far, seconds (/proc/PID/stat)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def frames_message(robot: str, frames: int, stamp_ns: int, k: int) -> TFMessage:
    stamp = Time.from_ns(stamp_ns)
    return TFMessage(tuple(
        TransformStamped(Header(stamp, "base" if i == 0 else f"f{i - 1}"), f"f{i}",
                         Transform(Vector3(0.01 * k, 0.1, 0.0), Quaternion()))
        for i in range(frames)
    ))


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# -- 1. robot processes ----------------------------------------------------------------


async def robot_main(endpoint: str, robot: str, frames: int, rate: float,
                     seconds: float) -> None:
    transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace=robot,
                               name="bench-robot")
    async with Bus(transport=transport) as bus:
        with anyio.fail_after(60):
            await transport.wait_matching("/tf")
        print("ready", flush=True)
        start_at = float(await anyio.to_thread.run_sync(sys.stdin.readline))
        await anyio.sleep(max(0.0, start_at - time.time()))
        period = 1.0 / rate
        count = int(seconds * rate)
        t0 = anyio.current_time()
        for k in range(count):
            await anyio.sleep(max(0.0, t0 + k * period - anyio.current_time()))
            bus.publish_nowait("/tf", frames_message(robot, frames, time.time_ns(), k))
        await anyio.sleep(1.0)  # let the last messages leave before the session closes
        sent = transport.statistics().sent
        print(f"sent {sent} rss {rss()}", flush=True)


async def scale(args: argparse.Namespace) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    router = subprocess.Popen([sys.executable, "-m", "tfbus.cli", "router", "--listen", endpoint],
                              stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    robots: list[subprocess.Popen[str]] = []
    try:
        assert router.stderr is not None
        line = router.stderr.readline()
        if "listening" not in line:
            raise RuntimeError(f"router did not start: {line!r}")
        transport = ZenohTransport(connect=endpoint, config={"mode": "client"}, namespace="*",
                                   name="bench-fleet", max_pending=200_000)
        latencies: list[float] = []
        async with Bus(transport=transport, queue_size=10) as bus, \
                FleetBuffer(bus, cache_time=10.0) as fleet:
            base_rss = rss()

            def on_tf(message: object) -> None:
                if isinstance(message, TFMessage) and message.transforms:
                    latencies.append((time.time_ns() - message.transforms[0].header.stamp.ns)
                                     / 1e6)

            names = [f"robot{k}" for k in range(args.robots)]
            for name in names:
                bus.subscribe_callback(f"/{name}/tf", on_tf)
            for name in names:
                robots.append(subprocess.Popen(
                    [sys.executable, __file__, "--as-robot", name, "--endpoint", endpoint,
                     "--frames", str(args.frames), "--rate", str(args.rate),
                     "--seconds", str(args.seconds)],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT))
            for p in robots:
                assert p.stdout is not None
                ready = await anyio.to_thread.run_sync(p.stdout.readline)
                if ready.strip() != "ready":
                    raise RuntimeError(f"a robot did not start: {ready!r}")
            with anyio.fail_after(60):
                while len(fleet) < args.robots:
                    await anyio.sleep(0.05)
            start_at = time.time() + 1.0
            for p in robots:
                assert p.stdin is not None
                p.stdin.write(f"{start_at}\n")
                p.stdin.flush()
            await anyio.sleep(max(0.0, start_at - time.time()))
            r0, u0 = cpu_seconds(router.pid), resource.getrusage(resource.RUSAGE_SELF)
            w0 = time.monotonic()
            sent = 0
            robot_rss: list[int] = []
            for p in robots:
                assert p.stdout is not None
                done = await anyio.to_thread.run_sync(p.stdout.readline)
                words = done.split()
                sent += int(words[1])
                robot_rss.append(int(words[3]))
            wall = time.monotonic() - w0
            r1, u1 = cpu_seconds(router.pid), resource.getrusage(resource.RUSAGE_SELF)
            with anyio.fail_after(30):
                while fleet.statistics().messages < sent and time.monotonic() - w0 < wall + 5:
                    await anyio.sleep(0.05)
            st = fleet.statistics()
            listener_rss = rss() - base_rss
            zs = transport.statistics()
        listener_cpu = (u1.ru_utime + u1.ru_stime - u0.ru_utime - u0.ru_stime) / wall
        print(f"scale: {args.robots} robot processes x {args.frames} frames x {args.rate:g} Hz "
              f"for {args.seconds:g} s through one router (127.0.0.1), one fleet listener")
        print(f"  messages received/sent      {st.messages} / {sent}  "
              f"(lost {sent - st.messages}; transforms {st.transforms}; "
              f"inbound overflow {zs.overflow})")
        print(f"  offered load                {args.robots * args.frames * args.rate:,.0f} "
              "transforms/s")
        if latencies:
            print(f"  latency stamp->listener     median {statistics.median(latencies):.2f} ms"
                  f"   p99 {pct(latencies, 0.99):.2f} ms   max {max(latencies):.2f} ms")
        print(f"  router CPU                  {100 * (r1 - r0) / wall:.0f} % of one core")
        print(f"  listener CPU                {100 * listener_cpu:.0f} % of one core")
        print(f"  RSS per robot process       "
              f"median {statistics.median(robot_rss) / 2**20:.1f} MiB")
        print(f"  listener memory per robot   {listener_rss / args.robots / 2**20:.2f} MiB "
              f"(RSS growth / robots, {args.frames} frames, 10 s cache)")
    finally:
        for p in robots:
            if p.poll() is None:
                p.kill()
            p.wait(10)
        router.terminate()
        try:
            router.wait(10)
        except subprocess.TimeoutExpired:
            router.kill()
            router.wait(10)


# -- 2. simulated robots in one process --------------------------------------------


async def simulated(args: argparse.Namespace) -> None:
    async with Bus() as bus, FleetBuffer(bus, cache_time=args.history + 1) as fleet:
        before = rss()
        names = [f"robot{k}" for k in range(args.sim_robots)]
        for name in names:
            fleet.add_robot(name)
        steps = int(args.history * args.rate)
        t0 = time.perf_counter()
        for step in range(steps):
            stamp = 1_000_000_000 + step * int(1e9 / args.rate)
            for name in names:
                bus.publish_nowait(f"/{name}/tf", frames_message(name, args.frames, stamp, step))
        fill = time.perf_counter() - t0
        grown = rss() - before
        mid = 1_000_000_000 + (steps // 2) * int(1e9 / args.rate)
        times = [Time.from_ns(mid + 7 + 1000 * k) for k in range(2000)]  # no two alike
        last = f"f{args.frames - 1}"
        n = len(times)
        t0 = time.perf_counter()
        for k, at in enumerate(times):
            fleet[names[k % len(names)]].lookup_transform("base", last, at)
        lookup = (time.perf_counter() - t0) / n
        t0 = time.perf_counter()
        for k in range(n):
            fleet[names[k % len(names)]].lookup_transform("f0", "f1", Time(0))
        short = (time.perf_counter() - t0) / n
    total = steps * args.sim_robots * args.frames
    print(f"simulated: {args.sim_robots} robots in one process x {args.frames} frames, "
          f"{args.history:g} s at {args.rate:g} Hz ({total:,} transforms stored in {fill:.1f} s)")
    print(f"  memory per robot            {grown / args.sim_robots / 2**20:.2f} MiB (RSS growth)")
    print(f"  FleetBuffer[robot] lookup   {lookup * 1e6:.1f} us ({args.frames}-link chain, "
          f"interpolated)   {short * 1e6:.1f} us (1 link, latest)")


# -- 3. remote lookups -------------------------------------------------------------


async def remote(args: argparse.Namespace) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    buffer = Buffer()
    for i, (parent, child) in enumerate([("map", "odom"), ("odom", "base"), ("base", "laser")]):
        buffer.set_transform_static(TransformStamped(
            Header(Time(0), parent), child,
            Transform(Vector3(float(i), 0.0, 0.0), Quaternion())), "bench")

    def client_bus(**kw: object) -> Bus:
        return Bus(transport=ZenohTransport(connect=endpoint, config={"mode": "client"}, **kw))

    async with ZenohRouter(listen=endpoint), client_bus(name="server") as sbus, \
            client_bus(name="client", topics=()) as cbus, BufferServer(buffer, sbus):
        client = BufferClient(cbus)
        with anyio.fail_after(30):
            while not await client.can_transform("map", "laser", Time(0), 0.0):
                await anyio.sleep(0.05)
        rtts = []
        for _ in range(args.queries):
            t0 = time.perf_counter_ns()
            await client.lookup_transform("map", "laser", Time(0), 1.0)
            rtts.append((time.perf_counter_ns() - t0) / 1e3)
        local = []
        for _ in range(args.queries):
            t0 = time.perf_counter_ns()
            buffer.lookup_transform("map", "laser", Time(0))
            local.append((time.perf_counter_ns() - t0) / 1e3)
        done = 0
        deadline = time.monotonic() + args.qps_seconds

        async def worker() -> None:
            nonlocal done
            while time.monotonic() < deadline:
                await client.lookup_transform("map", "laser", Time(0), 1.0)
                done += 1

        t0 = time.monotonic()
        async with anyio.create_task_group() as tg:
            for _ in range(args.concurrency):
                tg.start_soon(worker)
        qps = done / (time.monotonic() - t0)
    print(f"remote lookups on loopback (router + BufferServer + BufferClient, 3-link chain, "
          f"{args.queries} sequential):")
    print(f"  remote round trip           median {statistics.median(rtts):.0f} us   "
          f"p99 {pct(rtts, 0.99):.0f} us")
    print(f"  local lookup_transform      median {statistics.median(local):.1f} us   "
          f"p99 {pct(local, 0.99):.1f} us")
    print(f"  throughput                  {qps:,.0f} queries/s ({args.concurrency} in flight)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--robots", type=int, default=20)
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--rate", type=float, default=50.0)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--sim-robots", type=int, default=100)
    p.add_argument("--history", type=float, default=10.0)
    p.add_argument("--queries", type=int, default=2000)
    p.add_argument("--concurrency", type=int, default=32)
    p.add_argument("--qps-seconds", type=float, default=3.0)
    p.add_argument("--quick", action="store_true", help="a short run (5 robots, 3 s)")
    p.add_argument("--as-robot", default=None, help=argparse.SUPPRESS)
    p.add_argument("--endpoint", default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.as_robot is not None:
        anyio.run(robot_main, args.endpoint, args.as_robot, args.frames, args.rate,
                  args.seconds)
        return
    if args.quick:
        args.robots, args.seconds, args.sim_robots, args.history = 5, 3.0, 20, 2.0
        args.queries, args.qps_seconds = 300, 1.0
    anyio.run(scale, args)
    anyio.run(simulated, args)
    anyio.run(remote, args)


if __name__ == "__main__":
    main()
