"""Mesh sequencing: coarser cases (a rough polygon's boundary decimated with its mesh), the
cost model that decides whether a coarse level pays, and the prediction it gives."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml
from conftest import case_from, square_case_dict

from contactfem.discretize.meshing import MeshRequest
from contactfem.case import PolygonGeometry
from contactfem.mesh.polygon import Loop, polygon_problems
from contactfem.sequencing import (
    SEQUENCING_THRESHOLD,
    coarse_level_pays,
    coarser,
    decimated_loop,
    overlapped,
    patch_count,
    simple_polygon,
)


def rough_polygon_case(segments: int, seed: int = 1, size: float | None = None, material: dict | None = None):
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
        "material": material or {"E": 1.0e6, "nu": 0.3},
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
    coarse, refine = coarser(MeshRequest.of(case), 0, factor=4)
    assert refine == 0 and coarse.mesh.size == pytest.approx(4 * case.mesh.size)
    loop = coarse.geometry.outer
    assert loop.edge_names.count("base") == 100
    assert loop.edge_names[-3:] == ("side", "top", "side")
    assert polygon_problems(loop.vertices) is None
    fine = case.geometry.outer.vertices
    np.testing.assert_array_equal(loop.vertices[:101], fine[:401:4])
    # Twice more: 25 segments, then 7 (the run's last vertex is always kept).
    twice, _ = coarser(coarse, 0, factor=4)
    assert twice.geometry.outer.edge_names.count("base") == 25


def test_a_mesh_graded_onto_its_boundary_is_coarsened_until_it_keeps_a_sixteenth():
    """A rough base's triangles follow its edges: four times h keeps a quarter of them
    (less where the interior's coarser mesh holds some), so the base is decimated further,
    by 8 or 16, the first that keeps at most COARSE_SHARE (about the sixteenth that four
    times h keeps of a uniform mesh). The teeth of a tread, whose tips keep their edges,
    and a shipped polygon meshed uniformly stay at four."""
    import sys
    from pathlib import Path

    from contactfem.case import load_case
    from contactfem.discretize.meshing import estimate_triangles
    from contactfem.sequencing import COARSE_SHARE

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from fragmented import teeth_case

    cases = Path(__file__).resolve().parents[1] / "cases"
    # The test's block, its interior meshed at 28 base segments: 0.18, 0.082 and 0.040 of
    # the triangles at 4, 8 and 16; the shipped one at 4 segments: 0.25, 0.12 and 0.061.
    for case, factor in ((rough_polygon_case(1600), 8), (load_case(cases / "rough.yaml"), 16)):
        coarse, refine = coarser(MeshRequest.of(case), 0)
        assert refine == 0 and coarse.mesh.size == pytest.approx(factor * case.mesh.size)
        segments = case.geometry.outer.edge_names.count("base")
        assert coarse.geometry.outer.edge_names.count("base") == -(-segments // factor)
        fine = estimate_triangles(case, 0)
        assert estimate_triangles(coarse, 0) <= COARSE_SHARE * fine
        half, _ = coarser(MeshRequest.of(case), 0, factor=factor // 2)
        assert estimate_triangles(half, 0) > COARSE_SHARE * fine
    for kept in (teeth_case(80), load_case(cases / "hole.yaml")):
        coarse, _ = coarser(MeshRequest.of(kept), 0)
        assert coarse.mesh.size == pytest.approx(4 * kept.mesh.size)


def test_edges_already_as_long_as_the_coarse_mesh_are_kept():
    """The shipped polygons (and a 4-edge block) are only meshed coarser, never decimated."""
    case = rough_polygon_case(8, size=0.01)
    coarse, _ = coarser(MeshRequest.of(case), 0)
    np.testing.assert_array_equal(coarse.geometry.outer.vertices, case.geometry.outer.vertices)
    assert decimated_loop(case.geometry.outer, 4, {"base": 0.01}) is None


def test_the_cost_model_pays_for_a_quarter_but_not_for_half_the_unknowns():
    for meshed in (True, False):
        assert coarse_level_pays(60_000, 8_000, meshed)       # a decimated rough base: 7x fewer unknowns
        assert coarse_level_pays(2_100_000, 525_000, meshed)  # the square, h twice as large
        assert not coarse_level_pays(60_000, 28_000, meshed)  # a polygon whose boundary cannot be coarsened
        assert not coarse_level_pays(10_000, 10_000, meshed)
        assert not coarse_level_pays(10_000, 0, meshed)
    # A tread's teeth keep 38% of the unknowns: a level already meshed is barely not worth
    # solving, and one still to mesh is not worth meshing (estimated at 32%).
    assert not coarse_level_pays(26_060, 9_810)
    assert not coarse_level_pays(26_060, int(0.32 * 26_060), meshed=False)
    # Meshing is what a level not meshed yet still costs: between the two thresholds the
    # level is worth solving once meshed, not worth meshing.
    assert coarse_level_pays(100_000, 30_000) and not coarse_level_pays(100_000, 30_000, meshed=False)


def test_a_coarse_level_that_keeps_the_teeth_of_a_tread_is_not_meshed(monkeypatch):
    """The teeth cannot be decimated: a coarser level keeps 38% of the unknowns, and meshing
    it (graded onto every tip) cost 4-8 of its linear solves, so that sequencing made the
    solve twice as slow as a cold start. The level is refused from its estimated unknowns,
    before it is meshed, and no worker thread is started; the cold start is certified."""
    import sys
    from pathlib import Path

    import contactfem.coarse_levels as coarse_levels
    import contactfem.solve as solve_module
    from contactfem.kernel import Status

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from fragmented import teeth_case

    case = teeth_case(80)
    problem = solve_module.prepare(case)
    assert problem.n_unknowns > SEQUENCING_THRESHOLD
    request, refine = coarser(problem.mesh_request, problem.refinements)
    estimated = coarse_levels.estimated_unknowns(problem, request, refine)
    assert 0.25 < estimated / problem.n_unknowns < 0.45
    meshed, workers = [], []
    original = solve_module.prepare
    monkeypatch.setattr(solve_module, "prepare", lambda *args, **kwargs: meshed.append(args) or original(*args, **kwargs))
    # With no coarse level to mesh first, nothing runs beside the fine level's analysis.
    real_executor = solve_module.ThreadPoolExecutor
    monkeypatch.setattr(solve_module, "ThreadPoolExecutor",
                        lambda *args, **kwargs: workers.append(args) or real_executor(*args, **kwargs))
    result = solve_module.solve_case(case, problem=problem)
    assert meshed == [] and workers == [] and result.sequencing == {}
    assert result.kernel.status is Status.CONVERGED and patch_count(result.kernel.active) >= 10


@pytest.mark.parametrize("beside_from", [0, 10**9])
def test_a_sequenced_rough_solve_has_the_answer_of_a_cold_start(monkeypatch, beside_from):
    """2 000 segments (about 15 000 unknowns, a few hundred patches): the pipeline predicts
    from a decimated coarse level and converges to the cold start's active set and answer,
    certified, whether each level's system and analysis are made beside its coarser levels
    (a worker thread) or first."""
    import contactfem.solve as solve_module
    from contactfem.kernel import Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    monkeypatch.setattr(solve_module, "BESIDE_COARSER_FROM", beside_from)

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
    coarse, _ = coarser(MeshRequest.of(case), 0)
    assert coarse.mesh.divisions == (16, 16)


@pytest.mark.parametrize("divisions, refine, coarse", [
    ((400, 4), 0, ((100, 4), 0)),    # a strip keeps its 4 cells across
    ((400, 4), 1, ((200, 4), 0)),    # 800 x 8: halved across, to 4
    ((400, 4), 3, ((400, 4), 1)),    # 3 200 x 32: both sides by four, one refinement fewer
    ((8, 2), 0, ((4, 2), 0)),        # 2 across: kept; 8 along: halved, to 4
    ((400, 3), 0, ((100, 3), 0)),    # an odd side is kept, the other coarsened
    ((401, 3), 0, None),             # neither side can be halved
    ((64, 64), 1, ((64, 64), 0)),    # a refined square: one refinement fewer, as before
    ((64, 64), 3, ((64, 64), 1)),    # two fewer
    ((2, 2), 2, ((2, 2), 1)),        # 8 x 8: halved, to 4 across, not to 2
    ((4, 4), 0, None),               # nothing to halve without going below 4 across
])
def test_a_rectangle_keeps_its_cells_across_a_thin_side(divisions, refine, coarse):
    case = case_from({**square_case_dict(), "mesh": {"divisions": list(divisions)}})
    result = coarser(MeshRequest.of(case), refine)
    assert (None if result is None else (result[0].mesh.divisions, result[1])) == coarse


def test_a_thin_strip_is_predicted_from_a_level_as_thick_in_cells():
    """A strip 1 x 0.01 peeling off at 1 600 x 4 cells (16 000 unknowns): P1 triangles
    bend by their cells across, so one cell across (the old 400 x 1 level) was far stiffer,
    misplaced both zone edges by a few nodes and left 8 fine steps (the creep extrapolated).
    Its 400 x 4 level bends like the fine mesh: the fine level settles within 4 steps, and
    on the answer a cold start reaches (the contact problem's solution is unique)."""
    from contactfem.kernel import solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    case = case_from(_peeling_strip(1e-2, (1600, 4), 10, offset=0.5))
    problem = prepare(case)
    outcome = solve_case(case, problem=problem)
    assert outcome.sequencing["coarse_unknowns"] == 2 * 401 * 5 - 2 * 5  # 400 x 4 cells, the clamp's nodes fixed
    assert outcome.kernel.iterations <= 4 and outcome.kernel.certificate.passed
    cold = solve_contact(problem.contact_system(get_method("positive")).system)
    np.testing.assert_array_equal(outcome.kernel.active, cold.active)
    assert cold.iterations > 2 * outcome.kernel.iterations


def test_a_restricted_system_with_the_solutions_outer_values_has_the_solution():
    """K_kk u_k = F_k − K_ko u_o with u_o the converged solution's outer values is the same
    contact problem: its answer is the solution's, on every kept unknown (to round-off)."""
    from contactfem.kernel import Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.sequencing import contact_layer, layer_depth
    from contactfem.solve import prepare

    problem = prepare(rough_polygon_case(400))
    system = problem.contact_system(get_method("standard")).system
    full = solve_contact(system)
    assert full.status is Status.CONVERGED
    nodes = contact_layer(problem.mesh.points, problem.mesh.points[problem.contact.nodes], layer_depth(problem.mesh) / 4)
    keep = np.repeat(nodes, 2)
    assert 0 < keep.sum() < 0.9 * len(keep)
    layer = system.restricted(keep, full.displacement)
    part = solve_contact(layer)
    assert part.status is Status.CONVERGED
    np.testing.assert_array_equal(part.active, full.active)
    scale = np.abs(full.displacement).max()
    assert np.abs(part.displacement - full.displacement[keep]).max() < 1e-10 * scale
    assert np.abs(part.nodal_force - full.nodal_force).max() < 1e-8 * np.abs(full.nodal_force).max()
    # Only the outer unknowns a kept equation couples to are read.
    outside = system.coupled_outside(keep)
    scrambled = full.displacement.copy()
    untouched = np.ones(len(keep), dtype=bool)
    untouched[outside] = False
    untouched[keep] = False
    scrambled[untouched] = 1e3
    again = solve_contact(system.restricted(keep, scrambled))
    np.testing.assert_array_equal(again.active, full.active)


def test_the_layer_corrects_a_fragmented_prediction_at_asperity_scale(monkeypatch):
    """A rough base of 2 000 segments: the decimated coarse level mispredicts the fine zone
    at asperity scale; solved again in a layer along ΓC on the fine mesh (outer unknowns at
    the coarse displacement) the prediction misses at most half as many nodes."""
    import contactfem.sequencing as sequencing
    from contactfem.kernel import Status, default_c, solve_contact
    from contactfem.methods import get_method
    from contactfem.coarse_levels import CoarseSolve, correct_in_layer
    from contactfem.solve import prepare, solve_case

    # The size threshold and share bound are the cost model's (tested below), not the mechanism's.
    monkeypatch.setattr(sequencing, "LAYER_THRESHOLD", 0)
    monkeypatch.setattr(sequencing, "LAYER_MAX_FRACTION", 1.0)
    case = rough_polygon_case(2000)
    problem = prepare(case)
    reduced = problem.contact_system(get_method("positive"))
    c = default_c(reduced.system)
    request, refine = coarser(MeshRequest.of(case), 0)
    coarse = solve_case(case, problem=prepare(case, refine=refine, request=request))
    level = CoarseSolve(coarse.solution.contact, coarse.kernel, coarse.sequencing, coarse.problem.mesh,
                        coarse.solution.displacement)
    predicted = sequencing.predict_active_set(problem.contact, level.contact, c)
    corrected, record = correct_in_layer(reduced, level, predicted, c, 1e-10, 50, "auto")
    truth = solve_contact(reduced.system, c=c, initial_active=corrected)
    assert truth.status is Status.CONVERGED
    missed_before = int(np.count_nonzero(predicted != truth.active))
    missed_after = int(np.count_nonzero(corrected != truth.active))
    assert sequencing.patch_count(truth.active) > 50
    assert missed_after <= missed_before / 2, (missed_before, missed_after)
    assert record["layer_changes"] == int(np.count_nonzero(corrected != predicted))
    assert 0 < record["layer_unknowns"] < problem.n_unknowns


def test_a_layer_holding_most_of_a_graded_mesh_is_refused_from_a_sample_of_the_contact_nodes(monkeypatch):
    """On a mesh graded onto a rough profile nearly every node is within the layer's depth
    of ΓC: the nodes near every few contact nodes already exceed the layer's share, so the
    prediction is kept without a search among all contact nodes (a lower bound: a node near
    some of them is near one of them)."""
    import contactfem.coarse_levels as coarse_levels
    import contactfem.sequencing as sequencing
    from contactfem.methods import get_method
    from contactfem.coarse_levels import CoarseSolve, correct_in_layer
    from contactfem.solve import prepare

    monkeypatch.setattr(sequencing, "LAYER_THRESHOLD", 0)
    monkeypatch.setattr(coarse_levels, "LAYER_SAMPLES", 500)
    case = rough_polygon_case(2000)
    # Grading 0.25 (steep): h reaches size within a few layer depths of ΓC, so that the
    # layer holds 0.88 of the nodes. The rule's grading at this contact_size (0.05) spreads
    # the nodes deeper and the layer holds 0.56: still refused, but not twice the share.
    case = replace(case, mesh=replace(case.mesh, size=0.1, contact_size=1.0 / 2000, grading_key=0.25))
    problem = prepare(case)
    points, boundary = problem.mesh.points, problem.mesh.points[problem.contact.nodes]
    depth = sequencing.layer_depth(problem.mesh)
    assert sequencing.contact_layer(points, boundary, depth).mean() > 2 * sequencing.LAYER_MAX_FRACTION
    searched = []

    def recording(points, nearby, depth):
        searched.append(len(nearby))
        return sequencing.contact_layer(points, nearby, depth)

    monkeypatch.setattr(coarse_levels, "contact_layer", recording)
    predicted = np.zeros(len(boundary), dtype=bool)
    predicted[::4] = True
    level = CoarseSolve(None, None, {}, problem.mesh, np.zeros((problem.mesh.n_points, 2)))
    kept, record = correct_in_layer(problem.contact_system(get_method("positive")), level, predicted, 1.0, 1e-10,
                                    50, "auto")
    assert kept is predicted and record == {}
    assert searched == [len(boundary[::len(boundary) // 500])]  # one search, among every fourth
    sample = points[::7]
    few = sequencing.contact_layer(sample, boundary[::4], depth)
    assert not (few & ~sequencing.contact_layer(sample, boundary, depth)).any()


def test_the_layer_pays_only_on_a_fragmented_zone_of_a_large_mesh_with_an_interior():
    from contactfem.sequencing import layer_pays

    assert layer_pays(694_000, 128_000, 834)       # rough base of 16 000 segments, uniform interior
    assert not layer_pays(694_000, 128_000, 1)     # one zone: Schur columns absorb its ends
    assert not layer_pays(104_000, 64_000, 390)    # a mesh graded onto the profile: the layer is most of it
    assert not layer_pays(8_000, 1_000, 90)        # small: a refactorisation is cheaper than the layer's set-up


def test_p1_interpolation_is_exact_for_linear_fields_on_a_graded_mesh():
    """Points in large triangles next to many small ones (a mesh graded onto a rough base)
    are located, and a linear field is reproduced to round-off."""
    from contactfem.mesh.transfer import interpolate_p1
    from contactfem.solve import prepare

    mesh = prepare(rough_polygon_case(1000)).mesh
    rng = np.random.default_rng(3)
    triangles = rng.integers(0, mesh.n_triangles, 4000)
    weights = rng.dirichlet(np.ones(3), len(triangles))
    points = np.einsum("qi,qij->qj", weights, mesh.points[mesh.triangles[triangles]])
    field = np.column_stack([2.0 + 3.0 * mesh.points[:, 0] - mesh.points[:, 1], mesh.points[:, 1]])
    values = interpolate_p1(mesh, field, points)
    expected = np.column_stack([2.0 + 3.0 * points[:, 0] - points[:, 1], points[:, 1]])
    assert np.abs(values - expected).max() < 1e-12



@pytest.mark.parametrize("name", ["hertz", "hertz_platen", "hertz_quarter", "hole", "punch", "square"])
def test_a_layer_forced_on_every_shipped_geometry_leaves_the_answer_unchanged(name, monkeypatch):
    """Curved boundaries (rim points outside the coarse mesh), holes, symmetry lines,
    force-driven platens (frames whose unknowns span nodes in and out of the layer), bodies
    held by contact alone: with the cost model overruled so that the layer always runs,
    the solve is certified and has the cold start's active set and displacement. (The flat
    punch, pressed in over its whole face, needs no prediction: see below; a pressed-in face
    that releases, which does, is tested there with the layer forced.)"""
    from conftest import shipped_case

    import contactfem.sequencing as sequencing
    from contactfem.kernel import Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    monkeypatch.setattr(sequencing, "LAYER_THRESHOLD", 0)
    monkeypatch.setattr(sequencing, "LAYER_MAX_FRACTION", 1.0)
    monkeypatch.setattr(sequencing, "COLUMNS_PER_FACTORIZATION", 0)
    monkeypatch.setattr(sequencing, "EXPECTED_SAVING_SOLVES", 1e9)
    case = shipped_case(name)
    problem = prepare(case, refine=1)
    sequenced = solve_case(case, problem=problem, method="standard")
    assert sequenced.kernel.status is Status.CONVERGED
    assert "layer_unknowns" in sequenced.sequencing, sequenced.sequencing
    reduced = problem.contact_system(get_method("standard"))
    cold = solve_contact(reduced.system)
    np.testing.assert_array_equal(sequenced.kernel.active, cold.active)
    scale = np.abs(cold.displacement).max()
    assert np.abs(reduced.displacement(cold.displacement) - sequenced.solution.displacement).max() < 1e-8 * scale


def punch_case(segment):
    """cases/flat_punch.yaml with its rigid face the ``segment`` (from x = 1 to x = −1)."""
    from conftest import CASES

    data = yaml.safe_load((CASES / "flat_punch.yaml").read_text(encoding="utf-8"))
    data["obstacle"] = {"segment": segment}
    return case_from(data, name="punch.yaml", directory=CASES)


def cold_start(problem, method="positive"):
    from contactfem.kernel import solve_contact
    from contactfem.methods import get_method

    return solve_contact(problem.contact_system(get_method(method)).system)


def test_a_face_pressed_in_whole_is_its_own_answer_and_pays_for_no_coarse_level():
    """The flat punch pressed 1e-3 into the block (every contact node starts inside): the
    overlap is the start, the first step settles it, and no coarse level is solved: the
    solve costs what a cold start costs (sequenced, it cost 0.13 of a linear solve more)."""
    from conftest import shipped_case

    from contactfem.kernel import Status
    from contactfem.solve import prepare, solve_case

    case = shipped_case("flat_punch")
    problem = prepare(case, refine=1)
    assert problem.n_unknowns > 5_000  # large enough to be sequenced
    assert overlapped(problem.contact.gap, case.solver.tolerance).all()
    result = solve_case(case, problem=problem)
    assert result.kernel.status is Status.CONVERGED
    assert result.sequencing == {}
    assert result.kernel.iterations == result.kernel.factorizations == 1
    assert result.kernel.active.all()


def test_a_face_pressed_in_that_partly_releases_is_predicted_after_its_first_step(monkeypatch):
    """A tilted face pressed in everywhere (4e-3 at x = 1.05, 2e-4 at x = −1.05) lifts off
    about half its nodes: the first step from the overlap does not settle, the coarse
    prediction (with the correcting layer forced to run) replaces Newton's update, and the
    answer is the cold start's."""
    import contactfem.sequencing as sequencing
    from contactfem.kernel import Status
    from contactfem.solve import prepare, solve_case

    monkeypatch.setattr(sequencing, "LAYER_THRESHOLD", 0)
    monkeypatch.setattr(sequencing, "LAYER_MAX_FRACTION", 1.0)
    monkeypatch.setattr(sequencing, "COLUMNS_PER_FACTORIZATION", 0)
    monkeypatch.setattr(sequencing, "EXPECTED_SAVING_SOLVES", 1e9)
    case = punch_case([[1.05, -4e-3], [-1.05, -2e-4]])
    problem = prepare(case, refine=1)
    assert overlapped(problem.contact.gap, case.solver.tolerance).all()
    result = solve_case(case, problem=problem)
    cold = cold_start(problem)
    assert result.kernel.status is cold.status is Status.CONVERGED
    assert result.sequencing["levels"] >= 1 and "layer_unknowns" in result.sequencing
    first = result.kernel.history[0]
    assert first.active == len(problem.contact.gap)
    assert result.kernel.history[1].active == result.sequencing["predicted_active"]
    np.testing.assert_array_equal(result.kernel.active, cold.active)
    assert 0.25 < result.kernel.active.mean() < 0.75
    assert result.kernel.iterations < cold.iterations


def test_a_partial_overlap_starts_from_the_coarse_prediction():
    """A tilted face pressed in over part of its width only (4e-3 at x = 1, out of reach at
    x = −1): the overlap mispredicts, so the coarse level comes first and the first step
    starts from its prediction, to the cold start's answer."""
    from contactfem.kernel import Status
    from contactfem.solve import prepare, solve_case

    case = punch_case([[1.0, -3e-3], [-1.0, 1e-3]])
    problem = prepare(case, refine=1)
    inside = overlapped(problem.contact.gap, case.solver.tolerance)
    assert inside.any() and not inside.all()
    result = solve_case(case, problem=problem)
    cold = cold_start(problem)
    assert result.kernel.status is cold.status is Status.CONVERGED
    assert result.kernel.history[0].active == result.sequencing["predicted_active"]
    np.testing.assert_array_equal(result.kernel.active, cold.active)
    assert result.kernel.iterations < cold.iterations


def test_overlap_counts_a_gap_below_round_off_as_touching():
    gap = np.array([1.0, 0.5, -1e-17, 0.0])
    np.testing.assert_array_equal(overlapped(gap, 1e-10), [False, False, False, False])
    np.testing.assert_array_equal(overlapped(np.array([-1e-3, -2e-3, 1e-3]), 1e-10), [True, True, False])


@pytest.mark.parametrize("beside_from", [0, 10**9])
def test_the_fine_system_is_made_beside_the_coarse_levels_and_its_error_surfaces(monkeypatch, beside_from):
    """The fine level's kernel system, solver and analysis are made in a worker thread while
    the coarse levels mesh and solve (or the system first, in place, on a small mesh): an
    error in making the fine system reaches the caller as itself, after the coarse levels
    that ran beside it or before any."""
    import contactfem.solve as solve_module
    from contactfem.discretize import DiscreteProblem
    from contactfem.errors import SolverError
    from contactfem.solve import prepare, solve_case

    monkeypatch.setattr(solve_module, "BESIDE_COARSER_FROM", beside_from)

    case = rough_polygon_case(1000)
    problem = prepare(case)
    assert problem.n_unknowns > 5_000
    original = DiscreteProblem.contact_system
    coarse_systems = []

    def contact_system(self, method):
        if self is problem:
            raise SolverError("the fine system could not be made")
        coarse_systems.append(self.n_unknowns)
        return original(self, method)

    monkeypatch.setattr(DiscreteProblem, "contact_system", contact_system)
    with pytest.raises(SolverError, match="the fine system could not be made"):
        solve_case(case, problem=problem)
    if beside_from == 0:
        assert coarse_systems and max(coarse_systems) < problem.n_unknowns / 3
    else:
        assert coarse_systems == []


def test_below_the_worker_threshold_only_the_analysis_runs_beside_the_coarse_level(monkeypatch):
    """On a mesh with a coarse level but under BESIDE_COARSER_FROM unknowns, the fine
    solver's ordering and symbolic analysis (outside the interpreter's lock) run in another
    thread while the coarse level solves, and the coarse level's own (no coarser level
    below it) in the calling thread; the answer is the cold start's."""
    import threading

    from contactfem.kernel import ActiveSetSolver, Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import BESIDE_COARSER_FROM, prepare, solve_case

    case = rough_polygon_case(1000)
    problem = prepare(case)
    assert SEQUENCING_THRESHOLD <= problem.n_unknowns < BESIDE_COARSER_FROM
    original = ActiveSetSolver.analyse
    threads = {}

    def analyse(self):
        threads[self.stiffness.shape[0]] = threading.current_thread() is threading.main_thread()
        return original(self)

    monkeypatch.setattr(ActiveSetSolver, "analyse", analyse)
    sequenced = solve_case(case, problem=problem)
    assert sequenced.sequencing["levels"] == 1
    fine_size = max(threads)
    assert threads == {fine_size: False, min(threads): True} and min(threads) < fine_size / 3
    cold = solve_contact(problem.contact_system(get_method("positive")).system)
    assert sequenced.kernel.status is cold.status is Status.CONVERGED
    np.testing.assert_array_equal(sequenced.kernel.active, cold.active)


def test_compare_meshes_and_solves_the_coarse_levels_once_for_both_methods(monkeypatch):
    """Both methods' active sets are predicted from the same coarse levels (solved with the
    positive method whatever the fine one): compare meshes and solves them once, and the
    second method's solve is the one it would be on its own."""
    import contactfem.solve as solve_module
    from contactfem.studies import compare_methods

    case = rough_polygon_case(1000)
    prepared = []
    original = solve_module.prepare

    def counting_prepare(*args, **kwargs):
        problem = original(*args, **kwargs)
        prepared.append(problem.n_unknowns)
        return problem

    monkeypatch.setattr(solve_module, "prepare", counting_prepare)
    _, outcomes = compare_methods(case)
    positive, standard = outcomes["positive"], outcomes["standard"]
    levels = positive.sequencing["levels"]
    assert levels >= 1 and standard.sequencing["levels"] == levels
    assert "coarse_reused" not in positive.sequencing and standard.sequencing["coarse_reused"] is True
    assert len(prepared) == levels  # each coarse level once (compare meshes the fine one itself)
    alone = solve_module.solve_case(case, method="standard", problem=positive.problem)
    assert "coarse_reused" not in alone.sequencing
    np.testing.assert_array_equal(alone.kernel.active, standard.kernel.active)
    u, w = alone.solution.displacement, standard.solution.displacement
    assert np.abs(u - w).max() <= 1e-10 * np.abs(u).max()


def _peeling_strip(thickness: float, cells: tuple[int, int], wavenumber: int, offset: float = 0.3) -> dict:
    """A 1 x ``thickness`` strip clamped on its left, resting on the plane, under a pressure
    offset + sin(k x) that pulls it up in places: a body in bending peeling off."""
    data = square_case_dict()
    data["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [1, thickness]}}
    data["mesh"] = {"divisions": list(cells)}
    data["boundary"]["top"] = {"traction": [0.0, f"-1.0*({offset} + sin({wavenumber}*x))"]}
    return data


def test_a_kernel_that_has_not_settled_asks_for_its_stalled_guess_once():
    """The guess is asked at STALL_ITERATIONS only, and only by a solve still changing its
    set there: the square settles first and never asks; a strip 1 x 0.01 peeling off, its
    creep not extrapolated (no ΓC order: 51 steps cold), asks once, and from the answer's
    own set it settles in the step after."""
    from contactfem.kernel import STALL_ITERATIONS, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    asked = []
    square = prepare(case_from(square_case_dict(16))).contact_system(get_method("positive")).system
    settled = solve_contact(square, stalled_guess=lambda: asked.append("square"))
    assert settled.iterations < STALL_ITERATIONS and asked == []

    strip = replace(prepare(case_from(_peeling_strip(1e-2, (400, 4), 10, offset=0.5))).contact_system(
        get_method("positive")).system, contact_edges=None)
    answer = solve_contact(strip)
    assert answer.status.value == "converged" and answer.iterations > 3 * STALL_ITERATIONS

    def guess():
        asked.append("strip")
        return answer.active

    guided = solve_contact(strip, stalled_guess=guess)
    assert asked == ["strip"]
    assert guided.status.value == "converged" and guided.iterations == STALL_ITERATIONS + 1
    np.testing.assert_array_equal(guided.active, answer.active)


def test_a_small_cold_start_that_stalls_is_predicted_from_a_coarser_mesh():
    """A strip 1 x 0.001 at 400 x 2 cells (2 400 unknowns, below the size that sequences):
    cold, it creeps past the default cap of a step per contact node, with its creep
    extrapolated along ΓC or not (2 550 and 2 598 steps to settle). At STALL_ITERATIONS it
    is solved on 100 x 1 cells (a quarter) and settles a few steps after, certified: the
    answer, the contact problem's solution being unique."""
    from dataclasses import replace

    from contactfem.kernel import STALL_ITERATIONS, Status, solve_contact
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    case = case_from(_peeling_strip(1e-3, (400, 2), 30))
    problem = prepare(case)
    assert problem.n_unknowns < 5_000
    system = problem.contact_system(get_method("positive")).system
    for cold in (solve_contact(system), solve_contact(replace(system, contact_edges=None))):
        assert cold.status is Status.MAX_ITERATIONS and "raise solver.max_iterations" in cold.message
    outcome = solve_case(case, problem=problem)
    kernel = outcome.kernel
    assert kernel.status is Status.CONVERGED and kernel.certificate.passed
    stalled = outcome.sequencing["stalled"]
    assert stalled["at"] == STALL_ITERATIONS and stalled["coarse_unknowns"] < problem.n_unknowns / 2
    assert kernel.iterations <= STALL_ITERATIONS + 10


# --------------------------------------------------------------------------- half-plane correction


def test_the_half_plane_compliance_is_flamants_averaged_over_each_nodes_share():
    """C_ij is (2 / π E*) times the mean of ln(R / |s_i − t|)₊ over node j's share of ΓC
    (checked against Gauss–Legendre quadrature to 1e-10), symmetric, zero beyond R, and
    positive semi-definite on uneven spacings."""
    from contactfem.sequencing import half_plane_compliance

    rng = np.random.default_rng(3)
    s = np.cumsum(rng.uniform(0.5, 1.5, 60))
    share = np.gradient(s)  # each node's part of ΓC: halfway to its neighbours
    reach, modulus = 6.0, 2.5e3
    compliance = half_plane_compliance(s, share, reach, modulus).toarray()
    for i, j in [(10, 10), (10, 11), (10, 13), (30, 25), (40, 44)]:
        expected_ij = _flamant_mean(s, share, i, j, reach, modulus)
        if i == j:  # the mean of ln(R / |t|) over (−a, a) is ln(R / a) + 1
            assert compliance[i, j] == pytest.approx(2 / (np.pi * modulus) * (np.log(reach / (share[j] / 2)) + 1),
                                                     rel=1e-12)
            assert compliance[i, j] == pytest.approx(expected_ij, rel=1e-5)  # Gauss beside a log singularity
        else:
            assert compliance[i, j] == pytest.approx(0.5 * (expected_ij + _flamant_mean(s, share, j, i, reach,
                                                                                        modulus)), rel=1e-10)
    assert np.array_equal(compliance, compliance.T)
    assert np.all(compliance[np.abs(s[:, None] - s[None, :]) >= reach + share.max()] == 0)
    assert np.linalg.eigvalsh(compliance).min() > -1e-12 * np.abs(compliance).max()


def _flamant_mean(s, share, i, j, reach, modulus):
    """Mean over node j's share of (2 / π E*) ln(R / |s_i − t|)₊ by Gauss–Legendre quadrature,
    split at t = s_i so that each piece is smooth inside."""
    nodes, weights = np.polynomial.legendre.leggauss(400)
    low, high = s[j] - share[j] / 2, s[j] + share[j] / 2
    total = 0.0
    for a, b in ((low, min(high, s[i])), (max(low, s[i]), high)):
        if b > a:
            t = 0.5 * (b - a) * nodes + 0.5 * (a + b)
            total += 0.5 * (b - a) * np.sum(weights * np.maximum(np.log(reach / np.abs(s[i] - t)), 0.0))
    return 2 / (np.pi * modulus) * total / share[j]


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_the_half_plane_compliance_has_the_finite_elements_log_slope_along_a_rough_base(plane):
    """Flamant: the normal displacement under a line load falls by (2 / π E*) ln 2 each time
    the distance doubles. The finite element compliance of contact nodes on a rough base of
    1 000 segments (W = Nᵀ K⁻¹ N with the supports, no contact) does about the same from 2 to
    32 node spacings (measured: 0.88–0.97 of it, 0.93 on average in plane strain, 0.96 in
    plane stress): near ΓC the body answers like the half-plane the correction assumes, with
    the modulus of its law, E / (1 − ν²) in plane strain and E in plane stress (25% apart at
    ν = 0.45, which the mean within 10% tells apart)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from performance import linear_system

    from contactfem.linalg import factorize
    from contactfem.methods import get_method
    from contactfem.sequencing import plane_strain_modulus
    from contactfem.solve import prepare

    problem = prepare(rough_polygon_case(1000, material={"E": 1.0e6, "nu": 0.45, "plane": plane}))
    system = problem.contact_system(get_method("positive")).system
    matrix, _ = linear_system(system)
    middle = len(system.normal_dofs) // 2
    columns = system.normal_dofs[[middle + k for k in (2, 4, 8, 16, 32)]]
    unit = np.zeros((matrix.shape[0], len(columns)))
    unit[columns, np.arange(len(columns))] = 1.0
    response = factorize(matrix, check=False).solve(unit)[system.normal_dofs[middle]]  # W(middle, middle + k)
    per_doubling = 2 / (np.pi * plane_strain_modulus(problem.law)) * np.log(2.0)
    ratios = -np.diff(response) / per_doubling
    assert np.allclose(ratios, 1.0, atol=0.15) and abs(ratios.mean() - 1.0) < 0.1, ratios


def _predictions(case, refine: int = 0):
    """The fine problem, its kernel system and c, and the coarse level's contact fields."""
    from contactfem.kernel import default_c
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    problem = prepare(case, refine=refine)
    reduced = problem.contact_system(get_method("positive"))
    request, coarse_refine = coarser(MeshRequest.of(case), refine)
    coarse = solve_case(case, problem=prepare(case, refine=coarse_refine, request=request))
    return problem, reduced, default_c(reduced.system), coarse.solution.contact


@pytest.mark.parametrize("name, refine", [("rough", 0), ("hertz.yaml", 0), ("hertz_quarter.yaml", 1)])
def test_the_half_plane_correction_predicts_the_fine_zone_better(name, refine):
    """The coarse prediction corrected with the half-plane's compliance misses at most 60%
    as many fine nodes as the interpolated one (on a rough base of 2 000 segments, and at
    the ends of the Hertz disk's zone), and the fine kernel started from it reaches the
    same certified set in no more Newton steps."""
    from pathlib import Path

    from contactfem.case import load_case
    from contactfem.kernel import Status, solve_contact
    from contactfem.sequencing import predict_active_set

    case = rough_polygon_case(2000) if name == "rough" else load_case(
        Path(__file__).resolve().parents[1] / "cases" / name)
    problem, reduced, c, coarse = _predictions(case, refine)
    plain = predict_active_set(problem.contact, coarse, c)
    corrected = predict_active_set(problem.contact, coarse, c, problem.law)
    from_plain = solve_contact(reduced.system, c=c, initial_active=plain)
    from_corrected = solve_contact(reduced.system, c=c, initial_active=corrected)
    assert from_plain.status is Status.CONVERGED and from_corrected.status is Status.CONVERGED
    assert np.array_equal(from_plain.active, from_corrected.active)
    truth = from_corrected.active
    missed_plain, missed_corrected = (int(np.count_nonzero(p != truth)) for p in (plain, corrected))
    assert missed_plain > 0 and missed_corrected <= 0.6 * missed_plain, (missed_plain, missed_corrected)
    assert from_corrected.iterations <= from_plain.iterations


def test_a_half_plane_block_that_cannot_be_factorised_keeps_the_prediction(monkeypatch):
    """The correction is only a start: a compliance block the factorisation refuses leaves
    the interpolated prediction as it was."""
    from scipy.linalg import LinAlgError

    import contactfem.sequencing as sequencing

    problem, _reduced, c, coarse = _predictions(rough_polygon_case(2000))
    plain = sequencing.predict_active_set(problem.contact, coarse, c)

    def refuse(*args, **kwargs):
        raise LinAlgError("not positive definite")

    monkeypatch.setattr(sequencing, "cholesky_banded", refuse)
    assert np.array_equal(sequencing.predict_active_set(problem.contact, coarse, c, problem.law), plain)


def test_the_banded_compliance_solve_is_the_dense_one():
    """The half-plane compliance of nodes sorted along ΓC, restricted to any subset of them,
    is solved in its band: the same solution as a dense Cholesky solve, to round-off."""
    from scipy.linalg import cho_factor, cho_solve

    from contactfem.sequencing import _banded_solve, half_plane_compliance

    rng = np.random.default_rng(7)
    abscissa = np.linspace(0.0, 1.0, 400) + rng.uniform(-0.2, 0.2, 400) / 399  # a profile's nodes
    share = np.gradient(abscissa)
    compliance = half_plane_compliance(abscissa, share, 16 / 399, 1.0)
    subset = np.sort(rng.choice(400, 150, replace=False))
    block = compliance[subset][:, subset]
    rhs = rng.standard_normal(150)
    dense = cho_solve(cho_factor(block.toarray()), rhs)
    assert np.allclose(_banded_solve(block.tocsr(), rhs), dense, rtol=1e-10, atol=1e-10 * np.abs(dense).max())


def test_the_half_plane_correction_moves_only_nodes_near_a_predicted_patch_end():
    """Nodes farther than the reach (the coarse contact spacing) from every end of a
    predicted patch keep their prediction: only the band near the ends is solved for."""
    from contactfem.sequencing import correct_at_asperities

    problem, _reduced, c, coarse = _predictions(rough_polygon_case(2000))
    fine = problem.contact
    pressure = np.interp(fine.abscissa, coarse.abscissa, coarse.multiplier)
    normal = np.interp(fine.abscissa, coarse.abscissa, coarse.normal_displacement)
    force = pressure * fine.masses.lumped
    # A prediction with one long patch over the middle third: its two ends are the only ones.
    s = fine.abscissa
    active = (s > s[0] + (s[-1] - s[0]) / 3) & (s < s[0] + 2 * (s[-1] - s[0]) / 3)
    spacing = float(np.median(np.diff(np.sort(coarse.abscissa))))
    corrected = correct_at_asperities(fine, normal, force, problem.law, active, spacing)
    ends = s[np.flatnonzero(active[1:] != active[:-1])]
    moved = np.flatnonzero(corrected != active)
    assert len(moved) > 0
    assert np.all(np.min(np.abs(s[moved][:, None] - ends[None, :]), axis=1) <= spacing + np.diff(s).max())


def test_a_body_whose_interior_dominates_is_predicted_from_its_coarser_level():
    """The square of 128 cells a side (33 000 unknowns, 129 contact nodes on a grid: well
    within the model's node count) has 256 unknowns per contact node: its coarser level,
    a sixteenth of it, predicts the set, and the fine solve settles in at most two steps on
    one factorisation."""
    from contactfem.solve import prepare, solve_case

    case = case_from(square_case_dict(128))
    problem = prepare(case)
    result = solve_case(case, problem=problem)
    assert result.sequencing["coarse_unknowns"] < problem.n_unknowns / 8
    assert result.kernel.iterations <= 2 and result.kernel.factorizations == 1
