"""The contact kernel: a semismooth Newton (primal–dual active set) loop on arrays and sparse matrices.

Layout, one concern a module:

- :mod:`~contactfem.kernel.system`: the algebraic problem (:class:`ContactSystem`);
- :mod:`~contactfem.kernel.newton`: the iteration (:func:`solve_contact`), its theory and
  references;
- :mod:`~contactfem.kernel.certificate`: the conditions a result must meet;
- :mod:`~contactfem.kernel.proposers`: accelerators that propose a better next set
  (a coarser level's prediction, zone fronts) and their switches (:class:`Accelerators`);
- :mod:`~contactfem.kernel.schur`: the linear solver, Schur-complement updates of one
  factorisation (:class:`ActiveSetSolver`), with :mod:`~contactfem.kernel.columns`,
  :mod:`~contactfem.kernel.masking` and its cost model :mod:`~contactfem.kernel.costs`;
- :mod:`~contactfem.kernel.iterative`: the linear solver where a factorisation would not
  fit in memory, CG with algebraic multigrid (:class:`IterativeSetSolver`), measuring its
  iterates as the Schur solver does (:mod:`~contactfem.kernel.measures`);
- :mod:`~contactfem.kernel.paths`: load paths (:func:`solve_path`);
- :mod:`~contactfem.kernel.cycles`, :mod:`~contactfem.kernel.modes`,
  :mod:`~contactfem.kernel.starts`: the safeguards and starts of the iteration.

The kernel knows nothing of case files, meshes or the terminal.
"""

from contactfem.kernel.certificate import (
    EPS,
    FORCE_RESOLUTION_LIMIT,
    ZERO_FORCE_STRAIN,
    Certificate,
    Check,
    Scales,
    build_certificate,
    roundoff_bound,
)
from contactfem.kernel.fronts import MAX_OVERSHOOTS, ZoneFronts
from contactfem.kernel.iterative import IterativeSetSolver
from contactfem.kernel.newton import (
    MIN_ITERATIONS,
    Iteration,
    KernelResult,
    Status,
    default_max_iterations,
    solve_contact,
)
from contactfem.kernel.paths import PathSolver, PathStarts, extrapolated_active, solve_path
from contactfem.kernel.proposers import STALL_ITERATIONS, Accelerators, Proposer, Step
from contactfem.kernel.schur import REFINEMENT_STEPS, ActiveSetSolver
from contactfem.kernel.starts import translation_start
from contactfem.kernel.system import ContactSystem, default_c

__all__ = [
    "Accelerators", "ActiveSetSolver", "EPS", "IterativeSetSolver", "REFINEMENT_STEPS", "Certificate", "Check", "ContactSystem", "FORCE_RESOLUTION_LIMIT", "Iteration", "KernelResult", "MAX_OVERSHOOTS", "MIN_ITERATIONS", "PathSolver",
    "PathStarts", "Proposer", "STALL_ITERATIONS", "Scales", "Status", "Step", "ZERO_FORCE_STRAIN", "ZoneFronts",
    "build_certificate", "default_c", "default_max_iterations", "extrapolated_active", "roundoff_bound",
    "solve_contact", "solve_path", "translation_start",
]
