"""From the case's geometry to a checked mesh, with the size guard that runs before meshing."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactfem.case import Case, MeshFileGeometry, MeshSettings, Obstacle, PolygonGeometry, RectangleGeometry
from contactfem.errors import CaseError, MeshCapError, MeshError
from contactfem.estimate import MemoryLimit, largest_mesh_points, memory_limit
from contactfem.mesh import (
    Mesh,
    check_mesh,
    read_gmsh,
    refine_uniform,
    structured_rectangle,
    triangulate_domain,
)
from contactfem.mesh.core import coordinate_span
from contactfem.mesh.polygon import loop_signed_area


@dataclass(frozen=True, eq=False)
class MeshRequest:
    """What a mesh is made from: a geometry, its mesh settings, the contact parts the sizes
    grade towards and the obstacle whose ends refine them further.

    The case's own (:meth:`of`), or a coarser level's that mesh sequencing derives from it
    (:func:`contactfem.sequencing.coarser`): the case itself is never rewritten, only the
    request. Its fields are named as the case's, so that what reads a case's geometry and
    mesh settings (:func:`estimate_triangles`) reads a request's alike.
    """

    geometry: RectangleGeometry | PolygonGeometry | MeshFileGeometry
    mesh: MeshSettings
    contact_parts: tuple[str, ...]
    obstacle: Obstacle

    @classmethod
    def of(cls, case: Case) -> "MeshRequest":
        return cls(geometry=case.geometry, mesh=case.mesh, contact_parts=tuple(case.contact_parts),
                   obstacle=case.obstacle)


_GEOMETRY_KEYS = {RectangleGeometry: "rectangle", PolygonGeometry: "polygon", MeshFileGeometry: "mesh_file"}


def build_mesh(case: Case, refine: int | None = None, request: MeshRequest | None = None) -> Mesh:
    """Mesh the case's geometry (or a coarser level's ``request``), refine it ``refine``
    times (default: the request's), and check it. Messages name the case's file and keys."""
    shape = MeshRequest.of(case) if request is None else request
    limit = memory_limit()  # read once: the cgroup files and rlimits behind it cost 0.2 ms
    _refuse_oversized(case, shape, refine, limit)
    try:
        mesh = _mesh_geometry(case, shape, limit)
    except MeshCapError as error:
        raise MeshError(_capped_message(case, shape, limit, error)) from None
    except MeshError as error:
        raise MeshError(f"{case.source.name}: geometry.{_GEOMETRY_KEYS[type(shape.geometry)]}: {error}") from None
    missing = [p.name for p in case.parts if p.name not in mesh.part_names]
    if missing:
        raise CaseError(
            f"{case.source.name}: boundary.{missing[0]}: {_mesh_origin(shape)} has no boundary part "
            f"named {missing[0]!r}; it has {', '.join(mesh.part_names)}"
        )
    times = shape.mesh.refine if refine is None else refine
    # Only now is the mesh's real size known (a mesh file, or a polygon with small features
    # meshed finer than its size asked): the same model checks it before refinements allocate.
    _refuse_oversized(case, shape, refine, limit, base=mesh.n_triangles)
    if times:
        mesh = refine_uniform(mesh, times)
    try:
        check_mesh(mesh)
    except MeshError as error:  # e.g. slivers of a rectangle of aspect 1e9: name the key
        raise MeshError(f"{case.source.name}: geometry.{_GEOMETRY_KEYS[type(shape.geometry)]}: {error}") from None
    return mesh


def _capped_message(case: Case, shape: MeshRequest, limit: MemoryLimit, error: MeshCapError) -> str:
    """One line for a mesh whose refinement the memory budget's cap on nodes stopped: the keys
    that ask for it, what the cap is and what sets it, and what to turn. The case's own keys are
    named (a coarser level of mesh sequencing is made from them)."""
    settings = case.mesh
    keys = f"mesh.size = {settings.size:g}"
    turn = "a larger mesh.size"
    if settings.contact_size is not None:
        keys += f", mesh.contact_size = {settings.contact_size:g}"
        turn = "a larger mesh.size or mesh.contact_size"
    geometry = f"geometry.{_GEOMETRY_KEYS[type(shape.geometry)]}"
    return (
        f"{case.source.name}: {keys}: {geometry}: {error}; {error.max_points:,} nodes is the most whose solve "
        f"fits {limit.source} with {_backend(case)}, and a coarser mesh is not solved in its place; use {turn}, "
        "a simpler geometry (fewer or smoother profile points, no sliver or narrow gap) or more memory"
    )


def estimate_triangles(shape: Case | MeshRequest, refine: int | None = None) -> int:
    """Triangles a case (or a :class:`MeshRequest`) will be meshed into, estimated before
    meshing (0 for mesh files)."""
    geometry, settings = shape.geometry, shape.mesh
    times = settings.refine if refine is None else refine
    if isinstance(geometry, RectangleGeometry):
        nx, ny = settings.divisions
        base = (4 if settings.diagonal == "crossed" else 2) * nx * ny
    elif isinstance(geometry, PolygonGeometry):
        v = geometry.outer.vertices
        span = coordinate_span(v)
        extent = max(span.max(), 1e-300)
        # The body's area (its outer loop's, arcs included) over the area of an equilateral
        # triangle of side h, twice: Triangle makes 1.5-1.6 triangles per such area under
        # the size bound (a plate with a hole, a 3 x 1 block). The square of the bounding
        # box served before, 128 times the area of a 64 x 0.5 strip under a long profile,
        # whose 119 000 triangles at 16 000 points it took for a million.
        area = abs(loop_signed_area(geometry.outer))
        base = int(2.0 * area / (np.sqrt(3) / 4 * settings.size**2)) + 1
        # Every input edge is kept, and Triangle grades from its length to the mesh size:
        # measured 5.5-6 triangles per edge of a rough profile (1k-64k edges, size 10-800
        # times the edge), whatever the size.
        base += 7 * sum(len(loop.vertices) for loop in (geometry.outer, *geometry.holes))
        if settings.contact_size is not None:
            # The graded band: ∫ L dd / area(h(d)) with h = hc + g d is L / (√3/4 · g · hc),
            # with L bounded by π times the extent.
            band = np.pi * extent / (np.sqrt(3) / 4 * settings.grading * settings.contact_size)
            base += int(band)
    else:
        return 0
    return int(base * 4**times)


def _contact_grading(shape: MeshRequest):
    """The size field h(x) = min(size, contact_size + grading · distance(x, ΓC)).

    The distance is to points sampled on the contact edges of the geometry at a quarter
    of contact_size (:func:`_contact_samples`), so it is exact to that spacing.
    """
    from scipy.spatial import cKDTree

    settings = shape.mesh
    samples, ends = _contact_samples(shape)
    # Sliding-midpoint splits: the samples lie along curves, and the queries, most of them
    # near ΓC on a graded mesh, ran 1.4x faster than in the default median-split tree.
    tree = cKDTree(samples, balanced_tree=False, compact_nodes=False)
    end_tree = cKDTree(ends) if len(ends) else None
    end_size = settings.contact_size / END_REFINEMENT

    def reach(nearest: float) -> float:
        """The distance beyond which h is ``size`` whatever the distance: the nearest-point
        search stops there. Far from ΓC the nearest sample is otherwise sought among many
        almost as near (the centre of a disk is as far from every point of its rim): the
        queries took 65% of meshing the Hertz disk (0.13 s of 0.2 s at 32 000 unknowns;
        0.065 s with the bound). ``mesh.grading`` is at least 0.01 (:mod:`contactfem.case`)."""
        return max((settings.size - nearest) / settings.grading, 0.0)

    def size(points: np.ndarray) -> np.ndarray:
        distance, _ = tree.query(points, distance_upper_bound=reach(settings.contact_size))
        h = np.minimum(settings.size, settings.contact_size + settings.grading * distance)
        if end_tree is not None:
            # The pressure is singular (like 1/√r) at the end of a finite obstacle pressed
            # into the body: the mesh is finer there still.
            to_end, _ = end_tree.query(points, distance_upper_bound=reach(end_size))
            h = np.minimum(h, end_size + settings.grading * to_end)
        return h

    return size


def _contact_samples(shape: MeshRequest) -> tuple[np.ndarray, np.ndarray]:
    """Points on ΓC's edges, a quarter of ``mesh.contact_size`` apart (only those in front
    of a finite obstacle, which alone can touch it), and the points of ΓC facing the ends
    of a finite obstacle (:func:`_segment_ends_on_body`)."""
    settings = shape.mesh
    samples = []
    contact = set(shape.contact_parts)
    for loop in (shape.geometry.outer, *shape.geometry.holes):
        k = len(loop.vertices)
        on_contact = loop.on_parts(contact)
        straight = on_contact & loop.straight_edges
        # All straight contact edges at once: a rough profile has thousands.
        start, end = loop.vertices[straight], np.roll(loop.vertices, -1, axis=0)[straight]
        counts = np.maximum(2, (4 * np.hypot(*(end - start).T) / settings.contact_size).astype(np.int64) + 2)
        edge = np.repeat(np.arange(len(start)), counts)
        t = (np.arange(len(edge)) - np.repeat(np.cumsum(counts) - counts, counts)) / (counts[edge] - 1)
        samples.append(start[edge] + t[:, None] * (end - start)[edge])
        for i in np.flatnonzero(on_contact & ~straight):
            arc = loop.edge_arcs[i]
            start, end = loop.vertices[i], loop.vertices[(i + 1) % k]
            center = np.asarray(arc.center)
            radius = np.linalg.norm(start - center)
            a0 = np.arctan2(*(start - center)[::-1])
            a1 = np.arctan2(*(end - center)[::-1])
            sweep = (a1 - a0) % (2 * np.pi) if arc.ccw else -((a0 - a1) % (2 * np.pi))
            n = max(2, int(4 * radius * abs(sweep) / settings.contact_size) + 2)
            angle = a0 + sweep * np.linspace(0.0, 1.0, n)
            samples.append(center + radius * np.stack([np.cos(angle), np.sin(angle)], axis=1))
    samples = np.concatenate(samples)
    ends = _segment_ends_on_body(shape, samples)
    if shape.obstacle.ends is not None:
        from contactfem.discretize.obstacles import obstacle_of

        facing = obstacle_of(shape.obstacle).faces(samples)
        samples = samples[facing] if facing.any() else samples
    return samples, ends


#: How much finer than ``mesh.contact_size`` the mesh is at the ends of a finite obstacle
#: that lie on the body (a flat punch's edges).
END_REFINEMENT = 4


def _segment_ends_on_body(shape: MeshRequest, samples: np.ndarray) -> np.ndarray:
    """The points of ΓC (from ``samples`` (k, 2)) facing the ends of a finite obstacle that lie
    within ΓC's extent along it (a punch narrower than the body), (e, 2); empty otherwise."""
    if shape.obstacle.ends is None:
        return np.zeros((0, 2))
    from contactfem.discretize.obstacles import obstacle_of

    obstacle = obstacle_of(shape.obstacle)
    along = obstacle.abscissa(samples)
    found = []
    for end in obstacle.abscissa(obstacle.ends):
        if along.min() < end < along.max():
            found.append(samples[np.argmin(np.abs(along - end))])
    return np.array(found).reshape(-1, 2)


def _mesh_origin(shape: MeshRequest) -> str:
    if isinstance(shape.geometry, MeshFileGeometry):
        return f"the mesh file {shape.geometry.path.name}"
    return "the mesh"


def _backend(case: Case) -> str:
    from contactfem.errors import SolverError
    from contactfem.linalg import resolve_backend

    try:
        return resolve_backend(case.solver.backend)
    except SolverError as error:
        raise CaseError(f"{case.source.name}: solver.backend = {case.solver.backend}: {error}") from None


def _refuse_oversized(case: Case, shape: MeshRequest, refine: int | None, limit: MemoryLimit,
                      base: int | None = None) -> None:
    """Refuse before meshing (``base`` None) or, for a mesh file of ``base`` triangles, before
    refining, a mesh whose solve the cost model (:mod:`contactfem.estimate`, the figures
    ``contactfem check`` prints) says the memory this process may use, ``limit``, cannot hold
    (:func:`~contactfem.estimate.memory_limit`: the machine's, a cgroup's, ``ulimit -v``)."""
    from contactfem.estimate import backend_refusal, estimate_cost, unknowns_of_triangles

    if base is None:
        triangles = estimate_triangles(shape, refine)
    else:
        triangles = base * 4 ** (shape.mesh.refine if refine is None else refine)
    backend = _backend(case)
    unknowns = unknowns_of_triangles(triangles)
    needed = estimate_cost(unknowns, backend)["bytes"]
    if needed > limit.bytes:
        raise CaseError(
            f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the refinements), "
            f"{unknowns:.3g} unknowns, whose solve needs about {needed / 2**30:.3g} GiB with {backend}, more than "
            f"{limit.source}; use fewer divisions, a larger mesh.size or fewer refinements"
        )
    refusal = backend_refusal(unknowns, backend)
    if refusal is not None:
        raise CaseError(f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the "
                        f"refinements): {refusal}")


def _mesh_geometry(case: Case, shape: MeshRequest, limit: MemoryLimit) -> Mesh:
    geometry = shape.geometry
    settings = shape.mesh
    if isinstance(geometry, RectangleGeometry):
        mesh = structured_rectangle(
            geometry.lower, geometry.upper, *settings.divisions,
            diagonal=settings.diagonal, side_names=geometry.side_names,
        )
    elif isinstance(geometry, PolygonGeometry):
        mesh = triangulate_domain(
            geometry.outer, list(geometry.holes), max_edge=settings.size, min_angle=settings.min_angle,
            size=_contact_grading(shape) if settings.contact_size is not None else None,
            max_points=largest_mesh_points(_backend(case), limit.bytes),
        )
    else:
        assert isinstance(geometry, MeshFileGeometry)
        mesh = read_gmsh(geometry.path)
    return mesh
