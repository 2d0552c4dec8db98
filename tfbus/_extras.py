"""Optional dependencies: which extra brings which package, and the error a subpackage
raises at import when its extra is not installed (layer 1).

Each optional subpackage calls :func:`require` first thing, so ``import tfbus.bag``
without rosbags fails at once with a message naming the extra, both as installed from
the index and from a clone of the repository::

    tfbus.bag needs the 'rosbags' package: pip install 'tfbus[bag]'
    (from a clone of tfbus: pip install '.[bag]')

or, when this tfbus is installed editable from a clone (``make``'s ``.venv``), the
command that keeps it editable (:func:`extra_advice`).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import json
import sys
from pathlib import Path
from typing import Final
from urllib.parse import unquote, urlparse

from tfbus.errors import MissingExtraError

__all__ = [
    "EXTRAS", "MissingExtraError", "editable_clone", "extra_advice", "missing_extra", "require",
]

EXTRAS: Final[dict[str, str]] = {
    "rosbags": "bag", "mcap": "bag", "zenoh": "zenoh", "msgspec": "zenoh",
    "cyclonedds": "ros2", "urdf_parser_py": "robot", "lxml": "robot", "viser": "view",
    "foxglove": "view", "trio": "trio", "wsproto": "web",
}
"""The extra (``pyproject.toml`` ``[project.optional-dependencies]``) that installs each
importable top-level package tfbus uses optionally."""


def editable_clone() -> Path | None:
    """The clone this tfbus is installed editable from (``make``'s ``.venv``,
    ``pip install -e .``), or None: not installed, installed as a copy, or the tfbus
    imported is not the installed clone's (another one on ``PYTHONPATH``).

    Read from the distribution's ``direct_url.json`` (PEP 610: ``dir_info.editable`` and
    its ``file://`` ``url``).
    """
    try:
        text = importlib.metadata.distribution("tfbus").read_text("direct_url.json")
        info = json.loads(text or "null")
    except (importlib.metadata.PackageNotFoundError, ValueError, OSError):
        return None
    dir_info = info.get("dir_info") if isinstance(info, dict) else None
    url = info.get("url") if isinstance(info, dict) else None
    if not (isinstance(dir_info, dict) and dir_info.get("editable") is True
            and isinstance(url, str) and url.startswith("file://")):
        return None
    clone = Path(unquote(urlparse(url).path))
    here = Path(__file__).resolve().parent.parent  # the clone of the tfbus imported
    return clone if clone.resolve() == here else None


def extra_advice(package: str, extra: str) -> str:
    """How to install the ``extra`` that brings ``package``.

    ``pip install 'tfbus[EXTRA]' (from a clone of tfbus: pip install '.[EXTRA]')``; when
    this tfbus is installed editable from a clone (:func:`editable_clone`, e.g. the
    ``.venv`` that ``make`` makes), the command that keeps it editable, with this
    interpreter: ``PYTHON -m pip install -e 'CLONE[EXTRA]'`` (without ``-e``, pip would
    replace the editable install with a copy and compile the core again).
    """
    clone = editable_clone()
    if clone is not None:
        return (f"{sys.executable} -m pip install -e '{clone}[{extra}]' (tfbus is "
                f"installed editable from {clone}: -e keeps it so)")
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
            raise missing_extra(needed_by, package, extra or EXTRAS[package])


def missing_extra(needed_by: str, package: str, extra: str) -> MissingExtraError:
    """The :class:`MissingExtraError` for ``package`` (brought by ``extra``) that
    ``needed_by`` lacks, with :func:`extra_advice`'s install command."""
    return MissingExtraError(needed_by, package, extra, extra_advice(package, extra))
