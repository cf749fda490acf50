"""Where a learned-start ``solve_ik`` spends its CPU time.

Wraps a few parts of the solver with ``time.process_time`` counters, solves seeded random SAH
problems and prints each part's share of the total CPU time. The wrapping itself adds about 10 %.
The neighbour search and the alignment of the learned starts run inside a generator, so they are
in the remainder (the total minus the parts).

    python benchmarks/ik_profile.py [--problems 150] [--seed 777]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

from sahgrasp.ik import IKSettings, random_problems, solve_ik, solver
from sahgrasp.model.hand import load_hand

PARTS: tuple[tuple[object, str], ...] = (
    (solver, "_lm_loop"),
    (solver, "_separate"),
    (solver, "_result"),
    (solver, "ContactProblem"),
    (solver, "contact_key"),
    (solver, "self_collides"),
)


def _timed(f: Callable[..., Any], name: str, seconds: dict[str, float]) -> Callable[..., Any]:
    def timed(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        try:
            return f(*args, **kwargs)
        finally:
            seconds[name] = seconds.get(name, 0.0) + time.process_time() - start

    return timed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=150)
    parser.add_argument("--seed", type=int, default=777)
    args = parser.parse_args()
    hand = load_hand("sah")
    problems = random_problems(hand, args.problems, args.seed)
    solve_ik(hand, problems[0], IKSettings(seed=args.seed))  # loads the sequence and database
    seconds: dict[str, float] = {}
    for owner, name in PARTS:
        setattr(owner, name, _timed(getattr(owner, name), name, seconds))
    start = time.process_time()
    for target in problems:
        solve_ik(hand, target, IKSettings(seed=args.seed))
    total = time.process_time() - start
    print(f"{total / len(problems) * 1e6:.0f} us CPU per problem (wrapped)")
    for name, part in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"{name:16s} {part / len(problems) * 1e6:7.0f} us  {part / total:6.1%}")


if __name__ == "__main__":
    main()
