"""Build the compiled core (``tfbus/core/_c*.pyx``, the wire decoders
``tfbus/codecs/_cwire.pyx``, the laser projection ``tfbus/_claser.pyx``, the listener's
message handler ``tfbus/_clistener.pyx``, the bus's delivery ``tfbus/_cbus.pyx``, the
accounting of tf_monitor's tables ``tfbus/_cmonitor.pyx`` and of the doctor's checks
``tfbus/doctor/_cchecks.pyx``; Cython), optionally; everything else is in pyproject.toml.

The extensions are an accelerator, never a requirement: tfbus has a pure-Python core with
the same behaviour (``tfbus.core.COMPILED`` says which one is loaded).

* ``TFBUS_NO_EXTENSIONS=1`` (any value but ``""``/``0``) skips the extension altogether:
  the wheel is pure Python.
* Without a working C compiler (or without the Python headers) the build of the
  extension fails; this file then prints why and installs the pure-Python core instead
  of failing the whole install, in a wheel tagged ``py3-none-any`` as any pure wheel.
  ``TFBUS_REQUIRE_EXTENSIONS=1`` turns that fallback back into an error (used by
  ``make dist``: a release wheel must carry the compiled core).

The pattern is the one of PyYAML's and msgpack's ``setup.py`` (an optional extension whose
build failure falls back to pure Python).
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

# setuptools' editable install ends with an "Editable installation. Please be careful with
# folders in your working directory with the same name as your package" notice
# (setuptools.warnings.InformationOnly, setuptools/command/editable_wheel.py), which pip
# >= 25 shows even with -q: a box on every `make` target. tfbus's flat layout is the one
# it describes and is intended, so that notice (and only it) is not shown.
warnings.filterwarnings("ignore", message=r"Editable installation\.")


def _flag(name: str) -> bool:
    return os.environ.get(name, "").strip() not in ("", "0")


NO_EXTENSIONS = _flag("TFBUS_NO_EXTENSIONS")

COMPILED_MODULES = ("_cmath", "_ccache", "_ccore", "_cbatch")
"""The compiled core, one extension per job (``tfbus/core/<name>.pyx``; the ``.pxd`` files
beside them share declarations and inline math): scalar math, link storage, frame table
and walk, the batch kernel. All or none: ``tfbus.core._select`` loads the compiled core
only when every one of them is importable."""
COMPILED_CODECS = ("_cwire",)
"""The compiled codecs (``tfbus/codecs/<name>.pyx``), built with the core whose C helpers
they ``cimport``: ``_cwire``, the ROS 1 ``TFMessage`` decoder that
:mod:`tfbus.codecs.ros1` uses with the compiled core."""
COMPILED_SENSORS = ("_claser",)
"""Compiled sensor kernels (``tfbus/<name>.pyx``): ``_claser``, laser_geometry's
projection for :meth:`tfbus.laser.LaserProjection.project_laser`; used with the compiled
core, the numpy path otherwise."""
COMPILED_LISTENER = ("_clistener",)
"""The compiled message handler of a ``TransformListener`` (``tfbus/<name>.pyx``):
``_clistener``, a message of one transform stored with no Python frame; used with the
compiled core, the listener's own ``_handle`` otherwise."""
COMPILED_BUS = ("_cbus",)
"""The compiled publish path of the in-process bus (``tfbus/<name>.pyx``): ``_cbus``, a
publish's walk of its topic's subscribers and counters, the cancellation test before it
and the yield after it on asyncio, with no Python frame; used with the compiled core,
``Bus``'s own code otherwise."""
COMPILED_TABLES = ("_cmonitor",)
"""The compiled accounting of tf_monitor's tables (``tfbus/<name>.pyx``): ``_cmonitor``,
the loop of ``TfSummary.add`` over a message's transforms on typed fields; used with the
compiled core, ``TfSummary.add``'s own loop otherwise."""
COMPILED_DOCTOR = ("_cchecks",)
"""The compiled accounting of ``tfbus doctor``'s checks (``tfbus/doctor/<name>.pyx``):
``_cchecks``, the loop of ``Doctor.add`` over a message's transforms on typed per-link
fields; used with the compiled core, ``Doctor.add``'s own loop otherwise."""
REQUIRE_EXTENSIONS = _flag("TFBUS_REQUIRE_EXTENSIONS")

_FALLBACK = """
========================================================================
tfbus: the compiled core (tfbus/core/_c*.pyx) could not be built:
    {error}
tfbus is installed with its pure-Python core instead: same behaviour,
slower lookups (tfbus.core.COMPILED is False). To get the compiled core,
install a C compiler and the Python headers (Debian/Ubuntu:
`apt-get install gcc python3-dev`) and reinstall. Set
TFBUS_NO_EXTENSIONS=1 to skip this attempt and silence this message.
========================================================================
"""


class OptionalBuildExt(build_ext):
    """``build_ext`` whose failure (no compiler, no headers) is reported, not fatal."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # distutils' CompileError, PlatformError, ExecError...
            self._fallback(exc)
        if getattr(self.distribution, "tfbus_pure", False):
            self._remove_compiled()

    def build_extension(self, ext: Any) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:
            self._fallback(exc)

    def _remove_compiled(self) -> None:
        """A pure build carries no compiled module: all or none (``tfbus.core._select``).
        Those built before the failure, and an earlier build's in ``build/lib.*`` (which
        pip's in-tree build of a clone reuses), would otherwise go into the
        ``py3-none-any`` wheel."""
        for ext in self.extensions:
            path = self.get_ext_fullpath(ext.name)
            if os.path.exists(path):
                os.remove(path)

    def _fallback(self, exc: Exception) -> None:
        if REQUIRE_EXTENSIONS:
            raise
        self.distribution.tfbus_pure = True  # type: ignore[attr-defined]
        sys.stderr.write(_FALLBACK.format(error=f"{type(exc).__name__}: {exc}"))


def _pure_tagged(base: Any) -> Any:
    """``bdist_wheel`` whose wheel is tagged ``py3-none-any`` (and ``Root-Is-Purelib``)
    when the extension could not be built: it then holds no compiled code, and the
    tag bdist_wheel chose before the build (from ``has_ext_modules()``) would wrongly
    claim one Python and platform (``cp313-cp313-linux_x86_64``)."""

    class PureFallbackBdistWheel(base):  # type: ignore[misc, valid-type]
        def get_tag(self) -> tuple[str, str, str]:
            if getattr(self.distribution, "tfbus_pure", False):
                self.root_is_pure = True
            return tuple(super().get_tag())  # type: ignore[return-value]

    return PureFallbackBdistWheel


def _cmdclass() -> dict[str, Any]:
    commands: dict[str, Any] = {"build_ext": OptionalBuildExt}
    try:  # setuptools >= 70.1 (the build requires >= 77); else the wheel package's
        from setuptools.command.bdist_wheel import bdist_wheel
    except ImportError:
        try:
            from wheel.bdist_wheel import bdist_wheel  # type: ignore[no-redef]
        except ImportError:
            return commands  # no wheel building here (python setup.py build_ext)
    commands["bdist_wheel"] = _pure_tagged(bdist_wheel)
    return commands


def _extensions() -> list[Extension]:
    if NO_EXTENSIONS:
        sys.stderr.write("tfbus: TFBUS_NO_EXTENSIONS is set: pure-Python core only\n")
        return []
    try:
        from Cython.Build import cythonize
    except ImportError as exc:  # only outside pip's build isolation (Cython is required)
        if REQUIRE_EXTENSIONS:
            raise
        sys.stderr.write(_FALLBACK.format(error=f"Cython is not installed ({exc})"))
        return []
    # tf2's numbers are reproduced bit for bit only if the compiler keeps each multiply
    # and add separately rounded: no fused multiply-add contraction.
    extra = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]
    exts = [
        Extension(f"tfbus.{package}.{name}", [f"tfbus/{package}/{name}.pyx"],
                  extra_compile_args=extra)
        for package, names in (("core", COMPILED_MODULES), ("codecs", COMPILED_CODECS),
                               ("doctor", COMPILED_DOCTOR))
        for name in names
    ]
    exts += [
        Extension(f"tfbus.{name}", [f"tfbus/{name}.pyx"], extra_compile_args=extra)
        for name in (*COMPILED_SENSORS, *COMPILED_LISTENER, *COMPILED_BUS, *COMPILED_TABLES)
    ]
    return list(cythonize(exts, language_level=3))


setup(ext_modules=_extensions(), cmdclass=_cmdclass())
