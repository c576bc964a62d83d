"""A rigid obstacle driven along a direction: its advance as a shift of the supports.

Small deformations: the obstacle's gaps and normals are those of its rest position, and
moving it by δ d is the same as holding it still while every support moves by −δ d (a
rigid translation strains nothing). So a prescribed advance shifts every prescribed
displacement component c by −δ d_c, the kernel's system keeps its gaps, and the solved
field is moved back by +δ d (:meth:`ObstacleDrive.moved`). A load path scales δ with the
other prescribed values. A pushed obstacle (a force F along d) is driven the same way, its
advance the unknown δ whose reaction −Σ Λ_i n_i · d equals F (:mod:`contactfem.indenter`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from contactfem.case import Case, PlatenControl
from contactfem.errors import CaseError

if TYPE_CHECKING:
    from contactfem.discretize.supports import Supports


@dataclass(frozen=True, eq=False)
class ObstacleDrive:
    """The obstacle's motion: unit ``direction`` (2,), the ``advance`` δ the supports are
    shifted by, and the ``force`` it is pushed with (None when the advance is prescribed)."""

    direction: np.ndarray
    advance: float
    force: float | None = None
    #: Whether the advance is still the unknown of a pushed obstacle (False once a trial
    #: advance is set: :meth:`contactfem.discretize.problem.DiscreteProblem.advanced`).
    free: bool = False

    @property
    def pushed(self) -> bool:
        return self.force is not None and self.free

    def moved(self, displacement: np.ndarray) -> np.ndarray:
        """The displacement (n_points, 2) with the obstacle moved back to where it went."""
        return displacement + self.advance * self.direction

    def gap(self, gap: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Each contact node's gap (m,) to the obstacle at its advanced position."""
        return gap + self.advance * (normals @ self.direction)

    def reaction(self, nodal_force: np.ndarray, normals: np.ndarray) -> float:
        """The force along the direction that holds the obstacle against the contact forces."""
        return float(-(nodal_force @ (normals @ self.direction)))


def obstacle_drive(case: Case, held: "Supports") -> tuple[ObstacleDrive | None, "Supports"]:
    """The case's obstacle motion and the supports shifted by it (unchanged without one);
    refuses supports the shift cannot carry."""
    motion = case.obstacle.motion
    if motion is None:
        return None, held
    name = case.source.name
    direction = np.asarray(motion.direction, dtype=float)
    if held.platens:
        raise CaseError(f"{name}: obstacle.motion: a moving obstacle with a platen "
                        f"(boundary.{held.platens[0].name}); expected supports that hold the body still "
                        f"(clamped, prescribed displacements, symmetry lines along the motion)")
    across = np.abs(held.symmetry_normals @ direction) > 1e-12
    if across.any():
        raise CaseError(f"{name}: obstacle.motion.direction = {list(motion.direction)}: crosses a symmetry line "
                        f"(its normal {held.symmetry_normals[np.argmax(across)].tolist()}); expected a motion "
                        f"along every symmetry line")
    if len(held.dirichlet_dofs) == 0:
        raise CaseError(f"{name}: obstacle.motion: nothing holds the body (no clamped or prescribed part); "
                        f"expected supports that keep the body from following the obstacle")
    pushed = motion.control is PlatenControl.FORCE
    drive = ObstacleDrive(direction=direction, advance=0.0 if pushed else motion.value,
                          force=motion.value if pushed else None, free=pushed)
    return drive, shifted(held, drive.advance, direction)


def shifted(held: "Supports", advance: float, direction: np.ndarray) -> "Supports":
    """``held`` with every prescribed component c moved by −advance · d_c."""
    if advance == 0.0:
        return held
    dofs = held.dirichlet_dofs
    return replace(held, dirichlet_values=held.dirichlet_values - advance * direction[dofs % 2])


def refuse_receding(case: Case, drive: ObstacleDrive | None, gap: np.ndarray, normals: np.ndarray) -> None:
    """Refuse a motion that can bring the obstacle to no contact node: every node apart from
    it and none it moves towards (d · n < 0)."""
    if drive is None or not len(gap) or np.any(gap <= 0.0) or np.any(normals @ drive.direction < -1e-12):
        return
    raise CaseError(f"{case.source.name}: obstacle.motion.direction = {list(case.obstacle.motion.direction)}: moves "
                    "the obstacle away from every contact node it faces, which it can then never reach; expected a "
                    "direction towards the body")
