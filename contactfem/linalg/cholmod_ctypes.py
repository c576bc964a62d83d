"""ctypes bindings of the CHOLMOD library bundled in cvxopt's wheel, for
:mod:`contactfem.linalg.cholmod_direct` alone (see its docstring for what they assume).

The structs CHOLMOD exchanges (cholmod_sparse, cholmod_dense) are declared here as C
structs; cholmod_common and cholmod_factor are opaque buffers read and written at fixed
byte offsets, those of CHOLMOD 3's layout on 64-bit machines. The library is loaded once,
and only after cholmod_start's defaults read back at those offsets.
"""

from __future__ import annotations

import ctypes
import importlib.util
import threading

import numpy as np


class _SparseStruct(ctypes.Structure):
    """cholmod_sparse (the same layout in every CHOLMOD release)."""
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


class _DenseStruct(ctypes.Structure):
    """cholmod_dense."""
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("d", ctypes.c_size_t), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p),
                ("xtype", ctypes.c_int), ("dtype", ctypes.c_int)]


_SPARSE_P, _DENSE_P = ctypes.POINTER(_SparseStruct), ctypes.POINTER(_DenseStruct)
# CHOLMOD's constants: CHOLMOD_INT, CHOLMOD_REAL, CHOLMOD_DOUBLE; solve systems A, L and P.
_ITYPE_INT, _XTYPE_REAL, _DTYPE_DOUBLE = 0, 1, 0
_SYS_A, _SYS_L, _SYS_LT, _SYS_P, _SYS_PT = 0, 4, 5, 7, 8
#: cholmod_common is allocated here (CHOLMOD 3 needs 2 664 bytes) and filled by cholmod_start.
_COMMON_BYTES = 16384
#: Fields of cholmod_common read or written here: (offset, C type, the value cholmod_start
#: sets). The defaults are checked after cholmod_start before the library is used, so a
#: CHOLMOD whose layout differs is never written into: contactfem falls back to cvxopt's API.
_COMMON_DEFAULTS = ((0, ctypes.c_double, 0.0),      # dbound
                    (8, ctypes.c_double, 1.2),      # grow0
                    (40, ctypes.c_double, 40.0),    # supernodal_switch
                    (48, ctypes.c_int, 1),          # supernodal = CHOLMOD_AUTO
                    (52, ctypes.c_int, 1),          # final_asis
                    (60, ctypes.c_int, 0),          # final_ll
                    (144, ctypes.c_int, 3),         # print
                    (168, ctypes.c_int, 0))         # nmethods
_COMMON_PRINT, _COMMON_SUPERNODAL, _COMMON_FINAL_ASIS, _COMMON_FINAL_LL = 144, 48, 52, 60
#: Common->supernodal: CHOLMOD_AUTO (1), CHOLMOD's own choice by the factor's flops per
#: entry (supernodal from 40), or CHOLMOD_SUPERNODAL (2). With final_asis off and final_ll
#: on, a simplicial factor is an LLᵀ too (the default simplicial LDLᵀ passes a negative
#: pivot silently), so that W = L⁻¹ P B gives Bᵀ A⁻¹ B = Wᵀ W either way. The meshes here
#: have little fill, and CHOLMOD picks simplicial on graded and small ones, whose full
#: solves it runs two to three times faster, whose analysis skips the supernodal one, and
#: whose solves with a sparse right-hand side need no conversion.
_CHOLMOD_AUTO, _CHOLMOD_SUPERNODAL = 1, 2
_FACTOR_SWITCH = _CHOLMOD_AUTO
#: cholmod_factor starts with n, minor (the column where a non-positive pivot stopped it),
#: Perm (the fill-reducing permutation) and ColCount (the column counts of L, which the
#: symbolic analysis sets for either kind of factor); further on, xsize (a supernodal
#: factor's stored entries) and is_super, at the offsets of CHOLMOD 3 to 5's layout on
#: 64-bit machines (read to count the factor's cost and to tell the kinds apart; checked:
#: n must match and is_super be 0 or 1, see :func:`factor_counts`).
_FACTOR_MINOR, _FACTOR_PERM = ctypes.sizeof(ctypes.c_size_t), 2 * ctypes.sizeof(ctypes.c_size_t)
_FACTOR_XSIZE, _FACTOR_IS_SUPER = 120, 184
_FACTOR_COLCOUNT = 3 * ctypes.sizeof(ctypes.c_size_t)
#: CHOLMOD major versions whose struct layouts the offsets above are those of; a library
#: that reports another (cholmod_version) is not used.
KNOWN_MAJOR_VERSIONS = (3, 4, 5)


class CholmodLibrary:
    """CHOLMOD's C interface (int indices) in the shared library that cvxopt's wheel bundles,
    called through ctypes.

    cvxopt's own interface copies the matrix twice (its sparse matrix, then a CHOLMOD copy
    of it at every factorisation, both with 64-bit indices) and solves a block of
    right-hand sides one column at a time. Called directly, CHOLMOD reads the kernel's CSR
    arrays in place as the upper triangle of a symmetric matrix (stype = 1: the entries
    below the diagonal are ignored, and the CSR matrix of a symmetric matrix is its own CSC
    one) and solves blocks at once: a lower peak, a faster first factorisation and about
    twice as fast block solves (benchmarks/results/solvers.json; docs/performance.md).
    """

    def __init__(self, library: ctypes.CDLL) -> None:
        self.library = library
        library.cholmod_start.argtypes = [ctypes.c_void_p]
        library.cholmod_finish.argtypes = [ctypes.c_void_p]
        library.cholmod_analyze.restype = ctypes.c_void_p
        library.cholmod_analyze.argtypes = [_SPARSE_P, ctypes.c_void_p]
        library.cholmod_factorize.argtypes = [_SPARSE_P, ctypes.c_void_p, ctypes.c_void_p]
        library.cholmod_solve.restype = _DENSE_P
        library.cholmod_solve.argtypes = [ctypes.c_int, ctypes.c_void_p, _DENSE_P, ctypes.c_void_p]
        library.cholmod_spsolve.restype = _SPARSE_P
        library.cholmod_spsolve.argtypes = [ctypes.c_int, ctypes.c_void_p, _SPARSE_P, ctypes.c_void_p]
        library.cholmod_solve2.restype = ctypes.c_int
        library.cholmod_solve2.argtypes = [ctypes.c_int, ctypes.c_void_p, _DENSE_P, _SPARSE_P, ctypes.POINTER(_DENSE_P),
                                           ctypes.POINTER(_SPARSE_P), ctypes.POINTER(_DENSE_P),
                                           ctypes.POINTER(_DENSE_P), ctypes.c_void_p]
        library.cholmod_free_dense.argtypes = [ctypes.POINTER(_DENSE_P), ctypes.c_void_p]
        library.cholmod_free_sparse.argtypes = [ctypes.POINTER(_SPARSE_P), ctypes.c_void_p]
        library.cholmod_free_factor.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p]
        library.cholmod_copy_factor.restype = ctypes.c_void_p
        library.cholmod_copy_factor.argtypes = [ctypes.c_void_p, ctypes.c_void_p]

    def start(self) -> ctypes.Array | None:
        """A fresh cholmod_common with printing off, or None if its layout is not the known one."""
        common = ctypes.create_string_buffer(_COMMON_BYTES)
        self.library.cholmod_start(common)
        if any(kind.from_buffer(common, offset).value != value for offset, kind, value in _COMMON_DEFAULTS):
            self.library.cholmod_finish(common)
            return None
        # CHOLMOD would print its warnings (a non-positive pivot) on stdout; they are raised instead.
        ctypes.c_int.from_buffer(common, _COMMON_PRINT).value = 0
        ctypes.c_int.from_buffer(common, _COMMON_SUPERNODAL).value = _FACTOR_SWITCH
        ctypes.c_int.from_buffer(common, _COMMON_FINAL_ASIS).value = 0
        ctypes.c_int.from_buffer(common, _COMMON_FINAL_LL).value = 1
        return common

    @staticmethod
    def sparse(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, nrow: int, stype: int) -> _SparseStruct:
        """A cholmod_sparse over numpy arrays (int32 indices, float64 values), not copied:
        the arrays must outlive every call that is given it."""
        return _SparseStruct(nrow, len(indptr) - 1, len(indices), indptr.ctypes.data, indices.ctypes.data, None,
                             data.ctypes.data, None, stype, _ITYPE_INT, _XTYPE_REAL, _DTYPE_DOUBLE, 1, 1)


def _c_array(address: int, kind: type, count: int) -> np.ndarray:
    """A numpy view of ``count`` values of C type ``kind`` at ``address``."""
    if count == 0:
        return np.zeros(0, dtype=np.dtype(kind))
    return np.ctypeslib.as_array(ctypes.cast(address, ctypes.POINTER(kind)), (count,))


def factor_counts(address: int, size: int) -> tuple[np.ndarray, int, bool] | None:
    """(column counts of L, stored entries, whether supernodal) of the cholmod_factor at
    ``address``, the counts copied; None where its fields do not read back as those of a
    factor of ``size`` columns (another layout)."""
    n = ctypes.c_size_t.from_address(address).value
    supernodal = ctypes.c_int.from_address(address + _FACTOR_IS_SUPER).value
    counts_at = ctypes.c_void_p.from_address(address + _FACTOR_COLCOUNT).value
    if n != size or supernodal not in (0, 1) or (size and not counts_at):
        return None
    counts = _c_array(counts_at, ctypes.c_int32, size).copy()
    if size and (counts.min() < 1 or counts.max() > size):
        return None
    if supernodal:
        stored = ctypes.c_size_t.from_address(address + _FACTOR_XSIZE).value
    else:
        stored = int(counts.sum(dtype=np.int64))
    if not size <= stored < 2**40:
        return None
    return counts, stored, bool(supernodal)


def library_version(library: ctypes.CDLL) -> tuple[int, int, int] | None:
    """CHOLMOD's version (cholmod_version), or None where the library does not say."""
    try:
        function = library.cholmod_version
    except AttributeError:
        return None
    version = (ctypes.c_int * 3)()
    function.argtypes = [ctypes.POINTER(ctypes.c_int)]
    function(version)
    return version[0], version[1], version[2]


def _bundled_cholmod_files() -> list[str]:
    """CHOLMOD shared libraries shipped inside cvxopt's wheel (auditwheel puts them in
    cvxopt.libs beside the package, delvewheel and delocate inside it)."""
    import glob
    import os

    spec = importlib.util.find_spec("cvxopt")
    if spec is None or not spec.submodule_search_locations:
        return []
    package = list(spec.submodule_search_locations)[0]
    patterns = [os.path.join(os.path.dirname(package), "cvxopt.libs", "*cholmod*"),
                os.path.join(package, ".libs", "*cholmod*"), os.path.join(package, ".dylibs", "*cholmod*")]
    return sorted(path for pattern in patterns for path in glob.glob(pattern))


_LIBRARY_STATE: dict[str, CholmodLibrary | None] = {}


_LIBRARY_LOCK = threading.Lock()


def cholmod_library() -> CholmodLibrary | None:
    """The bundled CHOLMOD, loaded once (by one thread: a solver analyses its pattern while
    coarser levels factorise); None where cvxopt has none or its layout is unknown."""
    with _LIBRARY_LOCK:
        return _load_cholmod_library()


def _load_cholmod_library() -> CholmodLibrary | None:
    if "library" not in _LIBRARY_STATE:
        _LIBRARY_STATE["library"] = None
        try:
            import cvxopt.cholmod  # noqa: F401  (loads the bundled library and its dependencies)

            for path in _bundled_cholmod_files():
                library = ctypes.CDLL(path)
                version = library_version(library)
                if ctypes.sizeof(ctypes.c_size_t) != 8 or (version is not None
                                                          and version[0] not in KNOWN_MAJOR_VERSIONS):
                    continue
                candidate = CholmodLibrary(library)
                common = candidate.start()
                if common is not None:
                    candidate.library.cholmod_finish(common)
                    _LIBRARY_STATE["library"] = candidate
                    break
        except (ImportError, OSError, AttributeError):
            pass
    return _LIBRARY_STATE["library"]
