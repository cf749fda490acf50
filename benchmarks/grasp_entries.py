"""How many grasp entries pass through their own solid if solved without it (docs/methods/ik.md).

Draws the contact sets of the shipped SAH database's grasp entries (``sahgrasp learn``'s default
seed and size: the same solids and sets, :func:`sahgrasp.ik.learning.primitive_grasp_sets`),
solves each from the searched sequence twice, without and with its solid as the obstacle, and
prints how many are solved each way and how many of the solutions found without the solid are
inside it (the IK's own acceptance test with the solid).

    python benchmarks/grasp_entries.py [--grasps 1600] [--seed 61803398]
"""

from __future__ import annotations

import argparse

from tqdm import tqdm

from sahgrasp.cli.learn import LEARN_DEFAULTS
from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.ik.learning import primitive_chunks, primitive_grasp_sets, primitive_object
from sahgrasp.ik.solver import ContactProblem
from sahgrasp.model.hand import load_hand


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=LEARN_DEFAULTS["grasp_sets"])
    parser.add_argument("--seed", type=int, default=LEARN_DEFAULTS["seed"])
    args = parser.parse_args()
    hand = load_hand("sah")
    settings = IKSettings(init="sequence", seed=args.seed)
    chunks = primitive_chunks(args.grasps)
    solids = sum(chunks)
    plain = inside = with_solid = 0
    with tqdm(total=solids, unit="solid") as bar:
        for chunk, count in enumerate(chunks):
            for mesh, targets in primitive_grasp_sets(hand, args.seed, chunk, count):
                solid = primitive_object(mesh)
                for target in targets:
                    result = solve_ik(hand, target, settings)
                    if result.success:
                        plain += 1
                        problem = ContactProblem(hand, target, obstacle=solid)
                        inside += problem.collision(result.q) == "object_collision"
                    with_solid += solve_ik(hand, target, settings, obstacle=solid).success
            bar.update(count)
    print(
        f"{solids} solids: solved without the solid {plain}, of them inside it {inside} "
        f"({inside / max(plain, 1):.1%}); solved with the solid {with_solid}"
    )


if __name__ == "__main__":
    main()
