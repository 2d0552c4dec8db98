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
