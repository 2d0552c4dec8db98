"""Recordings read from S3 (``s3://`` through s3fs): moto's S3 server on 127.0.0.1, the
endpoint given explicitly (fsspec's ``conf["s3"]``) and dummy credentials in the
environment (no credential lookup, no network beyond 127.0.0.1). The server counts the
body bytes it sends: a window reads its part of the file by range requests, not the
file."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import pytest

pa = pytest.importorskip("pyarrow")
fsspec = pytest.importorskip("fsspec")
s3fs = pytest.importorskip("s3fs")
pytest.importorskip("moto")
pytest.importorskip("rosbags")
werkzeug_serving = pytest.importorskip("werkzeug.serving")

from moto.moto_server.werkzeug_app import (  # noqa: E402
    DomainDispatcherApplication,
    create_backend_app,
)
from table_recordings import SEC, START, same_table, write_mcap  # noqa: E402

from tfbus import Time  # noqa: E402
from tfbus.bag import load_buffer, read_messages, read_window  # noqa: E402
from tfbus.errors import BagNotFoundError  # noqa: E402
from tfbus.table import lookup, lookup_by_recording, lookup_recording  # noqa: E402

BUCKET = "tfbus-fleet"


class CountingS3:
    """moto's S3 application served by werkzeug on 127.0.0.1 (a thread), counting the
    body bytes of its GET responses (``served``) and the GET requests."""

    def __init__(self) -> None:
        self.served = 0
        self.requests = 0
        self.lock = threading.Lock()
        app = DomainDispatcherApplication(create_backend_app)

        def counting(environ: dict[str, Any], start_response: Callable[..., Any]
                     ) -> Iterable[bytes]:
            body = app(environ, start_response)
            if environ.get("REQUEST_METHOD") != "GET":
                return body
            chunks = list(body)
            with self.lock:
                self.served += sum(len(c) for c in chunks)
                self.requests += 1
            return chunks

        self.server = werkzeug_serving.make_server("127.0.0.1", 0, counting, threaded=True)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def reset(self) -> None:
        with self.lock:
            self.served = self.requests = 0


@pytest.fixture(scope="module")
def mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # 1200 s at 20 Hz in 64 KiB chunks: about 1.7 MB in some 60 chunks.
    return write_mcap(tmp_path_factory.mktemp("s3") / "long.mcap", seed=5,
                      chunk_size=65_536, seconds=1200)


@pytest.fixture(scope="module")
def s3(mcap: Path) -> Iterator[CountingS3]:
    server = CountingS3()
    server.thread.start()
    with pytest.MonkeyPatch.context() as mp:
        # Dummy credentials, no config files, no instance metadata: nothing looked up.
        for key, value in {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing",
                           "AWS_SESSION_TOKEN": "testing", "AWS_DEFAULT_REGION": "us-east-1",
                           "AWS_EC2_METADATA_DISABLED": "true",
                           "AWS_CONFIG_FILE": str(mcap.parent / "no-aws-config"),
                           "AWS_SHARED_CREDENTIALS_FILE": str(mcap.parent / "no-aws-creds"),
                           }.items():
            mp.setenv(key, value)
        mp.setitem(fsspec.config.conf, "s3", {"endpoint_url": server.url, "key": "testing",
                                              "secret": "testing"})
        s3fs.S3FileSystem.clear_instance_cache()
        try:
            fs = fsspec.filesystem("s3")
            fs.mkdir(BUCKET)
            fs.pipe(f"{BUCKET}/fleet/long.mcap", mcap.read_bytes())
            yield server
        finally:
            s3fs.S3FileSystem.clear_instance_cache()
            server.server.shutdown()
            server.server.server_close()
            server.thread.join(timeout=10)


def test_a_window_over_s3_reads_its_chunks_not_the_file(s3: CountingS3, mcap: Path) -> None:
    url = f"s3://{BUCKET}/fleet/long.mcap"
    size = mcap.stat().st_size
    assert size > 1_500_000
    lo, hi = Time.from_ns(START + 600 * SEC), Time.from_ns(START + 605 * SEC)
    s3.reset()
    remote = list(read_window(url, start=lo, end=hi))
    window_bytes = s3.served
    assert remote == list(read_window(mcap, start=lo, end=hi))
    assert len(remote) > 100
    # Twice (statics, then the window) the head, the footer and summary, and the chunks
    # they need, each with REMOTE_BLOCK_SIZE of read-ahead: a fifth of the file here.
    assert 0 < window_bytes < size // 5, (window_bytes, size)
    assert s3.requests >= 4  # range requests, not one download
    s3.reset()
    assert list(read_messages(url)) == list(read_messages(mcap))
    assert s3.served >= size * 0.9


def test_lookups_over_s3_equal_the_local_file(s3: CountingS3, mcap: Path) -> None:
    q = pa.table({"target_frame": ["map", "odom", "map"], "source_frame": ["laser"] * 3,
                  "stamp": pa.array([START + 10 * SEC, START + 900 * SEC, 0], pa.int64())})
    local = lookup(q, load_buffer(mcap))
    assert local.column("status").to_pylist() == ["ok", "ok", "ok"]
    url = f"s3://{BUCKET}/fleet/long.mcap"
    assert same_table(lookup_recording(url, q), local)
    # Windowed: the two stamped rows each from their 60 s window, the latest (stamp 0)
    # from the whole file.
    s3.reset()
    windowed = lookup_recording(url, q.slice(0, 2), window=60.0)
    assert same_table(windowed, local.slice(0, 2))
    assert 0 < s3.served < mcap.stat().st_size // 2, s3.served


def test_a_missing_object_fails_its_rows_only(s3: CountingS3, mcap: Path) -> None:
    missing = f"s3://{BUCKET}/fleet/missing.mcap"
    with pytest.raises(BagNotFoundError, match=r"missing\.mcap: no such file"):
        list(read_messages(missing))
    url = f"s3://{BUCKET}/fleet/long.mcap"
    q = pa.table({"recording": [url, missing, url],
                  "target_frame": ["map", "map", "odom"], "source_frame": ["laser"] * 3,
                  "stamp": pa.array([START + 10 * SEC] * 3, pa.int64())})
    got = lookup_by_recording(q)
    assert got.column("status").to_pylist() == ["ok", "BagNotFoundError", "ok"]
    assert got.column("message")[1].as_py() == f"{missing}: no such file"
    want = lookup(q.drop_columns(["recording"]), load_buffer(mcap))
    assert got.column("x").to_pylist()[::2] == want.column("x").to_pylist()[::2]
