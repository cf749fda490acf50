"""``sahgrasp bench plan``: the planner on the catalog objects, the shipped meshes and test meshes.

Per object: :func:`sahgrasp.plan_grasps` with the given settings, timed from before the object is
loaded (the mesh read, repaired and its collision pieces built: all included); the seconds to the
first verified force-closure grasp, verified grasps per second, the share of force-closure grasps,
the median and best L1 epsilon, and the verified grasps by finger count. Every returned grasp is
then checked once more by a fresh :class:`~sahgrasp.planner.verify.GraspVerifier` from its JSON
form (the count of failures must be 0). Then the machine's throughput: the folder of mesh objects
planned by :func:`sahgrasp.planner.folder.plan_jobs` on 1 and on 2 worker processes (wall time
from the first object submitted to the last document; the workers' start-up -- the process,
the planner's imports, the hand -- comes before and is reported apart as ``warm_up_s``):
verified force-closure grasps per second and the speed-up.

With MuJoCo (``sahgrasp[sim]``), the returned grasps are hold-tested (:mod:`sahgrasp.sim`)
with the default settings and the light squeeze at the object's mass from the default density
(1000 kg/m^3), the same two at the field's convention of 0.1 kg for every object
(DexGraspBench's), the default settings in DexGraspBench's MuJoCo solver settings
(:func:`~sahgrasp.sim.settings.dexgraspbench_solver`), the cross-check: the count of grasps that
hold by default but not there (``default_not_dexgraspbench``) should be 0, and with MuJoCo's
soft, creeping friction (:func:`~sahgrasp.sim.settings.soft_friction`), the strictest set-up.
And each object is planned once more as ``plan --verify physics`` plans it (the planner keeps
only the grasps that hold in the default hold test, ranked by their margin, drawing further
batches of candidates while fewer than asked hold, up to four times the candidates:
:data:`sahgrasp.planner.settings.CHECK_CANDIDATES_FACTOR`): the grasps it returns (and how many
of them passed after the first batch, what a plan without further batches returns), the seconds
to the first holding grasp and in all (from before the object is loaded), and how many of the
returned grasps hold in DexGraspBench's solver settings and with the light squeeze at 0.1 kg.

The test meshes (:func:`write_test_meshes`) are trimesh primitives of graspable size (4-15 cm):
boxes, a plate, a cube, cylinders, a sphere, a capsule, a cone, a torus, a tube, and a box
written in millimetres (planned with ``scale = 1e-3``; left out of the folder run, whose files
are in metres).
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from statistics import median
from typing import Any

from sahgrasp.model.hands import DEFAULT_HAND

__all__ = ["TEST_MESHES", "format_table", "run", "write_test_meshes"]

SHIPPED_MESHES = ("mug.stl", "bottle.obj")
"""The meshes of ``examples/meshes``."""

TEST_MESHES = (
    "box_50x70x90.stl",
    "plate_120x80x30.stl",
    "cube_60.stl",
    "cylinder_r35_h120.stl",
    "rod_r20_h150.stl",
    "sphere_r40.ply",
    "capsule_r25_h80.stl",
    "cone_r40_h100.obj",
    "torus_R45_r15.obj",
    "tube_r20_r35_h60.stl",
    "box_mm_60x40x80.stl",
)
"""The test meshes :func:`write_test_meshes` writes (file names say their sizes in mm)."""

_MM = "box_mm_60x40x80.stl"


def write_test_meshes(folder: str | os.PathLike[str]) -> dict[str, float]:
    """Write :data:`TEST_MESHES` into ``folder``; returns each file's scale to metres."""
    import trimesh

    root = Path(folder)
    c = trimesh.creation
    meshes = {
        "box_50x70x90.stl": c.box(extents=(0.05, 0.07, 0.09)),
        "plate_120x80x30.stl": c.box(extents=(0.12, 0.08, 0.03)),
        "cube_60.stl": c.box(extents=(0.06, 0.06, 0.06)),
        "cylinder_r35_h120.stl": c.cylinder(radius=0.035, height=0.12, sections=64),
        "rod_r20_h150.stl": c.cylinder(radius=0.02, height=0.15, sections=48),
        "sphere_r40.ply": c.icosphere(subdivisions=3, radius=0.04),
        "capsule_r25_h80.stl": c.capsule(radius=0.025, height=0.08, count=[24, 24]),
        "cone_r40_h100.obj": c.cone(radius=0.04, height=0.1, sections=64),
        "torus_R45_r15.obj": c.torus(
            major_radius=0.045, minor_radius=0.015, major_sections=64, minor_sections=24
        ),
        "tube_r20_r35_h60.stl": c.annulus(r_min=0.02, r_max=0.035, height=0.06, sections=64),
        _MM: c.box(extents=(60.0, 40.0, 80.0)),
    }
    for name, mesh in meshes.items():
        mesh.export(root / name)
    return {name: (1e-3 if name == _MM else 1.0) for name in meshes}


def _object_row(
    hand: Any,
    name: str,
    load: Any,
    settings: Any,
    object_spec: dict[str, Any],
    verify_physics: bool = True,
) -> dict[str, Any]:
    from sahgrasp.planner import plan_grasps
    from sahgrasp.planner.verify import GraspVerifier

    start, cpu = time.perf_counter(), time.process_time()
    obj = load()
    plan = plan_grasps(hand, obj, settings, object_spec=object_spec, started=start)
    cpu_s = time.process_time() - cpu
    s = plan.summary
    doc = plan.to_dict()
    mesh = obj.mesh().transformed(obj.T_world_object)
    check = GraspVerifier(
        hand.description, mesh.vertices_m, mesh.faces, settings.d_min_m, settings.link_tolerance_m
    )
    failing = sum(not check.check(g["wrist"], g["joints"], g["contacts"]).ok for g in doc["grasps"])
    epsilons = [g["quality"]["epsilon_l1"] for g in doc["grasps"] if g["quality"]["force_closure"]]
    return {
        "object": name,
        "faces": len(mesh.faces),
        "time_to_first_s": s.time_to_first_s,
        "time_s": s.time_s,
        "candidates": s.candidates,
        "verified": s.verified,
        "verified_per_s": s.verified / s.time_s,
        "cpu_s": cpu_s,
        "force_closure_per_cpu_s": s.verified_force_closure / cpu_s,
        "verified_force_closure": s.verified_force_closure,
        "force_closure_share": s.verified_force_closure / s.verified if s.verified else 0.0,
        "returned": s.grasps,
        "returned_failing_recheck": failing,
        "median_epsilon": float(median(epsilons)) if epsilons else 0.0,
        "best_epsilon": max(epsilons, default=0.0),
        "by_fingers": s.by_fingers,
        "failed_verification": s.failed_verification,
        "hold": _hold_rates(
            hand, obj, [g.q for g in plan.grasps], [g.fingers for g in plan.grasps]
        ),
        "verify_physics": (
            _verified_physics(hand, load, settings, object_spec) if verify_physics else None
        ),
    }


HOLD_SETTINGS = (
    "default", "light", "default_0.1kg", "light_0.1kg", "dexgraspbench", "soft_friction"
)  # fmt: skip
"""The hold tests of the returned grasps (module docstring), keys of each row's ``hold``."""


def _hold_settings() -> dict[str, Any] | None:
    """The hold tests of :data:`HOLD_SETTINGS` by name (None without MuJoCo)."""
    try:
        from sahgrasp.sim import (
            DEXGRASPBENCH_MASS_KG,
            LIGHT_SQUEEZE_N,
            HoldSettings,
            dexgraspbench_solver,
            soft_friction,
        )
    except ImportError:
        return None
    field = DEXGRASPBENCH_MASS_KG
    return {
        "default": HoldSettings(),
        "light": HoldSettings(squeeze_n=LIGHT_SQUEEZE_N),
        "default_0.1kg": HoldSettings(mass_kg=field),
        "light_0.1kg": HoldSettings(squeeze_n=LIGHT_SQUEEZE_N, mass_kg=field),
        "dexgraspbench": dexgraspbench_solver(HoldSettings()),
        "soft_friction": soft_friction(HoldSettings()),
    }


def _hold_rates(hand: Any, obj: Any, qs: list[Any], fingers: list[Any]) -> dict[str, Any] | None:
    """Hold rates of the returned grasps under :data:`HOLD_SETTINGS` (None without MuJoCo)."""
    settings = _hold_settings()
    if settings is None:
        return None
    from sahgrasp.sim.verify import hold_rates

    rates = hold_rates(hand, obj, qs, settings, fingers)
    crossed = zip(rates["default"]["held"], rates["dexgraspbench"]["held"], strict=True)
    return {
        **rates,
        "mass_kg": rates["default"]["mass_kg"],
        "default_not_dexgraspbench": sum(a and not b for a, b in crossed),
    }


class _FirstHold:
    """A planner check that records its first pass and the candidates solved at each pass.

    Attributes:
        first: ``perf_counter()`` at the first pass (None: none).
        candidates: Candidates solved so far (counted by :meth:`candidate`).
        passed_at: Per pass, the candidates solved when it was checked.
    """

    def __init__(self, check: Any) -> None:
        self.check = check
        self.first: float | None = None
        self.candidates = 0
        self.passed_at: list[int] = []

    def candidate(self) -> None:
        """One more candidate solved (the planner's ``on_candidate``)."""
        self.candidates += 1

    def __call__(self, grasp: Any) -> float | None:
        value = self.check(grasp)
        if value is not None:
            self.passed_at.append(self.candidates)
            if self.first is None:
                self.first = time.perf_counter()
        return value


def _verified_physics(
    hand: Any, load: Any, settings: Any, object_spec: dict[str, Any]
) -> dict[str, Any] | None:
    """``plan --verify physics`` on one object (module docstring); None without MuJoCo.

    Timed from before the object is loaded, the hold test's model compiled in the time. The
    returned grasps are then hold-tested in DexGraspBench's solver settings and with the light
    squeeze at 0.1 kg (untimed).
    """
    tests = _hold_settings()
    if tests is None:
        return None
    from sahgrasp.planner import plan_grasps
    from sahgrasp.planner.settings import CHECK_CANDIDATES_FACTOR
    from sahgrasp.sim.verify import PhysicsCheck, hold_rates

    cap = CHECK_CANDIDATES_FACTOR * settings.candidates
    start, cpu = time.perf_counter(), time.process_time()
    obj = load()
    physics = PhysicsCheck(hand, obj, tests["default"])
    check = _FirstHold(physics)
    plan = plan_grasps(
        hand, obj, settings, object_spec=object_spec, check=check, started=start,
        on_candidate=check.candidate, max_candidates=cap,
    )  # fmt: skip
    time_s, cpu_s = time.perf_counter() - start, time.process_time() - cpu
    s = plan.summary
    # The grasps that passed the check after the first batch of candidates: what a plan
    # without further batches returns (its selection is the first batch's).
    first_batch = sum(n <= settings.candidates for n in check.passed_at)
    rates = hold_rates(
        hand,
        obj,
        [g.q for g in plan.grasps],
        {name: tests[name] for name in ("dexgraspbench", "light_0.1kg")},
        [g.fingers for g in plan.grasps],
    )
    return {
        "requested": settings.grasps,
        "returned": s.grasps,
        "candidates": s.candidates,
        "max_candidates": cap,
        "verified": s.verified,
        "hold_checked": physics.checked,
        "hold_passed": sum(r.holds for r in physics.results.values()),
        "time_to_first_hold_s": None if check.first is None else check.first - start,
        "time_s": time_s,
        "cpu_s": cpu_s,
        "margins": [float(g.quality["check"]) for g in plan.grasps],
        "dexgraspbench": {k: rates["dexgraspbench"][k] for k in ("checked", "holds", "held")},
        "light_0.1kg": {k: rates["light_0.1kg"][k] for k in ("checked", "holds", "held")},
        "returned_first_batch": first_batch,
    }


ATLAS_OBJECTS = ("can", "bottle")
"""The objects of the atlas paper, whose atlas optimum the planner's best grasp is compared with."""


def atlas_comparison(hand: Any, name: str, settings: Any) -> dict[str, Any]:
    """The planner's best three-finger grasp of ``name`` vs the atlas optimum, per index.

    The atlas (``sahgrasp atlas NAME`` at its default radius) optimises over three-finger grasps
    (thumb, index, middle) with the object's twist taken at the object frame's origin; the
    planner's verified three-finger grasps are scored the same way (the indices at the object
    origin, not the centroid the plan reports) and the best of them, per index, is compared.
    """
    import dataclasses

    from sahgrasp.experiments.setups import run_experiment
    from sahgrasp.objects import load_object
    from sahgrasp.planner import plan_grasps
    from sahgrasp.planner.plan import manipulability_indices
    from sahgrasp.quality.ellipsoids import INDICES

    obj = load_object(name)
    three = dataclasses.replace(settings, fingers=(3,), grasps=settings.candidates)
    plan = plan_grasps(hand, obj, three)
    origin = obj.T_world_object[:3, 3]
    scored = [manipulability_indices(hand, g.q, g.fingers, origin) for g in plan.grasps]
    out: dict[str, Any] = {"object": name, "planner_grasps": len(scored), "indices": {}}
    for index in INDICES:
        result = run_experiment(name, index=index)
        atlas_best = float(result.values[result.best])
        best = max((s[index] for s in scored), default=None)
        out["indices"][index] = {
            "atlas_optimum": atlas_best,
            "atlas_charts": int(result.atlas.n_charts),
            "planner_best": best,
            "ratio": None if best is None else best / atlas_best,
        }
    return out


def _folder_run(hand: Any, jobs: list[Any], settings: Any, workers: int) -> dict[str, Any]:
    import resource
    from concurrent.futures import wait

    from sahgrasp.core.parallel import process_pool
    from sahgrasp.planner.folder import plan_jobs

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with process_pool(workers) as pool:
        # Each worker imports the planner and builds the hand before the clock starts (a
        # worker's start-up, once per run, not a cost of the objects).
        warm = time.perf_counter()
        started = [pool.submit(warm_worker, hand.description) for _ in range(workers)]
        wait(started)
        warm_up_s = time.perf_counter() - warm
        # Each worker's CPU seconds since its start, by process (two warm-ups may share one).
        start_up_cpu: dict[int, float] = {}
        for future in started:
            pid, cpu = future.result()
            start_up_cpu[pid] = max(cpu, start_up_cpu.get(pid, 0.0))
        start = time.perf_counter()
        docs = list(plan_jobs(hand.description, jobs, settings, pool, 2 * workers))
        seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)  # the workers, ended and reaped
    cpu_s = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    closure = sum(d["summary"]["verified_force_closure"] for d in docs if "summary" in d)
    verified = sum(d["summary"]["verified"] for d in docs if "summary" in d)
    return {
        "workers": workers,
        "objects": len(docs),
        "seconds": seconds,
        "verified": verified,
        "verified_force_closure": closure,
        "force_closure_per_s": closure / seconds,
        "verified_per_s": verified / seconds,
        "workers_cpu_s": cpu_s,
        "force_closure_per_cpu_s": closure / cpu_s if cpu_s > 0 else None,
        "warm_up_s": warm_up_s,
        "start_up_cpu_s": sum(start_up_cpu.values()),
        "force_closure_per_planning_cpu_s": (
            closure / (cpu_s - sum(start_up_cpu.values()))
            if cpu_s > sum(start_up_cpu.values())
            else None
        ),
    }


def _command_run(hand: str, target: str, scale: float, settings: Any, tmp: str) -> dict[str, Any]:
    """``sahgrasp plan TARGET`` in a fresh process: its times, from the process's start."""
    import json
    import subprocess
    import sys

    out = Path(tmp) / "command_plan.json"
    argv = [sys.executable, "-m", "sahgrasp", "plan", target, "--hand", hand, "--quiet"]
    argv += ["--candidates", str(settings.candidates), "--grasps", str(settings.grasps)]
    argv += ["--seed", str(settings.seed), "--json", str(out)]
    if scale != 1.0:
        argv += ["--scale", repr(scale)]
    start = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - start
    if done.returncode not in (0, 1) or not out.is_file():
        return {"command_time_to_first_s": None, "command_s": wall, "command_error": done.stderr}
    summary = json.loads(out.read_text(encoding="utf-8"))["summary"]
    out.unlink()
    return {"command_time_to_first_s": summary["time_to_first_s"], "command_s": wall}


def warm_worker(description: Any) -> tuple[int, float]:
    """A worker's start-up, once per hand and process.

    The planner's modules imported; the hand, its reach, the IK's initial-pose sequence and
    grasp database loaded. Returns the worker's process id and its CPU seconds so far.
    """
    from sahgrasp.ik import worker_hand
    from sahgrasp.ik.initial import default_sequence
    from sahgrasp.ik.learned import default_database
    from sahgrasp.planner.candidates import hand_reach
    from sahgrasp.planner.plan import plan_grasps  # noqa: F401

    hand = worker_hand(description, description.digest())
    hand_reach(hand)
    default_sequence(hand)
    default_database(hand)
    return os.getpid(), time.process_time()


def run(
    hand: str = DEFAULT_HAND,
    objects: Sequence[str] | None = None,
    meshes: Sequence[str] = (),
    folder: str | None = None,
    test_meshes: bool = True,
    candidates: int = 60,
    grasps: int = 10,
    seed: int = 0,
    rank: str = "weight",
    workers: Sequence[int] = (1, 2),
    atlas: bool = True,
    quiet: bool = False,
    commands: bool = True,
    verify_physics: bool = True,
) -> dict[str, Any]:
    """Run the benchmark; return its JSON document (module docstring).

    Args:
        hand: Hand name or description file.
        objects: Catalog objects (default: all).
        meshes: More mesh files (default: the shipped ones, from ``examples/meshes``).
        folder: A folder of mesh files (metres) to add.
        test_meshes: Add the generated test meshes.
        candidates: The planner's candidate budget per object.
        grasps: Grasps returned per object.
        seed: The plan seed.
        rank: What the planner ranks grasps by (:data:`sahgrasp.planner.settings.RANKINGS`).
        workers: Worker counts of the folder run (empty: no folder run).
        atlas: Compare with the atlas optimum on the can and the bottle (when among the objects).
        quiet: No progress bar.
        commands: Also run ``sahgrasp plan`` on each object in a fresh process and record the
            seconds from the process's start (interpreter, imports, hand, mesh: all included)
            to its first verified force-closure grasp.
        verify_physics: Also plan each object with ``--verify physics`` (with MuJoCo).
    """
    from tqdm import tqdm

    from sahgrasp.model.hand import load_hand
    from sahgrasp.objects import OBJECT_NAMES, load_mesh, load_object
    from sahgrasp.planner import PlanSettings
    from sahgrasp.planner.folder import ObjectJob, object_digest

    the_hand = load_hand(hand)
    settings = PlanSettings(candidates=candidates, grasps=grasps, seed=seed, rank=rank)
    names = list(OBJECT_NAMES if objects is None else objects)
    shipped = Path(__file__).resolve().parents[2] / "examples" / "meshes"
    files: dict[str, float] = {}
    if not meshes:
        files.update({str(shipped / m): 1.0 for m in SHIPPED_MESHES if (shipped / m).is_file()})
    files.update({str(Path(m).resolve()): 1.0 for m in meshes})
    if folder is not None:
        from sahgrasp.objects.mesh_file import MESH_SUFFIXES

        files.update(
            {
                str(p): 1.0
                for p in sorted(Path(folder).iterdir())
                if p.suffix.lower() in MESH_SUFFIXES
            }
        )
    with tempfile.TemporaryDirectory(prefix="sahgrasp-bench-plan-") as tmp:
        if test_meshes:
            files.update({str(Path(tmp) / n): s for n, s in write_test_meshes(tmp).items()})
        rows = []
        total = len(names) + len(files)
        with tqdm(total=total, unit="object", disable=True if quiet else None) as bar:
            for name in names:
                rows.append(
                    _object_row(
                        the_hand,
                        name,
                        lambda n=name: load_object(n),
                        settings,
                        {"name": name},
                        verify_physics,
                    )
                )
                bar.update()
            for path, scale in files.items():
                spec = {"mesh": path, **({"scale": scale} if scale != 1.0 else {})}
                rows.append(
                    _object_row(
                        the_hand,
                        Path(path).name,
                        lambda p=path, s=scale: load_mesh(p, scale=s),
                        settings,
                        spec,
                        verify_physics,
                    )
                )
                bar.update()
        jobs = [
            ObjectJob(p, 1.0, object_digest(p, settings, 1.0, the_hand.description.name))
            for p, s in files.items()
            if s == 1.0
        ]
        runs = [_folder_run(the_hand, jobs, settings, w) for w in workers] if jobs else []
        if commands:
            targets = [(n, 1.0) for n in names] + list(files.items())
            for row, (target, scale) in zip(rows, targets, strict=True):
                row.update(_command_run(hand, target, scale, settings, tmp))
    comparison = [
        atlas_comparison(the_hand, n, settings) for n in ATLAS_OBJECTS if atlas and n in names
    ]
    firsts = [r["time_to_first_s"] for r in rows]
    reached = [t for t in firsts if t is not None]
    commanded = [r["command_time_to_first_s"] for r in rows if "command_time_to_first_s" in r]
    commanded_reached = [t for t in commanded if t is not None]
    speedup = None
    by_workers = {r["workers"]: r for r in runs}
    if 1 in by_workers and 2 in by_workers:
        speedup = by_workers[2]["force_closure_per_s"] / by_workers[1]["force_closure_per_s"]
    return {
        "benchmark": "plan",
        "hand": the_hand.description.name,
        "settings": settings.to_dict(),
        "objects": rows,
        "summary": {
            "objects": len(rows),
            "with_force_closure_grasp": len(reached),
            "share_with_force_closure_grasp": len(reached) / len(rows) if rows else 0.0,
            "median_time_to_first_s": float(median(reached)) if reached else None,
            "median_command_time_to_first_s": (
                float(median(commanded_reached)) if commanded_reached else None
            ),
            "returned_failing_recheck": sum(r["returned_failing_recheck"] for r in rows),
            "returned": sum(r["returned"] for r in rows),
            "hold": hold_summary(rows),
            "verify_physics": verify_summary(rows),
        },
        "folder_runs": runs,
        "atlas_comparison": comparison,
        "speedup_2_workers": speedup,
        "load_average": list(os.getloadavg()),
    }


HOLD_TARGETS = {"default": 0.95, "light": 0.80, "default_0.1kg": 0.95, "light_0.1kg": 0.80}
"""The hold-rate targets per object of the planner's top grasps (the default squeeze and light)."""


def hold_summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """Per hold test of :data:`HOLD_SETTINGS`: grasps held, and objects at their target rate.

    ``objects_at_target``: objects whose returned grasps hold at :data:`HOLD_TARGETS`' rate or
    above (the cross-check has no target of its own); ``default_not_dexgraspbench``: grasps
    that hold with the default settings but not in DexGraspBench's solver settings.
    """
    holds = [r["hold"] for r in rows if r.get("hold") is not None]
    if not holds:
        return None
    out: dict[str, Any] = {}
    for key in HOLD_SETTINGS:
        present = [h[key] for h in holds if key in h and h[key]["checked"]]
        target = HOLD_TARGETS.get(key)
        out[key] = {
            "holds": sum(h["holds"] for h in present),
            "checked": sum(h["checked"] for h in present),
            "objects": len(present),
            "target": target,
            "objects_at_target": (
                None if target is None else sum(h["hold_rate"] >= target for h in present)
            ),
        }
    out["default_not_dexgraspbench"] = sum(h.get("default_not_dexgraspbench", 0) for h in holds)
    return out


def verify_summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """Totals of ``plan --verify physics`` over the objects (None when not run).

    ``objects_complete``: objects with as many holding grasps as asked (``objects_complete_first
    _batch``: within the first batch of candidates); ``dexgraspbench_share``: the returned
    grasps that hold in DexGraspBench's solver settings, of all returned.
    """
    runs = [r["verify_physics"] for r in rows if r.get("verify_physics") is not None]
    if not runs:
        return None
    returned = sum(v["returned"] for v in runs)
    crossed = sum(v["dexgraspbench"]["holds"] for v in runs)
    return {
        "objects": len(runs),
        "objects_complete": sum(v["returned"] == v["requested"] for v in runs),
        "objects_complete_first_batch": sum(
            v["returned_first_batch"] == v["requested"] for v in runs
        ),
        "objects_without_grasp": sum(v["returned"] == 0 for v in runs),
        "requested": sum(v["requested"] for v in runs),
        "returned": returned,
        "returned_first_batch": sum(v["returned_first_batch"] for v in runs),
        "dexgraspbench_holds": crossed,
        "dexgraspbench_share": crossed / returned if returned else None,
        "light_0.1kg_holds": sum(v["light_0.1kg"]["holds"] for v in runs),
        "time_s": sum(v["time_s"] for v in runs),
    }


def _verify_cells(v: dict[str, Any] | None) -> tuple[Any, ...]:
    if v is None:
        return ("-",) * 6
    full = v["returned"] == v["requested"]
    first = v["time_to_first_hold_s"]
    return (
        f"{v['returned_first_batch']}/{v['requested']}",
        f"{v['returned']}/{v['requested']} ({v['candidates']} cand.)"
        + ("" if full else ", too few hold"),
        f"{v['dexgraspbench']['holds']}/{v['dexgraspbench']['checked']}",
        f"{v['light_0.1kg']['holds']}/{v['light_0.1kg']['checked']}",
        "-" if first is None else round(first, 2),
        round(v["time_s"], 1),
    )


def _hold_cells(hold: dict[str, Any] | None) -> tuple[Any, ...]:
    if hold is None:
        # The mass, a rate per hold test, the cross-check count, the failures, the speed.
        return ("-",) * (len(HOLD_SETTINGS) + 4)

    def rate(row: dict[str, Any]) -> str:
        if not row["checked"]:
            return "-"
        return f"{round(100 * row['hold_rate'])}% ({row['holds']}/{row['checked']})"

    speed = hold["default"]["checks_per_cpu_s"]
    # Rows of an older document lack the 0.1 kg, cross-check and soft-friction columns.
    extra = [rate(hold[k]) if k in hold else "-" for k in HOLD_SETTINGS[2:]]
    return (
        round(hold["mass_kg"], 3),
        rate(hold["default"]),
        rate(hold["light"]),
        *extra,
        hold.get("default_not_dexgraspbench", "-"),
        _reasons(hold["default"]),
        "-" if speed is None else round(speed),
    )


def _reasons(row: dict[str, Any]) -> str:
    return ", ".join(f"{k} {v}" for k, v in row.get("reasons", {}).items()) or "-"


def format_table(doc: dict[str, Any]) -> str:
    """The benchmark's summary table."""
    from sahgrasp.core.tables import format_table as table

    rows = []
    for r in doc["objects"]:
        f = r["by_fingers"]
        first = r["time_to_first_s"]
        command = r.get("command_time_to_first_s")
        rows.append(
            (
                r["object"],
                r["faces"],
                "-" if first is None else round(first, 3),
                "-" if command is None else round(command, 3),
                round(r["verified_per_s"], 1),
                round(r["force_closure_per_cpu_s"], 1),
                round(100 * r["force_closure_share"]),
                round(r["median_epsilon"], 4),
                round(r["best_epsilon"], 4),
                f"{f.get('2', 0)}/{f.get('3', 0)}/{f.get('4', 0)}",
                r["returned_failing_recheck"],
                *_hold_cells(r.get("hold")),
                *_verify_cells(r.get("verify_physics")),
            )
        )
    headers = (
        "object",
        "faces",
        "first FC [s]",
        "command first FC [s]",
        "verified/s",
        "FC/CPU s",
        "FC [%]",
        "median eps",
        "best eps",
        "2/3/4 fingers",
        "re-check fails",
        "mass [kg]",
        "holds (default)",
        "holds (light)",
        "holds 0.1 kg",
        "holds light 0.1 kg",
        "holds (DexGraspBench solver)",
        "holds (soft friction)",
        "default, not DGB",
        "failures (default)",
        "checks/CPU s",
        "verified in physics, first batch",
        "verified in physics (<= 4x candidates)",
        "of them DexGraspBench",
        "of them light 0.1 kg",
        "first hold [s]",
        "verify time [s]",
    )
    s = doc["summary"]
    first = s["median_time_to_first_s"]
    lines = [
        f"bench plan: {doc['hand']}, {s['objects']} objects, {doc['settings']['candidates']} "
        f"candidates each, seed {doc['settings']['seed']}",
        table(headers, rows),
        f"objects with a verified force-closure grasp: {s['with_force_closure_grasp']}/"
        f"{s['objects']} ({100 * s['share_with_force_closure_grasp']:.0f}%); median time to "
        f"it: {'-' if first is None else f'{first:.3f} s'}; returned grasps failing the "
        f"re-check: {s['returned_failing_recheck']}/{s['returned']}",
    ]
    hold = s.get("hold")
    if hold is not None:
        parts = []
        for key in HOLD_SETTINGS:
            h = hold[key]
            at = "" if h["target"] is None else (
                f", {h['objects_at_target']}/{h['objects']} objects >= {100 * h['target']:.0f}%"
            )  # fmt: skip
            parts.append(f"{key} {h['holds']}/{h['checked']}{at}")
        lines.append("grasps held: " + "; ".join(parts))
        lines.append(
            "held by default but not in DexGraspBench's solver settings: "
            f"{hold['default_not_dexgraspbench']}"
        )
    verified = s.get("verify_physics")
    if verified is not None:
        share = verified["dexgraspbench_share"]
        lines.append(
            f"plan --verify physics: objects with {doc['settings']['grasps']} holding grasps "
            f"{verified['objects_complete']}/{verified['objects']} "
            f"({verified['objects_complete_first_batch']} within the first "
            f"{doc['settings']['candidates']} candidates), none: "
            f"{verified['objects_without_grasp']}; grasps returned {verified['returned']}/"
            f"{verified['requested']} ({verified['returned_first_batch']} from the first batch); "
            f"of them holding in DexGraspBench's solver settings {verified['dexgraspbench_holds']}"
            f" ({'-' if share is None else f'{100 * share:.0f}%'}), with the light squeeze at "
            f"0.1 kg {verified['light_0.1kg_holds']}; {verified['time_s']:.0f} s in all"
        )
    command = s.get("median_command_time_to_first_s")
    if command is not None:
        lines.append(
            f"median time to it from the start of 'sahgrasp plan OBJECT' (a fresh process: "
            f"interpreter, imports, hand and mesh included): {command:.3f} s"
        )
    for r in doc["folder_runs"]:
        lines.append(
            f"folder, {r['workers']} worker(s): {r['objects']} objects in {r['seconds']:.1f} s, "
            f"{r['force_closure_per_s']:.1f} verified force-closure grasps/s "
            f"({r['verified_per_s']:.1f} verified grasps/s); workers' CPU "
            f"{r['workers_cpu_s']:.1f} s (their start-up included, {r['warm_up_s']:.1f} s wall "
            "before the clock), "
            f"{r['force_closure_per_cpu_s'] or 0.0:.1f} force-closure grasps per CPU second, "
            f"{r['force_closure_per_planning_cpu_s'] or 0.0:.1f} per CPU second of planning "
            f"(start-up, {r['start_up_cpu_s']:.1f} s, left out)"
        )
    for c in doc.get("atlas_comparison", []):
        parts = [
            f"{i} {v['planner_best']:.4g} vs {v['atlas_optimum']:.4g}"
            if v["planner_best"] is not None
            else f"{i} - vs {v['atlas_optimum']:.4g}"
            for i, v in c["indices"].items()
        ]
        lines.append(
            f"{c['object']}, best 3-finger grasp, planner vs atlas optimum: " + "; ".join(parts)
        )
    if doc["speedup_2_workers"] is not None:
        lines.append(f"1 -> 2 workers: {doc['speedup_2_workers']:.2f}x")
    load = doc["load_average"]
    lines.append(f"load average at the end: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}")
    return "\n".join(lines)
