"""The one place that chooses tfbus's core: compiled (:mod:`tfbus.core._ccore`, Cython) or
pure Python (:mod:`tfbus.core._pycore`), same behaviour bit for bit.

* The compiled core is loaded when it was built (wheels and installs with a C compiler).
* The pure-Python core is loaded when the compiled module is absent (an install without
  a C compiler, or with ``TFBUS_NO_EXTENSIONS=1``), or when the environment variable
  ``TFBUS_PURE_PYTHON`` is set (to anything but ``""`` / ``"0"``) at import time: the
  test suite uses that to run the tf2 conformance corpus against both cores.

A compiled module that exists but fails to import (an ABI mismatch, a broken build) is
an error, never a silent fallback. ``COMPILED`` says which core is loaded (re-exported as
``tfbus.core.COMPILED``), :func:`core_description` says it in words (``tfbus
--version`` prints it). When the pure core is loaded because the compiled one is absent
(not asked for with ``TFBUS_PURE_PYTHON``), one warning line is logged at import on the
``tfbus`` logger (:data:`PURE_FALLBACK_WARNING`). Every other module imports the core's
names from here.
"""

from __future__ import annotations

import importlib.util
import logging
import os
from types import ModuleType
from typing import TYPE_CHECKING, Final

__all__ = [
    "COMPILED",
    "CONNECTIVITY_ERROR",
    "ENV_PURE_PYTHON",
    "EXTRAPOLATION_ERROR",
    "INVALID",
    "INVALID_ARGUMENT",
    "LOOKUP_ERROR",
    "MAX_GRAPH_DEPTH",
    "NO_ERROR",
    "OK",
    "OLD_DATA",
    "PURE_FALLBACK_WARNING",
    "REPEATED_DATA",
    "UNKNOWN_FRAME",
    "CoreBase",
    "Link",
    "StaticCache",
    "TimeCache",
    "apply_transforms",
    "batch_lookup",
    "compose",
    "compose_full",
    "core_description",
    "format_sec",
    "inverse",
    "lerp_rows",
    "lookup_rows",
    "quat_multiply",
    "quat_rotate",
    "slerp",
    "slerp_rows",
]

ENV_PURE_PYTHON: Final = "TFBUS_PURE_PYTHON"
"""Set (not ``""`` / ``"0"``) at import time: load the pure-Python core."""


def pure_python_requested() -> bool:
    """Whether ``TFBUS_PURE_PYTHON`` asks for the pure-Python core."""
    return os.environ.get(ENV_PURE_PYTHON, "").strip() not in ("", "0")


def _load() -> tuple[ModuleType, bool]:
    """The core module to use and whether it is the compiled one. The compiled module is
    looked for first (``find_spec``): absent, the pure core is loaded; present, it is
    imported and any error importing it propagates."""
    if not pure_python_requested() and importlib.util.find_spec("tfbus.core._ccore") is not None:
        from tfbus.core import _ccore

        return _ccore, True
    from tfbus.core import _pycore

    return _pycore, False


IMPLEMENTATION, COMPILED = _load()
"""The loaded core module, and whether it is the compiled one."""

PURE_FALLBACK_WARNING: Final = (
    "tfbus: the compiled core (tfbus.core._ccore) is not installed, using the pure-Python core "
    "(same results, slower lookups); reinstall with a C compiler and the Python headers "
    "for the compiled one, or set TFBUS_PURE_PYTHON=1 to choose the pure one"
)
"""The line logged (``tfbus`` logger, WARNING) when the compiled core is missing."""


def core_description() -> str:
    """Which core is loaded, in words: ``compiled core`` or ``pure-Python core`` and why
    (``TFBUS_PURE_PYTHON`` set, or the compiled module not installed)."""
    if COMPILED:
        return "compiled core"
    if pure_python_requested():
        return f"pure-Python core: {ENV_PURE_PYTHON} is set"
    return "pure-Python core: the compiled one is not installed"


if not COMPILED and not pure_python_requested():
    logging.getLogger("tfbus").warning(PURE_FALLBACK_WARNING)

if TYPE_CHECKING:
    # Both cores export the same names; the compiled core's stub is the contract.
    from tfbus.core._ccore import (
        CONNECTIVITY_ERROR,
        EXTRAPOLATION_ERROR,
        INVALID,
        INVALID_ARGUMENT,
        LOOKUP_ERROR,
        MAX_GRAPH_DEPTH,
        NO_ERROR,
        OK,
        OLD_DATA,
        REPEATED_DATA,
        UNKNOWN_FRAME,
        CoreBase,
        Link,
        StaticCache,
        TimeCache,
        apply_transforms,
        batch_lookup,
        compose,
        compose_full,
        format_sec,
        inverse,
        lerp_rows,
        lookup_rows,
        quat_multiply,
        quat_rotate,
        slerp,
        slerp_rows,
    )
else:
    for _name in __all__:
        if _name not in ("COMPILED", "ENV_PURE_PYTHON", "PURE_FALLBACK_WARNING",
                         "core_description"):
            globals()[_name] = getattr(IMPLEMENTATION, _name)
    del _name
