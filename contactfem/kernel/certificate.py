"""The certificate of a contact solve: the discrete problem's own conditions, measured in its units.

Before the kernel reports CONVERGED it measures the final iterate against equilibrium,
the signs of the contact forces, the gaps, complementarity and finiteness, each against a
tolerance stated in the system's units and never below the round-off bound of evaluating
the equations (Higham, *Accuracy and Stability of Numerical Algorithms*, §3.1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = float(np.finfo(float).eps)
#: A certificate is only issued when the equilibrium equations resolve the forces to at
#: least three significant digits: when the round-off bound of evaluating K u + Nᵀ Λ − F
#: (γ_k times the sum of the magnitudes of its terms) exceeds this fraction of the force
#: scale, the forces in play are lost in the cancellation of much larger terms (a huge
#: rigid motion prescribed with nothing to resist it, a body far too slender for double
#: precision), and a residual "within round-off" says nothing about the answer.
FORCE_RESOLUTION_LIMIT = 1e-3
#: The strain whose force over the body (its largest stiffness entry times its size) is the
#: force scale of an unloaded iterate whose forces are all round-off (see
#: :meth:`contactfem.kernel.ActiveSetSolver.measure`): forces below 1e-3 of it, a strain of
#: 1e-10, count as zero.
ZERO_FORCE_STRAIN = 1e-7


def roundoff_bound(terms: int) -> float:
    """γ_k = k ε / (1 − k ε): the relative error bound of a sum of k floating-point products.

    Evaluating one row of K u + Nᵀ Λ − F in floating point errs by at most γ_k times the
    sum of the magnitudes of its terms (Higham, Accuracy and Stability of Numerical
    Algorithms, §3.1), k the row's stored entries plus the load and the contact force; no
    solver, however accurate, can certify a residual below it.
    """
    return terms * EPS / (1.0 - terms * EPS)


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
