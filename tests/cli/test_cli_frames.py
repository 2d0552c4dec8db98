"""``tfbus frames`` (view_frames): the DOT text, rendering, output errors, and hostile or
escaped ids as one quoted node each."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    HOSTILE,
    LONG_ID,
    T0,
    TURTLE,
    assert_one_line_error,
    assert_usage_error,
    run,
    tf,
)

from tfbus import Time
from tfbus.bag import BagMessage, load_buffer, write_bag
from tfbus.cli import frames_dot
from tfbus.messages import TFMessage


def test_frames_dot_text(tmp_path: Path) -> None:
    out = tmp_path / "tree.gv"
    code, stdout, _ = run("frames", "--bag", str(TURTLE), "-o", str(out))
    assert code == 0 and str(out) in stdout
    dot = out.read_text()
    assert dot.startswith("digraph G {")
    assert "world -> turtle1" in dot and "world -> turtle2" in dot and "turtle1 -> carrot" in dot
    assert "Broadcaster: /turtle1_tf_broadcaster" in dot
    assert "Most recent transform: 1396293909.544" in dot
    assert "Oldest transform: 1396293888.056" in dot
    assert "Average rate: static" in dot
    assert "view_frames Result" in dot
    assert frames_dot(load_buffer(TURTLE)) == dot


def test_frames_pdf_renders_or_explains(tmp_path: Path) -> None:
    out = tmp_path / "frames.pdf"
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(out))
    assert (tmp_path / "frames.gv").exists()
    if shutil.which("dot"):
        assert code == 0, f"Graphviz failed: {err}"  # Graphviz's error text shown
        assert out.read_bytes().startswith(b"%PDF")
    else:
        assert code == 1 and "'dot' not found" in err and len(err.strip().splitlines()) == 1


def test_frames_bad_output() -> None:
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", "frames.jpg")
    assert_usage_error(code, err, "frames.jpg")


def _svg_nodes(svg: Path) -> list[str]:
    ns = {"s": "http://www.w3.org/2000/svg"}
    root = ET.parse(svg).getroot()
    assert not root.findall(".//s:a", ns), "a link was injected"
    return [g.findtext("s:title", namespaces=ns) or "" for g in root.iterfind(".//s:g", ns)
            if g.get("class") == "node"]


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_every_hostile_tree_renders_one_node_per_frame(
    hostile_bag: Path, tmp_path: Path
) -> None:
    """One node per frame, nothing injected, every tree renders (also a
    trailing backslash, <script> and a 16 KB id, which is shortened visibly)."""
    out = tmp_path / "tree.svg"
    code, _, err = run("frames", "--bag", str(hostile_bag), "-o", str(out))
    assert code == 0, err
    nodes = _svg_nodes(out)
    assert len(nodes) == len(HOSTILE) + 2  # + world + the legend
    texts = ET.tostring(ET.parse(out).getroot(), encoding="unicode")
    assert "cam:left" in nodes
    assert "...(16384 chars)..." in texts and LONG_ID not in texts
    for one in HOSTILE[:-1]:  # each alone, as its own tree
        single = tmp_path / "single.bag"
        single.unlink(missing_ok=True)
        write_bag(single, [BagMessage(Time.from_ns(T0), "/tf", TFMessage([tf("w", one, T0)]),
                                      "")])
        code, _, err = run("frames", "--bag", str(single), "-o", str(out))
        assert code == 0, (one, err)
        assert len(_svg_nodes(out)) == 3


def test_dot_text_quotes_every_id(hostile_bag: Path) -> None:
    """In the DOT text every id is one quoted identifier."""
    from tfbus.bag import load_buffer
    from tfbus.cli import frames_dot

    dot = frames_dot(load_buffer(hostile_bag))
    assert '\tworld -> "cam:left" [label=' in dot
    assert '\tworld -> "back\\\\\\\\" [label=' in dot  # drawn back\\, not an escape
    assert '\tworld -> "<script>" [label=' in dot
    assert "\x1b" not in dot


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_dot_errors_are_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Graphviz's own error (several lines) and an empty one are
    reported in one line."""
    import tfbus.cli.frames as frames

    monkeypatch.setattr(frames, "frames_dot", lambda core, **kw: "digraph G {\n a -> \n}\n")
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / "x.svg"))
    assert_one_line_error(code, err)
    assert "dot failed (exit status 1): Error: <stdin>: syntax error in line 3" in err

    import graphviz

    def silent_failure(self: object, format: str, quiet: bool = False) -> bytes:
        raise graphviz.CalledProcessError(1, ["dot"], output=b"", stderr=b"")

    monkeypatch.setattr(graphviz.Source, "pipe", silent_failure)
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / "x.svg"))
    assert_one_line_error(code, err)
    assert "no message from dot" in err


def test_unwritable_output_is_one_line(tmp_path: Path) -> None:
    """A missing directory or an unwritable path: a one-line error."""
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / "nodir" / "f.svg"))
    assert_one_line_error(code, err)
    assert "does not exist" in err
    for name in ("x" * 300 + ".gv", "x" * 300 + ".svg"):  # too long for the file system
        code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / name))
        assert_one_line_error(code, err)
        assert "cannot write" in err


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_escaped_and_raw_ids_stay_two_nodes(tmp_path: Path) -> None:
    """'a\\nb' (a newline) and the text 'a\\x0ab' were both drawn
    a\\x0ab, one DOT node for two frames (3 nodes for 4 frames); each frame is one node,
    drawn as Python writes it, and the tree renders."""
    ids = ["a\nb", "a\\x0ab", "c\\", "c\\\\"]
    bag = tmp_path / "esc.bag"
    write_bag(bag, [BagMessage(Time.from_ns(T0), "/tf",
                               TFMessage([tf("world", i, T0) for i in ids]), "")])
    out = tmp_path / "tree.svg"
    code, _, err = run("frames", "--bag", str(bag), "-o", str(out))
    assert code == 0, err
    assert len(set(_svg_nodes(out))) == len(ids) + 2  # + world + the legend
    ns = {"s": "http://www.w3.org/2000/svg"}
    drawn = [g.findtext("s:text", namespaces=ns) for g in ET.parse(out).getroot().iterfind(
        ".//s:g", ns) if g.get("class") == "node"]
    assert {"a\\x0ab", "a\\\\x0ab", "c\\\\", "c\\\\\\\\"} <= set(drawn)
