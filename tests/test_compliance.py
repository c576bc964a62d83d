"""The half-plane model of ΓC's compliance (contactfem.compliance) and the kernel's use of it.

- its columns are Flamant's ln(R / r)₊ / π E*, and its diagonal the mean of that over a
  node's share, against quadrature;
- its contact problem, settled, satisfies the model's own sign and complementarity
  conditions, and (a P-matrix problem has one solution) does not depend on the stages the
  free body is pushed in by;
- the kernel with the model reaches the set, displacement and certificate it reaches
  without it, in fewer steps on rough bases and curved bodies; a model that proposes
  nonsense costs steps, never the answer;
- it refuses what it cannot afford or factorise, and is not offered to a body that bends.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import shipped_case
from scipy.integrate import quad
from test_sequencing import rough_polygon_case

import contactfem.compliance as compliance_module
from contactfem.compliance import HalfPlaneModel, half_plane_model, plane_strain_modulus
from contactfem.kernel import Status, solve_contact
from contactfem.methods import get_method
from contactfem.solve import prepare, solve_case


def _model(m: int = 200, reach: float = 0.5) -> tuple[HalfPlaneModel, np.ndarray, np.ndarray]:
    """A model on m nodes over [0, 1] graded as a mesh is (spacings growing by 2% a node,
    fifty-fold across), with each node's share of ΓC."""
    steps = 1.02 ** np.arange(m - 1)
    s = np.concatenate([[0.0], np.cumsum(steps) / steps.sum()])
    share = np.diff(np.concatenate([[s[0]], 0.5 * (s[1:] + s[:-1]), [s[-1]]]))
    return HalfPlaneModel(s, share, np.zeros(m), 2.0e6, reach), s, share


def test_columns_are_flamants_log_and_the_diagonal_its_mean_over_a_share():
    model, s, share = _model()
    nodes = np.arange(len(s))
    model._hold(nodes)
    matrix = model.columns[:, model.slot[nodes]]
    scale = 1.0 / (np.pi * 2.0e6)
    distance = np.abs(s[:, None] - s[None, :])
    off = ~np.eye(len(s), dtype=bool)
    expected = scale * np.maximum(np.log(0.5 / np.where(off, distance, 1.0)), 0.0)
    assert np.abs(matrix[off] - expected[off]).max() <= 1e-12 * scale
    for j in (0, 57, 198):
        w = share[j]
        mean, _ = quad(lambda t: np.log(0.5 / abs(t)), -w / 2, w / 2, points=[0.0], epsabs=1e-14)
        assert abs(matrix[j, j] / scale - mean / w) <= 1e-10 * abs(mean / w)
    assert np.array_equal(matrix, matrix.T)
    assert np.linalg.eigvalsh(matrix).min() > 0


def test_the_models_contact_problem_settles_to_its_own_conditions_whatever_the_start(monkeypatch):
    """From the free body pushed 2e-5 onto equally spaced nodes whose gaps are random: the
    set proposed, with the forces it implies, satisfies Λ ≥ 0 on it, slack ≤ 0 off it (to
    round-off of the push); started from the projected gradients' near set or from the free
    body's stages (1, 2 or 8), the same set: a P-matrix problem has one solution."""
    monkeypatch.setattr(compliance_module, "MODEL_ITERATIONS", 200)
    rng = np.random.default_rng(5)
    m = 300
    s = np.linspace(0.0, 1.0, m)
    share = np.full(m, 1.0 / (m - 1))
    share[[0, -1]] *= 0.5
    gap = rng.uniform(0.0, 4e-5, m)
    push = np.full(m, 2e-5)
    sets = []
    for stages in (None, 1, 2, 8):
        model = HalfPlaneModel(s, share, gap, 1.0e6, 0.5)
        assert model.even is not None
        if stages is not None:
            model.even = None
            monkeypatch.setattr(compliance_module, "FREE_BODY_STAGES", stages)
        proposed = model(np.zeros(m, dtype=bool), push - gap, np.zeros(m))
        on = np.flatnonzero(proposed)
        forces = np.linalg.solve(model._block(on), (push - gap)[on])
        slack = push - gap - model._times(on, forces)
        assert 10 < len(on) < m - 10
        assert forces.min() >= 0
        assert np.abs(slack[on]).max() <= 1e-12 * 2e-5
        assert slack[~proposed].max() <= 1e-12 * 2e-5
        sets.append(proposed)
    assert all(np.array_equal(sets[0], other) for other in sets[1:])


def test_even_spacing_products_are_the_columns_products():
    """On equally spaced nodes (half shares at the ends) C x by FFTs equals the product
    of the columns (Flamant's log, computed node by node) to 1e-12 of its largest entry,
    for random x of both signs and for single nodes (the first and last ones meet the
    circulant's wrap), and its gathered blocks are the columns' entries to 1e-14; graded
    nodes have no even form."""
    m = 257
    s = np.linspace(-0.3, 0.7, m)
    share = np.full(m, 1.0 / (m - 1))
    share[[0, -1]] *= 0.5
    even = HalfPlaneModel(s, share, np.zeros(m), 3.0e5, 0.35).even
    columns = HalfPlaneModel(s, share, np.zeros(m), 3.0e5, 0.35)
    columns.even = None
    nodes = np.arange(m)
    rng = np.random.default_rng(2)
    for x in (rng.normal(size=m), np.eye(m)[0], np.eye(m)[128], np.eye(m)[-1]):
        exact = columns._times(nodes, x)
        assert np.abs(even @ x - exact).max() <= 1e-12 * np.abs(exact).max()
    some = np.sort(rng.choice(m, 40, replace=False))
    assert np.abs(even.block(some) - columns._block(some)).max() <= 1e-14 * columns._block(some).max()
    assert _model()[0].even is None
    # Offsets of R = 0.35 or more (90 h) couple nothing: the circulant needs m + 89 points,
    # not 2 m - 1, and the products above held with it.
    assert m + 89 <= even.length < 2 * m - 1


def _kernel_pair(problem, method: str = "positive", model=None):
    reduced = problem.contact_system(get_method(method))
    model = half_plane_model(problem.contact, problem.law, problem.mesh.points) if model is None else model
    plain = solve_contact(reduced.system, tolerance=1e-10)
    modelled = solve_contact(reduced.system, tolerance=1e-10, compliance=model)
    return plain, modelled


@pytest.mark.parametrize("name", ["rough", "hertz_quarter", "rough_rim", "hole"])
def test_the_model_changes_the_steps_never_the_answer(name):
    """Cold starts with and without the model reach the same certified set and
    displacement (to 1e-10 of the largest), the modelled one in fewer steps on the rough
    base, the quarter disk and the rough rim (a hole's few nodes: no more steps)."""
    case = rough_polygon_case(1000) if name == "rough" else shipped_case(name)
    problem = prepare(case)
    assert half_plane_model(problem.contact, problem.law, problem.mesh.points) is not None
    for method in ("positive", "standard"):
        plain, modelled = _kernel_pair(problem, method)
        assert plain.status is Status.CONVERGED and modelled.status is Status.CONVERGED
        assert np.array_equal(plain.active, modelled.active)
        scale = np.abs(plain.displacement).max()
        assert np.abs(plain.displacement - modelled.displacement).max() <= 1e-10 * scale
        if name == "hole":
            assert modelled.iterations <= plain.iterations
        else:
            assert modelled.iterations < plain.iterations, (method, plain.iterations, modelled.iterations)


def test_a_model_proposing_nonsense_costs_steps_never_the_answer():
    """A 'model' that proposes a random unseen set at every step: the kernel stops asking
    after MAX_PROPOSALS and Newton's update settles on the same certified answer."""
    from contactfem.kernel import MAX_PROPOSALS

    problem = prepare(rough_polygon_case(400))
    rng = np.random.default_rng(0)
    asked = []

    def nonsense(active, slack, force):
        asked.append(1)
        return rng.uniform(size=len(active)) < 0.5

    plain, confused = _kernel_pair(problem, model=nonsense)
    assert confused.status is Status.CONVERGED
    assert np.array_equal(plain.active, confused.active)
    assert len(asked) == MAX_PROPOSALS
    scale = np.abs(plain.displacement).max()
    assert np.abs(plain.displacement - confused.displacement).max() <= 1e-10 * scale


def test_it_refuses_what_it_cannot_afford_or_factorise(monkeypatch):
    model, s, share = _model(m=100)
    push = np.full(100, 1e-3)
    monkeypatch.setattr(compliance_module, "MODEL_BLOCK", 10)
    assert model(np.zeros(100, dtype=bool), push, np.zeros(100)) is None
    monkeypatch.setattr(compliance_module, "MODEL_BLOCK", 600)
    monkeypatch.setattr(compliance_module, "MODEL_COLUMN_ENTRIES", 100 * 5)
    assert _model(m=100)[0](np.zeros(100, dtype=bool), push, np.zeros(100)) is None
    monkeypatch.setattr(compliance_module, "MODEL_COLUMN_ENTRIES", 8_000_000)
    # Shares far wider than the reach: the diagonal (ln(2R / w) + 1) below its
    # neighbours, not positive definite.
    broken = HalfPlaneModel(s, share * 1e4, np.zeros(100), 1.0, 0.5)
    assert broken(np.zeros(100, dtype=bool), push, np.zeros(100)) is None


def test_a_strip_that_bends_is_offered_no_model_and_a_platen_keeps_its_coarse_level():
    strip = prepare(shipped_case("strip"))
    assert half_plane_model(strip.contact, strip.law, strip.mesh.points) is None
    platen = shipped_case("hertz_platen")
    solved = solve_case(replace(platen, load_path=None), method="positive")
    assert solved.kernel.status is Status.CONVERGED
    assert solved.sequencing.get("levels", 0) >= 1  # held by contact alone: the kernel asks no model


def test_plane_strain_modulus_is_e_over_one_minus_nu_squared():
    from contactfem.assembly import Elasticity

    E, nu = 2.0e5, 0.3
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    assert abs(plane_strain_modulus(Elasticity.from_lame(lam, mu, "strain")) - E / (1 - nu**2)) <= 1e-10 * E
    assert abs(plane_strain_modulus(Elasticity.from_lame(lam, mu, "stress")) - E) <= 1e-10 * E


@pytest.mark.parametrize("even", [True, False])
def test_set_solves_from_one_factor_are_the_dense_solves(even):
    """C[S, S] x = b[S] for sets that drift from a base by a few nodes (added and removed
    together, or only one kind), solved from the base's factor through the bordered
    system: its residual is within 1e-12 of ‖C[S, S]‖ ‖x‖ (the dense solve's is 1e-16; the
    bordered system's cancellations lose about three digits, as measured, far below what
    decides a node's sign); a set far from the base is factorised anew and becomes the base."""

    def backward_error(on, x):
        block = model._block(on)
        return np.abs(block @ x - free[on]).max() / (np.abs(block).sum(axis=1).max() * np.abs(x).max())

    m = 300
    if even:
        s = np.linspace(0.0, 1.0, m)
        share = np.full(m, 1.0 / (m - 1))
        share[[0, -1]] *= 0.5
        model = HalfPlaneModel(s, share, np.zeros(m), 1.0e6, 0.5)
        assert model.even is not None
    else:
        model = _model(m)[0]
    rng = np.random.default_rng(11)
    free = rng.normal(size=m)
    first = rng.random(m) < 0.4
    model.sets.solve(np.flatnonzero(first), free)
    base = model.sets.base
    for step in range(12):
        flips = rng.choice(m, 3 if step % 3 else 5, replace=False)
        if step % 4 == 1:
            flips = flips[first[flips]]  # removals only
        elif step % 4 == 2:
            flips = flips[~first[flips]]  # additions only
        current = first.copy()
        current[flips] = ~current[flips]
        on = np.flatnonzero(current)
        assert backward_error(on, model.sets.solve(on, free)) <= 1e-12
    assert model.sets.base is base  # every set above was solved from the first factor
    far = np.flatnonzero(rng.random(m) < 0.6)
    assert backward_error(far, model.sets.solve(far, free)) <= 1e-15
    assert np.array_equal(model.sets.base, far)


def test_nodes_on_a_common_grid_have_the_even_form():
    """A profile of 998 segments decimated by four keeps spacings of 4 h and, at its end,
    2 h: its nodes lie on a grid of 2 h (the coarsest that holds them), and C's products by FFTs on that grid equal the
    columns' (Flamant's log node by node) to 1e-12 of the largest entry, its gathered
    blocks to 1e-14. Spacings that are no whole multiples of one h (a graded mesh, or
    3 h and an extra 1e-3 h) have no even form."""
    fine = np.linspace(0.2, 1.4, 999)
    keep = np.unique(np.concatenate([np.arange(0, 999, 4), [998]]))
    s = fine[keep]
    share = np.diff(np.concatenate([[s[0]], 0.5 * (s[1:] + s[:-1]), [s[-1]]]))
    grid = HalfPlaneModel(s, share, np.zeros(len(s)), 5.0e5, 0.4).even
    assert grid is not None and grid.points == 500 and np.array_equal(grid.grid, keep // 2)
    columns = HalfPlaneModel(s, share, np.zeros(len(s)), 5.0e5, 0.4)
    columns.even = None
    nodes = np.arange(len(s))
    rng = np.random.default_rng(4)
    for x in (rng.normal(size=len(s)), np.eye(len(s))[-1], np.eye(len(s))[100]):
        exact = columns._times(nodes, x)
        assert np.abs(grid @ x - exact).max() <= 1e-12 * np.abs(exact).max()
    some = np.sort(rng.choice(len(s), 60, replace=False))
    other = np.sort(rng.choice(len(s), 25, replace=False))
    assert np.abs(grid.block(some) - columns._block(some)).max() <= 1e-14 * columns._block(some).max()
    assert np.abs(grid.block(some, other) - columns._block(some, other)).max() <= 1e-14 * columns._block(some).max()
    skewed = s.copy()
    skewed[-1] += 1e-3 * (fine[1] - fine[0])
    assert HalfPlaneModel(skewed, share, np.zeros(len(s)), 5.0e5, 0.4).even is None
