"""Global grasp optimisation of the SAH holding the bottle (atlas paper, Fig. 10b).

An atlas of the relevant grasps (k = 2) from the IK's first grasp, the volume of the
manipulability ellipsoid at every chart centre, the best and the worst grasp. Run
`python examples/optimize_bottle.py` to open the viewer, or add `--html OUT` to write the scene;
`--max-charts 200` gives a quick, partial atlas.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from sahgrasp.experiments.atlas_examples import run_optimize_example


def main(argv: Sequence[str] | None = None) -> int:
    return run_optimize_example("bottle", argv)


if __name__ == "__main__":
    sys.exit(main())
