"""What the petsc backend asks of MUMPS: the fill-reducing ordering its library has, and the
figures of a factorisation (its user guide's INFO, INFOG and RINFOG)."""

from __future__ import annotations

#: MUMPS's orderings (ICNTL(7)) in order of preference: nested dissection by METIS (5), then by
#: SCOTCH (3), when the library was built with them.
MUMPS_ORDERINGS = (5, 3)
#: ICNTL(7) = 7: MUMPS chooses among what it has (AMF on small matrices, its own PORD nested
#: dissection on large ones; benchmarks/petsc_install_route.py compares them on the square).
MUMPS_AUTOMATIC = 7
_mumps_ordering: int | None = None


def mumps_ordering(PETSc) -> int:
    """The first ordering of :data:`MUMPS_ORDERINGS` this MUMPS was built with, asked of the
    library once per process: the analysis of a small grid Laplacian on this rank alone
    reports in INFOG(7) the ordering it used, which is the one asked for when the library has
    it (MUMPS falls back to its automatic choice otherwise); :data:`MUMPS_AUTOMATIC` if none."""
    global _mumps_ordering
    if _mumps_ordering is None:
        _mumps_ordering = next((o for o in MUMPS_ORDERINGS if _mumps_used(PETSc, o) == o), MUMPS_AUTOMATIC)
    return _mumps_ordering


def _mumps_used(PETSc, ordering: int) -> int:
    """INFOG(7) of MUMPS's analysis of a 16 × 16 grid Laplacian with ICNTL(7) = ``ordering``."""
    import scipy.sparse as sp

    side = 16
    line = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(side, side))
    grid = sp.csr_matrix(sp.kron(sp.eye(side), line) + sp.kron(line, sp.eye(side)))
    matrix = PETSc.Mat().createAIJ(size=grid.shape, csr=(grid.indptr, grid.indices, grid.data), comm=PETSc.COMM_SELF)
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    prefix = "contactfem_ordering_probe_"
    options = PETSc.Options()
    options[f"{prefix}mat_mumps_icntl_7"] = ordering
    try:
        matrix.assemble()
        ksp.setOperators(matrix)
        ksp.setOptionsPrefix(prefix)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        ksp.setFromOptions()
        pc.setUp()
        return int(pc.getFactorMatrix().getMumpsInfog(7))
    finally:
        options.delValue(f"{prefix}mat_mumps_icntl_7")
        ksp.destroy()
        matrix.destroy()


def mumps_figures(factor) -> dict:
    """What MUMPS reports of a factorisation (its user guide's INFO/INFOG/RINFOG): entries of
    the factors over all ranks (INFOG(29), negative in millions), flops of the elimination
    (RINFOG(3)), the ordering it chose (INFOG(7): 2 AMF... 5 METIS, 7 automatic), and this
    rank's megabytes allocated (INFO(16)) and used (INFO(22)) by the factorisation."""
    entries = int(factor.getMumpsInfog(29))
    return {"factor_entries": entries if entries >= 0 else -entries * 10**6,
            "flops": float(factor.getMumpsRinfog(3)), "ordering": int(factor.getMumpsInfog(7)),
            "allocated_mb": int(factor.getMumpsInfo(16)), "used_mb": int(factor.getMumpsInfo(22))}
