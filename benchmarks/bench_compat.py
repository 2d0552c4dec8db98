"""tf2_py's API on tfbus (``tfbus.compat.tf2_py``) against Debian's real tf2_py 0.7.6,
in the same run: ``set_transform``, ``lookup_transform_core`` (a 5-link chain,
interpolated, never-repeated times), ``can_transform_core`` and ``_chain``, best of 7
rounds, microseconds per call. Needs ``/usr/bin/python3`` with python3-tf2.

Then ``tfbus.compat.tf2_ros`` for synchronous callers: how long after the
``set_transform`` that answers it a blocking ``lookup_transform(..., timeout)`` in
another thread returns (median and 95th percentile of 200 waits, woken through the
background loop, never polled), and the background loop's CPU while idle (process CPU
time over 3 s of wall time with the loop started and nothing to do, per cent of a core).

    .venv/bin/python benchmarks/bench_compat.py
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def side(python: str, which: str) -> dict[str, float]:
    r = subprocess.run([python, str(HERE / "_compat_side.py"), which], capture_output=True,
                       text=True, check=True, timeout=600)
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


if __name__ == "__main__":
    main()
