"""Penalty node-to-segment (2D) / node-to-face (3D) contact between facing walls.

For each slave node s and the master facet it projects onto (parameter xi, shape
functions N_a(xi), unit outward normal n of the master solid), the normal gap
is g = (x_s - sum_a N_a x_a) . n; g < 0 is penetration.  The penalty energy
is  E = sum_s eps A_s / 2 <-g_s>^2  (smoothed near g = 0, see ``smoothing``) with A_s the slave node's tributary area
(reference configuration; per mm of width in 2D) and eps the penalty stiffness
(MPa/mm), so a contact pressure t_N causes a penetration t_N / eps.  Its
gradient, with dg/dx_s = n and dg/dx_a = -N_a n (at the closest-point
projection), gives the nodal forces.  The tangent of these forces (including
the rotation of the master normal and the sliding of the projection point)
is taken by vectorised central differences of the local force of each
active slave with respect to its own and its master facet's coordinates
(6 or 15 dofs), which keeps Newton's convergence quadratic.
Both walls of a gap act as slave in turn (two-pass), so neither passes
through the other.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ContactPair", "contact_pairs_from_mesh"]

_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)


def _window(t: np.ndarray) -> np.ndarray:
    """C1 smoothstep on [0, 1] (0 below, 1 above)."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _tributary(p: np.ndarray, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slave nodes of a facet set and their tributary areas (reference configuration)."""
    x = p[:, facets].transpose(1, 2, 0)
    if p.shape[0] == 2:
        area = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    else:
        area = 0.5 * np.linalg.norm(np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 1]), axis=1)
    nodes, inv = np.unique(facets, return_inverse=True)
    w = np.bincount(inv.ravel(), weights=np.repeat(area / facets.shape[1], facets.shape[1]), minlength=nodes.size)
    return nodes, w


class ContactPair:
    """One-way contact of the nodes of ``slave_facets`` against ``master_facets``.

    Parameters
    ----------
    p : ndarray (dim, nnodes)
        Reference coordinates (for tributary areas), mm.
    slave_facets, master_facets : ndarray
        Outward-oriented facets of the two facing walls.
    search : float
        Largest |g| (mm) at which a penetrating node is still taken as in
        contact with a master facet (guards against far-away facets).
    extend : float
        The master wall is extended past its free edges by this fraction of
        the edge facet, so that a slave corner that slides past the master's
        corner (the outer corners of two blocks meet) is still caught.
    smoothing : float
        Width d (mm) of the C1 transition of the penalty law: the contact
        pressure rises smoothly from 0 at g = d to eps d/2 at g = 0 and then
        linearly, eps (d/2 - g).  d = 0 is the plain (C0) penalty.
    """

    def __init__(self, p: np.ndarray, slave_facets: np.ndarray, master_facets: np.ndarray, search: float = 1.0,
                 extend: float = 0.5, smoothing: float = 0.0):
        self.dim = p.shape[0]
        self.smoothing = float(smoothing)
        self.slave, self.area = _tributary(p, slave_facets)
        self.master = master_facets
        self.search = search
        # allowed parameter range per master facet: [0, 1] (2D) / [-1, 1]^2 (3D), widened at free edges
        nodes, cnt = np.unique(master_facets, return_counts=True)
        edge_count = 1 if self.dim == 2 else 2
        on_edge = np.isin(master_facets, nodes[cnt <= edge_count])
        if self.dim == 2:
            self.lo = np.where(on_edge[:, 0], -extend, 0.0)
            self.hi = np.where(on_edge[:, 1], 1.0 + extend, 1.0)
        else:
            self.lim = np.where(on_edge.any(axis=1), 1.0 + 2.0 * extend, 1.0)

    def _project(self, x: np.ndarray):
        """Closest master facet per slave: (facet index, N (ns, nfn), n (ns, dim), g (ns,), inside)."""
        xs = x[:, self.slave].T  # (ns, dim)
        xm = x[:, self.master].transpose(1, 2, 0)  # (nm, nfn, dim)
        if self.dim == 2:
            t = xm[:, 1] - xm[:, 0]
            L2 = np.einsum("mi,mi->m", t, t)
            d = xs[:, None, :] - xm[None, :, 0, :]
            xi = np.einsum("smi,mi->sm", d, t) / L2
            xic = np.clip(xi, 0.0, 1.0)
            dist = np.linalg.norm(d - xic[..., None] * t, axis=2)
            m = np.argmin(dist, axis=1)
            s = np.arange(xs.shape[0])
            xi_s = xi[s, m]
            tt = t[m] / np.sqrt(L2[m])[:, None]
            n = np.stack([tt[:, 1], -tt[:, 0]], axis=1)
            N = np.stack([1.0 - xi_s, xi_s], axis=1)
            g = np.einsum("si,si->s", d[s, m], n)
            inside = (xi_s >= self.lo[m] - 1e-6) & (xi_s <= self.hi[m] + 1e-6)
            return m, N, n, g, inside
        # 3D: candidate facets = the 4 nearest centroids, then Newton for (xi, eta)
        c = xm.mean(axis=1)
        dc = np.linalg.norm(xs[:, None, :] - c[None], axis=2)
        k = min(4, c.shape[0])
        cand = np.argpartition(dc, k - 1, axis=1)[:, :k]  # (ns, k)
        X = xm[cand]  # (ns, k, 4, 3)
        ab = np.zeros(cand.shape + (2,))
        for _ in range(8):
            N = 0.25 * (1 + _XI[:, 0] * ab[..., 0, None]) * (1 + _XI[:, 1] * ab[..., 1, None])
            dxi = 0.25 * _XI[:, 0] * (1 + _XI[:, 1] * ab[..., 1, None])
            deta = 0.25 * _XI[:, 1] * (1 + _XI[:, 0] * ab[..., 0, None])
            xp = np.einsum("ska,skai->ski", N, X)
            a1 = np.einsum("ska,skai->ski", dxi, X)
            a2 = np.einsum("ska,skai->ski", deta, X)
            r = xs[:, None, :] - xp
            M = np.stack([np.stack([(a1 * a1).sum(-1), (a1 * a2).sum(-1)], -1), np.stack([(a1 * a2).sum(-1), (a2 * a2).sum(-1)], -1)], -2)
            rhs = np.stack([(r * a1).sum(-1), (r * a2).sum(-1)], -1)
            ab = np.clip(ab + np.linalg.solve(M, rhs[..., None])[..., 0], -3.0, 3.0)
        N = 0.25 * (1 + _XI[:, 0] * ab[..., 0, None]) * (1 + _XI[:, 1] * ab[..., 1, None])
        xp = np.einsum("ska,skai->ski", N, X)
        nrm = np.cross(a1, a2)
        nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
        g = np.einsum("ski,ski->sk", xs[:, None, :] - xp, nrm)
        inside = np.all(np.abs(ab) <= self.lim[cand][..., None] + 1e-6, axis=-1)
        # closest facet = smallest distance to the projection clipped onto the facet itself
        # (as in 2D), so that an edge facet's extension never wins over the facet a slave is on
        abc = np.clip(ab, -1.0, 1.0)
        Nc = 0.25 * (1 + _XI[:, 0] * abc[..., 0, None]) * (1 + _XI[:, 1] * abc[..., 1, None])
        dist = np.linalg.norm(xs[:, None, :] - np.einsum("ska,skai->ski", Nc, X), axis=-1)
        j = np.argmin(dist, axis=1)
        s = np.arange(xs.shape[0])
        return cand[s, j], N[s, j], nrm[s, j], g[s, j], inside[s, j]

    def _local_force(self, X: np.ndarray, eps_area: np.ndarray, lim: tuple) -> np.ndarray:
        """Penalty force eps A w g dg (nc, nn*dim) for local node sets X (nc, nn, dim) = slave + master facet.

        w is 1 on the master facet and fades smoothly to 0 over its extension
        past a free edge (``lim``: (lo, hi) in 2D, the half-width in 3D), so the
        force stays continuous when a slave slides off the master's end.
        """
        xs, xm = X[:, 0], X[:, 1:]
        if self.dim == 2:
            t = xm[:, 1] - xm[:, 0]
            L = np.linalg.norm(t, axis=1)
            tt = t / L[:, None]
            n = np.stack([tt[:, 1], -tt[:, 0]], axis=1)
            xi = np.einsum("ci,ci->c", xs - xm[:, 0], tt) / L
            N = np.stack([1.0 - xi, xi], axis=1)
            lo, hi = lim
            w = np.where(xi < 0, _window((xi - lo) / np.maximum(-lo, 1e-12)), 1.0)
            w = w * np.where(xi > 1, _window((hi - xi) / np.maximum(hi - 1.0, 1e-12)), 1.0)
        else:
            ab = np.zeros((X.shape[0], 2))
            for _ in range(10):
                N = 0.25 * (1 + _XI[:, 0] * ab[:, 0, None]) * (1 + _XI[:, 1] * ab[:, 1, None])
                dxi = 0.25 * _XI[:, 0] * (1 + _XI[:, 1] * ab[:, 1, None])
                deta = 0.25 * _XI[:, 1] * (1 + _XI[:, 0] * ab[:, 0, None])
                a1 = np.einsum("ca,cai->ci", dxi, xm)
                a2 = np.einsum("ca,cai->ci", deta, xm)
                r = xs - np.einsum("ca,cai->ci", N, xm)
                M = np.stack([np.stack([(a1 * a1).sum(-1), (a1 * a2).sum(-1)], -1),
                              np.stack([(a1 * a2).sum(-1), (a2 * a2).sum(-1)], -1)], -2)
                rhs = np.stack([(r * a1).sum(-1), (r * a2).sum(-1)], -1)
                ab = ab + np.linalg.solve(M, rhs[..., None])[..., 0]
            N = 0.25 * (1 + _XI[:, 0] * ab[:, 0, None]) * (1 + _XI[:, 1] * ab[:, 1, None])
            dxi = 0.25 * _XI[:, 0] * (1 + _XI[:, 1] * ab[:, 1, None])
            deta = 0.25 * _XI[:, 1] * (1 + _XI[:, 0] * ab[:, 0, None])
            n = np.cross(np.einsum("ca,cai->ci", dxi, xm), np.einsum("ca,cai->ci", deta, xm))
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            (L,) = lim
            w = np.prod(np.where(np.abs(ab) > 1, _window((L[:, None] - np.abs(ab)) / np.maximum(L[:, None] - 1.0, 1e-12)), 1.0), axis=1)
        g = np.einsum("ci,ci->c", xs - np.einsum("ca,cai->ci", N, xm), n)
        coef = np.concatenate([np.ones((X.shape[0], 1)), -N], axis=1)
        dg = (coef[:, :, None] * n[:, None, :]).reshape(X.shape[0], -1)
        d = self.smoothing
        # C1 penalty: linear eps (g - d/2) in penetration, -eps (d - g)^2 / (2 d) for 0 < g < d, 0 beyond
        if d > 0:
            t = np.where(g <= 0.0, g - 0.5 * d, -((np.clip(d - g, 0.0, None)) ** 2) / (2.0 * d))
        else:
            t = np.minimum(g, 0.0)
        return (eps_area * w * t)[:, None] * dg

    def evaluate(self, x: np.ndarray, eps: float, tangent: bool = True):
        """Penalty forces (to add to the residual) and tangent for current nodes ``x``.

        Returns ``(dofs (nc, ndl), f (nc, ndl), K (nc, ndl, ndl) or None, gmin)`` for
        the active slaves, with ``gmin`` the smallest gap over all slaves that
        project inside a master facet (negative = largest penetration, mm).
        """
        m, N, n, g, inside = self._project(x)
        ok = inside & (np.abs(g) <= self.search)
        gmin = float(g[ok].min()) if ok.any() else np.inf
        act = ok & (g < self.smoothing)
        dim = self.dim
        if not act.any():
            return np.zeros((0, 0), int), np.zeros((0, 0)), (np.zeros((0, 0, 0)) if tangent else None), gmin
        nodes = np.concatenate([self.slave[act, None], self.master[m[act]]], axis=1)
        X = x[:, nodes].transpose(1, 2, 0)  # (nc, nn, dim)
        w = eps * self.area[act]
        lim = (self.lo[m[act]], self.hi[m[act]]) if dim == 2 else (self.lim[m[act]],)
        f = self._local_force(X, w, lim)
        dofs = (dim * nodes[:, :, None] + np.arange(dim)).reshape(nodes.shape[0], -1)
        K = None
        if tangent:
            # all 2*nd perturbed copies in one vectorised batch
            nc, nd = f.shape
            step = 1e-7 * max(1.0, float(np.abs(X).max()))
            E = np.eye(nd) * step
            Xf = X.reshape(nc, -1)
            Xb = np.concatenate([Xf[None] + E[:, None, :], Xf[None] - E[:, None, :]])  # (2nd, nc, nd)
            limb = tuple(np.tile(a, 2 * nd) for a in lim)
            fb = self._local_force(Xb.reshape((-1,) + X.shape[1:]), np.tile(w, 2 * nd), limb).reshape(2, nd, nc, nd)
            K = ((fb[0] - fb[1]) / (2 * step)).transpose(1, 2, 0)
        return dofs, f, K, gmin

    def energy(self, x: np.ndarray, eps: float) -> float:
        _, _, _, g, inside = self._project(x)
        ok = inside & (np.abs(g) <= self.search) & (g < 0)
        return float(np.sum(0.5 * eps * self.area[ok] * g[ok] ** 2))


def contact_pairs_from_mesh(unit_mesh, search: float = 1.0, two_pass: bool = True, extend: float = 0.5,
                            smoothing: float = 0.0) -> list[ContactPair]:
    """Contact pairs for every gap of a ``UnitMesh``.

    Each wall is slave once against the other (two-pass), each master
    extended past its free edges (with a smoothly vanishing penalty) so that
    the outer corners are caught when two blocks meet corner to corner.  With
    ``two_pass=False`` only the left wall is slave: the right wall's corner can
    then pass into the left block, and Newton stalls there (measured: the 2D
    unit stops at about 108 kPa).
    """
    p = unit_mesh.mesh.p
    out = []
    for a, b in unit_mesh.contact_pairs:
        fa, fb = unit_mesh.facets[a], unit_mesh.facets[b]
        out.append(ContactPair(p, fa, fb, search, extend, smoothing))
        if two_pass:
            out.append(ContactPair(p, fb, fa, search, extend, smoothing))
    return out
