"""``sahgrasp bench ik``: success and time of Algorithm 1 against the number of initial poses.

On the same problems, from the same initial configurations and with the same acceptance test, it
runs ``method=auto`` with ``init=learned`` (the database's nearest grasps first, then the
sequence), ``method=paper`` and ``method=auto`` each with ``init=sequence`` and ``init=random``, the
peers of :mod:`sahgrasp.bench.peers` with ``init=sequence``, and, when the hand's sequence comes
from the offline search, ``method=auto`` with the paper's Table 1 lambdas on the same PCA basis.
Because Algorithm 1 tries its initial configurations in order, one run with ``i_max = 12``
gives every smaller ``i_max`` too: a problem counts as solved within ``i`` configurations when it
succeeded with ``inits_used <= i``, and its time under that cap is the time at the end of its
``min(i, inits_used)``-th attempt (Fig. 9a). Fig. 9b is the share of problems solved within a time
budget.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.bench.peers import PEERS, available_peers
from sahgrasp.bench.report import progress_reporter
from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.ik import (
    PAPER_TABLE1_LAMBDAS,
    IKResult,
    IKSettings,
    default_sequence,
    random_problems,
)
from sahgrasp.ik.learned import QUERY_EPS, GraspDatabase, default_database, target_key
from sahgrasp.ik.solver import Init, Method, run_algorithm1, solve_ik
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.model.hands import DEFAULT_HAND
from sahgrasp.objects.targets import load_targets

__all__ = ["run", "summarize"]

RUNS: tuple[tuple[Method, Init], ...] = (
    ("auto", "learned"),
    ("auto", "sequence"),
    ("auto", "random"),
    ("paper", "sequence"),
    ("paper", "random"),
)


def summarize(
    results: Sequence[IKResult], max_inits: int, cpu_s: Sequence[float] | None = None
) -> dict[str, Any]:
    """Fig. 9 statistics of one configuration's results.

    Args:
        results: The configuration's results, one per problem.
        max_inits: ``i_max`` of the runs (Fig. 9a's x axis).
        cpu_s: Per problem, the CPU time [s] of the whole ``solve_ik`` call (this process), if
            measured: unlike the wall time it does not grow with other processes' load.
    """
    times_ms = np.array([r.time_s for r in results]) * 1e3
    iterations = max(sum(r.iterations for r in results), 1)
    by_inits = []
    for i in range(1, max_inits + 1):
        solved = [r.success and r.inits_used <= i for r in results]
        capped = [r.attempt_seconds[min(i, len(r.attempt_seconds)) - 1] * 1e3 for r in results]
        by_inits.append(
            {
                "inits": i,
                "success_rate": float(np.mean(solved)),
                "mean_time_ms": float(np.mean(capped)),
            }
        )
    return {
        "problems": len(results),
        "success_rate": float(np.mean([r.success for r in results])),
        "first_init_success_rate": by_inits[0]["success_rate"],
        "median_time_ms": float(np.median(times_ms)),
        "mean_time_ms": float(times_ms.mean()),
        "p95_time_ms": float(np.percentile(times_ms, 95)),
        "mean_iterations": float(np.mean([r.iterations for r in results])),
        # All in: the whole solve's time (starts, collision checks) per Jacobian iteration.
        "us_per_iteration": float(times_ms.sum() * 1e3 / iterations),
        "by_inits": by_inits,
        "solved_times_ms": sorted(
            float(t) for r, t in zip(results, times_ms, strict=True) if r.success
        ),
        **({} if cpu_s is None else _cpu_stats(np.asarray(cpu_s) * 1e3, iterations)),
    }


def _cpu_stats(cpu_ms: NDArray[np.float64], iterations: int) -> dict[str, float]:
    """Median, mean, p95 of the CPU time per problem [ms] and per Jacobian iteration [us]."""
    return {
        "cpu_median_ms": float(np.median(cpu_ms)),
        "cpu_mean_ms": float(cpu_ms.mean()),
        "cpu_p95_ms": float(np.percentile(cpu_ms, 95)),
        "cpu_us_per_iteration": float(cpu_ms.sum() * 1e3 / iterations),
    }


def lookup_stats(
    database: GraspDatabase, hand: Hand, targets: Sequence[Any], k: int
) -> dict[str, Any]:
    """The learned start's neighbour search on these targets: approximate against exact.

    Returns the share of the exact ``k`` nearest entries that the approximate query
    (:data:`~sahgrasp.ik.learned.QUERY_EPS`) finds, and the CPU time per query of each [us].
    """
    keys = [target_key(hand, t) for t in targets]
    keys = [key for key in keys if key is not None]
    found: dict[float, list[set[int]]] = {}
    cpu_us: dict[float, float] = {}
    for eps in (0.0, QUERY_EPS):
        start = time.process_time()
        found[eps] = [set(np.atleast_1d(database.tree.query(key, k=k, eps=eps)[1]).tolist())
                      for key in keys]  # fmt: skip
        cpu_us[eps] = (time.process_time() - start) / max(len(keys), 1) * 1e6
    recall = [len(a & b) / k for a, b in zip(found[QUERY_EPS], found[0.0], strict=True)]
    return {
        "entries": len(database.features),
        "k": k,
        "eps": QUERY_EPS,
        "recall": float(np.mean(recall)) if recall else None,
        "exact_query_cpu_us": cpu_us[0.0],
        "approximate_query_cpu_us": cpu_us[QUERY_EPS],
    }


def _solvers(hand: Hand, seed: int, peers: Sequence[str]) -> dict[str, Any]:
    """Configuration label -> function solving one target."""
    solvers: dict[str, Any] = {}
    for method, init in RUNS:
        settings = IKSettings(method=method, init=init, seed=seed)
        solvers[f"{method}/{init}"] = lambda t, s=settings: solve_ik(hand, t, s)
    searched = default_sequence(hand)
    # The sequences alone: Table 1 and the peers are compared from the sequence's starts.
    auto = IKSettings(init="sequence", seed=seed)
    if searched.source == "search":  # the paper's Table 1 on the same PCA basis, for comparison
        table1 = replace(searched, lambdas=PAPER_TABLE1_LAMBDAS, source="paper-table1")
        solvers["auto/paper-table1"] = lambda t: solve_ik(hand, t, auto, table1)
    if peers:
        for name in peers:
            solvers[f"peer:{name}/sequence"] = lambda t, fn=PEERS[name]: run_algorithm1(
                hand, t, fn, auto
            )
    return solvers


def run(
    hand: str = DEFAULT_HAND,
    problems: int = 1000,
    seed: int = 0,
    targets: str | None = None,
    peers: Sequence[str] = ("scipy", "pink"),
    peer_problems: int | None = 200,
    plot: str | None = None,
    quiet: bool = False,
    progress: ProgressCallback | None = None,
) -> dict[str, Any]:
    """Run the benchmark; returns the JSON document (and writes the figure to ``plot``).

    Every configuration solves problem ``i`` right after the others, so that a change in machine
    load affects them alike; peers, slower, see only the first ``peer_problems`` problems, and the
    ``auto/sequence`` statistics on that subset are reported beside them. A peer whose package is
    not installed is skipped with one line on stderr naming the ``bench`` extra; the document's
    ``skipped_peers`` says why.

    Args:
        hand: Hand name or description path.
        problems: Random feasible problems (ignored with ``targets``).
        seed: Seed of the problems and of the random initial configurations.
        targets: A targets file instead of random problems.
        peers: Peer solvers to run (``scipy``, ``pink``).
        peer_problems: Peers run on the first this-many problems (None = all).
        plot: PNG path for the Fig. 9 reproduction.
        quiet: No progress bar on stderr.
        progress: Hears of every problem solved (stage ``"bench ik: problems"``) instead of the
            bar.

    Raises:
        InvalidSettingsError: An unknown peer name, or ``problems`` or ``peer_problems`` < 1.
    """
    if problems < 1 or (peer_problems is not None and peer_problems < 1):
        raise InvalidSettingsError(
            f"problems and peer_problems must be >= 1 (peer_problems may be None for all); got "
            f"{problems} and {peer_problems}"
        )
    peers, skipped = available_peers(peers)
    for name, reason in skipped.items():
        print(f"bench ik: skipping peer {name}: {reason}", file=sys.stderr)
    model = load_hand(hand)
    problem_set = (
        list(load_targets(targets).problems) if targets else random_problems(model, problems, seed)
    )
    default_sequence(model)  # built before timing
    learned = default_database(model)
    if learned is not None:
        learned.tree  # noqa: B018 -- the k-d tree is built before timing
    solvers = _solvers(model, seed, peers)
    subset = len(problem_set) if peer_problems is None else peer_problems
    results: dict[str, list[IKResult]] = {label: [] for label in solvers}
    cpu_s: dict[str, list[float]] = {label: [] for label in solvers}
    load_before = os.getloadavg()
    with progress_reporter(progress, quiet) as report:
        for i, target in enumerate(problem_set):
            for label, solve in solvers.items():
                if i < subset or not label.startswith("peer:"):
                    start = time.process_time()
                    results[label].append(solve(target))
                    cpu_s[label].append(time.process_time() - start)
            if report is not None:
                report("bench ik: problems", i + 1, len(problem_set))
    max_inits = IKSettings().max_inits
    runs = {label: summarize(rs, max_inits, cpu_s[label]) for label, rs in results.items()}
    if peers:
        runs["auto/sequence (peer subset)"] = summarize(
            results["auto/sequence"][:subset], max_inits, cpu_s["auto/sequence"][:subset]
        )
    out: dict[str, Any] = {
        "benchmark": "ik",
        "hand": model.description.name,
        "seed": seed,
        "problems": len(problem_set),
        "peer_problems": min(subset, len(problem_set)),
        "skipped_peers": skipped,
        "runs": runs,
        # The machine may be shared: its 1-min load average (and cores) beside the timings.
        "load_average": {"before": load_before[0], "after": os.getloadavg()[0]},
        "cores": os.cpu_count(),
        "created_unix_s": time.time(),
    }
    if learned is not None:
        out["learned_lookup"] = lookup_stats(
            learned, model, problem_set, IKSettings().learned_starts
        )
    if plot:
        plot_fig9(out, plot)
        out["plot"] = plot
    return out


def plot_fig9(document: dict[str, Any], path: str) -> None:
    """Write the Fig. 9a/9b reproduction: success and time vs inits, success vs time."""
    from sahgrasp.core.extras import require_extra

    require_extra("plot", f"the figure {path}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_a, ax_b) = plt.subplots(1, 2, figsize=(12, 4.5))
    ax_t = ax_a.twinx()
    for label, stats in document["runs"].items():
        if "subset" in label:
            continue
        inits = [row["inits"] for row in stats["by_inits"]]
        ax_a.plot(inits, [100 * row["success_rate"] for row in stats["by_inits"]], "-o",
                  label=label, markersize=3)  # fmt: skip
        ax_t.plot(inits, [row["mean_time_ms"] for row in stats["by_inits"]], "--", alpha=0.6)
        times = stats["solved_times_ms"]
        share = 100 * np.arange(1, len(times) + 1) / stats["problems"]
        ax_b.plot(times, share, label=label)
    ax_a.set(xlabel="initial configurations allowed", ylabel="success [%] (solid)")
    ax_t.set_ylabel("mean time per problem [ms] (dashed)")
    ax_b.set(xlabel="time [ms]", ylabel="solved [%]", xscale="log")
    ax_a.legend(fontsize=7, loc="lower right")
    ax_b.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"{document['hand']}: {document['problems']} problems (cf. Fig. 9)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
