"""Penalty node-to-segment (2D) / node-to-face (3D) contact between facing walls.

For each slave node s and the master facet it projects onto (parameter xi, shape
functions N_a(xi), unit outward normal n of the master solid), the normal gap
is g = (x_s - sum_a N_a x_a) . n; g < 0 is penetration.  The penalty energy
is  E = sum_s eps A_s / 2 <-g_s>^2  (smoothed near g = 0, see ``smoothing``) with A_s the slave node's tributary area
(reference configuration; per mm of width in 2D) and eps the penalty stiffness
(MPa/mm), so a contact pressure t_N causes a penetration t_N / eps.  The slave
gets the force -eps A t_N n, the master facet's nodes N_a eps A t_N n (no net
force or couple: both act on the line through x_s along n).  The tangent of
these forces (including the rotation of the master normal and the sliding of
the projection point) is taken by vectorised central differences of the local
force of each active slave with respect to its own and its master facet's
coordinates, which keeps Newton's convergence quadratic.
Both walls of a gap act as slave in turn (two-pass), so neither passes
through the other.

Smoothed master normals (2D, ``smooth_normals``): with piecewise-straight
masters the normal jumps at every master node, so a slave that sits on a
master node (a block's corner pressed into the facing wall dents it exactly
there) flips between the two facets from one Newton iteration to the next and
the load step never converges (measured: the 2D unit at h = 0.5 mm stalled at
106 kPa, corner node of one block on a node of the other block's wall).
Instead the normal is interpolated between nodal normals (the mean of the two
facet normals at a node; the facet's own normal at a free edge),
n(xi) = (1 - xi) n_a + xi n_b normalised, and the slave is projected along it:
xi solves (x_s - x(xi)) x n(xi) = 0 (a quadratic in xi).  Gap, normal and
force are then continuous as a slave crosses a master node (a standard fix,
e.g. Wriggers, Computational Contact Mechanics, ch. 9 on smoothing).  The
force is not the gradient of a potential any more (the tangent is not
symmetric); Newton uses its exact finite-difference tangent.
In 3D the same (``smooth_normals``): the nodal normal at a facet's corner is the
mean of the unit normals of the facets of the same part around the node (a
pocket's wall and floor keep their edge), n(xi, eta) = sum_a N_a n_a normalised,
and the slave is projected along it: x(xi, eta) + gamma n(xi, eta) = x_s, three
equations solved by Newton from the orthogonal projection.  A slave's local node
set is then the facet's nodes and every node of the facets around them (up to
16 on a grid), so that the tangent includes the turning of the nodal normals.
Smoothing removes the normal's jump across an edge, not the kink of the
bilinear shape functions there (a slave on a master edge moves its force
between the edge's nodes and the next ones at a rate that jumps).

Summed extensions (2D, frictionless, ``sum_extensions``): a slave whose projection lies past the free edges of two
masters at once (the skin under the gap between two blocks' bottom faces, whose extensions overlap) presses on both,
each with its own faded penalty.  Choosing the nearer one makes the force jump from one block's corner to the other's
where that choice flips.

Friction (``mu`` > 0; frictionless by default, as the paper's Marc model): regularised Coulomb.  A slave
that comes into contact sticks, at the end of that load step (``commit``), to the master point it touches, as
(facet, xi); afterwards a tangential penalty eps_t = ``friction_factor`` * eps per unit area holds it there, with
the force capped at mu times its normal force (slip).  At the end of each accepted step a slipping slave's anchor
is moved along its current facet to the cap's distance behind it (return mapping); a slave that leaves contact
loses its anchor.  The tangent is the same vectorised central difference, over the slave, its current facet's
nodes and the anchor facet's (2D: 4 + 2, 3D: 4 + 4).

Over 400 lines: the penalty law, the facet search and its exact tangent are one algorithm; their conventions (facet orientation, parameter ranges) must change together.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ContactPair", "contact_pairs_from_mesh"]

_XI = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
FD_STEP = 1e-7  # finite-difference step of the contact tangent, relative to the largest coordinate (mm)
#: skip the projections of slaves out of reach of every facet of their pool (same result; benchmarks switch it off
#: to measure what it saves)
REACH_FILTER = True


def _bilinear(ab: np.ndarray):
    """Bilinear shape functions N and their derivatives dN/dxi, dN/deta (..., 4) at parameters ab (..., 2)."""
    xi, eta = ab[..., 0, None], ab[..., 1, None]
    N = 0.25 * (1 + _XI[:, 0] * xi) * (1 + _XI[:, 1] * eta)
    return N, 0.25 * _XI[:, 0] * (1 + _XI[:, 1] * eta), 0.25 * _XI[:, 1] * (1 + _XI[:, 0] * xi)


def _tangent_step(a1: np.ndarray, a2: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Parameter step (..., 2) whose move along the surface tangents a1, a2 best matches the vector r (least squares)."""
    # the 2 x 2 normal equations by Cramer's rule: 2.7x faster than a batched np.linalg.solve (4 544 systems)
    m11, m12, m22 = (a1 * a1).sum(-1), (a1 * a2).sum(-1), (a2 * a2).sum(-1)
    b1, b2 = (r * a1).sum(-1), (r * a2).sum(-1)
    det = m11 * m22 - m12 * m12
    with np.errstate(divide="ignore", invalid="ignore"):  # a degenerate facet gives NaN; _project drops it
        return np.stack([m22 * b1 - m12 * b2, m11 * b2 - m12 * b1], -1) / det[..., None]


def _window(t: np.ndarray) -> np.ndarray:
    """C1 smoothstep on [0, 1] (0 below, 1 above)."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def tributary_areas(p: np.ndarray, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slave nodes of a facet set and their tributary areas (reference configuration)."""
    x = p[:, facets].transpose(1, 2, 0)
    if p.shape[0] == 2:
        area = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    else:
        area = 0.5 * np.linalg.norm(np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 1]), axis=1)
    nodes, inv = np.unique(facets, return_inverse=True)
    w = np.bincount(inv.ravel(), weights=np.repeat(area / facets.shape[1], facets.shape[1]), minlength=nodes.size)
    return nodes, w


def _chain_neighbours(facets: np.ndarray, part: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """2D: per facet (a, b) of an oriented chain, the node before a and the node after b (-1 at a free edge).

    With ``part`` (an id per facet), a neighbour of another part counts as none: the nodal normal at a
    part's end is its own facet's (a block's corner stays a corner) while the chain stays closed for the
    facets' parameter ranges.
    """
    first = {int(a): k for k, a in enumerate(facets[:, 0])}
    second = {int(b): k for k, b in enumerate(facets[:, 1])}
    same = (lambda k, j: True) if part is None else (lambda k, j: part[k] == part[j])
    prev = np.array(
        [
            facets[second[int(a)], 0] if int(a) in second and same(k, second[int(a)]) else -1
            for k, a in enumerate(facets[:, 0])
        ],
        dtype=np.int64,
    )
    nxt = np.array(
        [
            facets[first[int(b)], 1] if int(b) in first and same(k, first[int(b)]) else -1
            for k, b in enumerate(facets[:, 1])
        ],
        dtype=np.int64,
    )
    return prev, nxt


def _normal_2d(t: np.ndarray) -> np.ndarray:
    """Unit normal R t = (t_y, -t_x) / |t| of segments t (..., 2): outward for oriented facets."""
    n = np.stack([t[..., 1], -t[..., 0]], axis=-1)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _cross3(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u x v over the last axis (3), written out: 1.4x faster than np.cross (4 544 vectors)."""
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], axis=-1)


def _orthogonal_step(xs: np.ndarray, xm: np.ndarray, ab: np.ndarray, clip: float) -> np.ndarray:
    """One Gauss-Newton step of the closest-point parameters ab (nc, 2) of xs (nc, 3) on facets xm (nc, 4, 3)."""
    N, dxi, deta = _bilinear(ab)
    a1, a2 = np.einsum("ca,cai->ci", dxi, xm), np.einsum("ca,cai->ci", deta, xm)
    return np.clip(ab + _tangent_step(a1, a2, xs - np.einsum("ca,cai->ci", N, xm)), -clip, clip)


def _orthogonal_ab(
    xs: np.ndarray, xm: np.ndarray, iters: int = 10, tol: float | None = None, clip: float = np.inf
) -> np.ndarray:
    """Parameters (nc, 2) of the closest point of bilinear facets xm (nc, 4, 3) to points xs (nc, 3), from the centre.

    ``iters`` Gauss-Newton steps, each parameter bounded by ``clip``.  With ``tol``, a projection whose step falls
    below it stops and only the others go on (most converge in a few steps; a far point on a warped facet only
    linearly); without, every one takes all steps, so that finite-difference copies stop alike.
    """
    ab = np.zeros((xs.shape[0], 2))
    if tol is None:
        for _ in range(iters):
            ab = _orthogonal_step(xs, xm, ab, clip)
        return ab
    live = np.arange(ab.shape[0])
    for _ in range(iters):
        new = _orthogonal_step(xs[live], xm[live], ab[live], clip)
        moved = np.abs(new - ab[live]).max(axis=1) >= tol
        ab[live] = new
        live = live[moved]
        if not live.size:
            break
    return ab


def _facet_normals_3d(Xf: np.ndarray) -> np.ndarray:
    """Unit normals (..., 3) of bilinear facets Xf (..., 4, 3) at their centres: along the cross product of the
    diagonals."""
    return _unit(_cross3(Xf[..., 2, :] - Xf[..., 0, :], Xf[..., 3, :] - Xf[..., 1, :]))


def _nodal_normals_3d(nf: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Unit nodal normals (..., 4, 3) of a facet's corners: the mean of the unit normals nf (..., 4, K, 3) of the K
    facets around each corner, of which mask (..., 4, K) says which are real."""
    return _unit((nf * mask[..., None]).sum(axis=-2))


def _smooth_step(xs, xm, nn, ab, gam):
    """One Newton step on x(ab) + gamma n(ab) = xs (see ``_smooth_projection_3d``): new ab, gamma and the step."""
    N, dxi, deta = _bilinear(ab)
    Nc, dxic, detac = _bilinear(np.clip(ab, -1.0, 1.0))
    on = (np.abs(ab) <= 1.0).astype(float)  # the normal's parameter derivative is zero where it is held
    nhat = np.einsum("...a,...ai->...i", Nc, nn)
    dn1 = np.einsum("...a,...ai->...i", dxic, nn) * on[..., :1]
    dn2 = np.einsum("...a,...ai->...i", detac, nn) * on[..., 1:]
    r = np.einsum("...a,...ai->...i", N, xm) + gam[..., None] * nhat - xs
    a1 = np.einsum("...a,...ai->...i", dxi, xm) + gam[..., None] * dn1
    a2 = np.einsum("...a,...ai->...i", deta, xm) + gam[..., None] * dn2
    # J = [a1 a2 nhat], J step = -r by Cramer's rule (triple products; cheaper than a batched 3 x 3 solve)
    c23, c31, c12 = _cross3(a2, nhat), _cross3(nhat, a1), _cross3(a1, a2)
    det = np.einsum("...i,...i->...", a1, c23)
    with np.errstate(divide="ignore", invalid="ignore"):  # as in _tangent_step
        step = -np.stack([np.einsum("...i,...i->...", r, c) for c in (c23, c31, c12)], -1) / det[..., None]
    return np.clip(ab + step[..., :2], -3.0, 3.0), gam + step[..., 2], step


def _smooth_projection_3d(
    xs: np.ndarray, xm: np.ndarray, nn: np.ndarray, ab: np.ndarray, iters: int = 6, tol: float | None = None
):
    """Projection of slaves xs (..., 3) onto facets xm (..., 4, 3) along the interpolated normal (3D).

    The normal field of the facet is n(ab) = sum_a N_a(ab) n_a over its nodal normals nn (..., 4, 3), held at its
    edge value past the facet (as the 2D segment's past a free edge).  Newton on x(ab) + gamma n(ab) = xs from the
    orthogonal projection ``ab``, ``iters`` steps.  With ``tol``, each projection stops once its step (parameters
    and gap, mm) is below it and only the others go on (the finite-difference copies run the fixed count, so that
    every copy stops alike).  Returns the parameters (..., 2), unit normal (..., 3) and gap (..., ) in mm.
    """
    nhat = np.einsum("...a,...ai->...i", _bilinear(np.clip(ab, -1.0, 1.0))[0], nn)
    N = _bilinear(ab)[0]
    gam = np.einsum("...i,...i->...", xs - np.einsum("...a,...ai->...i", N, xm), nhat) / np.einsum(
        "...i,...i->...", nhat, nhat
    )
    if tol is None:
        for _ in range(iters):
            ab, gam, _ = _smooth_step(xs, xm, nn, ab, gam)
    else:
        shape = ab.shape[:-1]
        xs_, xm_, nn_ = xs.reshape(-1, 3), xm.reshape(-1, 4, 3), nn.reshape(-1, 4, 3)
        ab, gam = ab.reshape(-1, 2).copy(), gam.reshape(-1).copy()
        live = np.arange(gam.size)
        for _ in range(iters):
            ab[live], gam[live], step = _smooth_step(xs_[live], xm_[live], nn_[live], ab[live], gam[live])
            live = live[np.abs(step).max(axis=1) >= tol]
            if not live.size:
                break
        ab, gam = ab.reshape(shape + (2,)), gam.reshape(shape)
    n = _unit(np.einsum("...a,...ai->...i", _bilinear(np.clip(ab, -1.0, 1.0))[0], nn))
    g = np.einsum("...i,...i->...", xs - np.einsum("...a,...ai->...i", _bilinear(ab)[0], xm), n)
    return ab, n, g


def _range_corner_shapes(lim: np.ndarray) -> np.ndarray:
    """Shape functions (nm, 4 corners, 4 nodes) at the corners of each facet's parameter range ``lim`` (nm, 2, 2)."""
    corners = np.stack([np.stack([lim[:, 0, i], lim[:, 1, j]], axis=-1) for i in (0, 1) for j in (0, 1)], axis=1)
    return _bilinear(corners)[0]


def _facet_reach(xm: np.ndarray, c: np.ndarray, corner_N: np.ndarray) -> np.ndarray:
    """Largest distance (nm,) from a bilinear facet's centroid ``c`` to its points over its parameter range, mm: at a
    corner of the range (shape functions ``corner_N``; the distance is convex in each parameter)."""
    pts = np.einsum("mca,mai->mci", corner_N, xm)
    return np.linalg.norm(pts - c[:, None, :], axis=-1).max(axis=1) * (1.0 + 1e-6) + 1e-6


def _segment_2d(X: np.ndarray, has_prev: np.ndarray, has_next: np.ndarray):
    """Projection of slaves onto master segments along the interpolated normal.

    X (k, 5, 2) = slave, a, b, node before a, node after b (mm).  Nodal normals:
    n_a = mean of the facet normals at a (the facet's own at a free edge), same
    for b.  xi solves (x_s - x_a - xi t) x ((1 - xi) n_a + xi n_b) = 0, the
    root near the straight projection; past a free edge the normal stays the
    edge normal.  Returns xi (k,), unit normal n(xi) (k, 2), gap g (k,) in mm.
    """
    xs, xa, xb, xp, xq = (X[:, i] for i in range(5))
    t = xb - xa
    nf = _normal_2d(t)
    na = np.where(has_prev[:, None], _unit(_normal_2d(xa - xp) + nf), nf)
    nb = np.where(has_next[:, None], _unit(_normal_2d(xq - xb) + nf), nf)
    d0, dn = xs - xa, nb - na
    A, B, C = -_cross(t, dn), _cross(d0, dn) - _cross(t, na), _cross(d0, na)
    disc = np.sqrt(np.maximum(B * B - 4.0 * A * C, 0.0))
    den = B + np.where(B >= 0, 1.0, -1.0) * disc
    xi = -2.0 * C / np.where(np.abs(den) > 1e-300, den, 1e-300)
    # past a free edge: the edge's own normal, i.e. the straight projection
    xi = np.where((xi < 0) & ~has_prev, C / _cross(t, na), xi)
    xi = np.where((xi > 1) & ~has_next, _cross(d0, nb) / _cross(t, nb), xi)
    xn = np.where((xi < 0) & ~has_prev, 0.0, np.where((xi > 1) & ~has_next, 1.0, xi))
    n = na + xn[:, None] * dn
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    g = np.einsum("ki,ki->k", d0 - xi[:, None] * t, n)
    return xi, n, g


def _excluded(facets: np.ndarray, nodes: np.ndarray, parts: np.ndarray | None = None) -> list[set]:
    """Per node, the facets of ``facets`` it must not pair with.

    Those that touch its star's nodes (the star of a node is the set of facets
    containing it: a facet that shares a node with the star lies next to the
    node on the same surface, where a gap is meaningless) and, with ``parts``
    (a part id per facet), every facet of the parts the node belongs to (a
    wall never contacts itself; near a convex corner of one block the ring
    alone would let a node see its own block's next facets from behind).
    """
    by_node: dict[int, set] = {}
    for k, f in enumerate(facets):
        for a in f:
            by_node.setdefault(int(a), set()).add(k)
    by_part = {} if parts is None else {int(q): set(np.flatnonzero(parts == q).tolist()) for q in np.unique(parts)}
    out = []
    for s in nodes:
        star = by_node[int(s)]
        ring = {int(a) for k in star for a in facets[k]}
        excl = set().union(*(by_node[a] for a in ring))
        if parts is not None:
            excl |= set().union(*(by_part[int(parts[k])] for k in star))
        out.append(excl)
    return out


class ContactPair:
    """Penalty contact of slave nodes against master facets, each slave against its own pool of facets.

    Two ways to build one (``evaluate`` vectorises over all of it):

    * ``ContactPair(p, slave_facets, master_facets)``: the nodes of the k-th
      slave wall against the k-th master wall only (walls must not share
      nodes), e.g. the actuator's skin against the finger's.
    * ``ContactPair.self_contact(p, surfaces)``: every node of a surface
      against every facet of the same surface except the facets next to it
      (``_excluded``: a facet never pairs with its own nodes or its
      neighbours), e.g. the closed wall loop of a pocket or the U of a gap, so
      that any two parts of it that meet are kept apart, opposite walls as well
      as a corner folding onto itself.

    Parameters
    ----------
    p : ndarray (dim, nnodes)
        Reference coordinates (for tributary areas), mm.
    slave_facets, master_facets : ndarray or list of ndarray
        Outward-oriented facets of the facing walls.
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
    smooth_normals : bool
        Interpolate the master normal between nodal normals (continuous across
        master nodes in 2D, nodes and edges in 3D); False = each facet's own
        normal (kinks at nodes and edges).
    penalty_factor : float
        This pair's penalty is ``penalty_factor`` times the eps passed to
        ``evaluate`` (the model's), e.g. a softer contact with flesh.
    """

    def __init__(
        self,
        p: np.ndarray,
        slave_facets,
        master_facets,
        search: float = 1.0,
        extend: float = 0.5,
        smoothing: float = 0.0,
        smooth_normals: bool = True,
        penalty_factor: float = 1.0,
        sum_extensions: bool = False,
    ):
        slaves = slave_facets if isinstance(slave_facets, (list, tuple)) else [slave_facets]
        masters = master_facets if isinstance(master_facets, (list, tuple)) else [master_facets]
        if len(slaves) != len(masters):
            raise ValueError("one master wall per slave wall")
        trib = [tributary_areas(p, f) for f in slaves]
        starts = np.cumsum([0] + [f.shape[0] for f in masters])
        pools = [[np.arange(starts[k], starts[k + 1])] * nd.size for k, (nd, _) in enumerate(trib)]
        self._setup(
            p,
            np.concatenate([nd for nd, _ in trib]),
            np.concatenate([a for _, a in trib]),
            np.concatenate(masters),
            [q for pool in pools for q in pool],
            search,
            extend,
            smoothing,
            smooth_normals,
            penalty_factor,
        )
        self.sum_extensions = bool(sum_extensions)

    @classmethod
    def self_contact(
        cls,
        p: np.ndarray,
        surfaces,
        search: float = 1.0,
        extend: float = 0.5,
        smoothing: float = 0.0,
        smooth_normals: bool = True,
        penalty_factor: float = 1.0,
        parts=None,
    ) -> "ContactPair":
        """Self-contact of each surface (list of outward-oriented facet arrays; surfaces must not share nodes).

        ``parts``: per surface a part id per facet (or None): see ``_excluded``.
        """
        obj = cls.__new__(cls)
        slave, area, pools, start, part_ids = [], [], [], 0, []
        for i, f in enumerate(surfaces):
            # globally unique part ids (a surface without parts is one part)
            q = np.zeros(f.shape[0], int) if parts is None or parts[i] is None else np.asarray(parts[i], int)
            part_ids.append(q + (1 + max((int(x.max()) for x in part_ids), default=-1)))
            nd, a = tributary_areas(p, f)
            excl = _excluded(f, nd, None if parts is None else parts[i])
            allf = np.arange(f.shape[0])
            pool = [start + np.setdiff1d(allf, sorted(e)) for e in excl]
            # on a coarse mesh a small surface (a pocket two elements around) can lie wholly next to a node:
            # such a node has nothing it may touch and is no slave
            keep = np.array([q.size > 0 for q in pool], bool)
            pools += [q for q, k in zip(pool, keep) if k]
            slave.append(nd[keep])
            area.append(a[keep])
            start += f.shape[0]
        obj._setup(
            p,
            np.concatenate(slave),
            np.concatenate(area),
            np.concatenate(list(surfaces)),
            pools,
            search,
            extend,
            smoothing,
            smooth_normals,
            penalty_factor,
            master_part=np.concatenate(part_ids),
        )
        return obj

    def _setup(
        self,
        p,
        slave,
        area,
        master_facets,
        pools,
        search,
        extend,
        smoothing,
        smooth_normals,
        penalty_factor,
        master_part=None,
    ):
        """Common set-up: slave nodes (ns,), their areas, master facets and per slave its facet ids."""
        self.dim = p.shape[0]
        self.penalty_factor = float(penalty_factor)
        self.smoothing = float(smoothing)
        self.smooth_normals = bool(smooth_normals)
        self.slave = np.asarray(slave)
        self.area = np.asarray(area, float)
        self.master = master_facets
        # per slave the facet ids it may pair with, padded by repeating its first (masked by a large distance)
        width = max((q.size for q in pools), default=1)
        self._pool = (
            np.stack([np.concatenate([q, np.full(width - q.size, q[0])]) for q in pools])
            if pools
            else np.zeros((0, width), np.int64)
        )
        self._pad = np.where(np.arange(width)[None, :] >= np.array([q.size for q in pools])[:, None], 1e9, 0.0)
        self.search = search
        # Coulomb friction (mu = 0: none): per slave the master point it sticks to, as (facet, parameters), set
        # at the accepted step where it came into contact (`commit`); -1 = none
        self.mu = 0.0
        self.friction_factor = 0.1
        #: 2D, frictionless: a slave in the extensions of two walls' free edges at once (the skin under the gap between
        #: two blocks) presses on both, each with its faded penalty, instead of on the nearer one (see
        #: ``_extension_partners``)
        self.sum_extensions = False
        self.anchor_facet = -np.ones(self.slave.size, dtype=np.int64)
        self.anchor_xi = np.zeros((self.slave.size, 2))
        # allowed parameter range per master facet: [0, 1] (2D) / [-1, 1]^2 (3D), widened at free edges
        nodes, cnt = np.unique(master_facets, return_counts=True)
        edge_count = 1 if self.dim == 2 else 2
        on_edge = np.isin(master_facets, nodes[cnt <= edge_count])
        if self.dim == 2:
            self.lo = np.where(on_edge[:, 0], -extend, 0.0)
            self.hi = np.where(on_edge[:, 1], 1.0 + extend, 1.0)
            self.prev, self.next = _chain_neighbours(master_facets, master_part)
            # per slave and pool facet, the facet's reach past its free edges as a share of its length, with the
            # 1e-6 slack of the range test in `_near_candidates_2d` (the search's reach filter)
            self._reach_share = (np.maximum(np.maximum(-self.lo, self.hi - 1.0), 0.0) + 1e-6)[self._pool]
            if not self.smooth_normals:
                self.prev[:] = -1
                self.next[:] = -1
        else:
            # per facet and reference direction (xi, eta) the range [lo, hi]: widened only across a free
            # edge (an edge of no other master facet), so that coplanar faces meeting at a corner are not
            # extended over each other
            edges = [(0, 1), (1, 2), (2, 3), (3, 0)]  # at eta = -1, xi = +1, eta = +1, xi = -1
            keys = np.sort(np.stack([master_facets[:, list(e)] for e in edges], axis=1), axis=2)  # (nm, 4, 2)
            _, inv, cnt = np.unique(keys.reshape(-1, 2), axis=0, return_inverse=True, return_counts=True)
            free = (cnt[inv.ravel()] == 1).reshape(-1, 4)
            wide = 1.0 + 2.0 * extend
            self.lim = np.stack(
                [
                    np.stack([np.where(free[:, 3], -wide, -1.0), np.where(free[:, 1], wide, 1.0)], -1),
                    np.stack([np.where(free[:, 0], -wide, -1.0), np.where(free[:, 2], wide, 1.0)], -1),
                ],
                axis=1,
            )  # (nm, 2 directions, lo/hi)
            self._corner_N = _range_corner_shapes(self.lim)
            if self.smooth_normals:
                self._setup_nodal_normals_3d(master_part)

    def _setup_nodal_normals_3d(self, master_part) -> None:
        """3D: per master facet and corner the facets whose normals average to that corner's nodal normal.

        The facets around the corner node of the same part (a block's wall and floor keep their edge), as global
        ids ``_adj`` (nm, 4, K) with ``_adj_mask``, and the facet's stencil: its own four nodes first, then every
        other node of those facets (``_patch`` (nm, W), padded with its first node), with ``_adj_local``
        (nm, 4, K, 4) the adjacent facets' nodes as positions in the local node set (slave first, so 1 + patch
        index).
        """
        mf = self.master
        part = np.zeros(mf.shape[0], np.int64) if master_part is None else np.asarray(master_part)
        star: dict[tuple, list] = {}
        for k, f in enumerate(mf):
            for a in f:
                star.setdefault((int(a), int(part[k])), []).append(k)
        K = max(len(v) for v in star.values())
        adj = np.repeat(np.arange(mf.shape[0])[:, None, None], 4, axis=1).repeat(K, axis=2)
        mask = np.zeros(adj.shape, bool)
        patches = []
        for k, f in enumerate(mf):
            nodes = [int(a) for a in f]
            for c, a in enumerate(f):
                around = star[(int(a), int(part[k]))]
                adj[k, c, : len(around)] = around
                mask[k, c, : len(around)] = True
                for j in around:
                    nodes += [int(b) for b in mf[j] if int(b) not in nodes]
            patches.append(nodes)
        W = max(len(q) for q in patches)
        self._patch = np.array([q + [q[0]] * (W - len(q)) for q in patches], np.int64)
        pos = [{a: i + 1 for i, a in reversed(list(enumerate(q)))} for q in self._patch.tolist()]
        self._adj, self._adj_mask = adj, mask
        self._adj_local = np.array(
            [[[[pos[k][int(b)] for b in mf[j]] for j in adj[k, c]] for c in range(4)] for k in range(mf.shape[0])],
            np.int64,
        )

    def _project(self, x: np.ndarray):
        """Closest master facet per slave: (facet index, N (ns, nfn), n (ns, dim), g (ns,), inside)."""
        xs = x[:, self.slave].T  # (ns, dim)
        xm = x[:, self.master].transpose(1, 2, 0)  # (nm, nfn, dim)
        if self.dim == 2:
            return self._project_2d(x, xs)
        # 3D: candidate facets = the 4 nearest centroids, then Newton for (xi, eta)
        c = xm.mean(axis=1)
        dc = np.linalg.norm(xs[:, None, :] - c[self._pool], axis=2) + self._pad  # (ns, width)
        # A slave within the search distance of a facet's (extended) range lies within reach + search of its
        # centroid; slaves beyond that for every facet of their pool cannot be in contact and skip the projections
        # (most slaves, most of the time).  The same result as projecting them: out of reach either way.
        if REACH_FILTER:
            near_any = (dc - _facet_reach(xm, c, self._corner_N)[self._pool] <= self.search + 1e-9).any(axis=1)
            if not near_any.all():
                return self._project_3d_subset(xs, xm, dc, near_any)
        return self._project_3d(xs, xm, dc, self._pool)

    def _project_3d_subset(self, xs, xm, dc, live):
        """``_project_3d`` for the slaves ``live`` only; the others out of reach (g = inf, not inside)."""
        ns = xs.shape[0]
        m = self._pool[:, 0].copy()
        N = np.full((ns, 4), 0.25)
        n = np.zeros((ns, 3))
        g = np.full(ns, np.inf)
        inside = np.zeros(ns, bool)
        idx = np.flatnonzero(live)
        if idx.size:
            m[idx], N[idx], n[idx], g[idx], inside[idx] = self._project_3d(xs[idx], xm, dc[idx], self._pool[idx])
        return m, N, n, g, inside

    def _project_3d(self, xs: np.ndarray, xm: np.ndarray, dc: np.ndarray, pool: np.ndarray):
        """3D closest master facet of slaves xs (ns, 3) among the 4 of their ``pool`` with the nearest centroids
        (distances ``dc``): (facet index, N (ns, 4), n (ns, 3), g (ns,), inside)."""
        k = min(4, dc.shape[1])
        cand = np.take_along_axis(pool, np.argpartition(dc, k - 1, axis=1)[:, :k], axis=1)  # (ns, k)
        X = xm[cand]  # (ns, k, 4, 3)
        # each candidate's closest point, 8 steps (1e-10: round-off on these nearly flat facets)
        ab = _orthogonal_ab(np.repeat(xs, k, axis=0), X.reshape(-1, 4, 3), 8, tol=1e-10, clip=3.0).reshape(
            cand.shape + (2,)
        )
        N, dxi, deta = _bilinear(ab)
        a1, a2 = np.einsum("ska,skai->ski", dxi, X), np.einsum("ska,skai->ski", deta, X)
        xp = np.einsum("ska,skai->ski", N, X)
        nrm = _cross3(a1, a2)
        nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
        g = np.einsum("ski,ski->sk", xs[:, None, :] - xp, nrm)
        # a degenerate candidate (its 2 x 2 system singular: NaN from Cramer's rule) is out of reach
        g = np.where(np.isfinite(g) & np.isfinite(ab).all(axis=-1), g, np.inf)
        if self.smooth_normals:
            # along smoothed normals only for slaves within twice the search radius of a candidate (the rest are
            # out of reach either way): most slaves are far from every wall most of the time
            near = np.flatnonzero(np.abs(g).min(axis=1) <= 2.0 * self.search)
            if near.size:
                nodal = _nodal_normals_3d(_facet_normals_3d(xm)[self._adj], self._adj_mask)  # (nm, 4, 3)
                nn = nodal[cand[near]]
                xsn = np.broadcast_to(xs[near, None, :], X[near].shape[:2] + (3,))
                ab[near], nrm[near], g[near] = _smooth_projection_3d(xsn, X[near], nn, ab[near], tol=1e-10)
                N = _bilinear(ab)[0]
        lim = self.lim[cand]  # (ns, k, 2, 2)
        inside = np.all((ab >= lim[..., 0] - 1e-6) & (ab <= lim[..., 1] + 1e-6), axis=-1) & np.isfinite(g)
        # as in 2D: facets whose (extended) range holds the projection first, then the one nearest to the
        # projection clipped onto the facet itself, so that an edge facet's extension never wins over the facet a
        # slave is on (along smoothed normals the projection is not the closest point: a slave on an edge can be
        # nearer, by a hair, to the neighbour it does not project into)
        abc = np.clip(ab, -1.0, 1.0)
        Nc = _bilinear(abc)[0]
        dist = np.linalg.norm(xs[:, None, :] - np.einsum("ska,skai->ski", Nc, X), axis=-1)
        dist = np.where(np.isfinite(g), dist, np.inf)
        j = np.argmin(np.where(inside, dist, dist + 1e6), axis=1)
        s = np.arange(xs.shape[0])
        return cand[s, j], N[s, j], nrm[s, j], g[s, j], inside[s, j]

    def _nodes_2d(self, m: np.ndarray) -> np.ndarray:
        """Local master nodes (k, 4) of facets m: a, b, the node before a, the node after b.

        A missing neighbour (free edge) is replaced by a or b itself; ``_segment_2d``
        then ignores it (flags from ``self.prev/next``).
        """
        a, b = self.master[m, 0], self.master[m, 1]
        pa = np.where(self.prev[m] >= 0, self.prev[m], a)
        qb = np.where(self.next[m] >= 0, self.next[m], b)
        return np.stack([a, b, pa, qb], axis=1)

    def _project_2d(self, x: np.ndarray, xs: np.ndarray):
        """2D: closest master facet per slave among the 3 nearest by straight clipped distance."""
        return self._pick_2d(self._candidates_2d(x, xs))[0]

    @staticmethod
    def _pick_2d(cands):
        """The chosen facet per slave from ``_candidates_2d``: (facet, N, n, g, inside), and its column j."""
        cand, xi, n, g, within, dist = cands
        j = np.argmin(np.where(within, dist, dist + 1e6), axis=1)
        s = np.arange(cand.shape[0])
        xi_s = xi[s, j]
        N = np.stack([1.0 - xi_s, xi_s], axis=1)
        return (cand[s, j], N, n[s, j], g[s, j], within[s, j]), j

    def _extension_partners(self, cands, j: np.ndarray):
        """2D: (slave index, facet, gap) of every slave whose projection lies past the free edge of a facet other
        than its chosen one (column ``j`` of ``_candidates_2d``'s ``cands``); of several, the nearest.

        Between two blocks the bottom faces' extensions overlap; a skin node under the gap would otherwise press on
        whichever block's corner is nearer by straight distance, and its force would jump from one corner to the
        other when that flips (measured: a two-cycle of Newton between the two corners, the finger-actuator check of
        TGE3 stalling at 29 % of its load).  Summed, each contribution fades to zero at its own extension's end, so
        the force stays continuous.
        """
        cand, xi, _, g, within, dist = cands
        ext = within & (((xi < 0) & (self.lo[cand] < 0)) | ((xi > 1) & (self.hi[cand] > 1)))
        other = ext & (cand != cand[np.arange(cand.shape[0]), j][:, None])
        k = np.argmin(np.where(other, dist, np.inf), axis=1)
        has = other.any(axis=1)
        idx = np.flatnonzero(has)
        return idx, cand[idx, k[idx]], g[idx, k[idx]]

    def _candidates_2d(self, x: np.ndarray, xs: np.ndarray):
        """The 3 nearest facets per slave by straight clipped distance: (facet, xi, n, g, within range, distance).

        A slave whose distance to every facet of its pool exceeds the search radius plus that facet's extension past
        a free edge is out of reach (g = inf, not within), its projections skipped (60 % of the FEA check's
        self-contact slaves at rest, 2.5 mm mesh).
        That is exact where a projection's |g| is the slave's distance to its foot point, which holds on the walls
        of the unit and the finger (turns of at most 90 degrees between facets: the unit's 2D datasets of a default
        run are the same to 1e-9 with and without it, and the check's solves replayed alike); on a master folded by
        more than about 108 degrees the interpolated
        normal can report a small gap for a slave well away from the facet, a spurious contact the filter drops.
        Distances in mm.
        """
        ns = xs.shape[0]
        xa0 = x[:, self.master[self._pool, 0]].transpose(1, 2, 0)  # (ns, width, 2)
        xb0 = x[:, self.master[self._pool, 1]].transpose(1, 2, 0)
        t0 = xb0 - xa0
        d = xs[:, None, :] - xa0
        tt = np.einsum("smi,smi->sm", t0, t0)
        c = np.clip(np.einsum("smi,smi->sm", d, t0) / tt, 0.0, 1.0)
        near = np.linalg.norm(d - c[..., None] * t0, axis=2) + self._pad
        k = min(3, near.shape[1])
        if REACH_FILTER:
            live = (near - self._reach_share * np.sqrt(tt) <= self.search + 1e-9).any(axis=1)
            if not live.all():
                cand = self._pool[:, :k].copy()
                xi, g = np.full((ns, k), 0.5), np.full((ns, k), np.inf)
                n, within, dist = np.zeros((ns, k, 2)), np.zeros((ns, k), bool), np.full((ns, k), np.inf)
                idx = np.flatnonzero(live)
                if idx.size:
                    sub = self._near_candidates_2d(x, xs[idx], self._pool[idx], near[idx], k)
                    for full, part in zip((cand, xi, n, g, within, dist), sub):
                        full[idx] = part
                return cand, xi, n, g, within, dist
        return self._near_candidates_2d(x, xs, self._pool, near, k)

    def _near_candidates_2d(self, x: np.ndarray, xs: np.ndarray, pool: np.ndarray, near: np.ndarray, k: int):
        """``_candidates_2d`` for slaves xs (ns, 2) with their ``pool`` and straight clipped distances ``near`` (mm)."""
        ns = xs.shape[0]
        cand = np.take_along_axis(pool, np.argpartition(near, k - 1, axis=1)[:, :k], axis=1)  # (ns, k)
        mn = self._nodes_2d(cand.ravel())
        X = np.concatenate([np.repeat(xs, k, axis=0)[:, None, :], x[:, mn].transpose(1, 2, 0)], axis=1)
        xi, n, g = _segment_2d(X, self.prev[cand.ravel()] >= 0, self.next[cand.ravel()] >= 0)
        xi, n, g = xi.reshape(ns, k), n.reshape(ns, k, 2), g.reshape(ns, k)
        xa, t = X[:, 1].reshape(ns, k, 2), (X[:, 2] - X[:, 1]).reshape(ns, k, 2)
        # facets whose (extended) range holds the projection first, then the one
        # nearest to the point clipped onto it (so an extension never beats the
        # facet a slave is on); a slave near a master node projects inside exactly
        # one of its two facets, and both give the same gap at the node
        within = (xi >= self.lo[cand] - 1e-6) & (xi <= self.hi[cand] + 1e-6)
        dist = np.linalg.norm(xs[:, None, :] - xa - np.clip(xi, 0.0, 1.0)[..., None] * t, axis=2)
        return cand, xi, n, g, within, dist

    def _local_force(self, X: np.ndarray, eps_area: np.ndarray, lim: tuple, return_normal: bool = False):
        """Penalty force eps A w g dg (nc, nn*dim) for local node sets X (nc, nn, dim) = slave + master facet.

        w is 1 on the master facet and fades smoothly to 0 over its extension
        past a free edge (``lim``: (lo, hi, has_prev, has_next) in 2D, the
        half-width in 3D), so the force stays continuous when a slave slides off
        the master's end.  2D node sets are (slave, a, b, node before a, node
        after b); the last two only turn the nodal normals and get no force.
        """
        xs, xm = X[:, 0], X[:, 1:]
        if self.dim == 2:
            lo, hi, has_prev, has_next = lim
            xi, n, _ = _segment_2d(X, has_prev, has_next)
            N = np.stack([1.0 - xi, xi, np.zeros_like(xi), np.zeros_like(xi)], axis=1)
            # the fade applies only past a free edge (an extension); at an end shared with the next facet
            # (lo = 0 / hi = 1) a projection a round-off outside still carries the full force, else a slave
            # sitting on a master node would lose its force whenever the tie between the two facets flips
            w = np.where((xi < 0) & (lo < 0), _window((xi - lo) / np.maximum(-lo, 1e-12)), 1.0)
            w = w * np.where((xi > 1) & (hi > 1), _window((hi - xi) / np.maximum(hi - 1.0, 1e-12)), 1.0)
        else:
            xm = X[:, 1:5]  # the facet's own nodes; with smoothed normals the rest of the stencil turns them
            if len(lim) >= 3:  # smoothed normals: (limits, adjacent facets' local nodes, their mask[, start])
                ab, n = self._smooth_local_3d(X, lim)
                N = _bilinear(ab)[0]
            else:
                ab = _orthogonal_ab(xs, xm)
                N, dxi, deta = _bilinear(ab)
                n = _cross3(np.einsum("ca,cai->ci", dxi, xm), np.einsum("ca,cai->ci", deta, xm))
                n /= np.linalg.norm(n, axis=1, keepdims=True)
            L = lim[0]  # (nc, 2 directions, lo/hi)
            lo, hi = L[..., 0], L[..., 1]
            # the penalty fades to 0 across the widened range past a free edge (continuous as a slave slides off)
            w = np.prod(
                np.where((ab > 1) & (hi > 1), _window((hi - ab) / np.maximum(hi - 1.0, 1e-12)), 1.0)
                * np.where((ab < -1) & (lo < -1), _window((ab - lo) / np.maximum(-1.0 - lo, 1e-12)), 1.0),
                axis=1,
            )
        g = np.einsum("ci,ci->c", xs - np.einsum("ca,cai->ci", N, xm), n)
        coef = np.zeros(X.shape[:2])  # stencil nodes past the facet's own only turn the normal: no force
        coef[:, 0] = 1.0
        coef[:, 1 : 1 + N.shape[1]] = -N
        dg = (coef[:, :, None] * n[:, None, :]).reshape(X.shape[0], -1)
        d = self.smoothing
        # C1 penalty: linear eps (g - d/2) in penetration, -eps (d - g)^2 / (2 d) for 0 < g < d, 0 beyond
        if d > 0:
            t = np.where(g <= 0.0, g - 0.5 * d, -((np.clip(d - g, 0.0, None)) ** 2) / (2.0 * d))
        else:
            t = np.minimum(g, 0.0)
        f = (eps_area * w * t)[:, None] * dg
        return (f, n) if return_normal else f

    def _smooth_local_3d(self, X: np.ndarray, lim: tuple):
        """Parameters (nc, 2) and unit normal (nc, 3) of slaves X[:, 0] on their facets along smoothed normals.

        With a fourth entry in ``lim`` (the parameters found at the unperturbed node set), Newton starts there and
        takes three iterations: the unperturbed set and its finite-difference copies (1e-7 mm away) converge to
        round-off.
        """
        xs, xm = X[:, 0], X[:, 1:5]
        warm = len(lim) == 4
        ab = lim[3] if warm else _orthogonal_ab(xs, xm)
        nf = _facet_normals_3d(X[np.arange(X.shape[0])[:, None, None, None], lim[1]])  # (nc, 4, K, 3)
        ab, n, _ = _smooth_projection_3d(xs, xm, _nodal_normals_3d(nf, lim[2]), ab, iters=3 if warm else 6)
        return ab, n

    def _anchor_weights(self, xi0: np.ndarray) -> np.ndarray:
        """Shape functions (nc, 2 or 4) of the anchor facet at its parameters xi0 (nc, 2)."""
        if self.dim == 2:
            return np.stack([1.0 - xi0[:, 0], xi0[:, 0]], axis=1)
        return _bilinear(xi0)[0]

    def _friction_terms(self, X: np.ndarray, eps_area: np.ndarray, lim: tuple, xi0: np.ndarray):
        """Normal force fn (nc, 5 dim), normal n, normal force magnitude pn, anchor weights W and the slave's
        tangential offset dt (mm) from its anchor, for node sets X = slave, current facet (4 nodes), anchor facet."""
        n0 = X.shape[1] - (2 if self.dim == 2 else 4)
        fn, n = self._local_force(X[:, :n0], eps_area, lim, return_normal=True)
        d = self.dim
        pn = np.abs(np.einsum("ci,ci->c", fn[:, :d], n))  # the slave's share of the penalty force
        W = self._anchor_weights(xi0)
        dv = X[:, 0] - np.einsum("ca,cai->ci", W, X[:, n0:])
        dt = dv - np.einsum("ci,ci->c", dv, n)[:, None] * n
        return fn, n, pn, W, dt

    def _local_friction(self, X: np.ndarray, eps_area: np.ndarray, lim: tuple, xi0: np.ndarray) -> np.ndarray:
        """Normal penalty force plus Coulomb friction for node sets X (nc, 5 + na, dim).

        Nodes: slave, the current master facet (2D: a, b, node before a, node after b; 3D: its four nodes) and
        the anchor facet (na = 2 / 4 nodes).  The slave's tangential offset from its anchor (the anchor facet's
        point at parameters xi0) is held by a penalty eps_t = friction_factor * eps per unit area, capped at mu
        times the normal force (slip).
        """
        fn, _, pn, W, dt = self._friction_terms(X, eps_area, lim, xi0)
        ft = self.friction_factor * eps_area[:, None] * dt  # residual = energy gradient: + k dt on the slave
        mag = np.linalg.norm(ft, axis=1)
        cap = self.mu * pn
        ft = ft * np.where(mag > cap, cap / np.maximum(mag, 1e-300), 1.0)[:, None]
        d = self.dim
        n0 = fn.shape[1] // d
        f = np.zeros((X.shape[0], X.shape[1] * d))
        f[:, : n0 * d] = fn
        f[:, :d] += ft
        f[:, n0 * d :] -= (W[:, :, None] * ft[:, None, :]).reshape(X.shape[0], -1)
        return f

    def _friction_on(self) -> bool:
        return self.mu > 0.0

    def _stencil(self, idx: np.ndarray, m: np.ndarray):
        """Local node sets (slave, current facet[, anchor facet]) and limits of slaves ``idx`` on facets ``m``."""
        if self.dim == 2:  # slave, facet (a, b) and the neighbours that set its nodal normals
            nodes = np.concatenate([self.slave[idx, None], self._nodes_2d(m)], axis=1)
            lim = (self.lo[m], self.hi[m], self.prev[m] >= 0, self.next[m] >= 0)
            own = nodes[:, 1:3]
        elif self.smooth_normals:  # slave, the facet's nodes, then the nodes that set its nodal normals
            nodes = np.concatenate([self.slave[idx, None], self._patch[m]], axis=1)
            lim = (self.lim[m], self._adj_local[m], self._adj_mask[m])
            own = nodes[:, 1:5]
        else:
            nodes = np.concatenate([self.slave[idx, None], self.master[m]], axis=1)
            lim = (self.lim[m],)
            own = nodes[:, 1:5]
        if not self._friction_on():
            return nodes, lim, None, None
        # the anchor facet's nodes (the current facet's, with no force, where there is no anchor)
        af = self.anchor_facet[idx]
        has = af >= 0
        anchor = np.where(has[:, None], self.master[np.maximum(af, 0)], own)
        return np.concatenate([nodes, anchor], axis=1), lim, has, np.where(has[:, None], self.anchor_xi[idx], 0.0)

    def _parameters(self, N: np.ndarray) -> np.ndarray:
        """Facet parameters (k, 2) of projections with shape functions N (2D: (xi, 0); 3D: sum_a N_a (xi_a, eta_a))."""
        if self.dim == 2:
            return np.stack([N[:, 1], np.zeros(len(N))], axis=1)
        return N @ _XI

    def commit(self, x: np.ndarray, eps: float) -> None:
        """After an accepted step: slaves in contact keep (or, slipping, drag along) their anchor; others lose it."""
        if not self._friction_on():
            return
        m, N, n, g, inside = self._project(x)
        act = inside & (np.abs(g) <= self.search) & (g < self.smoothing)
        param = self._parameters(N)
        new = act & (self.anchor_facet < 0)
        self.anchor_facet[new], self.anchor_xi[new] = m[new], param[new]
        self.anchor_facet[~act] = -1
        old = np.flatnonzero(act & ~new)
        if not old.size:
            return
        nodes, lim, _, xi0 = self._stencil(old, m[old])
        X = x[:, nodes].transpose(1, 2, 0)
        w = eps * self.penalty_factor * self.area[old]
        _, _, pn, _, dt = self._friction_terms(X, w, lim, xi0)
        slip = self.friction_factor * w * np.linalg.norm(dt, axis=1) > self.mu * pn
        if not slip.any():
            return
        # slip: the new anchor lies on the slave's current facet, the cap's distance behind it
        k = old[slip]
        ell = self.mu * pn[slip] / (self.friction_factor * w[slip])
        delta = -ell[:, None] * dt[slip] / np.linalg.norm(dt[slip], axis=1, keepdims=True)
        p0 = param[k]
        if self.dim == 2:
            t = X[slip, 2] - X[slip, 1]
            p1 = p0[:, 0] + np.einsum("ci,ci->c", delta, t) / np.einsum("ci,ci->c", t, t)
            self.anchor_xi[k] = np.stack([np.clip(p1, 0.0, 1.0), np.zeros_like(p1)], axis=1)
        else:
            xm = X[slip, 1:5]
            _, dxi, deta = _bilinear(p0)
            a1, a2 = np.einsum("ca,cai->ci", dxi, xm), np.einsum("ca,cai->ci", deta, xm)
            self.anchor_xi[k] = np.clip(p0 + _tangent_step(a1, a2, delta), -1.0, 1.0)
        self.anchor_facet[k] = m[k]

    def evaluate(self, x: np.ndarray, eps: float, tangent: bool = True):
        """Penalty forces (to add to the residual) and tangent for current nodes ``x``.

        Returns ``(dofs (nc, ndl), f (nc, ndl), K (nc, ndl, ndl) or None, gmin)`` for
        the active slaves, with ``gmin`` the smallest gap over all slaves that
        project inside a master facet (negative = largest penetration, mm).
        """
        dim = self.dim
        partners = self.sum_extensions and dim == 2 and not self._friction_on()
        if partners:  # one candidate search for the chosen facets and the partners
            cands = self._candidates_2d(x, x[:, self.slave].T)
            (m, N, n, g, inside), j = self._pick_2d(cands)
        else:
            m, N, n, g, inside = self._project(x)
        ok = inside & (np.abs(g) <= self.search)
        gmin = float(g[ok].min()) if ok.any() else np.inf
        act = ok & (g < self.smoothing)
        idx, fac = np.flatnonzero(act), m[act]
        if partners:
            i2, m2, g2 = self._extension_partners(cands, j)
            keep = (np.abs(g2) <= self.search) & (g2 < self.smoothing)
            idx, fac = np.concatenate([idx, i2[keep]]), np.concatenate([fac, m2[keep]])
        if not idx.size:
            return np.zeros((0, 0), int), np.zeros((0, 0)), (np.zeros((0, 0, 0)) if tangent else None), gmin
        friction = self._friction_on()
        nodes, lim, has, xi0 = self._stencil(idx, fac)
        X = x[:, nodes].transpose(1, 2, 0)  # (nc, nn, dim)
        w = eps * self.penalty_factor * self.area[idx]
        # a slave without an anchor (it came into contact during this step) gets the normal force alone
        if dim == 3 and len(lim) == 3:  # the projection along smoothed normals, once: the start of every copy's
            lim = lim + (self._smooth_local_3d(X, lim)[0],)
        f = self._friction_or_normal(X, w, lim, has, xi0) if friction else self._local_force(X, w, lim)
        dofs = (dim * nodes[:, :, None] + np.arange(dim)).reshape(nodes.shape[0], -1)
        K = None
        if tangent:
            # all 2*nd perturbed copies in one vectorised batch (central: a slave on a master edge, where the
            # force's rate jumps, gets the mean of the two one-sided rates; forward differences stall the 2D unit)
            nc, nd = f.shape
            step = FD_STEP * max(1.0, float(np.abs(X).max()))
            E = np.eye(nd) * step
            Xf = X.reshape(nc, -1)
            Xb = np.concatenate([Xf[None] + E[:, None, :], Xf[None] - E[:, None, :]])  # (2nd, nc, nd)
            limb = tuple(np.tile(a, (2 * nd,) + (1,) * (a.ndim - 1)) for a in lim)
            if friction:
                hb, xb = np.tile(has, 2 * nd), np.tile(xi0, (2 * nd, 1))
                fb = self._friction_or_normal(Xb.reshape((-1,) + X.shape[1:]), np.tile(w, 2 * nd), limb, hb, xb)
            else:
                fb = self._local_force(Xb.reshape((-1,) + X.shape[1:]), np.tile(w, 2 * nd), limb)
            K = (fb.reshape(2, nd, nc, nd)[0] - fb.reshape(2, nd, nc, nd)[1]) / (2 * step)
            K = K.transpose(1, 2, 0)
        return dofs, f, K, gmin

    def _friction_or_normal(self, X, w, lim, has, xi0):
        """Friction where a slave has an anchor, the normal force alone (padded to the 7-node set) elsewhere."""
        f = self._local_friction(X, w, lim, xi0)
        if (~has).any():
            d = self.dim
            n0 = X.shape[1] - (2 if d == 2 else 4)
            f[~has, n0 * d :] = 0.0
            f[~has, : n0 * d] = self._local_force(X[~has, :n0], w[~has], tuple(a[~has] for a in lim))
        return f

    def energy(self, x: np.ndarray, eps: float) -> float:
        _, _, _, g, inside = self._project(x)
        ok = inside & (np.abs(g) <= self.search) & (g < 0)
        return float(np.sum(0.5 * eps * self.penalty_factor * self.area[ok] * g[ok] ** 2))


def contact_pairs_from_mesh(
    unit_mesh,
    search: float = 1.0,
    extend: float = 0.5,
    smoothing: float = 0.0,
    smooth_normals: bool = True,
    friction: float = 0.0,
    friction_penalty_factor: float = 0.1,
) -> list[ContactPair]:
    """Self-contact of every contact surface of a ``UnitMesh`` (each gap's U, each pocket's walls) as one pair.

    Every node of a surface is slave against the facets of the same surface
    that are not next to it, so both walls of a gap and any two walls of a
    pocket are kept apart whichever moves; each surface is extended past its
    free edges (the top corners of a gap's walls; with a smoothly vanishing
    penalty) so that the outer corners are caught when two blocks meet corner
    to corner.
    """
    surfaces = [unit_mesh.facets[name] for name in unit_mesh.contact_surfaces]
    if not surfaces:
        return []
    parts = [unit_mesh.contact_parts.get(name) for name in unit_mesh.contact_surfaces]
    pair = ContactPair.self_contact(unit_mesh.mesh.p, surfaces, search, extend, smoothing, smooth_normals, parts=parts)
    pair.mu, pair.friction_factor = float(friction), float(friction_penalty_factor)
    return [pair]
