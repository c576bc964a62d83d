"""Invariants of the P1 elasticity assembly that hold exactly, whatever the mesh."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse.linalg as spla

from contactfem.assembly import (
    Elasticity,
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


def test_body_force_quadrature_exact_for_linear_force():
    """Σ_i F_i = ∫ f and Σ_i x_i F_i = ∫ x f (because Σ φ_i x_i = x) for f = (1 + 2x − y, 3y)
    on (0,2)x(0,1): ∫ f_x = 2 + 4 − 1 = 5, ∫ x f_x = 2 + 16/3 − 1 = 19/3, ∫ f_y = 3."""
    mesh = structured_rectangle((0.0, 0.0), (2.0, 1.0), 5, 3, diagonal="left")
    load = body_force_vector(mesh.points, mesh.triangles, (lambda x, y: 1 + 2 * x - y, lambda x, y: 3 * y))
    fx, fy = load[0::2], load[1::2]
    assert fx.sum() == pytest.approx(5.0, rel=1e-14)
    assert (mesh.points[:, 0] * fx).sum() == pytest.approx(19 / 3, rel=1e-14)
    assert fy.sum() == pytest.approx(3.0, rel=1e-14)


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
