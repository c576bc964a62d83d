"""The cycle safeguard of the active set iteration: sets already solved, oscillating nodes held, Murty's rule."""

from __future__ import annotations

import numpy as np


def _key(active: np.ndarray) -> bytes:
    return np.packbits(active).tobytes()


class CycleGuard:
    """Remembers every set solved and turns a next set that repeats one into a safe one.

    Plain Newton revisits a set on hard problems. On a fragmented contact zone the nodes
    that ping-pong are few among many correct changes: first every change of a node that
    has not flipped back and forth is kept, and only the lowest-numbered of the oscillating
    ones. If a set repeats even so, one node changes at a time, the lowest-numbered one
    whose sign condition fails (Murty's least-index rule), which terminates on P-matrix
    problems such as this one (S = P K⁻¹ Pᵀ is SPD). With ``safeguard`` False a repeat
    stops the iteration instead.
    """

    def __init__(self, m: int, safeguard: bool = True) -> None:
        self.safeguard = safeguard
        self.seen: dict[bytes, int] = {}
        #: The step at which a set first repeated (None: never).
        self.detected_at: int | None = None
        self.least_index = False
        self.least_index_from = 0
        self.flips = np.zeros(m, dtype=np.int64)

    def solved(self, active: np.ndarray, iteration: int) -> None:
        self.seen[_key(active)] = iteration

    def was_solved(self, active: np.ndarray) -> bool:
        return _key(active) in self.seen

    def next_set(self, active: np.ndarray, proposed: np.ndarray, iteration: int) -> tuple[np.ndarray | None, str]:
        """The set to solve after ``active`` instead of ``proposed``, or None and why the
        iteration cycles."""
        key = _key(proposed)
        if key in self.seen and not self.safeguard:
            return None, (f"the active set cycles: iteration {iteration + 1} would repeat the set of "
                          f"iteration {self.seen[key]}")
        if key in self.seen and self.detected_at is None:
            self.detected_at = iteration
        following = proposed.copy()
        changing = following != active
        if self.detected_at is not None and not self.least_index:
            oscillating = changing & (self.flips >= 2)
            if oscillating.any():
                held = np.flatnonzero(oscillating)[1:]
                following[held] = active[held]
                changing = following != active
            if _key(following) in self.seen:
                self.least_index, self.least_index_from = True, iteration
        if self.least_index:
            first_wrong = np.flatnonzero(changing)[0]
            following = active.copy()
            following[first_wrong] = not active[first_wrong]
            # Only a set the rule itself has visited is a cycle of it: its sequence may pass
            # through sets of the plain iteration before it.
            if self.seen.get(_key(following), 0) >= self.least_index_from:
                return None, (f"the active set cycles (first detected at iteration {self.detected_at}) "
                              "even under the least-index safeguard")
        return following, ""

    def moved(self, active: np.ndarray, following: np.ndarray) -> None:
        self.flips += following != active

    def resolution(self) -> str:
        """How a cycle met on the way was resolved, for the message of a converged solve."""
        if self.detected_at is None:
            return ""
        return (f"; the active set cycled at iteration {self.detected_at}, resolved by "
                + ("least-index single changes" if self.least_index else
                   "holding the oscillating nodes but the least-index one"))

    def hint(self) -> str:
        """What to do when the cap is reached under the least-index rule."""
        if not self.least_index:
            return ""
        return (f"; the least-index safeguard, a node per step since iteration {self.least_index_from}, had not "
                "settled: raise solver.max_iterations")
