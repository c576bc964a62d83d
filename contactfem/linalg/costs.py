"""Counted costs of the sparse factorisations, and the one place the rates that turn them
into seconds live.

Nothing in :mod:`contactfem.linalg` reads a clock: what a factorisation, a solve or a
forward route costs is *counted* (its factor's stored entries, the flops of its numeric
factorisation from the factor's column counts, the columns asked for, the factor entries
on the elimination-tree paths those columns reached) and, where a choice or a caller
needs seconds, divided by the rates below. The rates were measured once, on a 2-core
machine (benchmarks/linalg_costs.py, benchmarks/results/linalg_costs.json); on another
machine every modelled figure scales by about the same factor, which leaves every choice
made by comparing two of them unchanged. The same counts always give the same choices
and the same modelled seconds, whatever the machine's load.

Every figure named ``*_seconds`` in the package is such a *modelled* second: counted
work divided by a rate here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np


@dataclass(frozen=True)
class FactorCost:
    """The counted size of one factorisation.

    Attributes
    ----------
    size : int
        Unknowns (the matrix's order).
    entries : int
        Stored entries of the factor(s): nnz(L) for a Cholesky factor (a supernodal one's
        stored block entries, explicit zeros included), nnz(L) + nnz(U) for SuperLU,
        Pardiso's own report for Pardiso.
    flops : float
        Flops of the numeric factorisation: Σ c_j² over the column counts c_j of a Cholesky
        factor; Σ (c_j − 1) (1 + 2 (r_j − 1)) over L's column counts c_j and U's row counts
        r_j for SuperLU; an estimate for Pardiso (see :func:`estimated_flops`).
    kind : str
        Which rates apply (a key of :data:`RATES`): ``cholmod-supernodal``,
        ``cholmod-simplicial``, ``superlu`` or ``pardiso``.
    matrix_entries : int
        Stored entries of the matrix factorised (both triangles), which the ordering reads.
    """

    size: int
    entries: int
    flops: float
    kind: str = "cholmod-supernodal"
    matrix_entries: int = 0

    @property
    def fill(self) -> float:
        """Factor entries per column."""
        return self.entries / max(self.size, 1)


def cholesky_flops(column_counts: np.ndarray) -> float:
    """Σ c_j²: the numeric factorisation's flops for a Cholesky factor with column counts
    c_j (diagonal included), the standard count up to lower-order terms."""
    counts = np.asarray(column_counts, dtype=np.float64)
    return float(np.dot(counts, counts))


def lu_flops(l_column_counts: np.ndarray, u_row_counts: np.ndarray) -> float:
    """Σ (c_j − 1) (1 + 2 (r_j − 1)): an LU factorisation's flops from L's column counts c_j
    and U's row counts r_j (diagonals included): the column's divisions, then its
    rank-one update of the trailing matrix."""
    below = np.asarray(l_column_counts, dtype=np.float64) - 1.0
    right = np.asarray(u_row_counts, dtype=np.float64) - 1.0
    return float(np.dot(below, 1.0 + 2.0 * right))


#: Σ c_j² n / (Σ c_j)² for CHOLMOD's (AMD) factors of the kernel's matrices: how far the
#: column counts spread beyond their mean (1 if all were equal). Measured 1.3-1.4 on the
#: rough profile's graded meshes (7 000-418 000 unknowns) and 1.5-4.2 on the square
#: (2 000-526 000), growing with the mesh (benchmarks/results/linalg_costs.json, "spread").
COLUMN_COUNT_SPREAD = 2.5


def analysis_work(matrix_entries: int) -> float:
    """The ordering and symbolic analysis's counted work: m log₂ m for m stored matrix
    entries (its time per entry grew 2x from 25 000 to 6 million entries, as the logarithm
    does; the square's and the rough profile's matrices of the same size took the same)."""
    m = max(float(matrix_entries), 2.0)
    return m * math.log2(m)


def estimated_flops(entries: int, size: int) -> float:
    """Flops of a Cholesky-type factorisation whose column counts are not known, only
    their sum ``entries`` over ``size`` columns: :data:`COLUMN_COUNT_SPREAD` (Σ c)² / n,
    the mean column's square times the spread CHOLMOD's factors of these matrices show."""
    return COLUMN_COUNT_SPREAD * float(entries) ** 2 / max(size, 1)


@dataclass(frozen=True)
class Rates:
    """How fast one kind of factor does each operation (see :data:`RATES` for the values
    and where they were measured). Entries are the factor's stored entries
    (:attr:`FactorCost.entries`), flops its numeric factorisation's."""

    #: Flops per second of the numeric factorisation.
    factor_flops: float
    #: Factor entries per second of the numeric factorisation's work besides its flops
    #: (allocation, scatter, the simplicial kinds' per-entry bookkeeping).
    factor_entries: float
    #: Factor entries per second of a full solve A x = b with one right-hand side.
    solve_entries: float
    #: Factor entries per second of each further right-hand side of a block solved at once
    #: (the first costs a solve of one).
    block_solve_entries: float
    #: :func:`analysis_work` per second of the ordering and symbolic analysis (the kinds
    #: that keep an analysis: CHOLMOD's).
    analysis_work: float = math.nan
    #: Factor entries per second per column of the blocked sparse forward solve
    #: (W = L⁻¹ P B through CHOLMOD's sparse solve in dense blocks).
    blocked_forward_entries: float = math.nan
    #: Reached factor entries (on the column's elimination-tree path) per second of the
    #: pattern solve (CHOLMOD's solve with the right-hand side's pattern).
    pattern_entries: float = math.nan
    #: Seconds per column of the pattern solve whatever it reaches (the call, the Python
    #: that gathers its result).
    pattern_column_seconds: float = math.nan
    #: Stored entries per second of the conversion of a supernodal factor to a simplicial
    #: one (which the first pattern solve does).
    conversion_entries: float = math.nan
    #: Reached factor entries per second of a block of forward columns through the
    #: supernodal blocks (:mod:`contactfem.linalg.supernodal`) for its first right-hand side,
    #: for each further one, and seconds per reached supernode (its Python and BLAS calls).
    supernodal_entries: float = math.nan
    supernodal_block_entries: float = math.nan
    supernode_seconds: float = math.nan


#: The rates of each kind of factor. Measured on a 2-core AMD EPYC with cvxopt 1.3.3's
#: bundled CHOLMOD 3.0.6 and SciPy 1.17.1 (benchmarks/linalg_costs.py, its output in
#: benchmarks/results/linalg_costs.json): the kernel's matrices of the square (N = 32-512,
#: 2 000-526 000 unknowns; CHOLMOD makes their factors supernodal) and of the rough profile's
#: graded meshes (1 000-64 000 points, 7 000-418 000 unknowns; simplicial), each time the
#: fastest of 3 runs. Numeric factorisation: flops and entries fitted together (non-negative
#: least squares on relative errors; 0.64 + 0.52 s of 1.32 s at 526 000 unknowns); solves,
#: blocked forward columns, conversion and analysis: the median of counted work / seconds
#: over the matrices; pattern solve: reached entries and a fixed cost per column fitted
#: together per kind. The supernodal blocks' forward route was fitted apart, on the Hertz
#: platen's kernel matrix. How the model compares with the measured seconds at the largest
#: sizes: docs/performance.md#measured-design-choices.
_SUPERNODAL = Rates(factor_flops=4.8e10, factor_entries=1.5e8, analysis_work=5.1e8, solve_entries=5.1e8,
                    block_solve_entries=3.7e9, blocked_forward_entries=2.7e9, pattern_entries=1.05e9,
                    pattern_column_seconds=7.4e-6, conversion_entries=5.6e8,
                    supernodal_entries=1.0e9, supernodal_block_entries=5.0e9, supernode_seconds=1.0e-5)
RATES: dict[str, Rates] = {
    "cholmod-supernodal": _SUPERNODAL,
    # A simplicial factor's numeric factorisation is its flops alone (the entries' term fitted to 0).
    "cholmod-simplicial": Rates(factor_flops=1.0e9, factor_entries=math.inf, analysis_work=5.3e8,
                                solve_entries=6.1e8, block_solve_entries=9.7e8, blocked_forward_entries=1.9e9,
                                pattern_entries=5.8e8, pattern_column_seconds=3.9e-6),
    # cvxopt's interface: the same library's numeric work; its analysis copies the matrix
    # first (measured, per its own work); it solves a block one column at a time. Its
    # counts are lower estimates (its factor cannot be read), so its seconds are too.
    "cholmod-interface": Rates(factor_flops=4.8e10, factor_entries=1.5e8, analysis_work=1.8e8,
                               solve_entries=4.9e8, block_solve_entries=4.9e8),
    # SuperLU (MMD_AT_PLUS_A, symmetric mode) on the same matrices up to 132 000 unknowns.
    "superlu": Rates(factor_flops=1.5e10, factor_entries=3.1e7, solve_entries=5.2e8, block_solve_entries=6.7e8),
    # Pardiso was not installed where the rates were measured: CHOLMOD's supernodal rates
    # scaled by what benchmarks/results/solvers.json measured on the square at 132 000 and
    # 526 000 unknowns on the same kind of machine: its factorisation (phase 12, which
    # analyses too) 3.1-3.6x CHOLMOD's refactorisation, a solve 1.2-1.6x; a block of 4 took
    # 4 single solves' time.
    "pardiso": Rates(factor_flops=1.45e10, factor_entries=4.5e7, solve_entries=3.7e8, block_solve_entries=3.7e8),
}
#: Flops per second of a dense LU (LAPACK getrf through SciPy, 2 k³ / 3 flops for k × k),
#: for a Schur complement's dense solve: the median over k = 250-2 000 on the same machine
#: (1.6e10 at 250, 2.5e10 at 500, 4.0e10 at 1 000, 5.1e10 at 2 000).
DENSE_FLOPS = 3.2e10

# The direct CHOLMOD route's old guesses in full solves, BLOCKED_COLUMN_SHARE (a blocked
# forward column, 0.3) and CONVERSION_GUESS (the conversion, 3.0), are gone: both are now
# counted exactly (the factor's stored entries) and priced by the rates above (a blocked
# column 0.19 of a supernodal full solve, a conversion 0.9 of one). So is MEASURED_FROM (the
# batch size from which a batch's time per column was trusted): counts carry no fixed cost.

#: Until a factor's forward columns have been counted, a pattern-solve column is guessed
#: as this share of a full solve, from the factor's fill (entries per column), which sets
#: how long the columns on a path are: PATTERN_GUESS_SHARE (fill / PATTERN_GUESS_FILL) **
#: PATTERN_GUESS_EXPONENT, at most PATTERN_GUESS_CAP. Measured (as seconds, before this
#: module counted): 0.003 at 31 entries per column (a rough profile's graded mesh, 418 000
#: unknowns), 0.05-0.07 at 98-145 (the square), 0.08 at 105 (a uniform mesh under a rough base).
PATTERN_GUESS_SHARE = 0.003
PATTERN_GUESS_FILL = 31.0
PATTERN_GUESS_EXPONENT = 2.2
PATTERN_GUESS_CAP = 0.1


@dataclass(frozen=True)
class CostModel:
    """Modelled seconds from counted work: counts divided by the rates of :data:`RATES`.

    Every method is deterministic: the same counts give the same seconds. Use the
    module's :data:`MODEL`.

    Examples
    --------
    >>> from contactfem.linalg.costs import MODEL, FactorCost
    >>> cost = FactorCost(size=132_098, entries=16_044_470, flops=3.6e9)
    >>> MODEL.solve_seconds(cost, 4) > MODEL.solve_seconds(cost, 1)
    True
    """

    rates: Mapping[str, Rates] = field(default_factory=lambda: RATES)
    dense_flops: float = DENSE_FLOPS

    def _rates(self, cost: FactorCost) -> Rates:
        return self.rates[cost.kind]

    def factorize_seconds(self, cost: FactorCost) -> float:
        """The numeric factorisation (a refactorisation that reuses the analysis)."""
        rates = self._rates(cost)
        return cost.flops / rates.factor_flops + cost.entries / rates.factor_entries

    def analysis_seconds(self, cost: FactorCost) -> float:
        """The ordering and symbolic analysis of the matrix's pattern (:func:`analysis_work`)."""
        return analysis_work(cost.matrix_entries) / self._rates(cost).analysis_work

    def solve_seconds(self, cost: FactorCost, k: int = 1) -> float:
        """A full solve A X = B of ``k`` dense right-hand sides in one block: the first at a
        single solve's rate, each further one at the block's."""
        rates = self._rates(cost)
        if k < 1:
            return 0.0
        return cost.entries / rates.solve_entries + (k - 1) * cost.entries / rates.block_solve_entries

    def backward_seconds(self, cost: FactorCost) -> float:
        """The backward half of a full solve with one right-hand side (x = Pᵀ L⁻ᵀ v): one
        sweep of the factor's entries instead of two."""
        return 0.5 * self.solve_seconds(cost, 1)

    def blocked_forward_seconds(self, cost: FactorCost, k: int) -> float:
        """``k`` forward columns W = L⁻¹ P B through the blocked sparse solve."""
        return k * cost.entries / self._rates(cost).blocked_forward_entries

    def conversion_seconds(self, cost: FactorCost) -> float:
        """Converting a supernodal factor to a simplicial one (0 for a simplicial factor)."""
        if cost.kind != "cholmod-supernodal":
            return 0.0
        return cost.entries / self._rates(cost).conversion_entries

    def pattern_column_guess(self, cost: FactorCost) -> float:
        """Seconds of one pattern-solve column before any path has been counted: the
        share of a full solve that :data:`PATTERN_GUESS_SHARE` and its companions give."""
        share = min(PATTERN_GUESS_CAP,
                    PATTERN_GUESS_SHARE * (cost.fill / PATTERN_GUESS_FILL) ** PATTERN_GUESS_EXPONENT)
        return share * self.solve_seconds(cost, 1)

    def pattern_forward_seconds(self, cost: FactorCost, k: int, path_entries: float | None) -> float:
        """``k`` forward columns through the pattern solve, its conversion excluded.

        ``path_entries``: the factor entries a column reaches, on average (counted on the
        columns solved so far), or None before any: then :meth:`pattern_column_guess`.
        """
        if path_entries is None:
            return k * self.pattern_column_guess(cost)
        rates = self._rates(cost)
        return k * (path_entries / rates.pattern_entries + rates.pattern_column_seconds)

    def supernodal_forward_seconds(self, cost: FactorCost, k: int, entries: float, supernodes: float) -> float:
        """``k`` forward columns through the supernodal blocks, reaching ``entries`` stored
        entries of the factor in ``supernodes`` supernodes (inf where not measured)."""
        rates = self._rates(cost)
        seconds = entries / rates.supernodal_entries + (k - 1) * entries / rates.supernodal_block_entries \
            + supernodes * rates.supernode_seconds
        return seconds if math.isfinite(seconds) else math.inf

    def forward_routes(self, cost: FactorCost, k: int, *, converted: bool,
                       path_entries: float | None) -> tuple[float, float]:
        """(blocked, pattern): ``k`` forward columns through each route, the pattern route
        with the conversion it needs first unless the factor is simplicial or ``converted``."""
        conversion = 0.0 if converted else self.conversion_seconds(cost)
        return (self.blocked_forward_seconds(cost, k),
                conversion + self.pattern_forward_seconds(cost, k, path_entries))

    def forward_seconds(self, cost: FactorCost, k: int, *, converted: bool,
                        path_entries: float | None) -> float:
        """``k`` forward columns through the cheaper route (see :meth:`forward_routes`)."""
        return min(self.forward_routes(cost, k, converted=converted, path_entries=path_entries))

    def dense_factorize_seconds(self, k: int) -> float:
        """A dense LU of a k × k matrix (a Schur complement): 2 k³ / 3 flops."""
        return 2.0 * k**3 / 3.0 / self.dense_flops


#: The model every module of the package uses.
MODEL = CostModel()
