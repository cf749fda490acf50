"""Objects from mesh files (STL, OBJ, PLY): validation, repair, display, collision and sampling.

:func:`load_mesh` reads a triangle mesh with trimesh into a :class:`GraspObject` of one
:class:`MeshSolid`. Collision geometry, as for every object, is a union of convex coal pieces, so
that a link inside the object gets a negative signed distance (a ``coal.BVHModel`` of the triangles
gives none for a link wholly inside):

* ``"prisms"`` (default): one convex prism per triangle, from the triangle inward along its normal
  to the opposite wall (the shortest of four rays cast inward, from its centroid and corners),
  then neighbouring prisms joined into the convex hull of their union while no triangle enters
  that hull deeper than :data:`MERGE_TOLERANCE_M` (:class:`_PrismMerger`; the mug's 1452 prisms
  become 146 pieces, the bottle's 672 become 9). Outside, the distance is that to the triangles
  (a piece leaves the solid only where the wall facing it is concave between the rays, or by
  the merge tolerance: measured <= 0.1 mm on the shipped meshes); inside, every point near a
  triangle lies in a piece holding its prism, and a thin wall (a mug's) is its thickness.
  The depth reported inside is to the nearest piece face, which can underestimate it.
* ``"hull"``: the convex hull, exact for a convex mesh and larger than a concave one (it fills a
  mug's cavity).

Approximate convex decomposition (V-HACD through trimesh) was measured on the shipped mug and
bottle: 1.3-34 s per mesh and a hull surface up to 2-8 mm off the mesh, too coarse beside the
IK's 1.5 mm contact tolerance, so it is not offered.

Before parsing, the file's size and, where the format states it cheaply, its triangle count are
checked (:func:`load_mesh`): a file too large is refused unread. The file is read once and parsed
from its bytes, so no other file (an OBJ's material library) is opened.

Repairs, all made by trimesh and reported in :attr:`MeshSolid.repairs`: duplicate vertices merged,
degenerate (zero-area) and duplicate triangles removed, unreferenced vertices dropped, holes of
three or four edges filled, winding made consistent and outward (each body of a mesh of several
separate bodies on its own; a cavity modelled as an inner shell is thus filled, which changes
nothing outside the object). A mesh still open after that (with the number and size of its
holes), not a manifold (edges of more than two triangles), not orientable, empty, with NaN/inf
vertices, of zero volume, of more than ``max_faces`` triangles, or whose size is not that of a
graspable object in metres (a file in millimetres: give ``scale=1e-3``) gets a
:class:`MeshFileError` naming the problem and what would be valid.
"""

from __future__ import annotations

import collections
import errno
import io
import math
import numbers
import os
import re
import stat
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import coal
import numpy as np
import trimesh
from numpy.typing import NDArray

from sahgrasp.collision.shapes import BuiltOnce, CollisionShape, _support_points, convex_hull
from sahgrasp.core.errors import SahGraspError
from sahgrasp.core.frames import FloatArray, as_placement
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.meshing import Mesh
from sahgrasp.objects.patches import Patch

__all__ = [
    "COLLISION_MODES",
    "MAX_BYTES_PER_FACE",
    "MAX_FACES",
    "MESH_SUFFIXES",
    "SIZE_RANGE_M",
    "MeshFileError",
    "MeshSolid",
    "load_mesh",
]

MESH_SUFFIXES = (".stl", ".obj", ".ply")
"""File types :func:`load_mesh` reads."""

MAX_FACES = 20_000
"""Default cap on the triangle count (one collision prism per triangle, before merging)."""

MAX_BYTES_PER_FACE = 1024
"""Largest file size per accepted triangle [bytes]: an ASCII STL takes about 250 per triangle,
an OBJ with normals and texture coordinates about 350, a binary STL 50. A larger file is refused
before it is read (``max_faces`` times this, plus :data:`_HEADER_BYTES`)."""

_HEADER_BYTES = 1 << 16
"""Bytes allowed besides the triangles' (headers, comments), and the most searched for a PLY's
header."""

SIZE_RANGE_M = (0.005, 2.0)
"""Accepted largest extent [m] of an object: outside it, the file's unit is probably not metres."""

COLLISION_MODES = ("prisms", "hull")
"""Collision geometries :class:`MeshSolid` builds (module docstring)."""

_MIN_THICKNESS_M = 1e-4
"""Thinnest prism [m]: a wall thinner than this is modelled this thick."""

MERGE_TOLERANCE_M = 1e-4
"""Deepest a mesh triangle may enter a joined collision piece [m]: a single triangle's prism
leaves the shipped meshes by up to 0.09 mm already (module docstring)."""

MERGE_BUDGET = 500_000
"""Triangle tests (coal queries, at most) a mesh's merge may make; then the remaining prisms
stay single pieces. It bounds the build at a few seconds for any mesh: the shipped mug and bottle
need about 275 000 and 321 000, and a nearly convex mesh's cost grows with the square of its
triangles."""

SIMULATION_MERGE_BUDGET = 4 * MERGE_BUDGET
"""Triangle tests the merge of :meth:`MeshSolid.simulation_shapes` may make: a simulation
collides every piece at every step, so where :data:`MERGE_BUDGET` stops a merge early it pays
to merge further (the trimesh torus of ``sahgrasp bench plan``: 1379 pieces, 161 within this
budget in about 1.4 s more, and twice the hold tests per second)."""

_SLIVER_M = 1e-6
"""Offset [m] of the slivers :class:`_PrismMerger` tests the triangles as (outside the mesh)."""

_AREA_EPS_M2 = 1e-12
"""Triangles of smaller area [m^2] are degenerate and removed."""


class MeshFileError(SahGraspError):
    """A mesh file is missing, unreadable, empty, open, flat, too large or in the wrong unit."""


@dataclass(frozen=True, eq=False)
class MeshSolid(BuiltOnce):
    """A closed triangle mesh in the object frame (outward winding), with convex collision pieces.

    Attributes:
        name: Solid name.
        vertices_m: Vertex positions [m], (N, 3).
        faces: Vertex indices per triangle, counter-clockwise seen from outside, (M, 3).
        collision: ``"prisms"`` or ``"hull"`` (module docstring).
        repairs: What loading changed, in words (empty: the file was used as it is).
    """

    name: str
    vertices_m: FloatArray
    faces: NDArray[np.int64]
    collision: str = "prisms"
    repairs: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if self.collision not in COLLISION_MODES:
            raise MeshFileError(
                f"unknown collision geometry {self.collision!r}; valid: {list(COLLISION_MODES)}"
            )

    @cached_property
    def trimesh(self) -> trimesh.Trimesh:
        """The mesh as a ``trimesh.Trimesh`` (ray casting, sampling, proximity)."""
        return trimesh.Trimesh(self.vertices_m, self.faces, process=False)

    def boundary(self) -> tuple[Patch, ...]:
        """No parametric patches: sample the surface with :meth:`sample_surface` instead."""
        return ()

    def mesh(self) -> Mesh:
        """The triangles themselves."""
        return Mesh(self.vertices_m, self.faces)

    def collision_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex pieces whose union is the solid (built once)."""
        return self._pieces(MERGE_BUDGET)

    def simulation_shapes(self) -> tuple[CollisionShape, ...]:
        """Convex pieces for a physics simulation (built once).

        Those of :meth:`collision_shapes`, merged further within
        :data:`SIMULATION_MERGE_BUDGET` and the same tolerance where :data:`MERGE_BUDGET`
        stopped their merge.
        """
        return self._pieces(SIMULATION_MERGE_BUDGET)

    @cached_property
    def _merges(self) -> dict[int, tuple[tuple[CollisionShape, ...], int]]:
        """The merges made so far: per budget, the pieces and the triangle tests they took."""
        return {}

    def _pieces(self, budget: int) -> tuple[CollisionShape, ...]:
        """The pieces within ``budget`` triangle tests, from a merge already made if it serves.

        The merge is greedy and deterministic, and the budget only ever stops it: a merge that
        took fewer tests than two budgets gives the same pieces under both.
        """
        for made, (shapes, tests) in self._merges.items():
            if made == budget or tests < min(made, budget):
                return shapes
        shapes, tests = self._merge(budget)
        self._merges[budget] = (shapes, tests)
        return shapes

    def _merge(self, budget: int) -> tuple[tuple[CollisionShape, ...], int]:
        """The pieces within ``budget`` triangle tests, and the tests the merge took."""
        # A convex mesh is its own hull: exact, and the merge's worst case (one piece tested
        # against every triangle at each join) avoided.
        if self.collision == "hull" or self.trimesh.is_convex:
            return (convex_hull(self.vertices_m),), 0
        corners = self.vertices_m[self.faces]  # (M, 3, 3)
        depth = self.wall_thickness_m()[:, None, None] * self.trimesh.face_normals[:, None, :]
        prisms = np.concatenate([corners, corners - depth], axis=1)
        merger = _PrismMerger(self.trimesh, corners, budget)
        return tuple(merger.merge(prisms)), merger.tests

    def wall_thickness_m(self) -> FloatArray:
        """Per triangle, the solid's thickness [m] under it: shortest of four inward rays."""
        mesh = self.trimesh
        corners = self.vertices_m[self.faces]
        centroids = corners.mean(axis=1)
        # The centroid and the corners (nudged inside, so that a ray misses the neighbours): a
        # prism whose six vertices are inside a convex part of the solid is inside it.
        starts = np.concatenate([centroids[:, None], 0.99 * corners + 0.01 * centroids[:, None]], 1)
        normals = np.repeat(mesh.face_normals[:, None], 4, axis=1).reshape(-1, 3)
        origins = starts.reshape(-1, 3) - 1e-7 * normals
        locations, rays, _ = mesh.ray.intersects_location(origins, -normals, multiple_hits=False)
        reach = np.full(len(origins), float(np.ptp(self.vertices_m, axis=0).max()))
        reach[rays] = np.linalg.norm(locations - origins[rays], axis=1)
        return np.maximum(reach.reshape(-1, 4).min(axis=1), _MIN_THICKNESS_M)

    def sample_surface(self, count: int, seed: int = 0) -> tuple[FloatArray, FloatArray]:
        """``count`` points uniform on the surface and their outward unit normals, object frame."""
        points, faces = trimesh.sample.sample_surface(self.trimesh, count, seed=seed)
        return np.asarray(points, dtype=np.float64), self.trimesh.face_normals[faces]

    def nearest_surface(self, points_m: Any) -> tuple[FloatArray, FloatArray]:
        """The surface points nearest to ``points_m`` (N, 3) and the outward normals there."""
        query = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
        nearest, _, faces = trimesh.proximity.closest_point(self.trimesh, query)
        return np.asarray(nearest, dtype=np.float64), self.trimesh.face_normals[faces]


class _PrismMerger:
    """Joins neighbouring triangles' prisms into convex pieces that stay inside the mesh.

    Region growing, deterministic: from the first triangle not yet taken, the prisms of
    neighbouring triangles (sharing an edge) join the piece while no triangle of the mesh enters
    the convex hull of the joined prisms deeper than :data:`MERGE_TOLERANCE_M`. A triangle is
    tested as a sliver just outside the surface (between 1 and 2 um along its outward normal):
    a triangle on the hull's boundary (the hull's own faces, coplanar neighbours) is then clear
    of it, measured by GJK alone; one that enters the hull is measured by EPA, and where EPA
    fails (it returns no finite depth for some shallow, flat contacts) the sliver moved out by
    the tolerance must not touch the hull. A triangle entering the hull deeper than the
    tolerance would mean that the hull reaches outside the surface (across a cavity, a
    handle's gap, a concave edge); the hull's erosion by the tolerance, which no triangle
    meets, lies inside the solid, so the hull leaves the solid by about the tolerance at most
    (docs/methods/meshes.md). Every piece holds the prisms it joined, so the union of the
    pieces holds the union of the prisms. After ``budget`` triangle tests (:data:`MERGE_BUDGET`)
    the remaining prisms stay single pieces, which bounds the build for large meshes.
    """

    def __init__(
        self, mesh: trimesh.Trimesh, corners: FloatArray, budget: int = MERGE_BUDGET
    ) -> None:
        normals = mesh.face_normals[:, None, :]
        outside = corners + _SLIVER_M * normals
        self._triangles = [
            convex_hull(points)
            for points in np.concatenate([outside, outside + _SLIVER_M * normals], axis=1)
        ]
        self._at_triangles = [t.transform(np.eye(4)) for t in self._triangles]
        # Each sliver moved out by the tolerance: the test where EPA gives no depth.
        self._moved = [
            coal.Transform3s(np.eye(3), t.placement[:3, 3] + MERGE_TOLERANCE_M * n)
            for t, n in zip(self._triangles, mesh.face_normals, strict=True)
        ]
        self._lows, self._highs = corners.min(axis=1), corners.max(axis=1)
        self._neighbours: list[list[int]] = [[] for _ in range(len(corners))]
        for a, b in mesh.face_adjacency.tolist():
            self._neighbours[a].append(b)
            self._neighbours[b].append(a)
        self._budget = budget
        self.tests = 0
        """Triangle tests made so far (the budget stops the merge once they reach it)."""
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._collision = coal.CollisionRequest()

    def merge(self, prisms: FloatArray) -> list[CollisionShape]:
        """The convex pieces, each the hull of the prisms (M, 6, 3) of a set of neighbours."""
        taken = np.zeros(len(prisms), dtype=bool)
        pieces = []
        for seed in range(len(prisms)):
            if taken[seed]:
                continue
            taken[seed] = True
            piece, points = convex_hull(prisms[seed]), prisms[seed]
            frontier = collections.deque(self._neighbours[seed])
            while frontier and self.tests < self._budget:
                face = frontier.popleft()
                if taken[face]:
                    continue
                joined = convex_hull(np.vstack([points, prisms[face]]))
                joined_points = _support_points(joined)
                if self._inside(joined, joined_points):
                    taken[face] = True
                    piece, points = joined, joined_points
                    frontier.extend(n for n in self._neighbours[face] if not taken[n])
            pieces.append(piece)
        return pieces

    def _inside(self, piece: CollisionShape, points: FloatArray) -> bool:
        """Whether no triangle enters ``piece`` (vertices ``points``) deeper than the tolerance.

        The tolerance is :data:`MERGE_TOLERANCE_M`.
        """
        low = points.min(axis=0) - MERGE_TOLERANCE_M
        high = points.max(axis=0) + MERGE_TOLERANCE_M
        near = np.all((self._lows <= high) & (self._highs >= low), axis=1)
        self.tests += int(np.count_nonzero(near))
        at_piece = piece.transform(np.eye(4))
        for t in np.flatnonzero(near).tolist():
            sliver = self._triangles[t].geometry
            distance = coal.distance(
                piece.geometry,
                at_piece,
                sliver,
                self._at_triangles[t],
                self._request,
                coal.DistanceResult(),
            )
            if -1.0 < distance < math.inf:  # GJK's gap or EPA's depth
                if distance < -MERGE_TOLERANCE_M:
                    return False
            elif coal.collide(
                piece.geometry,
                at_piece,
                sliver,
                self._moved[t],
                self._collision,
                coal.CollisionResult(),
            ):
                return False
        return True


def load_mesh(
    path: str | os.PathLike[str],
    name: str | None = None,
    scale: float = 1.0,
    T_world_object: Any = None,
    rgba: tuple[float, float, float, float] = (0.75, 0.55, 0.35, 1.0),
    max_faces: int = MAX_FACES,
    collision: str = "prisms",
) -> GraspObject:
    """Read an STL, OBJ or PLY file into a graspable object of one :class:`MeshSolid`.

    The file's size, and its triangle count where the format states it cheaply (a binary STL's
    header, a PLY's ``element face``, an OBJ's ``f`` lines, an ASCII STL's facets), are checked
    before it is parsed, so that a file too large is refused without being read into memory.
    The file is read once, as bytes, and parsed from them: nothing else is opened (an OBJ's
    material library is not read). What the repairs changed is in the solid's
    :attr:`MeshSolid.repairs` (and :attr:`GraspObject.repairs`).

    Args:
        path: The mesh file; its coordinates are the object frame.
        name: Object name (default: the file name without suffix).
        scale: The file's unit in metres (e.g. ``1e-3`` for a file in millimetres).
        T_world_object: The object's placement in the world (identity if None).
        rgba: Display colour.
        max_faces: Largest accepted triangle count; files over :data:`MAX_BYTES_PER_FACE`
            bytes per accepted triangle are refused unread.
        collision: ``"prisms"`` or ``"hull"`` (module docstring).

    Raises:
        MeshFileError: The file is missing, a loop of links, not a regular file, of another
            type, too large, unreadable, empty, not finite, open or not manifold after repair,
            of zero volume, larger than ``max_faces``, or not object-sized.
    """
    if not isinstance(path, str | os.PathLike) or not str(path):
        raise MeshFileError(f"path must be the path of an STL, OBJ or PLY file, got {path!r}")
    path = Path(path)
    if collision not in COLLISION_MODES:
        raise MeshFileError(
            f"unknown collision geometry {collision!r}; valid: {list(COLLISION_MODES)}"
        )
    real = isinstance(scale, numbers.Real) and not isinstance(scale, bool | np.bool_)
    if not (real and math.isfinite(scale) and scale > 0):
        raise MeshFileError(f"scale must be a finite factor > 0 to metres, got {scale!r}")
    whole = isinstance(max_faces, numbers.Integral) and not isinstance(max_faces, bool | np.bool_)
    if not (whole and max_faces >= 1):
        raise MeshFileError(f"max_faces must be an integer >= 1, got {max_faces!r}")
    max_faces = int(max_faces)
    mesh = _read(path, max_faces)
    if len(mesh.faces) > max_faces:
        raise MeshFileError(_too_many(path, len(mesh.faces), max_faces))
    mesh.apply_scale(scale)
    repairs = _repair(mesh, path)
    _check_size(mesh, path, scale)
    solid = MeshSolid(
        name or path.stem,
        np.array(mesh.vertices, dtype=np.float64),
        np.array(mesh.faces, dtype=np.int64),
        collision,
        repairs,
    )
    placement = as_placement(np.eye(4) if T_world_object is None else T_world_object)
    return GraspObject(solid.name, (solid,), rgba, placement)


def _shown(path: Path) -> str:
    """``path`` for a message: control characters escaped, at most about 120 characters."""
    text = str(path)
    text = text if text.isprintable() else ascii(text)[1:-1]
    return text if len(text) <= 120 else f"{text[:60]}...{text[-57:]} ({len(text)} characters)"


def _too_many(path: Path, faces: int, max_faces: int, what: str = "has") -> str:
    return (
        f"{_shown(path)} {what} {faces} triangles, more than max_faces = {max_faces} (one "
        "collision prism each); decimate it (e.g. MeshLab's quadric edge collapse) or raise "
        "max_faces"
    )


def _read(path: Path, max_faces: int) -> trimesh.Trimesh:
    """The file's triangles as trimesh parses them, after the checks that need no parsing."""
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshFileError(
            f"{_shown(path)}: unsupported mesh type; use one of {list(MESH_SUFFIXES)}"
        )
    data = _read_bytes(path, max_faces)
    counted = _face_count(data, suffix)
    if counted is not None and counted > max_faces:
        raise MeshFileError(_too_many(path, counted, max_faces, "declares"))
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on malformed files
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
        raise MeshFileError(f"{_shown(path)} is not a readable mesh ({reason})") from None
    faces = getattr(loaded, "faces", None)
    if not isinstance(loaded, trimesh.Trimesh) or faces is None or len(faces) == 0:
        raise MeshFileError(f"{_shown(path)} holds no triangles; a closed triangle mesh is needed")
    if not np.all(np.isfinite(loaded.vertices)):
        raise MeshFileError(f"{_shown(path)} has NaN or inf vertex coordinates; all must be finite")
    return loaded


def _read_bytes(path: Path, max_faces: int) -> bytes:
    """The file's bytes, refused unread when it is not a regular file or too large.

    The file is opened without blocking (a named pipe would otherwise wait for a writer) and
    checked through the open descriptor, so that what is checked is what is read.
    """
    limit = max_faces * MAX_BYTES_PER_FACE + _HEADER_BYTES
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        if "\0" in str(path):
            raise ValueError("embedded null byte")
        fd = os.open(path, flags)
    except OSError as exc:
        raise MeshFileError(_unreadable(path, exc)) from None
    except ValueError:  # a NUL byte or a lone surrogate: no file has that name
        raise MeshFileError(f"mesh path {_shown(path)} is not a valid file name") from None
    with os.fdopen(fd, "rb") as stream:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise MeshFileError(
                f"{_shown(path)} is not a regular file (a folder, pipe or device); give a mesh file"
            )
        if info.st_size > limit:
            raise MeshFileError(_too_large(path, info.st_size, limit, max_faces))
        try:
            data = stream.read(limit + 1)
        except OSError as exc:
            raise MeshFileError(_unreadable(path, exc)) from None
    if len(data) > limit:  # it grew since it was looked at
        raise MeshFileError(_too_large(path, len(data), limit, max_faces))
    return data


def _too_large(path: Path, size: int, limit: int, max_faces: int) -> str:
    return (
        f"{_shown(path)} holds {size} bytes, more than {limit} for max_faces = {max_faces} "
        f"triangles ({MAX_BYTES_PER_FACE} bytes each at most); it was not read: decimate it "
        "(e.g. MeshLab's quadric edge collapse) or raise max_faces"
    )


def _unreadable(path: Path, exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return f"mesh file {_shown(path)} is a loop of symbolic links; give the file itself"
    if exc.errno in (errno.ENOENT, errno.ENOTDIR):
        return f"mesh file not found: {_shown(path)}"
    if exc.errno == errno.ENAMETOOLONG:
        return f"mesh path {_shown(path)} is too long for the file system"
    return f"cannot read mesh file {_shown(path)}: {exc.strerror or exc}"


_PLY_FACES = re.compile(rb"^element\s+face\s+(\d+)\s*$", re.MULTILINE)
_STL_FACETS = re.compile(rb"endfacet", re.IGNORECASE)
_OBJ_FACES = re.compile(rb"^[ \t]*f[ \t]", re.MULTILINE)


def _face_count(data: bytes, suffix: str) -> int | None:
    """The triangle count a file states without being parsed (a lower bound for OBJ), or None.

    A binary STL's header gives it (when the size agrees: 84 + 50 bytes per triangle), an ASCII
    STL has one ``endfacet`` per triangle, a PLY's header declares ``element face N`` (polygons
    may make more triangles), an OBJ has one ``f`` line per polygon.
    """
    if suffix == ".stl":
        declared = int.from_bytes(data[80:84], "little") if len(data) >= 84 else None
        if declared is not None and len(data) == 84 + 50 * declared:
            return declared
        if data.lstrip()[:5].lower() == b"solid":
            return len(_STL_FACETS.findall(data))
        return declared
    if suffix == ".ply":
        end = data.find(b"end_header")
        found = _PLY_FACES.search(data, 0, end if end >= 0 else min(len(data), _HEADER_BYTES))
        return int(found.group(1)) if found else None
    return len(_OBJ_FACES.findall(data))


def _repair(mesh: trimesh.Trimesh, path: Path) -> tuple[str, ...]:
    """Fix what trimesh can fix in place and say what; raise if the mesh cannot be an object."""
    repairs = []
    counts = (len(mesh.vertices), len(mesh.faces))
    mesh.merge_vertices()
    if len(mesh.vertices) < counts[0]:
        repairs.append(f"merged {counts[0] - len(mesh.vertices)} duplicate vertices")
    keep = mesh.area_faces > _AREA_EPS_M2
    keep &= mesh.unique_faces()  # a mask: the first of each set of duplicates
    if not keep.all():
        repairs.append(f"removed {int((~keep).sum())} degenerate or duplicate triangles")
        mesh.update_faces(keep)
    if len(mesh.faces) == 0:
        raise MeshFileError(f"{_shown(path)}: every triangle is degenerate (zero area)")
    unreferenced = len(mesh.vertices)
    mesh.remove_unreferenced_vertices()
    if len(mesh.vertices) < unreferenced:
        repairs.append(f"dropped {unreferenced - len(mesh.vertices)} unreferenced vertices")
    if not mesh.is_watertight:
        _close(mesh, path)
        repairs.append("filled holes")
    bodies = int(mesh.body_count)
    given = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)
    if not mesh.is_winding_consistent:
        raise MeshFileError(
            f"{_shown(path)} is not orientable (no consistent inside and outside, like a Moebius "
            "strip); a graspable object needs a closed surface bounding a solid"
        )
    trimesh.repair.fix_inversion(mesh, multibody=True)
    flipped = int(np.count_nonzero(np.any(given != mesh.faces, axis=1)))
    if flipped == len(mesh.faces):
        repairs.append("turned the surface outward (its triangles faced inward)")
    elif flipped:
        repairs.append(
            f"flipped {flipped} of {len(mesh.faces)} triangles to face outward (inconsistent "
            "winding or a body inside out)"
        )
    if bodies > 1:
        repairs.append(f"{bodies} separate bodies, each oriented outward, taken together")
    if not mesh.volume > 0:
        raise MeshFileError(
            f"{_shown(path)} encloses no volume ({mesh.volume:.3g} m^3): it is flat"
        )
    return tuple(repairs)


def _close(mesh: trimesh.Trimesh, path: Path) -> None:
    """Fill the holes trimesh fills (of three or four edges), or say why the mesh stays open.

    Raises:
        MeshFileError: Edges bound one triangle only (holes trimesh does not fill) or more than
            two (a surface that is not a manifold: touching bodies, inner walls, fins).
    """
    edges, shared = _edge_use(mesh)
    if not np.any(shared > 2):
        trimesh.repair.fill_holes(mesh)
        if mesh.is_watertight:
            return
        edges, shared = _edge_use(mesh)
    problems = []
    open_edges = edges[shared == 1]
    if len(open_edges):
        holes, largest = _loops(open_edges)
        problems.append(
            f"it is open: {_count(len(open_edges), 'edge')} bound one triangle only, in "
            f"{_count(holes, 'hole')}, the largest of {_count(largest, 'edge')} (trimesh fills "
            "holes of 3 or 4 edges only)"
        )
    crowded = int(np.count_nonzero(shared > 2))
    if crowded:
        problems.append(
            f"it is not a manifold surface: {_count(crowded, 'edge')} shared by more than two "
            "triangles each (bodies touching along an edge, inner walls or fins)"
        )
    raise MeshFileError(
        f"{_shown(path)} cannot be a solid object: {'; '.join(problems)}. A graspable object "
        "needs a closed surface whose every edge joins exactly two triangles: repair it (e.g. "
        "MeshLab's 'Close Holes' and 'Repair non Manifold Edges', or Blender's 3D-Print "
        "Toolbox) or export it as a solid"
    )


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" if number == 1 else f"{number} {noun}s"


def _edge_use(mesh: trimesh.Trimesh) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Each distinct edge (sorted vertex pair) and how many triangles share it."""
    edges, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    return np.asarray(edges, dtype=np.int64), np.asarray(counts, dtype=np.int64)


def _loops(edges: NDArray[np.int64]) -> tuple[int, int]:
    """The number of connected pieces of a set of boundary edges and the edges of the largest."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nodes, local = np.unique(edges, return_inverse=True)
    local = local.reshape(-1, 2)
    graph = coo_matrix(
        (np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(len(nodes), len(nodes))
    )
    count, labels = connected_components(graph, directed=False)
    per_piece = np.bincount(labels[local[:, 0]], minlength=count)
    return int(count), int(per_piece.max())


def _check_size(mesh: trimesh.Trimesh, path: Path, scale: float) -> None:
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    lo, hi = SIZE_RANGE_M
    if not lo <= extent <= hi:
        unit = " (is the file in millimetres?)" if extent > hi else ""
        raise MeshFileError(
            f"{_shown(path)} is {extent:.4g} m across at scale {scale:g}{unit}; a graspable "
            f"object is {lo}-{hi} m: give the file's unit in metres, scale=1e-3 for a file in "
            'millimetres, 1e-2 for centimetres (in a targets file: "scale": 0.001 in its mesh '
            "object)"
        )
