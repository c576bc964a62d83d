"""Where the active set iteration starts when the supports' own solution is known: a translation."""

from __future__ import annotations

import numpy as np

from contactfem.kernel.certificate import roundoff_bound
from contactfem.kernel.system import ContactSystem


def _translation_update(system: ContactSystem, linear, tolerance: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Newton's update from the supports' own solution when that is ``system.translation``,
    checked to be one: no load, the prescribed values its components to round-off, and K
    times it zero to the round-off bound of the equations (:meth:`ActiveSetSolver.measure`),
    with the slack d − G of the translation. None otherwise."""
    translation = system.translation
    if translation is None or np.any(system.load) or not getattr(linear, "serial", False):
        return None  # a distributed solver holds each rank's part of the vectors
    translation = np.asarray(translation, dtype=float)
    values = np.asarray(system.fixed_values, dtype=float)
    prescribed = translation[np.asarray(system.fixed_dofs, dtype=np.int64)]
    if np.abs(prescribed - values).max(initial=0.0) > 8 * np.finfo(float).eps * np.abs(values).max(initial=0.0):
        return None
    scales = linear.measure(translation, np.zeros(len(system.gap)))
    if not scales.equilibrium <= scales.roundoff:
        return None
    slack = linear.normals(translation) - np.asarray(system.gap, dtype=float)
    return slack > max(tolerance, roundoff_bound(2)) * scales.displacement, slack


def translation_start(system: ContactSystem, linear, tolerance: float) -> np.ndarray | None:
    """Where a cold start whose supports' own solution is ``system.translation`` begins
    (:func:`_translation_update`), without solving: Newton's update from it. None when that
    solution is no such translation. Needs no factorisation: a caller may run it while
    ``linear`` is analysed in another thread."""
    translated = _translation_update(system, linear, tolerance)
    return None if translated is None else translated[0]
