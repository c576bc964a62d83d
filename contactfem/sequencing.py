"""Mesh sequencing, as two pure steps: the same case on a coarser mesh, and the active set it predicts.

The coarse solution (h four times larger) is read along ΓC as functions of the abscissa
on the obstacle: its pressure λ and its normal displacement u_n. At each fine contact
node the indicator of the active set iteration, λ ω + c (u_n − g), is evaluated with those
interpolated values and the fine gap; the nodes where it is positive start active. Only
nodes near the ends of the contact zone can be mispredicted, so the fine iteration starts
a node or two from its answer. The recursion (solve the coarse case, itself predicted from
a coarser one) lives in :mod:`contactfem.solve`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from contactfem.case import Case, MeshFileGeometry, PolygonGeometry, RectangleGeometry
from contactfem.discretize import ContactBoundary
from contactfem.result import ContactFields

# Below this many unknowns a cold start is cheaper than solving a coarser case first.
SEQUENCING_THRESHOLD = 5_000
# Each coarser level has h four times larger: it costs about 1/16 of the finer solve,
# against 1/4 for halving, and mispredicts only nodes next to the ends of the zone, which
# the kernel's cached Schur columns absorb (measured on the square: 1024 from 256).
COARSENING = 4


def worth_sequencing(n_unknowns: int) -> bool:
    """Whether a problem of this size is worth predicting from a coarser one."""
    return n_unknowns >= SEQUENCING_THRESHOLD


def coarser(case: Case, refinements: int, factor: int = COARSENING) -> tuple[Case, int] | None:
    """The same case on a mesh ``factor`` times coarser (or twice, if that is all the
    mesh allows), with its refinement count; None if it cannot be coarsened."""
    levels = factor.bit_length() - 1
    if refinements >= 1:
        return case, max(refinements - levels, 0)
    settings = case.mesh
    if isinstance(case.geometry, RectangleGeometry):
        nx, ny = settings.divisions
        for step in (factor, 2):
            if nx % step == 0 and ny % step == 0:
                return replace(case, mesh=replace(settings, divisions=(nx // step, ny // step))), 0
        return None
    if isinstance(case.geometry, PolygonGeometry):
        contact_size = None if settings.contact_size is None else factor * settings.contact_size
        return replace(case, mesh=replace(settings, size=factor * settings.size, contact_size=contact_size)), 0
    assert isinstance(case.geometry, MeshFileGeometry)
    return None


def predict_active_set(fine: ContactBoundary, coarse: ContactFields, c: float) -> np.ndarray:
    """Initial active set (m,) of the fine contact nodes from a coarse solution's contact fields."""
    pressure = np.interp(fine.abscissa, coarse.abscissa, coarse.multiplier)
    normal = np.interp(fine.abscissa, coarse.abscissa, coarse.normal_displacement)
    return pressure * fine.masses.lumped + c * (normal - fine.gap) > 0
