"""Every option and argument of every ``tfbus`` command, given values that are not
numbers, not finite, huge, tiny, empty or malformed: a one-line usage error (exit status
2), or a clean run, or a clean one-line error; never a traceback, never a hang.

The commands and their parameters are found by walking the click command tree, so a new
command or option is swept without editing this file; a new command only needs a base
invocation in :data:`BASES` (the test says so when one is missing).
"""

from __future__ import annotations

import concurrent.futures
import math
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from cli_support import ROOT, TURTLE
from click.testing import CliRunner

from tfbus.cli import cli

VALUES = ("nan", "inf", "-inf", "1e300", "1e-300", "", "garbage", "-1")
"""What every parameter is given: non-finite, huge, tiny, empty, malformed, negative."""

URDF = ROOT / "demos" / "robot.urdf"
ONE_LINE = re.compile(r"^tfbus( [a-z-]+)*: (error|warning): ")

SERVERS = {"view", "web"}
"""Commands that serve until a signal (no ``--duration``): run in a subprocess, ended by
SIGTERM once they said they serve."""


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[str]]:
    """A short, bounded invocation of each command (after ``tfbus``), every parameter
    valid: a bag, an in-process bus, or Zenoh on 127.0.0.1 and a short ``--duration``."""
    out = tmp_path_factory.mktemp("sweep")
    zenoh = f"zenoh?port={_free_port()}"
    bag = str(TURTLE)
    return {
        "bag-info": [bag],
        "echo": ["world", "turtle1", "--bag", bag, "-n", "1"],
        "monitor": ["--bag", bag],
        "frames": ["--bag", bag, "-o", str(out / "f.gv")],
        "static-transform": ["0", "0", "1", "0", "0", "0", "world", "cam", "--once", "--local"],
        "replay": [bag, "--rate", "0", "-q", "--local"],
        "robot-state-publisher": [str(URDF), "--local", "--duration", "0"],
        "joint-states": [str(URDF), "--local", "--duration", "0"],
        "demo": ["--duration", "0"],
        "demo broadcaster": ["--bus", zenoh, "--duration", "0"],
        "demo listener": ["--bus", zenoh, "--duration", "0"],
        "demo laser": ["--duration", "0"],
        "view": ["--bag", bag, "--port", "0"],
        "router": ["--listen", f"tcp/127.0.0.1:{_free_port()}", "--duration", "0.05"],
        "serve-buffer": ["--bus", zenoh, "--duration", "0.05"],
        "doctor": ["--bag", bag],
        "lookup": ["--bag", bag, "--target", "world", "--source", "turtle1", "--every", "1",
                   "-o", str(out / "poses.parquet"), "-q"],
        "web": ["--bag", bag, "--port", "0"],
    }


def _leaves(group: click.Group, prefix: tuple[str, ...] = ()) -> Iterator[
        tuple[tuple[str, ...], click.Command]]:
    for name, cmd in group.commands.items():
        yield (*prefix, name), cmd
        if isinstance(cmd, click.Group):
            yield from _leaves(cmd, (*prefix, name))


def _positions(cmd: click.Command, base: list[str]) -> dict[str, list[int]]:
    """Indices in ``base`` of each argument's tokens (the positionals come first)."""
    n_pos = next((i for i, tok in enumerate(base) if tok.startswith("-")), len(base))
    out: dict[str, list[int]] = {}
    i = 0
    for p in cmd.params:
        if isinstance(p, click.Argument):
            take = n_pos - i if p.nargs == -1 else p.nargs
            out[p.name or ""] = list(range(i, min(i + take, n_pos)))
            i += len(out[p.name or ""])
    return out


def _cases(bases: dict[str, list[str]]) -> Iterator[tuple[str, str, list[str]]]:
    """(command, parameter, full argv) for every parameter of every command x VALUES."""
    for path, cmd in _leaves(cli):
        name = " ".join(path)
        assert name in bases, f"give 'tfbus {name}' a base invocation in BASES"
        base = bases[name]
        positions = _positions(cmd, base)
        for p in cmd.params:
            if isinstance(p, click.Option) and (p.is_flag or p.name in ("help", "version")):
                continue
            for value in VALUES:
                if isinstance(p, click.Argument):
                    for i in positions[p.name or ""]:
                        argv = list(base)
                        argv[i] = value
                        # "--" keeps "-1" and "-inf" values of arguments (else options)
                        n_pos = len([j for j in range(len(base)) if
                                     any(j in v for v in positions.values())])
                        yield name, p.name or "", [*path, *argv[n_pos:], "--",
                                                   *argv[:n_pos]]
                    continue
                argv = list(base)
                if p.opts[0] in ("--bus",):  # a bus instead of the bag / in-process bus
                    for flag, has_value in (("--bag", True), ("--local", False)):
                        if flag in argv:
                            k = argv.index(flag)
                            del argv[k:k + 1 + has_value]
                present = [k for k, tok in enumerate(argv) if tok in p.opts]
                if present:
                    argv[present[0] + 1] = value
                else:
                    argv += [p.opts[0], value]
                yield name, p.opts[0], [*path, *argv]


def _check(argv: list[str], code: int, out: str, err: str) -> None:
    assert "Traceback" not in out + err, (argv, err[-2000:])
    if code != 0:
        assert code in (1, 2), (argv, code, err)
        lines = [line for line in err.strip().splitlines() if line.strip()]
        assert lines and ONE_LINE.match(lines[-1]), (argv, code, err)


def _run_server(argv: list[str], cwd: Path = ROOT) -> tuple[int, str]:
    """``tfbus ARGV`` in a subprocess in ``cwd`` (a value taken as an output path, such
    as ``view --record``'s, lands there): ended by SIGTERM once it prints its address
    (bounded by a watchdog), or its own exit; (status, stderr)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    proc = subprocess.Popen([sys.executable, "-m", "tfbus.cli", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(60.0, proc.kill)
    watchdog.start()
    try:
        assert proc.stderr is not None
        err_lines = []
        for line in proc.stderr:  # EOF: it exited on its own
            err_lines.append(line)
            if line.startswith(("tfbus view: http://", "tfbus web: ws://")):
                proc.send_signal(signal.SIGTERM)
                break
        out, rest = proc.communicate(timeout=60)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, "".join(err_lines) + rest + out


def test_every_option_of_every_command_on_bad_values(
        bases: dict[str, list[str]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each parameter x nan, inf, -inf, 1e300, 1e-300, '', 'garbage', -1: exit status 2
    with one ``tfbus CMD: error:`` line, or a clean run / clean one-line error (1, 2);
    no traceback. A server command whose options pass serves and ends at SIGTERM."""
    monkeypatch.chdir(tmp_path)  # a value taken as an output path lands here, not in the repo
    runner = CliRunner()
    cases = list(_cases(bases))
    assert len(cases) > 300
    servers: dict[str, list[list[str]]] = {}
    refused = 0
    for name, param, argv in cases:
        if name in SERVERS:
            try:
                cli.commands[name].make_context(name, argv[1:])
            except click.ClickException:
                pass  # refused while parsing: in process below
            else:
                # a server takes seconds to start: two values per parameter
                # (the values a text option takes alike are all just text)
                servers.setdefault(param, []).append(argv)
                continue
        result = runner.invoke(cli, argv, catch_exceptions=True)
        exc = result.exception
        assert exc is None or isinstance(exc, SystemExit), (argv, repr(exc))
        _check(argv, result.exit_code, result.stdout, result.stderr)
        refused += result.exit_code == 2
    assert refused > 200
    started = [argv for runs in servers.values() for argv in (runs[0], runs[-1])]
    assert 0 < len(started) < 20
    with concurrent.futures.ThreadPoolExecutor(max_workers=4) as pool:
        folders = [tmp_path / f"server{k}" for k in range(len(started))]
        for folder in folders:  # one each: what one writes is not another's input
            folder.mkdir()
        runs = pool.map(_run_server, started, folders)
        for argv, (code, err) in zip(started, runs, strict=True):
            _check(argv, code, "", err)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e300", "", " ", "1e10", "-1", "0"])
@pytest.mark.parametrize(("argv", "option"), [
    (["view", "--bag", str(TURTLE), "--frame-timeout"], "--frame-timeout"),
    (["serve-buffer", "--cache-time"], "--cache-time"),
    (["monitor", "--duration"], "--duration"),
    (["router", "--duration"], "--duration"),
    (["echo", "a", "b", "--rate"], "--rate"),
    (["joint-states", str(URDF), "--local", "--rate"], "--rate"),
])
def test_non_finite_huge_and_empty_numbers_are_usage_errors(
    argv: list[str], option: str, value: str
) -> None:
    """The values that printed a traceback (``view --frame-timeout nan``, ``serve-buffer
    --cache-time 1e300``, ``monitor --duration nan``, ``joint-states --rate inf``) and
    their kin: one line naming the option, exit status 2, before anything runs."""
    result = CliRunner().invoke(cli, [*argv, value], catch_exceptions=False)
    assert result.exit_code == 2, (argv, value, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and ONE_LINE.match(lines[0]), result.stderr
    assert f"'{option}'" in lines[0], lines[0]


def test_rates_and_seconds_types() -> None:
    """The shared types: seconds in (0, 1e9], rates in [1e-9, 1e6] Hz; nan and inf never."""
    from tfbus.cli._common import MAX_HZ, MAX_SECONDS, FiniteFloat, hertz, seconds

    assert seconds().convert("2.5", None, None) == 2.5
    assert seconds().convert(str(MAX_SECONDS), None, None) == MAX_SECONDS
    assert seconds(zero=True).convert("0", None, None) == 0.0
    assert hertz().convert("1e-9", None, None) == 1e-9
    assert hertz().convert(str(MAX_HZ), None, None) == MAX_HZ
    for t, bad in ((seconds(), "0"), (seconds(), "1.5e9"), (seconds(zero=True), "-0.5"),
                   (hertz(), "1e-10"), (hertz(), "1e7"), (FiniteFloat(), "nan"),
                   (FiniteFloat(), "inf"), (FiniteFloat(), "-inf"), (FiniteFloat(), "")):
        with pytest.raises(click.BadParameter):
            t.convert(bad, None, None)
    assert math.isclose(1.0 / MAX_SECONDS, 1e-9)


def test_replay_at_a_rate_that_would_take_longer_than_max_seconds() -> None:
    """``replay --rate 1e-300``: a usage error giving the time it would take (the
    replay's due time overflowed int64 nanoseconds, a traceback)."""
    result = CliRunner().invoke(cli, ["replay", str(TURTLE), "--local", "-q", "--rate",
                                      "1e-300"], catch_exceptions=False)
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        "tfbus replay: error: --rate 1e-300: replaying 21.499 s of bag time would take "
        "2.15e+301 s, more than 1e+09 s")


@pytest.mark.parametrize(("argv", "said"), [
    (["--listen", "garbage"], "--listen 'garbage': a Zenoh endpoint is PROTOCOL/ADDRESS"),
    (["--listen", ""], "--listen '': a Zenoh endpoint is PROTOCOL/ADDRESS"),
    (["--connect", "127.0.0.1:7447"], "--connect '127.0.0.1:7447': a Zenoh endpoint is"),
])
def test_router_malformed_endpoints_are_usage_errors(argv: list[str], said: str) -> None:
    """``router --listen garbage`` printed Zenoh's traceback; now one line, status 2."""
    pytest.importorskip("zenoh")
    result = CliRunner().invoke(cli, ["router", *argv, "--duration", "0.05"],
                                catch_exceptions=False)
    assert result.exit_code == 2
    assert result.stderr.startswith(f"tfbus router: error: {said}"), result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(("text", "said"), [
    ("{", "expected identifier or string"),
    ("{mode: 5}", "invalid type: integer `5`"),
])
def test_router_malformed_config_file_is_a_usage_error(
    tmp_path: Path, text: str, said: str
) -> None:
    """``router --config BAD.json5``: Zenoh's complaint on one line, no Rust source
    location, status 2."""
    pytest.importorskip("zenoh")
    path = tmp_path / "bad.json5"
    path.write_text(text)
    result = CliRunner().invoke(cli, ["router", "--config", str(path), "--duration", "0.05"],
                                catch_exceptions=False)
    assert result.exit_code == 2, result.stderr
    line = result.stderr.strip()
    assert line.startswith("tfbus router: error: invalid Zenoh router configuration: ")
    assert said in line and "\n" not in line and ".cargo" not in line and ".rs:" not in line
