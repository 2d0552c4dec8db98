"""The layer order of ``tfbus/`` (docs/architecture.md "Layers"): no import runs up a layer, no
import cycles, no import sideways between the layer-4 packages, and every module has a place
in the table.

Imports are read with :mod:`ast` from every ``.py`` file under ``tfbus/`` (every
``import`` node: module level, inside functions, under ``if TYPE_CHECKING``) and with a
line scan from the compiled core's ``.pyx`` (Cython's ``cimport`` lines are C, not
Python modules, and are skipped). Nothing is imported: the test reads source only.

Adding a module? Put it in ``LAYERS`` below (and in ``docs/architecture.md``'s table):
a module missing from the table fails :func:`test_every_module_has_a_layer`.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "tfbus"

LAYERS: dict[str, int] = {
    # 0: values, pure functions
    "messages": 0,
    "sensor_msgs": 0,
    "time": 0,
    "ratelimit": 0,
    "topics": 0,  # the topic names, in one place
    "_version": 0,  # the distribution's version from package metadata
    "_claser": 0,  # compiled laser projection (laser.py's kernel): imports nothing of tfbus
    # 1: the sans-I/O core (geometry and convert call the tf2 scalar math of the core that
    # core/_select chose: compiled or pure-Python, same behaviour)
    "geometry": 1,
    "convert": 1,
    "core": 1,  # BufferCore, its text, batch values, velocity, caches, both twins
    "errors": 1,
    "_extras": 1,  # which extra brings which package; raises errors.MissingExtraError
    "codecs": 1,  # message codecs (ROS 1, CDR, tfbus's msgpack wire): sans-I/O
    # 2: the bus and time sources
    "_aio": 2,  # every CPython-asyncio shortcut (bus, clocks, buffer, transports use it)
    "bus": 2,
    "_cbus": 2,  # compiled delivery, cancellation test and yield of the bus (bus.py's kernel)
    "clock": 2,
    "latch": 2,
    "subscription": 2,
    # 3: awaitable tf2_ros pieces
    "buffer": 3,
    "listener": 3,
    "_clistener": 3,  # compiled message handler of the listener (listener.py's kernel)
    "broadcaster": 3,
    "fleet": 3,
    "session": 3,  # a bus, buffer, listener and broadcasters held by a background task
    "monitor": 3,  # tf_monitor's summaries over a sink (bag/ and cli/ use them)
    "_cmonitor": 3,  # compiled accounting of tf_monitor's tables (monitor.py's kernel)
    # 4: recordings, statistics, sensors, transports (packages count as one entry)
    "bag": 4,
    "filters": 4,
    "laser": 4,
    "robot": 4,
    "transports": 4,
    # 5: the command line, examples and the tf2 adapters (compat joins a ROS 1 graph
    # through tfbus's ROS 1 transport, as the command line opens buses)
    "compat": 5,
    "cli": 5,
    "remote": 5,  # lookups served over a transport (Zenoh queryable, ROS 1 action)
    "demos": 5,
    "view": 5,
    "doctor": 5,  # tree diagnosis over bags (bag/) and live buses (listener sinks)
    "table": 5,  # tf lookups as a table operator over recordings (Arrow, engines)
    "web": 5,  # tf for roslibjs / roslibpy web apps (rosbridge's ops; view's guard)
    "__main__": 5,
}
"""Layer of each top-level module or package of ``tfbus`` (a package's submodules share
its layer). ``tfbus/__init__.py`` is the facade above every layer."""

ONLY_IMPORTS: dict[str, set[str]] = {
    "errors": {"time", "messages"},  # the exception tree may name a Time or a message type
}
"""Modules allowed a narrower set of tfbus imports than their layer would give."""

SIDEWAYS_LAYER: int = 4
"""The layer whose packages are siblings: each may import only lower layers, never another
package of its own layer (bag, transports, compat, filters, laser, robot)."""

SIDEWAYS_PENDING: dict[tuple[str, str], str] = {
}
"""Known sideways imports between layer-4 packages being removed elsewhere, with why. An
entry whose packages both still exist but no longer import sideways fails the test."""

SANS_IO_FORBIDDEN = {"anyio", "asyncio", "trio", "sniffio", "time", "datetime", "threading"}
"""What layers 0-1 must not import: no event loop, no wall clock (docs/architecture.md "Sans-I/O
core"). ``time`` is the standard library's (tfbus's own is ``tfbus.time``)."""

WALL_CLOCK_PENDING: dict[str, str] = {
}
PERF_TIMERS: dict[str, str] = {
    "tfbus.core._cbatch": "perf_counter_ns times its own calls to choose one thread or two "
    "for a batch; the rows are bit for bit the same either way",
}
"""Layer 0-1 modules allowed the standard library's ``time`` as a performance timer only:
no result depends on it (what each one times, and why)."""
"""Known offenders of SANS_IO_FORBIDDEN being fixed elsewhere. An entry that no longer
offends fails the test, so the list cannot go stale."""

ERRORS_ELSEWHERE_PENDING: dict[str, str] = {
}
"""Exception classes still defined outside ``tfbus/errors.py``, each with where it is and
who moves it. An entry whose class is no longer found outside errors.py fails the test, so
the list cannot go stale."""

_EXCEPTION_BASE = re.compile(r"(Error|Exception)$")

_PYX_IMPORT = re.compile(r"^\s*(?:from\s+([\w.]+)\s+import\s|import\s+([\w.]+))", re.MULTILINE)
_PYX_CIMPORT = re.compile(r"^\s*(?:from\s+[\w.]+\s+cimport\s|cimport\s)")


def _module_files() -> Iterator[tuple[str, Path]]:
    """``(dotted name, path)`` of every Python or Cython module in the package."""
    for path in sorted(PACKAGE.rglob("*")):
        if path.suffix not in (".py", ".pyx") or "__pycache__" in path.parts:
            continue
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts.pop()
        yield ".".join(parts), path


MODULES: dict[str, Path] = dict(_module_files())


def _is_package(name: str) -> bool:
    return MODULES.get(name, Path()).name == "__init__.py"


def _entry(module: str) -> str | None:
    """The LAYERS key of a dotted tfbus module name (None for the package root)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def _resolve(importer: str, is_package: bool, level: int, target: str | None) -> str:
    """Absolute module name of a (possibly relative) import in ``importer``."""
    if level == 0:
        return target or ""
    base = importer.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def _imports(module: str, path: Path) -> Iterator[tuple[str, int]]:
    """``(absolute module name, line)`` for every import in a module's source."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".pyx":
        for match in _PYX_IMPORT.finditer(text):
            line_start = text.rfind("\n", 0, match.start()) + 1
            if _PYX_CIMPORT.match(text, line_start):
                continue
            yield match.group(1) or match.group(2), text.count("\n", 0, match.start()) + 1
        return
    for node in ast.walk(ast.parse(text, filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(module, _is_package(module), node.level, node.module)
            for alias in node.names:
                # ``from tfbus import clock`` imports the submodule tfbus.clock;
                # ``from tfbus import Time`` imports (runs) the package tfbus itself.
                sub = f"{base}.{alias.name}"
                yield (sub if sub in MODULES else base), node.lineno


def _tfbus_module(name: str) -> str | None:
    """The tfbus module an import name lands in (its longest existing prefix)."""
    if name != "tfbus" and not name.startswith("tfbus."):
        return None
    parts = name.split(".")
    while parts and ".".join(parts) not in MODULES:
        parts.pop()
    return ".".join(parts) if parts else None


def _graph() -> dict[str, dict[str, int]]:
    """importer -> {imported tfbus module: first line}, for every tfbus module."""
    graph: dict[str, dict[str, int]] = {}
    for module, path in MODULES.items():
        edges: dict[str, int] = {}
        for name, line in _imports(module, path):
            target = _tfbus_module(name)
            if target is not None and target != module:
                edges.setdefault(target, line)
        graph[module] = edges
    return graph


def _where(module: str, line: int) -> str:
    return f"{MODULES[module].relative_to(PACKAGE.parent)}:{line}"


def test_the_package_is_found() -> None:
    assert "tfbus.core" in MODULES and "tfbus.core._ccore" in MODULES and "tfbus" in MODULES
    assert "tfbus.messages" in _graph()["tfbus.core._ccore"]  # the compiled core's import is seen
    # the one selection point imports both cores, every module of each
    cores = {f"tfbus.core._{c}{job}" for c in ("c", "py") for job in ("math", "cache", "batch")}
    cores |= {"tfbus.core._ccore", "tfbus.core._pycore"}
    assert cores <= set(_graph()["tfbus.core._select"])


def test_only_the_core_imports_its_selection() -> None:
    """The implementation choice (compiled or pure-Python) stays inside ``tfbus.core``:
    modules above it use the public face ``tfbus.core.kernels``."""
    outside = sorted(
        _where(importer, edges["tfbus.core._select"])
        for importer, edges in _graph().items()
        if "tfbus.core._select" in edges and not importer.startswith("tfbus.core")
    )
    assert not outside, "import tfbus.core.kernels, not tfbus.core._select:\n" + "\n".join(
        outside
    )


def test_the_compiled_ros1_decoder_is_a_codec() -> None:
    """The compiled ``TFMessage`` decoders live under ``codecs/`` (``_cwire.pyx``, found by
    ``tfbus.codecs._compiled_wire`` for ``codecs/ros1.py`` and ``codecs/native.py``), not in
    the core: no codec imports the core's selection or its kernels, and nothing in
    ``core/`` imports a codec."""
    graph = _graph()
    assert "tfbus.codecs._cwire" in MODULES and "tfbus.core._cwire" not in MODULES
    assert "tfbus.codecs._cwire" in graph["tfbus.codecs"]
    for codec in ("tfbus.codecs.ros1", "tfbus.codecs.native"):
        assert "tfbus.codecs" in graph[codec], f"{codec} does not use _compiled_wire"
    codecs_into_core = sorted(
        _where(importer, line)
        for importer, edges in graph.items() if importer.startswith("tfbus.codecs")
        for target, line in edges.items()
        if target in ("tfbus.core._select", "tfbus.core.kernels")
    )
    assert not codecs_into_core, "a codec imports the core's selection:\n" + "\n".join(
        codecs_into_core
    )
    core_into_codecs = sorted(
        _where(importer, line)
        for importer, edges in graph.items() if importer.startswith("tfbus.core")
        for target, line in edges.items() if target.startswith("tfbus.codecs")
    )
    assert not core_into_codecs, "the core imports a codec:\n" + "\n".join(core_into_codecs)


def test_each_topic_name_has_one_home() -> None:
    """Topic names are defined in ``tfbus/topics.py`` only; elsewhere they are imported."""
    names = ("/tf", "/tf_static", "/tfbus/peers", "/joint_states", "/scan")
    pattern = re.compile(r'^[A-Z_]+(?::[^=]*)?\s*=\s*"(' + "|".join(map(re.escape, names)) + ')"',
                         re.MULTILINE)
    homes = sorted(
        f"{path.relative_to(PACKAGE.parent)}: {m.group(0)}"
        for module, path in MODULES.items()
        if path.suffix == ".py" and module != "tfbus.topics"
        for m in pattern.finditer(path.read_text(encoding="utf-8"))
    )
    assert not homes, "define topic names in tfbus/topics.py only:\n" + "\n".join(homes)


def test_every_module_has_a_layer() -> None:
    missing = sorted(
        {entry for m in MODULES if (entry := _entry(m)) is not None and entry not in LAYERS}
    )
    assert not missing, (
        f"tfbus module(s) {missing} have no layer: add each to LAYERS in "
        f"tests/test_layers.py (and to the layer table of docs/architecture.md), at the "
        f"lowest layer whose modules are all it imports"
    )


def test_no_import_runs_up_a_layer() -> None:
    problems: list[str] = []
    for importer, edges in _graph().items():
        entry = _entry(importer)
        if entry is None or entry not in LAYERS:
            continue  # the facade; unplaced modules fail the test above
        for target, line in edges.items():
            target_entry = _entry(target)
            if target_entry is None:
                problems.append(
                    f"{_where(importer, line)}: imports the package root 'tfbus' (which "
                    f"imports every layer); import the module that defines the name"
                )
                continue
            if target_entry == entry or target_entry not in LAYERS:
                continue
            if LAYERS[target_entry] > LAYERS[entry]:
                problems.append(
                    f"{_where(importer, line)}: {importer} (layer {LAYERS[entry]}) imports "
                    f"{target} (layer {LAYERS[target_entry]})"
                )
            allowed = ONLY_IMPORTS.get(entry)
            if allowed is not None and target_entry not in allowed:
                problems.append(
                    f"{_where(importer, line)}: {importer} may import only {sorted(allowed)} "
                    f"of tfbus, not {target}"
                )
    assert not problems, "imports against the layer order:\n" + "\n".join(problems)


def _sideways(
    graph: dict[str, dict[str, int]], layers: dict[str, int]
) -> dict[tuple[str, str], list[tuple[str, str, int]]]:
    """Imports between two different entries of :data:`SIDEWAYS_LAYER`:
    ``(importer entry, imported entry) -> [(importer, imported, line), ...]``."""
    found: dict[tuple[str, str], list[tuple[str, str, int]]] = {}
    for importer, edges in graph.items():
        entry = _entry(importer)
        if entry is None or layers.get(entry) != SIDEWAYS_LAYER:
            continue
        for target, line in edges.items():
            target_entry = _entry(target)
            if (target_entry is not None and target_entry != entry
                    and layers.get(target_entry) == SIDEWAYS_LAYER):
                found.setdefault((entry, target_entry), []).append((importer, target, line))
    return found


def test_no_import_sideways_between_layer_4_packages() -> None:
    """bag, transports, compat, monitor, ... each import only lower layers (the
    one sideways arrow was transports/ros1/tcpros.py importing tfbus.bag.decode; the
    shared code now lives a layer down, in tfbus.codecs)."""
    found = _sideways(_graph(), LAYERS)
    unexpected = [
        f"{_where(importer, line)}: {importer} imports {target} (both layer {SIDEWAYS_LAYER}: "
        f"move what they share down a layer)"
        for pair, edges in sorted(found.items())
        if pair not in SIDEWAYS_PENDING
        for importer, target, line in edges
    ]
    assert not unexpected, "imports sideways on layer 4:\n" + "\n".join(unexpected)
    stale = sorted(
        pair for pair in SIDEWAYS_PENDING
        if all(p in LAYERS and any(_entry(m) == p for m in MODULES) for p in pair)
        and pair not in found
    )
    assert not stale, f"{stale} no longer import sideways: remove them from SIDEWAYS_PENDING"


def test_the_sideways_rule_sees_a_sideways_import() -> None:
    """The rule itself: a layer-4 package importing another is reported, one importing a
    lower layer or itself is not (a synthetic graph, so the rule cannot pass vacuously)."""
    layers = {"bag": 4, "transports": 4, "codecs": 1}
    graph = {
        "tfbus.transports.ros1.tcpros": {
            "tfbus.bag.decode": 13,
            "tfbus.codecs.ros1": 14,
            "tfbus.transports.ros1.rpc": 15,
        },
        "tfbus.bag.decode": {"tfbus.codecs.cdr": 3},
    }
    assert _sideways(graph, layers) == {
        ("transports", "bag"): [("tfbus.transports.ros1.tcpros", "tfbus.bag.decode", 13)]
    }
    assert ("transports", "bag") not in _sideways(_graph(), LAYERS)


def _cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles() -> None:
    graph = _graph()
    # The facade imports everything and nothing may import it (checked above); a package's
    # own __init__ re-exporting its submodules is the package pattern, not a cycle.
    graph = {
        m: {t: ln for t, ln in edges.items() if t != "tfbus" and not m.startswith(f"{t}.")}
        for m, edges in graph.items()
        if m != "tfbus"
    }
    cycles = _cycles(graph)
    described = [
        " -> ".join(c) + "  (" + ", ".join(
            f"{a} imports {b} at {_where(a, graph[a][b])}"
            for a in c
            for b in c
            if b in graph[a]
        ) + ")"
        for c in cycles
    ]
    assert not cycles, "import cycles:\n" + "\n".join(described)


def test_layers_0_and_1_are_sans_io() -> None:
    """No event loop and no wall clock below layer 2 (time comes from the caller)."""
    offenders: dict[str, list[str]] = {}
    for module, path in MODULES.items():
        entry = _entry(module)
        if entry is None or LAYERS.get(entry, 99) > 1:
            continue
        for name, line in _imports(module, path):
            if name.split(".")[0] in SANS_IO_FORBIDDEN and not (
                name == "time" and module in PERF_TIMERS
            ):
                offenders.setdefault(module, []).append(f"{_where(module, line)}: {name}")
    unexpected = {m: v for m, v in offenders.items() if m not in WALL_CLOCK_PENDING}
    assert not unexpected, "layers 0-1 must not import an event loop or a clock:\n" + "\n".join(
        line for lines in unexpected.values() for line in lines
    )
    stale = sorted(m for m in WALL_CLOCK_PENDING if m in MODULES and m not in offenders)
    assert not stale, f"{stale} no longer import a clock: remove them from WALL_CLOCK_PENDING"


def _exception_classes() -> Iterator[tuple[str, str]]:
    """``(class name, where)`` of every class outside errors.py with a base named
    ``...Error`` or ``...Exception`` (what ``git grep "class .*(.*Error\\|Exception)"``
    finds, read with :mod:`ast`)."""
    for module, path in MODULES.items():
        if module == "tfbus.errors" or path.suffix != ".py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if not isinstance(node, ast.ClassDef):
                continue
            for base in node.bases:
                name = base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", "")
                if _EXCEPTION_BASE.search(name):
                    yield node.name, _where(module, node.lineno)
                    break


def test_every_exception_is_in_errors() -> None:
    """One exception tree, one module (httpx's ``_exceptions.py``): a new error class goes
    into ``tfbus/errors.py`` and is imported where it is raised."""
    found = dict(_exception_classes())
    unexpected = sorted(f"{where}: {name}" for name, where in found.items()
                        if name not in ERRORS_ELSEWHERE_PENDING)
    assert not unexpected, "exception classes outside tfbus/errors.py:\n" + "\n".join(unexpected)
    stale = sorted(name for name in ERRORS_ELSEWHERE_PENDING if name not in found)
    assert not stale, f"{stale} moved to errors.py: remove them from ERRORS_ELSEWHERE_PENDING"


TOPIC_NAMES = frozenset({"/tf", "/tf_static", "/joint_states", "/scan"})
"""The names ``tfbus/topics.py`` defines: written nowhere else in code."""


def test_topic_names_are_written_once() -> None:
    """``"/tf"`` and its siblings are string constants only in ``tfbus/topics.py``; every
    other module imports the name (docstrings, which show examples, are not code)."""
    problems: list[str] = []
    for module, path in MODULES.items():
        if module == "tfbus.topics" or path.suffix != ".py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        problems += [
            f"{_where(module, node.lineno)}: {node.value!r}"
            for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and node.value in TOPIC_NAMES
            and id(node) not in docstrings
        ]
    assert not problems, "import these names from tfbus.topics:\n" + "\n".join(problems)


@pytest.mark.parametrize(
    ("importer", "is_package", "level", "target", "expected"),
    [
        ("tfbus.errors", False, 1, "time", "tfbus.time"),
        ("tfbus.bag", True, 1, "reader", "tfbus.bag.reader"),  # a package's own submodule
        ("tfbus.bag.reader", False, 1, "formats", "tfbus.bag.formats"),
        ("tfbus.bag.reader", False, 2, "time", "tfbus.time"),
        ("tfbus.core", False, 0, "tfbus.messages", "tfbus.messages"),
        ("tfbus.geometry", False, 1, None, "tfbus"),
    ],
)
def test_relative_imports_resolve(
    importer: str, is_package: bool, level: int, target: str | None, expected: str
) -> None:
    assert _resolve(importer, is_package, level, target) == expected


def test_the_remote_facade_asks_the_transports_capability() -> None:
    """docs/architecture.md "a new capability goes on its transport": ``tfbus.remote``
    reaches transports only through ``transports._base`` (the ``LookupServing``
    Protocol), never a transport package: the middleware's lookups live in the
    transport's own package (on its own session or node)."""
    graph = _graph()
    remote = [m for m in graph if m == "tfbus.remote" or m.startswith("tfbus.remote.")]
    assert remote
    problems = [
        f"{_where(m, line)}: imports {target}"
        for m in remote
        for target, line in graph[m].items()
        if target.startswith("tfbus.transports") and target != "tfbus.transports._base"
    ]
    assert not problems, "remote/ imports a transport package:\n" + "\n".join(problems)
    assert "tfbus.transports.ros1.action" in MODULES
    assert "tfbus.transports.zenoh.lookups" in MODULES


def test_middleware_threads_reach_the_loop_only_through_thread_wakeup() -> None:
    """docs/architecture.md "a new capability goes on its transport": no transport
    imports ``anyio.from_thread`` (a second thread-to-loop bridge beside
    ``ThreadWakeup``), and only ``transports/zenoh/queryable.py`` declares Zenoh
    queryables (one module owns them)."""
    portals: list[str] = []
    queryables: list[str] = []
    for module, path in MODULES.items():
        if not module.startswith("tfbus.transports") or path.suffix != ".py":
            continue
        portals += [f"{_where(module, line)}: imports {name}"
                    for name, line in _imports(module, path)
                    if name.startswith("anyio.from_thread")]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        queryables += [
            _where(module, node.lineno) for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and node.attr == "declare_queryable"
            and module != "tfbus.transports.zenoh.queryable"
        ]
    assert not portals, "a second thread-to-loop bridge:\n" + "\n".join(portals)
    assert not queryables, "a Zenoh queryable outside zenoh/queryable.py:\n" + \
        "\n".join(queryables)
    assert "tfbus.transports.zenoh.queryable" in MODULES


FRAME_WALK_HOMES: dict[str, set[str]] = {
    "tfbus.core.buffer_core": {"up"},  # frame_path: tfbus's one frame path
    "tfbus.compat.tf2_py": {"_walk_chain"},  # tf2_py 0.7.6 ``_chain``
    "tfbus.view.scene": {"_largest_root"},  # each frame's root (a walk, not a chain)
}
"""The functions that walk a frame's ancestors by name (a loop over ``get_parent`` or a
``parents`` mapping), by module: the frame path has one home in the core and tf2_py's
ordered chain (quirks included) one in ``compat/tf2_py.py``; everyone else calls them."""


def _walks_parents(loop: ast.While) -> bool:
    for node in ast.walk(loop):
        if isinstance(node, ast.Attribute) and node.attr == "get_parent":
            return True
        if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name)
                and node.value.id == "parents"):
            return True
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get" and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "parents"):
            return True
    return False


def test_the_frame_chain_has_one_home() -> None:
    found: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        if path.suffix != ".py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef):
                continue
            own = [n for n in ast.iter_child_nodes(fn) if not isinstance(n, ast.FunctionDef)]
            loops = [n for top in own for n in ast.walk(top) if isinstance(n, ast.While)]
            if any(_walks_parents(loop) for loop in loops):
                found.setdefault(module, set()).add(fn.name)
    assert found == FRAME_WALK_HOMES


def test_do_transform_lives_in_convert_and_geometry_below_it() -> None:
    """tfbus's ``do_transform_*`` (messages) are defined in ``convert.py`` only (the tf2
    adapters under ``compat/`` keep their own, tf2's KDL arithmetic); ``geometry.py`` is
    array math, and the core imports neither (no lazy ``core`` -> ``geometry`` import)."""
    homes: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        if path.suffix != ".py" or module.startswith("tfbus.compat."):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        names = {n.name for n in ast.walk(tree)
                 if isinstance(n, ast.FunctionDef) and n.name.startswith("do_transform")}
        if names:
            homes[module] = names
    assert set(homes) == {"tfbus.convert"}
    assert {"do_transform_point", "do_transform_vector3", "do_transform_pose"} <= homes[
        "tfbus.convert"]
    graph = _graph()
    assert [m for m, edges in graph.items() if m.startswith("tfbus.core")
            and {"tfbus.geometry", "tfbus.convert"} & set(edges)] == []


SCHEME_NAMES_PENDING: dict[str, str] = {}
"""Command-line modules still testing scheme names, with why. An entry that no longer does
fails the test, so the list cannot go stale."""


def test_the_command_line_asks_schemes_for_capabilities() -> None:
    """``tfbus/cli`` never compares a scheme name with a string (``spec.scheme ==
    "zenoh"``): it asks the scheme table's facts (``TransportScheme.peer_aware``,
    ``is_fleet``, ``unknown_authority``, ...) or the transport's Protocols."""
    problems = []
    for module, path in MODULES.items():
        if not module.startswith("tfbus.cli.") or path.suffix != ".py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            sides = [node.left, *node.comparators]
            names = any(isinstance(s, ast.Attribute) and s.attr == "scheme" for s in sides)
            strings = any((isinstance(s, ast.Constant) and isinstance(s.value, str))
                          or isinstance(s, (ast.Tuple, ast.Set, ast.List)) for s in sides)
            if names and strings:
                problems.append((module, _where(module, node.lineno)))
    offenders = {module for module, _ in problems}
    assert offenders == set(SCHEME_NAMES_PENDING), "scheme names tested in the command line:\n" + (
        "\n".join(where for module, where in problems if module not in SCHEME_NAMES_PENDING))


def test_statistics_classes_are_named_statistics() -> None:
    """One shape for counters: classes named ``<Name>Statistics`` (no ``*Stats``), read
    through a ``statistics()`` method, never a ``statistics`` attribute."""
    problems = []
    for module, path in MODULES.items():
        if path.suffix != ".py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name.endswith("Stats"):
                problems.append(f"{_where(module, node.lineno)}: class {node.name}")
            if (isinstance(node, ast.Assign) and any(
                    isinstance(t, ast.Attribute) and t.attr == "statistics"
                    for t in node.targets)):
                problems.append(f"{_where(module, node.lineno)}: a statistics attribute")
    assert not problems, "\n".join(problems)


def test_the_clock_owns_jump_callbacks() -> None:
    """Backward jumps are the clock's: callbacks live in the clock (``Clock.on_jump``,
    one shared callback per ``key``); outside ``tfbus/clock`` only ``buffer.py``'s
    ``clear_on_jump_back`` registers them, and no module keeps a registry of its own
    (a module-level dict)."""
    callers = set()
    registries = []
    for module, path in MODULES.items():
        if path.suffix != ".py" or module.startswith("tfbus.clock"):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        if any(isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
               and n.func.attr == "on_jump" for n in ast.walk(tree)):
            callers.add(module)
            registries += [  # a module-level dict: built literally or annotated as one
                _where(module, node.lineno) for node in tree.body
                if (isinstance(node, ast.Assign)
                    and isinstance(node.value, (ast.Dict, ast.DictComp)))
                or (isinstance(node, ast.AnnAssign) and "dict" in ast.unparse(node.annotation))
            ]
    assert callers == {"tfbus.buffer"}
    assert registries == []
