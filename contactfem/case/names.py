"""The names a case's settings are checked against, as plain data.

The registries they name lie outside the case layer: the contact methods in
:mod:`contactfem.methods`, the solver backends in :mod:`contactfem.linalg`, the output
formats in :mod:`contactfem.io.registry`. The reader does not import them;
``tests/test_layers.py`` checks that these copies equal the registries, so that a method,
a backend or a format added there is added here too.
"""

from __future__ import annotations

#: The contact methods (``contactfem.methods.METHOD_NAMES``), in the order reports list them.
METHOD_NAMES = ("positive", "standard")
#: What ``solver.backend`` may name (``contactfem.linalg.BACKEND_CHOICES``): auto (the
#: fastest installed), the direct backends of one process, amg (CG with algebraic
#: multigrid) and petsc across MPI ranks.
BACKEND_CHOICES = ("auto", "cholmod", "pardiso", "superlu", "amg", "petsc")
#: The output formats (``contactfem.io.registry.FORMAT_NAMES``), in the order written.
FORMAT_NAMES = ("vtu", "h5", "xdmf", "csv", "path", "json")
#: Written unless the case lists its own (``contactfem.io.registry.DEFAULT_FORMATS``).
DEFAULT_FORMATS = ("vtu", "h5", "csv", "json")
#: The formats written beside others that they read: format → the formats it needs
#: (each ``OutputFormat.needs`` of the registry that is not empty).
FORMAT_NEEDS = {"xdmf": ("h5",)}
