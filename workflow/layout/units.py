"""The units per group a layout file holds (the search's rank-k candidate, or the chosen one): read by the plan
rule too, so it stays apart from the layout stage's plots and entry points."""

from __future__ import annotations

import numpy as np
import xarray as xr

__all__ = ["chosen_units", "top_units"]


def top_units(search: xr.Dataset, k: int) -> dict[str, int]:
    """The units per group of the search's rank-``k`` layout (0 = best on the chain).

    Raises ``ValueError`` when the search holds fewer than ``k + 1`` layouts.
    """
    hit = np.flatnonzero(search["rank"].values == int(k))
    if hit.size == 0:
        raise ValueError(f"the layout search holds {search.sizes['candidate']} layouts, none of rank {k}")
    return {str(g): int(v) for g, v in zip(search["group"].values, search["units"].values[int(hit[0])])}


def chosen_units(choice: xr.Dataset) -> dict[str, int]:
    """The units per group a layout choice (``layout.nc``) chose."""
    return {str(g): int(v) for g, v in zip(choice["group"].values, choice["chosen_units"].values)}
