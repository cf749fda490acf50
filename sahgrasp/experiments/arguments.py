"""Command-line options shared by the ``sahgrasp`` commands and the example scripts.

Imported to build parsers (``sahgrasp --help``), so it imports nothing heavy: the IK settings are
imported when :func:`ik_settings` first runs.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from sahgrasp.model.hands import DEFAULT_HAND, hand_help
from sahgrasp.quality.indices import QUALITY_INDICES

if TYPE_CHECKING:
    from sahgrasp.ik import IKSettings

__all__ = [
    "ATLAS_DEFAULTS",
    "HAND_HELP",
    "INDEX_CHOICES",
    "INITS_HELP",
    "MAX_INITS",
    "MESH_DEFAULTS",
    "METHOD_HELP",
    "PAPER_RADIUS_RANGE",
    "RADIUS_RANGES",
    "add_atlas_arguments",
    "add_html_argument",
    "add_ik_arguments",
    "atlas_geometry",
    "ik_settings",
    "int_at_least",
    "int_in_range",
    "nonnegative_int",
    "positive_float",
    "positive_int",
    "unit_interval_float",
]

MAX_INITS = 1000
"""Largest ``--inits`` accepted: the initial configurations are built before the first solve."""

HAND_HELP = hand_help()
"""The ``--hand`` help: the registered hands' names, or a description JSON."""
METHOD_HELP = "IK inner loop: the paper's (paper) or the Levenberg-Marquardt default (auto)"
INITS_HELP = f"i_max, initial configurations per problem (1..{MAX_INITS})"

ATLAS_DEFAULTS = {"planar": (0.125, 0.4), "can": (0.1, 0.5), "bottle": (0.1, 0.5)}
"""Per experiment: the chart radius ``r`` and ``epsilon`` used unless told otherwise (the one place
they are set). Planar: the atlas paper's values; SAH: ours, as ``x`` mixes radians and metres."""

RADIUS_RANGES = {"planar": (1e-3, 1.0), "can": (1e-3, 1.0), "bottle": (1e-3, 1.0)}
"""Per experiment: the chart radii ``--r`` accepts, in the units of ``x`` (the planar hand's unit
vectors and metres; the SAH's radians and metres). Below, an atlas needs millions of charts;
above, a chart spans the whole set of grasps and every step of the continuation fails."""

MESH_DEFAULTS = {"radius": 1.0, "epsilon": 0.5, "length_scale_m": 0.1, "unit_m": 0.003}
"""The mesh atlas's chart radius and epsilon (``sahgrasp atlas --mesh``), in scaled coordinates
whose unit moves a contact or the object by ``unit_m`` [m] and turns a joint by
``unit_m / length_scale_m`` [rad] (0.03 rad)."""

PAPER_RADIUS_RANGE = (0.1, 50.0)
"""The chart radii ``--r`` accepts with ``--paper`` for the SAH, in the paper's units (the paper:
r = 1; see :data:`sahgrasp.experiments.setups.PAPER_SETTINGS`)."""

INDEX_CHOICES = QUALITY_INDICES.names()
"""Names of the registered quality indices (a live view: numpy-free, as the registry is)."""


def _checked(kind: Callable[[str], Any], ok: Callable[[Any], bool], rule: str) -> Any:
    """An argparse ``type``: parse with ``kind``, then require ``ok`` (``rule`` says what is)."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {rule}") from None
        if not ok(value):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {rule}")
        return value

    parse.__name__ = rule  # argparse names the type in some messages
    return parse


def int_at_least(low: int) -> Any:
    """An argparse ``type`` accepting integers ``>= low``."""
    return _checked(int, lambda v: v >= low, f"an integer >= {low}")


def int_in_range(low: int, high: int) -> Any:
    """An argparse ``type`` accepting integers in ``low..high``."""
    return _checked(int, lambda v: low <= v <= high, f"an integer in {low}..{high}")


positive_int = int_at_least(1)
nonnegative_int = int_at_least(0)
positive_float = _checked(float, lambda v: math.isfinite(v) and v > 0.0, "a finite number > 0")
unit_interval_float = _checked(float, lambda v: 0.0 < v < 1.0, "a finite number > 0 and < 1")


def add_ik_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the IK options of the paper examples: ``--hand``, ``--method``, ``--inits``, ...

    :func:`ik_settings` turns them into the IK's settings.
    """
    parser.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    parser.add_argument("--method", choices=("auto", "paper"), default="auto", help=METHOD_HELP)
    parser.add_argument("--inits", type=int_in_range(1, MAX_INITS), default=12, help=INITS_HELP)
    parser.add_argument(
        "--iterations", type=positive_int, default=100, help="k_max, iterations per start"
    )


def ik_settings(args: argparse.Namespace) -> IKSettings:
    """The IK settings of :func:`add_ik_arguments`'s options."""
    from sahgrasp.ik import IKSettings

    # The paper's Algorithm 1: its starts come from the sequence of initial poses.
    return IKSettings(
        method=args.method, init="sequence", max_inits=args.inits, max_iterations=args.iterations
    )


def add_html_argument(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    """Add ``--html OUT``: write the scene there instead of opening the live viewer."""
    parser.add_argument(
        "--html",
        default=default,
        metavar="OUT",
        help="write the scene as a standalone HTML file"
        + (f" (default: {default})" if default else " instead of opening the viewer"),
    )


def _per_experiment(names: Sequence[str], i: int) -> str:
    return ", ".join(f"{name} {ATLAS_DEFAULTS[name][i]:g}" for name in names)


def add_atlas_arguments(
    parser: argparse.ArgumentParser, experiments: Sequence[str], workers: bool = True
) -> None:
    """Add ``--k``, ``--r``, ``--eps``, ``--index``, ``--max-charts``, ``--workers`` (validated).

    Args:
        parser: The parser.
        experiments: The experiments the parser runs (keys of :data:`ATLAS_DEFAULTS`). With one,
            ``--r`` and ``--eps`` default to its values; with several, to None, and the help lists
            each one's (:func:`atlas_geometry` resolves them).
        workers: Add ``--workers`` (not for the planar hand alone: it has no collision checks).
    """
    one = len(experiments) == 1
    radius, epsilon = ATLAS_DEFAULTS[experiments[0]] if one else (None, None)
    parser.add_argument(
        "--k", type=positive_int, default=2, help="dimension of the relevant-grasp set"
    )
    parser.add_argument(
        "--r",
        type=positive_float,
        default=radius,
        help="chart radius > 0" + ("" if one else f" (default: {_per_experiment(experiments, 0)})"),
    )
    parser.add_argument(
        "--eps",
        type=unit_interval_float,
        default=epsilon,
        help="epsilon in (0, 1) of Eqs. (17)-(18)"
        + ("" if one else f" (default: {_per_experiment(experiments, 1)})"),
    )
    parser.add_argument("--index", choices=INDEX_CHOICES, default="volume", help="quality index")
    parser.add_argument(
        "--max-charts", type=positive_int, default=20_000, help="stop the atlas at this many charts"
    )
    if workers:
        parser.add_argument(
            "--workers",
            type=int_at_least(0),
            default=0,
            help="processes checking the chart centres for collisions while the atlas is built "
            "(the SAH; 0: after the build, in this process; the same result)",
        )


def atlas_geometry(
    experiment: str, args: argparse.Namespace, defaults: tuple[float, float] | None = None
) -> tuple[float, float]:
    """Chart radius and epsilon of ``args``, ``defaults`` (the experiment's) where not given.

    Raises:
        argparse.ArgumentTypeError: ``--r`` is outside the experiment's range
            (:data:`RADIUS_RANGES`, or :data:`PAPER_RADIUS_RANGE` with a ``paper`` option set).
    """
    radius, epsilon = defaults or ATLAS_DEFAULTS[experiment]
    if args.r is not None:
        paper = bool(getattr(args, "paper", False)) and experiment != "planar"
        low, high = PAPER_RADIUS_RANGE if paper else RADIUS_RANGES[experiment]
        if not low <= args.r <= high:
            units = "the paper's units" if paper else "the units of x"
            raise argparse.ArgumentTypeError(
                f"--r {args.r:g} is out of range for {experiment}: valid {low:g}..{high:g} "
                f"({units}; smaller needs millions of charts, larger spans every grasp at once)"
            )
        radius = args.r
    return radius, epsilon if args.eps is None else args.eps
