"""FElupe model of the unit (2D plane strain and 3D half model): an independent code for the cross-checks.

Shared by tests/test_fem_felupe.py and the benchmarks (benchmarks/bench_fem.py,
bench_contact.py, bench_felupe.py).  It uses FElupe's public API only.

Same mesh, element formulation, material constants, K and follower pressure as
``workflow.fem`` with ``formulation="mixed"``: Q1 silicone with a mean-dilatation
volumetric part (FElupe's ``SolidBodyNearlyIncompressible``, U = K/2 (Jb - 1)^2)
and plain Q1 neo-Hooke paper (``SolidBody`` with ``NeoHookeCompressible``).
FElupe has no equivalent of our enhanced-strain paper layer.

FElupe has no contact between deformable bodies, so the 2D check with contact
gives it its own treatment (``SmoothedGapContact``), different from ours on
purpose: a penalty *energy* on the gap to an implicit moving-least-squares
surface of the master wall (a kernel-weighted mean of the facets' planes, smooth
everywhere, no closest-point projection) with complex-step gradients, against
our node-to-segment projection along interpolated nodal normals.  It acts on
the same surfaces as ours (``UnitMesh.contact_surfaces``: each gap's U and each
pocket's wall loop), split into straight walls, each wall against the rest of
its surface minus the facets next to it (``wall_pairs``), with the same penalty
eps = penalty_factor mu0 / penalty_length (MPa/mm).

Units: mm, MPa, N (per mm of width in 2D); pressures in kPa at the interface.
"""

from __future__ import annotations

import time

import felupe
import numpy as np
import scipy.sparse as sp

try:  # PARDISO as in workflow.fem when it is there; SuperLU otherwise
    import pypardiso

    _SPSOLVE = pypardiso.spsolve
except ImportError:  # pragma: no cover
    _SPSOLVE = None

__all__ = ["SmoothedGapContact", "straight_walls", "wall_pairs", "felupe_free_angles"]


def _smoothstep(t):
    """C2 step from 0 (t <= 0) to 1 (t >= 1) and its derivative; analytic inside (complex step)."""
    mid = (t.real > 0) & (t.real < 1)
    val = np.where(t.real >= 1, 1.0, np.where(mid, t**3 * (10.0 - 15.0 * t + 6.0 * t * t), 0.0))
    return val, np.where(mid, 30.0 * t * t * (1.0 - t) ** 2, 0.0)


def _penalty(f, d):
    """C2 penalty energy density (mm^2) and its derivative.

    (d - f)^3 / (3 d) for 0 < f < d, d^2/3 - d f + f^2 in penetration (f <= 0), 0 beyond d.
    The force eps A (f - d/2) in penetration is the same law as ``workflow.fem``'s smoothed penalty.
    """
    val = np.where(f.real >= d, 0.0, np.where(f.real > 0, (d - f) ** 3 / (3.0 * d), d * d / 3.0 - d * f + f * f))
    der = np.where(f.real >= d, 0.0, np.where(f.real > 0, -((d - f) ** 2) / d, 2.0 * f - d))
    return val, der


class SmoothedGapContact:
    """FElupe item: penalty on the gap of slave nodes to an implicit MLS surface of their master facets.

    Gap of slave x_s to its master facets (k: midpoint c_k, unit outward
    normal n_k, length L_k):  f = sum_k w_k n_k.(x_s - c_k) / sum_k w_k with
    w_k = L_k (1 - |x_s - c_k|^2 / R^2)^3_+ (compact, C2), R = 1.5 h; the
    implicit surface f = 0 is smooth and is a straight wall's own plane.
    Energy per slave  E_s = eps A_s / 2 phi(f) chi(W): phi = f^2 - d f + d^2/3
    in penetration and (d - f)^3 / (3 d) for 0 < f < d (C2, d = ``smoothing``
    mm), chi a C2 step of W = sum_k w_k that switches the contact off past the
    master's ends.  The force is the analytic dE/dx, the tangent its complex-step
    derivative (exact, symmetric).  ``walls``: (slave facets, master facets)
    pairs; ``eps`` MPa/mm, ``h`` the element size (mm).  Units: mm, MPa, N per
    mm of width.
    """

    def __init__(self, field, p, walls, eps, h, n_near=8, smoothing=0.01):
        self.field = field
        self.d = float(smoothing)
        self.p = p  # (npoints, 2) reference coordinates
        self.eps, self.R, self.W0, self.K = float(eps), 1.5 * h, 0.3 * h, int(n_near)
        self.slave, self.area, self.master = [], [], []
        for slave_facets, master_facets in walls:
            nodes, inv = np.unique(slave_facets, return_inverse=True)
            x = p[slave_facets]
            length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
            self.slave.append(nodes)
            self.area.append(np.bincount(inv.ravel(), np.repeat(length / 2, 2), minlength=nodes.size))
            self.master.append(master_facets)
        self.results = felupe.mechanics._helpers.Results()
        self.assemble = felupe.mechanics._helpers.Assemble(vector=self._vector, matrix=self._matrix)
        self._key, self._cache = None, None
        self.min_gap = np.inf

    def _gap(self, X):
        """MLS gap f, weight sum W and their gradients for local node sets X (batch, 1 + 2K, 2).

        Node order: the slave, then each facet's (a, b).  Analytic and free of
        abs/max on the unknowns, so complex perturbations pass through (the
        complex step of this gradient is the exact Hessian).
        """
        xs, xa, xb = X[:, 0], X[:, 1::2], X[:, 2::2]
        t = xb - xa
        L = np.sqrt(t[..., 0] ** 2 + t[..., 1] ** 2)
        tau = t / L[..., None]
        n = np.stack([tau[..., 1], -tau[..., 0]], axis=-1)
        r = xs[:, None, :] - 0.5 * (xa + xb)
        Rr = np.stack([-r[..., 1], r[..., 0]], axis=-1)  # R^T r for R t = (t_y, -t_x)
        rho = (r[..., 0] ** 2 + r[..., 1] ** 2) / self.R**2
        inside = rho.real < 1.0
        phi = np.where(inside, (1.0 - rho) ** 3, 0.0)
        dphi = np.where(inside, -3.0 * (1.0 - rho) ** 2, 0.0)
        w = L * phi
        g = (n * r).sum(axis=-1)
        # d/d(x_s), d/d(a_k), d/d(b_k) of w_k and g_k
        dw_s = (2.0 * L * dphi / self.R**2)[..., None] * r
        dw_ab = -(L * dphi / self.R**2)[..., None] * r
        dw_a, dw_b = dw_ab - phi[..., None] * tau, dw_ab + phi[..., None] * tau
        dg_b = Rr / L[..., None] - 0.5 * n - (g / L)[..., None] * tau
        dg_a = -Rr / L[..., None] - 0.5 * n + (g / L)[..., None] * tau
        W = w.sum(axis=1)
        Wsafe = np.where(W.real > 0, W, 1.0)
        f = (w * g).sum(axis=1) / Wsafe
        h = g - f[:, None]  # dF - f dW = sum_k (g_k - f) dw_k + w_k dg_k
        df_s = ((h[..., None] * dw_s + w[..., None] * n).sum(axis=1)) / Wsafe[:, None]
        df_a = (h[..., None] * dw_a + w[..., None] * dg_a) / Wsafe[:, None, None]
        df_b = (h[..., None] * dw_b + w[..., None] * dg_b) / Wsafe[:, None, None]
        nb, nn = X.shape[:2]
        df = np.concatenate([df_s[:, None], np.stack([df_a, df_b], axis=2).reshape(nb, nn - 1, 2)], axis=1)
        dW = np.concatenate([dw_s.sum(axis=1)[:, None], np.stack([dw_a, dw_b], axis=2).reshape(nb, nn - 1, 2)], axis=1)
        return f, W, df.reshape(nb, 2 * nn), dW.reshape(nb, 2 * nn)

    def _energy(self, X, A):
        """Energy (batch,), gradient (batch, 2 (1 + 2K)), gap f and weight W of local node sets X."""
        f, W, df, dW = self._gap(X)
        c = 0.5 * self.eps * A
        pen, dpen = _penalty(f, self.d)
        chi, dchi = _smoothstep(W / self.W0)
        e = c * pen * chi
        grad = c[:, None] * (dpen * chi)[:, None] * df + c[:, None] * (pen * dchi / self.W0)[:, None] * dW
        return e, grad, f, W

    def _local_sets(self, x):
        """Per slave: node ids (1 + 2K) of itself and its K nearest master facets, and its area."""
        nodes, areas = [], []
        K = min(self.K, min(m.shape[0] for m in self.master))  # one width for every wall (stacked below)
        for slave, area, master in zip(self.slave, self.area, self.master):
            c = 0.5 * (x[master[:, 0]] + x[master[:, 1]])
            d = np.linalg.norm(x[slave][:, None, :] - c[None], axis=2)
            near = np.argpartition(d, K - 1, axis=1)[:, :K]
            nodes.append(np.concatenate([slave[:, None], master[near].reshape(slave.size, -1)], axis=1))
            areas.append(area)
        return np.concatenate(nodes), np.concatenate(areas)

    def _evaluate(self):
        u = self.field[0].values
        key = u.tobytes()
        if key == self._key:
            return self._cache
        x = self.p + u
        nodes, A = self._local_sets(x)
        X = x[nodes]
        e, grad, f, W = self._energy(X, A)
        full = W >= self.W0  # the gap is a gap only where the master's weight is complete
        self.min_gap = float(f[full].min()) if full.any() else np.inf
        act = e > 0
        nodes, X, A, grad = nodes[act], X[act], A[act], grad[act]
        nc, nn = X.shape[:2]
        nd = 2 * nn
        dofs = (2 * nodes[:, :, None] + np.arange(2)).reshape(nc, nd)
        # tangent: complex step of the analytic gradient (exact, one column per coordinate)
        Z = np.repeat(X.reshape(nc, 1, nd), nd, axis=1).astype(complex) + 1j * 1e-30 * np.eye(nd)[None]
        _, gz, _, _ = self._energy(Z.reshape(nc * nd, nn, 2), np.repeat(A, nd))
        hess = gz.imag.reshape(nc, nd, nd) / 1e-30
        self._key, self._cache = key, (dofs, grad, hess)
        return self._cache

    def _vector(self, field=None, **kwargs):
        dofs, grad, _ = self._evaluate()
        n = self.field[0].values.size
        return sp.csr_matrix((grad.ravel(), (dofs.ravel(), np.zeros(dofs.size, int))), shape=(n, 1))

    def _matrix(self, field=None, **kwargs):
        dofs, _, hess = self._evaluate()
        n = self.field[0].values.size
        k = dofs.shape[1]
        rows, cols = np.repeat(dofs, k, axis=1).ravel(), np.tile(dofs, (1, k)).ravel()
        return sp.csr_matrix((hess.ravel(), (rows, cols)), shape=(n, n))


def straight_walls(p: np.ndarray, facets: np.ndarray) -> list[np.ndarray]:
    """Split 2D facets (nf, 2) into straight walls: chains of facets with the same normal that share nodes.

    ``p`` (npoints, 2) reference coordinates, mm.  A wall is a connected run of
    facets with one outward normal (the normal rounded to 1e-6).
    """
    t = p[facets[:, 1]] - p[facets[:, 0]]
    n = np.round(np.stack([t[:, 1], -t[:, 0]], axis=1) / np.linalg.norm(t, axis=1)[:, None], 6)
    walls = []
    for key in np.unique(n, axis=0):
        todo = list(np.flatnonzero(np.all(n == key, axis=1)))
        while todo:  # grow one connected run at a time
            run = [todo.pop(0)]
            nodes = set(facets[run[0]])
            grown = True
            while grown:
                grown = False
                for k in list(todo):
                    if nodes & set(facets[k]):
                        run.append(k)
                        nodes |= set(facets[k])
                        todo.remove(k)
                        grown = True
            walls.append(facets[sorted(run)])
    return walls


def wall_pairs(um) -> list[tuple[np.ndarray, np.ndarray]]:
    """(slave wall, master facets) pairs on the surfaces ``um.contact_surfaces`` of a 2D ``UnitMesh``.

    Each surface (a gap's U, a pocket's wall loop) is split into its straight
    walls; each wall is slave against the facets of the other walls of the same
    surface except those that share a node with it (the facets next to it,
    where a gap is meaningless), so every wall is also a master of the others.
    """
    p = um.mesh.p.T
    out = []
    for name in um.contact_surfaces:
        walls = straight_walls(p, um.facets[name])
        for i, slave in enumerate(walls):
            others = np.concatenate([w for j, w in enumerate(walls) if j != i])
            near = np.isin(others, np.unique(slave)).any(axis=1)
            if not np.all(near):
                out.append((slave, others[~near]))
    return out


def _fields(um):
    """Points and the field containers of a ``UnitMesh``: whole body, silicone, paper, pressure boundary.

    The silicone, paper and boundary containers are linked to the whole body's,
    which is the unknown of the job: FElupe holds the points of the unknown's
    mesh that have no cells, so with the silicone's mesh the mid-plane nodes of
    a paper layer of two or more elements would be held fixed.
    """
    p = um.mesh.p.T.copy()
    if um.dim == 2:
        t = um.mesh.t.T.copy()  # CCW quads: the same node order in both codes
        kind, region, boundary = "quad", felupe.RegionQuad, felupe.RegionQuadBoundary
        field = felupe.FieldPlaneStrain
    else:
        t = um.mesh.t.T[:, [0, 2, 4, 1, 3, 6, 7, 5]].copy()  # scikit-fem -> VTK hexahedron node order
        kind, region, boundary = "hexahedron", felupe.RegionHexahedron, felupe.RegionHexahedronBoundary
        field = felupe.Field
    mesh = felupe.Mesh(p, t, kind)
    f_all = felupe.FieldContainer([field(region(mesh), dim=um.dim)])
    f_sil = felupe.FieldContainer([field(region(felupe.Mesh(p, t[um.material == 0], kind)), dim=um.dim)])
    f_pap = felupe.FieldContainer([field(region(felupe.Mesh(p, t[um.material == 1], kind)), dim=um.dim)])
    f_sil.link(f_all)
    f_pap.link(f_all)
    mask = np.zeros(len(p), bool)
    mask[np.unique(um.facets["cavity_top"])] = True
    bnd = boundary(mesh, mask=mask, ensure_3d=True) if um.dim == 2 else boundary(mesh, mask=mask)
    if bnd.mesh.cells.shape[0] != um.facets["cavity_top"].shape[0]:
        raise RuntimeError("FElupe's pressure boundary differs from the cavity facets")
    f_bnd = felupe.FieldContainer([field(bnd, dim=um.dim)])
    f_bnd.link(f_all)
    return p, f_all, f_sil, f_pap, f_bnd


def _absolute_check(atol):
    """FElupe convergence check on |r| of the active dofs <= ``atol`` (N), as ``workflow.fem`` with rtol = 0."""

    def check(dx, x, f, xtol, ftol, dof1=None, dof0=None, items=None, eps=1e-3):
        fnorm = float(np.linalg.norm(f[slice(None) if dof1 is None else dof1]))
        return float(np.linalg.norm(dx)), fnorm, fnorm <= atol

    return check


def felupe_free_angles(um, pressures_kpa, mat, contact=False, eps=None, nsteps=20, info=None, partial=False, atol=None):
    """Total free bending angle (deg) of the unit in FElupe at each pressure (P_B = 0).

    ``um`` a 2D or 3D ``UnitMesh`` (3D: half model, u_z = 0 on z = 0), ``mat``
    from ``fem.material_constants``.  The ramp 0 -> max(pressures_kpa) is cut
    into ``nsteps`` equal substeps (make the pressures land on them; or ``nsteps`` the substeps' end
    pressures in kPa) and
    FElupe's ``CutbackPlugin`` subdivides a substep whose Newton iteration
    fails (the softer Table 5 silicone needs it even without contact).
    ``contact`` (2D only): ``SmoothedGapContact`` on ``wall_pairs(um)`` with
    penalty ``eps`` (MPa/mm; default 100 mu0 / 1 mm as ``workflow.fem``).
    ``partial``: if FElupe gives up (its cut-back cannot recover a substep),
    return the angles reached and NaN beyond the last converged substep
    instead of raising.  ``info`` (a dict) receives the wall time (s), the
    converged increments, the cut-backs, ``status`` (0 converged, 1 gave up),
    ``reason``, the pressure reached (kPa) and, with contact, the smallest gap
    (mm) over the substeps.  ``atol`` (N): converge on the absolute residual of the active dofs instead of
    FElupe's default (1e-8 relative to the reaction forces), so that two codes stop at the same residual.
    """
    t0 = time.perf_counter()
    p, f_all, f_sil, f_pap, f_bnd = _fields(um)
    umat = felupe.Hyperelastic(
        felupe.constitution.tensortrax.models.hyperelastic.third_order_deformation,
        C10=mat["c10"],
        C01=mat["c01"],
        C11=0.0,
        C20=mat["c20"],
        C30=0.0,
    )
    body = felupe.SolidBodyNearlyIncompressible(umat, f_sil, bulk=mat["bulk"])
    paper = felupe.SolidBody(felupe.NeoHookeCompressible(mu=mat["paper_mu"], lmbda=mat["paper_lambda"]), f_pap)
    load = felupe.SolidBodyPressure(f_bnd)
    items = [body, paper, load]
    gaps = []
    if contact:
        if um.dim != 2:
            raise NotImplementedError("SmoothedGapContact is 2D only")
        eps = 100.0 * mat["mu0"] / 1.0 if eps is None else float(eps)
        item = SmoothedGapContact(f_sil, p, wall_pairs(um), eps, um.h)
        items.append(item)
    bounds = {"clamp": felupe.Boundary(f_all[0], mask=np.isclose(p[:, 0], 0.0))}
    if um.dim == 3:
        bounds["symmetry"] = felupe.Boundary(f_all[0], mask=np.isclose(p[:, 2], 0.0), skip=(1, 1, 0))
    end, prev = um.nodes["backbone_end"], um.nodes["backbone_prev"]
    out = {}

    def record(stepnumber, substepnumber, substep):
        x = p + f_all[0].values
        a, b = x[end].mean(axis=0), x[prev].mean(axis=0)
        out[substepnumber] = -np.degrees(np.arctan2(a[1] - b[1], a[0] - b[0]))
        if contact:
            gaps.append(item.min_gap)

    # the ramp starts at zero so that the cut-back can subdivide the first substep too
    if np.ndim(nsteps):  # the substeps' end pressures themselves (kPa)
        steps = np.r_[0.0, np.sort(np.asarray(nsteps, float))] * 1e-3
    else:
        steps = np.linspace(0.0, max(pressures_kpa), nsteps + 1) * 1e-3
    step = felupe.Step(items=items, ramp={load: steps}, boundaries=bounds)
    # SuperLU raises RuntimeError on a matrix it cannot factorize (contact): cut back then too
    errors = (felupe.NewtonConvergenceError, ArithmeticError, np.linalg.LinAlgError, RuntimeError)
    cutback = felupe.plugins.CutbackPlugin(exceptions=errors)
    # PARDISO returns a perturbed solution for a singular matrix instead of failing: SuperLU with contact
    kwargs = {} if contact or _SPSOLVE is None else {"solver": _SPSOLVE}
    if atol is not None:
        kwargs["check"] = _absolute_check(float(atol))
    status, reason = 0, ""
    try:
        felupe.Job(steps=[step], callback=record, plugins=[cutback]).evaluate(x0=f_all, tol=1e-8, verbose=0, **kwargs)
    except felupe.NewtonConvergenceError as exc:
        if not partial:
            raise
        status, reason = 1, str(exc)
    reached = len(out)  # substeps 0 .. reached - 1 converged
    angles = np.array([out[i] for i in range(reached)])
    q = np.asarray(pressures_kpa, float) * 1e-3
    result = np.where(q <= steps[reached - 1] + 1e-12, np.interp(q, steps[:reached], angles), np.nan)
    if info is not None:
        info["status"], info["reason"], info["p_reached_kpa"] = status, reason, 1e3 * steps[reached - 1]
        info["wall_time_s"] = time.perf_counter() - t0
        info["increments"] = sum(len(v) for v in cutback.load_factors)
        info["cutbacks"] = int(sum(cutback.cutbacks))
        info["min_gap_mm"] = min(gaps, default=np.inf)
    return result
