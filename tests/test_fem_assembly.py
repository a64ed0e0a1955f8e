"""The batched-matmul element assembly against central finite differences.

On small deformed 2D and 3D meshes with silicone (Mooney-Rivlin, id 0), paper
(neo-Hooke, id 1) and a further neo-Hooke id, for the mean-dilatation and the
plain displacement element: every column of the assembled tangent equals the
central difference of the residual, and the residual the central difference
of the energy.
"""

import numpy as np
import pytest

from workflow import fem
from workflow.fem import _assembly

EPS = 1e-6
MAT = dict(fem.material_constants({}), neo_hooke={2: (0.5, 20.0)})  # MPa


def _deformed_mesh(dim, seed=0):
    """A 3x2 quad / 2x2x1 hex block with ids 0, 1, 2 and a smooth plus random displacement (mm)."""
    coords = (
        [np.linspace(0.0, 2.0, 4), np.linspace(0.0, 1.0, 3)]
        if dim == 2
        else [np.linspace(0.0, 2.0, 3), np.linspace(0.0, 1.0, 3), np.linspace(0.0, 1.0, 2)]
    )
    mesh, _, _ = fem.build_grid_mesh(coords)
    material = np.arange(mesh.t.shape[1]) % 3
    p = mesh.p
    rng = np.random.default_rng(seed)
    u = 0.15 * np.sin(p[0])[None] * np.linspace(1.0, 0.5, dim)[:, None] + 0.03 * rng.standard_normal(p.shape)
    return mesh, material, u.T.ravel()


def _tangent_error(solid, u):
    """max |K - K_fd| / max |K| over the full matrix."""
    f, k, jmin = solid.assemble(u)
    assert jmin > 0.5
    K = _assembly.Pattern(solid.rows, solid.cols, solid.ndofs).matrix(k).toarray()
    K_fd = np.empty_like(K)
    for j in range(solid.ndofs):
        e = np.zeros(solid.ndofs)
        e[j] = EPS
        K_fd[:, j] = (solid.assemble(u + e, False)[0] - solid.assemble(u - e, False)[0])[: solid.ndofs] / (2 * EPS)
    return np.abs(K - K_fd).max() / np.abs(K).max()


@pytest.mark.parametrize("mixed", [True, False])
@pytest.mark.parametrize("dim", [2, 3])
def test_tangent_matches_finite_differences(dim, mixed):
    mesh, material, u = _deformed_mesh(dim)
    solid = fem.SolidAssembler(mesh, material, MAT, mixed=mixed)
    assert _tangent_error(solid, u) < 1e-6


@pytest.mark.parametrize("dim", [2, 3])
def test_check_detects_a_missing_tangent_term(dim, monkeypatch):
    # drop the second half of p d2J (the c_ak c_bi term): the check above must see it
    mesh, material, u = _deformed_mesh(dim)
    solid = fem.SolidAssembler(mesh, material, MAT)
    monkeypatch.setattr(_assembly, "_swap_ik", lambda M, nbf, d: 0.0 * M)
    assert _tangent_error(solid, u) > 1e-3


@pytest.mark.parametrize("mixed", [True, False])
@pytest.mark.parametrize("dim", [2, 3])
def test_residual_is_energy_gradient(dim, mixed):
    mesh, material, u = _deformed_mesh(dim, seed=1)
    solid = fem.SolidAssembler(mesh, material, MAT, mixed=mixed)
    f, _, _ = solid.assemble(u, False)
    du = EPS * np.random.default_rng(2).standard_normal(u.size)
    dE = (solid.energy(u + du) - solid.energy(u - du)) / 2
    assert dE == pytest.approx(f[: u.size] @ du, rel=1e-6)


def test_unknown_material_id_is_an_error():
    mesh, material, _ = _deformed_mesh(2)
    with pytest.raises(ValueError, match="material ids"):
        fem.SolidAssembler(mesh, material, fem.material_constants({}))


def _random_system(n, seed, density=0.05):
    """A sparse, diagonally dominant nonsymmetric matrix (CSR) and a right-hand side."""
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng) + sp.eye(n) * n * density * 2
    return sp.csr_matrix(A), rng.standard_normal(n)


@pytest.mark.parametrize("backend", ["pardiso", "superlu"])
def test_direct_solver_reuses_analysis_while_the_pattern_fits(backend):
    from workflow.fem import _linsolve

    solver = _linsolve.DirectSolver()
    if backend == "superlu":
        solver._pardiso = None
    elif solver._pardiso is None:
        pytest.skip("pypardiso not installed")
    A, b = _random_system(200, 0)
    sub = A.tolil()
    sub[0, 1:] = 0.0  # a pattern inside the analysed one
    B, c = _random_system(200, 1)  # a different pattern
    for M, rhs in ((A, b), (1.5 * A, b), (sub.tocsr(), b), (B, c)):
        M = M.tocsr()
        M.eliminate_zeros()
        x = solver.solve(M, rhs)
        assert np.linalg.norm(M @ x - rhs) < 1e-10 * np.linalg.norm(rhs)
    if backend == "pardiso":
        assert solver.stats["analyses"] == 2 and solver.stats["factorisations"] == 4


@pytest.mark.parametrize("halo", [True, False])
def test_direct_solver_halo_takes_a_slave_sliding_to_the_next_facet_without_a_new_analysis(halo):
    """A coupling (0, 6) next to a new coupling (0, 5) (6 is coupled to 5 in the body) fits the pattern analysed
    with the halo; without it PARDISO analyses again.  Same solutions either way."""
    import scipy.sparse as sp

    from workflow.fem import _linsolve

    solver = _linsolve.DirectSolver(halo=halo)
    if solver._pardiso is None:
        pytest.skip("pypardiso not installed")
    n = 12
    body = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(n, n), format="lil")
    b = np.arange(1.0, n + 1)
    for j in (None, 5, 6):
        M = body.copy()
        if j is not None:
            M[0, j] = M[j, 0] = -0.5
        M = M.tocsr()
        x = solver.solve(M, b)
        assert np.linalg.norm(M @ x - b) < 1e-12 * np.linalg.norm(b)
    assert solver.stats["analyses"] == (2 if halo else 3)


def test_direct_solver_union_pattern_is_the_sorted_union_of_the_patterns_and_the_halo():
    """The analysed pattern after a matrix with new entries: old keys, the new ones and their halo, sorted and
    unique (the merge of sorted keys gives what np.unique of their concatenation gives)."""
    from workflow.fem import _linsolve

    solver = _linsolve.DirectSolver(max_growth=10.0)
    if solver._pardiso is None:
        pytest.skip("pypardiso not installed")
    A, b = _random_system(300, 2, density=0.02)
    B = A.tolil()
    for i, j in ((0, 299), (5, 150), (299, 0), (150, 5), (7, 8)):
        B[i, j] = 0.1
    B = B.tocsr()
    solver.solve(A, b)
    solver.solve(B, b)
    ka, kb = _linsolve._keys(A), _linsolve._keys(B)
    new = kb[~np.isin(kb, ka)]
    expected = np.unique(np.concatenate([ka, new, _linsolve._halo(B, new)]))
    np.testing.assert_array_equal(solver._pattern[0], expected)
    assert solver.stats["analyses"] == 2


def test_reduce_matrix_is_the_constraint_product():
    import scipy.sparse as sp

    from workflow.fem import _linsolve

    K, _ = _random_system(30, 2, density=0.2)
    # dofs 0 and 5 fixed, 7 / 8 / 9 tied to one unknown, the rest free
    col = np.full(30, -1)
    free = [i for i in range(30) if i not in (0, 5, 7, 8, 9)]
    col[free] = np.arange(len(free))
    col[[7, 8, 9]] = len(free)
    rows = np.flatnonzero(col >= 0)
    T = sp.csr_matrix((np.ones(rows.size), (rows, col[rows])), shape=(30, len(free) + 1))
    np.testing.assert_allclose(_linsolve.reduce_matrix(K, T).toarray(), (T.T @ K @ T).toarray(), rtol=1e-14, atol=1e-12)


def test_threads_give_the_same_assembly():
    um = fem.build_unit_mesh(h=2.0, dim=3)
    u = 0.01 * np.random.default_rng(3).standard_normal(3 * um.mesh.p.shape[1])
    mat = fem.material_constants({})
    one = fem.SolidAssembler(um.mesh, um.material, mat, threads=1, chunk_points=512).assemble(u)
    two = fem.SolidAssembler(um.mesh, um.material, mat, threads=2, chunk_points=512).assemble(u)
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])
    assert one[2] == two[2]


@pytest.mark.parametrize("dim", [2, 3])
def test_enhanced_strains_condense_exactly(dim):
    # enhanced (incompatible-mode) parameters in every material id, at a state with r_alpha != 0: the residual
    # is the energy's gradient in the full state, and along [du; recover(du)] the nodal residual changes by
    # K_c du + correction while r_alpha changes by -r_alpha (the Newton step of the static condensation)
    mesh, material, u = _deformed_mesh(dim)
    solid = fem.SolidAssembler(mesh, material, MAT, enhanced=(0, 1, 2), lagged_pressure=False)
    rng = np.random.default_rng(dim)
    state = np.concatenate([u, 0.01 * rng.standard_normal(solid.n_internal)])
    assert solid.n_internal == dim * dim * mesh.t.shape[1]
    f, k, jmin = solid.assemble(state)
    assert jmin > 0.5
    n = solid.ndofs
    d = 1e-6 * rng.standard_normal(solid.nstate)
    dE = (solid.energy(state + d) - solid.energy(state - d)) / 2
    assert dE == pytest.approx(f @ d, rel=1e-6)
    K = _assembly.Pattern(solid.rows, solid.cols, n).matrix(k)
    corr = solid.condensed_correction().copy()
    du = rng.standard_normal(n)
    step = np.concatenate([du, solid.recover(du)])
    fp, _, _ = solid.assemble(state + EPS * step, False)
    fm, _, _ = solid.assemble(state - EPS * step, False)
    dfdt = (fp - fm) / (2 * EPS)
    np.testing.assert_allclose(dfdt[:n], K @ du + corr, atol=1e-6 * np.abs(K @ du).max())
    np.testing.assert_allclose(dfdt[n:], -f[n:], atol=1e-6 * np.abs(f[n:]).max())


def test_enhanced_paper_layer_bends_exactly_on_one_element_through_its_thickness():
    # pure bending of a paper strip (neo-Hooke, nu = 0.2) one element thick at aspect 5: plain Q1 locks,
    # the incompatible modes reproduce beam theory (see tests/test_fem_beam.py for the laminate)
    xs, ys = np.linspace(0.0, 5.0, 6), np.array([-0.1, 0.1])
    mesh, _, _ = fem.build_grid_mesh([xs, ys])
    mat = fem.material_constants({})
    p = mesh.p
    lam, mu = mat["paper_lambda"], mat["paper_mu"]
    E = mu * (3 * lam + 2 * mu) / (lam + mu)
    nu = lam / (2 * (lam + mu))
    kappa = 1e-5  # 1/mm: the exact linear field u = (kappa x y, -kappa x^2/2 - nu' kappa y^2/2) is an equilibrium
    out = {}
    for enhanced in ((), (1,)):
        solid = fem.SolidAssembler(mesh, np.ones(mesh.t.shape[1], int), mat, enhanced=enhanced)
        M = kappa * E / (1 - nu**2) * 0.2**3 / 12  # N mm / mm
        root, tip = np.flatnonzero(p[0] == 0.0), np.flatnonzero(p[0] == 5.0)
        f = np.zeros(2 * p.shape[1])
        f[2 * tip] = M / 0.2 * np.sign(p[1, tip])  # the end couple as two opposite nodal forces
        fixed = np.concatenate([2 * root, [2 * root[0] + 1]])
        model = fem.Model(solid, fixed=fixed, extras=[_Load(f)])
        res = fem.solve_path(model, p, {"initial_step": 1.0})
        x = model.positions(res.state, p)
        top, bot = tip[np.argmax(p[1, tip])], tip[np.argmin(p[1, tip])]
        out[enhanced] = (x[0, top] - x[0, bot]) / 0.2  # end-face rotation, = kappa L in beam theory
    exact = kappa * 5.0
    assert out[(1,)] == pytest.approx(exact, rel=1e-3)
    assert out[()] < 0.2 * exact


class _Load:
    def __init__(self, f):
        self.f = f

    def evaluate(self, x, u, lam, tangent):
        return -lam * self.f, None

    def external(self, x, u, lam):
        return lam * self.f


def test_newton_forms_no_tangent_at_an_iterate_the_line_search_already_found_converged(monkeypatch):
    """The line search's residual at the full step is the next iterate's: a step that ends on a full step tests
    convergence on it and assembles no tangent there (before: one tangent per iteration plus one per step)."""
    from workflow.fem import _solve

    calls = {True: 0, False: 0}
    evaluate = _solve.Model.evaluate

    def counted(self, u, lam, p_ref, tangent=True):
        calls[tangent] += 1
        return evaluate(self, u, lam, p_ref, tangent)

    monkeypatch.setattr(_solve.Model, "evaluate", counted)
    res = fem.solve_unit(fem.build_unit_mesh(h=2.0, dim=2), 60.0, 0.0, "free", False)
    assert res.status == 0 and res.steps >= 5
    assert calls[True] < res.newton_iterations + res.steps // 2


@pytest.mark.parametrize("dim", [2, 3])
def test_lagged_pressure_changes_the_tangent_only_where_the_dilatation_is_not_the_actual_one(dim):
    # at a state whose lagged dilatations are the actual ones (what ``state`` builds) the lagged tangent is the
    # exact one; with other lagged values only the tangent's initial-stress term moves, never the residual
    mesh, material, u = _deformed_mesh(dim)
    exact = fem.SolidAssembler(mesh, material, MAT, lagged_pressure=False)
    lagged = fem.SolidAssembler(mesh, material, MAT, lagged_pressure=True)
    n_sil = int(np.sum(material == 0))
    assert lagged.n_internal == n_sil and exact.n_internal == 0
    f0, k0, _ = exact.assemble(u)
    state = lagged.state(u)
    f1, k1, _ = lagged.assemble(state)
    np.testing.assert_allclose(f1[: lagged.ndofs], f0, rtol=0, atol=1e-12 * np.abs(f0).max())
    np.testing.assert_array_equal(f1[lagged.ndofs :], 0.0)
    np.testing.assert_allclose(k1, k0, rtol=0, atol=1e-12 * np.abs(k0).max())
    shifted = state.copy()
    shifted[lagged.ndofs :] += 0.01
    f2, k2, _ = lagged.assemble(shifted)
    np.testing.assert_array_equal(f2[: lagged.ndofs], f1[: lagged.ndofs])
    assert np.abs(k2 - k1).max() > 1e-3 * np.abs(k1).max()


@pytest.mark.parametrize("enhanced", [(), (0, 1, 2)])
@pytest.mark.parametrize("dim", [2, 3])
def test_lagged_dilatation_is_the_linearised_volume(dim, enhanced):
    # after a tangent assembly, recover(du) moves each element's lagged dilatation to (v + h . dq) / V (dq the
    # element's nodal and enhanced increments), whose distance to the actual dilatation at the new state
    # shrinks with the step squared
    mesh, material, u = _deformed_mesh(dim)
    solid = fem.SolidAssembler(mesh, material, MAT, enhanced=enhanced, lagged_pressure=True)
    rng = np.random.default_rng(7)
    state = solid.state(u)
    n = solid.ndofs
    lag = np.concatenate(list(solid.theta_dofs.values()))
    alpha = np.setdiff1d(np.arange(n, solid.nstate), lag)
    for _ in range(20):  # enhanced parameters in equilibrium at u (damped Newton on r_alpha): recover linear in du
        solid.assemble(state)
        step = np.zeros(state.size)
        step[alpha] = solid.recover(np.zeros(n))[alpha - n]
        while solid.assemble(state + step, False)[2] < 0.1:  # no element inverted
            step /= 2
        state += step
    assert np.abs(solid.assemble(state, False)[0][alpha]).max(initial=0.0) < 1e-9
    state[lag] = solid.dilatation(state)
    solid.assemble(state)
    du = rng.standard_normal(n)
    err = []
    for eps in (1e-2, 5e-3):
        d_int = solid.recover(eps * du)
        new = state + np.concatenate([eps * du, d_int])
        err.append(np.abs(new[lag] - solid.dilatation(new)).max())
    assert err[1] == pytest.approx(err[0] / 4, rel=0.05)


def test_lagged_pressure_reaches_the_same_unit_angle_in_fewer_iterations(monkeypatch):
    # the 2D unit without contact to 300 kPa: the same free angle (one discrete problem), and Newton on the
    # lagged pressure avoids the cut-backs the exact element's initial-stress term causes (measured: 499 -> 97)
    um = fem.build_unit_mesh(h=1.0, dim=2)
    out = {}
    for lag in (False, True):
        monkeypatch.setattr(_assembly, "LAGGED_PRESSURE", lag)
        res = fem.solve_unit(um, 300.0, 0.0, "free", False)
        assert res.status == 0
        out[lag] = (res.bending_angle_deg, res.newton_iterations)
    assert out[True][0] == pytest.approx(out[False][0], rel=1e-6)
    assert out[True][1] < 0.5 * out[False][1]
