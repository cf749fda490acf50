"""``sahgrasp bench NAME``: run a benchmark, print its summary table and write its JSON.

With ``--json -`` the JSON document alone goes to stdout (progress stays on stderr).
"""

from __future__ import annotations

import argparse
import importlib
from typing import Any

from sahgrasp.cli.common import (
    HAND_HELP,
    add_command,
    add_json_argument,
    check_json_inputs,
    check_outputs,
    emit_json,
    human_stream,
    image_path,
    nonnegative_int,
    output_file,
    positive_int,
)
from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["add_parser", "run"]

_NOT_OPTIONS = ("command", "bench", "json", "run")
"""Namespace entries that are not keyword arguments of the benchmark's ``run``."""


def _add_quiet(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress bars on stderr")


def _kinematics(benches: Any) -> None:
    k = add_command(benches, "kinematics", "contact queries vs raw Pinocchio calls")
    k.add_argument("--calls", type=positive_int, default=20_000, help="timed calls per query")
    _add_quiet(k)
    add_json_argument(k, "the timings")


def _ik(benches: Any) -> None:
    ik = add_command(benches, "ik", "Algorithm 1: success and time vs initial poses, with peers")
    ik.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    ik.add_argument("--problems", type=positive_int, default=1000, help="random feasible problems")
    ik.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the problems (>= 0)")
    ik.add_argument("--targets", default=None, help="targets file instead of random problems")
    ik.add_argument(
        "--peers",
        nargs="*",
        default=["scipy", "pink"],
        choices=["scipy", "pink"],
        help="peer solvers to compare with (pink needs the [bench] extra)",
    )
    ik.add_argument(
        "--peer-problems", type=positive_int, default=200, help="problems the peers solve"
    )
    ik.add_argument(
        "--plot",
        type=image_path,
        default=None,
        metavar="IMAGE",
        help="write the Fig. 9 figure to IMAGE (.png, .pdf, .svg...)",
    )
    _add_quiet(ik)
    add_json_argument(ik, "the results")


def _atlas(benches: Any) -> None:
    atlas = add_command(benches, "atlas", "atlas on spheres and the planar hand vs CuikSuite")
    atlas.add_argument(
        "--repeats", type=positive_int, default=3, help="builds per timed case (best of)"
    )
    atlas.add_argument(
        "--cases", nargs="+", default=None, metavar="CASE", help="run only these cases (all)"
    )
    _add_quiet(atlas)
    add_json_argument(atlas, "the timings")


def _sequence(benches: Any) -> None:
    seq = add_command(benches, "sequence", "offline search: 1 vs 2 workers, cluster estimate")
    seq.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    seq.add_argument("--grid", type=positive_int, default=5, help="N values per lambda (>= 2)")
    seq.add_argument("--problems", type=positive_int, default=60, help="M problems per round")
    seq.add_argument("--rounds", type=positive_int, default=2, help="rounds of the search")
    seq.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the problems (>= 0)")
    seq.add_argument("--method", choices=("auto", "paper"), default="auto", help="IK method")
    seq.add_argument(
        "--workers", type=positive_int, nargs="+", default=[1, 2], help="worker counts to time"
    )
    seq.add_argument(
        "--cluster-workers", type=positive_int, default=16, help="workers of the estimate"
    )
    add_json_argument(seq, "the timings")


def _grasps(benches: Any) -> None:
    grasps = add_command(
        benches, "grasps", "contact sets sampled on objects, solved without and with the object"
    )
    grasps.add_argument(
        "--problems-per-object", type=positive_int, default=200, help="contact sets per object"
    )
    grasps.add_argument(
        "--seed", type=nonnegative_int, default=7305411, help="seed of the contact sets (>= 0)"
    )
    grasps.add_argument("--workers", type=positive_int, default=1, help="IK processes")
    grasps.add_argument(
        "--objects", nargs="*", default=None, metavar="NAME", help="catalog objects (all)"
    )
    grasps.add_argument(
        "--mesh", dest="meshes", action="append", default=[], metavar="PATH",
        help="a mesh file (STL, OBJ, PLY) as one more object; repeat for more",
    )  # fmt: skip
    grasps.add_argument(
        "--without-object", dest="with_object", action="store_false",
        help="solve without the object only (no second, collision-aware run)",
    )  # fmt: skip
    grasps.add_argument(
        "--targets-out", default=None, metavar="OUT", help="write the contact sets as targets"
    )
    _add_quiet(grasps)
    add_json_argument(grasps, "the results")


def _solve(benches: Any) -> None:
    solve = add_command(benches, "solve", "sahgrasp solve at scale: problems/s, peak memory")
    solve.add_argument("--problems", type=positive_int, default=10_000, help="random problems")
    solve.add_argument(
        "--lines", type=nonnegative_int, default=1_000_000, help="lines, mostly invalid (0: none)"
    )
    solve.add_argument("--seed", type=nonnegative_int, default=9090, help="seed of the problems")
    solve.add_argument(
        "--workers",
        type=positive_int,
        nargs="+",
        default=[1, 2],
        help="local worker counts to run (the speed-up needs 1 and 2)",
    )
    solve.add_argument(
        "--dask",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run on a Dask LocalCluster of 2 workers",
    )
    _add_quiet(solve)
    add_json_argument(solve, "the timings")


def _check(benches: Any) -> None:
    check = add_command(
        benches, "check", "physics hold test: checks/s on one core, hold rates (needs [sim])"
    )
    check.add_argument(
        "--problems-per-object", type=positive_int, default=20, help="contact sets per object"
    )
    check.add_argument(
        "--seed", type=nonnegative_int, default=7305411, help="seed of the contact sets (>= 0)"
    )
    check.add_argument(
        "--objects", nargs="*", default=None, metavar="NAME", help="catalog objects (all)"
    )
    _add_quiet(check)
    add_json_argument(check, "the results")


def _plan(benches: Any) -> None:
    plan = add_command(
        benches, "plan", "the grasp planner on catalog objects, shipped and test meshes"
    )
    plan.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    plan.add_argument(
        "--objects", nargs="*", default=None, metavar="NAME", help="catalog objects (all)"
    )
    plan.add_argument(
        "--mesh", dest="meshes", action="append", default=[], metavar="PATH",
        help="a mesh file (metres) instead of the shipped ones; repeat for more",
    )  # fmt: skip
    plan.add_argument("--folder", default=None, help="a folder of mesh files (metres) to add")
    plan.add_argument(
        "--no-test-meshes", dest="test_meshes", action="store_false",
        help="leave out the generated test meshes",
    )  # fmt: skip
    plan.add_argument("--candidates", type=positive_int, default=60, help="candidates per object")
    plan.add_argument("--grasps", type=positive_int, default=10, help="grasps returned per object")
    plan.add_argument("--seed", type=nonnegative_int, default=0, help="plan seed (>= 0)")
    plan.add_argument(
        "--rank", default="weight",
        choices=("epsilon", "weight", "inverse_condition", "volume", "min_semiaxis"),
        help="what the planner ranks grasps by (as plan --rank)",
    )  # fmt: skip
    plan.add_argument(
        "--workers", type=positive_int, nargs="*", default=[1, 2],
        help="worker counts of the folder throughput run (none: skip it)",
    )  # fmt: skip
    plan.add_argument(
        "--no-atlas", dest="atlas", action="store_false",
        help="no comparison with the atlas optimum on the can and the bottle",
    )  # fmt: skip
    plan.add_argument(
        "--no-commands",
        dest="commands",
        action="store_false",
        help="do not run 'sahgrasp plan' per object in a fresh process (time from its start)",
    )
    plan.add_argument(
        "--no-verify-physics", dest="verify_physics", action="store_false",
        help="do not plan each object again with --verify physics (MuJoCo)",
    )  # fmt: skip
    _add_quiet(plan)
    add_json_argument(plan, "the results")


def add_parser(sub: Any) -> None:
    """Register the subcommand and its benchmarks."""
    p = add_command(sub, "bench", "run a benchmark, print its summary table, write its JSON")
    benches = p.add_subparsers(dest="bench", required=True, metavar="BENCHMARK", help="benchmark")
    for add in (_kinematics, _ik, _atlas, _sequence, _grasps, _solve, _check, _plan):
        add(benches)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp bench``."""
    options = {k: v for k, v in vars(args).items() if k not in _NOT_OPTIONS}
    if options.get("objects") is None:
        options.pop("objects", None)
    check_outputs(
        [args.json, options.get("plot"), options.get("targets_out")],
        inputs=[options.get("targets"), *options.get("meshes", ()), options.get("folder")],
    )
    check_json_inputs(options.get("hand"))
    if options.get("plot") is not None:
        from sahgrasp.core.extras import require_extra

        require_extra("plot", f"--plot {options['plot']}")  # before the work, not after it
    module = importlib.import_module(f"sahgrasp.bench.{args.bench}")
    with output_file(options.get("plot")) as plot:
        if plot is not None:
            options["plot"] = plot
        data = module.run(**options)
    if plot is not None:
        data["plot"] = options["plot"] = args.plot  # the user's name, not the temporary one
    if args.json != "-":
        from sahgrasp.bench.report import summary_table

        print(summary_table(data))
    if args.json is not None:
        emit_json(data, args.json)
    if plot is not None:
        print(f"wrote {args.plot}", file=human_stream(args.json))
    return 0
