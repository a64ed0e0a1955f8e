"""Vectorised assembly of the hyperelastic solid on Q1 elements (mean dilatation).

The silicone uses the Q1/P0 mixed formulation with the element-wise constant
pressure and dilatation condensed out (mean dilatation; the displacement-only
form of the three-field Hu-Washizu principle, as Marc's Herrmann elements with
reduced integration and FElupe's ``SolidBodyNearlyIncompressible``):

    Pi(u) = sum_e [ int_e psi_iso(F) dV + V_e U(Jb_e) ],
    Jb_e  = (1/V_e) int_e J dV,   U(Jb) = K/2 (Jb - 1)^2,

so the residual is  int P_iso : dF + p_e int cof F : dF  with p_e = U'(Jb_e),
and the exact tangent adds  p_e int dF : d2J : DF  and the rank-one element
term  U''/V_e (int cof F : dF)(int cof F : DF).  The paper layer (and any
further material id listed in ``mat["neo_hooke"]``) is a plain displacement
element with a compressible neo-Hooke law (Poisson's ratio 0.2 does not lock).

The shape-function gradients and quadrature weights come from a scikit-fem
``Basis`` (2x2 / 2x2x2 Gauss).  Per quadrature point the gradient operator
B (d*d, nbf*d) maps local displacements to F - I, so that per element

    f_e = sum_q dx_q B_q^T P_q,    K_e = sum_q dx_q B_q^T A_q B_q

are batched matrix products (BLAS) over all elements of a chunk; the CSR
sparsity pattern is built once and reused (see notes/fem-assembly-speed.md).
Lengths in mm, stresses in MPa, forces in N (2D: N per mm of width).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import skfem

from ._material import det_inv, mooney_rivlin_isochoric, neo_hooke_compressible

__all__ = ["SolidAssembler", "Pattern", "vector_dofs"]

SILICONE, PAPER = 0, 1


def vector_dofs(nodes: np.ndarray, dim: int) -> np.ndarray:
    """Node-interleaved dofs ``dim*node + component`` of ``nodes`` (..., nn) -> (..., nn*dim)."""
    nodes = np.asarray(nodes)
    return (dim * nodes[..., :, None] + np.arange(dim)).reshape(nodes.shape[:-1] + (-1,))


class Pattern:
    """A fixed sparsity pattern: COO positions mapped once onto CSR storage."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, n: int):
        key = rows.astype(np.int64) * n + cols.astype(np.int64)
        ukey, self.inv = np.unique(key, return_inverse=True)
        self.n = n
        self.indices = (ukey % n).astype(np.int32)
        urows = ukey // n
        self.indptr = np.searchsorted(urows, np.arange(n + 1)).astype(np.int32)

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        data = np.bincount(self.inv, weights=values, minlength=self.indices.size)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


def gradient_operator(G: np.ndarray) -> np.ndarray:
    """B (e, q, d*d, nbf*d) with (F - I)_ij = B[(i, j), (a, k)] u_ak from gradients G (nbf, d, e, q).

    B[(i, j), (a, k)] = delta_ik dN_a/dX_j: two thirds zeros in 3D, but it turns
    every local contraction into one dense batched matrix product.
    """
    nbf, d, ne, nq = G.shape
    B = np.zeros((ne, nq, d, d, nbf, d))
    Gq = G.transpose(2, 3, 1, 0)  # (e, q, j, a)
    for i in range(d):
        B[:, :, i, :, :, i] = Gq
    return B.reshape(ne, nq, d * d, nbf * d)


def _flat(T: np.ndarray) -> np.ndarray:
    """(d, d, e, q) -> (e, q, d*d) row-major in (i, j)."""
    d = T.shape[0]
    return np.moveaxis(T.reshape(d * d, *T.shape[2:]), 0, -1)


def _swap_ik(M: np.ndarray, nbf: int, d: int) -> np.ndarray:
    """M[e, (a, i), (b, k)] -> M[e, (a, k), (b, i)]."""
    ne = M.shape[0]
    return M.reshape(ne, nbf, d, nbf, d).transpose(0, 1, 4, 3, 2).reshape(M.shape)


class SolidAssembler:
    """Internal forces and tangent of a multi-material body (silicone + paper [+ neo-Hooke parts]).

    Parameters
    ----------
    mesh : skfem.MeshQuad or skfem.MeshHex
    material : ndarray of int (ncells,)
        0 = silicone (mixed, Mooney-Rivlin), 1 = paper (neo-Hooke), any other
        id = neo-Hooke with ``mat["neo_hooke"][id] = (mu, lambda)`` (MPa).
    mat : dict
        ``c10, c01, c20`` (MPa), ``bulk`` (K, MPa), ``paper_mu``, ``paper_lambda`` (MPa).
    mixed : bool
        False gives plain Q1 displacement elements (full integration of the
        volumetric energy), which lock; kept for the locking test.
    chunk_points : int
        Quadrature points per vectorised batch (keeps the 4th-order tangents
        in cache).
    threads : int, optional
        Threads over the chunks; default ``OMP_NUM_THREADS`` (1 if unset), so
        that jobs which share the cores by that convention stay within it.
    """

    def __init__(self, mesh: skfem.Mesh, material: np.ndarray, mat: dict, mixed: bool = True, intorder: int = 2,
                 chunk_points: int = 2048, threads: int | None = None):
        self.dim = mesh.p.shape[0]
        elem = skfem.ElementQuad1() if self.dim == 2 else skfem.ElementHex1()
        basis = skfem.Basis(mesh, elem, intorder=intorder)
        nbf = basis.Nbfun
        self.nbf = nbf
        # shape-function gradients (nbf, d, nel, nq) and weights (nel, nq)
        self.G = np.stack([np.asarray(basis.basis[a][0].grad) for a in range(nbf)])
        self.dx = np.asarray(basis.dx)
        self.t = np.asarray(basis.element_dofs).T  # (nel, nbf) node indices
        self.edofs = vector_dofs(self.t, self.dim)
        self.ndofs = self.dim * mesh.p.shape[1]
        self.mat = dict(mat)
        self.mixed = mixed
        self.threads = int(threads if threads is not None else os.environ.get("OMP_NUM_THREADS", 1))
        self.volume = self.dx.sum(axis=1)
        material = np.asarray(material)
        missing = set(np.unique(material).tolist()) - {SILICONE, PAPER} - set(self.mat.get("neo_hooke", {}))
        if missing:
            raise ValueError(f"no constants for material ids {sorted(missing)}")
        nq = self.dx.shape[1]
        step = max(1, chunk_points // nq)
        self.chunks = []
        for gid in np.unique(material):
            cells = np.flatnonzero(material == gid)
            for i in range(0, cells.size, step):
                self.chunks.append((int(gid), cells[i:i + step]))
        nl = self.edofs.shape[1]
        self.rows = np.repeat(self.edofs, nl, axis=1).ravel()
        self.cols = np.tile(self.edofs, (1, nl)).ravel()

    def deformation_gradient(self, u: np.ndarray, cells=slice(None)) -> np.ndarray:
        """F at the quadrature points, (d, d, nel, nq) C-contiguous, for nodal displacement u (ndofs,).

        C order matters: the laws' many array operations run 2-8x slower on
        the strided layout einsum would return.
        """
        ue = u[self.edofs[cells]].reshape(-1, self.nbf, self.dim)
        G = self.G[:, :, cells]
        return np.eye(self.dim)[:, :, None, None] + np.einsum("eai,ajeq->ijeq", ue, G, order="C")

    def _law(self, gid: int, F: np.ndarray, tangent: bool):
        """Energy density, P (d,d,e,q) and A (d,d,d,d,e,q) of material ``gid`` without the mixed volumetric part."""
        m = self.mat
        if gid == SILICONE:
            return mooney_rivlin_isochoric(F, m["c10"], m["c01"], m["c20"], tangent)
        mu, lmbda = (m["paper_mu"], m["paper_lambda"]) if gid == PAPER else m["neo_hooke"][gid]
        return neo_hooke_compressible(F, mu, lmbda, tangent)

    def _volumetric(self, J: np.ndarray, dx: np.ndarray, V: np.ndarray):
        """Pressure p = U'(J) at the points (mean dilatation: per element, (e, 1)), MPa, and U'' (MPa)."""
        K = self.mat["bulk"]
        if self.mixed:
            return K * (np.einsum("eq,eq->e", J, dx) / V - 1.0)[:, None], K
        return K * (J - 1.0), K

    def assemble(self, u: np.ndarray, tangent: bool = True):
        """Return ``(f_int (ndofs,), K values (in COO order of rows/cols) or None, min J)``.

        The chunks run on ``threads`` threads (numpy releases the GIL in its
        array loops and BLAS calls); with an inverted element (J <= 0) the
        forces and values are incomplete and only ``min J`` counts.
        """
        nl = self.nbf * self.dim
        f = np.zeros(self.ndofs)
        kvals = np.zeros((self.t.shape[0], nl, nl)) if tangent else None
        jmin = np.inf

        def run(chunk):
            return chunk[1], self._chunk(*chunk, u, tangent)

        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as pool:
                results = list(pool.map(run, self.chunks))
        else:
            results = map(run, self.chunks)
        for cells, (fe, Ke, jc) in results:
            jmin = min(jmin, jc)
            if fe is None:
                continue
            f += np.bincount(self.edofs[cells].ravel(), weights=fe.ravel(), minlength=self.ndofs)
            if tangent:
                kvals[cells] = Ke
        return f, (kvals.ravel() if tangent else None), jmin

    def _chunk(self, gid: int, cells: np.ndarray, u: np.ndarray, tangent: bool):
        """Local forces (e, nl), local tangents (e, nl, nl) or None, and min J of one chunk of cells."""
        d, nbf = self.dim, self.nbf
        nl = nbf * d
        F = self.deformation_gradient(u, cells)
        J, Finv = det_inv(F)
        jmin = float(J.min())
        if not jmin > 0:
            return None, None, jmin
        G, dx = self.G[:, :, cells], self.dx[cells]
        _, P, A = self._law(gid, F, tangent)
        if gid == SILICONE:
            p, dp = self._volumetric(J, dx, self.volume[cells])
            cof = J * np.swapaxes(Finv, 0, 1)
            P = P + p * cof
        fe = np.einsum("ijeq,ajeq,eq->eai", P, G, dx).reshape(len(cells), nl)
        if not tangent:
            return fe, None, jmin
        ne, nq = dx.shape
        B = gradient_operator(G)
        # (e, q, d*d, d*d) in C order, so that the batched products run on contiguous matrices
        Aq = np.multiply(np.moveaxis(A.reshape(d * d, d * d, ne, nq), (0, 1), (2, 3)), dx[:, :, None, None], order="C")
        Bt = B.reshape(ne, nq * d * d, nl).transpose(0, 2, 1)
        Ke = Bt @ (Aq @ B).reshape(ne, nq * d * d, nl)
        if gid == SILICONE:
            Ke += self._volumetric_tangent(B, cof, J, p, dp, dx, cells)
        return fe, Ke, jmin

    def _volumetric_tangent(self, B, cof, J, p, dp, dx, cells):
        """Local tangent (e, nl, nl) of the volumetric part of the silicone.

        With c = B^T cof (the gradient of J at a point), p d2J contracts to
        (p/J) (c_ai c_bk - c_ak c_bi), and U'' gives the rank-one term
        U''/V_e (sum_q dx c)(sum_q dx c)^T (mean dilatation) or sum_q dx U'' c c^T.
        """
        ne, nq = dx.shape
        d, nbf = self.dim, self.nbf
        c = (B.transpose(0, 1, 3, 2) @ _flat(cof)[..., None])[..., 0]  # (e, q, nl)
        w = (p / J) * dx
        if not self.mixed:
            w2 = dp * dx
        M = (c.transpose(0, 2, 1) * w[:, None, :]) @ c
        Ke = M - _swap_ik(M, nbf, d)
        if self.mixed:
            cb = np.einsum("eqa,eq->ea", c, dx)
            Ke += (dp / self.volume[cells])[:, None, None] * cb[:, :, None] * cb[:, None, :]
        else:
            Ke += (c.transpose(0, 2, 1) * w2[:, None, :]) @ c
        return Ke

    def energy(self, u: np.ndarray) -> float:
        """Total strain energy (N mm; per mm of width in 2D), for checks."""
        E = 0.0
        for gid, cells in self.chunks:
            F = self.deformation_gradient(u, cells)
            J, _ = det_inv(F)
            dx = self.dx[cells]
            psi, _, _ = self._law(gid, F, False)
            E += float(np.sum(psi * dx))
            if gid != SILICONE:
                continue
            K = self.mat["bulk"]
            if self.mixed:
                V = self.volume[cells]
                Jb = np.einsum("eq,eq->e", J, dx) / V
                E += float(np.sum(V * 0.5 * K * (Jb - 1.0) ** 2))
            else:
                E += float(np.sum(0.5 * K * (J - 1.0) ** 2 * dx))
        return E
