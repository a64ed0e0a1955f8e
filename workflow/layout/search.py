"""Units per group searched against a forward model: every layout within the bounds, ranked.

A layout is the number of units of each group (CMC, MCP, PIP, DIP). The candidates are every integer combination
within per-group bounds whose actuator is no longer and no heavier than the bounds allow. Each is scored by an
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

from workflow.common.constants import GROUPS

__all__ = ["LayoutOutcome", "candidate_layouts", "rank_outcomes", "search_layouts"]


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

    def key(self) -> tuple[float, float, int]:
        """Sort key: the most exercises reached, then the least mean pressure, then the fewest units."""
        p = self.mean_pressure_kpa if np.isfinite(self.mean_pressure_kpa) else np.inf
        return (-self.n_reached, round(float(p), 9), int(sum(self.layout)))


def candidate_layouts(
    bounds: Mapping[str, Sequence[int]],
    *,
    unit_length_mm: float,
    unit_mass_g: float,
    max_length_mm: float = np.inf,
    max_mass_g: float = np.inf,
    max_candidates: int | None = None,
) -> list[tuple[int, int, int, int]]:
    """Every (CMC, MCP, PIP, DIP) within ``bounds`` ({group: [lo, hi]}, inclusive) whose actuator length
    (units x ``unit_length_mm``) and mass (units x ``unit_mass_g``) are within the bounds.

    Raises ``ValueError`` for a missing or reversed bound, a bound below one unit, or more candidates than
    ``max_candidates``.
    """
    ranges = []
    for g in GROUPS:
        if g not in bounds:
            raise ValueError(f"layout bounds: no bound for group {g}")
        lo, hi = (int(v) for v in bounds[g])
        if lo < 1 or hi < lo:
            raise ValueError(f"layout bounds: {g} = [{lo}, {hi}] must satisfy 1 <= lo <= hi")
        ranges.append(range(lo, hi + 1))
    out = [
        c
        for c in itertools.product(*ranges)
        if sum(c) * unit_length_mm <= max_length_mm + 1e-9 and sum(c) * unit_mass_g <= max_mass_g + 1e-9
    ]
    if not out:
        raise ValueError(
            f"layout bounds: no layout within {max_length_mm:g} mm and {max_mass_g:g} g "
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
