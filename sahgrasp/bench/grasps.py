"""``sahgrasp bench grasps``: the IK on contact sets a grasp planner draws on the catalog objects.

For each object, :func:`sahgrasp.objects.grasp_sampler.sample_object_grasps` draws four-finger
contact sets (seeded per object from the benchmark seed and the object's name) and the IK solves
each with its default settings. Every claimed solution is then re-checked independently of the
solver: the plain URDF hand (a fresh Pinocchio model without the solver's virtual contact joints,
mimic joints set from :meth:`Hand.joint_values`) is placed by forward kinematics, and coal
measures how deep each link's collision shape enters each convex collision piece of the object.
A solution penetrates the object when a link other than the four contact fingertips is deeper
than :data:`PENETRATION_TOLERANCE_M`.
"""

from __future__ import annotations

import sys
import time
import zlib
from collections import Counter
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from tqdm import tqdm

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.fileio import write_json_atomic
from sahgrasp.core.frames import transform_points
from sahgrasp.ik import IKResult, IKSettings, default_sequence, solve_ik, worker_hand
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, HandDescription, load_hand
from sahgrasp.model.hands import DEFAULT_HAND
from sahgrasp.objects import OBJECT_NAMES, GraspObject, load_object
from sahgrasp.objects.grasp_sampler import sample_object_grasps
from sahgrasp.objects.mesh_file import load_mesh
from sahgrasp.objects.reach import sampler_reach
from sahgrasp.objects.targets import save_targets

__all__ = [
    "BENCH_SEED",
    "PENETRATION_TOLERANCE_M",
    "RUNS",
    "ObjectPenetration",
    "Timed",
    "format_table",
    "run",
]

BENCH_SEED = 7_305_411
"""Default seed of the benchmark's contact sets (used nowhere else in the project)."""
PENETRATION_TOLERANCE_M = 2e-4
"""A link deeper than this in the object [m] makes a claimed solution penetrate."""
_CHUNK = 10
"""Problems per task sent to a worker process."""


class ObjectPenetration:
    """Penetration depths of the plain URDF hand's links into an object's convex pieces.

    Args:
        hand: The hand the solver used (its URDF and joint names; nothing else is reused).
        obj: The object, placed in the world.
    """

    def __init__(self, hand: Hand, obj: GraspObject) -> None:
        urdf = str(hand.description.urdf_path)
        dirs = [str(p) for p in hand.description.package_dirs]
        self.hand = hand
        self.model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
        self.geometry = pin.buildGeomFromUrdf(
            self.model, urdf, pin.GeometryType.COLLISION, None, dirs
        )
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        objects = self.geometry.geometryObjects
        self.links = [str(self.model.frames[g.parentFrame].name) for g in objects]
        for g in objects:
            g.geometry.computeLocalAABB()
        self._link_centres = np.array([np.asarray(g.geometry.aabb_center) for g in objects])
        self._link_radii = np.array([g.geometry.aabb_radius for g in objects])
        self.pieces = obj.collision_shapes()
        self._piece_transforms = [s.transform(obj.T_world_object) for s in self.pieces]
        centres = np.array([s.placement[:3, 3] for s in self.pieces])
        self._piece_centres = transform_points(obj.T_world_object, centres)
        self._piece_radii = np.array([s.bounding_radius_m for s in self.pieces])

    def plain_configuration(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The plain URDF model's configuration for the solver's ``q`` (same wrist, same joints)."""
        plain = pin.neutral(self.model)
        self.hand.wrist_part(plain)[:] = self.hand.wrist_part(q)
        for name, value in self.hand.joint_values(q).items():
            plain[self.model.joints[self.model.getJointId(name)].idx_q] = value
        return plain

    def depths(self, q: NDArray[np.float64]) -> dict[str, float]:
        """Deepest penetration [m] of each link that enters the object at the solver's ``q``.

        A link's depth is its largest penetration into any one convex piece (a lower bound of
        its depth in the union of the pieces).
        """
        pin.updateGeometryPlacements(
            self.model, self.data, self.geometry, self.geometry_data, self.plain_configuration(q)
        )
        out: dict[str, float] = {}
        request = coal.DistanceRequest()
        for k, (g, oMg) in enumerate(
            zip(self.geometry.geometryObjects, self.geometry_data.oMg, strict=True)
        ):
            centre = oMg.act(self._link_centres[k])
            gaps = np.linalg.norm(self._piece_centres - centre, axis=1)
            near = np.flatnonzero(gaps < self._piece_radii + self._link_radii[k])
            placed = coal.Transform3s(oMg.rotation, oMg.translation)
            for i in near:
                distance = coal.distance(
                    g.geometry, placed, self.pieces[i].geometry, self._piece_transforms[i],
                    request, coal.DistanceResult(),
                )  # fmt: skip
                if distance < 0.0:
                    out[self.links[k]] = max(out.get(self.links[k], 0.0), -distance)
        return out


def _object_seed(seed: int, name: str) -> int:
    """The contact-set seed of object ``name``: independent of which other objects run."""
    return int(np.random.SeedSequence([seed, zlib.crc32(name.encode())]).generate_state(1)[0])


RUNS = ("without_object", "with_object")
"""The IK runs per contact set: contacts only, and with ``obstacle=`` the object."""


@dataclass(frozen=True)
class Timed:
    """One IK solve of the benchmark and the CPU time it took.

    Attributes:
        result: The solver's result (its ``time_s`` is wall time).
        cpu_s: CPU time [s] of the process over the ``solve_ik`` call: on a shared machine,
            less affected by other jobs than wall time.
    """

    result: IKResult
    cpu_s: float


def _timed_solve(hand: Hand, target: GraspTarget, obj: GraspObject | None) -> Timed:
    start = time.process_time()
    result = solve_ik(hand, target, IKSettings(), obstacle=obj)
    return Timed(result, time.process_time() - start)


def _solve_chunk(
    hand: Hand, targets: list[GraspTarget], obj: GraspObject | None
) -> list[tuple[Timed, ...]]:
    """Solve each target without the object, then (if ``obj``) with it, one after the other.

    Solving each problem in both runs back to back lets a change of machine load affect both
    alike. The object's collision pieces and their tree are built once per object instance
    (:func:`_prepare`), before any timed solve.
    """
    return [
        (_timed_solve(hand, t, None),) + (() if obj is None else (_timed_solve(hand, t, obj),))
        for t in targets
    ]


def _prepare(hand: Hand, obj: GraspObject) -> None:
    """Build what the IK keeps per (hand, object) -- pieces, their tree -- outside the timing."""
    from sahgrasp.ik.obstacle import Obstacle

    Obstacle(hand, obj, (), 0.0)


_POOL_OBJECTS: dict[str, GraspObject] = {}
"""In a worker process: the object its pool serves (a pool serves one object), by name."""


def _pool_task(
    description: HandDescription,
    digest: str,
    targets: list[GraspTarget],
    obj: GraspObject | None,
) -> list[tuple[Timed, ...]]:
    """:func:`_solve_chunk` in a worker, on one unpickled instance of the object per process."""
    hand = worker_hand(description, digest)
    if obj is not None:
        if obj.name not in _POOL_OBJECTS:
            _prepare(hand, obj)
        obj = _POOL_OBJECTS.setdefault(obj.name, obj)
    return _solve_chunk(hand, targets, obj)


def _solve(
    hand: Hand, targets: list[GraspTarget], obj: GraspObject | None, workers: int, bar: tqdm[Any]
) -> list[tuple[Timed, ...]]:
    results: list[tuple[Timed, ...]] = []
    if workers <= 1:
        if obj is not None:
            _prepare(hand, obj)
        for target in targets:
            results += _solve_chunk(hand, [target], obj)
            bar.update()
        return results
    description, digest = hand.description, hand.description.digest()
    chunks = [targets[i : i + _CHUNK] for i in range(0, len(targets), _CHUNK)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(_pool_task, description, digest, c, obj) for c in chunks]
        for future, chunk in zip(futures, chunks, strict=True):
            results += future.result()
            bar.update(len(chunk))
    return results


def _penetration_summary(
    hand: Hand, obj: GraspObject, results: Sequence[IKResult], bar: tqdm[Any]
) -> dict[str, Any]:
    """Re-check every claimed solution against the object (module docstring)."""
    check = ObjectPenetration(hand, obj)
    tips = {f.tip_link for f in hand.description.fingers}
    worst_links: Counter[str] = Counter()
    link_depths, tip_depths = [], []
    for r in results:
        bar.update()
        if not r.success:
            continue
        depths = check.depths(r.q)
        others = {k: v for k, v in depths.items() if k not in tips}
        link_depths.append(max(others.values(), default=0.0))
        tip_depths.append(max((v for k, v in depths.items() if k in tips), default=0.0))
        if link_depths[-1] > PENETRATION_TOLERANCE_M:
            worst_links[max(others, key=others.__getitem__)] += 1
    deep = np.array(link_depths)[np.array(link_depths) > PENETRATION_TOLERANCE_M]
    return {
        "claimed": len(link_depths),
        "penetrating": len(deep),
        "penetrating_rate": len(deep) / len(link_depths) if link_depths else 0.0,
        "usable_rate": (len(link_depths) - len(deep)) / len(results),
        "median_penetrating_depth_mm": 1e3 * float(np.median(deep)) if len(deep) else 0.0,
        "max_link_depth_mm": 1e3 * max(link_depths, default=0.0),
        "max_fingertip_depth_mm": 1e3 * max(tip_depths, default=0.0),
        "deepest_links": dict(worst_links.most_common()),
    }


def _summary(timed: Sequence[Timed]) -> dict[str, Any]:
    results = [t.result for t in timed]
    times_ms = np.array([r.time_s for r in results]) * 1e3
    cpu_ms = np.array([t.cpu_s for t in timed]) * 1e3
    starts = np.array([r.inits_used for r in results])
    solved = np.array([r.success for r in results])
    return {
        "problems": len(results),
        "solved": int(solved.sum()),
        "success_rate": float(solved.mean()),
        "first_start_success_rate": float(np.mean(solved & (starts == 1))),
        "mean_starts": float(starts.mean()),
        "mean_starts_solved": float(starts[solved].mean()) if solved.any() else None,
        "median_time_ms": float(np.median(times_ms)),
        "mean_time_ms": float(times_ms.mean()),
        "p95_time_ms": float(np.percentile(times_ms, 95)),
        "median_cpu_ms": float(np.median(cpu_ms)),
        "mean_cpu_ms": float(cpu_ms.mean()),
        "mean_iterations": float(np.mean([r.iterations for r in results])),
        "reasons": dict(Counter(r.reason for r in results)),
    }


def _bench_object(
    hand: Hand,
    obj: GraspObject,
    count: int,
    seed: int,
    workers: int,
    progress: bool,
    with_object: bool,
) -> tuple[dict[str, Any], list[GraspTarget]]:
    object_seed = _object_seed(seed, obj.name)
    with tqdm(total=count, unit="set", disable=not progress, file=sys.stderr) as bar:
        bar.set_description(f"bench grasps {obj.name}: sample")
        start = time.perf_counter()
        targets = sample_object_grasps(
            obj, count, object_seed, sampler_reach(hand), on_set=bar.update
        )
        sampling_s = time.perf_counter() - start
        bar.reset()
        bar.set_description(f"bench grasps {obj.name}: solve")
        solved = _solve(hand, targets, obj if with_object else None, workers, bar)
        results = list(zip(*solved, strict=True))
        bar.reset(total=count * len(results))
        bar.set_description(f"bench grasps {obj.name}: check")
        runs = {}
        for label, run_results in zip(RUNS, results, strict=False):
            runs[label] = _summary(run_results)
            claimed = [t.result for t in run_results]
            runs[label]["penetration"] = _penetration_summary(hand, obj, claimed, bar)
    row: dict[str, Any] = {
        "object": obj.name,
        "contact_set_seed": object_seed,
        "sampling_s": sampling_s,
        "runs": runs,
    }
    if with_object:
        for stat in ("mean", "median"):
            key = f"{stat}_time_ms"
            row[f"time_ratio_{stat}"] = runs[RUNS[1]][key] / runs[RUNS[0]][key]
        row["same_starts"] = _same_starts(results[0], results[1])
        solved_qs = [t.result.q for t in results[1] if t.result.success]
        row["hold"] = _hold_rates(hand, obj, solved_qs)
    return row, targets


def _hold_rates(hand: Hand, obj: GraspObject, qs: list[NDArray[np.float64]]) -> Any:
    """Hold rates of the grasps solved with the object, default and light squeeze.

    None without MuJoCo (the optional extra ``sahgrasp[sim]``).
    """
    try:
        from sahgrasp.sim import LIGHT_SQUEEZE_N, HoldSettings
        from sahgrasp.sim.verify import hold_rates
    except ImportError:
        return None
    settings = {"default": HoldSettings(), "light": HoldSettings(squeeze_n=LIGHT_SQUEEZE_N)}
    return hold_rates(hand, obj, qs, settings)


def _same_starts(without: Sequence[Timed], with_object: Sequence[Timed]) -> dict[str, Any]:
    """The cost of the object checks: CPU time with / without on the sets solved alike.

    The sets both runs solve with the same number of starts: the same search, plus the object's
    queries. (Over all sets, the ratio also counts the starts the object rejects: other work.)
    """
    pairs = [
        (a.cpu_s, b.cpu_s)
        for a, b in zip(without, with_object, strict=True)
        if a.result.success and b.result.success and a.result.inits_used == b.result.inits_used
    ]
    if not pairs:
        return {"sets": 0, "cpu_ratio_total": None, "cpu_ratio_median": None}
    plain, checked = np.array(pairs).T
    return {
        "sets": len(pairs),
        "cpu_ratio_total": float(checked.sum() / plain.sum()),
        "cpu_ratio_median": float(np.median(checked / np.maximum(plain, 1e-9))),
    }


def run(
    problems_per_object: int = 200,
    seed: int = BENCH_SEED,
    workers: int = 1,
    json_out: str | None = None,
    quiet: bool = False,
    objects: Sequence[str] = OBJECT_NAMES,
    meshes: Sequence[str] = (),
    extra_objects: Sequence[GraspObject] = (),
    with_object: bool = True,
    targets_out: str | None = None,
) -> dict[str, Any]:
    """Run the benchmark; return its JSON document (written atomically to ``json_out`` if given).

    Args:
        problems_per_object: Contact sets drawn and solved per object.
        seed: Benchmark seed; each object's contact sets use a seed derived from it and the name.
        workers: Processes solving the IK (times are per problem, measured inside the solver).
        json_out: Path of the JSON document, or None.
        quiet: No progress bar (one per object, on stderr).
        objects: Catalog objects (:data:`sahgrasp.objects.OBJECT_NAMES`).
        meshes: Mesh files (STL, OBJ, PLY) loaded with :func:`load_mesh` as more objects, named
            ``mesh:<file name>``.
        extra_objects: More objects, placed in the world.
        with_object: Solve each contact set a second time with ``obstacle=`` the object.
        targets_out: Path of a targets file holding every contact set, e.g. for
            ``sahgrasp bench ik --targets`` (written atomically), or None.

    Raises:
        InvalidSettingsError: ``problems_per_object`` or ``workers`` below 1.
        InvalidTargetError: An unknown catalog object name (the message lists the valid ones).
        MeshFileError: A mesh file is missing or malformed.
    """
    if problems_per_object < 1 or workers < 1:
        raise InvalidSettingsError(
            f"problems_per_object and workers must be >= 1, got {problems_per_object}, {workers}"
        )
    hand = load_hand(DEFAULT_HAND)
    default_sequence(hand)  # loaded before any problem is timed
    bench_objects = [load_object(name) for name in objects]
    bench_objects += [load_mesh(path, name=f"mesh:{Path(path).name}") for path in meshes]
    bench_objects += extra_objects
    rows, problems = [], []
    for obj in bench_objects:
        row, targets = _bench_object(
            hand, obj, problems_per_object, seed, workers, not quiet, with_object
        )
        rows.append(row)
        problems += targets
    document: dict[str, Any] = {
        "benchmark": "grasps",
        "hand": hand.description.name,
        "seed": seed,
        "problems_per_object": problems_per_object,
        "workers": workers,
        "penetration_tolerance_mm": PENETRATION_TOLERANCE_M * 1e3,
        "reach": {
            "finger_spacing_mm": [1e3 * v for v in sampler_reach(hand).finger_spacing_m],
            "span_mm": [1e3 * v for v in sampler_reach(hand).span_m],
        },
        "objects": rows,
        "created_unix_s": time.time(),
    }
    if json_out is not None:
        write_json_atomic(json_out, document)
    if targets_out is not None:
        save_targets(targets_out, hand.description.name, problems)
    return document


def format_table(document: dict[str, Any]) -> str:
    """A Markdown table of :func:`run`'s document, one row per object and IK run."""
    lines = [
        "| object | IK | solved | 1st start | mean starts | median / mean / p95 ms "
        "| time with / without object (median, mean) "
        "| CPU with / without, same starts (total, median; sets) | claimed penetrating "
        "| depth median / max mm | solved, not penetrating | holds (default, light) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in document["objects"]:
        for label, stats in row["runs"].items():
            pen = stats["penetration"]
            ratio, same, held = "", "", ""
            if label == RUNS[1] and row.get("hold"):
                held = ", ".join(
                    "-"
                    if not row["hold"][k]["checked"]
                    else f"{100 * row['hold'][k]['hold_rate']:.0f}% "
                    f"({row['hold'][k]['holds']}/{row['hold'][k]['checked']})"
                    for k in ("default", "light")
                )
            if label == RUNS[1]:
                ratio = f"{row['time_ratio_median']:.2f}x, {row['time_ratio_mean']:.2f}x"
                alike = row["same_starts"]
                same = f"- ({alike['sets']})"
                if alike["sets"]:
                    same = (
                        f"{alike['cpu_ratio_total']:.2f}x, {alike['cpu_ratio_median']:.2f}x "
                        f"({alike['sets']})"
                    )
            lines.append(
                f"| {row['object']} | {label.replace('_', ' ')} | "
                f"{100 * stats['success_rate']:.1f}% ({stats['solved']}/{stats['problems']}) | "
                f"{100 * stats['first_start_success_rate']:.1f}% | {stats['mean_starts']:.2f} | "
                f"{stats['median_time_ms']:.1f} / {stats['mean_time_ms']:.1f} / "
                f"{stats['p95_time_ms']:.1f} | {ratio} | {same} | "
                f"{100 * pen['penetrating_rate']:.1f}% "
                f"({pen['penetrating']}/{pen['claimed']}) | "
                f"{pen['median_penetrating_depth_mm']:.1f} / {pen['max_link_depth_mm']:.1f} | "
                f"{100 * pen['usable_rate']:.1f}% | {held} |"
            )
    return "\n".join(lines)
