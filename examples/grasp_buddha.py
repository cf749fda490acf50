"""IK of the paper's buddha grasp with the SAH (Claret & Suárez, Section 4.1, Fig. 7b).

Paper: 3 initial configurations, 25 Jacobian iterations.

Run `python examples/grasp_buddha.py` to open the viewer, or add `--html OUT` to write
the scene to a standalone HTML file.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from sahgrasp.experiments.ik_examples import run_grasp_example


def main(argv: Sequence[str] | None = None) -> int:
    return run_grasp_example("buddha", argv)


if __name__ == "__main__":
    sys.exit(main())
