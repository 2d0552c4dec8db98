"""The install scripts of the real peers tell the truth with their exit status.

Each ``scripts/install/install_*.sh`` exits 0 with a ``ready`` line only when its peer works, and
non-zero with an ``unavailable: REASON`` line otherwise (``scripts/install/_peer.sh`` for the
Debian ones, ``scripts/install/install_ros2_env.sh`` for the ROS 2 venv). The failure paths run
the real scripts with stand-ins for the system's commands (``id``, ``dpkg-query``,
``apt-get``, ``chromium``) first on ``PATH``; the success paths run them as they are.
The ROS 2 venv is also built in a mount namespace where every ROS of ``/usr`` and ``/opt``
is hidden, and must use no package from outside itself.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from peer_install import INSTALL, require

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts" / "install"
APT_SCRIPTS = {
    "install_ros1.sh": "ros1",
    "install_ros1_rsp.sh": "ros1-robot-state-publisher",
    "install_laser_geometry.sh": "laser_geometry",
    "install_tf2_msgs_py.sh": "tf2-msgs-py",
    "install_chromium.sh": "chromium",
}
# What the scripts call, linked into the sandbox's PATH (everything else is absent).
TOOLS = ("bash", "cat", "date", "dirname", "grep", "mktemp", "rm", "timeout", "tr", "sed",
         "head", "tail", "sleep", "env")


def _sandbox(tmp_path: Path, stubs: dict[str, str]) -> dict[str, str]:
    """An environment whose PATH holds only TOOLS and the given stand-in commands."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in TOOLS:
        real = shutil.which(tool)
        assert real is not None, tool
        (bin_dir / tool).symlink_to(real)
    for name, body in stubs.items():
        path = bin_dir / name
        path.write_text("#!/bin/bash\n" + body + "\n")
        path.chmod(0o755)
    return {"PATH": str(bin_dir), "HOME": str(tmp_path), "LANG": "C"}


def _run(
    script: str, env: dict[str, str], timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    bash = shutil.which("bash")
    assert bash is not None
    return subprocess.run([bash, str(SCRIPTS / script)], env=env, capture_output=True,
                          text=True, timeout=timeout, check=False)


NOT_INSTALLED = {"dpkg-query": "exit 1", "pkg-config": "exit 1"}


@pytest.mark.parametrize("script", sorted(APT_SCRIPTS))
def test_not_root_and_not_installed_exits_non_zero_saying_why(script: str, tmp_path: Path) -> None:
    env = _sandbox(tmp_path, {**NOT_INSTALLED, "id": "echo 1000"})
    done = _run(script, env)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.strip() == (
        f"{APT_SCRIPTS[script]}: unavailable: not root: as root, run bash "
        f"{SCRIPTS / script} (apt-get install {_pkgs(script)})"
    )


@pytest.mark.parametrize("script", sorted(APT_SCRIPTS))
def test_a_failing_apt_get_exits_non_zero_saying_why(script: str, tmp_path: Path) -> None:
    calls = tmp_path / "apt-calls"
    env = _sandbox(tmp_path, {**NOT_INSTALLED, "id": "echo 0",
                              "apt-get": f'echo "$@" >> {calls}; exit 100'})
    done = _run(script, env)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.strip() == (
        f"{APT_SCRIPTS[script]}: unavailable: apt-get update failed or timed out "
        "(no package index?)"
    )
    lines = calls.read_text().splitlines()
    assert len(lines) == 2 and " install " in lines[0] and lines[1].endswith("update -qq")


@pytest.mark.parametrize("script", sorted(APT_SCRIPTS))
def test_an_install_that_leaves_the_packages_missing_is_not_ready(
    script: str, tmp_path: Path
) -> None:
    env = _sandbox(tmp_path, {**NOT_INSTALLED, "id": "echo 0", "apt-get": "exit 0"})
    done = _run(script, env)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.strip() == (
        f"{APT_SCRIPTS[script]}: unavailable: apt-get install {_pkgs(script)} ran, but the "
        "packages or their files are missing"
    )


def test_a_chromium_that_renders_nothing_is_not_ready(tmp_path: Path) -> None:
    """Installed (as dpkg says) but broken: the script renders a page and finds no output."""
    env = _sandbox(tmp_path, {"dpkg-query": "echo 'install ok installed'", "chromium": "exit 0"})
    done = _run("install_chromium.sh", env)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.strip() == (
        "chromium: unavailable: installed, but it does not work: "
        "headless chromium did not render a page"
    )


@pytest.mark.parametrize("script", sorted(APT_SCRIPTS))
def test_each_peer_installs_and_works_here(script: str) -> None:
    """On this machine (as CI runs it) every peer installs and its check passes; a second
    run finds it installed."""
    line = require(APT_SCRIPTS[script], script)
    assert line.startswith(f"{APT_SCRIPTS[script]}: ready ("), line
    again = subprocess.run(["bash", str(SCRIPTS / script)], capture_output=True, text=True,
                           timeout=300, check=False)
    assert again.returncode == 0
    assert again.stdout.strip() == f"{APT_SCRIPTS[script]}: ready (already installed)"


def _pkgs(script: str) -> str:
    for line in (SCRIPTS / script).read_text().splitlines():
        if line.startswith("PKGS="):
            return line.split("=", 1)[1].strip('"')
    raise AssertionError(f"{script} sets no PKGS")


def test_every_peer_has_an_install_command() -> None:
    scripts = {p.name for p in SCRIPTS.glob("install_*.sh")}
    named = {cmd.rsplit("/", 1)[1] for cmd in INSTALL.values()}
    assert named == scripts


def test_an_installer_that_exits_without_a_reason_is_named_by_its_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An installer exiting non-zero without an ``unavailable`` line: the skip's reason
    names it by its path from the repository root (where a reader runs it again), with its
    status and the end of its stderr."""
    import peer_install

    (tmp_path / "install_evo.sh").write_text("echo working\necho broken >&2\nexit 3\n")
    monkeypatch.setattr(peer_install, "SCRIPTS", tmp_path)
    monkeypatch.setenv("CI", "")
    with pytest.raises(pytest.skip.Exception) as info:
        peer_install.install("evo", "install_evo.sh", timeout=60)
    assert "evo unavailable: scripts/install/install_evo.sh exited 3: broken" in str(info.value)
    assert (ROOT / "scripts" / "install" / "install_evo.sh").is_file()


# -------------------------------------------------------------------------- ROS 2 venv


def _copy_recipe(tmp_path: Path) -> Path:
    """The ROS 2 recipe in a fresh root (no venv there yet)."""
    root = tmp_path / "root"
    (root / "scripts" / "install").mkdir(parents=True)
    shutil.copy(SCRIPTS / "install_ros2_env.sh", root / "scripts" / "install")
    shutil.copytree(SCRIPTS / "ros2", root / "scripts" / "install" / "ros2")
    return root


@pytest.mark.parametrize(
    ("env", "reason"),
    [
        ({"PY311": "/nonexistent/python3.11"},
         "/nonexistent/python3.11 not found (the ROS 2 wheels are cp311-only)"),
        ({"ROS_DISTRO": "noetic"}, "ROS_DISTRO must be kilted or jazzy, not 'noetic'"),
    ],
)
def test_ros2_env_that_cannot_be_built_exits_non_zero(
    env: dict[str, str], reason: str, tmp_path: Path
) -> None:
    root = _copy_recipe(tmp_path)
    done = subprocess.run(["bash", str(root / "scripts" / "install" / "install_ros2_env.sh")],
                          env={**os.environ, **env}, capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stdout.strip().splitlines()[-1] == f"ros2-env: unavailable: {reason}"
    assert not (root / ".venv-ros2").exists()


def test_ros2_env_uses_no_package_from_outside_it() -> None:
    """The built venv's tf2_msgs was configured with every CMake package from the venv."""
    require("ros2-env", "install_ros2_env.sh", timeout=1200)
    venv = ROOT / ".venv-ros2"
    found = (venv / ".tfbus-cmake-packages").read_text().split()
    dirs = dict(line.split(":PATH=", 1) for line in found)
    assert "ament_cmake_include_directories_DIR" in dirs  # the undeclared dependency
    assert "rosidl_default_generators_DIR" in dirs and "geometry_msgs_DIR" in dirs
    outside = {k: v for k, v in dirs.items() if not v.startswith(f"{venv}/")}
    assert not outside


def test_ros2_env_builds_with_every_system_ros_hidden(tmp_path: Path) -> None:
    """A fresh build where /opt and every ament or ROS directory of /usr/share are hidden
    by empty bind mounts (a private mount namespace): what a machine without Debian's
    ROS 1 sees. It must build from the pinned wheels alone and say ready."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("needs root and unshare(1) to hide /usr/share's ament in a mount namespace")
    require("ros2-env", "install_ros2_env.sh", timeout=1200)  # warms pip's cache
    root = _copy_recipe(tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    ros_dirs = sorted(
        p for p in Path("/usr/share").iterdir()
        if p.is_dir() and p.name.startswith(("ament", "ros", "catkin", "rosidl"))
    )
    hidden = [Path("/opt"), *ros_dirs]
    mounts = "".join(f"mount --bind {empty} {p} && " for p in hidden)
    check = ('test -z "$(ls /opt)" && '
             "! ls -d /usr/share/ament_cmake*/cmake 2>/dev/null | grep -q . && ")
    script = root / "scripts" / "install" / "install_ros2_env.sh"
    done = subprocess.run(
        ["unshare", "-m", "--propagation", "private", "bash", "-c",
         f"{mounts}{check}bash {script}"],
        capture_output=True, text=True, timeout=1200, check=False,
    )
    assert done.returncode == 0, (done.stdout[-2000:], done.stderr[-2000:])
    assert done.stdout.strip().splitlines()[-1].startswith("ros2-env: ready (")
    found = (root / ".venv-ros2" / ".tfbus-cmake-packages").read_text().split()
    assert found and all(f":PATH={root}/.venv-ros2/" in line for line in found)


# ------------------------------------------------------------------ a missing peer under CI


def test_a_missing_peer_fails_under_ci_and_skips_elsewhere(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from peer_install import peer_unavailable

    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception) as failed:
        peer_unavailable("ros1", "apt-get install failed")
    assert str(failed.value) == (
        "CI needs every real peer: ros1 unavailable: apt-get install failed "
        "(install it with: sudo bash scripts/install/install_ros1.sh)"
    )
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception) as skipped:
        peer_unavailable("ros2-env", "python3.11 not found")
    assert str(skipped.value) == (
        "ros2-env unavailable: python3.11 not found "
        "(install it with: bash scripts/install/install_ros2_env.sh)"
    )


SKIPPING = '''
import pytest

def test_netem_delay_and_loss():
    pytest.skip("tc qdisc netem is not available in this kernel: no such qdisc")

def test_other():
    pytest.skip("a peer that did not install")

def test_passes():
    pass
'''


@pytest.mark.parametrize("ci", ["true", ""])
def test_the_run_counts_skips_by_reason_and_ci_fails_on_an_unlisted_one(
    ci: str, tmp_path: Path
) -> None:
    """A run with this conftest: a listed skip (netem) and an unlisted one."""
    tests = tmp_path / "tests"
    (tests / "fleet").mkdir(parents=True)
    for name in ("conftest.py", "peer_install.py", "conformance.py"):
        shutil.copy(ROOT / "tests" / name, tests / name)
    (tests / "fleet" / "test_fleet_netns.py").write_text(SKIPPING)
    env = {**os.environ, "CI": ci}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         "-p", "no:randomly", "tests/fleet/test_fleet_netns.py"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False,
    )
    out = done.stdout
    assert "1 passed, 2 skipped" in out, out
    assert "skips by reason (2)" in out
    assert "   1  [listed] tc qdisc netem is not available in this kernel: no such qdisc" in out
    assert "   1  [NOT LISTED] a peer that did not install" in out
    if ci:
        assert done.returncode == 1, out
        assert "CI: 1 skip(s) not listed in tests/peer_install.py LEGITIMATE_SKIPS" in out
        assert "tests/fleet/test_fleet_netns.py::test_other: a peer that did not install" in out
    else:
        assert done.returncode == 0, out


# -------------------------------------------------------------------------- evo (PyPI)


def test_an_evo_that_pip_cannot_install_is_not_ready(tmp_path: Path) -> None:
    """``scripts/install/install_evo.sh`` with a pip that fails: status 1 and the reason, no ready
    line (the test peer is evo from PyPI, installed with ``pip install --target``)."""
    if not Path("/usr/bin/python3").exists():
        pytest.skip("the script checks Debian's python3 first; there is none here")
    failing = tmp_path / "python"
    failing.write_text("#!/bin/bash\necho 'no index here' >&2\nexit 1\n")
    failing.chmod(0o755)
    env = dict(os.environ, PIP_PYTHON=str(failing), TFBUS_EVO_DIR=str(tmp_path / "evo"))
    done = _run("install_evo.sh", env)
    lines = done.stdout.strip().splitlines()
    assert done.returncode == 1, (done.stdout, done.stderr)
    if "tf2_py or rospy does not import" in done.stdout:
        pytest.skip("Debian's ROS 1 is not installed: the script stops before pip")
    assert lines[-1].startswith(
        f"evo: unavailable: pip install --target {tmp_path / 'evo'} evo==1.38.1 failed"), lines
    assert lines[-1].endswith("no index here"), lines
    assert not (tmp_path / "evo" / ".tfbus-evo-ok").exists()
