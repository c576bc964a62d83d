"""A rigid obstacle driven along a direction: its advance as a shift of the supports.

Small deformations: the obstacle's gaps and normals are those of its rest position, and
moving it by δ d is the same as holding it still while every support moves by −δ d (a
rigid translation strains nothing). So a prescribed advance shifts every prescribed
displacement component c by −δ d_c, the kernel's system keeps its gaps, and the solved
field is moved back by +δ d (:meth:`ObstacleDrive.moved`). A load path scales δ with the
other prescribed values. A pushed obstacle (a force F along d) is driven the same way, its
advance δ one more unknown of the kernel's system (:class:`PushedAdvance`), as a platen's.
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
    #: Whether the advance is still the unknown of a pushed obstacle (False once the solve
    #: has found it: :meth:`contactfem.discretize.frames.ReducedSystem.settled`).
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


@dataclass(frozen=True, eq=False)
class PushedAdvance:
    """A pushed obstacle's advance δ as an unknown of the kernel: one held component p (its
    value v_p, its direction component d_p) keeps its own unknown s_p = v_p − δ d_p free;
    every other held component q is then s_q + r_q s_p, with r_q = d_q / d_p and the fixed
    s_q = v_q − r_q v_p, which is v_q − δ d_q. The work of the obstacle's force F and of the
    body's load f moved by δ d, (F + Σ f · d) δ, loads s_p with −(F + Σ f · d) / d_p: the
    equation of s_p is the obstacle's equilibrium, the contact force on it along d equal to
    F. Nothing but contact holds the translation of the whole body along d (:meth:`mode`).
    """

    #: The held component that carries δ, its position among the problem's held ones, d_p.
    slot: int
    position: int
    along: float
    #: The other held components (k,), their ratios r_q (k,), their positions among the held ones.
    coupled: np.ndarray
    ratios: np.ndarray
    rest: np.ndarray
    #: −(F + Σ f · d) / d_p: the load on s_p.
    load: float

    def fixed(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The fixed unknowns and their values, of the held values ``values`` (k + 1,)."""
        return self.coupled, values[self.rest] - self.ratios * values[self.position]

    def advance(self, reduced: np.ndarray, values: np.ndarray) -> float:
        """The advance δ of the kernel's unknowns ``reduced`` with held values ``values``."""
        return float((values[self.position] - reduced[self.slot]) / self.along)

    def release(self, reduced: np.ndarray) -> np.ndarray:
        """``reduced`` (2n,) or (2n, j) with each coupled unknown s_q = u_q − r_q u_p, of
        mesh values u at the held components (the inverse of the coupling)."""
        out = reduced.copy()
        coupling = self.ratios if reduced.ndim == 1 else self.ratios[:, None]
        out[self.coupled] -= coupling * reduced[self.slot]
        return out

    def mode(self, direction: np.ndarray, n_points: int) -> np.ndarray:
        """The translation of the whole body by −d (2 n_points,): what the force pushes."""
        return np.tile(-direction, n_points)


def pushed_advance(dofs: np.ndarray, direction: np.ndarray, force: float, load: np.ndarray,
                   framed: np.ndarray) -> PushedAdvance:
    """The coupling of the held components ``dofs`` (sorted) for an obstacle pushed by
    ``force`` along ``direction``, δ carried by the held component of largest |d_c| on a
    node that is not ``framed`` (bool per node)."""
    along = direction[dofs % 2]
    weight = np.where(framed[dofs // 2], 0.0, np.abs(along))
    position = int(np.argmax(weight))
    rest = np.delete(np.arange(len(dofs)), position)
    body = float(load[0::2].sum() * direction[0] + load[1::2].sum() * direction[1])
    return PushedAdvance(slot=int(dofs[position]), position=position, along=float(along[position]),
                         coupled=dofs[rest], ratios=along[rest] / along[position], rest=rest,
                         load=-(force + body) / float(along[position]))


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
    if not np.any(np.abs(direction[held.dirichlet_dofs % 2]) > 1e-12):
        raise CaseError(f"{name}: obstacle.motion: nothing holds the body along the motion (no clamped or "
                        f"prescribed component along it); expected supports that keep the body from following the obstacle")
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
