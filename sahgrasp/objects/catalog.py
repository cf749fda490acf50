"""The papers' objects, their precision grasps and their contact patches.

Objects of Claret & Suárez (Figs. 6-8: fork, cup, Buddha statuette, cup of coffee with saucer,
can) and of Rosales, Porta & Ros (Section V: the can, a Marquina oil drizzler). The figures give
no dimensions: docs/methods/objects.md lists the sizes chosen and why. Every object stands on the
world
``xy`` plane with its axis along ``z`` (the fork lies flat along ``x``) unless a placement
``T_world_object`` is given; grasps and patches follow the placement.

Paper grasps put the thumb on one side and index, middle and ring on the other, the thumb opposite
the middle finger. Neighbouring finger contacts are 26-34 mm apart: the SAH's fingers are 26-30 mm
wide, so closer contacts make neighbouring fingers collide. Contacts are computed on the exact
surfaces; every paper grasp is solved by ``sahgrasp.ik.solve_ik`` (docs/methods/objects.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.core.frames import FloatArray, as_placement, placement, rotation_about
from sahgrasp.core.registry import Registry
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.patches import (
    ContactRegion,
    CurvePatch,
    FixedContact,
    GraspPatches,
    Patch,
)
from sahgrasp.objects.profiles import Arc, Segment, rounded_polyline
from sahgrasp.objects.solids import BoxSolid, EllipsoidSolid, RevolvedSolid
from sahgrasp.objects.surfaces import RevolvedSurface, SurfaceJet

__all__ = [
    "CATALOG",
    "GRASP_NAMES",
    "OBJECT_NAMES",
    "PAPER_IK_REPORT",
    "CatalogEntry",
    "CatalogObject",
    "IKReport",
    "bottle_patches",
    "can_patches",
    "load_object",
    "paper_grasp",
    "register_object",
]

MM = 1e-3
"""One millimetre [m]: the designs below are written in millimetres."""


class IKReport(NamedTuple):
    """What Claret & Suárez reports for an example: initial configurations, iterations."""

    initial_configurations: int
    jacobian_iterations: int


PAPER_IK_REPORT: dict[str, IKReport] = {
    "fork": IKReport(1, 6),
    "cup": IKReport(1, 13),
    "buddha": IKReport(3, 25),
    "coffee_cup": IKReport(7, 38),
    "can": IKReport(1, 22),
}
"""Claret & Suárez Section 4.1: initial configurations used and Jacobian iterations."""


@dataclass(frozen=True)
class CatalogEntry:
    """A catalog object at the identity placement and its grasp (finger -> jet, object frame)."""

    object: GraspObject
    grasp: dict[str, SurfaceJet] | None = None


@dataclass(frozen=True)
class CatalogObject:
    """How to build one object of the catalog.

    Attributes:
        name: The object's name (``load_object(name)``, ``{"name": ...}`` in a targets file).
        build: Builds the object at the identity placement, with its grasp if it has one.
        grasped: Whether ``build`` gives a grasp (then :func:`paper_grasp` knows the name).
    """

    name: str
    build: Callable[[], CatalogEntry]
    grasped: bool


CATALOG: Registry[CatalogObject] = Registry("object", InvalidTargetError)
"""Every catalog object by name, in the papers' order; :func:`register_object` adds one."""

OBJECT_NAMES: Sequence[str] = CATALOG.names()
"""Names accepted by :func:`load_object`, in the papers' order (a live view of :data:`CATALOG`)."""
GRASP_NAMES: Sequence[str] = CATALOG.names(lambda entry: entry.grasped)
"""Names accepted by :func:`paper_grasp`: the objects with a grasp, those of Claret & Suárez."""


def register_object(
    name: str, build: Callable[[], CatalogEntry], grasped: bool = False
) -> CatalogObject:
    """Add an object to the catalog: from then on every loader and targets file knows ``name``.

    Args:
        name: The object's name.
        build: Builds the object at the identity placement (and its grasp: ``grasped``).
        grasped: Whether ``build`` gives a grasp.

    Raises:
        InvalidTargetError: The name is empty or taken.
    """
    return CATALOG.register(name, CatalogObject(name, build, grasped))


def _catalog(
    name: str, grasped: bool = True
) -> Callable[[Callable[[], CatalogEntry]], Callable[[], CatalogEntry]]:
    """Decorator: register the builder below as catalog object ``name``."""

    def add(build: Callable[[], CatalogEntry]) -> Callable[[], CatalogEntry]:
        register_object(name, build, grasped)
        return build

    return add


def _mm(*points: tuple[float, float]) -> list[tuple[float, float]]:
    return [(r * MM, z * MM) for r, z in points]


def _mm2(values: tuple[float, float]) -> tuple[float, float]:
    return values[0] * MM, values[1] * MM


def _mm3(values: tuple[float, float, float]) -> tuple[float, float, float]:
    return values[0] * MM, values[1] * MM, values[2] * MM


def _translation(x_mm: float, y_mm: float, z_mm: float) -> FloatArray:
    return placement(None, (x_mm * MM, y_mm * MM, z_mm * MM))


# ----- fork (Fig. 6) ----------------------------------------------------------------------------
_FORK_HANDLE_MM = (55.0, 11.0, 2.5)


@_catalog("fork")
def _fork() -> CatalogEntry:
    a, _, _ = _FORK_HANDLE_MM
    handle = EllipsoidSolid("handle", _mm3(_FORK_HANDLE_MM), _translation(a, 0, 0))
    neck = BoxSolid("neck", (40 * MM, 7 * MM, 3 * MM), _translation(120, 0, 0))
    head = BoxSolid("head", (22 * MM, 25 * MM, 2 * MM), _translation(150, 0, 0))
    tines = tuple(
        BoxSolid(f"tine{i}", (30 * MM, 3.5 * MM, 2 * MM), _translation(175, y, 0))
        for i, y in enumerate((-10.75, -3.58, 3.58, 10.75))
    )
    fork = GraspObject("fork", (handle, neck, head, *tines), (0.75, 0.75, 0.78, 1.0))

    def edge(x_mm: float, side: float) -> SurfaceJet:
        """Handle rim (equator) at ``x_mm`` from the handle's end, on side ``+1``/``-1`` of y."""
        return handle.jet(side * math.acos((x_mm - a) / a), 0.0)

    grasp = {
        "thumb": edge(55, -1),
        "index": edge(89, 1),
        "middle": edge(55, 1),
        "ring": edge(21, 1),
    }
    return CatalogEntry(fork, grasp)


# ----- cup (Fig. 7a) ----------------------------------------------------------------------------
@_catalog("cup")
def _cup() -> CatalogEntry:
    profile = rounded_polyline(
        _mm((0, 0), (30, 0), (36, 90), (32.5, 90), (26.8, 5), (0, 5)),
        [3 * MM, 1.5 * MM, 1.5 * MM, 4 * MM],
    )
    wall = RevolvedSolid("cup", profile)
    grasp = {
        "thumb": wall.outer_jet(math.pi, 53 * MM),
        "index": wall.outer_jet(0.0, 82 * MM),
        "middle": wall.outer_jet(0.0, 50 * MM),
        "ring": wall.outer_jet(0.0, 18 * MM),
    }
    return CatalogEntry(GraspObject("cup", (wall,), (0.55, 0.70, 0.85, 1.0)), grasp)


# ----- Buddha statuette (Fig. 7b) ---------------------------------------------------------------
_TORSO_CENTRE_Z_MM = 56.0
_TORSO_RADII_MM = (22.0, 30.0, 33.0)
_HEAD_CENTRE_Z_MM, _HEAD_RADIUS_MM = 100.0, 17.0


@_catalog("buddha")
def _buddha() -> CatalogEntry:
    base = RevolvedSolid(
        "base", rounded_polyline(_mm((0, 0), (45, 0), (45, 14), (0, 14)), [2 * MM, 3 * MM])
    )
    lap = EllipsoidSolid("lap", (26 * MM, 42 * MM, 11 * MM), _translation(2, 0, 22))
    torso = EllipsoidSolid(
        "torso",
        _mm3(_TORSO_RADII_MM),
        _translation(0, 0, _TORSO_CENTRE_Z_MM),
    )
    head = EllipsoidSolid(
        "head", _mm3((_HEAD_RADIUS_MM,) * 3), _translation(2, 0, _HEAD_CENTRE_Z_MM)
    )
    topknot = EllipsoidSolid("topknot", _mm3((6.5, 6.5, 6.5)), _translation(2, 0, 118))
    buddha = GraspObject("buddha", (base, lap, torso, head, topknot), (0.72, 0.53, 0.25, 1.0))

    def on_torso(longitude_rad: float, height_mm: float) -> SurfaceJet:
        latitude = math.asin((height_mm - _TORSO_CENTRE_Z_MM) / _TORSO_RADII_MM[2])
        return torso.jet(longitude_rad, latitude)

    grasp = {
        "thumb": on_torso(math.pi, 68),
        "index": head.jet(0.0, math.asin((102 - _HEAD_CENTRE_Z_MM) / _HEAD_RADIUS_MM)),
        "middle": on_torso(0.0, 68),
        "ring": on_torso(0.0, 42),
    }
    return CatalogEntry(buddha, grasp)


# ----- cup of coffee with saucer (Fig. 7c) ------------------------------------------------------
_SAUCER_WELL_MM = 8.0
_COFFEE_WALL_MM = ((26.0, 0.0), (40.0, 62.0))
"""The coffee cup's outer wall line, bottom and top corners (r, z) in the cup frame."""
_HANDLE_RING_MM = (38.5, 33.0, 15.0, 3.5)
"""Handle: ring centre (x, z) in the cup frame, ring radius, tube radius."""


@_catalog("coffee_cup")
def _coffee_cup() -> CatalogEntry:
    (r0, z0), (r1, z1) = _COFFEE_WALL_MM
    cup_profile = rounded_polyline(
        _mm((0, 0), (r0, z0), (r1, z1), (35.9, 62), (23.25, 6), (0, 6)),
        [5 * MM, 1.8 * MM, 1.8 * MM, 6 * MM],
    )
    on_saucer = _translation(0, 0, _SAUCER_WELL_MM)
    cup = RevolvedSolid("cup", cup_profile, on_saucer)
    saucer = RevolvedSolid(
        "saucer",
        rounded_polyline(
            _mm((0, 0), (42, 0), (70, 15), (69, 17.5), (36, _SAUCER_WELL_MM), (0, _SAUCER_WELL_MM)),
            [3 * MM, 1 * MM, 1 * MM, 6 * MM],
        ),
    )
    handle = _handle(on_saucer)
    coffee = GraspObject("coffee_cup", (saucer, cup, *handle), (0.95, 0.95, 0.92, 1.0))
    grasp = {
        "thumb": cup.outer_jet(math.pi / 2, 40 * MM),
        "index": cup.outer_jet(-math.pi / 2 + 0.6, 58 * MM),
        "middle": cup.outer_jet(-math.pi / 2, 40 * MM),
        "ring": cup.outer_jet(-math.pi / 2 - 0.6, 22 * MM),
    }
    return CatalogEntry(coffee, grasp)


def _handle(T_object_cup: FloatArray) -> tuple[RevolvedSolid, EllipsoidSolid, EllipsoidSolid]:
    """The cup handle: a torus sector in the cup's xz plane, ends on the outer wall, ball-capped.

    The sector's end angles are where the ring's centre circle meets the wall line
    ``r = r0 + k z``: ``R (cos t - k sin t) = r0 - x_c + k z_c``.
    """
    (r0, z0), (r1, z1) = _COFFEE_WALL_MM
    x_c, z_c, ring, tube = _HANDLE_RING_MM
    k = (r1 - r0) / (z1 - z0)
    half = math.acos((r0 - x_c + k * z_c) / (ring * math.hypot(1.0, k)))
    phase = math.atan(k)
    ends = (-half - phase, half - phase)
    # Torus frame: x along the cup's x, y along the cup's z, revolution axis z along the cup's -y.
    T_cup_torus = placement(rotation_about((1, 0, 0), math.pi / 2), (x_c * MM, 0, z_c * MM))
    T_object_torus = T_object_cup @ T_cup_torus
    circle = Arc(((ring * MM), 0.0), tube * MM, -math.pi, 2.0 * math.pi)
    torus = RevolvedSolid("handle", (circle,), T_object_torus, ends)
    caps = tuple(
        EllipsoidSolid(
            f"handle_end{i}",
            _mm3((tube, tube, tube)),
            T_object_torus @ placement(None, (ring * MM * math.cos(t), ring * MM * math.sin(t), 0)),
        )
        for i, t in enumerate(ends)
    )
    return torus, caps[0], caps[1]


# ----- can (Fig. 8; atlas paper Fig. 10a) -------------------------------------------------------
_CAN_RADIUS_MM = 33.0
_CAN_POLYLINE_MM = (
    (0, 0),
    (25, 0),
    (_CAN_RADIUS_MM, 8),
    (_CAN_RADIUS_MM, 102),
    (28, 113),
    (27, 115),
    (0, 115),
)
_CAN_CORNERS_MM = (2.0, 5.0, 5.0, 1.5, 1.0)
_CAN_THUMB_MM, _CAN_INDEX_MM, _CAN_MIDDLE_MM = 62.0, 93.0, 59.0
"""Contact heights [mm] shared by the paper grasp and the atlas patches' nominal grasp."""


def _can_solid() -> RevolvedSolid:
    return RevolvedSolid(
        "can", rounded_polyline(_mm(*_CAN_POLYLINE_MM), [r * MM for r in _CAN_CORNERS_MM])
    )


@_catalog("can")
def _can() -> CatalogEntry:
    can = _can_solid()
    grasp = {
        "thumb": can.outer_jet(math.pi, _CAN_THUMB_MM * MM),
        "index": can.outer_jet(0.0, _CAN_INDEX_MM * MM),
        "middle": can.outer_jet(0.0, _CAN_MIDDLE_MM * MM),
        "ring": can.outer_jet(0.0, 25 * MM),
    }
    return CatalogEntry(GraspObject("can", (can,), (0.80, 0.08, 0.10, 1.0)), grasp)


def _can_side_heights_m() -> tuple[float, float]:
    """Heights [m] where the can's straight side wall starts and ends (between the fillets)."""
    (side,) = (
        p
        for p in _can_solid().profile
        if isinstance(p, Segment)
        and math.isclose(p.start_m[0], p.end_m[0], abs_tol=1e-12)
        and math.isclose(p.start_m[0], _CAN_RADIUS_MM * MM)
    )
    return side.start_m[1], side.end_m[1]


def can_patches(T_world_object: Any = None) -> GraspPatches:
    """Contact regions of the atlas paper's can (Section V, Fig. 10a).

    The can is fixed to the thumb (no parameter: this removes the can's axial symmetry), and the
    index and middle fingers may touch anywhere on the side wall: ``u`` the angle [rad] in
    ``[-pi, pi]`` from the object's ``+x`` axis, ``v`` the height [m] above the can's bottom, over
    the straight part of the wall. Nominal parameters form a three-finger grasp with the thumb
    opposite the two fingers.
    """
    z_lo, z_hi = _can_side_heights_m()
    side = RevolvedSurface(Segment((_CAN_RADIUS_MM * MM, 0.0), (_CAN_RADIUS_MM * MM, 1.0)))
    thumb = side.jet(math.pi, _CAN_THUMB_MM * MM).parameter_columns([])
    regions: dict[str, ContactRegion] = {
        "thumb": FixedContact("can_thumb", thumb),
        "index": Patch(
            "can_side", side, (-math.pi, math.pi), (z_lo, z_hi), (0.0, _CAN_INDEX_MM * MM)
        ),
        "middle": Patch(
            "can_side", side, (-math.pi, math.pi), (z_lo, z_hi), (0.0, _CAN_MIDDLE_MM * MM)
        ),
    }
    return _placed(GraspPatches("can", regions), T_world_object)


# ----- Marquina oil drizzler (atlas paper Fig. 10b) ---------------------------------------------
_BOTTLE_POLYLINE_MM = (
    (0, 0), (32, 0), (21, 86), (14, 96), (14, 100), (17, 100), (17, 120), (0, 120)
)  # fmt: skip
_BOTTLE_CORNERS_MM = (3.0, 10.0, 3.0, 0.5, 0.5, 8.0)
_BOTTLE_BOTTOM_MM = (5.0, 45.0)
"""Arc-length range along the glass cone (from its bottom corner) of the bottom section [mm]."""
_BOTTLE_MIDDLE_MM = (45.0, 80.0)
"""Arc-length range along the glass cone of the middle section [mm]."""


def _bottle_cone() -> RevolvedSurface:
    """The glass body's cone, from its bottom corner to its shoulder corner."""
    (r0, z0), (r1, z1) = _BOTTLE_POLYLINE_MM[1:3]
    return RevolvedSurface(Segment((r0 * MM, z0 * MM), (r1 * MM, z1 * MM)))


def _bottle_cap_edge() -> RevolvedSurface:
    """The rounded top edge of the cap: the last corner's fillet (a quarter circle)."""
    (r, z), radius = _BOTTLE_POLYLINE_MM[-2], _BOTTLE_CORNERS_MM[-1]
    return RevolvedSurface(
        Arc(((r - radius) * MM, (z - radius) * MM), radius * MM, 0.0, math.pi / 2)
    )


@_catalog("bottle", grasped=False)
def _bottle() -> CatalogEntry:
    body = RevolvedSolid(
        "body", rounded_polyline(_mm(*_BOTTLE_POLYLINE_MM), [r * MM for r in _BOTTLE_CORNERS_MM])
    )
    spout = RevolvedSolid(
        "spout",
        rounded_polyline(_mm((0, 0), (3.5, 0), (3.5, 42), (0, 42)), [0.0, 1.5 * MM]),
        placement(rotation_about((0, 1, 0), math.radians(40.0)), (6 * MM, 0.0, 112 * MM)),
    )
    return CatalogEntry(GraspObject("bottle", (body, spout), (0.78, 0.85, 0.72, 1.0)))


def bottle_patches(T_world_object: Any = None) -> GraspPatches:
    """Contact regions of the atlas paper's oil drizzler (Section V, Fig. 10b).

    - ``index``: a curve on the top, the cap's rounded edge halfway between its side and its top
      (normal 45 degrees up), ``u`` the angle [rad] on the side opposite the thumb;
    - ``thumb``: the middle section of the glass cone, ``u`` the angle [rad], ``v`` the arc length
      [m] along the cone from its bottom corner;
    - ``middle``: the bottom section of the glass cone, same parameters.

    The spout points along the object's ``+x``; the fingers are on the ``+y`` side, the thumb on
    the ``-y`` side.
    """
    cap_edge = _bottle_cap_edge()
    quarter = math.pi / 4 * _BOTTLE_CORNERS_MM[-1] * MM
    cone = _bottle_cone()
    side = (math.pi / 6, 5 * math.pi / 6)
    top = (math.pi / 4, 3 * math.pi / 4)
    regions: dict[str, ContactRegion] = {
        "index": CurvePatch("bottle_top", cap_edge, quarter, top, math.pi / 2),
        "thumb": Patch(
            "bottle_middle",
            cone,
            (-side[1], -side[0]),
            _mm2(_BOTTLE_MIDDLE_MM),
            (-math.pi / 2, 60 * MM),
        ),
        "middle": Patch(
            "bottle_bottom",
            cone,
            side,
            _mm2(_BOTTLE_BOTTOM_MM),
            (math.pi / 2, 40 * MM),
        ),
    }
    return _placed(GraspPatches("bottle", regions), T_world_object)


# ----- lookups ----------------------------------------------------------------------------------
def _placed(patches: GraspPatches, T_world_object: Any) -> GraspPatches:
    return patches if T_world_object is None else patches.placed(T_world_object)


def _entry(name: str, valid: Sequence[str]) -> CatalogEntry:
    if name not in valid:
        raise InvalidTargetError(f"unknown object {name!r}; valid names are {list(valid)}")
    return CATALOG[name].build()


def load_object(name: str, T_world_object: Any = None) -> GraspObject:
    """Return the object ``name`` of :data:`OBJECT_NAMES`, placed at ``T_world_object``.

    Args:
        name: Object name.
        T_world_object: Placement (4x4 or ``pinocchio.SE3``); identity if None.

    Raises:
        InvalidTargetError: Unknown name; the message lists the valid ones.
    """
    obj = _entry(name, OBJECT_NAMES).object
    return obj if T_world_object is None else obj.placed(T_world_object)


def paper_grasp(name: str, T_world_object: Any = None) -> GraspTarget:
    """Return the precision grasp of object ``name`` (:data:`GRASP_NAMES`) in the world frame.

    Args:
        name: Object name.
        T_world_object: The object's placement (4x4 or ``pinocchio.SE3``); identity if None.

    Raises:
        InvalidTargetError: Unknown name; the message lists the valid ones.
    """
    grasp = _entry(name, GRASP_NAMES).grasp
    if grasp is None:
        raise InvalidTargetError(f"object {name!r} is registered with a grasp, but built none")
    T = as_placement(np.eye(4) if T_world_object is None else T_world_object)
    contacts = []
    for finger, jet in grasp.items():
        world = jet.transformed(T)
        contacts.append(ContactTarget(finger, world.point, world.normal))
    return GraspTarget(name, contacts)
