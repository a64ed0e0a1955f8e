"""Follower pressure on deformed boundary facets, with its load stiffness.

The virtual work of a pressure p acting on the current surface a of a solid
with outward normal n is  dW = -int_a p n . du da  (the pressure pushes into
the solid).  On a facet parametrised by xi (2D line) or (xi, eta) (3D
bilinear quadrilateral) with nodes oriented so that the outward normal is
R x_xi (2D, R = [[0, 1], [-1, 0]]) or x_xi x x_eta (3D):

    f_a = -p int N_a R x_xi dxi            (2D, per mm of width)
    f_a = -p int N_a (x_xi x x_eta) dxi deta (3D)

Both are exact for the current geometry and depend on the nodal positions
only, so the load stiffness  K_ab = -df_a/dx_b  is exact as well (it is not
symmetric facet by facet; over a closed cavity it is).  p in MPa, forces in N.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pressure_load"]

_R = np.array([[0.0, 1.0], [-1.0, 0.0]])
_G = 1.0 / np.sqrt(3.0)
_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)  # cyclic quad corners
_QP = np.array([[-_G, -_G], [_G, -_G], [_G, _G], [-_G, _G]])


def _skew(a: np.ndarray) -> np.ndarray:
    """Matrix [a]x with [a]x b = a x b, for a of shape (..., 3)."""
    z = np.zeros(a.shape[:-1])
    return np.stack(
        [
            np.stack([z, -a[..., 2], a[..., 1]], -1),
            np.stack([a[..., 2], z, -a[..., 0]], -1),
            np.stack([-a[..., 1], a[..., 0], z], -1),
        ],
        -2,
    )


def pressure_load(x: np.ndarray, facets: np.ndarray, p: float, tangent: bool = True):
    """External nodal forces of a follower pressure and the load stiffness.

    Parameters
    ----------
    x : ndarray (dim, nnodes)
        Current nodal coordinates, mm.
    facets : ndarray (nf, 2) or (nf, 4)
        Outward-oriented facets (see ``UnitMesh.facets``).
    p : float
        Pressure, MPa.

    Returns
    -------
    f : ndarray (nf, nfn, dim)
        Nodal external forces, N (2D: N/mm).
    K : ndarray (nf, nfn*dim, nfn*dim) or None
        ``-df/dx``, the contribution to the tangent of the residual
        ``f_int - f_ext``, in node-interleaved local dofs.
    """
    dim = x.shape[0]
    xf = x[:, facets].transpose(1, 2, 0)  # (nf, nfn, dim)
    nf = xf.shape[0]
    if dim == 2:
        t = xf[:, 1] - xf[:, 0]  # x_xi for xi in [0, 1]
        n = t @ _R.T
        f = -0.5 * p * np.repeat(n[:, None, :], 2, axis=1)
        if not tangent:
            return f, None
        # df_a/dx_b = -p/2 R * s_b,  s = (-1, +1)
        K = np.zeros((nf, 2, 2, 2, 2))
        for a in range(2):
            for b, s in enumerate((-1.0, 1.0)):
                K[:, a, :, b, :] = 0.5 * p * s * _R
        return f, K.reshape(nf, 4, 4)
    f = np.zeros((nf, 4, 3))
    K = np.zeros((nf, 4, 3, 4, 3)) if tangent else None
    for xi, eta in _QP:
        N = 0.25 * (1 + _XI[:, 0] * xi) * (1 + _XI[:, 1] * eta)
        dNxi = 0.25 * _XI[:, 0] * (1 + _XI[:, 1] * eta)
        dNeta = 0.25 * _XI[:, 1] * (1 + _XI[:, 0] * xi)
        x_xi = np.einsum("a,fai->fi", dNxi, xf)
        x_eta = np.einsum("a,fai->fi", dNeta, xf)
        n = np.cross(x_xi, x_eta)
        f -= p * N[None, :, None] * n[:, None, :]
        if tangent:
            # d n = -[x_eta]x dx_xi + [x_xi]x dx_eta
            dn = -np.einsum("b,fij->fbij", dNxi, _skew(x_eta)) + np.einsum("b,fij->fbij", dNeta, _skew(x_xi))
            K += p * np.einsum("a,fbij->faibj", N, dn)
    return f, (K.reshape(nf, 12, 12) if tangent else None)
