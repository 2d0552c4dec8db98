"""``tfbus bag-info``: frames, parents, broadcasters, rates and span of a bag; damaged
bags; hostile ids printed literally."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    LONG_ID,
    NAV2,
    RAW_CONTROL,
    TURTLE,
    assert_usage_error,
    run,
)


def test_bag_info() -> None:
    code, out, _ = run("bag-info", str(TURTLE))
    assert code == 0
    assert "ros1" in out
    assert "/tf 2688, /tf_static 1" in out
    assert "1396293888.046138414" in out and "21.499 s" in out
    assert "4 (1 static links, 2 dynamic links, 2689 transforms)" in out
    rows = {line.split()[0]: line for line in out.splitlines() if "│" in line}
    assert "world" in rows["turtle1"] and "dynamic" in rows["turtle1"]
    assert "1344" in rows["turtle1"] and "62.50" in rows["turtle1"]
    assert "/turtle1_tf_broadcaster" in rows["turtle1"]
    assert "static" in rows["carrot"] and "turtle1" in rows["carrot"]


def test_bag_info_mcap() -> None:
    code, out, _ = run("bag-info", str(NAV2))
    assert code == 0
    assert "mcap" in out and "34 (29 static links, 4 dynamic links, 4409 transforms)" in out


@pytest.mark.parametrize(("bag", "frames", "links"), [(TURTLE, 4, 3), (NAV2, 34, 33)])
def test_bag_info_and_doctor_count_the_same_frames(bag: Path, frames: int, links: int) -> None:
    """Both count frame ids with the roots (turtle: world, turtle1, turtle2, carrot) and
    links (child frames: one per parent -> child pair); each says which is which."""
    code, out, _ = run("bag-info", str(bag))
    assert code == 0
    static, dynamic = out.split(f"frames:     {frames} (")[1].split(" dynamic links")[0] \
        .split(" static links, ")
    assert int(static) + int(dynamic) == links
    code, out, _ = run("doctor", "--bag", str(bag))
    assert code == 0
    assert f" {frames} frames ({links} links), " in out.splitlines()[0]


def test_bag_info_errors(tmp_path: Path) -> None:
    code, _, err = run("bag-info", str(tmp_path / "missing.bag"))
    assert_usage_error(code, err, "missing.bag")
    junk = tmp_path / "junk.bag"
    junk.write_text("not a bag")
    code, _, err = run("bag-info", str(junk))
    assert_usage_error(code, err, "unknown format")


def test_bag_info_truncated_shows_prefix_and_warns(tmp_path: Path) -> None:
    cut = tmp_path / "cut.bag"
    data = TURTLE.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    code, out, err = run("bag-info", str(cut))
    assert code == 1
    assert "turtle1" in out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "warning" in lines[0] and "reading stopped" in lines[0]


def test_ids_print_literally_in_bag_info_and_monitor(hostile_bag: Path) -> None:
    """Ids and broadcaster names are never rich markup and control
    characters are escaped (bag-info, monitor, monitor A B)."""
    for args in (("bag-info", str(hostile_bag)), ("monitor", "--bag", str(hostile_bag)),
                 ("monitor", "[/]", "\x1b[2J", "--bag", str(hostile_bag))):
        code, out, err = run(*args)
        assert code == 0, err
        assert not RAW_CONTROL.search(out)
        assert "[/]" in out and "\\x1b[2J" in out
        assert "[bold red]evil[/]\\x1b]0;pwned\\x07" in out
        if args[1] != "[/]":
            assert "[bold red]x[/]" in out and "\\x1b]0;title\\x07" in out
        else:
            assert "Chain is: [/] -> world -> \\x1b[2J" in out
    code, out, _ = run("bag-info", str(hostile_bag))
    assert LONG_ID in out  # never cut off outside a terminal
