"""How accurate a solve is: report.json's ``accuracy``.

Two kinds of figure, neither a guaranteed bound:

- **Energy norm.** η = (Σ_T η_T²)^{1/2} of the residual estimator of
  :mod:`contactfem.estimator` (Hild & Nicaise), one vectorised pass over the mesh. It is
  reliable only up to a constant that the theory does not give (‖u − u_h‖_a ≤ C η + h.o.t.),
  so it is an estimate, not a bound. Its ratio to the true error (the effectivity index)
  stays put under refinement, so η falls at the rate of the error; the ratio measured on
  cases/manufactured.yaml is in docs/performance.md#accuracy-studies. It is defined for method (4) only: with method (5) the
  multiplier θ_h may be negative and the estimator's complementarity term loses its sign.
- **The quantities users read** — total contact force, contact width (the length of ΓC in
  contact, as ``contact_zone`` measures it: from the first to the last active node of each
  interval) and peak pressure (the largest nodal multiplier) — from their differences to
  the same case solved on coarser meshes (Richardson): with q_h on the solve's mesh and
  q_rh on one r times coarser, e_h ≈ |q_h − q_rh| / (r^p − 1), p the quantity's order.
  Where a third, coarser level exists p is observed from the three (kept when it lies
  within :data:`PLAUSIBLE_ORDERS` of the method's expected order, :data:`EXPECTED_ORDERS`);
  otherwise the expected order is assumed. Each estimate says which.

No figure here is a guaranteed bound: the energy estimate is an upper bound only up to the
unknown constant C, and a Richardson estimate only once the levels are in the asymptotic
range (their differences falling as h^p). Each entry says ``"guaranteed": false``.

Cost. By default the estimates are free: the estimator is one pass over the mesh (a few
per cent of the solve), and the quantities compare with the coarse level that mesh
sequencing solved anyway (problems from :data:`contactfem.sequencing.SEQUENCING_THRESHOLD`
unknowns solved with method (4)); without one they are not estimated, and say so. On
request (``solver.accuracy.levels: solve``, ``--accuracy-levels solve``) coarser levels are
solved for the purpose: the case on a mesh with h doubled (a quarter of the unknowns; its
own sequencing level then serves as the third level for nothing), and a third level h
quadrupled when none came for free: at most :data:`MAX_EXTRA_SHARE` of the solve's
unknowns — ``cost`` in the report counts them. A run refined towards a target
(:mod:`contactfem.accuracy_target`) compares with its own earlier meshes, for nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from contactfem.case import Case
from contactfem.discretize import DiscreteProblem
from contactfem.errors import ContactFemError
from contactfem.result import ContactFields
from contactfem.timings import clock

if TYPE_CHECKING:
    from contactfem.solve import SolveResult

#: The order in h each quantity's error is expected to fall at with P1 elements, assumed
#: when no third level shows it: the contact force is a functional of the solution (the
#: energy error squared, h² for P1 on a solution in H^{5/2−ε}); the zone's ends and the
#: peak of the nodal pressure are located to within an element (h).
EXPECTED_ORDERS = {"contact_force": 2.0, "contact_width": 1.0, "peak_pressure": 1.0}
#: Observed orders outside [low, high] × the expected order are taken for noise (levels
#: outside the asymptotic range, a zone end that jumped by an element): the expected order
#: is used instead.
PLAUSIBLE_ORDERS = (0.5, 2.0)
#: The extra unknowns solved for the estimates may be at most this share of the solve's:
#: a level with h doubled (a quarter, a little more with the boundary nodes) and one with h
#: quadrupled (a sixteenth).
MAX_EXTRA_SHARE = 1 / 3
#: The nearest level may keep at most this share of the solve's unknowns (estimated before
#: it is meshed): a quarter, and the boundary's nodes.
NEAREST_SHARE = 0.28
#: The least mesh size ratio along ΓC between two levels a Richardson estimate compares: it
#: divides their difference by r^p − 1, which magnifies a zone end's jump by an element as r
#: nears 1, and a level coarsened only across ΓC (r = 1) says nothing of the error.
MIN_RATIO = 1.4
#: The coarsest level that serves as the nearest one (h times this), and as the furthest.
NEAREST_RATIO = 4.0
FURTHEST_RATIO = 8.0
#: The coarsest sequencing level a plain solve's estimates reuse: a polygon's is up to 16
#: times coarser (:func:`contactfem.sequencing.coarser`), less reliable than one 4 times
#: coarser but free; its ratio is reported.
REUSED_RATIO = 16.0
#: The method sequencing solves its levels with (:data:`contactfem.solve.SEQUENCING_METHOD`).
SEQUENCING_METHOD = "positive"
#: The energy estimate's label in the report.
ENERGY_METHOD = "residual estimator (Hild & Nicaise), reliable up to an unknown constant"


@dataclass(frozen=True)
class Level:
    """A coarser solution of the same case: its mesh size relative to the solve's, its
    unknowns, where it came from and the quantities read from it."""

    ratio: float
    unknowns: int
    source: str  # "sequencing" (reused), "solved"
    quantities: dict
    seconds: float = 0.0

    def record(self) -> dict:
        return {"h_ratio": self.ratio, "unknowns": self.unknowns, "source": self.source,
                "seconds": self.seconds, **{name: value for name, value in self.quantities.items()}}


def quantities(problem: DiscreteProblem, contact: ContactFields) -> dict:
    """The total contact force, the contact width along ΓC and the peak pressure of a solve."""
    from contactfem.discretize.contact import contact_patches

    # The intervals of report.json's contact_zone (contactfem.report.contact_zone).
    boundary = problem.contact
    first, last, _ = contact_patches(boundary.abscissa, contact.active, boundary.node_edges())
    width = float(sum(boundary.abscissa[b] - boundary.abscissa[a] for a, b in zip(first, last)))
    return {"contact_force": float(contact.nodal_force.sum()), "contact_width": width,
            "peak_pressure": float(contact.multiplier.max(initial=0.0))}


def energy_estimate(result: "SolveResult") -> dict:
    """report.json's ``accuracy.energy``: η of the residual estimator, and relative to the
    energy norm of the solution a(u_h, u_h)^{1/2}."""
    from contactfem.estimator import estimate

    if result.solution.method != "positive":
        return {"estimate": None, "method": ENERGY_METHOD, "guaranteed": False,
                "reason": f"the residual estimator is defined for method (4) positive, not {result.solution.method}"}
    started = clock()
    estimated = estimate(result.problem, result.solution)
    seconds = clock() - started
    norm = _energy_norm(result.problem, result.solution.displacement)
    summary = estimated.summary()
    return {"estimate": summary["eta"], "relative": summary["eta"] / norm if norm > 0 else None,
            "method": ENERGY_METHOD, "guaranteed": False, "terms": summary["terms"], "seconds": seconds}


def _energy_norm(problem: DiscreteProblem, displacement: np.ndarray) -> float:
    if problem.stiffness is None:
        return 0.0
    u = displacement.ravel()
    return float(np.sqrt(max(u @ (problem.stiffness @ u), 0.0)))


def richardson(values: list[float], ratios: list[float], expected: float) -> dict:
    """The error of ``values[0]`` (on the solve's mesh, ratio 1) from the values on meshes
    ``ratios`` times coarser: the estimate, the order used and how it was obtained."""
    q, r = values, ratios
    difference = abs(q[0] - q[1])
    observed = observed_order(q[:3], r[:3]) if len(q) >= 3 else None
    low, high = PLAUSIBLE_ORDERS
    if observed is not None and low * expected <= observed <= high * expected:
        order, how = observed, f"richardson, order observed from {len(q[:3])} levels"
    else:
        order, how = expected, "richardson, expected order assumed"
    return {"estimate": difference / (r[1] ** order - 1.0), "order": order, "observed_order": observed,
            "method": how, "guaranteed": False}


def observed_order(values: list[float], ratios: list[float]) -> float | None:
    """p such that (q_3 − q_2)/(q_2 − q_1) = (r_3^p − r_2^p)/(r_2^p − r_1^p), three levels of
    mesh sizes r_1 < r_2 < r_3 (the error C h^p); None when the differences change sign or
    vanish, or no p in (1/8, 8) fits."""
    (q1, q2, q3), (r1, r2, r3) = values, ratios
    d1, d2 = q2 - q1, q3 - q2
    if d1 == 0 or d2 == 0 or (d1 > 0) != (d2 > 0):
        return None
    target = d2 / d1

    def ratio(p: float) -> float:
        return (r3**p - r2**p) / (r2**p - r1**p)

    low, high = 0.125, 8.0
    if not ratio(low) <= target <= ratio(high):
        return None
    for _ in range(60):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if ratio(middle) < target else (low, middle)
    return 0.5 * (low + high)


def accuracy_figures(case: Case, result: "SolveResult", load_factor: float | None = None,
                     levels: str = "reuse", history: list[Level] | None = None) -> dict:
    """report.json's ``accuracy``: the energy estimate and the quantities' estimates, the
    coarser levels they came from and what those cost. ``load_factor``: the load path's
    factor of ``result`` (its coarser levels are solved at that factor). ``levels``: "reuse"
    (sequencing's level only, free), "solve" (coarser levels solved for the purpose, see
    :func:`coarser_levels`) or "none" (a mesh that is not the case's own, as ``adapt`` makes:
    the quantities get no estimate). ``history``: the coarser levels to compare with instead
    (the earlier meshes of a refinement towards a target, finest first)."""
    started = clock()
    fine = quantities(result.problem, result.solution.contact)
    figures: dict = {"energy": energy_estimate(result)}
    if history is not None:
        found, reason = list(history), "no earlier mesh to compare with"
    elif levels == "none":
        found, reason = [], "the mesh was adapted: no coarser mesh of the same kind to compare with"
    elif levels == "reuse":
        base_size = _contact_edge_size(result.problem)
        kept = _kept_level(result.coarse_levels, result.method, base_size, REUSED_RATIO)
        found = [] if kept is None or load_factor is not None else [kept]
        reason = _reuse_reason(result.coarse_levels, base_size)
    else:
        try:
            found = coarser_levels(case, result, load_factor)
            reason = None if found else "no coarser mesh of this case could be made and solved within the budget"
        except ContactFemError as error:
            found, reason = [], str(error)
    figures["quantities"] = quantity_estimates(fine, found, reason)
    extra = sum(level.unknowns for level in found if level.source == "solved")
    fine_unknowns = result.problem.n_unknowns
    solve_seconds = float(sum(result.timings.values()))  # meshing and assembly too, as the levels'

    figures["levels"] = [level.record() for level in found]
    seconds = clock() - started
    figures["cost"] = {"unknowns": extra, "share_of_unknowns": extra / fine_unknowns if fine_unknowns else 0.0,
                       "seconds": seconds,
                       "share_of_seconds": seconds / solve_seconds if solve_seconds > 0 else None}
    return figures


def quantity_estimates(fine: dict, levels: list[Level], reason: str | None) -> dict:
    """Each quantity's value on the solve's mesh and its Richardson estimate from ``levels``
    (finest first), or no estimate and ``reason`` without any."""
    estimates = {}
    for name, value in fine.items():
        entry: dict = {"value": value}
        if levels:
            entry.update(richardson([value, *(level.quantities[name] for level in levels)],
                                    [1.0, *(level.ratio for level in levels)], EXPECTED_ORDERS[name]))
            entry["relative"] = entry["estimate"] / abs(value) if value else None
        else:
            entry.update({"estimate": None, "method": None, "guaranteed": False, "reason": reason})
        entry["expected_order"] = EXPECTED_ORDERS[name]
        estimates[name] = entry
    return estimates


def _sequencing_threshold() -> int:
    from contactfem.sequencing import SEQUENCING_THRESHOLD

    return SEQUENCING_THRESHOLD


def coarser_levels(case: Case, result: "SolveResult", load_factor: float | None = None) -> list[Level]:
    """Up to two coarser solutions of ``case``, coarsest last: sequencing's own when it
    solved with the same method on a mesh at most :data:`NEAREST_RATIO` times coarser, else h
    doubled; then the next one down, free when the doubled level's own sequencing solved it
    at most :data:`FURTHEST_RATIO` times coarser, else solved when it is within
    :data:`MAX_EXTRA_SHARE`."""
    from contactfem.sequencing import coarser

    problem = result.problem
    base_size = _contact_edge_size(problem)
    kept = _kept_level(result.coarse_levels, result.method, base_size, NEAREST_RATIO)
    if kept is not None:
        levels = [kept]
        nearest = (result.coarse_levels["problem"].mesh_request, result.coarse_levels["problem"].refinements)
    else:
        nearest = _nearest_request(problem)
        if nearest is None:
            return []
        level, below = _solve_level(case, result, *nearest, base_size, load_factor,
                                    budget=MAX_EXTRA_SHARE * problem.n_unknowns)
        if level is None:
            return []
        if below is not None:
            return [level, below]
        levels = [level]
    spent = sum(level.unknowns for level in levels if level.source == "solved")
    further = coarser(*nearest, factor=2)
    if further is not None:
        budget = MAX_EXTRA_SHARE * problem.n_unknowns - spent
        level, _ = _solve_level(case, result, *further, base_size, load_factor, budget=budget)
        if level is not None and MIN_RATIO * levels[-1].ratio <= level.ratio <= FURTHEST_RATIO:
            levels.append(level)
    return levels


def _nearest_request(problem: DiscreteProblem):
    """The coarser mesh request of the nearest level: h doubled, or quadrupled where doubling
    keeps more than :data:`NEAREST_SHARE` of the unknowns (a mesh graded onto ΓC keeps about
    half of them); None when neither can be made within it."""
    from contactfem.sequencing import coarser
    from contactfem.coarse_levels import estimated_unknowns

    for factor in (2, 4):
        coarse = coarser(problem.mesh_request, problem.refinements, factor=factor)
        if coarse is not None and estimated_unknowns(problem, *coarse) <= NEAREST_SHARE * problem.n_unknowns:
            return coarse
    return None


def _reuse_reason(kept: dict, base_size: float) -> str:
    """Why a plain solve's quantities have no estimate from the level sequencing solved."""
    remedy = "solver.accuracy.levels: solve (--accuracy-levels solve) solves some for the purpose"
    if "problem" in kept and "solve" in kept and _ratio(kept["problem"], base_size) < MIN_RATIO:
        return (f"the coarser level sequencing solved has ΓC edges {_ratio(kept['problem'], base_size):.3g} times "
                f"the solve's (a Richardson estimate needs {MIN_RATIO:g} or more); {remedy}")
    return ("no coarser level was solved on the way (mesh sequencing runs from "
            f"{_sequencing_threshold():,} unknowns, with method positive); {remedy}")


def _kept_level(kept, method: str, base_size: float, largest: float) -> "Level | None":
    """The coarse level sequencing solved (``kept``: a solve's ``coarse_levels``) as a
    :class:`Level`, when it was solved with ``method`` on a mesh at most ``largest`` times
    coarser (a polygon's sequencing level may be 16 times coarser, outside the range where
    the differences follow h^p)."""
    if "solve" not in kept or "problem" not in kept or method != SEQUENCING_METHOD:
        return None
    ratio = _ratio(kept["problem"], base_size)
    if not MIN_RATIO <= ratio <= largest:
        return None
    return Level(ratio, kept["problem"].n_unknowns, "sequencing", quantities(kept["problem"], kept["solve"].contact))


def _solve_level(case: Case, result: "SolveResult", request, refine: int, base_size: float,
                 load_factor: float | None, budget: float | None = None) -> tuple[Level | None, Level | None]:
    """The case solved on the mesh ``request`` refined ``refine`` times with the solve's
    method (None when it has more unknowns than ``budget``, or fails), and the coarse
    level its own sequencing solved on the way (reused), if any."""
    from contactfem.solve import prepare, solve_case

    started = clock()
    try:
        coarse_problem = prepare(case, refine=refine, request=request)
    except ContactFemError:
        return None, None
    if budget is not None and coarse_problem.n_unknowns > budget:
        return None, None
    if coarse_problem.n_unknowns >= result.problem.n_unknowns or _ratio(coarse_problem, base_size) < MIN_RATIO:
        return None, None  # not coarser along ΓC, where the contact quantities see h
    if load_factor is not None:
        coarse_problem = coarse_problem.scaled(load_factor)
    kept: dict = {}
    try:
        solved = solve_case(case, method=result.method, problem=coarse_problem, accept_uncertified=True,
                            coarse_levels=kept)
    except ContactFemError:
        return None, None
    level = Level(_ratio(coarse_problem, base_size), coarse_problem.n_unknowns, "solved",
                  quantities(coarse_problem, solved.solution.contact), clock() - started)
    # Its own sequencing level was solved at the full load: of no use on a load path.
    below = None if load_factor is not None else _kept_level(kept, result.method, base_size, FURTHEST_RATIO)
    return level, below


def _contact_edge_size(problem: DiscreteProblem) -> float:
    """The median length of the problem's ΓC edges (the mesh size the contact quantities
    see); the mean element size where it has none."""
    edges = problem.contact.edges
    points = problem.mesh.points
    if len(edges):
        return float(np.median(np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)))
    return float(np.sqrt(problem.mesh.triangle_areas().mean()))


def _ratio(coarse: DiscreteProblem, base_size: float) -> float:
    """A coarser level's mesh size relative to the solve's, from their ΓC edges, taken as the
    nearest power of two when within 10% of it (a rectangle's divisions, a polygon's sizes
    and refinements change h by powers of two)."""
    ratio = _contact_edge_size(coarse) / base_size if base_size > 0 else 1.0
    nearest = 2.0 ** round(np.log2(ratio)) if ratio > 0 else 1.0
    return float(nearest if abs(ratio / nearest - 1) < 0.1 else ratio)
