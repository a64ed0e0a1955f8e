"""Penalty contact of the unit's facing walls (issue 4 item 4): smoothness, balance, tangent, the former stall."""

import numpy as np
import pytest

from workflow import fem
from workflow.fem._contact import ContactPair, _segment_2d


def _kinked_wall(kink_deg=20.0):
    """Master: three facets of a wall x = 0 (solid on x < 0, outward normal +x), the upper two turned by the kink."""
    a = np.radians(kink_deg)
    pts = np.array([[0.0, 0.0], [0.0, 1.0], [-np.sin(a), 1.0 + np.cos(a)], [-2 * np.sin(a), 1.0 + 2 * np.cos(a)]])
    # facet (a, b) has the outward normal R (b - a) = (t_y, -t_x): upwards for +x
    facets = np.array([[0, 1], [1, 2], [2, 3]])
    return pts, facets


def _gap_along(pts, facets, smooth, ys, x0=-0.02):
    """Gap (mm) and force direction of a slave node sliding along y at x = x0 against the kinked wall."""
    p = np.concatenate([pts, [[x0, 0.0], [x0, 0.1]]]).T
    slave = np.array([[5, 4]])
    pair = ContactPair(p, slave, facets, search=1.0, extend=0.0, smoothing=0.0, smooth_normals=smooth)
    out = []
    for y in ys:
        x = p.copy()
        x[:, 4] = [x0, y]
        _, _, n, g, inside = pair._project(x)
        out.append((g[0], n[0, 0], n[0, 1], inside[0]))
    return np.array(out)


def test_smoothed_normal_is_continuous_across_a_master_node():
    pts, facets = _kinked_wall(20.0)
    ys = np.linspace(0.8, 1.2, 401)
    smooth = _gap_along(pts, facets, True, ys)
    plain = _gap_along(pts, facets, False, ys)
    assert smooth[:, 3].all()
    # the interpolated normal turns gradually across the node at y = 1 ...
    assert np.abs(np.diff(smooth[:, 1:3], axis=0)).max() < 0.01
    assert np.abs(np.diff(smooth[:, 0])).max() < 1e-3
    # ... whereas the facet normal jumps by the kink (20 deg: |dn| = 2 sin 10 deg = 0.35)
    assert np.abs(np.diff(plain[:, 1:3], axis=0)).max() > 0.3


def test_segment_projection_reduces_to_the_closest_point_on_a_straight_wall():
    X = np.array([[[0.3, -0.1], [0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [2.0, 0.0]]])
    xi, n, g = _segment_2d(X, np.array([True]), np.array([True]))
    np.testing.assert_allclose([xi[0], g[0]], [0.3, 0.1])
    np.testing.assert_allclose(n[0], [0.0, -1.0])


@pytest.fixture(scope="module")
def pressed_unit():
    """A 2D unit (h = 2 mm) at 150 kPa with contact: walls pressed together."""
    um = fem.build_unit_mesh(h=2.0, dim=2)
    res = fem.solve_unit(um, 150.0, 0.0, "free", True, keep_displacement=True)
    assert res.status == 0
    model = fem.unit_model(um, 150.0, 0.0, "free", True)
    return um, model, res.displacement


def test_contact_forces_balance_and_tangent_matches_finite_differences(pressed_unit):
    um, model, u = pressed_unit
    pair = model.contacts[0]
    x = model.positions(u, um.mesh.p)
    dofs, f, K, gmin = pair.evaluate(x, model.penalty)
    assert dofs.shape[0] > 4  # several slaves in contact
    assert gmin < 0.01
    # no net force and no net couple (each slave's force and reaction share the line along n)
    F = np.bincount(dofs.ravel(), weights=f.ravel(), minlength=x.size).reshape(-1, 2)
    np.testing.assert_allclose(F.sum(axis=0), 0.0, atol=1e-9 * np.abs(F).max())
    moment = np.sum(x[0] * F[:, 1] - x[1] * F[:, 0])
    assert abs(moment) < 1e-8 * np.abs(F).max() * 20.0
    # tangent against central differences of the assembled force in a random direction
    rng = np.random.default_rng(1)
    du = rng.normal(size=x.shape) * 1e-6
    n = x.size

    def force(xx):
        d, ff, _, _ = pair.evaluate(xx, model.penalty, tangent=False)
        return np.bincount(d.ravel(), weights=ff.ravel(), minlength=n)

    fd = (force(x + du) - force(x - du)) / 2
    du_flat = du.T.ravel()
    Kdu = np.zeros(n)
    np.add.at(Kdu, dofs, np.einsum("cij,cj->ci", K, du_flat[dofs]))
    assert np.linalg.norm(fd - Kdu) < 1e-4 * np.linalg.norm(Kdu)


def test_unit_with_contact_passes_the_former_stall_at_half_mm():
    # facet normals stalled at 106 kPa on this mesh (a block's corner on a node of the facing wall)
    res = fem.solve_unit({"dim": 2, "h": 0.5}, 120.0, 0.0, "free", True)
    assert res.status == 0, res.reason
    assert res.max_penetration_mm < 0.02
