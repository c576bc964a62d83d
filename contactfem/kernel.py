"""Semismooth Newton (primal–dual active set) kernel for a linear elastic system with nodal unilateral constraints.

The kernel sees arrays only. The discrete problem, in coordinates where each contact
node's normal displacement is one unknown (``normal_dofs``), is

    K u + P B μ = F,     B μ ≥ 0,   d − G ≤ 0,   (B μ)ᵀ (d − G) = 0   (row by row)

with d = u[normal_dofs], P the injection of the contact rows into the unknowns, and B
the multiplier mass of the method: the lumped D for the positive method, the consistent
M for the standard one. Newton's method on C(Bμ, d) = Bμ − max(0, Bμ + c (d − G)) is the
active set iteration: on A, d = G (a Dirichlet condition on one unknown); on I, (Bμ) = 0,
so each step is one SPD solve of the size of the linear problem, after which Bμ on A is
the reaction of the fixed normal unknowns and μ = B⁻¹(Bμ).

Plain Newton can revisit an active set on hard problems. The kernel detects the repeat
and continues with Murty's least-index rule (change only the lowest-numbered node whose
condition fails), which terminates for P-matrix complementarity problems like this one.

Every decision is relative to the data's own scales, so that multiplying E and the loads
by any factor, or c by any factor, changes nothing: after a solve, d = G exactly on A and
Bμ = 0 exactly on I, so the indicator Bμ + c (d − G) reduces to Bμ on A and to c (d − G)
on I and its sign is decided against the force scale on A and against the displacement
scale on I; c never enters (it only matters to a caller predicting the first active set).

Before reporting CONVERGED the kernel certifies the final iterate against the discrete
problem's own conditions (:class:`Certificate`): equilibrium, the signs, complementarity
and finiteness, each against a tolerance stated in the system's units. A result that
fails is returned with status NOT_CERTIFIED and the failed condition named; a singular
or numerically singular stiffness is reported by :mod:`contactfem.linalg` (SolverError).
"""

from __future__ import annotations

import dataclasses
import enum
import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.errors import SolverError
from contactfem.linalg import (
    FactorCheck,
    Factorizer,
    check_factorization,
    probe_vector,
    solve_sparse_columns,
)

EPS = float(np.finfo(float).eps)
#: Iterative refinement of each linear solve: at most this many corrections, stopping once
#: the residual of the equations is within their round-off bound (:func:`roundoff_bound`)
#: or stops decreasing.
REFINEMENT_STEPS = 3
#: A certificate is only issued when the equilibrium equations resolve the forces to at
#: least three significant digits: when the round-off bound of evaluating K u + Nᵀ Λ − F
#: (γ_k times the sum of the magnitudes of its terms) exceeds this fraction of the force
#: scale, the forces in play are lost in the cancellation of much larger terms (a huge
#: rigid motion prescribed with nothing to resist it, a body far too slender for double
#: precision), and a residual "within round-off" says nothing about the answer. Measured
#: bounds: ≤ 2e-12 on the shipped cases and the square up to 131 000 unknowns, 2e-5 on
#: a 1:1000 strip of 1000 × 4 cells; the square translated by a prescribed 1e45 gives 1.8.
FORCE_RESOLUTION_LIMIT = 1e-3
#: The strain whose force over the body (its largest stiffness entry times its size) is the
#: force scale of an unloaded iterate whose forces are all round-off (see
#: ActiveSetSolver.measure): forces below 1e-3 of it, a strain of 1e-10, count as zero.
ZERO_FORCE_STRAIN = 1e-7
#: Rate assumed for the dense Schur complement's LU (flop/s), in the cost model that
#: chooses between Schur updates and a refactorisation; measured 5–15e9 on 2 cores.
DENSE_FLOPS = 5e9
#: The most bytes the cached Schur columns (one full-length vector each) may hold: beyond
#: it the kernel refactorises, whatever the cost model says (at 2.1M unknowns: 32 columns).
#: Sparse forward columns are not capped; their dense blocks in a Schur product are.
COLUMN_BYTES = 2**29
#: Unknowns from which Schur columns come from forward solves when the backend has them:
#: below, a full solve takes milliseconds and the forward route's fixed cost per update
#: (its Schur product, one more full solve) outweighs it (a wavy strip of 5 120 unknowns
#: took 0.135 s that way against 0.059 s with full columns).
FORWARD_COLUMNS_FROM = 100_000
#: The same from a simplicial factor (CHOLMOD's choice on meshes with little fill, such as
#: one graded onto a rough profile), whose pattern solves need no conversion, as long as
#: its elimination tree's paths are short (see :data:`FORWARD_PATH_SHARE`): on the graded
#: profile at 27 000-52 000 unknowns the contact solve took 0.82x the time this way (one
#: fine factorisation instead of two or three), at 7 000-13 000 0.89x. The shipped smooth
#: cases of 16 000-68 000 unknowns, whose factors are supernodal, stay with full columns
#: (a plate with a hole at 42 000 took 1.07x the time with forward ones: two changed
#: nodes, one more full solve).
SIMPLICIAL_FORWARD_COLUMNS_FROM = 5_000
#: The largest share of the unknowns a forward column may touch, on average over the first
#: columns a step takes (or a sample of :data:`PATH_SAMPLES` contact normals, when a cost
#: decision needs them first), for a simplicial factor below :data:`FORWARD_COLUMNS_FROM`
#: unknowns to go on with forward columns: the column of e_j is the
#: elimination tree's path from j, 3% of the unknowns on a rough profile's graded mesh of
#: 7 000, 0.7% at 52 000, but 42% on a wavy strip of 5 120 (a long thin mesh, its tree
#: nearly a chain), where forward columns and their Schur blocks took twice the time of
#: full ones.
FORWARD_PATH_SHARE = 0.1
#: Up to this many dense entries and products (new columns times the unknowns and the
#: stored columns' entries) the Schur blocks of new forward columns are taken with those
#: columns made dense: below it the sparse route's passes over every unknown cost more
#: (2 columns against 250 at 105 000 unknowns: 0.85 ms against 1.2; 18: 2.7 against 1.4).
DENSE_CROSS_ENTRIES = 2**19
PATH_SAMPLES = 8


def roundoff_bound(terms: int) -> float:
    """γ_k = k ε / (1 − k ε): the relative error bound of a sum of k floating-point products.

    Evaluating one row of K u + Nᵀ Λ − F in floating point errs by at most γ_k times the
    sum of the magnitudes of its terms (Higham, Accuracy and Stability of Numerical
    Algorithms, §3.1), k the row's stored entries plus the load and the contact force; no
    solver, however accurate, can certify a residual below it.
    """
    return terms * EPS / (1.0 - terms * EPS)


class Status(enum.Enum):
    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    CYCLING = "cycling"
    #: The active set settled but the iterate fails its certificate (see :class:`Certificate`).
    NOT_CERTIFIED = "not_certified"


@dataclass(frozen=True, eq=False)
class ContactSystem:
    """The algebraic contact problem handed to the kernel.

    Attributes
    ----------
    stiffness : (n, n) sparse SPD
        Stiffness with contact nodes in normal/tangent coordinates; supports are given by
        ``fixed_dofs`` (or already eliminated).
    load : (n,)
    normal_dofs : (m,) int
        Index of the normal unknown of each contact node.
    gap : (m,)
        Initial gap G of each contact node (negative: the body starts inside the obstacle).
    multiplier_mass : (m, m) sparse SPD
        B: how the method's multiplier μ becomes nodal forces Bμ.
    fixed_dofs : (k,) int, optional
        Unknowns prescribed by supports, kept in the system (no slicing of K).
    fixed_values : (k,), optional
        Their values.
    free_modes : (n, j), optional
        Rigid motions the supports leave free and only contact holds (K r = 0); None when
        the supports hold the body. Every active set the kernel solves then holds them.
    length_scale : float, optional
        The body's size, in the case's length unit: with the stiffness it gives the force
        scale of an iterate that carries no force at all (no load, no contact force), whose
        computed forces are round-off of an exact zero (see :meth:`ActiveSetSolver.measure`).
        None: no such scale, and such an iterate is not certified.
    contact_edges : (e, 2) int, optional
        The ΓC edges as pairs of contact nodes (indices into ``normal_dofs``): the order
        along ΓC in which a creeping zone edge is recognised (:class:`ZoneFronts`). None:
        Newton's update alone.
    translation : (n,), optional
        A rigid translation of the body in these unknowns that the prescribed values are
        components of, given when nothing loads the body (a block pushed by its top): it is
        then the supports' own solution, which a cold start with no node inside the
        obstacle would factorise and solve for first (:func:`solve_contact` checks it and
        starts from its update instead). None: not known.
    """

    stiffness: sp.spmatrix
    load: np.ndarray
    normal_dofs: np.ndarray
    gap: np.ndarray
    multiplier_mass: sp.spmatrix
    fixed_dofs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    fixed_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    free_modes: np.ndarray | None = None
    length_scale: float | None = None
    contact_edges: np.ndarray | None = None
    translation: np.ndarray | None = None

    def scaled(self, factor: float) -> "ContactSystem":
        """The system with its load and prescribed values multiplied by ``factor`` (a step
        of a load path; the obstacle stays)."""
        return dataclasses.replace(self, load=factor * np.asarray(self.load, dtype=float),
                                   fixed_values=factor * np.asarray(self.fixed_values, dtype=float),
                                   translation=None if self.translation is None else factor * self.translation)

    def coupled_outside(self, keep: np.ndarray) -> np.ndarray:
        """The unknowns outside ``keep`` (bool, n) that a kept equation couples to: the only
        values :meth:`restricted` reads."""
        rows = sp.csr_matrix(self.stiffness)[np.flatnonzero(keep)]
        columns = np.unique(rows.indices)
        return columns[~keep[columns]]

    def restricted(self, keep: np.ndarray, values: np.ndarray) -> "ContactSystem":
        """The same contact problem on the unknowns ``keep`` (bool, n; every normal unknown
        of a contact node among them), every other unknown fixed at ``values`` (n,), or at
        its support's value where it has one.

        K_kk u_k = F_k − K_ko values_o: an exact subproblem when ``values`` are the outer
        unknowns of the solution, and held whatever the supports, since the outer unknowns
        are fixed (no free rigid motion is left to the contact).
        """
        keep = np.asarray(keep, dtype=bool)
        fixed_dofs = np.asarray(self.fixed_dofs, dtype=np.int64)
        values = np.array(values, dtype=float)
        values[fixed_dofs] = self.fixed_values
        normal_dofs = np.asarray(self.normal_dofs, dtype=np.int64)
        if not keep[normal_dofs].all():
            raise ValueError("a restricted contact system keeps every normal unknown of a contact node")
        kept = np.flatnonzero(keep)
        rows = sp.csr_matrix(self.stiffness)[kept]
        outside = np.where(keep, 0.0, np.asarray(values, dtype=float))
        position = np.full(len(keep), -1, dtype=np.int64)
        position[kept] = np.arange(len(kept))
        fixed_inside = keep[fixed_dofs]
        return ContactSystem(
            stiffness=rows[:, kept].tocsr(),
            load=np.asarray(self.load, dtype=float)[kept] - rows @ outside,
            normal_dofs=position[normal_dofs],
            gap=self.gap,
            multiplier_mass=self.multiplier_mass,
            fixed_dofs=position[fixed_dofs[fixed_inside]],
            fixed_values=np.asarray(self.fixed_values, dtype=float)[fixed_inside],
            contact_edges=self.contact_edges,
        )


@dataclass
class Iteration:
    """One Newton step. The residuals are scale-free: ``equilibrium_residual`` is
    ‖K u + Nᵀ Λ − F‖∞ over the force scale, ``complementarity_residual`` the natural
    residual max |min(Λ / force scale, (G − d) / displacement scale)| (see :class:`Certificate`)."""

    active: int
    added: int
    removed: int
    equilibrium_residual: float
    complementarity_residual: float
    seconds: float
    #: Nodes in which the step's next set differs from Newton's update: a creeping zone
    #: edge moved ahead, or an overshoot undone (see :class:`ZoneFronts`).
    extrapolated: int = 0
    #: Nodes in which the step's next set, proposed by a model of ΓC's compliance (the
    #: kernel's ``compliance``), differs from Newton's update.
    modelled: int = 0

    def summary(self) -> str:
        """One line of progress: the set, its changes and the residuals."""
        moved = f", {self.extrapolated} extrapolated" if self.extrapolated else ""
        moved += f", {self.modelled} from the compliance model" if self.modelled else ""
        return (f"{self.active} active (+{self.added} -{self.removed}{moved}), residuals "
                f"{self.equilibrium_residual:.1e} / {self.complementarity_residual:.1e}, {self.seconds:.2f} s")


@dataclass(frozen=True)
class Check:
    """One condition of a certificate: ``value`` must not exceed ``tolerance``."""

    value: float
    tolerance: float
    passed: bool
    meaning: str

    def __post_init__(self) -> None:
        # Plain Python numbers, whatever numpy handed in, so that reports serialise them.
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "tolerance", float(self.tolerance))
        object.__setattr__(self, "passed", bool(self.passed))


@dataclass(frozen=True)
class Certificate:
    """The discrete problem's own conditions, measured on the returned iterate.

    Scales (in the system's units, ``scales``):

    - ``force`` S_F = ‖F‖∞ + ‖K u‖∞ + ‖Nᵀ Λ‖∞ over all unknowns (the applied loads, the
      internal forces with the support reactions, the contact forces);
    - ``displacement`` S_D = max(‖u‖∞, ‖G‖∞);
    - ``roundoff``: γ_k max_i (|K| |u| + |F| + |Nᵀ Λ|)_i / S_F over the equations, the
      relative error bound of evaluating the equilibrium equations themselves
      (:func:`roundoff_bound`); its ratio to γ_k is a condition estimate of the forces;
    - ``condition_estimate`` κ̂ of the factorised stiffness the iterate was computed with
      (the probe of :func:`contactfem.linalg.check_factorization`),
      and ``relative_precision`` ε κ̂, the relative forward error a solve can have.

    Checks (``checks``, in this order; the message names the first that fails), with the
    tolerances ``tol_F`` = max(solver tolerance, roundoff) for forces and
    ``tol_D`` = max(solver tolerance, γ_2) for displacements:

    - ``finite``: no NaN or infinity in u, μ, Bμ (tolerance 0 entries);
    - ``force_resolution``: roundoff ≤ :data:`FORCE_RESOLUTION_LIMIT`;
    - ``equilibrium``: ‖K u + Nᵀ Λ − F‖∞ / S_F over the unsupported unknowns ≤ tol_F;
    - ``force_sign``: max(−Λ) / S_F ≤ tol_F over every contact node, Λ = Bμ (method (4):
      λ ≥ 0, as D > 0; method (5): (M θ)_x ≥ 0);
    - ``penetration``: max(N u − G) / S_D ≤ tol_D;
    - ``complementarity``: max |Λ_x (N u − G)_x| / (S_F S_D) ≤ max(tol_F, tol_D).
    """

    checks: dict[str, Check]
    scales: dict[str, float]

    @property
    def passed(self) -> bool:
        return all(check.passed for check in self.checks.values())

    @property
    def failed(self) -> list[str]:
        """Names of the failed checks, in order."""
        return [name for name, check in self.checks.items() if not check.passed]

    @property
    def message(self) -> str:
        """One line: the first failed condition with its value and tolerance, or 'certified'."""
        if self.passed:
            return "certified"
        name = self.failed[0]
        check = self.checks[name]
        return f"{name}: {check.meaning} = {check.value:.2e} exceeds its tolerance {check.tolerance:.2e}"

    def to_dict(self) -> dict:
        """JSON-ready figures (non-finite numbers become None)."""
        def number(value: float) -> float | None:
            return float(value) if np.isfinite(value) else None

        return {
            "passed": self.passed,
            "failed": self.failed,
            "checks": {name: {"value": number(c.value), "tolerance": number(c.tolerance), "passed": c.passed,
                              "meaning": c.meaning} for name, c in self.checks.items()},
            "scales": {name: number(value) for name, value in self.scales.items()},
        }


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


#: The fewest Newton steps a solve is allowed by default (see :func:`default_max_iterations`).
MIN_ITERATIONS = 50
#: Steps at the cap that a creeping zone is recognised from (see :func:`_creeping`).
CREEP_WINDOW = 5
#: Proposals a solve asks of its compliance model at most: the rough bases and the Hertz
#: disks settled after 1-3; beyond, Newton's update and its safeguards alone.
MAX_PROPOSALS = 8
#: Steps after which a solve that has not settled asks for its ``stalled_guess`` (a coarser
#: level's prediction, for a problem too small to have started from one): the cold starts
#: of the fragmented benchmark's scenes settle in 6-12 steps (a wavy traction's in 23, on
#: a mesh large enough to start from a prediction anyway), while a strip 1 x 0.001 peeling
#: off, 400 x 2 cells, had not settled after 400; from the prediction of the same case on
#: 100 x 1 cells (169 steps there, on a sixth of the unknowns) it took 2 more.
STALL_ITERATIONS = 15


def default_max_iterations(contact_nodes: int) -> int:
    """Newton steps allowed by default: :data:`MIN_ITERATIONS`, or one per contact node if
    there are more. A body in bending lifting off the obstacle (a strip 1 x 0.01 clamped at
    one end under a wavy pressure) releases one node per patch edge per step, each release
    putting the next node in tension: its zone creeps to its edges in as many steps as the
    edges move nodes, 51 at 400 cells along it, 59 at 1 600 and 234 for a strip 1 x 0.001,
    each step changing a few nodes. A monotone creep ends within that many steps; a set
    that repeats is caught by the cycle safeguard whatever the cap."""
    return max(MIN_ITERATIONS, int(contact_nodes))


def _creeping(history: Sequence["Iteration"]) -> str:
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


#: Consecutive steps a zone edge must have moved the same way before its move is
#: extrapolated (see :class:`ZoneFronts`): from the second step of a creep on. From the
#: third, 16 strips 1 x 0.01 and 1 x 0.005 took 470 steps in all instead of 320; from the
#: second, the tail of a rough profile's solve may take a step more (an edge that moves by
#: a node twice and stops: 5 steps instead of 4 on cases/rough.yaml's 1 000-point profile).
CREEP_RUN = 2
#: Overshoots (see :class:`ZoneFronts`) after which a solve goes on with Newton's update
#: alone; each halves the extrapolations that overshot.
MAX_OVERSHOOTS = 8
#: The most nodes one extrapolation moves a zone edge by.
MAX_EXTRAPOLATION = 4096
#: An extrapolation takes at most this share of the nodes ahead of it in the state it
#: leaves (two edges closing on a patch from both sides leave something of it). Without the
#: bound, a wavy traction's hundreds of patches, each shrinking by a node per edge per step
#: and kept at a core, were released whole: cold starts at k = 200, 400, 1 600 and 6 400
#: took 14, 10, 8 and 9 steps (Newton alone: 23, 7, 7, 7); with a half, 14, 9, 8 and 8. On
#: 16 strips 1 x 0.01 and 1 x 0.005 (400 x 2 and 800 x 4 cells, four pressures), a half or
#: a third took 320 steps in all, the whole 389, Newton alone 857.
SHARE_AHEAD = 2
#: ΓC chains beyond which no order along them is built (a contact part of thousands of
#: separate edges has no zone edge to creep): one graph search per chain.
MAX_CHAINS = 256


class ZoneFronts:
    """The edges of the contact zone along ΓC, to recognise a zone that creeps and move it
    ahead.

    A body in bending (a strip peeling off, a plate lifting at its ends) moves each zone
    edge by a node or a few per Newton step: releasing a node puts the next in tension.
    Strips 1 x 0.01 clamped at one end took 51 steps at 400 cells, 59 at 1 600 and 77 at
    6 400 (one 1 x 0.001 at 400 x 2 cells, 2 598).

    Each step's changes are taken as blocks, stretches of consecutive ΓC nodes changing
    the same way. A block whose neighbour on one side changed the same way at the last
    step (and stays so) continues a run; on a step whose every block continues one, each
    block from the :data:`CREEP_RUN`-th step of its run on is carried on beyond its far
    end by its own length times (run − 1)² nodes, through nodes in the state it leaves
    (at most a :data:`SHARE_AHEAD`-th of those ahead of it): the edge crosses n nodes in
    about (3n)^⅓ steps. Doubling instead (a galloping search)
    overshot more on strips lifting in several places. An extrapolation overshot when, at
    the next step, Newton changes a node of the stretch of nodes in one state that holds
    it (a strip released too far sags back onto the obstacle within its lifted span);
    then the far half of each such extrapolation is undone instead of taking Newton's
    update, whose answer to a body over-released is to bring back far more than the
    overshoot, and its farthest node is never extrapolated into again: a bisection. After
    :data:`MAX_OVERSHOOTS` of them the solve goes on with Newton's update alone, so that
    the iteration's termination (the cycle safeguard, the least-index rule) is kept.
    With it those strips took 14, 18 and 19 steps, and strips 1 x 0.005 and 1 x 0.02
    lifting in four and two places 35 and 14 instead of 70 and 29. Slenderer strips
    (1 x 0.002 and 1 x 0.001 at 400 x 2 cells) cycle, with or without it, and take hundreds
    or thousands of steps: a coarser level's prediction settles them (see
    :data:`STALL_ITERATIONS`).
    """

    def __init__(self, edges: np.ndarray, m: int):
        from scipy.sparse.csgraph import connected_components, depth_first_order

        self.enabled = False
        self.overshoots = 0
        self.last_change = np.zeros(m, dtype=np.int8)
        self.run = np.zeros(m, dtype=np.int64)
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)
        self.too_far = np.zeros(m, dtype=bool)
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        edges = edges[edges[:, 0] != edges[:, 1]]
        if m < 3 or len(edges) == 0 or np.bincount(edges.ravel(), minlength=m).max() > 2:
            return
        if np.all(np.abs(edges[:, 0] - edges[:, 1]) == 1):
            # Every edge joins nodes i and i + 1 (ΓC's nodes numbered along it, as the contact
            # boundary numbers them): the chains are runs of consecutive nodes, each walked
            # upwards, what the graph search below finds at a tenth of its cost.
            linked = np.zeros(m, dtype=bool)  # linked[i]: an edge joins i and i + 1
            linked[edges.min(axis=1)] = True
            starts = np.flatnonzero(np.r_[True, ~linked[:-1]])
            if len(starts) > MAX_CHAINS:
                return
            along, lengths = np.arange(m), np.diff(np.r_[starts, m])
        else:
            graph = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(m, m))
            graph = ((graph + graph.T) > 0).astype(np.int8).tocsr()
            count, labels = connected_components(graph, directed=False)
            if count > MAX_CHAINS:
                return
            # Each chain is walked from an end (a node of one edge), or from any node of a loop.
            start = np.zeros(count, dtype=np.int64)
            start[labels[::-1]] = np.arange(m)[::-1]  # each chain's lowest node
            ends = np.flatnonzero(np.diff(graph.indptr) == 1)
            start[labels[ends[::-1]]] = ends[::-1]
            orders = [depth_first_order(graph, node, directed=False, return_predecessors=False) for node in start]
            along, lengths = np.concatenate(orders), np.array([len(order) for order in orders])
        #: The contact nodes chain after chain, each chain in its order; ``where[i]`` is node
        #: i's place in it and ``first``/``last`` the places its chain spans.
        self.along = along
        self.where = np.empty(m, dtype=np.int64)
        self.where[along] = np.arange(m)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        self.first = np.repeat(starts, lengths)
        self.last = np.repeat(starts + lengths - 1, lengths)
        self.enabled = True

    def forget(self) -> None:
        """Start every run again (a step whose set came from elsewhere than Newton's update)."""
        self.last_change[:] = 0
        self.run[:] = 0
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)

    def extend(self, active: np.ndarray, proposed: np.ndarray) -> tuple[np.ndarray, int]:
        """Newton's proposed set with every creeping zone edge moved ahead, and how many
        nodes that changed beyond Newton's update; records this step's changes."""
        if not self.enabled:
            return proposed, 0
        change = proposed.astype(np.int8) - active.astype(np.int8)
        # An extrapolation overshot if Newton changes any node of the stretch of nodes in one
        # state that holds it: a node of the stretch itself, or one further on (a strip
        # released too far sags onto the obstacle in the middle of its lifted span).
        if len(self.moved):
            stretch, stretch_start, _ = self._stretches(active)
            changing = np.bincount(stretch, weights=change[self.along] != 0, minlength=len(stretch_start)) > 0
            back = changing[stretch[self.where[self.moved]]]
            if back.any():
                return self._bisect(active, proposed, back)
        # This step's changes as blocks: stretches of consecutive places along a chain that
        # change the same way (a creeping edge moves by one node or a few per step).
        places = np.sort(self.where[np.flatnonzero(change)])
        nodes = self.along[places]
        starts = np.ones(len(places), dtype=bool)
        starts[1:] = ((places[1:] != places[:-1] + 1) | (self.first[places[1:]] != self.first[places[:-1]])
                      | (change[nodes[1:]] != change[nodes[:-1]]))
        low = places[starts]
        high = places[np.r_[np.flatnonzero(starts)[1:] - 1, len(places) - 1]] if len(places) else low
        way = change[self.along[low]]

        def continued(outside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Whether the place next to each block (``outside``) changed the same way at the
            last step and stays so, and the node there."""
            inside = (outside >= self.first[low]) & (outside <= self.last[low])
            node = self.along[np.where(inside, outside, low)]
            return inside & (self.last_change[node] == way) & (change[node] == 0), node

        below, below_node = continued(low - 1)
        above, above_node = continued(high + 1)
        edge = below ^ above  # a run reaches a block from one side: it moves away from there
        run = np.where(edge, self.run[np.where(below, below_node, above_node)] + 1, 1)
        self.last_change[:] = 0
        self.last_change[nodes] = change[nodes]
        self.run[:] = 0
        self.run[nodes] = np.repeat(run, high - low + 1)
        self.moved = self.moved_owner = self.moved_offset = np.zeros(0, dtype=np.int64)
        fronts = np.flatnonzero(edge & (run >= CREEP_RUN))
        # Only a step that is all creep: taken on any step, a cold start under the rough
        # profiles took 3-5 steps more (7 → 10 at 1 000 segments), from patches that grow
        # for two steps and stop.
        if len(fronts) == 0 or not edge.all():
            return proposed, 0
        # Beyond each such block, its own length times (run − 1)² places, as far as they run
        # through nodes in the state the block leaves (at most MAX_EXTRAPOLATION, and a
        # SHARE_AHEAD-th of that state's stretch ahead of the block).
        stretch, stretch_start, stretch_end = self._stretches(active)
        length = high[fronts] - low[fronts] + 1
        direction = np.where(below[fronts], 1, -1)
        beyond = np.where(below[fronts], high[fronts], low[fronts])
        ahead = np.where(below[fronts], stretch_end[stretch[beyond]] - beyond, beyond - stretch_start[stretch[beyond]])
        reach = np.minimum(np.minimum(length * np.minimum(run[fronts] - 1, 64) ** 2, MAX_EXTRAPOLATION),
                           ahead // SHARE_AHEAD)
        fronts, direction, beyond, reach = fronts[reach > 0], direction[reach > 0], beyond[reach > 0], reach[reach > 0]
        if len(fronts) == 0:
            return proposed, 0
        owner = np.repeat(np.arange(len(fronts)), reach)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(reach) - reach, reach) + 1
        target_place = beyond[owner] + direction[owner] * offset
        ok = (target_place >= self.first[beyond[owner]]) & (target_place <= self.last[beyond[owner]])
        target = self.along[np.where(ok, target_place, beyond[owner])]
        leaving = way[fronts] < 0  # a released block leaves the active state
        ok &= (active[target] == leaving[owner]) & (change[target] == 0) & ~self.too_far[target]
        # Only the unbroken stretch next to each block: up to its first place that fails.
        blocked = np.where(ok, np.iinfo(np.int64).max, offset)
        first_blocked = np.minimum.reduceat(blocked, np.cumsum(reach) - reach)
        keep = ok & (offset < first_blocked[owner])
        target, owner = target[keep], owner[keep]
        if len(target) == 0:
            return proposed, 0
        extended = proposed.copy()
        extended[target] = ~leaving[owner]
        self.moved, self.moved_owner, self.moved_offset = target, owner, offset[keep]
        self.last_change[target] = way[fronts][owner]
        self.run[target] = run[fronts][owner]
        return extended, len(target)

    def _stretches(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The stretches of consecutive places in one state along each chain: each place's
        stretch, and each stretch's first and last place."""
        state = active[self.along]
        starts = np.ones(len(state), dtype=bool)
        starts[1:] = (state[1:] != state[:-1]) | (self.first[1:] != self.first[:-1])
        first = np.flatnonzero(starts)
        return np.cumsum(starts) - 1, first, np.r_[first[1:] - 1, len(state) - 1]

    def _bisect(self, active: np.ndarray, proposed: np.ndarray, back: np.ndarray) -> tuple[np.ndarray, int]:
        """The set after an overshoot: the far half of each stretch some of whose nodes
        Newton changes back is undone (its far end never extrapolated into again), the near
        half kept; nothing else changes at this step (Newton's update beside an overshoot answers
        the overshoot, not the edge). Counted as many nodes as it differs from Newton's."""
        self.overshoots += 1
        self.last_change[:] = 0
        self.run[:] = 0
        owners = np.unique(self.moved_owner[back])
        in_overshoot = np.isin(self.moved_owner, owners)
        reach = np.zeros(int(self.moved_owner.max()) + 1, dtype=np.int64)
        np.maximum.at(reach, self.moved_owner, self.moved_offset)
        # Never empty: the farthest node of each such stretch is in its far half.
        far = in_overshoot & (self.moved_offset > reach[self.moved_owner] // 2)
        if self.overshoots > MAX_OVERSHOOTS:
            self.enabled = False
            self.moved = np.zeros(0, dtype=np.int64)
            return proposed, 0
        result = active.copy()
        result[self.moved[far]] = ~result[self.moved[far]]
        # The stretch's far end went too far: no extrapolation reaches it again (the edge
        # lies before it, perhaps in the half undone, which Newton or a shorter
        # extrapolation from the kept half then reaches).
        self.too_far[self.moved[far & (self.moved_offset == reach[self.moved_owner])]] = True
        self.moved, self.moved_owner, self.moved_offset = (self.moved[~far], self.moved_owner[~far],
                                                           self.moved_offset[~far])
        self.last_change[self.moved] = (active[self.moved].astype(np.int8) * 2 - 1)
        return result, int(np.count_nonzero(result != proposed))


def default_c(system: ContactSystem) -> float:
    """c of the order of the normal nodal stiffness, so that c (d − G) is a force like Bμ.

    Scaling K by any factor scales c with it, which keeps the iteration unit-free.
    """
    if len(system.normal_dofs) == 0:
        return 1.0
    return float(np.mean(system.stiffness.diagonal()[system.normal_dofs]))


def _translation_update(system: ContactSystem, linear, tolerance: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Newton's update from the supports' own solution when that is ``system.translation``,
    checked to be one: no load, the prescribed values its components to round-off, and K
    times it zero to the round-off bound of the equations (:meth:`ActiveSetSolver.measure`),
    with the slack d − G of the translation. None otherwise."""
    translation = system.translation
    if translation is None or np.any(system.load) or not isinstance(linear, ActiveSetSolver):
        return None  # a distributed solver holds each rank's part of the vectors
    translation = np.asarray(translation, dtype=float)
    values = np.asarray(system.fixed_values, dtype=float)
    prescribed = translation[np.asarray(system.fixed_dofs, dtype=np.int64)]
    if np.abs(prescribed - values).max(initial=0.0) > 8 * np.finfo(float).eps * np.abs(values).max(initial=0.0):
        return None
    scales = linear.measure(translation, np.zeros(len(system.gap)))
    if not scales.equilibrium <= scales.roundoff:
        return None
    slack = linear.normals(translation) - np.asarray(system.gap, dtype=float)
    return slack > max(tolerance, roundoff_bound(2)) * scales.displacement, slack


def translation_start(system: ContactSystem, linear: "ActiveSetSolver", tolerance: float,
                      compliance: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray | None] | None = None,
                      ) -> tuple[np.ndarray, bool] | None:
    """Where a cold start whose supports' own solution is ``system.translation`` begins
    (:func:`_translation_update`), without solving: Newton's update from it, replaced by
    ``compliance``'s proposal from the same free body when it makes one; and whether
    ``compliance`` was asked. None when that solution is no such translation. Needs no
    factorisation: a caller may run it while ``linear`` is analysed in another thread."""
    translated = _translation_update(system, linear, tolerance)
    if translated is None:
        return None
    active, slack = translated
    if compliance is None:
        return active, False
    # Newton's update from the translation presses in every node it puts inside; the
    # model's own contact problem, from the same free body, keeps those that stay (824
    # and 171 of 1 000 on a rough base).
    m = len(slack)
    proposal = compliance(np.zeros(m, dtype=bool), slack, np.zeros(m))
    if proposal is not None and proposal.any():
        active = np.asarray(proposal, dtype=bool).copy()
    return active, True


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
    linear: "ActiveSetSolver | None" = None,
    second_guess: Callable[[], np.ndarray | None] | None = None,
    stalled_guess: Callable[[], np.ndarray | None] | None = None,
    compliance: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray | None] | None = None,
) -> KernelResult:
    """Run the primal–dual active set iteration until the active set repeats, then certify.

    Parameters
    ----------
    system : ContactSystem
    c : float, optional
        Weight of the gap against the force in the active set indicator Bμ + c (d − G);
        default :func:`default_c`. Recorded only: after a solve the indicator's sign is
        that of Bμ on A and of d − G on I, so the iteration does not depend on c.
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
        the indicator at u = 0, Bμ = 0 for any c.
    on_iteration : callable, optional
        Called with each :class:`Iteration` record (progress reporting).
    safeguard : bool
        When the active set repeats, go on with least-index single changes (default);
        False stops with status CYCLING instead.
    linear : ActiveSetSolver, optional
        The linear solver of an earlier solve of the same stiffness and constraints, set to
        this system's load (:meth:`ActiveSetSolver.set_load_factor`): its factorisation and
        cached columns are reused. The result counts only this solve's factorisations. Any
        object with its ``load``, ``solve``, ``normals``, ``measure``, ``non_finite``,
        ``certify``, ``factorizations`` and ``column_solves`` serves (the distributed
        solver of :mod:`contactfem.distributed`, whose vectors are each rank's part).
    second_guess : callable, optional
        Asked once, only if the first iterate's set does not settle: a better set to go on
        from (a prediction from a coarser mesh, which costs a coarse solve and is not paid
        for when the starting set was already the answer), or None to go on with Newton's
        update. It replaces that update for the second iteration.
    stalled_guess : callable, optional
        Asked once, if the set has not settled after :data:`STALL_ITERATIONS` steps (and no
        cycle was met): a set to go on from (a prediction from a coarser mesh, for a start
        that had none), or None to go on with Newton's update.
    compliance : callable, optional
        A model of ΓC's compliance (:class:`contactfem.compliance.HalfPlaneModel`): given a
        solved set, its slack d − G and its nodal forces Bμ, the set of the model's contact
        problem anchored there, or None. While the set has not settled its proposal
        replaces Newton's update (at most :data:`MAX_PROPOSALS` times, and never with a set
        solved before); Newton's update alone decides when the set has settled, so the
        model changes how many steps a solve takes, never its answer. A translation's
        known update (see ``initial_active``) is replaced likewise. Not asked of a body
        that contact alone holds.

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
    mass_solver = _mass_solver(mass) if m else None

    # The textbook start u = 0, Bμ = 0 gives the indicator c (0 − G): only nodes starting
    # inside the obstacle. Starting from every touching node instead saves a step on
    # bodies pressed flat but makes bending-dominated ones (a slender beam lifting off)
    # release one node per step.
    active = (gap < 0.0) if initial_active is None else np.asarray(initial_active, dtype=bool).copy()
    holder = _ModeHolder(system) if system.free_modes is not None and m else None
    fronts: ZoneFronts | None = None  # built at the second step, which a settled solve never reaches
    newtons: np.ndarray | None = None  # Newton's own update, when the set to solve was extrapolated
    if holder is not None:
        active = holder.hold(active, holder.first_touch())
    linear = ActiveSetSolver(system, backend, tolerance=tolerance) if linear is None else linear
    factorizations_before, column_solves_before = linear.factorizations, linear.column_solves
    # A cold start with no node inside the obstacle solves the supports alone first. When
    # that solution is a translation known in advance (a body pushed by a prescribed
    # displacement, nothing loading it), Newton's update from it is known too: the nodes
    # the translation presses into the obstacle, where the iteration starts instead.
    translated = (translation_start(system, linear, tolerance, compliance)
                  if initial_active is None and holder is None and m and not active.any() else None)
    skipped = int(translated is not None)  # that update counts as the first step's
    proposals = 0  # asked of ``compliance``
    if translated is not None:
        active, asked = translated
        proposals += int(asked)
    seen: dict[bytes, int] = {}
    cycle_detected_at: int | None = None
    least_index, least_index_from = False, 0
    flips = np.zeros(m, dtype=np.int64)
    history: list[Iteration] = []
    displacement = np.zeros(len(linear.load))
    multiplier = np.zeros(m)
    nodal_force = np.zeros(m)
    if max_iterations is None:
        max_iterations = default_max_iterations(m)
    status, message = Status.MAX_ITERATIONS, f"no convergence in {max_iterations} iterations"
    certificate: Certificate | None = None
    gap_floor = roundoff_bound(2)  # d − G: one subtraction of two numbers within S_D

    for iteration in range(1, max_iterations + 1):
        started = time.perf_counter()
        try:
            displacement, reaction = linear.solve(active)
        except SolverError:
            if newtons is not None:
                # An extrapolated set released so much of a slender body that its supports
                # no longer hold it in double precision (a strip 1 x 1/6 400 clamped at one
                # end): Newton's own update instead, and no more extrapolation.
                active, newtons = newtons, None
                fronts.enabled = False
                displacement, reaction = linear.solve(active)
            else:
                # The first set may leave free, in double precision, a body that contact
                # holds: a strip 1 x 1e-6 clamped at one end and resting on the plane,
                # started from the nodes inside the obstacle (none), is a cantilever of
                # slenderness 1e6. Every touching node holds it, and Newton releases the
                # rest; a body that no set of touching nodes holds stays a SolverError.
                touching = active | (gap <= 0.0)
                if iteration > 1 or np.array_equal(touching, active):
                    raise
                active = holder.hold(touching, holder.first_touch()) if holder is not None else touching
                displacement, reaction = linear.solve(active)
        newtons = None
        seen[np.packbits(active).tobytes()] = iteration
        reaction_at_contact = np.zeros(m)
        reaction_at_contact[active] = reaction
        multiplier = mass_solver(reaction_at_contact) if m else multiplier
        # The method's own complementarity rows: its multiplier times its mass.
        nodal_force = mass @ multiplier if m else nodal_force
        slack = linear.normals(displacement) - gap
        scales = linear.measure(displacement, nodal_force)

        # Newton's update of the active set, decided per node in the data's scales: on A
        # (slack exactly 0) by the sign of the reaction, on I (reaction exactly 0) by the
        # sign of the slack. Values within the certificate's tolerance of zero keep their
        # node's state, so that round-off cannot make the set flicker and whatever the
        # kernel treats as zero the certificate accepts.
        force_band = max(tolerance, scales.roundoff) * scales.force
        gap_band = max(tolerance, gap_floor) * scales.displacement
        new_active = np.where(active, reaction_at_contact >= -force_band, slack > gap_band)
        if holder is not None:
            indicator = np.where(active, reaction_at_contact, c * slack)
            new_active = holder.hold(new_active, indicator)
        finite = linear.non_finite(displacement) == 0 and bool(np.isfinite(nodal_force).all())
        seconds = time.perf_counter() - started  # this step's own, without the guess's cost
        guessed = False  # the next set comes from elsewhere than Newton's update
        if iteration == 1 and second_guess is not None and finite and not np.array_equal(new_active, active):
            guess = second_guess()
            if guess is not None:
                guess = np.asarray(guess, dtype=bool).copy()
                if not np.array_equal(guess, active):
                    new_active, guessed = guess, True

        modelled = 0
        if (compliance is not None and holder is None and not guessed and finite and cycle_detected_at is None
                and proposals < MAX_PROPOSALS and not np.array_equal(new_active, active)):
            proposal = compliance(active, slack, nodal_force)
            proposals += 1
            # ``seen`` holds the set just solved too: proposing it again is refused likewise.
            if proposal is not None and np.packbits(proposal).tobytes() not in seen:
                modelled = int(np.count_nonzero(proposal != new_active))
                new_active, guessed = np.asarray(proposal, dtype=bool).copy(), True

        if (iteration == STALL_ITERATIONS and stalled_guess is not None and finite and cycle_detected_at is None
                and not np.array_equal(new_active, active)):
            guess = stalled_guess()
            if guess is not None:
                guessed = True
                new_active = np.asarray(guess, dtype=bool).copy()
                if holder is not None:
                    new_active = holder.hold(new_active, np.where(active, reaction_at_contact, c * slack))

        extrapolated = 0
        if (fronts is None and system.contact_edges is not None and iteration + skipped >= 2 and finite
                and not np.array_equal(new_active, active)):
            fronts = ZoneFronts(system.contact_edges, m)
        if fronts is not None and fronts.enabled and finite:
            if guessed or cycle_detected_at is not None:
                fronts.forget()
            else:
                extended, extrapolated = fronts.extend(active, new_active)
                if extrapolated and holder is not None:
                    extended = holder.hold(extended, np.where(active, reaction_at_contact, c * slack))
                if extrapolated and np.packbits(extended).tobytes() not in seen:
                    newtons, new_active = new_active, extended
                elif extrapolated:  # a set already solved: Newton's update, and the runs begin again
                    extrapolated = 0
                    fronts.forget()

        with np.errstate(invalid="ignore", over="ignore"):
            complementarity = np.abs(
                np.minimum(nodal_force / scales.force, -slack / scales.displacement)
            ).max(initial=0.0)
        record = Iteration(
            active=int(active.sum()),
            added=int((new_active & ~active).sum()),
            removed=int((active & ~new_active).sum()),
            equilibrium_residual=float(scales.equilibrium),
            complementarity_residual=float(complementarity),
            seconds=seconds,
            extrapolated=extrapolated,
            modelled=modelled,
        )
        history.append(record)
        if on_iteration is not None:
            on_iteration(record)

        if not finite:
            certificate = linear.certify(displacement, multiplier, nodal_force, scales, tolerance)
            status = Status.NOT_CERTIFIED
            message = f"iteration {iteration} is not certified: {certificate.message}"
            break
        if np.array_equal(new_active, active):
            certificate = linear.certify(displacement, multiplier, nodal_force, scales, tolerance)
            if certificate.passed:
                status = Status.CONVERGED
                message = f"converged in {iteration} iterations, {int(active.sum())} active nodes"
                if cycle_detected_at is not None:
                    message += (
                        f"; the active set cycled at iteration {cycle_detected_at}, resolved by "
                        + ("least-index single changes" if least_index else
                           "holding the oscillating nodes but the least-index one")
                    )
            else:
                status = Status.NOT_CERTIFIED
                message = (
                    f"active set settled after {iteration} iterations ({int(active.sum())} active nodes) "
                    f"but the result is not certified: {certificate.message}"
                )
                if certificate.failed[0] == "force_resolution" and not active.any() and not np.any(linear.load):
                    # An unloaded rigid motion too large for the body's own force unit to
                    # resolve its round-off (see measure: a translation by 1e45).
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
            break
        key = np.packbits(new_active).tobytes()
        if key in seen and not safeguard:
            status = Status.CYCLING
            message = (
                f"the active set cycles: iteration {iteration + 1} would repeat the set of "
                f"iteration {seen[key]}"
            )
            break
        if key in seen and cycle_detected_at is None:
            # Plain Newton revisits a set. On a fragmented contact zone the nodes that
            # ping-pong are few among many correct changes: first keep every change of a
            # node that has not flipped back and forth, and only the lowest-numbered of the
            # oscillating ones. If a set repeats even so, change one node at a time, the
            # lowest-numbered one whose sign condition fails (Murty's least-index rule),
            # which terminates on P-matrix problems such as ours (S = P K⁻¹ Pᵀ is SPD).
            cycle_detected_at = iteration
        changing = new_active != active
        if cycle_detected_at is not None and not least_index:
            oscillating = changing & (flips >= 2)
            if oscillating.any():
                held = np.flatnonzero(oscillating)[1:]
                new_active[held] = active[held]
                changing = new_active != active
            if np.packbits(new_active).tobytes() in seen:
                least_index, least_index_from = True, iteration
        if least_index:
            first_wrong = np.flatnonzero(changing)[0]
            new_active = active.copy()
            new_active[first_wrong] = not active[first_wrong]
            # Only a set the rule itself has visited is a cycle of it: its sequence may pass
            # through sets of the plain iteration before it (a strip 1 x 0.001 peeling off
            # reached one after 168 steps and was refused as cycling).
            if seen.get(np.packbits(new_active).tobytes(), 0) >= least_index_from:
                status = Status.CYCLING
                message = (
                    f"the active set cycles (first detected at iteration {cycle_detected_at}) "
                    "even under the least-index safeguard"
                )
                break
        if holder is not None:
            new_active = holder.hold(new_active, np.where(active, reaction_at_contact, c * slack))
        flips += new_active != active
        active = new_active

    if status is Status.MAX_ITERATIONS:
        message += (f"; the least-index safeguard, a node per step since iteration {least_index_from}, had not "
                    "settled: raise solver.max_iterations" if least_index else _creeping(history))
    if certificate is None and history:
        # Stopped before the set settled (cap, cycling, non-finite): the figures of the last
        # iterate still tell the caller how far it is from an answer.
        certificate = linear.certify(displacement, multiplier, nodal_force, scales, tolerance)
    return KernelResult(
        status=status,
        message=message,
        displacement=displacement,
        multiplier=multiplier,
        nodal_force=nodal_force,
        active=active,
        c=c,
        history=history,
        cycle_detected_at=cycle_detected_at,
        factorizations=linear.factorizations - factorizations_before,
        column_solves=linear.column_solves - column_solves_before,
        certificate=certificate,
    )


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
    set, the answer, and takes one Newton step."""

    def __init__(self, system: ContactSystem, *, backend: str = "auto", initial_active: np.ndarray | None = None,
                 starts: PathStarts | None = None, **options) -> None:
        self.system, self.backend, self.options = system, backend, options
        self.linear = ActiveSetSolver(system, backend, tolerance=options.get("tolerance", 1e-10), scalable=True)
        self.c = options.get("c") or default_c(system)
        self.starts = starts or PathStarts()
        self.active = initial_active
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        #: (factor, contact force Λ, slack d − G) of the last two steps solved; before the
        #: first, the unloaded state when nothing starts inside the obstacle.
        self.history = [(0.0, np.zeros(len(self.gap)), -self.gap)] if (self.gap >= 0).all() else []
        self.steps = 0
        #: The settled set of every factor solved, packed to a bit a node (a path has at most
        #: 1 000 factors: 12 MB at 100 000 contact nodes).
        self.settled_sets: dict[float, np.ndarray] = {}

    def extrapolated(self, factor: float) -> np.ndarray | None:
        """The active set expected at ``factor`` from the steps solved (None before any)."""
        if self.steps == 0:
            return None
        if len(self.history) >= 2:
            return extrapolated_active(self.history[-2:], factor, self.c)
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
        result = solve_contact(self.system.scaled(factor), backend=self.backend, initial_active=start,
                               linear=self.linear, **self.options)
        result.column_solves = self.linear.column_solves - solves_before
        self.steps += 1
        if result.status is Status.CONVERGED:
            self.starts.settled(result.active)
            self.settled_sets[factor] = np.packbits(result.active)
            self.active = result.active
            state = (factor, result.nodal_force, result.displacement[self.normal_dofs] - self.gap)
            # Two states at one factor extrapolate nowhere: a repeated factor replaces its state.
            kept = self.history[:-1] if self.history and self.history[-1][0] == factor else self.history
            self.history = [*kept[-1:], state]
        return result


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
    path = PathSolver(system, backend=backend, initial_active=initial_active, starts=starts, **options)
    for factor in factors:
        result = path.step(factor)
        yield result
        if result.status is not Status.CONVERGED:
            return


def extrapolated_active(states: list[tuple[float, np.ndarray, np.ndarray]], factor: float, c: float) -> np.ndarray:
    """The active set predicted at load ``factor`` from the last two solved ``states``
    (factor, contact force Λ, slack d − G): both extrapolated linearly in the factor, a node
    is predicted active where the indicator Λ + c (d − G) is positive. Along a path the
    contact zone moves smoothly, so this is closer than the last set, which Newton's method
    would otherwise first overshoot (every node penetrating at once) and then release a few
    at a time."""
    (f0, force0, slack0), (f1, force1, slack1) = states
    ratio = (factor - f1) / (f1 - f0) if f1 != f0 else 0.0
    force = force1 + ratio * (force1 - force0)
    slack = slack1 + ratio * (slack1 - slack0)
    return force + c * slack > 0


@dataclass(frozen=True)
class Scales:
    """The data's scales at one iterate (see :class:`Certificate`) and its equilibrium residual."""

    force: float
    displacement: float
    roundoff: float
    equilibrium: float


def build_certificate(non_finite: int, slack: np.ndarray, multiplier: np.ndarray, nodal_force: np.ndarray,
                      scales: Scales, tolerance: float, condition: float) -> Certificate:
    """The :class:`Certificate` of an iterate: ``non_finite`` entries of its u (counted by the
    caller, who may hold only part of it), its ``slack`` N u − G and multipliers at every
    contact node, its ``scales``, and ``condition`` κ̂ of the factorisation it came from."""
    force_tolerance = max(tolerance, scales.roundoff)
    gap_tolerance = max(tolerance, roundoff_bound(2))
    non_finite += int(sum(np.count_nonzero(~np.isfinite(a)) for a in (multiplier, nodal_force)))
    checks = {"finite": Check(float(non_finite), 0.0, non_finite == 0, "non-finite entries of u, mu, B mu")}
    if non_finite == 0:
        force, displacement = scales.force, scales.displacement
        pushed = max(0.0, -nodal_force.min(initial=0.0)) / force
        penetration = max(0.0, slack.max(initial=0.0)) / displacement
        product = np.abs(nodal_force * slack).max(initial=0.0) / max(force * displacement, np.finfo(float).tiny)
        both = max(force_tolerance, gap_tolerance)
        checks.update({
            "force_resolution": Check(scales.roundoff, FORCE_RESOLUTION_LIMIT,
                                      scales.roundoff <= FORCE_RESOLUTION_LIMIT,
                                      "round-off bound of the equilibrium equations / force scale (forces lost in cancellation)"),
            "equilibrium": Check(scales.equilibrium, force_tolerance, scales.equilibrium <= force_tolerance,
                                 "max |K u + N^T Lambda - F| / force scale"),
            "force_sign": Check(pushed, force_tolerance, pushed <= force_tolerance,
                                "max(-Lambda) / force scale (Lambda = B mu >= 0)"),
            "penetration": Check(penetration, gap_tolerance, penetration <= gap_tolerance,
                                 "max(N u - G) / displacement scale"),
            "complementarity": Check(float(product), both, product <= both,
                                     "max |Lambda (N u - G)| / (force scale * displacement scale)"),
        })
    return Certificate(
        checks=checks,
        scales={
            "force": scales.force,
            "displacement": scales.displacement,
            "roundoff": scales.roundoff,
            "condition_estimate": condition,
            "relative_precision": EPS * condition,
            "solver_tolerance": float(tolerance),
        },
    )


def _row_positions(indptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the entries of CSR ``rows`` (in order) and each row's length."""
    starts, lengths = indptr[rows], indptr[rows + 1] - indptr[rows]
    return np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(int(lengths.sum())), lengths


def _cross(left: sp.csc_matrix, right: sp.csc_matrix) -> np.ndarray:
    """leftᵀ right for sparse forward columns, dense (k_left, k_right).

    The columns share the rows near the elimination tree's root and little else: the rows
    that an eighth of the right-hand columns or more touch go through BLAS as dense blocks
    (on the square at 526 000 unknowns, 256 columns share 14 000 rows: 0.04 s against
    0.66 s as a sparse product), the others through a sparse product (1 200 columns on a
    rough profile's mesh at 418 000 unknowns touch 68 000 rows, 1 200 of them shared: 2.4 s
    as one dense block over all of them, 0.25 s as a sparse product). A row in the sparse
    product costs about its two counts' product, in the dense block the two column counts':
    an eighth took 0.78-0.91 of a quarter's time on the rough profile's mesh from 27 000 to
    418 000 unknowns (a sixteenth 0.81-0.91, but 1.11 at 27 000; a thirty-second 1.0-1.35).
    """
    k = right.shape[1]
    if left.shape[1] * (left.shape[0] + right.nnz) <= DENSE_CROSS_ENTRIES:
        # A few new columns: rightᵀ times them made dense, one pass over right's entries
        # per column (0.05-0.11 ms against 0.27 for 1-16 columns at 7 000 unknowns).
        return np.asarray(right.T @ left.toarray()).T
    counts = np.bincount(right.indices, minlength=right.shape[0])
    shared = counts >= max(1, k // 8)
    if 8 * int(shared.sum()) * (k + left.shape[1]) > COLUMN_BYTES:
        shared[:] = False
    heavy = np.flatnonzero(shared)
    product = left[heavy].toarray().T @ right[heavy].toarray()
    if len(heavy) < int(np.count_nonzero(counts)):
        # left without the shared rows' entries, selected from its arrays (a product with a
        # diagonal mask cost twice the sparse product itself at 7 000-100 000 unknowns).
        light_entries = ~shared[left.indices]
        kept_before = np.concatenate([[0], np.cumsum(light_entries)])
        light = sp.csc_matrix((left.data[light_entries], left.indices[light_entries], kept_before[left.indptr]),
                              shape=left.shape)
        product += (light.T @ right).toarray()
    return product


class ActiveSetSolver:
    """Solves K u = F with supports and the normal unknowns of an active set fixed,
    reusing one factorisation across active sets.

    Fixed unknowns are not sliced out: their rows and columns are masked to the identity
    inside K's own sparsity pattern, which costs one pass over the nonzeros. The matrix is
    factorised once with the normals of a reference set A0 fixed. For another set A, the
    nodes of A0 ∖ A (released: their normal unknown becomes free) and of A ∖ A0 (added:
    fixed through a Lagrange multiplier) are few, and the solve reduces to a dense system
    over them: with K00 the factorised matrix and Z = K00⁻¹ [K0r, E],

        [K_rr − K_r0 Z_r    −K_r0 Z_d] [u_r]   [b_r − K_r0 z0]
        [   −Eᵀ Z_r          −Eᵀ Z_d ] [ μ ] = [G_d − Eᵀ z0 ],   z0 = K00⁻¹ b0,

    then u = z0 − Z_r u_r − Z_d μ. Each column of Z costs one solve with the factor and
    is kept for later iterations (the missing ones are solved as one block). A backend
    that solves with L alone (CHOLMOD) keeps W = L⁻¹ P [K0r, E] instead, sparse (the
    elimination tree's paths), forms the Schur blocks as Wᵀ D⁻¹ W and u with one full solve:
    a column then costs 0.003–0.3 of a solve, by the route and the mesh. The matrix is
    factorised anew, with the current set as reference, when that is cheaper than the
    missing columns: a cost model compares their number times the measured seconds per
    column (plus the dense solve, k³/3 flops at :data:`DENSE_FLOPS`) with the measured
    seconds of the last factorisation step (masking, factorising, probing and the first
    solves), less the ordering and symbolic analysis a refactorisation with CHOLMOD reuses
    (:class:`contactfem.linalg.Factorizer`); forward columns' cost comes from the backend
    (:meth:`contactfem.linalg._LibraryCholmod.forward_seconds`) with the Schur product
    added. With SuperLU a factorisation costs about 50 columns, with CHOLMOD about 15 full
    ones (below :data:`FORWARD_COLUMNS_FROM` unknowns) or, on a rough profile's graded mesh,
    a Schur update over about 1 000 changed nodes. ``max_changes``, when
    given, replaces the cost model by a fixed bound on the changed nodes. The columns never
    hold more than :data:`COLUMN_BYTES`; a Schur solve that cannot meet the certificate's
    equilibrium bound (``tolerance``) even after iterative refinement also refactorises.
    Every factorisation is probed for singularity
    (:func:`contactfem.linalg.check_factorization`), the probe's solve riding along with
    the first solve of the factor.
    """

    def __init__(self, system: ContactSystem, backend: str, max_changes: int | None = None,
                 tolerance: float = 1e-10, scalable: bool = False) -> None:
        self.tolerance = tolerance
        #: Whether the load and prescribed values will be scaled (:meth:`set_load_factor`):
        #: each factorisation then solves for the load and for the gaps separately.
        self.scalable = scalable
        self.load_factor = 1.0
        self.stiffness = sp.csr_matrix(system.stiffness)
        self.stiffness.sort_indices()
        self.load = np.asarray(system.load, dtype=float)
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        self.backend = backend
        self.max_changes = max_changes
        n = self.stiffness.shape[0]
        self.supported = np.zeros(n, dtype=bool)
        self.fixed_dofs = np.asarray(system.fixed_dofs, dtype=np.int64)
        self.supported[self.fixed_dofs] = True
        self.support_values = np.zeros(n)
        self.support_values[self.fixed_dofs] = system.fixed_values
        self.unit_load, self.unit_support_values = self.load, self.support_values
        k = self.stiffness
        row_lengths = np.diff(k.indptr)
        rows = np.repeat(np.arange(n, dtype=k.indices.dtype), row_lengths)
        on_diagonal = rows == k.indices
        if int(np.count_nonzero(on_diagonal)) != n:
            raise ValueError("the stiffness matrix must store its whole diagonal")
        largest_diagonal = float(np.abs(k.data[on_diagonal]).max(initial=0.0))
        # What is factorised for an active set lives in one pattern, so that CHOLMOD's
        # analysis serves every set: K's without the couplings of the supports, which are
        # fixed for good (the contact normals are masked inside it). Kept as stored zeros,
        # those couplings stay edges of the graph the ordering sees, and the square's
        # factorisation took 1.2-1.5x as long (525k and 2.1M unknowns, CHOLMOD).
        coupling = (np.repeat(self.supported, row_lengths) | self.supported[k.indices]) & ~on_diagonal
        del on_diagonal
        if coupling.any():
            removed = np.zeros(n + 1, dtype=k.indptr.dtype)
            np.cumsum(np.bincount(rows[coupling], minlength=n), out=removed[1:])
            kept = ~coupling
            rows = rows[kept]
            self.pattern = sp.csr_matrix((k.data[kept], k.indices[kept], k.indptr - removed), shape=k.shape)
        else:
            self.pattern = k
        del coupling
        self.entry_rows = rows
        self.diagonal = np.flatnonzero(rows == self.pattern.indices)
        self.longest_row = int(np.diff(self.pattern.indptr).max(initial=0))
        self.factorizations = 0
        self.column_solves = 0
        self.factorizer = Factorizer(
            backend, name="the stiffness matrix with its supports and active contact normals fixed")
        #: Measured seconds of one column solve within a block (None before any solve).
        self.column_seconds: float | None = None
        #: The share of the unknowns a forward column touches (None until measured).
        self.path_share: float | None = None
        self.reference: np.ndarray | None = None
        self.factor = None
        self.checks: list[FactorCheck] = []
        self._solved: np.ndarray | None = None
        self._internal: np.ndarray | None = None
        self._absolute: np.ndarray | None = None
        # |K|, for the round-off bound of the equations: k products and the load and contact force.
        self.absolute = sp.csr_matrix((np.abs(k.data), k.indices, k.indptr), shape=k.shape)
        self.absolute_row_sums = self.absolute @ np.ones(n)
        self.gamma = roundoff_bound(int(np.diff(k.indptr).max(initial=0)) + 2)
        #: The force that strains the body by its whole size (largest stiffness entry times
        #: its size), the force scale of an iterate without any force (see measure); 0 without
        #: a length scale.
        self.force_unit = largest_diagonal * float(system.length_scale) if system.length_scale else 0.0
        self._masked_matrix: sp.csr_matrix | None = None
        self._probe: np.ndarray | None = None  # the singularity probe, restricted to each set's equations
        self._masked_fixed: np.ndarray | None = None
        #: The last changed set's solution, an affine function of the load factor (see _changed_solution).
        self._affine: _AffineSolution | None = None

    def analyse(self) -> None:
        """Order and analyse the pattern every set is factorised in, ahead of the first set
        (:meth:`contactfem.linalg.Factorizer.analyse`): a caller with other work to do first
        may run this in another thread."""
        self.factorizer.analyse(self.pattern)

    def set_load_factor(self, factor: float) -> None:
        """Multiply the system's load and prescribed values by ``factor`` (a step of a load
        path; the solver must be built with ``scalable=True``). The factorisation and the
        cached columns (K00⁻¹ K0j, K00⁻¹ e_j) depend on neither, and the factor's solution
        for the reference set is linear in the factor, f b_load + b_gap, both parts kept
        from the factorisation: a new factor costs no solve."""
        if not self.scalable:
            raise ValueError("set_load_factor needs an ActiveSetSolver built with scalable=True")
        self.load_factor = float(factor)
        self.load = self.load_factor * self.unit_load
        self.support_values = self.load_factor * self.unit_support_values
        self._solved = self._internal = self._absolute = None
        if self.factor is not None:
            self.values = self.support_values.copy()
            self.values[self.normal_dofs[self.reference]] = self.gap[self.reference]
            self.base = self.load_factor * self.base_parts[0] + self.base_parts[1]

    @property
    def free_rows(self) -> np.ndarray:
        """Rows of the residual that are equations (not supports), for residual checks."""
        return ~self.supported

    @property
    def condition(self) -> float:
        """The condition estimate κ̂ of the current factorisation (1 before any)."""
        return self.checks[-1].condition if self.checks else 1.0

    def measure(self, u: np.ndarray, nodal_force: np.ndarray) -> Scales:
        """Force and displacement scales of the iterate (u, Λ = Bμ) and its equilibrium residual."""
        contact = np.zeros(len(u))
        contact[self.normal_dofs] = nodal_force
        # K u of the last solve, when this is its u (it was computed for its acceptance test).
        solved = u is self._solved
        internal = self._internal if solved else self.stiffness @ u
        equations = ~self.supported
        with np.errstate(invalid="ignore", over="ignore"):
            residual = (internal + contact - self.load)[equations]
            absolute = self._absolute if solved else self.absolute @ np.abs(u)
            terms = (absolute + np.abs(self.load) + np.abs(contact))[equations]
            force = (np.abs(self.load).max(initial=0.0) + np.abs(internal).max(initial=0.0)
                     + np.abs(nodal_force).max(initial=0.0))
            roundoff = self.gamma * terms.max(initial=0.0)
            if not np.any(self.load) and force * FORCE_RESOLUTION_LIMIT < roundoff:
                # Nothing loads the body, and its forces (K u, the contact's) are round-off:
                # a block lifted off the plane by its prescribed top, a load path's steps
                # before contact or the one where a node just grazes it. The exact forces
                # are zero, and round-off gives them no scale of their own; they are
                # measured against the force of a strain of ZERO_FORCE_STRAIN over the body,
                # so certified if round-off stays below 1e-3 of that: a rigid motion of up to
                # some 1e3-1e4 body sizes (the rough block lifted by 1e3 of its sizes is, by
                # 1e4 not; the square by 1e4 is, by 1e5 not; a translation by 1e45 never).
                force = max(force, ZERO_FORCE_STRAIN * self.force_unit)
            force = max(force, np.finfo(float).tiny) if np.isfinite(force) else np.inf
            displacement = max(np.abs(u).max(initial=0.0), np.abs(self.gap).max(initial=0.0))
            displacement = max(displacement, np.finfo(float).tiny) if np.isfinite(displacement) else np.inf
            return Scales(
                force=float(force),
                displacement=float(displacement),
                roundoff=float(roundoff / force),
                equilibrium=float(np.abs(residual).max(initial=0.0) / force),
            )

    def normals(self, u: np.ndarray) -> np.ndarray:
        """The normal displacement of every contact node (m,)."""
        return u[self.normal_dofs]

    def non_finite(self, u: np.ndarray) -> int:
        """Entries of u that are not finite."""
        return int(np.count_nonzero(~np.isfinite(u)))

    def certify(self, u: np.ndarray, multiplier: np.ndarray, nodal_force: np.ndarray, scales: Scales,
                tolerance: float) -> Certificate:
        """The :class:`Certificate` of the iterate (u, μ, Λ = Bμ) with its ``scales``."""
        return build_certificate(self.non_finite(u), self.normals(u) - self.gap, multiplier, nodal_force, scales,
                                 tolerance, self.condition)

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (n,) and the reactions (F − K u) at the normal unknowns of ``active``."""
        if self.reference is None or self._refactorize_first(active):
            self._factorize(active)
        u, reaction, accurate = self._solve_refined(active)
        if not accurate and np.any(active != self.reference):
            # The Schur update carries the errors of the reference factorisation, amplified
            # when that reference is much worse conditioned than the current set (a body held
            # by a tiny clamp until the contact takes hold): factorise the current set itself.
            self._factorize(active)
            u, reaction, _ = self._solve_refined(active)
        return u, reaction

    def _refactorize_first(self, active: np.ndarray) -> bool:
        """Whether factorising ``active`` itself is cheaper than the Schur update from the reference."""
        changed = np.flatnonzero(active != self.reference)
        if self.max_changes is not None:
            return len(changed) > self.max_changes
        missing = int((self.slot_of[changed] < 0).sum())
        stored = self.column_count + missing
        # The full columns, or the forward ones' Schur blocks (their store grows to twice
        # the columns each way).
        held = 8 * (2 * stored) ** 2 if self.forward else 8 * stored * self.stiffness.shape[0]
        if held > COLUMN_BYTES:
            return True
        k = len(changed)
        if self.forward and callable(getattr(self.factor, "forward_seconds", None)):
            # The backend knows its routes: a forward column costs 0.004 of a full solve on a
            # rough profile's mesh once the factor is converted, 0.3 through blocked solves.
            columns = self.factor.forward_seconds(missing) if missing else 0.0
        else:
            columns = missing * (self.column_seconds or 0.0)
        update = columns + k**3 / 3 / DENSE_FLOPS
        if self.forward:
            # u itself: one full solve; the Schur blocks Wᵀ W of the missing columns against
            # every stored one, at most a column's length each: its elimination-tree path,
            # sampled before any column is stored. On a long strip (a 100 x 0.5 block under a
            # rough profile, 162 000 unknowns) the paths hold 2.7% of the unknowns, ten times
            # √n, and 611 first columns taken for √n cost 3 s against a 0.13 s refactorisation.
            update += self.solve_seconds
            blocks_per_path = 2.0 * missing * stored / DENSE_FLOPS
            if self.column_count:
                path = self.forward_store.nnz / self.column_count
            else:
                if self.path_share is None and update + blocks_per_path * len(self.free) > self.refactorization_seconds:
                    # Sampling costs a few columns (and, for a supernodal factor, its
                    # conversion): only when even the longest paths could change the answer.
                    self._sample_paths(self.reference)
                path = np.sqrt(len(self.free)) if self.path_share is None else self.path_share * len(self.free)
            update += blocks_per_path * path
        return bool(update > self.refactorization_seconds)

    def _solve_refined(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """u, the reactions at the active normals, and whether the equilibrium residual meets
        the certificate's bound (see :class:`Certificate`)."""
        released = np.flatnonzero(self.reference & ~active)
        added = np.flatnonzero(~self.reference & active)
        u = self._changed_solution(released, added)
        fixed = self.normal_dofs[active]
        # Active normals satisfy u_n = G through the Schur system only to round-off; they
        # are constraints, so they are set exactly first (complementarity holds exactly),
        # and K u and |K| |u| serve the refinement, the reactions and the step's scales.
        u[fixed] = self.gap[active]
        equations = ~self.supported
        equations[fixed] = False
        internal = self.stiffness @ u
        with np.errstate(invalid="ignore", over="ignore"):
            absolute = self.absolute @ np.abs(u)
            target = self.gamma * (absolute + np.abs(self.load))[equations].max(initial=0.0)
        residual = np.where(equations, self.load - internal, 0.0)
        # Iterative refinement down to the round-off bound of the equations, for solves that
        # are not backward stable (SuperLU without pivoting, long chains of Schur updates); it
        # corrects with the same factor and Schur structure while the residual improves (a
        # correction is zero on every fixed unknown, so the active normals stay exact).
        for _ in range(REFINEMENT_STEPS):
            size = np.abs(residual).max(initial=0.0)
            if not size > target:  # also stops on NaN: the certificate reports it
                break
            correction_base = self.factor.solve(np.where(self.free, residual, 0.0))
            correction = self._solve_changed(
                released, added, correction_base, residual, np.zeros_like(u), np.zeros(len(added))
            )
            correction[fixed] = 0.0
            change = self.stiffness @ correction
            trial = np.where(equations, residual - change, 0.0)
            if not np.abs(trial).max(initial=0.0) < size:
                break
            u, residual, internal = u + correction, trial, internal + change
            absolute = None
        with np.errstate(invalid="ignore", over="ignore"):
            if absolute is None:
                absolute = self.absolute @ np.abs(u)
            self._solved, self._internal, self._absolute = u, internal, absolute
            reaction = self.load[fixed] - internal[fixed]
            force = (np.abs(self.load).max(initial=0.0) + np.abs(internal).max(initial=0.0)
                     + np.abs(reaction).max(initial=0.0))
            size = np.abs(self.load - internal)[equations].max(initial=0.0)
            accurate = bool(size <= max(self.tolerance * force, target))
        return u, reaction, accurate

    def _changed_solution(self, released: np.ndarray, added: np.ndarray) -> np.ndarray:
        """u for the reference set with ``released`` freed and ``added`` fixed at their gaps.

        Along a load path (``scalable``) u is affine in the load factor f: the Schur
        system's matrix does not depend on it, and its right-hand side is f (load and
        prescribed values) plus the gaps. So a changed set solved at one factor, u1 at f1,
        and met again at another is solved there for its gaps alone, U0; then u = f U1 + U0
        with U1 = (u1 − U0) / f1 serves every later step with that set at no cost. A zone
        that settles a few nodes off the reference (a square under traction, two nodes at
        its ends) would otherwise pay a Schur solve at every step (a full solve with forward
        columns: 0.04 s against nothing at 131 000 unknowns)."""
        if not self.scalable or (len(released) == 0 and len(added) == 0):
            return self._solve_changed(released, added, self.base, self.load, self.values, self.gap[added])
        key = (self.factorizations, released.tobytes(), added.tobytes())
        known = self._affine if self._affine is not None and self._affine.key == key else None
        if known is not None and known.at_gaps is not None:
            return self.load_factor * known.per_factor + known.at_gaps
        if known is not None and known.factor not in (self.load_factor, 0.0):
            gaps = self.values - self.support_values  # the reference's gaps, no prescribed values
            at_gaps = self._solve_changed(released, added, self.base_parts[1], np.zeros_like(self.load), gaps,
                                          self.gap[added])
            known.per_factor, known.at_gaps = (known.solution - at_gaps) / known.factor, at_gaps
            return self.load_factor * known.per_factor + at_gaps
        u = self._solve_changed(released, added, self.base, self.load, self.values, self.gap[added])
        self._affine = _AffineSolution(key, self.load_factor, u.copy())
        return u

    def _factorize(self, active: np.ndarray) -> None:
        started = time.perf_counter()
        try:
            self._factorize_set(active)
        except SolverError:
            self.reference = self.factor = None  # nothing to update from: the next set factorises
            raise
        # What factorising another set would cost: all of this but the analysis a
        # refactorisation of the pattern reuses (masking, the numeric factorisation, the
        # probe and the first solves count as much as the factorisation itself on meshes
        # with little fill: 0.09 s against 0.05 s at 105 000 unknowns on a rough base).
        self.refactorization_seconds = time.perf_counter() - started - self.factorizer.analysis_seconds[-1]

    def _factorize_set(self, active: np.ndarray) -> None:
        k = self.stiffness
        fixed = self.supported.copy()
        fixed[self.normal_dofs[active]] = True
        self.reference = active.copy()
        self.free = ~fixed
        self.values = self.support_values.copy()
        self.values[self.normal_dofs[active]] = self.gap[active]
        masked = self._masked(fixed)
        name = self.factorizer.name
        self.factor = None  # a CHOLMOD refactorisation overwrites the previous factor
        self.factor = self.factorizer.factorize(masked, check=False)
        self.factorizations += 1
        # The fixed unknowns' values reach the equations through their columns of K, that is
        # (K symmetric) their rows: a few thousand rows instead of a product with all of K.
        fixed_dofs = np.flatnonzero(fixed)
        owner, column, value = self._row_entries(fixed_dofs)
        n = k.shape[0]

        def fixed_columns_times(values: np.ndarray) -> np.ndarray:
            return np.bincount(column, weights=value * values[fixed_dofs][owner], minlength=n)

        if self.scalable:
            # The right-hand side is f (F − K s) + (−K g) on the equations and f s + g on the
            # fixed unknowns (s the unit prescribed values, g the gaps of the reference set).
            gaps = self.values - self.support_values
            parts = [self.unit_load - fixed_columns_times(self.unit_support_values), -fixed_columns_times(gaps)]
            parts[0][fixed] = self.unit_support_values[fixed]
            parts[1][fixed] = gaps[fixed]
        else:
            parts = [self.load - fixed_columns_times(self.values)]
            parts[0][fixed] = self.values[fixed]
        # The singularity probe's solve rides along with the first solve of the factor.
        if self._probe is None:
            self._probe = probe_vector(len(parts[0]))
        probe = np.where(self.free, self._probe, 0.0)
        started = time.perf_counter()
        solved = np.asarray(self.factor.solve(np.column_stack([*parts, probe]))).reshape(len(probe), -1)
        #: Seconds of one full solve with the factor (per right-hand side of this block).
        self.solve_seconds = (time.perf_counter() - started) / solved.shape[1]
        # With a backend that solves with L alone, the Schur complement comes from sparse
        # forward columns (see _slots), which are not capped; what they cost comes from the
        # backend when it can say (forward_seconds: CHOLMOD called directly, which has two
        # routes), else from measured batches, taken until then as a quarter of a full
        # solve (CHOLMOD's blocked sparse solve through cvxopt's interface: 0.24).
        # Along a load path too, from 5 000 unknowns whatever the factor (if the paths are
        # short): a set that two steps share costs no solve from the third on (see
        # _changed_solution), and under a rough profile, where thousands of nodes join along
        # the path, full columns made every step refactorise 5-9 times (20 steps on the
        # rough block refined once, 98 920 unknowns, supernodal: 51 factorisations and
        # 8.1 s, 2 and 4.7 s with forward columns; 10 steps at 104 000 unknowns under a
        # 16 000-point profile: 52 factorisations, 2). The Hertz platen's 20 steps, a few
        # nodes joining at each, took 6.0-6.3 s against 11.9 at 247 000 unknowns, but
        # 1.8-2.1 s against 1.5-1.6 at 62 000.
        forward_from = (SIMPLICIAL_FORWARD_COLUMNS_FROM
                        if getattr(self.factor, "simplicial", False) or self.scalable else FORWARD_COLUMNS_FROM)
        self.forward = callable(getattr(self.factor, "forward_sparse", None)) and k.shape[0] >= forward_from
        #: Whether the forward route stands only while its paths prove short (see _slots).
        self.checks_paths = self.forward and k.shape[0] < FORWARD_COLUMNS_FROM
        if self.checks_paths and self.path_share is not None:
            self.forward = self.path_share <= FORWARD_PATH_SHARE
        if self.column_seconds is None:
            self.column_seconds = self.solve_seconds * (0.25 if self.forward else 1.0)
        if self.scalable:
            self.base_parts = (np.ascontiguousarray(solved[:, 0]), np.ascontiguousarray(solved[:, 1]))
            self.base = self.load_factor * self.base_parts[0] + self.base_parts[1]
        else:
            self.base = np.ascontiguousarray(solved[:, 0])
        # ‖K00‖∞ over its equations: the masked rows keep only their free columns, so each
        # row sum of |K| loses its fixed columns (|K| symmetric: the fixed rows).
        free_sums = self.absolute_row_sums - np.bincount(column, weights=np.abs(value), minlength=n)
        norm = float(free_sums[self.free].max(initial=0.0))
        self.checks.append(check_factorization(masked, self.factor, equations=self.free, probe=probe,
                                               solution=solved[:, -1], norm=norm, name=name))
        # The cached columns, side by side in one Fortran-ordered block (n, capacity), so
        # that products with any subset of them run over contiguous memory without copying
        # the columns out: slot_of[j] is node j's column, −1 when not computed yet.
        self.slot_of = np.full(len(self.normal_dofs), -1)
        self.column_count = 0
        if self.forward:
            self.forward_store = sp.csc_matrix((k.shape[0], 0))
            self.scaled_store = sp.csc_matrix((k.shape[0], 0))
            self.gram_store = np.empty((0, 0))
        elif getattr(self, "column_store", None) is None:
            self.column_store = np.empty((k.shape[0], 0), order="F")

    def _masked(self, fixed: np.ndarray) -> sp.csr_matrix:
        """K in the factorised pattern with the rows and columns of ``fixed`` masked to the
        identity. The matrix is kept: a new set rewrites only the entries in the rows and
        columns whose state changed (a few thousand against millions)."""
        pattern = self.pattern
        if self._masked_matrix is None:
            # The first set: K's values, then the rows and columns of its fixed unknowns (a
            # few thousand) rewritten like a change, instead of a pass over every entry.
            self._masked_matrix = sp.csr_matrix((pattern.data.copy(), pattern.indices, pattern.indptr),
                                                shape=pattern.shape)
            self._masked_fixed = np.zeros_like(fixed)
        changed = np.flatnonzero(fixed != self._masked_fixed)
        indptr = pattern.indptr
        # Finding the changed rows' mirrors scans up to a row's length per entry; once that
        # is the whole pattern's size (a coarse level's first sets change most contact
        # nodes), one pass over every entry costs less (0.1 ms against 0.4 at 1 700 unknowns).
        searched = int((indptr[changed + 1] - indptr[changed]).sum()) * self.longest_row
        entries = self._entries_of(changed) if searched < len(pattern.indices) else None
        if entries is None:
            keep = ~fixed[self.entry_rows] & ~fixed[pattern.indices]
            data = np.where(keep, pattern.data, 0.0)
            data[self.diagonal[fixed]] = 1.0
            self._masked_matrix = sp.csr_matrix((data, pattern.indices, pattern.indptr), shape=pattern.shape)
        else:
            rows, columns = self.entry_rows[entries], pattern.indices[entries]
            data = self._masked_matrix.data
            data[entries] = np.where(~fixed[rows] & ~fixed[columns], pattern.data[entries], 0.0)
            data[entries[(rows == columns) & fixed[rows]]] = 1.0
        self._masked_fixed = fixed.copy()
        return self._masked_matrix

    def _sample_paths(self, active: np.ndarray) -> None:
        """Measure :attr:`path_share` once from the columns of e_j at an even sample of the
        free contact normals (a fixed one's column is e_j itself): for a cost decision that
        needs it before any column is taken (:meth:`_slots` measures the first ones)."""
        free = self.normal_dofs[~active]
        if self.path_share is not None or len(free) == 0:
            return  # measured, or nothing to measure this time
        sample = np.unique(free[np.linspace(0, len(free) - 1, PATH_SAMPLES).astype(np.int64)])
        n = self.stiffness.shape[0]
        rhs = sp.csc_matrix((np.ones(len(sample)), (sample, np.arange(len(sample)))), shape=(n, len(sample)))
        forward, _ = self.factor.forward_sparse(rhs)
        self.path_share = forward.nnz / len(sample) / n

    def _entries_of(self, dofs: np.ndarray) -> np.ndarray | None:
        """Positions in the pattern of every entry in the rows and columns of ``dofs`` (the
        pattern is symmetric: an entry (d, j) of row d has its mirror (j, d) in row j);
        None if some mirror is not stored."""
        indptr, indices = self.pattern.indptr, self.pattern.indices
        in_rows, lengths = _row_positions(indptr, dofs)
        owners = np.repeat(dofs, lengths)
        partners = indices[in_rows]
        # The mirror's offset in its (sorted) row: scan the at most max-row-length offsets.
        lo, length = indptr[partners], indptr[partners + 1] - indptr[partners]
        mirrors = np.full(len(partners), -1, dtype=np.int64)
        for offset in range(int(length.max(initial=0))):
            hit = (offset < length) & (indices[np.minimum(lo + offset, len(indices) - 1)] == owners)
            mirrors[hit] = lo[hit] + offset
        if (mirrors < 0).any():
            return None
        if 64 * len(in_rows) < len(indices):
            return np.unique(np.concatenate([in_rows, mirrors]))
        # Many rows (a first active set of thousands of nodes): marking beats sorting.
        marked = np.zeros(len(indices), dtype=bool)
        marked[in_rows] = True
        marked[mirrors] = True
        return np.flatnonzero(marked)

    def _slots(self, nodes: np.ndarray) -> np.ndarray:
        """The slots of K00⁻¹ K0j (released nodes) and K00⁻¹ e_j (added ones) in the column
        block, computing the missing ones as one block of solves."""
        n = self.stiffness.shape[0]
        missing = np.unique(nodes[self.slot_of[nodes] < 0])
        if len(missing):
            # The right-hand sides are sparse: K0j (the row of a released normal, K being
            # symmetric, restricted to the free unknowns) or e_j (an added one).
            dofs = self.normal_dofs[missing]
            released = self.reference[missing]
            owner, column, value = self._free_entries(*self._row_entries(dofs[released]))
            columns = np.concatenate([np.flatnonzero(released)[owner], np.flatnonzero(~released)])
            entries = np.concatenate([column, dofs[~released]])
            values = np.concatenate([value, np.ones(int((~released).sum()))])
            rhs = sp.csc_matrix((values, (entries, columns)), shape=(n, len(missing)))
            started = time.perf_counter()
            count = self.column_count
            if self.forward:
                forward, scaled = self.factor.forward_sparse(rhs)
                if self.checks_paths and count == 0:
                    # The paths measured on the first columns a step asks for (unless a cost
                    # decision sampled them first), instead of a sample solved for them
                    # alone (0.6 ms of a 17 ms solve at 7 000 unknowns): a long thin mesh's
                    # columns go on as full ones.
                    if self.path_share is None:
                        self.path_share = forward.nnz / len(missing) / n
                    if self.path_share > FORWARD_PATH_SHARE:
                        self.forward = False
                        self.column_store = np.empty((n, 0), order="F")
            if self.forward:
                self.forward_store = sp.hstack([self.forward_store, forward], format="csc")
                # An LLᵀ factor has D = I: the scaled columns are the forward ones, kept once.
                self.scaled_store = (self.forward_store if scaled is forward
                                     else sp.hstack([self.scaled_store, scaled], format="csc"))
                self._extend_gram(forward, count)
            else:
                solved = solve_sparse_columns(self.factor, rhs)
                if count + len(missing) > self.column_store.shape[1]:
                    grown = np.empty((n, max(16, 2 * (count + len(missing)))), order="F")
                    grown[:, :count] = self.column_store[:, :count]
                    self.column_store = grown
                self.column_store[:, count:count + len(missing)] = solved
            # Less what the backend spent once for this factor (a conversion), which later
            # batches do not pay.
            elapsed = time.perf_counter() - started - getattr(self.factor, "setup_seconds", 0.0)
            self.column_seconds = max(elapsed, 0.0) / len(missing)
            self.column_solves += len(missing)
            self.slot_of[missing] = np.arange(count, count + len(missing))
            self.column_count = count + len(missing)
        return self.slot_of[nodes]

    def _extend_gram(self, forward: sp.csc_matrix, count: int) -> None:
        """Add the new forward columns' rows and columns to the Schur blocks of every stored
        column, Wᵀ S (S = D⁻¹ W, W itself for an LLᵀ factor): a step then takes its blocks
        from the store instead of multiplying all its changed nodes' columns again (about
        as many as the last step's, with a handful new)."""
        total = count + forward.shape[1]
        if total > self.gram_store.shape[0]:
            grown = np.empty((2 * total, 2 * total))
            grown[:count, :count] = self.gram_store[:count, :count]
            self.gram_store = grown
        block = _cross(forward, self.scaled_store)  # (new, all): rows count ... total - 1
        block[:, count:] = 0.5 * (block[:, count:] + block[:, count:].T)  # symmetric to round-off
        self.gram_store[count:total, :total] = block
        self.gram_store[:count, count:total] = block[:, :count].T

    def _row_entries(self, dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The entries of K's rows ``dofs``: each one's row (its position in ``dofs``), column
        and value, row by row. Read from K's arrays: a step asks for a few rows, and SciPy's
        row indexing costs more in checks than in copying them."""
        k = self.stiffness
        positions, lengths = _row_positions(k.indptr, dofs)
        return np.repeat(np.arange(len(dofs)), lengths), k.indices[positions], k.data[positions]

    def _free_entries(self, owner: np.ndarray, column: np.ndarray,
                      value: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Entries of :meth:`_row_entries` in the reference set's free columns, without zeros (K_r0)."""
        keep = self.free[column] & (value != 0.0)
        return owner[keep], column[keep], value[keep]

    def _combine(self, slots: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Σ_k weights[k] · column(slots[k]) (n,), one matrix-vector product over the block."""
        if len(slots) == 0:
            return np.zeros(self.stiffness.shape[0])
        if 4 * len(slots) < self.column_count:
            return self.column_store[:, slots] @ weights
        full = np.zeros(self.column_count)
        np.add.at(full, slots, weights)
        return self.column_store[:, :self.column_count] @ full

    def _rows(self, rows: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Entries ``rows`` of the columns ``slots`` (len(rows), len(slots))."""
        return self.column_store[rows][:, slots]

    def _solve_changed(self, released: np.ndarray, added: np.ndarray, base: np.ndarray, load: np.ndarray,
                       fixed_values: np.ndarray, added_values: np.ndarray) -> np.ndarray:
        """Solve for ``load`` with the reference set's fixed unknowns at ``fixed_values``,
        ``released`` freed and ``added`` fixed to ``added_values``; ``base`` is the
        factor's solution for the reference set."""
        if len(released) == 0 and len(added) == 0:
            return base.copy()
        slots = self._slots(np.concatenate([released, added]))
        if self.forward:
            return self._solve_changed_forward(released, added, slots, base, load, fixed_values, added_values)
        s_r, s_d = slots[:len(released)], slots[len(released):]
        dofs_r = self.normal_dofs[released]
        dofs_d = self.normal_dofs[added]
        # Released normals lose their fixed value: b0 gains K_0r G_r, so z0 gains Z_r G_r.
        z0 = base + self._combine(s_r, fixed_values[dofs_r])
        k_r0, k_rr, b_r = self._released_rows(dofs_r, load, fixed_values)
        # K_r0 Z touches only the rows of Z where K_r0 has entries: a few per released node.
        touched = np.unique(k_r0.indices)
        k_touched = k_r0[:, touched]
        top = np.hstack([k_rr - k_touched @ self._rows(touched, s_r), -(k_touched @ self._rows(touched, s_d))])
        bottom = np.hstack([-self._rows(dofs_d, s_r), -self._rows(dofs_d, s_d)])
        rhs = np.concatenate([b_r - k_r0 @ z0, added_values - z0[dofs_d]])
        u_r, mu = self._solve_schur(top, bottom, rhs, len(released), len(added))
        u = z0 - self._combine(slots, np.concatenate([u_r, mu]))
        u[dofs_r] = u_r
        return u

    def _released_rows(self, dofs_r: np.ndarray, load: np.ndarray,
                       fixed_values: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """The released normals' equations: K_r0 (their rows on the reference set's free
        unknowns), K_rr and b_r = F_r − K_r· (fixed values, the released ones now free)."""
        n, r = self.stiffness.shape[0], len(dofs_r)
        owner, column, value = self._row_entries(dofs_r)
        # Each entry's column among the released normals, if it is one (a search among the
        # r of them, not a map over all n unknowns: this runs at every step).
        order = np.argsort(dofs_r)
        in_order = dofs_r[order]
        at = np.minimum(np.searchsorted(in_order, column), r - 1)
        among = in_order[at] == column
        k_rr = np.zeros((r, r))
        k_rr[owner[among], order[at[among]]] = value[among]
        # The released normals' own values are unknowns now: only the others' enter b_r.
        known = np.where(among, 0.0, value * fixed_values[column])
        b_r = load[dofs_r] - np.bincount(owner, weights=known, minlength=r)
        owner, column, value = self._free_entries(owner, column, value)
        starts = np.zeros(r + 1, dtype=np.int64)
        np.cumsum(np.bincount(owner, minlength=r), out=starts[1:])
        return sp.csr_matrix((value, column, starts), shape=(r, n)), k_rr, b_r

    @staticmethod
    def _solve_schur(top: np.ndarray, bottom: np.ndarray, rhs: np.ndarray, released: int,
                     added: int) -> tuple[np.ndarray, np.ndarray]:
        """The Schur system [top; bottom] [u_r; μ] = rhs of ``released`` freed and ``added``
        fixed normals, split into u_r and μ."""
        try:
            solution = np.linalg.solve(np.vstack([top, bottom]), rhs)
        except np.linalg.LinAlgError as error:
            raise SolverError(
                f"the stiffness matrix is singular once {released} contact nodes are released and "
                f"{added} added (Schur complement: {error}); is part of the body held only by contact?"
            ) from error
        return solution[:released], solution[released:]

    def _solve_changed_forward(self, released: np.ndarray, added: np.ndarray, slots: np.ndarray, base: np.ndarray,
                               load: np.ndarray, fixed_values: np.ndarray, added_values: np.ndarray) -> np.ndarray:
        """:meth:`_solve_changed` from sparse forward columns: with C = [K0r, E_d] (the
        released nodes' columns of K on the free unknowns, the added nodes' unit vectors)
        and K00 = Pᵀ L D Lᵀ P, Cᵀ K00⁻¹ C = Wᵀ D⁻¹ W for W = L⁻¹ P C, whose columns are
        sparse; the Schur system is the same, and u = z0 − K00⁻¹ C [u_r; μ] costs one full
        solve instead of a product with full-length columns."""
        r = len(released)
        dofs_r = self.normal_dofs[released]
        dofs_d = self.normal_dofs[added]
        gram = self.gram_store[np.ix_(slots, slots)]
        released_values = fixed_values[dofs_r]
        k_r0, k_rr, b_r = self._released_rows(dofs_r, load, fixed_values)
        # z0 = base + K00⁻¹ K0r G_r: the released normals lose their fixed values.
        top = np.hstack([k_rr - gram[:r, :r], -gram[:r, r:]])
        bottom = np.hstack([-gram[r:, :r], -gram[r:, r:]])
        rhs = np.concatenate([b_r - (k_r0 @ base + gram[:r, :r] @ released_values),
                              added_values - (base[dofs_d] + gram[r:, :r] @ released_values)])
        u_r, mu = self._solve_schur(top, bottom, rhs, r, len(added))
        combined = k_r0.T @ (released_values - u_r)
        combined[dofs_d] -= mu
        u = base + np.asarray(self.factor.solve(combined), dtype=float).reshape(len(base))
        u[dofs_r] = u_r
        return u


@dataclass(eq=False)
class _AffineSolution:
    """A changed set's solution along a load path (:meth:`ActiveSetSolver._changed_solution`):
    ``solution`` at ``factor``, and once met at a second factor u = f ``per_factor`` + ``at_gaps``.
    ``key`` names the reference factorisation and the change."""

    key: tuple
    factor: float
    solution: np.ndarray
    per_factor: np.ndarray | None = None
    at_gaps: np.ndarray | None = None


class _ModeHolder:
    """Completes an active set so that it holds the free rigid motions: K with the active
    normals fixed is singular unless the motions' normal components at the active nodes
    have full rank. Added nodes are the kernel's own candidates (largest indicator); one
    that should not be active fails the certificate instead of changing the answer."""

    def __init__(self, system: ContactSystem) -> None:
        modes = np.asarray(system.free_modes, dtype=float)
        self.normal = modes[np.asarray(system.normal_dofs, dtype=np.int64)]  # (m, j)
        self.gap = np.asarray(system.gap, dtype=float)
        self.rank = int(self.normal.shape[1])
        load = np.asarray(system.load, dtype=float) @ modes
        # Each motion oriented the way the load pushes it.
        self.pushed = self.normal * np.where(load < 0, -1.0, 1.0)
        self.scale = float(np.abs(self.normal).max(initial=0.0))

    def rank_of(self, active: np.ndarray) -> int:
        if not active.any():
            return 0
        values = np.linalg.svd(self.normal[active], compute_uv=False)
        return int((values > 1e-10 * self.scale).sum())

    def holds(self, active: np.ndarray) -> bool:
        return self.rank_of(active) >= self.rank

    def first_touch(self) -> np.ndarray:
        """Priority of each node by how soon the pushed motions close its gap (larger: sooner)."""
        along = self.pushed.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(along > 1e-10 * self.scale, -self.gap / along, -np.inf)

    def hold(self, active: np.ndarray, priority: np.ndarray) -> np.ndarray:
        if self.holds(active):
            return active
        held = active.copy()
        candidates = np.flatnonzero(~active)
        # Nodes that never close come last, in order of gap.
        order = np.lexsort((self.gap[candidates], -priority[candidates]))
        rank = self.rank_of(held)
        for node in candidates[order]:
            trial = held.copy()
            trial[node] = True
            if self.rank_of(trial) > rank:
                held, rank = trial, rank + 1
                if rank >= self.rank:
                    break
        return held


def _mass_solver(mass: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """Solve B μ = Λ: a division for a diagonal B, a sparse LU otherwise (B is small)."""
    diagonal = mass.diagonal()
    # Every nonzero on the diagonal: no off-diagonal one (a subtraction cost 20 times more).
    if mass.count_nonzero() == np.count_nonzero(diagonal):
        return lambda rhs: rhs / diagonal
    lu = spla.splu(mass)
    return lu.solve
