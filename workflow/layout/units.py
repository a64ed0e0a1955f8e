"""The units per group a layout file holds (the search's rank-k candidate, or the chosen one): read by the plan
rule too, so it stays apart from the layout stage's plots and entry points."""

from __future__ import annotations

import numpy as np
import xarray as xr

__all__ = ["chosen_units", "rank_index", "top_units"]


def rank_index(search: xr.Dataset, k: int) -> int:
    """The candidate index of the search's rank-``k`` layout (0 = best on the chain); ``ValueError`` if none."""
    hit = np.flatnonzero(search["rank"].values == int(k))
    if hit.size == 0:
        raise ValueError(f"the layout search holds {search.sizes['candidate']} layouts, none of rank {k}")
    return int(hit[0])


def top_units(search: xr.Dataset, k: int) -> dict[str, int]:
    """The units per group of the search's rank-``k`` layout (0 = best on the chain)."""
    return {str(g): int(v) for g, v in zip(search["group"].values, search["units"].values[rank_index(search, k)])}


def chosen_units(choice: xr.Dataset) -> dict[str, int]:
    """The units per group a layout choice (``layout.nc``) chose."""
    return {str(g): int(v) for g, v in zip(choice["group"].values, choice["chosen_units"].values)}
