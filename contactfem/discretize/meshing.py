"""From the case's geometry to a checked mesh, with the size guard that runs before meshing."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactfem.case import Case, MeshFileGeometry, MeshSettings, Obstacle, PolygonGeometry, RectangleGeometry
from contactfem.errors import CaseError, MeshCapError, MeshError
from contactfem.estimate import MemoryLimit, guarded_bytes, largest_mesh_points, memory_limit
from contactfem.mesh import (
    Mesh,
    check_mesh,
    read_gmsh,
    refine_uniform,
    structured_rectangle,
    triangulate_domain,
)
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
    limit = memory_limit()  # read once: it reads cgroup files and rlimits
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


#: Triangles Triangle makes per area of an equilateral triangle of side h under its size
#: bound h, uniform and graded bodies alike (Triangle accepts triangles up to 1.5 times the
#: target area); a little above the observed counts so that the estimate errs high
#: (tests/test_sizes.py and benchmarks/mesh_knob.py).
TRIANGLES_PER_AREA = 1.7
#: Triangles Triangle adds around an input vertex whose shorter edge is much shorter than
#: the size there: it keeps every input edge and grades from its length to the size, about
#: the same count whatever the ratio of size to edge (rounded up from rough profiles').
TRIANGLES_PER_SHORT_EDGE = 6.0
#: Most cells of the background quadtree on which :func:`estimate_triangles` integrates a
#: graded size field; past it (a band of more than some 10^8 triangles, which no machine
#: here solves) the band is counted as the contact length over grading · contact_size.
_ESTIMATE_CELLS = 2_000_000


def estimate_triangles(shape: Case | MeshRequest, refine: int | None = None) -> int:
    """Triangles a case (or a :class:`MeshRequest`) will be meshed into, estimated before
    meshing (0 for mesh files); each refinement multiplies them by four.

    A polygon's count is the integral over the body of the density of its size field,
    TRIANGLES_PER_AREA / (√3/4 · h(x)²), h the field the mesh is made with
    (:func:`_contact_grading`: graded towards ΓC and finer still at a punch's ends), plus
    the triangles Triangle adds around input vertices closer together than h (a rough
    profile's). The uniform part is the body's exact area over that of size; the graded
    band's excess is integrated on a quadtree of cells, split until h varies by at most a
    fifth across each (vectorised: a few thousand cells on the shipped cases)."""
    geometry, settings = shape.geometry, shape.mesh
    times = settings.refine if refine is None else refine
    if isinstance(geometry, RectangleGeometry):
        nx, ny = settings.divisions
        base = (4 if settings.diagonal == "crossed" else 2) * nx * ny
        return int(base * 4**times)
    if not isinstance(geometry, PolygonGeometry):
        return 0
    loops = (geometry.outer, *geometry.holes)
    area = abs(loop_signed_area(geometry.outer)) - sum(abs(loop_signed_area(hole)) for hole in geometry.holes)
    unit = np.sqrt(3) / 4
    count = TRIANGLES_PER_AREA * area / (unit * settings.size**2)
    field = None
    if settings.contact_size is not None and settings.contact_size < settings.size:
        band, field = _graded_band(shape)
        count += TRIANGLES_PER_AREA * band
    # Input vertices with an edge shorter than h: Triangle keeps them, and grades away from
    # them. The shorter edge counts: a tooth narrower than h is meshed at its width (on a
    # tread's coarse level the mean edge underestimates the count, the shorter one errs high).
    for loop in loops:
        v = loop.vertices
        edge = np.hypot(*(np.roll(v, -1, axis=0) - v).T)
        length = np.minimum(edge, np.roll(edge, 1))
        h = np.full(len(v), settings.size) if field is None else field(v)
        count += TRIANGLES_PER_SHORT_EDGE * float(np.clip(1.0 - length / h, 0.0, None).sum())
    return int(count * 4**times) + 1


def _graded_band(shape: MeshRequest) -> tuple[float, object]:
    """∫ (1/h(x)² − 1/size²) dx / (√3/4) over the body: the graded band's triangles beyond the
    uniform count, per TRIANGLES_PER_AREA; and the size field it integrated.

    The distance to ΓC is taken to samples spaced finer than the cells near ΓC (not the
    mesh's quarter of contact_size: a request whose band no machine could mesh is counted
    without sampling ΓC that finely)."""
    from contactfem.case.geometry import _points_inside
    from contactfem.case.loops import loop_outline

    settings = shape.mesh
    hc, size, g = settings.contact_size, settings.size, settings.grading
    unit = np.sqrt(3) / 4
    outlines = [loop_outline(loop) for loop in (shape.geometry.outer, *shape.geometry.holes)]
    # The contact length facing the obstacle, from samples 4 · contact_size apart (at most
    # two too many per edge: a little long on a profile of thousands of edges).
    step = 4 * hc
    perimeter = sum(float(np.hypot(*(np.roll(o, -1, axis=0) - o).T).sum()) for o in outlines)
    if perimeter / step > 1e7:
        contact_length = perimeter
    else:
        contact_length = min(len(_contact_samples(shape, spacing=step)[0]) * step, perimeter)
    # One-sided band of a straight ΓC: ∫ dd / (hc + g d)² from 0 to where h reaches size.
    analytic = contact_length * (1 / hc - 1 / size) / g / unit
    if analytic > 50 * _ESTIMATE_CELLS:
        return analytic, None
    field = _contact_grading(shape, spacing=hc)
    everything = np.concatenate(outlines)
    low, high = everything.min(axis=0), everything.max(axis=0)
    cell = max(float((high - low).max()) / 16, 1e-300)
    nx, ny = (np.ceil((high - low) / cell).astype(int) + 1).tolist()
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    centers = low + (np.stack([ix.ravel(), iy.ravel()], axis=1) + 0.5) * cell
    total = 0.0
    while len(centers):
        if len(centers) > _ESTIMATE_CELLS:
            return analytic, field
        h = field(centers)
        # Keep the cells that reach into the band; of those, accept the ones across which h
        # varies by at most a fifth, and split the others into four.
        near = h < size + g * cell * 0.7072
        centers, h = centers[near], h[near]
        done = g * cell <= 0.2 * h
        accepted = centers[done]
        if len(accepted):
            inside = _points_inside(outlines[0], accepted)
            for hole in outlines[1:]:
                inside &= ~_points_inside(hole, accepted)
            excess = 1 / h[done][inside] ** 2 - 1 / size**2
            total += float(excess.sum()) * cell**2
        split = centers[~done]
        cell /= 2
        offsets = np.array([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]]) * cell
        centers = (split[:, None, :] + offsets[None, :, :]).reshape(-1, 2)
    return total / unit, field


def _contact_grading(shape: MeshRequest, spacing: float | None = None):
    """The size field h(x) = min(size, contact_size + grading · distance(x, ΓC)).

    The distance is to points sampled on the contact edges of the geometry at a quarter
    of contact_size (:func:`_contact_samples`; ``spacing`` if given), so it is exact to
    that spacing. ``mesh.grading`` is the case's, or without one the rule of
    :func:`contactfem.case.model.grading_of`, which follows contact_size.
    """
    from scipy.spatial import cKDTree

    settings = shape.mesh
    samples, ends = _contact_samples(shape, spacing)
    # Sliding-midpoint splits: the samples lie along curves, and the queries, most of them
    # near ΓC on a graded mesh, descend a tree balanced for that faster than a median split.
    tree = cKDTree(samples, balanced_tree=False, compact_nodes=False)
    end_tree = cKDTree(ends) if len(ends) else None
    end_size = settings.contact_size / END_REFINEMENT

    def reach(nearest: float) -> float:
        """The distance beyond which h is ``size`` whatever the distance: the nearest-point
        search stops there. Far from ΓC the nearest sample is otherwise sought among many
        almost as near (the centre of a disk is as far from every point of its rim), which
        made those queries most of the cost of meshing a disk. ``mesh.grading`` is at least
        0.01 (:mod:`contactfem.case`)."""
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


def _contact_samples(shape: MeshRequest, spacing: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Points on ΓC's edges, a quarter of ``mesh.contact_size`` apart (only those in front
    of a finite obstacle, which alone can touch it), and the points of ΓC facing the ends
    of a finite obstacle (:func:`_segment_ends_on_body`)."""
    settings = shape.mesh
    step = settings.contact_size / 4 if spacing is None else spacing
    samples = []
    contact = set(shape.contact_parts)
    for loop in (shape.geometry.outer, *shape.geometry.holes):
        k = len(loop.vertices)
        on_contact = loop.on_parts(contact)
        straight = on_contact & loop.straight_edges
        # All straight contact edges at once: a rough profile has thousands.
        start, end = loop.vertices[straight], np.roll(loop.vertices, -1, axis=0)[straight]
        counts = np.maximum(2, (np.hypot(*(end - start).T) / step).astype(np.int64) + 2)
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
            n = max(2, int(radius * abs(sweep) / step) + 2)
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


def _backend(case: Case, unknowns: int | None = None, limit: MemoryLimit | None = None) -> str:
    """The backend whose memory a mesh is measured against: the one
    :func:`~contactfem.estimate.choose_backend` takes for ``unknowns`` within ``limit``, or
    without a count the one that fits the most (``amg`` where ``auto`` may choose it)."""
    from contactfem.errors import SolverError
    from contactfem.estimate import choose_backend
    from contactfem.linalg import iterative_available, resolve_backend

    iterative = case.load_path is None
    try:
        if unknowns is not None:
            return choose_backend(unknowns, case.solver.backend, limit or memory_limit(), iterative).name
        if case.solver.backend == "auto" and iterative and iterative_available():
            return "amg"
        return resolve_backend(case.solver.backend)
    except SolverError as error:
        raise CaseError(f"{case.source.name}: solver.backend = {case.solver.backend}: {error}") from None


def _refuse_oversized(case: Case, shape: MeshRequest, refine: int | None, limit: MemoryLimit,
                      base: int | None = None) -> None:
    """Refuse before meshing (``base`` None) or, for a mesh file of ``base`` triangles, before
    refining, a mesh whose solve the cost model (:mod:`contactfem.estimate`, the figures
    ``contactfem check`` prints) says the memory this process may use, ``limit``, cannot hold
    (:func:`~contactfem.estimate.memory_limit`: the machine's, a cgroup's, ``ulimit -v``)."""
    from contactfem.estimate import backend_refusal, estimate_cost, guard_text, unknowns_of_triangles

    if base is None:
        triangles = estimate_triangles(shape, refine)
    else:
        triangles = base * 4 ** (shape.mesh.refine if refine is None else refine)
    unknowns = unknowns_of_triangles(triangles)
    backend = _backend(case, unknowns, limit)
    needed = estimate_cost(unknowns, backend)["bytes"]
    if needed > guarded_bytes(limit):
        raise CaseError(
            f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the refinements), "
            f"{unknowns:.3g} unknowns, whose solve needs about {needed / 2**30:.3g} GiB with {backend}, more than "
            f"{guard_text(limit)}; {_knobs(shape, refine)}"
        )
    refusal = backend_refusal(unknowns, backend)
    if refusal is not None:
        raise CaseError(f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the "
                        f"refinements): {refusal}; {_knobs(shape, refine)}")


def _knobs(shape: MeshRequest, refine: int | None) -> str:
    """Which mesh settings make the request smaller, the one that weighs most first."""
    settings = shape.mesh
    times = settings.refine if refine is None else refine
    knobs = []
    if isinstance(shape.geometry, RectangleGeometry):
        knobs.append("fewer mesh.divisions (or a larger mesh.size)")
    elif isinstance(shape.geometry, PolygonGeometry):
        uniform = TRIANGLES_PER_AREA * abs(loop_signed_area(shape.geometry.outer)) / (np.sqrt(3) / 4 * settings.size**2)
        graded = settings.contact_size is not None and settings.contact_size < settings.size
        if graded and estimate_triangles(shape, 0) > 2 * uniform:
            knobs.append(f"a larger mesh.contact_size (now {settings.contact_size:g})")
            knobs.append(f"a larger mesh.grading (now {settings.grading:.3g})")
            knobs.append(f"a larger mesh.size (now {settings.size:g})")
        else:
            knobs.append(f"a larger mesh.size (now {settings.size:g})")
            if graded:
                knobs.append(f"a larger mesh.contact_size (now {settings.contact_size:g})")
    if times:
        knobs.append(f"fewer refinements (--refine or mesh.refine, now {times}; each multiplies the "
                     "triangles by four)")
    return "use " + ", ".join(knobs[:-1]) + (" or " if len(knobs) > 1 else "") + knobs[-1] if knobs else \
        "use a coarser mesh"


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
            max_points=largest_mesh_points(_backend(case), guarded_bytes(limit)),
        )
    else:
        assert isinstance(geometry, MeshFileGeometry)
        mesh = read_gmsh(geometry.path)
    return mesh
