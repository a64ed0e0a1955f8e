"""Vectorised assembly of the hyperelastic solid on Q1 elements (mean dilatation).

The silicone uses the Q1/P0 mixed formulation with the element-wise constant
pressure and dilatation condensed out (mean dilatation; the displacement-only
form of the three-field Hu-Washizu principle, as Marc's Herrmann elements with
reduced integration and FElupe's ``SolidBodyNearlyIncompressible``):

    Pi(u) = sum_e [ int_e psi_iso(F) dV + V_e U(Jb_e) ],
    Jb_e  = (1/V_e) int_e J dV,   U(Jb) = K/2 (Jb - 1)^2,

so the residual is  int P_iso : dF + p_e int cof F : dF  with p_e = U'(Jb_e),
and the exact tangent adds  p_e int dF : d2J : DF  and the rank-one element
term  U''/V_e (int cof F : dF)(int cof F : DF).  The paper layer is a plain
displacement element (its Poisson's ratio 0.2 does not lock).

The shape-function gradients and quadrature weights come from a scikit-fem
``Basis`` (2x2 / 2x2x2 Gauss); the local matrices of all elements are
computed at once with numpy, and the CSR sparsity pattern is built once and
reused (see notes/fem-assembly-speed.md).  Lengths in mm, stresses in MPa,
forces in N (2D: N per mm of width).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import skfem

from ._material import det_inv, mooney_rivlin_isochoric, neo_hooke_compressible

__all__ = ["SolidAssembler", "Pattern", "vector_dofs"]


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


class SolidAssembler:
    """Internal forces and tangent of a two-material body (silicone + paper).

    Parameters
    ----------
    mesh : skfem.MeshQuad or skfem.MeshHex
    material : ndarray of int (ncells,)
        0 = silicone (mixed, Mooney-Rivlin), 1 = paper (neo-Hooke); further
        ids are compressible neo-Hooke solids with the constants of
        ``mat["neo_hooke"]`` (e.g. the finger's flesh and bone).
    mat : dict
        ``c10, c01, c20`` (MPa), ``bulk`` (K, MPa), ``paper_mu``, ``paper_lambda`` (MPa);
        optional ``neo_hooke``: {material id: (mu, lambda) in MPa} for ids >= 1.
    mixed : bool
        False gives plain Q1 displacement elements (full integration of the
        volumetric energy), which lock; kept for the locking test.
    chunk_points : int
        Quadrature points per vectorised batch (keeps the 4th-order tangents
        in cache: about 4x faster than one batch for the whole mesh).
    """

    def __init__(self, mesh: skfem.Mesh, material: np.ndarray, mat: dict, mixed: bool = True, intorder: int = 2,
                 chunk_points: int = 2048):
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
        self.volume = self.dx.sum(axis=1)
        # id -> (mu, lambda) of every compressible neo-Hooke material (paper = 1)
        self.neo_hooke = {1: (mat.get("paper_mu", 0.0), mat.get("paper_lambda", 0.0))}
        self.neo_hooke.update({int(k): tuple(v) for k, v in dict(mat.get("neo_hooke", {})).items()})
        nq = self.dx.shape[1]
        step = max(1, chunk_points // nq)
        self.chunks = []
        for gid in [0] + sorted(self.neo_hooke):
            cells = np.flatnonzero(material == gid)
            for i in range(0, cells.size, step):
                self.chunks.append((gid, cells[i:i + step]))
        nl = self.edofs.shape[1]
        self.rows = np.repeat(self.edofs, nl, axis=1).ravel()
        self.cols = np.tile(self.edofs, (1, nl)).ravel()

    def deformation_gradient(self, u: np.ndarray, cells=slice(None)) -> np.ndarray:
        """F at the quadrature points, (d, d, nel, nq), for nodal displacement u (ndofs,)."""
        ue = u[self.edofs[cells]].reshape(-1, self.nbf, self.dim)
        G = self.G[:, :, cells]
        return np.eye(self.dim)[:, :, None, None] + np.einsum("eai,ajeq->ijeq", ue, G)

    def _stress(self, gid, F, J, dx, V, tangent):
        """P (d,d,e,q) and A (d,d,d,d,e,q) incl. the condensed pressure; cof and p for the rank-one term."""
        m = self.mat
        if gid != 0:
            _, P, A = neo_hooke_compressible(F, *self.neo_hooke[gid], tangent)
            return P, A, None, None
        _, P, A = mooney_rivlin_isochoric(F, m["c10"], m["c01"], m["c20"], tangent)
        _, Finv = det_inv(F)
        FiT = np.swapaxes(Finv, 0, 1)
        cof = J * FiT
        if self.mixed:
            p = m["bulk"] * (np.einsum("eq,eq->e", J, dx) / V - 1.0)[:, None]  # (e, 1)
        else:
            p = m["bulk"] * (J - 1.0)
        P = P + p * cof
        if tangent:
            # p d2J/dFdF, d2J_ijkl = J (Finv_ji Finv_lk - Finv_jk Finv_li)
            A = A + (p * J) * (FiT[:, :, None, None] * FiT[None, None] - FiT[:, None, None, :] * Finv[None, :, :, None])
            if not self.mixed:
                A = A + m["bulk"] * cof[:, :, None, None] * cof[None, None]
        return P, A, cof, p

    def assemble(self, u: np.ndarray, tangent: bool = True):
        """Return ``(f_int (ndofs,), K values (in COO order of rows/cols) or None, min J)``."""
        d, nbf = self.dim, self.nbf
        nl = nbf * d
        f = np.zeros(self.ndofs)
        kvals = np.zeros((self.t.shape[0], nl, nl)) if tangent else None
        jmin = np.inf
        for gid, cells in self.chunks:
            F = self.deformation_gradient(u, cells)
            J, _ = det_inv(F)
            jmin = min(jmin, float(J.min()))
            if not np.all(J > 0):
                return f, kvals, jmin
            G, dx, V = self.G[:, :, cells], self.dx[cells], self.volume[cells]
            P, A, cof, p = self._stress(gid, F, J, dx, V, tangent)
            fe = np.einsum("ijeq,ajeq,eq->eai", P, G, dx).reshape(len(cells), -1)
            f += np.bincount(self.edofs[cells].ravel(), weights=fe.ravel(), minlength=self.ndofs)
            if tangent:
                GA = np.einsum("ajeq,ijkleq->aikleq", G, A * dx)
                Ke = np.einsum("aikleq,bleq->eaibk", GA, G).reshape(len(cells), nl, nl)
                if gid == 0 and self.mixed:
                    c = np.einsum("ijeq,ajeq,eq->eai", cof, G, dx).reshape(len(cells), -1)
                    Ke += (self.mat["bulk"] / V)[:, None, None] * c[:, :, None] * c[:, None, :]
                kvals[cells] = Ke
        return f, (kvals.ravel() if tangent else None), jmin

    def energy(self, u: np.ndarray) -> float:
        """Total strain energy (N mm; per mm of width in 2D), for checks."""
        m = self.mat
        E = 0.0
        for gid, cells in self.chunks:
            F = self.deformation_gradient(u, cells)
            J, _ = det_inv(F)
            dx = self.dx[cells]
            if gid != 0:
                psi, _, _ = neo_hooke_compressible(F, *self.neo_hooke[gid], False)
                E += float(np.sum(psi * dx))
                continue
            psi, _, _ = mooney_rivlin_isochoric(F, m["c10"], m["c01"], m["c20"], False)
            E += float(np.sum(psi * dx))
            if self.mixed:
                V = self.volume[cells]
                Jb = np.einsum("eq,eq->e", J, dx) / V
                E += float(np.sum(V * 0.5 * m["bulk"] * (Jb - 1.0) ** 2))
            else:
                E += float(np.sum(0.5 * m["bulk"] * (J - 1.0) ** 2 * dx))
        return E
