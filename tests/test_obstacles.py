"""The obstacle protocol: each flat obstacle's gap, normals, facing and abscissa, by hand."""

from __future__ import annotations

import numpy as np
import pytest

from contactfem.discretize.obstacles import HalfPlane, Segment, obstacle_of

POINTS = np.array([[0.0, 1.0], [2.0, -0.5], [-3.0, 0.25], [1.0, 0.0]])


def test_a_half_plane_measures_the_gap_along_its_normal_and_faces_every_point():
    """Obstacle below y = 0, normal (0, −1) into it: the gap of (x, y) is y, the abscissa
    along the tangent (1, 0) is x, and every point faces the infinite line."""
    plane = HalfPlane(point=np.array([5.0, 0.0]), normal=np.array([0.0, -1.0]))
    np.testing.assert_allclose(plane.gap(POINTS), POINTS[:, 1], atol=0, rtol=0)
    np.testing.assert_allclose(plane.abscissa(POINTS), POINTS[:, 0], atol=0, rtol=0)
    np.testing.assert_array_equal(plane.normals(POINTS), np.tile([0.0, -1.0], (4, 1)))
    assert plane.faces(POINTS).all() and plane.extent is None
    assert plane.describe() == {"kind": "half-plane", "point": [5.0, 0.0], "normal": [0.0, -1.0]}


def test_a_tilted_half_plane_gives_the_euclidean_distance_to_its_line():
    """The line x + y = 1, obstacle on the side x + y ≥ 1: the gap is (1 − x − y)/√2."""
    normal = np.array([1.0, 1.0]) / np.sqrt(2.0)
    plane = HalfPlane(point=np.array([1.0, 0.0]), normal=normal)
    np.testing.assert_allclose(plane.gap(POINTS), (1.0 - POINTS.sum(axis=1)) / np.sqrt(2.0), rtol=1e-15, atol=1e-15)


def test_a_segment_faces_only_the_points_whose_projection_falls_between_its_ends():
    """The segment from (−1, 0) to (1.5, 0): points at x = −3 and x = 2 face nothing, x = 0
    and x = 1 do, and an end itself (x = 1.5 within round-off) does."""
    segment = Segment(point=np.array([-1.0, 0.0]), normal=np.array([0.0, -1.0]),
                      ends=np.array([[-1.0, 0.0], [1.5, 0.0]]))
    assert segment.extent == (-1.0, 1.5)
    np.testing.assert_array_equal(segment.faces(POINTS), [True, False, False, True])
    assert segment.faces(np.array([[1.5 + 1e-12, 3.0]]))[0]
    assert not segment.faces(np.array([[1.5 + 1e-6, 3.0]]))[0]
    assert segment.describe()["ends"] == [[-1.0, 0.0], [1.5, 0.0]]


@pytest.mark.parametrize("name, kind", [("square", "half-plane"), ("punch", "half-plane"), ("flat_punch", "segment")])
def test_the_case_builds_its_obstacle_and_the_contact_boundary_asks_it(name, kind):
    """The square and the tilted punch rest on half-planes, the flat punch is pressed by a segment: ΓC's gaps and
    normals are the obstacle's at its nodes."""
    from conftest import shipped_case

    from contactfem.solve import prepare

    case = shipped_case(name)
    problem = prepare(case)
    contact = problem.contact
    assert obstacle_of(case.obstacle).kind == kind == contact.obstacle.kind
    points = problem.mesh.points[contact.nodes]
    np.testing.assert_array_equal(contact.gap, contact.obstacle.gap(points))
    np.testing.assert_array_equal(contact.normals, contact.obstacle.normals(points))
