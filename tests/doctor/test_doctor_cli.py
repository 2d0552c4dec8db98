"""``tfbus doctor --bag``: the table, ``--json`` (valid against the documented schema),
the exit status by ``--fail-on``, hostile frame ids and senders printed literally, a
damaged bag as a finding without a traceback, and the options that only apply live."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from click.testing import CliRunner
from doctor_faults import T0, clean, clock_offset, rate_drop, tf, write_ros1

from tfbus.cli import cli
from tfbus.doctor import REPORT_SCHEMA

DOCS = Path(__file__).resolve().parents[2] / "docs" / "doctor.md"
# Control characters that must never reach a terminal (newline excepted).
RAW_CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, ["doctor", *args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("doctor")
    return {"clean": write_ros1(d / "clean.bag", clean()),
            "clock": write_ros1(d / "clock.bag", clock_offset()),
            "drop": write_ros1(d / "drop.bag", rate_drop())}


def test_a_clean_bag_exits_0_and_says_so(bags: dict[str, Path]) -> None:
    code, out, err = run("--bag", str(bags["clean"]), "--fail-on", "info")
    assert (code, err) == (0, "")
    assert "601 messages, 602 transforms, 5 frames (4 links)" in out
    assert "no problems found" in out
    assert "/odometry" in out  # the broadcasters' delays table


def test_the_table_names_check_frames_and_sender(bags: dict[str, Path]) -> None:
    code, out, _ = run("--bag", str(bags["clock"]))
    assert code == 1  # an error, --fail-on error by default
    assert "1 error, 0 warnings, 0 infos" in out
    row = next(line for line in out.splitlines() if "clock_offset" in line)
    cells = [c.strip() for c in row.split("│")]
    assert cells[:4] == ["error", "clock_offset", "base_link", "/odometry"]
    assert "0.300 s ahead" in cells[5]


@pytest.mark.parametrize(("fail_on", "clock", "drop"), [
    ("error", 1, 0), ("warning", 1, 1), ("info", 1, 1), ("never", 0, 0)])
def test_exit_status_by_fail_on(bags: dict[str, Path], fail_on: str, clock: int,
                                drop: int) -> None:
    """clock.bag has an error, drop.bag a warning (a rate drop)."""
    assert run("--bag", str(bags["clock"]), "--fail-on", fail_on)[0] == clock
    assert run("--bag", str(bags["drop"]), "--fail-on", fail_on)[0] == drop


def test_json_validates_against_the_schema(bags: dict[str, Path]) -> None:
    import jsonschema

    code, out, _ = run("--bag", str(bags["drop"]), "--json", "--fail-on", "never")
    assert code == 0
    doc = json.loads(out)
    jsonschema.validate(doc, REPORT_SCHEMA)
    assert doc["counts"] == {"error": 0, "warning": 1, "info": 0}
    (finding,) = doc["findings"]
    assert (finding["check"], finding["frames"], finding["senders"]) == (
        "rate_drop", ["base_link", "odom"], ["/odometry"])


def test_the_documented_schema_is_the_module_s() -> None:
    """docs/doctor.md shows REPORT_SCHEMA as it is (the JSON block after 'JSON schema')."""
    text = DOCS.read_text(encoding="utf-8")
    block = text.split("## JSON schema", 1)[1].split("```json", 1)[1].split("```", 1)[0]
    assert json.loads(block) == REPORT_SCHEMA


def test_hostile_ids_are_printed_literally(tmp_path: Path) -> None:
    """Frame ids and a sender that are rich markup or terminal escapes: printed as
    text, no control character reaches the terminal, the JSON escapes them too."""
    evil_frame = "\x1b]0;pwned\x07[bold red]x[/]"
    evil_sender = "[blink]n\x1b[2J"
    recs = [(T0 + k * 10**8, "/tf", evil_sender, [tf("map", evil_frame, T0 + k * 10**8)])
            for k in range(20)]
    recs += [(T0 + k * 10**8 + 1, "/tf", "/other", [tf("map", evil_frame, T0 + k * 10**8 + 7)])
             for k in range(20)]
    path = write_ros1(tmp_path / "evil.bag", recs)
    code, out, err = run("--bag", str(path))
    assert code == 1 and err == ""
    assert not RAW_CONTROL.search(out)
    assert "\\x1b]0;pwned\\x07[bold red]x[/]" in out and "[blink]n\\x1b[2J" in out
    code, out, _ = run("--bag", str(path), "--json")
    assert not RAW_CONTROL.search(out)
    doc = json.loads(out)
    assert doc["findings"][0]["frames"][0] == evil_frame
    assert evil_sender in doc["findings"][0]["senders"]


def test_a_damaged_bag_is_a_finding_not_a_traceback(bags: dict[str, Path],
                                                    tmp_path: Path) -> None:
    data = bags["clean"].read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 3])
    code, out, err = run("--bag", str(cut))
    assert code == 1 and "Traceback" not in out + err
    row = next(line for line in out.splitlines() if "damaged_recording" in line)
    assert row.split("│")[0].strip() == "error"
    code, out, _ = run("--bag", str(cut), "--json", "--fail-on", "never")
    assert code == 0
    assert [f["check"] for f in json.loads(out)["findings"]] == ["damaged_recording"]


def test_not_a_bag_and_live_only_options_are_usage_errors(bags: dict[str, Path],
                                                          tmp_path: Path) -> None:
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all")
    for args, needle in [
        (("--bag", str(junk)), "unknown format"),
        (("--bag", str(bags["clean"]), "--duration", "3"), "--duration applies to --bus"),
        (("--bag", str(bags["clean"]), "--use-sim-time"), "--use-sim-time applies to --bus"),
        (("--bag", str(bags["clean"]), "--bus", "memory"), "not both"),
        (("--bag", str(bags["clean"]), "--fail-on", "fatal"), "fatal"),
    ]:
        code, _, err = run(*args)
        assert code == 2, args
        lines = err.strip().splitlines()
        assert needle in lines[-1], err
        assert "Traceback" not in err


@pytest.mark.parametrize("sim", [(), ("--use-sim-time",)])
def test_a_quiet_live_bus_is_a_clean_report(sim: tuple[str, ...]) -> None:
    """The in-process bus, nothing published: --duration bounds the wait, the report
    says 0 messages and the exit status is 0 (with --use-sim-time too)."""
    code, out, err = run("--bus", "memory", "--duration", "0.2", "--json", *sim)
    assert code == 0, err
    doc = json.loads(out)
    assert (doc["source"], doc["messages"], doc["findings"]) == ("memory", 0, [])


def test_the_documented_checks_are_the_module_s() -> None:
    """docs/doctor.md's table has one row per check, with its rule and reference."""
    from tfbus.doctor import CHECKS

    text = DOCS.read_text(encoding="utf-8")
    section = text.split("## The checks", 1)[1].split("## Thresholds", 1)[0]
    rows = [line for line in section.splitlines() if re.match(r"^\| `\w+` \| ", line)]
    documented = {line.split("`")[1]: line for line in rows if line.split("`")[1] in CHECKS}
    assert set(documented) == set(CHECKS)
    for name, check in CHECKS.items():
        assert documented[name] == f"| `{name}` | {check.rule} | {check.reference} |"
