"""Packaging: version, LICENSE, CHANGELOG, what the sdist carries, and the optional
compiled core (a build without a C compiler, or with ``TFBUS_NO_EXTENSIONS=1``, gives a
pure-Python wheel instead of failing).

The wheel builds run ``pip wheel`` from the sdist (pip's build isolation fetches
setuptools and Cython from the package index), each bounded in time. The full user
journey — manylinux wheels in clean 3.10/3.13 venvs, the demo, the conformance corpus
on the pure-Python core — is ``make dist && make dist-check``.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

import tfbus

ROOT = Path(__file__).resolve().parents[1]
FALLBACK_MESSAGE = "tfbus: the compiled core (tfbus/core/_c*.pyx) could not be built"


def _pyproject_version() -> str:
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    m = re.search(r'(?m)^version = "([^"]+)"$', text)
    assert m, "pyproject.toml has no static version"
    return m.group(1)


def test_version_comes_from_the_metadata() -> None:
    assert tfbus.__version__ == importlib.metadata.version("tfbus") == _pyproject_version()


def test_changelog_has_the_current_version() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert text.startswith("# Changelog")
    assert re.search(rf"(?m)^## \[?{re.escape(_pyproject_version())}\]? - ", text)


def test_license_is_the_apache_2_0_text_pyproject_declares() -> None:
    text = (ROOT / "LICENSE").read_bytes()
    # The standard text as the ASF distributes it (LICENSE-2.0.txt), byte for byte.
    assert hashlib.md5(text).hexdigest() == "3b83ef96387f14655fc854ddc3c6bd57"
    assert b"Apache License\n                           Version 2.0, January 2004" in text
    pyproject = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert 'license = "Apache-2.0"' in pyproject
    assert 'license-files = ["LICENSE"]' in pyproject
    meta = importlib.metadata.metadata("tfbus")
    assert meta["License-Expression"] == "Apache-2.0"


def _run(cmd: list[str], *, timeout: float, env: dict[str, str] | None = None,
         cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              env=env, cwd=cwd, check=False)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"{cmd[:4]}... timed out after {timeout} s: {exc.stdout!r}")


@pytest.fixture(scope="module")
def sdist(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    out = tmp_path_factory.mktemp("sdist")
    done = _run([sys.executable, "-m", "build", "--sdist", "--outdir", str(out), str(ROOT)],
                timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    (path,) = out.glob("tfbus-*.tar.gz")
    yield path


def test_sdist_carries_everything_needed_to_build_and_test(sdist: Path) -> None:
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    required = {
        "pyproject.toml", "setup.py", "README.md", "LICENSE", "CHANGELOG.md", "MANIFEST.in",
        "tfbus/__init__.py", "tfbus/py.typed", "tfbus/core/_select.py",
        *(f"tfbus/core/_c{job}.{ext}" for job in ("math", "cache", "core", "batch")
          for ext in ("pyx", "pyi")),
        "tfbus/codecs/_cwire.pyx", "tfbus/codecs/_cwire.pyi",
        "tfbus/doctor/_cchecks.pyx", "tfbus/doctor/_cchecks.pyi",
        *(f"tfbus/core/_c{job}.pxd" for job in ("math", "cache", "core", "results")),
        "tfbus/_claser.pyx", "tfbus/_claser.pyi", "tfbus/_clistener.pyx", "tfbus/_clistener.pyi",
        "tfbus/_cmonitor.pyx", "tfbus/_cmonitor.pyi", "tfbus/_cdelay.pxd",
        "tfbus/_cbus.pyx", "tfbus/_cbus.pyi",
        *(f"tfbus/core/_py{job}.py" for job in ("math", "cache", "core", "batch")),
        "tests/core/test_conformance.py", "tests/conformance.py", "tests/data/public.jsonl.gz",
        "docs/index.md", "mkdocs.yml",
        # the peer programs the interop tests run beside tfbus, and the peers' installers
        "peers/ros1/ros1_peers.py", "peers/debian/tf2_py_side.py", "peers/ros2/tf_peer.py",
        "scripts/install/install_ros1.sh", "scripts/install/_peer.sh",
    }
    assert required <= names, sorted(required - names)
    # Never generated or built files: the C is regenerated from the .pyx by Cython.
    assert not [n for n in names if n.endswith((".so", ".pyc", ".c"))]


def _wheel(sdist: Path, out: Path, env: dict[str, str]) -> tuple[Path, str]:
    done = _run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "--no-cache-dir",
                 "-w", str(out), str(sdist)], timeout=900, env=env)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    (wheel,) = out.glob("tfbus-*.whl")
    return wheel, log


def _members(wheel: Path) -> list[str]:
    with zipfile.ZipFile(wheel) as z:
        return z.namelist()


def test_without_a_c_compiler_the_sdist_builds_pure_python(
    sdist: Path, tmp_path: Path
) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "TFBUS_NO_EXTENSIONS")}
    env["PATH"] = str(Path(sys.executable).parent)  # the configured compiler is not found
    wheel, log = _wheel(sdist, tmp_path, env)
    assert FALLBACK_MESSAGE in log
    assert "pure-Python core" in log
    # A pure wheel, not one tagged for this Python and platform.
    assert wheel.name == f"tfbus-{_pyproject_version()}-py3-none-any.whl"
    with zipfile.ZipFile(wheel) as z:
        meta = z.read(f"tfbus-{_pyproject_version()}.dist-info/WHEEL").decode()
    assert "Root-Is-Purelib: true" in meta and "Tag: py3-none-any" in meta, meta
    members = _members(wheel)
    pure = {"tfbus/core/buffer_core.py", "tfbus/core/_pycore.py", "tfbus/core/_select.py"}
    assert pure <= set(members)
    assert not [m for m in members if m.endswith(".so")]


def test_tfbus_no_extensions_gives_a_pure_wheel(sdist: Path, tmp_path: Path) -> None:
    env = dict(os.environ, TFBUS_NO_EXTENSIONS="1")
    wheel, log = _wheel(sdist, tmp_path, env)
    assert wheel.name.endswith("-py3-none-any.whl")
    assert "TFBUS_NO_EXTENSIONS is set" in log
    members = _members(wheel)
    assert not [m for m in members if m.endswith((".so", ".pyx", ".pxd", ".c"))]
    assert "tfbus/core/_ccore.pyi" in members and "tfbus/py.typed" in members


def _project_copy(dest: Path) -> Path:
    """The files a build reads, copied (a build writes build/ and *.egg-info next to them)."""
    for name in ("pyproject.toml", "setup.py", "README.md", "LICENSE", "MANIFEST.in"):
        shutil.copy2(ROOT / name, dest / name)
    shutil.copytree(ROOT / "tfbus", dest / "tfbus",
                    ignore=shutil.ignore_patterns("*.so", "*.c", "__pycache__"))
    return dest


def test_editable_install_is_quiet(tmp_path: Path) -> None:
    """``pip install -q -e .`` (what every ``make`` target may run) prints
    nothing: not setuptools' "Editable installation ... Please be careful" box, which pip
    shows even with -q. Into a new venv, from a copy of the project."""
    venv = tmp_path / "venv"
    done = _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], timeout=120)
    assert done.returncode == 0, done.stderr
    project = tmp_path / "project"
    project.mkdir()
    _project_copy(project)
    env = dict(os.environ, TFBUS_NO_EXTENSIONS="1")  # the box is the same with or without
    done = _run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"),
                 "install", "-q", "--no-deps", "-e", str(project)], timeout=900, env=env)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-4000:]
    assert "Editable installation" not in log and "Please be careful" not in log, log
    # pip's own notes about this machine's index configuration are not the build's.
    noise = [ln for ln in log.splitlines()
             if ln.strip() and not re.match(r"WARNING: Location .* is ignored", ln)]
    assert noise == [], log


# An editable install's finder (setuptools' __editable__ module) would still find the
# repository's tfbus.core._ccore: without it, the tfbus on PYTHONPATH is the one imported.
NO_EDITABLE_FINDER = ("import sys; sys.meta_path[:] = [f for f in sys.meta_path if not "
                      "getattr(f, '__module__', '').startswith('__editable__')]; ")


def test_the_pure_fallback_says_so(tmp_path: Path) -> None:
    """tfbus without its compiled module (a copy of the package, .py files
    only, first on sys.path) logs one warning line at import and ``tfbus --version``
    names the core; choosing the pure core with TFBUS_PURE_PYTHON=1 is silent."""
    shutil.copytree(ROOT / "tfbus", tmp_path / "tfbus",
                    ignore=shutil.ignore_patterns("*.so", "*.c", "*.pyx", "__pycache__"))
    env = {k: v for k, v in os.environ.items() if k != "TFBUS_PURE_PYTHON"}
    env["PYTHONPATH"] = str(tmp_path)
    code = NO_EDITABLE_FINDER + "import tfbus, tfbus.core as c; print(tfbus.__file__, c.COMPILED)"
    done = _run([sys.executable, "-c", code], timeout=120, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"{tmp_path / 'tfbus' / '__init__.py'} False\n"
    from tfbus.core._select import PURE_FALLBACK_WARNING

    assert done.stderr == PURE_FALLBACK_WARNING + "\n"
    assert "\n" not in PURE_FALLBACK_WARNING and "pure-Python core" in PURE_FALLBACK_WARNING
    version = importlib.metadata.version("tfbus")
    cli = NO_EDITABLE_FINDER + "from tfbus.cli import main; sys.exit(main(['--version']))"
    done = _run([sys.executable, "-c", cli], timeout=120, env=env, cwd=tmp_path)
    assert (done.returncode, done.stdout) == (
        0, f"tfbus {version} (pure-Python core: the compiled one is not installed)\n")
    env["TFBUS_PURE_PYTHON"] = "1"
    done = _run([sys.executable, "-c", cli], timeout=120, env=env, cwd=tmp_path)
    assert (done.returncode, done.stdout, done.stderr) == (
        0, f"tfbus {version} (pure-Python core: TFBUS_PURE_PYTHON is set)\n", "")


def test_a_pure_rebuild_of_a_clone_carries_no_stale_compiled_core(tmp_path: Path) -> None:
    """A clone built once with a compiler (its ``build/lib.*`` holds the compiled core),
    then again without one: the second wheel is pure, with no compiled module from the
    first build in it (pip builds a directory in place and reuses ``build/``)."""
    import sysconfig

    (tmp_path / "clone").mkdir()
    project = _project_copy(tmp_path / "clone")
    lib = project / "build" / f"lib.{sysconfig.get_platform()}-{sys.implementation.cache_tag}"
    (lib / "tfbus" / "core").mkdir(parents=True)
    # what a compiled build for this interpreter leaves in its build/lib.* (the checkout
    # may also hold other Pythons' builds, which no build of this one would copy there)
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    compiled = sorted((ROOT / "tfbus" / "core").glob(f"_c*{suffix}"))
    if not compiled:
        pytest.skip("this checkout has no compiled core to leave behind")
    for so in compiled:  # what the first, compiled build left in build/
        shutil.copy2(so, lib / "tfbus" / "core" / so.name)
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "TFBUS_NO_EXTENSIONS")}
    env["PATH"] = str(Path(sys.executable).parent)  # the configured compiler is not found
    wheel, log = _wheel(project, tmp_path / "out", env)
    assert FALLBACK_MESSAGE in log
    assert wheel.name == f"tfbus-{_pyproject_version()}-py3-none-any.whl"
    assert not [m for m in _members(wheel) if m.endswith(".so")]


def test_a_source_tree_shadowing_a_compiled_install_says_so(tmp_path: Path) -> None:
    """Python run from a clone imports the clone's tfbus (no compiled core there) before
    the installed one (compiled): the warning names both places and what to do, instead
    of telling the user to reinstall with a C compiler."""
    compiled = sorted((ROOT / "tfbus" / "core").glob("_c*.so"))
    if not compiled:
        pytest.skip("this checkout has no compiled core to install")
    clone = tmp_path / "clone"
    shutil.copytree(ROOT / "tfbus", clone / "tfbus",
                    ignore=shutil.ignore_patterns("*.so", "*.c", "*.pyx", "__pycache__"))
    # An installed tfbus (as pip lays one out): the package with its compiled core and a
    # dist-info whose RECORD lists the files.
    site = tmp_path / "site"
    shutil.copytree(ROOT / "tfbus", site / "tfbus",
                    ignore=shutil.ignore_patterns("*.c", "*.pyx", "__pycache__"))
    info = site / f"tfbus-{_pyproject_version()}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: tfbus\nVersion: {_pyproject_version()}\n"
    )
    record = [f"{p.relative_to(site).as_posix()},," for p in sorted((site / "tfbus").rglob("*"))
              if p.is_file()]
    (info / "RECORD").write_text("\n".join(record) + "\n")
    env = {k: v for k, v in os.environ.items() if k != "TFBUS_PURE_PYTHON"}
    env["PYTHONPATH"] = os.pathsep.join([str(clone), str(site)])
    code = NO_EDITABLE_FINDER + "import tfbus, tfbus.core as c; print(tfbus.__file__, c.COMPILED)"
    done = _run([sys.executable, "-c", code], timeout=120, env=env, cwd=clone)
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"{clone / 'tfbus' / '__init__.py'} False\n"
    assert done.stderr == (
        f"tfbus: the tfbus imported from {clone / 'tfbus'} has no compiled core and shadows "
        f"the one installed in {site / 'tfbus'}, which has it (Python puts the current "
        "directory first on sys.path): run from another directory, or build the tree's "
        "compiled core in place with `python setup.py build_ext --inplace`\n"
    )
