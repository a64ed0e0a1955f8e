"""Cross-check with an independent code, FElupe (issue 4 item 8, CLARIFICATIONS 9).

Same mesh, element formulation (Q1 with the mean-dilatation volumetric part:
FElupe's ``SolidBodyNearlyIncompressible`` with U = K/2 (Jb - 1)^2), material
constants, K and follower pressure; no contact.  Free angle on the P_B = 0 ray,
error divided by |theta(300 kPa)|.
"""

import numpy as np
import pytest

from workflow import fem

felupe = pytest.importorskip("felupe")
pytest.importorskip("tensortrax")


def felupe_free_angles(um, pressures_kpa, mat):
    """Total free bending angle (deg) of the 2D unit in FElupe at each pressure (fixed load steps)."""
    p = um.mesh.p.T.copy()
    t = um.mesh.t.T.copy()  # CCW quads: the same node order in both codes
    mesh = felupe.Mesh(p, t, "quad")
    sil = felupe.Mesh(p, t[um.material == 0], "quad")
    pap = felupe.Mesh(p, t[um.material == 1], "quad")
    f_sil = felupe.FieldContainer([felupe.FieldPlaneStrain(felupe.RegionQuad(sil), dim=2)])
    f_pap = felupe.FieldContainer([felupe.FieldPlaneStrain(felupe.RegionQuad(pap), dim=2)])
    f_pap.link(f_sil)
    mask = np.zeros(len(p), bool)
    mask[np.unique(um.facets["cavity_top"])] = True
    bnd = felupe.RegionQuadBoundary(mesh, mask=mask, ensure_3d=True)
    f_bnd = felupe.FieldContainer([felupe.FieldPlaneStrain(bnd, dim=2)])
    f_bnd.link(f_sil)
    n_facets = bnd.mesh.cells.shape[0]
    assert n_facets == um.facets["cavity_top"].shape[0]
    umat = felupe.Hyperelastic(felupe.constitution.tensortrax.models.hyperelastic.third_order_deformation,
                               C10=mat["c10"], C01=mat["c01"], C11=0.0, C20=mat["c20"], C30=0.0)
    body = felupe.SolidBodyNearlyIncompressible(umat, f_sil, bulk=mat["bulk"])
    paper = felupe.SolidBody(felupe.NeoHookeCompressible(mu=mat["paper_mu"], lmbda=mat["paper_lambda"]), f_pap)
    load = felupe.SolidBodyPressure(f_bnd)
    clamp = np.isclose(p[:, 0], 0.0)
    bounds = {"clamp": felupe.Boundary(f_sil[0], mask=clamp)}
    end, prev = um.nodes["backbone_end"], um.nodes["backbone_prev"]
    out = {}

    def record(stepnumber, substepnumber, substep):
        x = p + f_sil[0].values
        a, b = x[end].mean(axis=0), x[prev].mean(axis=0)
        out[substepnumber] = -np.degrees(np.arctan2(a[1] - b[1], a[0] - b[0]))

    steps = np.linspace(0.0, max(pressures_kpa), 61)[1:] * 1e-3
    step = felupe.Step(items=[body, paper, load], ramp={load: steps}, boundaries=bounds)
    felupe.Job(steps=[step], callback=record).evaluate(tol=1e-8, verbose=0)
    angles = np.array([out[i] for i in range(len(steps))])
    return np.interp(np.asarray(pressures_kpa) * 1e-3, steps, angles)


def test_free_angle_agrees_with_felupe_without_contact():
    um = fem.build_unit_mesh(h=1.0, dim=2)
    mat = fem.material_constants({})
    p = np.array([60.0, 180.0, 300.0])
    theirs = felupe_free_angles(um, p, mat)
    res = fem.solve_unit(um, 300.0, 0.0, "free", contact=False, stops=tuple(p / 300.0))
    assert res.status == 0
    ours = np.array([next(h["bending_angle_total_deg"] for h in res.history if abs(h["p_top_kpa"] - q) < 1e-6) for q in p])
    err = np.abs(ours - theirs) / abs(theirs[-1])
    assert np.all(err < 0.01), (ours, theirs)
