"""CPU time of another process as the benchmarks read it (Linux ``/proc``), shared by
``bench_ros1.py``, ``bench_ros1_floor.py`` and ``bench_demo_ros1.py``.

:func:`cpu_seconds` sums each live thread's scheduler run time in nanoseconds
(``/proc/PID/task/TID/schedstat``, field 1, the scheduler's own account: ``sum_exec_runtime``,
Documentation/scheduler/sched-stats.rst). ``/proc/PID/stat``'s utime + stime
(:func:`tick_seconds`) count in clock ticks of 10 ms: over 1 000 messages that quantises a
receiver's CPU per message to 10 us, and over an 8 s window at 1 % of a core to 8 +- 1 ticks.
A thread that ends inside a window loses its share (the receivers measured here keep their
threads for their whole life).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cpu_and_wakeups", "cpu_seconds", "thread_run_ns", "tick_seconds"]

TICK = os.sysconf("SC_CLK_TCK")
"""Clock ticks per second of ``/proc/PID/stat``'s times (100 on Linux)."""


def tick_seconds(pid: int) -> float:
    """User + system CPU seconds of a process so far (``/proc/PID/stat`` fields 14-15, in
    clock ticks of ``1 / TICK`` s).

    Raises:
        FileNotFoundError: no process ``pid``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def cpu_and_wakeups(pid: int) -> tuple[float, int]:
    """(CPU seconds, voluntary context switches) of a process's live threads so far: the
    scheduler's run time in ns (``/proc/PID/task/TID/schedstat`` field 1) and the
    ``voluntary_ctxt_switches`` of each thread's ``status``. Falls back to
    :func:`tick_seconds` (and 0 wake-ups) where the kernel keeps no schedstat.

    Raises:
        FileNotFoundError: no process ``pid``."""
    cpu_ns = 0
    wakeups = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            cpu_ns += int((task / "schedstat").read_text().split()[0])
            status = (task / "status").read_text()
        except FileNotFoundError:  # a thread that ended meanwhile, or no schedstat
            if not (task / "schedstat").exists() and task.exists():
                return tick_seconds(pid), 0
            continue
        for line in status.splitlines():
            if line.startswith("voluntary_ctxt_switches:"):
                wakeups += int(line.split()[1])
    return cpu_ns / 1e9, wakeups


def cpu_seconds(pid: int) -> float:
    """CPU seconds of a process's live threads so far, to the nanosecond
    (:func:`cpu_and_wakeups`'s first value).

    Raises:
        FileNotFoundError: no process ``pid``."""
    return cpu_and_wakeups(pid)[0]


def thread_run_ns(pid: int) -> dict[str, tuple[str, int]]:
    """Each live thread of a process: its id -> (its name, ``/proc/PID/task/TID/comm``;
    its scheduler run time so far in ns, ``schedstat`` field 1). A thread that ends while
    it is read is left out.

    Raises:
        FileNotFoundError: no process ``pid``."""
    out: dict[str, tuple[str, int]] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            comm = (task / "comm").read_text().strip()
            ns = int((task / "schedstat").read_text().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        out[task.name] = (comm, ns)
    return out
