"""From a validated case to a mesh and to the algebraic contact problem of each method.

Refusals of ill-posed cases that need the mesh to be seen (a contact part facing away
from the obstacle, supports that leave a rigid motion free, a boundary name a mesh file
lacks, loads that are not finite) are raised here as :class:`CaseError` naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from contactfem.assembly import (
    Elasticity,
    body_force_vector,
    boundary_mass,
    edge_geometry,
    stiffness_matrix,
    traction_vector,
)
from contactfem.case import Case, MeshFileGeometry, PolygonGeometry, RectangleGeometry
from contactfem.errors import CaseError, MeshError
from contactfem.expressions import Expression
from contactfem.kernel import ContactSystem
from contactfem.mesh import Mesh, check_mesh, read_gmsh, refine_uniform, structured_rectangle, triangulate_domain
from contactfem.methods import ContactBoundaryMasses, ContactMethod


def build_mesh(case: Case, refine: int | None = None) -> Mesh:
    """Mesh the case's geometry, refine it ``refine`` times (default: the case's), and check it."""
    _refuse_oversized(case, refine)
    try:
        mesh = _mesh_geometry(case)
    except MeshError as error:
        key = {RectangleGeometry: "rectangle", PolygonGeometry: "polygon", MeshFileGeometry: "mesh_file"}
        raise MeshError(f"{case.source.name}: geometry.{key[type(case.geometry)]}: {error}") from None
    missing = [p.name for p in case.parts if p.name not in mesh.part_names]
    if missing:
        raise CaseError(
            f"{case.source.name}: boundary.{missing[0]}: {_mesh_origin(case)} has no boundary part "
            f"named {missing[0]!r}; it has {', '.join(mesh.part_names)}"
        )
    times = case.mesh.refine if refine is None else refine
    if isinstance(case.geometry, MeshFileGeometry):
        # Only now is the mesh file's size known: refuse its refinements before they allocate.
        _refuse_oversized(case, refine, base=mesh.n_triangles)
    if times:
        mesh = refine_uniform(mesh, times)
    try:
        check_mesh(mesh)
    except MeshError as error:  # e.g. slivers of a rectangle of aspect 1e9: name the key
        kind = {RectangleGeometry: "rectangle", PolygonGeometry: "polygon", MeshFileGeometry: "mesh_file"}
        raise MeshError(f"{case.source.name}: geometry.{kind[type(case.geometry)]}: {error}") from None
    return mesh


# Peak memory of a solve per triangle, measured on the square case at 2.1M triangles
# (assembly, CHOLMOD factor, outputs), about 2 kB, with a margin.
BYTES_PER_TRIANGLE = 2500


def estimate_triangles(case: Case, refine: int | None = None) -> int:
    """Triangles the case will be meshed into, estimated before meshing (0 for mesh files)."""
    geometry, settings = case.geometry, case.mesh
    times = settings.refine if refine is None else refine
    if isinstance(geometry, RectangleGeometry):
        nx, ny = settings.divisions
        base = (4 if settings.diagonal == "crossed" else 2) * nx * ny
    elif isinstance(geometry, PolygonGeometry):
        v = geometry.outer.vertices
        span = np.ptp(v, axis=0)
        # Bounding box over the area of an equilateral triangle of side h, a safe upper bound.
        extent = max(span.max(), 1e-300)
        base = int(1.2 * extent * extent / (np.sqrt(3) / 4 * settings.size**2)) + 1
        if settings.contact_size is not None:
            # The graded band: ∫ L dd / area(h(d)) with h = hc + g d is L / (√3/4 · g · hc),
            # with L bounded by π times the extent.
            band = np.pi * extent / (np.sqrt(3) / 4 * settings.grading * settings.contact_size)
            base += int(band)
    else:
        return 0
    return int(base * 4**times)


def _contact_grading(case: Case):
    """The size field h(x) = min(size, contact_size + grading · distance(x, ΓC)).

    The distance is to points sampled on the contact edges of the geometry at a quarter
    of contact_size, so it is exact to that spacing.
    """
    from scipy.spatial import cKDTree

    settings = case.mesh
    samples = []
    for loop in (case.geometry.outer, *case.geometry.holes):
        k = len(loop.vertices)
        for i, (name, arc) in enumerate(zip(loop.edge_names, loop.edge_arcs)):
            if name not in case.contact_parts:
                continue
            start, end = loop.vertices[i], loop.vertices[(i + 1) % k]
            if arc is None:
                length = np.linalg.norm(end - start)
                t = np.linspace(0.0, 1.0, max(2, int(4 * length / settings.contact_size) + 2))
                samples.append(start + t[:, None] * (end - start))
            else:
                center = np.asarray(arc.center)
                radius = np.linalg.norm(start - center)
                a0 = np.arctan2(*(start - center)[::-1])
                a1 = np.arctan2(*(end - center)[::-1])
                sweep = (a1 - a0) % (2 * np.pi) if arc.ccw else -((a0 - a1) % (2 * np.pi))
                n = max(2, int(4 * radius * abs(sweep) / settings.contact_size) + 2)
                angle = a0 + sweep * np.linspace(0.0, 1.0, n)
                samples.append(center + radius * np.stack([np.cos(angle), np.sin(angle)], axis=1))
    tree = cKDTree(np.concatenate(samples))

    def size(points: np.ndarray) -> np.ndarray:
        distance, _ = tree.query(points)
        return np.minimum(settings.size, settings.contact_size + settings.grading * distance)

    return size


def _mesh_origin(case: Case) -> str:
    if isinstance(case.geometry, MeshFileGeometry):
        return f"the mesh file {case.geometry.path.name}"
    return "the mesh"


def _refuse_oversized(case: Case, refine: int | None, base: int | None = None) -> None:
    """Refuse before meshing (``base`` None) or, for a mesh file of ``base`` triangles, before refining."""
    import os

    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        memory = 16 * 2**30
    if base is None:
        triangles = estimate_triangles(case, refine)
    else:
        triangles = base * 4 ** (case.mesh.refine if refine is None else refine)
    limit = memory // BYTES_PER_TRIANGLE
    if triangles > limit:
        raise CaseError(
            f"{case.source.name}: mesh: about {triangles:.3g} triangles requested (with the refinements), "
            f"more than the {limit:.3g} this machine's {memory / 2**30:.0f} GiB can solve; "
            "use fewer divisions, a larger mesh.size or fewer refinements"
        )


def _mesh_geometry(case: Case) -> Mesh:
    geometry = case.geometry
    settings = case.mesh
    if isinstance(geometry, RectangleGeometry):
        mesh = structured_rectangle(
            geometry.lower, geometry.upper, *settings.divisions,
            diagonal=settings.diagonal, side_names=geometry.side_names,
        )
    elif isinstance(geometry, PolygonGeometry):
        mesh = triangulate_domain(
            geometry.outer, list(geometry.holes), max_edge=settings.size, min_angle=settings.min_angle,
            size=_contact_grading(case) if settings.contact_size is not None else None,
        )
    else:
        assert isinstance(geometry, MeshFileGeometry)
        mesh = read_gmsh(geometry.path)
    return mesh


@dataclass(frozen=True, eq=False)
class ContactBoundary:
    """The contact nodes and what the methods need of them.

    ``nodes`` (m,) sorted by ``abscissa`` (coordinate along the obstacle's tangent),
    ``edges`` (k, 2) the ΓC edges, ``gap`` (m,), ``masses`` the two boundary masses.
    """

    nodes: np.ndarray
    edges: np.ndarray
    gap: np.ndarray
    abscissa: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    masses: ContactBoundaryMasses


@dataclass(frozen=True, eq=False)
class DiscreteProblem:
    """The assembled linear elastic system with its supports and contact boundary.

    ``stiffness`` (2n, 2n) and ``load`` (2n,) carry no boundary condition;
    ``dirichlet_dofs`` (k,) sorted, with ``dirichlet_values`` (k,).
    """

    mesh: Mesh
    law: Elasticity
    stiffness: sp.csr_matrix
    load: np.ndarray
    dirichlet_dofs: np.ndarray
    dirichlet_values: np.ndarray
    contact: ContactBoundary
    refinements: int = 0  # uniform refinements of the case's own mesh (for mesh sequencing)
    # Nodes held on a symmetry line (u · n_s = 0) and the line's unit normal at each.
    symmetry_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    symmetry_normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def n_unknowns(self) -> int:
        """Displacement unknowns once the supports are eliminated."""
        return 2 * self.mesh.n_points - len(self.dirichlet_dofs)

    def contact_system(self, method: ContactMethod) -> "ReducedSystem":
        """The kernel's view: supports eliminated, contact nodes in (normal, tangent) unknowns."""
        return ReducedSystem.build(self, method)


@dataclass(frozen=True, eq=False)
class ReducedSystem:
    """A :class:`ContactSystem` in rotated unknowns and the map back to mesh displacements.

    The system keeps every unknown (supports are fixed unknowns of the kernel, not sliced
    out). At a contact node with both components free, (u_x, u_y) = u_n n + u_t t: its x
    slot holds u_n and its y slot u_t. A contact node on a roller (one component
    prescribed) keeps its prescribed slot, and its free slot c, along which the normal
    lies, holds u_n (u_c = n_c u_n with n_c = ±1).
    """

    system: ContactSystem
    rotation: sp.csr_matrix
    problem: DiscreteProblem

    @classmethod
    def build(cls, problem: DiscreteProblem, method: ContactMethod) -> "ReducedSystem":
        n_dof = 2 * problem.mesh.n_points
        contact = problem.contact
        supported = np.zeros(n_dof, dtype=bool)
        supported[problem.dirichlet_dofs] = True
        nodes, normal_slot, a, b = _frames(problem, supported)
        # Each framed node's slots hold u · a (x slot) and u · b (y slot): Q's 2x2 block is
        # [a b]. E = Q − I lives on those nodes only, so QᵀKQ = K + EᵀK + KE + EᵀKE costs a
        # few products with thin matrices instead of two full ones.
        x, y = 2 * nodes, 2 * nodes + 1
        rows = np.concatenate([x, x, y, y])
        cols = np.concatenate([x, y, x, y])
        vals = np.concatenate([a[:, 0] - 1.0, b[:, 0], a[:, 1], b[:, 1] - 1.0])
        shift = sp.csr_matrix((vals, (rows, cols)), shape=(n_dof, n_dof))
        shift.eliminate_zeros()
        stiffness = problem.stiffness
        k_shift = (stiffness @ shift).tocsr()
        # The three corrections live on the framed rows and columns: sum them first, then
        # add to K once (each full-size sparse addition costs as much as the others together).
        rotated = sp.csr_matrix(stiffness + (k_shift + k_shift.T + shift.T @ k_shift))
        rotated.sum_duplicates()
        rotation = (sp.identity(n_dof, format="csr") + shift).tocsr()
        fixed_dofs = np.concatenate([problem.dirichlet_dofs, 2 * problem.symmetry_nodes])
        fixed_values = np.concatenate([problem.dirichlet_values, np.zeros(len(problem.symmetry_nodes))])
        order = np.argsort(fixed_dofs)
        system = ContactSystem(
            stiffness=rotated,
            load=rotation.T @ problem.load,
            normal_dofs=normal_slot,
            gap=contact.gap,
            multiplier_mass=method.multiplier_mass(contact.masses),
            fixed_dofs=fixed_dofs[order],
            fixed_values=fixed_values[order],
        )
        return cls(system=system, rotation=rotation, problem=problem)

    def displacement(self, reduced: np.ndarray) -> np.ndarray:
        """Mesh displacement (n_points, 2) from the kernel's unknowns (in rotated coordinates)."""
        return (self.rotation @ reduced).reshape(-1, 2)


def _frames(problem: DiscreteProblem, supported: np.ndarray):
    """Local frames (a, b) of the nodes whose unknowns are rotated, and the contact normal slots.

    - contact node with both components free: a = n, b = t (u_n in the x slot);
    - contact node with one component prescribed (a roller, n along the free axis): the
      prescribed axis stays, the free slot holds u_n;
    - symmetry node: a = n_s (its x slot is fixed to 0), b = t_s, or b = n when it is also a
      contact node (n along the symmetry line), its y slot then holding u_n.
    Returns nodes (k,), normal_slot (m,) aligned with the contact nodes, a (k, 2), b (k, 2).
    """
    contact = problem.contact
    n_o, t_o = contact.normal, contact.tangent
    c = contact.nodes
    sx, sy = supported[2 * c], supported[2 * c + 1]
    sym_index = np.full(problem.mesh.n_points, -1)
    sym_index[problem.symmetry_nodes] = np.arange(len(problem.symmetry_nodes))
    on_symmetry = sym_index[c] >= 0
    m = len(c)
    a = np.tile(n_o, (m, 1))
    b = np.tile(t_o, (m, 1))
    slot = 2 * c
    roller_x = sx & ~sy  # u_x prescribed, normal along y
    a[roller_x] = (1.0, 0.0)
    b[roller_x] = (0.0, n_o[1])
    slot = np.where(roller_x, 2 * c + 1, slot)
    roller_y = sy & ~sx  # u_y prescribed, normal along x
    a[roller_y] = (n_o[0], 0.0)
    b[roller_y] = (0.0, 1.0)
    a[on_symmetry] = problem.symmetry_normals[sym_index[c[on_symmetry]]]
    b[on_symmetry] = n_o
    slot = np.where(on_symmetry, 2 * c + 1, slot)
    # Symmetry nodes that are not contact nodes: a = n_s, b = t_s.
    others = np.setdiff1d(problem.symmetry_nodes, c)
    normals = problem.symmetry_normals[sym_index[others]]
    tangents = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
    nodes = np.concatenate([c, others])
    return nodes, slot, np.concatenate([a, normals]), np.concatenate([b, tangents])


def build_problem(case: Case, mesh: Mesh) -> DiscreteProblem:
    """Assemble stiffness and loads, impose the supports and find the contact nodes."""
    material = case.material
    law = Elasticity.from_lame(material.lame_lambda, material.lame_mu, material.plane)
    points = mesh.points
    stiffness = stiffness_matrix(points, mesh.triangles, law)

    load = np.zeros(2 * mesh.n_points)
    exact = case.exact.solution if case.exact is not None else None
    if case.body_force is not None:
        _check_finite(case, "body_force", case.body_force, _centroids(mesh))
        load += body_force_vector(points, mesh.triangles, case.body_force)
    if exact is not None:
        # f = −div σ(u_exact), at the edge midpoints the load's quadrature uses.
        midpoints = 0.5 * (points[mesh.triangles] + np.roll(points[mesh.triangles], -1, axis=1)).reshape(-1, 2)
        _refuse_non_finite_exact(case, "body_force = 'exact' (-div sigma)", exact.body_force(*midpoints.T), midpoints)
        force = (lambda x, y: exact.body_force(x, y)[..., 0], lambda x, y: exact.body_force(x, y)[..., 1])
        load += body_force_vector(points, mesh.triangles, force)
    for part in case.parts:
        edges = mesh.edges_of(part.name)
        if part.exact and part.kind == "traction" and len(edges):
            _, outward = edge_geometry(points, edges)
            where = _edge_samples(points, edges)
            values = exact.traction(*where.T, np.concatenate([outward] * 3))
            _refuse_non_finite_exact(case, f"boundary.{part.name}.traction = 'exact' (sigma n)", values, where)
            load += traction_vector(points, edges, edge_traction=exact.traction)
        elif part.kind in ("traction", "pressure") and len(edges):
            key = f"boundary.{part.name}.{part.kind}"
            _check_finite(case, key, part.values, _edge_samples(points, edges))
            if part.kind == "traction":
                load += traction_vector(points, edges, traction=part.values)
            else:
                load += traction_vector(points, edges, pressure=part.values[0])

    dirichlet_dofs, dirichlet_values, symmetry_nodes, symmetry_normals = _supports(case, mesh)
    contact = _contact_boundary(case, mesh, dirichlet_dofs, symmetry_nodes, symmetry_normals)
    if exact is not None:
        check_exact_contact(case, mesh, contact.edges)
    return DiscreteProblem(
        mesh=mesh, law=law, stiffness=stiffness, load=load,
        dirichlet_dofs=dirichlet_dofs, dirichlet_values=dirichlet_values, contact=contact,
        symmetry_nodes=symmetry_nodes, symmetry_normals=symmetry_normals,
    )


def _supports(case: Case, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Prescribed unknowns and their values; refuses conflicts and supports that allow rigid motion."""
    values = np.full(2 * mesh.n_points, np.nan)
    owner = np.full(2 * mesh.n_points, -1)
    for index, part in enumerate(case.parts):
        if not part.is_dirichlet:
            continue
        nodes = mesh.nodes_of(part.name)
        components = part.values if part.kind == "displacement" else (None, None)
        for component in range(2):
            if part.kind == "displacement" and components[component] is None:
                continue
            if part.kind == "clamped":
                prescribed = np.zeros(len(nodes))
            else:
                key = f"boundary.{part.name}.displacement[{component}]"
                x, y = mesh.points[nodes].T
                prescribed = np.broadcast_to(components[component](x, y), x.shape)
                _refuse_non_finite(case, key, components[component], prescribed, mesh.points[nodes])
            dofs = 2 * nodes + component
            clash = (owner[dofs] >= 0) & ~np.isclose(values[dofs], prescribed, rtol=1e-9, atol=0)
            if clash.any():
                other = case.parts[owner[dofs][clash][0]].name
                where = mesh.points[nodes[clash][0]]
                raise CaseError(
                    f"{case.source.name}: boundary.{part.name}: prescribes a displacement that "
                    f"conflicts with boundary.{other} at the shared node ({where[0]:g}, {where[1]:g})"
                )
            values[dofs] = prescribed
            owner[dofs] = index
    prescribed = owner.reshape(-1, 2) >= 0
    symmetry_nodes, symmetry_normals = _symmetry_lines(case, mesh, prescribed)
    # A node on two symmetry lines that are not parallel cannot move at all.
    unique, first, counts = np.unique(symmetry_nodes, return_index=True, return_counts=True)
    pinned = unique[counts > 1]
    if len(pinned):
        values[np.concatenate([2 * pinned, 2 * pinned + 1])] = 0.0
        owner[np.concatenate([2 * pinned, 2 * pinned + 1])] = len(case.parts)
    keep = np.isin(unique, pinned, invert=True)
    symmetry_nodes, symmetry_normals = unique[keep], symmetry_normals[first[keep]]
    dofs = np.flatnonzero(owner >= 0)
    _refuse_rigid_motion(case, mesh, dofs, symmetry_nodes, symmetry_normals)
    return dofs, values[dofs], symmetry_nodes, symmetry_normals


def _symmetry_lines(case: Case, mesh: Mesh, prescribed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes of the symmetry parts (without prescribed components) and their line's normal.

    A symmetry part must be straight: all its edges on one line, whose outward unit normal
    n_s is the direction held (u · n_s = 0).
    """
    nodes, normals = [], []
    for part in case.parts:
        if part.kind != "symmetry":
            continue
        edges = mesh.edges_of(part.name)
        if len(edges) == 0:
            raise CaseError(f"{case.source.name}: boundary.{part.name}: the mesh has no edge on this part")
        _, outward = edge_geometry(mesh.points, edges)
        normal = outward.mean(axis=0)
        normal /= np.linalg.norm(normal)
        points = mesh.points[np.unique(edges)]
        offset = (points - points[0]) @ normal
        extent = np.ptp(mesh.points, axis=0).max()
        if np.abs(outward @ normal - 1.0).max() > 1e-9 or np.abs(offset).max() > 1e-9 * extent:
            raise CaseError(
                f"{case.source.name}: boundary.{part.name} = symmetry: the part is not straight; "
                "a symmetry support needs all its edges on one line"
            )
        part_nodes = np.unique(edges)
        part_nodes = part_nodes[~prescribed[part_nodes].any(axis=1)]
        nodes.append(part_nodes)
        normals.append(np.tile(normal, (len(part_nodes), 1)))
    if not nodes:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    return np.concatenate(nodes), np.concatenate(normals)


def _refuse_rigid_motion(case: Case, mesh: Mesh, dofs: np.ndarray, symmetry_nodes: np.ndarray,
                         symmetry_normals: np.ndarray) -> None:
    """The supports must pin the three rigid motions: translations along x and y, rotation."""
    # Each constraint holds u(p) · d = 0 for a point p and direction d: a prescribed
    # component (d = e_x or e_y) or a symmetry line (d = n_s).
    directions = np.concatenate([np.eye(2)[dofs % 2], symmetry_normals])
    p = mesh.points[np.concatenate([dofs // 2, symmetry_nodes])]
    centre = p.mean(axis=0) if len(p) else np.zeros(2)
    # Rigid displacement r = a e_x + b e_y + c (−(y−yc), x−xc), seen through each constraint.
    modes = np.zeros((len(p), 3))
    modes[:, 0] = directions[:, 0]
    modes[:, 1] = directions[:, 1]
    modes[:, 2] = -(p[:, 1] - centre[1]) * directions[:, 0] + (p[:, 0] - centre[0]) * directions[:, 1]
    scale = np.ptp(mesh.points, axis=0).max()
    modes[:, 2] /= scale
    singular = np.linalg.svd(modes, compute_uv=False) if len(modes) else np.zeros(0)
    rank = int((singular > 1e-8 * max(singular.max(initial=0.0), 1.0)).sum())
    if rank < 3:
        names = ", ".join(case.dirichlet_parts)
        raise CaseError(
            f"{case.source.name}: boundary: the supports ({names}) leave a rigid motion of the body "
            "free, so the problem is ill-posed; prescribe both components on a part of positive length"
        )


def _contact_boundary(case: Case, mesh: Mesh, dirichlet_dofs: np.ndarray, symmetry_nodes: np.ndarray,
                      symmetry_normals: np.ndarray) -> ContactBoundary:
    normal = np.asarray(case.obstacle.normal, dtype=float)
    tangent = np.array([-normal[1], normal[0]])
    edges = mesh.edges_of(list(case.contact_parts))
    for name in case.contact_parts:
        part_edges = mesh.edges_of(name)
        if len(part_edges) == 0:
            raise CaseError(f"{case.source.name}: boundary.{name}: the mesh has no edge on this part")
        _, outward = edge_geometry(mesh.points, part_edges)
        facing = outward @ normal
        if (facing <= 1e-9).any():
            bad = part_edges[np.argmin(facing)]
            a, b = mesh.points[bad[0]], mesh.points[bad[1]]
            raise CaseError(
                f"{case.source.name}: boundary.{name} = contact: the edge from ({a[0]:g}, {a[1]:g}) to "
                f"({b[0]:g}, {b[1]:g}) faces away from the obstacle (outward normal · obstacle normal = "
                f"{facing.min():.3g}); a contact part must face the obstacle"
            )
    # A node whose normal motion a support fixes carries no multiplier: both components
    # prescribed, or one prescribed while the obstacle's normal is not along the other.
    prescribed = np.zeros((mesh.n_points, 2), dtype=bool)
    prescribed[dirichlet_dofs // 2, dirichlet_dofs % 2] = True
    roller_keeps_normal = np.where(prescribed[:, 0], abs(normal[1]), abs(normal[0])) > 1 - 1e-12
    supported = prescribed.all(axis=1) | (prescribed.any(axis=1) & ~roller_keeps_normal)
    # On a symmetry line the node keeps contact only if the obstacle's normal runs along the line.
    along_line = np.abs(symmetry_normals @ np.array([-normal[1], normal[0]])) > 1 - 1e-12
    supported[symmetry_nodes[~along_line]] = True
    gamma_nodes = np.unique(edges)
    nodes = gamma_nodes[~supported[gamma_nodes]]
    abscissa = mesh.points[nodes] @ tangent
    order = np.argsort(abscissa, kind="stable")
    nodes, abscissa = nodes[order], abscissa[order]

    full_mass = boundary_mass(mesh.points, edges, mesh.n_points)
    lumped = np.asarray(full_mass.sum(axis=1)).ravel()[nodes]
    consistent = full_mass[nodes][:, nodes].tocsr()
    gap = (np.asarray(case.obstacle.point) - mesh.points[nodes]) @ normal
    return ContactBoundary(
        nodes=nodes, edges=edges, gap=gap, abscissa=abscissa, normal=normal, tangent=tangent,
        masses=ContactBoundaryMasses(lumped=lumped, consistent=consistent),
    )


#: Where on each ΓC edge the exact solution's contact conditions are checked (0 and 1: its ends).
EXACT_CHECK_POINTS = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
#: Relative tolerance of those checks, against the scales of the exact displacement and stress.
EXACT_CHECK_TOLERANCE = 1e-9


def check_exact_contact(case: Case, mesh: Mesh, edges: np.ndarray) -> None:
    """Refuse an exact solution that violates a frictionless contact condition on ΓC.

    At the ends and 4 interior points of every contact edge, with g the initial gap of
    the point, u_n = u·n, p = −n·σ n and σ_t = t·σ n: u_n − g ≤ τ_u, p ≥ −τ_σ,
    |p (u_n − g)| ≤ τ_σ τ_u / 1e-9 and |σ_t| ≤ τ_σ, where τ_u = 1e-9 × the largest |u| (at
    the mesh nodes and the check points) or |g|, and τ_σ = 1e-9 × the largest |σ| (at the
    check points and the triangle centroids). Points where the exact stress is not
    finite (the 0/0 of a derivative formula at a singular point such as the tip of
    r^{3/2}) are left out of the stress conditions; the displacement must be finite.

    Raises
    ------
    CaseError
        ``file: exact.displacement: <condition> fails at (x, y) (value ..., tolerance ...)``.
    """
    exact = case.exact.solution
    normal = np.asarray(case.obstacle.normal, dtype=float)
    a, b = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    where = np.concatenate([(1 - s) * a + s * b for s in EXACT_CHECK_POINTS])
    x, y = where.T
    u = exact.displacement(x, y)
    _refuse_non_finite_exact(case, "exact.displacement", u, where, "on the contact boundary")
    gap = (np.asarray(case.obstacle.point) - where) @ normal
    slack = exact.normal_displacement(x, y) - gap
    pressure = exact.pressure(x, y)
    tangential = exact.tangential_traction(x, y)
    stress_finite = np.isfinite(pressure) & np.isfinite(tangential)

    def largest(values: np.ndarray) -> float:
        values = np.abs(values[np.isfinite(values)])
        return float(values.max(initial=0.0))

    u_scale = max(largest(exact.displacement(*mesh.points.T)), largest(u), largest(gap))
    centroids = _centroids(mesh)
    s_scale = max(largest(exact.stress(x, y)), largest(exact.stress(*centroids.T)))
    tol_u = EXACT_CHECK_TOLERANCE * u_scale
    tol_s = EXACT_CHECK_TOLERANCE * s_scale
    complementarity = np.where(stress_finite, np.abs(pressure * slack), 0.0)
    conditions = (
        ("non-penetration u_n <= g", slack, slack > tol_u, tol_u),
        ("pressure -sigma_nn >= 0", pressure, stress_finite & (pressure < -tol_s), tol_s),
        ("complementarity pressure * (u_n - g) = 0", complementarity,
         complementarity > EXACT_CHECK_TOLERANCE * s_scale * u_scale, EXACT_CHECK_TOLERANCE * s_scale * u_scale),
        ("zero tangential traction sigma_t = 0 (frictionless)", tangential,
         stress_finite & (np.abs(tangential) > tol_s), tol_s),
    )
    for name, values, fails, tolerance in conditions:
        if fails.any():
            worst = np.flatnonzero(fails)[np.argmax(np.abs(values[fails]))]
            px, py = where[worst]
            raise CaseError(
                f"{case.source.name}: exact.displacement: {name} fails at ({px:g}, {py:g}) "
                f"(value {values[worst]:.3g}, tolerance {tolerance:.3g}); the exact solution must satisfy "
                f"the frictionless contact conditions on {', '.join(f'boundary.{n}' for n in case.contact_parts)}"
            )


def _refuse_non_finite_exact(case: Case, key: str, values: np.ndarray, where: np.ndarray,
                             reason: str = "where the load is integrated") -> None:
    """Refuse non-finite values (len(where), ...) of a field derived from exact.displacement."""
    bad = ~np.isfinite(values.reshape(len(where), -1)).all(axis=1)
    if bad.any():
        x, y = where[np.argmax(bad)]
        raise CaseError(
            f"{case.source.name}: {key}: not finite at ({x:g}, {y:g}) (derived from exact.displacement); "
            f"expected finite values {reason} (keep singular points off the mesh's quadrature points)"
        )


def _centroids(mesh: Mesh) -> np.ndarray:
    return mesh.points[mesh.triangles].mean(axis=1)


def _edge_samples(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    return np.concatenate([a, 0.5 * (a + b), b])


def _check_finite(case: Case, key: str, fields: tuple[Expression | None, ...], where: np.ndarray) -> None:
    for i, expression in enumerate(fields):
        if expression is None:
            continue
        values = np.broadcast_to(expression(where[:, 0], where[:, 1]), len(where))
        _refuse_non_finite(case, f"{key}[{i}]" if len(fields) > 1 else key, expression, values, where)


def _refuse_non_finite(case: Case, key: str, field: Expression, values: np.ndarray, where: np.ndarray) -> None:
    from contactfem.case import SCALE_LIMIT

    # Values beyond SCALE_LIMIT would overflow once integrated and solved (NaN residuals).
    bad = ~(np.abs(values) <= SCALE_LIMIT)
    if bad.any():
        x, y = where[np.argmax(bad)]
        value = values.flat[np.argmax(bad)]
        what = "not finite" if not np.isfinite(value) else f"{value:.3g} exceeds {SCALE_LIMIT:g} in magnitude"
        raise CaseError(
            f"{case.source.name}: {key} = {field.text!r}: {what} at ({x:g}, {y:g}); "
            "expected finite values on the whole part"
        )
