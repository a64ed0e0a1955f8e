"""Pressure limits: no chamber pressure beyond what was simulated or what the silicone bears.

Every pressure a plan, a correction step or an FEA check applies (the 2D
pressures after the 2D-to-3D mapping too) is bounded by the smallest of the
material limit (config ``actuator.material.p_limit_kpa``; default 300 kPa,
the largest pressure Chung & Venter 2024 considered, Fig. 11), the pressure
range the surrogate in use was fitted on (its sweep's p_max) and, for plans,
``cascade.p_max_kpa``.  The config check (:mod:`workflow.settings`) refuses a
config that asks for more; at run time the bound is applied again where the
pressures are made, and anything cut back to it is logged.  Pressures in kPa.
No I/O here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

__all__ = ["PressureLimit", "material_limit", "smallest", "clip_pressures", "DEFAULT_LIMIT_KPA", "DEFAULT_SOURCE"]

log = logging.getLogger(__name__)

DEFAULT_LIMIT_KPA = 300.0
DEFAULT_SOURCE = "Chung & Venter 2024, Fig. 11: the largest pressure considered"


@dataclass(frozen=True)
class PressureLimit:
    """A pressure bound (kPa) and what sets it (a config key and its source, or a surrogate's sampled range)."""

    kpa: float
    source: str

    def __str__(self) -> str:
        return f"{self.kpa:g} kPa ({self.source})"


def material_limit(material_cfg: Mapping[str, Any] | None) -> PressureLimit:
    """The silicone's limit from the config's ``actuator.material`` section."""
    mat = dict(material_cfg or {})
    kpa = float(mat.get("p_limit_kpa", DEFAULT_LIMIT_KPA))
    return PressureLimit(kpa, f"actuator.material.p_limit_kpa: {mat.get('p_limit_source', DEFAULT_SOURCE)}")


def smallest(*limits: PressureLimit | None) -> PressureLimit:
    """The tightest of the given limits (None and infinite ones are skipped; none at all: no bound)."""
    given = [lim for lim in limits if lim is not None and np.isfinite(lim.kpa)]
    return min(given, key=lambda lim: lim.kpa) if given else PressureLimit(np.inf, "no bound given")


def clip_pressures(p_kpa, limit: PressureLimit, *, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``p_kpa`` cut back to the limit, and where it was cut; a warning names what, how many and the limit."""
    p = np.asarray(p_kpa, float)
    over = p > limit.kpa * (1 + 1e-12)  # a value scaled onto the bound is not over it
    if over.any():
        log.warning(
            "%s: %d pressure(s) up to %.1f kPa cut back to the limit %s",
            what,
            int(over.sum()),
            float(p[over].max()),
            limit,
        )
    return np.minimum(p, limit.kpa), over
