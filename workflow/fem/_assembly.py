"""Vectorised assembly of the hyperelastic solid on Q1 elements (mean dilatation, enhanced strains).

The silicone uses the Q1/P0 mixed formulation with the element-wise constant
pressure and dilatation condensed out (mean dilatation; the displacement-only
form of the three-field Hu-Washizu principle, as Marc's Herrmann elements and
FElupe's ``SolidBodyNearlyIncompressible``):

    Pi(u) = sum_e [ int_e psi_iso(F) dV + V_e U(Jb_e) ],
    Jb_e  = (1/V_e) int_e J dV,   U(Jb) = K/2 (Jb - 1)^2,

so the residual is  int P_iso : dF + p_e int cof F : dF  with p_e = U'(Jb_e),
and the exact tangent adds  p_e int dF : d2J : DF  and the rank-one element
term  U''/V_e (int cof F : dF)(int cof F : DF).

Newton's path (``lagged_pressure``, default on): the residual always takes
p_e from the actual element volume, but the tangent's initial-stress term
takes it from the dilatation linearised at the previous iterate,
Jb_lin = (v + h . du) / V (h = int cof F : dF/du, v = int J dV), carried per
element in the solver's state.  This is the Newton step of the three-field
form with the cell's dilatation and pressure as unknowns of their own
(FElupe's ``SolidBodyNearlyIncompressible`` updates them the same way): after
a large correction the actual volume of a ballooning thin wall can sit far
off the linearisation, and K (Jb - 1), with K = 1000 mu0, then puts a large
spurious initial stress into the next tangent, which sends the next
correction into inverted elements.  The converged solution is the same.

The paper layer (and any
further material id listed in ``mat["neo_hooke"]``) is a displacement element
with a compressible neo-Hooke law (Poisson's ratio 0.2 does not lock).

Enhanced strains (``enhanced``): fully integrated Q1 elements shear-lock in
bending (a bilinear field cannot bend without a parasitic shear strain, whose
energy grows with the element's aspect ratio: the 0.2 mm paper layer meshed
one element thick at 1 mm is 5:1).  Material ids listed in ``enhanced`` get
the incompatible modes of Wilson and Taylor in the finite-strain form of Simo
and Armero (1992, IJNME 33:1413), Q1/E4 in 2D and H1/E9 in 3D:

    F = I + Grad u + (j0 / j(xi)) A diag-free(xi_hat) J0^-1,
    i.e. F_ij += sum_k alpha_ik (j0/j) xi_hat_k (J0^-1)_kj,

with xi_hat in [-1, 1]^d the reference coordinates, J0 and j0 the Jacobian and
its determinant at the element centre (so that int F_enh dV = 0 and the patch
test holds).  The d*d parameters alpha per element are internal unknowns of
the solver's state, appended after the nodal displacements: the solid's
residual is [f_u; r_alpha], and each tangent assembly condenses them out
element by element,

    K_c = K_uu - K_ua K_aa^-1 K_au,    f_c = f_u - K_ua K_aa^-1 r_a,

so the linear systems keep the nodal size; after the solve ``recover`` gives
d alpha = -K_aa^-1 (r_a + K_au du) (the textbook static condensation of
Simo-Armero; one element evaluation per Newton iteration, and the state, not
a cache, carries alpha, so a cut-back restores it).  The enhanced modes act
as extra "nodes" of the element (the same gradient operator B, the same laws
and volumetric terms), so mean dilatation and enhancement combine without
extra code.

The shape-function gradients and quadrature weights come from a scikit-fem
``Basis`` (2x2 / 2x2x2 Gauss).  Per quadrature point the gradient operator
B (d*d, nb*d) maps local values to F - I, so that per element

    f_e = sum_q dx_q B_q^T P_q,    K_e = sum_q dx_q B_q^T A_q B_q

are batched matrix products (BLAS) over all elements of a chunk; the CSR
sparsity pattern is built once and reused.
Lengths in mm, stresses in MPa, forces in N (2D: N per mm of width).

Over 400 lines: the mixed silicone, the enhanced-strain paper layer and their static condensation share one vectorised quadrature loop and its sparsity pattern.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import skfem

from ._material import det_inv, mooney_rivlin_isochoric, neo_hooke_compressible

__all__ = ["SolidAssembler", "Pattern", "vector_dofs", "gradient_operator", "enhanced_gradients"]

SILICONE, PAPER = 0, 1
#: Default of ``SolidAssembler(lagged_pressure=...)``; a study flips it to compare the two Newton paths
#: (``benchmarks/bench_newton.py --compare-lag``), or sets WORKFLOW_FEM_LAGGED_PRESSURE=0 for the processes it spawns.
LAGGED_PRESSURE = os.environ.get("WORKFLOW_FEM_LAGGED_PRESSURE", "1") != "0"


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
    """B (e, q, d*d, nb*d) with (F - I)_ij = B[(i, j), (a, k)] q_ak from gradients G (nb, d, e, q).

    B[(i, j), (a, k)] = delta_ik dN_a/dX_j: two thirds zeros in 3D, but it turns
    every local contraction into one dense batched matrix product.
    """
    nb, d, ne, nq = G.shape
    B = np.zeros((ne, nq, d, d, nb, d))
    Gq = G.transpose(2, 3, 1, 0)  # (e, q, j, a)
    for i in range(d):
        B[:, :, i, :, :, i] = Gq
    return B.reshape(ne, nq, d * d, nb * d)


def enhanced_gradients(mesh: skfem.Mesh, X: np.ndarray) -> np.ndarray:
    """Gradients (d, d, e, q) of the d incompatible modes at reference points X (d, q) in [0, 1]^d.

    Mode k has the natural gradient xi_hat_k e_k (xi_hat = 2 X - 1), mapped with
    the centre Jacobian and scaled by j0 / j (Simo-Armero / Taylor): its
    integral over the element vanishes for any element shape.
    """
    d = X.shape[0]
    mapping = mesh.mapping()
    centre = np.full((d, 1), 0.5)
    inv0 = mapping.invDF(centre)[..., 0]  # (d, d, e): inv0[k, j] = d xi_k / d x_j at the centre
    ratio = mapping.detDF(centre) / mapping.detDF(X)  # (e, q)
    xi = 2.0 * X - 1.0
    return inv0[:, :, :, None] * xi[:, None, None, :] * ratio[None, None]


def _flat(T: np.ndarray) -> np.ndarray:
    """(d, d, e, q) -> (e, q, d*d) row-major in (i, j)."""
    d = T.shape[0]
    return np.moveaxis(T.reshape(d * d, *T.shape[2:]), 0, -1)


def _swap_ik(M: np.ndarray, nb: int, d: int) -> np.ndarray:
    """M[e, (a, i), (b, k)] -> M[e, (a, k), (b, i)]."""
    ne = M.shape[0]
    return M.reshape(ne, nb, d, nb, d).transpose(0, 1, 4, 3, 2).reshape(M.shape)


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
    enhanced : iterable of int
        Material ids with enhanced (incompatible-mode) strains, Q1/E4 and
        H1/E9 (see the module docstring); empty = plain Q1, which shear-locks
        in bending.
    lagged_pressure : bool, optional
        Default ``LAGGED_PRESSURE`` (True).  Mixed silicone only: the pressure in the tangent's initial-stress term
        p_e int dF : d2J : DF is K (Jb_lin - 1), with Jb_lin the element
        dilatation linearised from the previous iterate, (v + h . du) / V
        (an internal state variable per element), instead of U'(Jb_e) of the
        actual volume (see the module docstring).  The residual is unchanged,
        so is the solution; only Newton's path differs.
    chunk_points : int
        Quadrature points per vectorised batch (keeps the 4th-order tangents
        in cache).
    threads : int, optional
        Threads over the chunks; default ``OMP_NUM_THREADS`` (1 if unset), so
        that jobs which share the cores by that convention stay within it.

    The solver's state is ``ndofs`` nodal displacements followed by
    ``n_internal`` enhanced parameters (mm; zero without enhanced ids).
    """

    def __init__(
        self,
        mesh: skfem.Mesh,
        material: np.ndarray,
        mat: dict,
        mixed: bool = True,
        intorder: int = 2,
        chunk_points: int = 2048,
        threads: int | None = None,
        enhanced=(),
        lagged_pressure: bool | None = None,
    ):
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
        self.enhanced = frozenset(int(i) for i in enhanced) & set(np.unique(material).tolist())
        self.G_enh = enhanced_gradients(mesh, np.asarray(basis.X)) if self.enhanced else None
        nq = self.dx.shape[1]
        step = max(1, chunk_points // nq)
        na = self.dim * self.dim
        self.chunks = []
        self.internal_dofs = {}  # chunk -> (e, d*d) positions of its enhanced parameters in the state
        n_int = 0
        for gid in np.unique(material):
            cells = np.flatnonzero(material == gid)
            for i in range(0, cells.size, step):
                part = cells[i : i + step]
                if int(gid) in self.enhanced:
                    self.internal_dofs[len(self.chunks)] = (
                        self.ndofs + n_int + np.arange(part.size * na).reshape(-1, na)
                    )
                    n_int += part.size * na
                self.chunks.append((int(gid), part))
        # silicone chunk -> (e,) positions of Jb_lin - 1 in the state; empty without the lagged pressure
        self.theta_dofs = {}
        if (LAGGED_PRESSURE if lagged_pressure is None else lagged_pressure) and mixed:
            for k, (gid, part) in enumerate(self.chunks):
                if gid == SILICONE:
                    self.theta_dofs[k] = self.ndofs + n_int + np.arange(part.size)
                    n_int += part.size
        self.n_internal = n_int
        self.nstate = self.ndofs + n_int
        self._condensed: dict[int, np.ndarray] = {}  # chunk -> K_aa^-1 [K_au | r_a] of the last tangent assembly
        self._theta: dict[int, tuple] = {}  # silicone chunk -> (h / V, v / V - 1 - state) of the last tangent assembly
        self._correction = np.zeros(self.ndofs)  # -K_ua K_aa^-1 r_a of the last tangent assembly
        nl = self.edofs.shape[1]
        self.rows = np.repeat(self.edofs, nl, axis=1).ravel()
        self.cols = np.tile(self.edofs, (1, nl)).ravel()

    def deformation_gradient(self, u: np.ndarray, cells=slice(None)) -> np.ndarray:
        """Compatible F = I + Grad u at the quadrature points, (d, d, nel, nq) C-contiguous.

        C order matters: the laws' many array operations run 2-8x slower on
        the strided layout einsum would return.  (Enhanced elements add their
        internal modes on top; see ``assemble``.)
        """
        ue = u[self.edofs[cells]]
        return self._deformation(ue, self.G[:, :, cells])

    def _deformation(self, q: np.ndarray, G: np.ndarray) -> np.ndarray:
        """F (d, d, e, q) from local values q (e, nb*d) and gradients G (nb, d, e, q)."""
        qe = q.reshape(q.shape[0], G.shape[0], self.dim)
        return np.eye(self.dim)[:, :, None, None] + np.einsum("eai,ajeq->ijeq", qe, G, order="C")

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

    def state(self, u: np.ndarray) -> np.ndarray:
        """The full state (nstate,) from nodal displacements (enhanced parameters 0, lagged dilatations the
        actual ones) or a state itself."""
        u = np.asarray(u, float)
        if u.size == self.nstate:
            return u
        if u.size != self.ndofs:
            raise ValueError(f"expected {self.ndofs} nodal values or a state of {self.nstate}, got {u.size}")
        full = np.concatenate([u, np.zeros(self.n_internal)])
        if self.theta_dofs:  # the lagged dilatations start at the actual ones
            full[np.concatenate(list(self.theta_dofs.values()))] = self.dilatation(full)
        return full

    def dilatation(self, state: np.ndarray) -> np.ndarray:
        """The actual mean dilatation Jb_e - 1 = v_e / V_e - 1 of the state's silicone elements, in the order of
        the lagged-pressure variables (empty without them)."""
        out = []
        for k, pos in self.theta_dofs.items():
            cells = self.chunks[k][1]
            G, q = self.G[:, :, cells], state[self.edofs[cells]]
            if k in self.internal_dofs:
                G = np.concatenate([G, self.G_enh[:, :, cells]], axis=0)
                q = np.concatenate([q, state[self.internal_dofs[k]]], axis=1)
            J, _ = det_inv(self._deformation(q, G))
            out.append(np.einsum("eq,eq->e", J, self.dx[cells]) / self.volume[cells] - 1.0)
        return np.concatenate(out) if out else np.zeros(0)

    def assemble(self, u: np.ndarray, tangent: bool = True):
        """Return ``(f (nstate,), K values (in COO order of rows/cols) or None, min J)``.

        ``u`` is the state (or the nodal displacements, enhanced parameters 0).
        ``f`` is the solid's full residual: nodal internal forces, then
        r_alpha of the enhanced parameters.  ``K`` is the tangent with the
        enhanced parameters condensed out (nodal pattern); a tangent assembly
        also keeps the condensation for ``condensed_correction`` and
        ``recover``.  The chunks run on ``threads`` threads (numpy releases the
        GIL in its array loops and BLAS calls); with an inverted element
        (J <= 0) the forces and values are incomplete and only ``min J`` counts.
        """
        u = self.state(u)
        nl = self.nbf * self.dim
        f = np.zeros(self.nstate)
        kvals = np.zeros((self.t.shape[0], nl, nl)) if tangent else None
        jmin = np.inf

        def run(k):
            return k, self._chunk(k, u, tangent)

        if self.threads > 1:
            with ThreadPoolExecutor(self.threads) as pool:
                results = list(pool.map(run, range(len(self.chunks))))
        else:
            results = map(run, range(len(self.chunks)))
        corr = np.zeros(self.ndofs) if tangent else None
        for k, (fe, Ke, jc, extra, theta) in results:
            jmin = min(jmin, jc)
            if fe is None:
                continue
            if theta is not None:
                self._theta[k] = theta
            cells = self.chunks[k][1]
            f += np.bincount(self.edofs[cells].ravel(), weights=fe[:, :nl].ravel(), minlength=self.nstate)
            if extra is not None:  # enhanced chunk: r_alpha, condensation
                f[self.internal_dofs[k]] = fe[:, nl:]
                if tangent:
                    X, fc = extra
                    self._condensed[k] = X
                    corr += np.bincount(self.edofs[cells].ravel(), weights=fc.ravel(), minlength=self.ndofs)
            if tangent:
                kvals[cells] = Ke
        if tangent:
            self._correction = corr
        return f, (kvals.ravel() if tangent else None), jmin

    def condensed_correction(self) -> np.ndarray:
        """-K_ua K_aa^-1 r_a (ndofs,) of the last tangent assembly: add it to the nodal residual for the condensed system."""
        return self._correction

    def recover(self, du: np.ndarray) -> np.ndarray:
        """Increment of the enhanced parameters (n_internal,) for a nodal increment du (ndofs,).

        d alpha = -K_aa^-1 (r_a + K_au du_e) with the matrices of the last
        tangent assembly.
        """
        out = np.zeros(self.n_internal)
        for k, X in self._condensed.items():
            due = du[self.edofs[self.chunks[k][1]]]
            nl = due.shape[1]
            out[self.internal_dofs[k] - self.ndofs] = -(np.einsum("eal,el->ea", X[:, :, :nl], due) + X[:, :, nl])
        for k, (hV, off) in self._theta.items():
            dq = du[self.edofs[self.chunks[k][1]]]
            if k in self.internal_dofs:
                dq = np.concatenate([dq, out[self.internal_dofs[k] - self.ndofs]], axis=1)
            out[self.theta_dofs[k] - self.ndofs] = off + np.einsum("ea,ea->e", hV, dq)
        return out

    def _chunk(self, k: int, u: np.ndarray, tangent: bool):
        """Chunk ``k``: local forces (e, nl [+ d*d]), condensed local tangents (e, nl, nl) or None, min J,
        for enhanced chunks with a tangent (K_aa^-1 [K_au | r_a], -K_ua K_aa^-1 r_a), and for lagged-pressure
        chunks with a tangent (h / V (e, nl [+ d*d]), v / V - 1 - state (e,)) (else None)."""
        gid, cells = self.chunks[k]
        ue = u[self.edofs[cells]]
        G, dx, V = self.G[:, :, cells], self.dx[cells], self.volume[cells]
        p_geo = None
        if k in self.theta_dofs:
            p_geo = self.mat["bulk"] * u[self.theta_dofs[k]][:, None]
        if gid not in self.enhanced:
            fe, Ke, je, vol = self._element(gid, G, dx, V, ue, tangent, p_geo)
            return fe, Ke, float(je.min()), None, self._theta_update(k, u, vol, V)
        nl = ue.shape[1]
        G = np.concatenate([G, self.G_enh[:, :, cells]], axis=0)
        q = np.concatenate([ue, u[self.internal_dofs[k]]], axis=1)
        fe, Ke, je, vol = self._element(gid, G, dx, V, q, tangent, p_geo)
        if fe is None or not tangent:
            return fe, None, float(je.min()), (), None
        ra = fe[:, nl:]
        X = np.linalg.solve(Ke[:, nl:, nl:], np.concatenate([Ke[:, nl:, :nl], ra[:, :, None]], axis=2))
        Kua = Ke[:, :nl, nl:]
        Kc = Ke[:, :nl, :nl] - Kua @ X[:, :, :nl]
        return fe, Kc, float(je.min()), (X, -(Kua @ X[:, :, nl:])[:, :, 0]), self._theta_update(k, u, vol, V)

    def _theta_update(self, k: int, u: np.ndarray, vol, V: np.ndarray):
        """(h / V, v / V - 1 - state) of a lagged-pressure chunk's tangent assembly, so that
        Jb_lin - 1 = v / V - 1 + (h / V) . dq after a correction dq (None elsewhere)."""
        if vol is None or k not in self.theta_dofs:
            return None
        h, v = vol
        return h / V[:, None], v / V - 1.0 - u[self.theta_dofs[k]]

    def _element(
        self, gid: int, G: np.ndarray, dx: np.ndarray, V: np.ndarray, q: np.ndarray, tangent: bool, p_geo=None
    ):
        """Forces (e, nb*d), tangents (e, nb*d, nb*d) or None, min J per element (e,) for local values q (e, nb*d),
        and for the mixed silicone with a tangent (h = int cof F : dF/dq (e, nb*d), v = int J dV (e,)), else None.

        ``p_geo`` (e, 1): the pressure of the tangent's initial-stress term (MPa; default the element's own)."""
        d = self.dim
        nb = G.shape[0]
        nl = nb * d
        F = self._deformation(q, G)
        J, Finv = det_inv(F)
        je = J.min(axis=1)
        if not je.min() > 0:
            return None, None, je, None
        _, P, A = self._law(gid, F, tangent)
        if gid == SILICONE:
            p, dp = self._volumetric(J, dx, V)
            cof = J * np.swapaxes(Finv, 0, 1)
            P = P + p * cof
        fe = np.einsum("ijeq,ajeq,eq->eai", P, G, dx).reshape(q.shape[0], nl)
        if not tangent:
            return fe, None, je, None
        ne, nq = dx.shape
        B = gradient_operator(G)
        # (e, q, d*d, d*d) in C order, so that the batched products run on contiguous matrices
        Aq = np.multiply(np.moveaxis(A.reshape(d * d, d * d, ne, nq), (0, 1), (2, 3)), dx[:, :, None, None], order="C")
        Bt = B.reshape(ne, nq * d * d, nl).transpose(0, 2, 1)
        Ke = Bt @ (Aq @ B).reshape(ne, nq * d * d, nl)
        vol = None
        if gid == SILICONE:
            dKe, vol = self._volumetric_tangent(B, cof, J, p if p_geo is None else p_geo, dp, dx, V, nb)
            Ke += dKe
        return fe, Ke, je, vol

    def _volumetric_tangent(self, B, cof, J, p, dp, dx, V, nb):
        """Local tangent (e, nl, nl) of the volumetric part of the silicone, and (h, v) of the mean dilatation
        (h = sum_q dx c, v = sum_q dx J; None without it).

        With c = B^T cof (the gradient of J at a point), p d2J contracts to
        (p/J) (c_ai c_bk - c_ak c_bi), and U'' gives the rank-one term
        U''/V_e (sum_q dx c)(sum_q dx c)^T (mean dilatation) or sum_q dx U'' c c^T.
        """
        d = self.dim
        c = (B.transpose(0, 1, 3, 2) @ _flat(cof)[..., None])[..., 0]  # (e, q, nl)
        w = (p / J) * dx
        M = (c.transpose(0, 2, 1) * w[:, None, :]) @ c
        Ke = M - _swap_ik(M, nb, d)
        if self.mixed:
            cb = np.einsum("eqa,eq->ea", c, dx)
            Ke += (dp / V)[:, None, None] * cb[:, :, None] * cb[:, None, :]
            return Ke, (cb, np.einsum("eq,eq->e", J, dx))
        Ke += (c.transpose(0, 2, 1) * (dp * dx)[:, None, :]) @ c
        return Ke, None

    def energy(self, u: np.ndarray) -> float:
        """Total strain energy (N mm; per mm of width in 2D) of the state ``u``, for checks."""
        u = self.state(u)
        E = 0.0
        K = self.mat["bulk"]
        for k, (gid, cells) in enumerate(self.chunks):
            G = self.G[:, :, cells]
            q = u[self.edofs[cells]]
            if gid in self.enhanced:
                G = np.concatenate([G, self.G_enh[:, :, cells]], axis=0)
                q = np.concatenate([q, u[self.internal_dofs[k]]], axis=1)
            F = self._deformation(q, G)
            J, _ = det_inv(F)
            dx = self.dx[cells]
            psi, _, _ = self._law(gid, F, False)
            E += float(np.sum(psi * dx))
            if gid != SILICONE:
                continue
            if self.mixed:
                V = self.volume[cells]
                Jb = np.einsum("eq,eq->e", J, dx) / V
                E += float(np.sum(V * 0.5 * K * (Jb - 1.0) ** 2))
            else:
                E += float(np.sum(0.5 * K * (J - 1.0) ** 2 * dx))
        return E
