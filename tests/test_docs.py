"""The documentation site: every code example runs, the site builds, and a browser shows it.

* Every fenced ```` ```python ```` block of every page under ``docs/`` is executed (in
  this process, with the repository root as the working directory). A block that calls
  ``anyio.run(...)`` runs twice, on asyncio and on trio (``anyio.run`` is replaced by one
  that forces the backend); ``asyncio.run`` / ``trio.run`` blocks run on their own loop.
  A block that cannot run here is fenced ```` ```python title="Not run: <reason>" ````:
  the reason is shown to the reader as the block's title and reported by pytest as the
  skip reason. Any other fence info on a python block fails (Markdown would otherwise
  swallow a mistyped block silently).
* ``mkdocs build --strict`` (warnings are errors) builds the site once per session.
* Headless Debian ``chromium`` (installed by ``scripts/install/install_chromium.sh`` when absent)
  renders the home page and one API page served on 127.0.0.1; the test checks their
  titles and headings, and that every internal link and anchor on them resolves.
"""

from __future__ import annotations

import contextlib
import functools
import html.parser
import http.server
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio
import pytest
from peer_install import LEGITIMATE_SKIPS, require

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
NOT_RUN = "Not run: "
EXAMPLE_TIMEOUT = 60  # seconds; examples use ManualClock or short real timeouts

_FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<ticks>`{3,})(?P<info>[^`\n]*)$")
_PY_INFO = re.compile(r'^python(?: title="(?P<title>[^"]*)")?$')


@dataclass(frozen=True)
class Example:
    """One ```python block of a page."""

    page: Path
    line: int  # 1-based line of the opening fence
    info: str
    code: str

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(DOCS).as_posix()}:{self.line}"

    @property
    def title(self) -> str | None:
        m = _PY_INFO.match(self.info)
        return m.group("title") if m else None

    def backends(self) -> list[str | None]:
        """The event loops to run on; ``[None]`` for synchronous code."""
        if "anyio.run(" in self.code:
            return ["asyncio", "trio"]
        if "trio.run(" in self.code:
            return ["trio"]
        if "asyncio.run(" in self.code:
            return ["asyncio"]
        return [None]


def extract(page: Path) -> list[Example]:
    """Every fenced block whose info string starts with ``python``, in page order."""
    found: list[Example] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, ticks, info = m.group("indent"), m.group("ticks"), m.group("info").strip()
        j = i + 1
        while j < len(lines) and not (
            lines[j].startswith(indent + ticks) and lines[j].strip() == ticks
        ):
            j += 1
        if info.split(" ", 1)[0].lstrip("{.").rstrip("}") in ("python", "py", "python3"):
            body = [ln[len(indent):] if ln.startswith(indent) else ln for ln in lines[i + 1 : j]]
            found.append(Example(page, i + 1, info, "\n".join(body) + "\n"))
        i = j + 1
    return found


def _pages() -> list[Path]:
    return sorted(DOCS.rglob("*.md"))


def _cases() -> Iterator[Any]:
    for page in _pages():
        for ex in extract(page):
            for backend in ex.backends():
                marks = []
                if ex.title is not None and ex.title.startswith(NOT_RUN):
                    marks.append(pytest.mark.skip(reason=f"{ex.id}: {ex.title}"))
                suffix = f"[{backend}]" if backend else ""
                yield pytest.param(ex, backend, id=ex.id + suffix, marks=marks)


def test_docs_have_examples() -> None:
    """The runner finds the pages and their examples (a broken extractor cannot pass)."""
    examples = [ex for page in _pages() for ex in extract(page)]
    pages = {ex.page.name for ex in examples}
    assert {"index.md", "tutorial.md", "concepts.md", "async.md", "bags.md"} <= pages
    assert len(examples) >= 20


def test_extractor_reads_fences_and_titles() -> None:
    text = (
        "# t\n\n```python\nprint(1)\n```\n\n```sh\nls\n```\n\n"
        '!!! note\n    ```python title="Not run: needs a robot"\n    x = 1\n    ```\n'
    )
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "p.md"
        page.write_text(text)
        got = extract(page)
    assert [(e.line, e.code, e.title) for e in got] == [
        (3, "print(1)\n", None),
        (12, "x = 1\n", "Not run: needs a robot"),
    ]


@pytest.mark.parametrize(("example", "backend"), list(_cases()))
def test_example(example: Example, backend: str | None, monkeypatch: pytest.MonkeyPatch) -> None:
    assert _PY_INFO.match(example.info), (
        f"{example.id}: fence info {example.info!r}: write ```python or "
        f'```python title="{NOT_RUN}<reason>"'
    )
    monkeypatch.chdir(ROOT)
    if backend is not None:
        monkeypatch.setattr(anyio, "run", _forcing(anyio.run, backend))
    # Padded so that line numbers in a traceback are the page's own lines.
    code = compile("\n" * example.line + example.code, str(example.page), "exec")
    namespace: dict[str, Any] = {"__name__": "__docs_example__"}
    with _time_limit(EXAMPLE_TIMEOUT, example.id):
        exec(code, namespace)


@contextlib.contextmanager
def _time_limit(seconds: int, what: str) -> Iterator[None]:
    """Fail an example that runs longer than ``seconds`` (SIGALRM; main thread only)."""

    def expire(signum: int, frame: object) -> None:
        raise TimeoutError(f"{what}: still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _forcing(real_run: Callable[..., Any], backend: str) -> Callable[..., Any]:
    """``anyio.run`` that ignores the example's backend choice and uses ``backend``."""

    def run(func: Callable[..., Any], *args: Any, **_ignored: Any) -> Any:
        return real_run(func, *args, backend=backend)

    return run


# --------------------------------------------------------------------------- the site


@pytest.fixture(scope="session")
def site() -> Iterator[Path]:
    """``mkdocs build --strict`` into a temporary directory (the build must not warn)."""
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    if mkdocs is None:
        pytest.fail("mkdocs is not installed: `pip install -e '.[docs]'` (make install does)")
    with tempfile.TemporaryDirectory(prefix="tfbus-site-") as tmp:
        out = Path(tmp) / "site"
        done = subprocess.run(
            [mkdocs, "build", "--strict", "--site-dir", str(out)],
            cwd=ROOT, capture_output=True, text=True, timeout=600, check=False,
        )
        assert done.returncode == 0, done.stdout + done.stderr
        yield out


def test_site_builds_every_page(site: Path) -> None:
    for page in _pages():
        built = site / page.relative_to(DOCS).with_suffix(".html")  # use_directory_urls off
        assert built.is_file(), f"{page} was not built ({built})"
        text = built.read_text(encoding="utf-8")
        # A mistyped fence leaves its backticks in the page instead of a code block.
        assert "```" not in text, f"{built}: a code fence was not parsed"


class _PageParser(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.title = ""
        self.h1: list[str] = []
        self.links: list[str] = []
        self.ids: set[str] = set()
        self._in: str | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if a.get("id"):
            self.ids.add(str(a["id"]))
        if tag == "a" and a.get("href"):
            self.links.append(str(a["href"]))
        if tag in ("title", "h1"):
            self._in = tag
            if tag == "h1":
                self.h1.append("")

    def handle_endtag(self, tag: str) -> None:
        if tag == self._in:
            self._in = None

    def handle_data(self, data: str) -> None:
        if self._in == "title":
            self.title += data
        elif self._in == "h1":
            self.h1[-1] += data


def _parse(text: str) -> _PageParser:
    p = _PageParser()
    p.feed(text)
    return p


@pytest.fixture(scope="session")
def chromium() -> str:
    require("chromium", "install_chromium.sh", timeout=2400)
    exe = shutil.which("chromium")
    assert exe is not None, "install_chromium.sh said ready, but chromium is not on PATH"
    return exe


@pytest.fixture(scope="session")
def served(site: Path) -> Iterator[str]:
    """The built site over HTTP on 127.0.0.1 (a free port)."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        thread.join(timeout=10)
        server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: Any) -> None:
        pass


def _render(chromium: str, url: str) -> str:
    """The DOM after Chromium loaded ``url`` and ran its scripts (a fresh profile, the
    browser's processes ended and the profile removed after the run:
    ``headless_chromium.run_headless``)."""
    from headless_chromium import run_headless

    done = run_headless(
        chromium,
        ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run",
         "--virtual-time-budget=5000", "--dump-dom"],
        url, timeout=120.0,
    )
    out = done.stdout.decode("utf-8", "replace")
    assert done.returncode == 0 and "<html" in out, done.stderr[-2000:]
    return out


def _fetch(url: str) -> str:
    with urllib.request.urlopen(url, timeout=10) as resp:  # 127.0.0.1 only
        assert resp.status == 200
        return str(resp.read().decode("utf-8", "replace"))


@pytest.mark.parametrize(
    ("path", "title", "heading"),
    [("index.html", "tfbus", "tfbus"), ("api/core.html", "tfbus.core - tfbus", "tfbus.core")],
)
def test_page_renders_in_chromium(
    chromium: str, served: str, path: str, title: str, heading: str
) -> None:
    url = urllib.parse.urljoin(served, path)
    page = _parse(_render(chromium, url))
    assert page.title.strip() == title
    assert heading in [h.replace("¶", "").strip() for h in page.h1]
    checked = 0
    for href in page.links:
        target = urllib.parse.urljoin(url, href)
        if not target.startswith(served):
            continue  # external: not fetched (no network but 127.0.0.1)
        base, _, fragment = target.partition("#")
        try:
            text = _fetch(base)
        except urllib.error.HTTPError as err:
            pytest.fail(f"{url}: broken link {href!r} -> {base}: HTTP {err.code}")
        if fragment:
            ids = page.ids if base == url.partition("#")[0] else _parse(text).ids
            assert urllib.parse.unquote(fragment) in ids, f"{url}: no anchor for {href!r}"
        checked += 1
    assert checked >= 10, f"{url}: only {checked} internal links found"


def test_site_is_browsable_from_disk(site: Path) -> None:
    """``make docs`` then site/index.html over file://: every internal link
    of every page names a file of the site (page.html), never a directory, which a
    browser shows as a listing without a server's index.html."""
    pages = sorted(site.rglob("*.html"))
    assert (site / "index.html") in pages and (site / "api" / "core.html") in pages
    checked = 0
    for built in pages:
        if built.name == "404.html":
            continue  # a server's error page: its links are absolute on purpose
        for href in _parse(built.read_text(encoding="utf-8")).links:
            parts = urllib.parse.urlsplit(href)
            if parts.scheme or parts.netloc or not parts.path:
                continue  # external, or an anchor on the same page
            target = (built.parent / urllib.parse.unquote(parts.path)).resolve()
            assert target.is_file(), f"{built.relative_to(site)}: {href!r} is not a file"
            checked += 1
    assert checked > 500


def test_site_carries_no_build_extension(site: Path) -> None:
    """docs/ext (the mkdocstrings extension the build loads) is not copied into the
    site, nor any source or compiled file."""
    assert (DOCS / "ext" / "sphinx_roles.py").is_file()
    assert not (site / "ext").exists()
    found = [p for p in site.rglob("*") if p.suffix in (".py", ".pyx", ".c", ".so", ".pyi")]
    assert found == []


def _exported_table() -> dict[str, str]:
    """Name -> the page its row links to, from the "Exported names" table of
    docs/api/tfbus.md (``""`` for a row without a link)."""
    text = (DOCS / "api" / "tfbus.md").read_text(encoding="utf-8")
    table = text[text.index("## Exported names"):].split("\n\n")[1]
    rows: dict[str, str] = {}
    for line in table.splitlines()[2:]:
        names, where = line.strip("|").split("|")
        page = re.search(r"\]\(([\w.]+\.md)\)", where)
        for name in re.findall(r"`(\w+)`", names):
            rows[name] = page.group(1) if page else ""
    return rows


def test_api_page_lists_every_exported_name() -> None:
    """The API page's exported-names table lists ``tfbus.__all__`` (and ``__version__``),
    each linking to the API page that documents the module defining it (a ``:::``
    directive of that module or of a package above it)."""
    import tfbus

    rows = _exported_table()
    assert set(rows) == set(tfbus.__all__) | {"__version__"}
    for name in tfbus.__all__:
        defined = getattr(tfbus, name).__module__
        page = (DOCS / "api" / rows[name]).read_text(encoding="utf-8")
        documented = re.findall(r"(?m)^::: ([\w.]+)", page)
        assert any(defined == d or defined.startswith(d + ".") for d in documented), (
            f"{name} ({defined}) links to api/{rows[name]}, which documents {documented}")


def test_pointers_to_documents_resolve() -> None:
    """No pointer to a document that does not exist (the package docstring pointed at
    design notes in the README, which has none): every ``docs/*.md`` path named in the
    code, the tests, the README or CONTRIBUTING.md exists, and no design file is named."""
    files = [*ROOT.glob("tfbus/**/*.py"), *ROOT.glob("tests/*.py"), ROOT / "README.md",
             ROOT / "CONTRIBUTING.md"]
    named = 0
    for path in files:
        text = path.read_text(encoding="utf-8")
        assert not re.search("DESIGN[ .]", text), path
        for ref in re.findall(r"\bdocs/[\w/.-]+\.md\b", text):
            assert (ROOT / ref).is_file(), f"{path.relative_to(ROOT)} names {ref}"
            named += 1
    assert named >= 5
    assert "docs/architecture.md" in (ROOT / "tfbus" / "__init__.py").read_text()


def test_contributing_says_how_to_set_up_test_and_benchmark() -> None:
    """CONTRIBUTING.md: every ``make`` target it names exists, every repository path it
    names exists, and it points at the architecture page."""
    text = (ROOT / "CONTRIBUTING.md").read_text(encoding="utf-8")
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    targets = set(re.findall(r"(?m)^([a-z][\w-]*):", makefile))
    named = set(re.findall(r"\bmake ([a-z][\w-]*)", text))
    assert {"install", "test", "lint", "bench", "docs"} <= named <= targets, named - targets
    paths = set(re.findall(r"`((?:tfbus|tests|benchmarks|docs|scripts|demos|peers)/[\w/.*-]*)`",
                           text))
    for ref in paths:
        assert list(ROOT.glob(ref.rstrip("/"))), f"CONTRIBUTING.md names {ref}, absent"
    assert "docs/architecture.md" in paths


def test_contributing_counts_the_skips_a_machine_with_every_peer_prints() -> None:
    """CONTRIBUTING.md's number of skipped documentation examples is the number of examples the
    pages mark 'Not run: ...' (each backend of an async one counts), and the legitimate
    skips it names are the ones of ``tests/peer_install.py``."""
    not_run = sum(
        len(list(ex.backends()))
        for page in _pages()
        for ex in extract(page)
        if ex.title is not None and ex.title.startswith(NOT_RUN)
    )
    text = " ".join((ROOT / "CONTRIBUTING.md").read_text(encoding="utf-8").split())
    match = re.search(r"the (\d+) documentation examples that need other hosts", text)
    assert match is not None, "CONTRIBUTING.md: no count of the skipped documentation examples"
    assert int(match.group(1)) == not_run
    assert "listed in `tests/peer_install.py`" in text
    assert {pattern for pattern, _ in LEGITIMATE_SKIPS} == {
        "tests/test_docs.py::test_example",
        "tests/fleet/test_fleet_netns.py::test_netem_delay_and_loss",
    }


def test_async_examples_cover_both_backends() -> None:
    """At least one example runs on each backend (the forcing of anyio.run is in use)."""
    backends = {b for page in _pages() for ex in extract(page) for b in ex.backends()}
    assert {"asyncio", "trio"} <= backends


def test_performance_page_shows_the_saved_benchmark_output() -> None:
    """docs/performance.md's tables are what scripts/docs/perf_tables.py makes of
    benchmarks/results/ (rerun the script after a benchmark run)."""
    script = ROOT / "scripts" / "docs" / "perf_tables.py"
    done = subprocess.run([sys.executable, str(script), "--check"], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stdout + done.stderr


def _perf_tables() -> Any:
    import importlib.util

    path = ROOT / "scripts" / "docs" / "perf_tables.py"
    spec = importlib.util.spec_from_file_location("perf_tables", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_quoted_figures_are_the_saved_output_lines() -> None:
    """A figure quoted in a page is filled in from the saved
    benchmark output (the lines its expression picks, and when they were measured), so
    it cannot outlive a new run; an expression that picks nothing is an error."""
    pt = _perf_tables()
    saved = (ROOT / "benchmarks" / "results" / "core.txt").read_text(encoding="utf-8")
    line = next(ln for ln in saved.splitlines() if "set_transform, chain of 10" in ln)
    marker = (
        "<!-- perf-quote core /chain of 10/ "
        "(generated by scripts/docs/perf_tables.py; do not edit) -->"
    )
    page = f"text\n  {marker}\n  stale 1.0 ns\n  <!-- perf-quote end -->\nmore\n"
    filled = pt.fill_quotes(page)
    assert "stale" not in filled and filled.startswith(f"text\n  {marker}\n  ```text\n")
    assert f"  {line.strip()}\n  ```\n\n  (`benchmarks/bench_core.py`, " in filled
    assert filled.endswith("UTC)\n  <!-- perf-quote end -->\nmore\n")
    assert pt.fill_quotes(filled) == filled
    for bad in ("core /no such line/", "nope /./", "core /(/"):
        with pytest.raises(pt.QuoteError):
            pt.fill_quotes(marker.replace("core /chain of 10/", bad) + "\n<!-- perf-quote end -->")
    quoting = [p for p in pt.QUOTING if pt.QUOTE.search(p.read_text(encoding="utf-8"))]
    assert {p.name for p in quoting} >= {"performance.md", "sensors.md", "robot.md",
                                         "transports.md", "zenoh.md", "view.md"}
