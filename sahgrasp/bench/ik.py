"""``sahgrasp bench ik``: success and time of Algorithm 1 against the number of initial poses.

On the same problems, from the same initial configurations and with the same acceptance test, it
runs ``method=paper`` and ``method=auto`` each with ``init=sequence`` and ``init=random``, and the
peers of :mod:`sahgrasp.bench.peers` with ``init=sequence``. Because Algorithm 1 tries its initial
configurations in order, one run with ``i_max = 12`` gives every smaller ``i_max`` too: a
problem counts as solved within ``i`` configurations when it succeeded with ``inits_used <= i``,
and its time under that cap is the time at the end of its ``min(i, inits_used)``-th attempt
(Fig. 9a). Fig. 9b is the share of problems solved within a time budget.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from sahgrasp.contacts import GraspTarget, load_targets
from sahgrasp.hand import Hand, load_hand
from sahgrasp.ik import IKResult, IKSettings, default_sequence, random_problems
from sahgrasp.ik.solver import AttemptFn, run_algorithm1, solve_ik

__all__ = ["run", "summarize"]

RUNS: tuple[tuple[str, str], ...] = (
    ("auto", "sequence"),
    ("auto", "random"),
    ("paper", "sequence"),
    ("paper", "random"),
)


def summarize(results: Sequence[IKResult], max_inits: int) -> dict[str, Any]:
    """Fig. 9 statistics of one configuration's results."""
    times_ms = np.array([r.time_s for r in results]) * 1e3
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
        "by_inits": by_inits,
        "solved_times_ms": sorted(
            float(t) for r, t in zip(results, times_ms, strict=True) if r.success
        ),
    }


def _solve_all(
    hand: Hand,
    problems: Sequence[GraspTarget],
    label: str,
    solve: Any,
) -> list[IKResult]:
    return [solve(p) for p in tqdm(problems, desc=label, unit="problem", leave=False)]


def _peer(hand: Hand, fn: AttemptFn, settings: IKSettings) -> Any:
    return lambda target: run_algorithm1(hand, target, fn, settings)


def run(
    hand: str = "sah",
    problems: int = 1000,
    seed: int = 0,
    targets: str | None = None,
    peers: Sequence[str] = ("scipy", "pink"),
    peer_problems: int | None = 200,
    plot: str | None = None,
) -> dict[str, Any]:
    """Run the benchmark; returns the JSON document (and writes the figure to ``plot``).

    Args:
        hand: Hand name or description path.
        problems: Random feasible problems (ignored with ``targets``).
        seed: Seed of the problems and of the random initial configurations.
        targets: A targets file instead of random problems.
        peers: Peer solvers to run (``scipy``, ``pink``).
        peer_problems: Peers are slow: run them on the first this-many problems (None = all).
        plot: PNG path for the Fig. 9 reproduction.
    """
    model = load_hand(hand)
    problem_set = (
        list(load_targets(targets).problems) if targets else random_problems(model, problems, seed)
    )
    default_sequence(model)  # built before timing
    out: dict[str, Any] = {"benchmark": "ik", "hand": model.description.name, "seed": seed,
                           "problems": len(problem_set), "runs": {}}  # fmt: skip
    for method, init in RUNS:
        settings = IKSettings(method=method, init=init, seed=seed)
        results = _solve_all(model, problem_set, f"{method}/{init}",
                             lambda t, s=settings: solve_ik(model, t, s))  # fmt: skip
        out["runs"][f"{method}/{init}"] = summarize(results, settings.max_inits)
    if peers:
        from sahgrasp.bench.peers import PEERS

        subset = problem_set[:peer_problems] if peer_problems else problem_set
        auto = IKSettings(seed=seed)
        results = _solve_all(model, subset, "auto/sequence (peer subset)",
                             lambda t: solve_ik(model, t, auto))  # fmt: skip
        out["runs"]["auto/sequence (peer subset)"] = summarize(results, auto.max_inits)
        for name in peers:
            results = _solve_all(model, subset, name, _peer(model, PEERS[name], auto))
            out["runs"][f"peer:{name}/sequence"] = summarize(results, auto.max_inits)
    out["created_unix_s"] = time.time()
    if plot:
        plot_fig9(out, plot)
        out["plot"] = plot
    return out


def plot_fig9(document: dict[str, Any], path: str) -> None:
    """Write the Fig. 9a/9b reproduction: success and time vs inits, success vs time."""
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
