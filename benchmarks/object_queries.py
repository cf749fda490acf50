"""Where the IK's time with an object goes, query by query (docs/methods/meshes.md).

Draws the first ``--sets`` contact sets of the grasp benchmark per object (``sample_object_grasps``
with the benchmark's per-object seed), solves each without and then with the object, and

* ``profile``: wraps every method of ``HandObjectClearance`` with a CPU timer and prints, per
  object, the CPU with and without the object and the calls, total and mean CPU per method, and
  the GJK/EPA calls per hand link (the timers add their own cost: per-call times are upper
  bounds);
* ``compare OLD_CLEARANCE_PY``: records every hand-object query the IK made and times it with
  the ``HandObjectClearance`` of another version of ``sahgrasp/collision/hand_object.py`` (e.g.
  ``git show 6285f32:sahgrasp/collision/hand_object.py > old.py``) and with this one, query by query
  alternating, best of ``--repeats``; prints the mean CPU per query and whether every answer
  (pairs, clearance, link) is the same;
* ``ik OLD_CLEARANCE_PY``: the same with the IK's own questions, the repair query
  (``per_link=REPAIR_PAIRS_PER_LINK``; pairs and witnesses compared to the bit) and the
  acceptance test (``clearance_if_clear``), the latter split by verdict;
* ``solves OLD_CLEARANCE_PY``: the solves themselves, per set alternating the old checker with
  the old acceptance test (the exact clearance, as before the fourth round) and this code, best
  of ``--repeats`` (``--new-first``: this code before the old in each pair); prints the CPU
  without the object, with old and with new, and whether every
  result (success, starts, reason, clearance, closest link, ``q``) is identical;
* ``sets``: per set solved alike without and with the object (success, same starts), the CPU
  of each solve, the repair queries and exact-clearance queries of the solve with the object
  and their CPU, and the iterations of each solve: what the same-start ratio is made of;
* ``alone``: the sets solved with the object only, one after the other: the CPU and the solved
  count, for comparing versions in separate processes (``PYTHONPATH`` selecting the code);
* ``verdicts``: for the acceptance tests the IK made, the exact clearance against
  ``clearance_if_clear`` (the verdict, and the clearance of a clear configuration), split by
  verdict, and how many answers differ (verdict; distance and link when clear);
* ``finer``: every solution claimed with the object, re-checked as the grasp benchmark does
  (``ObjectPenetration``, links other than the contact tips deeper than 0.2 mm) against the
  finer pieces the joined ones replaced (one per band sector of a revolved solid, one prism per
  mesh triangle): whether joining the pieces let a solution through the finer geometry;
* ``pieces``: the queries the IK made (with the joined pieces), timed with a checker of the
  finer pieces and one of the joined pieces, query by query alternating, best of ``--repeats``;
* ``compiled``: the IK's acceptance tests and repair queries answered by coal alone
  (``clearance_if_clear``; ``penetrations`` with one pair per link) and by the compiled
  verdicts the IK uses (``Obstacle``: GJK, then coal's witnesses of the links it finds), best
  of ``--repeats`` per kind; prints the mean CPU per query and how many answers differ
  (verdict, closest link, clearance beyond 1e-6 m; repair pairs and depths).

The modes that record the IK's queries solve with the compiled verdicts turned off, so that
every query goes through ``HandObjectClearance`` (the same solves).

    python benchmarks/object_queries.py profile --sets 20
    python benchmarks/object_queries.py compare old.py --sets 20
    python benchmarks/object_queries.py ik old.py --sets 60 --repeats 3
    python benchmarks/object_queries.py solves old.py --sets 20 --repeats 2
    python benchmarks/object_queries.py sets --sets 30
    python benchmarks/object_queries.py alone --sets 100 --objects coffee_cup
    python benchmarks/object_queries.py verdicts --sets 20
    python benchmarks/object_queries.py finer --sets 200 --objects coffee_cup can mesh:mug.stl
    python benchmarks/object_queries.py pieces --sets 40 --repeats 3
    python benchmarks/object_queries.py compiled --sets 40 --repeats 3 --objects can coffee_cup

Objects: catalog names, or ``mesh:FILE`` for a file in examples/meshes (default: the coffee cup,
the mug and the bottle meshes).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sahgrasp.bench.grasps import (
    BENCH_SEED,
    PENETRATION_TOLERANCE_M,
    ObjectPenetration,
    _object_seed,
    _prepare,
)
from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.collision.shapes import CollisionShape, convex_hull
from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.ik import obstacle as obstacle_module
from sahgrasp.ik.obstacle import REPAIR_PAIRS_PER_LINK, Obstacle
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import GraspObject, load_object
from sahgrasp.objects.grasp_sampler import registered_reach, sample_object_grasps
from sahgrasp.objects.mesh_file import MeshSolid, load_mesh
from sahgrasp.objects.profiles import chord_count
from sahgrasp.objects.solids import COLLISION_SAGITTA_M, RevolvedSolid, _bands

MESHES = Path(__file__).resolve().parent.parent / "examples" / "meshes"
ALLOWANCE_M = IKSettings().d_min_m


def _object(name: str) -> GraspObject:
    if name.startswith("mesh:"):
        return load_mesh(MESHES / name[5:], name=name)
    return load_object(name)


def _sets(obj: GraspObject, count: int) -> list[GraspTarget]:
    return sample_object_grasps(
        obj, count, _object_seed(BENCH_SEED, obj.name), registered_reach("sah")
    )


def _cpu(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[float, Any]:
    start = time.process_time()
    out = fn(*args, **kwargs)
    return time.process_time() - start, out


def _tallied(method: Any, name: str, tally: dict[str, list[float]]) -> Any:
    """``method`` counting its calls and CPU seconds in ``tally[name]``."""

    def timed(*args: Any, **kw: Any) -> Any:
        spent, out = _cpu(method, *args, **kw)
        tally[name][0] += 1
        tally[name][1] += spent
        return out

    return timed


def profile(hand: Hand, obj: GraspObject, targets: list[GraspTarget]) -> None:
    stats: dict[str, list[float]] = defaultdict(lambda: [0, 0.0])
    originals = {}
    for name, method in vars(HandObjectClearance).items():
        if callable(method) and name not in ("__init__", "links"):
            originals[name] = method
            setattr(HandObjectClearance, name, _tallied(method, name, stats))
    gjk = originals["_gjk"]

    def per_link(self: Any, T: Any, g: int) -> Any:  # GJK/EPA calls and CPU by hand link
        distance = gjk(self, T, g)

        def timed(piece: int) -> float:
            spent, out = _cpu(distance, piece)
            stats["GJK/EPA " + self.links[g]][0] += 1
            stats["GJK/EPA " + self.links[g]][1] += spent
            return float(out)

        return timed

    HandObjectClearance._gjk = per_link  # type: ignore[method-assign]
    try:
        without = with_object = 0.0
        for t in targets:
            without += _cpu(solve_ik, hand, t, IKSettings())[0]
            with_object += _cpu(solve_ik, hand, t, IKSettings(), obstacle=obj)[0]
    finally:
        for name, method in originals.items():
            setattr(HandObjectClearance, name, method)
    pieces = len(obj.collision_shapes())
    print(f"== {obj.name} ({pieces} pieces): CPU without {without:.2f} s, with {with_object:.2f} s")
    for name, (calls, spent) in sorted(stats.items(), key=lambda kv: -kv[1][1])[:20]:
        print(
            f"  {name:22s} {int(calls):7d} calls {spent:8.3f} s {spent / calls * 1e6:8.1f} us/call"
        )


def _queries(
    hand: Hand, obj: GraspObject, targets: list[GraspTarget]
) -> list[tuple[str, np.ndarray, tuple[str, ...], Any]]:
    """Every query the IK's obstacle made while solving ``targets`` (kind, q, contacts, arg).

    ``arg``: the margin of a repair query; for a clearance, True for the acceptance test
    (``clearance_if_clear``), False for the exact clearance.
    """
    log: list[tuple[str, np.ndarray, tuple[str, ...], Any]] = []
    originals = {
        n: getattr(HandObjectClearance, n)
        for n in ("penetrations", "clearance", "clearance_if_clear")
    }

    def logged_penetrations(
        self: Any, q: np.ndarray, margin_m: float, contacts: Any, *a: Any, **kw: Any
    ) -> Any:
        log.append(("penetrations", q.copy(), tuple(contacts), margin_m))
        return originals["penetrations"](self, q, margin_m, contacts, *a, **kw)

    def logged(name: str, accepting: bool) -> Any:
        def query(self: Any, q: np.ndarray, contacts: Any, *a: Any, **kw: Any) -> Any:
            log.append(("clearance", q.copy(), tuple(contacts), accepting))
            return originals[name](self, q, contacts, *a, **kw)

        return query

    HandObjectClearance.penetrations = logged_penetrations  # type: ignore[method-assign]
    HandObjectClearance.clearance = logged("clearance", False)  # type: ignore[method-assign]
    HandObjectClearance.clearance_if_clear = logged("clearance_if_clear", True)  # type: ignore[method-assign]
    # The IK asks the compiled verdicts when it can (docs/methods/ik.md): without them it asks every
    # query of these, and makes the same solves.
    compiled = obstacle_module.pieces_of
    obstacle_module.pieces_of = lambda checker: None  # type: ignore[assignment]
    try:
        for t in targets:
            solve_ik(hand, t, IKSettings(), obstacle=obj)
    finally:
        for name, method in originals.items():
            setattr(HandObjectClearance, name, method)
        obstacle_module.pieces_of = compiled
    return log


def _ask_all(pairs: list[tuple[Callable[[], Any], Callable[[], Any]]], side: int) -> None:
    for pair in pairs:
        pair[side]()


def compiled(hand: Hand, obj: GraspObject, targets: list[GraspTarget], repeats: int) -> None:
    """The IK's queries answered by coal alone and by the compiled verdicts (docs/methods/ik.md)."""
    checker = HandObjectClearance(hand, obj)
    obstacles: dict[tuple[str, ...], Obstacle] = {}
    rows: dict[str, list[tuple[Callable[[], Any], Callable[[], Any]]]] = defaultdict(list)
    differ: dict[str, int] = defaultdict(int)
    for kind, q, contacts, arg in _queries(hand, obj, targets):
        if kind == "clearance" and not arg:
            continue  # the exact clearance of a result: not a verdict
        obstacle = obstacles.setdefault(contacts, Obstacle(hand, obj, contacts, ALLOWANCE_M))
        pieces = obstacle._pieces
        assert pieces is not None, f"{obj.name}: the compiled verdicts do not know its pieces"
        if kind == "clearance":
            pair = (
                lambda q=q, c=contacts: checker.clearance_if_clear(q, c, ALLOWANCE_M),
                lambda q=q, o=obstacle, p=pieces: o._compiled_clearance(q, p),
            )
            coal_found, found = pair[0](), pair[1]()
            same = (coal_found is None) == (found is None) and (
                found is None
                or (
                    (coal_found.link == found.link)
                    and abs(coal_found.distance_m - found.distance_m) <= 1e-6
                )
            )
            rows["acceptance test"].append(pair)
        else:
            pair = (
                lambda q=q, c=contacts, m=arg: checker.penetrations(
                    q, m, c, ALLOWANCE_M, per_link=REPAIR_PAIRS_PER_LINK
                ),
                lambda q=q, o=obstacle, m=arg: o.penetrations(q, m),
            )
            same = [(p.joint_b, p.depth_m) for p in pair[0]()] == [
                (p.joint_b, p.depth_m) for p in pair[1]()
            ]
            rows["repair query"].append(pair)
        differ[kind] += not same
    for label, pairs in rows.items():
        best = np.full(2, np.inf)
        for _ in range(repeats):
            for j in range(2):
                best[j] = min(best[j], _cpu(_ask_all, pairs, j)[0])
        coal_us, compiled_us = best / len(pairs) * 1e6
        print(
            f"{obj.name:16s} {label:15s} {len(pairs):5d} queries: coal {coal_us:6.1f} us, "
            f"compiled {compiled_us:6.1f} us; answers differing: "
            f"{differ['clearance' if label == 'acceptance test' else 'penetrations']}"
        )


def _answer(checker: Any, kind: str, q: np.ndarray, contacts: tuple[str, ...], arg: Any) -> Any:
    if kind == "clearance":  # the exact clearance: both versions have it
        found = checker.clearance(q, contacts, ALLOWANCE_M, all_links=False)
        return round(found.distance_m, 12), found.link
    pairs = checker.penetrations(q, arg, contacts, ALLOWANCE_M, per_link=4)
    return [(p.joint_b, round(p.depth_m, 12), tuple(np.round(p.normal, 9))) for p in pairs]


def _old_module(old_path: str) -> Any:
    spec = importlib.util.spec_from_file_location("old_clearance", old_path)
    assert spec is not None and spec.loader is not None
    old = importlib.util.module_from_spec(spec)
    sys.modules["old_clearance"] = old
    spec.loader.exec_module(old)
    return old


def _alternate(
    checkers: tuple[Any, Any], queries: list[Any], answer: Callable[..., Any], repeats: int
) -> tuple[float, float, bool]:
    """Mean best-of-``repeats`` CPU [us] per query of two checkers, query by query alternating
    (which one goes first alternates too), and whether every answer is the same."""
    best = np.full((len(queries), 2), np.inf)
    same = True
    for r in range(repeats):
        for i, (kind, q, contacts, arg) in enumerate(queries):
            answers = [None, None]
            for j in (0, 1) if (i + r) % 2 == 0 else (1, 0):
                spent, answers[j] = _cpu(answer, checkers[j], kind, q, contacts, arg)
                best[i, j] = min(best[i, j], spent)
            same &= answers[0] == answers[1]
    old_us, new_us = best.mean(axis=0) * 1e6 if queries else (math.nan, math.nan)
    return float(old_us), float(new_us), same


def _queries_and_checkers(
    hand: Hand, obj: GraspObject, targets: list[GraspTarget], old_path: str
) -> tuple[list[tuple[str, np.ndarray, tuple[str, ...], Any]], tuple[Any, HandObjectClearance]]:
    """The IK's logged queries on ``targets``, and the old and the new checker of ``obj``."""
    old = _old_module(old_path)
    log = _queries(hand, obj, targets)
    return log, (old.HandObjectClearance(hand, obj), HandObjectClearance(hand, obj))


def compare(
    hand: Hand, obj: GraspObject, targets: list[GraspTarget], old_path: str, repeats: int
) -> None:
    log, checkers = _queries_and_checkers(hand, obj, targets, old_path)
    for kind in ("penetrations", "clearance"):
        queries = [entry for entry in log if entry[0] == kind]
        old_us, new_us, same = _alternate(checkers, queries, _answer, repeats)
        print(
            f"{obj.name:16s} {kind:12s} {len(queries):5d} queries: old {old_us:6.0f} us, "
            f"new {new_us:6.0f} us ({new_us / old_us - 1:+.0%}), same answers: {same}"
        )


def _ik_answer(checker: Any, kind: str, q: np.ndarray, contacts: tuple[str, ...], arg: Any) -> Any:
    """What the IK asks: its repair query (pairs, witnesses to the bit) or acceptance test."""
    if kind == "clearance":  # as a tuple: each version has its own Clearance class
        found = checker.clearance_if_clear(q, contacts, ALLOWANCE_M)
        return None if found is None else (found.distance_m, found.link, dict(found.links_m))
    pairs = checker.penetrations(q, arg, contacts, ALLOWANCE_M, per_link=REPAIR_PAIRS_PER_LINK)
    return [
        (p.joint_b, p.depth_m, tuple(p.point_a), tuple(p.point_b), tuple(p.normal)) for p in pairs
    ]


def ik(
    hand: Hand, obj: GraspObject, targets: list[GraspTarget], old_path: str, repeats: int
) -> None:
    log, checkers = _queries_and_checkers(hand, obj, targets, old_path)
    groups: dict[str, list[Any]] = {"repair": [], "accept, inside": [], "accept, clear": []}
    for entry in log:
        if entry[0] == "penetrations":
            groups["repair"].append(entry)
        elif entry[3]:  # an acceptance test
            clear = checkers[1].clearance_if_clear(entry[1], entry[2], ALLOWANCE_M) is not None
            groups["accept, clear" if clear else "accept, inside"].append(entry)
    for group, queries in groups.items():
        old_us, new_us, same = _alternate(checkers, queries, _ik_answer, repeats)
        print(
            f"{obj.name:16s} {group:14s} {len(queries):5d} queries: old {old_us:6.0f} us, "
            f"new {new_us:6.0f} us ({new_us / old_us - 1:+.0%}), same answers: {same}"
        )


def _exact_clearance(self: Obstacle, q: np.ndarray) -> Any:
    """The acceptance test before the fourth round: the exact clearance, kept for ``q``."""
    key, last = q.tobytes(), self._last[1]
    if self._last[0] != key or last is None:
        last = self.checker.clearance(q, self.contacts, self.allowance_m, all_links=False)
        self._last = (key, last)
    return last


def solves(
    hand: Hand,
    obj: GraspObject,
    targets: list[GraspTarget],
    old_path: str,
    repeats: int,
    new_first: bool = False,
) -> None:
    old = _old_module(old_path)
    import sahgrasp.ik.obstacle as obstacle_module

    versions = {
        "old": (
            old.HandObjectClearance(hand, obj),
            lambda self, q: not _exact_clearance(self, q).clear(),
            _exact_clearance,
        ),
        "new": (HandObjectClearance(hand, obj), Obstacle.penetrated, Obstacle.clearance),
    }
    saved = obstacle_module.checker_of, Obstacle.penetrated, Obstacle.clearance
    best = np.full((len(targets), 3), np.inf)
    same = True
    try:
        for _ in range(repeats):
            for i, t in enumerate(targets):
                best[i, 0] = min(best[i, 0], _cpu(solve_ik, hand, t, IKSettings())[0])
                results = []
                order = list(enumerate(versions.values(), 1))
                for j, (checker, penetrated, clearance) in order[::-1] if new_first else order:
                    obstacle_module.checker_of = lambda h, o, c=checker: c  # type: ignore[assignment,misc]
                    Obstacle.penetrated, Obstacle.clearance = penetrated, clearance  # type: ignore[method-assign]
                    spent, r = _cpu(solve_ik, hand, t, IKSettings(), obstacle=obj)
                    best[i, j] = min(best[i, j], spent)
                    q = r.q.tobytes()
                    results.append((r.success, r.inits_used, r.reason, r.closest_link, q))
                    results[-1] += (r.object_clearance_m,)
                same &= results[0] == results[1]
    finally:
        obstacle_module.checker_of, Obstacle.penetrated, Obstacle.clearance = saved  # type: ignore[method-assign]
    without, with_old, with_new = best.sum(axis=0)
    print(
        f"{obj.name:16s} {len(targets)} sets, best of {repeats}: CPU without {without:.2f} s, "
        f"with old {with_old:.2f} s, with new {with_new:.2f} s ({with_new / with_old - 1:+.0%}); "
        f"identical results: {same}"
    )


def sets(hand: Hand, obj: GraspObject, targets: list[GraspTarget]) -> None:
    counts: dict[str, list[float]] = defaultdict(lambda: [0, 0.0])
    originals = {n: getattr(HandObjectClearance, n) for n in ("penetrations", "clearance")}
    for name, method in originals.items():
        setattr(HandObjectClearance, name, _tallied(method, name, counts))
    rows = []
    try:
        for t in targets:
            plain_s, plain = _cpu(solve_ik, hand, t, IKSettings())
            counts.clear()
            checked_s, checked = _cpu(solve_ik, hand, t, IKSettings(), obstacle=obj)
            alike = plain.success and checked.success and plain.inits_used == checked.inits_used
            if alike:
                pen, clr = counts["penetrations"], counts["clearance"]
                rows.append((plain_s, checked_s, *pen, *clr, checked.inits_used))
                rows[-1] += (checked.iterations, plain.iterations)
    finally:
        for name, method in originals.items():
            setattr(HandObjectClearance, name, method)
    ratios = [r[1] / r[0] for r in rows]
    print(f"== {obj.name}: {len(rows)} sets solved alike, median ratio {np.median(ratios):.2f}")
    print("  without ms | with ms | repair queries, ms | clearances, ms | starts | iterations")
    for r in sorted(rows, key=lambda r: r[1] / r[0]):
        print(
            f"  {r[0] * 1e3:7.2f} | {r[1] * 1e3:7.2f} | {int(r[2]):3d}, {r[3] * 1e3:6.2f} | "
            f"{int(r[4]):2d}, {r[5] * 1e3:5.2f} | {r[6]} | {r[7]} with, {r[8]} without"
        )


def alone(hand: Hand, obj: GraspObject, targets: list[GraspTarget]) -> None:
    spent, solved = _cpu(
        lambda: sum(solve_ik(hand, t, IKSettings(), obstacle=obj).success for t in targets)
    )
    print(f"{obj.name:16s} {len(targets)} sets with the object: {spent:.2f} s CPU, {solved} solved")


def verdicts(hand: Hand, obj: GraspObject, targets: list[GraspTarget], repeats: int) -> None:
    tests = [e for e in _queries(hand, obj, targets) if e[0] == "clearance" and e[3]]
    checker = HandObjectClearance(hand, obj)
    rows: dict[bool, list[list[float]]] = {True: [], False: []}
    differ = 0
    for _, q, contacts, _ in tests:
        best = [np.inf, np.inf]
        for _ in range(repeats):
            spent, exact = _cpu(checker.clearance, q, contacts, ALLOWANCE_M, all_links=False)
            best[0] = min(best[0], spent)
            spent, found = _cpu(checker.clearance_if_clear, q, contacts, ALLOWANCE_M)
            best[1] = min(best[1], spent)
        rows[found is None].append(best)
        # The same verdict, and for a clear configuration the same distance and link.
        same = (
            found is None
            if not exact.clear()
            else found is not None
            and (
                found.distance_m,
                found.link,
            )
            == (exact.distance_m, exact.link)
        )
        differ += not same
    for inside, times in rows.items():
        if times:
            exact_us, verdict_us = np.mean(times, axis=0) * 1e6
            label = "inside" if inside else "clear"
            print(
                f"{obj.name:16s} {label:6s} {len(times):4d} tests: exact clearance {exact_us:6.0f} "
                f"us, clearance_if_clear {verdict_us:6.0f} us"
            )
    print(f"{obj.name:16s} answers differing from the exact clearance: {differ}")


def _finer_pieces(obj: GraspObject) -> list[CollisionShape]:
    """The pieces before joining: band sectors at the solid's largest radius, triangle prisms."""
    pieces: list[CollisionShape] = []
    for solid in obj.solids:
        if isinstance(solid, RevolvedSolid):
            count = chord_count(solid._turn_rad, solid._max_radius_m, COLLISION_SAGITTA_M)
            angles = np.linspace(*solid.angle_range_rad, count + 1)
            for band in _bands(solid.profile):
                if math.isclose(solid._turn_rad, 2 * math.pi) and np.allclose(band[:, 0], 0.0):
                    pieces.append(solid._hull(band[:, 2:], angles))
                else:
                    pieces.extend(solid._hull(band, angles[k : k + 2]) for k in range(count))
        elif isinstance(solid, MeshSolid) and solid.collision == "prisms":
            corners = solid.vertices_m[solid.faces]
            depth = solid.wall_thickness_m()[:, None, None] * solid.trimesh.face_normals[:, None]
            pieces.extend(convex_hull(p) for p in np.concatenate([corners, corners - depth], 1))
        else:
            pieces.extend(solid.collision_shapes())
    return pieces


def finer(hand: Hand, obj: GraspObject, targets: list[GraspTarget]) -> None:
    check = ObjectPenetration(hand, obj)
    check.pieces = tuple(_finer_pieces(obj))
    check._piece_transforms = [s.transform(obj.T_world_object) for s in check.pieces]
    centres = np.array([s.placement[:3, 3] for s in check.pieces])
    check._piece_centres = centres @ obj.T_world_object[:3, :3].T + obj.T_world_object[:3, 3]
    check._piece_radii = np.array([s.bounding_radius_m for s in check.pieces])
    tips = {f.tip_link for f in hand.description.fingers}
    deepest = []
    for t in targets:
        r = solve_ik(hand, t, IKSettings(), obstacle=obj)
        if r.success:
            depths = check.depths(r.q)
            deepest.append(max((v for k, v in depths.items() if k not in tips), default=0.0))
    depth_mm = np.array(deepest) * 1e3
    deep = int((depth_mm > PENETRATION_TOLERANCE_M * 1e3).sum())
    print(
        f"{obj.name:16s} {len(obj.collision_shapes())} pieces, {len(check.pieces)} finer: "
        f"{len(deepest)} of {len(targets)} solved, {deep} penetrate the finer pieces "
        f"(deepest link other than a contact tip: {depth_mm.max(initial=0.0):.3f} mm)"
    )


def pieces(hand: Hand, obj: GraspObject, targets: list[GraspTarget], repeats: int) -> None:
    finer_obj = _object(obj.name)
    finer_pieces = tuple(_finer_pieces(finer_obj))
    object.__setattr__(finer_obj, "collision_shapes", lambda: finer_pieces)
    log = _queries(hand, obj, targets)
    checkers = (HandObjectClearance(hand, finer_obj), HandObjectClearance(hand, obj))
    for kind in ("penetrations", "clearance"):
        queries = [entry for entry in log if entry[0] == kind]
        best = np.full((len(queries), 2), np.inf)
        for _ in range(repeats):
            for i, (_, q, contacts, arg) in enumerate(queries):
                for j, checker in enumerate(checkers):
                    best[i, j] = min(best[i, j], _cpu(_answer, checker, kind, q, contacts, arg)[0])
        finer_us, joined_us = best.mean(axis=0) * 1e6
        print(
            f"{obj.name:16s} {kind:12s} {len(queries):5d} queries: {len(finer_pieces)} finer "
            f"pieces {finer_us:6.0f} us, {len(obj.collision_shapes())} joined {joined_us:6.0f} us "
            f"({joined_us / finer_us - 1:+.0%})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "mode",
        choices=(
            "profile",
            "compare",
            "ik",
            "solves",
            "sets",
            "alone",
            "verdicts",
            "finer",
            "pieces",
            "compiled",
        ),
    )
    parser.add_argument(
        "old", nargs="?", help="compare, ik, solves: another version's clearance.py"
    )
    parser.add_argument("--sets", type=int, default=20, help="contact sets per object")
    parser.add_argument(
        "--repeats", type=int, default=5, help="compare, ik, verdicts, pieces: best of"
    )
    parser.add_argument("--new-first", action="store_true", help="solves: this code first")
    parser.add_argument(
        "--objects", nargs="+", default=["coffee_cup", "mesh:mug.stl", "mesh:bottle.obj"]
    )
    args = parser.parse_args()
    if args.mode in ("compare", "ik", "solves") and not args.old:
        parser.error(f"{args.mode} needs the other version's clearance.py")
    hand = load_hand("sah")
    for name in args.objects:
        obj = _object(name)
        targets = _sets(obj, args.sets)
        _prepare(hand, obj)
        if args.mode == "profile":
            profile(hand, obj, targets)
        elif args.mode == "compare":
            compare(hand, obj, targets, args.old, args.repeats)
        elif args.mode == "ik":
            ik(hand, obj, targets, args.old, args.repeats)
        elif args.mode == "solves":
            solves(hand, obj, targets, args.old, args.repeats, args.new_first)
        elif args.mode == "sets":
            sets(hand, obj, targets)
        elif args.mode == "compiled":
            compiled(hand, obj, targets, args.repeats)
        elif args.mode == "alone":
            alone(hand, obj, targets)
        elif args.mode == "finer":
            finer(hand, obj, targets)
        elif args.mode == "pieces":
            pieces(hand, obj, targets, args.repeats)
        else:
            verdicts(hand, obj, targets, args.repeats)


if __name__ == "__main__":
    main()
