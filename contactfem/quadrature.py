"""Quadrature rules shared by the loads, the error norms and the error estimator."""

from __future__ import annotations

import numpy as np

# Strang–Fix / Dunavant 7-point rule on a triangle, exact for degree 5: barycentric
# points (7, 3) and weights summing to 1 (multiply by |T|).
_A1, _B1 = 0.059715871789770, 0.470142064105115
_A2, _B2 = 0.797426985353087, 0.101286507323456
TRIANGLE_POINTS = np.array([
    [1 / 3, 1 / 3, 1 / 3],
    [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
    [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2],
])
TRIANGLE_WEIGHTS = np.array([0.225] + [0.132394152788506] * 3 + [0.125939180544827] * 3)


def gauss_on_unit_interval(n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points and weights on [0, 1], exact for degree 2n − 1."""
    nodes, weights = np.polynomial.legendre.leggauss(n)
    return 0.5 * (nodes + 1), 0.5 * weights


#: The one rule for surface forces on boundary edges: Simpson's, on [0, 1] along the edge
#: (points at the ends and the midpoint). It integrates g·φ exactly for quadratic g (the
#: load vector) and ‖g − σν‖² exactly for linear g (the estimator's Neumann residual).
EDGE_RULE_POINTS = np.array([0.0, 0.5, 1.0])
EDGE_RULE_WEIGHTS = np.array([1 / 6, 4 / 6, 1 / 6])
