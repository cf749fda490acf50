"""Plan, then refine: the planner's best grasps of the shipped mug, improved by the atlas.

``sahgrasp.plan_grasps`` returns ranked grasps that passed an independent verification on the
mesh. The atlas (Rosales, Porta and Ros, RSS 2011) then explores, around each of them, the
grasps whose contacts stay on smooth local models of the mesh, and returns the best one on the
same manipulability index that again passes the planner's verification on the true mesh. Run
`python examples/refine_mug.py`; `--json OUT` writes the refined grasps as `sahgrasp plan` writes
its grasps (so `sahgrasp solve`, `check` or `atlas --start` can read them).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import sahgrasp
from sahgrasp.core.fileio import write_json_atomic
from sahgrasp.experiments.arguments import MESH_DEFAULTS, positive_int
from sahgrasp.experiments.mesh_atlas import MeshStart, optimize_mesh_grasps, start_patches
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.objects import MeshFileError, load_mesh
from sahgrasp.objects.smooth_surface import SurfaceModelError
from sahgrasp.optimization import OptimizationSettings
from sahgrasp.planner.candidates import ObjectFrame
from sahgrasp.planner.pieces import planning_object
from sahgrasp.planner.plan import manipulability_indices

MUG = Path(__file__).resolve().parent / "meshes" / "mug.stl"
INDEX = "volume"  # the planner ranks by the index the atlas optimizes


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Plan grasps of a mesh, then refine them.")
    parser.add_argument("--mesh", type=Path, default=MUG, help="STL, OBJ or PLY (default: mug)")
    parser.add_argument("--starts", type=positive_int, default=3, help="planned grasps refined")
    parser.add_argument("--candidates", type=positive_int, default=60, help="candidates solved")
    parser.add_argument("--json", type=Path, help="write the refined grasps there")
    args = parser.parse_args(argv)
    hand = sahgrasp.load_hand("sah")
    try:
        # The planner's collision pieces (the triangles' prisms, unjoined): quick to build.
        obj = planning_object(load_mesh(args.mesh))
    except MeshFileError as error:  # a file the user named: one line, not a traceback
        parser.error(str(error))
    # 1. Plan: 3- and 4-finger grasps (two hard fingers have no manipulability), by the index.
    settings = sahgrasp.PlanSettings(
        fingers=(3, 4), grasps=10, candidates=args.candidates, rank=INDEX, seed=0
    )
    plan = sahgrasp.plan_grasps(hand, obj, settings)
    # 2. The best planned grasps the atlas can start from: a smooth model of the mesh at every
    #    contact (a contact on a sharp edge or a rim has none).
    starts, planned = [], []
    for i, grasp in enumerate(plan.grasps, start=1):
        target = GraspTarget(f"rank {i}", list(grasp.contacts))
        try:
            start_patches(obj, target)
        except SurfaceModelError as error:
            print(f"  rank {i}: not refined: {error}")
            continue
        starts.append(MeshStart(target, grasp.q, f"rank {i}"))
        planned.append(grasp)
        if len(starts) == args.starts:
            break
    if not starts:
        print(f"{obj.name}: no planned grasp with a smooth model at every contact")
        return 1
    # 3. Refine: the atlas around each start, each optimum verified on the true mesh.
    atlas = OptimizationSettings(MESH_DEFAULTS["radius"], MESH_DEFAULTS["epsilon"], INDEX)
    search = optimize_mesh_grasps(hand, obj, starts, atlas)
    mesh = obj.mesh().transformed(obj.T_world_object)
    centroid = ObjectFrame.of(mesh.vertices_m, mesh.faces).centroid_m
    refined = []
    for k, (start, grasp, owner, error) in enumerate(
        zip(starts, planned, search.start_components, search.start_errors, strict=True)
    ):
        line = f"  {start.label}: {'+'.join(grasp.fingers)}, {INDEX} {grasp.quality[INDEX]:.4g}"
        if owner is None:
            print(f"{line}; not refined: {error}")
            continue
        c = search.components[owner]
        if c.starts[0] != k:
            print(f"{line}; in the component of {starts[c.starts[0]].label}")
            continue
        if c.q_world is None:
            print(f"{line}; no chart of {c.result.atlas.n_charts} passed the verification")
            continue
        fingers = tuple(t.finger for t in c.contacts)
        value = manipulability_indices(hand, c.q_world, fingers, centroid)[INDEX]
        gain = 100.0 * (value / grasp.quality[INDEX] - 1.0)
        print(f"{line} -> {value:.4g} ({gain:+.1f}%) after {c.result.atlas.n_charts} charts; "
              f"verified on the mesh")  # fmt: skip
        refined.append({
            "rank": len(refined) + 1, "fingers": list(fingers),
            "contacts": [t.to_dict() for t in c.contacts],
            "wrist": {"xyz": c.q_world[:3].tolist(), "quat": c.q_world[3:7].tolist()},
            "joints": hand.joint_values(c.q_world), "quality": {INDEX: value},
        })  # fmt: skip
    print(f"{obj.name}: {len(refined)} of {len(starts)} planned grasps refined")
    if args.json is not None:
        document = plan.to_dict()
        write_json_atomic(args.json, {**document, "grasps": refined})
    return 0 if refined else 1


if __name__ == "__main__":
    raise SystemExit(main())
