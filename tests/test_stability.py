"""Stability maps: locking, failure counts, penetration, surrogate coverage, design range.

The sweeps here are TEST DOUBLES (tests/_doubles.py), with statuses set by hand
so that every count is known; the locking test runs the real FE unit (2D,
h = 2 mm, a few seconds).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from _doubles import double_response  # noqa: E402

from workflow.actuator import sampled_region
from workflow.doe.ccd import ccd_dataset, ccd_design
from workflow.stability import design as DR
from workflow.stability import entry_fem
from workflow.stability import rays as S
from workflow.stability import samples as SM


# -- 1. Newton failures ------------------------------------------------------
def test_ray_statuses_first_unreached_sample_is_the_failure():
    s = [0.25, 0.5, 0.75, 1.0]
    assert S.ray_statuses(s, 1.0, 0).tolist() == [0, 0, 0, 0]
    assert S.ray_statuses(s, 0.6, 1).tolist() == [0, 0, 1, 2]
    assert S.ray_statuses(s, 0.0, 3).tolist() == [3, 2, 2, 2]  # raised at once: solver error, rest not reached
    assert S.ray_statuses(s, 0.5, 2).tolist() == [0, 0, 1, 2]  # a sample exactly at the last load factor converged


def _response_with_failures():
    """Double sweep (6 rays x 4) whose r = 0.2 ray (ray 1) stalls after its second sample."""
    ds = double_response(n_ratios=6, n_pressures=4)
    ds.attrs.update({"fea": "2d", "h_mm": 1.0, "contact": 1})
    st = ds["status"].values.copy()
    sel = np.flatnonzero((ds["ray"].values == 1) & (ds["scale"].values > 0.5))
    st[sel] = 2
    st[sel[ds["scale"].values[sel].argmin()]] = 1
    ds["status"] = ("point", st)
    ds["converged"] = ("point", st == 0)
    return ds


def test_failure_counts_on_a_synthetic_sweep():
    ds = _response_with_failures()
    samples = SM.fe_samples([("sweep", ds)])
    counts = SM.failure_counts(samples)
    name = S.method_name("sweep", "2d", 1.0, True)
    c = counts.sel(fe_method=name)
    solved = int((~ds["mirrored"]).sum())
    assert solved == 24
    # ray 1 is solved once and mirrored once: its failures count once (2 of its 4 samples)
    assert int(c.sel(status_code=1)) == 1 and int(c.sel(status_code=2)) == 1 and int(c.sel(status_code=3)) == 0
    assert int(c.sel(status_code=0)) == solved - 2
    assert int(c.sum()) == solved
    # the failed samples carry their ray's last converged load: 2/4 of 300 kPa
    failed = samples["status"].values != 0
    assert np.allclose(samples["ray_last_converged_kpa"].values[failed], 150.0)


def test_rays_dataset_from_a_fake_solver():
    def solve(variant, pt, pb, stops):
        lam = 0.5 if variant["contact"] and pb == 0 else 1.0  # the contact ray on P_B = 0 stalls halfway
        hist = [{"lam": s, "bending_angle_deg": 10 * s, "max_penetration_mm": 0.1 * s} for s in stops if s <= lam]
        return SimpleNamespace(
            status=0 if lam == 1.0 else 1,
            reason="" if lam == 1 else "stalled",
            load_factor=lam,
            history=hist,
            newton_iterations=5,
            wall_time_s=0.1,
        )

    variants = [
        {"h_mm": 2.0, "contact": True, "formulation": "mixed", "ratios": [0.0, 1.0]},
        {"h_mm": 0.5, "contact": False, "formulation": "displacement", "ratios": [0.0]},
    ]
    rays = S.solve_rays(solve, variants, p_max_kpa=300.0, n_pressures=4)
    ds = S.rays_dataset(rays, variants, p_max_kpa=300.0)
    assert ds["status"].values.tolist() == [[0, 0, 1, 2], [0, 0, 0, 0], [0, 0, 0, 0]]
    assert np.isnan(ds["bending_angle_deg"].values[0, 2:]).all()
    assert ds["formulation"].values.tolist() == ["mixed", "mixed", "displacement"]
    assert np.allclose(ds["p_bottom_kpa"].values[1], [75, 150, 225, 300])
    counts = SM.failure_counts(SM.fe_samples([("rays", ds)]))
    assert int(counts.sel(fe_method=S.method_name("rays", "2d", 2.0, True, "mixed"), status_code=0)) == 6
    with pytest.raises(ValueError, match="formulation"):
        S.solve_rays(
            solve, [{"h_mm": 1, "contact": True, "formulation": "hybrid", "ratios": [0]}], p_max_kpa=1, n_pressures=1
        )


# -- 2. Locking --------------------------------------------------------------
def test_plain_q1_locks_at_high_bulk_modulus_while_mixed_does_not():
    from workflow import fem

    mesh = fem.build_unit_mesh(None, h=2.0, dim=2)
    ang = {}
    for f in S.LOCKING_FORMULATIONS:
        for k in (10.0, 1.0e4):
            r = fem.solve_unit(mesh, 1.0, 0.0, "free", False, material={"bulk_ratio": k}, formulation=f)
            assert r.status == 0
            ang[f, k] = r.bending_angle_deg
    assert ang["mixed", 1e4] / ang["mixed", 10.0] > 0.9  # mean-dilatation: nearly incompressible costs little
    assert abs(ang["displacement", 1e4] / ang["mixed", 1e4]) < 0.05  # plain Q1: the bending is locked away
    ds = SM.locking_dataset(
        [10.0, 1e4],
        {f: [ang[f, 10.0], ang[f, 1e4]] for f in S.LOCKING_FORMULATIONS},
        {f: [0, 0] for f in S.LOCKING_FORMULATIONS},
        p_top_kpa=1.0,
        h_mm=2.0,
    )
    assert float(ds["locking_ratio"].sel(bulk_ratio=1e4)) < 0.05
    # the plain Q1 paper layer one element thick shear-locks: the enhanced one bends far more at small load
    assert float(ds["shear_locking_ratio"].sel(bulk_ratio=1e4)) < 0.7


def test_locking_ratio_ignores_failed_solves():
    ds = SM.locking_dataset(
        [10, 100],
        {"enhanced_paper": [6.0, 5.0], "mixed": [5.0, 4.0], "displacement": [4.0, 1.0]},
        {"enhanced_paper": [0, 0], "mixed": [0, 1], "displacement": [0, 0]},
        p_top_kpa=60.0,
        h_mm=2.0,
    )
    assert ds["locking_ratio"].values[0] == pytest.approx(0.8)
    assert np.isnan(ds["locking_ratio"].values[1])
    assert ds["shear_locking_ratio"].values[0] == pytest.approx(5.0 / 6.0)


# -- 3. Penetration ----------------------------------------------------------
def test_penetration_summary_counts_converged_samples_above_the_bound():
    ds = _response_with_failures()
    pen = np.linspace(0.0, 0.1, ds.sizes["point"])
    pen[ds["status"].values != 0] = 1.0  # failed samples must not count
    ds["max_penetration_mm"] = ("point", pen)
    samples = SM.fe_samples([("sweep", ds)])
    out = SM.penetration_summary(samples, 0.05)
    ok = ds["status"].values == 0
    assert int(out["n_above_bound"].values[0]) == int(np.count_nonzero(ok & (pen > 0.05)))
    assert float(out["max_penetration_mm"].values[0]) == pytest.approx(pen[ok].max())


# -- 4. Surrogate queries outside the sampled grid -----------------------------
def _lower_triangle_region():
    """Converged samples only where P_B <= P_T (the mirrors missing), and one failed sample at (300, 0)."""
    g = np.linspace(0, 300, 7)
    pts = np.array([(a, b) for a in g for b in g if b <= a and not (a == 300 and b == 0)])
    ds = xr.Dataset(
        {"status": ("point", np.r_[np.zeros(len(pts), int), 1])},
        coords={"p_top_kpa": ("point", np.r_[pts[:, 0], 300.0]), "p_bottom_kpa": ("point", np.r_[pts[:, 1], 0.0])},
    )
    return sampled_region.SampledRegion.from_response(ds)


def test_query_outside_the_hull_of_converged_samples_is_flagged():
    region = _lower_triangle_region()
    f = region.flags(np.array([200.0, 50.0, 150.0, 400.0]), np.array([50.0, 250.0, 150.0, 0.0]))
    assert f["in_hull"].tolist() == [True, False, True, False]  # (150, 150) on the hull's edge counts as inside
    assert f["in_range"].tolist() == [True, True, True, False]  # the range box alone would miss (50, 250)
    # next to the failed sample: a known failure region, whatever the hull says
    near = region.flags(295.0, 2.0)
    assert bool(near["near_failure"]) and not bool(near["trusted"])


def test_flag_pressure_table_marks_pairs_and_writes_one_message_each():
    region = _lower_triangle_region()
    p = np.zeros((2, 4, 2))
    p[0, 1] = (200.0, 50.0)  # inside
    p[1, 2] = (50.0, 250.0)  # outside
    da = xr.DataArray(
        p,
        dims=("exercise", "group", "chamber"),
        coords={"exercise": ["TGE1", "TGE2"], "group": ["CMC", "MCP", "PIP", "DIP"], "chamber": ["top", "bottom"]},
    )
    flags, msgs = sampled_region.flag_pressure_table(da, region, label="patient x: ")
    assert flags.dims == ("exercise", "group")
    assert flags.values.sum() == 7 and not bool(flags.sel(exercise="TGE2", group="PIP"))
    assert len(msgs) == 1 and "TGE2" in msgs[0] and "PIP" in msgs[0] and "outside the sampled region" in msgs[0]
    # (0, 0) is inside: the unloaded state is a known sample
    assert bool(flags.sel(exercise="TGE1", group="CMC"))


def test_coverage_grid_of_a_full_symmetric_sweep_covers_the_square():
    ds = double_response(n_ratios=3, n_pressures=2)
    cov = sampled_region.coverage_grid(sampled_region.SampledRegion.from_response(ds), 300.0, n=11)
    assert bool(cov["trusted"].all())
    half = sampled_region.coverage_grid(_lower_triangle_region(), 300.0, n=11)
    assert 0.4 < float(half["in_hull"].mean()) < 0.7


# -- 5. Design range and feasibility --------------------------------------------
def test_prediction_variance_sums_to_the_model_terms_at_the_design_and_grows_outside():
    design = ccd_dataset(ccd_design())
    X = np.column_stack([design[d].values for d in ("depth", "length", "breadth")])
    spv = DR.scaled_prediction_variance(X, X)
    assert spv.sum() / X.shape[0] == pytest.approx(10.0)  # trace of the hat matrix = number of terms
    u = np.ones(3) / np.sqrt(3)
    r = DR.scaled_prediction_variance(X, np.outer([1.0, 1.5, 2.0], u))
    assert r[0] < r[1] < r[2] and r[2] > 5 * r[0]


def test_design_range_and_feasibility_tables():
    def loads(x, ok):
        return xr.Dataset(
            {"x": ("dimension", np.array(x, float)), "in_design_range": ((), ok)},
            coords={"dimension": ["depth", "length", "breadth"]},
        )

    t = DR.design_range_table({"a": loads([0, 0, 0], True), "b": loads([1.2, 0, 0.5], False)})
    assert t["coded_norm"].values == pytest.approx([0.0, 1.3])
    assert t["in_design_range"].values.tolist() == [True, False]

    def plan(ach):
        return xr.Dataset(
            {
                "achieved": ("exercise", np.array(ach)),
                "reason": ("exercise", np.array(["" if a else "PIP off target" for a in ach], dtype=object)),
            },
            coords={"exercise": ["TGE1", "TGE2"]},
        )

    f = DR.feasibility_table({"a": plan([True, False]), "b": plan([False, False])})
    assert f["achieved"].values.tolist() == [[True, False], [False, False]]
    assert str(f["reason"].sel(patient="b", exercise="TGE1").values) == "PIP off target"


# -- the rule's entry point, end to end on doubles ------------------------------------
def test_write_stability_end_to_end(tmp_path):
    from workflow.common.provenance import write_dataset
    from workflow.stability import entry as R

    paths = {}
    for fea in ("2d", "3d"):
        paths[fea] = tmp_path / f"response_{fea}.nc"
        write_dataset(_response_with_failures(), paths[fea], rule="test", config_slice={}, title="double")

    def solve(variant, pt, pb, stops):
        hist = [
            {"lam": s, "bending_angle_deg": 10 * s, "max_penetration_mm": 0.08 * s * variant["contact"]} for s in stops
        ]
        return SimpleNamespace(status=0, reason="", load_factor=1.0, history=hist, newton_iterations=3, wall_time_s=0.1)

    rays_cfg = {
        "p_max_kpa": 300.0,
        "n_pressures": 3,
        "variants": [{"h_mm": 2.0, "contact": True, "formulation": "mixed", "ratios": [0.0, 0.5]}],
    }
    entry_fem.write_rays(tmp_path / "rays.nc", rays_cfg=rays_cfg, actuator={}, config_slice={}, solve=solve)

    def lock_solve(k, formulation):
        angle = 5.0 / (1 + k / 50) if formulation == "displacement" else 5.0
        return SimpleNamespace(status=0, bending_angle_deg=angle, wall_time_s=0.01)

    entry_fem.write_locking(
        tmp_path / "locking.nc",
        locking_cfg={"h_mm": 2.0, "p_top_kpa": 60.0, "contact": False, "bulk_ratios": [10, 1e4]},
        actuator={},
        config_slice={},
        solve=lock_solve,
    )
    write_dataset(ccd_dataset(ccd_design()), tmp_path / "ccd.nc", rule="test", config_slice={}, title="ccd")
    loads = tmp_path / "loads.nc"
    write_dataset(
        xr.Dataset(
            {"x": ("dimension", np.array([1.1, 0.0, 0.0])), "in_design_range": ((), False)},
            coords={"dimension": ["depth", "length", "breadth"]},
        ),
        loads,
        rule="t",
        config_slice={},
        title="l",
    )
    pr = np.zeros((2, 4, 2))
    pr[1, 1] = (250.0, 40.0)
    plan = tmp_path / "plan.nc"
    write_dataset(
        xr.Dataset(
            {
                "pressure_kpa": (("exercise", "group", "chamber"), pr),
                "achieved": ("exercise", np.array([True, False])),
                "reason": ("exercise", np.array(["", "MCP off target"], dtype=object)),
            },
            coords={"exercise": ["TGE1", "TGE2"], "group": ["CMC", "MCP", "PIP", "DIP"], "chamber": ["top", "bottom"]},
        ),
        plan,
        rule="t",
        config_slice={},
        title="p",
    )
    plots = {k: tmp_path / f"{k}.png" for k in ("failures", "locking", "penetration", "coverage", "design")}
    ds = R.write_stability(
        tmp_path / "stability.nc",
        responses=paths,
        unit_check=None,
        rays=tmp_path / "rays.nc",
        locking=tmp_path / "locking.nc",
        ccd=tmp_path / "ccd.nc",
        loads={"p": loads},
        plans={"p": plan},
        actuator={"mesh": {"h_2d_mm": 1.0, "h_3d_mm": 2.0}, "contact": {"enabled": True}},
        stab_cfg={"penetration_bound_mm": 0.05, "coverage_grid": 11},
        cascade_surrogate="3d",
        config_slice={},
        plots=plots,
        table_html=tmp_path / "summary.html",
    )
    back = xr.load_dataset(tmp_path / "stability.nc")
    for k in ("config_sha256", "git_commit", "created_utc", "rule", "package_versions"):
        assert k in back.attrs
    assert all(p.stat().st_size > 10_000 for p in plots.values())
    assert "locking" in (tmp_path / "summary.html").read_text()
    # the double sweep's failures: 2 per sweep; the rays' penetration 0.08 mm > 0.05 at s = 1
    assert int(ds["failure_count"].sel(status_code=[1, 2, 3]).sum()) == 4
    assert int(ds["n_above_bound"].sum()) == 4  # s = 2/3 and 1 of both rays (0.053 and 0.08 mm)
    assert not bool(ds["in_design_range"].sel(patient="p"))
    assert ds["achieved"].sel(patient="p").values.tolist() == [True, False]
    assert float(ds["locking_ratio"].sel(bulk_ratio=1e4)) < 0.01
