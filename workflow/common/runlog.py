"""One convention for the log lines that report a solve or a sample, so each job ends with a tally.

A line that reports solves passes ``extra=solved(...)``; the ``script:``
adapters (workflow/scripts/_common.py) count them and end every job's log
with, e.g., ``done: 12 solves, 12 converged, 0 failed, 43.2 s``.  No I/O here.
"""

from __future__ import annotations

__all__ = ["solved"]


def solved(failed: bool | int = 0, n: int = 1) -> dict[str, int]:
    """``extra=`` of a log record reporting ``n`` solves (or samples), ``failed`` of them not converged."""
    return {"solves": int(n), "solves_failed": int(failed)}
