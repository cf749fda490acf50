"""The IK examples of Claret & Suárez's IK paper, Section 4.1 (Figs. 6-8): solve, report, show.

Each example is a paper object with its precision grasp (``sahgrasp.objects``). It is solved with
the default IK (iterates recorded), reported beside the paper's counts of initial configurations
and Jacobian iterations, and drawn as Fig. 6 draws the fork: object, contact disks with normal
cylinders, and the hand animated from the initial configuration to the solution. ``sahgrasp demo``
runs all five through this module.
The paper's counts are :data:`sahgrasp.objects.PAPER_IK_REPORT`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.tables import format_table
from sahgrasp.ik import IKResult, IKSettings, solve_ik
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import (
    GRASP_NAMES,
    PAPER_IK_REPORT,
    GraspObject,
    IKReport,
    load_object,
    paper_grasp,
    transform_points,
)
from sahgrasp.objects.targets import ObjectCache, build_object
from sahgrasp.viz.grasp_view import grasp_points, show_grasp
from sahgrasp.viz.viewer import Viewer

__all__ = [
    "EXAMPLE_GAP_M",
    "EXAMPLE_NAMES",
    "ROW_ASPECT",
    "GraspExample",
    "SolvedGrasp",
    "format_report",
    "format_solved",
    "scene_name",
    "show_examples",
    "solve_example",
    "solve_problems",
]

EXAMPLE_NAMES = GRASP_NAMES
"""The examples, in the paper's order: fork, cup, buddha, coffee_cup, can."""

EXAMPLE_GAP_M = 0.06
"""Gap along x between the extents of neighbouring grasps in a row [m]."""

ROW_ASPECT = 1.5
"""Smallest width/height ratio of the window a row of grasps fits in (1280x800 is 1.6)."""


@dataclass(frozen=True)
class SolvedGrasp:
    """A grasp problem and the IK's result, as :func:`show_examples` draws it.

    Attributes:
        name: Problem name.
        obj: The object grasped (world frame), or None.
        target: The contact targets (world frame).
        result: The IK result (iterates recorded to animate the hand).
    """

    name: str
    obj: GraspObject | None
    target: GraspTarget
    result: IKResult

    @property
    def contact_centre_m(self) -> NDArray[np.float64]:
        """Mean of the contact points [m]."""
        return np.mean([c.point for c in self.target.contacts], axis=0)


@dataclass(frozen=True)
class GraspExample(SolvedGrasp):
    """A paper example, solved.

    Attributes:
        name: Object name.
        obj: The object (world frame).
        target: Its precision grasp (world frame).
        result: The IK result, iterates recorded.
        paper: What the paper reports for it.
    """

    paper: IKReport


def solve_problems(
    hand: Hand, problems: Iterable[GraspTarget], settings: IKSettings | None = None
) -> list[SolvedGrasp]:
    """Solve the problems of a targets file, each with its object as the IK's obstacle.

    Each distinct object (same catalog name or mesh file and placement) is built once, so the
    IK builds its collision pieces once per object. Iterates are recorded.

    Raises:
        MeshFileError: A problem's mesh file cannot be read.
        InvalidTargetError: A problem the solver refuses (e.g. fingers the hand lacks).
    """
    objects: dict[str, GraspObject] = {}
    built = ObjectCache()  # a mesh placed twice is built once
    solved = []
    for problem in problems:
        spec = problem.object_spec
        if spec is not None and spec.key() not in objects:
            objects[spec.key()] = build_object(spec, built)
        obj = None if spec is None else objects[spec.key()]
        result = solve_ik(hand, problem, settings, obstacle=obj, record_history=True)
        solved.append(SolvedGrasp(problem.name, obj, problem, result))
    return solved


def solve_example(hand: Hand, name: str, settings: IKSettings | None = None) -> GraspExample:
    """Solve the paper grasp of object ``name`` (:data:`EXAMPLE_NAMES`), recording the iterates.

    Raises:
        InvalidTargetError: Unknown name; the message lists the valid ones.
    """
    target = paper_grasp(name)
    result = solve_ik(hand, target, settings, record_history=True)
    return GraspExample(name, load_object(name), target, result, PAPER_IK_REPORT[name])


_HEADERS = ("object", "solved", "inits (paper)", "iterations (paper)", "time [ms]",
            "max error [mm]")  # fmt: skip


def format_report(examples: Iterable[GraspExample]) -> str:
    """A table of the results beside the paper's numbers (Section 4.1); one row per example.

    The paper gives no per-example time (5 ms on average per initial configuration, Section 4.2)
    and solves to ``d_min = 1.5 mm``; ``solved`` gives the solver's reason when it failed. Columns
    are as wide as their content.
    """
    rows = [
        (
            ex.name,
            "yes" if ex.result.success else f"no ({ex.result.reason})",
            f"{ex.result.inits_used} ({ex.paper.initial_configurations})",
            f"{ex.result.iterations} ({ex.paper.jacobian_iterations})",
            f"{ex.result.time_s * 1e3:.1f}",
            f"{ex.result.max_error_m * 1e3:.3f}",
        )
        for ex in examples
    ]
    return format_table(_HEADERS, rows)


_SOLVED_HEADERS = ("problem", "object", "solved", "inits", "iterations", "time [ms]",
                   "max error [mm]", "object clearance [mm]")  # fmt: skip


def _clearance_cell(result: IKResult) -> str:
    if result.object_clearance_m is None:
        return "-"
    return f"{result.object_clearance_m * 1e3:.2f} ({result.closest_link})"


def format_solved(solved: Iterable[SolvedGrasp]) -> str:
    """A table of solved problems, one row each: the object and the clearance the IK kept."""
    rows = [
        (
            ex.name,
            "-" if ex.obj is None else ex.obj.name,
            "yes" if ex.result.success else f"no ({ex.result.reason})",
            str(ex.result.inits_used),
            str(ex.result.iterations),
            f"{ex.result.time_s * 1e3:.1f}",
            f"{ex.result.max_error_m * 1e3:.3f}",
            _clearance_cell(ex.result),
        )
        for ex in solved
    ]
    return format_table(_SOLVED_HEADERS, rows)


def show_examples(
    viewer: Viewer, hand: Hand, examples: Sequence[SolvedGrasp], facing: bool = True
) -> None:
    """Draw the grasps in a row along x (``grasps/<name>``), hands animated; frame them.

    Args:
        viewer: The scene.
        hand: The hand.
        examples: The solved grasps.
        facing: Turn each grasp so that its palm lies behind the object (+y) as the camera, in
            front (-y) and above, sees it. False (a targets file's grasps): turn each grasp about
            the vertical only, so that the camera sees the palm side while every object stays
            as upright as the world has it, at its placement relative to the hand.
    """
    extents, cursor = [], 0.0
    paths: set[str] = set()
    for ex in examples:
        path = _unused(f"grasps/{scene_name(ex.name)}", paths)
        paths.add(path)
        T = _facing_placement(ex) if facing else _upright_placement(ex)
        extent = transform_points(T, grasp_points(hand, ex.result.q, ex.obj))
        shift = cursor - extent[:, 0].min()
        T[0, 3] += shift
        extent[:, 0] += shift
        cursor = extent[:, 0].max() + EXAMPLE_GAP_M
        show_grasp(
            viewer, path, hand, ex.result.q, ex.obj, ex.target,
            history=ex.result.history, T_scene=T,
        )  # fmt: skip
        extents.append(extent)
    if len(examples) == 1:
        viewer.frame(extents[0], _SINGLE_VIEW)
    else:
        viewer.frame(np.concatenate(extents), _ROW_VIEW, aspect=ROW_ASPECT)


_BEHIND = np.array([0.0, 1.0, 0.0])
_SINGLE_VIEW = np.array([0.5, -1.0, 0.8])
_ROW_VIEW = np.array([0.1, -1.0, 0.7])


def scene_name(name: str) -> str:
    """``name`` as one meshcat path element (a ``/`` would nest the grasp).

    Characters other than letters, digits and ``._-`` become ``_``; :func:`show_examples` adds
    ``-2``, ``-3``... to a name drawn before.
    """
    return re.sub(r"[^A-Za-z0-9._-]", "_", name) or "_"


def _unused(path: str, used: set[str]) -> str:
    """``path``, or ``path-2``, ``path-3``... the first not in ``used``."""
    candidate, k = path, 1
    while candidate in used:
        k += 1
        candidate = f"{path}-{k}"
    return candidate


def _upright_placement(example: SolvedGrasp) -> NDArray[np.float64]:
    """Placement turning a grasp about the vertical so that its palm is behind the object, centred.

    The horizontal direction from the contacts' centre to the wrist goes to +y (away from the
    camera); the vertical is kept, so a grasp from straight above or below only moves.
    """
    back = example.result.q[:3] - example.contact_centre_m
    angle = 0.0
    if np.hypot(back[0], back[1]) > 1e-9:
        angle = 0.5 * np.pi - float(np.arctan2(back[1], back[0]))
    T = np.eye(4)
    T[:3, :3] = pin.utils.rotate("z", angle)
    T[:3, 3] = -T[:3, :3] @ example.contact_centre_m
    return T


def _facing_placement(example: SolvedGrasp) -> NDArray[np.float64]:
    """Placement turning a grasp so that its palm is behind the object (+y), centred.

    A grasp from the side turns about the vertical (the object stays upright); a grasp from above
    or below turns by the smallest rotation taking the object-to-palm direction to +y. The centre
    of the contacts goes to the origin.
    """
    back = example.result.q[:3] - example.contact_centre_m
    if abs(back[2]) < np.hypot(back[0], back[1]):
        back = np.array([back[0], back[1], 0.0])
    T = np.eye(4)
    T[:3, :3] = pin.Quaternion.FromTwoVectors(back, _BEHIND).toRotationMatrix()
    T[:3, 3] = -T[:3, :3] @ example.contact_centre_m
    return T
