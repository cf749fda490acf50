"""CPU time of the compiled Levenberg-Marquardt loop alone (docs/methods/ik.md, "Compiled loop").

Each seeded random SAH problem starts from the thumb-hung mid-range configuration; the loop runs
every start once per repeat and the least total CPU time is kept. Prints microseconds per start
and per iteration (accepted and rejected steps together), and of one contact stack and Jacobian
call.

    python benchmarks/ik_loop.py [--problems 200] [--seed 777] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sahgrasp.ik import IKSettings, hang_from_thumb, random_problems
from sahgrasp.ik.compiled import compiled_tree
from sahgrasp.ik.solver import ContactProblem
from sahgrasp.model.hand import load_hand


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=200)
    parser.add_argument("--seed", type=int, default=777)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    hand, s = load_hand("sah"), IKSettings()
    tree = compiled_tree(hand)
    starts = []
    for target in random_problems(hand, args.problems, args.seed):
        problem = ContactProblem(hand, target)
        q0 = hang_from_thumb(hand, 0.5 * (hand.lower + hand.upper), target)[0]
        starts.append((problem, q0))
    best, iterations = float("inf"), 0
    for _ in range(args.repeats):
        begin, iterations = time.process_time(), 0
        for problem, q0 in starts:
            q = q0.copy()
            _, used, _ = tree.solve(
                q, problem.target_stack, problem.rows, s.max_iterations, s.refine_m,
                s.d_min_m, s.stall_iterations, None,
            )  # fmt: skip
            iterations += used
        best = min(best, time.process_time() - begin)
    print(f"{best / len(starts) * 1e6:.1f} us per start, {best / iterations * 1e6:.2f} us per "
          f"iteration, {iterations / len(starts):.1f} iterations per start")  # fmt: skip
    problem, q = starts[0]
    stack, J = np.empty(len(problem.target_stack)), np.empty((len(problem.target_stack), hand.nv))
    calls, begin = 20_000, time.process_time()
    for _ in range(calls):
        tree.stack(q, problem.rows, stack, J)
    print(f"{(time.process_time() - begin) / calls * 1e6:.2f} us per Tree.stack call")


if __name__ == "__main__":
    main()
