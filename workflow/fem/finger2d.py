"""Planar finger for the whole-actuator check: mesh, hinges, straps, dead loads.

Mesh.  Each phalanx (PP, MP, DP) is its own body: a structured quadrilateral
grid mapped between five profile lines sampled along the segment (palmar
skin, palmar bone surface, the bone's centre line, dorsal bone surface, dorsal
skin), so the bone is the middle band of rows (material ``BONE``) and flesh
(``FLESH``) surrounds it.  The segments meet only at the joint centres: the
centre-row node of a segment's distal end face *is* the centre-row node of
the next segment's proximal end face (one shared node, a pin), as the paper's
nodes A/B with rigid links (Fig. 19).  Like the paper, segments do not contact
each other, so the palmar flesh of two segments may overlap in deep flexion.

Hinge springs.  A segment's orientation is that of the chord between two of
its bone nodes (the joint-centre nodes; for the distal phalanx the bone's
distal-most centre node).  Bone (E = 20 GPa) keeps that chord rigid, so the
joint angle theta = -(phi_distal - phi_proximal) (flexion positive, the
``workflow.cascade.finger`` frame) follows from node positions alone, and a passive
moment M(theta) enters as the energy  int M dtheta  with its exact gradient
and Hessian (``HingeSpring``).

Straps and loads.  ``StrapSpring`` ties an actuator node to a point carried
by the bones (a nylon strap), ``DeadLoad`` a constant nodal force (gravity), ramped
with the load factor or held, and ``DofSpring`` a spring from single dofs to
ground (a numerical regularisation of a rigid-body mode, see its docstring).

All objects follow ``Model``'s ``extras`` protocol: ``evaluate(x, u, lam,
tangent) -> (f (n,), K (n, n) sparse or None)``, f added to the residual
(internal-force sign).  Units: mm, N (per mm of width in 2D), N mm, rad.

Over 400 lines: the finger's mesh and the springs, straps and dead loads acting on it are one model; split, each half would need the other's node bookkeeping.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import scipy.sparse as sp

from workflow.fem._mesh import _divisions, _orient

__all__ = [
    "SegmentProfile",
    "FingerMesh",
    "build_finger_mesh",
    "HingeSpring",
    "StrapSpring",
    "DeadLoad",
    "DofSpring",
    "chord_angle",
    "RigidRotationUpdate",
]

#: Material ids of the finger in ``SolidAssembler`` (0/1 are silicone/paper).
FLESH, BONE = 2, 3


@dataclass(frozen=True)
class SegmentProfile:
    """Sagittal section of one phalanx, sampled at stations ``x`` (mm, increasing).

    ``lines`` (5, m): y (mm) of the palmar skin, palmar bone surface, bone
    centre line, dorsal bone surface and dorsal skin at each station, in this
    (increasing) order.  ``bone_end_x``: the bone ends here (cells beyond are
    flesh; the segment's last station for PP and MP).
    """

    name: str
    x: np.ndarray
    lines: np.ndarray
    bone_end_x: float


@dataclass
class FingerMesh:
    """The finger's planar mesh (all segments in one node numbering).

    ``material`` (FLESH/BONE) and ``segment`` (0, 1, 2) per cell; ``facets``:
    ``dorsal`` (outward-oriented dorsal skin facets, for contact) and
    ``dorsal_{k}`` per segment; ``nodes``: ``joint_{MCP,PIP,DIP}`` (one node
    each, the pins), ``dp_end`` (the distal bone's last centre node);
    ``chords``: per segment the (node, node) whose direction is its orientation.
    """

    p: np.ndarray
    t: np.ndarray
    material: np.ndarray
    segment: np.ndarray
    facets: dict
    nodes: dict
    chords: list = field(default_factory=list)


def _segment_grid(prof: SegmentProfile, h: float, min_band: float):
    """Mapped grid of one segment: nodes (2, n), cells (4, ne), bone mask, row/column counts."""
    xs = _divisions(np.array([prof.x[0], prof.x[-1]]), h)
    if prof.bone_end_x < prof.x[-1] - 1e-9:
        xs = _divisions(np.array([prof.x[0], prof.bone_end_x, prof.x[-1]]), h)
    lines = np.array([np.interp(xs, prof.x, ln) for ln in prof.lines])  # (5, nx)
    # keep every band at least min_band thick (tips close to zero depth)
    for b in range(1, 5):
        lines[b] = np.maximum(lines[b], lines[b - 1] + min_band)
    thick = np.diff(lines, axis=0).max(axis=1)
    nrow = [max(1, int(np.ceil(tb / h - 1e-9))) for tb in thick]
    # rows: fractions within each band
    ys, band_of_row = [lines[0]], []
    for b in range(4):
        for r in range(1, nrow[b] + 1):
            ys.append(lines[b] + (lines[b + 1] - lines[b]) * r / nrow[b])
            band_of_row.append(b)
    Y = np.array(ys)  # (ny, nx)
    ny, nx = Y.shape
    X = np.broadcast_to(xs, (ny, nx))
    idx = np.arange(ny * nx).reshape(ny, nx)
    # counter-clockwise cells (x right, y up)
    t = np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()])
    band = np.repeat(np.array(band_of_row), nx - 1)
    xc = np.tile(0.5 * (xs[:-1] + xs[1:]), ny - 1)
    bone = ((band == 1) | (band == 2)) & (xc < prof.bone_end_x + 1e-9)
    p = np.stack([X.ravel(), Y.ravel()])
    centre_row = int(np.sum(nrow[:2]))
    return p, t, bone, idx, centre_row, xs


def build_finger_mesh(profiles: Sequence[SegmentProfile], h: float = 1.5, min_band_mm: float = 0.3) -> FingerMesh:
    """Mesh the three segments and pin them at the joint centres (see the module docstring).

    The first station's centre-line point of each segment is its proximal
    joint centre; PP's and MP's last station's is the next joint centre (they
    must coincide with the next segment's first, to 1e-6 mm).
    """
    if len(profiles) != 3:
        raise ValueError("the finger has three segments (PP, MP, DP)")
    ps, ts, mats, segs, dors = [], [], [], [], []
    first, last, dp_end = [], [], None
    off = 0
    for k, prof in enumerate(profiles):
        p, t, bone, idx, cr, xs = _segment_grid(prof, h, min_band_mm)
        ps.append(p)
        ts.append(t + off)
        mats.append(np.where(bone, BONE, FLESH))
        segs.append(np.full(t.shape[1], k))
        top = idx[-1]
        dors.append(np.stack([top[1:], top[:-1]], axis=1) + off)  # right to left: outward normal up
        first.append(idx[cr, 0] + off)
        last.append(idx[cr, -1] + off)
        if k == 2:
            j = int(np.flatnonzero(xs <= prof.bone_end_x + 1e-9)[-1])
            dp_end = idx[cr, j] + off
        off += p.shape[1]
    p = np.concatenate(ps, axis=1)
    t = np.concatenate(ts, axis=1)
    # pin: the distal segment's proximal joint node becomes the proximal segment's distal one
    remap = np.arange(p.shape[1])
    for k in (1, 2):
        a, b = last[k - 1], first[k]
        if np.linalg.norm(p[:, a] - p[:, b]) > 1e-6:
            raise ValueError(f"segments {k - 1} and {k} do not meet at the joint centre: {p[:, a]} vs {p[:, b]}")
        remap[b] = a
    keep = np.ones(p.shape[1], bool)
    keep[[first[1], first[2]]] = False
    new = -np.ones(p.shape[1], dtype=np.int64)
    new[keep] = np.arange(keep.sum())
    final = new[remap]
    p = p[:, keep]
    t = final[t]
    dorsal = [final[d] for d in dors]
    centroids = p[:, t].mean(axis=1)
    seg_all = np.concatenate(segs)
    facets = {}
    for k, d in enumerate(dorsal):
        top_cells = np.flatnonzero(seg_all == k)[-d.shape[0] :]  # the top row, left to right like d
        facets[f"dorsal_{k}"] = _orient(p, d, centroids[:, top_cells])
    facets["dorsal"] = np.concatenate([facets[f"dorsal_{k}"] for k in range(3)])
    j = {"MCP": final[first[0]], "PIP": final[last[0]], "DIP": final[last[1]]}
    nodes = {f"joint_{n}": int(v) for n, v in j.items()}
    nodes["dp_end"] = int(final[dp_end])
    chords = [
        (nodes["joint_MCP"], nodes["joint_PIP"]),
        (nodes["joint_PIP"], nodes["joint_DIP"]),
        (nodes["joint_DIP"], nodes["dp_end"]),
    ]
    return FingerMesh(
        p=p,
        t=t.astype(np.int64),
        material=np.concatenate(mats),
        segment=np.concatenate(segs),
        facets=facets,
        nodes=nodes,
        chords=chords,
    )


# --------------------------------------------------------------------------
# Extras: hinge springs, straps, dead loads
# --------------------------------------------------------------------------
def chord_angle(x: np.ndarray, a: int, b: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Direction phi (rad, ccw) of the chord a -> b, its gradient wrt d = x_b - x_a (2,) and Hessian (2, 2)."""
    d = x[:, b] - x[:, a]
    r2 = float(d @ d)
    phi = float(np.arctan2(d[1], d[0]))
    g = np.array([-d[1], d[0]]) / r2
    H = np.array([[2 * d[0] * d[1], d[1] ** 2 - d[0] ** 2], [d[1] ** 2 - d[0] ** 2, -2 * d[0] * d[1]]]) / r2**2
    return phi, g, H


class HingeSpring:
    """Rotational spring between two segments' orientations (``extras`` term).

    theta = -[(phi_B - phi_B0) - (phi_A - phi_A0)] (rad, positive = flexion:
    the distal chord B turns clockwise relative to the proximal chord A); with
    ``chord_a=None`` the proximal side is fixed (the hand).  The energy
    W(theta) = int_0^theta M gives f = M(theta) dtheta/dx and the exact tangent
    K = M'(theta) dtheta dtheta^T + M(theta) d2theta/dx2.

    Parameters
    ----------
    ndofs : total dofs (2 per node)
    p_ref : (2, nnodes) reference coordinates, mm
    chord_a, chord_b : (node, node) or None
    moment : callable theta (rad) -> M (N mm per mm of width); ``stiffness`` -> dM/dtheta
    """

    def __init__(
        self,
        ndofs: int,
        p_ref: np.ndarray,
        chord_a,
        chord_b,
        moment: Callable[[float], float],
        stiffness: Callable[[float], float],
    ):
        self.n = ndofs
        self.a, self.b = chord_a, chord_b
        self.moment, self.stiffness = moment, stiffness
        self.phi_a0 = chord_angle(p_ref, *chord_a)[0] if chord_a is not None else 0.0
        self.phi_b0 = chord_angle(p_ref, *chord_b)[0]

    def angle(self, x: np.ndarray) -> float:
        """Joint angle theta (rad) at node positions x (2, nnodes)."""
        th = -(chord_angle(x, *self.b)[0] - self.phi_b0)
        if self.a is not None:
            th += chord_angle(x, *self.a)[0] - self.phi_a0
        return float((th + np.pi) % (2 * np.pi) - np.pi)

    def _parts(self, x):
        """(dofs (k,), dtheta/dx (k,), d2theta/dx2 (k, k)) over the chords' nodes."""
        dofs, grad, hess = [], [], []
        for chord, sign in ((self.b, -1.0), (self.a, 1.0)):
            if chord is None:
                continue
            _, g, H = chord_angle(x, *chord)
            n0, n1 = chord
            dofs.append([2 * n0, 2 * n0 + 1, 2 * n1, 2 * n1 + 1])
            # d = x_n1 - x_n0: d/dx_n0 = -I, d/dx_n1 = +I
            B = np.array([[-1, 0], [0, -1], [1, 0], [0, 1]], float)
            grad.append(sign * B @ g)
            hess.append(sign * B @ H @ B.T)
        dofs = np.concatenate(dofs)
        k = dofs.size
        Hf = np.zeros((k, k))
        Hf[:4, :4] = hess[0]
        if len(hess) > 1:
            Hf[4:, 4:] = hess[1]
        return dofs, np.concatenate(grad), Hf

    def evaluate(self, x, u, lam, tangent=True):
        th = self.angle(x)
        dofs, g, H = self._parts(x)
        M = float(self.moment(th))
        f = np.bincount(dofs, weights=M * g, minlength=self.n)
        if not tangent:
            return f, None
        Kl = float(self.stiffness(th)) * np.outer(g, g) + M * H
        r, c = np.meshgrid(dofs, dofs, indexing="ij")
        return f, sp.csr_matrix((Kl.ravel(), (r.ravel(), c.ravel())), shape=(self.n, self.n))


def _similarity_weights(p_ref: np.ndarray, chord: tuple[int, int], point: np.ndarray) -> np.ndarray:
    """Weights (2, 2, 2) W[i] so that a point carried rigidly by chord (a, b) is sum_i W[i] @ x_i.

    x = x_a + alpha (x_b - x_a) + beta J (x_b - x_a), J = rotation by +90 deg:
    linear in the two nodes' positions, exact for rigid motions of the chord.
    """
    a, b = chord
    d = p_ref[:, b] - p_ref[:, a]
    r = np.asarray(point, float) - p_ref[:, a]
    L2 = float(d @ d)
    alpha, beta = float(r @ d) / L2, float(d[0] * r[1] - d[1] * r[0]) / L2
    J = np.array([[0.0, -1.0], [1.0, 0.0]])
    Wb = alpha * np.eye(2) + beta * J
    return np.stack([np.eye(2) - Wb, Wb])


class StrapSpring:
    """A strap: zero-length spring of stiffness k (all directions) between a node of the
    actuator and a point of the finger carried by its bones (``extras`` term).

    The finger point starts at the actuator node's reference position and
    moves with the mean of the similarity maps of the given bone chords (for a
    strap at a joint: the two adjacent segments, so the point stays on the
    bisector of the joint angle).  Being linear in the node positions, the
    energy k/2 |x_node - x_point|^2 has a constant tangent and no preferred
    frame.  ``k`` in N/mm (per mm of width in 2D).
    """

    def __init__(self, ndofs: int, p_ref: np.ndarray, node: int, chords: Sequence[tuple[int, int]], k: float):
        self.n, self.node, self.k = ndofs, int(node), float(k)
        nodes = [self.node]
        blocks = [np.eye(2)]
        for ch in chords:
            W = _similarity_weights(p_ref, ch, p_ref[:, self.node])
            for i, nd in enumerate(ch):
                nodes.append(int(nd))
                blocks.append(-W[i] / len(chords))
        self.B = np.concatenate(blocks, axis=1)  # (2, 2 m): gap vector = B @ x_local
        self.dofs = np.concatenate([[2 * nd, 2 * nd + 1] for nd in nodes])
        self.K = self.k * self.B.T @ self.B

    def gap(self, x: np.ndarray) -> np.ndarray:
        """Actuator node minus finger point, mm (2,)."""
        return self.B @ x.T.ravel()[self.dofs]

    def force(self, x: np.ndarray) -> float:
        """Strap force magnitude k |gap| (N, per mm of width in 2D)."""
        return self.k * float(np.linalg.norm(self.gap(x)))

    def evaluate(self, x, u, lam, tangent=True):
        f = np.bincount(self.dofs, weights=self.k * self.B.T @ self.gap(x), minlength=self.n)
        if not tangent:
            return f, None
        r, c = np.meshgrid(self.dofs, self.dofs, indexing="ij")
        return f, sp.csr_matrix((self.K.ravel(), (r.ravel(), c.ravel())), shape=(self.n, self.n))


class SlidingStrap(StrapSpring):
    """A strap that holds the actuator node to the finger point fully across the finger and with a share of its
    stiffness along it (a band round finger and actuator that the actuator can slide through), where
    ``StrapSpring`` holds it fully in every direction.

    Energy k/2 [(n . g)^2 + beta (t . g)^2], g the gap of ``StrapSpring``, n the unit normal to the mean direction
    t of the bone chords, which turns with the bones, and beta = ``hold_along`` in (0, 1) the share of the strap's
    stiffness left along the finger (beta = 1 is ``StrapSpring``'s energy k/2 |g|^2); the force is its exact
    gradient (n's variation included), the tangent a central difference of that force over the strap's few local
    dofs.  ``k`` in N/mm (per mm of width in 2D).
    """

    #: relative step of the tangent's central difference
    FD_STEP = 1e-6

    def __init__(
        self, ndofs: int, p_ref: np.ndarray, node: int, chords: Sequence[tuple[int, int]], k: float, hold_along: float
    ):
        super().__init__(ndofs, p_ref, node, chords, k)
        self.nchords = len(chords)
        self.beta = float(hold_along)

    def _normal(self, P: np.ndarray):
        """Unit normal n (m, 2) of local node rows P (m, nl, 2), with what its derivative needs: the unit mean
        direction s^ and |s| (m, 1), and per chord its unit direction and length."""
        dirs = []
        s = np.zeros((P.shape[0], 2))
        for c in range(self.nchords):
            d = P[:, 2 + 2 * c] - P[:, 1 + 2 * c]
            ld = np.linalg.norm(d, axis=1, keepdims=True)
            dirs.append((d / ld, ld))
            s += d / ld
        ls = np.linalg.norm(s, axis=1, keepdims=True)
        sh = s / ls
        return np.stack([-sh[:, 1], sh[:, 0]], axis=1), sh, ls, dirs

    def _local_force(self, XL: np.ndarray) -> np.ndarray:
        """Force (m, 2 nl) of local coordinate rows XL (m, 2 nl), node-interleaved in the order of ``dofs``
        (the actuator node, then each chord's two nodes)."""
        m = XL.shape[0]
        g = XL @ self.B.T  # (m, 2)
        n, sh, ls, dirs = self._normal(XL.reshape(m, -1, 2))
        gn = np.sum(n * g, axis=1, keepdims=True)
        G = (n @ self.B).reshape(m, -1, 2)  # d(n . g)/dXL at fixed n, then n's variation:
        # dn = J (I - s^ s^T) ds / |s|, ds = sum_c (I - d^ d^T)(dx_b - dx_a) / |d|
        Jg = np.stack([g[:, 1], -g[:, 0]], axis=1)  # J^T g
        w = (Jg - sh * np.sum(sh * Jg, axis=1, keepdims=True)) / ls
        for c, (dh, ld) in enumerate(dirs):
            v = (w - dh * np.sum(dh * w, axis=1, keepdims=True)) / ld
            G[:, 2 + 2 * c] += v
            G[:, 1 + 2 * c] -= v
        # (t . g)^2 = |g|^2 - (n . g)^2
        return self.k * ((1.0 - self.beta) * gn * G.reshape(m, -1) + self.beta * g @ self.B)

    def normal_gap(self, x: np.ndarray) -> float:
        """The gap across the finger, n . g (mm)."""
        xl = x.T.ravel()[self.dofs]
        n = self._normal(xl.reshape(1, -1, 2))[0][0]
        return float(n @ (self.B @ xl))

    def force(self, x: np.ndarray) -> float:
        """Strap force magnitude k |(n . g) n + beta (t . g) t| (N, per mm of width in 2D)."""
        gn, g2 = self.normal_gap(x), float(np.sum(self.gap(x) ** 2))
        return self.k * float(np.sqrt(gn**2 + self.beta**2 * max(g2 - gn**2, 0.0)))

    def evaluate(self, x, u, lam, tangent=True):
        xl = x.T.ravel()[self.dofs]
        f = np.bincount(self.dofs, weights=self._local_force(xl[None])[0], minlength=self.n)
        if not tangent:
            return f, None
        h = self.FD_STEP * max(1.0, float(np.abs(xl).max()))
        E = np.eye(xl.size) * h
        fb = self._local_force(np.concatenate([xl + E, xl - E]))
        K = (fb[: xl.size] - fb[xl.size :]).T / (2 * h)
        r, c = np.meshgrid(self.dofs, self.dofs, indexing="ij")
        return f, sp.csr_matrix((K.ravel(), (r.ravel(), c.ravel())), shape=(self.n, self.n))


def strap(ndofs: int, p_ref: np.ndarray, node: int, chords: Sequence[tuple[int, int]], k: float, hold_along: float):
    """The strap that holds ``hold_along`` (0, 1] of its stiffness along the finger: ``StrapSpring`` at 1 (its exact
    constant tangent), ``SlidingStrap`` below."""
    if not 0.0 < hold_along <= 1.0:
        raise ValueError(f"a strap's hold along the finger must be in (0, 1], got {hold_along!r}")
    if hold_along == 1.0:
        return StrapSpring(ndofs, p_ref, node, chords, k)
    return SlidingStrap(ndofs, p_ref, node, chords, k, hold_along)


class DeadLoad:
    """Constant external nodal force ``f_ext`` (n,), e.g. gravity.

    ``ramp=True`` scales it with the load factor (the gravity phase),
    ``False`` holds it at full value (the pressure phase that follows).
    """

    def __init__(self, f_ext: np.ndarray, ramp: bool = True):
        self.f_ext = np.asarray(f_ext, float)
        self.ramp = bool(ramp)

    def evaluate(self, x, u, lam, tangent=True):
        return -(lam if self.ramp else 1.0) * self.f_ext, None

    def external(self, x, u, lam):
        """The applied load (for the solver's convergence reference)."""
        return (lam if self.ramp else 1.0) * self.f_ext


class DofSpring:
    """Springs from single dofs to ground, f = k u (N/mm).

    Used with a tiny k to remove a rigid-body mode that only frictionless
    contact and unstressed straps would leave singular at the first Newton
    iteration (the actuator sliding along the finger); its force is reported
    so that it can be checked to be negligible.
    """

    def __init__(self, ndofs: int, dofs: Sequence[int], k: float):
        self.n = ndofs
        self.dofs = np.asarray(dofs, dtype=np.int64)
        self.k = float(k)

    def force(self, u: np.ndarray) -> np.ndarray:
        return self.k * u[self.dofs]

    def evaluate(self, x, u, lam, tangent=True):
        f = np.zeros(self.n)
        f[self.dofs] = self.k * u[self.dofs]
        if not tangent:
            return f, None
        return f, sp.csr_matrix((np.full(self.dofs.size, self.k), (self.dofs, self.dofs)), shape=(self.n, self.n))


class SupportPlane:
    """A rigid, frictionless plane ``y >= y0`` under some nodes (the back of the hand under the actuator's CMC units).

    Node-to-plane penalty with the self-contact's C1 law (see :mod:`workflow.fem._contact`): per node, the
    energy eps A / 2 <g>^2 in penetration, g = y - y0, smoothed over a band ``smoothing`` above the plane;
    ``eps`` MPa/mm, ``area`` (nodes,) the nodes' tributary lengths (mm, per mm of width in 2D).
    """

    def __init__(self, ndofs: int, nodes: Sequence[int], area: np.ndarray, y0: float, eps: float, smoothing: float):
        self.n = ndofs
        self.nodes = np.asarray(nodes, dtype=np.int64)
        self.dofs = 2 * self.nodes + 1
        self.k = float(eps) * np.asarray(area, float)
        self.y0, self.d = float(y0), float(smoothing)

    def _law(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = x[1, self.nodes] - self.y0
        d = self.d
        if d > 0:
            t = np.where(g <= 0.0, g - 0.5 * d, -(np.clip(d - g, 0.0, None) ** 2) / (2.0 * d))
            dt = np.where(g <= 0.0, 1.0, np.clip(d - g, 0.0, None) / d)
        else:
            t, dt = np.minimum(g, 0.0), (g < 0.0).astype(float)
        return t, dt

    def force(self, x: np.ndarray) -> float:
        """Total support reaction (N, per mm of width in 2D), upward."""
        t, _ = self._law(x)
        return float(-np.sum(self.k * t))

    def evaluate(self, x, u, lam, tangent=True):
        t, dt = self._law(x)
        f = np.zeros(self.n)
        f[self.dofs] = self.k * t  # in the residual: minus the upward reaction
        if not tangent:
            return f, None
        return f, sp.csr_matrix((self.k * dt, (self.dofs, self.dofs)), shape=(self.n, self.n))


class RigidRotationUpdate:
    """Newton update of nearly rigid bodies by their finite rotation (a ``Model`` updater, 2D).

    A stiff body (bone, E = 20 GPa) that turns by theta under a Newton
    correction du = theta J r (the linearised rotation) is stretched by
    theta^2 / 2: with the soft hinge and flesh around it, that spurious strain
    makes a residual far larger than the loads, whose projection on the soft
    joint rotation throws the next iterate off again, and Newton wanders
    (measured: 20-30 iterations per load step, no quadratic convergence).
    Here each group's correction is split into the rotation about its pivot
    node, fitted by least squares over its ``fit`` nodes (the bone),
    dtheta = sum r x (du - du_pivot) / sum |r|^2, and the rest; the rotation is
    applied exactly (R(dtheta) - I) r to every node of the group (bone and
    the flesh of that segment), the rest additively.  To first order this is
    du itself, so the converged solution is unchanged; only the iterates avoid
    the artificial stretch.  Groups are processed in order, so a pivot moved
    by an earlier group (PIP is the proximal phalanx's distal node) carries
    the next group along.
    """

    def __init__(self, groups: Sequence[tuple], blend: tuple | None = None):
        # (pivot node, nodes moved with the group, fit nodes) per group; ``blend`` = (nodes, W (n, ngroups)):
        # further nodes whose correction is the W-weighted sum of the groups' corrections at their
        # position (smooth across the joints, e.g. the actuator on the finger)
        self.groups = [(int(g[0]), np.asarray(g[1], dtype=np.int64), np.asarray(g[2], dtype=np.int64)) for g in groups]
        self.blend = None if blend is None else (np.asarray(blend[0], dtype=np.int64), np.asarray(blend[1], float))

    @staticmethod
    def _corr(th, r):
        """Exact rotation by th minus its linearisation, applied to r (k, 2); th scalar or (k,)."""
        c, s = np.cos(th), np.sin(th)
        return np.stack([(c - 1.0) * r[:, 0] - (s - th) * r[:, 1], (s - th) * r[:, 0] + (c - 1.0) * r[:, 1]], axis=1)

    def increment(self, p_ref: np.ndarray, u: np.ndarray, du: np.ndarray) -> np.ndarray:
        out = du.copy()
        U, D, O = u.reshape(-1, 2), du.reshape(-1, 2), out.reshape(-1, 2)
        X = p_ref.T + U
        parts = []
        for pv, nodes, fit in self.groups:
            rf = X[fit] - X[pv]
            df = D[fit] - D[pv]
            den = float(np.sum(rf * rf))
            th = float(np.sum(rf[:, 0] * df[:, 1] - rf[:, 1] * df[:, 0])) / den if den > 0 else 0.0
            carry = O[pv] - D[pv]  # the pivot's own correction (moved by an earlier group)
            O[nodes] = D[nodes] + self._corr(th, X[nodes] - X[pv]) + carry
            parts.append((th, X[pv].copy(), carry.copy()))
        if self.blend is not None:
            nodes, W = self.blend
            acc = np.zeros((nodes.size, 2))
            for k, (th, xp, carry) in enumerate(parts):
                acc += W[:, k, None] * (self._corr(th, X[nodes] - xp) + carry)
            O[nodes] = D[nodes] + acc
        return out
