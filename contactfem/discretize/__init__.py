"""From a validated case to a mesh and to the algebraic contact problem of each method.

One module per concern: ``meshing`` (geometry → checked mesh, the size guard), ``loads``
(body force and surface forces, compiled once), ``supports`` (prescribed displacements,
symmetry lines, rigid motions), ``contact`` (the obstacle and ΓC), ``frames`` (the
kernel's rotated unknowns), ``exact_checks`` and ``finite`` (refusals of data that
cannot be solved), and ``problem`` (the assembled whole). Refusals that need the mesh to
be seen are raised here as :class:`~contactfem.errors.CaseError` naming the key.
"""

from contactfem.discretize.contact import ContactBoundary
from contactfem.discretize.obstacles import HalfPlane, Obstacle, Segment, obstacle_of
from contactfem.discretize.frames import ReducedSystem
from contactfem.discretize.loads import Loads, NaturalBoundary
from contactfem.discretize.meshing import (
    build_mesh,
    estimate_triangles,
)
from contactfem.discretize.problem import DiscreteProblem, build_problem

__all__ = [
    "ContactBoundary",
    "DiscreteProblem",
    "HalfPlane",
    "Obstacle",
    "Segment",
    "obstacle_of",
    "Loads",
    "NaturalBoundary",
    "ReducedSystem",
    "build_mesh",
    "build_problem",
    "estimate_triangles",
]
