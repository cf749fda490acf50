"""What the atlas paper reports for its experiments, to print our figures beside them.

Rosales, Porta and Ros, "Global optimization of robotic grasps", Robotics: Science and Systems,
2011, Section V (C and Matlab on an Intel Core 2 Duo at 3 GHz). The IK paper's counts are
:data:`sahgrasp.objects.PAPER_IK_REPORT`.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["PAPER_ATLAS_REPORT", "PAPER_ATLAS_RUNS", "AtlasReport"]


class AtlasReport(NamedTuple):
    """What the atlas paper reports for an experiment (None: not reported).

    Attributes:
        figure: The figure showing it.
        charts: Number of charts of the atlas.
        n: Number of variables of F.
        t: Dimension of F.
        k: Dimension of the explored set R.
        r: Chart radius.
        epsilon: Threshold of Eqs. (17)-(18).
        atlas_seconds: Atlas time [s].
        quality_seconds: Quality-index time [s].
        total_seconds: Whole optimisation time [s].
        retained_variance: Share of the hand-motion variance the kept motions explain, at least
            (the paper: "more than 99%" for the can).
    """

    figure: str
    charts: int
    n: int | None
    t: int
    k: int
    r: float
    epsilon: float
    atlas_seconds: float | None
    quality_seconds: float | None
    total_seconds: float
    retained_variance: float | None = None


PAPER_ATLAS_REPORT: dict[str, AtlasReport] = {
    "planar": AtlasReport("Fig. 9", 750, None, 3, 2, 0.125, 0.4, 0.1, 1.5, 1.6),
    "can": AtlasReport("Fig. 10a", 4800, 134, 8, 2, 1.0, 0.5, 140.0, 10.0, 150.0, 0.99),
    "bottle": AtlasReport("Fig. 10b", 1400, 142, 9, 2, 1.0, 0.5, None, None, 45.0),
}
"""Per experiment, the paper's figures (Section V)."""

PAPER_ATLAS_RUNS: dict[tuple[str, int], AtlasReport] = {
    **{(name, 2): report for name, report in PAPER_ATLAS_REPORT.items()},
    ("bottle", 3): AtlasReport("Section V-B", 95000, 142, 9, 3, 1.0, 0.5, None, None, 1300.0),
}
"""Per (experiment, k), the paper's figures: those of :data:`PAPER_ATLAS_REPORT` (k = 2) and the
bottle with k = 3 ("the atlas includes 95000 charts and the optimization takes 1300 seconds")."""
