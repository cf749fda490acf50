"""Plan grasps of an object from a mesh file: the SAH's best grasps of the shipped mug.

``sahgrasp.plan_grasps`` draws candidate contact sets of 2, 3 and 4 fingers on the mesh, solves
each with the object as an obstacle, re-checks every solved grasp independently (the plain URDF
against the true mesh), scores it (force closure, the Ferrari-Canny epsilon, the manipulability
indices) and returns the best distinct grasps, ranked. Run `python examples/plan_mug.py` to open
the viewer on the best grasps side by side, or add `--html OUT` to write the scene.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import sahgrasp
from sahgrasp.experiments.arguments import add_html_argument, positive_float, positive_int
from sahgrasp.objects import MeshFileError, load_mesh
from sahgrasp.viz import present
from sahgrasp.viz.plan_view import draw_plan

MUG = Path(__file__).resolve().parent / "meshes" / "mug.stl"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Ranked, verified grasps of a mesh.")
    parser.add_argument("--mesh", type=Path, default=MUG, help="STL, OBJ or PLY (default: mug)")
    parser.add_argument("--scale", type=positive_float, default=1.0, help="file unit in metres")
    parser.add_argument("--grasps", type=positive_int, default=6, help="grasps to show")
    parser.add_argument("--candidates", type=positive_int, default=60, help="candidates solved")
    add_html_argument(parser)
    args = parser.parse_args(argv)
    hand = sahgrasp.load_hand("sah")
    try:
        obj = load_mesh(args.mesh, scale=args.scale)
    except MeshFileError as error:  # a file the user named: one line, not a traceback
        parser.error(str(error))
    settings = sahgrasp.PlanSettings(grasps=args.grasps, candidates=args.candidates, seed=0)
    plan = sahgrasp.plan_grasps(hand, obj, settings)
    s = plan.summary
    print(
        f"{obj.name}: {s.grasps} grasps ({s.force_closure} in force closure) of {s.verified} "
        f"verified, from {s.candidates} candidates in {s.time_s:.2f} s"
    )
    for rank, grasp in enumerate(plan.grasps, start=1):
        q = grasp.quality
        print(
            f"  #{rank}: {'+'.join(grasp.fingers)}, force closure {q['force_closure']}, "
            f"epsilon {q['epsilon_l1']:.4f}, volume {q['volume']:.3g}, clearance "
            f"{1e3 * grasp.object_clearance_m:.2f} mm ({grasp.closest_link})"
        )
    present(lambda viewer: draw_plan(viewer, hand, obj, plan), args.html, f"plan: {obj.name}")
    return 0 if plan.grasps else 1


if __name__ == "__main__":
    raise SystemExit(main())
