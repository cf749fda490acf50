"""``sahgrasp info``: the hand's fingers, joints, limits, couplings, DoF and contact region."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

from sahgrasp.cli.common import (
    HAND_HELP,
    add_command,
    check_json_inputs,
    check_outputs,
    emit_json,
    printable,
)
from sahgrasp.model.hands import DEFAULT_HAND

if TYPE_CHECKING:
    from sahgrasp.model.hand import Hand

__all__ = ["add_parser", "describe", "run"]


def add_parser(sub: Any) -> None:
    """Register the subcommand."""
    p = add_command(sub, "info", "describe a hand model")
    p.add_argument("--hand", default=DEFAULT_HAND, help=HAND_HELP)
    p.add_argument(
        "--json",
        nargs="?",
        const="-",
        default=None,
        metavar="OUT",
        help="print the description as JSON on stdout (or write it to OUT)",
    )
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


def _say(line: str) -> None:
    """Print a line; names from a user's hand description could hold terminal escapes."""
    print(printable(line))


def _print_text(info: dict[str, Any]) -> None:
    deg = 180.0 / math.pi
    dof = info["dof"]
    _say(f"hand {info['hand']}  ({info['urdf']})")
    _say(f"DoF: wrist {dof['wrist']} + fingers {dof['fingers']} + virtual {dof['virtual']}"
         f" = {dof['total']}")  # fmt: skip
    _say(f"fingertip radius: {info['fingertip_radius_m'] * 1000:.1f} mm")
    region = info["contact_region_rad"]
    _say(
        "contact region: pitch {:.0f}..{:.0f} deg, yaw {:.0f}..{:.0f} deg".format(
            *(v * deg for v in region["pitch"] + region["yaw"])
        )
    )
    _say("fingers: " + ", ".join(f"{n} ({v['tip_link']})" for n, v in info["fingers"].items()))
    _say("joints [deg]:")
    for name, lim in {**info["joints"], **info["virtual_joints"]}.items():
        _say(f"  {name:22s} {lim['lower'] * deg:8.2f} .. {lim['upper'] * deg:8.2f}")
    for name, m in info["mimic"].items():
        _say(f"  {name:22s} = {m['multiplier']:g} * {m['leader']} + {m['offset']:g}")
    _say(f"self-collision pairs checked: {info['self_collision_pairs']}")


def run(args: argparse.Namespace) -> int:
    """Execute ``sahgrasp info``."""
    from sahgrasp.model.hand import load_hand

    check_outputs([args.json], inputs=[args.hand])
    check_json_inputs(args.hand)
    info = describe(load_hand(args.hand))
    if args.json is None:
        _print_text(info)
    else:
        emit_json(info, args.json)
    return 0
