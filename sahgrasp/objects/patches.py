"""Contact regions on an object (atlas paper, Eqs. (3)-(4)): ``o = O(params)``, ``m = M(params)``.

A region has ``dim`` parameters bound to a box ``lower <= params <= upper`` and gives, at any
parameters, the contact point, the outward unit normal and their derivatives (``3 x dim`` each),
in the frame of its ``placement`` (the world frame for the catalog's regions). Three kinds:

- :class:`Patch`: a two-parameter piece of a surface, ``point(u, v)``;
- :class:`CurvePatch`: a curve on a surface (``v`` fixed), ``point(u)``;
- :class:`FixedContact`: a single point, no parameter (a finger the object is fixed to).

Every region has ``nominal`` parameters inside its bounds: together they form a first grasp that
the IK can solve (:meth:`GraspPatches.target`), the starting point of the atlas.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.core.frames import FloatArray, as_placement
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.objects.surfaces import Surface, SurfaceJet, placed_jet

__all__ = ["ContactRegion", "CurvePatch", "FixedContact", "GraspPatches", "Patch"]


class ContactRegion(Protocol):
    """What the grasp equations need from a contact region, whatever its dimension."""

    @property
    def name(self) -> str:
        """Region name."""
        ...

    @property
    def lower(self) -> FloatArray:
        """Lower parameter bounds, shape (dim,)."""
        ...

    @property
    def upper(self) -> FloatArray:
        """Upper parameter bounds, shape (dim,)."""
        ...

    @property
    def nominal(self) -> FloatArray:
        """Parameters of the first grasp, shape (dim,)."""
        ...

    def evaluate(self, params: ArrayLike) -> SurfaceJet:
        """Return point, normal and their (3, dim) Jacobians at ``params``."""
        ...

    def placed(self, T: Any) -> ContactRegion:
        """Return the region moved by placement ``T`` (applied after its own placement)."""
        ...


def _identity() -> FloatArray:
    return as_placement(np.eye(4))


def _box(lower: ArrayLike, upper: ArrayLike, nominal: ArrayLike, what: str) -> None:
    lo, hi, x0 = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (lower, upper, nominal))
    if not np.all(lo < hi) or not np.all((lo <= x0) & (x0 <= hi)):
        raise ValueError(f"{what}: need lower < upper and nominal inside, got {lo}, {hi}, {x0}")


@dataclass(frozen=True, eq=False)
class Patch:
    """A two-parameter surface patch ``(u, v)`` in ``u_range x v_range``.

    Attributes:
        name: Region name.
        surface: The parametrised surface (units of ``u``, ``v`` are the surface's).
        u_range: Bounds of ``u``.
        v_range: Bounds of ``v``.
        nominal_uv: Parameters of the first grasp, inside the bounds.
        placement: Placement of the surface frame in the reporting frame (4x4).
    """

    name: str
    surface: Surface
    u_range: tuple[float, float]
    v_range: tuple[float, float]
    nominal_uv: tuple[float, float]
    placement: FloatArray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))
        _box(self.lower, self.upper, self.nominal_uv, f"patch {self.name!r}")

    @property
    def lower(self) -> FloatArray:
        """``(u_min, v_min)``."""
        return np.array([self.u_range[0], self.v_range[0]])

    @property
    def upper(self) -> FloatArray:
        """``(u_max, v_max)``."""
        return np.array([self.u_range[1], self.v_range[1]])

    @property
    def nominal(self) -> FloatArray:
        """``nominal_uv`` as an array."""
        return np.array(self.nominal_uv, dtype=np.float64)

    def evaluate(self, params: ArrayLike) -> SurfaceJet:
        """Return point, normal and their (3, 2) Jacobians at ``params = (u, v)``."""
        u, v = np.asarray(params, dtype=np.float64)
        return placed_jet(self.surface, u, v, self.placement)

    def point(self, u: float, v: float) -> FloatArray:
        """Contact point ``O(u, v)`` [m], shape (3,)."""
        return self.evaluate((u, v)).point

    def normal(self, u: float, v: float) -> FloatArray:
        """Outward unit normal ``M(u, v)``, shape (3,)."""
        return self.evaluate((u, v)).normal

    def point_jacobian(self, u: float, v: float) -> FloatArray:
        """``[dO/du, dO/dv]``, shape (3, 2)."""
        return self.evaluate((u, v)).point_jacobian

    def normal_jacobian(self, u: float, v: float) -> FloatArray:
        """``[dM/du, dM/dv]``, shape (3, 2)."""
        return self.evaluate((u, v)).normal_jacobian

    def placed(self, T: Any) -> Patch:
        """Return the patch moved by placement ``T``."""
        return dataclasses.replace(self, placement=as_placement(T) @ self.placement)


@dataclass(frozen=True, eq=False)
class CurvePatch:
    """A one-parameter curve ``u -> surface(u, v_fixed)`` for ``u`` in ``u_range``.

    Attributes:
        name: Region name.
        surface: The surface carrying the curve.
        v_fixed: The fixed second parameter.
        u_range: Bounds of ``u``.
        nominal_u: Parameter of the first grasp, inside the bounds.
        placement: Placement of the surface frame in the reporting frame (4x4).
    """

    name: str
    surface: Surface
    v_fixed: float
    u_range: tuple[float, float]
    nominal_u: float
    placement: FloatArray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))
        _box(self.lower, self.upper, self.nominal_u, f"curve {self.name!r}")

    @property
    def lower(self) -> FloatArray:
        """``(u_min,)``."""
        return np.array([self.u_range[0]])

    @property
    def upper(self) -> FloatArray:
        """``(u_max,)``."""
        return np.array([self.u_range[1]])

    @property
    def nominal(self) -> FloatArray:
        """``(nominal_u,)``."""
        return np.array([self.nominal_u])

    def evaluate(self, params: ArrayLike) -> SurfaceJet:
        """Return point, normal and their (3, 1) Jacobians at ``params = (u,)``."""
        (u,) = np.atleast_1d(np.asarray(params, dtype=np.float64))
        return placed_jet(self.surface, u, self.v_fixed, self.placement, curve=True)

    def point(self, u: float) -> FloatArray:
        """Contact point [m], shape (3,)."""
        return self.evaluate(u).point

    def normal(self, u: float) -> FloatArray:
        """Outward unit normal, shape (3,)."""
        return self.evaluate(u).normal

    def point_jacobian(self, u: float) -> FloatArray:
        """``dO/du``, shape (3, 1)."""
        return self.evaluate(u).point_jacobian

    def normal_jacobian(self, u: float) -> FloatArray:
        """``dM/du``, shape (3, 1)."""
        return self.evaluate(u).normal_jacobian

    def placed(self, T: Any) -> CurvePatch:
        """Return the curve moved by placement ``T``."""
        return dataclasses.replace(self, placement=as_placement(T) @ self.placement)


@dataclass(frozen=True, eq=False)
class FixedContact:
    """A fixed contact point (no parameter), e.g. the finger the can is attached to.

    Attributes:
        name: Region name.
        jet: Point and outward normal (Jacobians of shape (3, 0)), in the reporting frame.
    """

    name: str
    jet: SurfaceJet

    @property
    def lower(self) -> FloatArray:
        """Empty: no parameter."""
        return np.zeros(0)

    @property
    def upper(self) -> FloatArray:
        """Empty: no parameter."""
        return np.zeros(0)

    @property
    def nominal(self) -> FloatArray:
        """Empty: no parameter."""
        return np.zeros(0)

    def evaluate(self, params: ArrayLike = ()) -> SurfaceJet:
        """Return the fixed point and normal (``params`` must be empty)."""
        if np.asarray(params).size:
            raise ValueError(f"fixed contact {self.name!r} takes no parameter")
        return self.jet

    def placed(self, T: Any) -> FixedContact:
        """Return the contact moved by placement ``T``."""
        return FixedContact(self.name, self.jet.transformed(as_placement(T)))


@dataclass(frozen=True, eq=False)
class GraspPatches:
    """The contact regions of a constrained grasp (atlas paper, Section V), one per finger.

    Attributes:
        name: Problem name.
        regions: Finger name -> contact region.
    """

    name: str
    regions: Mapping[str, ContactRegion]

    def target(self, params: Mapping[str, ArrayLike] | None = None) -> GraspTarget:
        """Return the grasp at ``params`` per finger (default: every region's nominal parameters).

        Raises:
            InvalidTargetError: ``params`` names a finger without a region.
        """
        chosen = dict(params or {})
        unknown = sorted(set(chosen) - set(self.regions))
        if unknown:
            raise InvalidTargetError(
                f"{self.name}: no region for finger(s) {unknown}; "
                f"fingers with a region are {sorted(self.regions)}"
            )
        contacts = []
        for finger, region in self.regions.items():
            jet = region.evaluate(chosen.get(finger, region.nominal))
            contacts.append(ContactTarget(finger, jet.point, jet.normal))
        return GraspTarget(self.name, contacts)

    def placed(self, T: Any) -> GraspPatches:
        """Return every region moved by placement ``T``."""
        return GraspPatches(self.name, {f: r.placed(T) for f, r in self.regions.items()})
