"""What a sweep ray is, shared by the sweep and the fidelity study, which solves the sweep's P_B = 0 ray on its
coarser meshes: the ray's load factors, and the hash of the config it is solved with.

In a module of their own so that the study's FE cases, whose rules track the code they import, do not rerun when
the sweep's code changes.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from workflow.common.provenance import config_sha256

__all__ = ["sweep_scales", "shared_stops", "ray_config_sha256"]


def sweep_scales(n_pressures: int) -> np.ndarray:
    """Load factors s = 1/n, 2/n, ..., 1 of a sweep ray's samples (fractions of its end pressure)."""
    return np.arange(1, int(n_pressures) + 1) / int(n_pressures)


def shared_stops(p_top_kpa: Sequence[float], sweep: Mapping[str, Any] | None) -> tuple[float, ...]:
    """The sweep ray's load factors for a ray through the study points ``p_top_kpa`` (kPa, P_B = 0), or () where
    they cannot be the same ray: the sweep's end pressure ``p_max_kpa`` is not the study's largest point, or a study
    point is not one of the sweep's samples (within 1e-9 of the end pressure), so that the ray would take steps the
    sweep's does not."""
    if not sweep:
        return ()
    p = np.asarray(p_top_kpa, float)
    pmax = float(p.max())
    if float(sweep["p_max_kpa"]) != pmax:
        return ()
    scales = sweep_scales(sweep["n_pressures"])
    if not all(np.min(np.abs(scales - v)) <= 1e-9 for v in p / pmax):
        return ()
    return tuple(float(s) for s in scales)


def ray_config_sha256(actuator: Mapping[str, Any]) -> str:
    """Hash of the actuator config a ray is solved with, its Newton budget left out (compared on its own)."""
    return config_sha256({k: v for k, v in dict(actuator).items() if k != "iteration_budget"})
