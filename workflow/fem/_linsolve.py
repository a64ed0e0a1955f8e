"""Sparse direct solves of the Newton systems: PARDISO with a reused analysis, SuperLU as the fallback.

Two costs of a Newton iteration that do not depend on the new values:

* ``reduce_matrix``: the reduced tangent T^T K T of a 0/1 constraint matrix T
  (fixed dofs left out, tied dofs summed into one unknown) is a gather of K's
  entries with renumbered rows and columns, summed where ties meet (about
  half the time of the two sparse products).
* ``DirectSolver``: MKL PARDISO's phase 11 (reordering, symbolic
  factorisation, scaling and matching; about 40 % of a fresh solve here) runs
  only when a matrix brings entries outside the analysed pattern.  The body's
  pattern is fixed, the contact entries come and go, so the analysed pattern
  is the union of the patterns seen so far (with a halo round the entries each
  new analysis adds) and each matrix is padded with explicit zeros onto it.
  Scaling and matching then come from older values: a solve whose residual
  ||A x - b|| exceeds ``check_rtol`` ||b|| is repeated with a fresh analysis
  of the matrix itself.

PARDISO runs through pypardiso's ``PyPardisoSolver`` (0.4.x; its
``_call_pardiso`` is the only way there to run single phases).  Without
pypardiso (no MKL wheel for the platform), SciPy's SuperLU solves each system
from scratch.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # MKL PARDISO when it installs (x86_64 wheels); SuperLU otherwise
    import pypardiso as _pypardiso
except ImportError:  # pragma: no cover - depends on the platform
    _pypardiso = None

__all__ = ["DirectSolver", "reduce_matrix", "default_solver"]


def _keys(A: sp.csr_matrix) -> np.ndarray:
    """Row-major keys row * n + col of the stored entries (sorted for a canonical CSR matrix)."""
    rows = np.repeat(np.arange(A.shape[0], dtype=np.int64), np.diff(A.indptr))
    return rows * A.shape[1] + A.indices


class DirectSolver:
    """Solve A x = b for a sequence of matrices whose patterns mostly repeat.

    Parameters
    ----------
    reuse_analysis : bool
        Keep PARDISO's analysis while the matrices fit in the analysed
        pattern (False: analyse every matrix, as ``pypardiso.spsolve`` does).
    check_rtol : float
        Largest accepted relative residual of a solve with a reused analysis.
    max_growth : float
        Start the union afresh from the current pattern when it would exceed
        this multiple of the current matrix's entries (bounds the padding).
    halo : bool
        When a matrix brings new entries (i, j), analyse also (i, k) and (k, i)
        for the k coupled to j: a contact slave that couples to a new master
        facet is likely to slide onto that facet's neighbours next, and then
        fits without another analysis.
    """

    def __init__(
        self, reuse_analysis: bool = True, check_rtol: float = 1e-8, max_growth: float = 1.5, halo: bool = True
    ):
        self.reuse_analysis = reuse_analysis
        self.halo = halo
        self.check_rtol = check_rtol
        self.max_growth = max_growth
        self._pardiso = _pypardiso.PyPardisoSolver(mtype=11) if _pypardiso is not None else None
        self._pattern = None  # analysed pattern: sorted keys and its CSR (indptr, indices)
        self._last = None  # (indptr, indices, positions in the analysed pattern) of the last matrix
        self.stats = {"analyses": 0, "factorisations": 0, "reanalysed_for_accuracy": 0}

    def reset(self) -> None:
        """Forget the analysed pattern: the next solve analyses its own matrix (as the first one does)."""
        self._pattern = self._last = None

    @property
    def backend(self) -> str:
        return "pardiso" if self._pardiso is not None else "superlu"

    def solve(self, A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
        """x (n,) for a square sparse A (CSR preferred) and b (n,)."""
        if self._pardiso is None:
            return spla.spsolve(sp.csc_matrix(A), b)
        A = sp.csr_matrix(A)
        A.sum_duplicates()  # canonical: sorted indices, no duplicates
        pos = self._positions(A) if self.reuse_analysis else None
        try:
            if pos is None:
                pos = self._analyse(A, union=self.reuse_analysis)
                return self._factor_solve(A, pos, b)
            x = self._factor_solve(A, pos, b)
            if self._accurate(A, x, b):
                return x
            self.stats["reanalysed_for_accuracy"] += 1
            return self._factor_solve(A, self._analyse(A, union=False), b)
        except Exception:
            self._pattern = self._last = None  # start the next solve from a fresh analysis
            raise

    def _positions(self, A: sp.csr_matrix):
        """Positions of A's entries in the analysed pattern, or None if A does not fit in it."""
        if self._pattern is None or self._pattern[1].size != A.shape[0] + 1:
            return None
        last = self._last
        if last is not None and np.array_equal(A.indptr, last[0]) and np.array_equal(A.indices, last[1]):
            return last[2]
        pos, found = _find_sorted(_keys(A), self._pattern[0])
        if not found.all():
            return None
        self._last = (A.indptr.copy(), A.indices.copy(), pos)
        return pos

    def _analyse(self, A: sp.csr_matrix, union: bool) -> np.ndarray:
        """PARDISO phase 11 on A's pattern (joined with the previous one if ``union``); A's positions in it."""
        n = A.shape[0]
        akeys = _keys(A)
        keys = akeys
        if union and self._pattern is not None and self._pattern[1].size == n + 1:
            old = self._pattern[0]
            extra = akeys[~_in_sorted(akeys, old)]
            if self.halo:
                extra = np.concatenate([extra, _halo(A, extra)])
            # both sorted: merge the few new keys into the old ones (np.unique of the whole union sorted
            # ~10^6 keys at every analysis, a fifth of a 3D ray's time)
            extra = np.unique(extra)
            extra = extra[~_in_sorted(extra, old)]
            joined = np.insert(old, np.searchsorted(old, extra), extra)
            if joined.size <= self.max_growth * akeys.size:
                keys = joined
        indptr = np.searchsorted(keys // n, np.arange(n + 1)).astype(np.int32)
        indices = (keys % n).astype(np.int32)
        self._pattern = (keys, indptr, indices)
        pos = np.searchsorted(keys, akeys)
        self._last = (A.indptr.copy(), A.indices.copy(), pos)
        M = self._padded(A, pos)
        self._pardiso._check_A(M)  # CSR (not transposed) mode; raises on an empty row (PARDISO would crash)
        self._pardiso.set_phase(11)
        self._pardiso._call_pardiso(M, np.zeros((n, 1)))
        self.stats["analyses"] += 1
        return pos

    def _padded(self, A: sp.csr_matrix, pos: np.ndarray) -> sp.csr_matrix:
        """A on the analysed pattern (explicit zeros where A has no entry)."""
        keys, indptr, indices = self._pattern
        data = np.zeros(keys.size)
        data[pos] = A.data
        M = sp.csr_matrix((data, indices, indptr), shape=A.shape)
        M.has_sorted_indices = True
        return M

    def _factor_solve(self, A: sp.csr_matrix, pos: np.ndarray, b: np.ndarray) -> np.ndarray:
        """PARDISO phases 22 + 33 with the current analysis."""
        M = self._padded(A, pos)
        self._pardiso.set_phase(23)
        x = self._pardiso._call_pardiso(M, np.asfortranarray(b, dtype=float).reshape(-1, 1))
        self.stats["factorisations"] += 1
        return x.ravel()

    def _accurate(self, A: sp.csr_matrix, x: np.ndarray, b: np.ndarray) -> bool:
        res = np.linalg.norm(A @ x - b)
        return bool(np.isfinite(res) and res <= self.check_rtol * np.linalg.norm(b))


def _find_sorted(a: np.ndarray, sorted_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the entries of ``a`` in the sorted array ``sorted_keys`` and the mask of those found there."""
    if not sorted_keys.size:
        return np.zeros(a.shape, np.int64), np.zeros(a.shape, bool)
    pos = np.minimum(np.searchsorted(sorted_keys, a), sorted_keys.size - 1)
    return pos, sorted_keys[pos] == a


def _in_sorted(a: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    """Mask of the entries of ``a`` found in the sorted array ``sorted_keys``."""
    return _find_sorted(a, sorted_keys)[1]


def _halo(A: sp.csr_matrix, keys: np.ndarray) -> np.ndarray:
    """Keys of (i, k) and (k, i) for every entry (i, j) in ``keys`` and every k with an entry (j, k) in A."""
    if not keys.size:
        return keys
    n = A.shape[0]
    i, j = keys // n, keys % n
    deg = np.diff(A.indptr)[j]
    start = np.repeat(A.indptr[j] - np.cumsum(deg) + deg, deg)
    k = A.indices[start + np.arange(deg.sum())].astype(np.int64)
    ii = np.repeat(i, deg)
    return np.concatenate([ii * n + k, k * n + ii])


def reduce_matrix(K: sp.spmatrix, T: sp.csr_matrix) -> sp.csr_matrix:
    """T^T K T (canonical CSR) for a CSR constraint matrix T (n, m) with at most one entry, 1, per row.

    Other T fall back to the sparse products.
    """
    nper = np.diff(T.indptr)
    if nper.max(initial=0) > 1 or np.any(T.data != 1.0):
        return (T.T @ K @ T).tocsr()
    col = np.full(T.shape[0], -1, dtype=np.int64)
    col[nper == 1] = T.indices
    K = sp.csr_matrix(K)
    rows = np.repeat(col, np.diff(K.indptr))
    cols = col[K.indices]
    keep = (rows >= 0) & (cols >= 0)
    m = T.shape[1]
    Kr = sp.csr_matrix((K.data[keep], (rows[keep], cols[keep])), shape=(m, m))
    Kr.sum_duplicates()
    return Kr


#: The solver ``linear_solve`` uses (one per process, like pypardiso's own).
default_solver = DirectSolver()
