"""``make check-installs``: what a new user gets, tried in new virtual environments.

CI runs it before ``make test``, whose environment (every extra and the test tools) hides
a dependency that tfbus imports but does not declare. Every stage starts from a fresh
``git clone`` of the repository's HEAD and a new venv:

1. **make demo**: the README's first command, in the fresh clone; it must print the
   tutorial's line and exit 0.
2. **pip install .** (no extra), with pip picking the newest release of every dependency:
   ``tfbus --version``, ``tfbus demo``, the README's example on asyncio, and the import
   sweep below.
3. **Each extra alone**: for every extra of ``pyproject.toml``, a new venv with
   ``tfbus[EXTRA]`` only (the wheel built once from the clone), the import sweep, and the
   commands docs/cli.md says the extra enables, run once on ``tests/data/`` (``--help``
   where a command needs a peer: a bus, a browser).
4. **Oldest**: the core install at the lowest versions ``pyproject.toml`` allows (uv's
   ``--resolution lowest-direct``): the sweep, the demo, the README's example and the
   tf2 conformance corpus run against the installed package.

The import sweep imports every ``tfbus`` module in the venv. A module must import, or
raise :class:`tfbus.errors.MissingExtraError` naming an extra that is *not* installed
there. Anything else fails, naming the module and the missing package: a plain
``ModuleNotFoundError`` is an import no extra declares (or a subpackage that does not
check its extra with ``tfbus._extras.require``), and ``MissingExtraError`` naming an
installed extra is a package that extra forgot.

uv (from PyPI, into a tools venv) makes the stage-3 and stage-4 venvs; stages 1 and 2 use
the plain ``venv`` + ``pip`` a newcomer has. Every step is bounded in time and prints its
time; exit status 1 on any failure, with the step's last output lines.

    python3 scripts/release/check_installs.py                  # all stages
    python3 scripts/release/check_installs.py --only extras --extras bag,web
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DEMO_LINE = "base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20)"
TURTLE_BAG = "tests/data/webviz_turtle_tf_example.bag"
STAGES = ("demo", "core", "extras", "oldest")
FAILURES: list[str] = []
TIMES: dict[str, float] = {}

# Imports every tfbus module of the venv it runs in; prints one JSON object: module ->
# "ok" | ["MissingExtraError", extra, message] | [exception class, missing name, message].
SWEEP = r"""
import importlib, json, pkgutil, sys
import tfbus
from tfbus.errors import MissingExtraError
result = {"tfbus": "ok"}
def walk_error(name):
    pass  # the failing package itself is recorded below
for info in pkgutil.walk_packages(tfbus.__path__, "tfbus.", onerror=walk_error):
    name = info.name
    if name.rsplit(".", 1)[-1] == "__main__":
        continue  # running the command line is not importing it
    try:
        importlib.import_module(name)
    except MissingExtraError as exc:
        result[name] = ["MissingExtraError", exc.extra, str(exc)]
    except Exception as exc:
        result[name] = [type(exc).__name__, getattr(exc, "name", None) or "", str(exc)[:300]]
    else:
        result[name] = "ok"
print(json.dumps(result))
"""


def step(name: str, cmd: Sequence[str | Path], *, timeout: float, cwd: Path | None = None,
         env: dict[str, str] | None = None, expect: str | None = None) -> tuple[bool, str]:
    """Run one bounded step; record a failure instead of raising."""
    t0 = time.perf_counter()
    try:
        done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True,
                              timeout=timeout, cwd=cwd, env=env, check=False,
                              stdin=subprocess.DEVNULL)
        out = done.stdout + done.stderr
        ok = done.returncode == 0 and (expect is None or expect in out)
        why = "" if ok else (f"exit {done.returncode}" if done.returncode else
                             f"output lacks {expect!r}")
    except subprocess.TimeoutExpired as exc:
        out, ok, why = f"{exc}", False, f"timed out after {timeout:.0f} s"
    print(f"  [{'ok' if ok else 'FAIL'}] {name} ({time.perf_counter() - t0:.1f} s)"
          + (f": {why}" if why else ""), flush=True)
    if not ok:
        FAILURES.append(name)
        print("    " + "\n    ".join(out.strip().splitlines()[-25:]), flush=True)
    return ok, out


def serve_step(name: str, cmd: Sequence[str | Path], ready: str, *, cwd: Path,
               env: dict[str, str], timeout: float = 120.0) -> None:
    """Start a server command, wait (bounded) for its ``ready`` line, then Ctrl-C it: it
    must have printed that line, exit 0, and print no error or traceback."""
    t0 = time.perf_counter()
    lines: list[str] = []
    seen = threading.Event()
    proc = subprocess.Popen([str(c) for c in cmd], cwd=cwd, env=env, text=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if ready in line:
                seen.set()
        seen.set()  # end of output: nothing more to wait for

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        seen.wait(timeout)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            lines.append("(still running 60 s after Ctrl-C: killed)")
            proc.kill()
            proc.wait(timeout=60)
        reader.join(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=60)
    problems = []
    if ready not in "\n".join(lines):
        problems.append(f"never printed {ready!r}")
    if proc.returncode != 0:
        problems.append(f"exit {proc.returncode} after Ctrl-C")
    bad = [line for line in lines if "Traceback" in line or "error:" in line]
    if bad:
        problems.append(f"printed {bad[0]!r}")
    why = "; ".join(problems)
    print(f"  [{'FAIL' if why else 'ok'}] {name} ({time.perf_counter() - t0:.1f} s)"
          + (f": {why}" if why else ""), flush=True)
    if why:
        FAILURES.append(name)
        print("    " + "\n    ".join(lines[-25:]), flush=True)


def fail(name: str, why: str) -> None:
    FAILURES.append(name)
    print(f"  [FAIL] {name}: {why}", flush=True)


def load_extras(clone: Path) -> dict[str, set[str]]:
    """Each extra of the clone's pyproject.toml -> the extras it installs (itself and the
    ``tfbus[...]`` extras it names, transitively)."""
    import tomllib

    table = tomllib.loads((clone / "pyproject.toml").read_text(encoding="utf-8"))
    declared: dict[str, list[str]] = table["project"]["optional-dependencies"]
    direct: dict[str, set[str]] = {}
    for extra, requirements in declared.items():
        direct[extra] = {extra}
        for requirement in requirements:
            m = re.match(r"\s*tfbus\[([^\]]+)\]", requirement)
            if m:
                direct[extra] |= {x.strip() for x in m.group(1).split(",")}
    closed: dict[str, set[str]] = {}
    for extra in direct:
        seen: set[str] = set()
        todo = [extra]
        while todo:
            x = todo.pop()
            if x not in seen:
                seen.add(x)
                todo.extend(direct.get(x, set()) - seen)
        closed[extra] = seen
    return closed


def sweep(label: str, python: Path, installed: set[str], cwd: Path) -> None:
    """The import sweep in one venv (``installed``: the extras installed there)."""
    ok, out = step(f"{label}: import every tfbus module", [python, "-c", SWEEP],
                   timeout=600, cwd=cwd)
    if not ok:
        return
    result: dict[str, object] = json.loads(out.strip().splitlines()[-1])
    imported = sum(1 for v in result.values() if v == "ok")
    needing = {}
    for module, outcome in sorted(result.items()):
        if outcome == "ok":
            continue
        assert isinstance(outcome, list)
        kind, name, message = outcome
        if kind == "MissingExtraError" and name not in installed:
            needing[module] = name
        elif kind == "MissingExtraError":
            fail(f"{label}: {module}",
                 f"the '{name}' extra is installed but {module} misses a package: {message}")
        elif kind == "ModuleNotFoundError":
            fail(f"{label}: {module}",
                 f"imports '{name}', which no installed extra brings and no "
                 f"tfbus._extras.require names: declare it in the extra that enables "
                 f"{module} and check it there ({message})")
        else:
            fail(f"{label}: {module}", f"import raised {kind}: {message}")
    extras_needed = ", ".join(f"{m} [{e}]" for m, e in needing.items()) or "none"
    print(f"    {imported} modules imported; needing an extra not installed here: "
          f"{extras_needed}", flush=True)


README_BLOCK = re.compile(r"```python\n(.*?)```", re.S)


def readme_example(label: str, python: Path, clone: Path, tmp: Path, backend: str) -> None:
    """The README's example, pasted into a file as it is (and run on ``backend``)."""
    code = README_BLOCK.search((clone / "README.md").read_text(encoding="utf-8"))
    if code is None:
        fail(f"{label}: README example", "no python block in README.md")
        return
    text = code.group(1)
    if backend != "asyncio":
        text = text.replace("anyio.run(main)", f"anyio.run(main, backend={backend!r})")
    script = tmp / f"readme_{label}_{backend}.py"
    script.write_text(text, encoding="utf-8")
    step(f"{label}: README example on {backend}", [python, script], timeout=120, cwd=tmp,
         expect="Point(x=1.1")


def clean_env(venv: Path) -> dict[str, str]:
    """The environment a user's shell has with ``venv`` activated (nothing of ours)."""
    env = {k: v for k, v in os.environ.items()
           if k not in {"PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME", "TFBUS_PURE_PYTHON"}}
    env["VIRTUAL_ENV"] = str(venv)
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return env


def stage_demo(python: str, clone: Path) -> None:
    print("== make demo (a fresh clone, a new .venv: the README's first command)", flush=True)
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV"}}
    step("make demo", ["make", "demo", f"PYTHON={python}"], timeout=1200, cwd=clone, env=env,
         expect=DEMO_LINE)


def stage_core(python: str, clone: Path, tmp: Path) -> None:
    print("== pip install . (no extra; the newest release of every dependency)", flush=True)
    venv = tmp / "venv-core"
    subprocess.run([python, "-m", "venv", str(venv)], check=True, timeout=300)
    env = clean_env(venv)
    bin_ = venv / "bin"
    ok, _ = step("pip install .", [bin_ / "python", "-m", "pip", "install", "-q", "."],
                 timeout=1200, cwd=clone, env=env)
    if not ok:
        return
    versions(bin_ / "python", env)
    step("core: tfbus --version", [bin_ / "tfbus", "--version"], timeout=60, cwd=tmp, env=env)
    step("core: tfbus demo", [bin_ / "tfbus", "demo", "--duration", "2"], timeout=120,
         cwd=tmp, env=env, expect=DEMO_LINE)
    sweep("core", bin_ / "python", set(), tmp)
    readme_example("core", bin_ / "python", clone, tmp, "asyncio")


def versions(python: Path, env: dict[str, str]) -> None:
    """Print the versions a venv resolved for tfbus's direct dependencies (one whose
    environment marker leaves it out here, e.g. ``exceptiongroup`` on Python >= 3.11, is
    named as not installed)."""
    code = (
        "import importlib.metadata as m, re\n"
        "names = {re.split(r'[ ;<>=!~\\[]', r)[0]\n"
        "         for r in m.requires('tfbus') or () if 'extra ==' not in r}\n"
        "def version(n):\n"
        "    try:\n"
        "        return f'{n}=={m.version(n)}'\n"
        "    except m.PackageNotFoundError:\n"
        "        return f'{n} (not installed: its marker leaves it out)'\n"
        "print(', '.join(sorted(version(n) for n in names)))\n"
    )
    done = subprocess.run([str(python), "-c", code], capture_output=True, text=True,
                          timeout=60, env=env, check=False)
    print(f"    resolved: {done.stdout.strip() or done.stderr.strip()[-300:]}", flush=True)


def tools_uv(tmp: Path, python: str) -> Path:
    """uv, from PyPI, in a venv of its own."""
    tools = tmp / "venv-tools"
    subprocess.run([python, "-m", "venv", str(tools)], check=True, timeout=300)
    ok, _ = step("pip install uv (tools venv)", [tools / "bin" / "python", "-m", "pip",
                 "install", "-q", "uv>=0.5"], timeout=600)
    if not ok:
        raise SystemExit(1)
    return tools / "bin" / "uv"


def build_wheel(python: str, clone: Path, tmp: Path) -> Path | None:
    out = tmp / "wheel"
    ok, _ = step("build the wheel once (pip wheel --no-deps)",
                 [python, "-m", "pip", "wheel", "-q", "--no-deps", "-w", out, "."],
                 timeout=1200, cwd=clone)
    wheels = sorted(out.glob("tfbus-*.whl"))
    return wheels[0] if ok and wheels else None


def core_requirements(clone: Path) -> list[str]:
    """``[project] dependencies`` of the clone's pyproject.toml."""
    import tomllib

    table = tomllib.loads((clone / "pyproject.toml").read_text(encoding="utf-8"))
    return list(table["project"]["dependencies"])


def uv_venv(uv: Path, python: str, venv: Path, requirement: str, *,
            lowest: Sequence[str] = ()) -> tuple[bool, dict[str, str]]:
    env = clean_env(venv)
    env.pop("UV_PYTHON", None)
    subprocess.run([str(uv), "venv", "-q", "--seed", "-p", python, str(venv)], check=True,
                   timeout=300, env=env)
    cmd: list[str | Path] = [uv, "pip", "install", "-q", "-p", venv / "bin" / "python"]
    if lowest:
        # tfbus's own requirements given as direct ones, so that lowest-direct takes
        # each at its floor (the wheel's requirements alone are transitive to uv).
        cmd += ["--resolution", "lowest-direct", *lowest]
    ok, _ = step(f"install {requirement.split('/')[-1]}"
                 + (" (lowest-direct)" if lowest else ""),
                 [*cmd, requirement], timeout=1200, env=env)
    return ok, env


def extra_commands(extra: str, bin_: Path, clone: Path, tmp: Path, env: dict[str, str],
                   closed: set[str]) -> None:
    """The commands docs/cli.md says ``extra`` enables, once each."""
    tfbus = bin_ / "tfbus"
    py = bin_ / "python"
    run = {"timeout": 180.0, "cwd": clone, "env": env}
    if "bag" in closed:
        step(f"[{extra}] tfbus bag-info", [tfbus, "bag-info", TURTLE_BAG], **run,
             expect="turtle1")
        step(f"[{extra}] tfbus echo --bag", [tfbus, "echo", "world", "turtle1", "--bag",
             TURTLE_BAG, "--time", "1396293889.0"], **run, expect="Translation")
        step(f"[{extra}] tfbus monitor --bag", [tfbus, "monitor", "--bag", TURTLE_BAG], **run)
        step(f"[{extra}] tfbus doctor --bag", [tfbus, "doctor", "--bag", TURTLE_BAG], **run)
        step(f"[{extra}] tfbus frames --bag", [tfbus, "frames", "--bag", TURTLE_BAG, "-o",
             tmp / f"frames-{extra}.gv"], **run)
    if "zenoh" in closed:
        step(f"[{extra}] tfbus router --help", [tfbus, "router", "--help"], **run)
        serve_step(f"[{extra}] tfbus router on 127.0.0.1, then Ctrl-C",
                   [tfbus, "router", "--listen", "tcp/127.0.0.1:0"], "listening on",
                   cwd=clone, env=env)
        step(f"[{extra}] tfbus.transports.zenoh", [py, "-c",
             "import tfbus.transports.zenoh as z; print(z.__name__)"], **run)
    if "ros1" in closed:
        step(f"[{extra}] tfbus.transports.ros1", [py, "-c",
             "import tfbus.transports.ros1 as r; print(r.__name__)"], **run)
    if "ros2" in closed:
        step(f"[{extra}] tfbus.transports.ros2", [py, "-c",
             "import tfbus.transports.ros2 as r; print(r.__name__)"], **run)
    if "robot" in closed:
        step(f"[{extra}] tfbus.robot.load_urdf", [py, "-c",
             "from tfbus.robot import load_urdf; "
             "m = load_urdf('tests/data/urdf/tb3_burger.urdf'); print(m.name)"], **run,
             expect="turtlebot3_burger")
        step(f"[{extra}] tfbus robot-state-publisher --help",
             [tfbus, "robot-state-publisher", "--help"], **run)
    if "trio" in closed:
        readme_example(extra, py, clone, tmp, "trio")
    if "view" in closed:
        step(f"[{extra}] tfbus view --help", [tfbus, "view", "--help"], **run)
        serve_step(f"[{extra}] tfbus view --bus memory, then Ctrl-C",
                   [tfbus, "view", "--bus", "memory", "--port", "0"], "tfbus view: http://",
                   cwd=clone, env=env)
    if "web" in closed:
        step(f"[{extra}] tfbus web --help", [tfbus, "web", "--help"], **run)
        serve_step(f"[{extra}] tfbus web --bus memory, then Ctrl-C",
                   [tfbus, "web", "--bus", "memory", "--port", "0"], "tfbus web: ws://",
                   cwd=clone, env=env)
    if "table" in closed:
        parquet = tmp / f"poses-{extra}.parquet"
        step(f"[{extra}] tfbus lookup --bag", [tfbus, "lookup", "--bag", TURTLE_BAG,
             "--target", "world", "--source", "turtle1", "--every", "1", "-o", parquet],
             **run)
        step(f"[{extra}] read the Parquet table", [py, "-c",
             f"import pyarrow.parquet as pq; t = pq.read_table({str(parquet)!r}); "
             "assert t.num_rows > 0, t.num_rows; print(t.num_rows, 'rows')"], **run)
    if "dask" in closed:
        step(f"[{extra}] tfbus.table.dask", [py, "-c", "import tfbus.table.dask"], **run)
    if "ray" in closed:
        step(f"[{extra}] tfbus.table.ray", [py, "-c", "import tfbus.table.ray"], **run)


def stage_extras(uv: Path, python: str, wheel: Path, clone: Path, tmp: Path,
                 only: Sequence[str]) -> None:
    print("== each extra alone (a new venv with tfbus[EXTRA] only)", flush=True)
    closure = load_extras(clone)
    for extra in only or sorted(closure):
        if extra not in closure:
            fail(f"extra {extra}", "not an extra of pyproject.toml")
            continue
        t0 = time.perf_counter()
        print(f"-- [{extra}] (installs {', '.join(sorted(closure[extra]))})", flush=True)
        venv = tmp / f"venv-extra-{extra}"
        ok, env = uv_venv(uv, python, venv, f"{wheel}[{extra}]")
        if ok:
            sweep(f"[{extra}]", venv / "bin" / "python", closure[extra], tmp)
            extra_commands(extra, venv / "bin", clone, tmp, env, closure[extra])
        shutil.rmtree(venv, ignore_errors=True)
        TIMES[f"extra {extra}"] = time.perf_counter() - t0


def stage_oldest(uv: Path, python: str, wheel: Path, clone: Path, tmp: Path) -> None:
    print("== the core at the lowest versions pyproject.toml allows", flush=True)
    venv = tmp / "venv-oldest"
    ok, env = uv_venv(uv, python, venv, str(wheel), lowest=core_requirements(clone))
    if not ok:
        return
    bin_ = venv / "bin"
    versions(bin_ / "python", env)
    step("oldest: tfbus demo", [bin_ / "tfbus", "demo", "--duration", "2"], timeout=120,
         cwd=tmp, env=env, expect=DEMO_LINE)
    sweep("oldest", bin_ / "python", set(), tmp)
    readme_example("oldest", bin_ / "python", clone, tmp, "asyncio")
    # pytest alone beside the oldest core (its own dependencies leave tfbus's pins alone).
    step("oldest: install pytest", [uv, "pip", "install", "-q", "-p", bin_ / "python",
         "pytest>=8"], timeout=600, env=env)
    # The `pytest` script (not `python -m`): the clone's source tree stays off sys.path,
    # so `import tfbus` is the installed wheel at the oldest dependencies.
    step("oldest: tf2 conformance corpus", [bin_ / "pytest", "-q", "-p", "no:cacheprovider",
         "-p", "no:randomly", "tests/core/test_conformance.py"], timeout=1200, cwd=clone,
         env=env, expect=" passed")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--python", default=os.environ.get("PYTHON", "python3"),
                        help="the interpreter a user has (default: python3)")
    parser.add_argument("--only", default=",".join(STAGES),
                        help=f"stages to run, comma-separated (of {', '.join(STAGES)})")
    parser.add_argument("--extras", default="",
                        help="extras for the extras stage, comma-separated (default: all)")
    args = parser.parse_args()
    stages = [s for s in args.only.split(",") if s]
    unknown = set(stages) - set(STAGES)
    if unknown:
        parser.error(f"--only: unknown stage(s) {sorted(unknown)}; known: {STAGES}")
    python = shutil.which(args.python) or args.python
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="tfbus-check-installs-") as tmp_dir:
        tmp = Path(tmp_dir)
        clone = tmp / "clone"
        subprocess.run(["git", "clone", "-q", "--no-hardlinks", str(ROOT), str(clone)],
                       check=True, timeout=300)
        head = subprocess.run(["git", "-C", str(clone), "log", "-1", "--format=%h %s"],
                              capture_output=True, text=True, check=True).stdout.strip()
        print(f"check-installs: a fresh clone of {head[:72]} with {python}", flush=True)
        for stage in stages:
            t0 = time.perf_counter()
            if stage == "demo":
                stage_demo(python, clone)
            elif stage == "core":
                stage_core(python, clone, tmp)
            else:
                if "uv and the wheel" not in TIMES:
                    t_uv = time.perf_counter()
                    uv = tools_uv(tmp, python)
                    wheel = build_wheel(python, clone, tmp)
                    TIMES["uv and the wheel"] = time.perf_counter() - t_uv
                    if wheel is None:
                        break
                if stage == "extras":
                    stage_extras(uv, python, wheel, clone, tmp,
                                 [e for e in args.extras.split(",") if e])
                else:
                    stage_oldest(uv, python, wheel, clone, tmp)
            TIMES[stage] = time.perf_counter() - t0
    total = time.perf_counter() - started
    print("check-installs times: " + ", ".join(f"{k} {v:.0f} s" for k, v in TIMES.items())
          + f"; total {total:.0f} s")
    print("check-installs:", "all passed" if not FAILURES else
          f"{len(FAILURES)} FAILED: {FAILURES}")
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
