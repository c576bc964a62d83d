"""The mesh topology against a brute-force construction from the triangles."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import contactfem.mesh.topology as topology_module
from contactfem.assembly import Elasticity, stiffness_matrix
from contactfem.errors import MeshError
from contactfem.mesh import (
    Mesh,
    circle_loop,
    refine_uniform,
    structured_rectangle,
    triangulate_domain,
)
from contactfem.mesh.adapt import bisect, label_longest_edge
from contactfem.mesh.polygon import Loop
from contactfem.mesh.topology import Topology


def _loop(vertices, name):
    vertices = np.asarray(vertices, dtype=float)
    return Loop(vertices, (name,) * len(vertices), (None,) * len(vertices))


def _shuffled(mesh: Mesh, seed: int) -> Mesh:
    """The same mesh with nodes and triangles renumbered at random (rotations keep orientation)."""
    rng = np.random.default_rng(seed)
    new_of_old = rng.permutation(mesh.n_points)
    points = np.empty_like(mesh.points)
    points[new_of_old] = mesh.points
    triangles = new_of_old[mesh.triangles][rng.permutation(mesh.n_triangles)]
    shift = rng.integers(0, 3, size=len(triangles))
    triangles = np.take_along_axis(triangles, (shift[:, None] + np.arange(3)) % 3, axis=1)
    return Mesh(points=points, triangles=triangles, boundary_edges=new_of_old[mesh.boundary_edges],
                edge_parts=mesh.edge_parts, part_names=mesh.part_names)


def meshes():
    """(name, mesh, number of holes)."""
    for diagonal in ("right", "left", "alternate", "crossed"):
        yield f"structured {diagonal}", structured_rectangle((0.0, 0.0), (2.0, 1.0), 5, 3, diagonal=diagonal), 0
    outer = _loop([[0.0, 0.0], [2.0, 0.0], [2.3, 1.4], [0.4, 1.9], [-0.2, 0.8]], "a")
    one_hole = triangulate_domain(outer, [_loop([[0.6, 0.6], [0.9, 1.2], [1.3, 0.7]], "h")], max_edge=0.3)
    yield "triangle, one hole", one_hole, 1
    square = _loop([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]], "s")
    two_holes = triangulate_domain(square, [circle_loop((1.0, 1.5), 0.5, "c"), circle_loop((3.0, 1.5), 0.4, "d")],
                                   max_edge=0.5)
    yield "triangle, two holes", two_holes, 2
    yield "refined structured", refine_uniform(structured_rectangle((0.0, 0.0), (1.0, 1.0), 3, 2), 2), 0
    yield "refined triangle", refine_uniform(one_hole, 1), 1
    labelled = label_longest_edge(two_holes)
    yield "bisected", bisect(labelled, np.random.default_rng(0).random(labelled.n_triangles) < 0.3), 2
    yield "shuffled", _shuffled(one_hole, 5), 1
    yield "single triangle", Mesh(points=np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
                                  triangles=np.array([[0, 1, 2]]), boundary_edges=np.array([[0, 1], [1, 2], [2, 0]]),
                                  edge_parts=np.zeros(3, dtype=np.int64), part_names=("all",)), 0


MESHES = list(meshes())
IDS = [name for name, _, _ in MESHES]


def brute_force(triangles: np.ndarray):
    """Sorted edges, the triangle on each side of every edge and the boundary, with Python sets."""
    directed = {}
    for t, tri in enumerate(triangles.tolist()):
        for k in range(3):
            a, b = tri[k], tri[(k + 1) % 3]
            assert (a, b) not in directed
            directed[(a, b)] = t
    edges = sorted({(min(a, b), max(a, b)) for a, b in directed})
    sides = [(directed.get((lo, hi), -1), directed.get((hi, lo), -1)) for lo, hi in edges]
    boundary = [e for e, (left, right) in enumerate(sides) if left < 0 or right < 0]
    return edges, sides, boundary


@pytest.mark.parametrize("name, mesh, holes", MESHES, ids=IDS)
def test_topology_matches_a_brute_force_construction(name, mesh, holes):
    topology = mesh.topology
    edges, sides, boundary = brute_force(mesh.triangles)
    assert topology.n_points == mesh.n_points and topology.n_triangles == mesh.n_triangles
    assert topology.edges.shape == (len(edges), 2) and topology.n_edges == len(edges)
    assert topology.edges.tolist() == [list(e) for e in edges]
    assert topology.edge_triangles.dtype == np.int64
    assert topology.edge_triangles.tolist() == [list(s) for s in sides]
    assert topology.boundary.tolist() == boundary
    assert np.all((topology.edge_triangles[topology.boundary] < 0).sum(axis=1) == 1)

    # Half-edge 3 t + k runs from node k to node k + 1 of triangle t.
    start = mesh.triangles.ravel()
    end = mesh.triangles[:, [1, 2, 0]].ravel()
    index = {e: i for i, e in enumerate(edges)}
    expected = [index[(min(a, b), max(a, b))] for a, b in zip(start.tolist(), end.tolist())]
    assert topology.half_edge_edge.shape == (3 * mesh.n_triangles,)
    assert topology.half_edge_edge.tolist() == expected
    assert topology.half_edge_flipped.dtype == bool
    assert np.array_equal(topology.half_edge_flipped, start > end)
    half = topology.boundary_half_edges
    assert np.array_equal(topology.half_edge_edge[half], topology.boundary)

    # The listed boundary is the topological one, each row with the triangle it came from.
    listed = {(int(a), int(b)) for a, b in mesh.boundary_edges}
    assert listed == {(int(start[h]), int(end[h])) for h in half}
    for (a, b), t in zip(mesh.boundary_edges.tolist(), mesh.boundary_edge_triangles.tolist()):
        assert sides[index[(min(a, b), max(a, b))]][0 if a < b else 1] == t
        assert (a, b) in {tuple(mesh.triangles[t, [k, (k + 1) % 3]].tolist()) for k in range(3)}


@pytest.mark.parametrize("name, mesh, holes", MESHES, ids=IDS)
def test_euler_formula(name, mesh, holes):
    """V - E + F = 1 - holes for a connected planar triangulation."""
    assert mesh.n_points - mesh.topology.n_edges + mesh.n_triangles == 1 - holes
    # Every boundary loop has as many edges as nodes, and there are 1 + holes loops.
    boundary = mesh.topology.edges[mesh.topology.boundary]
    assert len(np.unique(boundary)) == len(boundary)


@pytest.mark.parametrize("name, mesh, holes", MESHES, ids=IDS)
def test_edge_index(name, mesh, holes):
    topology = mesh.topology
    edges = {tuple(e) for e in topology.edges.tolist()}
    rng = np.random.default_rng(2)
    n = mesh.n_points
    a = np.concatenate([topology.edges[:, 1], rng.integers(-2, n + 3, size=300)])
    b = np.concatenate([topology.edges[:, 0], rng.integers(-2, n + 3, size=300)])
    expected = [topology.edges.tolist().index([min(x, y), max(x, y)]) if (min(x, y), max(x, y)) in edges else -1
                for x, y in zip(a.tolist(), b.tolist())]
    found = topology.edge_index(a, b)
    assert found.dtype == np.int64 and found.tolist() == expected
    assert np.array_equal(topology.edge_index(b, a), found)
    even = len(a) // 2 * 2
    assert np.array_equal(topology.edge_index(a[:even].reshape(2, -1), b[:even].reshape(2, -1)),
                          found[:even].reshape(2, -1))
    lo, hi = topology.edges[0]
    assert topology.edge_index(int(hi), int(lo)) == 0
    assert topology.edge_index(int(lo), int(lo)) == -1


def test_topology_is_built_once_per_mesh_and_read_only():
    mesh = structured_rectangle((0.0, 0.0), (1.0, 1.0), 4, 4)
    topology = mesh.topology
    assert mesh.topology is topology
    assert mesh.boundary_edge_triangles is mesh.boundary_edge_triangles
    assert refine_uniform(mesh).topology is not topology
    for array in (topology.edges, topology.half_edge_edge, topology.half_edge_flipped, topology.edge_triangles,
                  topology.boundary, topology.boundary_half_edges, mesh.boundary_edge_triangles):
        assert not array.flags.writeable
    # Column-major, so that each node column is contiguous for the assembly.
    assert topology.edges[:, 0].flags.c_contiguous and topology.edges[:, 1].flags.c_contiguous
    assert topology.half_edge_edge.dtype == np.int32


def test_int64_indices_give_the_same_topology(monkeypatch):
    mesh = MESHES[4][1]
    reference = Topology.from_triangles(mesh.triangles, mesh.n_points)
    monkeypatch.setattr(topology_module, "_INT32_LIMIT", 10)
    wide = Topology.from_triangles(mesh.triangles, mesh.n_points)
    assert wide.edges.dtype == np.int64 and wide.half_edge_edge.dtype == np.int64
    for name in ("edges", "half_edge_edge", "half_edge_flipped", "edge_triangles", "boundary"):
        assert np.array_equal(getattr(wide, name), getattr(reference, name)), name


def test_unusual_triangulations():
    empty = Topology.from_triangles(np.zeros((0, 3), dtype=np.int64), 4)
    assert empty.edges.shape == (0, 2) and empty.edge_triangles.shape == (0, 2) and empty.boundary.size == 0
    assert empty.edge_index([0, 1], [1, 2]).tolist() == [-1, -1]
    with pytest.raises(ValueError, match="repeats a node"):
        Topology.from_triangles(np.array([[0, 1, 2], [2, 3, 2]]), 4)
    with pytest.raises(ValueError, match="in \\[0, 4\\)"):
        Topology.from_triangles(np.array([[0, 1, 4]]), 4)
    with pytest.raises(ValueError, match="integer"):
        Topology.from_triangles(np.array([[0.0, 1.0, 2.0]]), 4)
    bad = Mesh(points=np.zeros((3, 2)), triangles=np.array([[0, 1, 1]]), boundary_edges=np.zeros((0, 2), dtype=int),
               edge_parts=np.zeros(0, dtype=np.int64), part_names=())
    with pytest.raises(MeshError, match="repeats a node"):
        bad.topology

    # Two triangles on the same side of an edge: no pair of sides, but the boundary
    # (edges in exactly one triangle) is still defined.
    overlap = Topology.from_triangles(np.array([[0, 1, 2], [0, 1, 3]]), 4)
    with pytest.raises(ValueError, match=r"edge \(0, 1\) runs the same way"):
        overlap.edge_triangles
    assert overlap.edges[overlap.boundary].tolist() == [[0, 2], [0, 3], [1, 2], [1, 3]]
    # An edge in three triangles is not a boundary edge.
    fan = Topology.from_triangles(np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]), 5)
    assert [0, 1] not in fan.edges[fan.boundary].tolist()
    with pytest.raises(ValueError):
        fan.edge_triangles


def test_boundary_edge_triangles_rejects_a_reversed_boundary_edge():
    mesh = structured_rectangle((0.0, 0.0), (1.0, 1.0), 2, 2)
    reversed_edges = mesh.boundary_edges.copy()
    reversed_edges[3] = reversed_edges[3, ::-1]
    bad = Mesh(points=mesh.points, triangles=mesh.triangles, boundary_edges=reversed_edges,
               edge_parts=mesh.edge_parts, part_names=mesh.part_names)
    with pytest.raises(MeshError, match=r"boundary_edges\[3\]"):
        bad.boundary_edge_triangles


def test_stiffness_matrix_takes_the_mesh_topology():
    law = Elasticity.from_young(1.0e3, 0.3)
    mesh = MESHES[4][1]
    built = stiffness_matrix(mesh.points, mesh.triangles, law)
    given = stiffness_matrix(mesh.points, mesh.triangles, law, topology=mesh.topology)
    for name in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(built, name), getattr(given, name))
    with pytest.raises(ValueError, match="topology"):
        stiffness_matrix(mesh.points, mesh.triangles[1:], law, topology=mesh.topology)


def test_topology_module_imports_only_numpy_and_scipy():
    source = Path(topology_module.__file__).read_text(encoding="utf-8")
    imported = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            imported.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            imported.add((node.module or "").split(".")[0])
    assert imported <= {"__future__", "dataclasses", "functools", "numpy", "scipy"}
