"""The atlas paper's experiments as grasp manifolds: the planar hand, the SAH with a can, a bottle.

Rosales, Porta and Ros, "Global optimization of robotic grasps", RSS 2011, Section V: the planar
three-finger hand (Figs. 8-9), the SAH holding a can (Fig. 10a) and an oil bottle (Fig. 10b).
:func:`make_experiment` builds the problem, :func:`run_experiment` runs Algorithm 1 on it
(:func:`sahgrasp.optimization.optimizer.optimize`), with the experiment's default chart radius and
epsilon (:data:`sahgrasp.experiments.arguments.ATLAS_DEFAULTS`) unless told otherwise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from sahgrasp.atlas import AtlasCheckpoint
from sahgrasp.core.errors import OptimizationError
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.experiments.arguments import ATLAS_DEFAULTS
from sahgrasp.model.hand import load_hand
from sahgrasp.model.hands import DEFAULT_HAND
from sahgrasp.objects import GraspObject, GraspPatches, bottle_patches, can_patches, load_object
from sahgrasp.optimization.grasp import HandGraspManifold, ik_seeds, make_sah_manifold
from sahgrasp.optimization.optimizer import (
    ComponentSearch,
    GraspManifold,
    OptimizationResult,
    OptimizationSettings,
    optimize,
    optimize_components,
)
from sahgrasp.optimization.planar import make_planar_problem

__all__ = [
    "EXPERIMENTS",
    "PAPER_SETTINGS",
    "SAH_EXPERIMENTS",
    "PaperSettings",
    "SahExperiment",
    "experiment_settings",
    "make_experiment",
    "run_components",
    "run_experiment",
]


@dataclass(frozen=True)
class SahExperiment:
    """One of the atlas paper's SAH experiments (Section V).

    Attributes:
        patches: Builds the object's contact regions.
        object: Builds the object, in the regions' frame.
        free_object: Whether the object pose varies.
        symmetry_axis: Axis of revolution shared by every contact region (object frame), if any.
    """

    patches: Callable[[], GraspPatches]
    object: Callable[[], GraspObject]
    free_object: bool = True
    symmetry_axis: tuple[float, float, float] | None = None


SAH_EXPERIMENTS = {
    # The thumb's fixed point breaks the can's symmetry.
    "can": SahExperiment(can_patches, lambda: load_object("can")),
    "bottle": SahExperiment(
        bottle_patches, lambda: load_object("bottle"), symmetry_axis=(0.0, 0.0, 1.0)
    ),
}
"""The SAH + can (Fig. 10a) and SAH + oil bottle (Fig. 10b) experiments, by name."""

EXPERIMENTS = ("planar", *SAH_EXPERIMENTS)
"""Every experiment's name."""


@dataclass(frozen=True)
class PaperSettings:
    """The atlas paper's settings of one experiment, in the coordinates that reproduce it.

    Attributes:
        radius: The paper's chart radius r.
        epsilon: The paper's epsilon.
        length_scale_m: The length [m] a joint angle is compared with (about a finger's), or
            None: the experiment's own coordinates (the planar hand is the paper's formulation).
        unit_m: What a unit of the scaled coordinates moves [m]: a joint turns by
            ``unit_m / length_scale_m`` rad, the object and the contacts move by ``unit_m``.
    """

    radius: float
    epsilon: float
    length_scale_m: float | None = None
    unit_m: float | None = None


PAPER_SETTINGS: dict[tuple[str, int], PaperSettings] = {
    ("planar", 2): PaperSettings(0.125, 0.4),
    ("can", 2): PaperSettings(1.0, 0.5, 0.1, 0.0015),
    ("bottle", 2): PaperSettings(1.0, 0.5, 0.1, 0.00088),
    ("bottle", 3): PaperSettings(1.0, 0.5, 0.1, 0.00101),
}
"""Per (experiment, k), the paper's r and epsilon (Section V) and the unit in which they apply.

The paper states no unit for the SAH's r = 1. Our F differs from the paper's (t = 11 against 8 for
the can: rolling fingertips, the coupled distal joints, a free object), so no unit makes the two
atlases the same set; the unit here is the one at which our atlas has the paper's number of
charts, about 1 mm of contact or object motion (1.5 mm can, 0.88 mm bottle, 1.01 mm bottle with
k = 3), i.e. r = 1 in millimetres. docs/methods/atlas.md, "The paper's sizes", explains."""

_MOTION_SAMPLES = {"random": 2000, "grasps": 200}
"""Configurations sampled for the principal motions per source (an IK solve each for grasps)."""


def make_experiment(
    name: str,
    k: int = 2,
    hand: str = DEFAULT_HAND,
    motions: str = "random",
    length_scale_m: float | None = None,
    unit_m: float | None = None,
) -> GraspManifold:
    """The grasp manifold of experiment ``name`` with ``k`` kept dimensions.

    The SAH experiments check their chart centres against the object.

    Args:
        name: One of :data:`EXPERIMENTS`.
        k: Dimension of the relevant-grasp set R.
        hand: The hand of the SAH experiments (a name or a hand-description JSON).
        motions: Source of the SAH's principal motions, one of
            :data:`~sahgrasp.optimization.grasp.MOTION_SOURCES` (``"grasps"``: 200 solved grasps).
        length_scale_m: Scale the SAH's coordinates at this length
            (:func:`sahgrasp.optimization.grasp.coordinate_scales`); None: unscaled.
        unit_m: What a unit of the scaled coordinates moves [m] (default ``length_scale_m``).

    Raises:
        OptimizationError: ``name`` is unknown, or the IK finds no first grasp.
        GraspSystemError: ``k`` is out of range.
    """
    if name == "planar":
        return make_planar_problem(k)
    if name not in SAH_EXPERIMENTS:
        raise OptimizationError(f"unknown experiment {name!r}; valid: {', '.join(EXPERIMENTS)}")
    setup = SAH_EXPERIMENTS[name]
    samples = _MOTION_SAMPLES.get(motions, 0)
    return make_sah_manifold(
        load_hand(hand), setup.patches(), k, setup.free_object, setup.symmetry_axis,
        setup.object(), samples, motion_source=motions, length_scale_m=length_scale_m,
        unit_m=unit_m,
    )  # fmt: skip


def experiment_settings(
    name: str,
    radius: float | None = None,
    epsilon: float | None = None,
    index: str = "volume",
    max_charts: int = 20_000,
    progress: ProgressCallback | None = None,
    workers: int = 0,
) -> OptimizationSettings:
    """The optimization settings of experiment ``name``: its radius and epsilon where None.

    Raises:
        OptimizationError: ``name`` or ``index`` is unknown.
        InvalidSettingsError: ``workers`` is not an integer in 0 .. 4 per core.
    """
    if name not in ATLAS_DEFAULTS:
        raise OptimizationError(f"unknown experiment {name!r}; valid: {', '.join(EXPERIMENTS)}")
    default_radius, default_epsilon = ATLAS_DEFAULTS[name]
    return OptimizationSettings(
        radius=default_radius if radius is None else radius,
        epsilon=default_epsilon if epsilon is None else epsilon,
        index=index,
        max_charts=max_charts,
        progress=progress,
        workers=workers,
    )


def run_experiment(
    name: str,
    k: int = 2,
    radius: float | None = None,
    epsilon: float | None = None,
    index: str = "volume",
    max_charts: int = 20_000,
    progress: ProgressCallback | None = None,
    hand: str = DEFAULT_HAND,
    motions: str = "random",
    length_scale_m: float | None = None,
    workers: int = 0,
    unit_m: float | None = None,
    checkpoint: AtlasCheckpoint | None = None,
) -> OptimizationResult:
    """Algorithm 1 on experiment ``name``.

    The arguments are those of :func:`make_experiment` and :func:`experiment_settings`;
    ``checkpoint`` saves (and resumes) the atlas build (:func:`sahgrasp.atlas.build_atlas`).
    """
    settings = experiment_settings(name, radius, epsilon, index, max_charts, progress, workers)
    problem = make_experiment(name, k, hand, motions, length_scale_m, unit_m)
    return optimize(problem, settings, checkpoint=checkpoint)


def run_components(
    name: str,
    seeds: int = 8,
    k: int = 2,
    radius: float | None = None,
    epsilon: float | None = None,
    index: str = "volume",
    max_charts: int = 20_000,
    motions: str = "random",
) -> ComponentSearch:
    """Algorithm 1 on every connected component of an SAH experiment's R met by IK seeds.

    The seeds are the first grasp and the IK's solutions of the same contacts from ``seeds``
    random starts (:func:`sahgrasp.optimization.grasp.ik_seeds`); other arguments as
    :func:`run_experiment`.

    Raises:
        OptimizationError: ``name`` is not an SAH experiment, or no seed reaches R.
    """
    problem = make_experiment(name, k, motions=motions)
    if not isinstance(problem, HandGraspManifold):
        raise OptimizationError(
            f"components are searched for {sorted(SAH_EXPERIMENTS)}, not {name!r}"
        )
    settings = experiment_settings(name, radius, epsilon, index, max_charts)
    return optimize_components(problem, settings, ik_seeds(problem, seeds))
