"""The streams the compiled accounting's twin tests feed both loops with (the compiled loop
and its Python twin: ``tests/doctor/test_compiled_accounting.py`` for the doctor's checks,
``tests/monitor/test_compiled_tables.py`` for tf_monitor's tables), and the run of a
twin test module's own ``state(feed(...))`` under the pure-Python core in a process of its
own. Each test module keeps its own ``state`` (what its object keeps, as exact text) and
``feed``; what is shared here is what both send.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from doctor_faults import FAULTS, T0, Record, tf
from hypothesis import strategies as st

from tfbus.messages import Header, TransformStamped
from tfbus.time import Time

HERE = Path(__file__).resolve().parent
MS = 1_000_000


class Stamped(TransformStamped):
    """A subclass of TransformStamped (read by attribute, as the Python loops read it)."""


class SubHeader(Header):
    """A subclass of Header."""


def by_receive_time(records: list[Record]) -> list[Record]:
    """``records`` in receive-time order (a fault recording lists them per sender)."""
    return sorted(records, key=lambda r: r[0])


def peer_items(i: int, t: int) -> list[Any]:
    """Message ``i`` (received at ``t`` ns) of a peer's stream: an ordinary transform,
    and, between them, what only a peer or a hand-made call sends: a non-transform, a
    child that is not a str, a stamp that is not a Time, subclasses of TransformStamped
    and Header, and (message 30) a stamp so far behind the receive clock that the delay
    is beyond 2**53 ns."""
    items: list[Any] = [tf("odom", "base_link", t - 5 * MS)]
    if i % 7 == 0:
        items.append("junk")
    if i % 11 == 0:
        items.append(TransformStamped(Header(Time.from_ns(t), "odom"), 5))  # type: ignore[arg-type]
    if i % 13 == 0:
        items.append(TransformStamped(Header(5, "odom"), "x"))  # type: ignore[arg-type]
    if i % 5 == 0:
        base = tf("map", "odom", t - 20 * MS)
        items.append(Stamped(SubHeader(*base.header), base.child_frame_id, base.transform))
    if i == 30:
        items.append(tf("odom", "far", 1))
    return items


def stream_strategy(parents: list[str], children: list[str],
                    max_size: int) -> st.SearchStrategy[list[Any]]:
    """Random streams: steps of (receive time step ns, topic, caller id, links as
    (parent, child, stamp relative to the receive time in ns)); :func:`records_of` makes
    records of one."""
    return st.lists(
        st.tuples(
            st.integers(0, 3 * 10**8),
            st.sampled_from(["/tf", "/tf", "/tf", "/tf_static"]),
            st.sampled_from(["/a", "/b", "/a"]),
            st.lists(st.tuples(st.sampled_from(parents), st.sampled_from(children),
                               st.integers(-3 * 10**8, 10**8)),
                     min_size=1, max_size=4),
        ),
        max_size=max_size,
    )


def records_of(steps: list[tuple[int, str, str, list[tuple[str, str, int]]]]) -> list[Record]:
    """The records of a stream drawn from :func:`stream_strategy`, from :data:`T0`."""
    t = T0
    records: list[Record] = []
    for step, topic, caller, links in steps:
        t += step
        records.append((t, topic, caller,
                        [tf(parent, child, max(t + rel, 0)) for parent, child, rel in links]))
    return records


def named_streams(module: Any) -> dict[str, list[Record]]:
    """Every fault recording in receive-time order, and ``"peer"``: the twin test
    module's ``peer_stream()``."""
    streams = {name: by_receive_time(f()) for name, f in FAULTS.items()}
    streams["peer"] = module.peer_stream()
    return streams


_PURE_SCRIPT = """
import sys
sys.path[:0] = [{where!r}, {doctor!r}]
import {module} as t
import twin_streams
assert t.COMPILED is None, "the compiled accounting in use under TFBUS_PURE_PYTHON"
streams = twin_streams.named_streams(t)
for name in sorted(streams):
    print(name, t.state(t.feed(streams[name], False)))
"""


def pure_states(test_file: str) -> dict[str, str]:
    """``state(feed(stream, False))`` of the twin test module ``test_file`` (its
    ``__file__``) for each of :func:`named_streams`, computed in a process with
    ``TFBUS_PURE_PYTHON`` set: the pure twin's own field classes (slots)."""
    path = Path(test_file).resolve()
    env = {**os.environ, "TFBUS_PURE_PYTHON": "1"}
    script = _PURE_SCRIPT.format(where=str(path.parent), doctor=str(HERE), module=path.stem)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                         text=True, timeout=120, check=True).stdout
    return dict(line.split(" ", 1) for line in out.splitlines())
