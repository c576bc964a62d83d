"""Residual a posteriori error estimator of method (4), after Hild & Nicaise.

P. Hild and S. Nicaise, "A posteriori error estimations of residual type for Signorini's
problem", Numer. Math. 101 (2005) 523–549, introduced the positivity-preserving method (4)
(reference [7] of the note this package implements) together with a residual estimator;
the elasticity version is Hild & Nicaise, M2AN 41 (2007) 897–923. Their estimator has the
usual residual terms of linear elasticity, two residuals of the frictionless contact
conditions σ(u)ν = −λ n, σ_t = 0 on ΓC, and one complementarity term
(∫_{T∩ΓC} −λh u_hn)^{1/2} that is nonnegative precisely because λh ≥ 0 and u_hn ≤ 0
hold pointwise for method (4) — the term that makes this estimator "simple".

What is implemented, per triangle T (P1 displacement: σ_T = σ(u_h)|_T is constant and
div σ(u_h) = 0 in T):

    η_T² = 1/(2μ) · [ h_T² ‖f‖²_T                                        (volume)
                     + Σ_{E ⊂ ∂T interior}  ½ h_E ‖[σ(u_h) ν]_E‖²_E        (jumps)
                     + Σ_{E ⊂ ∂T ∩ ΓN}      h_E ‖g − σ_T ν‖²_E             (Neumann)
                     + Σ_{E ⊂ ∂T ∩ ΓC}      h_E ‖λ_h + n·σ_T ν‖²_E         (contact, normal)
                     + Σ_{E ⊂ ∂T ∩ ΓC}      h_E ‖t·σ_T ν‖²_E ]             (contact, tangential)
           + Σ_{E ⊂ ∂T ∩ ΓC} ∫_E λ_h (g0 − u_hn)                          (complementarity)

and η = (Σ_T η_T²)^{1/2}. Notation and conventions:

- h_T is the longest edge of T, h_E the length of E, ν the outward unit normal of T on E,
  [σν]_E = (σ_{T1} − σ_{T2}) ν_{T1} the jump across an interior edge (each of its two
  triangles takes half of h_E ‖[σν]‖²_E).
- n is the obstacle's unit normal pointing from the body into the obstacle (the case's
  ``obstacle.normal``), t = (−n_y, n_x); λ = −σ_n ≥ 0 is the pressure, u_n = u·n ≤ g0,
  g0(x) = (point − x)·n the initial gap (affine along ΓC). The discrete problem's contact
  term ∫ λ_h v·n makes σ(u_h)ν = −λ_h n the natural condition, so the contact residual is
  the vector σ_T ν + λ_h n, split along n and t. On a flat ΓC resting on the obstacle
  ν = n and the two terms are exactly Hild–Nicaise's ‖λ_h + σ_n(u_h)‖ and ‖σ_t(u_h)‖.
- The complementarity term generalises Hild–Nicaise's ∫ λ_h (−u_hn) (zero gap) to the
  gap: it is ∫ λ_h (g0 − u_hn) ≥ 0, both factors P1 and ≥ 0 on each ΓC edge (λ_h ≥ 0 and
  u_hn ≤ g0 at the nodes). With nodal complementarity λ_x (g0 − u_hn)(x) = 0 it lives only
  on edges joining an active and an inactive node. Round-off negatives are clipped at 0.
- On ΓC, λ_h is the P1 field of the nodal multipliers, zero at ΓC nodes that belong to a
  support (they carry no multiplier, W_h vanishes there).
- ΓN is every boundary part that is not clamped, contact or displacement: free parts and
  parts the case does not list (g = 0), tractions (g given, or σ(u_exact)ν for
  ``traction: exact``), pressures (g = −p ν). A displacement part with one component left
  free (a roller) contributes the residual of that component only.
- Scaling: the residual terms are stresses² × length², the energy error a(e, e) is
  stress × displacement × length; dividing the residual terms by 2μ (a(v, v) ≥ 2μ‖ε(v)‖²)
  makes η an estimate of the energy norm a(u − u_h, u − u_h)^{1/2} in the case's units,
  so its effectivity index does not depend on the units of the case. The complementarity
  term already has energy units and is not scaled. Without the scaling (μ = ½) the formula
  is Hild–Nicaise's estimator η_1..η_5 verbatim.
- Quadrature: exact for the P1/P0 parts (jumps, contact residual: λ_h is linear and σ_T
  constant on an edge, so ‖·‖²_E = h_E/3 (r_0² + r_0 r_1 + r_1²) and ∫_E λ_h s =
  h_E/6 (2λ_0 s_0 + λ_0 s_1 + λ_1 s_0 + 2λ_1 s_1)); the 7-point degree-5 rule on triangles
  for f; 5-point Gauss on edges for g. The data oscillation terms of the theory are not
  separated: ‖f‖ and ‖g − σν‖ contain them. Dirichlet data are taken as interpolated
  exactly (no term for the interpolation of a nonlinear prescribed displacement).

The estimator is defined for method (4); for method (5) the multiplier θh may be
negative and the complementarity term loses its sign, so :func:`estimate` refuses it.
Everything is vectorised: interior edges are paired through one sort of the half-edge
keys (an edge → (t1, t2) map), boundary edges are found in the same sorted keys.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactfem.assembly import edge_geometry
from contactfem.case import Case
from contactfem.discretize import DiscreteProblem
from contactfem.quadrature import TRIANGLE_POINTS, TRIANGLE_WEIGHTS
from contactfem.result import Solution

#: Names of the parts of η², in the order of the formula above.
TERM_NAMES = ("volume", "jump", "neumann", "contact_normal", "contact_tangential", "complementarity")


@dataclass(frozen=True, eq=False)
class Estimate:
    """The estimator of one solution.

    Attributes
    ----------
    indicators : (n_triangles,) float64
        η_T, the element indicators (square roots).
    terms : dict of str to (n_triangles,) float64
        Each of :data:`TERM_NAMES` as its contribution to η_T² (already scaled by 1/(2μ)).
    total : float
        η = (Σ η_T²)^{1/2}.
    """

    indicators: np.ndarray
    terms: dict[str, np.ndarray]
    total: float

    def summary(self) -> dict:
        """JSON-ready: η and each term's share (Σ_T of its contribution)^{1/2}."""
        return {
            "eta": float(self.total),
            "terms": {name: float(np.sqrt(max(values.sum(), 0.0))) for name, values in self.terms.items()},
            "max_indicator": float(self.indicators.max(initial=0.0)),
        }


def estimate(case: Case, problem: DiscreteProblem, solution: Solution) -> Estimate:
    """Element indicators η_T and the global estimate η of a method (4) solution."""
    if solution.method != "positive":
        raise ValueError(f"the residual estimator is defined for method (4) 'positive', not {solution.method!r}")
    mesh = problem.mesh
    points, triangles = mesh.points, mesh.triangles
    n_tri = len(triangles)
    law = problem.law
    scale = 1.0 / (2.0 * law.mu)
    sxx, syy, sxy = solution.stress[:, 0], solution.stress[:, 1], solution.stress[:, 2]
    sigma = np.empty((n_tri, 2, 2))
    sigma[:, 0, 0], sigma[:, 1, 1] = sxx, syy
    sigma[:, 0, 1] = sigma[:, 1, 0] = sxy
    terms = {name: np.zeros(n_tri) for name in TERM_NAMES}

    # Volume: h_T² ‖f‖²_T (div σ(u_h) = 0 for P1).
    force = _body_force(case)
    if force is not None:
        h = mesh.triangle_diameters()
        area = mesh.triangle_areas()
        corners = points[triangles]
        total = np.zeros(n_tri)
        for weight, bary in zip(TRIANGLE_WEIGHTS, TRIANGLE_POINTS):
            q = np.einsum("i,tia->ta", bary, corners)
            f = force(q[:, 0], q[:, 1])
            total += weight * np.sum(f * f, axis=1)
        terms["volume"] = scale * h**2 * area * total

    # Edges: one sort of the half-edge keys pairs the interior ones.
    n_points = mesh.n_points
    starts = triangles.T.reshape(-1)
    ends = triangles[:, [1, 2, 0]].T.reshape(-1)
    owner = np.tile(np.arange(n_tri), 3)
    keys = np.minimum(starts, ends).astype(np.int64) * n_points + np.maximum(starts, ends)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    _, first, counts = np.unique(sorted_keys, return_index=True, return_counts=True)
    pair = first[counts == 2]
    h1, h2 = order[pair], order[pair + 1]
    t1, t2 = owner[h1], owner[h2]
    length, normal = edge_geometry(points, np.stack([starts[h1], ends[h1]], axis=1))
    jump = np.einsum("eab,eb->ea", sigma[t1] - sigma[t2], normal)
    share = scale * 0.5 * length**2 * np.sum(jump * jump, axis=1)
    terms["jump"] = np.bincount(t1, share, minlength=n_tri) + np.bincount(t2, share, minlength=n_tri)

    # Boundary edges: their triangle from the single half-edges.
    single = first[counts == 1]
    single_keys = sorted_keys[single]
    bedges = mesh.boundary_edges
    bkeys = np.minimum(bedges[:, 0], bedges[:, 1]).astype(np.int64) * n_points + np.maximum(bedges[:, 0], bedges[:, 1])
    slot = np.searchsorted(single_keys, bkeys)
    btri = owner[order[single[slot]]]
    blength, bnormal = edge_geometry(points, bedges)
    btraction = np.einsum("eab,eb->ea", sigma[btri], bnormal)  # σ_T ν, constant on each edge

    gauss_s, gauss_w = np.polynomial.legendre.leggauss(5)  # on [-1, 1]
    gauss_s, gauss_w = 0.5 * (gauss_s + 1.0), 0.5 * gauss_w
    a, b = points[bedges[:, 0]], points[bedges[:, 1]]
    parts = {p.name: p for p in case.parts}
    exact = case.exact.solution if case.exact is not None else None
    for index, name in enumerate(mesh.part_names):
        selected = np.flatnonzero(mesh.edge_parts == index)
        if selected.size == 0:
            continue
        part = parts.get(name)
        kind = part.kind if part is not None else "free"
        if kind in ("clamped", "contact"):
            continue
        mask = np.ones(2)
        if kind == "displacement":
            mask = np.array([0.0 if v is not None else 1.0 for v in part.values])
            if not mask.any():
                continue
        residual2 = np.zeros(selected.size)
        sel_normal = bnormal[selected]
        for s, w in zip(gauss_s, gauss_w):
            q = (1 - s) * a[selected] + s * b[selected]
            g = _traction(part, kind, exact, q, sel_normal)
            r = (g - btraction[selected]) * mask
            residual2 += w * np.sum(r * r, axis=1)
        values = scale * blength[selected] ** 2 * residual2
        terms["neumann"] += np.bincount(btri[selected], values, minlength=n_tri)

    # Contact edges: σ_T ν + λ_h n along n and t, and ∫ λ_h (g0 − u_hn).
    contact_selected = np.flatnonzero(np.isin(mesh.edge_parts, [mesh.part_index(c) for c in case.contact_parts
                                                                if c in mesh.part_names]))
    if contact_selected.size:
        n = np.asarray(case.obstacle.normal, dtype=float)
        t = np.array([-n[1], n[0]])
        lam = np.zeros(n_points)
        lam[solution.contact.nodes] = solution.contact.multiplier
        slack = (np.asarray(case.obstacle.point, dtype=float) - points) @ n - solution.displacement @ n
        e = bedges[contact_selected]
        L = blength[contact_selected]
        traction = btraction[contact_selected]
        l0, l1 = lam[e[:, 0]], lam[e[:, 1]]
        r0, r1 = traction @ n + l0, traction @ n + l1
        normal_part = L / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
        tangential_part = L * (traction @ t) ** 2
        tri = btri[contact_selected]
        terms["contact_normal"] = np.bincount(tri, scale * L * normal_part, minlength=n_tri)
        terms["contact_tangential"] = np.bincount(tri, scale * L * tangential_part, minlength=n_tri)
        s0, s1 = slack[e[:, 0]], slack[e[:, 1]]
        complementarity = np.maximum(L / 6.0 * (2 * l0 * s0 + l0 * s1 + l1 * s0 + 2 * l1 * s1), 0.0)
        terms["complementarity"] = np.bincount(tri, complementarity, minlength=n_tri)

    squared = sum(terms.values())
    return Estimate(indicators=np.sqrt(squared), terms=terms, total=float(np.sqrt(squared.sum())))


def _body_force(case: Case):
    """f(x, y) -> (k, 2), or None when the case has no volume force."""
    if case.exact is not None:
        exact = case.exact.solution
        return lambda x, y: exact.body_force(x, y)
    if case.body_force is None:
        return None
    fx, fy = case.body_force
    return lambda x, y: np.stack([np.broadcast_to(fx(x, y), x.shape), np.broadcast_to(fy(x, y), x.shape)], axis=1)


def _traction(part, kind: str, exact, q: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The prescribed surface force g (k, 2) at points q of edges with outward normals ``normal``."""
    x, y = q[:, 0], q[:, 1]
    if kind == "traction":
        if part.exact:
            return np.broadcast_to(exact.traction(x, y, normal), q.shape)
        return np.stack([np.broadcast_to(f(x, y), x.shape) for f in part.values], axis=1)
    if kind == "pressure":
        return -normal * np.broadcast_to(part.values[0](x, y), x.shape)[:, None]
    return np.zeros_like(q)  # free, unlisted, or the free component of a displacement part
