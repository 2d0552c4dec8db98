"""Recordings read through fsspec URLs: an HTTP server on 127.0.0.1 with range requests
(bytes served counted: a window reads its part of the file, not the file), ``memory://``
and ``file://``."""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

pa = pytest.importorskip("pyarrow")
fsspec = pytest.importorskip("fsspec")
pytest.importorskip("aiohttp")
pytest.importorskip("rosbags")

from table_recordings import SEC, START, same_table, write, write_mcap  # noqa: E402

from tfbus import Time  # noqa: E402
from tfbus.bag import load_buffer, read_messages, read_window  # noqa: E402
from tfbus.errors import BagFormatError, BagNotFoundError  # noqa: E402
from tfbus.table import lookup, lookup_recording  # noqa: E402


class RangeServer:
    """Files served over HTTP/1.1 on 127.0.0.1 with ``Range: bytes=a-b`` (206), HEAD, and
    404 for anything else; ``served`` counts the body bytes sent."""

    def __init__(self, files: dict[str, bytes]) -> None:
        self.files = files
        self.served = 0
        self.requests = 0
        self.lock = threading.Lock()
        owner = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args: Any) -> None:
                pass

            def _body(self, head_only: bool) -> None:
                data = owner.files.get(self.path)
                if data is None:
                    self.send_response(404)
                    self.send_header("Content-Length", "0")
                    self.end_headers()
                    return
                start, end = 0, len(data) - 1
                match = re.fullmatch(r"bytes=(\d+)-(\d*)", self.headers.get("Range", ""))
                if match:
                    start = int(match[1])
                    end = min(end, int(match[2])) if match[2] else end
                    self.send_response(206)
                    self.send_header("Content-Range", f"bytes {start}-{end}/{len(data)}")
                else:
                    self.send_response(200)
                body = data[start:end + 1]
                self.send_header("Accept-Ranges", "bytes")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                if not head_only:
                    self.wfile.write(body)
                    with owner.lock:
                        owner.served += len(body)
                        owner.requests += 1

            def do_HEAD(self) -> None:
                self._body(True)

            def do_GET(self) -> None:
                self._body(False)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def reset(self) -> None:
        with self.lock:
            self.served = self.requests = 0


@pytest.fixture(scope="module")
def mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # 1200 s at 20 Hz in 64 KiB chunks: about 1.7 MB in some 60 chunks.
    return write_mcap(tmp_path_factory.mktemp("http") / "long.mcap", seed=5,
                      chunk_size=65_536, seconds=1200)


@pytest.fixture(scope="module")
def server(mcap: Path) -> Iterator[RangeServer]:
    bag = write(mcap.parent, "plain", "ros1", seed=5, seconds=5)
    srv = RangeServer({"/fleet/long.mcap": mcap.read_bytes(), "/fleet/plain.bag":
                       bag.read_bytes()})
    srv.thread.start()
    try:
        yield srv
    finally:
        srv.server.shutdown()
        srv.server.server_close()
        srv.thread.join(timeout=10)


def test_a_window_over_http_reads_its_chunks_not_the_file(
    server: RangeServer, mcap: Path
) -> None:
    url = f"{server.url}/fleet/long.mcap"
    size = mcap.stat().st_size
    assert size > 1_500_000
    lo, hi = Time.from_ns(START + 600 * SEC), Time.from_ns(START + 605 * SEC)
    server.reset()
    remote = list(read_window(url, start=lo, end=hi))
    window_bytes = server.served
    assert remote == list(read_window(mcap, start=lo, end=hi))
    assert len(remote) > 100
    # Twice (statics, then the window) the head, the footer and summary, and the chunks
    # they need, each with REMOTE_BLOCK_SIZE of read-ahead: a fifth of the file here.
    assert 0 < window_bytes < size // 5, (window_bytes, size)
    server.reset()
    assert list(read_messages(url)) == list(read_messages(mcap))
    assert server.served >= size * 0.9


def test_lookups_over_http_and_memory_equal_the_local_file(
    server: RangeServer, mcap: Path
) -> None:
    q = pa.table({"target_frame": ["map", "odom", "map"], "source_frame": ["laser"] * 3,
                  "stamp": pa.array([START + 10 * SEC, START + 900 * SEC, 0], pa.int64())})
    local = lookup(q, load_buffer(mcap))
    url = f"{server.url}/fleet/long.mcap"
    assert same_table(lookup_recording(url, q), local)
    memory = fsspec.filesystem("memory")
    memory.pipe("/tfbus-tests/long.mcap", mcap.read_bytes())
    try:
        assert same_table(lookup_recording("memory://tfbus-tests/long.mcap", q), local)
    finally:
        memory.rm("/tfbus-tests/long.mcap")
    assert same_table(lookup_recording(mcap.as_uri(), q), local)
    assert local.column("status").to_pylist() == ["ok", "ok", "ok"]


def test_what_a_url_cannot_be(server: RangeServer, mcap: Path) -> None:
    with pytest.raises(BagFormatError, match="over a URL only MCAP files are read"):
        list(read_messages(f"{server.url}/fleet/plain.bag"))
    with pytest.raises(BagNotFoundError, match="no such file"):
        list(read_messages(f"{server.url}/fleet/missing.mcap"))
    # A ROS 1 bag through file:// is a local path.
    bag = mcap.parent / "plain.bag"
    assert list(read_messages(bag.as_uri())) == list(read_messages(bag))
