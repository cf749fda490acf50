"""The compiled part of sahgrasp; everything else is declared in pyproject.toml."""

import sys

from setuptools import Extension, setup

# The compiled code keeps one order of floating-point operations: no fused multiply-add (the
# atlas kernels do numpy's or Python's arithmetic bit for bit, and the IK's results match on
# every machine).
FLAGS = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]
MODULES = ("atlas/_polytope", "atlas/_planar", "atlas/_quality", "ik/_lm")

setup(
    ext_modules=[
        Extension(
            "sahgrasp." + module.replace("/", "."),
            sources=[f"sahgrasp/{module}.c"],
            depends=["sahgrasp/_arrays.h", "sahgrasp/collision/_gjk.h"],
            extra_compile_args=FLAGS,
        )
        for module in MODULES
    ]
)
