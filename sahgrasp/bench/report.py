"""What every benchmark shares: its progress reports on stderr and a one-screen summary table.

A benchmark's ``run(..., quiet=False, progress=None)`` reports its progress through
:func:`progress_reporter` (bars on stderr unless ``quiet``, or the caller's callback) and returns
its JSON document; :func:`summary_table` turns any benchmark's document into a short text table
(``document["benchmark"]`` says which) for the terminal, the JSON staying the full record.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.progress import ProgressCallback, StderrProgress
from sahgrasp.core.tables import format_table

__all__ = ["progress_reporter", "summary_table"]

Document = dict[str, Any]


@contextmanager
def progress_reporter(
    progress: ProgressCallback | None, quiet: bool
) -> Iterator[ProgressCallback | None]:
    """The callback a benchmark reports to: ``progress`` if given, else stderr bars unless quiet.

    Bars are drawn only on a terminal: in a log file or a pipe their carriage returns and
    redraws are noise, not progress.
    """
    if progress is not None or quiet or not _is_terminal(sys.stderr):
        yield progress
        return
    with StderrProgress() as bar:
        yield bar


def _is_terminal(stream: object) -> bool:
    try:
        return bool(stream.isatty())  # type: ignore[attr-defined]
    except (AttributeError, ValueError):  # no stream, or a closed one
        return False


def _ik_table(doc: Document) -> str:
    rows = [
        (label, s["problems"], 100 * s["success_rate"], 100 * s["first_init_success_rate"],
         s["median_time_ms"], s["p95_time_ms"], s.get("cpu_median_ms"), s.get("cpu_mean_ms"),
         s["mean_iterations"])
        for label, s in doc["runs"].items()
    ]  # fmt: skip
    headers = ("run", "problems", "solved [%]", "1st init [%]", "median [ms]", "p95 [ms]",
               "CPU median [ms]", "CPU mean [ms]", "iterations")  # fmt: skip
    lines = [f"bench ik: {doc['hand']}, {doc['problems']} problems, seed {doc['seed']}"]
    lines.append(format_table(headers, rows))
    for name, reason in doc.get("skipped_peers", {}).items():
        lines.append(f"peer {name} skipped: {reason}")
    return "\n".join(lines)


def _atlas_table(doc: Document) -> str:
    rows = []
    for name, case in doc["cases"].items():
        target = "-"
        if "target_seconds" in case:
            low, high = case["baseline_seconds"]
            target = (
                f"{case['seconds'] / case['target_seconds']:.3g}x target "
                f"{case['target_seconds']:g} s (CuikSuite {low:g}-{high:g} s)"
            )
        elif "whole_seconds" in case:
            target = (
                f"atlas + indices {case['whole_seconds']:.3g} s, target "
                f"{case['whole_target_seconds']:g} s (paper: {case['baseline_charts']} charts)"
            )
        elif "whole_target_seconds" in case:
            target = (
                f"whole run, {case['workers']} checking process(es): target "
                f"{case['whole_target_seconds']:g} s (paper {case['paper_charts']:g} charts, "
                f"{case['paper_seconds']:g} s)"
            )
        elif "speedup" in case:
            target = f"{case['speedup']:.3g}x paper rate ({doc['sah_speedup_target']:g}x)"
        elif "baseline_charts" in case:
            target = f"C: {case['baseline_charts']} charts"
        one = case.get("one_chart", {})
        rows.append((name, case["charts"], case["complete"], case["seconds"],
                     case["charts_per_second"], one.get("charts"), one.get("seconds"),
                     target))  # fmt: skip
    headers = ("case", "charts", "complete", "best [s]", "charts/s", "one-chart charts",
               "one-chart [s]", "against")  # fmt: skip
    return "bench atlas\n" + format_table(headers, rows)


def _kinematics_table(doc: Document) -> str:
    rows = [
        (name, h["raw_fk_us"], h["contact_state_us"], h["contact_state_ratio"],
         h["contact_stack_us"], h["contact_stack_ratio"], h["raw_jacobians_us"],
         h["contact_jacobians_us"], h["contact_jacobians_ratio"],
         h["contact_stack_jacobian_us"], h["contact_stack_jacobian_ratio"])
        for name, h in doc["hands"].items()
    ]  # fmt: skip
    headers = ("hand", "raw fk [us]", "state [us]", "ratio", "stack [us]", "ratio",
               "raw jac [us]", "jacobians [us]", "ratio", "stack jac [us]", "ratio")  # fmt: skip
    title = f"bench kinematics: {doc['calls']} calls, target ratio <= {doc['target_ratio']:g}"
    return f"{title}\n{format_table(headers, rows)}"


def _sequence_table(doc: Document) -> str:
    rows = [
        (workers, row["wall_seconds"], row["ik_runs"], row["ik_runs_per_second"])
        for workers, row in doc["workers"].items()
    ]
    scale = doc["paper_scale"]
    return "\n".join((
        f"bench sequence: {doc['hand']}",
        format_table(("workers", "wall [s]", "IK runs", "runs/s"), rows),
        f"speed-up {doc['speedup']:.3g}; paper scale on {scale['cluster_workers']} workers: "
        f"{scale['hours']:.3g} h",
    ))  # fmt: skip


def _solve_table(doc: Document) -> str:
    rows = [
        (c["where"], c["lines"], c["wall_s"], c["problems_per_s"], c["cpu_s"],
         c["problems_per_cpu_s"], c["peak_rss_mb"])
        for c in doc["cases"]
    ]  # fmt: skip
    headers = ("case", "lines", "wall [s]", "lines/s", "CPU [s]", "lines/CPU s", "peak [MB]")
    speedup = doc["speedup_1_to_2_workers"]
    return "\n".join((
        f"bench solve: {doc['problems']} problems, seed {doc['seed']}",
        format_table(headers, rows),
        "speed-up 1 -> 2 workers " + ("not run" if speedup is None else f"{speedup:.3g}"),
    ))  # fmt: skip


def _grasps_table(doc: Document) -> str:
    from sahgrasp.bench.grasps import format_table as grasps_table

    return f"bench grasps: {doc['hand']}, seed {doc['seed']}\n{grasps_table(doc)}"


def _check_table(doc: Document) -> str:
    rows = [
        (r["object"], r["solved"], r["default"]["hold_rate"], r["light"]["hold_rate"],
         r["check_cpu_median_ms"], r["checks_per_s_one_core"])
        for r in doc["objects"]
    ]  # fmt: skip
    headers = ("object", "solved", "hold rate", "light squeeze", "CPU ms", "checks/s")
    return format_table(headers, rows)


def _plan_table(doc: Document) -> str:
    from sahgrasp.bench.plan import format_table as plan_table

    return plan_table(doc)


_TABLES: dict[str, Callable[[Document], str]] = {
    "check": _check_table,
    "ik": _ik_table,
    "atlas": _atlas_table,
    "kinematics": _kinematics_table,
    "sequence": _sequence_table,
    "grasps": _grasps_table,
    "solve": _solve_table,
    "plan": _plan_table,
}


def summary_table(document: Document) -> str:
    """A benchmark's JSON document as a short text table (a few lines per case).

    Raises:
        InvalidSettingsError: The document names no known benchmark.
    """
    name = document.get("benchmark")
    if name not in _TABLES:
        raise InvalidSettingsError(
            f"not a benchmark document (benchmark = {name!r}); valid: {', '.join(_TABLES)}"
        )
    return _TABLES[name](document)
