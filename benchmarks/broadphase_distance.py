"""Coal's broad-phase distance query against the exact clearance (why the clearance keeps it out).

For each paper grasp, configurations about the IK's solution (joints and wrist perturbed,
seeded) that are clear of the object. Per configuration, the smallest hand-object distance from
(a) :meth:`HandObjectClearance.clearance` (``all_links=False``, the query the IK runs), and
(b) one C++ query: the object's pieces in a ``coal.DynamicAABBTreeCollisionManager``, the hand's
geometries in Pinocchio's ``BroadPhaseManager`` (refit in C++ at each configuration), and
``manager.distance(other, coal.DistanceCallBackDefault())``. Prints a Markdown table: how many
answers of (b) miss the smallest distance by more than 1 um, the largest miss, and the CPU time
per query of each (mean over the configurations).

    python benchmarks/broadphase_distance.py [--configurations 40] [--seed 11]
"""

from __future__ import annotations

import argparse
import time

import coal
import numpy as np
import pinocchio as pin

from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.ik import solve_ik
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import GRASP_NAMES, load_object, paper_grasp


def _configurations(hand: Hand, name: str, count: int, seed: int) -> list[np.ndarray]:
    q0 = solve_ik(hand, paper_grasp(name), obstacle=load_object(name)).q
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        q = q0.copy()
        q[7:] = np.clip(q[7:] + rng.normal(0.0, 0.03 * (k % 4), len(q) - 7), hand.lower, hand.upper)
        q[:3] += rng.normal(0.0, 2e-3 * (k % 3), 3)
        out.append(q)
    return out


def _row(hand: Hand, name: str, count: int, seed: int) -> str:
    obj = load_object(name)
    checker = HandObjectClearance(hand, obj)
    pieces = [
        coal.CollisionObject(s.geometry, s.transform(obj.T_world_object))
        for s in obj.collision_shapes()
    ]
    tree = coal.DynamicAABBTreeCollisionManager()
    for piece in pieces:
        piece.computeAABB()
        tree.registerObject(piece)
    tree.setup()
    model, data = hand.model, hand.model.createData()
    geometry_model = hand.collision.geometry_model
    geometry_data = pin.GeometryData(geometry_model)
    links = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
        model, geometry_model, geometry_data
    )
    callback = coal.DistanceCallBackDefault()
    misses, worst, clear = 0, 0.0, 0
    exact_s = broad_s = 0.0
    for q in _configurations(hand, name, count, seed):
        start = time.process_time()
        exact = checker.clearance(q, (), all_links=False).distance_m
        exact_s += time.process_time() - start
        start = time.process_time()
        pin.updateGeometryPlacements(model, data, geometry_model, geometry_data, q)
        links.update()
        callback.init()
        tree.distance(links.getManager(), callback)
        broad = float(callback.data.result.min_distance)
        broad_s += time.process_time() - start
        if exact > 0.0:
            clear += 1
            misses += abs(broad - exact) > 1e-6
            worst = max(worst, abs(broad - exact))
    return (
        f"| {name} ({len(pieces)} pieces) | {clear} | {misses} | {worst * 1e3:.3f} mm | "
        f"{exact_s / count * 1e3:.3f} ms | {broad_s / count * 1e3:.3f} ms |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=40, help="per paper grasp")
    parser.add_argument("--seed", type=int, default=11, help="seed of the perturbations")
    args = parser.parse_args()
    hand = load_hand("sah")
    print(
        "| grasp | clear | broad phase off by > 1 um | largest miss | exact query | broad phase |"
    )
    print("|---|---|---|---|---|---|")
    for name in GRASP_NAMES:
        print(_row(hand, name, args.configurations, args.seed))


if __name__ == "__main__":
    main()
