"""The unit's base layering as a cantilever against laminated Timoshenko beam theory (shear locking).

A plane-strain cantilever with the layering of the unit's backbone (silicone
2 mm - paper 0.2 mm - silicone 2 mm, the paper one element thick) on the unit
mesh's element size, length / thickness 5-20, under a pure end moment and
under a tip shear force, small loads (linear range).  Closed forms per mm of
width, plane-strain moduli E' = E / (1 - nu^2) of each layer:

* pure moment M:  tip rotation  M L / D,  D = sum_i E'_i int_i y^2 dy;
* tip force F:    tip deflection  F L^3 / (3 D) + F L / S  with the laminate's
  shear stiffness S from the energy of the Jourawski shear stress,
  1/S = int tau(y)^2 / (F^2 G(y)) dy,  tau(y) = F/D int_y^top E'(s) s ds.

The loads are applied as the tractions of that solution on the end face (the
linear bending stress, the Jourawski shear stress), so there are no end
effects; the clamp holds u_x on x = 0 and u_y at one node.  Through the
thickness the mesh has the unit mesh's layers at h = 1 mm (one paper element,
four per base layer).  Measured (FE / theory - 1, L/t = 5, 10, 20): moment
-0.45 %, force -0.06 to -0.44 %; tolerance 2 %.  With two elements per base
layer (elements as tall as long) the Q1/P0 silicone is +2.2 to +2.5 % too
flexible; the plain Q1 paper layer (shear-locking, as the unit used before)
makes the laminate about 30 % too stiff.
"""

import numpy as np
import pytest

from workflow import fem

H = 1.0  # the 2D unit's element size, mm
T_SIL, T_PAP = 2.0, 0.2  # base layer and paper thickness, mm (Table 6)
MAT = fem.material_constants({})


def _moduli():
    """Plane-strain E' and shear modulus G (MPa) of silicone and paper at small strain."""
    mu, K = MAT["mu0"], MAT["bulk"]
    E = 9 * K * mu / (3 * K + mu)
    nu = (3 * K - 2 * mu) / (2 * (3 * K + mu))
    Ep = MAT["paper_mu"] * (3 * MAT["paper_lambda"] + 2 * MAT["paper_mu"]) / (MAT["paper_lambda"] + MAT["paper_mu"])
    nup = MAT["paper_lambda"] / (2 * (MAT["paper_lambda"] + MAT["paper_mu"]))
    return {0: (E / (1 - nu**2), mu), 1: (Ep / (1 - nup**2), MAT["paper_mu"])}


def _layers(y):
    return np.where(np.abs(y) < T_PAP / 2, 1, 0)


def _beam_theory(L):
    """Bending stiffness D (N mm^2 / mm), shear stiffness S (N / mm) and tau(y) / F (1/mm) of the laminate."""
    mod = _moduli()
    c = T_PAP / 2 + T_SIL
    y = np.linspace(-c, c, 200001)
    Ey = np.where(_layers(y) == 1, mod[1][0], mod[0][0])
    Gy = np.where(_layers(y) == 1, mod[1][1], mod[0][1])
    D = np.trapezoid(Ey * y**2, y)
    # first moment of E' y from y to the top, by cumulative trapezoid from the top down
    g = Ey * y
    Q = np.concatenate([[0.0], np.cumsum(0.5 * (g[1:] + g[:-1]) * np.diff(y))])
    Q = Q[-1] - Q
    tau = Q / D  # per unit shear force
    S = 1.0 / np.trapezoid(tau**2 / Gy, y)
    return D, S, (y, tau, Ey)


def _cantilever(L, load, formulation):
    """FE tip rotation (pure moment) or neutral-axis tip deflection (tip force), per unit load."""
    c = T_PAP / 2 + T_SIL
    # through the thickness as the unit mesh at this element size (workflow.fem._mesh.layer_counts)
    n_pap, n_sil = fem.layer_counts({"bot_layer": T_SIL}, H)
    ys = np.concatenate(
        [
            np.linspace(-c, -T_PAP / 2, n_sil + 1),
            np.linspace(-T_PAP / 2, T_PAP / 2, n_pap + 1)[1:],
            np.linspace(T_PAP / 2, c, n_sil + 1)[1:],
        ]
    )
    xs = np.linspace(0.0, L, int(np.ceil(L / H - 1e-9)) + 1)
    mesh, _, _ = fem.build_grid_mesh([xs, ys])
    p = mesh.p
    material = _layers(p[:, mesh.t].mean(axis=1)[1])
    solid = fem.solid_assembler(mesh, material, MAT, formulation)
    root = np.flatnonzero(p[0] < 1e-9)
    tip = np.flatnonzero(p[0] > L - 1e-9)
    tip = tip[np.argsort(p[1, tip])]
    fixed = np.concatenate([2 * root, [2 * root[np.argmin(np.abs(p[1, root] - T_PAP / 2))] + 1]])
    D, S, (yq, tau, Ey) = _beam_theory(L)
    # consistent nodal forces of the end traction (linear shape functions on the end face's segments)
    f = np.zeros(2 * p.shape[1])
    yt = p[1, tip]
    for a, b, na, nb in zip(yt[:-1], yt[1:], tip[:-1], tip[1:]):
        s = np.linspace(0.0, 1.0, 2001)
        y = a + s * (b - a)
        if load == "moment":  # M = 1 N mm / mm: sigma_x = E'(y) y / D
            tr, comp = np.interp(y, yq, Ey) * y / D, 0
        else:  # F = 1 N / mm downwards along -y: Jourawski shear stress
            tr, comp = -np.interp(y, yq, tau), 1
        f[2 * na + comp] += np.trapezoid(tr * (1 - s), s) * (b - a)
        f[2 * nb + comp] += np.trapezoid(tr * s, s) * (b - a)
    scale = 1e-4  # small load: the linear range
    model = fem.Model(solid, fixed=fixed, extras=[_DeadLoad(scale * f)])
    res = fem.solve_path(model, p, {"initial_step": 1.0})
    assert res.status == 0, res.reason
    x = model.positions(res.state, p)
    if load == "moment":
        tip_face = x[:, tip]  # rotation of the end face (least-squares slope of x against y)
        dx, dy = np.polyfit(tip_face[1], tip_face[0], 1)[0], 1.0
        return abs(np.arctan2(dx, dy)) / scale, L / D
    mid = np.interp(0.0, p[1, tip], x[1, tip] - p[1, tip])  # neutral-axis (y = 0) deflection
    return -mid / scale, L**3 / (3 * D) + L / S


class _DeadLoad:
    """A fixed external nodal force (N per mm of width)."""

    def __init__(self, f):
        self.f = f

    def evaluate(self, x, u, lam, tangent):
        return -lam * self.f, None

    def external(self, x, u, lam):
        return lam * self.f


@pytest.mark.parametrize("load", ["moment", "force"])
@pytest.mark.parametrize("slenderness", [5, 10, 20])
def test_layered_cantilever_matches_laminated_beam_theory(slenderness, load):
    L = slenderness * (T_PAP + 2 * T_SIL)
    fe, exact = _cantilever(L, load, "enhanced_paper")
    assert fe == pytest.approx(exact, rel=0.02)


@pytest.mark.parametrize("load", ["moment", "force"])
def test_plain_q1_paper_layer_shear_locks(load):
    # the formulation the unit used before: one row of fully integrated Q1 elements at aspect 5
    L = 10 * (T_PAP + 2 * T_SIL)
    fe, exact = _cantilever(L, load, "mixed")
    assert fe < 0.8 * exact
