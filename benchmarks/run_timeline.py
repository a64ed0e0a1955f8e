"""How busy a Snakemake run kept the cores: a timeline of its jobs from the run's log.

Usage::

    snakemake -c2 > run.log 2>&1
    python benchmarks/run_timeline.py run.log [--cores 2] [--png benchmarks/out/run_timeline.png]

Reads the start (``[date]`` then ``rule``/``localrule`` with its ``jobid``) and the end
(``Finished jobid: N``) of every job in the log Snakemake writes to its terminal, and
the threads each job was given (1 unless the log names ``threads``).  Prints the run's
wall time, the job-seconds, the mean number of busy cores over the wall time, the
share of the wall time in which fewer than ``--cores`` were busy and which job ran
alone then, and the longest jobs; draws a Gantt chart when ``--png`` is given.
Jobs still running at the log's end are counted up to its last timestamp and flagged.

With ``--simulate DRYRUN`` (the terminal output of ``snakemake -n --forceall`` of the
rules to judge, which lists every job with its inputs, outputs and priority) the
measured jobs are scheduled again on ``--cores`` cores by their dependencies (an input
another job writes) and priorities: whenever a core is free the ready job of highest
priority starts, ties in the order the measured run started them.  Run it on the dry
run of the rules that ran to see how closely it reproduces the measured wall time,
then on another dry run for an estimate of what a change of the rules' order or
dependencies does, without a second cold run.  An estimate: jobs the log does not
hold take the mean of their rule's measured jobs (else 0 s), and jobs still running at
the log's end their time so far (a lower bound; the output says how many).
Not a test: a measurement of one run on one machine.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

STAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
RULE = re.compile(r"^(?:local)?rule (\w+):$")
JOBID = re.compile(r"^\s+jobid: (\d+)$")
THREADS = re.compile(r"^\s+threads: (\d+)$")
WILDCARDS = re.compile(r"^\s+wildcards: (.*)$")
LINE_STAMP = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),\d+ ")  # a job's log line: moves the clock only
FINISHED = re.compile(r"^Finished jobid: (\d+)")
ERROR = re.compile(r"^Error in rule (\w+):")


@dataclass
class Job:
    """One job of the run: rule, wildcards, threads, start and end (s from the run's first timestamp)."""

    jobid: int
    rule: str
    wildcards: str = ""
    threads: int = 1
    start: float = 0.0
    end: float | None = None
    failed: bool = False

    @property
    def name(self) -> str:
        return _key(self.rule, self.wildcards)  # the same key as a dry run's job, so the replay can match them


def parse_log(text: str) -> tuple[list[Job], float]:
    """Jobs of a Snakemake log and the time (s) of its last timestamp, both from its first timestamp."""
    jobs: dict[int, Job] = {}
    t0 = last = None
    stamp = None
    pending: Job | None = None
    failing = False
    for line in text.splitlines():
        m = STAMP.match(line)
        if m:
            stamp = datetime.strptime(" ".join(m.group(1).split()), "%a %b %d %H:%M:%S %Y").timestamp()
            t0 = stamp if t0 is None else t0
            last = stamp
            pending = None
            continue
        if stamp is None:
            continue
        if m := LINE_STAMP.match(line):
            last = max(last, datetime.strptime(m.group(1), "%Y-%m-%d %H:%M:%S").timestamp())
            continue
        if m := RULE.match(line):
            pending, failing = Job(jobid=-1, rule=m.group(1), start=stamp - t0), False
        elif pending is not None and (m := JOBID.match(line)):
            pending.jobid = int(m.group(1))
            jobs[pending.jobid] = pending
        elif pending is not None and (m := THREADS.match(line)):
            pending.threads = int(m.group(1))
        elif pending is not None and (m := WILDCARDS.match(line)):
            pending.wildcards = m.group(1)
        elif m := FINISHED.match(line):
            job = jobs.get(int(m.group(1)))
            if job is not None:
                job.end = stamp - t0
        elif ERROR.match(line):
            failing = True  # the failed job's jobid follows on its own line
        elif failing and (m := JOBID.match(line)):
            job = jobs.get(int(m.group(1)))
            if job is not None and job.end is None:
                job.end, job.failed = stamp - t0, True
            failing = False
    if t0 is None:
        raise SystemExit("no timestamps in the log: is it the terminal output of a Snakemake run?")
    return list(jobs.values()), last - t0


def busy_profile(jobs: list[Job], wall: float, cores: int) -> tuple[float, float, list[tuple[float, float, list[str]]]]:
    """Mean busy cores over the wall time, seconds with fewer than ``cores`` busy, and those spans with their jobs."""
    edges = sorted({0.0, wall, *(j.start for j in jobs), *((j.end if j.end is not None else wall) for j in jobs)})
    busy_area, under, spans = 0.0, 0.0, []
    for a, b in zip(edges[:-1], edges[1:]):
        running = [j for j in jobs if j.start <= a and (j.end if j.end is not None else wall) >= b]
        busy = min(cores, sum(j.threads for j in running))
        busy_area += busy * (b - a)
        if busy < cores and b > a:
            under += b - a
            spans.append((a, b, [j.name for j in running]))
    return busy_area / wall if wall else 0.0, under, spans


FILES = re.compile(r"^\s+(input|output): (.*)$")
PRIORITY = re.compile(r"^\s+priority: (-?\d+)$")


def _key(rule: str, wildcards: str) -> str:
    return f"{rule}[{wildcards}]" if wildcards else rule


@dataclass
class PlannedJob:
    """One job of a dry run: its key (rule[wildcards]), the files it reads and writes, its priority."""

    key: str
    inputs: list[str]
    outputs: list[str]
    priority: int = 0


def read_plan(text: str) -> tuple[dict[int, PlannedJob], dict[int, set[int]]]:
    """Jobs of a dry run (``snakemake -n``) by jobid, and the jobids each waits for (an input another job writes)."""
    jobs: dict[int, PlannedJob] = {}
    cur: dict | None = None

    def close():
        if cur and cur.get("jobid") is not None:
            jobs[cur["jobid"]] = PlannedJob(
                _key(cur["rule"], cur.get("wildcards", "")),
                cur.get("input", []),
                cur.get("output", []),
                cur.get("priority", 0),
            )

    for line in text.splitlines():
        if m := RULE.match(line):
            close()
            cur = {"rule": m.group(1)}
        elif cur is None:
            continue
        elif m := FILES.match(line):
            cur[m.group(1)] = [f.strip() for f in m.group(2).split(", ")]
        elif m := JOBID.match(line):
            cur["jobid"] = int(m.group(1))
        elif m := WILDCARDS.match(line):
            cur["wildcards"] = m.group(1)
        elif m := PRIORITY.match(line):
            cur["priority"] = int(m.group(1))
    close()
    writer = {f: j for j, job in jobs.items() for f in job.outputs}
    deps = {j: {writer[f] for f in job.inputs if f in writer and writer[f] != j} for j, job in jobs.items()}
    return jobs, deps


def simulate(
    jobs: list[Job], plan: dict[int, PlannedJob], deps: dict[int, set[int]], cores: int, wall: float
) -> tuple[float, float, int, int]:
    """(wall time, core-seconds idle, jobs without a measured time, jobs still running in the log) of the plan, s."""
    measured = {j.name: j for j in jobs if not j.failed}
    by_rule: dict[str, list[float]] = {}
    for j in measured.values():
        if j.end is not None:
            by_rule.setdefault(j.rule, []).append(j.end - j.start)
    dur, order, unmeasured, running_in_log = {}, {}, 0, 0
    for n, job in plan.items():
        rule = job.key.split("[", 1)[0]
        if job.key in measured:
            j = measured[job.key]
            running_in_log += j.end is None
            dur[n], order[n] = (j.end if j.end is not None else wall) - j.start, j.start
        else:
            dur[n] = sum(by_rule[rule]) / len(by_rule[rule]) if rule in by_rule else 0.0
            order[n], unmeasured = -1.0, unmeasured + 1
    done: set[int] = set()
    running: list[tuple[float, int]] = []
    t = idle = 0.0
    pending = set(plan)
    while pending or running:
        ready = sorted((n for n in pending if deps[n] <= done), key=lambda n: (-plan[n].priority, order[n]))
        while ready and len(running) < cores:
            n = ready.pop(0)
            pending.discard(n)
            running.append((t + dur[n], n))
        if not running:
            raise SystemExit("the dry run has a cycle or a job waits for one it does not hold")
        running.sort()
        t_next, n = running.pop(0)
        idle += (cores - len(running) - 1) * (t_next - t)
        t = t_next
        done.add(n)
    return t, idle, unmeasured, running_in_log


def draw(jobs: list[Job], wall: float, png: Path) -> None:
    """Gantt chart of the jobs, one row per job in start order (minutes on the x axis)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = sorted(jobs, key=lambda j: j.start)
    # rules with a job over 2 % of the run get a colour of their own (tab10, distinct), the rest grey
    long = sorted({j.rule for j in jobs if ((j.end if j.end is not None else wall) - j.start) > 0.02 * wall})
    colours = {r: plt.cm.tab10(i % 10) for i, r in enumerate(long)}
    fig, ax = plt.subplots(figsize=(11, max(4, 0.12 * len(order))))
    for row, j in enumerate(order):
        end = j.end if j.end is not None else wall
        c = colours.get(j.rule, "0.85")
        # failed jobs outlined, jobs still running at the log's end hatched
        ax.barh(
            row,
            (end - j.start) / 60,
            left=j.start / 60,
            color=c,
            edgecolor="k" if j.failed else None,
            hatch="//" if j.end is None else None,
        )
    ax.set_yticks([])
    ax.invert_yaxis()
    ax.set_xlabel("wall time since the run's start (min)")
    ax.set_ylabel("jobs in start order")
    ax.set_title(f"{len(jobs)} jobs, {wall / 60:.1f} min")
    # the bars run from top left to bottom right: the legend goes top right
    ax.legend(
        handles=[plt.Rectangle((0, 0), 1, 1, color=colours[r]) for r in long],
        labels=long,
        fontsize=8,
        loc="upper right",
    )
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--png", type=Path)
    ap.add_argument("--top", type=int, default=12, help="longest jobs to list")
    ap.add_argument("--simulate", type=Path, nargs="+", help="dry runs (snakemake -n --forceall) to schedule")
    args = ap.parse_args(argv)
    jobs, wall = parse_log(args.log.read_text())
    job_s = sum(((j.end if j.end is not None else wall) - j.start) * j.threads for j in jobs)
    mean_busy, under, spans = busy_profile(jobs, wall, args.cores)
    running = [j for j in jobs if j.end is None]
    print(
        f"jobs started {len(jobs)}, finished {sum(j.end is not None and not j.failed for j in jobs)}, "
        f"failed {sum(j.failed for j in jobs)}, still running at the log's end {len(running)}"
    )
    print(f"wall {wall:.0f} s ({wall / 60:.1f} min); job-seconds {job_s:.0f} ({job_s / 60:.1f} job-min)")
    print(
        f"mean busy cores {mean_busy:.2f} of {args.cores}; fewer than {args.cores} busy for {under:.0f} s "
        f"({100 * under / wall:.0f} % of the wall time)"
    )
    alone: dict[str, float] = {}
    for a, b, names in spans:
        key = " + ".join(names) if names else "(none)"
        alone[key] = alone.get(key, 0.0) + b - a
    print("running while a core idled (s):")
    for key, s in sorted(alone.items(), key=lambda kv: -kv[1])[:8]:
        print(f"  {s:7.0f}  {key}")
    print("longest jobs (s):")
    for j in sorted(jobs, key=lambda j: -((j.end if j.end is not None else wall) - j.start))[: args.top]:
        end = j.end if j.end is not None else wall
        flag = " (still running)" if j.end is None else (" (failed)" if j.failed else "")
        print(f"  {end - j.start:7.0f}  {j.start / 60:6.1f}-{end / 60:6.1f} min  {j.name}{flag}")
    for dry in args.simulate or []:
        plan, deps = read_plan(dry.read_text())
        t, idle, unmeasured, lower = simulate(jobs, plan, deps, args.cores, wall)
        print(
            f"{dry}: {len(plan)} jobs scheduled on {args.cores} cores: wall {t:.0f} s ({t / 60:.1f} min), "
            f"a core idle {idle:.0f} s; {unmeasured} jobs without a measured time (their rule's mean), "
            f"{lower} still running in the log (their time so far)"
        )
    if args.png:
        draw(jobs, wall, args.png)
        print(f"chart: {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
