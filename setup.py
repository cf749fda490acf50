"""The compiled part of sahgrasp; everything else is declared in pyproject.toml."""

import sys

from setuptools import Extension, setup

# The polytope code keeps Python's order of floating-point operations: no fused multiply-add.
FLAGS = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]

setup(
    ext_modules=[
        Extension(
            "sahgrasp.atlas._polytope",
            sources=["sahgrasp/atlas/_polytope.c"],
            extra_compile_args=FLAGS,
        ),
        Extension(
            "sahgrasp.atlas._planar",
            sources=["sahgrasp/atlas/_planar.c"],
            extra_compile_args=FLAGS,
        ),
        Extension(
            "sahgrasp.atlas._quality",
            sources=["sahgrasp/atlas/_quality.c"],
            extra_compile_args=FLAGS,
        ),
    ]
)
