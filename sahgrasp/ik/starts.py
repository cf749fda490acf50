"""The initial configurations of one problem, drawn lazily and seeded by the problem's content.

A problem's random starts depend only on the settings' ``seed`` and on what the problem is (its
name and contacts), never on where it stands in a list or which worker solves it:
:func:`problem_seed` mixes the seed with a SHA-256 digest of the problem's exact content.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

import numpy as np

from sahgrasp.ik.initial import Sequence
from sahgrasp.model.contacts import GraspTarget

__all__ = ["initial_lambdas", "problem_digest", "problem_seed"]


def problem_digest(target: GraspTarget) -> bytes:
    """SHA-256 of the problem's name and contacts (fingers sorted, exact float64 bits).

    The contacts are sorted by finger, so listing them in another order is the same problem.
    """
    chunks = [target.name.encode("utf-8", "surrogatepass")]
    for contact in sorted(target.contacts, key=lambda c: c.finger):
        chunks.append(contact.finger.encode("utf-8", "surrogatepass"))
        chunks.append(np.asarray([contact.point, contact.normal], dtype="<f8").tobytes())
    # Length-prefixed, so that no two different problems hash the same concatenation.
    return hashlib.sha256(b"".join(len(c).to_bytes(8, "little") + c for c in chunks)).digest()


def problem_seed(seed: int, target: GraspTarget) -> int:
    """The 64-bit seed of ``target``'s random starts under the settings' ``seed`` (>= 0)."""
    words = np.frombuffer(problem_digest(target), dtype="<u4")
    state = np.random.SeedSequence([seed, *words.tolist()]).generate_state(1, np.uint64)
    return int(state[0])


def initial_lambdas(
    init: str, max_inits: int, seed: int, sequence: Sequence, target: GraspTarget
) -> Iterator[tuple[float, float]]:
    """The ``max_inits`` lambdas of Algorithm 1's starts, one at a time (nothing built up front).

    Args:
        init: ``"sequence"`` cycles through ``sequence.lambdas``; ``"random"`` draws each pair
            uniformly in [0, 1)^2 from :func:`problem_seed`.
        max_inits: Starts to yield at most.
        seed: The settings' seed.
        sequence: The pose sequence.
        target: The problem (seeds the random starts).
    """
    if init == "random":
        rng = np.random.default_rng(problem_seed(seed, target))
        for _ in range(max_inits):
            a, b = rng.uniform(0.0, 1.0, 2)
            yield float(a), float(b)
        return
    lambdas = sequence.lambdas
    for i in range(max_inits):
        yield lambdas[i % len(lambdas)]
