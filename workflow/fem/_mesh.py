"""Structured meshes of the three-chamber PNA unit (Table 6 geometry).

Geometry, lengths in mm, x along the actuator, y across the
paper layer (height), z across the width:

* the strain-limiting paper layer, ``paper_width`` thick, centred on y = 0;
* per side a base layer ``bot_layer`` thick, then ``n_chambers`` blocks
  ``depth`` long and ``height`` tall, ``gap`` apart (no gap at the two ends,
  so the model is ``n*depth + (n-1)*gap`` = 22.4 mm long);
* each block holds an air pocket inset by ``ac_th_for`` along the length and
  ``ac_th_side`` across the width, from ``ac_th_down`` above the block's base
  (the top of the base layer; Table 6 has no pocket floor, 0) up to
  ``height - ac_th_up``;
* the bottom side mirrors the top.  Air vents and ``ends_ext`` are left out;
* optionally (``fillet`` > 0, not in Table 6) the blocks' outer corners of the
  x-y section rounded to that radius (`round_corners`, after every node and
  facet set is chosen on the square geometry).

2D: the longitudinal section through the width's symmetry plane (plane strain,
bilinear quadrilaterals).  3D: the half model z in [0, width/2] with the
symmetry plane at z = 0 (trilinear hexahedra).  The meshes are tensor-product
grids through every geometric breakpoint, each interval cut into
``ceil(length / h)`` elements (so halving ``h`` nests the meshes), with the
pocket and gap cells removed.  Through their thickness the paper layer has
``paper_layers`` elements (default ceil(1 mm / h): one down to h = 1 mm, then
refined with h, so that halving h halves every element) and each base layer
``base_layers`` (default ceil(2 bot_layer / h): elements half as tall as h).
Meshes of different h are not a systematic refinement (a 2 mm wall gets one
element at h = 2 and 1.4 mm, two at 1 mm); ``refine`` = r multiplies every
interval's count at one h, the layers' included, so that r = 1, 2, 3, ... are.
The base layers carry the actuator's bending: on Q1/P0 silicone elements a
bent layer is measurably too flexible when its elements are as tall as long
(+2.3 % at 2 elements through the 2 mm base and h = 1 mm) and too stiff when
they are much flatter (parasitic shear), and elements half as tall as long
keep the layered cantilever within 2 % of beam theory
(``tests/test_fem_beam.py``).

The whole actuator is the same chain with ``sum(units_per_group)``
chambers: ``build_actuator_mesh`` adds per-group cavity facet sets
(``cavity_top_{group}`` / ``cavity_bottom_{group}``), the outer faces of the
two sides and the backbone nodes, so that each group gets its own pressures.

Over 400 lines: the unit's tensor-product grid, its layers and chambers, and the boundary sets every other engine module addresses are defined together.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import skfem
from scipy.spatial import cKDTree

from ._overlap import boundary_faces

__all__ = [
    "DEFAULT_GEOMETRY",
    "UnitMesh",
    "build_unit_mesh",
    "build_actuator_mesh",
    "build_grid_mesh",
    "layer_counts",
    "round_corners",
    "top_bottom_symmetric",
]

#: Table 6 values used by the unit model, mm.
DEFAULT_GEOMETRY: dict[str, float] = {
    "depth": 6.8,
    "gap": 1.0,
    "height": 15.0,
    "width": 20.0,
    "bot_layer": 2.0,
    "ac_th_for": 2.0,
    "ac_th_up": 2.0,
    "ac_th_down": 0.0,
    "ac_th_side": 3.0,
    "paper_width": 0.2,
    "n_chambers": 3,
    "fillet": 0.0,
}

# Local node offsets (dx, dy[, dz]) in scikit-fem's node order of a cell
# (MeshQuad: counter-clockwise; MeshHex: the order of MeshHex.init_tensor).
_QUAD = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
_HEX = np.array([(0, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1), (1, 1, 1)])


@dataclass
class UnitMesh:
    """A mesh with the named node and facet sets the unit model needs.

    Attributes
    ----------
    mesh : skfem.MeshQuad or skfem.MeshHex
        Coordinates in mm.
    material : ndarray of int, (ncells,)
        0 = silicone, 1 = paper layer.
    facets : dict of str -> ndarray (nfacets, nodes per facet)
        Boundary facets with nodes ordered so that the outward normal of the
        solid is ``R (x2 - x1)`` (2D) or ``x_xi x x_eta`` (3D).  Keys
        ``cavity_top``, ``cavity_bottom``; per gap g and side s
        ``wall_{s}{g}_left`` / ``wall_{s}{g}_right`` (the two facing walls);
        ``gap_{s}{g}`` (both walls, the floor between them and the blocks' outer faces over those walls) and per
        chamber k ``pocket_{s}{k}`` (all walls of the pocket).
    nodes : dict of str -> ndarray of int
        ``clamp`` (x = 0), ``end`` (x = L), ``symmetry`` (z = 0, 3D only),
        ``backbone_end`` / ``backbone_prev`` (paper-layer nodes of the last
        and the last-but-one x column).
    geometry : dict
        The geometry parameters used (mm).
    h : float
        Target element size, mm.
    """

    mesh: skfem.Mesh
    material: np.ndarray
    facets: dict[str, np.ndarray]
    nodes: dict[str, np.ndarray]
    geometry: dict
    h: float
    #: facet sets with self-contact: every gap (its two walls and floor) and every pocket (its walls)
    contact_surfaces: list[str] = field(default_factory=list)
    #: per contact surface the part of each facet: a node never pairs with facets of its own parts
    #: (a gap's left block, floor, right block; a pocket's walls)
    contact_parts: dict[str, np.ndarray] = field(default_factory=dict)
    #: chamber -> group name (whole actuator only; empty for the unit)
    chamber_group: tuple[str, ...] = ()
    #: the chain is cut at gap centres (the backbone runs on by half a gap past both end blocks)
    end_gaps: bool = False
    #: every interval's element count at ``h`` multiplied by this along the length, through the height and across
    #: the width (``build_unit_mesh``)
    refine: tuple[int, int, int] = (1, 1, 1)
    _boundary: np.ndarray | None = field(default=None, repr=False)

    @property
    def boundary(self) -> np.ndarray:
        """All boundary faces (nf, nodes per face) in cyclic node order (for the overlap check)."""
        if self._boundary is None:
            self._boundary = boundary_faces(self.mesh.t)[0]
        return self._boundary

    @property
    def dim(self) -> int:
        return self.mesh.p.shape[0]

    @property
    def length(self) -> float:
        g = self.geometry
        return g["n_chambers"] * g["depth"] + (g["n_chambers"] - (0 if self.end_gaps else 1)) * g["gap"]


def top_bottom_symmetric(um: UnitMesh, tol_mm: float = 1e-8) -> bool:
    """Whether the unit mesh is its own mirror image across the paper layer's mid-plane (y = mean of the extreme y).

    Nodes, each cell's material and the top and bottom cavities must map onto each other (every other facet
    set and node set is built from them).  Then a load with P_T = P_B is mirror symmetric too, and the unit
    neither bends nor needs a couple to stay straight: its free angle and blocked moment are zero.
    """
    p = um.mesh.p
    y0 = 0.5 * (p[1].min() + p[1].max())

    def same(a: np.ndarray, b: np.ndarray) -> bool:
        """The point sets a and b (dim, n) are equal to ``tol_mm`` (each point of b has its own match in a)."""
        if a.shape != b.shape:
            return False
        dist, idx = cKDTree(a.T).query(b.T)
        return bool(np.all(dist <= tol_mm) and np.unique(idx).size == idx.size)

    def mirror(x: np.ndarray) -> np.ndarray:
        out = x.copy()
        out[1] = 2 * y0 - x[1]
        return out

    if not same(p, mirror(p)):
        return False
    cells = p[:, um.mesh.t].mean(axis=1)
    for m in np.unique(um.material):
        c = cells[:, um.material == m]
        if not same(c, mirror(c)):
            return False
    top, bottom = (p[:, um.facets[k]].mean(axis=2) for k in ("cavity_top", "cavity_bottom"))  # facets (nf, k)
    return same(top, mirror(bottom))


def _divisions(breaks: np.ndarray, h: float, refine: int = 1) -> np.ndarray:
    """Grid coordinates through ``breaks``: each interval in ``refine`` x ceil(length / h) equal parts."""
    pts = [breaks[:1]]
    for a, b in zip(breaks[:-1], breaks[1:]):
        n = int(refine) * max(1, int(np.ceil((b - a) / h - 1e-9)))
        pts.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(pts)


def round_corners(p: np.ndarray, corners: Sequence[tuple[float, float, float, float]], r: float) -> np.ndarray:
    """Node coordinates with each corner of the x-y section rounded to a fillet of radius ``r`` (mm).

    ``corners``: (x, y, sx, sy) per corner, (sx, sy) = +-1 pointing out of the solid.  The nodes in the
    r x r square inside each corner are mapped radially from the fillet's centre: a node at offsets
    v = (a, b) from the centre moves to v max(a, b) / |v|, so the square's two outer sides land on the
    quarter circle while its two inner sides, and everything outside the square, stay where they are
    (the map is continuous with the unmoved mesh).  3D: the same map for every z.
    """
    q = p.copy()
    if r <= 0.0:
        return q
    tol = 1e-9 * max(1.0, r)
    for x, y, sx, sy in corners:
        cx, cy = x - sx * r, y - sy * r
        a, b = sx * (p[0] - cx), sy * (p[1] - cy)
        inside = (a >= -tol) & (a <= r + tol) & (b >= -tol) & (b <= r + tol)
        a, b = np.clip(a[inside], 0.0, r), np.clip(b[inside], 0.0, r)
        n2 = np.hypot(a, b)
        f = np.divide(np.maximum(a, b), n2, out=np.ones_like(n2), where=n2 > tol)
        q[0, inside] = cx + sx * a * f
        q[1, inside] = cy + sy * b * f
    return q


def _orient(p: np.ndarray, faces: np.ndarray, centroids: np.ndarray) -> np.ndarray:
    """Reverse faces whose normal points into their cell (so all point outwards)."""
    x = p[:, faces]  # (dim, nf, nfn)
    if p.shape[0] == 2:
        t = x[:, :, 1] - x[:, :, 0]
        n = np.stack([t[1], -t[0]])
    else:
        n = np.cross((x[:, :, 2] - x[:, :, 0]).T, (x[:, :, 3] - x[:, :, 1]).T).T
    mid = x.mean(axis=2)
    flip = np.einsum("if,if->f", n, mid - centroids) < 0
    faces = faces.copy()
    faces[flip] = faces[flip, ::-1]
    return faces


def build_grid_mesh(coords: list[np.ndarray], keep=None):
    """Tensor-product quad/hex mesh on grid ``coords``; ``keep(centres)`` masks cells.

    Returns ``(mesh, boundary_faces, face_cells)`` with outward-oriented boundary
    faces.  Unused nodes are removed.
    """
    dim = len(coords)
    shape = [len(c) for c in coords]
    grids = np.meshgrid(*coords, indexing="ij")
    p = np.stack([g.ravel() for g in grids])
    idx = np.arange(p.shape[1]).reshape(shape)
    offs = _QUAD if dim == 2 else _HEX
    ncell = [s - 1 for s in shape]
    cells = []
    for off in offs:
        sl = tuple(slice(o, o + n) for o, n in zip(off, ncell))
        cells.append(idx[sl].ravel())
    t = np.stack(cells)
    centres = p[:, t].mean(axis=1)
    if keep is not None:
        t = t[:, keep(centres)]
    used = np.unique(t)
    remap = -np.ones(p.shape[1], dtype=np.int64)
    remap[used] = np.arange(used.size)
    p = p[:, used]
    t = remap[t]
    mesh = (skfem.MeshQuad if dim == 2 else skfem.MeshHex)(p, t.astype(np.int64))
    faces, owner = boundary_faces(t)  # the faces of exactly one cell
    faces = _orient(p, faces, p[:, t].mean(axis=1)[:, owner])
    return mesh, faces, owner


def layer_counts(
    g: Mapping, h: float, paper_layers: int | None = None, base_layers: int | None = None
) -> tuple[int, int]:
    """Elements through the paper layer and through each base layer (defaults: see the module docstring)."""
    npap = int(paper_layers) if paper_layers else max(1, int(np.ceil(1.0 / h - 1e-9)))
    nbase = int(base_layers) if base_layers else max(1, int(np.ceil(2.0 * g["bot_layer"] / h - 1e-9)))
    return npap, nbase


def build_unit_mesh(
    geom: Mapping | None = None,
    h: float = 0.5,
    dim: int = 2,
    paper_layers: int | None = None,
    base_layers: int | None = None,
    end_gaps: bool = False,
    refine: int | Sequence[int] = 1,
) -> UnitMesh:
    """Structured mesh of the three-chamber unit.

    Parameters
    ----------
    geom : mapping, optional
        Table 6 parameters in mm (``DEFAULT_GEOMETRY`` keys); missing keys take
        the defaults.
    h : float
        Target element size in mm (every geometric interval is cut into
        ``ceil(length / h)`` equal elements).
    dim : {2, 3}
        2 = plane-strain section, 3 = half model across the width.
    paper_layers, base_layers : int, optional
        Elements through the paper layer's and each base layer's thickness
        (default: ``layer_counts``).
    end_gaps : bool
        Cut the chain at gap centres: the backbone runs on by half a gap past
        both end blocks, as in a unit inside a longer chain.
    refine : int or (int, int[, int])
        Every interval's element count, the paper's and the base layers' included, multiplied by this: the
        meshes of one ``h`` and ``refine`` = 1, 2, 3, ... form a systematic family (every element's shape
        kept, its size divided by ``refine``), which meshes of different ``h`` are not (a 2 mm interval
        gets 1 element at h = 2 and 1.4 mm but 2 at h = 1 mm).  A pair or triple refines the length, the
        height (the paper and base layers with it) and the width (3D; default: as the length) each by its
        own factor, to separate the directions' errors (docs/fea.md, "Mesh convergence").
    """
    g = dict(DEFAULT_GEOMETRY)
    g.update(dict(geom or {}))
    npap, nbase = layer_counts(g, h, paper_layers, base_layers)
    r = _refine_factors(refine)
    return _chain_mesh(g, h, dim, (r[1] * npap, r[1] * nbase), None, end_gaps, r)


def _refine_factors(refine) -> tuple[int, int, int]:
    """(length, height, width) factors of ``refine``: one positive integer for all, or two (width = length) or three."""
    vals = [refine] if np.ndim(refine) == 0 else list(refine)
    if not 1 <= len(vals) <= 3 or any(isinstance(v, bool) or int(v) != v or int(v) < 1 for v in vals):
        raise ValueError(f"refine must be a positive integer or two or three of them, got {refine!r}")
    r = [int(v) for v in vals]
    if len(r) == 1:
        return (r[0], r[0], r[0])
    return (r[0], r[1], r[2] if len(r) == 3 else r[0])


def build_actuator_mesh(
    geom: Mapping | None,
    units_per_group: Mapping[str, int] | Sequence[tuple[str, int]],
    h: float = 1.0,
    dim: int = 2,
    paper_layers: int | None = None,
    base_layers: int | None = None,
) -> UnitMesh:
    """Structured mesh of the whole actuator: chambers in groups, left to right.

    Same geometry, element layout and facet orientation as ``build_unit_mesh``
    (the unit is the special case of one group of three chambers), with
    ``n_chambers`` = the sum of the group sizes.  Extra sets:

    * facets ``cavity_top_{group}`` / ``cavity_bottom_{group}`` (each group's
      pockets; ``cavity_top`` / ``cavity_bottom`` still hold all),
      ``outer_top`` / ``outer_bottom`` (the blocks' outer faces, y = +-(paper/2
      + bot_layer + height));
    * nodes ``backbone`` (every paper-layer node), ``clamp`` / ``end`` (x = 0 / L).

    ``chamber_group`` names the group of each chamber.  Lengths mm.
    """
    items = list(units_per_group.items()) if isinstance(units_per_group, Mapping) else list(units_per_group)
    names = tuple(str(k) for k, n in items for _ in range(int(n)))
    if not names:
        raise ValueError("the actuator needs at least one chamber")
    g = dict(DEFAULT_GEOMETRY)
    g.update(dict(geom or {}))
    g["n_chambers"] = len(names)
    return _chain_mesh(g, h, dim, layer_counts(g, h, paper_layers, base_layers), names)


def _chain_mesh(
    g: dict,
    h: float,
    dim: int,
    layers: tuple[int, int],
    groups: tuple[str, ...] | None,
    end_gaps: bool = False,
    refine: tuple[int, int, int] = (1, 1, 1),
) -> UnitMesh:
    """Chain of ``g["n_chambers"]`` chambers; ``groups`` (per chamber) adds the actuator's sets.

    ``end_gaps``: the paper and base layers run on by half a gap past both end
    blocks, so the chain is cut at gap centres as a unit inside a longer chain
    is (length n (depth + gap)); its end faces are then the backbone alone.
    """
    n = int(g["n_chambers"])
    d, gap, H, bl = g["depth"], g["gap"], g["height"], g["bot_layer"]
    tf, tu, ts, tp = g["ac_th_for"], g["ac_th_up"], g["ac_th_side"], g["paper_width"]
    L = n * d + (n - 1) * gap
    y0 = tp / 2
    yb = y0 + bl  # top of the base layer = block base
    yf = yb + float(g.get("ac_th_down", 0.0))  # pocket floor (the block base unless the section has a floor)
    yp = yb + H - tu  # pocket roof
    fillet = float(g.get("fillet", 0.0))
    if fillet < 0.0 or fillet > min(tf, tu) + 1e-12:
        raise ValueError(
            f"fillet {fillet:g} mm must lie in [0, {min(tf, tu):g}] mm (the block's wall ac_th_for and roof ac_th_up)"
        )
    if yf < yb or yp - yf <= 1e-9 * max(H, 1.0):
        raise ValueError(f"pocket floor {yf - yb:g} mm must lie below the pocket roof ({H - tu:g} mm above the base)")
    yt = yb + H  # block top
    xs = [-gap / 2, 0.0] if end_gaps else [0.0]
    for k in range(n):
        x0 = k * (d + gap)
        xs += [x0 + tf, x0 + d - tf, x0 + d]
        if k < n - 1:
            xs.append(x0 + d + gap)
    if end_gaps:
        xs.append(L + gap / 2)
    xb = np.array(xs)
    above = np.array([yb, yf, yp, yt]) if yf > yb else np.array([yb, yp, yt])  # breakpoints of one side
    rx, ry, rz = refine
    xc = _divisions(xb, h, rx)
    npap, nbase = layers
    yc = np.concatenate(
        [
            _divisions(-above[::-1], h, ry),
            np.linspace(-yb, -y0, nbase + 1)[1:],
            np.linspace(-y0, y0, npap + 1)[1:],
            np.linspace(y0, yb, nbase + 1)[1:],
            _divisions(above, h, ry)[1:],
        ]
    )
    coords = [xc, yc]
    if dim == 3:
        zb = np.array([0.0, g["width"] / 2 - ts, g["width"] / 2])
        coords.append(_divisions(zb, h, rz))
    pockets = [(k * (d + gap) + tf, k * (d + gap) + d - tf) for k in range(n)]
    gaps = [(k * (d + gap) + d, (k + 1) * (d + gap)) for k in range(n - 1)]

    def solid(c):
        x, ay = c[0], np.abs(c[1])
        hole = np.zeros(x.shape, bool)
        in_z = np.ones(x.shape, bool) if dim == 2 else c[2] < g["width"] / 2 - ts
        for a, b in pockets:
            hole |= (x > a) & (x < b) & (ay > yf) & (ay < yp) & in_z
        for a, b in gaps:
            hole |= (x > a) & (x < b) & (ay > yb)
        hole |= ((x < 0) | (x > L)) & (ay > yb)  # the half gaps past the end blocks (end_gaps)
        return ~hole

    mesh, faces, owner = build_grid_mesh(coords, solid)
    p = mesh.p
    centres = p[:, mesh.t].mean(axis=1)
    material = (np.abs(centres[1]) < y0).astype(np.int64)
    mid = p[:, faces].mean(axis=2)
    tol = 1e-9 * max(L, 1.0) + 1e-9
    facets: dict[str, np.ndarray] = {}
    for side, sgn in (("top", 1.0), ("bottom", -1.0)):
        ys = sgn * mid[1]
        sel = np.zeros(faces.shape[0], bool)
        in_z = np.ones(faces.shape[0], bool) if dim == 2 else mid[2] < g["width"] / 2 - ts + tol
        for a, b in pockets:
            sel |= (mid[0] > a - tol) & (mid[0] < b + tol) & (ys > yf - tol) & (ys < yp + tol) & in_z
        facets[f"cavity_{side}"] = faces[sel]
    surfaces = []
    part_of: dict[str, np.ndarray] = {}  # per contact surface, the part (wall, floor, block side) of each facet
    for side, sgn in (("top", 1.0), ("bottom", -1.0)):
        ys = sgn * mid[1]
        for k, (a, b) in enumerate(gaps):
            for name, x in (("left", a), ("right", b)):
                sel = (np.abs(mid[0] - x) < tol) & (ys > yb)
                facets[f"wall_{side}{k}_{name}"] = faces[sel]
            floor = (np.abs(ys - yb) < tol) & (mid[0] > a) & (mid[0] < b)
            # the blocks' outer faces over the walls next to the gap: when two blocks meet corner to
            # corner, each corner presses on the other's outer face, a master surface of its own
            outer = (np.abs(ys - yt) < tol) & (((mid[0] > a - tf) & (mid[0] < a)) | ((mid[0] > b) & (mid[0] < b + tf)))
            left_outer = outer & (mid[0] < a)
            right_outer = outer & (mid[0] > b)
            parts = [
                np.concatenate([facets[f"wall_{side}{k}_left"], faces[left_outer]]),
                faces[floor],
                np.concatenate([facets[f"wall_{side}{k}_right"], faces[right_outer]]),
            ]
            facets[f"gap_{side}{k}"] = np.concatenate(parts)
            part_of[f"gap_{side}{k}"] = np.repeat(np.arange(3), [len(q) for q in parts])
            surfaces.append(f"gap_{side}{k}")
        if end_gaps:  # the end blocks' outer walls and the backbone's top past them: half a gap each
            for name, x, lo, hi in (("first", 0.0, -gap / 2, 0.0), ("last", L, L, L + gap / 2)):
                wall = (np.abs(mid[0] - x) < tol) & (ys > yb)
                top = (np.abs(ys - yb) < tol) & (mid[0] > lo) & (mid[0] < hi)
                facets[f"gap_{side}_{name}"] = np.concatenate([faces[wall], faces[top]])
                part_of[f"gap_{side}_{name}"] = np.repeat([0, 1], [int(wall.sum()), int(top.sum())])
                surfaces.append(f"gap_{side}_{name}")
    # each pocket's walls (the solid's outward normals point into the pocket); 3D: the half pocket
    # is open at the symmetry plane z = 0
    for side, sgn in (("top", 1.0), ("bottom", -1.0)):
        ys = sgn * mid[1]
        in_z = np.ones(faces.shape[0], bool) if dim == 2 else mid[2] < g["width"] / 2 - ts - tol
        for k, (a, b) in enumerate(pockets):
            in_x = (mid[0] > a + tol) & (mid[0] < b - tol)
            in_y = (ys > yf + tol) & (ys < yp - tol)
            walls = {
                "left": (np.abs(mid[0] - a) < tol) & in_y & in_z,
                "right": (np.abs(mid[0] - b) < tol) & in_y & in_z,
                "floor": (np.abs(ys - yf) < tol) & in_x & in_z,
                "roof": (np.abs(ys - yp) < tol) & in_x & in_z,
            }
            if dim == 3:
                walls["side"] = (np.abs(mid[2] - (g["width"] / 2 - ts)) < tol) & in_x & in_y
            name = f"pocket_{side}{k}"
            facets[name] = np.concatenate([faces[sel] for sel in walls.values()])
            part_of[name] = np.repeat(np.arange(len(walls)), [int(sel.sum()) for sel in walls.values()])
            surfaces.append(name)
    ux = np.unique(np.round(p[0], 9))
    paper = np.abs(p[1]) <= y0 + tol
    x_lo, x_hi = float(xb[0]), float(xb[-1])
    nodes = {
        "clamp": np.flatnonzero(np.abs(p[0] - x_lo) < tol),
        "end": np.flatnonzero(np.abs(p[0] - x_hi) < tol),
        "backbone_end": np.flatnonzero(paper & (np.abs(p[0] - x_hi) < tol)),
        "backbone_prev": np.flatnonzero(paper & (np.abs(p[0] - ux[-2]) < tol)),
    }
    if dim == 3:
        nodes["symmetry"] = np.flatnonzero(np.abs(p[2]) < tol)
    if groups is not None:
        for side, sgn in (("top", 1.0), ("bottom", -1.0)):
            ys = sgn * mid[1]
            in_z = np.ones(faces.shape[0], bool) if dim == 2 else mid[2] < g["width"] / 2 - ts + tol
            for name in dict.fromkeys(groups):
                sel = np.zeros(faces.shape[0], bool)
                for k, (a, b) in enumerate(pockets):
                    if groups[k] == name:
                        sel |= (mid[0] > a - tol) & (mid[0] < b + tol) & (ys > yf - tol) & (ys < yp + tol) & in_z
                facets[f"cavity_{side}_{name}"] = faces[sel]
            facets[f"outer_{side}"] = faces[np.abs(ys - yt) < tol]
        nodes["backbone"] = np.flatnonzero(paper)
    if fillet > 0.0:
        # the blocks' outer corners, both sides; every set above was selected on the square geometry
        blocks = [(k * (d + gap), k * (d + gap) + d) for k in range(n)]
        corners = [(x, sgn * yt, sx, sgn) for a, b in blocks for x, sx in ((a, -1.0), (b, 1.0)) for sgn in (1.0, -1.0)]
        mesh = type(mesh)(round_corners(mesh.p, corners, fillet), mesh.t)
    return UnitMesh(
        mesh=mesh,
        material=material,
        facets=facets,
        nodes=nodes,
        geometry=g,
        h=float(h),
        contact_surfaces=surfaces,
        chamber_group=tuple(groups or ()),
        end_gaps=bool(end_gaps),
        refine=tuple(int(v) for v in refine),
        contact_parts=part_of,
        _boundary=faces,
    )
