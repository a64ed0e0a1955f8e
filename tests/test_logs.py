"""Logs a person can read: no third-party INFO chatter unless asked for, a tally at each job's end,
one line for a damaged input.

Each case runs a ``script:``-like job in a fresh interpreter (logging is process-wide, and the
tally is written at exit).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from workflow.settings import REPO_ROOT

JOB = """
import logging, sys
from types import SimpleNamespace
from workflow.scripts._common import setup_logging
from workflow.common.runlog import solved
setup_logging(SimpleNamespace(log=[sys.argv[1]], rule="demo"))
from skfem import Basis, ElementTriP1, MeshTri
Basis(MeshTri().refined(2), ElementTriP1())  # scikit-fem logs 'Initializing CellBasis...' at INFO
logging.getLogger("skfem.mesh.mesh").warning("Transforming over 1000 vertices to C_CONTIGUOUS.")  # as it does
logging.getLogger("workflow.actuator.sweep").info("ray 1: converged", extra=solved(False))
logging.getLogger("workflow.actuator.sweep").info("ray 2: stalled", extra=solved(True))
if sys.argv[2] == "corrupt":
    from workflow.common.provenance import corrupt_input
    raise corrupt_input("results/actuator/response_3d.nc", "not a readable netCDF file")
"""


def _job(tmp_path, mode="ok", **env):
    log = tmp_path / f"{mode}.log"
    proc = subprocess.run(
        [sys.executable, "-c", JOB, str(log), mode],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT), **env},
    )
    return proc, log.read_text().splitlines()


def test_library_chatter_is_off_and_each_job_ends_with_a_tally(tmp_path):
    proc, lines = _job(tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert not any("skfem" in line for line in lines)
    assert [line.split(": ", 1)[1] for line in lines] == [
        "ray 1: converged",
        "ray 2: stalled",
        lines[-1].split(": ", 1)[1],
    ]
    assert "demo: done: 2 solves, 1 converged, 1 failed, " in lines[-1] and lines[-1].endswith(" s")


@pytest.mark.parametrize("value", ["1", "yes"])
def test_the_environment_switch_brings_the_library_lines_back(tmp_path, value):
    _, lines = _job(tmp_path, FINGER_REHAB_VERBOSE_LIBS=value)
    assert any("Initializing CellBasis" in line for line in lines)
    assert any("C_CONTIGUOUS" in line for line in lines)


def test_a_damaged_input_fails_the_job_with_one_line(tmp_path):
    proc, lines = _job(tmp_path, "corrupt")
    assert proc.returncode != 0
    errors = [line for line in lines if " ERROR " in line]
    assert len(errors) == 2 and "Traceback" not in "\n".join(lines)
    assert errors[0].endswith(
        "results/actuator/response_3d.nc: not a readable netCDF file; delete it and rerun: Snakemake recomputes it"
    )
    assert "failed after 2 solves, 1 converged, 1 failed" in errors[1]
