"""Mesh sequencing: coarser cases (a rough polygon's boundary decimated with its mesh), the
cost model that decides whether a coarse level pays, and the prediction it gives."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import case_from, square_case_dict

from contactfem.case import PolygonGeometry
from contactfem.mesh.polygon import Loop, polygon_problems
from contactfem.sequencing import (
    coarse_level_pays,
    coarser,
    decimated_loop,
    simple_polygon,
)


def rough_polygon_case(segments: int, seed: int = 1, size: float | None = None):
    """A 1 x 0.5 block on a rough base of ``segments`` edges, pushed onto y <= min(h)."""
    rng = np.random.default_rng(seed)
    x = np.arange(segments + 1) / segments
    k = np.arange(1, segments // 2 + 1)
    h = (k[:, None] ** -1.3 * np.cos(2 * np.pi * k[:, None] * x + rng.uniform(0, 2 * np.pi, (len(k), 1)))).sum(0)
    h *= 2e-4 / h.std()
    data = {
        "geometry": {"polygon": {"vertices": [[0, 0], [1, 0], [1, 0.5], [0, 0.5]],
                                 "edges": ["base", "side", "top", "side"]}},
        "mesh": {"size": size or 28.0 / segments},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"top": {"displacement": [0, -9e-4]}, "side": "free", "base": "contact"},
        "obstacle": {"point": [0, float(h.min())], "normal": [0, -1]},
    }
    case = case_from(data)
    vertices = np.vstack([np.column_stack([x, h]), [[1.0, 0.5], [0.0, 0.5]]])
    loop = Loop(vertices, ("base",) * segments + ("side", "top", "side"))
    return replace(case, geometry=PolygonGeometry(loop, ()))


@pytest.mark.parametrize("vertices, simple", [
    ([[0, 0], [1, 0], [1, 1], [0, 1]], True),
    ([[0, 0], [1, 1], [1, 0], [0, 1]], False),          # a bow tie
    ([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]], False),  # a vertex touching an edge
    ([[0, 0], [1, 0], [2, 0], [1, 0.5]], True),         # collinear neighbours are fine
    ([[0, 0], [2, 0], [1, 0], [1, 1]], False),          # an edge doubling back on the previous
    ([[0, 0], [1, 0], [0, 0.0], [0, 1]], False),         # a repeated vertex
])
def test_simple_polygon_agrees_with_the_case_readers_check(vertices, simple):
    v = np.array(vertices, dtype=float)
    assert simple_polygon(v) is simple
    if simple:
        assert polygon_problems(v) is None or "clockwise" in polygon_problems(v)


def test_simple_polygon_on_a_rough_profile_matches_the_exhaustive_check():
    case = rough_polygon_case(600)
    vertices = case.geometry.outer.vertices
    assert simple_polygon(vertices) and polygon_problems(vertices) is None
    # Push one profile vertex through the top edge: both checks must see the crossing.
    broken = vertices.copy()
    broken[300, 1] = 0.75
    assert not simple_polygon(broken) and polygon_problems(broken) is not None


def test_a_rough_base_is_decimated_with_its_mesh_and_stays_a_valid_polygon():
    """400 base segments, coarse edge length 4x the segments': every fourth vertex is kept
    (100 segments), the three other edges unchanged, counter-clockwise, named as before."""
    case = rough_polygon_case(400)
    coarse, refine = coarser(case, 0)
    assert refine == 0 and coarse.mesh.size == pytest.approx(4 * case.mesh.size)
    loop = coarse.geometry.outer
    assert loop.edge_names.count("base") == 100
    assert loop.edge_names[-3:] == ("side", "top", "side")
    assert polygon_problems(loop.vertices) is None
    fine = case.geometry.outer.vertices
    np.testing.assert_array_equal(loop.vertices[:101], fine[:401:4])
    # Twice more: 25 segments, then 7 (the run's last vertex is always kept).
    twice, _ = coarser(coarse, 0)
    assert twice.geometry.outer.edge_names.count("base") == 25


def test_edges_already_as_long_as_the_coarse_mesh_are_kept():
    """The shipped polygons (and a 4-edge block) are only meshed coarser, never decimated."""
    case = rough_polygon_case(8, size=0.01)
    coarse, _ = coarser(case, 0)
    np.testing.assert_array_equal(coarse.geometry.outer.vertices, case.geometry.outer.vertices)
    assert decimated_loop(case.geometry.outer, 4, {"base": 0.01}) is None


def test_the_cost_model_pays_for_a_quarter_but_not_for_half_the_unknowns():
    assert coarse_level_pays(60_000, 8_000)       # a decimated rough base: 7x fewer unknowns
    assert coarse_level_pays(2_100_000, 525_000)  # the square, h twice as large
    assert not coarse_level_pays(60_000, 28_000)  # a polygon whose boundary cannot be coarsened
    assert not coarse_level_pays(10_000, 10_000)
    assert not coarse_level_pays(10_000, 0)


def test_a_sequenced_rough_solve_has_the_answer_of_a_cold_start():
    """2 000 segments (about 15 000 unknowns, a few hundred patches): the pipeline predicts
    from a decimated coarse level and converges to the cold start's active set and answer,
    certified."""
    from contactfem.kernel import Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    case = rough_polygon_case(2000)
    problem = prepare(case)
    assert problem.n_unknowns > 5_000
    sequenced = solve_case(case, problem=problem)
    cold = solve_contact(problem.contact_system(get_method("positive")).system)
    assert cold.status is sequenced.kernel.status is Status.CONVERGED
    assert sequenced.sequencing["coarse_unknowns"] < problem.n_unknowns / 3
    np.testing.assert_array_equal(sequenced.kernel.active, cold.active)
    active = sequenced.kernel.active
    assert int(active[0]) + int(np.count_nonzero(active[1:] & ~active[:-1])) > 50
    assert sequenced.kernel.iterations < cold.iterations


def test_a_square_is_still_coarsened_by_four():
    case = case_from(square_case_dict(64))
    coarse, _ = coarser(case, 0)
    assert coarse.mesh.divisions == (16, 16)
