"""Higher-dimensional continuation: an atlas of an implicitly defined k-manifold F(x) = 0.

Henderson's method as used in Section IV of Rosales, Porta and Ros, "Global optimization of robotic
grasps", Robotics: Science and Systems (2011). A chart
``C_i`` has a centre ``x_i`` on the manifold and an orthonormal basis ``Phi_i`` (n x k) of the
tangent space there. A point ``u`` of the chart's parameter space maps to ``x_i + Phi_i u``
(Eq. (14)) and then onto the manifold by the orthogonal projection of Eq. (15). The domain of a
chart is a polytope ``P_i`` in parameter space: a cube enclosing the ball ``B_i`` of radius ``r``,
cut by one half-space per neighbouring chart (the plane through the intersection of ``B_i`` and
the ball ``B_j^i`` of radius ``r`` around the neighbour's projected centre). A vertex of ``P_i``
outside ``B_i`` is expanded into a new chart (Eqs. (16)-(18)); when every vertex lies inside its
ball the chart is bounded and, once all charts are, the connected component of the start point is
covered.

Box bounds on ``x`` (joint limits, patch parameter ranges): a new centre must lie inside the box;
when a candidate crosses a bound, the bound's linearisation cuts the chart's polytope, and a
vertex whose expansion fails down to the smallest step is blocked (marked as boundary, never
expanded again). A drop of the rank of ``J`` at a candidate centre, or a sign
change of ``det([J; Phi_i^T])`` between a chart and its child (a branch crossing), is reported as a
singular point; neither stops the continuation.

This package knows nothing of hands: it is tested on spheres, tori and curves. Its modules:
``model`` (settings and the frozen :class:`Atlas`), ``polytope`` (chart domains), ``projection``
(Newton projection and tangent spaces), ``neighbours`` (ball queries over chart centres),
``checks`` (input checks), ``checkpoint`` (saving and resuming a build) and ``builder`` (the
continuation, :func:`build_atlas`).
"""

from sahgrasp.atlas.builder import build_atlas
from sahgrasp.atlas.checkpoint import AtlasCheckpoint
from sahgrasp.atlas.model import STOP_REASONS, Atlas, AtlasSettings
from sahgrasp.atlas.projection import project

__all__ = [
    "STOP_REASONS",
    "Atlas",
    "AtlasCheckpoint",
    "AtlasSettings",
    "build_atlas",
    "project",
]
