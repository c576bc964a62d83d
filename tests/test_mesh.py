"""Tests of mesh construction: structured rectangles, Triangle meshes, Gmsh input, refinement, checks."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from contactfem.errors import MeshError
from contactfem.mesh import (
    Arc,
    Loop,
    Mesh,
    boundary_edges,
    check_mesh,
    circle_loop,
    polygon_problems,
    read_gmsh,
    refine_uniform,
    structured_rectangle,
    triangulate_domain,
)

DIAGONALS = ["right", "left", "alternate", "crossed"]


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def edge_lengths(mesh: Mesh, edges: np.ndarray) -> np.ndarray:
    """Lengths (k,) of edges (k, 2)."""
    return np.linalg.norm(mesh.points[edges[:, 1]] - mesh.points[edges[:, 0]], axis=1)


def part_length(mesh: Mesh, name: str) -> float:
    """Total length of the boundary part ``name``."""
    return float(edge_lengths(mesh, mesh.edges_of(name)).sum())


def min_angle_degrees(mesh: Mesh) -> float:
    """Smallest interior angle over all triangles."""
    p = mesh.points[mesh.triangles]
    angles = []
    for i in range(3):
        u = p[:, (i + 1) % 3] - p[:, i]
        v = p[:, (i + 2) % 3] - p[:, i]
        cos = np.einsum("ij,ij->i", u, v) / (np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return float(np.min(angles))


def shoelace_twice_area(mesh: Mesh) -> float:
    """Sum over boundary edges of the cross product of their end points: twice the area."""
    a = mesh.points[mesh.boundary_edges[:, 0]]
    b = mesh.points[mesh.boundary_edges[:, 1]]
    return float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))


def same_edge_set(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two (k, 2) arrays hold the same directed edges, ignoring row order."""
    return len(a) == len(b) and set(map(tuple, a.tolist())) == set(map(tuple, b.tolist()))


def l_shape() -> Loop:
    """The L-shaped polygon [0,2]x[0,1] + [0,1]x[1,2] with one name per edge."""
    vertices = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], dtype=float)
    return Loop(vertices, ("bottom", "right", "step_top", "step_side", "top", "left"))


def square(half: float = 2.0) -> Loop:
    """The square [-half, half]^2 with sides named bottom, right, top, left."""
    h = half
    return Loop(np.array([[-h, -h], [h, -h], [h, h], [-h, h]]), ("bottom", "right", "top", "left"))


def half_disk(radius: float = 1.0) -> Loop:
    """Upper half disk: the arc from (R, 0) to (-R, 0) and the straight diameter back."""
    vertices = np.array([[radius, 0.0], [-radius, 0.0]])
    return Loop(vertices, ("arc", "flat"), (Arc((0.0, 0.0), ccw=True), None))


# --------------------------------------------------------------------------------------
# structured_rectangle
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("diagonal", DIAGONALS)
def test_structured_counts(diagonal):
    """Counts: (nx+1)(ny+1) grid nodes (+ nx ny centres if crossed), 2 nx ny (crossed: 4 nx ny) triangles."""
    nx, ny = 5, 3
    mesh = structured_rectangle((0.0, 0.0), (2.0, 1.0), nx, ny, diagonal)
    per_cell = 4 if diagonal == "crossed" else 2
    extra = nx * ny if diagonal == "crossed" else 0
    assert mesh.n_points == (nx + 1) * (ny + 1) + extra
    assert mesh.n_triangles == per_cell * nx * ny
    assert mesh.triangles.dtype == np.int64 and mesh.boundary_edges.dtype == np.int64
    assert mesh.edge_parts.dtype == np.int64 and mesh.points.dtype == np.float64
    assert len(mesh.boundary_edges) == 2 * (nx + ny)


@pytest.mark.parametrize("diagonal", DIAGONALS)
def test_structured_areas(diagonal):
    """All triangle areas are positive (counter-clockwise) and sum to the rectangle's area."""
    mesh = structured_rectangle((-1.0, 0.5), (2.0, 2.5), 7, 4, diagonal)
    areas = mesh.triangle_areas()
    assert np.all(areas > 0)
    assert abs(areas.sum() - 6.0) < 1e-12


@pytest.mark.parametrize("diagonal", DIAGONALS)
def test_structured_side_names_and_lengths(diagonal):
    """Each side's edges carry its part name, lie on that side and add up to its length."""
    lower, upper = (-1.0, 0.5), (2.0, 2.5)
    mesh = structured_rectangle(lower, upper, 6, 4, diagonal, side_names={"bottom": "contact"})
    assert mesh.part_names == ("contact", "right", "top", "left")
    sides = {"contact": (1, lower[1]), "right": (0, upper[0]), "top": (1, upper[1]), "left": (0, lower[0])}
    for name, (axis, value) in sides.items():
        nodes = mesh.nodes_of(name)
        assert np.all(mesh.points[nodes, axis] == value)
    assert part_length(mesh, "contact") == pytest.approx(3.0, abs=1e-12)
    assert part_length(mesh, "top") == pytest.approx(3.0, abs=1e-12)
    assert part_length(mesh, "left") == pytest.approx(2.0, abs=1e-12)
    assert part_length(mesh, "right") == pytest.approx(2.0, abs=1e-12)


def test_structured_shared_part_name():
    """Two sides mapped to one name give a single part holding both sides' edges."""
    mesh = structured_rectangle((0, 0), (1, 1), 4, 4, side_names={"left": "walls", "right": "walls"})
    assert mesh.part_names == ("bottom", "walls", "top")
    assert len(mesh.edges_of("walls")) == 8
    assert part_length(mesh, "walls") == pytest.approx(2.0, abs=1e-12)


@pytest.mark.parametrize("diagonal", DIAGONALS)
def test_structured_boundary_matches_triangulation(diagonal):
    """boundary_edges are exactly the triangulation's boundary edges, with the same orientation."""
    mesh = structured_rectangle((0, 0), (1, 2), 5, 7, diagonal)
    assert same_edge_set(mesh.boundary_edges, boundary_edges(mesh.triangles))
    check_mesh(mesh)


@pytest.mark.parametrize("diagonal", DIAGONALS)
def test_structured_orientation(diagonal):
    """Boundary runs counter-clockwise: the shoelace sum over boundary edges is twice the area."""
    mesh = structured_rectangle((1.0, 1.0), (3.0, 2.0), 4, 3, diagonal)
    assert shoelace_twice_area(mesh) == pytest.approx(4.0, abs=1e-12)


def test_structured_alternate_is_mirror_symmetric():
    """With even nx the alternating mesh maps onto itself under x -> -x (about the centre line)."""

    def triangle_set(points: np.ndarray, triangles: np.ndarray) -> set:
        corners = np.round(points[triangles], 12) + 0.0  # + 0.0 turns -0.0 into 0.0
        return {tuple(sorted(map(tuple, c))) for c in corners.tolist()}

    mirror = np.array([-1.0, 1.0])
    alternate = structured_rectangle((-1.0, 0.0), (1.0, 1.0), 6, 3, "alternate")
    assert triangle_set(alternate.points * mirror, alternate.triangles) == triangle_set(
        alternate.points, alternate.triangles
    )
    # whereas "right" is not symmetric
    right = structured_rectangle((-1.0, 0.0), (1.0, 1.0), 6, 3, "right")
    assert triangle_set(right.points * mirror, right.triangles) != triangle_set(right.points, right.triangles)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"nx": 0},
        {"ny": -2},
        {"nx": 2.5},
        {"upper": (0.0, 1.0)},
        {"diagonal": "diagonal"},
        {"side_names": {"front": "x"}},
        {"side_names": {"top": ""}},
    ],
)
def test_structured_rejects_bad_arguments(kwargs):
    """Non-positive counts, empty rectangles, unknown diagonals or sides raise MeshError."""
    args = {"lower": (0.0, 0.0), "upper": (1.0, 1.0), "nx": 2, "ny": 2} | kwargs
    with pytest.raises(MeshError):
        structured_rectangle(**args)


# --------------------------------------------------------------------------------------
# polygon_problems
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("vertices", "reason"),
    [
        ([[0, 0], [1, 0]], "fewer than 3 vertices"),
        ([[0, 0], [1, 0], [1, 1], [1, 0], [0, 1]], "repeated vertex 3"),
        ([[0, 0], [1, 1], [1, 0], [0, 1]], "edges 0 and 2 intersect"),  # bow-tie
        ([[0, 0], [4, 0], [4, 4], [2, 0], [0, 4]], "edges 0 and 2 intersect"),  # vertex touching an edge
        ([[0, 0], [2, 0], [1, 0], [1, 1]], "edges 0 and 1 intersect"),  # edge doubling back
        ([[0, 0], [1, 0], [2, 0], [3, 0]], "zero area"),
        ([[0, 0], [0.1, 0.1], [0.3, 0.3]], "zero area"),  # collinear off-axis, decided exactly
        ([[0, 0], [0, 1], [1, 1], [1, 0]], "vertices are clockwise; list them counter-clockwise"),
    ],
)
def test_polygon_problems_catches_degenerate(vertices, reason):
    """Each degenerate class gets its reason: too few, repeated, self-intersecting, zero area, clockwise."""
    assert polygon_problems(np.array(vertices, dtype=float)) == reason


def test_polygon_problems_passes_good_polygons():
    """A counter-clockwise square and L-shape (with a redundant collinear vertex) have no problems."""
    assert polygon_problems(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)) is None
    assert polygon_problems(l_shape().vertices) is None
    assert polygon_problems(np.array([[0, 0], [1, 0], [2, 0], [2, 1], [0, 1]], dtype=float)) is None


def test_polygon_problems_bad_input():
    """Wrong shapes and non-finite coordinates are reported, not raised."""
    assert "(k, 2)" in polygon_problems(np.zeros((3, 3)))
    assert polygon_problems(np.array([[0, 0], [1, np.nan], [1, 1]])) == "vertex 1 is not finite"


# --------------------------------------------------------------------------------------
# Loop, Arc, triangulate_domain
# --------------------------------------------------------------------------------------


def test_loop_validation():
    """Loops need one name and one arc entry per edge, and arcs need equal start and end radii."""
    with pytest.raises(MeshError, match="edge names"):
        Loop(np.array([[0, 0], [1, 0], [0, 1]]), ("a", "b"))
    with pytest.raises(MeshError, match="edge_arcs"):
        Loop(np.array([[0, 0], [1, 0], [0, 1]]), ("a", "b", "c"), (None,))
    with pytest.raises(MeshError, match="distance"):
        Loop(np.array([[1, 0], [-1.1, 0]]), ("arc", "flat"), (Arc((0, 0)), None))
    with pytest.raises(MeshError, match="same point"):
        Loop(np.array([[0, 0], [0, 0], [0, 1]]), ("a", "b", "c"))
    with pytest.raises(MeshError, match="edge 1 must be a non-empty string"):
        Loop(np.array([[0, 0], [1, 0], [0, 1]]), ("a", "", "c"))
    with pytest.raises(MeshError, match="edge 2 must be a non-empty string, got 3"):
        Loop(np.array([[0, 0], [1, 0], [0, 1]]), ("a", "b", 3))
    with pytest.raises(MeshError, match="radius"):
        circle_loop((0, 0), -1.0, "c")


def test_circle_loop():
    """circle_loop gives four counter-clockwise quarter arcs on the circle, all with the given name."""
    loop = circle_loop((1.0, 2.0), 0.5, "rim")
    assert loop.edge_names == ("rim",) * 4
    assert all(arc is not None and arc.ccw and arc.center == (1.0, 2.0) for arc in loop.edge_arcs)
    assert np.allclose(np.linalg.norm(loop.vertices - [1.0, 2.0], axis=1), 0.5, rtol=0, atol=1e-15)


def test_triangulate_l_shape():
    """L-shape: exact area, names on the right edges with exact lengths, quality and size near max_edge."""
    h = 0.1
    mesh = triangulate_domain(l_shape(), [], max_edge=h)
    check_mesh(mesh)
    assert mesh.part_names == ("bottom", "right", "step_top", "step_side", "top", "left")
    assert mesh.triangle_areas().sum() == pytest.approx(3.0, abs=1e-12)
    assert shoelace_twice_area(mesh) == pytest.approx(6.0, abs=1e-12)
    expected = {
        "bottom": (1, 0.0, 2.0),
        "right": (0, 2.0, 1.0),
        "step_top": (1, 1.0, 1.0),
        "step_side": (0, 1.0, 1.0),
        "top": (1, 2.0, 1.0),
        "left": (0, 0.0, 2.0),
    }
    for name, (axis, value, length) in expected.items():
        assert np.all(mesh.points[mesh.nodes_of(name), axis] == value), name
        assert part_length(mesh, name) == pytest.approx(length, abs=1e-12), name
    assert np.all(mesh.edge_curves == -1) and mesh.curves == ()
    assert min_angle_degrees(mesh) >= 28.0
    longest = mesh.triangle_diameters().max()
    assert 0.8 * h <= longest <= 1.5 * h
    assert edge_lengths(mesh, mesh.boundary_edges).max() <= h * (1 + 1e-12)


def test_a_triangulated_domain_builds_its_edge_topology_once(monkeypatch):
    """The mesh keeps the topology its boundary was oriented from (points projected onto a
    hole's circle afterwards): it is the one Topology.from_triangles builds for its
    triangles, and no stage builds it again."""
    from contactfem.mesh.topology import Topology

    builds = []
    original = Topology.from_triangles.__func__

    def counting(cls, triangles, n_points):
        builds.append(len(triangles))
        return original(cls, triangles, n_points)

    monkeypatch.setattr(Topology, "from_triangles", classmethod(counting))
    mesh = triangulate_domain(square(), [circle_loop((0.3, -0.2), 1.0, "hole")], max_edge=0.2)
    check_mesh(mesh)
    assert builds == [mesh.n_triangles]
    fresh = original(Topology, mesh.triangles, mesh.n_points)
    np.testing.assert_array_equal(mesh.topology.edges, fresh.edges)
    np.testing.assert_array_equal(mesh.topology.boundary, fresh.boundary)
    np.testing.assert_array_equal(mesh.topology.half_edge_flipped, fresh.half_edge_flipped)
    assert builds == [mesh.n_triangles]


def test_triangulate_square_with_circular_hole():
    """Square minus disk: area error O(h^2) from the inscribed polygon; hole nodes exactly on the circle."""
    center, radius = (0.3, -0.2), 1.0
    exact = 16.0 - math.pi * radius**2
    errors = []
    for h in (0.2, 0.1):
        mesh = triangulate_domain(square(), [circle_loop(center, radius, "hole")], max_edge=h)
        check_mesh(mesh)
        assert mesh.part_names == ("bottom", "right", "top", "left", "hole")
        hole_nodes = mesh.nodes_of("hole")
        distance = np.linalg.norm(mesh.points[hole_nodes] - center, axis=1)
        assert np.max(np.abs(distance - radius)) <= 1e-12
        assert len(mesh.curves) == 1 and mesh.curves[0].radius == radius
        hole = mesh.part_index("hole")
        assert np.all((mesh.edge_curves == 0) == (mesh.edge_parts == hole))
        # the other sides stay straight, with their lengths
        assert np.all(mesh.points[mesh.nodes_of("top"), 1] == 2.0)
        assert part_length(mesh, "left") == pytest.approx(4.0, abs=1e-12)
        # hole boundary runs clockwise: the shoelace sum still gives twice the meshed area
        area = mesh.triangle_areas().sum()
        assert shoelace_twice_area(mesh) == pytest.approx(2 * area, rel=1e-12)
        errors.append(area - exact)
        assert 0 < area - exact <= h**2  # inscribed polygon: the hole is slightly too small
        assert min_angle_degrees(mesh) >= 28.0
        assert mesh.triangle_diameters().max() <= 1.5 * h
    assert errors[0] / errors[1] > 3.0  # second order


def test_triangulate_half_disk():
    """Half disk from one arc and one straight edge: names, arc nodes on the circle, O(h^2) area."""
    h = 0.1
    mesh = triangulate_domain(half_disk(), [], max_edge=h)
    check_mesh(mesh)
    assert mesh.part_names == ("arc", "flat")
    assert np.all(mesh.points[mesh.nodes_of("flat"), 1] == 0.0)
    assert part_length(mesh, "flat") == pytest.approx(2.0, abs=1e-12)
    distance = np.linalg.norm(mesh.points[mesh.nodes_of("arc")], axis=1)
    assert np.max(np.abs(distance - 1.0)) <= 1e-12
    assert np.all(mesh.points[mesh.nodes_of("arc"), 1] >= 0.0)
    error = math.pi / 2 - mesh.triangle_areas().sum()
    assert 0 < error <= h**2
    assert part_length(mesh, "arc") == pytest.approx(math.pi, abs=h**2)
    assert min_angle_degrees(mesh) >= 28.0


def test_triangulate_tiny_domain_uses_fixed_point_area():
    """A max area below 1e-5 (which %g would print as 2.4e-06) still bounds the triangle size."""
    h = 2e-3
    loop = Loop(np.array([[0, 0], [0.02, 0], [0.02, 0.01], [0, 0.01]]), ("b", "r", "t", "l"))
    mesh = triangulate_domain(loop, [], max_edge=h)
    check_mesh(mesh)
    assert mesh.triangle_areas().max() <= h**2 * math.sqrt(3) / 4 * (1 + 1e-9)
    assert mesh.n_triangles >= 2e-4 / (h**2 * math.sqrt(3) / 4)


def test_triangulate_rejects_bad_domains():
    """Holes crossing or outside the outer loop, overlapping holes, bow-ties, bad parameters: MeshError."""
    with pytest.raises(MeshError, match="area"):
        triangulate_domain(square(), [circle_loop((1.8, 0.0), 1.0, "hole")], 0.1)  # crosses the outer loop
    with pytest.raises(MeshError, match="area"):
        triangulate_domain(square(), [circle_loop((0, 0), 0.5, "a"), circle_loop((0.5, 0), 0.5, "b")], 0.1)
    with pytest.raises(MeshError, match="area"):
        triangulate_domain(square(), [circle_loop((5.0, 0.0), 1.0, "hole")], 0.1)  # outside
    bow_tie = Loop(np.array([[0, 0], [1, 1], [1, 0], [0, 1]], dtype=float), ("a", "b", "c", "d"))
    with pytest.raises(MeshError):
        triangulate_domain(bow_tie, [], 0.1)
    with pytest.raises(MeshError, match="max_edge"):
        triangulate_domain(square(), [], 0.0)
    with pytest.raises(MeshError, match="min_angle"):
        triangulate_domain(square(), [], 0.1, min_angle=40.0)


# --------------------------------------------------------------------------------------
# refinement
# --------------------------------------------------------------------------------------


def test_boundary_edges_of_two_triangles():
    """boundary_edges of a square split in two: the four sides, counter-clockwise as in their triangle."""
    triangles = np.array([[0, 1, 3], [0, 3, 2]])
    edges = boundary_edges(triangles)
    assert edges.dtype == np.int64
    assert same_edge_set(edges, np.array([[0, 1], [1, 3], [3, 2], [2, 0]]))


@pytest.mark.parametrize("diagonal", ["right", "crossed"])
def test_refine_structured_twice(diagonal):
    """Two red refinements: area kept exactly, 16x triangles, old nodes unchanged, part lengths kept."""
    coarse = structured_rectangle((0, 0), (3, 2), 3, 2, diagonal, side_names={"bottom": "contact"})
    fine = refine_uniform(coarse, times=2)
    check_mesh(fine)
    assert fine.n_triangles == 16 * coarse.n_triangles
    assert np.array_equal(fine.points[: coarse.n_points], coarse.points)
    assert fine.triangle_areas().sum() == pytest.approx(6.0, abs=1e-12)
    assert fine.part_names == coarse.part_names
    for name in coarse.part_names:
        assert part_length(fine, name) == pytest.approx(part_length(coarse, name), abs=1e-12)
        assert len(fine.edges_of(name)) == 4 * len(coarse.edges_of(name))
    # the structured refinement of a structured mesh is the finer structured mesh
    assert fine.n_points == structured_rectangle((0, 0), (3, 2), 12, 8, diagonal).n_points


def test_refine_is_nested():
    """Children 4t..4t+3 of coarse triangle t tile it: areas add up and their centroids lie inside it."""
    coarse = triangulate_domain(l_shape(), [], 0.5)
    fine = refine_uniform(coarse)
    child_area = fine.triangle_areas().reshape(-1, 4).sum(axis=1)
    assert np.allclose(child_area, coarse.triangle_areas(), rtol=1e-12, atol=0)
    centroids = fine.points[fine.triangles].mean(axis=1).reshape(-1, 4, 2)
    corners = coarse.points[coarse.triangles]
    for k in range(3):  # each child centroid is left of every parent edge
        a = corners[:, k][:, None, :]
        b = corners[:, (k + 1) % 3][:, None, :]
        cross = (b[..., 0] - a[..., 0]) * (centroids[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
            centroids[..., 0] - a[..., 0]
        )
        assert np.all(cross > 0)


def test_refine_l_shape_keeps_names():
    """Refining a Triangle mesh of the L-shape twice keeps area, names and lengths of every part."""
    coarse = triangulate_domain(l_shape(), [], 0.3)
    fine = refine_uniform(coarse, 2)
    check_mesh(fine)
    assert fine.triangle_areas().sum() == pytest.approx(3.0, abs=1e-12)
    for name in coarse.part_names:
        assert part_length(fine, name) == pytest.approx(part_length(coarse, name), abs=1e-12)


def test_refine_curved_boundary():
    """Refinement puts new nodes of arc edges on the circle, keeps curves and converges to the true area."""
    center, radius = (0.0, 0.0), 1.0
    coarse = triangulate_domain(square(), [circle_loop(center, radius, "hole")], 0.4)
    fine = refine_uniform(coarse, 2)
    check_mesh(fine)
    assert fine.curves == coarse.curves
    new_nodes = np.setdiff1d(fine.nodes_of("hole"), np.arange(coarse.n_points))
    assert new_nodes.size == 3 * len(coarse.edges_of("hole"))
    distance = np.linalg.norm(fine.points[fine.nodes_of("hole")] - center, axis=1)
    assert np.max(np.abs(distance - radius)) <= 1e-12
    exact = 16.0 - math.pi
    assert abs(fine.triangle_areas().sum() - exact) < abs(coarse.triangle_areas().sum() - exact) / 10
    assert np.array_equal(fine.edge_curves >= 0, fine.edge_parts == fine.part_index("hole"))


def test_refine_zero_times_and_bad_count():
    """times=0 returns the mesh unchanged; a negative count raises MeshError."""
    mesh = structured_rectangle((0, 0), (1, 1), 2, 2)
    assert refine_uniform(mesh, 0) is mesh
    with pytest.raises(MeshError):
        refine_uniform(mesh, -1)


# --------------------------------------------------------------------------------------
# Gmsh input
# --------------------------------------------------------------------------------------


def write_gmsh_rectangle(
    path: Path,
    named_sides: tuple[str, ...] = ("bottom", "right", "top", "left"),
    quads: bool = False,
    order: int = 1,
) -> Path:
    """Mesh [0,2]x[0,1] with the gmsh API, physical lines for ``named_sides`` and a physical surface."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("rectangle")
        surface = gmsh.model.occ.addRectangle(0, 0, 0, 2, 1)
        gmsh.model.occ.synchronize()
        curves = [tag for _, tag in gmsh.model.getBoundary([(2, surface)], oriented=False)]
        by_side = {}
        for tag in curves:
            x, y, _ = gmsh.model.occ.getCenterOfMass(1, tag)
            side = "bottom" if y < 1e-9 else "top" if y > 1 - 1e-9 else "left" if x < 1e-9 else "right"
            by_side[side] = tag
        for side in named_sides:
            gmsh.model.addPhysicalGroup(1, [by_side[side]], name=side)
        gmsh.model.addPhysicalGroup(2, [surface], name="body")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        if quads:
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.model.mesh.generate(2)
        if order > 1:
            gmsh.model.mesh.setOrder(order)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def test_read_gmsh_rectangle(tmp_path):
    """A gmsh rectangle with physical lines reads back with those names, lengths, area and valid topology."""
    mesh = read_gmsh(write_gmsh_rectangle(tmp_path / "rect.msh"))
    check_mesh(mesh)
    assert set(mesh.part_names) == {"bottom", "right", "top", "left"}
    assert mesh.triangle_areas().sum() == pytest.approx(2.0, abs=1e-12)
    assert np.all(mesh.triangle_areas() > 0)
    assert np.all(mesh.points[mesh.nodes_of("bottom"), 1] == 0.0)
    assert np.all(mesh.points[mesh.nodes_of("right"), 0] == 2.0)
    assert part_length(mesh, "top") == pytest.approx(2.0, abs=1e-12)
    assert part_length(mesh, "left") == pytest.approx(1.0, abs=1e-12)
    assert shoelace_twice_area(mesh) == pytest.approx(4.0, abs=1e-12)
    assert mesh.points.shape[1] == 2
    assert mesh.n_points == len(np.unique(mesh.triangles))  # no unused nodes


def test_read_gmsh_unnamed_sides(tmp_path):
    """Boundary edges without a physical line go to the part 'unnamed'."""
    mesh = read_gmsh(write_gmsh_rectangle(tmp_path / "partial.msh", named_sides=("bottom", "top")))
    check_mesh(mesh)
    assert mesh.part_names == ("bottom", "top", "unnamed")
    assert part_length(mesh, "unnamed") == pytest.approx(2.0, abs=1e-12)


def test_read_gmsh_rejects_quads_and_second_order(tmp_path):
    """Quadrilateral and second-order meshes are refused with a message naming the cells found."""
    with pytest.raises(MeshError, match="quad"):
        read_gmsh(write_gmsh_rectangle(tmp_path / "quads.msh", quads=True))
    with pytest.raises(MeshError, match="triangle6"):
        read_gmsh(write_gmsh_rectangle(tmp_path / "p2.msh", order=2))


def test_read_gmsh_rejects_nonplanar(tmp_path):
    """A triangle mesh with nonzero z coordinates is refused."""
    meshio = pytest.importorskip("meshio")
    path = tmp_path / "lifted.msh"
    points = np.array([[0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0]])
    lifted = meshio.Mesh(points, [("triangle", np.array([[0, 1, 2]]))])
    meshio.write(path, lifted, file_format="gmsh22", binary=False)
    with pytest.raises(MeshError, match="planar"):
        read_gmsh(path)


def test_read_gmsh_bad_files(tmp_path):
    """A garbage file, a truncated file and a nonexistent path give MeshError naming the path."""
    garbage = tmp_path / "garbage.msh"
    garbage.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(MeshError, match="garbage.msh"):
        read_gmsh(garbage)
    text = tmp_path / "text.msh"
    text.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match="text.msh"):
        read_gmsh(text)
    good = write_gmsh_rectangle(tmp_path / "good.msh")
    truncated = tmp_path / "truncated.msh"
    truncated.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    with pytest.raises(MeshError, match="truncated.msh"):
        read_gmsh(truncated)
    with pytest.raises(MeshError, match="no such file"):
        read_gmsh(tmp_path / "missing.msh")


# --------------------------------------------------------------------------------------
# check_mesh
# --------------------------------------------------------------------------------------


def unit_square() -> Mesh:
    """The unit square as two triangles (0,1,3), (0,3,2) with all four sides in one part."""
    names = dict.fromkeys(("bottom", "right", "top", "left"), "all")
    return structured_rectangle((0, 0), (1, 1), 1, 1, side_names=names)


def test_check_mesh_accepts_valid():
    """A valid structured mesh passes."""
    check_mesh(unit_square())


def test_check_mesh_degenerate_triangle():
    """A triangle squashed onto a line is reported as degenerate with its index."""
    mesh = unit_square()
    points = mesh.points.copy()
    points[1] = [0.5, 0.5]  # triangle 0 = (0, 1, 3) becomes collinear
    with pytest.raises(MeshError, match="triangle 0 is degenerate"):
        check_mesh(dataclasses.replace(mesh, points=points))


def test_check_mesh_other_defects():
    """Clockwise triangles, bad indices, non-finite points and wrong boundary lists are reported."""
    mesh = unit_square()
    with pytest.raises(MeshError, match="clockwise"):
        check_mesh(dataclasses.replace(mesh, triangles=mesh.triangles[:, [0, 2, 1]]))
    with pytest.raises(MeshError, match="out of range"):
        check_mesh(dataclasses.replace(mesh, triangles=mesh.triangles + 1))
    points = mesh.points.copy()
    points[2, 0] = np.inf
    with pytest.raises(MeshError, match="non-finite"):
        check_mesh(dataclasses.replace(mesh, points=points))
    keep = np.arange(3)
    partial = dataclasses.replace(
        mesh, boundary_edges=mesh.boundary_edges[keep], edge_parts=mesh.edge_parts[keep], edge_curves=None
    )
    with pytest.raises(MeshError, match="has no part"):
        check_mesh(partial)
    with pytest.raises(MeshError, match="not a boundary edge"):
        check_mesh(dataclasses.replace(mesh, boundary_edges=mesh.boundary_edges[:, ::-1].copy()))
    with pytest.raises(MeshError, match="edge_parts"):
        check_mesh(dataclasses.replace(mesh, edge_parts=mesh.edge_parts + 5))


def test_write_gmsh_round_trips_through_read_gmsh(tmp_path):
    """write_gmsh is read_gmsh's inverse: same points, triangles, boundary edges and names."""
    from contactfem.mesh import write_gmsh

    mesh = structured_rectangle((0.0, 0.0), (2.0, 1.0), 6, 3, diagonal="alternate",
                                side_names={"bottom": "base", "right": "side", "top": "lid", "left": "side"})
    back = read_gmsh(write_gmsh(mesh, tmp_path / "mesh.msh"))
    np.testing.assert_array_equal(back.points, mesh.points)
    np.testing.assert_array_equal(back.triangles, mesh.triangles)
    assert set(back.part_names) == set(mesh.part_names)
    for name in mesh.part_names:
        assert sorted(map(tuple, back.edges_of(name))) == sorted(map(tuple, mesh.edges_of(name)))


def test_a_loops_edge_attributes_as_arrays_match_its_edges():
    """part_codes, on_parts and arc_edges agree edge by edge with the names and arcs they
    are made from (in C, for profiles of 10^5 edges)."""
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    loop = Loop(square, ("base", "side", "top", "side"))
    names, codes = loop.part_codes
    assert names == ("base", "side", "top")
    assert [names[c] for c in codes] == list(loop.edge_names)
    assert loop.on_parts({"side", "elsewhere"}).tolist() == [False, True, False, True]
    assert loop.on_parts(()).tolist() == [False] * 4
    assert loop.arc_edges.tolist() == []
    disk = half_disk()
    assert disk.arc_edges.tolist() == [0]
    assert disk.on_parts(["flat"]).tolist() == [False, True]


def test_coordinate_span_is_each_coordinates_range():
    """The range of each coordinate, as np.ptp along the first axis gives it, for points
    in the plane and in space; zeros for no points."""
    from contactfem.mesh import coordinate_span

    rng = np.random.default_rng(7)
    for shape in ((3600, 2), (50, 3), (1, 2)):
        points = rng.normal(size=shape) * np.arange(1, shape[1] + 1)
        assert np.array_equal(coordinate_span(points), np.ptp(points, axis=0))
    assert np.array_equal(coordinate_span(np.zeros((0, 2))), np.zeros(2))
