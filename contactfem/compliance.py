"""ΓC's compliance modelled by the elastic half-plane's: where the active set iteration goes next.

Newton's update of the active set (the primal–dual active set iteration) decides each
node by its own sign test. From a start far from the answer, a rough base pushed onto
the plane, it presses in every node the free body would put inside the obstacle (824 of
1 000, of which 171 stay), and then releases them a cascade at a time: nine steps and
three factorisations, because a node's force depends on which of its neighbours carry
load, which the sign test does not know.

Near ΓC a body answers like a half-plane: a line load P lowers the surface at distance r
by (2 / π E*) P ln(R / r) plus a constant (Flamant), with R of the order of the distance
to where the body is held (its depth). :class:`HalfPlaneModel` solves, after each solve,
the contact problem of that model anchored on the solved iterate,

    slack' = slack − C (Λ − force),   Λ ≥ 0,  slack' ≤ 0,  Λ slack' = 0,

and proposes its set. (Its columns take ln(R / r)₊ at the nodes, the far-field form of
:func:`half_plane_compliance`'s mean over each node's share, which the correction of a
coarse prediction uses on its sparse band: dense, the means cost ten times as much.) The
next solve measures the true answer for that set, so the
model's error is corrected at every step and only decides how many steps there are; the
kernel's own sign test still decides when the set has settled. On the rough block of
1 000 segments the model's first proposal missed 16 of 1 000 nodes (Newton's update 653)
and the solve took three steps. Where the contact nodes lie on a grid (a profile of
heights at equal steps, or one a coarser level decimated), C is Toeplitz in the grid
index and its products FFTs (:class:`EvenCompliance`): the first proposal then starts
from a few projected conjugate gradient steps on the whole boundary instead of pushing
the free body in stages. The sets of one iteration differ by a few nodes, and are solved
from one factor (:class:`_SetSolves`). Beyond :data:`EVEN_MODEL_NODES` (3 000 on a grid)
a coarser level's prediction costs less than the model's dense blocks.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import fft as sp_fft
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.linalg.blas import dgemv

from contactfem.assembly import Elasticity
from contactfem.discretize import ContactBoundary

#: The model is offered to bodies at least this deep along the obstacle's normal, as a
#: share of their contact nodes' span along it. A half-plane answers a load spread over
#: less than its depth; a strip 1 x 0.02 resting on its length bends instead, and there
#: the model proposed what Newton's update did while stopping the kernel's extrapolation
#: of its creeping zone edge.
MIN_DEPTH_SHARE = 0.25
#: Contact nodes up to which a cold start with the model is preferred to a coarser level's
#: prediction (:mod:`contactfem.solve`). Measured (solve ms, cold with the model against
#: sequenced) with its columns of logs: rough base of 1 000 segments 19-21 against 31; of
#: 2 000, 38-56 against 41; the rough rim (668 nodes) 21 against 30; the Hertz disk (1 551) 55 against 68; its
#: quarter (776) 28 against 41.
MODEL_NODES = 1_600
#: The same on nodes of a grid, whose model gathers its blocks and multiplies by FFTs
#: (:class:`EvenCompliance`), its set solves updating one factor and its first proposal
#: made beside the pattern's analysis, with one BLAS thread (:mod:`contactfem.threads`):
#: the rough base of 3 000 segments 52-62 ms cold with the model against 60-70 sequenced
#: (fastest of 7, in turns); of 4 000, 74-85 against 71-80; of 6 000, 150 against 102.
EVEN_MODEL_NODES = 3_000
#: A cold start with the model replaces a coarser level only on bodies with at most this
#: many unknowns per contact node: meshes graded onto ΓC, whose coarser level keeps much of
#: the boundary (rough profiles 7, the Hertz disks and the rough rim 19-21). Where the
#: interior dominates, the coarser level costs a sixteenth of the fine solve and predicts
#: the set to a node or two: the square of 1 024 cells a side (2 048 unknowns per contact
#: node), started cold with the model, took 6 steps and 2.5 linear solves against one step
#: and 1.1-1.3 from its coarser level.
MODEL_UNKNOWNS_PER_NODE = 40
#: The largest set the model factorises (dense, n³ / 3): beyond, it proposes nothing.
MODEL_BLOCK = 600
#: Stages in which the first proposal, from the free body (no force anywhere), is pushed
#: in: each stage's set starts the next one's iteration, so that the model's factorised
#: blocks stay near the answer's size instead of every node the free body would press in.
FREE_BODY_STAGES = 4
#: Steps of the model's own active set iteration at each stage or proposal: its set after
#: them is proposed, settled or not (it settled in 2-9; the proposal is only where the
#: next solve starts, and five steps cost less than the ones after them saved).
MODEL_ITERATIONS = 5
#: Compliance columns the model may hold (each is one per contact node): beyond, it
#: proposes nothing and Newton's update goes on.
MODEL_COLUMN_ENTRIES = 8_000_000
#: Contact nodes count as equally spaced along the obstacle when no spacing differs from
#: their mean by more than this share: a profile given as heights at equal steps, or any
#: polygon whose contact vertices are. C is then Toeplitz in the node index (up to its
#: diagonal, the mean over each node's own share) and its products cost two FFTs.
EVEN_SPACING = 1e-6
#: Contact nodes also count as on a grid when every spacing is a whole multiple of the
#: least one over 1, 2, ... this (a profile of 3 999 segments decimated by four keeps
#: spacings of 4 h and, at its end, 3 h), on a grid of at most :data:`GRID_GROWTH` times
#: as many points as nodes (each product is an FFT of the grid's length).
GRID_DIVISORS = 8
GRID_GROWTH = 8
#: On equally spaced nodes the first proposal starts its active set iteration from the
#: set of a few steps of projected conjugate gradients (Polonsky and Keer's iteration for
#: the half-space, without its load balance: here the push is given) on the whole
#: boundary, instead of the free body's stages: stopped when an iteration changes the
#: forces by less than :data:`NEAR_TOLERANCE` of their sum, or after
#: :data:`NEAR_ITERATIONS`. On the rough base of 1 000 segments: 18 iterations, 59 of
#: 1 000 nodes off the model's own answer, which the active set iteration then reaches:
#: the first proposal in 2.7 ms instead of the stages' 6.1; of 2 000: 5.8 against 16 ms.
NEAR_TOLERANCE = 1e-2
NEAR_ITERATIONS = 100


def plane_strain_modulus(law: Elasticity) -> float:
    """E* of the 2D law: E / (1 − ν²) in plane strain, E in plane stress (4μ(λ+μ)/(λ+2μ)
    with the λ the 2D law holds)."""
    return 4.0 * law.mu * (law.lam + law.mu) / (law.lam + 2.0 * law.mu)


def half_plane_model(boundary: ContactBoundary, law: Elasticity, points: np.ndarray) -> "HalfPlaneModel | None":
    """The model of ``boundary``'s compliance for a body of ``law`` whose mesh has these
    ``points``, with R its depth along the obstacle's normal; None for a body shallower
    than :data:`MIN_DEPTH_SHARE` of its contact nodes' span (a strip bends instead) or
    with no contact node."""
    if len(boundary.abscissa) == 0:
        return None
    depth = float(np.ptp(np.asarray(points) @ boundary.normal))
    span = float(np.ptp(boundary.abscissa))
    if not depth > 0 or depth < MIN_DEPTH_SHARE * span:
        return None
    return HalfPlaneModel(boundary.abscissa, boundary.masses.lumped, boundary.gap, plane_strain_modulus(law), depth)


class EvenCompliance:
    """C of :class:`HalfPlaneModel` on nodes of a common grid (``abscissa`` sorted, node i
    at s₀ + k_i h for integers k_i): equally spaced nodes (k_i = i), or a subset of such (a
    profile a coarser level decimated, every fourth node and the last). Its off-diagonal
    ln(R / |k_i − k_j| h)₊ / π E* depends on k_i − k_j alone, so C x is a convolution on
    the grid, computed with FFTs of the Toeplitz part's circulant embedding (length ≥
    g + w for g grid points and w the last offset within R), plus each node's own
    diagonal less the Toeplitz one."""

    def __init__(self, grid: np.ndarray, spacing: float, share: np.ndarray, reach: float, scale: float):
        points = int(grid[-1]) + 1
        offsets = np.arange(1, points) * spacing
        toeplitz = np.empty(points)
        toeplitz[1:] = np.maximum(np.log(reach / offsets), 0.0)
        toeplitz[0] = np.log(2.0 * reach / spacing) + 1.0
        # Offsets of R or more couple nothing: a kernel of half-width w (its last nonzero
        # offset) needs a circulant of g + w points, not 2 g − 1 (a block as deep as half
        # its contact zone is wide: 1.5 g, and products 0.6x the time at 2 000 nodes).
        coupled = np.flatnonzero(toeplitz[1:] > 0)
        width = int(coupled[-1]) + 1 if len(coupled) else 0
        self.length = sp_fft.next_fast_len(points + width, real=True)
        embedded = np.zeros(self.length)
        embedded[:width + 1] = toeplitz[:width + 1]
        embedded[self.length - width:] = toeplitz[width:0:-1]
        # The embedding is symmetric: its spectrum is real.
        self.spectrum = sp_fft.rfft(scale * embedded).real
        self.toeplitz = scale * toeplitz
        self.diagonal = scale * (np.log(2.0 * reach / share) + 1.0)
        self.correction = self.diagonal - self.toeplitz[0]
        self.grid = grid
        self.points = points
        self.size = len(grid)

    @classmethod
    def of(cls, abscissa: np.ndarray, share: np.ndarray, reach: float, scale: float) -> "EvenCompliance | None":
        """The grid form of these nodes' C, or None: every spacing must be a whole multiple of
        the grid's h (the least spacing over 1 to :data:`GRID_DIVISORS`) within
        :data:`EVEN_SPACING` of h, on a grid of at most :data:`GRID_GROWTH` times the nodes
        (or there are fewer than 2 nodes)."""
        if len(abscissa) < 2:
            return None
        spacings = np.diff(abscissa)
        least = float(spacings.min())
        if not least > 0:
            return None
        for divisor in range(1, GRID_DIVISORS + 1):
            spacing = least / divisor
            steps = np.rint(spacings / spacing)
            if np.abs(spacings - steps * spacing).max() > EVEN_SPACING * spacing:
                continue
            if steps.sum() + 1 > GRID_GROWTH * len(abscissa):
                return None
            grid = np.concatenate([[0], np.cumsum(steps)]).astype(np.int64)
            # Their mean spacing, not the least one: round-off spread over the whole span.
            return cls(grid, float((abscissa[-1] - abscissa[0]) / grid[-1]), share, reach, scale)
        return None

    def block(self, rows: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """C[rows][:, columns] (``columns`` default: ``rows``), gathered from the Toeplitz column."""
        grid = self.grid
        if columns is None:
            block = self.toeplitz[np.abs(grid[rows][:, None] - grid[rows][None, :])]
            block.flat[::len(rows) + 1] = self.diagonal[rows]
            return block
        block = self.toeplitz[np.abs(grid[rows][:, None] - grid[columns][None, :])]
        same_row, same_column = np.nonzero(rows[:, None] == columns[None, :])
        block[same_row, same_column] = self.diagonal[rows[same_row]]
        return block

    def __matmul__(self, forces: np.ndarray) -> np.ndarray:
        if self.points == self.size:  # every grid point a node
            spread = sp_fft.irfft(sp_fft.rfft(forces, self.length) * self.spectrum, self.length)
            return spread[:self.size] + self.correction * forces
        on_grid = np.zeros(self.points)
        on_grid[self.grid] = forces
        spread = sp_fft.irfft(sp_fft.rfft(on_grid, self.length) * self.spectrum, self.length)
        return spread[self.grid] + self.correction * forces

    def near_contact(self, free: np.ndarray) -> np.ndarray:
        """Nodes near the contact set of Λ ≥ 0, free − C Λ ≤ 0, Λ (free − C Λ) = 0: a few
        iterations of projected conjugate gradients on min ½ Λᵀ C Λ − freeᵀ Λ over Λ ≥ 0
        (see :data:`NEAR_TOLERANCE`). A node whose force the step would make negative
        leaves the set; one without force that the current forces leave inside the
        obstacle joins it, and the directions restart."""
        forces = np.maximum(free, 0.0) / self.diagonal
        direction = np.zeros_like(forces)
        conjugate = False
        previous = 1.0
        for _ in range(NEAR_ITERATIONS):
            gradient = self @ forces - free  # minus the slack the forces leave
            carried = forces > 0
            if not carried.any():
                break
            steepest = np.where(carried, gradient, 0.0)
            norm = float(steepest @ steepest)
            direction = steepest + (norm / previous) * direction if conjugate else steepest
            direction[~carried] = 0.0
            previous = norm
            curvature = float(direction @ (self @ direction))
            if not curvature > 0:
                break
            step = float(steepest @ direction) / curvature
            before = forces
            forces = np.maximum(forces - step * direction, 0.0)
            inside = (forces == 0) & (gradient < 0)
            conjugate = not inside.any()
            forces[inside] -= step * gradient[inside]
            if np.abs(forces - before).sum() <= NEAR_TOLERANCE * forces.sum():
                break
        return forces > 0


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


class HalfPlaneModel:
    """The half-plane's compliance between the contact nodes (``abscissa`` sorted along the
    obstacle, each node's ``share`` of ΓC), C_ij = (1 / π E*) ln(R / |s_i − s_j|)₊ and on
    the diagonal the mean of that over the node's own share; ``gap`` the nodes' initial
    gaps. On equally spaced nodes its ``even`` form (:class:`EvenCompliance`) gives its
    blocks, its products and the first proposal's start; elsewhere its columns are
    computed when an iteration needs them and kept.

    Called with a solved set, its slack d − G and its nodal forces, it returns the set of
    the model's contact problem anchored there (see the module), or None where it has
    none: its block is not positive definite, larger than :data:`MODEL_BLOCK`, or its
    columns would hold more than :data:`MODEL_COLUMN_ENTRIES`.
    """

    def __init__(self, abscissa: np.ndarray, share: np.ndarray, gap: np.ndarray, modulus: float, reach: float):
        self.abscissa = np.asarray(abscissa, dtype=float)
        self.share = np.asarray(share, dtype=float)
        self.gap = np.asarray(gap, dtype=float)
        self.reach = float(reach)
        self.scale = 1.0 / (np.pi * float(modulus))
        m = len(self.abscissa)
        self.slot = np.full(m, -1, dtype=np.int64)  # node -> its column in ``columns``, or -1
        self.columns = np.zeros((m, 0), order="F")  # the first ``held`` are C's columns of the nodes in ``slot``
        self.held = 0
        self.even = EvenCompliance.of(self.abscissa, self.share, self.reach, self.scale)
        self.sets = _SetSolves(self._block)

    def __call__(self, active: np.ndarray, slack: np.ndarray, force: np.ndarray) -> np.ndarray | None:
        active = np.asarray(active, dtype=bool)
        slack = np.asarray(slack, dtype=float)
        force = np.where(active, np.asarray(force, dtype=float), 0.0)
        try:
            loaded = np.flatnonzero(force)
            free = slack + self._times(loaded, force[loaded])  # the slack with no force at all
            if not active.any():
                if self.even is not None:
                    return self._settle(free, self.even.near_contact(free))
                # From the free body: the same push in stages (a linear body's free
                # displacement scales with its load), each started from the last's set.
                displacement = free + self.gap
                settled = active
                for stage in range(1, FREE_BODY_STAGES + 1):
                    settled = self._settle(stage / FREE_BODY_STAGES * displacement - self.gap, settled)
                return settled
            # From Newton's update of the solved set (the model's own problem has one
            # answer; this start is nearer it than the solved set's nodes that the free
            # body presses in: 2-4 set solves a proposal instead of 3-5 on a rough base).
            return self._settle(free, np.where(active, force > 0, slack > 0))
        except (LinAlgError, MemoryError):
            return None

    def replaces_coarser_level(self, unknowns: int) -> bool:
        """Whether a cold start with this model costs less than a coarser level's prediction
        for a body of ``unknowns``: for at most :data:`MODEL_NODES` contact nodes,
        :data:`EVEN_MODEL_NODES` on a grid, and at most :data:`MODEL_UNKNOWNS_PER_NODE`
        unknowns per contact node."""
        nodes = len(self.abscissa)
        if unknowns > MODEL_UNKNOWNS_PER_NODE * nodes:
            return False
        return nodes <= (EVEN_MODEL_NODES if self.even is not None else MODEL_NODES)

    def _settle(self, free: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The model's active set iteration on Λ ≥ 0, free − C Λ ≤ 0 from ``start``: its
        set after at most :data:`MODEL_ITERATIONS` steps."""
        current = start
        for _ in range(MODEL_ITERATIONS):
            on = np.flatnonzero(current)
            if len(on) > MODEL_BLOCK:
                raise MemoryError("the half-plane model's block")
            forces = self.sets.solve(on, free) if len(on) else np.zeros(0)
            slack = free - self._times(on, forces)
            updated = slack > 0
            updated[on] = forces > 0
            if np.array_equal(updated, current):
                return current
            current = updated
        return current

    def _block(self, rows: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """C[rows][:, columns] (default: the square block of ``rows``): from the even form,
        or from the columns' columns (held now)."""
        if self.even is not None:
            return self.even.block(rows, columns)
        columns = rows if columns is None else columns
        self._hold(columns)
        return self.columns[np.ix_(rows, self.slot[columns])]

    def _times(self, nodes: np.ndarray, forces: np.ndarray) -> np.ndarray:
        """C[:, nodes] @ forces: by FFTs on the even form, else from the nodes' columns."""
        if not len(nodes):
            return np.zeros(len(self.abscissa))
        if self.even is not None:
            spread = np.zeros(len(self.abscissa))
            spread[nodes] = forces
            return self.even @ spread
        self._hold(nodes)
        spread = np.zeros(self.held)
        spread[self.slot[nodes]] = forces
        # SciPy's BLAS, as the factorisations use: numpy's own is a second thread pool, and
        # the two busy-waiting on the same cores made each call 5-10 times slower.
        return dgemv(1.0, self.columns[:, :self.held], spread)

    def _hold(self, nodes: np.ndarray) -> None:
        """Compute C's columns of the ``nodes`` not held yet."""
        missing = nodes[self.slot[nodes] < 0]
        if not len(missing):
            return
        m = len(self.abscissa)
        needed = self.held + len(missing)
        if needed > self.columns.shape[1]:
            if needed * m > MODEL_COLUMN_ENTRIES:
                raise MemoryError("the half-plane model's columns")
            grown = np.zeros((m, min(max(2 * needed, 64), max(MODEL_COLUMN_ENTRIES // max(m, 1), needed))), order="F")
            grown[:, :self.held] = self.columns[:, :self.held]
            self.columns = grown
        k = np.arange(len(missing))
        distance = np.abs(self.abscissa[:, None] - self.abscissa[missing][None, :])
        distance[missing, k] = self.reach  # the diagonal, set below
        block = np.log(self.reach / distance)
        np.maximum(block, 0.0, out=block)
        # A node's own entry: the mean of ln(R / |t|) over its share, ln(2R / w) + 1.
        block[missing, k] = np.log(2.0 * self.reach / self.share[missing]) + 1.0
        block *= self.scale
        self.columns[:, self.held:needed] = block
        self.slot[missing] = self.held + k
        self.held = needed


class _SetSolves:
    """Solves C[S, S] x = b[S] for the sets S of an active set iteration, which differ from
    one another by a few nodes, with one Cholesky factor of a base set S0 (``block(rows,
    columns)`` gives C's blocks). For S = S0 ∖ R ∪ A the system is solved on S0 ∪ A with
    x_R = 0 held by multipliers μ: with Z = C00⁻¹ C0A, Y = C00⁻¹ E_R and z = C00⁻¹ b0,

        [CAA − C0Aᵀ Z   −Z_Rᵀ] [x_A]   [b_A − C0Aᵀ z]
        [    −Z_R        −Y_R] [ μ ] = [    −z_R    ],   x0 = z − Z x_A − Y μ,

    a dense system of |A| + |R| unknowns and (1 + |A| + |R|) solves with the factor:
    O(n² (|A| + |R|)) instead of n³ / 3. The base is refactorised when the changes outgrow
    :data:`REBASE_SHARE` of it (the updates would then cost about as much)."""

    #: The share of the base set that added and removed nodes may reach before a new factor.
    REBASE_SHARE = 0.125

    def __init__(self, block):
        self.block = block
        self.base = np.zeros(0, dtype=np.int64)
        self.factor = None

    def solve(self, on: np.ndarray, free: np.ndarray) -> np.ndarray:
        """x on the sorted nodes ``on``, C[on, on] x = free[on]."""
        base = self.base
        within = np.isin(on, base, assume_unique=True)  # on's nodes the base has
        kept = np.isin(base, on, assume_unique=True)  # the base's nodes still on
        added, removed_at = on[~within], np.flatnonzero(~kept)  # removed: positions in the base
        a, changes = len(added), len(added) + len(removed_at)
        if self.factor is None or changes > max(4, self.REBASE_SHARE * len(base)):
            self.base = on
            self.factor = cho_factor(self.block(on), overwrite_a=True, check_finite=False)
            return cho_solve(self.factor, free[on], check_finite=False)
        b0 = free[base]
        b0[removed_at] = 0.0  # held at zero by μ: its own entry is immaterial
        coupling = self.block(base, added)  # C0A
        right = np.zeros((len(base), 1 + changes))
        right[:, 0] = b0
        right[:, 1:1 + a] = coupling
        right[removed_at, 1 + a + np.arange(len(removed_at))] = 1.0
        solved = cho_solve(self.factor, right, check_finite=False)
        z, z_added, y_removed = solved[:, 0], solved[:, 1:1 + a], solved[:, 1 + a:]
        bordered = np.empty((changes, changes))
        bordered[:a, :a] = self.block(added) - coupling.T @ z_added
        bordered[a:, :a] = -z_added[removed_at]
        bordered[:a, a:] = bordered[a:, :a].T
        bordered[a:, a:] = -y_removed[removed_at]
        rhs = np.concatenate([free[added] - coupling.T @ z, -z[removed_at]])
        unknowns = np.linalg.solve(bordered, rhs)
        x_added, multipliers = unknowns[:a], unknowns[a:]
        x_base = z - z_added @ x_added - y_removed @ multipliers
        # Back onto the sorted set: the base's kept nodes and the added ones.
        forces = np.empty(len(on))
        forces[within] = x_base[kept]
        forces[~within] = x_added
        return forces
