"""The ``tfbus`` group, through click's CliRunner: help, version, unknown commands, the
``--bus`` option every live command shares, log lines, signals, missing optional
dependencies, one rate definition across tools, the fuzz run of every command on damaged,
empty, missing and hostile inputs, and one run of the installed entry point (escaped
log lines, one rate, one-line errors, bad --bus values). Each command's own tests are in
``tests/cli/test_cli_<command>.py``. Bag data: tests/data/webviz_turtle_tf_example.bag
(Apache-2.0)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import (
    HOSTILE,
    RAW_CONTROL,
    ROOT,
    T0,
    TURTLE,
    assert_usage_error,
    run,
    tf,
)

from tfbus import Time, TransformStamped
from tfbus.bag import BagMessage, write_bag
from tfbus.cli import main, parse_static_args
from tfbus.messages import TFMessage

COMMANDS = ["bag-info", "echo", "monitor", "frames", "static-transform", "replay",
            "robot-state-publisher", "joint-states", "demo", "view", "doctor"]


def test_group_help_lists_commands() -> None:
    code, out, _ = run("--help")
    assert code == 0
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_has_help_with_examples(command: str) -> None:
    code, out, _ = run(command, "--help")
    assert code == 0
    assert "Examples:" in out and f"tfbus {command}" in out


def test_version() -> None:
    from importlib.metadata import version

    from tfbus.core import _select

    code, out, _ = run("--version")
    assert code == 0
    core = "compiled core" if _select.COMPILED else "pure-Python core: "
    assert out.startswith(f"tfbus {version('tfbus')} ({core}")
    assert out == f"tfbus {version('tfbus')} ({_select.core_description()})\n"


def test_version_of_a_source_tree_that_is_not_installed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Without package metadata, tfbus._version (the one source of the version) says
    ``0+unknown`` rather than a stale number, and --version shows that."""
    import importlib
    import importlib.metadata

    import tfbus._version

    def not_installed(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    try:
        importlib.reload(tfbus._version)
        code, out, _ = run("--version")
        assert (code, out.split(" (")[0]) == (0, "tfbus 0+unknown")
    finally:
        monkeypatch.undo()
        importlib.reload(tfbus._version)
    code, out, _ = run("--version")
    assert (code, out.split(" (")[0]) == (0, f"tfbus {importlib.metadata.version('tfbus')}")


def test_unknown_command_and_option_are_one_line() -> None:
    code, _, err = run("nope")
    assert_usage_error(code, err, "nope")
    code, _, err = run("bag-info", "--bogus", str(TURTLE))
    assert_usage_error(code, err, "--bogus")


@pytest.mark.parametrize("command", ["echo", "monitor", "frames"])
def test_bus_option_is_documented(command: str) -> None:
    code, out, _ = run(command, "--help")
    assert code == 0
    assert "--bus SPEC" in out and "--bus zenoh" in out and "--duration" in out


def test_bus_argument_errors() -> None:
    pytest.importorskip("zenoh")
    code, _, err = run("monitor", "--bag", str(TURTLE), "--bus", "zenoh")
    assert_usage_error(code, err, "not both")
    code, _, err = run("echo", "a", "b", "--bus", "carrier-pigeon")
    assert_usage_error(code, err, "unsupported bus")
    code, _, err = run("monitor", "--bus", "zenoh?bogus=1")
    assert_usage_error(code, err, "bogus")
    code, _, err = run("monitor", "--bag", str(TURTLE), "--duration", "1")
    assert_usage_error(code, err, "--duration applies to --bus")
    code, _, err = run("frames", "--bag", str(TURTLE), "--wait", "1", "-o", "x.gv")
    assert_usage_error(code, err, "--bus")
    code, _, err = run("echo", "world", "turtle1", "--bag", str(TURTLE), "--duration", "1")
    assert_usage_error(code, err, "--bus")


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.anyio
async def test_bus_source_collects_attributes_and_sees_a_broadcaster_go() -> None:
    """BusSource in process, against a broadcaster on a second Zenoh session (127.0.0.1
    only, bounded waits); the subprocess versions are in tests/cli/test_three_terminals.py."""
    pytest.importorskip("zenoh")
    import anyio
    import anyio.abc

    from tfbus.broadcaster import StaticTransformBroadcaster, TransformBroadcaster
    from tfbus.bus import Bus
    from tfbus.cli import BusSource
    from tfbus.cli.monitor import liveliness_table
    from tfbus.messages import Header, Transform, TransformStamped, Vector3
    from tfbus.transports.zenoh import ZenohTransport

    port = _free_port()
    events: list[tuple[str, str]] = []
    src = BusSource(f"zenoh?connect=tcp/127.0.0.1:{port}", name="test-monitor")
    assert src.name == "test-monitor" and src.label.startswith("the bus")
    publisher = ZenohTransport(listen=f"tcp/127.0.0.1:{port}", name="robot_tf_publisher")
    stop = anyio.Event()

    async def broadcaster(*, task_status: anyio.abc.TaskStatus[Bus]) -> None:
        async with Bus(transport=publisher) as bus:
            await StaticTransformBroadcaster(bus).send_transform(
                parse_static_args(["0", "0", "1", "0", "0", "0", "base_link", "camera"])
            )
            task_status.started(bus)
            await stop.wait()

    async with anyio.create_task_group() as tg:
        bus: Bus = await tg.start(broadcaster)
        async with src.attach(lambda what, info: events.append((what, info.name))):
            tf = TransformBroadcaster(bus)

            def laser(ns: int) -> TransformStamped:
                return TransformStamped(Header(Time.from_ns(ns), "base_link"), "base_laser",
                                        Transform(Vector3(0.1, 0.0, 0.2)))

            with anyio.fail_after(15):
                ns = 1
                while ("alive", "robot_tf_publisher") not in events or not src.buffer(
                ).can_transform("camera", "base_laser", Time(0)):
                    await tf.send_transform(laser(ns))
                    ns += 1
                    await anyio.sleep(0.02)
                for _ in range(30):  # now attributed: the majority is the broadcaster
                    await tf.send_transform(laser(ns))
                    ns += 1
                    await anyio.sleep(0.005)
                while src.summary().frames["base_laser"].count < ns - 1 - 5:
                    await anyio.sleep(0.02)
            s = src.summary()
            # The live source is a TransformListener feeding the Buffer and
            # tfbus.monitor's statistics, not a second feed loop.
            from tfbus.listener import TransformListener

            assert isinstance(src.listener, TransformListener)
            assert src.listener.statistics().stored >= s.transform_count - 1
            assert s.frames["base_laser"].authority == "robot_tf_publisher"
            assert s.frames["camera"].static
            got = src.buffer().lookup_transform("base_link", "base_laser", Time(0))
            assert got.transform.translation.z == 0.2
            assert [p.name for p in src.alive_broadcasters().values()] == ["robot_tf_publisher"]
            stop.set()  # the broadcaster goes away
            with anyio.fail_after(10):
                while ("gone", "robot_tf_publisher") not in events:
                    await anyio.sleep(0.02)
            assert not src.alive_broadcasters()
            assert [p.name for p in src.gone.values()] == ["robot_tf_publisher"]
            assert liveliness_table(src).row_count == 1
    assert src.transport is None and not src.alive_broadcasters()


def test_main_returns_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bag-info", str(TURTLE)]) == 0
    assert main(["echo", "world"]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith("tfbus echo: error: ")
    assert main(["--help"]) == 0


def test_installed_entry_point() -> None:
    exe = Path(sys.executable).parent / "tfbus"
    if not exe.exists():
        pytest.skip("the tfbus entry point is not installed in this environment")
    proc = subprocess.run([str(exe), "bag-info", str(TURTLE)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "/tf 2688, /tf_static 1" in proc.stdout
    proc = subprocess.run([str(exe), "echo", "world"], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "tfbus echo: error: Missing argument 'TARGET'."


def test_log_lines_from_peers_are_literal() -> None:
    """The live source's log lines (a peer's bad transform) are escaped."""
    import logging

    from tfbus.cli._common import SafeLogFormatter

    record = logging.LogRecord("tfbus.listener", logging.WARNING, __file__, 1,
                               "ignoring a transform on %s: %s", ("/tf", "\x1b[2J bad"), None)
    assert SafeLogFormatter("%(message)s").format(record) == (
        "ignoring a transform on /tf: \\x1b[2J bad"
    )


def test_one_rate_definition_across_tools(tmp_path: Path) -> None:
    """frames, monitor and bag-info give the same rate on a bag with
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


def _python(code: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          timeout=timeout, check=False, cwd=ROOT)


def _without(module: str, argv: Sequence[str]) -> subprocess.CompletedProcess[str]:
    """``tfbus ARGV`` in a child where importing ``module`` fails as if not installed."""
    return _python(f"import sys; sys.modules[{module!r}] = None\n"
                   "from tfbus.cli import main\nsys.exit(main(sys.argv[1:]))", *argv)


def test_missing_click_names_the_extra() -> None:
    """``tfbus`` without click: one line naming tfbus[cli]."""
    proc = _without("click", ["--help"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    from tfbus._extras import extra_advice

    assert proc.stderr.strip() == (
        f"tfbus: error: the command line needs the 'click' package: "
        f"{extra_advice('click', 'cli')}"
    )


def test_missing_rosbags_names_the_extra(tmp_path: Path) -> None:
    """Reading an .mcap without rosbags: one line naming tfbus[bag]."""
    folder = tmp_path / "b"
    write_bag(folder, [BagMessage(Time.from_ns(T0), "/tf", TFMessage([tf("a", "b", T0)]), "")],
              format="mcap")
    mcap = next(folder.glob("*.mcap"))
    proc = _without("rosbags", ["bag-info", str(mcap)])
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'tfbus[bag]'" in lines[0]


@pytest.mark.parametrize("loop", ["trio", "uvloop"])
def test_missing_event_loop_package_is_one_line(loop: str) -> None:
    """--backend trio without trio, --backend uvloop without uvloop: one line saying what
    to install."""
    proc = _without(loop, ["demo", "--backend", loop, "--duration", "0"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (
        f"tfbus demo: error: --backend {loop} needs the '{loop}' package: pip install {loop}"
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


def test_sigterm_ends_commands_cleanly() -> None:
    """SIGTERM ends a long-running command as Ctrl-C does: no
    traceback, a clean exit status."""
    code, out, err = _sigterm_after_first_line(
        "static-transform", "0", "0", "1", "0", "0", "0", "world", "cam", "--local")
    assert out.startswith("publishing static transform world -> cam")
    assert code == 0 and "Traceback" not in err, err
    code, out, err = _sigterm_after_first_line("demo", "--duration", "60")
    assert code in (0, 130) and "Traceback" not in err, err
    assert "summary:" in out


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
    """Fuzzing: every command on damaged, empty and missing bags: a one-line
    error (or warning after what was readable), a non-zero exit, never a traceback."""
    failures = 0
    for name, path in damaged_inputs.items():
        for args in _commands(str(path), "world", "turtle1", tmp_path):
            code, out, err = run(*args)
            _check(args, code, out, err)
            # (version-only.bag: an error once tfbus.bag reports it as one)
            if name in ("missing.bag", "empty.bag", "text.bag", "junk.mcap"):
                assert code != 0, (args, out)
            failures += code != 0
    assert failures > 0


def test_fuzz_every_command_on_hostile_ids(hostile_bag: Path, tmp_path: Path) -> None:
    """Fuzzing: every command with every hostile id (as argument and in the
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
def test_bad_bus_values_are_one_line_usage_errors(
    spec: str, said: str, command: list[str]
) -> None:
    """A --bus value the transport refuses printed a traceback (exit
    status 1) when the bus was opened, and port=99999 was accepted; each is now one
    line naming the spec and the value, exit status 2, before anything runs."""
    pytest.importorskip("zenoh" if spec.startswith("zenoh") else
                        "cyclonedds" if spec.startswith("ros2") else "rosbags")
    code, out, err = run(command[0], "--bus", spec, *command[1:])
    assert code == 2, (out, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"--bus {spec!r}: " in err and said in err, err


def test_zenoh_port_out_of_range_is_refused_by_the_library() -> None:
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
