"""The planner's settings (:class:`PlanSettings`) and its error type."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from sahgrasp.core.errors import SahGraspError
from sahgrasp.quality.ellipsoids import INDICES
from sahgrasp.quality.wrench import CONE_EDGES, FRICTION, LINF_CONE_EDGES

__all__ = [
    "CHECK_CANDIDATES_FACTOR",
    "FINGER_COUNTS",
    "RANKINGS",
    "PlanSettings",
    "PlanningError",
]

CHECK_CANDIDATES_FACTOR = 4
"""With an extra check (``plan --verify physics``): the candidates the planner may draw in
batches while fewer grasps than asked pass it, as a multiple of
:attr:`PlanSettings.candidates` (``plan_grasps(max_candidates=)``, ``--max-candidates``)."""

FINGER_COUNTS = (2, 3, 4)
"""Grasps the planner draws: 2 (thumb + index), 3 (+ middle), 4 (+ ring) fingers."""
RANKINGS = ("epsilon", "weight", *INDICES)
"""What grasps are ranked by: the L1 epsilon, the weight support
(:mod:`sahgrasp.quality.weight`), or one of the atlas paper's manipulability indices."""


class PlanningError(SahGraspError):
    """Planner settings or inputs are invalid."""


@dataclass(frozen=True)
class PlanSettings:
    """How :func:`sahgrasp.plan_grasps` plans (docs/methods/planner.md).

    Attributes:
        fingers: Finger counts to draw (any of 2, 3, 4), in the order their draws interleave.
        grasps: How many distinct grasps to return (>= 1).
        candidates: Contact sets solved with the IK per object: the planner's deterministic budget.
        seed: Seed (>= 0) of every draw; each object's draws also depend on its identity.
        mu: Coulomb friction coefficient of the quality and of the pre-filter.
        cone_edges: Friction cone edges of the L1 epsilon and of force closure.
        linf_edges: Friction cone edges of the L-infinity epsilon (computed for returned grasps).
        rank: ``"weight"`` (the weight support, :func:`sahgrasp.quality.weight.weight_support`:
            the pull through the centre of mass the contacts resist in six directions; the
            default, as the grasps it ranks first hold best in the physics hold test),
            ``"epsilon"`` (L1) or a manipulability index
            (:data:`sahgrasp.quality.ellipsoids.INDICES`); force-closure grasps always rank before
            the others.
        time_limit_s: Optional cap on the planning time [s]: a run it cuts depends on the
            machine's speed (the candidate budget does not).
        ik_max_inits: Initial configurations the IK tries per candidate.
        d_min_m: Contact tolerance of the IK and of the verification [m].
        link_tolerance_m: Deepest a non-contact link may enter the object [m].
        distinct_m: Two grasps of the same fingers whose wrists are within this distance [m]
            and ``distinct_deg`` [deg], and whose contacts are each within this distance, are
            the same grasp: only the better one is returned.
        distinct_deg: See ``distinct_m`` [deg].
        max_draws_per_candidate: Draws allowed per candidate before the object is given up.
    """

    fingers: tuple[int, ...] = (3, 4, 2)
    grasps: int = 10
    candidates: int = 60
    seed: int = 0
    mu: float = FRICTION
    cone_edges: int = CONE_EDGES
    linf_edges: int = LINF_CONE_EDGES
    rank: str = "weight"
    time_limit_s: float | None = None
    ik_max_inits: int = 6
    d_min_m: float = 1.5e-3
    link_tolerance_m: float = 5e-4
    distinct_m: float = 0.01
    distinct_deg: float = 15.0
    max_draws_per_candidate: int = 200

    def __post_init__(self) -> None:
        fingers = tuple(self.fingers)
        if (
            not fingers
            or any(f not in FINGER_COUNTS for f in fingers)
            or len(set(fingers)) != len(fingers)
        ):
            raise PlanningError(
                f"fingers must be distinct finger counts among {list(FINGER_COUNTS)}, got "
                f"{list(fingers)}"
            )
        object.__setattr__(self, "fingers", fingers)
        for name, low in (
            ("grasps", 1),
            ("candidates", 1),
            ("seed", 0),
            ("ik_max_inits", 1),
            ("max_draws_per_candidate", 1),
            ("cone_edges", 3),
            ("linf_edges", 3),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise PlanningError(f"{name} must be an integer >= {low}, got {value!r}")
        for name in ("mu", "d_min_m", "link_tolerance_m", "distinct_m", "distinct_deg"):
            value = getattr(self, name)
            if not (_real(value) and math.isfinite(value) and value > 0.0):
                raise PlanningError(f"{name} must be a finite number > 0, got {value!r}")
        if self.time_limit_s is not None and not (
            _real(self.time_limit_s) and self.time_limit_s > 0.0
        ):
            raise PlanningError(f"time_limit_s must be > 0 [s] or None, got {self.time_limit_s!r}")
        if self.rank not in RANKINGS:
            raise PlanningError(f"rank must be one of {list(RANKINGS)}, got {self.rank!r}")

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (the ``settings`` of a plan document)."""
        data = dataclasses.asdict(self)
        data["fingers"] = list(self.fingers)
        return data


def _real(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)
