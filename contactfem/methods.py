"""The two mixed contact methods of the paper, as data: how each multiplier becomes nodal forces.

Both methods share the displacement space and the contact nodes; they differ in the
multiplier's mass B in the contact term Nᵀ B μ and in the rows (B μ)_x ≥ 0 of their
complementarity conditions:

- ``positive`` (method 4): B = D, the lumped boundary mass (trapezoidal rule
  ∫ I_h(λ_h v_hn)); λ_h ≥ 0 at every node, hence everywhere on ΓC.
- ``standard`` (method 5): B = M, the consistent boundary mass (exact ∫ θ_h v_hn);
  only ∫ θ_h ψ_x ≥ 0 holds, θ_h itself may dip below zero where the body lifts off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class ContactBoundaryMasses:
    """The two boundary masses of the contact nodes.

    ``lumped`` (m,): ω_x = ∫_ΓC ψ_x; ``consistent`` (m, m): M_xy = ∫_ΓC ψ_x ψ_y.
    """

    lumped: np.ndarray
    consistent: sp.spmatrix


@dataclass(frozen=True)
class ContactMethod:
    name: str
    equation: str
    multiplier_symbol: str
    summary: str
    multiplier_mass: Callable[[ContactBoundaryMasses], sp.spmatrix]


METHODS: dict[str, ContactMethod] = {
    "positive": ContactMethod(
        name="positive",
        equation="(4)",
        multiplier_symbol="lambda_h",
        summary="positivity-preserving: lumped multiplier mass, λh ≥ 0 at the nodes",
        multiplier_mass=lambda masses: sp.diags(masses.lumped, format="csr"),
    ),
    "standard": ContactMethod(
        name="standard",
        equation="(5)",
        multiplier_symbol="theta_h",
        summary="standard: consistent multiplier mass, ∫ θh ψx ≥ 0 only",
        multiplier_mass=lambda masses: sp.csr_matrix(masses.consistent),
    ),
}

#: The methods' names, in the order reports and studies list them.
METHOD_NAMES: tuple[str, ...] = tuple(METHODS)


def get_method(name: str) -> ContactMethod:
    """The method registered under ``name`` (``positive`` or ``standard``)."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"unknown contact method {name!r}; pick one of {', '.join(METHODS)}") from None
