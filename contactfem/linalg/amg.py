"""Algebraic multigrid for one SPD system: pyamg's smoothed aggregation as the preconditioner of CG.

Where a sparse factorisation would not fit in memory, each Newton step's system (the
stiffness with its supports and active normals fixed) is solved iteratively. The
preconditioner is pyamg's smoothed aggregation (Vaněk, Mandel & Brezina, Computing 56,
1996) on the 2x2 node blocks of the displacement unknowns, given the body's rigid motions
(two translations and a rotation in 2D) as its near-null space: with them the coarse
spaces reproduce what elasticity leaves unstrained, and the iterations barely grow with
the mesh. CG stops on the residual's largest entry, the quantity the contact certificate
bounds (:class:`contactfem.kernel.Certificate`), not on a 2-norm that a large mesh
averages away.

pyamg draws random starts for the spectral radii that scale its prolongation and its
Chebyshev smoother; they are drawn from a fixed seed here, with NumPy's global state put back after,
so that two runs give the same hierarchy and the same answer, bit for bit.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError

#: The seed of the random draws of pyamg's set-up (see the module docstring).
SEED = 20261206
#: Smoothed aggregation's settings: the symmetric strength measure with no dropping (the
#: P1 stiffness has no weak couplings worth dropping on a shape-regular mesh), standard
#: aggregation over nodes, one Jacobi step smoothing the tentative prolongation, a degree-3
#: Chebyshev polynomial before and after (a symmetric V-cycle, as CG needs; as few CG
#: iterations as symmetric block Gauss–Seidel and cheaper sweeps: docs/performance.md), and
#: coarse levels down to a few hundred unknowns solved directly.
SETTINGS = {
    "strength": ("symmetric", {"theta": 0.0}),
    "aggregate": "standard",
    "smooth": ("jacobi", {"omega": 4.0 / 3.0}),
    "presmoother": ("chebyshev", {"degree": 3}),
    "postsmoother": ("chebyshev", {"degree": 3}),
    "improve_candidates": None,
    "max_coarse": 400,
    "max_levels": 25,
}
#: CG gives up after this many iterations (a system that is not positive definite, or one
#: the preconditioner does not fit, stalls far below it: 20–40 iterations are typical).
MAX_ITERATIONS = 2000


def amg_available() -> bool:
    """Whether pyamg can be imported."""
    try:
        return importlib.util.find_spec("pyamg") is not None
    except (ImportError, ValueError):
        return False


@dataclass
class CGRecord:
    """One CG solve: its ``iterations`` and the largest residual entry before and after,
    relative to the right-hand side's largest entry."""

    iterations: int
    initial_residual: float
    final_residual: float

    def to_dict(self) -> dict:
        return {"iterations": self.iterations, "initial_residual": self.initial_residual,
                "final_residual": self.final_residual}


@dataclass
class AmgFigures:
    """What a hierarchy costs: its levels' unknowns and stored entries (the operator
    complexity is their total over the finest level's)."""

    unknowns: list[int] = field(default_factory=list)
    entries: list[int] = field(default_factory=list)

    @property
    def operator_complexity(self) -> float:
        return float(sum(self.entries) / self.entries[0]) if self.entries else 0.0

    def to_dict(self) -> dict:
        return {"levels": len(self.unknowns), "unknowns": self.unknowns, "entries": self.entries,
                "operator_complexity": self.operator_complexity}


def node_blocks(matrix: sp.spmatrix) -> sp.spmatrix:
    """``matrix`` without stored zeros, in 2x2 node blocks (BSR) when its size is even: the
    aggregation then groups nodes, not single components, and the products run blockwise."""
    blocks = sp.csr_matrix(matrix)
    blocks.eliminate_zeros()
    return blocks.tobsr(blocksize=(2, 2)) if blocks.shape[0] % 2 == 0 else blocks


class AmgSolver:
    """CG preconditioned by smoothed aggregation for one SPD matrix.

    Parameters
    ----------
    matrix : (n, n) sparse SPD
        Unknowns interleaved by node (2 i + c), n even; rows and columns of fixed unknowns
        already reduced to a positive diagonal entry.
    near_null : (n, k)
        The near-null space (the rigid motions), zero on fixed unknowns.
    name : str
        What error messages call the matrix.
    """

    def __init__(self, matrix: sp.spmatrix, near_null: np.ndarray, name: str = "the matrix") -> None:
        import pyamg

        self.name = name
        blocks = node_blocks(matrix)
        state = np.random.get_state()
        np.random.seed(SEED)
        try:
            self.hierarchy = pyamg.smoothed_aggregation_solver(
                blocks, B=np.ascontiguousarray(near_null, dtype=float), **SETTINGS)
        finally:
            np.random.set_state(state)
        #: The operator CG solves with: the matrix the hierarchy was built for, or another of
        #: the same unknowns (:meth:`set_operator`).
        self.matrix = self.hierarchy.levels[0].A
        self.preconditioner = self.hierarchy.aspreconditioner(cycle="V")
        self.figures = AmgFigures([int(level.A.shape[0]) for level in self.hierarchy.levels],
                                  [int(level.A.nnz) for level in self.hierarchy.levels])

    def set_operator(self, matrix: sp.spmatrix) -> None:
        """Solve with ``matrix`` from now on, preconditioned by the hierarchy built for the
        first: still a symmetric positive definite preconditioner, so CG converges; the
        closer the two matrices, the fewer the iterations."""
        if matrix.shape != self.matrix.shape:
            raise ValueError("the new operator must have the unknowns of the hierarchy's matrix")
        self.matrix = node_blocks(matrix)

    def solve(self, rhs: np.ndarray, target: float, x0: np.ndarray | None = None,
              max_iterations: int = MAX_ITERATIONS) -> tuple[np.ndarray, CGRecord]:
        """x with ‖rhs − A x‖∞ ≤ ``target`` (absolute), by preconditioned CG from ``x0``.

        Raises
        ------
        SolverError
            If CG meets a direction of non-positive curvature (the matrix is not positive
            definite: a part of the body that nothing holds) or does not reach ``target``.
        """
        b = np.asarray(rhs, dtype=float)
        x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
        r = b - self.matrix @ x if x0 is not None else b.copy()
        scale = float(np.abs(b).max(initial=0.0)) or 1.0
        size = initial = float(np.abs(r).max(initial=0.0))
        iterations = 0
        if not np.isfinite(size):
            raise SolverError(f"{self.name}: the right-hand side is not finite")
        if size > target:
            z = self.preconditioner @ r
            p = z.copy()
            rz = float(r @ z)
            while size > target:
                if iterations >= max_iterations:
                    raise SolverError(
                        f"{self.name} could not be solved by CG with algebraic multigrid: residual "
                        f"{size / scale:.1e} of the load after {iterations} iterations, target {target / scale:.1e} "
                        "(is part of the body held only by contact, or too slender for double precision?)")
                q = self.matrix @ p
                curvature = float(p @ q)
                if not curvature > 0.0:
                    raise SolverError(
                        f"{self.name} is singular or not positive definite: CG met a direction of "
                        f"curvature {curvature:.1e} after {iterations} iterations (a part of the body not held?)")
                alpha = rz / curvature
                x += alpha * p
                r -= alpha * q
                iterations += 1
                size = float(np.abs(r).max(initial=0.0))
                if not np.isfinite(size):
                    raise SolverError(f"{self.name} is singular: CG gives non-finite values")
                z = self.preconditioner @ r
                rz_next = float(r @ z)
                p *= rz_next / rz
                p += z
                rz = rz_next
        return x, CGRecord(iterations, initial / scale, size / scale)
