"""Global grasp optimisation of the planar three-finger hand (atlas paper, Figs. 8-9).

An atlas of the relevant grasps (k = 2, r = 0.125, epsilon = 0.4 as in the paper), the three
manipulability indices at every chart centre, and the best and worst grasps of one of them
(``--index``, default the volume). Run `python examples/optimize_planar.py` to open the viewer,
or add `--html OUT` to write the scene.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from sahgrasp.experiments.atlas_examples import run_optimize_example


def main(argv: Sequence[str] | None = None) -> int:
    return run_optimize_example("planar", argv)


if __name__ == "__main__":
    sys.exit(main())
