"""The installed distribution's version (``tfbus.__version__``, ``tfbus --version``).

Read from the package metadata (``importlib.metadata``), so ``pyproject.toml`` is the one
place the version is written. A source tree imported without being installed has no
metadata: it reports ``0+unknown`` rather than a stale number.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__: str = version("tfbus")
except PackageNotFoundError:  # a source checkout on sys.path, never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
