"""ROS 2 domain ids for the tests that talk DDS: a fresh one for each use, never handed out
twice in a run, and never the same in two pytest processes running side by side.

DDS peers on one domain discover each other (on loopback too), so two tests that share a
domain at the same time see each other's topics. The suite runs in two pytest-xdist
worker processes (``make test``): each worker takes its own share of the ids (worker
``gwN`` of ``PYTEST_XDIST_WORKER_COUNT`` takes the ids ``d`` with ``d % count == N``), so
tests running at once in two workers never meet. A run without xdist takes every id.
Ids 1..232 (ROS 2's ``ROS_DOMAIN_ID`` range on Linux: a higher one maps DDS's ports beyond
65535; 0, the ROS 2 default, is left out).
"""

from __future__ import annotations

import os
import random

__all__ = ["DOMAIN_IDS", "new_domain", "worker_share"]

DOMAIN_IDS = range(1, 233)
"""Every domain id a test may take."""

_rng = random.SystemRandom()
_used: set[int] = set()


def worker_share(ids: range = DOMAIN_IDS) -> list[int]:
    """This pytest process's share of ``ids``: every id under pytest-xdist's worker
    ``gwN`` (of ``PYTEST_XDIST_WORKER_COUNT``) whose remainder by the count is ``N``;
    all of them outside xdist."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "")
    if not (worker.startswith("gw") and worker[2:].isdigit() and count.isdigit()
            and int(count) > 0):
        return list(ids)
    n = int(count)
    index = int(worker[2:]) % n
    return [d for d in ids if d % n == index]


def new_domain() -> int:
    """A random domain id of this process's share (:func:`worker_share`) not handed out
    before in it.

    Raises:
        RuntimeError: the share is used up.
    """
    free = [d for d in worker_share() if d not in _used]
    if not free:
        raise RuntimeError("no free ROS 2 domain id left in this test process's share")
    d = _rng.choice(free)
    _used.add(d)
    return d
