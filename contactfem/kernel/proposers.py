"""Accelerators of the active set iteration: proposers of a better next set than Newton's update.

The semismooth Newton loop (:mod:`contactfem.kernel.newton`) computes Newton's update of
the active set after every solve. A *proposer* may offer a different next set; the loop
takes the first proposal that differs from Newton's update and from every set solved
before. Proposals change how many steps a solve takes, never its answer: Newton's update
alone decides when the set has settled, and the certificate checks the final iterate.

A proposer implements :class:`Proposer`:

- ``propose(step)`` returns a set (m,) bool or None;
- ``overruled()`` is told that the next set came from elsewhere than its own proposal
  (another proposer, the cycle safeguard) or that its proposal was refused as seen;
- ``unsolvable()`` is told that its last proposal left the body free (a singular
  stiffness): it proposes no more.

The proposers shipped are :class:`CoarserLevel` (a prediction from a coarser mesh, asked
when the first step does not settle or the iteration stalls) and :class:`FrontsProposer`
(:class:`contactfem.kernel.fronts.ZoneFronts`). The switches in
:class:`Accelerators` turn each accelerator off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from contactfem.kernel.fronts import ZoneFronts

#: Steps after which a solve that has not settled asks :class:`CoarserLevel` for its
#: stalled guess (a coarser level's prediction, for a problem too small to have started
#: from one): a body in bending peeling off creeps a node per edge per step, which a
#: coarser level does at a quarter of the size.
STALL_ITERATIONS = 15


@dataclass(frozen=True)
class Accelerators:
    """Which accelerators a solve uses; each changes the cost of a solve, never its answer.

    ``sequencing``: start from (or go on from) the active set a coarser mesh predicts;
    ``zone_fronts``: move creeping zone edges ahead (:class:`FrontsProposer`);
    ``schur_updates``: solve a changed active set by Schur-complement updates of one
    factorisation instead of factorising every set
    (:class:`contactfem.kernel.schur.ActiveSetSolver`); ``start_checks``: correct a load
    path step's start where its Schur system alone shows Newton's update would change it
    (:meth:`contactfem.kernel.PathSolver.checked_start`).
    """

    sequencing: bool = True
    zone_fronts: bool = True
    schur_updates: bool = True
    start_checks: bool = True


@dataclass(frozen=True, eq=False)
class Step:
    """What a proposer sees after a solve.

    ``iteration``: the loop's step (1, 2, ...); ``number``: the same, counting a start
    known without a solve as a step; ``active``: the set just solved; ``newton``: Newton's
    update of it; ``reaction`` (m,): the reactions at the active contact normals (zero
    elsewhere); ``slack`` (m,): d − G.
    """

    iteration: int
    number: int
    active: np.ndarray
    newton: np.ndarray
    reaction: np.ndarray
    slack: np.ndarray


class Proposer(Protocol):
    """Offers a next active set (see the module docstring)."""

    name: str

    def propose(self, step: Step) -> np.ndarray | None: ...

    def overruled(self) -> None: ...

    def unsolvable(self) -> None: ...


class CoarserLevel:
    """The active set a coarser level predicts, asked at most twice.

    ``first`` is asked after the first step when that step does not settle (the starting
    set was not already the answer, so the coarse solve is paid for only then); ``stalled``
    when the iteration has not settled after :data:`STALL_ITERATIONS` steps. Either is a
    callable returning a set (m,) bool or None.
    """

    name = "coarser level"

    def __init__(self, first: Callable[[], np.ndarray | None] | None = None,
                 stalled: Callable[[], np.ndarray | None] | None = None) -> None:
        self.first, self.stalled = first, stalled

    def propose(self, step: Step) -> np.ndarray | None:
        ask = (self.first if step.iteration == 1 else
               self.stalled if step.iteration == STALL_ITERATIONS else None)
        if ask is None:
            return None
        guess = ask()
        return None if guess is None else np.asarray(guess, dtype=bool).copy()

    def overruled(self) -> None:
        return None

    def unsolvable(self) -> None:
        self.first = self.stalled = None


class FrontsProposer:
    """:class:`contactfem.kernel.fronts.ZoneFronts` as a proposer, built at the second step
    (a solve that settles at once never pays for ordering ΓC)."""

    name = "zone fronts"

    def __init__(self, edges: np.ndarray, m: int) -> None:
        self.edges, self.m = edges, m
        self.fronts: ZoneFronts | None = None
        self.enabled = True

    def propose(self, step: Step) -> np.ndarray | None:
        if not self.enabled or step.number < 2:
            return None
        if self.fronts is None:
            self.fronts = ZoneFronts(self.edges, self.m)
        if not self.fronts.enabled:
            return None
        extended, moved = self.fronts.extend(step.active, step.newton)
        return extended if moved else None

    def overruled(self) -> None:
        if self.fronts is not None:
            self.fronts.forget()

    def unsolvable(self) -> None:
        self.enabled = False


def default_proposers(contact_edges: np.ndarray | None, m: int, accelerators: Accelerators,
                      first: Callable[[], np.ndarray | None] | None = None,
                      stalled: Callable[[], np.ndarray | None] | None = None) -> list[Proposer]:
    """The proposers a solve asks, in order: the coarser level's guesses (``first``,
    ``stalled``; with ``accelerators.sequencing``), then the zone fronts along
    ``contact_edges`` (with ``accelerators.zone_fronts``)."""
    proposers: list[Proposer] = []
    if accelerators.sequencing and (first is not None or stalled is not None):
        proposers.append(CoarserLevel(first, stalled))
    if accelerators.zone_fronts and contact_edges is not None:
        proposers.append(FrontsProposer(contact_edges, m))
    return proposers
