"""Share of fresh problems a shipped sequence solves within i poses (docs/results.md).

Solves problems ``0 .. M-1`` of the stream ``--seed`` (not the search's) with ``init="sequence"``
and the default solver, once with the hand's shipped sequence and once with the lambdas of the
paper's Table 1 on the same PCA basis, and prints the share solved within i poses.

    python benchmarks/sequence_fresh.py --hand sah [--problems 300] [--seed 12345]
"""

from __future__ import annotations

import argparse
import dataclasses

from tqdm import tqdm

from sahgrasp.ik import IKSettings, Sequence, random_problems, solve_ik
from sahgrasp.ik.initial import PAPER_TABLE1_LAMBDAS, default_sequence
from sahgrasp.model.hand import Hand, load_hand

COLUMNS = (1, 2, 3, 4, 6, 8, 12)


def within(hand: Hand, sequence: Sequence, problems: int, seed: int) -> list[float]:
    """Share of the problems solved with at most i initial poses, i in :data:`COLUMNS`."""
    settings = IKSettings(init="sequence")
    used = []
    for target in tqdm(random_problems(hand, problems, seed), desc=sequence.source, leave=False):
        result = solve_ik(hand, target, settings, sequence=sequence)
        used.append(result.inits_used if result.success else None)
    return [sum(u is not None and u <= i for u in used) / problems for i in COLUMNS]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hand", default="sah")
    parser.add_argument("--problems", type=int, default=300)
    parser.add_argument("--seed", type=int, default=12345)
    args = parser.parse_args()
    hand = load_hand(args.hand)
    shipped = default_sequence(hand)
    table1 = dataclasses.replace(shipped, lambdas=PAPER_TABLE1_LAMBDAS, source="paper-table1")
    print("| i | " + " | ".join(map(str, COLUMNS)) + " |")
    for name, sequence in (("search sequence", shipped), ("Table 1 lambdas", table1)):
        shares = within(hand, sequence, args.problems, args.seed)
        cells = " | ".join(f"{100 * s:.1f}%" for s in shares)
        print(f"| {args.hand}, {name} | {cells} |")


if __name__ == "__main__":
    main()
