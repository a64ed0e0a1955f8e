"""The workflow catalogue's checks: Snakemake's linter, and the formatters of the rules and the code.

A rule without a declared environment, a misformatted rule file or a module
that `ruff format` would change fails here, so the README's one test command
(which CI runs) also checks the style.
"""

from __future__ import annotations

import subprocess
import sys

from workflow import settings

REPO = settings.REPO_ROOT


def _run(*cmd: str) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)


def test_snakemake_lint_finds_nothing():
    proc = _run(sys.executable, "-m", "snakemake", "--lint", "--cores", "1")
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "Lints for" not in out, out[-4000:]


def test_rules_are_snakefmt_formatted():
    proc = _run(sys.executable, "-m", "snakefmt", "--check", "--line-length", "120", "Snakefile", "rules")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]


def test_python_is_ruff_formatted_and_clean():
    fmt = _run(sys.executable, "-m", "ruff", "format", "--check", "workflow", "tests", "benchmarks")
    assert fmt.returncode == 0, fmt.stdout[-4000:]
    # undefined names, unused imports, import order: the checks that catch a broken move of code
    lint = _run(sys.executable, "-m", "ruff", "check", "--select", "F,I", "workflow", "tests", "benchmarks")
    assert lint.returncode == 0, lint.stdout[-4000:]
