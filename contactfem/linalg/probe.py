"""The probe every factorisation gets: one solve that tells a singular or numerically
singular matrix from a sound one, whatever the backend.

None of the backends can be trusted to notice a singular matrix: SuperLU in symmetric
mode without pivoting (``diag_pivot_thresh=0``) and CHOLMOD both complete with a tiny
round-off pivot where the exact one is zero, and the solves are then garbage. So every
factorisation is followed by a probe (:func:`check_factorization`): one solve with a
positive random right-hand side, whose residual and size tell a singular or numerically
singular matrix from a sound one whatever the backend.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError

#: Bound on the probe's two figures, ‖b − A x‖∞ / ‖b‖∞ after one step of iterative
#: refinement and ε κ̂ with κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞, beyond which a matrix is reported
#: numerically singular. A backward-stable solve leaves a relative residual of about ε κ,
#: and κ̂ is a lower estimate of κ∞ (the positive probe loads the softest, smooth modes, so
#: it is typically within a factor of ten), so either figure above 0.1 means a generic load
#: is solved with no correct digit. An exactly singular matrix is far past it: the component
#: of the positive probe along a null vector (a rigid motion of an unheld part) lies outside
#: A's range, so no x can cancel it and the residual stays of the order of ‖b‖; and x grows
#: like ‖b‖ / (round-off pivot), κ̂ like 1/ε. For scale, measured ε κ̂: 3e-10 on the square
#: at 131 000 unknowns, 3e-4 at ν = 0.499999995, 7e-3 on a 1:1000 strip of 1000 × 4 cells.
SINGULARITY_LIMIT = 0.1
# The probe is reproducible: the same matrix always gets the same verdict.
_PROBE_SEED = 20050101


class Factorization(Protocol):
    """What every backend's factorisation offers: ``solve(rhs)``, A⁻¹ rhs for a vector or a
    block of columns, and ``cost``, its counted :class:`~contactfem.linalg.costs.FactorCost`."""

    def solve(self, rhs: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class FactorCheck:
    """What the probe of a factorisation measured (see :func:`check_factorization`).

    ``residual``: ‖b − A x‖∞ / ‖b‖∞ for the probe b (after refinement, if one was needed);
    ``condition``: κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞, a lower estimate of the condition number κ∞(A),
    so that ε κ̂ estimates the relative forward error of a solve; ``refined``: whether a step
    of iterative refinement was needed.
    """

    residual: float
    condition: float
    refined: bool = False

    @property
    def relative_precision(self) -> float:
        """ε κ̂: the relative accuracy a solve with this factor can be expected to reach."""
        return float(np.finfo(float).eps * self.condition)


def probe_vector(size: int, equations: np.ndarray | None = None) -> np.ndarray:
    """The probe's right-hand side: uniform in [0.5, 1.5] on ``equations``, zero elsewhere.

    Positive entries give every rigid motion of a part (and every smooth soft mode) a
    component of the order of ‖b‖, which is what makes the probe see them.
    """
    probe = np.random.default_rng(_PROBE_SEED).uniform(0.5, 1.5, size)
    if equations is not None:
        probe[~np.asarray(equations, dtype=bool)] = 0.0
    return probe


def check_factorization(matrix: sp.spmatrix, factor: Factorization, *, equations: np.ndarray | None = None,
                        probe: np.ndarray | None = None, solution: np.ndarray | None = None,
                        norm: float | None = None, name: str = "the matrix") -> FactorCheck:
    """Probe ``factor`` of ``matrix`` with one solve; raise :class:`SolverError` if it is singular.

    Solves A x = b for b = :func:`probe_vector` (or ``probe``, with ``solution`` its solve if
    the caller already has it), and measures ‖b − A x‖∞ / ‖b‖∞ and κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞
    over the rows of ``equations`` (default all; rows outside it must be decoupled
    identity rows, such as masked supports, which would only blur the norms; ``norm``, their
    ‖A‖∞, if the caller has it). A residual
    above :data:`SINGULARITY_LIMIT` gets one step of iterative refinement, so that a solve
    that is merely not backward stable is not mistaken for a singular matrix. Costs one
    solve and two products with A (one more of each when refining).
    """
    size = matrix.shape[0]
    rows = np.ones(size, dtype=bool) if equations is None else np.asarray(equations, dtype=bool)
    if not rows.any():
        return FactorCheck(residual=0.0, condition=1.0)
    b = probe_vector(size, rows) if probe is None else np.asarray(probe, dtype=float)
    x = np.asarray(factor.solve(b) if solution is None else solution, dtype=float).reshape(size)
    scale = np.abs(b[rows]).max()
    matrix = sp.csr_matrix(matrix)
    if norm is None:
        absolute = sp.csr_matrix((np.abs(matrix.data), matrix.indices, matrix.indptr), shape=matrix.shape)
        norm = float((absolute @ np.ones(size))[rows].max())

    def measure(x: np.ndarray) -> tuple[np.ndarray, float]:
        residual = np.where(rows, b - matrix @ x, 0.0)
        return residual, float(np.abs(residual).max() / scale)

    refined = False
    if np.isfinite(x).all():
        residual, relative = measure(x)
        if relative > SINGULARITY_LIMIT:
            refined = True
            x = x + np.asarray(factor.solve(residual), dtype=float).reshape(size)
            residual, relative = measure(x) if np.isfinite(x).all() else (residual, np.inf)
    else:
        relative = np.inf
    if not np.isfinite(relative):
        raise SolverError(f"{name} is singular: solving with its factorisation gives non-finite values")
    condition = float(norm * np.abs(x[rows]).max() / scale)
    eps = np.finfo(float).eps
    if relative > SINGULARITY_LIMIT or eps * condition > SINGULARITY_LIMIT:
        raise SolverError(
            f"{name} is singular or numerically singular: probe residual {relative:.1e} after refinement, "
            f"condition estimate {condition:.1e} (eps*kappa {eps * condition:.1e}), bound {SINGULARITY_LIMIT:g} "
            "(a part of the body not held, or too slender for double precision)"
        )
    return FactorCheck(residual=relative, condition=condition, refined=refined)
