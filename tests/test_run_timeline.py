"""benchmarks/run_timeline.py: a Snakemake log's jobs, the idle cores, and the schedule of a DAG rebuilt from them."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location(
    "run_timeline", Path(__file__).resolve().parents[1] / "benchmarks" / "run_timeline.py"
)
rt = sys.modules["run_timeline"] = importlib.util.module_from_spec(_spec)  # registered first: it holds a dataclass
_spec.loader.exec_module(rt)


def _start(t: str, rule: str, jobid: int, wildcards: str = "") -> str:
    wc = f"\n    wildcards: {wildcards}" if wildcards else ""
    return f"[Sun Dec  6 10:{t} 2026]\nrule {rule}:\n    output: x\n    jobid: {jobid}{wc}\n"


def _end(t: str, jobid: int, rule: str) -> str:
    return f"[Sun Dec  6 10:{t} 2026]\nFinished jobid: {jobid} (Rule: {rule})\n"


# a: 0-100 s and b: 0-10 s side by side; c (waits for b) 10-40 s; d (waits for a and c) 100-110 s
LOG = (
    _start("00:00", "a", 1)
    + _start("00:00", "b", 2, "fea=2d")
    + _end("00:10", 2, "b")
    + _start("00:10", "c", 3)
    + _end("00:40", 3, "c")
    + _end("01:40", 1, "a")
    + _start("01:40", "d", 4)
    + _end("01:50", 4, "d")
)


def _planned(rule: str, jobid: int, inputs: str, outputs: str, wildcards: str = "", priority: int = 0) -> str:
    wc = f"\n    wildcards: {wildcards}" if wildcards else ""
    pr = f"\n    priority: {priority}" if priority else ""
    return f"[Sun Dec  6 11:00:00 2026]\nrule {rule}:\n    input: {inputs}\n    output: {outputs}\n    jobid: {jobid}{wc}{pr}\n"


def _dry_run(priority_a: int = 0) -> str:
    """The dry run of LOG's DAG (d waits for a and c, c for b); jobids differ from the log's."""
    return (
        _planned("d", 0, "A.nc, C.nc, code.py", "D.nc")
        + _planned("a", 7, "code.py", "A.nc", priority=priority_a)
        + _planned("b", 8, "code.py", "B_2d.nc", "fea=2d")
        + _planned("c", 9, "B_2d.nc", "C.nc")
    )


def test_the_log_gives_each_jobs_span_and_the_time_a_core_idled():
    jobs, wall = rt.parse_log(LOG)
    spans = {j.name: (j.start, j.end) for j in jobs}
    assert spans == {"a": (0, 100), "b[fea=2d]": (0, 10), "c": (10, 40), "d": (100, 110)}
    assert wall == 110
    mean_busy, under, idle = rt.busy_profile(jobs, wall, cores=2)
    # one core idles from 40 s (c ends) to 110 s: 70 s of 110 s with fewer than 2 cores busy
    assert under == pytest.approx(70) and mean_busy == pytest.approx((2 * 40 + 70) / 110)
    assert [names for *_, names in idle][0] == ["a"]


@pytest.mark.parametrize("cores, wall", [(2, 110), (1, 150)])
def test_the_dry_run_rebuilt_from_the_measured_jobs_keeps_their_order_and_dependencies(cores, wall):
    jobs, log_wall = rt.parse_log(LOG)
    plan, deps = rt.read_plan(_dry_run())
    assert deps == {0: {7, 9}, 7: set(), 8: set(), 9: {8}} and plan[8].key == "b[fea=2d]"
    t, idle, unmeasured, running = rt.simulate(jobs, plan, deps, cores, log_wall)
    assert (t, unmeasured, running) == (wall, 0, 0)
    assert idle == pytest.approx(cores * wall - 150)


def test_a_priority_changes_the_simulated_order():
    """Ties keep the measured order (the short jobs before a: 120 s); a priority on a starts it first (110 s)."""
    log = (  # b, c (10 s each) first, a (100 s) after them on the second core: the run took 110 s
        _start("00:00", "b", 2, "fea=2d")
        + _start("00:00", "c0", 5)
        + _end("00:10", 2, "b")
        + _start("00:10", "c", 3)
        + _end("00:10", 5, "c0")
        + _start("00:10", "a", 1)
        + _end("00:20", 3, "c")
        + _end("01:50", 1, "a")
        + _start("01:50", "d", 4)
        + _end("02:00", 4, "d")
    )
    jobs, wall = rt.parse_log(log)
    dry = _dry_run() + _planned("c0", 10, "code.py", "C0.nc")
    assert rt.simulate(jobs, *rt.read_plan(dry), 2, wall)[0] == 120
    # a first: a runs 0-100 beside b, c0, c (0-30); d 100-110
    dry = _dry_run(priority_a=5) + _planned("c0", 10, "code.py", "C0.nc")
    assert rt.simulate(jobs, *rt.read_plan(dry), 2, wall)[0] == 110


def test_a_failed_job_is_the_one_the_error_names_and_a_running_one_counts_its_time_so_far():
    log = (
        _start("00:00", "b", 2, "fea=2d")
        + _start("00:00", "b", 6, "fea=3d")
        + "[Sun Dec  6 10:00:05 2026]\nError in rule b:\n    message: None\n    jobid: 6\n"
        + _start("00:05", "a", 1)
        + _end("00:10", 2, "b")
        + "2026-12-06 10:00:30,000 INFO a: still going\n"
    )
    jobs, wall = rt.parse_log(log)
    state = {j.name: (j.end, j.failed) for j in jobs}
    assert state == {"b[fea=2d]": (10, False), "b[fea=3d]": (5, True), "a": (None, False)}
    assert wall == 30
    plan, deps = rt.read_plan(_planned("a", 3, "code.py", "A.nc"))
    assert rt.simulate(jobs, plan, deps, 1, wall)[::3] == (25, 1)
