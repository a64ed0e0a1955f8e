"""The choice among the layouts the FEA checked: the chain's best few and the default beside them.

The chain ranks every layout, but its verdict on the exercises is not the FEA's; so the choice is made on the FEA
check alone: the most exercises the FEA reaches, then the least mean planned pressure (kPa), then the better chain
rank. The default layout (the plan a patient gets without the layout design: ``cascade.units_per_group``, else the
length rule of section 2.3) is checked on the same chain and mesh and competes on the same terms, so the design never
chooses a layout the FEA finds worse than the default.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from workflow.layout.search import ranking_key

__all__ = ["CheckedLayout", "choose_layout", "why_chosen"]


@dataclass(frozen=True)
class CheckedLayout:
    """One layout the FEA checked."""

    #: how it came to be checked: ``"rank k"`` (the chain's rank-k layout) or ``"default"`` (the plan's without the layout design)
    label: str
    #: units per group (CMC, MCP, PIP, DIP)
    units: tuple[int, int, int, int]
    #: per exercise: reached on the chain / by the FEA check (after its correction step)
    chain_reached: np.ndarray
    fea_reached: np.ndarray
    #: the mean planned chamber pressure over the exercises, kPa
    mean_pressure_kpa: float
    #: its rank among the search's candidates (0 = best); the number of candidates when it is not one of them
    chain_rank: int

    def key(self) -> tuple[int, float, int]:
        """Sort key (:func:`workflow.layout.search.ranking_key`): the most exercises the FEA reaches, then the least
        mean planned pressure, then the better chain rank."""
        return ranking_key(int(np.sum(self.fea_reached)), self.mean_pressure_kpa, self.chain_rank)


def choose_layout(checked: Sequence[CheckedLayout]) -> int:
    """The index of the chosen layout in ``checked``: the most exercises the FEA reaches, then the least mean planned
    pressure, then the better chain rank (ties keep ``checked``'s order). ``ValueError`` if nothing was checked."""
    if not checked:
        raise ValueError("layout choice: no FEA-checked layout to choose from")
    return min(range(len(checked)), key=lambda i: checked[i].key())


def _how(c: CheckedLayout, n_candidates: int | None) -> str:
    if c.label != "default":
        return f"{c.label} on the chain"
    if n_candidates is not None and c.chain_rank >= n_candidates:
        return "the default layout, outside the searched bounds"
    return f"the default layout, rank {c.chain_rank} on the chain"


def why_chosen(
    checked: Sequence[CheckedLayout], winner: int, exercises: Sequence[str], n_candidates: int | None = None
) -> str:
    """One sentence saying why ``checked[winner]`` won, naming the default's outcome when it lost (``n_candidates``:
    how many layouts the search ranked, to tell a default outside them)."""
    w = checked[winner]
    reached = [e for e, r in zip(exercises, w.fea_reached) if r]
    units = "/".join(str(v) for v in w.units)
    text = (
        f"{units} ({_how(w, n_candidates)}); the FEA reaches {len(reached)} of {len(exercises)} "
        f"({', '.join(reached) or 'none'}); the most of the {len(checked)} checked, then the least mean planned "
        f"pressure ({w.mean_pressure_kpa:.1f} kPa)"
    )
    default = [c for c in checked if c.label == "default"]
    if default and w.label != "default":
        d = default[0]
        text += (
            f"; the default {'/'.join(str(v) for v in d.units)} (the plan without the layout design) reaches "
            f"{int(np.sum(d.fea_reached))} at {d.mean_pressure_kpa:.1f} kPa"
        )
    return text
