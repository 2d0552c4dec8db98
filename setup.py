"""Build the compiled core (``tfbus/_ccore.pyx``, Cython); everything else is in
pyproject.toml."""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

# tf2's numbers are reproduced bit for bit only if the compiler keeps each multiply and
# add separately rounded: no fused multiply-add contraction.
extra = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]

setup(
    ext_modules=cythonize(
        [Extension("tfbus._ccore", ["tfbus/_ccore.pyx"], extra_compile_args=extra)],
        language_level=3,
    )
)
