"""The compiled part of sahgrasp; everything else is declared in pyproject.toml."""

import sys

from setuptools import Extension, setup

# The compiled code keeps one order of floating-point operations: no fused multiply-add (the
# polytopes do Python's arithmetic bit for bit, and the IK's results match on every machine).
FLAGS = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]

setup(
    ext_modules=[
        Extension(
            "sahgrasp.atlas._polytope",
            sources=["sahgrasp/atlas/_polytope.c"],
            extra_compile_args=FLAGS,
        ),
        Extension("sahgrasp.ik._lm", sources=["sahgrasp/ik/_lm.c"], extra_compile_args=FLAGS),
    ]
)
