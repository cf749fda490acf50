"""Random feasible IK problems: read the contacts off a random valid hand configuration."""

from __future__ import annotations

import numpy as np

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand

__all__ = ["random_problem", "random_problems"]


def random_problem(hand: Hand, seed: int, index: int) -> GraspTarget:
    """Problem ``index`` of the stream ``seed``: the same whatever else is drawn.

    A collision-free configuration is drawn with every joint uniform in its range (virtual
    contact joints inside the contact region) and a uniformly random wrist orientation at a random
    position in a 0.2 m cube; its contact points and the object normals (opposite to the
    fingertip normals) form the target, and the configuration is forgotten.
    """
    for name, value in (("seed", seed), ("index", index)):
        _check_count(name, value)
    rng = np.random.default_rng([seed, index])
    q = hand.random_configuration(rng, collision_free=True)
    q[:3] = rng.uniform(-0.1, 0.1, 3)
    state = hand.contact_state(q)
    contacts = [
        ContactTarget(f, state.points[i], _unit(-state.normals[i]))
        for i, f in enumerate(hand.fingers)
    ]
    return GraspTarget(f"random-{seed}-{index}", contacts)


def random_problems(hand: Hand, count: int, seed: int, start: int = 0) -> list[GraspTarget]:
    """Problems ``start .. start + count - 1`` of the stream ``seed``.

    Raises:
        InvalidSettingsError: ``count``, ``seed`` or ``start`` is not an integer >= 0.
    """
    for name, value in (("count", count), ("seed", seed), ("start", start)):
        _check_count(name, value)
    return [random_problem(hand, seed, i) for i in range(start, start + count)]


def _check_count(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise InvalidSettingsError(f"{name} must be an integer >= 0, got {value!r}")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)
