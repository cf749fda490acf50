"""``sahgrasp info``: the hand's fingers, joints, limits, couplings, DoF and contact region."""

from __future__ import annotations

import argparse
import math
from typing import Any

from sahgrasp.cli.common import emit_json
from sahgrasp.hand import Hand, load_hand

__all__ = ["add_parser", "describe", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = sub.add_parser("info", help="describe a hand model")
    p.add_argument("--hand", default="sah", help="sah, allegro, or a hand-description JSON path")
    p.add_argument("--json", nargs="?", const="-", default=None, metavar="OUT",
                   help="print JSON (or write it to OUT)")  # fmt: skip
    p.set_defaults(run=run)


def describe(hand: Hand) -> dict[str, Any]:
    """The hand's description as a JSON-able dict."""
    d = hand.description
    limits = dict(zip(hand.coordinate_names, zip(hand.lower, hand.upper, strict=True), strict=True))
    return {
        "hand": d.name,
        "urdf": str(d.urdf_path),
        "digest": d.digest(),
        "fingers": {f.name: {"tip_link": f.tip_link} for f in d.fingers},
        "fingertip_radius_m": d.fingertip_radius_m,
        "contact_region_rad": {
            "pitch": list(d.contact_pitch_limits_rad),
            "yaw": list(d.contact_yaw_limits_rad),
        },
        "joints": {
            n: {"lower": float(limits[n][0]), "upper": float(limits[n][1])}
            for n in hand.joint_names
        },
        "mimic": {
            m: {"leader": lead, "multiplier": k, "offset": o}
            for m, (lead, k, o) in hand.mimic_joints.items()
        },
        "virtual_joints": {
            n: {"lower": float(limits[n][0]), "upper": float(limits[n][1])}
            for n in hand.virtual_joint_names
        },
        "dof": hand.dof(),
        "self_collision_pairs": len(hand.collision.pairs),
    }


def _print_text(info: dict[str, Any]) -> None:
    deg = 180.0 / math.pi
    dof = info["dof"]
    print(f"hand {info['hand']}  ({info['urdf']})")
    print(f"DoF: wrist {dof['wrist']} + fingers {dof['fingers']} + virtual {dof['virtual']}"
          f" = {dof['total']}")  # fmt: skip
    print(f"fingertip radius: {info['fingertip_radius_m'] * 1000:.1f} mm")
    region = info["contact_region_rad"]
    print(
        "contact region: pitch {:.0f}..{:.0f} deg, yaw {:.0f}..{:.0f} deg".format(
            *(v * deg for v in region["pitch"] + region["yaw"])
        )
    )
    print("fingers: " + ", ".join(f"{n} ({v['tip_link']})" for n, v in info["fingers"].items()))
    print("joints [deg]:")
    for name, lim in {**info["joints"], **info["virtual_joints"]}.items():
        print(f"  {name:22s} {lim['lower'] * deg:8.2f} .. {lim['upper'] * deg:8.2f}")
    for name, m in info["mimic"].items():
        print(f"  {name:22s} = {m['multiplier']:g} * {m['leader']} + {m['offset']:g}")
    print(f"self-collision pairs checked: {info['self_collision_pairs']}")


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp info``."""
    info = describe(load_hand(args.hand))
    if args.json is None:
        _print_text(info)
    else:
        emit_json(info, args.json)
    return 0
