"""Active sets that hold the free rigid motions of a body that contact alone holds."""

from __future__ import annotations

import numpy as np

from contactfem.kernel.system import ContactSystem


class ModeHolder:
    """Completes an active set so that it holds the free rigid motions: K with the active
    normals fixed is singular unless the motions' normal components at the active nodes
    have full rank. Added nodes are the kernel's own candidates (largest indicator); one
    that should not be active fails the certificate instead of changing the answer."""

    def __init__(self, system: ContactSystem) -> None:
        modes = np.asarray(system.free_modes, dtype=float)
        self.normal = modes[np.asarray(system.normal_dofs, dtype=np.int64)]  # (m, j)
        self.gap = np.asarray(system.gap, dtype=float)
        self.rank = int(self.normal.shape[1])
        load = np.asarray(system.load, dtype=float) @ modes
        # Each motion oriented the way the load pushes it.
        self.pushed = self.normal * np.where(load < 0, -1.0, 1.0)
        self.scale = float(np.abs(self.normal).max(initial=0.0))

    def rank_of(self, active: np.ndarray) -> int:
        if not active.any():
            return 0
        values = np.linalg.svd(self.normal[active], compute_uv=False)
        return int((values > 1e-10 * self.scale).sum())

    def holds(self, active: np.ndarray) -> bool:
        return self.rank_of(active) >= self.rank

    def first_touch(self) -> np.ndarray:
        """Priority of each node by how soon the pushed motions close its gap (larger: sooner)."""
        along = self.pushed.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(along > 1e-10 * self.scale, -self.gap / along, -np.inf)

    def hold(self, active: np.ndarray, priority: np.ndarray) -> np.ndarray:
        if self.holds(active):
            return active
        held = active.copy()
        candidates = np.flatnonzero(~active)
        # Nodes that never close come last, in order of gap.
        order = np.lexsort((self.gap[candidates], -priority[candidates]))
        rank = self.rank_of(held)
        for node in candidates[order]:
            trial = held.copy()
            trial[node] = True
            if self.rank_of(trial) > rank:
                held, rank = trial, rank + 1
                if rank >= self.rank:
                    break
        return held
