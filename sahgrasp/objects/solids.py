"""Solids that objects are assembled from.

Each solid gives its boundary patches, a display mesh and convex collision pieces, all in the
object frame (through its ``placement``):

- :class:`RevolvedSolid`: a closed profile (profiles.py) revolved about the solid's ``z`` axis,
  fully or over an angle range (a cup handle is a torus sector);
- :class:`EllipsoidSolid`: a triaxial ellipsoid (a sphere when the radii agree);
- :class:`BoxSolid`: a rectangular box.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import coal
import numpy as np

from sahgrasp.collision.shapes import BuiltOnce, CollisionShape, convex_hull
from sahgrasp.core.frames import FloatArray, as_placement
from sahgrasp.objects.meshing import Mesh, tessellate
from sahgrasp.objects.patches import Patch
from sahgrasp.objects.profiles import (
    Arc,
    ProfilePiece,
    chord_count,
    piece_chords,
    sample_profile,
)
from sahgrasp.objects.surfaces import (
    EllipsoidSurface,
    RectangleSurface,
    RevolvedSurface,
    SurfaceJet,
)

__all__ = ["BoxSolid", "EllipsoidSolid", "RevolvedSolid", "Solid"]

DISPLAY_SAGITTA_M = 5e-5
"""Largest gap between a display mesh's chord and the exact surface [m]."""
COLLISION_SAGITTA_M = 5e-5
"""Largest chord gap of a collision piece [m], across the axis and along the profile each."""
_FULL_TURN = 2.0 * math.pi
_TURN_TOLERANCE = 1e-9
"""Largest sine of a turn [-] between two profile chords counted as straight (rounding only)."""


class Solid(Protocol):
    """A closed solid placed in the object frame."""

    @property
    def name(self) -> str:
        """Solid name, unique within its object."""
        ...

    def boundary(self) -> tuple[Patch, ...]:
        """Patches covering the solid's boundary, in the object frame."""
        ...

    def mesh(self) -> Mesh:
        """Display mesh in the object frame."""
        ...

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex pieces whose union is the solid, in the object frame.

        A solid may also offer ``simulation_shapes()``, coarser pieces for a physics
        simulation (:meth:`GraspObject.simulation_shapes`).
        """
        ...


def _identity() -> FloatArray:
    return as_placement(np.eye(4))


@dataclass(frozen=True, eq=False)
class RevolvedSolid(BuiltOnce):
    """A profile revolved about ``z`` over ``angle_range_rad``.

    Attributes:
        name: Solid name.
        profile: Pieces running with the material on their left: from the axis back to the axis
            (a closed solid), or a closed loop (a torus).
        placement: Placement of the solid frame in the object frame (4x4).
        angle_range_rad: Revolution range; the default is a full turn. A partial turn leaves the
            ends open: close them with other solids (as the cup handle's spherical ends).
    """

    name: str
    profile: tuple[ProfilePiece, ...]
    placement: FloatArray = field(default_factory=_identity)
    angle_range_rad: tuple[float, float] = (-math.pi, math.pi)

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))

    @property
    def _turn_rad(self) -> float:
        return self.angle_range_rad[1] - self.angle_range_rad[0]

    @property
    def _max_radius_m(self) -> float:
        return float(sample_profile(self.profile, DISPLAY_SAGITTA_M)[:, 0].max())

    def boundary(self) -> tuple[Patch, ...]:
        """One patch per profile piece: ``u`` the angle [rad], ``v`` the arc length [m]."""
        return tuple(
            Patch(
                f"{self.name}[{i}]",
                RevolvedSurface(piece),
                self.angle_range_rad,
                (0.0, piece.length_m),
                (sum(self.angle_range_rad) / 2.0, piece.length_m / 2.0),
                self.placement,
            )
            for i, piece in enumerate(self.profile)
        )

    def mesh(self) -> Mesh:
        """Display mesh: chords within ``DISPLAY_SAGITTA_M`` of the exact surface."""
        n_angle = chord_count(self._turn_rad, self._max_radius_m, DISPLAY_SAGITTA_M)
        return Mesh.concatenate(
            tessellate(patch, (n_angle, piece_chords(piece, DISPLAY_SAGITTA_M)))
            for patch, piece in zip(self.boundary(), self.profile, strict=True)
        )

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex pieces: the cross-section cut into convex slabs, each slab revolved.

        The cross-section is cut into horizontal bands (at the profile's sample heights) and
        consecutive bands are joined while their union stays a convex polygon (:func:`_slabs`).
        A slab touching the axis over a full turn is one convex solid of revolution; any other
        slab is cut into angular sectors (as few as keep its own largest radius within
        ``COLLISION_SAGITTA_M``), each the convex hull of its corners. The cross-section must
        meet every horizontal line in a single interval. Built once per solid (Qhull per
        sector).
        """
        return self._shapes

    @cached_property
    def _shapes(self) -> tuple[CollisionShape, ...]:
        full_turn = math.isclose(self._turn_rad, _FULL_TURN)
        shapes = []
        for slab in _slabs(_bands(self.profile)):
            n_sectors = chord_count(self._turn_rad, slab[:, 2].max(), COLLISION_SAGITTA_M)
            angles = np.linspace(*self.angle_range_rad, n_sectors + 1)
            if full_turn and np.allclose(slab[:, 0], 0.0):
                # A convex section against the axis: its outer radius is concave in z, so the
                # whole turn is convex (one piece, its rings within the sagitta).
                shapes.append(self._hull(slab[:, 2:], angles))
            else:
                shapes.extend(self._hull(slab, angles[k : k + 2]) for k in range(n_sectors))
        return tuple(shapes)

    def _hull(self, band: FloatArray, angles: FloatArray) -> CollisionShape:
        """Hull of the slab's ``(r, z, r, z)`` rows revolved to every angle in ``angles``."""
        rz = band.reshape(-1, 2)
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        z = np.broadcast_to(rz[:, 1], (len(angles), len(rz)))
        points = np.stack([rz[:, 0] * c, rz[:, 0] * s, z], axis=-1)
        shape = convex_hull(np.unique(points.reshape(-1, 3).round(12), axis=0))
        return CollisionShape(
            shape.geometry, self.placement @ shape.placement, shape.bounding_radius_m
        )

    def outer_jet(self, angle_rad: float, height_m: float) -> SurfaceJet:
        """Return the outermost surface point at ``angle_rad`` and ``height_m``.

        Both are in the solid's frame (``height_m`` along its axis); the jet is in the object frame.

        Raises:
            ValueError: No piece of the profile reaches ``height_m``.
        """
        candidates = [
            (float(piece.evaluate(s)[0][0]), i, s)
            for i, piece in enumerate(self.profile)
            for s in _params_at_height(piece, height_m)
        ]
        if not candidates:
            raise ValueError(f"solid {self.name!r} has no surface at height {height_m} m")
        _, i, s = max(candidates)
        return RevolvedSurface(self.profile[i]).jet(angle_rad, s).transformed(self.placement)


def _params_at_height(piece: ProfilePiece, height_m: float) -> list[float]:
    """Arc lengths ``s`` in ``[0, length]`` where the piece is at height ``height_m``."""
    if isinstance(piece, Arc):
        ratio = (height_m - piece.centre_m[1]) / piece.radius_m
        if abs(ratio) > 1.0:
            return []
        base = math.asin(ratio)
        sign = math.copysign(1.0, piece.sweep_rad)
        params = []
        for angle in (base, math.pi - base):
            turn = (sign * (angle - piece.start_rad)) % _FULL_TURN
            params.append(turn * piece.radius_m)
    else:
        (_, z0), (_, z1) = piece.start_m, piece.end_m
        params = [] if z0 == z1 else [(height_m - z0) / (z1 - z0) * piece.length_m]
    return [s for s in params if -1e-12 <= s <= piece.length_m + 1e-12]


def _bands(profile: tuple[ProfilePiece, ...]) -> list[FloatArray]:
    """Cut the cross-section into bands ``[[r_in, z_lo, r_out, z_lo], [r_in, z_hi, r_out, z_hi]]``.

    Raises:
        ValueError: The profile is open, or a horizontal line meets the cross-section twice.
    """
    polygon = sample_profile(profile, COLLISION_SAGITTA_M).round(10)
    if np.allclose(polygon[0], polygon[-1]):
        polygon = polygon[:-1]
    elif not (abs(polygon[0, 0]) < 1e-12 and abs(polygon[-1, 0]) < 1e-12):
        raise ValueError("a solid's profile must end on the axis where it starts, or close")
    edges = np.stack([polygon, np.roll(polygon, -1, axis=0)], axis=1)
    z_lo, z_hi = edges[:, :, 1].min(axis=1), edges[:, :, 1].max(axis=1)
    levels = np.unique(polygon[:, 1])
    bands = []
    for low, high in itertools.pairwise(levels):
        middle = 0.5 * (low + high)
        crossing = edges[(z_lo < middle) & (middle < z_hi)]
        if len(crossing) != 2:
            raise ValueError("a horizontal line meets the profile's cross-section more than once")
        ends = np.array([[_r_at(edge, z) for z in (low, high)] for edge in crossing])
        inner, outer = ends[np.argsort(ends.sum(axis=1))]
        bands.append(np.array([[inner[0], low, outer[0], low], [inner[1], high, outer[1], high]]))
    return bands


def _slabs(bands: list[FloatArray]) -> list[FloatArray]:
    """Join consecutive bands into slabs whose cross-sections are convex polygons.

    A slab's rows ``(r_in, z, r_out, z)`` run up its levels; its polygon is convex when the
    outer radius is concave in ``z`` and the inner one convex (each chain turns one way only),
    checked turn by turn with a relative tolerance for the collinear samples of a straight
    profile piece. Bands on the axis (``r_in = 0``) are joined only with bands on the axis, so
    that a slab either touches the axis all along or not at all. The slabs' union is the
    bands' union: a slab's sector hull holds its bands' sector hulls and, its polygon being
    convex, lies within the same sagitta of the exact solid (docs/methods/objects.md).
    """
    slabs: list[FloatArray] = []
    for band in bands:
        if slabs and _joinable(slabs[-1], band):
            slabs[-1] = np.vstack([slabs[-1], band[1:]])
        else:
            slabs.append(band)
    return slabs


def _joinable(slab: FloatArray, band: FloatArray) -> bool:
    """Whether ``band`` on top of ``slab`` leaves the joined cross-section convex."""
    on_axis = np.allclose(slab[:, 0], 0.0)
    if on_axis != bool(np.allclose(band[:, 0], 0.0)):
        return False
    below, top = slab[-2:], band[1]
    # Going up, the outer chain of a convex polygon turns left (towards -r) or runs straight,
    # the inner chain right.
    return _turn(below[:, 2:], top[2:]) >= -_TURN_TOLERANCE and (
        on_axis or _turn(below[:, :2], top[:2]) <= _TURN_TOLERANCE
    )


def _turn(first: FloatArray, point: FloatArray) -> float:
    """Sine of the turn from edge ``first[0] -> first[1]`` to ``first[1] -> point``, in (r, z).

    Positive: a left turn (counter-clockwise in the plane of ``r`` right and ``z`` up).
    """
    a, b = first[1] - first[0], point - first[1]
    length = float(np.hypot(*a) * np.hypot(*b))
    return float(a[0] * b[1] - a[1] * b[0]) / length if length > 0.0 else 0.0


def _r_at(edge: FloatArray, height_m: float) -> float:
    (r0, z0), (r1, z1) = edge
    return float(r0 + (height_m - z0) / (z1 - z0) * (r1 - r0))


@dataclass(frozen=True, eq=False)
class EllipsoidSolid:
    """An ellipsoid with semi-axes ``radii_m`` along the axes of its frame, centred at its origin.

    Attributes:
        name: Solid name.
        radii_m: Semi-axes (a, b, c) [m].
        placement: Placement of the ellipsoid frame in the object frame (4x4).
    """

    name: str
    radii_m: tuple[float, float, float]
    placement: FloatArray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))

    def boundary(self) -> tuple[Patch, ...]:
        """One patch: ``u`` the longitude, ``v`` the latitude [rad]."""
        return (
            Patch(
                self.name,
                EllipsoidSurface(self.radii_m),
                (-math.pi, math.pi),
                (-math.pi / 2.0, math.pi / 2.0),
                (0.0, 0.0),
                self.placement,
            ),
        )

    def mesh(self) -> Mesh:
        """Display mesh within ``DISPLAY_SAGITTA_M`` on the largest radius."""
        n = chord_count(_FULL_TURN, max(self.radii_m), DISPLAY_SAGITTA_M)
        return tessellate(self.boundary()[0], (n, max(2, n // 2)))

    def jet(self, longitude_rad: float, latitude_rad: float) -> SurfaceJet:
        """Return the surface point at the given longitude and latitude (object frame)."""
        return self.boundary()[0].evaluate((longitude_rad, latitude_rad))

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """The ellipsoid itself (coal primitive)."""
        return (CollisionShape(coal.Ellipsoid(*self.radii_m), self.placement, max(self.radii_m)),)


@dataclass(frozen=True, eq=False)
class BoxSolid:
    """A box of edge lengths ``size_m`` along the axes of its frame, centred at its origin.

    Attributes:
        name: Solid name.
        size_m: Edge lengths (x, y, z) [m].
        placement: Placement of the box frame in the object frame (4x4).
    """

    name: str
    size_m: tuple[float, float, float]
    placement: FloatArray = field(default_factory=_identity)

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))

    def boundary(self) -> tuple[Patch, ...]:
        """Six faces; on each, ``(u, v)`` are metres from the face centre."""
        half = np.asarray(self.size_m) / 2.0
        axes = np.eye(3)
        faces = []
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            for sign, (a, b) in ((1.0, (j, k)), (-1.0, (k, j))):
                centre = sign * half[i] * axes[i]
                surface = RectangleSurface(_triple(centre), _triple(axes[a]), _triple(axes[b]))
                name = f"{self.name}[{'+' if sign > 0 else '-'}{'xyz'[i]}]"
                bounds = ((-half[a], half[a]), (-half[b], half[b]))
                faces.append(Patch(name, surface, *bounds, (0.0, 0.0), self.placement))
        return tuple(faces)

    def mesh(self) -> Mesh:
        """Two triangles per face."""
        return Mesh.concatenate(tessellate(face, (1, 1)) for face in self.boundary())

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """The box itself (coal primitive)."""
        radius = float(np.linalg.norm(self.size_m) / 2.0)
        return (CollisionShape(coal.Box(*self.size_m), self.placement, radius),)


def _triple(vector: FloatArray) -> tuple[float, float, float]:
    return float(vector[0]), float(vector[1]), float(vector[2])
