"""Bags the ``tfbus`` command tests write once per module: hostile ids, two trees."""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_support import EVIL_CALLER, HOSTILE, T0, tf

from tfbus import Time
from tfbus.messages import TFMessage


@pytest.fixture(scope="module")
def hostile_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every hostile id as a child of ``world``, 5 messages 0.1 s apart, sent by a
    hostile caller id."""
    from tfbus.bag import BagMessage, write_bag

    path = tmp_path_factory.mktemp("hostile") / "hostile.bag"
    msgs = [
        BagMessage(Time.from_ns(T0 + k * 100_000_000 + 1000), "/tf",
                   TFMessage([tf("world", h, T0 + k * 100_000_000) for h in HOSTILE]), "")
        for k in range(5)
    ]
    write_bag(path, msgs, callerid=EVIL_CALLER)
    return path


@pytest.fixture(scope="module")
def two_trees_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """a -> b and c -> d: two trees that are not connected."""
    from tfbus.bag import BagMessage, write_bag

    path = tmp_path_factory.mktemp("trees") / "trees.bag"
    msgs = [
        BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                   TFMessage([tf("a", "b", T0 + k * 10**8), tf("c", "d", T0 + k * 10**8)]), "")
        for k in range(3)
    ]
    write_bag(path, msgs)
    return path
