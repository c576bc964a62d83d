"""Vectorised P1 assembly: elasticity stiffness, loads, stresses and the contact boundary masses."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp

from contactfem.mesh.topology import Topology, _counting_sort

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


def stiffness_matrix(
    points: np.ndarray, triangles: np.ndarray, law: Elasticity, topology: Topology | None = None
) -> sp.csr_matrix:
    """The 2n x 2n stiffness matrix of ∫ σ(u):ε(v), no boundary conditions.

    Element entries in closed form: K[(i,a),(j,b)] = |T| (λ g_i^a g_j^b + μ g_j^a g_i^b
    + μ δ_ab g_i·g_j), with g_i the gradient of the basis function of node i.

    The result is in canonical CSR form (sorted indices, no duplicates) with a full 2x2
    block for every node and every mesh edge, explicit zeros included.

    ``topology`` is the :class:`~contactfem.mesh.topology.Topology` of ``triangles``
    (e.g. ``mesh.topology``); without it the edges are computed here.
    """
    points = np.asarray(points)
    triangles = np.asarray(triangles)
    if not _edge_assembly_applies(points, triangles):
        return _stiffness_matrix_by_elements(points, triangles, law)
    n_points = len(points)
    # 4 (n + 2 n_edges) entries with n_edges <= 3 n_triangles bounds the nnz.
    index_type = np.int32 if 4 * (n_points + 6 * len(triangles)) <= _INT32_LIMIT else np.int64
    tri = np.ascontiguousarray(triangles, dtype=index_type)
    if topology is None:
        if _repeats_a_node(tri):
            return _stiffness_matrix_by_elements(points, triangles, law)
        topology = Topology.from_triangles(tri, n_points)
    elif topology.n_points != n_points or topology.n_triangles != len(tri):
        raise ValueError(
            f"topology of {topology.n_triangles} triangles on {topology.n_points} nodes given for "
            f"{len(tri)} triangles on {n_points} nodes"
        )
    # _block_csr builds the CSR index arrays in the dtype of edge_lo.
    edge_lo = topology.edges[:, 0].astype(index_type, copy=False)
    edge_hi = topology.edges[:, 1].astype(index_type, copy=False)
    x = np.ascontiguousarray(points[:, 0], dtype=np.float64)
    y = np.ascontiguousarray(points[:, 1], dtype=np.float64)
    edge_blocks, node_blocks = _pair_blocks(
        x, y, tri, topology.half_edge_edge, topology.half_edge_flipped, topology.n_edges, law
    )
    # Frees the half-edge arrays of a topology built here before the matrix is allocated.
    del topology, tri
    return _block_csr(n_points, edge_lo, edge_hi, edge_blocks, node_blocks)


# Largest index (and entry count) that int32 CSR arrays can hold.
_INT32_LIMIT = np.iinfo(np.int32).max


def _edge_assembly_applies(points: np.ndarray, triangles: np.ndarray) -> bool:
    """Whether the edge-wise assembly takes this input (it gives the element-wise matrix
    up to round-off).

    Anything unusual (other dtypes, empty or malformed input, out-of-range nodes) goes
    through the straightforward element-wise assembly, which keeps its behaviour.
    """
    return (
        points.ndim == 2
        and points.shape[1] == 2
        and points.dtype == np.float64
        and triangles.ndim == 2
        and triangles.shape[1] == 3
        and len(triangles) > 0
        and np.issubdtype(triangles.dtype, np.integer)
        and int(triangles.min()) >= 0
        and int(triangles.max()) < len(points)
    )


def _stiffness_matrix_by_elements(points: np.ndarray, triangles: np.ndarray, law: Elasticity) -> sp.csr_matrix:
    """The same matrix from the 36 entries of every element, summed by scipy (slow, general)."""
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


def _repeats_a_node(tri: np.ndarray) -> bool:
    """Whether a triangle of ``tri`` (n, 3) names a node twice (it then has no edges)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    return bool(np.any((a == b) | (b == c) | (c == a)))


# Triangles per block of the element loop: its temporaries stay in cache.
_CHUNK = 16384


def _pair_blocks(
    x: np.ndarray,
    y: np.ndarray,
    tri: np.ndarray,
    edge_of: np.ndarray,
    flipped: np.ndarray,
    n_edges: int,
    law: Elasticity,
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The assembled 2x2 blocks of K, summed over the triangles of each edge and node.

    With b_i = y_j − y_k, c_i = x_k − x_j (i, j, k cyclic), g_i = (b_i, c_i) / 2|T| and
    the block of nodes (i, j) of a triangle is (λ g_i g_jᵀ + μ g_j g_iᵀ + μ g_i·g_j I) |T|:
    with w = 1 / 4|T|,
    xx = w ((λ+2μ) b_i b_j + μ c_i c_j),  yy = w ((λ+2μ) c_i c_j + μ b_i b_j),
    xy = w (λ b_i c_j + μ c_i b_j),       yx = w (λ c_i b_j + μ b_i c_j).

    Returns
    -------
    edge blocks (xx, xy, yx, yy), each (n_edges,): block (lo, hi) of every edge, whose
        transpose is block (hi, lo)
    node blocks (xx, xy, yy), each (n_points,): the symmetric diagonal blocks
    """
    n_points = len(x)
    lam, mu = law.lam, law.mu
    lam2mu = lam + 2.0 * mu
    exx, exy, eyx, eyy = (np.zeros(n_edges) for _ in range(4))
    dxx, dxy, dyy = (np.zeros(n_points) for _ in range(3))
    nxt, prv = [1, 2, 0], [2, 0, 1]
    for s in range(0, len(tri), _CHUNK):
        t = tri[s : s + _CHUNK]
        px, py = x[t], y[t]
        b = py[:, nxt] - py[:, prv]
        c = px[:, prv] - px[:, nxt]
        twice_area = (px[:, 1] - px[:, 0]) * (py[:, 2] - py[:, 0]) - (px[:, 2] - px[:, 0]) * (py[:, 1] - py[:, 0])
        w = (0.5 / twice_area)[:, None]
        bw, cw = b * w, c * w

        nodes = t.ravel()
        bb, cc = bw * b, cw * c
        np.add.at(dxx, nodes, (lam2mu * bb + mu * cc).ravel())
        np.add.at(dyy, nodes, (lam2mu * cc + mu * bb).ravel())
        np.add.at(dxy, nodes, ((lam + mu) * (bw * c)).ravel())

        # Half-edge k of the triangle: from node k (i) to node k+1 (j).
        bj, cj = b[:, nxt], c[:, nxt]
        bb, cc, bc, cb = bw * bj, cw * cj, bw * cj, cw * bj
        half = slice(3 * s, 3 * s + t.size)
        edge, flip = edge_of[half], flipped[half]
        np.add.at(exx, edge, (lam2mu * bb + mu * cc).ravel())
        np.add.at(eyy, edge, (lam2mu * cc + mu * bb).ravel())
        xy = (lam * bc + mu * cb).ravel()
        yx = (lam * cb + mu * bc).ravel()
        # A half-edge from high to low node carries the transpose of block (lo, hi).
        np.add.at(exy, edge, np.where(flip, yx, xy))
        np.add.at(eyx, edge, np.where(flip, xy, yx))
    return (exx, exy, eyx, eyy), (dxx, dxy, dyy)


def _block_csr(
    n_points: int,
    edge_lo: np.ndarray,
    edge_hi: np.ndarray,
    edge_blocks: tuple[np.ndarray, ...],
    node_blocks: tuple[np.ndarray, ...],
) -> sp.csr_matrix:
    """The interleaved 2n x 2n CSR matrix from the 2x2 blocks of the nodes and edges.

    Node row i holds, in column order, the blocks (i, lo) of the edges with hi = i, the
    diagonal block (if i is on an edge, i.e. in a triangle), then the blocks (i, hi) of
    the edges with lo = i; a node in no triangle has empty rows. Dof rows 2i and 2i+1
    both have 2 L_i entries (L_i blocks in node row i), so with p the node-level position
    of a block in row i, its first-row pair of entries starts at entry 2 (p + ptr[i]) and
    its second-row pair at 2 (p + ptr[i + 1]).
    """
    n_edges = len(edge_lo)
    index_type = edge_lo.dtype
    ramp = np.arange(n_edges + 1, dtype=index_type)
    # Edges by (hi, lo): the lower-triangle blocks in CSR order.
    lower, lower_col, lower_start = _counting_sort(edge_hi, n_points, edge_lo, ramp)
    lower_count = np.diff(lower_start)
    upper_start = np.searchsorted(edge_lo, np.arange(n_points + 1, dtype=index_type)).astype(index_type)
    upper_count = np.diff(upper_start)
    used = (lower_count + upper_count) > 0
    has_diagonal = used.astype(index_type)
    ptr = np.zeros(n_points + 1, dtype=index_type)
    np.cumsum(lower_count + has_diagonal + upper_count, out=ptr[1:])
    nnz = 4 * int(ptr[-1])

    indptr = np.empty(2 * n_points + 1, dtype=index_type)
    indptr[0::2] = 4 * ptr
    indptr[1::2] = 2 * (ptr[:-1] + ptr[1:])
    data = np.empty(nnz)
    indices = np.empty(nnz, dtype=index_type)
    first, second = data[0::2], data[1::2]
    column = indices[0::2]

    def put(row: np.ndarray, position: np.ndarray, col: np.ndarray, xx, xy, yx, yy, take=None) -> None:
        # position: node-level index of each block; row: its node row; the values are
        # taken at ``take`` one array at a time, which keeps the peak memory down.
        top = position + ptr[:-1][row]
        bottom = position + ptr[1:][row]
        for target, where, values in ((first, top, xx), (second, top, xy), (first, bottom, yx), (second, bottom, yy)):
            target[where] = values if take is None else values[take]
        column[top] = column[bottom] = 2 * col

    exx, exy, eyx, eyy = edge_blocks
    ramp = ramp[:n_edges]
    # Upper blocks (lo, hi): edges are sorted by (lo, hi), so row lo's run is contiguous.
    put(edge_lo, ramp + (ptr[:-1] + lower_count + has_diagonal - upper_start[:-1])[edge_lo], edge_hi,
        exx, exy, eyx, eyy)
    # Lower blocks (hi, lo) = (lo, hi)ᵀ, taken in (hi, lo) order.
    row = np.repeat(np.arange(n_points, dtype=index_type), lower_count)
    put(row, ramp + (ptr[:-1] - lower_start[:-1])[row], lower_col, exx, eyx, exy, eyy, take=lower)
    del row, lower, lower_col
    nodes = np.flatnonzero(used).astype(index_type)
    dxx, dxy, dyy = node_blocks
    put(nodes, (ptr[:-1] + lower_count)[nodes], nodes, dxx, dxy, dxy, dyy, take=nodes)
    np.add(column, 1, out=indices[1::2])

    n_dof = 2 * n_points
    matrix = sp.csr_matrix((data, indices, indptr), shape=(n_dof, n_dof))
    matrix.has_canonical_format = True  # sorted by construction, one entry per (row, col)
    return matrix


def body_force_points(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The points (q, n_triangles, 2) where :func:`body_force_vector` evaluates the body force:
    the q = 7 points of the degree-5 rule of :mod:`contactfem.quadrature` in every triangle."""
    from contactfem.quadrature import TRIANGLE_POINTS

    return np.einsum("qi,tia->qta", TRIANGLE_POINTS, points[triangles])


def body_force_vector(points: np.ndarray, triangles: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Load vector (2n,) of ∫ f·v from f at :func:`body_force_points`, ``values`` (q, n_triangles, 2).

    The 7-point rule is exact for f of degree 4 (f·φ of degree 5) and keeps P1's optimal
    rates for loads that are only piecewise smooth (√-type terms of a singular solution),
    where a degree-2 rule holds the L² rate near 1.5.
    """
    from contactfem.quadrature import TRIANGLE_POINTS, TRIANGLE_WEIGHTS

    _, area = shape_gradients(points, triangles)
    # ∫_T f φ_i = |T| Σ_q w_q λ_i(q) f(q), λ_i the barycentric coordinate of vertex i.
    local = np.einsum("q,qi,qtc->tic", TRIANGLE_WEIGHTS, TRIANGLE_POINTS, values) * area[:, None, None]
    n_dof = 2 * len(points)
    load = np.zeros(n_dof)
    for component in range(2):
        load += np.bincount(2 * triangles.ravel() + component, local[:, :, component].ravel(), minlength=n_dof)
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


def edge_load_vector(edges: np.ndarray, length: np.ndarray, traction: np.ndarray, n_points: int) -> np.ndarray:
    """Load vector (2 n_points,) of ∫_E g·v over boundary edges (k, 2) of lengths (k,), from g
    at the points of the edge rule, ``traction`` (q, k, 2) (see :mod:`contactfem.quadrature`)."""
    from contactfem.quadrature import EDGE_RULE_POINTS, EDGE_RULE_WEIGHTS

    n_dof = 2 * n_points
    load = np.zeros(n_dof)
    if len(edges) == 0:
        return load
    # ∫ g φ_a = L Σ_q w_q (1 − s_q) g_q and ∫ g φ_b = L Σ_q w_q s_q g_q.
    at_start = length[:, None] * np.einsum("q,qkc->kc", EDGE_RULE_WEIGHTS * (1 - EDGE_RULE_POINTS), traction)
    at_end = length[:, None] * np.einsum("q,qkc->kc", EDGE_RULE_WEIGHTS * EDGE_RULE_POINTS, traction)
    for component in range(2):
        load += np.bincount(2 * edges[:, 0] + component, at_start[:, component], minlength=n_dof)
        load += np.bincount(2 * edges[:, 1] + component, at_end[:, component], minlength=n_dof)
    return load


def boundary_mass(points: np.ndarray, edges: np.ndarray, n_points: int) -> sp.csr_matrix:
    """Consistent P1 mass matrix (n_points, n_points) of a 1D boundary: h_E/6 [[2, 1], [1, 2]] per edge."""
    length, _ = edge_geometry(points, edges)
    rows = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 1], edges[:, 0]])
    vals = np.concatenate([length / 3, length / 3, length / 6, length / 6])
    return sp.coo_matrix((vals, (rows, cols)), shape=(n_points, n_points)).tocsr()


def strains(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray,
            gradients: np.ndarray | None = None) -> np.ndarray:
    """Engineering strains (n_triangles, 3): ε_xx, ε_yy, γ_xy = 2 ε_xy, constant per P1 triangle.

    ``gradients`` are :func:`shape_gradients`' of the mesh, when the caller keeps them (the
    steps of a load path share one mesh)."""
    g = shape_gradients(points, triangles)[0] if gradients is None else gradients
    u = displacement[triangles]  # (n, 3, 2)
    grad_u = np.einsum("tia,tib->tab", u, g)  # grad_u[t, a, b] = ∂u_a/∂x_b
    return np.stack([grad_u[:, 0, 0], grad_u[:, 1, 1], grad_u[:, 0, 1] + grad_u[:, 1, 0]], axis=1)


def stresses(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray, law: Elasticity,
             gradients: np.ndarray | None = None) -> np.ndarray:
    """Cauchy stress per triangle (n_triangles, 4): xx, yy, xy, zz (zz = 0 in plane stress)."""
    e = strains(points, triangles, displacement, gradients)
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
