"""Load paths: one contact system solved at a sequence of load factors with one factorisation.

The stiffness and the constraints do not change along a path, so the factorisation and the
Schur columns carry over (:class:`contactfem.kernel.schur.ActiveSetSolver` with
``scalable=True``), and each step starts from the active set the steps before predict.
"""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from contactfem.errors import SolverError
from contactfem.kernel.newton import KernelResult, Status, solve_contact
from contactfem.kernel.proposers import Accelerators
from contactfem.kernel.schur import ActiveSetSolver
from contactfem.kernel.system import ContactSystem, default_c


#: Rounds of corrections :meth:`PathSolver.checked_start` makes to a step's start.
START_CHECKS = 3


class PathStarts:
    """Where each step of a load path starts (see :class:`PathSolver`): ``choose`` is given
    the step's factor and the set expected from the steps before (:meth:`PathSolver.extrapolated`,
    None at the first step) and returns the starting set (None: the expected one); ``settled``
    is told the set the step settled on. This one always takes the expected set."""

    def choose(self, factor: float, extrapolated: np.ndarray | None) -> np.ndarray | None:
        return None

    def settled(self, active: np.ndarray) -> None:
        return None

    def revisited(self, factor: float) -> None:
        """A step at a factor solved before starts from that step's set (choose is not asked)."""
        return None


class PathSolver:
    """``system`` solved at load factors in turn (any order, any spacing) with one
    :class:`ActiveSetSolver`.

    The stiffness and the constraints do not change along a path, so the factorisation and
    the Schur columns carry over, and a new load factor costs no solve (the reference
    solution is linear in it: see :meth:`ActiveSetSolver.set_load_factor`). Each step starts
    where ``starts`` says (:class:`PathStarts`), by default from the active set of the two
    steps before extrapolated in the factor (:func:`extrapolated_active`), or from the last
    step's set after one, or from ``initial_active`` (the kernel's cold start if None). A
    factor solved before (a path that unloads and loads again) starts from its own settled
    set, the answer, and takes one Newton step. Any other start is first corrected where
    its Schur system alone shows Newton's first update would change it
    (:meth:`checked_start`, with ``accelerators.start_checks``): a start one node off the
    zone's edge otherwise costs a whole Newton step, a backward solve of the factor."""

    def __init__(self, system: ContactSystem, *, backend: str = "auto", initial_active: np.ndarray | None = None,
                 starts: PathStarts | None = None, linear=None, **options) -> None:
        self.system, self.backend, self.options = system, backend, options
        accelerators = options.get("accelerators", Accelerators())
        # ``linear``: another solver with ActiveSetSolver's interface (the distributed one).
        self.linear = linear if linear is not None else ActiveSetSolver(
            system, backend, tolerance=options.get("tolerance", 1e-10), scalable=True,
            schur_updates=accelerators.schur_updates)
        self.c = options.get("c") or default_c(system)
        self.starts = starts or PathStarts()
        self.active = initial_active
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        #: (factor, contact force Λ, slack d − G) of the last two steps solved; before the
        #: first, the unloaded state when nothing starts inside the obstacle.
        self.history = [(0.0, np.zeros(len(self.gap)), -self.gap)] if (self.gap >= 0).all() else []
        self.steps = 0
        self.tolerance = options.get("tolerance", 1e-10)
        self.check_starts = accelerators.start_checks
        #: Starts corrected by :meth:`checked_start` (rounds that changed a start).
        self.start_checks = 0
        self.edges = None if system.contact_edges is None else np.asarray(system.contact_edges, dtype=np.int64)
        #: The settled set of every factor solved, packed to a bit a node (a path has at most
        #: 1 000 factors: 12 MB at 100 000 contact nodes).
        self.settled_sets: dict[float, np.ndarray] = {}

    def extrapolated(self, factor: float) -> np.ndarray | None:
        """The active set expected at ``factor`` from the steps solved (None before any)."""
        if self.steps == 0:
            return None
        if len(self.history) >= 2:
            return extrapolated_active(self.history[-2:], factor, self.c, apart=~self.active)
        return self.active

    def step(self, factor: float) -> KernelResult:
        """The contact solve at ``factor`` (its ``column_solves``: this step's solves with the factor)."""
        known = self.settled_sets.get(factor)
        if known is not None:
            start = np.unpackbits(known, count=len(self.gap)).astype(bool)
            self.starts.revisited(factor)
        else:
            expected = self.extrapolated(factor)
            chosen = self.starts.choose(factor, expected)
            start = chosen if chosen is not None else expected if expected is not None else self.active
        solves_before = self.linear.column_solves
        self.linear.set_load_factor(factor)
        if known is None:
            start = self.checked_start(start)
        result = solve_contact(self.system.scaled(factor), backend=self.backend, initial_active=start,
                               linear=self.linear, **self.options)
        result.column_solves = self.linear.column_solves - solves_before
        self.steps += 1
        if result.status is Status.CONVERGED:
            self.starts.settled(result.active)
            self.settled_sets[factor] = np.packbits(result.active)
            self.active = result.active
            state = (factor, result.nodal_force, self.linear.normals(result.displacement) - self.gap)
            # Two states at one factor extrapolate nowhere: a repeated factor replaces its state.
            kept = self.history[:-1] if self.history and self.history[-1][0] == factor else self.history
            self.history = [*kept[-1:], state]
        return result

    def checked_start(self, start: np.ndarray | None) -> np.ndarray | None:
        """``start`` corrected where its Schur system alone shows Newton's update would
        change it (:meth:`ActiveSetSolver.preview`): a node it adds with a negative
        reaction leaves, a node beside the set (along ΓC) or released by it with a
        positive slack joins, and so on for at most :data:`START_CHECKS` rounds."""
        preview = getattr(self.linear, "preview", None)
        if start is None or preview is None or not self.check_starts:
            return start
        start = np.asarray(start, dtype=bool)
        for _ in range(START_CHECKS):
            try:
                seen = preview(start, self._beside(start))
            except SolverError:
                return start
            if seen is None:
                return start
            reaction, slack = seen
            with np.errstate(invalid="ignore"):
                force = self.tolerance * np.nanmax(np.abs(reaction), initial=0.0)
                length = self.tolerance * max(np.nanmax(np.abs(slack), initial=0.0), np.abs(self.gap).max(initial=0.0))
                leave = start & (reaction < -force)
                join = ~start & (slack > length)
            if not (leave.any() or join.any()):
                return start
            start = (start & ~leave) | join
            self.start_checks += 1
        return start

    def _beside(self, active: np.ndarray) -> np.ndarray:
        """The contact nodes outside ``active`` next to one in it along ΓC."""
        edges = self.edges
        if edges is None or len(edges) == 0:
            return np.zeros(0, dtype=np.int64)
        first, second = active[edges[:, 0]], active[edges[:, 1]]
        return np.unique(np.concatenate([edges[first & ~second, 1], edges[second & ~first, 0]]))

    def walk(self, factors: Sequence[float]) -> Iterator[KernelResult]:
        """:meth:`step` at each of ``factors`` in turn, yielding each result as it is solved;
        stops after the first step that does not converge."""
        for factor in factors:
            result = self.step(factor)
            yield result
            if result.status is not Status.CONVERGED:
                return


def solve_path(
    system: ContactSystem,
    factors: Sequence[float],
    *,
    backend: str = "auto",
    initial_active: np.ndarray | None = None,
    starts: PathStarts | None = None,
    **options,
) -> Iterator[KernelResult]:
    """Solve ``system`` with its load and prescribed values multiplied by each of ``factors``
    in turn (a :class:`PathSolver`), yielding each step's result as it is solved (the
    caller keeps what it needs: a long path need not hold every step). ``options`` are
    those of :func:`solve_contact`. Stops after the first step that does not converge.
    """
    return PathSolver(system, backend=backend, initial_active=initial_active, starts=starts, **options).walk(factors)


#: The power of the distance from a smooth contact's edge with which the gap opens beyond it
#: (δ^{3/2}: Hertz, and any elastic contact whose pressure falls like √δ inside its edge).
EDGE_GAP_POWER = 1.5


def extrapolated_active(states: list[tuple[float, np.ndarray, np.ndarray]], factor: float, c: float,
                        apart: np.ndarray | None = None) -> np.ndarray:
    """The active set predicted at load ``factor`` from the last two solved ``states``
    (factor, contact force Λ, slack d − G); ``apart``: the nodes not in the last state's
    active set (by default those with a negative slack there).

    A node in contact at the last step stays predicted active where the indicator
    Λ + c (d − G), both extrapolated linearly in the factor, is positive. A node apart from
    the obstacle joins where its gap closes, and beyond the edge of a growing zone the gap
    opens like δ^{3/2} (:data:`EDGE_GAP_POWER`, δ the distance from the edge, which moves
    steadily with the load): it is (G − d)^{2/3} that closes linearly, not the gap, whose
    linear extrapolation reaches zero too early and predicted the nodes up to 0.7 of a
    step's advance beyond the edge active (a Hertz platen at 247 000 unknowns, equal steps
    of the zone's width: 84 nodes predicted wrong over 18 steps against 4). Both are closer
    than the last set, which Newton's method would otherwise first overshoot (every node
    penetrating at once) and then release a few at a time."""
    (f0, force0, slack0), (f1, force1, slack1) = states
    ratio = (factor - f1) / (f1 - f0) if f1 != f0 else 0.0
    force = force1 + ratio * (force1 - force0)
    slack = slack1 + ratio * (slack1 - slack0)
    active = force + c * slack > 0
    opening0 = np.maximum(-slack0, 0.0) ** (1.0 / EDGE_GAP_POWER)
    opening1 = np.maximum(-slack1, 0.0) ** (1.0 / EDGE_GAP_POWER)
    closed = opening1 + ratio * (opening1 - opening0) <= 0.0
    apart = slack1 < 0.0 if apart is None else np.asarray(apart, dtype=bool) & (slack1 < 0.0)
    return np.where(apart, active & closed, active)
