"""Solve a case to a requested accuracy: refine where the estimator says until the estimated
error of one quantity is below a relative target, or a budget is spent.

The loop is :func:`contactfem.adaptive.adapt` (SOLVE → ESTIMATE → MARK (Dörfler) → REFINE by
newest-vertex bisection, method (4)); what this module adds is the stopping rule and the
estimate it reads after each solve:

- ``energy``: η / ‖u_h‖_a, η the residual estimator's (:mod:`contactfem.estimator`), reliable
  up to an unknown constant, larger than one on the cases measured (see
  docs/performance.md#accuracy-studies), so the true relative error is then well below
  the target).
- ``contact_width``, ``peak_pressure``, ``contact_force``: a Richardson estimate from the
  run's own earlier meshes (:func:`contactfem.accuracy.richardson`), their mesh size relative
  to the current one taken as r = (N / N_j)^{1/2}, N the unknowns (the ratio of h for uniform
  refinement, its mean for adaptive); the order observed from three steps when plausible,
  else the quantity's expected order. A target is met only when the last two estimates are
  both below it, since one difference may vanish by chance (a zone end that has not moved).

Neither is a guaranteed bound (see :mod:`contactfem.accuracy`). The decisions read only
counts and estimates, never the clock; the seconds are reported.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from contactfem.accuracy import EXPECTED_ORDERS, MIN_RATIO, Level, accuracy_figures, quantities, richardson
from contactfem.case import Case
from contactfem.errors import CaseError
from contactfem.timings import clock

if TYPE_CHECKING:
    from contactfem.solve import Progress, SolveResult

#: Dörfler's bulk parameter for a run towards a target: the marked triangles carry this share
#: of η². Larger than ``adapt``'s 0.5 so that the unknowns about double per step and
#: successive meshes differ enough for their differences to say something.
THETA = 0.7
#: Dörfler's parameter when the quantity is a contact one: its own triangles are marked
#: besides (:func:`quantity_marks`), and the estimator's share only keeps the rest of the
#: mesh from falling behind.
THETA_CONTACT = 0.3
#: Without a budget in unknowns, the run stops before a mesh whose solve the memory model
#: says would not fit (:func:`contactfem.estimate.largest_mesh_points`).
DEFAULT_STEPS = 30


@dataclass(frozen=True, eq=False)
class TargetRun:
    """A run towards a target: the last solve, its accuracy section, and one record a step."""

    result: "SolveResult"
    accuracy: dict
    steps: list[dict]
    target: float
    quantity: str
    reached: float | None
    met: bool
    stop_reason: str
    seconds: float

    def record(self) -> dict:
        """report.json's ``accuracy.target``."""
        return {"target": self.target, "quantity": self.quantity, "reached": self.reached, "met": self.met,
                "stop_reason": self.stop_reason, "unknowns": self.result.problem.n_unknowns,
                "seconds": self.seconds, "steps": self.steps, "guaranteed": False}


def solve_to_accuracy(case: Case, *, target: float, quantity: str = "energy", max_unknowns: int | None = None,
                      max_steps: int = DEFAULT_STEPS, refine: int | None = None, theta: float | None = None,
                      progress: "Progress | None" = None) -> TargetRun:
    """Refine ``case`` from its mesh (refined ``refine`` times) until the estimated relative
    error of ``quantity`` is at most ``target``, the next mesh would pass ``max_unknowns``
    (default: what memory holds) or ``max_steps`` solves are spent."""
    from contactfem.adaptive import adapt
    from contactfem.discretize import build_mesh

    if quantity not in ("energy", *EXPECTED_ORDERS):
        raise CaseError(f"{case.source.name}: solver.accuracy.quantity = {quantity}: expected one of energy, "
                        f"{', '.join(EXPECTED_ORDERS)}")
    say = progress or (lambda message: None)
    started = clock()
    history: list[Level] = []
    records: list[dict] = []

    def on_step(row: dict, problem, solution) -> None:
        values = quantities(problem, solution.contact)
        unknowns = problem.n_unknowns
        energy = float(np.sqrt(max(solution.displacement.ravel() @ (problem.stiffness @ solution.displacement.ravel()),
                                   0.0)))
        if quantity == "energy":
            estimate = row["eta"] / energy if energy > 0 else None
            order = None
        else:
            estimate, order = _richardson_estimate(values[quantity], unknowns, history, quantity)
            if quantity == "contact_width" and values[quantity] > 0:
                resolution = width_resolution(problem, solution.contact.active) / values[quantity]
                row["resolved"] = resolution <= target
                estimate = None if estimate is None else max(estimate, resolution)
        record = {"step": row["step"], "unknowns": unknowns, "value": values.get(quantity, row["eta"]),
                  "estimate": estimate, "order": order, "seconds": row["cumulative_seconds"]}
        records.append(record)
        history.insert(0, Level(ratio=1.0, unknowns=unknowns, source="earlier step", quantities=values))
        say(f"accuracy step {row['step']}: {unknowns:,} unknowns, {quantity} estimated "
            + ("n/a" if estimate is None else f"{100 * estimate:.3g}%") + f" (target {100 * target:.3g}%)")

    def converged(row: dict) -> bool:
        last = [r["estimate"] for r in records[-2:]]
        if quantity == "energy":
            return last[-1] is not None and last[-1] <= target
        return len(last) == 2 and all(e is not None and e <= target for e in last)

    def theta_of(row: dict) -> float:
        # The width's own marks first, until its ends are resolved to the target; then the
        # bulk, which the Richardson check needs (a mesh about twice as large).
        return THETA if row.get("resolved", True) else theta

    if theta is None:
        theta = THETA if quantity in ("energy", "contact_force") else THETA_CONTACT
    mesh = build_mesh(case, refine=refine)
    limit = max_unknowns if max_unknowns is not None else _memory_unknowns(case)
    run = adapt(case, theta=theta, max_unknowns=limit, max_steps=max_steps, mesh=mesh, on_step=on_step,
                converged=converged, also_mark=lambda problem, solution: quantity_marks(problem, solution, quantity),
                theta_of=theta_of, progress=None)
    result = run.result
    levels = _levels_below(history[1:], result.problem.n_unknowns)
    accuracy = accuracy_figures(case, result, history=levels)
    reached = records[-1]["estimate"] if records else None
    met = run.stop_reason == "target"
    return TargetRun(result=result, accuracy=accuracy, steps=records, target=target, quantity=quantity,
                     reached=reached, met=met, stop_reason=run.stop_reason, seconds=clock() - started)


def _zone_ends(problem, active: np.ndarray) -> list[tuple[int, int]]:
    """(last active, first inactive) ΓC node indices (in ``problem.contact``'s order) at each end of
    each contact interval that has a neighbour beyond it (none at a symmetry axis or ΓC's end)."""
    from contactfem.discretize.contact import contact_patches

    contact = problem.contact
    first, last, _ = contact_patches(contact.abscissa, active, contact.node_edges())
    ends = []
    for a, b in zip(first, last):
        if a > 0 and not active[a - 1]:
            ends.append((int(a), int(a) - 1))
        if b + 1 < len(active) and not active[b + 1]:
            ends.append((int(b), int(b) + 1))
    return ends


def width_resolution(problem, active: np.ndarray) -> float:
    """How finely the mesh resolves the contact width: the summed lengths (along the obstacle)
    of the ΓC edges from each zone end's last active node to its first inactive one. The end
    of the true zone lies in or about that edge, so the node-to-node width cannot be trusted
    below it whatever successive meshes say (they may agree because the end did not move)."""
    s = problem.contact.abscissa
    return float(sum(abs(s[beyond] - s[end]) for end, beyond in _zone_ends(problem, active)))


def quantity_marks(problem, solution, quantity: str) -> np.ndarray:
    """The triangles a quantity's own error sits in, marked beside Dörfler's (bool,
    (n_triangles,)): the contact width's, those at the zone's ends (the nodes on either side
    of each end); the peak pressure's, those around the peak node; none for the force and
    the energy (a functional of the solution, and the estimator's own norm)."""
    mesh = problem.mesh
    contact = problem.contact
    nodes: list[int] = []
    if quantity == "contact_width":
        nodes = [int(contact.nodes[i]) for pair in _zone_ends(problem, solution.contact.active) for i in pair]
    elif quantity == "peak_pressure" and len(contact.nodes):
        peak = int(np.argmax(solution.contact.multiplier))
        nodes = [int(contact.nodes[i]) for i in range(max(peak - 1, 0), min(peak + 2, len(contact.nodes)))]
    marked = np.zeros(mesh.n_triangles, dtype=bool)
    if nodes:
        marked |= np.isin(mesh.triangles, nodes).any(axis=1)
    return marked


def _richardson_estimate(value: float, unknowns: int, history: list[Level],
                         name: str) -> tuple[float | None, float | None]:
    """The relative Richardson estimate of ``value`` on ``unknowns`` from the earlier steps
    (``history``, latest first), and the order used; None before there is one."""
    levels = _levels_below(history, unknowns)
    if not levels or value == 0:
        return None, None
    entry = richardson([value, *(level.quantities[name] for level in levels)],
                       [1.0, *(level.ratio for level in levels)], EXPECTED_ORDERS[name])
    return entry["estimate"] / abs(value), entry["order"]


def _levels_below(history: list[Level], unknowns: int) -> list[Level]:
    """Up to two earlier steps, latest first, as levels of mesh size r = (N / N_j)^{1/2}
    relative to a mesh of N = ``unknowns``, each at least :data:`MIN_RATIO` coarser than the
    one before (a Richardson step divides by r^p − 1: from meshes 4% apart it multiplied
    a zone end's jump by 50)."""
    levels: list[Level] = []
    finer = unknowns
    for level in history:
        if level.unknowns * MIN_RATIO**2 <= finer:
            levels.append(Level(ratio=float(np.sqrt(unknowns / level.unknowns)), unknowns=level.unknowns,
                                source="earlier step", quantities=level.quantities))
            finer = level.unknowns
            if len(levels) == 2:
                break
    return levels


def _memory_unknowns(case: Case) -> int:
    """The most unknowns whose solve the memory model fits in what this process may use."""
    from contactfem.discretize.meshing import _backend
    from contactfem.estimate import guarded_bytes, largest_mesh_points, memory_limit

    return 2 * largest_mesh_points(_backend(case), guarded_bytes(memory_limit()))
