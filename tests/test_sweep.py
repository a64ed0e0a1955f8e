"""Sweep plumbing: ray design, shards, merge, symmetry, resumption.

The solver here is a TEST DOUBLE: a smooth analytic function with the unit's
symmetries (swapping P_T and P_B negates angle and moment; P_T = P_B gives 0).
It is not a model of the actuator.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
import xarray as xr
from _doubles import double_angle, double_moment  # noqa: E402

from workflow.actuator import entry_fem, fe_solver, sweep
from workflow.common.provenance import write_dataset


class DoubleSolver:
    """Callable ray solver returning the double's values; counts calls; can fail on chosen rays."""

    def __init__(self, fail_ratio=None, raise_ratio=None, interrupt_ratio=None):
        self.calls = []
        self.fail_ratio, self.raise_ratio, self.interrupt_ratio = fail_ratio, raise_ratio, interrupt_ratio

    def __call__(self, direction, scales, progress=None):
        pt0, pb0 = direction
        ratio = pb0 / pt0
        self.calls.append(round(ratio, 6))
        if self.interrupt_ratio is not None and np.isclose(ratio, self.interrupt_ratio):
            raise KeyboardInterrupt  # stands for a killed job
        if self.raise_ratio is not None and np.isclose(ratio, self.raise_ratio):
            raise RuntimeError("singular tangent")
        pt, pb = scales * pt0, scales * pb0
        status = np.zeros(scales.size, dtype=int)
        angle, moment = double_angle(pt, pb), double_moment(pt, pb)
        if self.fail_ratio is not None and np.isclose(ratio, self.fail_ratio):
            status[-2] = 1  # diverged at the last-but-one step, the last one not reached
            status[-1] = 2
            angle[-2:] = np.nan
            moment[-2:] = np.nan
        for k in range(scales.size):
            if progress is not None:
                progress(k + 1)
        return {
            "p_top_kpa": pt,
            "p_bottom_kpa": pb,
            "bending_angle_deg": angle,
            "bending_moment_nm": moment,
            "status": status,
            "newton_iterations": np.full(scales.size, 4),
            "wall_time_s": np.full(scales.size, 0.01),
        }


DESIGN = dict(p_max_kpa=300.0, n_ratios=6, n_pressures=5)


def run_all(solver, n_shards=3, **kw):
    design = {**DESIGN, **kw}
    return [
        sweep.run_shard(solver, shard=i, n_shards=n_shards, **design) for i in range(min(n_shards, design["n_ratios"]))
    ]


def test_ray_design_covers_the_lower_triangle():
    d = sweep.ray_design(300.0, 11, 10)
    assert d["ratio"][0] == 0.0 and d["ratio"][-1] == 1.0
    assert np.all(d["direction_kpa"][:, 1] <= d["direction_kpa"][:, 0])
    assert d["scales"][0] > 0 and d["scales"][-1] == 1.0
    np.testing.assert_allclose(np.diff(d["scales"]), 0.1)


@pytest.mark.parametrize("n_ratios, n_shards", [(6, 1), (6, 4), (11, 11), (5, 9)])
def test_every_ray_in_exactly_one_shard(n_ratios, n_shards):
    shards = sweep.shard_rays(n_ratios, n_shards)
    assert len(shards) == min(n_ratios, n_shards)
    np.testing.assert_array_equal(np.sort(np.concatenate(shards)), np.arange(n_ratios))


def test_merge_mirrors_and_symmetry():
    merged = sweep.merge_shards(run_all(DoubleSolver()), n_ratios=6, n_pressures=5)
    n = sweep.n_points_total(6, 5)
    assert merged.sizes["point"] == n == 55
    assert int(merged["mirrored"].sum()) == 25  # r = 1 ray not mirrored
    pt, pb = merged["p_top_kpa"].values, merged["p_bottom_kpa"].values
    # every mirrored point is the swapped twin of its source, with angle and moment negated
    mir = np.flatnonzero(merged["mirrored"].values)
    src = merged["source_point"].values[mir]
    np.testing.assert_array_equal(pt[mir], pb[src])
    np.testing.assert_array_equal(pb[mir], pt[src])
    np.testing.assert_array_equal(merged["bending_angle_deg"].values[mir], -merged["bending_angle_deg"].values[src])
    np.testing.assert_array_equal(merged["bending_moment_nm"].values[mir], -merged["bending_moment_nm"].values[src])
    # the mirrored values equal what solving there would give (the double has the symmetry)
    np.testing.assert_allclose(merged["bending_angle_deg"].values[mir], double_angle(pt[mir], pb[mir]), atol=1e-12)
    # no duplicate pressure pairs; the square [0, 300]^2 is covered on both sides of the diagonal
    pairs = set(zip(np.round(pt, 9), np.round(pb, 9)))
    assert len(pairs) == n
    assert pt.max() == pb.max() == 300.0
    assert np.all(merged["wall_time_s"].values[mir] == 0)
    diag = np.isclose(pt, pb)
    np.testing.assert_allclose(merged["bending_angle_deg"].values[diag], 0.0, atol=1e-12)


def test_failed_points_kept_with_status():
    solver = DoubleSolver(fail_ratio=0.4, raise_ratio=0.8)
    merged = sweep.merge_shards(run_all(solver), n_ratios=6, n_pressures=5)
    st = merged["status"].values
    solved = ~merged["mirrored"].values
    assert np.count_nonzero((st == 1) & solved) == 1
    assert np.count_nonzero((st == 2) & solved) == 1
    assert np.count_nonzero((st == 3) & solved) == 5  # the raising ray, all its samples
    np.testing.assert_array_equal(merged["converged"].values, st == 0)
    assert np.all(np.isnan(merged["bending_angle_deg"].values[st != 0]))
    assert np.all(np.isfinite(merged["bending_angle_deg"].values[st == 0]))
    # mirrors inherit the status of their twin
    assert np.count_nonzero(st == 3) == 10
    assert merged["status"].attrs["flag_meanings"].split()[0] == "converged"
    assert list(merged["status"].attrs["flag_values"]) == [0, 1, 2, 3]


def test_merge_rejects_missing_shard():
    parts = run_all(DoubleSolver())
    with pytest.raises(ValueError, match="missing or duplicated"):
        sweep.merge_shards(parts[:-1], n_ratios=6, n_pressures=5)
    with pytest.raises(ValueError, match="missing or duplicated"):
        sweep.merge_shards(parts + parts[:1], n_ratios=6, n_pressures=5)


def test_bad_status_code_is_an_error():
    def bad(direction, scales):
        n = scales.size
        return (
            scales * direction[0],
            scales * direction[1],
            np.zeros(n),
            np.zeros(n),
            np.full(n, 7),
            np.zeros(n),
            np.zeros(n),
        )

    # An unknown code is a wiring error and is reported as a solver_error ray, not silently stored.
    ds = sweep.run_shard(bad, shard=0, n_shards=1, **DESIGN)
    assert np.all(ds["status"].values == 3)


def test_progress_logging(caplog):
    with caplog.at_level(logging.INFO):
        sweep.run_shard(DoubleSolver(), shard=0, n_shards=2, **DESIGN)
    msgs = [r.getMessage() for r in caplog.records if "points done" in r.getMessage()]
    # per-sample progress from the solver (3 rays x 5 samples) plus one line per finished ray
    assert any("points done 15 of 15" in m for m in msgs)
    assert any("points done 1 of 15" in m for m in msgs)
    assert all("s per point" in m for m in msgs)


def shard_path(root, i):
    return root / f"shard{i}.nc"


def run_missing(solver, root, n_shards):
    """What Snakemake does on a rerun: produce only the shard files that are missing."""
    for i in range(n_shards):
        path = shard_path(root, i)
        if not path.exists():
            ds = sweep.run_shard(solver, shard=i, n_shards=n_shards, **DESIGN)
            write_dataset(ds, path, rule="sweep_shard", config_slice=DESIGN, title="test shard")


def test_interrupted_sweep_resumes_missing_shards_only(tmp_path):
    n_shards = 3
    # first run is killed while solving shard 1 (its ray r = 0.2)
    with pytest.raises(KeyboardInterrupt):
        run_missing(DoubleSolver(interrupt_ratio=0.2), tmp_path, n_shards)
    assert shard_path(tmp_path, 0).exists() and not shard_path(tmp_path, 1).exists()
    assert not list(tmp_path.glob("*.part"))  # nothing half-written left behind
    rerun = DoubleSolver()
    run_missing(rerun, tmp_path, n_shards)
    # shard 0 (rays 0, 3) was not recomputed; shards 1 (rays 1, 4) and 2 (rays 2, 5) were
    assert sorted(rerun.calls) == [0.2, 0.4, 0.8, 1.0]
    resumed = sweep.merge_shards(sorted(tmp_path.glob("shard*.nc")), n_ratios=6, n_pressures=5)
    fresh = sweep.merge_shards(run_all(DoubleSolver(), n_shards=n_shards), n_ratios=6, n_pressures=5)
    xr.testing.assert_identical(resumed.drop_attrs(), fresh.drop_attrs())


def test_shard_roundtrip_netcdf(tmp_path):
    ds = sweep.run_shard(DoubleSolver(fail_ratio=0.0), shard=0, n_shards=2, **DESIGN)
    path = write_dataset(ds, tmp_path / "s.nc", rule="sweep_shard", config_slice=DESIGN, title="t")
    back = xr.load_dataset(path)
    xr.testing.assert_identical(back.drop_attrs(deep=False), ds.drop_attrs(deep=False))
    # write_dataset stores booleans as int8 (see provenance._encoding); values survive
    np.testing.assert_array_equal(back["converged"].values.astype(bool), back["status"].values == 0)
    assert back.attrs["rule"] == "sweep_shard"


def test_make_solver_rejects_unknown_model():
    with pytest.raises(ValueError, match="4d"):
        fe_solver.make_solver("4d", {})


def test_real_solver_samples_a_ray_at_its_scales():
    """The wired FE solver (coarse 2D mesh) lands on the ray's scales with the right signs."""
    solve_ray = fe_solver.make_solver("2d", {"mesh": {"h_2d_mm": 2.0}})
    out = solve_ray((60.0, 0.0), np.array([0.5, 1.0]))
    np.testing.assert_allclose(out["p_top_kpa"], [30.0, 60.0])
    assert list(out["status"]) == [0, 0]
    assert 0 < out["bending_angle_deg"][0] < out["bending_angle_deg"][1]
    assert 0 < out["bending_moment_nm"][0] < out["bending_moment_nm"][1]


def test_diagonal_ray_takes_the_blocked_moment_from_the_mirror_symmetry(monkeypatch):
    """P_T = P_B on the symmetric unit: the blocked case is not solved, its moment is zero, and solving it gives zero
    to round-off (the symmetry the short-cut rests on); a mesh that is not its own mirror image solves it."""
    from workflow import fem

    act = {"mesh": {"h_2d_mm": 2.0}}
    calls = []
    real = fem.solve_unit_from_config

    def counting(actuator, dim, pt, pb, case, **kw):
        calls.append(case)
        return real(actuator, dim, pt, pb, case, **kw)

    monkeypatch.setattr(fem, "solve_unit_from_config", counting)
    scales = np.array([0.5, 1.0])
    out = fe_solver.make_solver("2d", act)((60.0, 60.0), scales)
    assert calls == ["free"] and list(out["status"]) == [0, 0]
    assert np.all(out["bending_moment_nm"] == 0.0)
    assert np.all(np.abs(out["bending_angle_deg"]) < 1e-8)
    assert np.all(out["min_pocket_area_mm2"] > 0)  # the checks come from the free case
    # the blocked case solved: zero to round-off, against the moment of the (60, 0) ray
    solved = real(act, 2, 60.0, 60.0, "blocked", stops=tuple(scales))
    one_sided = real(act, 2, 60.0, 0.0, "blocked")
    assert solved.status == 0 and abs(solved.bending_moment_nm) < 1e-9 * abs(one_sided.bending_moment_nm)
    # not symmetric (a node moved): both cases solved
    calls.clear()
    mesh = fem.unit_mesh_from_config(act, 2)
    mesh.mesh.p[1, 7] += 0.01
    monkeypatch.setattr(fem, "unit_mesh_from_config", lambda *a, **k: mesh)
    assert not fem.top_bottom_symmetric(mesh)
    fe_solver.make_solver("2d", act)((20.0, 20.0), np.array([1.0]))
    assert calls == ["free", "blocked"]


def test_the_3d_unit_is_its_own_mirror_image_until_a_material_or_a_cavity_differs():
    from workflow import fem

    mesh = fem.unit_mesh_from_config({"mesh": {"h_3d_mm": 4.0}}, 3)
    assert fem.top_bottom_symmetric(mesh)
    mesh.material[0] = 1 - mesh.material[0]
    assert not fem.top_bottom_symmetric(mesh)
    mesh.material[0] = 1 - mesh.material[0]
    mesh.facets["cavity_bottom"] = mesh.facets["cavity_bottom"][1:]
    assert not fem.top_bottom_symmetric(mesh)


@pytest.mark.slow
def test_snakemake_resumes_a_missing_shard_and_builds_downstream(tmp_path, repo):
    """Snakemake level: shards from the double stand in for the FE sweep (make_solver is not wired yet).

    With every shard present, the stage's rules build response, CV, surrogates and
    mapping; after one shard is deleted, a dry run schedules that shard only (and
    what depends on it).  When the real solver is wired, drop the pre-made shards
    and let Snakemake run sweep_shard itself.
    """
    import shutil
    import subprocess
    import sys

    import yaml

    small = {
        "sweep": {f: {"p_max_kpa": 300.0, "n_ratios": 4, "n_pressures": 4, "n_shards": 2} for f in ("2d", "3d")},
        "surrogates": {"regressors": ["knn", "linear"]},
        "fidelity": {"auto": False},
    }  # the sweeps on the config's meshes: no FE fidelity study here
    (tmp_path / "small.yaml").write_text(yaml.safe_dump(small))
    (tmp_path / "Snakefile").write_text(
        f'configfile: "{repo}/config/config.yaml"\n'
        f'include: "{repo}/rules/common.smk"\n'
        f'include: "{repo}/rules/actuator.smk"\n'
        'rule all_test:\n    input: "results/actuator/mapping_2d3d.nc"\n'
    )
    (tmp_path / "resources").mkdir()
    for table in ("table08_planned_pressures_3d.csv", "table07_unit_targets.csv"):  # the mapping's inputs
        shutil.copy(repo / "resources" / table, tmp_path / "resources")
    for fea in ("2d", "3d"):
        for i in range(2):
            entry_fem.write_shard(
                tmp_path / f"results/actuator/sweep/{fea}/shard{i}.nc",
                fea=fea,
                shard=i,
                sweep_cfg=small["sweep"][fea],
                actuator_cfg={},
                config_slice=small,
                solver=DoubleSolver(),
            )
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "-s",
        str(tmp_path / "Snakefile"),
        "-d",
        str(tmp_path),
        "-c2",
        "--configfile",
        str(repo / "config" / "config.yaml"),
        str(tmp_path / "small.yaml"),
        # not mtime: the pre-made shards must not look older than code edited meanwhile
        "--rerun-triggers",
        "params",
        "input",
        "code",
        "software-env",
    ]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    mapped = xr.load_dataset(tmp_path / "results/actuator/mapping_2d3d.nc")
    assert mapped.attrs["rule"] == "mapping_2d3d"
    assert (tmp_path / "results/actuator/surrogate_cv.png").exists()
    resp = xr.load_dataset(tmp_path / "results/actuator/response_3d.nc")
    assert resp.sizes["point"] == sweep.n_points_total(4, 4)

    # an interrupted sweep: shard 1 of 3D never finished, so nothing downstream of it exists either
    (tmp_path / "results/actuator/sweep/3d/shard1.nc").unlink()
    for f in (tmp_path / "results/actuator").glob("*.*"):
        if f.name != "response_2d.nc":
            f.unlink()
    dry = subprocess.run(cmd + ["-n"], capture_output=True, text=True, timeout=300)
    assert dry.returncode == 0, dry.stderr[-3000:]
    out = dry.stdout + dry.stderr  # the job table goes to stderr
    jobs = [line.split() for line in out.splitlines() if line.strip().startswith(("sweep_", "surrogate_", "mapping_"))]
    counts = {j[0]: int(j[1]) for j in jobs if len(j) == 2 and j[1].isdigit()}
    assert counts.get("sweep_shard") == 1, out
    assert counts.get("sweep_merge") == 1  # 3D only: the 2D response is complete


def test_samples_from_paths_exact_interpolated_and_failed():
    scales = np.arange(1, 11) / 10
    free = {
        "status": 0,
        "wall_time_s": 6.0,
        "history": [{"lam": s, "iterations": 3, "bending_angle_deg": 10 * s} for s in scales],
    }
    lam_b = [0.05, 0.15, 0.3, 0.6, 1.0]
    blocked = {
        "status": 0,
        "wall_time_s": 4.0,
        "history": [{"lam": s, "iterations": 5, "bending_moment_nm": 0.2 * s} for s in lam_b],
    }
    out = fe_solver.samples_from_paths((300.0, 60.0), scales, free, blocked)
    np.testing.assert_allclose(out["bending_angle_deg"], 10 * scales)  # exact steps
    np.testing.assert_allclose(out["bending_moment_nm"], 0.2 * scales)  # linear data: interpolation is exact
    np.testing.assert_allclose(out["p_bottom_kpa"], 60.0 * scales)
    assert np.all(out["status"] == 0)
    assert out["newton_iterations"].sum() == 10 * 3 + 5 * 5  # every Newton iteration counted once
    assert out["wall_time_s"].sum() == pytest.approx(10.0)

    blocked_failed = {
        "status": 1,
        "wall_time_s": 4.0,
        "history": blocked["history"][:3] + [{"lam": 0.55, "iterations": 9, "bending_moment_nm": 0.11}],
    }
    out = fe_solver.samples_from_paths((300.0, 60.0), scales, free, blocked_failed)
    np.testing.assert_array_equal(out["status"], [0, 0, 0, 0, 0, 1, 2, 2, 2, 2])
    assert np.all(np.isnan(out["bending_angle_deg"][5:])) and np.all(np.isnan(out["bending_moment_nm"][5:]))
    assert np.all(np.isfinite(out["bending_moment_nm"][:5]))
    # the samples plug into a shard: the wrapper the lead writes around workflow.fem has this shape
    ds = sweep.run_shard(
        lambda d, s: fe_solver.samples_from_paths(d, s, free, blocked_failed),
        shard=0,
        n_shards=1,
        p_max_kpa=300.0,
        n_ratios=2,
        n_pressures=10,
    )
    assert int((ds["status"] == 0).sum()) == 10


def test_samples_carry_the_overlap_checks_up_to_each_sample():
    from workflow.actuator.fe_solver import samples_from_paths

    hist = [
        {
            "lam": s,
            "iterations": 3,
            "bending_angle_deg": 10 * s,
            "bending_moment_nm": 0.1 * s,
            "max_penetration_mm": pen,
            "overlap_depth_mm": ov,
            "min_pocket_area_mm2": area,
        }
        for s, pen, ov, area in ((0.5, 0.01, 0.0, 30.0), (0.75, 0.03, 0.2, 20.0), (1.0, 0.02, 0.0, 25.0))
    ]
    out = samples_from_paths(
        (300.0, 0.0), np.array([0.5, 1.0]), {"status": 0, "history": hist}, {"status": 0, "history": hist}
    )
    np.testing.assert_allclose(out["max_penetration_mm"], [0.01, 0.03])
    np.testing.assert_allclose(out["overlap_depth_mm"], [0.0, 0.2])  # the worst state so far, not the last
    np.testing.assert_allclose(out["min_pocket_area_mm2"], [30.0, 20.0])
    assert "min_pocket_volume_mm3" not in out
