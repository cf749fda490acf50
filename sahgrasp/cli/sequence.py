"""``sahgrasp sequence``: the offline search for the initial-pose sequence (Section 3.2)."""

from __future__ import annotations

import argparse
from typing import Any

from tqdm import tqdm

from sahgrasp.ik import IKSettings
from sahgrasp.sequence import Progress, SearchResult, SearchSettings, search_sequence

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    d = SearchSettings()
    p = sub.add_parser("sequence", help="search the sequence of initial hand poses")
    p.add_argument("--hand", default="sah", help="sah, allegro, or a hand-description JSON path")
    p.add_argument("--grid", type=int, default=d.grid, help="N values per lambda (N^2 cells)")
    p.add_argument("--problems", type=int, default=d.problems, help="M problems per round")
    p.add_argument("--rounds", type=int, default=d.rounds, help="sequence length i_max")
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the random problems")
    p.add_argument("--method", choices=("auto", "paper"), default=d.method, help="IK method")
    p.add_argument("--out", required=True, metavar="DIR", help="output and checkpoint folder")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="local worker processes (default: one per core)")  # fmt: skip
    where.add_argument("--scheduler", default=None, metavar="ADDR",
                       help="Dask scheduler address, e.g. tcp://host:8786")  # fmt: skip
    p.add_argument("--resume", action="store_true", help="continue the search checkpointed in DIR")
    p.set_defaults(run=run)


class _Bar:
    """A tqdm bar over the grid's IK runs, fed by the search's progress reports."""

    def __init__(self) -> None:
        self.bar: tqdm[Any] | None = None

    def __call__(self, p: Progress) -> None:
        if self.bar is None:
            self.bar = tqdm(total=p.runs_total, initial=p.runs_done, unit="IK", smoothing=0.05)
        self.bar.set_description(f"round {p.round}/{p.rounds} {p.stage}", refresh=False)
        screening = p.stage == "screening"
        if screening:
            postfix = f"found {p.found}/{p.problems} problems in {p.scanned}"
        else:
            postfix = f"cells {p.cells_done}/{p.cells}"
        self.bar.set_postfix_str(postfix, refresh=screening)
        self.bar.update(p.runs_done - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _print_summary(result: SearchResult, out: str) -> None:
    print(f"{'i':>3} {'lambda1':>8} {'lambda2':>8} {'E_i':>7} {'SEQ before':>10} {'scanned':>8}")
    for r in result.rounds:
        print(f"{r.index:3d} {r.lambdas[0]:8.3f} {r.lambdas[1]:8.3f} "
              f"{100 * r.success_rates.max():6.1f}% {100 * r.prior_success_rate:9.1f}% "
              f"{r.scanned:8d}")  # fmt: skip
    print(f"{result.cells_computed} cells and {result.ik_runs_computed} IK runs computed in "
          f"{result.wall_seconds:.1f} s")  # fmt: skip
    print(f"wrote {out}/sequence.json, search.json, fig4.png")


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp sequence``."""
    settings = SearchSettings(
        grid=args.grid, problems=args.problems, rounds=args.rounds, seed=args.seed,
        ik=IKSettings(method=args.method),
    )  # fmt: skip
    bar = _Bar()
    try:
        result = search_sequence(
            args.hand, settings, args.out, executor=args.scheduler, workers=args.workers,
            resume=args.resume, progress=bar,
        )  # fmt: skip
    finally:
        bar.close()
    _print_summary(result, args.out)
    return 0
