"""Penalty contact of the unit's facing walls: smoothness, balance, tangent, the former stall."""

import numpy as np
import pytest

from workflow import fem
from workflow.fem import _contact
from workflow.fem._contact import ContactPair, _segment_2d
from workflow.fem._unit import self_contact_pairs


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


def _kinked_sheet(kink_deg=20.0):
    """3D master: a 3 x 2 grid of facets, the x > 1 column turned down by the kink about the edge x = 1 (outward +y)."""
    a = np.radians(kink_deg)
    xs = [(-1.0, 0.0), (0.0, 0.0), (1.0, 0.0), (1.0 + np.cos(a), -np.sin(a))]
    pts = np.array([[x, y, z] for z in (0.0, 1.0, 2.0) for x, y in xs])  # node = 4 z + i
    facets = np.array(
        [[4 * j + i, 4 * (j + 1) + i, 4 * (j + 1) + i + 1, 4 * j + i + 1] for j in (0, 1) for i in (0, 1, 2)]
    )
    return pts, facets


def test_smoothed_normal_is_continuous_across_a_master_edge_in_3d():
    pts, facets = _kinked_sheet(20.0)
    xs = np.linspace(0.8, 1.2, 401)
    out = {}
    for smooth in (True, False):
        p = np.concatenate([pts, [[0.9, 0.02, 1.0], [0.9, 0.02, 1.2], [0.95, 0.02, 1.1], [0.85, 0.02, 1.1]]]).T
        pair = ContactPair(p, np.array([[12, 13, 14, 15]]), facets, extend=0.0, smooth_normals=smooth)
        rows = []
        for x0 in xs:
            x = p.copy()
            x[:, pair.slave] = np.array([[x0], [-0.02], [1.0 + 0.3 * (x0 - 1.0) + 0.37]])[:, [0] * pair.slave.size]
            _, _, n, g, inside = pair._project(x)
            rows.append(np.concatenate([[g[0]], n[0], [inside[0]]]))
        out[smooth] = np.array(rows)
    assert out[True][:, 4].all()
    # the interpolated normal turns gradually across the edge at x = 1 ...
    assert np.abs(np.diff(out[True][:, 1:4], axis=0)).max() < 0.01
    assert np.abs(np.diff(out[True][:, 0])).max() < 1e-3
    # ... whereas the facet normal jumps by the kink (20 deg: |dn| = 2 sin 10 deg = 0.35)
    assert np.abs(np.diff(out[False][:, 1:4], axis=0)).max() > 0.3


def test_a_slave_just_past_a_ridge_pairs_with_the_facet_its_smoothed_normal_reaches():
    """Along smoothed normals the projection is not the closest point: a slave 2 um past the ridge of a convex
    edge (20 deg) projects into the near facet, while the clipped point of the facet beyond is nearer by a hair;
    the facet it projects into must win (else the slave counts as outside every facet and drops out of contact)."""
    pts, facets = _kinked_sheet(20.0)
    p = np.concatenate([pts, [[1.002, 0.02, 1.5], [1.002, 0.02, 1.6], [1.1, 0.02, 1.6], [1.1, 0.02, 1.5]]]).T
    pair = ContactPair(p, np.array([[12, 13, 14, 15]]), facets, extend=0.0)
    m, _, _, g, inside = pair._project(p)
    k = int(np.flatnonzero(pair.slave == 12)[0])
    assert inside[k] and m[k] in (1, 4)  # the x in (0, 1) column, not the turned-down one
    assert g[k] == pytest.approx(0.02, rel=0.02)


def test_segment_projection_reduces_to_the_closest_point_on_a_straight_wall():
    X = np.array([[[0.3, -0.1], [0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [2.0, 0.0]]])
    xi, n, g = _segment_2d(X, np.array([True]), np.array([True]))
    np.testing.assert_allclose([xi[0], g[0]], [0.3, 0.1])
    np.testing.assert_allclose(n[0], [0.0, -1.0])


@pytest.fixture(scope="module")
def pressed_unit():
    """A 2D unit (h = 1 mm) at 150 kPa with contact: walls pressed together."""
    um = fem.build_unit_mesh(h=1.0, dim=2)
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


#: The stated penetration bound of the unit's penalty contact (config stability.penetration_bound_mm): 5 % of the gap.
PENETRATION_BOUND_MM = 0.05


def test_pockets_stay_open_at_300kpa_2d():
    """P_T = 300 kPa, P_B = 0: the squeezed bottom pockets' walls meet but do not cross.

    The global check (no search radius) finds no boundary node inside foreign material beyond the penalty's
    bound, and the smallest pocket keeps a positive area; with contact across the gaps only (the former model)
    the same check sees the walls pass through each other.
    """
    um = fem.build_unit_mesh(h=1.0, dim=2)
    res = fem.solve_unit_from_config({}, 2, 300.0, 0.0, "free", mesh=um)  # with the workflow's restarts
    assert res.status == 0, res.reason
    assert max(h["overlap_depth_mm"] for h in res.history) <= PENETRATION_BOUND_MM
    assert res.max_penetration_mm <= PENETRATION_BOUND_MM
    assert min(h["min_pocket_area_mm2"] for h in res.history) > 0.1 * 36.4
    gaps_only = fem.build_unit_mesh(h=1.0, dim=2)
    gaps_only.contact_surfaces = [s for s in gaps_only.contact_surfaces if s.startswith("gap_")]
    old = fem.solve_unit(gaps_only, 300.0, 0.0, "free", True, keep_displacement=True)
    x = gaps_only.mesh.p + old.displacement.reshape(-1, 2).T
    depth, n_inside = fem.overlap_depth(x, gaps_only.mesh.t)
    assert depth > 10 * PENETRATION_BOUND_MM and n_inside > 0
    assert min(h["min_pocket_area_mm2"] for h in old.history) < 0.1 * 36.4


@pytest.mark.slow
def test_pockets_stay_open_at_300kpa_3d():
    um = fem.build_unit_mesh(h=2.0, dim=3)
    res = fem.solve_unit_from_config({}, 3, 300.0, 0.0, "free", mesh=um, stops=(0.2, 0.6))  # as the unit check
    assert res.status == 0, res.reason
    assert max(h["overlap_depth_mm"] for h in res.history) <= PENETRATION_BOUND_MM
    assert res.max_penetration_mm <= PENETRATION_BOUND_MM
    assert min(h["min_pocket_volume_mm3"] for h in res.history) > 0.1 * 509.6


def test_overlap_check_sees_a_node_pushed_through_a_wall():
    # a 2x1 block of two cells: move a corner node of the left cell deep into the right cell
    mesh, _, _ = fem.build_grid_mesh([np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0])])
    x = mesh.p.copy()
    assert fem.overlap_depth(x, mesh.t) == (0.0, 0)
    corner = int(np.flatnonzero((x[0] == 0.0) & (x[1] == 1.0))[0])
    x[:, corner] = [1.5, 0.6]  # inside the right cell, 0.4 mm below its top face
    depth, n = fem.overlap_depth(x, mesh.t)
    assert n == 1 and depth == pytest.approx(0.4)
    # pocket area: a unit square hole's walls oriented clockwise (outward normals of the solid point into it)
    sq = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]).T
    walls = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    assert fem.pocket_sizes(sq, [walls])[0] == pytest.approx(1.0)


def test_a_slave_on_a_shared_master_node_keeps_its_force_on_either_facet():
    """A slave at the node two master facets share gets the same force from both (no fade at a shared end).

    The fade of the penalty is meant for the extension past a free edge; at a shared end a projection a
    round-off outside the facet used to get weight 0, so the force vanished whenever the tie between the
    two facets went to that one (Newton then cycled between two residual levels).
    """
    pts, facets = _kinked_wall(20.0)
    a = np.radians(20.0)
    n1 = np.array([1.0 + np.cos(a), np.sin(a)]) / np.linalg.norm([1.0 + np.cos(a), np.sin(a)])  # node 1's normal
    s = pts[1] - 0.02 * n1 + [0.0, 1e-9]  # 0.02 mm inside on node 1's normal, a round-off past facet 0's end
    p = np.concatenate([pts, [s, s + [0.0, 0.1]]]).T
    pair = ContactPair(p, np.array([[5, 4]]), facets, search=1.0, extend=0.5, smoothing=0.01, penalty_factor=1.0)
    forces = []
    for m in (0, 1):  # facet 0 ends at node 1 (the projection lies 1e-9 past it), facet 1 starts there
        nodes = np.concatenate([[4], pair._nodes_2d(np.array([m]))[0]])
        X = p[:, np.maximum(nodes, 0)].T[None]
        lim = (pair.lo[[m]], pair.hi[[m]], pair.prev[[m]] >= 0, pair.next[[m]] >= 0)
        forces.append(pair._local_force(X, np.array([1.0]), lim)[0, :2])
    assert np.linalg.norm(forces[0]) > 0.01  # ~ eps g: the slave is 0.02 mm inside
    np.testing.assert_allclose(forces[0], forces[1], rtol=1e-6, atol=1e-9)


def _block_corner():
    """Master: the convex corner of a block occupying x < 0, y < 0 (wall x = 0, top face y = 0), outward normals."""
    pts = np.array([[0.0, -2.0], [0.0, -1.0], [0.0, 0.0], [-1.0, 0.0], [-2.0, 0.0]])
    return pts, np.array([[0, 1], [1, 2], [2, 3], [3, 4]])  # wall facets (normal +x), then top facets (+y)


def test_contact_tangent_matches_finite_differences_for_a_slave_sliding_round_a_block_corner():
    """The contact tangent, normal's rotation and projection's sliding included, on a slave that slides along the
    wall and along the top face 0.005 mm inside the block (the penalty's linear part) and round the convex corner
    0.005 mm outside it, inside the 0.01 mm band (interpolated nodal normals, the corner's on the bisector)."""
    pts, facets = _block_corner()
    slave_facet = np.array([[6, 5]])
    depth = 0.005
    path = [(-depth, y) for y in np.linspace(-1.6, -0.05, 7)]  # along the wall
    path += [(depth * np.cos(t), depth * np.sin(t)) for t in np.linspace(0.1, 1.4, 5)]  # round the corner, outside
    path += [(x, -depth) for x in np.linspace(-0.05, -1.6, 7)]  # along the top face
    checked = 0
    for xs in path:
        p = np.concatenate([pts, [xs, np.add(xs, [0.0, -0.3])]]).T
        pair = ContactPair(p, slave_facet, facets, search=1.0, extend=0.0, smoothing=0.01)
        x = p.copy()
        dofs, f, K, gmin = pair.evaluate(x, 100.0)
        slaves = dofs[:, 0] // 2 if dofs.size else []
        if 5 not in list(slaves):
            continue  # outside the corner the bisector projection may leave the slave out of reach of the band
        n = x.size

        def force(xx):
            d, ff, _, _ = pair.evaluate(xx, 100.0, tangent=False)
            return np.bincount(d.ravel(), weights=ff.ravel(), minlength=n)

        rng = np.random.default_rng(3)
        for _ in range(3):
            du = rng.normal(size=x.shape) * 1e-7
            fd = (force(x + du) - force(x - du)) / 2
            du_flat = du.T.ravel()
            Kdu = np.zeros(n)
            np.add.at(Kdu, dofs, np.einsum("cij,cj->ci", K, du_flat[dofs]))
            assert np.linalg.norm(fd - Kdu) < 1e-4 * np.linalg.norm(Kdu), xs
        checked += 1
    assert checked == len(path)  # the wall, the corner and the top face: every position in contact


def test_newton_converges_quadratically_on_a_contact_step_whose_active_set_does_not_change(pressed_unit):
    """From the converged 150 kPa state (walls pressed together), 150 -> 152 kPa: the same slaves stay in contact on
    the same facets at every iterate, and once in its asymptotic range the residual falls quadratically,
    r_k+1 / r_0 <= 10 (r_k / r_0)^2, down to 1e-8 r_0 within eight iterations (a tangent without the normal's
    rotation or the projection's sliding contracts linearly here)."""
    from workflow.fem import _solve

    um, model, _ = pressed_unit
    start = _solve.solve_path(model, um.mesh.p)
    assert start.status == 0
    nxt = fem.unit_model(um, 152.0, 0.0, "free", True)
    norms, active = [], []
    evaluate = nxt.evaluate

    def recording(u, lam, p_ref, tangent=True):
        r, K, info = evaluate(u, lam, p_ref, tangent)
        if tangent and r is not None:
            rr = nxt.T.T @ r
            norms.append(float(np.sqrt(rr @ rr + info["r_internal"] @ info["r_internal"])))
            pair = nxt.contacts[0]
            m, _, _, g, inside = pair._project(nxt.positions(u, p_ref))
            act = inside & (g < pair.smoothing)
            active.append(frozenset(zip(pair.slave[act].tolist(), m[act].tolist())))
        return r, K, info

    nxt.evaluate = recording
    opts = dict(_solve.DEFAULT_SOLVER, rtol=1e-9, atol=1e-14, max_iter=8, line_search=False)
    ok, *_ = _solve._newton(nxt, start.state, 1.0, um.mesh.p, opts)
    assert ok
    assert len(active[0]) > 4 and all(a == active[0] for a in active)
    r = np.array(norms) / norms[0]
    assert r[-1] < 1e-8
    # the last contraction before convergence (above round-off) is quadratic
    k = int(np.flatnonzero(r > 1e-7)[-1])
    assert r[k + 1] <= 10.0 * r[k] ** 2, r


def _sliding_block(dx_mm: float, mu: float, friction_factor: float = 0.1):
    """A 2 x 2 mm silicone block pressed 0.1 mm into a wider one (after a 0.1 mm gap) and pushed along it.

    Plane strain, h = 0.5 mm; the wide block's base is fixed, the small block's top face is moved by
    (dx_mm, -0.2 mm), proportionally.  Returns the pair, the penalty (MPa/mm) and the final nodal positions (mm).
    """
    dim = 2
    from workflow.fem._mesh import build_grid_mesh
    from workflow.fem._solve import Model, solve_path
    from workflow.fem._unit import DEFAULT_FORMULATION, material_constants, solid_assembler

    xs = np.linspace(0.0, 6.0, 13)
    ys = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.1, 2.6, 3.1, 3.6, 4.1])

    def keep(c):
        upper = c[1] > 2.1
        return (~upper & (c[1] < 2.0)) | (upper & (c[0] > 1.0) & (c[0] < 3.0))

    mesh, faces, _ = build_grid_mesh([xs, ys], keep)
    p = mesh.p
    mid = p[:, faces].mean(axis=2)
    master, slave = faces[np.abs(mid[1] - 2.0) < 1e-9], faces[np.abs(mid[1] - 2.1) < 1e-9]
    mat = material_constants()
    solid = solid_assembler(mesh, np.zeros(mesh.t.shape[1], int), mat, DEFAULT_FORMULATION)
    base, top = np.flatnonzero(p[1] < 1e-9), np.flatnonzero(np.abs(p[1] - 4.1) < 1e-9)
    moved = {int(dim * n): dx_mm for n in top} | {int(dim * n + 1): -0.2 for n in top}
    pair = ContactPair(p, slave, master, search=1.0, extend=0.0, smoothing=0.0)
    pair.mu, pair.friction_factor = mu, friction_factor
    eps = 100.0 * mat["mu0"]  # the unit's penalty, MPa/mm
    fixed = (dim * base[:, None] + np.arange(dim)).ravel()
    model = Model(solid, contacts=[pair], penalty=eps, fixed=fixed, prescribed=moved)
    res = solve_path(model, p, {"initial_step": 0.05, "max_step": 0.1})
    assert res.status == 0, res.reason
    return pair, eps, model.positions(res.u, p)


@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_a_sliding_block_carries_mu_times_its_normal_force(mu):
    pair, eps, x = _sliding_block(1.0, mu)
    _, f, _, _ = pair.evaluate(x, eps, tangent=False)
    f = f[:, :2]  # the slaves' share
    tangential, normal = -f[:, 0].sum(), -f[:, 1].sum()  # force of the wide block on the slaves, N (per mm in 2D)
    assert normal > 0.1
    # Coulomb: every slave slides, so the tangential force is mu times the normal force, opposing the push
    # (2 %: the pushed block tilts, so its facets' normals are not quite the y axis)
    assert -tangential / normal == pytest.approx(mu, rel=0.02)


def test_a_block_pushed_less_than_the_friction_limit_sticks_and_frictionless_contact_carries_no_shear():
    pair, eps, x = _sliding_block(0.05, 0.5)
    _, f, _, _ = pair.evaluate(x, eps, tangent=False)
    assert 0 < f[:, 0].sum() / -f[:, 1].sum() < 0.25  # well below mu = 0.5: it sticks
    assert (pair.anchor_facet >= 0).all()
    pair, eps, x = _sliding_block(1.0, 0.0)
    _, f, _, _ = pair.evaluate(x, eps, tangent=False)
    assert abs(f[:, 0].sum()) < 1e-9 * abs(f[:, 1].sum())


def _assembled(pair, x, eps, tangent=False):
    """A pair's force on every dof (node-interleaved) and, with ``tangent``, its dense assembled tangent."""
    dofs, f, K, _ = pair.evaluate(x, eps, tangent)
    r = np.bincount(dofs.ravel(), weights=f.ravel(), minlength=x.size)
    if not tangent:
        return r
    k = dofs.shape[1]
    rows, cols = np.repeat(dofs, k, axis=1).ravel(), np.tile(dofs, (1, k)).ravel()
    Kg = np.zeros((x.size, x.size))
    np.add.at(Kg, (rows, cols), K.ravel())
    return r, Kg


def test_friction_tangent_matches_finite_differences_in_stick_and_slip():
    for dx in (0.05, 1.0):  # stick, slip
        pair, eps, x = _sliding_block(dx, 0.5)
        if dx > 0.5:
            # a slipping slave's anchor sits exactly at the friction limit after the step (return mapping): move
            # the slaves on by 1 um so that each lies inside the slip branch, not on the switch between the two
            x = x.copy()
            x[0, pair.slave] += 1e-3
        _, K = _assembled(pair, x, eps, tangent=True)
        v = np.random.default_rng(0).standard_normal(x.shape) * 1e-6
        fd = (_assembled(pair, x + v, eps) - _assembled(pair, x - v, eps)) / 2.0
        lin = K @ v.T.ravel()  # node-interleaved dofs
        assert np.abs(fd - lin).max() <= 1e-4 * np.abs(lin).max()


def _stacked_slabs(mu: float) -> tuple:
    """Two hexahedral slabs, the upper (x 2..4 mm) 0.1 mm above the lower, on aligned grids: the pair of the upper
    one's bottom face (slave) against the lower one's top face (master), Coulomb mu; and the reference nodes."""
    from workflow.fem._mesh import build_grid_mesh

    xs, zs = np.linspace(0.0, 6.0, 13), np.linspace(0.0, 2.0, 5)
    ys = np.array([0.0, 1.0, 2.0, 2.1, 3.1])

    def keep(c):
        upper = c[1] > 2.1
        return (~upper & (c[1] < 2.0)) | (upper & (c[0] > 2.0) & (c[0] < 4.0))

    mesh, faces, _ = build_grid_mesh([xs, ys, zs], keep)
    p = mesh.p
    mid = p[:, faces].mean(axis=2)
    master, slave = faces[np.abs(mid[1] - 2.0) < 1e-9], faces[np.abs(mid[1] - 2.1) < 1e-9]
    pair = ContactPair(p, slave, master, search=1.0, extend=0.5, smoothing=0.0)
    pair.mu, pair.friction_factor = mu, 0.1
    return pair, p


def test_friction_in_3d_sticks_then_slides_at_mu_times_the_normal_force():
    """Contact pair alone (no FE solve): the faces of two stacked hexahedral slabs, the upper one's nodes
    pressed 0.05 mm in and anchored, then moved along x by a little (stick) or a lot (slip)."""
    pair, p = _stacked_slabs(0.5)
    eps = 71.6
    pressed = p.copy()
    pressed[1, pair.slave] -= 0.15  # 0.05 mm into the lower slab
    pressed[0, pair.slave] += 0.13  # off the lower slab's nodes (the projection is then inside one facet)
    pair.commit(pressed, eps)
    assert (pair.anchor_facet >= 0).all()
    k_t = 0.1 * eps * pair.area  # tangential spring per slave, N/mm
    for shift, slips in ((0.1, False), (1.0, True)):  # the cap: mu eps g = 1.79 MPa, the spring 7.16 MPa/mm
        x = pressed.copy()
        x[0, pair.slave] += shift
        _, f, _, _ = pair.evaluate(x, eps, tangent=False)
        fs = f[:, :3]
        normal, tangential = fs[:, 1].sum(), fs[:, 0].sum()  # residual shares: the slab pushes up, friction back
        assert normal < 0
        if slips:
            assert tangential == pytest.approx(0.5 * -normal, rel=1e-9)
        else:
            assert tangential == pytest.approx(k_t.sum() * shift, rel=1e-6)
            assert tangential < 0.5 * -normal


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_3d_contact_tangent_matches_finite_differences_off_the_master_edges(mu):
    """The 3D pair's tangent (its own local finite differences, smoothed normals) against central differences of
    the assembled force.

    Stacked slabs with aligned grids put every slave exactly on a master edge, where node-to-face contact has a kink
    (the master's bilinear shape functions peak there), and a central difference straddling it is not a derivative:
    shifted off the edges in x and z and perturbed, the two agree to 1e-9 (measured); with the slaves on the z
    edges they differ by 12-99 % (tangent and force are right, the force is just not differentiable there).
    """
    pair, p = _stacked_slabs(mu)
    eps = 71.6
    rng = np.random.default_rng(0)
    x = p.copy()
    x[1, pair.slave] -= 0.15
    x[0, pair.slave] += 0.13
    x[2, pair.slave] += 0.13
    x += 0.01 * rng.standard_normal(x.shape)  # facets no longer coplanar: the nodal normals turn
    pair.commit(x, eps)
    x[0, pair.slave] += 0.05 if mu else 0.0  # friction: stretch the anchors' springs (stick)
    _, K = _assembled(pair, x, eps, tangent=True)
    v = rng.standard_normal(x.shape) * 1e-5
    fd = (_assembled(pair, x + v, eps) - _assembled(pair, x - v, eps)) / 2.0
    lin = K @ v.T.ravel()
    assert np.linalg.norm(fd - lin) <= 1e-6 * np.linalg.norm(lin)


def test_a_collapsed_master_facet_is_out_of_reach_not_a_nan():
    """A master facet squeezed to a point has a singular projection (Cramer's rule gives NaN): its slaves pair with
    a sound neighbour or with nothing, and the search returns no NaN gap."""
    pair, p = _stacked_slabs(0.0)
    x = p.copy()
    x[1, pair.slave] -= 0.15  # pressed 0.05 mm into the lower slab
    k = len(pair.master) // 2
    f = pair.master[k]
    x[:, f] = x[:, f].mean(axis=1, keepdims=True)  # that facet's four nodes on one point
    m, _, _, g, inside = pair._project(x)
    assert not np.isnan(g).any()
    assert inside.any() and np.isfinite(g[inside]).all() and (m[inside] != k).all()
    dofs, force, K, gmin = pair.evaluate(x, 71.6)
    assert np.isfinite(force).all() and np.isfinite(K).all() and np.isfinite(gmin)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_search_skips_only_slaves_out_of_reach(monkeypatch, dim):
    """The search projects only slaves within reach + search of some facet of their pool (3D: of its centroid; 2D:
    of the facet with its extension past a free edge); every slave the full search finds within the search distance
    of a facet it projects into is found alike, and the rest are out of reach (the unit's pocket and gap walls,
    moved by a smooth field and noise)."""
    um = fem.build_unit_mesh(None, h=4.0 if dim == 3 else 0.5, dim=dim)
    pairs = self_contact_pairs(um)
    rng = np.random.default_rng(1)
    p = um.mesh.p
    x = p + 0.3 * np.sin(p[np.roll(np.arange(dim), -1)] / 3.0) + 0.05 * rng.standard_normal(p.shape)
    skipped = 0
    for pair in pairs:
        m, N, n, g, inside = pair._project(x)
        monkeypatch.setattr(_contact, "REACH_FILTER", False)
        m0, N0, n0, g0, in0 = pair._project(x)  # every slave projected
        monkeypatch.setattr(_contact, "REACH_FILTER", True)
        ok0 = in0 & (np.abs(g0) <= pair.search)
        assert ok0.any()
        np.testing.assert_array_equal(inside & (np.abs(g) <= pair.search), ok0)
        np.testing.assert_array_equal(m[ok0], m0[ok0])
        np.testing.assert_array_equal(g[ok0], g0[ok0])
        np.testing.assert_array_equal(n[ok0], n0[ok0])
        skipped += int(np.isinf(g).sum())
    assert skipped > 0  # the filter did skip some


@pytest.mark.parametrize("summed", [False, True])
def test_skin_under_a_gap_between_two_blocks_feels_a_continuous_force(summed):
    """A slave 0.02 mm below the gap between two master walls (two blocks' bottoms 1 mm apart, their extensions
    past the free edges overlapping) slides across the gap: with the extensions summed its force changes by less
    than 2 % of its largest value between samples 0.005 mm apart; choosing the nearer wall alone jumps by 34 % of it."""
    p = np.array([[-2.0, -0.5, 0.5, 2.0, 0.0, 10.0], [0.0, 0.0, -0.03, -0.03, -0.02, -50.0]])
    pair = ContactPair(
        p, np.array([[4, 5]]), np.array([[0, 1], [2, 3]]), search=1.0, extend=0.5, smoothing=0.1, sum_extensions=summed
    )
    forces = []
    for xs in np.linspace(-0.6, 0.6, 241):
        x = p.copy()
        x[0, 4] = xs
        dofs, f, _, _ = pair.evaluate(x, 1.0, tangent=False)
        forces.append(np.bincount(dofs.ravel(), weights=f.ravel(), minlength=12))
    forces = np.array(forces)
    jump = np.abs(np.diff(forces, axis=0)).max() / np.abs(forces).max()
    assert (jump < 0.02) if summed else (jump > 0.3)
