"""A hand's reach for the contact samplers: measured (the hand registry) or derived from its model.

The samplers draw contact sets a hand can span: neighbouring finger contacts a finger spacing apart
and the thumb within the hand's span of the fingers. A hand's registry entry may give a reach
measured with the IK (:class:`~sahgrasp.model.hands.SamplerReach`); otherwise
:func:`derive_reach` bounds it from the model's kinematics.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pinocchio as pin

from sahgrasp.model.hand import Hand
from sahgrasp.model.hands import hand_entry
from sahgrasp.objects.grasp_sampler import HandReach, registered_reach

__all__ = ["derive_reach", "finger_set", "hand_reach", "sampler_reach"]

_REACH_SAMPLES = 1000
"""Random configurations whose fingertip distances bound a hand's span."""
_FACING_COS = math.cos(math.radians(45.0))
"""Thumb and finger pads within 45 degrees of facing each other count for the span."""


def finger_set(hand: Hand, count: int) -> tuple[str, ...]:
    """The fingers of a ``count``-finger grasp: the thumb, then the others in the hand's order.

    Raises:
        ValueError: The hand has fewer than ``count`` fingers.
    """
    names = list(hand.fingers)
    if count > len(names) or count < 2:
        raise ValueError(f"a {count}-finger grasp needs 2..{len(names)} fingers on this hand")
    thumb = "thumb" if "thumb" in names else names[0]
    others = [f for f in names if f != thumb]
    return (thumb, *others[: count - 1])


def hand_reach(hand: Hand) -> HandReach:
    """A hand's reach derived from its model (:func:`derive_reach`), once per hand (``hand.cache``).

    The planner's draw uses it for every hand.
    """
    return hand.cache.get("derived_reach", lambda: derive_reach(hand))


def sampler_reach(hand: Hand) -> HandReach:
    """The contact sampler's reach of ``hand``: its registry entry's measured reach, if it has one.

    A hand whose entry gives no reach (or that is not registered) gets :func:`hand_reach`, derived
    from its model.
    """
    entry = hand_entry(hand.description.name)
    if entry is None or entry.reach is None:
        return hand_reach(hand)
    return registered_reach(entry.name)


def derive_reach(hand: Hand) -> HandReach:
    """A hand's spacing, span and fingertip radius, derived from its model.

    Finger spacing: from 0.7 to 1.0 times the mean distance between the bases of neighbouring
    non-thumb fingers (for the SAH, 28-40 mm, as measured with the IK). Span: up to the largest
    thumb-to-finger contact distance (fingertip centres, less two radii) over random
    configurations whose thumb and finger pads face each other within 45 degrees (a bound for
    the draw: the IK decides).
    """
    model, data = hand.model, hand.model.createData()
    pin.forwardKinematics(model, data, hand.configuration())
    thumb = finger_set(hand, 2)[0]
    bases = []
    for finger in hand.fingers:
        if finger == thumb:
            continue
        first = int(hand.finger_coordinates[finger][0])
        joint = model.getJointId(hand.coordinate_names[first])
        bases.append(np.array(data.oMi[joint].translation))
    gaps = [float(np.linalg.norm(a - b)) for a, b in itertools.pairwise(bases)]
    spacing = float(np.mean(gaps)) if gaps else 0.04
    rng = np.random.default_rng(0)
    specs = dict(zip(hand.fingers, hand.description.fingers, strict=True))
    frames = {f: model.getFrameId(s.tip_link) for f, s in specs.items()}
    others = [f for f in hand.fingers if f != thumb]
    # The same draws as hand.random_configuration(rng, identity) one after the other (a
    # Generator fills an array in order), assembled at once: q = identity wrist + coordinates.
    coordinates = rng.uniform(hand.lower, hand.upper, size=(_REACH_SAMPLES, len(hand.lower)))
    q = np.zeros((_REACH_SAMPLES, model.nq))
    q[:, 6] = 1.0
    q[:, 7:] = coordinates
    positions = {f: np.empty((_REACH_SAMPLES, 3)) for f in hand.fingers}
    pads = {f: np.empty((_REACH_SAMPLES, 3)) for f in hand.fingers}
    for k in range(_REACH_SAMPLES):
        pin.framesForwardKinematics(model, data, q[k])
        for f in hand.fingers:
            placement = data.oMf[frames[f]]
            positions[f][k] = placement.translation
            pads[f][k] = placement.rotation @ np.array(specs[f].pad_axis)
    span = 0.0
    for f in others:
        gap = positions[f] - positions[thumb]
        facing = np.einsum("ij,ij->i", pads[thumb], pads[f])
        # Pads facing each other (an opposition grasp), the finger in front of the thumb pad.
        ok = (facing < -_FACING_COS) & (np.einsum("ij,ij->i", gap, pads[thumb]) > 0.0)
        if ok.any():
            span = max(span, float(np.linalg.norm(gap[ok], axis=1).max()))
    span = span - 2.0 * hand.radius_m if span > 2.0 * hand.radius_m else 0.15
    return HandReach(
        finger_spacing_m=(0.7 * spacing, spacing),
        span_m=(1e-3, span),
        fingertip_radius_m=hand.radius_m,
    )
