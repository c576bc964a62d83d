"""What the active-set solvers share: the scales, residual and certificate of an iterate they solved."""

from __future__ import annotations

import numpy as np

from contactfem.kernel.certificate import Certificate, Scales, ZERO_FORCE_STRAIN, FORCE_RESOLUTION_LIMIT, \
    build_certificate


class IterateMeasures:
    """Measures an iterate of a linear solver of the active set iteration.

    The solver provides ``stiffness`` K (CSR), ``absolute`` |K|, ``load``, ``supported``
    (n,) bool, ``normal_dofs``, ``gap``, ``gamma`` (the round-off bound of a row of K),
    ``force_unit`` and ``checks`` (the singularity checks of its factorisations), and after
    each solve ``_solved``, ``_internal`` and ``_absolute``: its u, K u and |K| |u|.
    """

    @property
    def free_rows(self) -> np.ndarray:
        """Rows of the residual that are equations (not supports), for residual checks."""
        return ~self.supported

    @property
    def condition(self) -> float:
        """The condition estimate κ̂ of the current factorisation (1 before any)."""
        return self.checks[-1].condition if self.checks else 1.0

    def measure(self, u: np.ndarray, nodal_force: np.ndarray) -> Scales:
        """Force and displacement scales of the iterate (u, Λ = Bμ) and its equilibrium residual."""
        contact = np.zeros(len(u))
        contact[self.normal_dofs] = nodal_force
        # K u of the last solve, when this is its u (it was computed for its acceptance test).
        solved = u is self._solved
        internal = self._internal if solved else self.stiffness @ u
        equations = ~self.supported
        with np.errstate(invalid="ignore", over="ignore"):
            residual = (internal + contact - self.load)[equations]
            absolute = self._absolute if solved else self.absolute @ np.abs(u)
            terms = (absolute + np.abs(self.load) + np.abs(contact))[equations]
            force = (np.abs(self.load).max(initial=0.0) + np.abs(internal).max(initial=0.0)
                     + np.abs(nodal_force).max(initial=0.0))
            roundoff = self.gamma * terms.max(initial=0.0)
            if not np.any(self.load) and force * FORCE_RESOLUTION_LIMIT < roundoff:
                # Nothing loads the body, and its forces (K u, the contact's) are round-off:
                # a block lifted off the plane by its prescribed top, a load path's steps
                # before contact or the one where a node just grazes it. The exact forces
                # are zero, and round-off gives them no scale of their own; they are
                # measured against the force of a strain of ZERO_FORCE_STRAIN over the body,
                # so certified if round-off stays below 1e-3 of that: a rigid motion of up to
                # some 1e3-1e4 body sizes (the rough block lifted by 1e3 of its sizes is, by
                # 1e4 not; the square by 1e4 is, by 1e5 not; a translation by 1e45 never).
                force = max(force, ZERO_FORCE_STRAIN * self.force_unit)
            force = max(force, np.finfo(float).tiny) if np.isfinite(force) else np.inf
            displacement = max(np.abs(u).max(initial=0.0), np.abs(self.gap).max(initial=0.0))
            displacement = max(displacement, np.finfo(float).tiny) if np.isfinite(displacement) else np.inf
            return Scales(
                force=float(force),
                displacement=float(displacement),
                roundoff=float(roundoff / force),
                equilibrium=float(np.abs(residual).max(initial=0.0) / force),
            )

    def normals(self, u: np.ndarray) -> np.ndarray:
        """The normal displacement of every contact node (m,)."""
        return u[self.normal_dofs]

    def non_finite(self, u: np.ndarray) -> int:
        """Entries of u that are not finite."""
        return int(np.count_nonzero(~np.isfinite(u)))

    def certify(self, u: np.ndarray, multiplier: np.ndarray, nodal_force: np.ndarray, scales: Scales,
                tolerance: float) -> Certificate:
        """The :class:`Certificate` of the iterate (u, μ, Λ = Bμ) with its ``scales``."""
        return build_certificate(self.non_finite(u), self.normals(u) - self.gap, multiplier, nodal_force, scales,
                                 tolerance, self.condition)
