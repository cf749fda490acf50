"""``sahgrasp plan OBJECT``: ranked, verified grasps of a mesh, a catalog object or a folder."""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sahgrasp.cli.common import (
    HAND_HELP,
    add_command,
    check_json_inputs,
    check_outputs,
    emit_json,
    human_stream,
    nonnegative_int,
    positive_float,
    positive_int,
    printable,
    work_executor,
)
from sahgrasp.cli.solve import resume_hint
from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["add_parser", "run"]

_START_UP_S = 10.0
"""A process older than this when the module is imported did not start as this command."""


def _process_start() -> float:
    """``time.perf_counter()``'s value at this process's start (Linux), else now.

    The interpreter's start-up and every import come before this module runs: a command's
    times count from the process's creation (``/proc/self/stat``, in clock ticks since boot,
    against ``/proc/uptime``: 10 ms resolution).
    """
    now = time.perf_counter()
    try:
        with open("/proc/self/stat", encoding="ascii") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        with open("/proc/uptime", encoding="ascii") as uptime:
            since_boot_s = float(uptime.read().split()[0])
        age_s = since_boot_s - int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22: starttime
    except (OSError, ValueError, IndexError):
        return now
    if not 0.0 <= age_s <= _START_UP_S:  # imported late in a longer-lived process: from now
        return now
    return now - age_s


_STARTED = _process_start()
"""The command's start (the process's creation): times count from it."""

OBJECT_HELP = (
    "a mesh file (STL, OBJ, PLY), a catalog object name (see 'sahgrasp info'), or a folder of "
    "mesh files (one JSON Lines document per object)"
)


def _fingers(text: str) -> tuple[int, ...]:
    try:
        counts = tuple(int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected finger counts like 2,3,4, got {text!r}"
        ) from None
    if not counts or any(c not in (2, 3, 4) for c in counts) or len(set(counts)) != len(counts):
        raise argparse.ArgumentTypeError(
            f"finger counts must be distinct values of 2, 3, 4: {text!r}"
        )
    return counts


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(
        sub,
        "plan",
        "ranked, verified grasps of an object (a mesh file, a catalog object, a folder)",
    )
    p.add_argument("object", help=OBJECT_HELP)
    p.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    p.add_argument(
        "--fingers",
        type=_fingers,
        default=(3, 4, 2),
        help="finger counts to plan: 2 thumb+index, 3 +middle, 4 +ring",
    )
    p.add_argument("--grasps", type=positive_int, default=10, help="distinct grasps to return")
    p.add_argument(
        "--candidates",
        type=positive_int,
        default=60,
        help="contact sets solved per object: the deterministic budget",
    )
    p.add_argument(
        "--time-limit",
        type=positive_float,
        default=None,
        metavar="S",
        help="cap on each object's planning time [s] (results then depend on speed)",
    )
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (>= 0)")
    p.add_argument(
        "--rank",
        default="weight",
        choices=("epsilon", "weight", "inverse_condition", "volume", "min_semiaxis"),
        help="rank force-closure grasps by the weight support (the pull they resist in six "
        "directions per newton of finger force; the default), the L1 epsilon or a "
        "manipulability index",
    )
    p.add_argument("--mu", type=positive_float, default=0.5, help="Coulomb friction coefficient")
    p.add_argument(
        "--scale",
        type=positive_float,
        default=1.0,
        help="factor from the mesh file's unit to metres (1e-3 for millimetres)",
    )
    p.add_argument(
        "--xyz",
        type=float,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help="object position in the world [m] (default: the origin)",
    )
    p.add_argument(
        "--quat",
        type=float,
        nargs=4,
        default=None,
        metavar=("X", "Y", "Z", "W"),
        help="object orientation in the world, unit quaternion (default: identity)",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=positive_int, default=1, help="worker processes for a folder (>= 1)"
    )
    where.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="Dask scheduler for a folder, e.g. tcp://host:8786",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="folder: continue the JSON Lines output of a stopped run",
    )
    p.add_argument(
        "--html",
        default=None,
        metavar="OUT",
        help="write the top grasps side by side as one HTML scene (single object)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_verify_arguments(p)
    p.add_argument(
        "--json",
        default=None,
        metavar="OUT",
        help="write the plan as JSON to OUT (a folder: JSON Lines, OUT.jsonl); "
        "'-': JSON alone on stdout",
    )
    p.set_defaults(run=run, on_interrupt=resume_hint)


def _add_verify_arguments(p: Any) -> None:
    """``--verify physics`` and the hold test's settings (docs/methods/physics.md)."""
    p.add_argument(
        "--verify",
        choices=("physics",),
        default=None,
        help="physics: keep only grasps that hold in the MuJoCo hold test (pip install "
        '"sahgrasp[sim]"), ranked by their hold margin',
    )
    squeeze = p.add_mutually_exclusive_group()
    squeeze.add_argument("--squeeze", type=positive_float, default=None, metavar="N",
                         help="--verify: mean normal force per finger [N] (10)")  # fmt: skip
    squeeze.add_argument("--light", action="store_true",
                         help="--verify: the light squeeze, 1 N per contact finger")  # fmt: skip
    p.add_argument(
        "--max-candidates",
        type=positive_int,
        default=None,
        metavar="N",
        help="--verify: while fewer than --grasps grasps hold, draw further batches of "
        "--candidates candidates, up to N in all (default: 4 x --candidates)",
    )
    mass = p.add_mutually_exclusive_group()
    mass.add_argument("--mass-kg", type=positive_float, default=None,
                      help="--verify: object mass [kg] (default: from --density)")  # fmt: skip
    mass.add_argument("--density", type=positive_float, default=None,
                      help="--verify: object density [kg/m^3] (1000)")  # fmt: skip


def _hold_settings(args: argparse.Namespace) -> Any:
    """The hold test's settings of ``--verify physics`` (None without it)."""
    from sahgrasp.core.errors import InvalidSettingsError

    given = args.light or args.squeeze is not None or args.mass_kg or args.density
    if args.verify is None:
        if given or args.max_candidates is not None:
            raise InvalidSettingsError(
                "--squeeze, --light, --mass-kg, --density and --max-candidates need "
                "--verify physics"
            )
        return None
    from sahgrasp.core.extras import require_extra

    require_extra("sim", "--verify physics")  # one line naming the extra when missing
    from sahgrasp.sim import LIGHT_SQUEEZE_N, HoldSettings

    default = HoldSettings()
    squeeze = LIGHT_SQUEEZE_N if args.light else args.squeeze
    return HoldSettings(
        squeeze_n=default.squeeze_n if squeeze is None else squeeze,
        density_kg_m3=default.density_kg_m3 if args.density is None else args.density,
        mass_kg=args.mass_kg,
    )


def _max_candidates(args: argparse.Namespace) -> int | None:
    """The candidate cap of ``--verify physics`` (None without it)."""
    if args.verify is None:
        return None
    if args.max_candidates is not None:
        return int(args.max_candidates)
    from sahgrasp.planner.settings import CHECK_CANDIDATES_FACTOR

    return CHECK_CANDIDATES_FACTOR * int(args.candidates)


def _settings(args: argparse.Namespace) -> Any:
    from sahgrasp.planner import PlanSettings

    return PlanSettings(
        fingers=args.fingers,
        grasps=args.grasps,
        candidates=args.candidates,
        seed=args.seed,
        mu=args.mu,
        rank=args.rank,
        time_limit_s=args.time_limit,
    )


def _placement(args: argparse.Namespace) -> Any:
    from sahgrasp.objects.targets import object_spec

    data: dict[str, Any] = {"name": "can"}
    if args.xyz is not None:
        data["xyz"] = args.xyz
    if args.quat is not None:
        data["quat"] = args.quat
    spec = object_spec(data, ".")
    assert spec is not None
    return spec


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp plan``; 0 when every object got a grasp, 1 otherwise."""
    from sahgrasp.core.errors import InvalidSettingsError

    folder = Path(args.object).is_dir()
    hold = _hold_settings(args)  # the verify options checked before any work
    check_outputs([args.json, args.html], inputs=[args.object, args.hand])
    check_json_inputs(args.hand)
    if folder:
        from sahgrasp.ik.stream import is_jsonl

        if args.html:
            raise InvalidSettingsError("--html shows one object's grasps; give a mesh file")
        if args.json not in (None, "-") and not is_jsonl(args.json):
            raise InvalidSettingsError("a folder gives JSON Lines: give --json OUT.jsonl or -")
        return _run_folder(args, hold)
    if args.resume:
        raise InvalidSettingsError("--resume continues a folder's JSON Lines output")
    return _run_object(args, hold)


def _load(args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    from sahgrasp.core.errors import InvalidTargetError
    from sahgrasp.objects import OBJECT_NAMES, load_mesh, load_object

    spec = _placement(args)
    path = Path(args.object)
    if args.object in OBJECT_NAMES and not path.exists():
        if args.scale != 1.0:
            raise InvalidTargetError("--scale applies to mesh files, not catalog objects")
        return load_object(args.object, spec.placement()), {
            "name": args.object,
            "xyz": list(spec.xyz),
            "quat": list(spec.quat),
        }
    if not path.exists():
        raise InvalidTargetError(
            f"{args.object!r} is neither a mesh file, a folder, nor a catalog object "
            f"({', '.join(OBJECT_NAMES)})"
        )
    obj = load_mesh(path, scale=args.scale, T_world_object=spec.placement())
    data: dict[str, Any] = {
        "mesh": str(path.resolve()),
        "xyz": list(spec.xyz),
        "quat": list(spec.quat),
    }
    if args.scale != 1.0:
        data["scale"] = args.scale
    return obj, data


def _run_object(args: argparse.Namespace, hold: Any) -> int:
    settings = _settings(args)
    from sahgrasp.model.hand import load_hand
    from sahgrasp.planner import plan_grasps

    out = human_stream(args.json)
    hand = load_hand(args.hand)
    obj, spec = _load(args)
    check = None
    if hold is not None:
        from sahgrasp.sim.verify import PhysicsCheck

        check = PhysicsCheck(hand, obj, hold)
    with _bar(args, settings.candidates, "candidate") as bar:
        plan = plan_grasps(
            hand,
            obj,
            settings,
            object_spec=spec,
            check=check,
            started=_STARTED,
            on_candidate=_growing(bar, settings.candidates),
            max_candidates=_max_candidates(args),
        )
    document = plan.to_dict() if check is None else check.annotate(plan.to_dict())
    for line in _lines(document):
        print(line, file=out)
    if args.html:
        from sahgrasp.viz.plan_view import write_plan_html

        write_plan_html(hand, obj, plan, args.html)
        print(f"wrote {args.html}", file=out)
    if args.json:
        emit_json(document, args.json)
    return 0 if plan.grasps else 1


def _lines(doc: dict[str, Any]) -> list[str]:
    s = doc["summary"]
    name = doc["object"].get("name") or doc["object"].get("mesh")
    lines = [
        f"{printable(str(name))}: {s['grasps']} grasps ({s['force_closure']} force closure) "
        f"of {s['verified']} verified from {s['candidates']} candidates in {s['time_s']:.2f} s; "
        f"first force-closure grasp at "
        f"{'-' if s['time_to_first_s'] is None else format(s['time_to_first_s'], '.2f') + ' s'}"
    ]
    if "hold_checked" in s:
        lines.append(
            f"  physics: {s['hold_passed']} of {s['hold_checked']} grasps checked hold "
            "(those that do not are dropped)"
        )
    # The index the grasps are ranked by comes first, so the order of the lines reads off it.
    ranked_by = doc["settings"].get("rank", "epsilon")
    for g in doc["grasps"]:
        q = g["quality"]
        held = f"  holds, margin {g['hold']['margin']:.2f}" if "hold" in g else ""
        index = (
            f"{ranked_by} {q[ranked_by]:<7.4g} "
            if ranked_by != "epsilon" and q.get(ranked_by) is not None
            else ""
        )
        lines.append(
            f"  {g['rank']:>2} {'+'.join(g['fingers']):<24} {index}epsilon {q['epsilon_l1']:.4f}  "
            f"force closure {'yes' if q['force_closure'] else 'no ':<3}  "
            f"clearance {g['object_clearance_mm']:.2f} mm ({g['closest_link']}){held}"
        )
    return lines


def _run_folder(args: argparse.Namespace, hold: Any) -> int:
    settings = _settings(args)
    from sahgrasp.ik.stream import ResultsWriter
    from sahgrasp.model.hand import load_hand
    from sahgrasp.planner.folder import folder_jobs, plan_jobs

    out = human_stream(args.json)
    hand = load_hand(args.hand)
    jobs = folder_jobs(args.object, settings, args.scale, hand.description.name)
    make_check = None
    if hold is not None:
        from sahgrasp.sim.verify import PhysicsCheckFactory

        make_check = PhysicsCheckFactory(hold)
    writer = None
    done: set[str] = set()
    failed = 0
    if args.json not in (None, "-"):
        header = _header(hand, settings, args, hold)
        writer = ResultsWriter(args.json, header, args.resume)
        for entry in writer.finished():
            done.add(str(entry.get("object_digest")))
            failed += not entry.get("grasps")
    todo = [j for j in jobs if j.digest not in done]
    complete = False
    try:
        with (
            work_executor(args) as pool,
            _bar(args, len(jobs), "object", len(jobs) - len(todo)) as bar,
        ):
            for doc in plan_jobs(
                hand.description,
                todo,
                settings,
                pool,
                2 * max(args.workers, 1),
                make_check,
                _max_candidates(args),
            ):
                bar.update()
                failed += not doc.get("grasps")
                if "error" in doc:
                    print(
                        f"{printable(doc['object']['mesh'])}: refused: {printable(doc['error'])}",
                        file=sys.stderr,
                    )
                else:
                    for line in _lines(doc)[:1]:
                        print(line, file=out)
                if writer is not None:
                    writer.write([doc])
                elif args.json == "-":
                    import json

                    sys.stdout.write(json.dumps(doc) + "\n")
        complete = True
    finally:
        if writer is not None:
            writer.close(complete)
    print(f"{len(jobs) - failed}/{len(jobs)} objects with a grasp", file=out)
    return 0 if failed == 0 else 1


def _header(hand: Any, settings: Any, args: argparse.Namespace, hold: Any) -> dict[str, Any]:
    import hashlib
    import json

    from sahgrasp.ik.stream import RESULTS_FORMAT

    data = {
        "hand": hand.description.name,
        "hand_digest": hand.description.digest(),
        "settings": {**settings.to_dict(), "scale": args.scale, **_verify_header(args, hold)},
        "sequence_digest": "plan",
    }
    digest = hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()
    return {
        "format": RESULTS_FORMAT,
        **data,
        "targets": Path(args.object).name,
        "settings_digest": digest,
    }


def _verify_header(args: argparse.Namespace, hold: Any) -> dict[str, Any]:
    """The hold test's settings ``hold`` in a folder run's header (a resume must use the same)."""
    import dataclasses

    if hold is None:
        return {}
    physics = dataclasses.asdict(hold)
    return {"verify": {"physics": physics, "max_candidates": _max_candidates(args)}}


def _growing(bar: Any, batch: int) -> Callable[[], None]:
    """Advance ``bar`` by one candidate, its total by a batch when a further batch is drawn."""

    def step() -> None:
        # --verify physics draws further batches while too few grasps hold.
        if bar.total is not None and bar.n >= bar.total:
            bar.total += batch
            bar.refresh()
        bar.update()

    return step


def _bar(args: argparse.Namespace, total: int, unit: str, done: int = 0) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=done,
        unit=unit,
        file=sys.stderr,
        disable=True if args.quiet else None,
        dynamic_ncols=True,
    )
