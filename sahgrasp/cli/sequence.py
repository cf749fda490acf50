"""``sahgrasp sequence``: the offline search for the initial-pose sequence (Section 3.2)."""

from __future__ import annotations

import argparse
import shlex
from typing import TYPE_CHECKING, Any

from sahgrasp.cli.common import (
    HAND_HELP,
    add_command,
    check_json_inputs,
    int_at_least,
    nonnegative_int,
    positive_int,
    scheduler_address,
)
from sahgrasp.core.fileio import check_output_path
from sahgrasp.model.hands import DEFAULT_HAND

if TYPE_CHECKING:
    from sahgrasp.sequence import Progress, SearchResult

__all__ = [
    "SEARCH_DEFAULTS",
    "SUMMARY_HEADERS",
    "add_parser",
    "resume_command",
    "run",
    "summary_rows",
]

SEARCH_DEFAULTS = {"grid": 10, "problems": 300, "rounds": 12, "seed": 0, "method": "auto"}
"""``SearchSettings()``'s values, spelled out so that ``--help`` need not import the search."""

DESCRIPTION = (
    "Search the sequence of initial hand poses (Claret & Suárez, Section 3.2). With the defaults "
    "(N = 10, M = 300, 12 rounds) this is a job of about 10 minutes on 2 cores (SAH); the work is "
    "checkpointed in DIR, so an interrupted search continues with --resume."
)


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    d = SEARCH_DEFAULTS
    p = add_command(sub, "sequence", "search the sequence of initial hand poses", DESCRIPTION)
    p.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    p.add_argument(
        "--grid", type=int_at_least(2), default=d["grid"], help="N values per lambda (N^2 cells)"
    )
    p.add_argument("--problems", type=positive_int, default=d["problems"], help="M per round")
    p.add_argument("--rounds", type=positive_int, default=d["rounds"], help="sequence length")
    p.add_argument("--seed", type=nonnegative_int, default=d["seed"], help="problem seed (>= 0)")
    p.add_argument("--method", choices=("auto", "paper"), default=d["method"], help="IK method")
    p.add_argument("--out", required=True, metavar="DIR", help="output and checkpoint folder")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="local worker processes (default: one per core)",
    )
    where.add_argument(
        "--scheduler",
        type=scheduler_address,
        default=None,
        metavar="ADDR",
        help="Dask scheduler address: tcp://HOST:PORT or HOST:PORT",
    )
    p.add_argument("--resume", action="store_true", help="continue the search checkpointed in DIR")
    p.set_defaults(run=run, on_interrupt=resume_command)


def resume_command(args: argparse.Namespace) -> str:
    """The command that continues this search after an interruption."""
    words = ["sahgrasp", "sequence", "--hand", args.hand, "--grid", str(args.grid),
             "--problems", str(args.problems), "--rounds", str(args.rounds),
             "--seed", str(args.seed), "--method", args.method, "--out", args.out]  # fmt: skip
    if args.workers is not None:
        words += ["--workers", str(args.workers)]
    if args.scheduler is not None:
        words += ["--scheduler", args.scheduler]
    resume = shlex.join([*words, "--resume"])
    return f"interrupted; continue from the last checkpoint with: {resume}"


class _Bar:
    """A tqdm bar over the grid's IK runs, fed by the search's progress reports."""

    def __init__(self) -> None:
        self.bar: Any = None

    def __call__(self, p: Progress) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(
                total=p.runs_total, initial=p.runs_done, unit="IK", smoothing=0.05,
                disable=None,  # on a terminal only: no carriage returns in a log
            )  # fmt: skip
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


SUMMARY_HEADERS = (
    "round", "lambda1", "lambda2", "chosen pose solves [%]", "earlier poses solved [%]",
    "problems scanned",
)  # fmt: skip
"""Columns of the summary: per round the chosen pose (lambda1, lambda2), the share of the round's
problems it solves (E_i), the share of the screened problems the poses chosen before had solved
(the round's problems are among those they did not), and the problems screened to find them."""


def summary_rows(result: SearchResult) -> list[tuple[object, ...]]:
    """One row of :data:`SUMMARY_HEADERS` per round of ``result``."""
    return [
        (r.index, f"{r.lambdas[0]:.3f}", f"{r.lambdas[1]:.3f}",
         f"{100 * r.success_rates.max():.1f}", f"{100 * r.prior_success_rate:.1f}", r.scanned)
        for r in result.rounds
    ]  # fmt: skip


def _print_summary(result: SearchResult, out: str) -> None:
    from sahgrasp.core.tables import format_table

    print(format_table(SUMMARY_HEADERS, summary_rows(result)))
    print(f"{result.cells_computed} cells and {result.ik_runs_computed} IK runs computed in "
          f"{result.wall_seconds:.1f} s")  # fmt: skip
    from sahgrasp.core.extras import has_extra, install_hint

    figure = "fig4.png" if has_extra("plot") else f"no fig4.png (needs {install_hint('plot')})"
    print(f"wrote {out}/sequence.json, search.json, {figure}")


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp sequence``."""
    check_output_path(args.out, inputs=[args.hand], folder=True)
    check_json_inputs(args.hand)
    from sahgrasp.ik import IKSettings
    from sahgrasp.sequence import SearchSettings, search_sequence

    settings = SearchSettings(
        grid=args.grid, problems=args.problems, rounds=args.rounds, seed=args.seed,
        ik=IKSettings(method=args.method, init="sequence"),
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
