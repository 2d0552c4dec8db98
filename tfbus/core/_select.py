"""The one place that chooses tfbus's core: compiled (Cython) or pure Python, same
behaviour bit for bit. Each is split by job into twins:

==================  =========================  =========================
job                 compiled                   pure Python
==================  =========================  =========================
scalar math, rows   :mod:`tfbus.core._cmath`   :mod:`tfbus.core._pymath`
link storage        :mod:`tfbus.core._ccache`  :mod:`tfbus.core._pycache`
frame table, walk   :mod:`tfbus.core._ccore`   :mod:`tfbus.core._pycore`
batch kernel        :mod:`tfbus.core._cbatch`  :mod:`tfbus.core._pybatch`
==================  =========================  =========================

* The compiled core is loaded when it was built (wheels and installs with a C compiler).
* The pure-Python core is loaded when the compiled module is absent (an install without
  a C compiler, or with ``TFBUS_NO_EXTENSIONS=1``), or when the environment variable
  ``TFBUS_PURE_PYTHON`` is set (to anything but ``""`` / ``"0"``) at import time: the
  test suite uses that to run the tf2 conformance corpus against both cores.

A compiled module that exists but fails to import (an ABI mismatch, a broken build) is
an error, never a silent fallback. ``COMPILED`` says which core is loaded (re-exported as
``tfbus.core.COMPILED``), :func:`core_description` says it in words (``tfbus
--version`` prints it). The compiled modules above the core (the listener's handler,
the laser projection, the tables' and the doctor's accounting) are found by
:func:`compiled_extension`, by the same rule (the wire codecs, below the core's kernels,
by ``tfbus.codecs._compiled_wire``). When the pure core is loaded because the
compiled one is absent (not asked for with ``TFBUS_PURE_PYTHON``), one warning line is
logged at import on the ``tfbus`` logger (:data:`PURE_FALLBACK_WARNING`). Every other
module imports the core's names from here.
"""

from __future__ import annotations

import importlib.util
import logging
import os
from types import ModuleType
from typing import TYPE_CHECKING, Final

__all__ = [
    "COMPILED",
    "COMPILED_MODULES",
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
    "compiled_extension",
    "compose",
    "compose_full",
    "core_description",
    "fallback_warning",
    "format_sec",
    "inverse",
    "lerp_rows",
    "lookup_rows",
    "quat_multiply",
    "quat_rotate",
    "shadowed_install",
    "slerp",
    "slerp_rows",
]

ENV_PURE_PYTHON: Final = "TFBUS_PURE_PYTHON"
"""Set (not ``""`` / ``"0"``) at import time: load the pure-Python core."""


def pure_python_requested() -> bool:
    """Whether ``TFBUS_PURE_PYTHON`` asks for the pure-Python core."""
    return os.environ.get(ENV_PURE_PYTHON, "").strip() not in ("", "0")


COMPILED_MODULES: Final = ("_cmath", "_ccache", "_ccore", "_cbatch")
"""The compiled core's extensions (``setup.py`` builds them all or none)."""


def _load() -> tuple[tuple[ModuleType, ...], bool]:
    """The core's modules by job (math, caches, frame table and walk, batch kernel) and
    whether they are the compiled ones. The compiled modules are looked for first
    (``find_spec``): any absent, the pure core is loaded; all present, they are imported
    and any error importing them propagates."""
    if not pure_python_requested() and all(
        importlib.util.find_spec(f"tfbus.core.{name}") is not None for name in COMPILED_MODULES
    ):
        from tfbus.core import _cbatch, _ccache, _ccore, _cmath

        return (_cmath, _ccache, _ccore, _cbatch), True
    from tfbus.core import _pybatch, _pycache, _pycore, _pymath

    return (_pymath, _pycache, _pycore, _pybatch), False


IMPLEMENTATIONS, COMPILED = _load()
"""The loaded core's modules (math, caches, frame table and walk, batch kernel), and
whether they are the compiled ones."""

IMPLEMENTATION: Final = IMPLEMENTATIONS[2]
"""The loaded core's frame table and walk (``_ccore`` or ``_pycore``): the core proper."""


def compiled_extension(name: str) -> ModuleType | None:
    """The compiled extension ``name`` (a dotted module name, e.g. ``tfbus._clistener``)
    when the compiled core is loaded (:data:`COMPILED`: built, and ``TFBUS_PURE_PYTHON``
    not set) and the extension is installed; else None, and its caller runs its pure-Python
    twin. An extension that is installed but fails to import raises, as the core's own
    modules do (:func:`_load`): never a silent fallback.

    Raises:
        ImportError: the extension is installed but cannot be imported (an ABI mismatch,
            a broken build).
    """
    if not COMPILED or importlib.util.find_spec(name) is None:
        return None
    return importlib.import_module(name)


PURE_FALLBACK_WARNING: Final = (
    "tfbus: the compiled core (tfbus.core._c*) is not installed, using the pure-Python core "
    "(same results, slower lookups); reinstall with a C compiler and the Python headers "
    "for the compiled one, or set TFBUS_PURE_PYTHON=1 to choose the pure one"
)
"""The line logged (``tfbus`` logger, WARNING) when the compiled core is missing."""


def shadowed_install() -> str | None:
    """The directory of an installed tfbus that has the compiled core, when the tfbus
    imported is another copy without it (a source tree first on ``sys.path``: Python puts
    the current directory first, so running from a clone imports the clone), else None.

    The installed distribution is the one ``importlib.metadata`` finds (its ``RECORD``
    lists the compiled modules); an editable install lists none and is never reported.
    """
    from importlib.metadata import PackageNotFoundError, distribution
    from pathlib import Path

    try:
        files = distribution("tfbus").files or []
    except PackageNotFoundError:
        return None
    here = Path(__file__).resolve().parent
    for file in files:
        if file.parts[:2] == ("tfbus", "core") and file.name.startswith(COMPILED_MODULES):
            located = Path(str(file.locate())).resolve()
            if located.suffix in (".so", ".pyd") and located.parent != here and located.exists():
                return str(located.parent.parent)
    return None


def fallback_warning() -> str:
    """The warning logged at import when the compiled core is not loaded though not asked
    for: :data:`PURE_FALLBACK_WARNING`, or, when a source tree without it shadows an
    installed tfbus that has it, a line that says so and what to do."""
    installed = shadowed_install()
    if installed is None:
        return PURE_FALLBACK_WARNING
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return (
        f"tfbus: the tfbus imported from {here} has no compiled core and shadows the one "
        f"installed in {installed}, which has it (Python puts the current directory first "
        "on sys.path): run from another directory, or build the tree's compiled core in "
        "place with `python setup.py build_ext --inplace`"
    )


def core_description() -> str:
    """Which core is loaded, in words: ``compiled core`` or ``pure-Python core`` and why
    (``TFBUS_PURE_PYTHON`` set, or the compiled module not installed)."""
    if COMPILED:
        return "compiled core"
    if pure_python_requested():
        return f"pure-Python core: {ENV_PURE_PYTHON} is set"
    return "pure-Python core: the compiled one is not installed"


if not COMPILED and not pure_python_requested():
    logging.getLogger("tfbus").warning(fallback_warning())

if TYPE_CHECKING:
    # Both cores export the same names; the compiled modules' stubs are the contract.
    from tfbus.core._cbatch import batch_lookup, lookup_rows
    from tfbus.core._ccache import (
        OK,
        OLD_DATA,
        REPEATED_DATA,
        Link,
        StaticCache,
        TimeCache,
        format_sec,
    )
    from tfbus.core._ccore import (
        CONNECTIVITY_ERROR,
        EXTRAPOLATION_ERROR,
        INVALID,
        INVALID_ARGUMENT,
        LOOKUP_ERROR,
        MAX_GRAPH_DEPTH,
        NO_ERROR,
        UNKNOWN_FRAME,
        CoreBase,
    )
    from tfbus.core._cmath import (
        apply_transforms,
        compose,
        compose_full,
        inverse,
        lerp_rows,
        quat_multiply,
        quat_rotate,
        slerp,
        slerp_rows,
    )
else:
    for _module in IMPLEMENTATIONS:
        for _name in _module.__all__:
            globals()[_name] = getattr(_module, _name)
    del _module, _name

