"""Material laws and element against closed forms and finite differences."""

import numpy as np
import pytest

from workflow import fem

C10, C01, C20 = 0.26056762, 0.09754981, 0.05750069  # MPa, Table 5 (resources/table05_*.csv)
MAT = fem.material_constants({})


def _fd_check(law, args, d, seed=0):
    rng = np.random.default_rng(seed)
    F = (np.eye(d) + 0.2 * rng.standard_normal((6, d, d))).transpose(1, 2, 0)
    psi, P, A = law(F, *args)
    eps = 1e-6
    Pn, An = np.zeros_like(P), np.zeros_like(A)
    for i in range(d):
        for j in range(d):
            dF = np.zeros_like(F)
            dF[i, j] = eps
            pp, Pp, _ = law(F + dF, *args)
            pm, Pm, _ = law(F - dF, *args)
            Pn[i, j] = (pp - pm) / (2 * eps)
            An[:, :, i, j] = (Pp - Pm) / (2 * eps)
    return np.abs(P - Pn).max() / np.abs(P).max(), np.abs(A - An).max() / np.abs(A).max()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize(
    "law,args", [(fem.mooney_rivlin_isochoric, (C10, C01, C20)), (fem.neo_hooke_compressible, (500.0, 333.0))]
)
def test_stress_and_tangent_are_derivatives(law, args, d):
    eP, eA = _fd_check(law, args, d)
    assert eP < 1e-7 and eA < 1e-7


def test_plane_strain_is_3d_law_with_f33_one():
    rng = np.random.default_rng(3)
    F2 = (np.eye(2) + 0.3 * rng.standard_normal((4, 2, 2))).transpose(1, 2, 0)
    F3 = np.zeros((3, 3, 4))
    F3[:2, :2], F3[2, 2] = F2, 1.0
    psi2, P2, A2 = fem.mooney_rivlin_isochoric(F2, C10, C01, C20)
    psi3, P3, A3 = fem.mooney_rivlin_isochoric(F3, C10, C01, C20)
    np.testing.assert_allclose(psi2, psi3, atol=1e-14)
    np.testing.assert_allclose(P2, P3[:2, :2], atol=1e-13)
    np.testing.assert_allclose(A2, A3[:2, :2, :2, :2], atol=1e-12)


def _cube_nominal_stress(stretch, mode):
    """Mean-dilatation hex cube (2x2x2 elements, symmetry BCs) under displacement control."""
    c = np.linspace(0.0, 1.0, 3)
    mesh, _, _ = fem.build_grid_mesh([c, c, c])
    # K = 1e5 mu0 so that the compressibility error (order stress/K) is far below the tolerance
    solid = fem.SolidAssembler(mesh, np.zeros(mesh.t.shape[1], int), fem.material_constants({"bulk_ratio": 1e5}))
    p = mesh.p
    fixed = np.concatenate([3 * np.flatnonzero(p[k] == 0.0) + k for k in range(3)])
    loaded = {"uniaxial": [0], "equibiaxial": [0, 1]}[mode]
    pres = {}
    for k in loaded:
        for n in np.flatnonzero(p[k] == 1.0):
            pres[3 * n + k] = stretch - 1.0
    model = fem.Model(solid, fixed=fixed, prescribed=pres)

    def measure(u, lam, info):
        r = info["r"]
        return {"force": float(r[3 * np.flatnonzero(p[0] == 1.0)].sum())}  # on the unit face x = 1

    res = fem.solve_path(model, p, {"initial_step": 0.25}, measure)
    assert res.status == 0
    return res.history[-1]["force"]


@pytest.mark.parametrize("mode", ["uniaxial", "equibiaxial"])
@pytest.mark.parametrize("stretch", [1.3, 1.8])
def test_mooney_rivlin_homogeneous_stress_closed_form(mode, stretch):
    lam = stretch
    if mode == "uniaxial":
        I1 = lam**2 + 2.0 / lam
        W1 = C10 + 2 * C20 * (I1 - 3)
        P = 2.0 * (lam - lam**-2) * (W1 + C01 / lam)
    else:
        I1 = 2 * lam**2 + lam**-4
        W1 = C10 + 2 * C20 * (I1 - 3)
        P = 2.0 * (lam - lam**-5) * (W1 + C01 * lam**2)
    force = _cube_nominal_stress(stretch, mode)
    assert force == pytest.approx(P, rel=1e-3)


def test_element_tangent_matches_finite_differences_and_energy():
    um = fem.build_unit_mesh(h=2.0, dim=3)
    solid = fem.SolidAssembler(um.mesh, um.material, MAT)
    pat = fem._assembly.Pattern(solid.rows, solid.cols, solid.ndofs)
    rng = np.random.default_rng(1)
    u = 0.02 * rng.standard_normal(solid.ndofs)
    f, k, _ = solid.assemble(u)
    K = pat.matrix(k)
    du = 1e-6 * rng.standard_normal(solid.ndofs)
    n = solid.ndofs  # the state's lagged dilatations follow; the forces are the first n entries
    fp, _, _ = solid.assemble(u + du, False)
    fm, _, _ = solid.assemble(u - du, False)
    assert np.abs((fp - fm)[:n] / 2 - K @ du).max() < 1e-6 * np.abs(K @ du).max()
    dE = (solid.energy(u + du) - solid.energy(u - du)) / 2
    assert dE == pytest.approx(f[:n] @ du, rel=1e-5)


@pytest.mark.parametrize("dim", [2, 3])
def test_follower_pressure_stiffness_finite_differences(dim):
    rng = np.random.default_rng(dim)
    nfn = 2 if dim == 2 else 4
    x = rng.standard_normal((dim, 5 * nfn))
    facets = np.arange(5 * nfn).reshape(5, nfn)
    f, K = fem.pressure_load(x, facets, 0.3)
    eps = 1e-6
    dx = rng.standard_normal(x.shape)
    fp, _ = fem.pressure_load(x + eps * dx, facets, 0.3, False)
    fm, _ = fem.pressure_load(x - eps * dx, facets, 0.3, False)
    dloc = dx[:, facets].transpose(1, 2, 0).reshape(5, -1)
    df = ((fp - fm) / (2 * eps)).reshape(5, -1)
    np.testing.assert_allclose(-np.einsum("fij,fj->fi", K, dloc), df, atol=1e-8)


def test_pressure_resultant_on_closed_square_is_zero_and_scales_with_area():
    # a square cavity: the forces on its walls cancel; on one wall it is p * length
    c = np.linspace(0.0, 3.0, 4)
    mesh, faces, _ = fem.build_grid_mesh([c, c], keep=lambda m: ~((np.abs(m[0] - 1.5) < 1) & (np.abs(m[1] - 1.5) < 1)))
    mid = mesh.p[:, faces].mean(axis=2)
    inner = faces[(np.abs(mid[0] - 1.5) <= 0.5 + 1e-9) & (np.abs(mid[1] - 1.5) <= 0.5 + 1e-9)]
    f, _ = fem.pressure_load(mesh.p, inner, 0.2)
    np.testing.assert_allclose(f.sum(axis=(0, 1)), 0.0, atol=1e-14)
    top = inner[mesh.p[1, inner].mean(axis=1) == 2.0]
    ft, _ = fem.pressure_load(mesh.p, top, 0.2)
    # the cavity's roof is pushed up (+y) by p * 1 mm
    np.testing.assert_allclose(ft.sum(axis=(0, 1)), [0.0, 0.2], atol=1e-14)


def test_silicone_constants_are_table_5():
    """config, schema default and workflow.fem all hold Table 5 as carried into resources/ (MPa)."""
    import pandas as pd
    import yaml

    from workflow.settings import REPO_ROOT

    t = pd.read_csv(REPO_ROOT / "resources" / "table05_mooney_rivlin_smooth_sil_950.csv").set_index("parameter")
    want = {f"{k.lower()}_mpa": float(t.loc[k, "value"]) * 1e-6 for k in ("C10", "C01", "C20")}
    cfg = yaml.safe_load((REPO_ROOT / "config" / "config.yaml").read_text())["actuator"]["material"]
    schema = yaml.safe_load((REPO_ROOT / "config" / "schema.yaml").read_text())
    defaults = schema["properties"]["actuator"]["properties"]["material"]["properties"]
    for key, value in want.items():
        assert cfg[key] == pytest.approx(value, rel=1e-9)
        assert defaults[key]["default"] == pytest.approx(value, rel=1e-9)
        assert fem.DEFAULT_MATERIAL[key] == pytest.approx(value, rel=1e-9)
    assert fem.material_constants({})["mu0"] == pytest.approx(0.716, abs=5e-4)


def test_mode_stresses_are_the_energy_derivatives_and_table5_is_drucker_stable():
    """Nominal stress of each incompressible mode = dW/dl per loaded direction (W along the mode)."""
    from workflow.fem.material_stability import drucker_instabilities, mooney_rivlin_mode_stress

    c10, c01, c20 = 0.26056762, 0.09754981, 0.05750069
    stretches = {
        "uniaxial": lambda l: (l, l**-0.5, l**-0.5),
        "equibiaxial": lambda l: (l, l, l**-2),
        "planar": lambda l: (l, 1.0, 1.0 / l),
    }
    loaded = {"uniaxial": 1, "equibiaxial": 2, "planar": 1}

    def energy(mode, lam):
        a = np.array(stretches[mode](lam)) ** 2
        i1, i2 = a.sum(), a[0] * a[1] + a[1] * a[2] + a[0] * a[2]
        return c10 * (i1 - 3) + c01 * (i2 - 3) + c20 * (i1 - 3) ** 2

    for mode in stretches:
        for lam in (0.4, 0.8, 1.3, 2.5):
            h = 1e-6
            dw = (energy(mode, lam + h) - energy(mode, lam - h)) / (2 * h)
            _, nominal = mooney_rivlin_mode_stress(c10, c01, c20, lam, mode)
            assert nominal == pytest.approx(dw / loaded[mode], rel=1e-6)
    assert drucker_instabilities(c10, c01, c20) == []
    # a softening c20 < 0: the large-stretch end goes first in tension
    (uni,) = [i for i in drucker_instabilities(0.26, 0.1, -0.01) if i.mode == "uniaxial"]
    ((first, last),) = uni.ranges
    assert 2.0 < first < last == 3.0 and not uni.within
