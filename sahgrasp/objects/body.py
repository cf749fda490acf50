"""A graspable object: named solids placed in the world, with display and collision data."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.collision.shapes import CollisionShape, signed_distances
from sahgrasp.core.frames import FloatArray, as_placement
from sahgrasp.objects.meshing import Mesh
from sahgrasp.objects.patches import Patch
from sahgrasp.objects.solids import Solid

__all__ = ["GraspObject"]


@dataclass(frozen=True, eq=False)
class GraspObject:
    """An object to grasp: the union of its solids, placed in the world.

    Plain data (picklable); the display mesh and the coal shapes are built on request.

    Attributes:
        name: Object name.
        solids: The solids, each placed in the object frame.
        rgba: Display colour, components in [0, 1].
        T_world_object: Placement of the object frame in the world (4x4).
    """

    name: str
    solids: tuple[Solid, ...]
    rgba: tuple[float, float, float, float]
    T_world_object: FloatArray = field(default_factory=lambda: as_placement(np.eye(4)))

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_world_object", as_placement(self.T_world_object))

    def solid(self, name: str) -> Solid:
        """Return the solid called ``name``.

        Raises:
            KeyError: No such solid; the message lists the object's solids.
        """
        for s in self.solids:
            if s.name == name:
                return s
        raise KeyError(f"{self.name} has no solid {name!r}; it has {[s.name for s in self.solids]}")

    @property
    def repairs(self) -> tuple[str, ...]:
        """What loading changed in the solids' files, in words (empty: used as they are).

        Only mesh files are repaired (:attr:`sahgrasp.objects.MeshSolid.repairs`).
        """
        return tuple(r for s in self.solids for r in getattr(s, "repairs", ()))

    def placed(self, T_world_object: Any) -> GraspObject:
        """Return the same object at another placement in the world.

        The solids are shared, not copied: their display meshes and collision pieces, built in
        the object frame, serve every placement.
        """
        return dataclasses.replace(self, T_world_object=as_placement(T_world_object))

    def mesh(self) -> Mesh:
        """Display mesh of all solids, in the object frame (place it with ``T_world_object``)."""
        return Mesh.concatenate(s.mesh() for s in self.solids)

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex coal pieces whose union is the object, in the object frame."""
        return tuple(shape for s in self.solids for shape in s.collision_shapes())

    def simulation_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex pieces for a physics simulation, in the object frame.

        A solid's ``simulation_shapes()`` where it has one (a mesh whose merge of collision
        pieces stopped at its budget merges them further,
        :meth:`~sahgrasp.objects.MeshSolid.simulation_shapes`), otherwise its collision pieces.
        """
        return tuple(
            shape
            for s in self.solids
            for shape in getattr(s, "simulation_shapes", s.collision_shapes)()
        )

    def surface_patches(self) -> tuple[Patch, ...]:
        """The solids' boundary patches in the world frame (parts inside other solids included)."""
        return tuple(p.placed(self.T_world_object) for s in self.solids for p in s.boundary())

    def signed_distance(self, points_m: ArrayLike, probe_radius_m: float = 0.0) -> FloatArray:
        """Signed distance [m] of balls about world points (N, 3) to the object (collision.py).

        Positive outside, negative inside; build the shapes once and call with many points.
        """
        return signed_distances(
            self.collision_shapes(), self.T_world_object, points_m, probe_radius_m
        )
