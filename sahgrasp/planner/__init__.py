"""The grasp planner: from an object (a mesh, a catalog object) to ranked, verified grasps.

:func:`plan_grasps` (:mod:`~sahgrasp.planner.plan`) draws candidate contact sets
(:mod:`~sahgrasp.planner.candidates`), solves them with the IK, re-checks each independently
(:mod:`~sahgrasp.planner.verify`), scores (:mod:`sahgrasp.quality.wrench`,
:mod:`sahgrasp.quality.ellipsoids`) and ranks them; :mod:`~sahgrasp.planner.folder` plans a folder
of meshes on worker processes.
"""

from sahgrasp.planner.plan import GraspPlan, PlannedGrasp, PlanSummary, plan_grasps
from sahgrasp.planner.settings import PlanningError, PlanSettings

__all__ = [
    "GraspPlan",
    "PlanSettings",
    "PlanSummary",
    "PlannedGrasp",
    "PlanningError",
    "plan_grasps",
]
