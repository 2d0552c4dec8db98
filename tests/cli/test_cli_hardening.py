"""Issue 11's CLI items (5, 6, 10, 19-23) and the CLI fuzz run: hostile frame ids and
broadcaster names, damaged / empty / missing inputs, missing optional dependencies and
signals. Each test names its item; bags are written here with ``tfbus.bag.write_bag``."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from click.testing import CliRunner

from tfbus import Header, Quaternion, Time, Transform, TransformStamped, Vector3
from tfbus.bag import BagMessage, write_bag
from tfbus.cli import cli
from tfbus.messages import TFMessage

ROOT = Path(__file__).resolve().parents[2]
TURTLE = ROOT / "tests" / "data" / "webviz_turtle_tf_example.bag"

LONG_ID = "L" * 16384
HOSTILE = [
    "[/]",
    "[bold red]x[/]",
    "\x1b]0;title\x07",
    "\x1b[2J",
    '<x>; injected [URL="http://e.invalid"]; <y>',
    "cam:left",
    "back\\",
    "<script>",
    LONG_ID,
]
EVIL_CALLER = "[bold red]evil[/]\x1b]0;pwned\x07"
T0 = 1_700_000_000 * 10**9
# Control characters that must never reach a terminal (newline excepted).
RAW_CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")


def tf(parent: str, child: str, ns: int, x: float = 1.0) -> TransformStamped:
    return TransformStamped(Header(Time.from_ns(ns), parent), child,
                            Transform(Vector3(x, 0.0, 0.0), Quaternion(0.0, 0.0, 0.0, 1.0)))


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def assert_one_line_error(code: int, err: str) -> None:
    assert code != 0
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert re.match(r"^tfbus( [a-z-]+)*: (error|warning): ", lines[0]), lines[0]


@pytest.fixture(scope="module")
def hostile_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every hostile id as a child of ``world``, 5 messages 0.1 s apart, sent by a
    hostile caller id."""
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
    path = tmp_path_factory.mktemp("trees") / "trees.bag"
    msgs = [
        BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                   TFMessage([tf("a", "b", T0 + k * 10**8), tf("c", "d", T0 + k * 10**8)]), "")
        for k in range(3)
    ]
    write_bag(path, msgs)
    return path


# --------------------------------------------------------------------------- item 5


def test_item5_ids_print_literally_in_bag_info_and_monitor(hostile_bag: Path) -> None:
    """Issue 11 item 5: ids and broadcaster names are never rich markup and control
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


def test_item5_echo_failure_path_is_literal(hostile_bag: Path) -> None:
    """Issue 11 item 5 and 20: the echo failure text keeps bracketed names and escapes
    control characters, including in the list of frames."""
    code, out, _ = run("echo", "[bold red]x[/]", "\x1b[2J", "--bag", str(hostile_bag),
                       "--time", "1")
    assert code == 1
    assert not RAW_CONTROL.search(out)
    assert "Failure at 1.000000000\nException thrown:" in out
    assert "[bold red]x[/]" in out.split("The current list of frames is:")[0]
    assert "Frame \\x1b[2J exists with parent world." in out


def test_item5_log_lines_from_peers_are_literal() -> None:
    """Issue 11 item 5: the live source's log lines (a peer's bad transform) are escaped."""
    import logging

    from tfbus.cli._common import SafeLogFormatter

    record = logging.LogRecord("tfbus.listener", logging.WARNING, __file__, 1,
                               "ignoring a transform on %s: %s", ("/tf", "\x1b[2J bad"), None)
    assert SafeLogFormatter("%(message)s").format(record) == (
        "ignoring a transform on /tf: \\x1b[2J bad"
    )


# --------------------------------------------------------------------------- item 6


def _svg_nodes(svg: Path) -> list[str]:
    ns = {"s": "http://www.w3.org/2000/svg"}
    root = ET.parse(svg).getroot()
    assert not root.findall(".//s:a", ns), "a link was injected"
    return [g.findtext("s:title", namespaces=ns) or "" for g in root.iterfind(".//s:g", ns)
            if g.get("class") == "node"]


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_item6_every_hostile_tree_renders_one_node_per_frame(
    hostile_bag: Path, tmp_path: Path
) -> None:
    """Issue 11 item 6: one node per frame, nothing injected, every tree renders (also a
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


def test_item6_dot_text_quotes_every_id(hostile_bag: Path) -> None:
    """Issue 11 item 6: in the DOT text every id is one quoted identifier."""
    from tfbus.bag import load_buffer
    from tfbus.cli import frames_dot

    dot = frames_dot(load_buffer(hostile_bag))
    assert '\tworld -> "cam:left" [label=' in dot
    assert '\tworld -> "back\\\\\\\\" [label=' in dot  # drawn back\\ (issue 21)
    assert '\tworld -> "<script>" [label=' in dot
    assert "\x1b" not in dot


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_item6_dot_errors_are_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 11 item 6: Graphviz's own error (several lines) and an empty one are
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


# --------------------------------------------------------------------------- item 10


def test_item10_unwritable_output_is_one_line(tmp_path: Path) -> None:
    """Issue 11 item 10: a missing directory or an unwritable path: a one-line error."""
    code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / "nodir" / "f.svg"))
    assert_one_line_error(code, err)
    assert "does not exist" in err
    for name in ("x" * 300 + ".gv", "x" * 300 + ".svg"):  # too long for the file system
        code, _, err = run("frames", "--bag", str(TURTLE), "-o", str(tmp_path / name))
        assert_one_line_error(code, err)
        assert "cannot write" in err


# --------------------------------------------------------------------------- item 20


def test_item20_echo_on_two_trees_prints_tf2_echo_failure(two_trees_bag: Path) -> None:
    """Issue 11 item 20: no KeyError; tf_echo's failure text with the frame names."""
    code, out, err = run("echo", "b", "d", "--bag", str(two_trees_bag))
    assert code == 1 and "Traceback" not in err
    assert out.startswith("Failure at 0.000000000\nException thrown:Could not find a "
                          "connection between 'b' and 'd' because they are not part of the "
                          "same tree.Tf has two or more unconnected trees.\n"
                          "The current list of frames is:\n")
    assert "Frame b exists with parent a." in out and "Frame d exists with parent c." in out
    assert out.endswith(".\n\n")  # tf_echo: allFramesAsString() << std::endl


# --------------------------------------------------------------------------- item 21


def test_item21_monitor_chain_and_net_delay_lines(tmp_path: Path) -> None:
    """Issue 11 item 21: tf_monitor's ``Chain is:`` and ``Net delay`` lines, exactly.

    Hand-computed: world -> base at 10 Hz (stamps k*0.1 s, received 0.01 s later) and
    base -> cam static. Net delay at each /tf message = 0.01 s."""
    path = tmp_path / "chain.bag"
    msgs = [BagMessage(Time.from_ns(T0), "/tf_static",
                       TFMessage([tf("base", "cam", 0)]), "")]
    msgs += [BagMessage(Time.from_ns(T0 + k * 10**8 + 10**7), "/tf",
                        TFMessage([tf("world", "base", T0 + k * 10**8)]), "") for k in range(5)]
    write_bag(path, msgs)
    code, out, _ = run("monitor", "world", "cam", "--bag", str(path))
    assert code == 0
    lines = out.splitlines()
    assert lines[:3] == ["RESULTS: for world to cam", "Chain is: world -> base -> cam",
                         "Net delay     avg = 0.01: max = 0.01"]
    code, _, err = run("monitor", "b", "d", "--bag", str(tmp_path / "chain.bag"))
    assert code == 2 and "'b'" in err


def test_item21_monitor_two_trees_is_one_line(two_trees_bag: Path) -> None:
    """Issue 11 item 21: frames in different trees: a one-line error, not a crash."""
    code, _, err = run("monitor", "b", "d", "--bag", str(two_trees_bag))
    assert_one_line_error(code, err)
    assert "not connected" in err


def test_item21_names_never_cut_off_in_80_columns(hostile_bag: Path) -> None:
    """Issue 11 item 21: in an 80-column terminal, long names wrap inside their cell."""
    from io import StringIO

    from rich.console import Console

    from tfbus.cli._sources import BagSource
    from tfbus.cli.monitor import print_monitor

    name = "a_very_long_frame_name_" * 6
    path = hostile_bag.parent / "long.bag"
    path.unlink(missing_ok=True)
    write_bag(path, [BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                                TFMessage([tf("world", name, T0 + k * 10**8)]), "")
                     for k in range(3)])
    buf = StringIO()
    out = Console(file=buf, width=80, markup=False, highlight=False, emoji=False)
    print_monitor(out, BagSource(path).summary(), ())
    lines = buf.getvalue().splitlines()
    assert max(len(line) for line in lines) <= 80
    first_cells = "".join(line.split("│")[0].strip() for line in lines if "│" in line)
    assert name in first_cells


def test_item21_sim_time_delays_are_relative_to_the_bag_clock(tmp_path: Path) -> None:
    """Issue 11 item 21: stamps in simulated time (10 s) recorded at 1.7e9 s: delays
    against the newest stamp, with a note, not 1.7e9 s. Hand-computed: every message
    stamps the newest time, so every delay is 0."""
    path = tmp_path / "sim.bag"
    write_bag(path, [BagMessage(Time.from_ns(T0 + k * 10**8), "/tf",
                                TFMessage([tf("map", "odom", 10 * 10**9 + k * 10**8)]), "")
                     for k in range(4)])
    code, out, _ = run("monitor", "--bag", str(path))
    assert code == 0
    assert "note: header stamps are simulated time" in out
    row = next(line for line in out.splitlines() if line.lstrip().startswith("odom"))
    assert row.split("│")[4].strip() == "0.000000"
    assert "1700000000" not in row


# --------------------------------------------------------------------------- item 22


def test_item22_one_rate_definition_across_tools(tmp_path: Path) -> None:
    """Issue 11 item 22: frames, monitor and bag-info give the same rate on a bag with
    repeated stamps. Hand-computed: stamps 0, 0.1, 0.1, 0.2, 0.4 s -> 4 distinct stamps
    over 0.4 s -> (4 - 1) / 0.4 = 7.5 Hz."""
    path = tmp_path / "rep.bag"
    stamps = [0, 10**8, 10**8, 2 * 10**8, 4 * 10**8]
    write_bag(path, [BagMessage(Time.from_ns(T0 + s + i), "/tf",
                                TFMessage([tf("world", "robot", T0 + s)]), "")
                     for i, s in enumerate(stamps)])
    _, info, _ = run("bag-info", str(path))
    assert "7.50" in next(line for line in info.splitlines() if "robot" in line)
    _, mon, _ = run("monitor", "--bag", str(path))
    assert "7.500" in next(line for line in mon.splitlines() if "robot" in line)
    gv = tmp_path / "rep.gv"
    run("frames", "--bag", str(path), "-o", str(gv))
    assert "Average rate: 7.500" in gv.read_text()
    for command in ("frames", "monitor", "bag-info"):
        _, helptext, _ = run(command, "--help")
        assert "distinct header stamps - 1" in " ".join(helptext.split())


# --------------------------------------------------------------------------- item 23


def _python(code: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=timeout, check=False, cwd=ROOT)


def _without(module: str, argv: Sequence[str]) -> subprocess.CompletedProcess[str]:
    """``tfbus ARGV`` in a child where importing ``module`` fails as if not installed."""
    return _python(f"import sys; sys.modules[{module!r}] = None\n"
                   "from tfbus.cli import main\nsys.exit(main(sys.argv[1:]))", *argv)


def test_item23_missing_click_names_the_extra() -> None:
    """Issue 11 item 23: ``tfbus`` without click: one line naming tfbus[cli]."""
    proc = _without("click", ["--help"])
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (
        "tfbus: error: the command line needs the 'click' package: pip install 'tfbus[cli]'"
    )


def test_item23_missing_rosbags_names_the_extra(tmp_path: Path) -> None:
    """Issue 11 item 23: reading an .mcap without rosbags: one line naming tfbus[bag]."""
    folder = tmp_path / "b"
    write_bag(folder, [BagMessage(Time.from_ns(T0), "/tf", TFMessage([tf("a", "b", T0)]), "")],
              format="mcap")
    mcap = next(folder.glob("*.mcap"))
    proc = _without("rosbags", ["bag-info", str(mcap)])
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'tfbus[bag]'" in lines[0]


def test_item23_missing_trio_is_one_line() -> None:
    """Issue 11 item 23: --backend trio without trio: one line saying what to install."""
    proc = _without("trio", ["demo", "--backend", "trio", "--duration", "0"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (
        "tfbus demo: error: --backend trio needs the 'trio' package: pip install trio"
    )


def _sigterm_after_first_line(*args: str) -> tuple[int, str, str]:
    proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # bounded by the communicate timeout below
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, first + out, err


def test_item23_sigterm_ends_commands_cleanly() -> None:
    """Issue 11 item 23: SIGTERM ends a long-running command as Ctrl-C does: no
    traceback, a clean exit status."""
    code, out, err = _sigterm_after_first_line(
        "static-transform", "0", "0", "1", "0", "0", "0", "world", "cam", "--local")
    assert out.startswith("publishing static transform world -> cam")
    assert code == 0 and "Traceback" not in err, err
    code, out, err = _sigterm_after_first_line("demo", "--duration", "60")
    assert code in (0, 130) and "Traceback" not in err, err
    assert "summary:" in out


def test_item23_sigterm_during_replay() -> None:
    """Issue 11 item 23: replay stops on SIGTERM with its count line and status 130."""
    proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", "replay", str(TURTLE),
                             "--local"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, env={**os.environ, "COLUMNS": "80"})
    try:
        assert proc.stderr is not None
        seen = ""
        while "replaying" not in seen:  # it has started (bounded: EOF ends the loop)
            char = proc.stderr.read(1)
            if not char:
                break
            seen += char
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130 and "Traceback" not in seen + err
    assert "(interrupted)" in out


# --------------------------------------------------------------------------- fuzzing


@pytest.fixture(scope="module")
def damaged_inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("damaged")
    data = TURTLE.read_bytes()
    inputs = {
        "empty.bag": b"",
        "version-only.bag": data[:13],
        "header-cut.bag": data[:4000],
        "half.bag": data[: len(data) // 2],
        "flipped.bag": data[:5000] + bytes(b ^ 0x5A for b in data[5000:9000]) + data[9000:],
        "junk.mcap": b"\x89MCAP0\r\n" + b"\x00\xff" * 100,
        "junk.db3": b"SQLite format 3\x00" + b"\x01" * 200,
        "text.bag": b"not a bag at all\n",
    }
    paths = {}
    for name, blob in inputs.items():
        path = d / name
        path.write_bytes(blob)
        paths[name] = path
    paths["missing.bag"] = d / "missing.bag"
    return paths


def _commands(bag: str, a: str, b: str, out_dir: Path) -> list[list[str]]:
    return [
        ["bag-info", bag],
        ["echo", a, b, "--bag", bag, "-n", "3"],
        ["echo", a, b, "--bag", bag, "--time", "1"],
        ["monitor", "--bag", bag],
        ["monitor", a, b, "--bag", bag],
        ["frames", "--bag", bag, "-o", str(out_dir / "f.gv")],
        ["replay", bag, "--rate", "0", "-q", "--local"],
    ]


def _check(args: list[str], code: int, out: str, err: str) -> None:
    assert "Traceback" not in out + err, (args, err)
    assert not RAW_CONTROL.search(out), (args, out[:300])
    assert not RAW_CONTROL.search(err), (args, err[:300])
    if code != 0:
        lines = err.strip().splitlines()
        if "Exception thrown:" in out and not lines:  # tf_echo's failure text, on stdout
            return
        assert len(lines) == 1, (args, err)
        assert re.match(r"^tfbus [a-z-]+: (error|warning): ", lines[0]), (args, lines[0])


def test_fuzz_every_command_on_damaged_empty_and_missing_inputs(
    damaged_inputs: dict[str, Path], tmp_path: Path
) -> None:
    """Issue 11 fuzzing: every command on damaged, empty and missing bags: a one-line
    error (or warning after what was readable), a non-zero exit, never a traceback."""
    failures = 0
    for name, path in damaged_inputs.items():
        for args in _commands(str(path), "world", "turtle1", tmp_path):
            code, out, err = run(*args)
            _check(args, code, out, err)
            # (version-only.bag: an error once tfbus.bag reports it, issue 11 item 9)
            if name in ("missing.bag", "empty.bag", "text.bag", "junk.mcap"):
                assert code != 0, (args, out)
            failures += code != 0
    assert failures > 0


def test_fuzz_every_command_on_hostile_ids(hostile_bag: Path, tmp_path: Path) -> None:
    """Issue 11 fuzzing: every command with every hostile id (as argument and in the
    bag): no raw control character on stdout, one-line errors, no traceback."""
    for a in HOSTILE:
        for args in _commands(str(hostile_bag), a, "world", tmp_path):
            code, out, err = run(*args)
            _check(args, code, out, err)
        args = ["static-transform", "0", "0", "1", "0", "0", "0", "world", a, "--once",
                "--local"]
        code, out, err = run(*args)
        _check(args, code, out, err)
        assert code == 0
    for args in (["echo", "nope", "\x1b[2J", "--bag", str(hostile_bag)],
                 ["monitor", "nope", "[/]", "--bag", str(hostile_bag)],
                 ["frames", "--bag", str(hostile_bag), "-o", str(tmp_path / "\x1b[2J.jpg")]):
        code, out, err = run(*args)
        _check(args, code, out, err)
        assert code == 2


# --------------------------------------------------------------------------- issue 21


@pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz 'dot' is not installed")
def test_issue21_item11_escaped_and_raw_ids_stay_two_nodes(tmp_path: Path) -> None:
    """Issue 21, item 11: 'a\\nb' (a newline) and the text 'a\\x0ab' were both drawn
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


BAD_BUS_SPECS = [
    ("zenoh?port=abc", "'port' must be an integer, got 'abc'"),
    ("zenoh?port=99999", "'port' must be in 1..65535, got '99999'"),
    ("zenoh?express=maybe", "'express' must be a boolean, got 'maybe'"),
    ("zenoh?namespace=**", "namespace '**' must be"),
    ("ros2:domain=999", "domain_id must be in 0..232, got 999"),
    ("ros2:domain=abc", "'domain' must be an integer, got 'abc'"),
    ("ros2:config=/nonexistent/tfbus-test.xml", "cannot read the Cyclone XML file"),
    ("ros1:master=ftp://x", "master_uri must be http://host:port, got 'ftp://x'"),
    ("ros1:name=bad name", "is not a ROS graph name"),
    ("ros1:remote=2", "remote must be 0 or 1, got '2'"),
]


@pytest.mark.parametrize(("spec", "said"), BAD_BUS_SPECS)
@pytest.mark.parametrize("command", [["monitor", "--duration", "0.1"],
                                     ["echo", "a", "b", "--duration", "0.1"]])
def test_issue21_item12_bad_bus_values_are_one_line_usage_errors(
    spec: str, said: str, command: list[str]
) -> None:
    """Issue 21, item 12: a --bus value the transport refuses printed a traceback (exit
    status 1) when the bus was opened, and port=99999 was accepted; each is now one
    line naming the spec and the value, exit status 2, before anything runs."""
    pytest.importorskip("zenoh" if spec.startswith("zenoh") else
                        "cyclonedds" if spec.startswith("ros2") else "rosbags")
    code, out, err = run(command[0], "--bus", spec, *command[1:])
    assert code == 2, (out, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"--bus {spec!r}: " in err and said in err, err


def test_issue21_item12_zenoh_port_out_of_range_is_refused_by_the_library() -> None:
    """The same check where the spec becomes options, for scripts: open_transport and
    ZenohTransport refuse a port outside 1..65535 with a ValueError naming it."""
    pytest.importorskip("zenoh")
    from tfbus.transports.spec import open_transport
    from tfbus.transports.zenoh import ZenohTransport

    with pytest.raises(ValueError, match=r"'port' must be in 1\.\.65535, got '65536'"):
        open_transport("zenoh?port=65536")
    with pytest.raises(ValueError, match=r"port must be a TCP port number in 1\.\.65535"):
        ZenohTransport(port=0)
    assert open_transport("zenoh?port=65535") is not None
