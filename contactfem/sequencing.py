"""Mesh sequencing: predict the active set of a large case from the same case on a coarser mesh.

The coarse solution (h four times larger), itself predicted from a coarser one while it is large, is read along
ΓC as functions of the abscissa on the obstacle: its pressure λ and its normal
displacement u_n. At each fine contact node the indicator of the active set iteration,
λ ω + c (u_n − g), is evaluated with those interpolated values and the fine gap; the
nodes where it is positive start active. Only nodes near the ends of the contact zone
can be mispredicted, so the fine iteration starts a node or two from its answer.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from contactfem.case import Case, MeshFileGeometry, PolygonGeometry, RectangleGeometry
from contactfem.errors import SolverError

# Below this many unknowns a cold start is cheaper than solving a coarser case first.
SEQUENCING_THRESHOLD = 5_000
# Each coarser level has h four times larger: it costs about 1/16 of the finer solve,
# against 1/4 for halving, and mispredicts only nodes next to the ends of the zone, which
# the kernel's cached Schur columns absorb (measured on the square: 1024 from 256).
COARSENING = 4


def coarser(case: Case, refinements: int, factor: int = COARSENING) -> tuple[Case, int] | None:
    """The same case on a mesh ``factor`` times coarser (or twice, if that is all the
    mesh allows), with its refinement count; None if it cannot be coarsened."""
    levels = factor.bit_length() - 1
    if refinements >= 1:
        return case, max(refinements - levels, 0)
    settings = case.mesh
    if isinstance(case.geometry, RectangleGeometry):
        nx, ny = settings.divisions
        for step in (factor, 2):
            if nx % step == 0 and ny % step == 0:
                return replace(case, mesh=replace(settings, divisions=(nx // step, ny // step))), 0
        return None
    if isinstance(case.geometry, PolygonGeometry):
        contact_size = None if settings.contact_size is None else factor * settings.contact_size
        return replace(case, mesh=replace(settings, size=factor * settings.size, contact_size=contact_size)), 0
    assert isinstance(case.geometry, MeshFileGeometry)
    return None


def predict_active_set(case: Case, problem, c: float, progress=None) -> tuple[np.ndarray | None, dict]:
    """Initial active set (m,) for ``problem`` from a coarser solve, and what it cost.

    Returns (None, {}) when the problem is small or no coarser mesh can be made.
    """
    from contactfem.solve import prepare, solve_case  # the pipeline sits above this module

    if problem.n_unknowns < SEQUENCING_THRESHOLD:
        return None, {}
    coarse = coarser(case, problem.refinements)
    if coarse is None:
        return None, {}
    coarse_case, coarse_refine = coarse
    coarse_problem = prepare(coarse_case, refine=coarse_refine)
    if coarse_problem.n_unknowns >= problem.n_unknowns:
        return None, {}
    try:
        outcome = solve_case(coarse_case, method="positive", problem=coarse_problem)
    except SolverError:
        # A prediction is only a starting point: without one the fine solve starts cold.
        return None, {}
    coarse_contact = outcome.problem.contact
    s_coarse = coarse_contact.abscissa
    fine = problem.contact
    pressure = np.interp(fine.abscissa, s_coarse, outcome.solution.contact.multiplier)
    normal = np.interp(fine.abscissa, s_coarse, outcome.solution.contact.normal_displacement)
    indicator = pressure * fine.masses.lumped + c * (normal - fine.gap)
    active = indicator > 0
    if progress is not None:
        progress(f"  predicted {int(active.sum())} active nodes from {coarse_problem.n_unknowns} unknowns")
    return active, {
        "coarse_unknowns": coarse_problem.n_unknowns,
        "coarse_iterations": outcome.kernel.iterations,
        "predicted_active": int(active.sum()),
        "levels": 1 + outcome.report["solver"].get("sequencing", {}).get("levels", 0),
    }
