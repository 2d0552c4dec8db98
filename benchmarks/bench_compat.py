"""tf2_py's API on tfbus (``tfbus.compat.tf2_py``) against Debian's real tf2_py 0.7.6,
in the same run: ``set_transform``, ``lookup_transform_core`` (a 5-link chain,
interpolated, never-repeated times), ``can_transform_core`` and ``_chain``, best of 7
rounds, microseconds per call. Needs ``/usr/bin/python3`` with python3-tf2.

Then ``tfbus.compat.tf2_ros`` for synchronous callers: how long after the
``set_transform`` that answers it a blocking ``lookup_transform(..., timeout)`` in
another thread returns (median and 95th percentile of 200 waits, woken through the
background loop, never polled), and the background loop's CPU while idle (process CPU
time over 3 s of wall time with the loop started and nothing to do, per cent of a core).

Then the same two figures on a ROS 1 graph (a roscore on 127.0.0.1, Debian's ROS 1),
tfbus.compat beside Debian's tf2_ros (rospy) running the same program
(``peers/ros1/compat_blocking_side.py``): a thread blocked in ``Buffer.lookup_transform(..., t,
timeout=5 s)`` for a stamp ``t`` not yet received, answered by one ``/tf`` message from
the same rospy publisher process; the delay from the message's arrival in the waiting
process (a ``/tf`` callback there registered before the listener's) to the call's
return, median and 90th percentile of 200; and the CPU of a process holding only a
``Buffer`` and a ROS 1 ``TransformListener``, idle for 10 s. The targets
(``tfbus.compat`` column): a blocking call returns within 1 ms of the arrival that
answers it (p90), and the idle process costs < 0.5 % of a core.

    .venv/bin/python benchmarks/bench_compat.py
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "peers" / "ros1"))  # the ROS 1 peers, shared with the tests

from ros1_peers import Master, Proc, ros1_missing, start_master  # noqa: E402

WAITS = 200
IDLE_SECONDS = 10.0
SIDE = str(ROOT / "peers" / "ros1" / "compat_blocking_side.py")


def side(python: str, which: str) -> dict[str, float]:
    r = subprocess.run([python, str(ROOT / "peers" / "debian" / "compat_side.py"), which],
                       capture_output=True, text=True, check=True, timeout=600)
    result: dict[str, float] = json.loads(r.stdout)
    return result


def main() -> None:
    real = side("/usr/bin/python3", "real")
    ours = side(sys.executable, "compat")
    print(f"{'call':24} {'tf2_py 0.7.6 us':>16} {'tfbus.compat us':>16} {'ratio':>7}")
    for name in real:
        print(f"{name:24} {real[name] * 1e6:16.2f} {ours[name] * 1e6:16.2f} "
              f"{real[name] / ours[name]:6.1f}x")
    blocking_rows()
    ros1_rows()


def blocking_rows() -> None:
    import statistics
    import threading
    import time

    from tfbus import Header, Time, Transform, TransformStamped, Vector3
    from tfbus.compat import tf2_ros
    from tfbus.compat._loop import background

    delays = []
    for i in range(200):
        buf = tf2_ros.Buffer()
        returned: list[float] = []
        waiter = threading.Thread(target=lambda b=buf, r=returned: (
            b.lookup_transform("map", "base", Time(0), 10.0), r.append(time.perf_counter())))
        waiter.start()
        deadline = time.monotonic() + 10.0
        while background.call(lambda b=buf: b.buffer.pending_waits) < 1:
            if time.monotonic() > deadline:
                raise RuntimeError("the blocking call never waited")
            time.sleep(0.001)
        sent = time.perf_counter()
        buf.set_transform(TransformStamped(Header(Time(i + 1), "map"), "base",
                                           Transform(Vector3(1.0, 0.0, 0.0))), "bench")
        waiter.join(10.0)
        delays.append(returned[0] - sent)
    delays.sort()
    print(f"blocking lookup_transform: returns {statistics.median(delays) * 1e6:.0f} us "
          f"(median), {delays[189] * 1e6:.0f} us (p95) after the arrival that answers it")
    cpu0, wall0 = time.process_time(), time.monotonic()
    time.sleep(3.0)
    cpu = (time.process_time() - cpu0) / (time.monotonic() - wall0)
    print(f"background loop idle: {cpu * 100:.3f} % of a core")



def _env(master: Master) -> dict[str, str]:
    env = dict(master.env)
    env["PYTHONPATH"] = str(ROOT)
    return env


def _delays(master: Master, python: str, mode: str) -> list[float]:
    """Run the ``mode`` waiter against one rospy publisher; its WAITS delays (s)."""
    pub = subprocess.Popen(["/usr/bin/python3", SIDE, "publisher"], env=master.env,
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    waiter = Proc([python, SIDE, mode, str(WAITS)], _env(master), cwd=ROOT)
    try:
        assert pub.stdin is not None and pub.stdout is not None
        assert pub.stdout.readline().strip() == "PUBLISHING"
        waiter.wait_for("^READY$", 60.0)
        deadline = time.monotonic() + 60.0
        while True:  # until the publisher's connection delivers: the warm-up message
            pub.stdin.write("-1\n")
            pub.stdin.flush()
            try:
                waiter.wait_for("^WARM$", 0.2)
                break
            except AssertionError:
                if time.monotonic() > deadline:
                    raise
        for i in range(WAITS):
            waiter.wait_for(f"^WAITING {i}$", 30.0)
            pub.stdin.write(f"{i}\n")
            pub.stdin.flush()
        out: list[float] = json.loads(waiter.wait_for("^DELAYS (.*)$", 60.0).group(1))
        return out
    finally:
        waiter.stop()
        if pub.stdin is not None:
            pub.stdin.close()
        pub.wait(15)


def _idle(master: Master, python: str, mode: str) -> float:
    proc = Proc([python, SIDE, mode, str(IDLE_SECONDS)], _env(master), cwd=ROOT)
    try:
        return float(proc.wait_for(r"^CPU (\S+)$", IDLE_SECONDS + 60.0).group(1))
    finally:
        proc.stop()


def ros1_rows() -> None:
    """The ROS 1 rows (module doc), with PASS/FAIL against the targets."""
    why = ros1_missing(("tf2_ros",))
    if why is not None:
        print(f"ROS 1 rows not run: {why}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        master = start_master(Path(tmp) / "ros_home")
        try:
            ours = sorted(_delays(master, sys.executable, "tfbus-wait"))
            theirs = sorted(_delays(master, "/usr/bin/python3", "rospy-wait"))
            idle_ours = _idle(master, sys.executable, "tfbus-idle")
            idle_theirs = _idle(master, "/usr/bin/python3", "rospy-idle")
        finally:
            master.stop()

    def p90(d: list[float]) -> float:
        return d[int(0.9 * len(d)) - 1]

    print(f"ROS 1 graph, one rospy publisher; n={WAITS} waits; "
          f"idle over {IDLE_SECONDS:.0f} s (pid {os.getpid()})")
    print(f"{'':44} {'tf2_ros (rospy)':>16} {'tfbus.compat':>13}  target")
    print(f"{'blocking lookup_transform, arrival->return':44} "
          f"{statistics.median(theirs) * 1e3:13.3f} ms {statistics.median(ours) * 1e3:10.3f} ms"
          f"  (median)")
    verdict = "PASS" if p90(ours) <= 1e-3 else "FAIL"
    print(f"{'':44} {p90(theirs) * 1e3:13.3f} ms {p90(ours) * 1e3:10.3f} ms"
          f"  p90 <= 1 ms: {verdict}")
    verdict = "PASS" if idle_ours < 0.005 else "FAIL"
    print(f"{'idle Buffer + ROS 1 TransformListener, CPU':44} {idle_theirs * 100:11.3f} % "
          f"{idle_ours * 100:10.3f} %  < 0.5 % of a core: {verdict}")


if __name__ == "__main__":
    main()
