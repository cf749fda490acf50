"""Global grasp optimization (the atlas paper, Algorithm 1) on any grasp manifold.

Rosales, Porta and Ros, "Global optimization of robotic grasps", Robotics: Science and Systems,
2011: ``GraspOptimization(F, X_h, x_1, Q, t, k, r, epsilon)`` builds an atlas of the relevant-grasp
set ``R`` (the feasible grasps F reduced by ``s = t - k`` principal-motion constraints, Eq. (11))
from a first grasp ``x_1`` and evaluates a quality index at every chart centre.

One protocol, :class:`GraspManifold`, says what the optimization needs of a problem: ``F`` and
``J`` of ``R``, its box bounds, the start point, the dimension ``k``, the manipulability ellipsoid
at chart centres and the collision checks of chart centres. The planar hand
(:class:`sahgrasp.optimization.planar.PlanarGraspProblem`) and the SAH grasp system with its
principal motions (:class:`sahgrasp.optimization.grasp.HandGraspManifold`) implement it;
:func:`optimize` runs Algorithm 1 on either and returns one :class:`OptimizationResult`.

Collisions (Section IV: "collisions could be considered as well ... returning the best collision
free grasp"): the problem checks every chart centre (:meth:`GraspManifold.check_charts`; the SAH
places its free fingers first). Colliding chart centres are no candidates: the optimum returned is
the best collision-free grasp, and the best over all charts is kept beside it. With
``OptimizationSettings.workers`` the checks run on worker processes while this process builds the
atlas, on the centres as they come.

This module knows no hand: it imports neither Pinocchio nor the IK.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas import Atlas, AtlasCheckpoint, AtlasSettings, build_atlas
from sahgrasp.core.errors import OptimizationError
from sahgrasp.core.parallel import check_workers, process_pool
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.quality.ellipsoids import (
    QUALITY_INDICES,
    IndexEvaluation,
    Manipulability,
    evaluate_index,
)

__all__ = [
    "ChartChecks",
    "ComponentSearch",
    "GraspManifold",
    "IndexFunction",
    "OptimizationResult",
    "OptimizationSettings",
    "optimize",
    "optimize_components",
]

FloatArray = NDArray[np.float64]

IndexFunction = Callable[[FloatArray], ArrayLike]
"""A user quality index: chart centres (N, n) -> N values, larger is better (NaN: undefined).

The centres are in the problem's coordinates (a scaled
:class:`~sahgrasp.optimization.grasp.HandGraspManifold` maps them back with ``x_of``)."""


@dataclass(frozen=True)
class ChartChecks:
    """Per chart centre: the configuration to show (free fingers placed) and its collisions.

    Attributes:
        configurations: The problem's configuration at each centre, (N, ...) (the SAH: the hand
            configuration with the palm at the origin; the planar hand: the centre itself).
        self_collision: Centres where the hand collides with itself, (N,).
        object_collision: Centres where a link is inside the object, (N,).
    """

    configurations: FloatArray
    self_collision: NDArray[np.bool_]
    object_collision: NDArray[np.bool_]

    @classmethod
    def none(cls, centres: FloatArray) -> ChartChecks:
        """No collision anywhere; the centres are the configurations."""
        clear = np.zeros(len(centres), dtype=bool)
        return cls(centres, clear, clear.copy())

    @classmethod
    def joined(cls, parts: Sequence[ChartChecks]) -> ChartChecks:
        """The checks of consecutive runs of centres, in their order."""
        return cls(
            np.concatenate([p.configurations for p in parts]),
            np.concatenate([p.self_collision for p in parts]),
            np.concatenate([p.object_collision for p in parts]),
        )


class GraspManifold(Protocol):
    """What Algorithm 1 needs of a grasp problem: the relevant-grasp set ``R`` (Eq. (11)).

    ``F``, ``J`` and :meth:`manipulability` take one point (n,) or, where the problem allows it,
    a batch (..., n). A problem whose ``F`` and ``J`` take a stack of points (B, n) says so with
    an optional attribute ``stacked = True`` (the planar hand does): the atlas's waves then call
    them once per Newton iteration for all their points (``build_atlas(..., stacked=True)``).
    """

    @property
    def dimension(self) -> int:
        """``k``, the dimension of R (Eq. (12))."""
        ...

    @property
    def t(self) -> int:
        """Dimension of the feasible-grasp manifold F (``s = t - k`` motion constraints)."""
        ...

    @property
    def start(self) -> FloatArray:
        """The first grasp ``x_1`` on R, (n,), inside the bounds."""
        ...

    def F(self, x: FloatArray) -> FloatArray:
        """``R(x)``: the grasp equations plus the principal-motion constraints, (m,)."""
        ...

    def J(self, x: FloatArray) -> FloatArray:
        """Jacobian of :meth:`F`, (m, n)."""
        ...

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper box bounds on ``x`` (joint limits, contact regions), (n,) each."""
        ...

    def manipulability(self, x: FloatArray) -> Manipulability:
        """Manipulability ellipsoids at the grasps ``x`` (..., n)."""
        ...

    def check_charts(self, centres: FloatArray, executor: Executor | None = None) -> ChartChecks:
        """Configurations and collisions at the chart centres (N, n), on ``executor`` if given."""
        ...


@dataclass(frozen=True)
class OptimizationSettings:
    """Settings of :func:`optimize`.

    Attributes:
        radius: Chart radius ``r`` (in the units of ``x``).
        epsilon: Threshold of Eqs. (17)-(18).
        index: Manipulability index to maximise
            (:data:`~sahgrasp.quality.ellipsoids.QUALITY_INDICES`); ignored when ``index_fn`` is
            given.
        index_fn: A user quality index instead of ``index`` (see :data:`IndexFunction`).
        max_charts: Cap on the atlas size (``result.atlas.stop_reason`` says if it was hit).
        progress: Hears of every new chart (:class:`~sahgrasp.core.progress.ProgressCallback`).
        workers: Processes that check the chart centres for collisions while the atlas is
            built (0: this process checks them after the build). The result is the same for any
            number.

    Raises:
        OptimizationError: ``index`` is unknown and no ``index_fn`` is given.
        InvalidSettingsError: ``workers`` is not an integer in 0 .. 4 per core.
    """

    radius: float
    epsilon: float
    index: str = "volume"
    index_fn: IndexFunction | None = None
    max_charts: int = 20_000
    progress: ProgressCallback | None = None
    workers: int = 0

    def __post_init__(self) -> None:
        if self.workers != 0 or isinstance(self.workers, bool):
            check_workers(self.workers)
        if self.index_fn is None and self.index not in QUALITY_INDICES:
            raise OptimizationError(
                f"unknown index {self.index!r}; valid: {', '.join(QUALITY_INDICES)} or an index_fn"
            )

    @property
    def index_name(self) -> str:
        """The index's name: ``"user"`` for an ``index_fn``."""
        return "user" if self.index_fn is not None else self.index

    def atlas_settings(self) -> AtlasSettings:
        """The atlas settings (start tolerance 1e-4: the IK's first grasp is that accurate)."""
        return AtlasSettings(
            radius=self.radius, epsilon=self.epsilon, max_charts=self.max_charts, start_tol=1e-4
        )


@dataclass(frozen=True)
class OptimizationResult:
    """Outcome of :func:`optimize`.

    Attributes:
        problem: The grasp manifold.
        atlas: The atlas of R.
        settings: The settings.
        all_values: Index per chart, colliding charts included (NaN: undefined).
        valid: Chart centres without collision (self and hand-object).
        best: Chart with the largest index among valid ones.
        worst: Chart with the smallest index among valid ones.
        best_overall: Chart with the largest index over all charts (``best`` if that is valid).
        checks: Configurations (free fingers placed) and collisions per chart.
        quality: Manipulability ellipsoid per chart (None with a user ``index_fn``).
        quality_seconds: Index evaluation time, with the collision checks [s].
    """

    problem: GraspManifold
    atlas: Atlas
    settings: OptimizationSettings
    all_values: FloatArray
    valid: NDArray[np.bool_]
    best: int
    worst: int
    best_overall: int
    checks: ChartChecks
    quality: Manipulability | None
    quality_seconds: float

    @property
    def index(self) -> str:
        """Name of the quality index (``"user"`` for a user ``index_fn``)."""
        return self.settings.index_name

    @property
    def values(self) -> FloatArray:
        """Index per chart, NaN where the chart centre collides."""
        return np.where(self.valid, self.all_values, np.nan)

    @property
    def atlas_seconds(self) -> float:
        """Atlas build time [s]."""
        return self.atlas.build_seconds

    @property
    def configurations(self) -> FloatArray:
        """Configuration per chart, free fingers placed."""
        return self.checks.configurations

    def ranked_by(self, index: str) -> IndexEvaluation:
        """Values, best and worst valid charts by a built-in index of the same ellipsoids.

        Raises:
            OptimizationError: A user ``index_fn`` was optimised (no ellipsoids).
            QualityError: ``index`` is unknown.
        """
        return evaluate_index(self.atlas, _ellipsoid_index(self.quality, index), True, self.valid)


def _ellipsoid_index(quality: Manipulability | None, index: str) -> IndexFunction:
    """The values of built-in ``index`` of the ellipsoids already computed, as an index function.

    Raises:
        OptimizationError: No ellipsoids (a user ``index_fn`` was optimised).
    """
    if quality is None:
        raise OptimizationError("a user index_fn was optimised: no ellipsoids to rank by")
    values = quality.index(index)
    return lambda _centres: values


def optimize(
    problem: GraspManifold,
    settings: OptimizationSettings,
    start: ArrayLike | None = None,
    checkpoint: AtlasCheckpoint | None = None,
) -> OptimizationResult:
    """Algorithm 1: atlas of R from ``problem.start``, then the index at every chart centre.

    Args:
        problem: The grasp manifold.
        settings: Chart radius, epsilon, index, cap, progress.
        start: A point of R to start from instead of ``problem.start`` (n,): the atlas covers
            the connected component of R holding it.
        checkpoint: Save the atlas build's state there and resume from it
            (:func:`sahgrasp.atlas.build_atlas`); the checks and the index run after the build.

    Raises:
        AtlasError: The atlas settings are out of range, or the start is not on R.
        OptimizationError: No chart centre is collision-free.
        QualityError: A user ``index_fn`` gives the wrong number of values or only NaN.
    """
    lower, upper = problem.bounds()
    x0 = problem.start if start is None else np.asarray(start, dtype=np.float64)
    with _background_checks(problem, x0, settings.workers) as background:
        atlas = build_atlas(
            problem.F, problem.J, x0, problem.dimension, settings.atlas_settings(),
            lower, upper, settings.progress, stacked=bool(getattr(problem, "stacked", False)),
            new_charts=None if background is None else background.add, checkpoint=checkpoint,
        )  # fmt: skip
        if background is None:
            return _evaluate(problem, atlas, settings, lambda: problem.check_charts(atlas.centres))
        return _evaluate(problem, atlas, settings, lambda: background.result(atlas))


_CHECK_BATCH = 256
"""New chart centres handed to the workers at a time while the atlas grows."""


class _BackgroundChecks:
    """The chart centres checked on worker processes while the atlas grows.

    The atlas builder hands over every new centre (:meth:`add`); batches of :data:`_CHECK_BATCH`
    go to a thread that has the workers check them, and waits for them with the GIL released,
    so that the checks overlap the build. Before the first batch, each worker checks the first
    grasp and keeps the hand and the object's collision pieces it built (about 2 s), also while
    the atlas grows.
    """

    def __init__(self, problem: GraspManifold, pool: Executor, x0: FloatArray, workers: int):
        self.problem, self.pool = problem, pool
        self.centres: list[FloatArray] = []
        self._batch: list[FloatArray] = []
        self._queue: queue.SimpleQueue[FloatArray | None] = queue.SimpleQueue()
        self._parts: list[ChartChecks] = []
        self._error: BaseException | None = None
        warm_up = np.repeat(x0[None], workers, axis=0)
        self._thread = threading.Thread(target=self._check, args=(warm_up,), daemon=True)
        self._thread.start()

    def add(self, centres: FloatArray) -> None:
        """Queue new chart centres (B, n) for checking."""
        self.centres.append(centres)
        self._batch.append(centres)
        if sum(len(c) for c in self._batch) >= _CHECK_BATCH:
            self._queue.put(np.concatenate(self._batch))
            self._batch = []

    def stop(self) -> None:
        """Send what is left and let the thread end after it."""
        if self._batch:
            self._queue.put(np.concatenate(self._batch))
            self._batch = []
        self._queue.put(None)

    def result(self, atlas: Atlas) -> ChartChecks:
        """The checks of every centre of ``atlas``, in its order (waits for the last ones)."""
        self.stop()
        self._thread.join()
        if self._error is not None:
            raise self._error
        if not np.array_equal(np.concatenate(self.centres), atlas.centres):
            return self.problem.check_charts(atlas.centres, self.pool)  # not the builder's order
        return ChartChecks.joined(self._parts)

    def _check(self, warm_up: FloatArray) -> None:
        with suppress(Exception):  # a failing check fails again below, and is raised then
            self.problem.check_charts(warm_up, self.pool)
        while (centres := self._queue.get()) is not None:
            if self._error is None:
                try:
                    self._parts.append(self.problem.check_charts(centres, self.pool))
                except BaseException as exc:  # raised in result()
                    self._error = exc


@contextmanager
def _background_checks(
    problem: GraspManifold, x0: FloatArray, workers: int
) -> Iterator[_BackgroundChecks | None]:
    """Checks on ``workers`` processes during the build (None: none, checks after the build)."""
    if workers == 0:
        yield None
        return
    with process_pool(workers) as pool:
        background = _BackgroundChecks(problem, pool, x0, workers)
        try:
            yield background
        finally:
            background.stop()


def _evaluate(
    problem: GraspManifold,
    atlas: Atlas,
    settings: OptimizationSettings,
    check: Callable[[], ChartChecks],
) -> OptimizationResult:
    """Lines 14-21 of Algorithm 1: checks, then the index at every centre, best and worst."""
    begin = time.perf_counter()
    checks = check()
    valid = ~(checks.self_collision | checks.object_collision)
    if not valid.any():
        raise OptimizationError(
            f"no chart centre is a collision-free grasp ({int(checks.self_collision.sum())} of "
            f"{atlas.n_charts} self-colliding, {int(checks.object_collision.sum())} inside the "
            "object)"
        )
    quality = None if settings.index_fn else problem.manipulability(atlas.centres)
    index_fn = settings.index_fn or _ellipsoid_index(quality, settings.index)
    evaluation = evaluate_index(atlas, index_fn, candidates=valid)
    return OptimizationResult(
        problem, atlas, settings, evaluation.values, valid, evaluation.best, evaluation.worst,
        evaluation.best_overall, checks, quality, time.perf_counter() - begin,
    )  # fmt: skip


@dataclass(frozen=True)
class ComponentSearch:
    """Algorithm 1 run once per connected component of R met by a set of seed grasps.

    Attributes:
        components: One optimization per component, in the order their first seed came.
        seed_components: Per seed, the component it fell in; None when it could not be brought
            onto R inside the bounds.
    """

    components: tuple[OptimizationResult, ...]
    seed_components: tuple[int | None, ...]

    @property
    def best(self) -> tuple[int, int]:
        """Component and chart of the best valid grasp over every component."""
        values = [result.all_values[result.best] for result in self.components]
        component = int(np.argmax(values))
        return component, self.components[component].best


def optimize_components(
    problem: GraspManifold, settings: OptimizationSettings, seeds: ArrayLike
) -> ComponentSearch:
    """Seed Algorithm 1 from several grasps; one atlas per connected component of R they reach.

    Each seed is moved onto R (Newton's method, minimum-norm steps); a seed within one chart
    radius of a chart centre of an atlas already built lies in that atlas's component (components
    closer than ``r`` to each other count as one), any other starts a new atlas.

    Args:
        problem: The grasp manifold.
        settings: As for :func:`optimize`.
        seeds: Grasps near R, (S, n), e.g. IK solutions of the same contacts from other starts.

    Raises:
        OptimizationError: ``seeds`` is not (S, n), or no seed reaches R inside the bounds.
    """
    X = np.asarray(seeds, dtype=np.float64)
    n = problem.start.size
    if X.ndim != 2 or X.shape[1] != n or not len(X):
        raise OptimizationError(f"seeds must be an (S, {n}) array with S >= 1, got {X.shape}")
    components: list[OptimizationResult] = []
    owners: list[int | None] = []
    for seed in X:
        x = _onto(problem, seed)
        owner = None if x is None else _component_of(components, x)
        if x is not None and owner is None:
            components.append(optimize(problem, settings, start=x))
            owner = len(components) - 1
        owners.append(owner)
    if not components:
        raise OptimizationError(f"none of the {len(X)} seeds could be brought onto R in bounds")
    return ComponentSearch(tuple(components), tuple(owners))


def _onto(problem: GraspManifold, x: FloatArray, tol: float = 1e-10) -> FloatArray | None:
    """``x`` moved onto ``F = 0`` by minimum-norm Newton steps; None on failure or out of bounds."""
    lower, upper = problem.bounds()
    for _ in range(30):
        residual = problem.F(x)
        if np.linalg.norm(residual) <= tol:
            return x if np.all((x >= lower) & (x <= upper)) else None
        x = x - np.linalg.lstsq(problem.J(x), residual, rcond=None)[0]
    return None


def _component_of(components: list[OptimizationResult], x: FloatArray) -> int | None:
    """The first component whose atlas has a chart centre within one radius of ``x``."""
    for i, result in enumerate(components):
        atlas = result.atlas
        if np.min(np.linalg.norm(atlas.centres - x, axis=1)) <= atlas.radius:
            return i
    return None
