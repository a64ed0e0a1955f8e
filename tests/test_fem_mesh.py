"""The unit mesh's rounded block corners (``geometry.fillet``): geometry only, no solve."""

from __future__ import annotations

import numpy as np
import pytest

from workflow import fem
from workflow.fem._mesh import round_corners


def _quad_areas(p, t):
    x, y = p[0][t], p[1][t]
    return 0.5 * ((x[0] - x[2]) * (y[1] - y[3]) - (x[1] - x[3]) * (y[0] - y[2]))


@pytest.mark.parametrize("h, r", [(1.0, 2.0), (0.5, 1.0), (0.25, 2.0)])
def test_fillet_puts_the_corner_nodes_on_the_arc_and_leaves_the_rest(h, r):
    square = fem.build_unit_mesh(h=h, dim=2)
    round_ = fem.build_unit_mesh({"fillet": r}, h=h, dim=2)
    p0, p = square.mesh.p, round_.mesh.p
    assert np.array_equal(square.mesh.t, round_.mesh.t)
    for key in square.facets:  # the sets are chosen on the square geometry: same facets
        assert np.array_equal(square.facets[key], round_.facets[key])
    g = square.geometry
    yt = g["paper_width"] / 2 + g["bot_layer"] + g["height"]
    moved = np.flatnonzero(np.any(np.abs(p - p0) > 1e-12, axis=0))
    # every moved node lies within r of a block's outer corner, inside the block
    d, gap = g["depth"], g["gap"]
    corners = [(k * (d + gap) + e, s * yt) for k in range(3) for e in (0.0, d) for s in (1.0, -1.0)]
    near = np.zeros(p0.shape[1], bool)
    for cx, cy in corners:
        near |= (np.abs(p0[0] - cx) <= r + 1e-9) & (np.abs(p0[1] - cy) <= r + 1e-9)
    assert moved.size and near[moved].all()
    # the corner nodes and every boundary node of the corner squares' outer sides lie on the arc
    for k in range(3):
        x0 = k * (d + gap)
        for cx, sx in ((x0, -1.0), (x0 + d, 1.0)):
            for s in (1.0, -1.0):
                on_outer = (
                    (np.abs(p0[1] - s * yt) < 1e-9) & (sx * (p0[0] - cx) >= -r - 1e-9) & (sx * (p0[0] - cx) <= 1e-9)
                ) | ((np.abs(p0[0] - cx) < 1e-9) & (s * (p0[1] - s * yt) >= -r - 1e-9))
                centre = np.array([cx - sx * r, s * yt - s * r])
                dist = np.hypot(p[0, on_outer] - centre[0], p[1, on_outer] - centre[1])
                np.testing.assert_allclose(dist, r, rtol=1e-12)
    areas = _quad_areas(p, round_.mesh.t)
    assert areas.min() > 0.1 * h * h / 4  # no inverted or collapsed element
    # the section loses (4 - pi) r^2 / 4 per corner, 12 corners
    loss = _quad_areas(p0, square.mesh.t).sum() - areas.sum()
    n_arc = int(np.ceil(r / h))
    exact = 12 * (4 - np.pi) * r * r / 4
    # the arc's nodes: the square's outer sides' nodes sent radially, at angles atan(j / n) and pi/2 - those
    half = np.arctan(np.arange(n_arc + 1) / n_arc)
    theta = np.concatenate([half, np.pi / 2 - half[::-1][1:]])
    polygon = 12 * r * r * (1 - 0.5 * np.sin(np.diff(theta)).sum())
    assert loss == pytest.approx(polygon, rel=1e-9)
    assert loss == pytest.approx(exact, rel=0.2 if n_arc < 4 else 0.02)


def test_round_corners_maps_a_square_onto_a_quarter_disc():
    s = np.linspace(0.0, 1.0, 5)
    X, Y = np.meshgrid(s, s)
    p = np.stack([X.ravel(), Y.ravel()])
    q = round_corners(p, [(1.0, 1.0, 1.0, 1.0)], 1.0)
    r = np.hypot(q[0], q[1])
    outer = (np.abs(p[0] - 1) < 1e-12) | (np.abs(p[1] - 1) < 1e-12)
    np.testing.assert_allclose(r[outer], 1.0)
    inner = (p[0] == 0) | (p[1] == 0)
    np.testing.assert_allclose(q[:, inner], p[:, inner])
    assert np.all(r <= 1.0 + 1e-12)


def test_a_fillet_larger_than_the_walls_is_an_error():
    with pytest.raises(ValueError, match="fillet 2.5 mm"):
        fem.build_unit_mesh({"fillet": 2.5}, h=1.0, dim=2)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_divides_every_element_of_the_base_mesh_into_r_per_direction(dim):
    # a systematic family: every interval's count, the paper's and base layers' included, times r, so that
    # each cell of the base mesh becomes r**dim cells and every base node stays a node
    base = fem.build_unit_mesh(h=4.0, dim=dim)
    for r in (2, 3):
        fine = fem.build_unit_mesh(h=4.0, dim=dim, refine=r)
        assert fine.refine == (r, r, r)
        assert fine.mesh.t.shape[1] == r**dim * base.mesh.t.shape[1]
        for k in range(dim):
            xb, xf = np.unique(base.mesh.p[k]), np.unique(fine.mesh.p[k])
            assert xf.size == r * (xb.size - 1) + 1
            assert np.all(np.min(np.abs(xf[:, None] - xb[None, :]), axis=0) < 1e-12)
        paper = fine.material == 1
        assert paper.sum() == r**dim * (base.material == 1).sum()
    with pytest.raises(ValueError, match="refine"):
        fem.build_unit_mesh(h=4.0, dim=2, refine=0)


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_per_direction_divides_only_the_directions_asked_for(dim):
    # (length, height) = (1, 2): the height's intervals and the paper and base layers halved, the length and the
    # width (3D: as the length) untouched
    base = fem.build_unit_mesh(h=4.0, dim=dim)
    fine = fem.build_unit_mesh(h=4.0, dim=dim, refine=(1, 2))
    assert fine.refine == (1, 2, 1)
    assert fine.mesh.t.shape[1] == 2 * base.mesh.t.shape[1]
    assert (fine.material == 1).sum() == 2 * (base.material == 1).sum()
    counts = [np.unique(m.mesh.p[k]).size - 1 for m in (base, fine) for k in range(dim)]
    assert counts[dim:] == [counts[0], 2 * counts[1]] + counts[2:dim]
    for bad in ((1, 2, 1, 1), True, (1, 0)):
        with pytest.raises(ValueError, match="refine"):
            fem.build_unit_mesh(h=4.0, dim=2, refine=bad)
