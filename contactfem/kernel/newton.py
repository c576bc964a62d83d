"""Semismooth Newton (primal–dual active set) iteration for nodal unilateral contact.

The problem (:class:`contactfem.kernel.system.ContactSystem`), in coordinates where each
contact node's normal displacement d_x is one unknown, is

    K u + P Λ = F,    Λ ≥ 0,    d − G ≤ 0,    Λ_x (d − G)_x = 0  at every contact node,

with Λ = B μ the nodal contact forces of the method's multiplier μ (B the lumped mass D
for the positive method (4), the consistent mass M for the standard method (5)). Writing
complementarity as C(Λ, d) = Λ − max(0, Λ + c (d − G)) = 0, the function is piecewise
smooth and Newton's method on it, with the generalised (slant) derivative, is the
primal–dual active set method (Hintermüller, Ito & Kunisch, SIAM J. Optim. 13, 2002):

1. A = {x : Λ_x + c (d − G)_x > 0}, I = the other contact nodes;
2. solve K u + P Λ = F with d = G on A and Λ = 0 on I: one SPD solve of the size of
   the linear problem, A's normal unknowns fixed (:mod:`contactfem.kernel.schur`);
3. stop when A repeats, after the certificate (:mod:`contactfem.kernel.certificate`).

After a solve d = G exactly on A and Λ = 0 exactly on I, so the indicator reduces to Λ
on A and to c (d − G) on I: its sign is decided against the force scale on A and the
displacement scale on I, and c never enters (multiplying E, the loads or c by any factor
changes nothing). The iteration converges locally superlinearly and, for the M-matrix
structure of frictionless contact on a flat obstacle, typically in a few steps from a
good start (Hüeber & Wohlmuth, CMAME 194, 2005).

Plain Newton can revisit a set on hard problems. The loop detects the repeat and first
holds the nodes that flip back and forth, then falls back on Murty's least-index rule
(change only the lowest-numbered node whose condition fails), which terminates for
P-matrix linear complementarity problems such as this one (Murty, Math. Programming 6,
1974): S = P K⁻¹ Pᵀ is SPD.

Accelerators propose a better next set than Newton's update through one protocol
(:mod:`contactfem.kernel.proposers`); they change the number of steps, never the answer.
Before reporting CONVERGED the final iterate is certified against the discrete problem's
own conditions; a result that fails is returned with status NOT_CERTIFIED and the failed
condition named. A singular stiffness raises :class:`contactfem.errors.SolverError`.
No decision depends on the clock: the seconds recorded per step are for reports only.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.errors import SolverError
from contactfem.kernel.certificate import Certificate, roundoff_bound
from contactfem.kernel.cycles import CycleGuard
from contactfem.kernel.modes import ModeHolder
from contactfem.kernel.proposers import Accelerators, Proposer, Step, default_proposers
from contactfem.kernel.schur import ActiveSetSolver
from contactfem.kernel.starts import translation_start
from contactfem.kernel.system import ContactSystem, default_c
from contactfem.timings import clock

#: The fewest Newton steps a solve is allowed by default (see :func:`default_max_iterations`).
MIN_ITERATIONS = 50
#: Steps at the cap that a creeping zone is recognised from (see :func:`_creeping`).
CREEP_WINDOW = 5


class Status(enum.Enum):
    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    CYCLING = "cycling"
    #: The active set settled but the iterate fails its certificate (see :class:`Certificate`).
    NOT_CERTIFIED = "not_certified"


@dataclass
class Iteration:
    """One Newton step. The residuals are scale-free: ``equilibrium_residual`` is
    ‖K u + Nᵀ Λ − F‖∞ over the force scale, ``complementarity_residual`` the natural
    residual max |min(Λ / force scale, (G − d) / displacement scale)| (see :class:`Certificate`).
    ``proposed``: the nodes by which the next set differs from Newton's update, taken from
    the proposer named ``proposer`` (see :mod:`contactfem.kernel.proposers`)."""

    active: int
    added: int
    removed: int
    equilibrium_residual: float
    complementarity_residual: float
    seconds: float
    proposed: int = 0
    proposer: str = ""

    def summary(self) -> str:
        """One line of progress: the set, its changes and the residuals."""
        moved = f", {self.proposed} from the {self.proposer}" if self.proposed else ""
        return (f"{self.active} active (+{self.added} -{self.removed}{moved}), residuals "
                f"{self.equilibrium_residual:.1e} / {self.complementarity_residual:.1e}, {self.seconds:.2f} s")


@dataclass(eq=False)
class KernelResult:
    """What the kernel returns; it never raises on non-convergence or a failed certificate,
    the caller decides.

    ``displacement`` (n,), ``multiplier`` μ (m,), ``nodal_force`` Bμ (m,), ``active`` (m,) bool;
    ``certificate`` the final iterate's :class:`Certificate` (whatever the status; status
    CONVERGED implies it passed).
    """

    status: Status
    message: str
    displacement: np.ndarray
    multiplier: np.ndarray
    nodal_force: np.ndarray
    active: np.ndarray
    c: float
    history: list[Iteration] = field(default_factory=list)
    cycle_detected_at: int | None = None
    factorizations: int = 0
    column_solves: int = 0
    certificate: Certificate | None = None

    @property
    def iterations(self) -> int:
        return len(self.history)


def default_max_iterations(contact_nodes: int) -> int:
    """Newton steps allowed by default: :data:`MIN_ITERATIONS`, or one per contact node if
    there are more. A body in bending lifting off the obstacle releases one node per patch
    edge per step, each release putting the next node in tension: a monotone creep ends
    within that many steps; a set that repeats is caught by the cycle safeguard whatever
    the cap."""
    return max(MIN_ITERATIONS, int(contact_nodes))


@dataclass(eq=False)
class _Iterate:
    """A solved set's displacement and contact quantities."""

    displacement: np.ndarray
    reaction: np.ndarray  # (m,): at the active normals, zero elsewhere
    multiplier: np.ndarray
    nodal_force: np.ndarray
    slack: np.ndarray
    scales: object


def solve_contact(
    system: ContactSystem,
    *,
    c: float | None = None,
    tolerance: float = 1e-10,
    max_iterations: int | None = None,
    backend: str = "auto",
    initial_active: np.ndarray | None = None,
    on_iteration: Callable[[Iteration], None] | None = None,
    safeguard: bool = True,
    linear: ActiveSetSolver | None = None,
    accelerators: Accelerators = Accelerators(),
    second_guess: Callable[[], np.ndarray | None] | None = None,
    stalled_guess: Callable[[], np.ndarray | None] | None = None,
    proposers: Sequence[Proposer] | None = None,
) -> KernelResult:
    """Run the primal–dual active set iteration until the active set repeats, then certify.

    Parameters
    ----------
    system : ContactSystem
    c : float, optional
        Weight of the gap in the indicator Λ + c (d − G); default :func:`default_c`.
    tolerance : float
        Relative bound of every condition of the certificate (raised to the round-off
        bound of the equations where that is larger), and the band within which a nodal
        force or a gap counts as zero when the active set is updated.
    max_iterations : int, optional
        Newton steps allowed; default :func:`default_max_iterations` of the contact nodes.
    backend : str
        Sparse direct solver backend (see :mod:`contactfem.linalg`).
    initial_active : (m,) bool, optional
        Starting active set; default: the nodes that start inside the obstacle (G < 0),
        the indicator at u = 0, Λ = 0 for any c.
    on_iteration : callable, optional
        Called with each :class:`Iteration` record (progress reporting).
    safeguard : bool
        Go on with the cycle safeguard when a set repeats; False stops with CYCLING.
    linear : ActiveSetSolver, optional
        The linear solver of an earlier solve of the same stiffness and constraints (its
        factorisation and cached columns are reused), or any object with its interface
        (the distributed solver of :mod:`contactfem.distributed`). The result counts only
        this solve's factorisations.
    accelerators : Accelerators
        Which accelerators to use (all by default); see :mod:`contactfem.kernel.proposers`.
    second_guess, stalled_guess : callable, optional
        A coarser level's prediction, asked when the first step does not settle and when
        the iteration stalls (:class:`contactfem.kernel.proposers.CoarserLevel`).
    proposers : sequence of Proposer, optional
        The proposers to ask instead of the default ones.

    Raises
    ------
    SolverError
        If the stiffness (with its supports and an active set fixed) is singular or
        numerically singular: there is no answer to certify.
    """
    gap = np.asarray(system.gap, dtype=float)
    mass = sp.csc_matrix(system.multiplier_mass)
    m = len(gap)
    c = default_c(system) if c is None else float(c)
    holder = ModeHolder(system) if system.free_modes is not None and m else None
    mass_solve = _mass_solver(mass)
    if linear is None:
        linear = ActiveSetSolver(system, backend, tolerance=tolerance, schur_updates=accelerators.schur_updates)
    factorizations_before, column_solves_before = linear.factorizations, linear.column_solves
    active, skipped = _starting_set(system, linear, tolerance, initial_active, holder)
    if proposers is None:
        proposers = default_proposers(system.contact_edges, m, accelerators, second_guess, stalled_guess)
    max_iterations = default_max_iterations(m) if max_iterations is None else max_iterations
    iterate = _Iterate(np.zeros(len(linear.load)), np.zeros(m), np.zeros(m), np.zeros(m), -gap, None)
    guard, history = CycleGuard(m, safeguard), []
    newton, proposer = active, None  # the set solved, and who proposed it instead of Newton's update
    status, message, certificate = Status.MAX_ITERATIONS, f"no convergence in {max_iterations} iterations", None

    for iteration in range(1, max_iterations + 1):
        started = clock()
        active, solved = _solve_set(linear, active, newton, proposer, iteration, gap, holder)
        guard.solved(active, iteration)
        iterate = _measure(linear, active, solved, mass, mass_solve, gap)
        newton = _newton_update(active, iterate, tolerance, holder, c)
        finite = linear.non_finite(iterate.displacement) == 0 and bool(np.isfinite(iterate.nodal_force).all())
        seconds = clock() - started
        settled = np.array_equal(newton, active)
        proposal, proposer = newton, None
        if finite and not settled and guard.detected_at is None:
            step = Step(iteration, iteration + skipped, active, newton, iterate.reaction, iterate.slack)
            proposal, proposer = _proposal(proposers, step, guard, holder, c)
        history.append(_record(active, proposal, newton, proposer, iterate, seconds))
        if on_iteration is not None:
            on_iteration(history[-1])
        if not finite or settled:
            certificate = linear.certify(iterate.displacement, iterate.multiplier, iterate.nodal_force,
                                         iterate.scales, tolerance)
            status, message = _verdict(certificate, finite, iteration, active, guard, linear)
            break
        following, cycling = guard.next_set(active, proposal, iteration)
        if following is None:
            status, message = Status.CYCLING, cycling
            break
        if holder is not None:
            following = holder.hold(following, _indicator(active, iterate, c))
        guard.moved(active, following)
        active = following

    if status is Status.MAX_ITERATIONS:
        message += guard.hint() or _creeping(history)
    if certificate is None and history:
        # Stopped before the set settled: the last iterate's figures still tell the caller
        # how far it is from an answer.
        certificate = linear.certify(iterate.displacement, iterate.multiplier, iterate.nodal_force,
                                     iterate.scales, tolerance)
    return KernelResult(
        status=status, message=message, displacement=iterate.displacement, multiplier=iterate.multiplier,
        nodal_force=iterate.nodal_force, active=active, c=c, history=history,
        cycle_detected_at=guard.detected_at,
        factorizations=linear.factorizations - factorizations_before,
        column_solves=linear.column_solves - column_solves_before,
        certificate=certificate,
    )


def _starting_set(system: ContactSystem, linear, tolerance: float, initial_active: np.ndarray | None,
                  holder: ModeHolder | None) -> tuple[np.ndarray, int]:
    """The first set to solve, and whether a step was known without a solve (0 or 1).

    The textbook start u = 0, Λ = 0 gives the indicator c (0 − G): the nodes starting
    inside the obstacle. A cold start with none of them solves the supports alone first;
    when that solution is a translation known in advance (a body pushed by a prescribed
    displacement, nothing loading it), Newton's update from it is known too, and the
    iteration starts there.
    """
    gap = np.asarray(system.gap, dtype=float)
    if initial_active is not None:
        active = np.asarray(initial_active, dtype=bool).copy()
    else:
        active = gap < 0.0
    if holder is not None:
        return holder.hold(active, holder.first_touch()), 0
    if initial_active is None and len(gap) and not active.any():
        translated = translation_start(system, linear, tolerance)
        if translated is not None:
            return translated, 1
    return active, 0


def _solve_set(linear, active: np.ndarray, newton: np.ndarray, proposer: Proposer | None, iteration: int,
               gap: np.ndarray, holder: ModeHolder | None) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The set actually solved and its (u, reactions at its normals).

    A proposed set that leaves the body free in double precision (an extrapolation that
    released most of a slender strip) gives way to Newton's update, and its proposer
    proposes no more. A first set that leaves free a body that contact holds (a strip
    1 x 1e-6 clamped at one end, resting on the plane: a cantilever of slenderness 1e6)
    gives way to every touching node, from which Newton releases the rest; a body that no
    set of touching nodes holds stays a SolverError.
    """
    try:
        return active, linear.solve(active)
    except SolverError:
        if proposer is not None:
            proposer.unsolvable()
            return newton, linear.solve(newton)
        touching = active | (gap <= 0.0)
        if iteration > 1 or np.array_equal(touching, active):
            raise
        if holder is not None:
            touching = holder.hold(touching, holder.first_touch())
        return touching, linear.solve(touching)


def _measure(linear, active: np.ndarray, solved: tuple[np.ndarray, np.ndarray], mass: sp.csc_matrix,
             mass_solve: Callable[[np.ndarray], np.ndarray], gap: np.ndarray) -> _Iterate:
    """The iterate of a solved set: its multiplier from the reactions (B μ = Λ), the
    method's own nodal forces B μ, the slack and the scales."""
    displacement, reaction = solved
    m = len(gap)
    reaction_at_contact = np.zeros(m)
    reaction_at_contact[active] = reaction
    multiplier = mass_solve(reaction_at_contact) if m else np.zeros(0)
    nodal_force = mass @ multiplier if m else np.zeros(0)
    slack = linear.normals(displacement) - gap
    return _Iterate(displacement, reaction_at_contact, multiplier, nodal_force, slack,
                    linear.measure(displacement, nodal_force))


def _newton_update(active: np.ndarray, iterate: _Iterate, tolerance: float, holder: ModeHolder | None,
                   c: float) -> np.ndarray:
    """Newton's update of the active set, decided per node in the data's scales: on A (slack
    exactly 0) by the sign of the reaction, on I (reaction exactly 0) by the sign of the
    slack. Values within the certificate's tolerance of zero keep their node's state, so
    that round-off cannot make the set flicker and whatever the kernel treats as zero the
    certificate accepts."""
    scales = iterate.scales
    force_band = max(tolerance, scales.roundoff) * scales.force
    gap_band = max(tolerance, roundoff_bound(2)) * scales.displacement  # d − G: one subtraction
    update = np.where(active, iterate.reaction >= -force_band, iterate.slack > gap_band)
    if holder is not None:
        update = holder.hold(update, _indicator(active, iterate, c))
    return update


def _indicator(active: np.ndarray, iterate: _Iterate, c: float) -> np.ndarray:
    """Λ + c (d − G) after a solve: the reaction on A, c times the slack on I."""
    return np.where(active, iterate.reaction, c * iterate.slack)


def _proposal(proposers: Sequence[Proposer], step: Step, guard: CycleGuard, holder: ModeHolder | None,
              c: float) -> tuple[np.ndarray, Proposer | None]:
    """The next set: the first proposal that differs from Newton's update and from every set
    solved, or Newton's update; every other proposer is told it was overruled."""
    chosen, by = step.newton, None
    for proposer in proposers:
        offered = proposer.propose(step)
        if offered is None:
            continue
        if holder is not None:
            indicator = np.where(step.active, step.reaction, c * step.slack)
            offered = holder.hold(offered, indicator)
        if not np.array_equal(offered, step.newton) and not guard.was_solved(offered):
            chosen, by = offered, proposer
            break
        proposer.overruled()
    for proposer in proposers:
        if by is not None and proposer is not by:
            proposer.overruled()
    return chosen, by


def _record(active: np.ndarray, following: np.ndarray, newton: np.ndarray, proposer: Proposer | None,
            iterate: _Iterate, seconds: float) -> Iteration:
    scales = iterate.scales
    with np.errstate(invalid="ignore", over="ignore"):
        complementarity = np.abs(
            np.minimum(iterate.nodal_force / scales.force, -iterate.slack / scales.displacement)).max(initial=0.0)
    return Iteration(
        active=int(active.sum()),
        added=int((following & ~active).sum()),
        removed=int((active & ~following).sum()),
        equilibrium_residual=float(scales.equilibrium),
        complementarity_residual=float(complementarity),
        seconds=seconds,
        proposed=int(np.count_nonzero(following != newton)),
        proposer=proposer.name if proposer is not None else "",
    )


def _verdict(certificate: Certificate, finite: bool, iteration: int, active: np.ndarray, guard: CycleGuard,
             linear) -> tuple[Status, str]:
    """The status and message of a solve whose set settled (or whose iterate is not finite)."""
    if not finite:
        return Status.NOT_CERTIFIED, f"iteration {iteration} is not certified: {certificate.message}"
    if certificate.passed:
        return Status.CONVERGED, (f"converged in {iteration} iterations, {int(active.sum())} active nodes"
                                  + guard.resolution())
    message = (f"active set settled after {iteration} iterations ({int(active.sum())} active nodes) "
               f"but the result is not certified: {certificate.message}")
    if certificate.failed[0] == "force_resolution" and not active.any() and not np.any(linear.load):
        # An unloaded rigid motion too large for the body's own force unit to resolve its
        # round-off (see ActiveSetSolver.measure: a translation by 1e45).
        message += ("; nothing loads the body and nothing touches the obstacle: it moves rigidly, "
                    "free of stress, and its forces are round-off alone")
    elif certificate.failed[0] == "force_resolution":
        # |K| |u| / S_F: the forces the displacement would make were it all strain.
        ratio = certificate.scales["roundoff"] / linear.gamma
        message += (f"; the displacement (up to {certificate.scales['displacement']:.3g}) would make "
                    f"forces {ratio:.1e} times the body's were it all strain: it is mostly a rigid "
                    "motion (a gap crossed by a body that contact alone holds, a prescribed "
                    "translation) whose strains double precision cannot resolve; close the gap in "
                    "the geometry or load the body more")
    return Status.NOT_CERTIFIED, message


def _creeping(history: Sequence[Iteration]) -> str:
    """What the last steps of a solve stopped at its cap were doing, when the zone was
    still moving by a few nodes per step: a hint for the message."""
    last = history[-CREEP_WINDOW:]
    if len(last) < CREEP_WINDOW or not all(0 < step.added + step.removed for step in last):
        return ""
    changed = max(step.added + step.removed for step in last)
    if changed > max(8, last[-1].active // 10):
        return ""
    return (f"; the contact zone was still creeping, {changed} or fewer nodes changing per step over the last "
            f"{CREEP_WINDOW}, as a body peeling off the obstacle in bending does: raise solver.max_iterations")


def _mass_solver(mass: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """Solve B μ = Λ: a division for a diagonal B, a sparse LU otherwise (B is small)."""
    diagonal = mass.diagonal()
    if mass.shape[0] == 0 or mass.count_nonzero() == np.count_nonzero(diagonal):
        return lambda rhs: rhs / diagonal
    return spla.splu(mass).solve
