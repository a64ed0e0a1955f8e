"""The workflow end to end: dry run, smoke run on config/smoke.yaml, reruns.

The smoke run works on a copy of the workflow files in a temporary directory,
so it never touches the repository's results/.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr
import yaml

from workflow import settings

REPO = settings.REPO_ROOT
SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def _copy_workflow(dst: Path) -> None:
    for name in ("Snakefile", "rules", "config", "resources", "report"):
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dst / name)
        else:
            shutil.copy2(src, dst / name)
    # the rules' script: adapters live in the package; link it rather than copy
    (dst / "workflow").symlink_to(REPO / "workflow", target_is_directory=True)


def _run(workdir: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    proc = subprocess.run([*SNAKEMAKE, *args], cwd=workdir, capture_output=True, text=True, env=env, timeout=1500)
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-6000:]}")
    return proc


def _local_overrides(workdir: Path) -> Path:
    """Point the table backend at the shared export by absolute path (the copy lives elsewhere)."""
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    over: dict = {}
    if cfg.get("musculoskeletal", {}).get("backend", "table") == "table":
        table = (REPO / cfg["musculoskeletal"]["table_path"]).resolve()
        if not table.is_file():
            pytest.skip(f"default backend reads the authors' export, absent here: {table}")
        over["musculoskeletal"] = {"table_path": str(table)}
    path = workdir / "config" / "local.yaml"
    path.write_text(yaml.safe_dump(over))
    return path


def _planned_jobs(proc: subprocess.CompletedProcess) -> dict[str, int]:
    """Job counts from a dry run's 'Job stats' table."""
    out = proc.stdout + proc.stderr
    if "Nothing to be done" in out:
        return {}
    jobs: dict[str, int] = {}
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Job stats"))
    for line in lines[start + 3:]:
        parts = line.split()
        if len(parts) != 2 or parts[0] == "total":
            break
        jobs[parts[0]] = int(parts[1])
    return jobs


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    workdir = tmp_path_factory.mktemp("smoke")
    _copy_workflow(workdir)
    local = _local_overrides(workdir)
    cfgs = ["--configfile", "config/smoke.yaml", str(local)]
    _run(workdir, "-c2", *cfgs)
    return workdir, cfgs


def test_dry_run_of_the_default_config(tmp_path):
    _copy_workflow(tmp_path)
    local = _local_overrides(tmp_path)
    proc = _run(tmp_path, "-n", "--configfile", "config/config.yaml", str(local))
    assert "patient_loads" in proc.stdout


def test_bad_config_fails_before_any_job(tmp_path):
    _copy_workflow(tmp_path)
    (tmp_path / "config" / "bad.yaml").write_text("patients:\n  px:\n    measurements_mm: {L3PP: -4.0}\n")
    proc = _run(tmp_path, "-n", "--configfile", "config/bad.yaml", check=False)
    assert proc.returncode != 0
    assert "-4.0" in proc.stdout + proc.stderr
    assert not (tmp_path / "results").exists()


def test_smoke_outputs(smoke):
    workdir, _ = smoke
    res = workdir / "results"
    with xr.open_dataset(res / "doe" / "ccd.nc") as ccd:
        assert ccd.sizes["run"] == 15 and "Original" in ccd["marker"].values
        for key in ("config_sha256", "git_commit", "created_utc", "rule", "package_versions"):
            assert key in ccd.attrs
    with xr.open_dataset(res / "validation" / "scaling.nc") as v:
        assert v.attrs["max_abs_error_excluding_paper_inconsistency"] <= 0.0025
    with xr.open_dataset(res / "musculoskeletal" / "rsm.nc") as r:
        assert set(r["form"].values) == {"linear", "quadratic", "quadratic_3fi"}
        assert "F3_P_MCP_90" in r["response"].values
        assert int(r["selected"].sum()) == r.sizes["response"]
    for patient in ("mean", "p01"):
        with xr.open_dataset(res / "patients" / patient / "joint_loads.nc") as jl:
            assert set(jl["exercise"].values) == {f"TGE{i}" for i in range(1, 6)}
            assert float(jl["passive_moment_nm"].sel(exercise="TGE1").sum()) == 0
            assert (jl["active_limit_nm"] > 0).all()
    assert (res / "musculoskeletal" / "rsm_r2.png").stat().st_size > 10_000
    assert any((res / "benchmarks" / "rules").glob("rsm.tsv"))
    # the run ledger: one MLflow run per patient, with headline metrics
    import json

    row = json.loads((res / "tracking" / "mean.json").read_text())
    assert row["metrics"]["scaling_max_abs_error"] <= 0.0025 and row["metrics"]["time_rsm_s"] > 0


def test_rerun_with_nothing_changed_does_nothing(smoke):
    workdir, cfgs = smoke
    assert _planned_jobs(_run(workdir, "-n", *cfgs)) == {}


def test_editing_one_patient_reruns_only_that_patient(smoke):
    workdir, cfgs = smoke
    edited = workdir / "config" / "edited.yaml"
    edited.write_text(yaml.safe_dump({"patients": {"p01": {"finger": "F3", "measurements_mm": {"L3PP": 55.0}}}}))
    jobs = _planned_jobs(_run(workdir, "-n", *cfgs, str(edited)))
    assert jobs.get("patient_loads") == 1
    # only per-patient rules; the shared stages (DOE, moments, RSM, actuator sweeps) are reused
    per_patient = {"patient_loads", "track_patient", "cascade_plan", "fea_check"}
    assert set(jobs) - {"all"} <= per_patient
    assert all(n == 1 for r, n in jobs.items() if r != "all")
    proc = _run(workdir, "-n", *cfgs, str(edited))
    assert "output: results/patients/p01/" in proc.stdout
    assert "output: results/patients/mean/" not in proc.stdout
