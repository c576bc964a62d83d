"""A mesh file must cover each point once and be cut nowhere: conforming triangles can
still be a body cut by unmerged nodes, or pieces that overlap or meet at a point, and each
of those solved without error into the answer for a body nobody drew (two halves meshed
apart and not merged: the upper one clamped alone, no contact at all).
:func:`contactfem.mesh.quality.check_body` refuses them, naming where; separate pieces
that neither touch nor overlap stay allowed."""

from __future__ import annotations

import math
from pathlib import Path

import meshio
import numpy as np
import pytest

from contactfem.errors import MeshError
from contactfem.mesh import Mesh
from contactfem.mesh.gmsh_io import read_gmsh
from contactfem.mesh.quality import boundary_loops, check_body, check_mesh
from contactfem.mesh.refine import boundary_edges
from contactfem.mesh.structured import structured_rectangle

from conftest import make_runner
from contactfem.cli import main

ROOT = Path(__file__).resolve().parents[1]


def mesh_of(points: np.ndarray, triangles: np.ndarray) -> Mesh:
    """The triangulation as a mesh with one boundary part, checked as check_mesh checks it."""
    used, triangles = np.unique(np.asarray(triangles, dtype=np.int64), return_inverse=True)
    triangles = triangles.reshape(-1, 3)
    edges = boundary_edges(triangles)
    mesh = Mesh(points=np.asarray(points, dtype=float)[used], triangles=triangles, boundary_edges=edges,
                edge_parts=np.zeros(len(edges), dtype=np.int64), part_names=("all",))
    check_mesh(mesh)  # every mesh below is a valid conforming triangulation: only the body is wrong
    return mesh


def stacked(merged_where=lambda x: True, shift: float = 0.0, lift: float = 0.0) -> Mesh:
    """[0, 1] x [0, 0.5] and a second block on top (moved by ``shift``, ``lift``), whose
    coincident nodes on y = 0.5 are merged where ``merged_where(x)``."""
    low = structured_rectangle((0, 0), (1, 0.5), 8, 4)
    high = structured_rectangle((shift, 0.5 + lift), (1 + shift, 1 + lift), 8, 4)
    points = np.vstack([low.points, high.points])
    triangles = np.vstack([low.triangles, high.triangles + low.n_points])
    keep = np.arange(len(points))
    for i in np.flatnonzero(np.isclose(high.points[:, 1], 0.5)) + low.n_points:
        same = np.flatnonzero(np.all(low.points == points[i], axis=1))
        if same.size and merged_where(points[i, 0]):
            keep[i] = same[0]
    return mesh_of(points, keep[triangles])


def ring(turn: float, cells: int = 48) -> Mesh:
    """A ring r in [1, 1.5] over angles 0 to ``turn``, one strip of quads split in two."""
    angles = np.linspace(0.0, turn, cells + 1)
    points = np.concatenate([np.column_stack([r * np.cos(angles), r * np.sin(angles)]) for r in (1.0, 1.5)])
    i = np.arange(cells)
    inner, outer = i, i + cells + 1
    triangles = np.concatenate([np.column_stack([inner, outer + 1, inner + 1]), np.column_stack([inner, outer, outer + 1])])
    return mesh_of(points, triangles)


def test_valid_bodies_pass_and_their_loops_close_with_the_body_on_the_left():
    """A merged block and a block with a hole pass; the loops are the outer boundary
    counter-clockwise and the hole clockwise, each a closed chain of boundary edges."""
    check_body(stacked())
    grid = structured_rectangle((0, 0), (4, 4), 4, 4)
    centre = grid.points[grid.triangles].mean(axis=1)
    holed = mesh_of(grid.points, grid.triangles[~np.all((centre > 1) & (centre < 3), axis=1)])
    check_body(holed)
    loops = boundary_loops(holed)
    assert sorted(len(loop) for loop in loops) == [8, 16]
    for loop in loops:
        x, y = holed.points[loop].T
        twice_area = np.sum(x * np.roll(y, -1) - y * np.roll(x, -1))
        assert twice_area == pytest.approx(32.0 if len(loop) == 16 else -8.0, rel=1e-12)
        chained = {tuple(edge) for edge in np.column_stack([loop, np.roll(loop, -1)]).tolist()}
        assert chained <= {tuple(edge) for edge in holed.boundary_edges.tolist()}


def test_surfaces_meshed_apart_and_not_merged_are_refused_at_their_coincident_nodes():
    with pytest.raises(MeshError, match=r"coincide at \([01.0-9]+, 0\.5\) on the boundary: the mesh is 2 pieces that "
                                        r"share no edge.*Coherence"):
        check_body(stacked(merged_where=lambda x: False))


def test_nodes_merged_to_a_tolerance_they_missed_are_refused_too():
    """A CAD interface 1e-9 apart (8e-9 of the edges there) is the same cut; a gap of 1e-3
    (0.008 of them) is two separate blocks, a scene of its own."""
    with pytest.raises(MeshError, match=r"are 1e-09 apart at \([01.0-9]+, 0\.5\), less than 1e-06 of the edges"):
        check_body(stacked(merged_where=lambda x: False, lift=1e-9))
    check_body(stacked(merged_where=lambda x: False, lift=1e-3))


def test_a_slit_of_unmerged_nodes_cuts_the_body():
    """Half the interface merged: one piece, whose boundary passes twice through the slit."""
    with pytest.raises(MeshError, match=r"coincide at \(0(\.\d+)?, 0\.5\) on the boundary: the mesh is cut"):
        check_body(stacked(merged_where=lambda x: x >= 0.5))


def test_overlapping_pieces_are_refused_where_their_boundaries_cross():
    with pytest.raises(MeshError, match="two boundary loops meet near .*: triangles overlap"):
        check_body(stacked(merged_where=lambda x: False, shift=0.3, lift=-0.2))


def squares(*boxes: tuple[float, float, float, float]) -> Mesh:
    """Separate structured squares (x0, y0, x1, y1), 4 x 4 cells each, in one mesh."""
    parts = [structured_rectangle(box[:2], box[2:], 4, 4) for box in boxes]
    offsets = np.cumsum([0] + [part.n_points for part in parts])
    return mesh_of(np.vstack([part.points for part in parts]),
                   np.vstack([part.triangles + offset for part, offset in zip(parts, offsets)]))


def test_separate_pieces_are_allowed_unless_one_lies_in_the_others_triangles():
    """Two punches side by side, or a disk in a frame's hole, are bodies a case may hold
    each by its supports; a square inside another square's triangles crosses no boundary
    but covers that area twice."""
    check_body(squares((0, 0, 1, 1), (2, 0, 3, 1)))
    grid = structured_rectangle((0, 0), (4, 4), 4, 4)
    centre = grid.points[grid.triangles].mean(axis=1)
    frame = grid.triangles[~np.all((centre > 1) & (centre < 3), axis=1)]
    island = structured_rectangle((1.5, 1.5), (2.5, 2.5), 2, 2)
    check_body(mesh_of(np.vstack([grid.points, island.points]), np.vstack([frame, island.triangles + grid.n_points])))
    with pytest.raises(MeshError, match=r"a piece of the mesh, at \(1\.2, 1\.2\), lies inside another piece"):
        check_body(squares((0, 0, 4, 4), (1.2, 1.2, 2.2, 2.2)))


def test_a_strip_that_wraps_over_itself_crosses_its_own_boundary():
    """One piece, every triangle counter-clockwise, no edge shared wrongly: only the
    boundary's crossing shows the overlap."""
    check_body(ring(1.5 * math.pi))
    with pytest.raises(MeshError, match="the boundary crosses itself near"):
        check_body(ring(2.0 * math.pi + 0.5))


def test_a_hole_that_touches_the_outline_at_a_node_is_refused():
    grid = structured_rectangle((0, 0), (3, 3), 3, 3)
    centre = grid.points[grid.triangles].mean(axis=1)
    cell = np.floor(centre).astype(int)
    notched = ~(((cell[:, 0] == 0) & (cell[:, 1] == 0)) | ((cell[:, 0] == 1) & (cell[:, 1] == 1)))
    with pytest.raises(MeshError, match=r"touches itself at node \d+ \(1, 1\)"):
        check_body(mesh_of(grid.points, grid.triangles[notched]))


def test_the_loops_of_a_long_boundary_are_ranked_without_a_walk():
    """20 000 boundary edges in one loop come back in order (each edge's end starts the next)."""
    mesh = structured_rectangle((0, 0), (1, 1e-3), 10_000, 1)
    (loop,) = boundary_loops(mesh)
    assert len(loop) == 20_002
    following = {int(a): int(b) for a, b in mesh.boundary_edges}
    assert all(following[int(a)] == int(b) for a, b in zip(loop, np.roll(loop, -1)))


def write_two_halves(path: Path) -> Path:
    """The square of cases/square.yaml meshed as two halves whose interface nodes are not merged, with physical lines."""
    low = structured_rectangle((0, 0), (1, 0.5), 8, 4)
    high = structured_rectangle((0, 0.5), (1, 1), 8, 4)
    names = ["bottom", "right", "top", "left"]
    cells, physical = [("triangle", np.vstack([low.triangles, high.triangles + low.n_points]))], [np.full(low.n_triangles + high.n_triangles, 9)]
    for part, offset, skip in ((low, 0, "top"), (high, low.n_points, "bottom")):
        for name in part.part_names:
            if name != skip:
                cells.append(("line", part.edges_of(name) + offset))
                physical.append(np.full(len(part.edges_of(name)), names.index(name) + 1))
    field_data = {name: np.array([k + 1, 1]) for k, name in enumerate(names)} | {"body": np.array([9, 2])}
    points = np.vstack([low.points, high.points])
    meshio.write(path, meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), cells,
                                   cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
                                   field_data=field_data), file_format="gmsh22", binary=False)
    return path


def test_a_mesh_file_of_two_unmerged_halves_is_refused_in_one_line(tmp_path):
    """The square case on such a file solved before, exit 0, into no contact at all."""
    write_two_halves(tmp_path / "halves.msh")
    with pytest.raises(MeshError, match="2 pieces that share no edge"):
        read_gmsh(tmp_path / "halves.msh")
    text = (ROOT / "cases" / "square.yaml").read_text(encoding="utf-8")
    text = text.replace("  rectangle: {lower: [0, 0], upper: [1, 1]}", "  mesh_file: halves.msh")
    text = "\n".join(line for line in text.splitlines() if "divisions" not in line and "diagonal" not in line)
    case = tmp_path / "halves.yaml"
    case.write_text(text, encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(case), "--out", str(tmp_path / "out")])
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "halves.yaml: geometry.mesh_file" in lines[0] and "2 pieces that share no edge" in lines[0]
    assert "Coherence" in lines[0]
    assert not (tmp_path / "out").exists()


def test_a_file_whose_elements_name_an_entity_it_never_declares_says_so(tmp_path):
    """Format 4.1 with boundary lines in entities missing from $Entities (meshio writes such
    a file when every node is put in the surface's entity): the reader's KeyError became
    "cannot read mesh ...: np.int32(1) (KeyError)"."""
    square = structured_rectangle((0, 0), (1, 1), 2, 2)
    lines = square.edges_of("bottom")
    physical = [np.full(square.n_triangles, 5), np.full(len(lines), 1)]
    meshio.write(tmp_path / "broken.msh", meshio.Mesh(
        np.column_stack([square.points, np.zeros(square.n_points)]), [("triangle", square.triangles), ("line", lines)],
        cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
        field_data={"bottom": np.array([1, 1]), "body": np.array([5, 2])},
        point_data={"gmsh:dim_tags": np.tile([2, 5], (square.n_points, 1))}), file_format="gmsh", binary=False)
    with pytest.raises(MeshError, match=r"broken.msh: it refers to entity or tag 1, which it does not define \(KeyError\)"):
        read_gmsh(tmp_path / "broken.msh")
