"""Units per group searched against a forward model: every layout within the bounds, ranked.

A layout is the number of units of each group (CMC, MCP, PIP, DIP). The candidates are every integer combination
within per-group bounds whose actuator is no longer and no heavier than the bounds allow and reaches no further past
the fingertip than the overhang bound (the actuator's CMC group ends at the MCP joint, see
:func:`workflow.cascade.model.actuator_start_mm`, so the distal groups set how far it overhangs the tip). Each is scored by an
``evaluate`` callable (the reduced-order chain's plans, or any double of it in tests) and ranked: most exercises
reached first, then the least mean planned pressure (kPa), then the fewest units. The search is exhaustive, so it
returns the optimum of the ranking over the candidates, not a local one; its cost is one evaluation per candidate,
which is why the bounds are checked against ``max_candidates`` before any evaluation.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from workflow.cascade.model import actuator_start_mm
from workflow.common.constants import GROUPS

__all__ = ["LayoutOutcome", "candidate_layouts", "overhang_mm", "rank_outcomes", "ranking_key", "search_layouts"]


def ranking_key(n_reached: int, mean_pressure_kpa: float, tiebreak: int) -> tuple[int, float, int]:
    """Sort key of the search and of the choice: the most exercises reached, then the least mean pressure (kPa; a
    non-finite one last, rounded to 1e-9 so that equal plans tie), then the smaller ``tiebreak``."""
    p = float(mean_pressure_kpa) if np.isfinite(mean_pressure_kpa) else np.inf
    return (-int(n_reached), round(p, 9), int(tiebreak))


@dataclass(frozen=True)
class LayoutOutcome:
    """What a forward model says of one layout: per exercise reached or not, and the mean planned pressure (kPa)."""

    layout: tuple[int, int, int, int]
    reached: tuple[bool, ...]
    mean_pressure_kpa: float
    #: the planned pressures (exercise, 8) kPa, where the forward model gives them
    pressures_kpa: np.ndarray | None = None

    @property
    def n_reached(self) -> int:
        return int(sum(self.reached))

    def key(self) -> tuple[int, float, int]:
        """Sort key (:func:`ranking_key`): the most exercises reached, then the least mean pressure, then the fewest
        units."""
        return ranking_key(self.n_reached, self.mean_pressure_kpa, sum(self.layout))


def overhang_mm(layout: Sequence[int], *, unit_length_mm: float, tip_mm: float, layout_shift_mm: float = 0.0) -> float:
    """How far the actuator of ``layout`` (CMC, MCP, PIP, DIP units) reaches past the fingertip, mm (negative: it ends
    short of the tip). ``tip_mm``: the tip's distance from the MCP joint on the straight finger."""
    start = actuator_start_mm(layout[0], unit_length_mm, layout_shift_mm)
    return start + sum(int(v) for v in layout) * float(unit_length_mm) - float(tip_mm)


def candidate_layouts(
    bounds: Mapping[str, Sequence[int]],
    *,
    unit_length_mm: float,
    unit_mass_g: float,
    max_length_mm: float = np.inf,
    max_mass_g: float = np.inf,
    tip_mm: float | None = None,
    max_overhang_mm: float = np.inf,
    layout_shift_mm: float = 0.0,
    max_candidates: int | None = None,
) -> list[tuple[int, int, int, int]]:
    """Every (CMC, MCP, PIP, DIP) within ``bounds`` ({group: [lo, hi]}, inclusive) whose actuator length
    (units x ``unit_length_mm``), mass (units x ``unit_mass_g``) and, when ``tip_mm`` is given, overhang past the
    fingertip (:func:`overhang_mm`, mm) are within the bounds.

    Raises ``ValueError`` for a missing or reversed bound, a bound below one unit, no layout within the bounds, or
    more candidates than ``max_candidates``.
    """
    ranges = []
    for g in GROUPS:
        if g not in bounds:
            raise ValueError(f"layout bounds: no bound for group {g}")
        lo, hi = (int(v) for v in bounds[g])
        if lo < 1 or hi < lo:
            raise ValueError(f"layout bounds: {g} = [{lo}, {hi}] must satisfy 1 <= lo <= hi")
        ranges.append(range(lo, hi + 1))

    def overhangs(c):
        if tip_mm is None:
            return False
        return overhang_mm(c, unit_length_mm=unit_length_mm, tip_mm=tip_mm, layout_shift_mm=layout_shift_mm) > (
            max_overhang_mm + 1e-9
        )

    out = [
        c
        for c in itertools.product(*ranges)
        if sum(c) * unit_length_mm <= max_length_mm + 1e-9
        and sum(c) * unit_mass_g <= max_mass_g + 1e-9
        and not overhangs(c)
    ]
    if not out:
        past = f" and {max_overhang_mm:g} mm past the fingertip" if tip_mm is not None else ""
        raise ValueError(
            f"layout bounds: no layout within {max_length_mm:g} mm, {max_mass_g:g} g{past} "
            f"(a unit is {unit_length_mm:g} mm and {unit_mass_g:.3g} g)"
        )
    if max_candidates is not None and len(out) > max_candidates:
        raise ValueError(f"layout bounds: {len(out)} candidates, more than max_candidates = {max_candidates}")
    return out


def rank_outcomes(outcomes: Sequence[LayoutOutcome]) -> list[int]:
    """Indices of ``outcomes``, best first (see :meth:`LayoutOutcome.key`; ties keep the candidates' order)."""
    return sorted(range(len(outcomes)), key=lambda i: outcomes[i].key())


def search_layouts(
    candidates: Sequence[tuple[int, int, int, int]],
    evaluate: Callable[[tuple[int, int, int, int]], LayoutOutcome],
    progress: Callable[[int, int], None] | None = None,
) -> tuple[list[LayoutOutcome], list[int]]:
    """Evaluate every candidate; return the outcomes (candidates' order) and their ranking, best first."""
    outcomes = []
    for i, c in enumerate(candidates):
        outcomes.append(evaluate(tuple(int(v) for v in c)))
        if progress is not None:
            progress(i + 1, len(candidates))
    return outcomes, rank_outcomes(outcomes)
