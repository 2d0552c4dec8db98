"""tfbus.table.summary and findings: a recording's links and doctor findings as Arrow
rows, checked against numbers computed by hand from generated recordings."""

from __future__ import annotations

from pathlib import Path

import pytest

pa = pytest.importorskip("pyarrow")

from table_recordings import SEC, START, ts  # noqa: E402

from tfbus.bag import TF_STATIC_TOPIC, TF_TOPIC, BagMessage, write_bag  # noqa: E402
from tfbus.doctor import diagnose  # noqa: E402
from tfbus.errors import BagNotFoundError  # noqa: E402
from tfbus.messages import TFMessage  # noqa: E402
from tfbus.table import findings, findings_schema, summary, summary_schema  # noqa: E402
from tfbus.time import Time  # noqa: E402

MS = 1_000_000


def _messages() -> list[BagMessage]:
    """``base_link -> laser`` static once; ``odom -> base_link`` every 100 ms at 0-300
    and 600-900 ms (a 300 ms gap) from ``/robot``, the 900 ms stamp sent again by
    ``/other``; ``map -> odom`` once at 500 ms."""
    out = [BagMessage(Time.from_ns(START), TF_STATIC_TOPIC,
                      TFMessage([ts("base_link", "laser", START, (0.2, 0.0, 0.3), 0.0)]),
                      "/static_publisher")]
    for k in (0, 1, 2, 3, 6, 7, 8, 9):
        ns = START + k * 100 * MS
        out.append(BagMessage(Time.from_ns(ns + MS), TF_TOPIC, TFMessage(
            [ts("odom", "base_link", ns, (0.1 * k, 0.0, 0.0), 0.0)]), "/robot"))
        if k == 6:
            out.append(BagMessage(Time.from_ns(START + 500 * MS + MS), TF_TOPIC, TFMessage(
                [ts("map", "odom", START + 500 * MS, (1.0, 0.0, 0.0), 0.0)]), "/localizer"))
    out.append(BagMessage(Time.from_ns(START + 900 * MS + 2 * MS), TF_TOPIC, TFMessage(
        [ts("odom", "base_link", START + 900 * MS, (0.9, 0.0, 0.0), 0.0)]), "/other"))
    out.sort(key=lambda m: m.time.ns)
    return out


def _write_ros1(path: Path, records: list[BagMessage]) -> Path:
    """``records`` as a ROS 1 bag, one connection per (topic, authority): each record's
    authority is its caller id (write_bag stores one caller id for the whole bag)."""
    from rosbags.rosbag1 import Writer

    from tfbus.codecs.ros1 import ROSBAGS_TF_TYPE, tf_typestore, to_rosbags

    store = tf_typestore(ros1=True)
    with Writer(path) as writer:
        conns: dict[tuple[str, str], object] = {}
        for rec in records:
            conn = conns.get((rec.topic, rec.authority))
            if conn is None:
                conn = conns[(rec.topic, rec.authority)] = writer.add_connection(
                    rec.topic, ROSBAGS_TF_TYPE, typestore=store, callerid=rec.authority,
                    latching=1 if rec.topic == TF_STATIC_TOPIC else 0)
            raw = store.serialize_ros1(
                to_rosbags(store, list(rec.message.transforms), ros1=True), ROSBAGS_TF_TYPE)
            writer.write(conn, rec.time.ns, raw)
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    directory = tmp_path_factory.mktemp("summary")
    ros1 = directory / "robot.bag"
    _write_ros1(ros1, _messages())
    folder = directory / "robot_mcap"
    write_bag(folder, _messages(), format="mcap")
    return ros1, next(folder.glob("*.mcap"))


def test_summary_rows_per_link(bags: tuple[Path, Path]) -> None:
    ros1, _ = bags
    table = summary(ros1)
    assert table.schema == summary_schema()
    assert table.to_pylist() == [
        {"file": str(ros1), "parent": "base_link", "child": "laser", "static": True,
         "first_stamp": START, "last_stamp": START, "count": 1, "rate": None,
         "largest_gap": None, "authorities": ["/static_publisher"]},
        {"file": str(ros1), "parent": "map", "child": "odom", "static": False,
         "first_stamp": START + 500 * MS, "last_stamp": START + 500 * MS, "count": 1,
         "rate": None, "largest_gap": None, "authorities": ["/localizer"]},
        # 9 transforms (the 900 ms stamp twice) over 0.9 s; the gap 300 -> 600 ms.
        {"file": str(ros1), "parent": "odom", "child": "base_link", "static": False,
         "first_stamp": START, "last_stamp": START + 900 * MS, "count": 9,
         "rate": 8 / 0.9, "largest_gap": 300 * MS, "authorities": ["/other", "/robot"]},
    ]


def test_summary_of_several_files_in_order(bags: tuple[Path, Path]) -> None:
    ros1, mcap = bags
    table = summary([mcap, str(ros1)])
    assert table.column("file").to_pylist() == [str(mcap)] * 3 + [str(ros1)] * 3
    rows = table.to_pylist()
    # ROS 2 recordings carry no caller id: tf2_ros's placeholder authority.
    assert [r["authorities"] for r in rows[:3]] == [["Authority undetectable"]] * 3
    for a, b in zip(rows[:3], rows[3:], strict=True):
        assert {k: v for k, v in a.items() if k not in ("file", "authorities")} == \
            {k: v for k, v in b.items() if k not in ("file", "authorities")}


def test_findings_rows_are_the_doctor_findings(bags: tuple[Path, Path]) -> None:
    ros1, _ = bags
    table = findings([ros1])
    assert table.schema == findings_schema()
    report = diagnose(ros1)
    assert len(report.findings) == table.num_rows > 0
    rows = table.to_pylist()
    for row, f in zip(rows, report.findings, strict=True):
        assert row["file"] == str(ros1)
        assert (row["check"], row["level"], row["message"]) == (f.check, f.level.value,
                                                                f.message)
        assert row["frames"] == list(f.frames) and row["senders"] == list(f.senders)
        assert (row["start_ns"], row["end_ns"]) == (f.start_ns, f.end_ns)
        assert dict(row["counts"]) == {k: float(v) for k, v in f.counts.items()}
        assert row["reference"] == f.reference
    # /robot sent base_link 8 times, /other once, repeating /robot's 900 ms stamp.
    assert [(r["check"], r["level"], r["frames"], r["senders"], dict(r["counts"]))
            for r in rows] == [
        ("repeated_stamps", "warning", ["base_link", "odom"], ["/other"], {"/other": 1.0}),
        ("several_authorities", "info", ["base_link", "odom"], ["/robot", "/other"],
         {"/robot": 8.0, "/other": 1.0}),
    ]


def test_findings_of_a_clean_file_have_no_rows(tmp_path: Path) -> None:
    path = tmp_path / "clean.bag"
    write_bag(path, [BagMessage(Time.from_ns(START + k * SEC // 10), TF_TOPIC, TFMessage(
        [ts("odom", "base_link", START + k * SEC // 10, (0.0, 0.0, 0.0), 0.0)]), "/robot")
        for k in range(50)], format="ros1")
    assert findings(path).num_rows == 0
    assert summary(path).column("rate").to_pylist() == [pytest.approx(10.0, rel=1e-12)]


def test_bad_paths(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="paths must be paths or strings, got int"):
        summary([tmp_path / "a.bag", 3])  # type: ignore[list-item]
    with pytest.raises(BagNotFoundError):
        summary(tmp_path / "missing.bag")
    with pytest.raises(BagNotFoundError):
        findings(tmp_path / "missing.bag")
