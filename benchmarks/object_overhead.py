"""The cost of the object in the IK on the paper grasps: CPU time with / without ``obstacle=``.

Prints a Markdown table (docs/methods/ik.md): per paper grasp (and the can's three-finger grasp
with the
ring finger free), the CPU time of one solve without and with the object (best of ``--repeats``
rounds of ``--calls`` solves each, both runs interleaved per round so that a change of machine
load affects both alike), their ratio, and the clearance and closest link the IK reports.

    python benchmarks/object_overhead.py [--repeats 3] [--calls 5]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

from sahgrasp.ik import IKResult, solve_ik
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects import GRASP_NAMES, GraspObject, load_object, paper_grasp


def _cpu_s(solve: Callable[[], IKResult], calls: int) -> float:
    start = time.process_time()
    for _ in range(calls):
        solve()
    return (time.process_time() - start) / calls


def _row(
    hand: Hand, label: str, target: GraspTarget, obj: GraspObject, free: tuple[str, ...],
    repeats: int, calls: int,
) -> str:  # fmt: skip
    def plain() -> IKResult:
        return solve_ik(hand, target, free_fingers=free)

    def checked() -> IKResult:
        return solve_ik(hand, target, free_fingers=free, obstacle=obj)

    result = checked()  # builds the object's pieces once, before any timing
    plain()
    rounds = [(_cpu_s(plain, calls), _cpu_s(checked, calls)) for _ in range(repeats)]
    without, with_object = min(r[0] for r in rounds), min(r[1] for r in rounds)
    clearance = (
        "-" if result.object_clearance_m is None else f"{result.object_clearance_m * 1e3:.2f} mm"
    )
    return (
        f"| {label} | {without * 1e3:.2f} ms | {with_object * 1e3:.2f} ms | "
        f"{with_object / without:.2f} | {result.inits_used} | {clearance} | {result.closest_link} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="rounds; the best one counts")
    parser.add_argument("--calls", type=int, default=5, help="solves per round and run")
    args = parser.parse_args()
    hand = load_hand("sah")
    print("| grasp | without | with the object | ratio | starts | clearance | closest link |")
    print("|---|---|---|---|---|---|---|")
    for name in GRASP_NAMES:
        obj = load_object(name)
        label = f"{name} ({len(obj.collision_shapes())} pieces)"
        print(_row(hand, label, paper_grasp(name), obj, (), args.repeats, args.calls))
    can = paper_grasp("can")
    three = GraspTarget("can, ring free", [c for c in can.contacts if c.finger != "ring"])
    print(_row(hand, "can, 3 fingers, ring free", three, load_object("can"), ("ring",),
               args.repeats, args.calls))  # fmt: skip


if __name__ == "__main__":
    main()
