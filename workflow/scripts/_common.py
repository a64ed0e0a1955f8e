"""Glue shared by the ``script:`` adapters: logging to the rule's log file, once per job.

Third-party chatter (scikit-fem's "Initializing CellBasis..." and "Transforming
over 1000 vertices to C_CONTIGUOUS", matplotlib's font cache, numexpr's thread
count) is off: set ``FINGER_REHAB_VERBOSE_LIBS=1`` in the environment to keep
it.  Each job's log ends with one summary line, e.g.
``done: 12 solves, 12 converged, 0 failed, 43.2 s`` (solves are counted from
the lines that report them, see :mod:`workflow.common.runlog`).
"""

from __future__ import annotations

import atexit
import logging
import os
import sys
import time
from pathlib import Path

from workflow.common.provenance import CorruptInputError

#: Libraries whose chatter would bury the workflow's own lines, and the least level they still log: scikit-fem
#: warns at WARNING that it copies a mesh to C order (a speed note, not a problem of the run).
QUIET_LIBRARIES = {
    "skfem": logging.ERROR,
    **{
        name: logging.WARNING
        for name in (
            "matplotlib",
            "numexpr",
            "PIL",
            "fontTools",
            "h5py",
            "urllib3",
            "mlflow",
            "alembic",
            "git",
            "numba",
        )
    },
}
VERBOSE_ENV = "FINGER_REHAB_VERBOSE_LIBS"


class _SolveTally(logging.Handler):
    """Counts the solves reported by records carrying ``extra=workflow.common.runlog.solved(...)``."""

    def __init__(self) -> None:
        super().__init__()
        self.solves = self.failed = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.solves += getattr(record, "solves", 0)
        self.failed += getattr(record, "solves_failed", 0)

    def summary(self) -> str:
        if not self.solves:
            return ""
        return (
            f"{self.solves} solve{'s' if self.solves != 1 else ''}, {self.solves - self.failed} converged, "
            f"{self.failed} failed, "
        )


def setup_logging(snakemake) -> logging.Logger:  # noqa: ANN001 - Snakemake's object
    """Send ``logging`` output (INFO and up) to the rule's log file and stderr.

    Returns the logger named after the rule.  An uncaught exception is logged
    with its traceback before the job fails; a damaged input file
    (:class:`workflow.common.provenance.CorruptInputError`) with its one-line message only.
    """
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if snakemake.log:
        log_path = Path(str(snakemake.log[0]))
        log_path.parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w"))
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", handlers=handlers, force=True
    )
    verbose = os.environ.get(VERBOSE_ENV, "").strip().lower() not in ("", "0", "false", "no")
    for name, level in QUIET_LIBRARIES.items():
        logging.getLogger(name).setLevel(logging.NOTSET if verbose else level)
    tally = _SolveTally()
    logging.getLogger().addHandler(tally)
    logger = logging.getLogger(snakemake.rule)
    t0, failed = time.perf_counter(), []

    def _hook(exc_type, exc, tb):  # noqa: ANN001
        failed.append(exc)
        if isinstance(exc, CorruptInputError):  # the message says it all: file, what is wrong, the fix
            logger.error("rule %s: %s", snakemake.rule, exc)
        else:
            logger.error("rule %s failed", snakemake.rule, exc_info=(exc_type, exc, tb))

    def _summary():
        state = "failed after" if failed else "done:"
        logger.log(
            logging.ERROR if failed else logging.INFO, "%s %s%.1f s", state, tally.summary(), time.perf_counter() - t0
        )

    sys.excepthook = _hook
    atexit.register(_summary)
    return logger
