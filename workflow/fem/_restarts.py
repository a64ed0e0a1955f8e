"""One mechanism for a solve that stalls: try it again with other contact and solver settings.

A stall of these models is mostly a contact event (blocks meeting corner to corner, a pocket squeezed flat) that
other steps or a wider regularisation band carry past (docs/fea.md, "Newton with contact").  Every FE model of the
workflow retries through :func:`first_converged`, with one of two ways to build its attempts:

* :func:`separate_attempts`: each restart applied alone over the configured settings (the unit's rays:
  ``actuator.restarts``);
* :func:`cumulative_attempts`: each restart applied over the previous ones (the whole actuator, on the finger and
  stand-alone: ``fea_check.restarts``).
"""

from __future__ import annotations

import logging
from typing import Callable, Iterable, Mapping, Sequence, TypeVar

__all__ = ["cumulative_attempts", "first_converged", "separate_attempts"]

log = logging.getLogger(__name__)
R = TypeVar("R")


def _band(contact: Mapping) -> str:
    """The contact band of an attempt for the log: one number, or one per model."""
    band = contact.get("smoothing_mm", "default")
    if isinstance(band, Mapping):
        return " / ".join(f"{k} {v:g}" for k, v in band.items())
    return f"{band:g}" if isinstance(band, (int, float)) else str(band)


def _over(base: Mapping, override: Mapping) -> dict:
    return {**dict(base), **dict(override)}


def separate_attempts(contact: Mapping, solver: Mapping, restarts: Sequence[Mapping]) -> list[tuple[dict, dict]]:
    """(contact, solver) per attempt: as configured, then each restart's ``contact``/``solver`` alone over it."""
    out = [(dict(contact), dict(solver))]
    for r in restarts:
        out.append((_over(contact, r.get("contact", {})), _over(solver, r.get("solver", {}))))
    return out


def cumulative_attempts(contact: Mapping, solver: Mapping, restarts: Sequence[Mapping]) -> list[tuple[dict, dict]]:
    """(contact, solver) per attempt: as configured, then each restart applied over the previous attempt."""
    out = [(dict(contact), dict(solver))]
    for r in restarts:
        c, s = out[-1]
        out.append((_over(c, r.get("contact", {})), _over(s, r.get("solver", {}))))
    return out


def first_converged(
    attempts: Iterable[tuple[dict, dict]],
    solve: Callable[[dict, dict], R],
    label: str = "solve",
    budget_left: Callable[[], bool] | None = None,
) -> tuple[R, int]:
    """Run ``solve(contact, solver)`` per attempt until one converges (``status`` 0).

    Returns that result and its attempt index (0 = as configured), else the one that got furthest
    (``load_factor``) and its index.  Each stall is logged.  ``budget_left()`` (optional) is asked
    before every attempt after the first: False ends the attempts (a shared budget is spent).
    """
    best, best_k = None, -1
    for k, (contact, solver) in enumerate(attempts):
        if k > 0 and budget_left is not None and not budget_left():
            log.info("%s: budget spent after %d attempt(s), no further restart", label, k)
            break
        res = solve(contact, solver)
        if res.status == 0:
            return res, k
        log.info(
            "%s: attempt %d (band %s mm, %s) stopped at %.0f %% (%s)",
            label,
            k + 1,
            _band(contact),
            {key: v for key, v in solver.items() if key in ("predictor", "max_step")} or "configured steps",
            100 * res.load_factor,
            getattr(res, "reason", ""),
        )
        if best is None or res.load_factor > best.load_factor:
            best, best_k = res, k
    return best, best_k
