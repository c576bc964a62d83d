"""Vectorised P1 assembly: elasticity stiffness, loads, stresses and the contact boundary masses."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

# A field given on points: f(x, y) -> array broadcast to x's shape.
Field = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Elasticity:
    """Isotropic Hooke law in the plane, already reduced for plane strain or plane stress.

    ``lam`` is the λ that enters the 2D law: λ itself in plane strain, 2λμ/(λ+2μ) in
    plane stress. ``lam_3d`` keeps the 3D λ for the out-of-plane stress of plane strain.
    """

    lam: float
    mu: float
    plane: str  # "strain" | "stress"
    lam_3d: float

    @classmethod
    def from_lame(cls, lam: float, mu: float, plane: str = "strain") -> "Elasticity":
        lam_2d = lam if plane == "strain" else 2.0 * lam * mu / (lam + 2.0 * mu)
        return cls(lam=lam_2d, mu=mu, plane=plane, lam_3d=lam)

    @classmethod
    def from_young(cls, young: float, poisson: float, plane: str = "strain") -> "Elasticity":
        lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
        mu = young / (2.0 * (1.0 + poisson))
        return cls.from_lame(lam, mu, plane)


def shape_gradients(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the three P1 basis functions and the area of every triangle.

    Returns
    -------
    gradients : (n_triangles, 3, 2)
    areas : (n_triangles,)
    """
    p = points[triangles]
    x, y = p[..., 0], p[..., 1]
    # b_i = y_j - y_k, c_i = x_k - x_j with (i, j, k) cyclic; both over 2|T|.
    b = np.roll(y, -1, axis=1) - np.roll(y, -2, axis=1)
    c = np.roll(x, -2, axis=1) - np.roll(x, -1, axis=1)
    twice_area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    gradients = np.stack([b, c], axis=2) / twice_area[:, None, None]
    return gradients, 0.5 * twice_area


def element_dofs(triangles: np.ndarray) -> np.ndarray:
    """Interleaved unknowns (n_triangles, 6): node i carries 2i (x) and 2i+1 (y)."""
    return (2 * triangles[:, :, None] + np.arange(2)).reshape(len(triangles), 6)


def stiffness_matrix(points: np.ndarray, triangles: np.ndarray, law: Elasticity) -> sp.csr_matrix:
    """The 2n x 2n stiffness matrix of ∫ σ(u):ε(v), no boundary conditions.

    Element entries in closed form: K[(i,a),(j,b)] = |T| (λ g_i^a g_j^b + μ g_j^a g_i^b
    + μ δ_ab g_i·g_j), with g_i the gradient of the basis function of node i.
    """
    g, area = shape_gradients(points, triangles)
    n_tri = len(triangles)
    gi_gj = np.einsum("tia,tja->tij", g, g)  # (n, 3, 3)
    # Index order (t, i, a, j, b) so that the reshape below gives 6x6 blocks in dof order.
    ke = law.lam * g[:, :, :, None, None] * g[:, None, None, :, :]
    ke += law.mu * g.transpose(0, 2, 1)[:, None, :, :, None] * g[:, :, None, None, :]
    eye = np.eye(2)
    ke += law.mu * gi_gj[:, :, None, :, None] * eye[None, None, :, None, :]
    ke *= area[:, None, None, None, None]
    dofs = element_dofs(triangles)
    index_type = np.int32 if 2 * len(points) < np.iinfo(np.int32).max else np.int64
    dofs = dofs.astype(index_type)
    rows = np.broadcast_to(dofs[:, :, None], (n_tri, 6, 6)).ravel()
    cols = np.broadcast_to(dofs[:, None, :], (n_tri, 6, 6)).ravel()
    n_dof = 2 * len(points)
    matrix = sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(n_dof, n_dof)).tocsr()
    matrix.sum_duplicates()
    return matrix


def body_force_vector(points: np.ndarray, triangles: np.ndarray, force: tuple[Field, Field]) -> np.ndarray:
    """Load vector (2n,) of ∫ f·v, exact for quadratic f·v (edge-midpoint rule)."""
    _, area = shape_gradients(points, triangles)
    p = points[triangles]
    # Midpoint of the edge opposite vertex k; basis i is 1/2 at the two midpoints
    # of the edges touching i and 0 at the third.
    midpoints = 0.5 * (np.roll(p, -1, axis=1) + np.roll(p, -2, axis=1))  # (n, 3, 2), opposite k
    load = np.zeros(2 * len(points))
    for component, f in enumerate(force):
        values = np.broadcast_to(f(midpoints[..., 0], midpoints[..., 1]), midpoints.shape[:2])
        # ∫ f φ_i = |T|/3 * (1/2) * (sum of f at the two midpoints next to i)
        local = (area / 6.0)[:, None] * (values.sum(axis=1, keepdims=True) - values)
        load += np.bincount(2 * triangles.ravel() + component, local.ravel(), minlength=2 * len(points))
    return load


def edge_geometry(points: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lengths (k,) and outward unit normals (k, 2) of boundary edges with the body on their left."""
    d = points[edges[:, 1]] - points[edges[:, 0]]
    length = np.hypot(d[:, 0], d[:, 1])
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1) / length[:, None]
    return length, normal


# A traction that depends on the boundary's outward unit normal: g(x, y, n) -> (k, 2).
EdgeTraction = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def traction_vector(
    points: np.ndarray,
    edges: np.ndarray,
    traction: tuple[Field, Field] | None = None,
    pressure: Field | None = None,
    edge_traction: EdgeTraction | None = None,
) -> np.ndarray:
    """Load vector (2n,) of ∫_E g·v over boundary edges, by Simpson's rule (exact for quadratic g).

    Give one of: ``traction`` g = (g_x, g_y) directly; ``pressure`` p, g = −p n with n the
    outward normal; ``edge_traction`` g(x, y, n) → (k, 2), called with the k points of one
    Simpson node on every edge and the edges' outward normals (k, 2), e.g. σ n of an exact
    stress.
    """
    n_dof = 2 * len(points)
    if len(edges) == 0:
        return np.zeros(n_dof)
    length, normal = edge_geometry(points, edges)
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    m = 0.5 * (a + b)
    if edge_traction is not None:
        values = [np.broadcast_to(edge_traction(q[:, 0], q[:, 1], normal), normal.shape) for q in (a, m, b)]
    elif pressure is not None:
        values = [-normal * np.broadcast_to(pressure(q[:, 0], q[:, 1]), length.shape)[:, None] for q in (a, m, b)]
    else:
        values = [np.stack([np.broadcast_to(f(q[:, 0], q[:, 1]), length.shape) for f in traction], axis=1)
                  for q in (a, m, b)]
    ga, gm, gb = values
    load = np.zeros(n_dof)
    for component in range(2):
        # Simpson: ∫ g φ_a = L/6 (g(a) + 2 g(m)), ∫ g φ_b = L/6 (g(b) + 2 g(m)).
        load += np.bincount(2 * edges[:, 0] + component, length / 6 * (ga[:, component] + 2 * gm[:, component]),
                            minlength=n_dof)
        load += np.bincount(2 * edges[:, 1] + component, length / 6 * (gb[:, component] + 2 * gm[:, component]),
                            minlength=n_dof)
    return load


def boundary_mass(points: np.ndarray, edges: np.ndarray, n_points: int) -> sp.csr_matrix:
    """Consistent P1 mass matrix (n_points, n_points) of a 1D boundary: h_E/6 [[2, 1], [1, 2]] per edge."""
    length, _ = edge_geometry(points, edges)
    rows = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 1], edges[:, 0]])
    vals = np.concatenate([length / 3, length / 3, length / 6, length / 6])
    return sp.coo_matrix((vals, (rows, cols)), shape=(n_points, n_points)).tocsr()


def strains(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """Engineering strains (n_triangles, 3): ε_xx, ε_yy, γ_xy = 2 ε_xy, constant per P1 triangle."""
    g, _ = shape_gradients(points, triangles)
    u = displacement[triangles]  # (n, 3, 2)
    grad_u = np.einsum("tia,tib->tab", u, g)  # grad_u[t, a, b] = ∂u_a/∂x_b
    return np.stack([grad_u[:, 0, 0], grad_u[:, 1, 1], grad_u[:, 0, 1] + grad_u[:, 1, 0]], axis=1)


def stresses(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray, law: Elasticity) -> np.ndarray:
    """Cauchy stress per triangle (n_triangles, 4): xx, yy, xy, zz (zz = 0 in plane stress)."""
    e = strains(points, triangles, displacement)
    trace = e[:, 0] + e[:, 1]
    sxx = law.lam * trace + 2 * law.mu * e[:, 0]
    syy = law.lam * trace + 2 * law.mu * e[:, 1]
    sxy = law.mu * e[:, 2]
    szz = law.lam_3d * trace if law.plane == "strain" else np.zeros_like(trace)
    return np.stack([sxx, syy, sxy, szz], axis=1)


def von_mises(stress: np.ndarray) -> np.ndarray:
    """Von Mises equivalent stress (n,) from (n, 4) xx, yy, xy, zz stresses."""
    sxx, syy, sxy, szz = stress.T
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy**2)


def _scalar_matrix(triangles: np.ndarray, local: np.ndarray, n_points: int) -> sp.csr_matrix:
    rows = np.broadcast_to(triangles[:, :, None], local.shape).ravel()
    cols = np.broadcast_to(triangles[:, None, :], local.shape).ravel()
    return sp.coo_matrix((local.ravel(), (rows, cols)), shape=(n_points, n_points)).tocsr()


def mass_matrix(points: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Scalar P1 mass matrix (n, n): ∫ φ_i φ_j = |T|/12 (1 + δ_ij) per triangle."""
    _, area = shape_gradients(points, triangles)
    local = (area / 12.0)[:, None, None] * (np.ones((3, 3)) + np.eye(3))
    return _scalar_matrix(triangles, local, len(points))


def laplacian_matrix(points: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Scalar P1 stiffness (n, n): ∫ ∇φ_i·∇φ_j."""
    g, area = shape_gradients(points, triangles)
    local = area[:, None, None] * np.einsum("tia,tja->tij", g, g)
    return _scalar_matrix(triangles, local, len(points))


def vector_form(scalar: sp.spmatrix) -> sp.csr_matrix:
    """The same form on both displacement components, in interleaved unknowns 2i + c."""
    return sp.kron(scalar, sp.identity(2), format="csr")
