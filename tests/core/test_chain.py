"""``tfbus.compat.tf2_py.chain``: the frame path of a time-travel lookup, exactly as Debian's real
tf2_py 0.7.6 ``BufferCore._chain`` returns it (run in a side process under
``/usr/bin/python3``, ``peers/debian/tf2_py_side.py``), on fixed cases and random trees."""

from __future__ import annotations

import random
from typing import Any

import pytest
from conformance import rolling_class
from tf2_py_harness import have_tf2_py, run_side

from tfbus import (
    BufferCore,
    ConnectivityException,
    ExtrapolationException,
    Header,
    LookupException,
    Quaternion,
    Time,
    Transform,
    TransformException,
    TransformStamped,
    Vector3,
)
from tfbus.compat.tf2_py import chain

SEC = 1_000_000_000

needs_tf2_py = pytest.mark.usefixtures("tf2_py_installed")  # tests/conftest.py


def _add(core: BufferCore, ops: list[list[Any]], parent: str, child: str, ns: int,
         static: bool = False) -> None:
    t, q = (0.1, 0.2, 0.3), (0.0, 0.0, 0.0, 1.0)
    ts = TransformStamped(Header(Time.from_ns(ns), parent), child,
                          Transform(Vector3(*t), Quaternion(*q)))
    (core.set_transform_static if static else core.set_transform)(ts)
    ops.append(["set", parent, child, ns, list(t), list(q), static])


def test_known_chains() -> None:
    core = BufferCore()
    for k in (1, 2):
        for parent, child in (("A", "B"), ("B", "C"), ("A", "D")):
            core.set_transform(TransformStamped(Header(Time(k), parent), child, Transform()))
    t0 = Time(0)
    assert chain(core, "D", t0, "C", t0, "A") == ["C", "B", "A", "D"]
    assert chain(core, "C", t0, "D", t0, "A") == ["D", "A", "B", "C"]
    assert chain(core, "C", t0, "C", t0, "C") == []
    assert chain(core, "A", t0, "C", t0, "B") == ["C", "B", "A"]
    # tf2 0.7.6's pruning keeps the root when the branches meet one level below it
    assert chain(core, "C", t0, "B", t0, "A") == ["B", "A", "B", "C"]
    with pytest.raises(LookupException):
        chain(core, "C", t0, "nowhere", t0, "A")
    with pytest.raises(ExtrapolationException):
        chain(core, "C", Time(5), "D", t0, "A")
    core.set_transform(TransformStamped(Header(Time(1), "Z"), "Y", Transform()))
    with pytest.raises(ConnectivityException):
        chain(core, "C", t0, "Y", t0, "A")


def _random_case(rng: random.Random) -> tuple[BufferCore, list[list[Any]], list[str]]:
    core = BufferCore(100.0)
    ops: list[list[Any]] = []
    n = rng.randrange(3, 9)
    names = [f"n{i}" for i in range(n)]
    parents: dict[str, str] = {}
    for i in range(1, n):
        parents[names[i]] = names[rng.randrange(i)]
    # a second tree now and then, and a re-parented frame at later stamps
    if rng.random() < 0.2:
        parents[names[-1]] = "other_root"
    for name, parent in parents.items():
        if rng.random() < 0.25:
            _add(core, ops, parent, name, 0, static=True)
            continue
        first = rng.randrange(1, 3)
        for s in range(first, first + rng.randrange(2, 5)):
            _add(core, ops, parent, name, s * SEC)
    if rng.random() < 0.3 and n > 3:
        child = names[-1]
        new_parent = names[rng.randrange(1, n - 2)]
        if new_parent != child and parents.get(child) != new_parent:
            for s in (7, 8):
                _add(core, ops, new_parent, child, s * SEC)
    return core, ops, [*names, "other_root"]


@needs_tf2_py
def test_chain_equals_real_tf2_py_on_random_trees() -> None:
    rng = random.Random(23)
    ops: list[list[Any]] = []
    ours: list[list[str] | tuple[str, str]] = []
    for _ in range(60):
        core, setup, names = _random_case(rng)
        ops.append(["new"])
        ops.extend(setup)
        for _ in range(25):
            target, source, fixed = (rng.choice(names) for _ in range(3))
            tt, st = (rng.choice([0, rng.randrange(0, 9) * SEC, rng.randrange(SEC, 5 * SEC)])
                      for _ in range(2))
            ops.append(["call", "_chain", [target, {"t": tt}, source, {"t": st}, fixed]])
            try:
                ours.append(chain(core, target, Time.from_ns(tt), source, Time.from_ns(st), fixed))
            except TransformException as e:
                ours.append((type(e).__name__, str(e)))
    answers = run_side(ops, cache_time_s=100.0)
    assert len(answers) == len(ours)
    lists = errors = 0
    for mine, ref in zip(ours, answers, strict=True):
        if "err" in ref:
            # tf2's text, and the class ROS 2 derives from it (tfbus raises ROS 2's
            # extrapolation subclasses: tests/conformance.py rolling_class)
            assert mine == (rolling_class(ref["err"], ref["msg"]), ref["msg"]), (mine, ref)
            errors += 1
        else:
            assert mine == ref["ok"], (mine, ref)
            lists += 1 if mine else 0
    assert lists > 300 and errors > 50, (lists, errors)



def test_monitor_chain_line_is_tf2s() -> None:
    """``tfbus monitor A B``'s ``Chain is:`` line is tf2's ``_chainAsVector(B, 0, A, 0,
    B)``, as tf_monitor prints it, quirks included (here the root A, where the branches
    meet one level below it); the net delay still follows the lookup's path."""
    from tfbus.cli.monitor import chain_lines, tf2_chain
    from tfbus.monitor import TfSummary

    stats = TfSummary()
    links = [("A", "B"), ("B", "C"), ("B", "E")]
    stats.add(Time(1), [TransformStamped(Header(Time(1), p), c, Transform()) for p, c in links],
              "n", static=False)
    stats.watch_chain("C", "E")
    assert tf2_chain(stats.parents(), "C", "E") == ["C", "B", "A", "E"]
    assert chain_lines(stats, ["C", "E"])[0] == "Chain is: C -> B -> A -> E"
    assert stats.chains[0].frames == ("C", "B", "E")  # the path the lookup walks
    assert tf2_chain({"x": "y", "p": "q"}, "x", "p") is None  # two trees
    if have_tf2_py():
        ops: list[list[Any]] = [["set", p, c, SEC, [0, 0, 0], [0, 0, 0, 1], False]
                                for p, c in links]
        ops.append(["call", "_chain", ["E", {"t": 0}, "C", {"t": 0}, "E"]])
        assert run_side(ops) == [{"ok": ["C", "B", "A", "E"]}]


def test_frame_path_is_the_lowest_common_ancestor_path() -> None:
    core = BufferCore()
    for parent, child in (("A", "B"), ("B", "C"), ("B", "E"), ("A", "D")):
        core.set_transform_static(TransformStamped(Header(Time(0), parent), child, Transform()))
    core.set_transform_static(TransformStamped(Header(Time(0), "Z"), "Y", Transform()))
    # no tf2 0.7.6 pruning quirk: C to E meets at B, the root A is not visited
    assert core.frame_path("C", "E") == ["C", "B", "E"]
    assert core.frame_path("D", "C") == ["D", "A", "B", "C"]
    assert core.frame_path("A", "C") == ["A", "B", "C"]
    assert core.frame_path("C", "C") == ["C"]
    assert core.frame_path("C", "Y") is None  # two trees
    assert core.frame_path("C", "nowhere") is None
    # tf2_py's ordering of the same walk keeps its quirk
    assert chain(core, "E", Time(0), "C", Time(0), "E") == ["C", "B", "A", "E"]
