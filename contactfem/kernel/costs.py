"""The cost model of the Schur-update solver: counted work at fixed rates, never the clock.

:class:`contactfem.kernel.schur.ActiveSetSolver` chooses, for each active set, between a
Schur-complement update of its factorisation and factorising the set anew. Both sides are
*modelled* seconds: counted work (factor entries, factorisation flops, columns, dense
flops) divided by the rates of :mod:`contactfem.linalg.costs`, so that the same case takes
the same path on a quiet or a busy machine. The rates are those of the machine the
benchmarks run on (2 cores, ``benchmarks/results/linalg_costs.json``); a faster or slower
machine scales both sides alike and changes no decision. The thresholds below are the
kernel's own.
"""

from __future__ import annotations

import numpy as np

from contactfem.linalg import MODEL, Factorizer

#: The most bytes the cached Schur columns (one full-length vector each) may hold: beyond
#: it the solver refactorises, whatever the model says. Sparse forward columns are not
#: capped; their dense blocks in a Schur product are.
COLUMN_BYTES = 2**29
#: Unknowns from which Schur columns come from forward solves when the backend has them:
#: below, a full solve is cheap and the forward route's fixed cost per update (its Schur
#: product, one more full solve) outweighs it.
FORWARD_COLUMNS_FROM = 100_000
#: The same from a simplicial factor (meshes with little fill, such as one graded onto a
#: rough profile), whose pattern solves need no conversion, as long as its elimination
#: tree's paths are short (:data:`FORWARD_PATH_SHARE`).
SIMPLICIAL_FORWARD_COLUMNS_FROM = 5_000
#: The largest share of the unknowns a forward column may touch, on average over the first
#: columns a step takes (or over :data:`PATH_SAMPLES` sampled contact normals), for a
#: simplicial factor below :data:`FORWARD_COLUMNS_FROM` unknowns to go on with forward
#: columns: on a long thin mesh the elimination tree is nearly a chain and its paths are
#: long.
FORWARD_PATH_SHARE = 0.1
PATH_SAMPLES = 8
#: Up to this many dense entries and products the Schur blocks of new forward columns are
#: taken with those columns made dense (see :func:`contactfem.kernel.columns.cross`).
DENSE_CROSS_ENTRIES = 2**19
#: What a factorisation step costs beyond the numeric factorisation, in full solves: the
#: masking of the changed rows, the singularity probe and the first block of solves.
FACTORIZATION_EXTRA_SOLVES = 3.0
#: The most bytes the dense copy of the forward columns over the rows they touch may
#: hold (:meth:`contactfem.kernel.schur.ActiveSetSolver._cross_stored`); beyond it the
#: Schur blocks come from the sparse columns themselves.
DENSE_ROWS_BYTES = 2**27
#: A Schur block Wᵀ S of sparse forward columns is taken densely (both gathered over the
#: rows W touches, one BLAS product) while its flops, 2 · rows · k_W · k_S, are at most this
#: many times the multiply-adds of the sparse product (pairs of entries sharing a row).
#: Columns that share their rows (a contact zone's nodes, whose paths meet in the same
#: separators) have nearly as many pairs as flops, and BLAS runs them faster; columns spread
#: over many patches (a rough profile's) touch rows they mostly do not share, and the dense
#: product multiplies zeros. Measured by the crossover of the two on both kinds of block
#: (docs/performance.md#measured-design-choices).
DENSE_PRODUCT_SHARE = 8.0
#: The most a start check's round (:meth:`contactfem.kernel.schur.ActiveSetSolver.preview`)
#: may cost, modelled, as a share of the backward solve a Newton step pays for its
#: displacement: its new forward columns, their Schur blocks and its dense Schur solve.
#: A Hertz platen's round (a handful of changed nodes, one or two new columns) costs a few
#: percent of it; a rough profile's (hundreds changed, dozens of new columns beside many
#: patches) several times it, and its starts are rarely settled in three rounds anyway.
START_CHECK_SHARE = 0.25
#: A forward column in full solves, for a backend that does not model its forward routes
#: (CHOLMOD's blocked sparse solve through cvxopt's interface).
FORWARD_COLUMN_SHARE = 0.25


def factor_figures(factorizer: Factorizer) -> tuple[float, float]:
    """(modelled seconds of one full solve, of the numeric factorisation) of the latest
    factorisation of ``factorizer``, from its counted cost (:class:`contactfem.linalg.FactorCost`)."""
    cost = factorizer.costs[-1]
    return MODEL.solve_seconds(cost, 1), MODEL.factorize_seconds(cost)


def backward_seconds(factorizer: Factorizer) -> float:
    """Modelled seconds of the backward half of a full solve with the latest factorisation."""
    return MODEL.backward_seconds(factorizer.costs[-1])


def dense_seconds(changed: int) -> float:
    """The dense LU of a Schur complement over ``changed`` nodes."""
    return MODEL.dense_factorize_seconds(changed)


def cross_seconds(missing: int, stored: int, path: float) -> float:
    """The Schur blocks of ``missing`` new forward columns against ``stored`` ones, each a
    path of ``path`` entries (Wᵀ W: two flops per shared entry)."""
    return 2.0 * missing * stored * path / MODEL.dense_flops


def typical_path(unknowns: int, share: float | None) -> float:
    """The entries of a forward column: the counted ``share`` of the unknowns, or √n (a 2D
    mesh's separators) until one is counted."""
    return float(np.sqrt(unknowns)) if share is None else share * unknowns
