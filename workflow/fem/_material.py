"""Hyperelastic laws, vectorised over quadrature points, for 2D plane strain and 3D.

Each law takes the deformation gradient ``F`` of shape ``(d, d, ...)`` (the
point axes last, so every operation runs over contiguous arrays) with d = 2
(plane strain: F33 = 1) or d = 3, and returns the strain energy density
``psi`` (...), the first Piola-Kirchhoff stress ``P = dpsi/dF`` (d, d, ...)
and the tangent ``A = d2psi/dFdF`` (d, d, d, d, ...).  Stresses in MPa when
the constants are in MPa.  Plane strain evaluates the 3D law on F embedded
with F33 = 1 and keeps the in-plane components (exactly the derivatives with
respect to the in-plane entries of F); only those are ever formed.

Both laws are written through the invariants I1 = tr C, I2 = (I1^2 - C:C)/2
and J = det F, with the chain rule

    P = sum_a psi_a dI_a/dF,
    A = sum_ab psi_ab dI_a/dF (x) dI_b/dF + sum_a psi_a d2I_a/dFdF,

dI1 = 2F, dI2 = 2(I1 F - F C), dJ = J F^-T and their second derivatives
(``_law``, which adds them into A term by term; the tangents are checked
against finite differences of P in the tests).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mooney_rivlin_isochoric", "neo_hooke_compressible", "det_inv"]


def det_inv(F: np.ndarray):
    """Determinant and inverse of 2x2 or 3x3 matrices stored as (d, d, ...)."""
    if F.shape[0] == 2:
        J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        inv = np.array([[F[1, 1], -F[0, 1]], [-F[1, 0], F[0, 0]]]) / J
        return J, inv
    cof = np.empty_like(F)  # cofactor matrix: cof_ij = dJ/dF_ij
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            cof[i, j] = F[i1, j1] * F[i2, j2] - F[i1, j2] * F[i2, j1]
    J = np.einsum("j...,j...->...", F[0], cof[0])
    return J, np.swapaxes(cof, 0, 1) / J


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, :, None, None] * b[None, None]


def _basics(F: np.ndarray):
    """C = F^T F, b = F F^T, I1, I2, J and F^-1 of F (d, d, ...) (plane strain: of F embedded with F33 = 1)."""
    d = F.shape[0]
    C = np.einsum("ki...,kj...->ij...", F, F)
    b = np.einsum("ik...,jk...->ij...", F, F)
    I1 = np.trace(C) + (3 - d)
    I2 = 0.5 * (I1**2 - np.einsum("ij...,ij...->...", C, C) - (3 - d))
    J, Finv = det_inv(F)
    return C, b, I1, I2, J, Finv


def _law(F, psi_of, tangent):
    """psi, P and A (None without ``tangent``) of a law psi(I1, I2, J) given by ``psi_of(I1, I2, J)`` ->
    (psi, gradient g (3 arrays or scalars), Hessian H (3 x 3 of arrays, scalars or None)).

    P = sum_a g_a dI_a/dF and A = sum_ab H_ab dI_a/dF (x) dI_b/dF + sum_a g_a d2I_a/dFdF, with the Hessians of the
    invariants added term by term,

        d2I1 = 2 d_ik d_jl,
        d2I2 = 4 F_ij F_kl - 2 F_il F_kj + 2 I1 d_ik d_jl - 2 d_ik C_lj - 2 b_ik d_jl,
        d2J  = J (Finv_ji Finv_lk - Finv_jk Finv_li):

    the identity-tensor parts touch d^3 of the d^4 entries, so they go in by index instead of as dense products
    (with the H sum as three outer products, the 3D Mooney-Rivlin tangent 1.8x as fast as the dense form).
    """
    d = F.shape[0]
    C, b, I1, I2, J, Finv = _basics(F)
    FiT = np.swapaxes(Finv, 0, 1)
    dv = (2.0 * F, 2.0 * (I1 * F - np.einsum("ik...,kj...->ij...", F, C)), J * FiT)
    psi, g, H = psi_of(I1, I2, J)
    used = [not (np.isscalar(ga) and ga == 0.0) for ga in g]  # a law may not depend on an invariant (neo-Hooke: I2)
    P = sum(ga * dva for ga, dva, u in zip(g, dv, used) if u)
    if not tangent:
        return psi, P, None
    # dense parts: g2 (4 F_ij F_kl - 2 F_il F_kj) + g3 J (Finv_ji Finv_lk - Finv_jk Finv_li)
    A = (g[2] * J) * (_outer(FiT, FiT) - FiT[:, None, None, :] * Finv[None, :, :, None])
    if used[1]:
        A += g[1] * (4.0 * _outer(F, F) - 2.0 * F[:, None, None, :] * np.swapaxes(F, 0, 1)[None, :, :, None])
    for a in range(3):  # sum_ac H_ac dv_a (x) dv_c as sum_a dv_a (x) (sum_c H_ac dv_c): three outer products, not six
        w = [H[a][c] * dv[c] for c in range(3) if H[a][c] is not None]
        if w:
            A += _outer(dv[a], sum(w))
    # identity parts: (2 g1 + 2 g2 I1) d_ik d_jl - 2 g2 (d_ik C_lj + b_ik d_jl)
    diag = 2.0 * g[0] + 2.0 * g[1] * I1
    for i in range(d):
        for j in range(d):
            A[i, j, i, j] += diag
            if used[1]:
                A[i, j, i, :] -= 2.0 * g[1] * C[:, j]
                A[i, j, :, j] -= 2.0 * g[1] * b[i, :]
    return psi, P, A


def mooney_rivlin_isochoric(F: np.ndarray, c10: float, c01: float, c20: float = 0.0, tangent: bool = True):
    """Three-term Mooney-Rivlin law on the isochoric invariants (Table 5).

    psi = c10 (I1b - 3) + c01 (I2b - 3) + c20 (I1b - 3)^2 with
    I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2.  The volumetric part is added by
    the element (mean dilatation, see ``_assembly``).  Initial shear modulus
    mu0 = 2 (c10 + c01).
    """

    def psi_of(I1, I2, J):
        j23, j43 = J ** (-2.0 / 3.0), J ** (-4.0 / 3.0)
        I1b, I2b = I1 * j23, I2 * j43
        W1 = c10 + 2.0 * c20 * (I1b - 3.0)
        W2 = c01
        psi = c10 * (I1b - 3.0) + c01 * (I2b - 3.0) + c20 * (I1b - 3.0) ** 2
        # derivatives of I1b, I2b with respect to (I1, I2, J)
        d1 = [j23, 0.0, -2.0 / 3.0 * I1b / J]
        d2 = [0.0, j43, -4.0 / 3.0 * I2b / J]
        g = [W1 * d1[a] + W2 * d2[a] for a in range(3)]
        H = [[2.0 * c20 * d1[a] * d1[c] for c in range(3)] for a in range(3)]
        H[0][2] = H[2][0] = H[0][2] - W1 * (2.0 / 3.0) * j23 / J
        H[1][2] = H[2][1] = H[1][2] - W2 * (4.0 / 3.0) * j43 / J
        H[2][2] = H[2][2] + W1 * (10.0 / 9.0) * I1b / J**2 + W2 * (28.0 / 9.0) * I2b / J**2
        H[0][1] = H[1][0] = H[1][1] = None  # W12 = W22 = 0 and d1[1] = 0
        return psi, g, H

    return _law(F, psi_of, tangent)


def neo_hooke_compressible(F: np.ndarray, mu: float, lmbda: float, tangent: bool = True):
    """Compressible neo-Hooke law (paper layer), exact under large rotations.

    psi = mu/2 (I1 - 3) - mu ln J + lmbda/2 (ln J)^2; small-strain limit:
    linear elasticity with Lame constants (lmbda, mu).
    """

    def psi_of(I1, I2, J):
        lnJ = np.log(J)
        psi = 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * lmbda * lnJ**2
        g = [0.5 * mu, 0.0, (lmbda * lnJ - mu) / J]
        H = [[None, None, None], [None, None, None], [None, None, (mu + lmbda - lmbda * lnJ) / J**2]]
        return psi, g, H

    return _law(F, psi_of, tangent)
