"""``tfbus lookup``: a folder of recordings to one Parquet table of poses, every row the
whole file's ``lookup_transform`` where it answers; bad arguments and damaged files."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("rosbags")

from click.testing import CliRunner  # noqa: E402
from table_recordings import SEC, START, write, write_mcap  # noqa: E402

from tfbus import Time, TransformException  # noqa: E402
from tfbus.bag import load_buffer  # noqa: E402
from tfbus.cli import cli  # noqa: E402


def run(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(cli, list(args), catch_exceptions=False)
    return result.exit_code, result.stderr


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("fleet")
    write(d, "a", "ros1", seed=1, seconds=25)
    write(d, "b", "sqlite3", seed=2, seconds=25)
    write_mcap(d / "c.mcap", seed=3, seconds=25)
    shutil.rmtree(d / "c_ros2")  # (write_mcap's intermediate ROS 2 bag)
    return d


def test_a_folder_of_recordings_becomes_one_parquet_table(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "poses.parquet"
    code, err = run("lookup", "--bag", str(folder / "*"), "--target", "map",
                    "--source", "laser", "--every", "0.1", "-o", str(out),
                    "--window", "7", "--margin", "6")
    assert code == 0, err
    assert "recordings" in err or "lookup" in err  # the progress bar, on stderr
    table = pq.read_table(out)
    assert table.column_names[:4] == ["recording", "target_frame", "source_frame", "stamp"]
    names = sorted(set(table.column("recording").to_pylist()))
    assert [Path(n).name for n in names] == ["a.bag", "b", "c.mcap"]
    for name in names:
        rows = table.filter(pa.compute.equal(table.column("recording"), name)).to_pylist()
        stamps = [r["stamp"] for r in rows]
        first = stamps[0]
        # Every 0.1 s from the first /tf message to the last, each once, in order.
        assert stamps == list(range(first, first + len(stamps) * SEC // 10, SEC // 10))
        assert 240 <= len(stamps) <= 250
        whole = load_buffer(name)
        answered = 0
        for r in rows:
            try:
                ts = whole.lookup_transform("map", "laser", Time.from_ns(r["stamp"]))
            except TransformException as exc:
                assert r["status"] == type(exc).__name__
                continue
            (x, y, z), (qx, qy, qz, qw) = ts.transform
            assert r["status"] == "ok" and r["message"] is None
            assert (r["x"], r["y"], r["z"], r["qx"], r["qy"], r["qz"], r["qw"]) == (
                x, y, z, qx, qy, qz, qw)
            answered += 1
        assert answered >= 230


def test_no_match_and_a_damaged_file(folder: Path, tmp_path: Path) -> None:
    code, err = run("lookup", "--bag", str(tmp_path / "none*.mcap"), "--target", "map",
                    "--source", "laser", "--every", "1", "-o", str(tmp_path / "x.parquet"))
    assert code == 2
    assert "matches no file or folder" in err
    code, err = run("lookup", "--bag", str(folder / "a.bag"), "--target", "map",
                    "--source", "laser", "--every", "0", "-o", str(tmp_path / "x.parquet"))
    assert code == 2
    assert "--every" in err
    cut = tmp_path / "cut.bag"
    data = (folder / "a.bag").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    out = tmp_path / "cut.parquet"
    code, err = run("lookup", "--bag", str(cut), "--bag", str(folder / "c.mcap"),
                    "--target", "map", "--source", "laser", "--every", "0.5", "-o", str(out),
                    "-q")
    assert code == 1
    assert "Traceback" not in err
    assert "warning: 1 recording(s) could not be read whole" in err
    table = pq.read_table(out)
    by_file = {Path(n).name for n in table.column("recording").to_pylist()}
    # The readable part of the damaged file (before the cut) and the whole other one.
    assert by_file == {"cut.bag", "c.mcap"}
    cut_stamps = np.array([r["stamp"] for r in table.to_pylist()
                           if r["recording"].endswith("cut.bag")])
    assert cut_stamps.size and int(cut_stamps.max()) < START + 20 * SEC


DATA = Path(__file__).resolve().parents[1] / "data"
NAV2 = DATA / "nav2_like.mcap"
"""A Nav2-like recording in simulated time: header stamps 928-987 s, received at
1.78e9 s (tests/data/README.md)."""


def _tf_stamps(path: Path) -> np.ndarray:
    """Every header stamp of the recording's /tf transforms, read message by message."""
    from tfbus.bag import read_messages

    return np.array([ts.header.stamp.ns for rec in read_messages(path, topics=("/tf",))
                     for ts in rec.message.transforms], dtype=np.int64)


def test_the_grid_follows_the_header_stamps_of_a_simulated_time_recording(
        tmp_path: Path) -> None:
    """docs/table.md's command on the repository's Nav2-like recording: one row every
    0.5 s from the first /tf header stamp to the last (simulated time, 928-987 s, not
    the 1.78e9 s receive times), each row the whole file's lookup_transform."""
    out = tmp_path / "out.parquet"
    code, err = run("lookup", "--bag", str(NAV2), "--target", "map", "--source",
                    "base_link", "--every", "0.5", "-o", str(out))
    assert code == 0, err
    stamps = _tf_stamps(NAV2)
    first, last = int(stamps.min()), int(stamps.max())
    assert 900 * SEC < first < last < 1000 * SEC  # simulated time
    grid = list(range(first, last + 1, SEC // 2))
    table = pq.read_table(out)
    assert table.column("stamp").to_pylist() == grid
    whole = load_buffer(NAV2)
    answered = 0
    for r in table.to_pylist():
        try:
            ts = whole.lookup_transform("map", "base_link", Time.from_ns(r["stamp"]))
        except TransformException as exc:
            assert (r["status"], r["message"]) == (type(exc).__name__, str(exc))
            continue
        (x, y, z), (qx, qy, qz, qw) = ts.transform
        assert r["status"] == "ok"
        assert (r["x"], r["y"], r["z"], r["qx"], r["qy"], r["qz"], r["qw"]) == (
            x, y, z, qx, qy, qz, qw)
        answered += 1
    # map -> odom starts 0.093 s after the first stamp and ends 0.125 s before the last:
    # those two rows extrapolate, as tf2 says; every other row is answered.
    assert answered == len(grid) - 2 == 119
    assert f"{len(grid)} rows (2 not answered) from 1 recording -> " in err


def test_a_stray_stamp_adds_one_row_not_a_span(tmp_path: Path) -> None:
    """One /tf message stamped 10^6 s ahead of the others (a bogus header) gives the
    grid one more row at most, not 10^7 rows to fill the gap."""
    from table_recordings import messages, ts

    from tfbus.bag import TF_TOPIC, BagMessage, write_bag
    from tfbus.messages import TFMessage

    recorded = messages(seed=4, seconds=10)
    stray = START + 5 * SEC
    recorded.append(BagMessage(Time.from_ns(stray), TF_TOPIC, TFMessage([
        ts("odom", "wheel", stray + 10**6 * SEC, (0.0, 0.0, 0.0), 0.0)]), "/stray"))
    recorded.sort(key=lambda m: m.time.ns)
    bag = tmp_path / "stray.bag"
    write_bag(bag, recorded, format="ros1")
    out = tmp_path / "out.parquet"
    code, err = run("lookup", "--bag", str(bag), "--target", "map", "--source", "laser",
                    "--every", "0.1", "-o", str(out), "-q")
    assert code == 0, err
    stamps = pq.read_table(out).column("stamp").to_pylist()
    normal = sorted(s for s in _tf_stamps(bag).tolist() if s < stray + 1000 * SEC)
    assert len(range(normal[0], normal[-1] + 1, SEC // 10)) <= len(stamps) <= len(
        range(normal[0], normal[-1] + 1, SEC // 10)) + 1
    assert stamps == sorted(set(stamps))


def test_a_run_that_answers_nothing_exits_1_says_why_and_keeps_the_output(
        tmp_path: Path) -> None:
    out = tmp_path / "out.parquet"
    out.write_bytes(b"the previous run's table")
    code, err = run("lookup", "--bag", str(NAV2), "--target", "map", "--source",
                    "no_such_frame", "--every", "0.5", "-o", str(out))
    assert code == 1
    assert ("tfbus lookup: error: none of the 121 rows was answered; the first: "
            'LookupException: "no_such_frame" passed to lookupTransform argument '
            "source_frame does not exist.") in err
    assert f"121 rows (121 not answered) from 1 recording; {out} not written" in err
    assert out.read_bytes() == b"the previous run's table"
    assert [p.name for p in tmp_path.iterdir()] == ["out.parquet"]


def test_the_summary_of_a_truncated_recording_counts_what_was_read(
        folder: Path, tmp_path: Path) -> None:
    """Half of an MCAP of small chunks: its readable part is written and counted as read
    from one damaged recording, exit 1 with the damage named; a file that cannot be read
    at all is counted as not read."""
    cut = tmp_path / "cut.mcap"
    data = (folder / "c.mcap").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out.parquet"
    code, err = run("lookup", "--bag", str(cut), "--target", "map", "--source",
                    "laser", "--every", "0.5", "-o", str(out))
    assert code == 1
    table = pq.read_table(out)
    rows = table.num_rows
    failed = rows - table.column("status").to_pylist().count("ok")
    assert 0 < failed < rows < 50  # 25 s at 0.5 s: about half of the rows
    assert (f"{rows} rows ({failed} not answered) from 1 recording, 1 of them damaged "
            f"(read up to the damage) -> {out}") in err
    assert "warning: 1 recording(s) could not be read whole" in err
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a recording")
    code, err = run("lookup", "--bag", str(junk), "--bag", str(cut), "--target", "map",
                    "--source", "laser", "--every", "0.5", "-o", str(out))
    assert code == 1
    assert (f"{rows} rows ({failed} not answered) from 1 recording, 1 of them damaged "
            f"(read up to the damage), 1 of 2 not read -> {out}") in err
    assert "warning: 2 recording(s) could not be read whole" in err
    code, err = run("lookup", "--bag", str(junk), "--target", "map", "--source", "laser",
                    "--every", "0.5", "-o", str(out))
    assert code == 1
    assert "error: no row to answer: the recording could not be read" in err
    (tmp_path / "junk2.mcap").write_bytes(b"nor this")
    code, err = run("lookup", "--bag", str(tmp_path / "junk*.mcap"), "--target", "map",
                    "--source", "laser", "--every", "0.5", "-o", str(out))
    assert code == 1
    assert "error: no row to answer: no recording could be read" in err
    assert pq.read_table(out).num_rows == rows  # the first run's table, kept


@pytest.mark.parametrize("failure", [KeyboardInterrupt, MemoryError])
def test_a_run_stopped_midway_leaves_the_previous_output_and_no_partial_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, failure: type[BaseException]) -> None:
    """The first window's table is written, then the run stops (Ctrl-C, or any error):
    the output is the previous run's, and the temporary file beside it is gone."""
    import tfbus.table.recordings as recordings

    real = recordings.poses_every

    def stopping(*args: object, **kwargs: object) -> object:
        yield next(iter(real(*args, **kwargs)))  # type: ignore[arg-type]
        assert [p.name for p in tmp_path.iterdir()] != ["out.parquet"]  # the partial one
        raise failure()

    monkeypatch.setattr(recordings, "poses_every", stopping)
    out = tmp_path / "out.parquet"
    out.write_bytes(b"the previous run's table")
    result = CliRunner().invoke(cli, ["lookup", "--bag", str(NAV2), "--target", "map",
                                      "--source", "base_link", "--every", "0.5", "-o",
                                      str(out), "-q"])
    assert isinstance(result.exception, failure) or result.exit_code != 0
    assert out.read_bytes() == b"the previous run's table"
    assert [p.name for p in tmp_path.iterdir()] == ["out.parquet"]


def test_sigint_while_a_recording_is_being_opened_leaves_no_partial_file(
        tmp_path: Path) -> None:
    """A real Ctrl-C: the second recording is a FIFO no one writes, so ``tfbus lookup``
    waits in its open() (Linux: /proc/PID/wchan reads ``wait_for_partner``) after the
    first recording's rows went to the temporary file; SIGINT then ends it with status
    130, no traceback, the previous output as it was and no temporary file left."""
    import os
    import signal
    import subprocess
    import sys
    import time

    if not Path("/proc/self/wchan").exists():
        pytest.skip("needs Linux /proc/PID/wchan to see the process wait on the FIFO")
    shutil.copy(NAV2, tmp_path / "a.mcap")
    os.mkfifo(tmp_path / "b.mcap")
    out = tmp_path / "out.parquet"
    out.write_bytes(b"the previous run's table")
    proc = subprocess.Popen(
        [sys.executable, "-m", "tfbus.cli", "lookup", "--bag", str(tmp_path / "*.mcap"),
         "--target", "map", "--source", "base_link", "--every", "0.5", "-o", str(out),
         "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wchan = Path(f"/proc/{proc.pid}/wchan")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if wchan.read_text() == "wait_for_partner":
                break
            time.sleep(0.02)  # polling the process's state, bounded by the deadline
        else:
            pytest.fail(f"tfbus lookup never waited on the FIFO: {proc.communicate()}")
        assert any(p.name.endswith(".part") for p in tmp_path.iterdir())
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130
    assert "Traceback" not in err
    assert out.read_bytes() == b"the previous run's table"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mcap", "b.mcap", "out.parquet"]
