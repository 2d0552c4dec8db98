"""Optional dependencies: which extra brings which package, and the error a subpackage
raises at import when its extra is not installed (layer 1).

Each optional subpackage calls :func:`require` first thing, so ``import tfbus.bag``
without rosbags fails at once with a message naming the extra, both as installed from
the index and from a clone of the repository::

    tfbus.bag needs the 'rosbags' package: pip install 'tfbus[bag]'
    (from a clone of tfbus: pip install '.[bag]')
"""

from __future__ import annotations

import importlib.util
from typing import Final

from tfbus.errors import MissingExtraError

__all__ = ["EXTRAS", "MissingExtraError", "extra_advice", "require"]

EXTRAS: Final[dict[str, str]] = {
    "rosbags": "bag", "mcap": "bag", "zenoh": "zenoh", "msgspec": "zenoh",
    "cyclonedds": "ros2", "urdf_parser_py": "robot", "lxml": "robot", "viser": "view",
    "foxglove": "view", "trio": "trio", "wsproto": "web",
}
"""The extra (``pyproject.toml`` ``[project.optional-dependencies]``) that installs each
importable top-level package tfbus uses optionally."""


def extra_advice(package: str, extra: str) -> str:
    """``pip install 'tfbus[EXTRA]' (from a clone of tfbus: pip install '.[EXTRA]')``."""
    return (f"pip install 'tfbus[{extra}]' (from a clone of tfbus: pip install "
            f"'.[{extra}]')")


def _installed(package: str) -> bool:
    try:
        return importlib.util.find_spec(package) is not None
    except (ImportError, ValueError):  # a finder refusing it, or sys.modules[name] = None
        return False


def require(needed_by: str, *packages: str, extra: str | None = None) -> None:
    """Raise :class:`MissingExtraError` for the first of ``packages`` that cannot be
    imported (found by :func:`importlib.util.find_spec`, without importing it).

    Args:
        needed_by: the module asking (``__name__``), named in the message.
        packages: top-level package names, keys of :data:`EXTRAS`.
        extra: the extra to name (default: the package's in :data:`EXTRAS`; e.g.
            ``ros1`` also brings rosbags).
    """
    for package in packages:
        if not _installed(package):
            raise MissingExtraError(needed_by, package, extra or EXTRAS[package])
