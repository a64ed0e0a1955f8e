"""Glue shared by the ``script:`` adapters: logging to the rule's log file."""

from __future__ import annotations

import logging
import sys
from pathlib import Path


def setup_logging(snakemake) -> logging.Logger:  # noqa: ANN001 - Snakemake's object
    """Send ``logging`` output (INFO and up) to the rule's log file and stderr.

    Returns the logger named after the rule.  Uncaught exceptions are logged
    with their traceback before the job fails.
    """
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if snakemake.log:
        log_path = Path(str(snakemake.log[0]))
        log_path.parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w"))
    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        handlers=handlers,
        force=True,
    )
    logger = logging.getLogger(snakemake.rule)

    def _hook(exc_type, exc, tb):  # noqa: ANN001
        logger.error("rule %s failed", snakemake.rule, exc_info=(exc_type, exc, tb))

    sys.excepthook = _hook
    return logger
