"""The object a grasp must not pass through, as the IK sees it (issue: IK with the object).

Every hand link must stay outside the object, except the fingertip sphere of each finger that has
a contact: it touches the object at its contact by design, and Eq. (9) accepts its contact point
up to ``d_min`` from the target, so that sphere alone may penetrate by up to ``d_min``. The
signed distances come from :class:`sahgrasp.objects.clearance.HandObjectClearance` (coal GJK/EPA
between each link shape and the object's convex pieces); its penetration records have the object
as body ``a`` (joint 0, fixed), so the IK's separation rows push the links out along the normals.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from sahgrasp.collision import Penetration
from sahgrasp.errors import InvalidTargetError
from sahgrasp.hand import Hand

# The objects package is imported on first use: it adds 0.2 s to ``import sahgrasp``, and only
# solves with an obstacle need it.
if TYPE_CHECKING:
    from sahgrasp.objects import GraspObject
    from sahgrasp.objects.clearance import Clearance, HandObjectClearance

__all__ = ["REPAIR_PAIRS_PER_LINK", "Obstacle", "check_obstacle", "checker_of"]

REPAIR_PAIRS_PER_LINK = 1
"""Most (link, piece) pairs one link adds to a collision-repair step.

A link deep in a finely cut object overlaps many pieces (the coffee cup's revolved sectors, a
mesh's joined prisms); a row per pair costs a GJK call and a Jacobian each, for normals that
mostly agree. With one pair per link the repair query is one coal collision test per link in
the piece tree (``HandObjectClearance.penetrations`` with ``per_link=1``), the first pair that
test finds. Measured with ``sahgrasp bench grasps`` (200 sets each of the coffee cup and the mug
mesh, ``--workers 1``): 87 and 74 solved with one pair per link against 88 and 70 with four
pairs (taken by increasing lower bound), 0 claimed solutions penetrating either way; the repair
query took 298 instead of 1099 us on the coffee cup and 229 instead of 788 us on the mug
(docs/benchmarks.md, "Sixth round"). Four pairs per link had been measured against every pair
(22 against 23 solved on 40 sets, 16.8 s against 47.3 s of CPU) when the objects had one piece
per band sector or mesh triangle.
"""


@functools.lru_cache(maxsize=8)
def checker_of(hand: Hand, obj: GraspObject | None) -> HandObjectClearance:
    """One clearance checker per (hand, object) pair, by identity (None: no object).

    Building one (about 0.7 ms without an object, for placing free fingers) builds the piece
    tree (up to 0.04 s for the catalog objects) and, on the object's first use, its convex pieces
    (0.01 s for the can, 0.15 s for the coffee cup, 1.6-2.2 s for the shipped meshes, whose
    triangle prisms are merged): too much to repeat for every problem.
    """
    from sahgrasp.objects.clearance import HandObjectClearance

    return HandObjectClearance(hand, obj)


def check_obstacle(obj: object) -> None:
    """Raise :class:`InvalidTargetError` unless ``obj`` is a GraspObject."""
    from sahgrasp.objects import GraspObject

    if not isinstance(obj, GraspObject):
        raise InvalidTargetError(
            f"obstacle must be a GraspObject (sahgrasp.objects: load_object(name) or a loaded "
            f"mesh), got {type(obj).__name__}"
        )


class Obstacle:
    """An object at its placement, the fingers in contact with it and their allowance.

    One definition decides whether a configuration is inside the object, for the solver's
    acceptance test and for the clearance it reports: :meth:`HandObjectClearance.clearance`
    with the contact fingers and the allowance. :meth:`penetrated` asks
    :meth:`HandObjectClearance.clearance_if_clear`, which gives a clear configuration's exact
    clearance and only the verdict for one inside; the clearance is kept, so the result's
    clearance of an accepted start costs no second query, and a rejected start's is measured
    only if the result reports it.

    Args:
        hand: The hand.
        obj: The object (a :class:`sahgrasp.objects.GraspObject`, placed in the world).
        contacts: Fingers whose fingertip spheres touch the object at their contacts.
        allowance_m: How deep those spheres may enter the object [m] (the IK's ``d_min``).

    Raises:
        InvalidTargetError: ``obj`` is not a GraspObject.
    """

    def __init__(
        self, hand: Hand, obj: GraspObject, contacts: tuple[str, ...], allowance_m: float
    ) -> None:
        check_obstacle(obj)
        self.checker = checker_of(hand, obj)
        self.contacts = contacts
        self.allowance_m = allowance_m
        # The last q asked about and its exact clearance (None: only known to be inside).
        self._last: tuple[bytes, Clearance | None] = (b"", None)

    def penetrations(self, q: NDArray[np.float64], margin_m: float) -> list[Penetration]:
        """Links closer to the object than ``margin_m`` [m] (contact tips: deeper than allowed).

        At most :data:`REPAIR_PAIRS_PER_LINK` pairs per link: a separation row each in the repair.
        """
        return self.checker.penetrations(
            q, margin_m, self.contacts, self.allowance_m, per_link=REPAIR_PAIRS_PER_LINK
        )

    def penetrated(self, q: NDArray[np.float64]) -> bool:
        """True if a link is inside the object (contact tips: deeper than the allowance)."""
        # The inner solver, Algorithm 1's Step 8 and the result all ask about the accepted q.
        key = q.tobytes()
        if self._last[0] == key:
            return self._last[1] is None or not self._last[1].clear()
        found = self.checker.clearance_if_clear(q, self.contacts, self.allowance_m)
        self._last = (key, found)
        return found is None

    def clearance(self, q: NDArray[np.float64]) -> Clearance:
        """Smallest signed distance [m] of a link to the object and that link (kept for ``q``)."""
        key = q.tobytes()
        last = self._last[1]
        if self._last[0] != key or last is None:
            last = self.checker.clearance(q, self.contacts, self.allowance_m, all_links=False)
            self._last = (key, last)
        return last
