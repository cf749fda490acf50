"""Chart domains: convex polytopes in a chart's parameter space, cut by neighbours' half-spaces.

The polytope itself is compiled (``_polytope.c``): a chart's polytope has a handful of vertices
and a build cuts polytopes hundreds of thousands of times, one plane at a time, so that the cost
in Python was the interpreter's per call, not the arithmetic (docs/methods/atlas.md, "Compiled
polytopes"). Vertex/face incidence is kept as bit masks; for k = 2 the vertices go round the
polygon counter-clockwise, so that a cut is a clip of consecutive vertices, and a polytope is
built from all its planes at once through the dual polygon (Andrew's monotone chain); for other
k it is the cube cut by one plane after the other.
"""

from __future__ import annotations

from sahgrasp.atlas._polytope import MAX_FACES, Polytope, compatible

__all__ = ["CUT_TOL", "MAX_FACES", "Polytope", "compatible"]

CUT_TOL = 1e-9
"""A vertex closer than this (times the chart radius r) to a plane lies on it."""
