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
- ΓN is the discrete problem's natural boundary (:class:`contactfem.discretize.NaturalBoundary`):
  every boundary edge whose traction is prescribed in some direction. Free parts and parts
  the case does not list (g = 0), tractions (g given, or σ(u_exact)ν for
  ``traction: exact``) and pressures (g = −p ν) contribute the whole residual g − σ_T ν; a
  roller (a displacement part with one component left free) the residual of that component
  only; a symmetry line its tangential component only (the normal component is the
  support's reaction, not an error).
- Scaling: the residual terms are stresses² × length², the energy error a(e, e) is
  stress × displacement × length; dividing the residual terms by 2μ (a(v, v) ≥ 2μ‖ε(v)‖²)
  makes η an estimate of the energy norm a(u − u_h, u − u_h)^{1/2} in the case's units,
  so its effectivity index does not depend on the units of the case. The complementarity
  term already has energy units and is not scaled. Without the scaling (μ = ½) the formula
  is Hild–Nicaise's estimator η_1..η_5 verbatim.
- Quadrature: exact for the P1/P0 parts (jumps, contact residual: λ_h is linear and σ_T
  constant on an edge, so ‖·‖²_E = h_E/3 (r_0² + r_0 r_1 + r_1²) and ∫_E λ_h s =
  h_E/6 (2λ_0 s_0 + λ_0 s_1 + λ_1 s_0 + 2λ_1 s_1)); the 7-point degree-5 rule on triangles
  for f; on edges, g at the points of the one boundary rule the load vector was assembled
  with (Simpson's, exact for linear g). The data oscillation terms of the theory are not
  separated: ‖f‖ and ‖g − σν‖ contain them. Dirichlet data are taken as interpolated
  exactly (no term for the interpolation of a nonlinear prescribed displacement).

The estimator is defined for method (4); for method (5) the multiplier θh may be
negative and the complementarity term loses its sign, so :func:`estimate` refuses it.
Everything is vectorised and reads the mesh's own topology (edges and the triangles on
each side); nothing here reads the case.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactfem.assembly import edge_geometry
from contactfem.discretize import DiscreteProblem
from contactfem.quadrature import EDGE_RULE_WEIGHTS, TRIANGLE_POINTS, TRIANGLE_WEIGHTS
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


def estimate(problem: DiscreteProblem, solution: Solution) -> Estimate:
    """Element indicators η_T and the global estimate η of a method (4) solution."""
    if solution.method != "positive":
        raise ValueError(f"the residual estimator is defined for method (4) 'positive', not {solution.method!r}")
    mesh = problem.mesh
    points, triangles = mesh.points, mesh.triangles
    n_tri = len(triangles)
    scale = 1.0 / (2.0 * problem.law.mu)
    sigma = stress_tensors(solution.stress)
    terms = {name: np.zeros(n_tri) for name in TERM_NAMES}

    # Volume: h_T² ‖f‖²_T (div σ(u_h) = 0 for P1).
    force = problem.loads.body_force
    if force is not None:
        terms["volume"] = volume_terms(points, triangles, force, scale, mesh.triangle_diameters(),
                                       mesh.triangle_areas())

    # Interior edges: t1 has the edge running lo → hi (its outward normal is edge_geometry's).
    topology = mesh.topology
    interior = (topology.edge_triangles >= 0).all(axis=1)
    t1, t2 = topology.edge_triangles[interior].T
    length, normal = edge_geometry(points, topology.edges[interior])
    share = jump_shares(sigma[t1], sigma[t2], length, normal, scale)
    terms["jump"] = np.bincount(t1, share, minlength=n_tri) + np.bincount(t2, share, minlength=n_tri)

    # Natural boundary: ‖P (g − σ_T ν)‖² with P the directions the supports leave free.
    natural = problem.loads.natural
    if len(natural.edges):
        tri = _edge_triangle(mesh, natural.edges)
        terms["neumann"] = np.bincount(tri, natural_terms(natural, sigma[tri], scale), minlength=n_tri)

    # Contact edges: σ_T ν + λ_h n along n and t, and ∫ λ_h (g0 − u_hn).
    contact = problem.contact
    if len(contact.edges):
        tri = _edge_triangle(mesh, contact.edges)
        lam = np.zeros(mesh.n_points)
        lam[solution.contact.nodes] = solution.contact.multiplier
        parts = contact_terms(contact, points, sigma[tri], lam, solution.displacement, scale)
        for name, values in zip(("contact_normal", "contact_tangential", "complementarity"), parts):
            terms[name] = np.bincount(tri, values, minlength=n_tri)

    squared = sum(terms.values())
    return Estimate(indicators=np.sqrt(squared), terms=terms, total=float(np.sqrt(squared.sum())))


def stress_tensors(stress: np.ndarray) -> np.ndarray:
    """The symmetric 2×2 tensors (t, 2, 2) of stresses (t, 4), columns xx yy xy zz."""
    sigma = np.empty((len(stress), 2, 2))
    sigma[:, 0, 0], sigma[:, 1, 1] = stress[:, 0], stress[:, 1]
    sigma[:, 0, 1] = sigma[:, 1, 0] = stress[:, 2]
    return sigma


def volume_terms(points: np.ndarray, triangles: np.ndarray, force, scale: float, h: np.ndarray,
                 area: np.ndarray) -> np.ndarray:
    """h_T² ‖f‖²_T / (2μ) of each triangle (t,), by the degree-5 rule."""
    corners = points[triangles]
    total = np.zeros(len(triangles))
    for weight, bary in zip(TRIANGLE_WEIGHTS, TRIANGLE_POINTS):
        q = np.einsum("i,tia->ta", bary, corners)
        f = force(q[:, 0], q[:, 1])
        total += weight * np.sum(f * f, axis=1)
    return scale * h**2 * area * total


def jump_shares(sigma_1: np.ndarray, sigma_2: np.ndarray, length: np.ndarray, normal: np.ndarray,
                scale: float) -> np.ndarray:
    """Each side's half of h_E ‖[σν]‖²_E / (2μ) of interior edges (e,): σ of the triangle the
    normal leaves (e, 2, 2), of the other, the edges' lengths and unit normals."""
    jump = np.einsum("eab,eb->ea", sigma_1 - sigma_2, normal)
    return scale * 0.5 * length**2 * np.sum(jump * jump, axis=1)


def natural_terms(natural, sigma: np.ndarray, scale: float) -> np.ndarray:
    """h_E ‖P (g − σ_T ν)‖²_E / (2μ) of each natural edge (k,), σ_T (k, 2, 2) its triangle's."""
    own = np.einsum("eab,eb->ea", sigma, natural.normal)  # σ_T ν, constant on each edge
    residual2 = np.zeros(len(natural.edges))
    for weight, g in zip(EDGE_RULE_WEIGHTS, natural.traction):
        r = np.einsum("eab,eb->ea", natural.free, g - own)
        residual2 += weight * np.sum(r * r, axis=1)
    return scale * natural.length**2 * residual2


def contact_terms(contact, points: np.ndarray, sigma: np.ndarray, lam: np.ndarray, displacement: np.ndarray,
                  scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The normal, tangential and complementarity terms of each contact edge (k,): σ_T
    (k, 2, 2) its triangle's, ``lam`` the multiplier and ``displacement`` (n, 2) at the mesh's
    nodes (read at the contact edges' ends only)."""
    n, t, node_normal = _contact_directions(contact, points)
    e = contact.edges
    L, edge_normal = edge_geometry(points, e)
    traction = np.einsum("eab,eb->ea", sigma, edge_normal)
    l0, l1 = lam[e[:, 0]], lam[e[:, 1]]
    if n is None:  # a curved obstacle: each edge along the mean of its nodes' normals
        n = node_normal[e[:, 0]] + node_normal[e[:, 1]]
        n = n / np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-300)[:, None]
        t = np.stack([-n[:, 1], n[:, 0]], axis=1)
        along_n, along_t = np.einsum("ea,ea->e", traction, n), np.einsum("ea,ea->e", traction, t)
    else:
        along_n, along_t = traction @ n, traction @ t
    r0, r1 = along_n + l0, along_n + l1
    normal_part = L / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
    tangential_part = L * along_t ** 2
    ends = np.unique(e)
    slack = np.zeros(len(points))
    if node_normal is None:
        slack[ends] = contact.obstacle.gap(points[ends]) - displacement[ends] @ n
    else:
        slack[ends] = contact.obstacle.gap(points[ends]) - np.einsum("ea,ea->e", displacement[ends],
                                                                     node_normal[ends])
    s0, s1 = slack[e[:, 0]], slack[e[:, 1]]
    complementarity = np.maximum(L / 6.0 * (2 * l0 * s0 + l0 * s1 + l1 * s0 + 2 * l1 * s1), 0.0)
    return scale * L * normal_part, scale * L * tangential_part, complementarity


def _edge_triangle(mesh, edges: np.ndarray) -> np.ndarray:
    """The one triangle (k,) of each boundary edge (k, 2)."""
    topology = mesh.topology
    index = topology.edge_index(edges[:, 0], edges[:, 1])
    if (index < 0).any():
        raise ValueError("a boundary edge of the problem is not an edge of its mesh")
    return topology.edge_triangles[index].max(axis=1)


def _contact_directions(contact, points: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """A flat obstacle's normal and tangent (and None); for a curved one (None, None and
    each mesh node's obstacle normal (n_points, 2) at its closest point, on ΓC's nodes)."""
    if getattr(contact.obstacle, "flat", False):
        return contact.normal, contact.tangent, None
    node_normal = np.zeros((len(points), 2))
    ends = np.unique(contact.edges)
    node_normal[ends] = contact.obstacle.normals(points[ends])
    return None, None, node_normal
