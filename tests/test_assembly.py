"""Invariants of the P1 elasticity assembly that hold exactly, whatever the mesh."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.assembly import (
    Elasticity,
    body_force_points,
    body_force_vector,
    boundary_mass,
    stiffness_matrix,
    stresses,
    traction_vector,
    von_mises,
)
from contactfem.mesh import structured_rectangle, triangulate_domain
from contactfem.mesh.polygon import Loop

LAW = Elasticity.from_young(2.0e5, 0.3, "strain")


def meshes():
    yield structured_rectangle((0.0, 0.0), (2.0, 1.0), 6, 4, diagonal="alternate")
    yield structured_rectangle((-1.0, 0.5), (0.0, 1.5), 3, 5, diagonal="crossed")
    square = Loop(np.array([[0.0, 0.0], [1.0, 0.0], [1.2, 0.8], [0.1, 1.0]]), ("a", "b", "c", "d"), (None,) * 4)
    yield triangulate_domain(square, [], max_edge=0.2)


def rigid_modes(points: np.ndarray) -> np.ndarray:
    modes = np.zeros((2 * len(points), 3))
    modes[0::2, 0] = 1.0
    modes[1::2, 1] = 1.0
    modes[0::2, 2] = -points[:, 1]
    modes[1::2, 2] = points[:, 0]
    return modes


@pytest.mark.parametrize("mesh", list(meshes()))
def test_stiffness_symmetric_with_exactly_the_rigid_modes_as_kernel(mesh):
    """K is symmetric, K r = 0 for the 3 rigid motions, and its null space has dimension 3."""
    k = stiffness_matrix(mesh.points, mesh.triangles, LAW)
    scale = abs(k).max()
    assert abs(k - k.T).max() <= 1e-14 * scale
    assert np.abs(k @ rigid_modes(mesh.points)).max() <= 1e-12 * scale
    eigenvalues = scipy.linalg.eigvalsh(k.toarray())
    assert np.sum(np.abs(eigenvalues) < 1e-10 * eigenvalues.max()) == 3
    assert eigenvalues.min() > -1e-10 * eigenvalues.max()


@pytest.mark.parametrize("plane", ["strain", "stress"])
@pytest.mark.parametrize("mesh", list(meshes()))
def test_patch_test_reproduces_a_linear_displacement(mesh, plane):
    """With the boundary displacement of a linear field prescribed and no load, P1 recovers
    the field exactly at interior nodes, and its stress is the constant Hooke stress."""
    law = Elasticity.from_young(2.0e5, 0.3, plane)
    a = np.array([[1e-3, 2e-3], [-5e-4, 3e-3]])
    exact = mesh.points @ a.T + np.array([1e-3, -2e-3])
    k = stiffness_matrix(mesh.points, mesh.triangles, law).tocsr()
    boundary = np.unique(mesh.boundary_edges)
    fixed = np.concatenate([2 * boundary, 2 * boundary + 1])
    free = np.setdiff1d(np.arange(2 * mesh.n_points), fixed)
    u = exact.ravel().copy()
    u[free] = spla.spsolve(k[free][:, free].tocsc(), -k[free][:, fixed] @ u[fixed])
    np.testing.assert_allclose(u, exact.ravel(), atol=1e-14)

    stress = stresses(mesh.points, mesh.triangles, u.reshape(-1, 2), law)
    exx, eyy, gxy = a[0, 0], a[1, 1], a[0, 1] + a[1, 0]
    sxx = law.lam * (exx + eyy) + 2 * law.mu * exx
    syy = law.lam * (exx + eyy) + 2 * law.mu * eyy
    szz = law.lam_3d * (exx + eyy) if plane == "strain" else 0.0
    np.testing.assert_allclose(stress, np.tile([sxx, syy, law.mu * gxy, szz], (mesh.n_triangles, 1)),
                               rtol=1e-10, atol=1e-12 * abs(sxx))


def test_plane_stress_has_no_out_of_plane_stress():
    """Uniaxial stress state σ_xx = s: in plane stress ε_yy = −ν ε_xx and σ_yy = σ_zz = 0."""
    young, nu = 2.0e5, 0.3
    law = Elasticity.from_young(young, nu, "stress")
    mesh = structured_rectangle((0.0, 0.0), (1.0, 1.0), 2, 2)
    exx = 1e-3
    u = np.stack([exx * mesh.points[:, 0], -nu * exx * mesh.points[:, 1]], axis=1)
    stress = stresses(mesh.points, mesh.triangles, u, law)
    np.testing.assert_allclose(stress[:, 0], young * exx, rtol=1e-12)
    np.testing.assert_allclose(stress[:, 1:], 0.0, atol=1e-12 * young * exx)
    np.testing.assert_allclose(von_mises(stress), young * exx, rtol=1e-12)


def test_body_force_quadrature_exact_for_quartic_force():
    """The 7-point rule is exact for f·φ of degree 5. Σ_i F_i = ∫ f and Σ_i x_i F_i = ∫ x f
    (because Σ φ_i x_i = x) for f = (x⁴ − y³ x, 3y) on (0,2)x(0,1):
    ∫ f_x = 32/5 − 2/4 = 5.9, ∫ x f_x = 64/6 − (8/3)/4 = 10, ∫ f_y = 3."""
    mesh = structured_rectangle((0.0, 0.0), (2.0, 1.0), 5, 3, diagonal="left")
    where = body_force_points(mesh.points, mesh.triangles)
    values = np.stack([where[..., 0] ** 4 - where[..., 1] ** 3 * where[..., 0], 3 * where[..., 1]], axis=-1)
    load = body_force_vector(mesh.points, mesh.triangles, values)
    fx, fy = load[0::2], load[1::2]
    assert fx.sum() == pytest.approx(5.9, rel=1e-13)
    assert (mesh.points[:, 0] * fx).sum() == pytest.approx(10.0, rel=1e-13)
    assert fy.sum() == pytest.approx(3.0, rel=1e-13)


def test_traction_quadrature_exact_for_quadratic_traction_and_pressure():
    """On the top edge of (0,1)², ∫ g_y = ∫ (1 − 1.5x + x²) = 1 − 0.75 + 1/3 and
    ∫ x g_y = 1/2 − 1/2 + 1/4; a pressure p = 2 on the top pushes with total −2 along y."""
    mesh = structured_rectangle((0.0, 0.0), (1.0, 1.0), 7, 7)
    top = mesh.edges_of("top")
    load = traction_vector(mesh.points, top, traction=(lambda x, y: 0 * x, lambda x, y: 1 - 1.5 * x + x**2))
    gy = load[1::2]
    assert gy.sum() == pytest.approx(1 - 0.75 + 1 / 3, rel=1e-14)
    assert (mesh.points[:, 0] * gy).sum() == pytest.approx(0.25, rel=1e-13)
    pressure = traction_vector(mesh.points, top, pressure=lambda x, y: 2.0 + 0 * x)
    assert pressure[1::2].sum() == pytest.approx(-2.0, rel=1e-14)
    assert abs(pressure[0::2]).max() == 0.0


def test_boundary_mass_integrates_products_of_hat_functions():
    """1ᵀ M 1 = |Γ| and xᵀ M x = ∫ x² over the bottom edge of (0,3)x(0,1): 9."""
    mesh = structured_rectangle((0.0, 0.0), (3.0, 1.0), 5, 2)
    mass = boundary_mass(mesh.points, mesh.edges_of("bottom"), mesh.n_points)
    ones = np.ones(mesh.n_points)
    x = mesh.points[:, 0]
    assert ones @ mass @ ones == pytest.approx(3.0, rel=1e-14)
    assert x @ mass @ x == pytest.approx(9.0, rel=1e-14)


# ------------------------------------------------- edge-wise assembly vs a reference


def reference_stiffness(points: np.ndarray, triangles: np.ndarray, law: Elasticity) -> sp.csr_matrix:
    """Textbook assembly: Bᵀ D B |T| per element (Voigt notation), 36 entries each, summed by COO."""
    p = points[triangles]  # (t, 3, 2)
    edge = p[:, [1, 2, 0]] - p[:, [2, 0, 1]]  # edge opposite vertex i, from j to k
    u, v = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    twice_area = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    gx = -edge[:, :, 1] / twice_area[:, None]  # ∂φ_i/∂x = (y_j − y_k) / 2|T|
    gy = edge[:, :, 0] / twice_area[:, None]
    b = np.zeros((len(triangles), 3, 6))
    b[:, 0, 0::2] = gx
    b[:, 1, 1::2] = gy
    b[:, 2, 0::2] = gy
    b[:, 2, 1::2] = gx
    d = np.array([[law.lam + 2 * law.mu, law.lam, 0.0], [law.lam, law.lam + 2 * law.mu, 0.0], [0.0, 0.0, law.mu]])
    ke = np.einsum("tki,kl,tlj,t->tij", b, d, b, 0.5 * twice_area)
    dofs = (2 * triangles[:, :, None] + np.arange(2)).reshape(-1, 6)
    rows = np.repeat(dofs, 6, axis=1).ravel()
    cols = np.tile(dofs, (1, 6)).ravel()
    n = 2 * len(points)
    return sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(n, n)).tocsr()


def assert_same_matrix(k: sp.csr_matrix, ref: sp.csr_matrix) -> None:
    assert isinstance(k, sp.csr_matrix)
    assert k.shape == ref.shape
    ref.sum_duplicates()
    # Same pattern, explicit zeros of the element matrices included.
    np.testing.assert_array_equal(k.indptr, ref.indptr)
    np.testing.assert_array_equal(k.indices, ref.indices)
    scale = np.abs(ref.data).max()
    np.testing.assert_allclose(k.data, ref.data, rtol=0, atol=1e-12 * scale)
    # Canonical form, checked from scratch rather than trusted from the flags.
    fresh = sp.csr_matrix((k.data, k.indices, k.indptr), shape=k.shape)
    assert fresh.has_sorted_indices and fresh.has_canonical_format
    assert abs(k - k.T).max() == 0.0


def comparison_meshes():
    yield "structured right", structured_rectangle((0.0, 0.0), (2.0, 1.0), 7, 5)
    yield "structured crossed", structured_rectangle((-1.0, 0.5), (0.0, 1.5), 4, 6, diagonal="crossed")
    yield "structured alternate", structured_rectangle((3.0, -2.0), (4.0, 0.0), 5, 8, diagonal="alternate")
    outer = Loop(np.array([[0.0, 0.0], [2.0, 0.0], [2.3, 1.4], [0.4, 1.9], [-0.2, 0.8]]), ("a",) * 5, (None,) * 5)
    hole = Loop(np.array([[0.6, 0.6], [0.9, 1.2], [1.3, 0.7]]), ("h",) * 3, (None,) * 3)
    yield "unstructured", triangulate_domain(outer, [hole], max_edge=0.15)


@pytest.mark.parametrize("plane", ["strain", "stress"])
@pytest.mark.parametrize("name, mesh", list(comparison_meshes()), ids=lambda v: v if isinstance(v, str) else "")
def test_stiffness_equals_the_elementwise_reference(name, mesh, plane):
    law = Elasticity.from_young(3.0e5, 0.28, plane)
    k = stiffness_matrix(mesh.points, mesh.triangles, law)
    assert k.indices.dtype == np.int32 and k.indptr.dtype == np.int32
    assert_same_matrix(k, reference_stiffness(mesh.points, mesh.triangles, law))


def test_stiffness_with_shuffled_nodes_clockwise_triangles_and_an_unused_node():
    """Random node numbering, some triangles clockwise (negative area, as the closed
    form gives), int32 triangles and a node in no triangle (its rows stay empty)."""
    mesh = list(comparison_meshes())[-1][1]
    rng = np.random.default_rng(3)
    n = mesh.n_points
    new_of_old = rng.permutation(n + 1)[:n]  # node n in the new numbering may be unused
    points = np.empty((n + 1, 2))
    points[new_of_old] = mesh.points
    unused = np.setdiff1d(np.arange(n + 1), new_of_old)
    points[unused] = [10.0, 10.0]
    triangles = new_of_old[mesh.triangles].astype(np.int32)
    flip = rng.random(len(triangles)) < 0.3
    triangles[flip] = triangles[flip][:, ::-1]
    triangles = triangles[rng.permutation(len(triangles))]
    k = stiffness_matrix(points, triangles, LAW)
    assert_same_matrix(k, reference_stiffness(points, triangles.astype(np.int64), LAW))
    rows = 2 * unused
    assert k[rows].nnz == 0 and k[rows + 1].nnz == 0


def test_stiffness_of_a_single_triangle_and_of_unusual_input():
    points = np.array([[0.0, 0.0], [1.0, 0.2], [0.3, 0.9]])
    triangles = np.array([[0, 1, 2]])
    assert_same_matrix(stiffness_matrix(points, triangles, LAW), reference_stiffness(points, triangles, LAW))
    # Integer coordinates take the element-wise path and give the same matrix.
    k_int = stiffness_matrix(np.array([[0, 0], [2, 0], [0, 1]]), triangles, LAW)
    k_float = stiffness_matrix(np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]]), triangles, LAW)
    assert_same_matrix(k_int, k_float.copy())
    empty = stiffness_matrix(points, np.zeros((0, 3), dtype=np.int64), LAW)
    assert empty.shape == (6, 6) and empty.nnz == 0


def test_counting_sort_is_a_stable_sort():
    from contactfem.assembly import _counting_sort

    rng = np.random.default_rng(0)
    keys = rng.integers(0, 50, size=1000).astype(np.int32)
    payload = rng.integers(-5, 5, size=1000).astype(np.int32)
    order, sorted_payload, starts = _counting_sort(keys, 60, payload, np.arange(1001, dtype=np.int32))
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
    np.testing.assert_array_equal(sorted_payload, payload[order])
    np.testing.assert_array_equal(starts, np.searchsorted(keys[order], np.arange(61)))


def test_stiffness_with_int64_indices_for_huge_meshes(monkeypatch):
    """Above the int32 range the edge-wise assembly runs on int64 indices, same matrix."""
    import contactfem.assembly as assembly

    mesh = list(comparison_meshes())[-1][1]
    monkeypatch.setattr(assembly, "_INT32_LIMIT", 100)
    k = stiffness_matrix(mesh.points, mesh.triangles, LAW)
    assert_same_matrix(k, reference_stiffness(mesh.points, mesh.triangles, LAW))
