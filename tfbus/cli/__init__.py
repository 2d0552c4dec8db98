"""The ``tfbus`` command line: the tf2 tools every tf user knows.

::

    tfbus bag-info PATH                       frames, parents, rates, span, static/dynamic
    tfbus echo SOURCE TARGET --bag PATH       like tf2_echo
    tfbus monitor --bag PATH                  like tf_monitor
    tfbus doctor --bag PATH                   what is wrong with the tree (--bus: live)
    tfbus frames --bag PATH -o frames.pdf     like view_frames (Graphviz)
    tfbus static-transform x y z yaw pitch roll parent child     (on --bus, default zenoh)
    tfbus replay PATH --rate 2                publish a bag on --bus, with a progress bar
    tfbus robot-state-publisher MODEL.urdf    robot_state_publisher (on --bus, default zenoh)
    tfbus joint-states MODEL.urdf             joint_state_publisher, animated (--bus)
    tfbus demo --duration 10                  the seed demo (tfbus.demos.tutorial)
    tfbus demo laser                          a simulated laser projected three ways
    tfbus demo listener / demo broadcaster    the tutorial's nodes as two processes (Zenoh)
    tfbus echo SOURCE TARGET --bus zenoh      ... echo, monitor, frames on a live bus
    tfbus view --bag PATH                     the frames live in a browser (rviz's TF display)
    tfbus router                              Zenoh's router for fleets (tcp/127.0.0.1:7447)
    tfbus serve-buffer --bus SPEC             answer lookups for thin clients (tfbus.remote)
    tfbus lookup --bag GLOB --target T --source S --every 0.1 -o poses.parquet
    tfbus web --bus SPEC                      tf for roslibjs / roslibpy web apps (rosbridge)
    tfbus --version                           tfbus <version> (the core in use)

One module per command (``tfbus/cli/<command>.py``, each defining ``command``), the
group and shared plumbing in ``_common.py``, the ``--bus`` option in ``_bus_spec.py``,
the transform sources in ``_tf_source.py`` (their face), ``_bag_source.py`` and
``_bus_source.py``, chosen from the options by ``_source_options.py``, running on a live
bus in ``_live_session.py``, what the two robot commands share in ``_robot.py``.
A command is registered by one line in :data:`COMMANDS`.

Every command has ``--help`` with examples. A bad argument prints one line,
``tfbus <command>: error: ...``, and exits with status 2; a damaged bag prints what was
readable, a one-line warning, and exits with status 1; a missing optional dependency is
one line naming the extra to install (``pip install 'tfbus[bag]'``, and the form for a
clone of the repository, ``pip install '.[bag]'``), exit status 2 as a usage error
(``tfbus.cli._common.MISSING_EXTRA_STATUS``). Ids from bags and peers are printed literally
(control characters escaped, never rich markup). Ctrl-C and SIGTERM end every command
cleanly.

Importing this package needs nothing beyond tfbus's own dependencies: click and rich are
imported when the command runs (:func:`main`), so ``tfbus`` without them says which
extra to install.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence
from typing import Any

__all__ = ["COMMANDS", "cli", "frames_dot", "main", "parse_static_args", "parse_time"]

COMMANDS: tuple[str, ...] = (
    "bag_info",
    "echo",
    "monitor",
    "frames",
    "static_transform",
    "replay",
    "robot_state_publisher",
    "joint_states",
    "demo",
    "view",
    "router",
    "serve_buffer",
    "doctor",
    "lookup",
    "web",
)
"""The command modules of ``tfbus/cli/``, in ``--help`` order: one line per command."""

# Public names re-exported lazily (they need click), by the module defining them.
_LAZY = {
    "cli": "tfbus.cli._common",
    "parse_time": "tfbus.cli._common",
    "frames_dot": "tfbus.cli.frames",
    "parse_static_args": "tfbus.cli.static_transform",
    "BagSource": "tfbus.cli._bag_source",
    "BusSource": "tfbus.cli._bus_source",
    "TfSource": "tfbus.cli._tf_source",
}

_loaded = False


def _load() -> Any:
    """The click group with every command of :data:`COMMANDS` registered."""
    global _loaded
    common = importlib.import_module("tfbus.cli._common")
    if not _loaded:
        for name in COMMANDS:
            common.cli.add_command(importlib.import_module(f"tfbus.cli.{name}").command)
        _loaded = True
    return common.cli


def __getattr__(name: str) -> Any:
    if name == "cli":
        return _load()
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'tfbus.cli' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tfbus`` command (``pyproject.toml``); returns the exit status.

    Without click or rich installed it prints one line naming the extra (``tfbus[cli]``)
    and returns 2, as for every missing optional dependency. Ctrl-C while the commands
    load (click, rich and the command modules: about a second on a loaded machine) ends
    it with status 130 and no traceback, as Ctrl-C during a command does."""
    try:
        _load()
    except KeyboardInterrupt:
        return 130
    except ImportError as err:
        missing = (getattr(err, "name", None) or "").partition(".")[0]
        if missing not in ("click", "rich"):
            raise
        from tfbus._extras import extra_advice

        print(f"tfbus: error: the command line needs the '{missing}' package: "
              f"{extra_advice(missing, 'cli')}", file=sys.stderr)
        return 2  # MISSING_EXTRA_STATUS (tfbus.cli._common needs click)
    common = importlib.import_module("tfbus.cli._common")
    code: int = common.run_main(argv)
    return code
