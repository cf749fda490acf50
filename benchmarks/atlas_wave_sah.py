"""One-chart against wave-front atlas on an SAH experiment (docs/results.md, docs/methods/atlas.md).

Builds the atlas of one SAH experiment with ``batch = 1`` and with ``batch = --batch``,
alternating, and prints the chart count and CPU time of each build. The defaults are the oil
bottle at the paper's size (k = 2, scaled coordinates with a length scale of 0.1 m).

    python benchmarks/atlas_wave_sah.py [--object bottle] [--k 2] [--radius 0.0088]
        [--scale 0.1 | --unscaled] [--rounds 2]
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
    parser.add_argument("--k", type=int, default=2, help="dimension of the atlas")
    parser.add_argument("--radius", type=float, default=0.0088, help="chart radius")
    parser.add_argument("--scale", type=float, default=0.1, help="length scale [m]")
    parser.add_argument("--unscaled", action="store_true", help="unscaled coordinates")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    scale = None if args.unscaled else args.scale
    problem = make_experiment(args.object, args.k, "sah", "random", scale)
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
