"""How the learned start's database size trades start quality for lookup cost (docs/methods/ik.md).

Takes a large SAH database (``sahgrasp learn --hand sah --samples 10000 --grasps 10000 --out
BIG``) and cuts databases of ``R + G`` entries from it: its first R random entries and first G
grasp entries (a smaller build with the same seed is such a cut, up to the last bits of the IK
that solved its grasp entries). Each problem is solved by every cut in turn and by the sequence
alone, with a random-start and a paper-method solve after each, so that each configuration finds
its data out of the cache as in ``sahgrasp bench ik``. Prints, per configuration, the share
solved, solved at the first start, and the median, mean and p95 of the solves' wall time.

    python benchmarks/learned_size.py BIG [--targets SETS] [--problems 300] [--seed 90417]
        [--sizes 10000+9497 2500+1500 ...]
"""

from __future__ import annotations

import argparse

import numpy as np
from tqdm import tqdm

from sahgrasp.ik import IKResult, IKSettings, random_problems, solve_ik
from sahgrasp.ik.initial import default_sequence
from sahgrasp.ik.learned import GraspDatabase
from sahgrasp.model.hand import load_hand
from sahgrasp.objects.targets import load_targets


def cut(db: GraspDatabase, random_entries: int, grasp_entries: int) -> GraspDatabase:
    """The first ``random_entries`` random and first ``grasp_entries`` grasp entries of ``db``."""
    first_grasp = len(db.configurations) - db.grasp_entries
    rows = np.concatenate(
        [np.arange(min(random_entries, first_grasp)),
         first_grasp + np.arange(min(grasp_entries, db.grasp_entries))]
    )  # fmt: skip
    part = GraspDatabase(
        db.hand, db.hand_digest, db.configurations[rows], db.features[rows], db.seed,
        int(min(grasp_entries, db.grasp_entries)),
    )  # fmt: skip
    part.tree  # noqa: B018 -- built before timing
    return part


def report(label: str, results: list[IKResult]) -> str:
    times_ms = np.array([r.time_s for r in results]) * 1e3
    return (
        f"{label:16s} solved {np.mean([r.success for r in results]):6.1%}  "
        f"1st start {np.mean([r.success and r.inits_used == 1 for r in results]):6.1%}  "
        f"median / mean / p95 {np.median(times_ms):.3f} / {times_ms.mean():.3f} / "
        f"{np.percentile(times_ms, 95):.3f} ms  iterations "
        f"{np.mean([r.iterations for r in results]):.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("database", help="a large SAH database (.npz)")
    parser.add_argument("--targets", help="a targets file instead of random problems")
    parser.add_argument("--problems", type=int, default=300)
    parser.add_argument("--seed", type=int, default=90417)
    parser.add_argument("--sizes", nargs="+", default=["10000+9497", "2500+1500", "1000+1000"],
                        metavar="R+G", help="random + grasp entries of each cut")  # fmt: skip
    args = parser.parse_args()
    hand = load_hand("sah")
    big = GraspDatabase.load(args.database)
    big.check_hand(hand)
    default_sequence(hand)
    cuts = {size: cut(big, *map(int, size.split("+"))) for size in args.sizes}
    problems = (
        list(load_targets(args.targets).problems)
        if args.targets
        else random_problems(hand, args.problems, args.seed)
    )
    learned, sequence = IKSettings(), IKSettings(init="sequence")
    others = (IKSettings(init="random"), IKSettings(method="paper", init="sequence", max_inits=2))
    results: dict[str, list[IKResult]] = {label: [] for label in [*cuts, "sequence alone"]}
    for target in tqdm(problems, desc="problems"):
        for label in results:
            db = cuts.get(label)
            settings = sequence if db is None else learned
            results[label].append(solve_ik(hand, target, settings, database=db))
            for other in others:
                solve_ik(hand, target, other)
    for label, found in results.items():
        print(report(label, found))


if __name__ == "__main__":
    main()
