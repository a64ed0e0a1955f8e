"""Global overlap check of a deformed Q1 mesh, and the pockets' sizes.

Penalty contact only acts where it was declared (pairs of facing walls), and
only within its search distance, so it cannot tell whether the solid passed
through itself somewhere else.  This check looks at the deformed geometry
alone:

* ``overlap_depth``: every boundary node is tested against every element that
  does not contain it (candidates by bounding box, then the inverse of the
  bilinear / trilinear map by Newton); a node inside a foreign element lies
  inside the material, and its depth is its distance to the nearest boundary
  facet not incident to it.  The result is the deepest such node (0 when
  none): a penalty contact gives the small penetration its penalty allows, a
  pass-through a depth of the order of a wall's thickness.
* ``pocket_sizes``: the area (2D, shoelace over the pocket's walls) or volume
  (3D, divergence theorem with 2x2 Gauss on the bilinear walls; the half model
  is open at the symmetry plane z = 0, where z n_z vanishes, and the value is
  doubled to the whole pocket) of each air pocket.  A pocket whose walls cross
  has a smaller, or negative, area.

Lengths in mm.  Pure functions of the current coordinates.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "boundary_faces",
    "overlap_depth",
    "pocket_sizes",
    "pocket_names",
    "overlap_measures",
    "QUAD_FACES",
    "HEX_FACES",
]

# Faces of a cell as local node lists in cyclic order (scikit-fem's node order of MeshQuad / MeshHex.init_tensor).
QUAD_FACES = [(0, 1), (1, 2), (2, 3), (3, 0)]
HEX_FACES = [(0, 2, 4, 1), (3, 5, 7, 6), (0, 1, 5, 3), (2, 6, 7, 4), (0, 3, 6, 2), (1, 4, 7, 5)]
_XI_QUAD = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], dtype=float)
_XI_HEX = np.array(
    [(0, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1), (1, 1, 1)], dtype=float
)


def boundary_faces(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces of exactly one cell of a quad (4, nc) / hex (8, nc) mesh, with their cells.

    Returns ``(faces (nf, nfn) in cyclic node order, owner cell (nf,))``;
    orientation is not fixed here.
    """
    flist = QUAD_FACES if t.shape[0] == 4 else HEX_FACES
    faces = np.concatenate([t[list(f)].T for f in flist])
    owner = np.tile(np.arange(t.shape[1]), len(flist))
    key = np.sort(faces, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    bnd = cnt[inv.ravel()] == 1
    return faces[bnd], owner[bnd]


def _shape(xi: np.ndarray, dim: int):
    """Q1 shape functions (k, nbf) and their derivatives (k, nbf, dim) at reference points xi (k, dim) in [0, 1]^dim."""
    ref = _XI_QUAD if dim == 2 else _XI_HEX
    f = np.where(ref[None] > 0.5, xi[:, None, :], 1.0 - xi[:, None, :])  # (k, nbf, dim) factors per direction
    sgn = np.where(ref > 0.5, 1.0, -1.0)
    N = np.prod(f, axis=2)
    dN = np.empty(f.shape)
    for j in range(dim):
        others = np.prod(np.delete(f, j, axis=2), axis=2)
        dN[:, :, j] = sgn[None, :, j] * others
    return N, dN


def _inside(X: np.ndarray, xp: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Whether points xp (k, dim) lie inside Q1 cells with corner coordinates X (k, nbf, dim)."""
    k, _, dim = X.shape
    xi = np.full((k, dim), 0.5)
    for _ in range(12):
        N, dN = _shape(xi, dim)
        r = np.einsum("ka,kai->ki", N, X) - xp
        Jm = np.einsum("kaj,kai->kij", dN, X)
        ok = np.abs(np.linalg.det(Jm)) > 1e-300
        step = np.zeros_like(xi)
        step[ok] = np.linalg.solve(Jm[ok], r[ok][..., None])[..., 0]
        xi = np.clip(xi - step, -0.5, 1.5)
    N, _ = _shape(xi, dim)
    res = np.linalg.norm(np.einsum("ka,kai->ki", N, X) - xp, axis=1)
    size = np.linalg.norm(X.max(axis=1) - X.min(axis=1), axis=1)
    return np.all((xi > tol) & (xi < 1.0 - tol), axis=1) & (res <= 1e-8 * size)


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    t = b - a
    s = np.clip(np.einsum("ki,ki->k", p - a, t) / np.maximum(np.einsum("ki,ki->k", t, t), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - a - s[:, None] * t, axis=1)


def _point_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from points p (k, 3) to triangles (a, b, c) (k, 3 each)."""
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=1)
    n = n / np.maximum(nn, 1e-300)[:, None]
    h = np.einsum("ki,ki->k", p - a, n)
    q = p - h[:, None] * n  # projection onto the plane
    inside = np.ones(p.shape[0], bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ki,ki->k", np.cross(v - u, q - u), n) >= 0.0
    edge = np.minimum(np.minimum(_point_segment(p, a, b), _point_segment(p, b, c)), _point_segment(p, c, a))
    return np.where(inside & (nn > 0), np.abs(h), edge)


def _point_face(p: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Distance from points p (k, dim) to boundary faces with corners F (k, nfn, dim): segments or bilinear quads."""
    if F.shape[1] == 2:
        return _point_segment(p, F[:, 0], F[:, 1])
    c = F.mean(axis=1)  # the quad as four triangles about its centroid
    return np.min([_point_triangle(p, F[:, i], F[:, (i + 1) % 4], c) for i in range(4)], axis=0)


def overlap_depth(
    x: np.ndarray, t: np.ndarray, faces: np.ndarray | None = None, ignore: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[float, int]:
    """Deepest boundary node inside an element that does not contain it.

    Parameters
    ----------
    x : ndarray (dim, nnodes)
        Current nodal coordinates, mm.
    t : ndarray (nbf, ncells)
        Q1 cells (scikit-fem's node order).
    faces : ndarray (nf, nfn), optional
        Boundary faces (default: ``boundary_faces(t)``).
    ignore : (node mask (nnodes,), cell mask (ncells,)), optional
        Pairs of a masked node inside a masked cell are not counted (e.g. the
        finger's segments, which overlap at their pinned joints by design).

    Returns
    -------
    (depth in mm (0 when no node is inside foreign material), number of such nodes)
    """
    if faces is None:
        faces, _ = boundary_faces(t)
    bnodes = np.unique(faces)
    Xc = x[:, t].transpose(2, 1, 0)  # (nc, nbf, dim)
    lo, hi = Xc.min(axis=1), Xc.max(axis=1)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo, axis=1).max())
    tree = cKDTree(centre)
    cand = tree.query_ball_point(x[:, bnodes].T, radius)
    node = np.repeat(bnodes, [len(c) for c in cand])
    cell = np.fromiter((c for cs in cand for c in cs), dtype=np.int64, count=node.size)
    xp = x[:, node].T
    keep = np.all((xp >= lo[cell] - 1e-12) & (xp <= hi[cell] + 1e-12), axis=1) & ~np.any(t[:, cell] == node, axis=0)
    if ignore is not None:
        keep &= ~(ignore[0][node] & ignore[1][cell])
    node, cell, xp = node[keep], cell[keep], xp[keep]
    if node.size == 0:
        return 0.0, 0
    inside = _inside(Xc[cell], xp)
    hits = np.unique(node[inside])
    if hits.size == 0:
        return 0.0, 0
    # depth: distance to the nearest boundary face not incident to the node (nearest face centroids first)
    fc = x[:, faces].mean(axis=2).T
    k = min(24, faces.shape[0])
    _, near = cKDTree(fc).query(x[:, hits].T, k=k)
    near = near.reshape(hits.size, k)
    pts = np.repeat(x[:, hits].T, k, axis=0)
    fids = near.ravel()
    d = _point_face(pts, x[:, faces[fids]].transpose(1, 2, 0)).reshape(hits.size, k)
    d[np.any(faces[near] == hits[:, None, None], axis=2)] = np.inf
    depth = d.min(axis=1)
    return float(np.max(np.where(np.isfinite(depth), depth, 0.0))), int(hits.size)


def pocket_sizes(x: np.ndarray, pockets: list[np.ndarray], half_model: bool = True) -> np.ndarray:
    """Area (2D, mm^2) or volume (3D, mm^3; whole pocket of a half model) of each pocket.

    ``pockets``: per pocket its wall facets, oriented with the solid's outward
    normal (pointing into the pocket), as ``UnitMesh.facets["pocket_*"]``.
    """
    out = np.empty(len(pockets))
    for i, f in enumerate(pockets):
        X = x[:, f].transpose(1, 2, 0)  # (nf, nfn, dim)
        if x.shape[0] == 2:
            # the solid's outward normal points into the hole: its walls run clockwise around it
            out[i] = -0.5 * float(np.sum(X[:, 0, 0] * X[:, 1, 1] - X[:, 1, 0] * X[:, 0, 1]))
            continue
        g = 1.0 / np.sqrt(3.0)
        vol = 0.0
        for a in (-g, g):
            for b in (-g, g):
                N = 0.25 * np.array([(1 - a) * (1 - b), (1 + a) * (1 - b), (1 + a) * (1 + b), (1 - a) * (1 + b)])
                dxi = 0.25 * np.array([-(1 - b), (1 - b), (1 + b), -(1 + b)])
                deta = 0.25 * np.array([-(1 - a), -(1 + a), (1 + a), (1 - a)])
                z = np.einsum("a,fa->f", N, X[:, :, 2])
                n = np.cross(np.einsum("a,fai->fi", dxi, X), np.einsum("a,fai->fi", deta, X))
                vol -= float(np.sum(z * n[:, 2]))
        out[i] = (2.0 if half_model else 1.0) * vol
    return out


def pocket_names(facets) -> list[str]:
    """Names of the per-pocket facet sets ``pocket_{top,bottom}{k}`` of a ``UnitMesh``."""
    return sorted(
        k for k in facets if k.startswith("pocket_") and k.rsplit("_", 1)[-1][-1].isdigit() and k.count("_") == 1
    )


def overlap_measures(um, x: np.ndarray, info: dict | None = None, ignore=None) -> dict:
    """Per-sample checks of an actuator model at current coordinates x (dim, nnodes), mm.

    ``contact_penetration_mm``: the deepest penetration the contact pairs see
    (within their search distance; from ``info["gmin"]``); ``overlap_depth_mm``:
    the global check (``overlap_depth``); ``max_penetration_mm``: the larger of
    the two, so a pass-through is never reported as small;
    ``min_pocket_area_mm2`` (2D) / ``min_pocket_volume_mm3`` (3D, whole pocket):
    the smallest pocket (``pocket_sizes``).
    """
    gmin = (info or {}).get("gmin", np.inf)
    pen = float(max(0.0, -gmin)) if np.isfinite(gmin) else 0.0
    depth, _ = overlap_depth(x, um.mesh.t, um.boundary, ignore)
    names = pocket_names(um.facets)
    sizes = pocket_sizes(x, [um.facets[k] for k in names]) if names else np.array([np.nan])
    key = "min_pocket_area_mm2" if x.shape[0] == 2 else "min_pocket_volume_mm3"
    return {
        "contact_penetration_mm": pen,
        "overlap_depth_mm": depth,
        "max_penetration_mm": max(pen, depth),
        key: float(np.min(sizes)),
    }
