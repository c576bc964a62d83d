"""Mesh sequencing, as pure steps: a coarser mesh request, whether solving the case on it first pays, and the active set it predicts.

The coarse solution (h four times larger, but never fewer than four cells across a
rectangle's thin side: a body in bending must bend like its fine mesh) is read along ΓC as functions of the abscissa
on the obstacle: its pressure λ and its normal displacement u_n. At each fine contact
node the indicator of the active set iteration, λ ω + c (u_n − g), is evaluated with those
interpolated values and the fine gap; the nodes where it is positive start active. Only
nodes near the ends of contact patches can be mispredicted, so the fine iteration starts
a node or so per patch end from its answer. The recursion (solve the coarse level, itself
predicted from a coarser one) lives in :mod:`contactfem.solve`.

A polygon whose boundary is finer than the coarse mesh (a rough profile of thousands of
short edges) would force the coarse mesh to keep every vertex, and cost nearly as much as
the fine one: its runs of short straight edges are decimated with the mesh, keeping every
``factor``-th vertex, as long as the polygon stays simple and counter-clockwise.

A decimated profile, or a coarse mesh wider than the asperities, misplaces a fragmented
fine zone at asperity scale (a quarter of its active nodes on a rough base), while away
from ΓC the coarse solution is right: the prediction is then corrected on the fine mesh
in a layer along ΓC (:func:`contact_layer`, :func:`layer_depth`), solved with contact and
the coarse displacement outside, when :func:`layer_pays`.
"""

from __future__ import annotations

import operator
from dataclasses import replace
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded

from contactfem.assembly import Elasticity
from contactfem.case import MeshFileGeometry, PolygonGeometry, RectangleGeometry
from contactfem.discretize import ContactBoundary
from contactfem.discretize.meshing import MeshRequest, estimate_triangles
from contactfem.kernel import PathStarts
from contactfem.mesh import Mesh
from contactfem.mesh.polygon import Loop
from contactfem.result import ContactFields

#: Below this many unknowns a cold start is cheaper than solving a coarser case first: the
#: fixed cost of meshing and solving a level outweighs the factorisations a prediction saves.
SEQUENCING_THRESHOLD = 5_000
#: Each coarser level has h this many times larger. Four leaves about a sixteenth of the
#: unknowns (halving would leave a quarter), and the prediction it gives misses only nodes
#: next to the ends of the zone, which the kernel's cached Schur columns absorb; a larger
#: factor saves more on the coarse level and mispredicts more on the fine one.
COARSENING = 4
#: The share of the fine level's estimated triangles a polygon's coarser level keeps at
#: most: about the sixteenth that h four times larger leaves of a uniform mesh. A mesh
#: graded onto its boundary (a long profile, a contact size) keeps a quarter at four times
#: h, its triangles following the boundary's edges, and its coarse level then costs more
#: than the fine level's system and analysis beside it: its boundary and sizes are
#: coarsened by 8, then 16 (COARSENING squared), until the estimate is within this share.
#: A smaller share makes the coarse level cheaper at no cost in fine Newton steps on the
#: rough profiles and the Hertz platen (benchmarks/rough.py; see
#: docs/performance.md#measured-design-choices).
COARSE_SHARE = 1 / 12
#: Each further doubling must leave at most this share of the last level's estimated
#: triangles (a half where the boundary sets them): a boundary that cannot be decimated
#: (the teeth of a tread, whose tips stay) shrinks too little for the doubling to pay.
FURTHER_COARSENING_SHARE = 0.6
#: What a coarse level's contact solve costs, in linear solves of its own size, once
#: predicted from the level below (fitted on the square and the rough profiles,
#: benchmarks/fragmented.py and rough.py). A larger value refuses more coarse levels.
COARSE_LEVEL_SOLVES = 3.0
#: What meshing and assembling a coarse level costs, in linear solves of its own size
#: (fitted on the shipped polygons' and the rough profiles' coarse levels; graded meshes
#: cost more). A larger value refuses more coarse levels.
MESHING_SOLVES = 3.0
#: What a prediction saves on the fine level, in its linear solves: the difference between
#: a cold start's factorisations and a predicted start's (benchmarks/fragmented.py).
EXPECTED_SAVING_SOLVES = 2.0
#: Sparse factorisation time grows like unknowns ** GROWTH on these 2D meshes.
GROWTH = 1.1
#: Cells a coarser level keeps across each side of a rectangle (all the fine mesh has, if
#: fewer): P1 triangles resist bending by their cells across a thin body, so a strip
#: coarsened to one cell across is far stiffer than its fine mesh and misplaces the edges of
#: a zone that peels off, and the fine level then takes many steps. Keeping four costs a
#: quarter of the unknowns instead of a sixteenth on a thin strip, and returns the fine
#: level to a few steps (benchmarks/fragmented.py; see
#: docs/performance.md#measured-design-choices).
MIN_CELLS_ACROSS = 4
#: Candidate edge pairs the simplicity check of a decimated polygon may test; beyond it the
#: polygon is kept as it is (an outline with many long, overlapping edges).
MAX_EDGE_PAIRS = 5_000_000
#: Depth of the layer along ΓC in which a fragmented prediction is corrected on the fine
#: mesh, in median fine triangle diameters (four coarse ones). A deeper layer corrects more
#: of the mispredicted nodes and costs more to solve (benchmarks/rough.py; see
#: docs/performance.md#measured-design-choices).
LAYER_DEPTH = 16
#: The largest share of the fine unknowns the layer may hold (a mesh graded onto ΓC puts
#: most of its nodes near it, and the layer then costs as much as the fine solve).
LAYER_MAX_FRACTION = 0.3
#: Nodes sampled to estimate the share of the mesh a layer would hold before it is built.
LAYER_SAMPLES = 4_000
#: Below this many fine unknowns a refactorisation costs less than the layer's set-up.
LAYER_THRESHOLD = 50_000
#: Schur columns costing about one refactorisation (CHOLMOD; see :mod:`contactfem.kernel`).
COLUMNS_PER_FACTORIZATION = 20
#: Steps of the half-plane correction of a prediction (:func:`correct_at_asperities`): a
#: bound with room to spare, since the correction settles in a few steps on the rough
#: profiles and the Hertz disk.
ASPERITY_ITERATIONS = 8
#: Fine contact nodes on either side within the half-plane correction's reach at most (the
#: coarse level's spacing, four fine ones on the rough profiles): its compliance matrix
#: has at most 2 x this + 1 entries a row.
ASPERITY_NEIGHBOURS = 16


def worth_sequencing(n_unknowns: int) -> bool:
    """Whether a problem of this size is worth predicting from a coarser one."""
    return n_unknowns >= SEQUENCING_THRESHOLD


def coarse_level_pays(fine_unknowns: int, coarse_unknowns: int, meshed: bool = True) -> bool:
    """Whether solving ``coarse_unknowns`` first is expected to cost less than it saves.

    Cost model, in linear solves of the fine problem: a linear solve of the coarse level
    costs q = (coarse / fine) ** :data:`GROWTH` of a fine one; the coarse level's contact
    solve costs :data:`COARSE_LEVEL_SOLVES` of its own, and meshing and assembling it
    :data:`MESHING_SOLVES` more; the levels below it cost as much again in proportion (q² +
    q³ + …, the same ratio assumed down the chain); the prediction saves
    :data:`EXPECTED_SAVING_SOLVES`. ``meshed``: the level is meshed already (its meshing is
    spent, and its unknowns counted); otherwise ``coarse_unknowns`` is an estimate made before
    meshing it, and its meshing counts.

    A square coarsened by four in h (a sixteenth of the unknowns), h twice as large (a
    quarter) or a decimated rough base (a fifth) pays; a polygon whose boundary cannot be
    coarsened (the teeth of a tread, whose coarse level keeps over a third of the unknowns)
    does not: solving it first is slower than a cold start.
    """
    if coarse_unknowns <= 0 or coarse_unknowns >= fine_unknowns:
        return False
    q = (coarse_unknowns / fine_unknowns) ** GROWTH
    level = COARSE_LEVEL_SOLVES + MESHING_SOLVES
    below = level * q * q / (1.0 - q)
    cost = (COARSE_LEVEL_SOLVES if meshed else level) * q + below
    return cost < EXPECTED_SAVING_SOLVES


def coarser(request: MeshRequest, refinements: int, factor: int | None = None) -> tuple[MeshRequest, int] | None:
    """The mesh ``request`` (a discrete problem's ``mesh_request``) ``factor`` times coarser
    (or twice, if that is all the mesh allows), with its refinement count; None if it cannot
    be coarsened. The request is not rewritten: the coarser level is the same request meshed from
    this request. By default
    :data:`COARSENING`, and for an unrefined polygon whose coarse level would keep more than
    :data:`COARSE_SHARE` of its estimated triangles, twice or four times that, as long as
    each doubling halves the estimate about (see :data:`FURTHER_COARSENING_SHARE`).

    A rectangle's divisions shrink by ``factor`` (or 2) along each side that keeps
    :data:`MIN_CELLS_ACROSS` of them, or all it has if fewer (see :func:`_coarser_rectangle`).
    A polygon's mesh sizes grow by ``factor``, and its runs of straight edges shorter than
    the coarse mesh's edge length are decimated by the same factor (see
    :func:`decimated_loop`); a loop whose decimation would not be simple keeps its vertices.
    """
    if factor is not None:
        return _coarser_by(request, refinements, factor)
    factor = COARSENING
    coarse = _coarser_by(request, refinements, factor)
    if coarse is None or refinements or not isinstance(request.geometry, PolygonGeometry):
        return coarse
    fine, estimate = estimate_triangles(request, refinements), estimate_triangles(*coarse)
    while factor < COARSENING**2 and estimate > COARSE_SHARE * fine:
        further = _coarser_by(request, refinements, 2 * factor)
        further_estimate = None if further is None else estimate_triangles(*further)
        if further_estimate is None or further_estimate > FURTHER_COARSENING_SHARE * estimate:
            break
        factor, coarse, estimate = 2 * factor, further, further_estimate
    return coarse


def _coarser_by(request: MeshRequest, refinements: int, factor: int) -> tuple[MeshRequest, int] | None:
    """:func:`coarser` by the given ``factor``."""
    if isinstance(request.geometry, RectangleGeometry):
        return _coarser_rectangle(request, refinements, factor)
    if refinements >= 1:
        return request, max(refinements - (factor.bit_length() - 1), 0)
    settings = request.mesh
    if isinstance(request.geometry, PolygonGeometry):
        contact_size = None if settings.contact_size is None else factor * settings.contact_size
        mesh = replace(settings, size=factor * settings.size, contact_size=contact_size)
        coarse_edge = {name: mesh.size for name in _part_names(request.geometry)}
        if contact_size is not None:
            coarse_edge.update({name: contact_size for name in request.contact_parts})
        outer = decimated_loop(request.geometry.outer, factor, coarse_edge)
        holes = tuple(decimated_loop(hole, factor, coarse_edge) for hole in request.geometry.holes)
        if outer is not None and _signed_area(outer.vertices) <= 0.0:
            outer = None  # the case's outer loop is counter-clockwise; so must its decimation be
        geometry = PolygonGeometry(
            outer if outer is not None else request.geometry.outer,
            tuple(new if new is not None else old for new, old in zip(holes, request.geometry.holes)),
        )
        return replace(request, geometry=geometry, mesh=mesh), 0
    assert isinstance(request.geometry, MeshFileGeometry)
    return None


def _coarser_rectangle(request: MeshRequest, refinements: int, factor: int) -> tuple[MeshRequest, int] | None:
    """A rectangle's coarser level. Its cells across each side (the divisions refined
    ``refinements`` times) are divided by ``factor``, or by 2, or kept: the largest step
    that leaves :data:`MIN_CELLS_ACROSS` cells, or as many as the fine mesh has if fewer.
    None unless the cells are at least halved. Where both sides take the same step, a
    refined mesh's coarser level is its divisions refined fewer times (by the step, or all
    its refinements if fewer), as for any geometry."""
    nx, ny = request.mesh.divisions
    across = (nx << refinements, ny << refinements)

    def step(cells: int) -> int:
        for divisor in (factor, 2):
            if cells % divisor == 0 and cells // divisor >= min(cells, MIN_CELLS_ACROSS):
                return divisor
        return 1

    steps = (step(across[0]), step(across[1]))
    if steps[0] * steps[1] < 2:
        return None
    if steps[0] == steps[1] and refinements >= 1:
        # Each refinement undone halves the cells: as many as the step allows, or there are.
        return request, refinements - min(steps[0].bit_length() - 1, refinements)
    coarse = (across[0] // steps[0], across[1] // steps[1])
    return replace(request, mesh=replace(request.mesh, divisions=coarse)), 0


def decimated_loop(loop: Loop, factor: int, coarse_edge: dict[str, float]) -> Loop | None:
    """``loop`` with every run of consecutive straight edges of one part, each shorter than
    that part's coarse edge length (``coarse_edge``), reduced to every ``factor``-th vertex
    (the run's ends kept); None when nothing is decimated or the result is not a simple
    polygon (checked by :func:`simple_polygon`, with the original orientation)."""
    vertices = loop.vertices
    k = len(vertices)
    lengths = np.linalg.norm(np.roll(vertices, -1, axis=0) - vertices, axis=1)
    # Each edge's part as a code (a profile has 10^5 edges).
    names, part = loop.part_codes
    arcs = loop.edge_arcs
    straight = loop.straight_edges
    coarse_length = np.array([coarse_edge.get(name, np.inf) for name in names], dtype=float)[part]
    short = straight & (lengths < coarse_length)
    if short.sum() < 2:
        return None
    # A run starts at an edge that is short while the previous edge is not short or belongs
    # to another part; a loop that is one single run starts at vertex 0.
    same = part == np.roll(part, 1)
    starts = np.flatnonzero(short & ~(np.roll(short, 1) & same))
    first = int(starts[0]) if len(starts) else 0
    # In the loop's order from the first start, every short edge continues the run of the
    # latest start; its place in that run decides whether its start vertex is kept.
    order = (np.arange(k) + first) % k
    is_start = np.zeros(k, dtype=bool)
    is_start[starts] = True
    is_start[first] = True
    begun = np.flatnonzero(is_start[order])
    run_start = begun[np.searchsorted(begun, np.arange(k), side="right") - 1]
    place = np.arange(k) - run_start
    # Vertices strictly inside a run (places 1, 2, ...): every ``factor``-th is kept; its
    # last edge's end vertex is not inside it and stays.
    drop = short[order] & (place >= 1) & (place % factor != 0)
    keep = np.ones(k, dtype=bool)
    keep[order[drop]] = False
    if keep.all() or keep.sum() < 3:
        return None
    new = vertices[keep]
    if not simple_polygon(new):
        return None
    if np.sign(_signed_area(new)) != np.sign(_signed_area(vertices)):
        return None
    index = np.flatnonzero(keep).tolist()
    return Loop(vertices=new, edge_names=tuple(operator.itemgetter(*index)(loop.edge_names)),
                edge_arcs=tuple(operator.itemgetter(*index)(arcs)))


def simple_polygon(vertices: np.ndarray) -> bool:
    """Whether the closed polygon through ``vertices`` (k, 2) is simple: distinct vertices,
    no two edges meeting except adjacent ones at their common vertex (touching counts as
    meeting), nonzero area. Edge pairs are found by sweeping along x, so a rough profile of
    thousands of short edges costs a few milliseconds; False also when there are more than
    :data:`MAX_EDGE_PAIRS` candidate pairs."""
    v = np.asarray(vertices, dtype=float)
    k = len(v)
    if k < 3 or _signed_area(v) == 0.0:
        return False
    by_point = v[np.lexsort((v[:, 1], v[:, 0]))]
    if np.any(np.all(by_point[1:] == by_point[:-1], axis=1)):
        return False  # a repeated vertex
    a, b = v, np.roll(v, -1, axis=0)
    after = np.roll(v, -2, axis=0)
    folded = (_orientation(a, b, after) == 0) & (np.einsum("ij,ij->i", b - a, after - b) < 0)
    if folded.any():
        return False
    low_x, high_x = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    order = np.argsort(low_x, kind="stable")
    ends = np.searchsorted(low_x[order], high_x[order], side="right")
    counts = np.maximum(ends - np.arange(k) - 1, 0)
    total = int(counts.sum())
    if total > MAX_EDGE_PAIRS:
        return False
    if total == 0:
        return True
    first = np.repeat(np.arange(k), counts)
    offset = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    i, j = order[first], order[first + 1 + offset]
    adjacent = (np.abs(i - j) == 1) | (np.abs(i - j) == k - 1)
    low_y, high_y = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    near = ~adjacent & (low_y[i] <= high_y[j]) & (low_y[j] <= high_y[i])
    i, j = i[near], j[near]
    return not _segments_meet(a[i], b[i], a[j], b[j]).any()


def _orientation(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Sign of the turn p → q → r (+1 left, −1 right, 0 collinear), row by row."""
    cross = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    return np.sign(cross)


def _segments_meet(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Whether segment p1p2 meets q1q2 (touching included), row by row."""
    d1, d2 = _orientation(q1, q2, p1), _orientation(q1, q2, p2)
    d3, d4 = _orientation(p1, p2, q1), _orientation(p1, p2, q2)
    proper = (d1 * d2 < 0) & (d3 * d4 < 0)

    def on(p, q, r):  # r on segment pq, given collinear
        return ((np.minimum(p[:, 0], q[:, 0]) <= r[:, 0]) & (r[:, 0] <= np.maximum(p[:, 0], q[:, 0]))
                & (np.minimum(p[:, 1], q[:, 1]) <= r[:, 1]) & (r[:, 1] <= np.maximum(p[:, 1], q[:, 1])))

    touching = (((d1 == 0) & on(q1, q2, p1)) | ((d2 == 0) & on(q1, q2, p2))
                | ((d3 == 0) & on(p1, p2, q1)) | ((d4 == 0) & on(p1, p2, q2)))
    return proper | touching


def _signed_area(vertices: np.ndarray) -> float:
    following = np.roll(vertices, -1, axis=0)
    return 0.5 * float(np.sum(vertices[:, 0] * following[:, 1] - vertices[:, 1] * following[:, 0]))


def _part_names(geometry: PolygonGeometry) -> set[str]:
    names = set(geometry.outer.edge_names)
    for hole in geometry.holes:
        names.update(hole.edge_names)
    return names


def overlapped(gap: np.ndarray, tolerance: float) -> np.ndarray:
    """The contact nodes that start inside the obstacle by more than round-off: gap below
    −``tolerance`` times the largest gap (a curved body resting on the obstacle has its
    lowest node's gap at round-off, of either sign)."""
    gap = np.asarray(gap, dtype=float)
    return gap < -tolerance * np.abs(gap).max(initial=0.0)


def starting_set(gap: np.ndarray, tolerance: float,
                 predict: Callable[[], tuple[np.ndarray | None, dict]],
                 ) -> tuple[np.ndarray | None, Callable[[], np.ndarray | None] | None, dict]:
    """Where the kernel starts: its starting set, the second guess it may ask for
    (:func:`contactfem.kernel.solve_contact`) and the record of the coarse prediction, filled
    when ``predict`` (the coarse levels: a set or None, and what they cost) is called.

    When every contact node starts inside the obstacle (a flat punch pressed in over its
    whole face), Newton can only release nodes from there, and for a face that stays pressed
    in the overlap is the answer, which the first step tells at the cost of the
    factorisation any start needs: the coarse prediction is then only the second guess, paid
    for if that step does not settle. Otherwise it comes first; a partial overlap (a tilted
    punch, a disk pressed in) is no prediction.
    """
    record: dict = {}

    def predicted() -> np.ndarray | None:
        active, cost = predict()
        record.update(cost)
        return active

    if not prediction_first(gap, tolerance):
        return overlapped(gap, tolerance), predicted, record
    return predicted(), None, record


def prediction_first(gap: np.ndarray, tolerance: float) -> bool:
    """Whether :func:`starting_set` starts from the coarse prediction: not every contact
    node starts inside the obstacle."""
    inside = overlapped(gap, tolerance)
    return not (len(inside) and inside.all())


def predict_active_set(fine: ContactBoundary, coarse: ContactFields, c: float,
                       law: Elasticity | None = None) -> np.ndarray:
    """Initial active set (m,) of the fine contact nodes from a coarse solution's contact
    fields; with the body's ``law``, corrected at the scale of the coarse level's contact
    nodes (:func:`correct_at_asperities`)."""
    pressure = np.interp(fine.abscissa, coarse.abscissa, coarse.multiplier)
    normal = np.interp(fine.abscissa, coarse.abscissa, coarse.normal_displacement)
    force = pressure * fine.masses.lumped
    active = force + c * (normal - fine.gap) > 0
    if law is None or len(coarse.abscissa) < 2:
        return active
    return correct_at_asperities(fine, normal, force, law, active, float(np.median(np.diff(np.sort(coarse.abscissa)))))


def correct_at_asperities(fine: ContactBoundary, normal: np.ndarray, force: np.ndarray, law: Elasticity,
                          active: np.ndarray, spacing: float) -> np.ndarray:
    """The predicted ``active`` set corrected where the fine boundary differs from the
    coarse one within ``spacing`` (the coarse contact nodes'), with the elastic half-plane's
    compliance.

    The coarse level gives, interpolated at the fine nodes, a normal displacement ``normal``
    and nodal forces ``force``, right at its own scale. Below it, the fine profile's
    asperities and the ends of its patches move the force about: near ΓC the body answers
    like a half-plane, whose normal displacement under a line load P is
    (2 / π E*) P ln(R / r) plus a constant (Flamant; E* the plane-strain modulus). So the
    fine nodal forces Λ are taken as those of the contact problem

        u_n = normal − C (Λ − force),   Λ ≥ 0,  u_n ≤ g,  Λ (g − u_n) = 0,

    with C the half-plane's compliance between nodes less than R = ``spacing`` apart (each
    node's force spread over its share of ΓC). Only nodes within R of an end of a predicted
    patch are unknowns; the others keep the coarse force (those predicted active) or none.
    It is solved by the primal–dual active set iteration from ``active``, at most
    :data:`ASPERITY_ITERATIONS` steps; its set is the prediction. Any failure (a block
    that is not positive definite) keeps ``active``.

    On the rough profiles it halves the mispredicted nodes (benchmarks/results/ablation.json).
    """
    s = fine.abscissa
    m = len(s)
    fine_spacing = float(np.median(np.diff(s))) if m > 1 else 0.0
    ends = np.flatnonzero(active[1:] != active[:-1])
    if len(ends) == 0 or not fine_spacing > 0:
        return active  # nothing predicted, or everything: no patch end to move
    # At most ASPERITY_NEIGHBOURS nodes within reach on either side: C stays O(m).
    reach = min(spacing, ASPERITY_NEIGHBOURS * fine_spacing)
    between = 0.5 * (s[ends] + s[ends + 1])
    after = np.searchsorted(between, s)
    distance = np.minimum(np.abs(s - between[np.maximum(after - 1, 0)]),
                          np.abs(between[np.minimum(after, len(between) - 1)] - s))
    band = np.flatnonzero(distance <= reach)
    compliance = half_plane_compliance(s, fine.masses.lumped, reach, plane_strain_modulus(law), rows=band)
    held = np.where(active, force, 0.0)
    held[band] = 0.0
    slack = normal[band] - fine.gap[band] + compliance @ (force - held)  # u_n − g with the band's Λ = 0
    local = compliance[:, band]
    settled = active[band]
    for _ in range(ASPERITY_ITERATIONS):
        on = np.flatnonzero(settled)
        forces = np.zeros(len(band))
        try:
            if len(on):
                forces[on] = _banded_solve(local[on][:, on], slack[on])
        except (MemoryError, LinAlgError):
            return active
        updated = np.where(settled, forces > 0, slack - local @ forces > 0)
        if np.array_equal(updated, settled):
            break
        settled = updated
    corrected = active.copy()
    corrected[band] = settled
    return corrected


def _banded_solve(block: sp.csr_matrix, rhs: np.ndarray) -> np.ndarray:
    """``block``⁻¹ ``rhs`` for a symmetric positive definite ``block`` whose entries lie near
    its diagonal: the compliance of nodes sorted along ΓC couples each node with those within
    reach only, so its band holds about 2 :data:`ASPERITY_NEIGHBOURS` + 1 diagonals and the
    banded Cholesky costs O(n · band²), whatever n."""
    upper = sp.triu(block, format="coo")
    width = int((upper.col - upper.row).max(initial=0))
    bands = np.zeros((width + 1, block.shape[0]))
    bands[width + upper.row - upper.col, upper.col] = upper.data
    return cho_solve_banded((cholesky_banded(bands), False), rhs)


def plane_strain_modulus(law: Elasticity) -> float:
    """E* of the 2D law: E / (1 − ν²) in plane strain, E in plane stress (4μ(λ+μ)/(λ+2μ)
    with the λ the 2D law holds)."""
    return 4.0 * law.mu * (law.lam + law.mu) / (law.lam + 2.0 * law.mu)


def half_plane_compliance(abscissa: np.ndarray, share: np.ndarray, reach: float, modulus: float,
                          rows: np.ndarray | None = None) -> sp.csr_matrix:
    """C (m, m), or its ``rows``: the normal displacement at node i of the elastic
    half-plane of plane-strain ``modulus`` under a unit force at node j spread evenly over
    its ``share`` of ΓC, (2 / π E*) times the mean of ln(reach / |s_i − t|)₊ over that
    segment, symmetrised (the mean of C_ij and C_ji); zero for nodes farther apart than
    ``reach`` (whose differences the coarse level holds). ``abscissa`` sorted.
    ln(R / r)₊ is positive definite in the plane (the Green's function of a disk), so C is
    positive semi-definite on a line up to the segments' spreading."""
    s = np.asarray(abscissa, dtype=float)
    share = np.asarray(share, dtype=float)
    rows = np.arange(len(s)) if rows is None else np.asarray(rows, dtype=np.int64)
    low = np.searchsorted(s, s[rows] - reach, side="left")
    high = np.searchsorted(s, s[rows] + reach, side="right")
    counts = high - low
    row = np.repeat(np.arange(len(rows)), counts)
    cols = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(low, counts)
    offset = s[rows][row] - s[cols]

    def integral(t: np.ndarray) -> np.ndarray:  # ∫_0^t ln(reach / |τ|)₊ dτ, odd in t
        a = np.minimum(np.abs(t), reach)
        safe = np.where(a > 0, a, reach)
        return np.sign(t) * np.where(a > 0, a * (np.log(reach / safe) + 1.0), 0.0)

    def mean_over(half: np.ndarray) -> np.ndarray:  # over (s_j − half, s_j + half), seen from s_i
        with np.errstate(divide="ignore", invalid="ignore"):
            return (integral(offset + half) - integral(offset - half)) / np.where(half > 0, 2.0 * half, np.inf)

    values = (mean_over(0.5 * share[cols]) + mean_over(0.5 * share[rows][row])) * (1.0 / (np.pi * modulus))
    return sp.csr_matrix((values, (row, cols)), shape=(len(rows), len(s)))


def contact_layer(points: np.ndarray, boundary: np.ndarray, depth: float) -> np.ndarray:
    """Which of ``points`` (q, 2) lie within ``depth`` of one of the ``boundary`` points
    (the contact nodes): the layer along ΓC in which a coarse prediction is corrected on
    the fine mesh (see :func:`layer_depth`)."""
    from scipy.spatial import cKDTree

    # Only points in the contact nodes' bounding box grown by ``depth`` can be near them.
    low, high = boundary.min(axis=0) - depth, boundary.max(axis=0) + depth
    candidates = np.flatnonzero(((points >= low) & (points <= high)).all(axis=1))
    distance, _ = cKDTree(boundary).query(points[candidates], distance_upper_bound=depth)
    layer = np.zeros(len(points), dtype=bool)
    layer[candidates[np.isfinite(distance)]] = True
    return layer


def layer_depth(mesh: Mesh, samples: int = 5_000) -> float:
    """How deep the correcting layer reaches: :data:`LAYER_DEPTH` of the fine mesh's typical
    (median) triangle diameters, that is :data:`LAYER_DEPTH` / :data:`COARSENING` of the
    coarse level's, beyond which the coarse solution is taken as right. The median is
    taken over an even sample of at most ``samples`` triangles."""
    step = max(1, mesh.n_triangles // samples)
    a, b, c = (mesh.points[mesh.triangles[::step, k]] for k in range(3))
    longest = np.maximum.reduce([((a - b) ** 2).sum(axis=1), ((b - c) ** 2).sum(axis=1), ((c - a) ** 2).sum(axis=1)])
    return LAYER_DEPTH * float(np.sqrt(np.median(longest)))


def layer_pays(fine_unknowns: int, layer_unknowns: int, patches: int) -> bool:
    """Whether correcting the prediction in a layer of ``layer_unknowns`` is expected to
    save more than it costs, for a predicted zone of ``patches`` runs of active nodes.

    The kernel's Schur columns absorb a node or two mispredicted at each end of a patch
    (about :data:`COLUMNS_PER_FACTORIZATION` columns cost a refactorisation), so a zone of
    few patches gains nothing. A fragmented one (hundreds of patches on a rough profile)
    is mispredicted at asperity scale, a node in four, and costs two or three fine
    factorisations from the coarse prediction alone, one once corrected in the layer.
    The layer is solved like a coarse level (:data:`COARSE_LEVEL_SOLVES` of its own linear
    solves, each (layer / fine) ** :data:`GROWTH` of a fine one) and must not take more than
    :data:`LAYER_MAX_FRACTION` of the unknowns.
    """
    if (fine_unknowns < LAYER_THRESHOLD or patches * 2 < COLUMNS_PER_FACTORIZATION
            or layer_unknowns > LAYER_MAX_FRACTION * fine_unknowns):
        return False
    q = (layer_unknowns / fine_unknowns) ** GROWTH
    return COARSE_LEVEL_SOLVES * q < EXPECTED_SAVING_SOLVES


def patch_count(active: np.ndarray) -> int:
    """Runs of consecutive active nodes (the contact nodes are numbered along ΓC)."""
    a = np.asarray(active, dtype=bool)
    return int(a[0]) + int(np.count_nonzero(a[1:] & ~a[:-1])) if len(a) else 0


class PredictedStarts(PathStarts):
    """Where each step of a load path on a fine mesh starts: from the set a coarser level
    predicts at the step's factor (``predict``, which solves that level there) or from the
    set extrapolated from the steps before, whichever missed fewer nodes of the last step
    that had both. Extrapolation is exact where the zone stays put (a traction on the
    square, a punch's face) and costs nothing; where asperities come into contact step by
    step it predicts every node whose gap the push would close at the last steps' rate,
    and the zone's stiffening makes that a large overshoot (769 predicted wrong against
    47 from the coarser level, 140 active, on a 16 000-point rough profile at the second
    of ten steps). The first step asks the coarser level; a tie goes to extrapolation. A
    step that extrapolation alone started and missed hands the next to the coarser level
    unless it missed no more than that level did when last compared; that record serves
    once (a Hertz platen's zone edge, which the coarser level often misses by a node,
    extrapolation by none: two Newton steps for each hand-over)."""

    def __init__(self, predict: Callable[[float], np.ndarray | None]) -> None:
        self.predict = predict
        self.prefer_coarse = True
        #: The nodes the coarser level missed when last compared (0 once that served).
        self.coarse_missed = 0
        self.candidates: dict[str, np.ndarray] = {}
        #: Steps started from each kind of set (solved: a factor solved before, its own set).
        self.started = {"coarse": 0, "extrapolated": 0, "solved": 0}

    def choose(self, factor: float, extrapolated: np.ndarray | None) -> np.ndarray | None:
        self.candidates = {} if extrapolated is None else {"extrapolated": extrapolated}
        if self.prefer_coarse or extrapolated is None:
            predicted = self.predict(factor)
            if predicted is not None:
                self.candidates["coarse"] = predicted
                self.started["coarse"] += 1
                return predicted
        self.started["extrapolated"] += extrapolated is not None
        return None

    def revisited(self, factor: float) -> None:
        # A factor solved before starts from its own set, the answer (the path solver's):
        # no prediction was made, and the step judges neither.
        self.candidates = {}
        self.started["solved"] += 1

    def settled(self, active: np.ndarray) -> None:
        missed = {name: int(np.count_nonzero(guess != active)) for name, guess in self.candidates.items()}
        if "coarse" in missed:
            self.coarse_missed = missed["coarse"]
        if "extrapolated" in missed:
            self.prefer_coarse = missed["extrapolated"] > self.coarse_missed
            if "coarse" not in missed and missed["extrapolated"]:
                self.coarse_missed = 0
