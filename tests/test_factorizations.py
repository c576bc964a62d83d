"""The sparse direct factorisations behind the kernel: every installed provider solves the
kernel's matrices to round-off, reuses its analysis for a new matrix of the same pattern,
and reports a matrix that is not positive definite as a SolverError; CHOLMOD called
directly in cvxopt's bundled library gives what cvxopt's own interface gives."""

from __future__ import annotations

import gc

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import contactfem.linalg as linalg
from contactfem.errors import SolverError
from contactfem.linalg import (
    cholmod_ctypes,
    cholmod_cvxopt,
    cholmod_direct,
    cholmod_sksparse,
    pardiso,
    registry,
    superlu,
)


def _elasticity_like(size: int, seed: int) -> sp.csr_matrix:
    """A sparse SPD matrix with the kernel's structure: a 2D grid Laplacian (5-point, so
    fill-in is real) on two components coupled weakly, plus a random diagonal that keeps it
    positive definite (κ below 100)."""
    side = int(np.sqrt(size))
    grid = sp.diags([-1.0, -1.0, 4.0, -1.0, -1.0], [-side, -1, 0, 1, side], shape=(side * side, side * side))
    blocks = sp.kron(sp.eye(2), grid) + 0.1 * sp.kron(sp.csr_matrix([[0, 1], [1, 0]]), sp.eye(side * side))
    rng = np.random.default_rng(seed)
    return sp.csr_matrix(blocks + sp.diags(rng.uniform(0.2, 0.3, blocks.shape[0])))


def _providers() -> list[tuple[str, object]]:
    found = [("superlu", superlu.SuperLUFactor)]
    if registry.installed("cvxopt"):
        found.append(("cvxopt-interface", cholmod_cvxopt.CvxoptCholmodFactor))
        if cholmod_ctypes.cholmod_library() is not None:
            found.append(("cholmod-library", cholmod_direct.DirectCholmodFactor))
    if registry.installed("sksparse"):
        found.append(("scikit-sparse", cholmod_sksparse.SksparseCholmodFactor))
    if registry.installed("pypardiso"):
        found.append(("pardiso", pardiso.PardisoFactor))
    return found


PROVIDERS = _providers()
needs_library = pytest.mark.skipif(not registry.installed("cvxopt") or cholmod_ctypes.cholmod_library() is None,
                                   reason="no CHOLMOD library bundled with cvxopt here")


@pytest.mark.parametrize("size", [9, 400, 6400])
@pytest.mark.parametrize(("label", "provider"), PROVIDERS, ids=[label for label, _ in PROVIDERS])
def test_every_provider_solves_to_round_off_and_reuses_its_analysis(label, provider, size):
    """A solve agrees with SciPy's to 1e-12 relative (these matrices have κ below 1e3), for
    one right-hand side and a block; refactorising new values of the same pattern with the
    kept analysis solves the new matrix, not the old one."""
    matrix = _elasticity_like(size, seed=1)
    rng = np.random.default_rng(2)
    rhs = rng.standard_normal((matrix.shape[0], 3))
    factor = provider(matrix, "the test matrix")
    expected = spla.spsolve(sp.csc_matrix(matrix), rhs)
    scale = np.abs(expected).max()
    assert np.abs(np.asarray(factor.solve(rhs[:, 0])).ravel() - expected[:, 0]).max() < 1e-12 * scale
    assert np.abs(np.asarray(factor.solve(rhs)).reshape(rhs.shape) - expected).max() < 1e-12 * scale
    # New values, still diagonally dominant: off-diagonal entries shrunk, the diagonal grown.
    rows = np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))
    factors = np.where(rows == matrix.indices, rng.uniform(1.0, 2.0, matrix.nnz), rng.uniform(0.5, 1.0, matrix.nnz))
    changed = sp.csr_matrix((matrix.data * factors, matrix.indices, matrix.indptr), shape=matrix.shape)
    changed = sp.csr_matrix((changed + changed.T) / 2)
    refactored = provider(changed, "the test matrix", getattr(factor, "analysis", None))
    expected = spla.spsolve(sp.csc_matrix(changed), rhs[:, 0])
    assert np.abs(np.asarray(refactored.solve(rhs[:, 0])).ravel() - expected).max() < 1e-12 * np.abs(expected).max()


@pytest.mark.parametrize(("label", "provider"), PROVIDERS, ids=[label for label, _ in PROVIDERS])
def test_every_factorisation_counts_its_entries_and_flops(label, provider):
    """Every factorisation has a counted cost: its factor's stored entries (at least one per
    column) and its numeric factorisation's flops, the same for the same matrix; SuperLU's
    from its L and U (nnz(L) + nnz(U), flops from L's column counts and U's row counts),
    its free estimate with the same entries. A Factorizer keeps each one, and its seconds
    are the modelled ones: analysis plus counted work over the rates of costs.py."""
    from contactfem.linalg.costs import MODEL, FactorCost, lu_flops

    matrix = _elasticity_like(1600, seed=30)
    n = matrix.shape[0]
    factor = provider(matrix, "the test matrix")
    cost = factor.cost
    assert isinstance(cost, FactorCost) and cost.size == n and cost.kind in MODEL.rates
    assert n <= cost.entries and cost.flops > 0 and cost.matrix_entries == matrix.nnz
    assert provider(matrix, "the test matrix").cost == cost
    if label == "superlu":
        lower, upper = factor._lu.L, factor._lu.U
        assert cost.entries == lower.nnz + upper.nnz
        assert cost.flops == lu_flops(np.diff(lower.indptr), np.bincount(upper.indices, minlength=n))
        assert factor.estimated_cost.entries == cost.entries
    factorizer = linalg.Factorizer({"superlu": "superlu", "pardiso": "pardiso"}.get(label, "cholmod"))
    if type(factorizer.factorize(matrix)) is type(factor):  # the provider this backend uses here
        factorizer.factorize(matrix)
        assert len(factorizer.costs) == 2 and factorizer.costs[0].entries == factorizer.costs[1].entries
        assert factorizer.seconds == [analysis + MODEL.factorize_seconds(c)
                                      for c, analysis in zip(factorizer.costs, factorizer.analysis_seconds)]


@pytest.mark.parametrize(("label", "provider"), [p for p in PROVIDERS if p[0] != "superlu"],
                         ids=[label for label, _ in PROVIDERS if label != "superlu"])
def test_a_matrix_that_is_not_positive_definite_is_refused(label, provider, capfd):
    """A symmetric matrix with a negative eigenvalue is a SolverError saying so, and the
    library prints nothing (a --json run's stdout stays one document)."""
    matrix = _elasticity_like(400, seed=3)
    matrix = sp.csr_matrix(matrix - sp.diags(np.r_[np.zeros(matrix.shape[0] - 1), 10.0]))
    with pytest.raises(SolverError, match="not positive definite"):
        provider(matrix, "the test matrix")
    assert capfd.readouterr().out == ""


@needs_library
@pytest.mark.parametrize("kind", ["simplicial", "supernodal"])
@pytest.mark.parametrize("size", [9, 6400])
def test_library_sparse_solves_match_dense_ones(size, kind, monkeypatch):
    """The Schur columns from the library: full columns A⁻¹ B in dense blocks equal
    A⁻¹ B column by column, and the forward ones satisfy Wᵀ W = Bᵀ A⁻¹ B and
    Pᵀ L⁻ᵀ W y = A⁻¹ B y (the backward half of a solve) to 1e-12 through either route, whichever kind of factor (always an LLᵀ, even for a 2 × 2 grid); only a
    supernodal one is converted by the pattern solve."""
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", {"simplicial": 0, "supernodal": 2}[kind])
    matrix = _elasticity_like(size, seed=4)
    n = matrix.shape[0]
    rng = np.random.default_rng(5)
    columns = 37 if n > 100 else 3
    rhs = sp.random(n, columns, density=min(1.0, 4.0 / n), random_state=6, format="csc") + \
        sp.csc_matrix((np.ones(columns), (rng.choice(n, columns, replace=False), np.arange(columns))), shape=(n, columns))
    factor = cholmod_direct.DirectCholmodFactor(matrix, "the test matrix")
    dense = factor.solve(rhs.toarray())
    full = factor.solve_sparse(sp.csc_matrix(rhs))
    assert full.flags.f_contiguous and np.abs(full - dense).max() < 1e-13 * np.abs(dense).max()
    expected = rhs.T @ dense
    # Every route: the supernodal blocks (a supernodal factor), CHOLMOD's blocked sparse
    # solve, then its solve with each column's pattern (which converts a supernodal factor
    # to a simplicial one), then whichever forward_sparse picks.
    assert factor.analysis.simplicial is (kind == "simplicial")
    # The supernodal blocks are read only from a supernodal factor (a simplicial one's fields
    # do not read back as one).
    assert (factor._supernodes() is None) is (kind == "simplicial")
    weights = rng.standard_normal(columns)
    combined = dense @ weights
    routes = [factor._blocked_forward, lambda b: factor._pattern_forward(factor._permuted(b)), factor.forward_sparse]
    if kind == "supernodal":
        routes.insert(0, lambda b: factor._supernodal_forward(factor._permuted(b)))
    for route in routes:
        forward, scaled = route(sp.csc_matrix(rhs))
        schur = (forward.T @ scaled).toarray()
        assert np.abs(schur - expected).max() < 1e-12 * np.abs(expected).max()
        # A⁻¹ B y from the forward columns by the backward half of a solve: Pᵀ L⁻ᵀ (W y).
        assert np.abs(factor.backward(scaled @ weights) - combined).max() < 1e-12 * np.abs(combined).max()
    assert factor.analysis.simplicial
    assert factor.analysis.converted is (kind == "supernodal")


@needs_library
def test_library_and_cvxopt_interface_give_the_same_factor():
    """Both routes reach the same CHOLMOD with the same AMD ordering: their solves agree to
    round-off on the kernel's own matrix (the square's stiffness with its supports masked)."""
    from conftest import case_from, square_case_dict

    from contactfem.methods import get_method
    from contactfem.solve import prepare

    system = prepare(case_from(square_case_dict(24))).contact_system(get_method("positive")).system
    fixed = np.zeros(system.stiffness.shape[0], dtype=bool)
    fixed[np.asarray(system.fixed_dofs, dtype=np.int64)] = True
    kept = sp.diags((~fixed).astype(float))
    matrix = sp.csr_matrix(kept @ system.stiffness @ kept + sp.diags(fixed.astype(float)))
    matrix.eliminate_zeros()
    rhs = np.where(fixed, 0.0, system.load)
    library = cholmod_direct.DirectCholmodFactor(matrix, "the square")
    interface = cholmod_cvxopt.CvxoptCholmodFactor(matrix, "the square")
    x, y = library.solve(rhs), np.asarray(interface.solve(rhs)).ravel()
    assert np.abs(x - y).max() < 1e-12 * np.abs(y).max()
    assert np.abs(rhs - matrix @ x).max() < 1e-12 * np.abs(rhs).max() * 1e3


@needs_library
def test_library_is_used_only_when_its_layout_is_the_known_one(monkeypatch):
    """cholmod_common's fields are written only after cholmod_start's defaults read back
    at the offsets relied on; a library with another layout is left to cvxopt's interface."""
    library = cholmod_ctypes.cholmod_library()
    common = library.start()
    assert common is not None
    library.library.cholmod_finish(common)
    offset, kind, value = cholmod_ctypes._COMMON_DEFAULTS[-1]
    monkeypatch.setattr(cholmod_ctypes, "_COMMON_DEFAULTS", (*cholmod_ctypes._COMMON_DEFAULTS[:-1], (offset, kind, value + 7)))
    assert library.start() is None
    monkeypatch.setitem(cholmod_ctypes._LIBRARY_STATE, "library", None)
    matrix = _elasticity_like(400, seed=7)
    assert isinstance(cholmod_cvxopt.cvxopt_cholmod(matrix, "m"), cholmod_cvxopt.CvxoptCholmodFactor)


@needs_library
def test_library_frees_a_factor_with_its_last_user(monkeypatch):
    """The symbolic and numeric factor live as long as a factorisation or the Factorizer
    still holds them, and are freed (cholmod_free_factor, cholmod_finish) after."""
    freed = []
    original = cholmod_direct._free_analysis
    monkeypatch.setattr(cholmod_direct, "_free_analysis", lambda *args: (freed.append(args[2]), original(*args)))
    factorizer = linalg.Factorizer("cholmod")
    first = factorizer.factorize(_elasticity_like(400, seed=8))
    address = first.analysis.symbolic
    factorizer.factorize(_elasticity_like(400, seed=9))  # same pattern: same factor, refactorised
    assert freed == []
    factorizer.factorize(_elasticity_like(900, seed=9))  # a new pattern
    del first
    gc.collect()
    assert freed == [address]


@needs_library
@pytest.mark.parametrize("copy_bytes", [0, 2**30])
def test_library_refactorises_after_sparse_solves_and_refuses_a_replaced_factor(copy_bytes, monkeypatch):
    """A solve with sparse right-hand sides converts CHOLMOD's supernodal factor to a
    simplicial one in place, after a supernodal copy is kept for the dense solves (which
    still solve the matrix); the next factorisation of the pattern numbers that copy, or
    without one starts again from the symbolic analysis, so it is a supernodal LLᵀ again
    (its forward columns still give Bᵀ A⁻¹ B = Wᵀ W, which an LDLᵀ would not), and the
    factorisation it replaced refuses to solve."""
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", 2)
    monkeypatch.setattr(cholmod_direct, "SUPERNODAL_COPY_BYTES", copy_bytes)
    matrix = _elasticity_like(6400, seed=13)
    n = matrix.shape[0]
    rhs = sp.csc_matrix((np.ones(5), (np.arange(0, n, n // 5)[:5], np.arange(5))), shape=(n, 5))
    factorizer = linalg.Factorizer("cholmod")
    first = factorizer.factorize(matrix)
    first._pattern_forward(first._permuted(rhs))
    assert first.analysis.simplicial and bool(first.analysis.solving.value) is (copy_bytes > 0)
    x = first.solve(np.ones(n))
    assert np.abs(matrix @ x - 1.0).max() < 1e-10 * np.abs(matrix).max() * np.abs(x).max()
    changed = sp.csr_matrix(matrix + sp.diags(np.full(n, 0.5)))
    second = factorizer.factorize(changed)
    assert not second.analysis.simplicial and not second.analysis.solving.value
    forward, scaled = second._pattern_forward(second._permuted(rhs))
    expected = rhs.T @ second.solve(rhs.toarray())
    assert np.abs((forward.T @ scaled).toarray() - expected).max() < 1e-12 * np.abs(expected).max()
    assert np.abs(expected - rhs.T @ spla.spsolve(sp.csc_matrix(changed), rhs.toarray())).max() \
        < 1e-10 * np.abs(expected).max()
    with pytest.raises(SolverError, match="replaced it"):
        first.solve(np.ones(n))


@needs_library
def test_library_picks_the_cheaper_forward_route_from_counts(monkeypatch):
    """The route of a block of forward columns is the cheapest of the modelled ones, from
    counts alone: with a supernodal factor, its blocks on the supernodes the block reaches
    (counted exactly before solving: their stored entries and number), which convert
    nothing; without them (a layout that does not read back), a few columns go through the
    blocked solve while converting the factor is modelled to cost more than it saves; every
    forward call counts the factor entries its columns' paths reach (Σ of L's column counts
    over each column's rows), and with those counts (not a guess) the choice for many
    columns is the pattern solve, whose conversion is then modelled in setup_seconds."""
    from contactfem.linalg import supernodal
    from contactfem.linalg.costs import MODEL

    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", 2)
    matrix = _elasticity_like(6400, seed=14)
    n = matrix.shape[0]
    factor = cholmod_direct.DirectCholmodFactor(matrix, "the test matrix")
    analysis = factor.analysis
    few = sp.csc_matrix((np.ones(2), ([3, n // 2], [0, 1])), shape=(n, 2))
    structure = factor._supernodes()
    reach = structure.reach(factor._permuted(few).indices)
    blocked, pattern, through_blocks = factor._route_seconds(2, reach)
    assert through_blocks == MODEL.supernodal_forward_seconds(factor.cost, 2, structure.reach_entries(reach),
                                                              len(reach)) < min(blocked, pattern)
    forward, _ = factor.forward_sparse(few)
    assert factor.route == "supernodal" and not analysis.simplicial and not analysis.solving.value
    expected = few.T @ factor.solve(few.toarray())
    assert np.abs((forward.T @ forward).toarray() - expected).max() < 1e-12 * np.abs(expected).max()

    monkeypatch.setattr(supernodal.SupernodalFactor, "read", classmethod(lambda cls, address, size: None))
    factor = cholmod_direct.DirectCholmodFactor(matrix, "the test matrix")
    analysis = factor.analysis
    assert factor.cost.kind == "cholmod-supernodal" and analysis.path_entries is None
    blocked, pattern, through_blocks = factor._route_seconds(2)
    assert through_blocks == np.inf and blocked < pattern and pattern > MODEL.conversion_seconds(factor.cost) > 0
    forward, _ = factor.forward_sparse(few)
    assert factor.route == "blocked" and factor.setup_seconds == 0.0 and not analysis.simplicial
    reached = int(analysis.column_counts[forward.indices].sum())
    assert (analysis.path_columns, analysis.path_entries) == (2, reached / 2)
    k = 400
    many = sp.csc_matrix((np.ones(k), (np.arange(0, 8 * k, 8), np.arange(k))), shape=(n, k))
    blocked, pattern, _ = factor._route_seconds(k)
    assert factor.forward_seconds(k) == min(blocked, pattern)
    assert pattern == MODEL.conversion_seconds(factor.cost) + MODEL.pattern_forward_seconds(
        factor.cost, k, reached / 2)
    forward, scaled = factor.forward_sparse(many)
    assert factor.route == ("blocked" if blocked < pattern else "pattern")
    if factor.route == "pattern":
        assert analysis.simplicial and factor.setup_seconds == MODEL.conversion_seconds(factor.cost)
        assert factor._route_seconds(k)[1] == MODEL.pattern_forward_seconds(factor.cost, k, analysis.path_entries)
    expected = many.T @ factor.solve(many.toarray())
    assert np.abs((forward.T @ scaled).toarray() - expected).max() < 1e-12 * np.abs(expected).max()


@needs_library
def test_the_direct_factors_cost_is_counted_from_its_column_counts(monkeypatch):
    """The factor's cost is read from CHOLMOD's own counts: its column counts sum to the
    entries of a simplicial factor, a supernodal one stores at least as many; flops are
    Σ c_j². Before any path is counted, a pattern column is guessed from the fill, a
    positive share of a full solve, larger with more fill and at most 0.1 of it. Where the
    factor's fields do not read back as its own (another layout), the cost falls back to
    the matrix's counts and the factor still solves."""
    from contactfem.linalg.costs import MODEL, PATTERN_GUESS_CAP, cholesky_flops

    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", 0)
    simplicial = cholmod_direct.DirectCholmodFactor(_elasticity_like(6400, seed=15), "m")
    counts = simplicial.analysis.column_counts
    assert simplicial.cost.kind == "cholmod-simplicial" and simplicial.cost.entries == counts.sum()
    assert simplicial.cost.flops == cholesky_flops(counts) and simplicial.cost.size == 2 * 6400
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", 2)
    sparse_grid = cholmod_direct.DirectCholmodFactor(_elasticity_like(400, seed=15), "m")
    dense_grid = cholmod_direct.DirectCholmodFactor(_elasticity_like(40000, seed=15), "m")
    assert dense_grid.cost.kind == "cholmod-supernodal"
    assert dense_grid.cost.entries >= dense_grid.analysis.column_counts.sum()
    shares = [MODEL.pattern_column_guess(f.cost) / MODEL.solve_seconds(f.cost) for f in (sparse_grid, dense_grid)]
    assert 0.0 < shares[0] < shares[1] <= PATTERN_GUESS_CAP
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_IS_SUPER", cholmod_ctypes._FACTOR_XSIZE)
    matrix = _elasticity_like(400, seed=16)
    fallback = cholmod_direct.DirectCholmodFactor(matrix, "m")
    assert fallback.cost.entries >= fallback.cost.size and fallback.cost.flops > 0
    assert np.abs(matrix @ fallback.solve(np.ones(800)) - 1.0).max() < 1e-10


@needs_library
def test_cholmod_chooses_the_kind_of_factor_and_keeps_it_an_llt(monkeypatch):
    """CHOLMOD picks the kind by the factor's flops per entry: simplicial for the little
    fill of a small grid, supernodal for a larger one. A simplicial factor is an LLᵀ as
    well (forward columns give Bᵀ A⁻¹ B = Wᵀ W), refuses a matrix that is not positive
    definite, and is refactorised in place after pattern solves (nothing to convert)."""
    small = cholmod_direct.DirectCholmodFactor(_elasticity_like(400, seed=16), "m")
    large = cholmod_direct.DirectCholmodFactor(_elasticity_like(6400, seed=16), "m")
    assert small.analysis.analysed_simplicial and not large.analysis.analysed_simplicial
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", 0)
    matrix = _elasticity_like(6400, seed=17)
    n = matrix.shape[0]
    factorizer = linalg.Factorizer("cholmod")
    first = factorizer.factorize(matrix)
    assert first.analysis.analysed_simplicial
    rhs = sp.csc_matrix((np.ones(6), (np.arange(0, n, n // 6)[:6], np.arange(6))), shape=(n, 6))
    first._pattern_forward(first._permuted(rhs))
    address = first.analysis.numeric.value
    changed = sp.csr_matrix(matrix + sp.diags(np.full(n, 0.25)))
    second = factorizer.factorize(changed)
    assert second.analysis.numeric.value == address and not second.analysis.converted
    forward, scaled = second._pattern_forward(second._permuted(rhs))
    expected = rhs.T @ spla.spsolve(sp.csc_matrix(changed), rhs.toarray())
    assert np.abs((forward.T @ scaled).toarray() - expected).max() < 1e-12 * np.abs(expected).max()
    bad = sp.csr_matrix(matrix - sp.diags(np.r_[np.zeros(n - 1), 10.0]))
    with pytest.raises(SolverError, match="not positive definite"):
        cholmod_direct.DirectCholmodFactor(bad, "the shifted matrix")


@pytest.mark.parametrize("backend", linalg.available_backends())
def test_an_analysis_made_ahead_in_another_thread_serves_the_first_factorisation(backend):
    """Factorizer.analyse orders and analyses a pattern for the factorisations to come, in
    another thread while this one factorises other matrices (a fine level's solver while
    its coarser levels solve): the first factorisation then analyses nothing (a backend
    that reuses no analysis does it all then) and solves as a fresh one does, to round-off."""
    from concurrent.futures import ThreadPoolExecutor

    matrix = _elasticity_like(6400, seed=3)
    rhs = np.random.default_rng(4).standard_normal(matrix.shape[0])
    expected = spla.spsolve(sp.csc_matrix(matrix), rhs)
    ahead = linalg.Factorizer(backend, name="the test matrix")
    with ThreadPoolExecutor(max_workers=1) as pool:
        analysed = pool.submit(ahead.analyse, matrix)
        others = [linalg.factorize(_elasticity_like(size, seed=size), backend) for size in (400, 900, 1600)]
        analysed.result()
    assert all(np.isfinite(np.asarray(other.solve(np.ones(other_size)))).all()
               for other, other_size in zip(others, (800, 1800, 3200)))
    factor = ahead.factorize(matrix)
    provider = linalg.backend_provider(backend)
    reuses = provider == "sksparse" or (provider == "cvxopt" and cholmod_ctypes.cholmod_library() is not None)
    if reuses:
        assert ahead.ahead_seconds > 0 and ahead.analysis_seconds == [pytest.approx(0.0, abs=1e-3)]
    else:
        assert ahead.ahead_seconds == 0.0
    solved = np.asarray(factor.solve(rhs)).ravel()
    assert np.abs(solved - expected).max() < 1e-12 * np.abs(expected).max()


def test_superlus_32_bit_first_guess_sets_its_largest_matrix():
    """SciPy 1.17's SuperLU (int32 permutations) sizes its first guess of the factor as 30
    times the nonzeros in a C int: 71 582 788 nonzeros at most."""
    if np.asarray(spla.splu(sp.identity(2, format="csc")).perm_c).dtype.itemsize >= 8:
        pytest.skip("this SciPy's SuperLU counts in 64 bits")
    assert linalg.superlu_max_nonzeros() == (2**31 - 1) // 30 == 71_582_788
    assert linalg.superlu_refusal(71_582_788, 5_000_000) is None
    assert "71.58 million" in linalg.superlu_refusal(71_582_789, 5_000_000)


def test_a_matrix_past_superlus_first_guess_is_refused_before_it_is_tried(monkeypatch):
    """The limit checked on the matrix itself, before SuperLU spends anything on it."""
    from contactfem.errors import FactorCapacityError

    monkeypatch.setattr(superlu, "superlu_max_nonzeros", lambda: 10)
    monkeypatch.setattr(superlu.spla, "splu", lambda *args, **kwargs: pytest.fail("SuperLU was called"))
    with pytest.raises(FactorCapacityError, match=r"the test matrix: SciPy's SuperLU cannot factorise a matrix of "
                                                  r"1\.6e-05 million nonzeros \(4 unknowns\).*32-bit integer"):
        superlu.SuperLUFactor(sp.csc_matrix(np.ones((4, 4)) + 4 * np.eye(4)), "the test matrix")


@pytest.mark.slow
def test_superlu_fails_at_once_past_its_first_guess_whatever_the_fill():
    """A band matrix of 23 diagonals (its factor as sparse as itself): 71.30 million nonzeros
    factorise, 71.99 million fail at once with MemoryError, about 3 GB each."""
    def band(n: int) -> sp.csc_matrix:
        offsets = range(-11, 12)
        return sp.diags([np.full(n - abs(k), 24.0 if k == 0 else -1.0) for k in offsets], list(offsets),
                        shape=(n, n), format="csc")

    above = band(3_130_000)
    assert above.nnz > linalg.superlu_max_nonzeros()
    with pytest.raises(MemoryError):
        spla.splu(above, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    del above
    below = band(3_100_000)
    assert below.nnz <= linalg.superlu_max_nonzeros()
    factor = spla.splu(below, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    assert factor.L.nnz < 2 * below.nnz


def test_superlu_running_out_of_room_says_both_causes_through_the_command_line(tmp_path, monkeypatch):
    """SciPy's SuperLU reports an overflow of its 32-bit entry counts as MemoryError ("Not
    enough memory to perform factorization."), and the command said "out of memory ... use a
    coarser mesh". It now names both causes and what lifts either; exit 1, one line,
    nothing written."""
    from pathlib import Path

    from click.testing import CliRunner

    from contactfem.cli import main
    from contactfem.errors import FactorCapacityError

    def overflowing(*args, **kwargs):
        raise MemoryError("Not enough memory to perform factorization.")

    monkeypatch.setattr(superlu.spla, "splu", overflowing)
    with pytest.raises(FactorCapacityError, match="32-bit") as caught:
        superlu.SuperLUFactor(sp.identity(3, format="csc"), "the test matrix")
    assert isinstance(caught.value, MemoryError)
    case = Path(__file__).resolve().parents[1] / "cases" / "square.yaml"
    result = CliRunner().invoke(main, ["solve", str(case), "--backend", "superlu", "--out", str(tmp_path / "out")])
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 1 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "SuperLU could not hold the factor" in lines[0] and "32-bit entry counts" in lines[0]
    assert "solver.backend: cholmod" in lines[0]
    assert not (tmp_path / "out").exists()


def test_a_pardiso_factor_is_released_with_its_last_user():
    """MKL keeps a Pardiso factor in its own memory until phase -1 releases it, which the
    solver object does not do when collected: each factorisation stayed resident to the end
    of the process (0.3 GB each at 490 000 unknowns, a convergence study at 13.7 GB against
    8.2 for one solve of its finest mesh). Four more factorisations of a 250 000-unknown
    Laplacian now leave the resident memory where the first left it."""
    pytest.importorskip("pypardiso")
    n = 500
    line = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(n, n))
    matrix = (sp.kronsum(line, line) + sp.identity(n * n)).tocsr()

    def resident() -> float:
        with open("/proc/self/status", encoding="utf-8") as status:
            return int(status.read().split("VmRSS:")[1].split()[0]) * 1024.0

    def factorise_once() -> None:
        factor = pardiso.PardisoFactor(matrix, "the Laplacian")
        assert np.abs(matrix @ factor.solve(np.ones(n * n)) - 1.0).max() < 1e-10
        del factor
        gc.collect()

    factorise_once()
    before = resident()
    factor = pardiso.PardisoFactor(matrix, "the Laplacian")
    held = resident() - before  # one factor, resident
    del factor
    gc.collect()
    for _ in range(4):
        factorise_once()
    assert held > 50e6  # the factor is large enough to see
    assert resident() - before < 0.5 * held


@needs_library
@pytest.mark.parametrize("size", [400, 6400])
def test_the_direct_route_switched_off_gives_the_same_answers_through_cvxopts_interface(size, monkeypatch):
    """``cholmod`` with the direct route on (the bundled library through ctypes) and off
    (cvxopt's interface): the same solves, the same Schur blocks Bᵀ A⁻¹ B from forward
    columns and the same A⁻¹ B y from their backward solve, to 1e-12 relative, through a Factorizer refactorising one pattern. Switched
    off, the library is not asked for at all."""
    matrix = _elasticity_like(size, seed=21)
    n = matrix.shape[0]
    changed = sp.csr_matrix(matrix + sp.diags(np.full(n, 0.5)))
    rhs = np.random.default_rng(22).standard_normal((n, 3))
    columns = sp.csc_matrix((np.ones(6), (np.arange(0, n, n // 6)[:6], np.arange(6))), shape=(n, 6))
    weights = np.linspace(-1.0, 2.0, 6)

    def run() -> tuple[type, list[np.ndarray]]:
        factorizer = linalg.Factorizer("cholmod", name="the test matrix")
        results = []
        for values in (matrix, changed):
            factor = factorizer.factorize(values)
            forward, scaled = factor.forward_sparse(columns)
            results += [np.asarray(factor.solve(rhs)).reshape(rhs.shape), (forward.T @ scaled).toarray(),
                        factor.backward(scaled @ weights)]
        return type(factor), results

    assert linalg.direct_cholmod_enabled()
    on_kind, on = run()
    with linalg.direct_cholmod(False):
        assert not linalg.direct_cholmod_enabled()
        for module in (cholmod_ctypes, cholmod_direct):
            monkeypatch.setattr(module, "cholmod_library", lambda: pytest.fail("the library was asked for"))
        off_kind, off = run()
    monkeypatch.undo()
    assert linalg.direct_cholmod_enabled()
    assert (on_kind, off_kind) == (cholmod_direct.DirectCholmodFactor, cholmod_cvxopt.CvxoptCholmodFactor)
    for direct, interface in zip(on, off):
        assert np.abs(direct - interface).max() <= 1e-12 * np.abs(interface).max()


@pytest.mark.skipif(not registry.installed("cvxopt"), reason="cvxopt is not installed")
@pytest.mark.parametrize("setting", ["0", "off", "1"])
def test_the_environment_switch_keeps_ctypes_away_from_cholmod(setting):
    """In a fresh process with ``CONTACTFEM_CHOLMOD_DIRECT=0`` (or ``off``), factorising,
    solving and forward columns with ``cholmod`` load no CHOLMOD library through ctypes and
    never import the direct route's modules; with ``1`` they do (where the wheel bundles it)."""
    import json
    import os
    import subprocess
    import sys
    import textwrap

    script = textwrap.dedent("""
        import ctypes, json, sys
        import numpy as np, scipy.sparse as sp
        loaded = []
        original = ctypes.CDLL.__init__
        def recording(self, name, *args, **kwargs):
            loaded.append(str(name))
            original(self, name, *args, **kwargs)
        ctypes.CDLL.__init__ = recording
        from contactfem.linalg import Factorizer, direct_cholmod_enabled
        grid = sp.diags([-1.0, -1.0, 4.2, -1.0, -1.0], [-20, -1, 0, 1, 20], shape=(400, 400), format="csr")
        factor = Factorizer("cholmod").factorize(grid)
        x = factor.solve(np.ones(400))
        factor.forward_sparse(sp.csc_matrix(sp.identity(400, format="csc")[:, :3]))
        print(json.dumps({"enabled": direct_cholmod_enabled(), "kind": type(factor).__name__,
                          "cholmod_loaded": [name for name in loaded if "cholmod" in name.lower()],
                          "direct_imported": "contactfem.linalg.cholmod_direct" in sys.modules,
                          "bindings_imported": "contactfem.linalg.cholmod_ctypes" in sys.modules,
                          "residual": float(np.abs(grid @ x - 1.0).max())}))
    """)
    environment = dict(os.environ, CONTACTFEM_CHOLMOD_DIRECT=setting)
    done = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["residual"] < 1e-12
    if setting == "1":
        assert report["enabled"] and report["direct_imported"]
        if cholmod_ctypes.cholmod_library() is not None:
            assert report["kind"] == "DirectCholmodFactor" and report["cholmod_loaded"]
    else:
        assert not report["enabled"] and report["kind"] == "CvxoptCholmodFactor"
        assert report["cholmod_loaded"] == [] and not report["direct_imported"] and not report["bindings_imported"]
