"""``make dist-check``: use ``dist/`` the way a new user would, in clean venvs.

* For each Python asked (default 3.10 and 3.13, those found): a fresh venv installs that
  interpreter's manylinux wheel with its dependencies, then ``tfbus --version`` and
  ``tfbus demo --duration 3`` must succeed and the demo must print the tutorial's line.
* The sdist installs with **no C compiler** (``PATH`` holds only the venv, so the
  configured ``gcc`` is not found): the install must succeed with the pure-Python core,
  say so in its build log, ship no compiled module, report ``tfbus.core.COMPILED`` False,
  and pass the tf2 conformance corpus (``tests/core/test_conformance.py`` from the sdist,
  run against the installed package).
* Optionally (``--sdist-compiled``) the sdist also installs *with* the compiler.

Every step is bounded in time; prints each step's time. Exit status 1 on any failure.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pythons import find_pythons

ROOT = Path(__file__).resolve().parents[2]
DEMO_LINE = "base_laser: (1.00, 0.20. 0.00) -----> base_link: (1.10, 0.20, 0.20)"
FAILURES: list[str] = []


def step(name: str, cmd: list[str], *, timeout: float, env: dict[str, str] | None = None,
         cwd: Path | None = None, expect: str | None = None) -> str:
    """Run one bounded step; record a failure instead of raising. Returns its output."""
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              env=env, cwd=cwd, check=False)
        out = done.stdout + done.stderr
        ok = done.returncode == 0 and (expect is None or expect in out)
    except subprocess.TimeoutExpired as exc:
        out, ok = f"timed out after {timeout} s: {exc}", False
    print(f"  [{'ok' if ok else 'FAIL'}] {name} ({time.perf_counter() - t0:.1f} s)", flush=True)
    if not ok:
        FAILURES.append(name)
        print("    " + "\n    ".join(out.strip().splitlines()[-25:]), flush=True)
    return out


def fresh_venv(python: Path, where: Path) -> Path:
    subprocess.run([str(python), "-m", "venv", str(where)], check=True, timeout=300)
    return where / "bin"


def check_wheel(version: str, python: Path, dist: Path, tmp: Path) -> None:
    tag = "cp" + version.replace(".", "")
    wheels = sorted(dist.glob(f"tfbus-*-{tag}-{tag}-*manylinux*.whl"))
    if not wheels:
        FAILURES.append(f"no manylinux wheel for {version} in {dist}")
        print(f"  [FAIL] no manylinux wheel for {version}")
        return
    print(f"Python {version}: {wheels[0].name}")
    bin_ = fresh_venv(python, tmp / f"venv-wheel-{version}")
    step("pip install wheel", [str(bin_ / "pip"), "install", "-q", str(wheels[0])], timeout=900)
    step("tfbus --version", [str(bin_ / "tfbus"), "--version"], timeout=60)
    step("tfbus demo --duration 3", [str(bin_ / "tfbus"), "demo", "--duration", "3"],
         timeout=120, cwd=tmp, expect=DEMO_LINE)
    step("compiled core loaded", [str(bin_ / "python"), "-c",
         "import tfbus.core as c; assert c.COMPILED is True, c.COMPILED"], timeout=60, cwd=tmp)


def check_sdist(python: Path, dist: Path, tmp: Path, *, compiler: bool) -> None:
    (sdist,) = dist.glob("tfbus-*.tar.gz")
    label = "with" if compiler else "without"
    print(f"sdist {label} a C compiler ({python}): {sdist.name}")
    bin_ = fresh_venv(python, tmp / f"venv-sdist-{label}")
    env = dict(os.environ)
    env.pop("CC", None)
    if not compiler:
        env["PATH"] = str(bin_)  # the configured compiler (gcc) is not found
    log = step("pip install sdist", [str(bin_ / "pip"), "install", "-v", "--no-cache-dir",
               str(sdist)], timeout=1200, env=env)
    fallback = "tfbus: the compiled core (tfbus/core/_c*.pyx) could not be built"
    if not compiler and fallback not in log:
        FAILURES.append("sdist without compiler: no fallback message in the build log")
        print("  [FAIL] the build log does not explain the fallback")
    expected = "True" if compiler else "False"
    step(f"tfbus.core.COMPILED is {expected}", [str(bin_ / "python"), "-c",
         f"import tfbus.core as c; assert c.COMPILED is {expected}, c.COMPILED"],
         timeout=60, cwd=tmp)
    if compiler:
        return
    src = tmp / "sdist-src"
    with tarfile.open(sdist) as tar:
        tar.extractall(src, filter="data") if sys.version_info >= (3, 12) else tar.extractall(src)
    (top,) = src.iterdir()
    step("pip install pytest hypothesis trio", [str(bin_ / "pip"), "install", "-q", "pytest",
         "hypothesis", "trio"], timeout=600)
    # The `pytest` script (not `python -m`): the current directory is not on sys.path, so
    # `import tfbus` is the installed package, not the sdist's source tree.
    out = step("conformance corpus (pure-Python core)", [str(bin_ / "pytest"), "-q", "-p",
               "no:cacheprovider", "tests/core/test_conformance.py"], timeout=1200, cwd=top,
               expect=" passed")
    print("    " + next((line for line in reversed(out.splitlines()) if " passed" in line), ""))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dist", type=Path, default=ROOT / "dist")
    parser.add_argument("--pythons", default="3.10,3.13")
    parser.add_argument("--sdist-compiled", action="store_true")
    args = parser.parse_args()
    found = find_pythons([v for v in args.pythons.split(",") if v])
    for missing in sorted(set(args.pythons.split(",")) - set(found)):
        print(f"Python {missing}: not found, skipped")
    with tempfile.TemporaryDirectory(prefix="tfbus-dist-check-") as tmp_dir:
        tmp = Path(tmp_dir)
        for version, python in found.items():
            check_wheel(version, python, args.dist, tmp)
        newest = found[max(found, key=lambda v: tuple(map(int, v.split("."))))]
        check_sdist(newest, args.dist, tmp, compiler=False)
        if args.sdist_compiled:
            check_sdist(newest, args.dist, tmp, compiler=True)
    print("dist-check:", "all passed" if not FAILURES else f"FAILED: {FAILURES}")
    return 1 if FAILURES else 0


if __name__ == "__main__":
    sys.exit(main())
