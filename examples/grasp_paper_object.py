"""IK of one of the paper's precision grasps with the SAH (Claret & Suárez, Section 4.1, Figs. 6-8).

The objects: fork (Fig. 6), cup (Fig. 7a), buddha (Fig. 7b), coffee_cup (Fig. 7c), can (Fig. 8).

Load the hand, load the object and its precision grasp (a contact point and the surface normal per
finger), solve the IK with the object as an obstacle (no link may enter it), print the outcome
beside the paper's counts, and show the hand moving from its initial configuration to the grasp.
Run `python examples/grasp_paper_object.py can` to open the live viewer, or add `--html OUT` to
write the scene to a standalone HTML file.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import sahgrasp
from sahgrasp.experiments.arguments import add_html_argument, add_ik_arguments, ik_settings
from sahgrasp.objects import GRASP_NAMES, PAPER_IK_REPORT, load_object, paper_grasp
from sahgrasp.viz import Viewer, frame_grasp, present, show_grasp


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("object", choices=GRASP_NAMES, help="the paper's object to grasp")
    add_ik_arguments(parser)  # --hand, --method, --inits, --iterations
    add_html_argument(parser)  # --html OUT
    args = parser.parse_args(argv)
    name = args.object

    hand = sahgrasp.load_hand(args.hand)
    obj = load_object(name)  # placed in the world frame, as the grasp is
    target = paper_grasp(name)
    result = sahgrasp.solve_ik(hand, target, ik_settings(args), obstacle=obj, record_history=True)

    paper = PAPER_IK_REPORT[name]
    print(f"{name}: {'solved' if result.success else 'not solved'} ({result.reason}), "
          f"{result.inits_used} initial configurations (paper {paper.initial_configurations}), "
          f"{result.iterations} iterations (paper {paper.jacobian_iterations})")  # fmt: skip
    print(f"initial configurations: {', '.join(result.attempts)}")
    errors = zip(result.fingers, result.position_errors_m, strict=True)
    print("contact errors:", ", ".join(f"{f} {e * 1e3:.3f} mm" for f, e in errors))
    if result.object_clearance_m is not None:  # None only without an obstacle
        print(f"object clearance: {result.object_clearance_m * 1e3:.2f} mm "
              f"at {result.closest_link}")  # fmt: skip

    def build(viewer: Viewer) -> None:
        show_grasp(viewer, name, hand, result.q, obj, target, result.history)
        frame_grasp(viewer, hand, result.q, target, obj)

    present(build, args.html, f"sahgrasp {name}")
    return 0 if result.success else 1


if __name__ == "__main__":
    sys.exit(main())
