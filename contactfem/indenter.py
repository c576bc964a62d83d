"""A rigid obstacle pushed by a force: its advance found so that the contact reaction equals the force.

The obstacle's advance δ along its unit direction d is the unknown; the contact forces Λ
hold it with the reaction R(δ) = −Σ Λ_i n_i · d (:class:`contactfem.discretize.motion.ObstacleDrive`).
For a fixed active set the contact problem is linear in δ, so R is continuous, piecewise
affine and nondecreasing in δ, affine on each interval where the active set stays: a
secant step between two advances with the same active set lands on the answer to
round-off. The iteration keeps a bracket [δ_lo, δ_hi] with R(δ_lo) < F < R(δ_hi) and
takes the secant of the two latest advances when it falls inside it, otherwise the
Illinois step of regula falsi (Dowell and Jarratt, BIT 11, 1971), which stays inside.
Each trial is a displacement-driven solve of the same assembled problem.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from contactfem.errors import SolverError

#: The reaction is accepted within this share of the force.
FORCE_TOLERANCE = 1e-12
#: Trial solves before the search gives up.
MAX_TRIALS = 60


def touch_advance(problem) -> float:
    """The advance at which the obstacle first reaches a contact node of the body at rest."""
    drive, contact = problem.drive, problem.contact
    approach = -(contact.normals @ drive.direction)
    closing = approach > 0
    if not closing.any():  # a node already touching holds it (refuse_receding allows no other case)
        return 0.0
    return float(np.min(contact.gap[closing] / approach[closing]))


def solve_pushed(problem, solve: Callable, modulus: float, say: Callable[[str], None]):
    """The solve (``solve(problem)``'s result) at the advance whose reaction equals the
    pushed obstacle's force, and the number of trial solves."""
    drive = problem.drive
    force = float(drive.force)
    start = touch_advance(problem)
    size = force / modulus  # a half-plane's indentation scale for a force per unit thickness
    lo = (start, 0.0) if not np.any(problem.load) else None
    hi = None
    history: list[tuple[float, float]] = [] if lo is None else [lo]
    advance = start + size
    trials = 0
    side = 0
    while True:
        trials += 1
        if trials > MAX_TRIALS:
            raise SolverError(f"the pushed obstacle's advance was not found in {MAX_TRIALS} solves "
                              f"(reaction {history[-1][1]:.6g} against the force {force:.6g})")
        result = solve(problem.advanced(advance))
        reaction = drive.reaction(result.kernel.nodal_force, problem.contact.normals)
        say(f"  pushed obstacle: advance {advance:.9g}, reaction {reaction:.9g} of {force:.9g}")
        history.append((advance, reaction))
        if abs(reaction - force) <= FORCE_TOLERANCE * force:
            return result, trials
        if reaction < force:
            lo, side = (advance, reaction), (side - 1 if side < 0 else -1)
        else:
            hi, side = (advance, reaction), (side + 1 if side > 0 else 1)
        if hi is None:
            advance = (start + 2.0 * (advance - start) if len(history) < 2 or reaction <= 0.0
                       else _secant(history, force, 4.0))
            continue
        if lo is None:
            advance = start + 0.5 * (advance - start) if advance > start else advance - size
            continue
        advance = _secant(history, force, None)
        if not lo[0] < advance < hi[0]:
            # Illinois: halve the weight of the end that has stayed twice in a row.
            w_lo = 0.5 if side >= 2 else 1.0
            w_hi = 0.5 if side <= -2 else 1.0
            f_lo, f_hi = (lo[1] - force) * w_lo, (hi[1] - force) * w_hi
            advance = lo[0] + (hi[0] - lo[0]) * f_lo / (f_lo - f_hi)


def _secant(history: list[tuple[float, float]], force: float, widest: float | None) -> float:
    """The secant root of the last two trials (growing the step by at most ``widest``
    times the last one)."""
    (a0, r0), (a1, r1) = history[-2], history[-1]
    if r1 == r0:
        return a1 + (a1 - a0)
    step = (force - r1) * (a1 - a0) / (r1 - r0)
    if widest is not None:
        step = min(step, widest * abs(a1 - a0))
    return a1 + step
