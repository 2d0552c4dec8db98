"""Every command that reads one bag (``bag-info``, ``frames``, ``monitor``, ``doctor``,
``view``, ``web``) answers a file that is not a readable bag with one ``tfbus CMD: error:``
line and exit status 2, before it starts anything: a file of unknown format, and an MCAP
file not named ``*.mcap`` (rosbags opens a bare MCAP file by its suffix). ``lookup``, which
reads many, names each such file in a warning, goes on with the others and exits 1."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("click")
pytest.importorskip("rich")
pytest.importorskip("rosbags")

from cli_support import NAV2, assert_usage_error, run

COMMANDS = [
    ("bag-info", "{}"),
    ("frames", "--bag {}"),
    ("monitor", "--bag {}"),
    ("doctor", "--bag {}"),
    ("view", "--bag {} --port 0"),
    ("web", "--bag {} --port 0"),
]


@pytest.mark.parametrize(("command", "args"), COMMANDS, ids=[c for c, _ in COMMANDS])
@pytest.mark.parametrize("kind", ["unknown", "misnamed_mcap"])
def test_a_file_that_is_not_a_readable_bag_is_one_error_line(
        tmp_path: Path, command: str, args: str, kind: str) -> None:
    if kind == "unknown":
        bag = tmp_path / "junk.mcap"
        bag.write_bytes(b"not a bag at all")
        needle = "unknown format"
    else:
        bag = tmp_path / "recording.bin"
        bag.write_bytes(NAV2.read_bytes())
        needle = "must be named *.mcap"
    argv = args.format(bag, out=tmp_path / "poses.parquet").split()
    code, _, err = run(command, *argv)
    assert "Traceback" not in err
    assert_usage_error(code, err, str(bag), needle)


@pytest.mark.parametrize("kind", ["unknown", "misnamed_mcap"])
def test_lookup_names_each_unreadable_recording_and_goes_on(tmp_path: Path, kind: str) -> None:
    good = tmp_path / "good.mcap"
    good.write_bytes(NAV2.read_bytes())
    bad = tmp_path / ("junk.mcap" if kind == "unknown" else "recording.bin")
    bad.write_bytes(b"not a bag at all" if kind == "unknown" else NAV2.read_bytes())
    needle = "unknown format" if kind == "unknown" else "must be named *.mcap"
    out_path = tmp_path / "poses.parquet"
    code, out, err = run("lookup", "--bag", str(bad), "--bag", str(good), "--target", "map",
                         "--source", "base_link", "--every", "1", "-o", str(out_path), "--quiet")
    text = out + err
    assert code == 1 and "Traceback" not in text
    assert any(str(bad) in line and needle in line and line.startswith("tfbus lookup: warning:")
               for line in text.splitlines()), text
    assert "1 recording(s) could not be read whole" in err
    assert out_path.exists()
