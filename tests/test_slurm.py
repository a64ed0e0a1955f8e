"""The smoke workflow through a real single-node SLURM cluster and the profile profiles/slurm.

tests/slurm/start_slurm.sh installs Debian's slurm-wlm and munge if missing and starts
munged, slurmctld and slurmd on this machine (root only); the module fixture stops
them again (tests/slurm/stop_slurm.sh) unless they were already running. The test
runs `snakemake --profile profiles/slurm --configfile config/smoke.yaml <local> <targets>`
(one job of each kind: DOE, scaling, the OpenSim model and one sampling run, one FE sweep shard) on a copy of the workflow and checks that every job went through SLURM: seen by squeue
while the run lasted and recorded COMPLETED in the job completion log.

Skips, with the reason, where SLURM cannot be started here: not root, no apt-get or
the packages cannot be installed, a real SLURM configuration already present, or the
SLURM executor plugin not installed. Under CI (env CI=true) these fail instead, so
that CI cannot pass without running it; SLURM_TEST_ALLOW_SKIP=1 lets them skip there too.
SLURM_TEST_SKIP=1 skips the module outright.
"""

from __future__ import annotations

import collections
import importlib.util
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from _smoke import REPO, SNAKEMAKE, copy_workflow, local_overrides, planned_jobs, run_snakemake, snakemake_env

HERE = Path(__file__).resolve().parent
START = HERE / "slurm" / "start_slurm.sh"
STOP = HERE / "slurm" / "stop_slurm.sh"
JOBCOMP = Path("/var/log/slurm/jobcomp.log")  # JobCompLoc in start_slurm.sh
PROFILE = yaml.safe_load((REPO / "profiles" / "slurm" / "config.yaml").read_text())
PARTITION = PROFILE["default-resources"]["slurm_partition"]
RUN_TIMEOUT_S = 900  # the smoke run through SLURM; the plugin can hang without a working status query
# What goes through SLURM: one job of each kind the workflow has (numpy-only DOE and scaling jobs, the
# OpenSim model and one OpenSim sampling run, one FE sweep shard): six jobs, two at a time. The executor is
# what is tested here; the whole smoke DAG runs locally in tests/test_workflow.py (CI time budget).
SLURM_TARGETS = [
    "results/validation/scaling.nc",
    "results/musculoskeletal/opensim/run1.nc",
    "results/actuator/sweep/2d/shard0.nc",
]

pytestmark = pytest.mark.slow


def _on_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes") and not os.environ.get("SLURM_TEST_ALLOW_SKIP")


def _cannot_run(reason: str):
    """Skip (fail under CI) with the reason, also printed for the log."""
    print(f"SLURM test not run: {reason}", file=sys.stderr)
    if _on_ci():
        pytest.fail(f"CI must run the SLURM test, but: {reason} (SLURM_TEST_ALLOW_SKIP=1 skips it)")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def slurm_cluster():
    if os.environ.get("SLURM_TEST_SKIP"):
        pytest.skip("SLURM_TEST_SKIP is set")
    if not sys.platform.startswith("linux"):
        _cannot_run(f"needs Linux (Debian slurm-wlm), this is {sys.platform}")
    if os.geteuid() != 0:
        _cannot_run(f"needs root to install and start slurmctld/slurmd/munged (uid {os.geteuid()})")
    if importlib.util.find_spec("snakemake_executor_plugin_slurm") is None:
        _cannot_run('snakemake-executor-plugin-slurm is not installed (pip install -e ".[test]")')
    t0 = time.monotonic()
    env = dict(os.environ, SLURM_TEST_PARTITION=PARTITION)
    try:
        proc = subprocess.run(["bash", str(START)], capture_output=True, text=True, timeout=600, env=env)
    except subprocess.TimeoutExpired:
        pytest.fail("tests/slurm/start_slurm.sh did not finish within 600 s")
    start_s = time.monotonic() - t0
    print(proc.stderr, end="")
    if proc.returncode in (2, 3, 4):  # not root / packages unavailable / a real SLURM config present
        _cannot_run(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}")
    if proc.returncode != 0:
        subprocess.run(["bash", str(STOP)], timeout=120)  # whatever half started
        pytest.fail(f"start_slurm.sh failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    started = "STATE=started" in proc.stdout
    apt = re.search(r"apt-get install took (\d+) s", proc.stderr)
    print(
        f"SLURM cluster {'started' if started else 'already running'} in {start_s:.1f} s"
        f" (apt-get install: {apt.group(1) + ' s' if apt else 'not needed'})"
    )
    yield {"started": started, "start_s": start_s}
    if started:
        subprocess.run(["bash", str(STOP)], timeout=120)


def _squeue() -> list[dict[str, str]]:
    """All jobs slurmctld still knows (finished ones stay for MinJobAge = 600 s)."""
    try:
        out = subprocess.run(
            ["squeue", "--states=all", "--noheader", "--format=%i|%j|%T|%k|%P"],
            capture_output=True,
            text=True,
            timeout=30,
        ).stdout
    except subprocess.TimeoutExpired:
        return []
    keys = ("id", "name", "state", "comment", "partition")
    return [dict(zip(keys, line.split("|"))) for line in out.splitlines() if line.count("|") == 4]


def _jobcomp(offset: int) -> list[dict[str, str]]:
    """Job completion records (jobcomp/filetxt) written after byte `offset`."""
    if not JOBCOMP.exists():
        return []
    with JOBCOMP.open("rb") as f:
        f.seek(offset)
        text = f.read().decode(errors="replace")
    return [dict(re.findall(r"(\w+)=(\S*)", line)) for line in text.splitlines() if line.startswith("JobId=")]


def _rule_of(comment: str) -> str:
    """The plugin's job comment is rule_<name> or rule_<name>_wildcards_<values>."""
    return comment.removeprefix("rule_").split("_wildcards_")[0]


def test_smoke_workflow_through_slurm(slurm_cluster, tmp_path):
    copy_workflow(tmp_path, extra=("profiles",))
    local = local_overrides(tmp_path)
    # fidelity.auto off: the sweep shard then depends on the config alone, not on the FE study (which the
    # smoke run of tests/test_workflow.py covers), so the cluster runs a handful of short jobs
    (tmp_path / "config" / "slurm_test.yaml").write_text(yaml.safe_dump({"fidelity": {"auto": False}}))
    cfgs = ["--configfile", "config/smoke.yaml", str(local), "config/slurm_test.yaml"]

    # targets before --configfile, which takes every following argument as a file
    dry = run_snakemake(tmp_path, "-n", *SLURM_TARGETS, *cfgs)
    expected = collections.Counter({r: n for r, n in planned_jobs(dry).items() if r != "all"})
    targets = SLURM_TARGETS
    assert expected, "the smoke workflow plans no jobs"

    offset = JOBCOMP.stat().st_size if JOBCOMP.exists() else 0
    log = tmp_path / "snakemake_slurm.log"
    # the README's command; a short first status check only to keep the test quick
    cmd = [
        *SNAKEMAKE,
        *SLURM_TARGETS,
        "--profile",
        "profiles/slurm",
        *cfgs,
        "--slurm-init-seconds-before-status-checks",
        "1",
    ]
    seen: dict[str, dict[str, str]] = {}  # SLURM job id -> its last squeue row
    t0 = time.monotonic()
    with log.open("w") as out:
        proc = subprocess.Popen(
            cmd,
            cwd=tmp_path,
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
            env=snakemake_env(),
            start_new_session=True,
        )
        try:
            while proc.poll() is None:
                if time.monotonic() - t0 > RUN_TIMEOUT_S:
                    os.killpg(proc.pid, signal.SIGTERM)
                    proc.wait(30)
                    break
                for row in _squeue():
                    if row["name"].startswith(PROFILE["slurm-jobname-prefix"] + "_"):
                        seen[row["id"]] = row
                time.sleep(0.5)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    run_s = time.monotonic() - t0
    text = log.read_text()
    run_id = re.search(r"SLURM run ID: (\S+)", text)
    if run_id:
        subprocess.run(["scancel", "--name", run_id.group(1)], capture_output=True, timeout=30)  # leftovers, if any
    print(f"smoke workflow through SLURM: {sum(expected.values())} jobs in {run_s:.1f} s")
    assert proc.returncode == 0, (
        f"snakemake through SLURM failed (exit {proc.returncode}) after {run_s:.0f} s:\n{text[-6000:]}"
    )
    assert run_id, "the SLURM executor did not report its run ID:\n" + text[-3000:]
    run_id = run_id.group(1)

    # the targets exist and nothing is left to do for them
    missing = [t for t in targets if not (tmp_path / t).is_file() or (tmp_path / t).stat().st_size == 0]
    assert not missing, f"targets missing after the SLURM run: {missing}"
    assert planned_jobs(run_snakemake(tmp_path, "-n", *SLURM_TARGETS, *cfgs)) == {}

    # every job ran as a SLURM job: recorded COMPLETED in the job completion log ...
    records = [r for r in _jobcomp(offset) if r.get("Name") == run_id]
    assert len(records) == sum(expected.values()), (
        f"jobcomp has {len(records)} records of run {run_id}, the workflow planned {dict(expected)}"
    )
    assert {r["JobState"] for r in records} == {"COMPLETED"}
    assert {r["Partition"] for r in records} == {PARTITION}
    # ... and was visible in the queue while the run lasted, one job per planned rule instance
    mine = {i: row for i, row in seen.items() if row["name"] == run_id}
    assert set(mine) == {r["JobId"] for r in records}, (
        f"squeue saw {sorted(mine)}, jobcomp lists {sorted(r['JobId'] for r in records)}"
    )
    assert collections.Counter(_rule_of(row["comment"]) for row in mine.values()) == expected
