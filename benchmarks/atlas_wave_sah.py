"""One-chart against wave-front atlas on an SAH experiment at the paper's size (docs/results.md).

Builds the atlas of one SAH experiment (scaled coordinates, k = 2) with ``batch = 1`` and with
``batch = --batch``, alternating, and prints the chart count and CPU time of each build.

    python benchmarks/atlas_wave_sah.py [--object bottle] [--radius 0.0088] [--rounds 2]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from sahgrasp.atlas import build_atlas
from sahgrasp.experiments.setups import experiment_settings, make_experiment


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--object", default="bottle", choices=("bottle", "can"))
    parser.add_argument("--radius", type=float, default=0.0088, help="chart radius (scaled)")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    problem = make_experiment(args.object, 2, "sah", "random", 0.1)
    settings = experiment_settings(args.object, args.radius).atlas_settings()
    lower, upper = problem.bounds()
    for _ in range(args.rounds):
        for batch in (1, args.batch):
            start = time.process_time()
            atlas = build_atlas(
                problem.F, problem.J, problem.start, problem.dimension,
                replace(settings, batch=batch), lower, upper,
            )  # fmt: skip
            print(f"batch {batch:3d}: {atlas.n_charts} charts, "
                  f"{time.process_time() - start:.2f} s CPU")  # fmt: skip


if __name__ == "__main__":
    main()
