"""Helpers for running the workflow on a copy of its files (smoke runs).

Shared by tests/test_workflow.py and tests/test_slurm.py: copy the workflow into a temporary directory, link
the `workflow` package, write the local config override, run snakemake, read a
dry run's job counts.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from workflow import settings

REPO = settings.REPO_ROOT
SNAKEMAKE = [sys.executable, "-m", "snakemake"]
# Every job (local or on a cluster, where sbatch exports the environment) gets one BLAS/OpenMP thread.
THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
WORKFLOW_FILES = ("Snakefile", "rules", "config", "resources", "report", "envs")


def copy_workflow(dst: Path, extra: tuple[str, ...] = ()) -> None:
    """Copy the workflow's files (and `extra` repository paths, e.g. "profiles") into dst."""
    for name in (*WORKFLOW_FILES, *extra):
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dst / name)
        else:
            shutil.copy2(src, dst / name)
    # the rules' script: adapters live in the package; link it rather than copy
    (dst / "workflow").symlink_to(REPO / "workflow", target_is_directory=True)


def snakemake_env() -> dict[str, str]:
    return dict(os.environ, **THREAD_ENV)


def run_snakemake(workdir: Path, *args: str, check: bool = True, timeout: float = 1500) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [*SNAKEMAKE, *args], cwd=workdir, capture_output=True, text=True, env=snakemake_env(), timeout=timeout
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-6000:]}")
    return proc


def local_overrides(workdir: Path) -> Path:
    """Point the table backend and the finger section at the shared files by absolute path (the copy lives elsewhere)."""
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    over: dict = {}
    if cfg.get("musculoskeletal", {}).get("backend", "table") == "table":
        table = (REPO / cfg["musculoskeletal"]["table_path"]).resolve()
        if not table.is_file():
            pytest.skip(f"default backend reads the authors' export, absent here: {table}")
        over["musculoskeletal"] = {"table_path": str(table)}
    # the authors' finger section beside the repository: the copy reaches it by absolute path, so the
    # smoke run checks its plan by FEA as the default run does
    section = (REPO / cfg["cascade"]["section_points"]).resolve()
    if section.is_file():
        over["cascade"] = {"section_points": str(section)}
    path = workdir / "config" / "local.yaml"
    path.write_text(yaml.safe_dump(over))
    return path


def planned_jobs(proc: subprocess.CompletedProcess) -> dict[str, int]:
    """Job counts from a dry run's 'Job stats' table."""
    out = proc.stdout + proc.stderr
    if "Nothing to be done" in out:
        return {}
    jobs: dict[str, int] = {}
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Job stats"))
    for line in lines[start + 3 :]:
        parts = line.split()
        if len(parts) != 2 or parts[0] == "total":
            break
        jobs[parts[0]] = int(parts[1])
    return jobs
