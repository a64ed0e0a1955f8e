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
DOT = """digraph snakemake_dag {
	0[label = "d", color = "0 0 0"];
	1[label = "a", color = "0 0 0"];
	2[label = "b\\nfea: 2d", color = "0 0 0"];
	3[label = "c", color = "0 0 0"];
	1 -> 0
	3 -> 0
	2 -> 3
}"""


def test_the_log_gives_each_jobs_span_and_the_time_a_core_idled():
    jobs, wall = rt.parse_log(LOG)
    spans = {j.name: (j.start, j.end) for j in jobs}
    assert spans == {"a": (0, 100), "b[fea=2d]": (0, 10), "c": (10, 40), "d": (100, 110)}
    assert wall == 110
    mean_busy, under, idle = rt.busy_profile(jobs, wall, cores=2)
    # one core idles from 40 s (c ends) to 110 s: 70 s of 110 s with fewer than 2 cores busy
    assert under == pytest.approx(70) and mean_busy == pytest.approx((2 * 40 + 70) / 110)
    assert [names for *_, names in idle][0] == ["a"]


@pytest.mark.parametrize("cores, priority, wall", [(2, {}, 110), (1, {}, 150), (1, {"c": 5, "b": 5}, 150)])
def test_the_dag_rebuilt_from_the_measured_jobs_keeps_their_order_and_dependencies(cores, priority, wall):
    jobs, _ = rt.parse_log(LOG)
    nodes, deps = rt.read_dag(DOT)
    assert deps[0] == {1, 3} and deps[3] == {2} and nodes[2] == "b[fea=2d]"
    t, idle, unmeasured = rt.simulate(jobs, nodes, deps, priority, cores)
    assert (t, unmeasured) == (wall, 0)
    assert idle == pytest.approx(cores * wall - 150)
