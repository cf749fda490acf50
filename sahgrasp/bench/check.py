"""``sahgrasp bench check``: the physics hold test's speed and hold rates on the catalog objects.

Per object: contact sets drawn as ``sahgrasp bench grasps`` draws them (same seed derivation),
solved by the IK with the object as the obstacle; every solution is hold-tested with the default
settings and with the light squeeze (:data:`~sahgrasp.sim.LIGHT_SQUEEZE_N` per contact finger).
The object's paper grasp, if it has one, is tested too. Times are CPU seconds of this process
(one core), the model built once per object and timed apart. Every solution is also tested with
the default settings in DexGraspBench's MuJoCo solver settings
(:func:`~sahgrasp.sim.settings.dexgraspbench_solver`, untimed), the independent cross-check:
``default_not_dexgraspbench`` counts the grasps that hold by default but not there.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from statistics import mean, median
from typing import Any

from sahgrasp.bench.grasps import BENCH_SEED, _object_seed
from sahgrasp.bench.report import progress_reporter
from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.fileio import write_json_atomic
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.ik import default_sequence, solve_ik
from sahgrasp.model.hand import load_hand
from sahgrasp.model.hands import DEFAULT_HAND
from sahgrasp.objects import GRASP_NAMES, OBJECT_NAMES, load_object, paper_grasp
from sahgrasp.objects.grasp_sampler import sample_object_grasps
from sahgrasp.objects.reach import sampler_reach
from sahgrasp.sim import (
    LIGHT_SQUEEZE_N,
    HoldResult,
    HoldSettings,
    HoldTester,
    dexgraspbench_solver,
)

__all__ = ["format_table", "run"]


def _rates(results: Sequence[HoldResult]) -> dict[str, Any]:
    count = len(results)
    reasons: dict[str, int] = {}
    for r in results:
        if not r.holds:
            reasons[r.reason] = reasons.get(r.reason, 0) + 1
    return {
        "checked": count,
        "holds": sum(r.holds for r in results),
        "hold_rate": sum(r.holds for r in results) / count if count else None,
        "hold_rate_bodex": sum(r.holds_bodex for r in results) / count if count else None,
        "failures": reasons,
    }


def run(
    problems_per_object: int = 20,
    seed: int = BENCH_SEED,
    objects: Sequence[str] = OBJECT_NAMES,
    json_out: str | None = None,
    quiet: bool = False,
    progress: ProgressCallback | None = None,
) -> dict[str, Any]:
    """Run the benchmark; return its JSON document (written atomically to ``json_out`` if given).

    Args:
        problems_per_object: Contact sets drawn and solved per object (the solved ones are
            hold-tested).
        seed: Benchmark seed (each object's contact sets as in ``sahgrasp bench grasps``).
        objects: Catalog objects.
        json_out: Path of the JSON document, or None.
        quiet: No progress on stderr.
        progress: Called as ``progress(stage, done, total)`` instead of the stderr bars.

    Raises:
        InvalidSettingsError: ``problems_per_object`` below 1.
        InvalidTargetError: An unknown catalog object.
    """
    if problems_per_object < 1:
        raise InvalidSettingsError(f"problems_per_object must be >= 1, got {problems_per_object}")
    hand = load_hand(DEFAULT_HAND)
    default_sequence(hand)
    settings = HoldSettings()
    light = dataclasses.replace(settings, squeeze_n=LIGHT_SQUEEZE_N)
    rows: list[dict[str, Any]] = []
    with progress_reporter(progress, quiet) as report:
        for name in objects:
            obj = load_object(name)
            stage = f"bench check {name}"
            targets = sample_object_grasps(obj, problems_per_object, _object_seed(seed, name),
                                           sampler_reach(hand))  # fmt: skip
            if name in GRASP_NAMES:
                targets = [paper_grasp(name), *targets]
            solved = []
            for k, target in enumerate(targets):
                result = solve_ik(hand, target, obstacle=obj)
                if result.success:
                    solved.append((k == 0 and name in GRASP_NAMES, result))
                if report is not None:
                    report(f"{stage}: solve", k + 1, len(targets))
            start = time.process_time()
            testers = {
                "default": HoldTester(hand, obj, settings),
                "light": HoldTester(hand, obj, light),
            }
            build_s = (time.process_time() - start) / 2
            cross = HoldTester(hand, obj, dexgraspbench_solver(settings))
            out: dict[str, list[HoldResult]] = {"default": [], "light": [], "dexgraspbench": []}
            cpu: list[float] = []
            paper: dict[str, bool] = {}
            for k, (is_paper, result) in enumerate(solved):
                for label, tester in testers.items():
                    start = time.process_time()
                    held = tester.test(result)
                    cpu.append(time.process_time() - start)
                    if is_paper:
                        paper[label] = held.holds
                    else:
                        out[label].append(held)
                if not is_paper:  # the cross-check, untimed
                    out["dexgraspbench"].append(cross.test(result))
                if report is not None:
                    report(f"{stage}: hold test", k + 1, len(solved))
            rows.append({
                "object": name,
                "mass_kg": testers["default"].sim.mass_kg,
                "pieces": len(obj.collision_shapes()),
                "contact_sets": problems_per_object,
                "solved": sum(not p for p, _ in solved),
                "model_build_s": build_s,
                "check_cpu_median_ms": 1e3 * median(cpu) if cpu else None,
                "check_cpu_mean_ms": 1e3 * mean(cpu) if cpu else None,
                "checks_per_s_one_core": 1.0 / mean(cpu) if cpu else None,
                "default": _rates(out["default"]),
                "light": _rates(out["light"]),
                "dexgraspbench": _rates(out["dexgraspbench"]),
                "default_not_dexgraspbench": sum(
                    a.holds and not b.holds
                    for a, b in zip(out["default"], out["dexgraspbench"], strict=True)
                ),
                "paper_grasp_holds": paper or None,
            })  # fmt: skip
    all_cpu = [float(r["check_cpu_mean_ms"]) for r in rows if r["check_cpu_mean_ms"] is not None]
    document: dict[str, Any] = {
        "benchmark": "check",
        "hand": hand.description.name,
        "seed": seed,
        "problems_per_object": problems_per_object,
        "settings": dataclasses.asdict(settings),
        "light_squeeze_n": LIGHT_SQUEEZE_N,
        "objects": rows,
        "mean_check_cpu_ms": mean(all_cpu) if all_cpu else None,
        "created_unix_s": time.time(),
    }
    if json_out is not None:
        write_json_atomic(json_out, document)
    return document


def format_table(document: dict[str, Any]) -> str:
    """A Markdown table of :func:`run`'s document, one row per object."""
    lines = [
        "| object | mass kg | pieces | solved | holds (default) | BODex (default) "
        "| holds (light squeeze) | paper grasp (default, light) | check CPU ms (median) "
        "| checks/s, 1 core | holds (DexGraspBench solver) | default, not DexGraspBench |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def pct(rates: dict[str, Any], key: str) -> str:
        value = rates[key]
        if value is None:
            return "-"
        return f"{100 * value:.0f}% ({round(value * rates['checked'])}/{rates['checked']})"

    for row in document["objects"]:
        paper = row["paper_grasp_holds"]
        paper_cell = (
            "-"
            if not paper
            else ", ".join("holds" if paper.get(k) else "fails" for k in ("default", "light"))
        )
        cpu = row["check_cpu_median_ms"]
        rate = row["checks_per_s_one_core"]
        lines.append(
            f"| {row['object']} | {row['mass_kg']:.3f} | {row['pieces']} | "
            f"{row['solved']}/{row['contact_sets']} | {pct(row['default'], 'hold_rate')} | "
            f"{pct(row['default'], 'hold_rate_bodex')} | {pct(row['light'], 'hold_rate')} | "
            f"{paper_cell} | {'-' if cpu is None else f'{cpu:.0f}'} | "
            f"{'-' if rate is None else f'{rate:.0f}'} | "
            f"{pct(row['dexgraspbench'], 'hold_rate') if 'dexgraspbench' in row else '-'} | "
            f"{row.get('default_not_dexgraspbench', '-')} |"
        )
    return "\n".join(lines)
